// A controller vendor's kinematic description of a five-axis machine
// (docs/controllers.md): the values the controller stores (Siemens' swivel
// data record, Heidenhain's kinematics table, Fanuc's tool centre point
// parameters, Beckhoff's universal kinematics), the map from a neutral
// kinematics table onto them, their way back, and the controller's own
// kinematic transformation written from its public manual, apart from
// fivecal's chain code, so that an export is checked by a round trip and not
// only printed.
//
// One export path for every vendor (ExportToVendor): Absorb the identified
// errors into the model the vendor's kinematics can represent, map the
// absorbed table onto the vendor's values, propagate the identification's
// covariance onto their change, and evaluate the vendor's own kinematics
// with the new values over the poses (the round trip).
//
// Adding a vendor: a RegisteredVendor<XVendor> subclass (below) in
// cpp/src/controllers/<name>.cc with its header, one line
// `&XVendor::Instance()` in ControllerVendors() (vendor.cc), a writer of its
// file format in python/fivecal/io/<name>.py.
//
// Units: mm, degrees for rotary commands; each value in its VendorValue::unit.
#ifndef FIVECAL_CONTROLLERS_VENDOR_H_
#define FIVECAL_CONTROLLERS_VENDOR_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

// One value the controller stores, named as its manual names it.
struct VendorValue {
  std::string name;    // "$TC_CARR4[1]", "19703", "kinematik[91].axis[2].point[0]", ...
  // "mm", "deg", "" (a code: an axis type, a number), "letter" (a code that
  // is a letter: the value is its character code, 80 for "P"; shown and
  // written as the letter)
  std::string unit;
  std::string source;  // manual, edition, section and page
  // A code or a value fixed by the topology (a type letter, an axis number):
  // written, never changed by an export, not part of the covariance.
  bool fixed = false;
  // An error-motion table entry (MapMotions fills it, Map never does): a
  // volumetric compensation that a sphere check cannot verify, and whose
  // covariance with other values is not kept (VendorExport::covariance).
  bool motion = false;
};

// Conventions the user states where the public manual does not decide them
// (a sign, the frame a vector is expressed in): key -> value, each vendor
// validating its own keys (an unknown key, or a missing one it needs, is an
// std::invalid_argument naming the key and the values it takes).
using VendorOptions = std::map<std::string, std::string>;

// The absorption a vendor's kinematics represents for a machine.
struct VendorModel {
  ControllerModel model = ControllerModel::kTableTable;
  bool directions = true;
  bool tool_length = true;
};

class ControllerVendor {
 public:
  virtual ~ControllerVendor() = default;
  virtual std::string Name() const = 0;   // "siemens": the command's and the registry's name
  virtual std::string Title() const = 0;  // "Siemens SINUMERIK 840D sl / ONE: swivel data record"

  // The option keys this vendor reads, with what each means and its values.
  virtual std::map<std::string, std::string> OptionHelp() const = 0;

  // The model its kinematics represents for `m`; std::invalid_argument saying
  // why when the controller does not support the machine's topology.
  virtual VendorModel Model(const Machine& m, const VendorOptions& o) const = 0;

  // The values (names, units, sources) for `m`, in the order Map returns them.
  virtual std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const = 0;

  // The controller's values that describe `table` (a neutral kinematics
  // table of `m`, nominal or absorbed).
  virtual Eigen::VectorXd Map(const Machine& m, const KinematicsTable& table,
                              const VendorOptions& o) const = 0;

  // The way back: the neutral table that `values` describe (to read a
  // controller's current values, or a loaded file, into fivecal's terms).
  virtual KinematicsTable Table(const Machine& m, const Eigen::VectorXd& values,
                                const VendorOptions& o) const = 0;

  // Values that come from the error motions of theta (the identified
  // machine's full parameter vector), which no kinematics table carries:
  // Beckhoff's volumetric compensation tables. Same length and order as
  // Values, zero at every entry Map fills; Map(absorbed table) +
  // MapMotions(theta_e) are the new values, and theta_e's error motions are
  // then not for Absorb (no double counting). Empty (the default): the
  // vendor takes no error motions.
  virtual Eigen::VectorXd MapMotions(const Machine& /*m*/, const Eigen::VectorXd& /*theta*/,
                                     const VendorOptions& /*o*/) const {
    return Eigen::VectorXd();
  }

  // The controller's own kinematic transformation from its manual: the tool
  // points (N x 3, mm) that `values` give for the machine's commands q
  // (N x m.num_axes(), mm / degrees), in the controller's workpiece frame:
  // the machine frame at the zero pose, carried by the workpiece chain (a
  // controller knows no part frame; the work offset the user probes is it).
  // fivecal's part frame differs from it by KinematicsTable::part_origin /
  // part_rotation (a table axis's location error moves the part with it);
  // ExportToVendor and VendorToTheta apply that, not the vendor.
  virtual Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& values,
                                     const Eigen::MatrixXd& q, const VendorOptions& o) const = 0;
};

// What every vendor shares, written once: its one instance (what
// ControllerVendors() lists) and Name / Title from the class's constants
// kName and kTitle; the vendor writes only what differs (its options,
// model, values, map, way back and kinematics).
template <class Derived>
class RegisteredVendor : public ControllerVendor {
 public:
  static const Derived& Instance() {
    static const Derived vendor;
    return vendor;
  }
  std::string Name() const final { return Derived::kName; }
  std::string Title() const final { return Derived::kTitle; }
};

// The registered vendors, and one by name (std::invalid_argument listing the names).
const std::vector<const ControllerVendor*>& ControllerVendors();
const ControllerVendor& FindVendor(const std::string& name);

struct VendorExport {
  std::string vendor;
  VendorModel model;
  Absorption absorption;
  std::vector<VendorValue> values;
  Eigen::VectorXd old_values;   // the controller's current values (given, or the nominal machine's)
  Eigen::VectorXd new_values;   // old + change
  Eigen::VectorXd change;       // Map(absorbed table) - Map(nominal table) (+ MapMotions)
  // The change's 1 sigma of every value, from the identification's
  // covariance (0 for fixed values), and the covariance of the values
  // covariance_index lists: every value but the error-motion table entries
  // (VendorValue::motion), whose values x values covariance a fine grid
  // would make hundreds of MB and no consumer reads.
  Eigen::VectorXd sigma;
  std::vector<Eigen::Index> covariance_index;
  Eigen::MatrixXd covariance;
  // The round trip: the vendor's own kinematics with the new values, against
  // the absorbed model's tool points plus the workpiece shift (what fivecal's
  // compensated controller runs), over the poses; N x 3 mm and its max norm.
  Eigen::MatrixXd round_trip;
  double round_trip_max = 0;
  // The values' difference from the nominal machine's Map when old values
  // were given (a machine file that is not what the controller runs shows here).
  Eigen::VectorXd old_minus_nominal;
};

// theta_e: the identified machine's full parameter vector (errors; nominal 0;
// of the tool offset tip.* only the length along the tool axis is taken, and
// only by a vendor whose model holds the tool length: an offset across the
// spindle is the stylus's, not the machine's, and no vendor value holds it);
// theta_covariance: its covariance (num_parameters square; zero rows for
// parameters not estimated; an empty matrix: sigma NaN); poses: N x num_axes;
// old_values: the controller's current values (empty: the nominal machine's).
VendorExport ExportToVendor(const Machine& m, const ControllerVendor& vendor,
                            const Eigen::VectorXd& theta_e, const Eigen::MatrixXd& theta_covariance,
                            const Eigen::MatrixXd& poses, const VendorOptions& options,
                            const Eigen::VectorXd& old_values = Eigen::VectorXd());

// The covariance (num_parameters square) of the absorbed model's errors
// (Absorption::theta): what the new values compensate, as fivecal
// parameters, for verification after loading. Empty covariance: NaN.
Eigen::MatrixXd AbsorbedCovariance(const VendorExport& ex, const Eigen::MatrixXd& theta_covariance);

// What a controller running `values` does, in fivecal's terms: the vendor's
// own tool points (ToolPoints(values)) over the poses absorbed into the
// vendor's model (Absorption::theta: the errors of that model, relative to
// the nominal machine). Verification uses it to say what a loaded file changed.
Absorption VendorToTheta(const Machine& m, const ControllerVendor& vendor, const Eigen::VectorXd& values,
                         const Eigen::MatrixXd& poses, const VendorOptions& options);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_VENDOR_H_
