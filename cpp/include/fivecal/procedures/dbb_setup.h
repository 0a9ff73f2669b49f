// Where the two balls of a double ball bar are on the nominal machine, and the
// linear commands that put the spindle ball at a chosen place. Shared by the
// DBB test planners and analyses (Jiang & Cripps four-step test, Wang et al.
// simultaneous A/C test), which reason in the machine frame F.
//
//   spindle (tool) ball in F:  S = T_ft(q) . (tool_ball - p_last_tool)
//   table ball in F:           B = T_fw(q) . table_ball
//
// with the nominal (error-free) chains of kinematics.h. `tool_ball` is given
// in F at the zero pose, like the machine tip; `table_ball` in the workpiece
// frame (= F at the zero pose). Axis commands are mm / degrees.
#ifndef FIVECAL_DBB_SETUP_H_
#define FIVECAL_DBB_SETUP_H_

#include <Eigen/Core>

#include "fivecal/model/machine.h"

namespace fivecal {

// Nominal spindle-ball position in F at the axis commands `cmd` (num_axes values).
Eigen::Vector3d NominalToolBallInF(const Machine& m, const Eigen::VectorXd& cmd,
                                   const Eigen::Vector3d& tool_ball);

// Nominal table-ball position in F at the axis commands `cmd`.
Eigen::Vector3d NominalTableBallInF(const Machine& m, const Eigen::VectorXd& cmd,
                                    const Eigen::Vector3d& table_ball);

// Commands equal to `pose` except the tool-side linear axes, which are set so
// the nominal spindle ball sits at `target` (F). The tool-side chain is affine
// in its linear commands once its rotary axes are fixed, so one linear solve is
// exact. Throws std::invalid_argument when the tool side has no three
// independent linear axes (the spindle ball could not be placed freely).
Eigen::VectorXd ToolBallCommands(const Machine& m, const Eigen::Vector3d& tool_ball,
                                 const Eigen::Vector3d& target, const Eigen::VectorXd& pose);

// The nominal tool ball seen from the workpiece (the tool point of
// kinematics.h with tip = tool_ball) at the axis commands `cmd`.
Eigen::Vector3d NominalToolBallInWorkpiece(const Machine& m, const Eigen::VectorXd& cmd,
                                           const Eigen::Vector3d& tool_ball);

// Each pose (a row of `poses`, N x num_axes, mm / degrees) with its linear
// axes, on either branch, moved so that the nominal balls are `length` apart,
// the tool ball moving along the bar (the line from the table ball, workpiece
// frame, through the tool ball). As in ToolBallCommands the tool ball is
// affine in the linear commands once the rotary axes are fixed, so one
// linear solve is exact (a second one removes rounding); with more than
// three linear axes the smallest change of the commands is taken (minimum
// norm). Throws std::invalid_argument naming the field for a length not
// > 0, non-finite commands, a pose where the balls coincide (no bar
// direction), or linear axes that cannot move the ball in three independent
// directions.
Eigen::MatrixXd BarLengthCommands(const Machine& m, const Eigen::Vector3d& tool_ball,
                                  const Eigen::Vector3d& table_ball, double length,
                                  const Eigen::MatrixXd& poses);

}  // namespace fivecal

#endif  // FIVECAL_DBB_SETUP_H_
