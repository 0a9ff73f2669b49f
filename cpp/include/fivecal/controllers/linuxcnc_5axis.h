// Controller model: LinuxCNC's 5axiskins (src/emc/kinematics/5axiskins.c of
// LinuxCNC 2.9 as packaged in Debian 12): a spindle head carrying C (about z)
// and on it B (about y), both axes meeting at the pivot, the tool tip
// `pivot-length` below it on the C axis.
//
// With joints X Y Z B C (mm, degrees) and L = pivot-length the forward
// kinematics (W = 0) is
//
//   p = 180 deg - B
//   world = (X, Y, Z) + L (sin p cos C, sin p sin C, cos p) + (0, 0, L)
//
// so at B = 0 the world point is the joints' X Y Z. LinuxCNC's B turns the
// tool about -y and its C about +z (5axiskins.c, note 10 on the tilt
// direction).
//
// A fivecal machine matches when its tool chain holds C and, after it, B
// (both rotary, C along +-z, B along +-y), B's line crosses the C axis, the
// tool tip lies on the C axis, and X Y Z are along the machine axes. The
// joint is sign * the fivecal command: u.e for a tool-side linear axis and
// -u.e for a workpiece-side one; sign(u_z) for C, -sign(u_y) for B.
#ifndef FIVECAL_CONTROLLERS_LINUXCNC_5AXIS_H_
#define FIVECAL_CONTROLLERS_LINUXCNC_5AXIS_H_

#include <Eigen/Core>
#include <array>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

struct FiveAxisMapping {
  std::array<int, 5> axis{};     // index into Machine::axes() of joints X Y Z B C
  std::array<double, 5> sign{};  // joint = sign * fivecal command
  double pivot_length = 0;       // mm: B's pivot above the tool tip
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // world = workpiece point - origin
};

// Throws std::invalid_argument saying why the machine does not fit.
FiveAxisMapping MatchFiveAxis(const Machine& m);

// 5axiskins.c forward kinematics: joints (N x 5: X Y Z B C, mm / degrees) ->
// world (N x 3, mm).
Eigen::MatrixXd FiveAxisForward(double pivot_length, const Eigen::MatrixXd& joints);
// Its inverse: world rows (N x 5: X Y Z B C) -> joints (N x 5).
Eigen::MatrixXd FiveAxisInverse(double pivot_length, const Eigen::MatrixXd& world);
// Joints (N x 5) for fivecal commands (N x num_axes, mm / degrees).
Eigen::MatrixXd FiveAxisJoints(const Machine& m, const FiveAxisMapping& map,
                               const Eigen::MatrixXd& commands);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_LINUXCNC_5AXIS_H_
