// Inverse kinematics: axis commands that put the tool point (and, when a tool
// axis is given, the tool axis) at a target in the workpiece frame.
//
// The orientation axes (the rotary axes other than the spindle S) are solved
// in closed form (Paden-Kahan subproblem 2 on the tool axis direction), which
// gives up to two solutions; each angle is unwrapped by multiples of 360 deg
// to the equivalent nearest the current pose and the solution with the
// smallest squared move is taken (Wang et al. 2013). The linear axes then
// follow from a linear solve, since with the rotary axes fixed the nominal
// tool point is affine in the linear commands. With non-zero error values the
// nominal solution seeds a Gauss-Newton refinement on the erroneous model,
// which is what compensation needs.
#ifndef FIVECAL_INVERSE_H_
#define FIVECAL_INVERSE_H_

#include <Eigen/Core>

#include "fivecal/model/machine.h"

namespace fivecal {

struct InverseOptions {
  int max_iterations = 50;
  double tolerance = 1e-12;  // mm (and rad for the tool axis)
};

// points: N x 3 targets (mm, workpiece frame). tool_axes: N x 3 target tool
// axis directions or null (then the orientation axes keep their current
// values). start: the current pose (num_axes values, mm / degrees). Each pose
// is solved from the previous solution, so a path stays on one branch.
// dirs: optional N x num_axes approach directions for backlash.
// Returns N x num_axes commands in mm / degrees.
Eigen::MatrixXd InverseKinematics(const Machine& m, const Eigen::VectorXd& theta,
                                  const Eigen::MatrixXd& points, const Eigen::MatrixXd* tool_axes,
                                  const Eigen::VectorXd& start,
                                  const Eigen::MatrixXi* dirs = nullptr,
                                  const InverseOptions& options = InverseOptions());

}  // namespace fivecal

#endif  // FIVECAL_INVERSE_H_
