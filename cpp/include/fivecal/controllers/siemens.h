// Siemens SINUMERIK 840D sl / ONE: the swivel data record (TOOLCARRIER, the
// kinematic description CYCLE800 swivels with and TRAORI uses with
// transformer type 72) as a ControllerVendor (vendor.h, docs/controllers.md).
//
// The record n holds offset vectors I1 ($TC_CARR1..3[n]), I2 (4..6), I3
// (15..17), I4 (18..20), rotary axis vectors V1 (7..9), V2 (10..12) and the
// kinematics type $TC_CARR23[n]: "T" swivel head, "P" swivel table, "M" head
// + table (rotary axis 1 the head's). All in the machine axes X, Y, Z at the
// non-swivelled state, mm. Sources: SINUMERIK Operate commissioning manual
// 03/2013 (6FC5397-1DP40-3BA1) §22.6 p. 502; 12/2017 (6FC5397-1DP40-6BA1)
// §21.7 pp. 568, 572; function manual W1 tool offset 08/2005
// (6FC5397-0BP10-0BA0) §2.5 pp. 2-88, 2-91, 2-92 and example §4.1 p. 4-3.
//
// The transformation (ToolPoints), from those pages; R_k = rotation about V_k
// by the axis position, right-handed ("counted positively for clockwise
// rotation facing the direction of the rotation vector", W1 p. 2-92); L the
// tool length vector, from the tip to the tool adapter (W1 p. 2-88: offsets
// are positive from the tool tip towards the reference point); P = (X, Y, Z)
// the linear axes' position:
//
//   tool side  T:  tip = P - [I1 + R1 (I2 + R2 (I3 + L))]
//              M:  tip = P - [I1 + R1 (I2 + L)]
//              P:  tip = P - L
//   table side P:  machine position of the part point y
//                      = I2 + R1 (I3 + R2 (I4 + y)) - (I2 + I3 + I4)
//              M:      = I3 + R2 (I4 + y) - (I3 + I4)
//
// The table side is the zero offset the W1 example prints (I4 = (0, 0, 15),
// B = 45: X 10.607 = 15 sin 45, Z -4.393 = -15 (1 - cos 45)) with the
// table's rotation (PAROT) on top; for a closed chain (I4 = -(I2 + I3)) it is
// the rigid motion of the table about its two pivot lines.
//
// fivecal's frame: the machine reference point, and the tool adapter at the
// zero pose, are the machine file's origin; L = -(the machine file's tool tip)
// is tool data, never written. Map closes the table chain (I4) as the manual
// states for fixed kinematics, so the record carries no part frame: the
// controller's tool points are part_rotation * (fivecal's) + part_origin of
// the table mapped, the work offset the user probes. The tool chain keeps
// the identified tool position at the zero pose (I1 need not close), so that
// a head's pivot errors are reproduced exactly.
#ifndef FIVECAL_CONTROLLERS_SIEMENS_H_
#define FIVECAL_CONTROLLERS_SIEMENS_H_

#include <map>
#include <string>
#include <vector>

#include "fivecal/controllers/vendor.h"

namespace fivecal {
namespace controllers {

class SiemensVendor final : public RegisteredVendor<SiemensVendor> {
 public:
  static constexpr const char* kName = "siemens";
  static constexpr const char* kTitle =
      "Siemens SINUMERIK 840D sl / ONE: swivel data record (TOOLCARRIER, CYCLE800 / TRAORI)";
  std::map<std::string, std::string> OptionHelp() const override;
  VendorModel Model(const Machine& m, const VendorOptions& o) const override;
  std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const override;
  Eigen::VectorXd Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const override;
  KinematicsTable Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const override;
  Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                             const VendorOptions& o) const override;

  // 'T', 'P' or 'M' for the machine; std::invalid_argument saying why a
  // topology has no swivel data record.
  static char KinematicsType(const Machine& m);

  // The vectors a type uses, in the order of Values (each x, y, z), then
  // $TC_CARR23: T  I1 I2 I3 V1 V2;  P  I2 I3 I4 V1 V2;  M  I1 I2 I3 I4 V1 V2
  // (the manual's TOOLCARRIER <=> TRAORI table, 12/2017 p. 572, names no
  // other vector per type; the record's other vectors are left as they are).
  static std::vector<std::string> Vectors(char type);
};

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_SIEMENS_H_
