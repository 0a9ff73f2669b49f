// R-test evaluation (ISO 10791-6 style K tests, python/fivecal/procedures/
// rtest.py plans them): the ball3d samples are grouped by their mounting
// (`setup`; "" is "(no setup)"), in order of first appearance, and each
// group's figure is the range of the recorded deviation in X, Y and Z of the
// workpiece frame:
//
//   range_d = max_i m_i,d - min_i m_i,d        (mm, d = x y z)
//
// With `identify`, the location errors of the rotary axes are fitted to
// every group at once (Identify; each mounting's ball positions are part of
// the default set-up, as for any ball3d data).
//
// Units: mm, degrees for commands, rad for angular errors.
#ifndef FIVECAL_PROCEDURES_RTEST_H_
#define FIVECAL_PROCEDURES_RTEST_H_

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"

namespace fivecal {

// The location errors (ISO 230-7 position and orientation errors of an axis
// line) an R-test of the rotary axes can see: per rotary axis (spindle
// aside, topology order) PivotParameters(axis, false), spindle-named.
std::vector<std::string> RTestLocationErrors(const Machine& m);

// The two rotary axes of a K test: the turning axis (the one nearest the
// table normal / tool axis, the largest |z| of its direction at the zero
// pose, the first in topology order on a tie) and the tilting axis. Throws
// std::invalid_argument unless the machine has exactly two (spindle aside).
struct RTestRoles {
  char turn = 'C', tilt = 'A';
};
RTestRoles RTestAxisRoles(const Machine& m);

// The rotary poses of K test `test` (rows: turning, tilting axis, degrees):
//   K1  turn 0, step, ... 360, tilt 0
//   K2  turn 0, tilt tilt_min, tilt_min + step, ... tilt_max
//   K3  as K1 with the tilting axis at `tilt`
//   K4  as K1 with the tilting axis at tilt * sin(turn)
// Throws std::invalid_argument naming the field: test, step (finite, >= 360
// / 100000 deg: at most 100000 samples a turn), tilt, tilt_range.
Eigen::MatrixXd RTestSequence(const Machine& m, const std::string& test, double step, double tilt,
                              double tilt_min, double tilt_max);

// The axis commands of an R-test path (rtest.py plans them,
// nc_programs.rtest_program subdivides them): per row of `rotary` (N x
// num_axes, the rotary axes' commands but the spindle's; other columns are
// not read) the commands that put the tool ball on the table ball on the
// nominal machine. The tool ball is `tool_ball` (F at the zero pose), the
// table ball `table_ball` (workpiece frame); the tool tip's target is the
// table ball plus tip - ball turned with the rotary pose,
//   target = table_ball + P(q, tip) - P(q, tool_ball)
// (P: the tool point in the workpiece frame at the row's pose q), and the
// linear axes (and the spindle) come from InverseKinematics started at q.
// q takes its other axes from `start` for the first row and then, with
// `chain`, from the previous row's commands (a path), else from `start`
// again (points between two samples).
Eigen::MatrixXd RTestPathCommands(const Machine& m, const Eigen::MatrixXd& rotary, const Eigen::VectorXd& start,
                                  const Eigen::Vector3d& table_ball, const Eigen::Vector3d& tool_ball, bool chain);

struct RTestOptions {
  bool identify = true;
  std::vector<std::string> estimate;  // empty: RTestLocationErrors
};

struct RTestGroup {
  std::string name;            // the mounting (setup) id, "(no setup)" for ""
  std::vector<int> observations;
  Eigen::MatrixXd deviations;  // samples x 3, mm
  Eigen::Vector3d ranges = Eigen::Vector3d::Zero();
};

struct RTestResult {
  std::vector<RTestGroup> tests;
  bool identified = false;
  std::vector<std::string> estimated;  // what was asked of the fit
  Result fit;                          // when identified
};

// Throws std::invalid_argument: no ball3d observations, an empty name in
// `estimate`, and whatever Identify refuses (unknown names ...).
RTestResult EvaluateRTest(const Dataset& ds, const RTestOptions& options);

}  // namespace fivecal

#endif  // FIVECAL_PROCEDURES_RTEST_H_
