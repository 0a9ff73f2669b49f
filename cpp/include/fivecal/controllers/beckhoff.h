// Beckhoff TwinCAT 3 CNC (ISG kernel): the universal kinematics (TF5240,
// kinematic ID 91) and the volumetric compensation tables (TF5280) as one
// ControllerVendor (docs/controllers.md, "Beckhoff TwinCAT CNC").
//
// Sources: the Beckhoff Information System (infosys.beckhoff.com, English,
// the online help is the edition; pages named by their id):
//  * TF5240 Universal Kinematics: "Programming or description of the
//    kinematic chain" (278674827), "Sequence of axes in the kinematic chain"
//    (278706443), "3. Example of an AC machine with cardanic table"
//    (278732555), "Description of flange and tool" (556386059), "Classic
//    programming modes" (278765451);
//  * TF5200 channel parameters P-CHAN-00262 (trafo[j].id 91), -00285
//    zero_orientation, -00286 zero_position (0.1 um, written as unit 0.0001mm), -00289 number_of_axes,
//    -00290 chain[k], -00291 axis[k].type (1 translator, 2 rotator), -00292
//    axis[k].orientation, -00293 axis[k].point (0.1 um);
//  * TF5280 Volumetric compensation: "List of parameters supported"
//    (296423819: EXX ... ECC as ISO 230 component errors), "ISG CSV format"
//    (296429067), "Etalon Exchange Format" (296430091), P-VOLC-00007 chain,
//    -00009 negate, -00014 interpolation (GRID: linear interpolation).
//
// The universal kinematics, as those pages state it: every vector is in one
// coordinate system at the zero position; the chain walks from the workpiece
// to the machine origin and on to the tool tip, listing the channel indices
// of the axes met; a workpiece-side axis has its orientation multiplied by
// -1; type 1 moves along the orientation, type 2 turns about the line
// through `point` along the orientation (mathematically positive); the tool
// centre point at the zero position is zero_position - L * zero_orientation
// (L the tool length of the tool table). ID 91 has no parameter saying which
// axes are on the workpiece side, so every chain axis is applied alike: the
// stored vector of a workpiece-side axis is the motion of the next link
// relative to the table, the opposite of the table's own (carriage)
// direction. BeckhoffToolPoints below is that transformation.
//
// The volumetric tables carry what a kinematics cannot: the error motions of
// every axis (fivecal's polynomials, tabulated on a grid per axis and
// linearly interpolated). The split: location errors, pivots, directions and
// the tool length go to the kinematics (Absorb); the error motions go to the
// tables (MapMotions), never both.
#ifndef FIVECAL_CONTROLLERS_BECKHOFF_H_
#define FIVECAL_CONTROLLERS_BECKHOFF_H_

#include "fivecal/controllers/vendor.h"

namespace fivecal {
namespace controllers {

class BeckhoffVendor final : public RegisteredVendor<BeckhoffVendor> {
 public:
  static constexpr const char* kName = "beckhoff";
  static constexpr const char* kTitle =
      "Beckhoff TwinCAT 3 CNC / ISG: universal kinematics (TF5240, kinematic ID 91) and volumetric "
      "compensation tables (TF5280)";
  std::map<std::string, std::string> OptionHelp() const override;
  VendorModel Model(const Machine& m, const VendorOptions& o) const override;
  std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const override;
  Eigen::VectorXd Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const override;
  KinematicsTable Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const override;
  Eigen::VectorXd MapMotions(const Machine& m, const Eigen::VectorXd& theta,
                             const VendorOptions& o) const override;
  // ID 91 plus, with volcomp on, the TF5280 tables (see the file comment).
  Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                             const VendorOptions& o) const override;
};

// theta with every error-motion coefficient set to 0: what Absorb takes when
// the tables carry the error motions.
Eigen::VectorXd WithoutErrorMotions(const Machine& m, const Eigen::VectorXd& theta);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_BECKHOFF_H_
