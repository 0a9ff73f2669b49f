// Compensation of axis commands on the identified machine, batched over
// poses: the commands that put the real tool point (and, where the
// kinematics allow, the real tool axis) on the targets the nominal (or a
// reference) machine gives at the nominal commands.
//
// Every pose is solved on its own, seeded at its nominal commands, so each
// stays on its own solution branch (InverseKinematics of one row, start =
// the nominal pose). With `orientation`, the tool axis is kept too unless
// that needs a rotary correction (A B C) larger than max_rotary_correction
// degrees or has no solution (next to a singularity, e.g. the tool axis along
// a table axis): the pose then falls back to the tool point only, its
// rotary axes staying as commanded.
#ifndef FIVECAL_CONTROLLERS_COMPENSATE_H_
#define FIVECAL_CONTROLLERS_COMPENSATE_H_

#include <Eigen/Core>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

struct CompensatedCommands {
  Eigen::MatrixXd commands;   // N x num_axes, mm / degrees
  std::vector<bool> oriented; // the tool axis was compensated too
};

// theta: the identified machine. points / tool_axes (N x 3, workpiece frame):
// the targets; tool_axes may be null (tool point only). nominal: N x
// num_axes commands (the seeds). dirs: optional N x num_axes approach
// directions (backlash). Throws std::invalid_argument "pose i: ..." for a
// pose whose tool point cannot be reached.
CompensatedCommands CompensateCommands(const Machine& m, const Eigen::VectorXd& theta,
                                       const Eigen::MatrixXd& points, const Eigen::MatrixXd* tool_axes,
                                       const Eigen::MatrixXd& nominal, const Eigen::MatrixXi* dirs,
                                       bool orientation, double max_rotary_correction);

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_COMPENSATE_H_
