// Controller model: LinuxCNC's table-rotary-tilting kinematics
// (xyzac-trt-kins, xyzbc-trt-kins; src/emc/kinematics/trtfuncs.c of
// LinuxCNC 2.9 as packaged in Debian 12).
//
// LinuxCNC's model has five joints X Y Z T C (T = A or B, degrees) and these
// HAL input pins (mm):
//
//   xyzac-trt: x|y|z-rot-point, y-offset, z-offset, tool-offset
//   xyzbc-trt: x|y|z-rot-point, x-offset, z-offset, tool-offset
//
// With r = (x,y,z-rot-point), d = (0, y-offset, z-offset + tool-offset) for
// xyzac and d = (x-offset, 0, z-offset + tool-offset) for xyzbc, the
// inverse kinematics (world w -> joints j) of trtfuncs.c is
//
//   j_xyz = r + d + R_T(t) . ( Rz(c) . (w - r) - d )      R_T = Rx (xyzac), Ry (xyzbc)
//
// so the C axis is the line through r along +z, the tilt axis the line
// through r + d along +x (A) or +y (B), and a positive joint turns the table
// positively about +z / +x / +y (the opposite of ISO 841 for a table, which
// LinuxCNC's documentation notes). Only r + d matters along the tilt axis and
// only r_x, r_y for C: z-rot-point and z-offset trade off, so one of them is
// held (z-offset) when fitting.
//
// A fivecal machine matches when its workpiece chain (from the foundation)
// holds the tilt axis and then C, the linear axes X Y Z are parallel to the
// machine axes (either sign, on either side but not between a rotary axis and
// the workpiece) and the rotary directions are +-x|y and +-z. The joint value
// is sign * the fivecal command (sign = u.e for a workpiece-side rotary or a
// tool-side linear axis, -u.e for a workpiece-side linear axis), and
// LinuxCNC's world coordinates are the workpiece-frame tool point minus the
// machine's tool tip at the zero pose (the controlled point, tool-offset 0).
#ifndef FIVECAL_CONTROLLERS_LINUXCNC_TRT_H_
#define FIVECAL_CONTROLLERS_LINUXCNC_TRT_H_

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

enum class TrtKins { kXyzac, kXyzbc };

// "xyzac-trt" or "xyzbc-trt" (a trailing "-kins" is accepted); throws otherwise.
TrtKins ParseTrtKins(const std::string& name);
std::string TrtKinsName(TrtKins kins);  // "xyzac-trt" | "xyzbc-trt"

// Values of the HAL input pins, mm.
struct TrtPins {
  double x_rot_point = 0, y_rot_point = 0, z_rot_point = 0;
  double x_offset = 0, y_offset = 0, z_offset = 0, tool_offset = 0;
};

// The pin names a kinematics module has ("x-rot-point", ...), in a fixed order,
// and access to TrtPins by those names.
std::vector<std::string> TrtPinNames(TrtKins kins);
double& TrtPin(TrtPins& pins, const std::string& name);
double TrtPin(const TrtPins& pins, const std::string& name);

// LinuxCNC's forward kinematics: joints (X Y Z mm, T C degrees) -> world XYZ.
Eigen::Vector3d TrtForward(TrtKins kins, const TrtPins& pins, const Eigen::Matrix<double, 5, 1>& j);
// LinuxCNC's inverse kinematics: world XYZ at tilt t and rotation c (degrees) ->
// joint X Y Z.
Eigen::Vector3d TrtInverse(TrtKins kins, const TrtPins& pins, const Eigen::Vector3d& world,
                           double t_deg, double c_deg);

// Which fivecal axis drives each LinuxCNC joint (X Y Z T C), and how.
struct TrtMapping {
  TrtKins kins = TrtKins::kXyzac;
  std::array<int, 5> axis{};   // index into Machine::axes()
  std::array<double, 5> sign{};  // joint = sign * fivecal command
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world = workpiece point - origin
};

// Throws std::invalid_argument saying why the machine does not fit the model.
TrtMapping MatchTrt(const Machine& m, TrtKins kins);

// Joints (N x 5) from fivecal commands (N x num_axes, mm / degrees) and back
// (the spindle and any axis LinuxCNC lacks stay 0).
Eigen::MatrixXd TrtJoints(const Machine& m, const TrtMapping& map, const Eigen::MatrixXd& commands);
Eigen::MatrixXd TrtCommands(const Machine& m, const TrtMapping& map, const Eigen::MatrixXd& joints);

struct TrtFit {
  TrtPins pins;                        // best absorbing pin values
  std::vector<std::string> solved;     // the pins fitted (the others held)
  // Where the workpiece frame sits relative to the nominal one (mm): the
  // constant part of the error, which probing the part into the work offset
  // (G54) absorbs, so LinuxCNC's point is TrtForward + origin + this shift.
  Eigen::Vector3d workpiece_shift = Eigen::Vector3d::Zero();
  Eigen::Vector3d workpiece_shift_held = Eigen::Vector3d::Zero();
  Eigen::MatrixXd residual;            // N x 3 mm: true tool point - LinuxCNC's, after
  Eigen::MatrixXd residual_held;       // N x 3 mm: the same with the held (input) pins
  double rms = 0, max = 0;             // |residual| over the poses, mm
  double rms_held = 0, max_held = 0;   // with the input pins
};

// Pins that best absorb the machine errors theta, together with a constant
// workpiece shift (least squares of the tool point over the poses: N x num_axes fivecal commands, mm / degrees, spanning
// at least two tilt and two C angles). x/y/z-rot-point and the tilt axis's
// offset (y-offset for xyzac, x-offset for xyzbc) are fitted; z-offset and
// tool-offset are held at their values in `held`, which also gives the
// "before" pins for residual_held. With theta = 0 the fit returns the
// machine's nominal pins (residual 0).
TrtFit FitTrtPins(const Machine& m, TrtKins kins, const Eigen::VectorXd& theta,
                  const Eigen::MatrixXd& poses, const TrtPins& held);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_LINUXCNC_TRT_H_
