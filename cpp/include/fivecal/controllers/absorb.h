// What a controller's kinematic model can absorb of identified errors: one
// absorber for every controller model (docs/controllers.md).
//
// A controller model is a set of directions in fivecal's parameter space
// (ControllerParameter::column: the change of theta per unit of the
// controller value) that the controller's own kinematics can represent:
//
//   table-table, head-head, table-head   per rotary axis its pivot (the two
//       position components perpendicular to its direction), optionally its
//       direction (two small rotations perpendicular to it), and the tool
//       length (along the tool axis at the zero pose);
//   xyzac-trt, xyzbc-trt                 LinuxCNC's trt pins: the rotary
//       pivots only (linuxcnc_trt.h; the pins themselves come from
//       FitTrtPins, which Absorb also runs);
//   5axiskins                            LinuxCNC's pivot-length: the tool
//       length only (linuxcnc_5axis.h).
//
// Every model also takes a constant shift s of the workpiece frame (probing
// the part into the work offset absorbs it). With B the columns, P(theta, q)
// the tool point and theta_e the identified machine, Absorb solves
//
//   min_{phi, s}  sum_i | P(theta_e, q_i) - P(theta_0 + B phi, q_i) - s |^2
//
// by Gauss-Newton with the analytic Jacobian dP/dphi = (dP/dtheta) B
// (KinematicModel::ToolPointJacobian). Columns the poses cannot tell from
// earlier ones (the shift first, then the parameters in order; sequential
// projection at the start) are held at 0 and named in `held`.
//
// Units: mm, degrees for rotary commands, rad for angular parameters.
#ifndef FIVECAL_CONTROLLERS_ABSORB_H_
#define FIVECAL_CONTROLLERS_ABSORB_H_

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "fivecal/controllers/linuxcnc_trt.h"
#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

enum class ControllerModel { kTableTable, kHeadHead, kTableHead, kXyzacTrt, kXyzbcTrt, kFiveAxis };

// "table-table", "head-head", "table-head", "xyzac-trt", "xyzbc-trt",
// "5axiskins"; throws std::invalid_argument naming the expected ones.
ControllerModel ParseControllerModel(const std::string& name);
std::string ControllerModelName(ControllerModel model);
std::vector<std::string> ControllerModelNames();

struct ControllerParameter {
  std::string label;      // "C pivot x", "A direction about z", "tool length"
  std::string unit;       // "mm" or "rad"
  Eigen::VectorXd column; // num_parameters: d theta per unit of the value
};

// The parameters of `model` on the machine. directions and tool_length apply
// to the generic models (the LinuxCNC ones fix what they hold). Throws when
// the machine's topology does not fit the model, saying why.
std::vector<ControllerParameter> ControllerParameters(const Machine& m, ControllerModel model,
                                                      bool directions = false, bool tool_length = true);

struct AbsorbOptions {
  bool directions = false;
  bool tool_length = true;
  // LinuxCNC trt models: the pins held (z-offset, tool-offset) and the
  // "before" pins of TrtFit::residual_held.
  TrtPins held_pins;
};

struct Absorption {
  ControllerModel model = ControllerModel::kTableTable;
  std::vector<ControllerParameter> parameters;
  Eigen::VectorXd values;             // fitted controller values (mm, rad)
  std::vector<std::string> held;      // labels the poses cannot determine (held at 0)
  Eigen::VectorXd theta;              // fivecal parameters of the absorbed model
  Eigen::Vector3d workpiece_shift = Eigen::Vector3d::Zero();
  Eigen::MatrixXd residual;           // N x 3 mm: tool point error left
  Eigen::MatrixXd residual_old;       // N x 3 mm: with the nominal model, mean removed
  double rms = 0, max = 0, rms_old = 0, max_old = 0;
  std::optional<TrtFit> trt;          // the pins, for xyzac-trt / xyzbc-trt
  // d values / d theta_true (k x num_parameters) at the solution, the
  // Gauss-Newton linearisation: how the identification's covariance reaches
  // the controller values (rows of held values are 0). Empty when the truth
  // came as tool points (AbsorbToolPoints).
  Eigen::MatrixXd sensitivity;
};

// The least-squares absorption of the errors `theta` (the identified
// machine's full parameter vector) over `poses` (N x num_axes, mm / degrees).
Absorption Absorb(const Machine& m, ControllerModel model, const Eigen::VectorXd& theta,
                  const Eigen::MatrixXd& poses, const AbsorbOptions& options = AbsorbOptions());

// The frame given tool points are in: fivecal's part frame, or a
// controller's workpiece frame (vendor.h, ToolPoints): the part frame of the
// model being fitted carried by its KinematicsTable part_origin /
// part_rotation. A table axis's location error moves the part frame, so in
// the controller frame the frame's own derivative enters the Jacobian.
enum class PointFrame { kPart, kController };

// The same absorption of given tool points (N x 3, mm, in `frame`) at
// `poses`, for a truth that is not a fivecal machine (a controller's own
// kinematics with its values: VendorToTheta). No trt pins, no sensitivity.
Absorption AbsorbToolPoints(const Machine& m, ControllerModel model, const Eigen::MatrixXd& truth,
                            const Eigen::MatrixXd& poses, const AbsorbOptions& options = AbsorbOptions(),
                            PointFrame frame = PointFrame::kPart);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_ABSORB_H_
