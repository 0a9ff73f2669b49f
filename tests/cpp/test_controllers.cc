// The one controller absorber (generic pivots, LinuxCNC trt, 5axiskins),
// 5axiskins's kinematics and the batched compensation: represented errors
// are absorbed exactly, unrepresented ones leave a map whose fit is a
// least-squares optimum, and compensation puts the tool on its targets.
#include <gtest/gtest.h>

#include <random>

#include "controller_fixtures.h"
#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/compensate.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/controllers/linuxcnc_5axis.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {
namespace {

using test_fixtures::Poses;
using test_fixtures::Theta;

Machine HeadHead() {  // B on C in the spindle head, 5axiskins-like
  return Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,300]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
}

Machine TableTable() {
  return Machine::FromJson(R"({"name": "tt", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,1], "point": [12,-7,0]},
    "A": {"type": "rotary", "direction": [1,0,0], "point": [0,20,-45]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,150]}})");
}

TEST(Controllers, RepresentedErrorsAreAbsorbedExactly) {
  const Machine m = HeadHead();
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}, {"EY0C", -0.01}, {"EX0B", -0.01}, {"EZ0B", 0.015}, {"EA0B", 3e-5},
                                       {"EC0B", -2e-5}, {"tip.z", 0.01}});
  AbsorbOptions o;
  o.directions = true;
  const Absorption ab = Absorb(m, ControllerModel::kHeadHead, th, Poses(m, 80, 3), o);
  EXPECT_GT(ab.max_old, 5e-3);
  EXPECT_LT(ab.max, 1e-9);
  EXPECT_FALSE(ab.trt.has_value());
}

// The fit in a controller's frame (PointFrame::kController, what
// VendorToTheta uses): table location errors move fivecal's part frame, so
// the same points read in the part frame leave an error the controller-frame
// fit does not; the controller-frame fit recovers the model exactly.
TEST(Controllers, ControllerFrameFitRecoversTheModelInItsOwnFrame) {
  const Machine m = TableTable();
  const Eigen::MatrixXd q = Poses(m, 60, 4);
  AbsorbOptions o;
  o.directions = true;
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}, {"EY0A", -0.015}, {"EZ0A", 0.01}, {"EB0A", 4e-5},
                                       {"EC0A", -3e-5}, {"EA0C", 2e-5}});
  const Absorption exact = Absorb(m, ControllerModel::kTableTable, th, q, o);
  ASSERT_LT(exact.max, 1e-9);
  const KinematicsTable t = MakeKinematicsTable(m, exact.theta);
  const Eigen::MatrixXd controller =
      (ToolPoints(m, exact.theta, q) * t.part_rotation.transpose()).rowwise() + t.part_origin.transpose();
  const Absorption ab = AbsorbToolPoints(m, ControllerModel::kTableTable, controller, q, o, PointFrame::kController);
  EXPECT_LT(ab.max, 1e-9);
  EXPECT_LT((ab.theta - exact.theta).cwiseAbs().maxCoeff(), 1e-8);
  const Absorption part = AbsorbToolPoints(m, ControllerModel::kTableTable, controller, q, o, PointFrame::kPart);
  EXPECT_GT(part.max, 1e-4);  // the frame's own motion is not a pivot change
}

TEST(Controllers, UnrepresentedErrorsLeaveAStationaryFit) {
  // The absorber's analytic Jacobian: at the optimum the residual is
  // orthogonal to every finite-difference column of the model.
  const Machine m = TableTable();
  const Eigen::MatrixXd q = Poses(m, 60, 3);
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.03}, {"EA0C", 4e-5}, {"EB0A", -3e-5}, {"EC0Y", 5e-5}});
  AbsorbOptions o;
  o.directions = true;
  const Absorption ab = Absorb(m, ControllerModel::kTableTable, th, q, o);
  EXPECT_GT(ab.max, 1e-3);
  EXPECT_LT(ab.rms, ab.rms_old);
  Eigen::VectorXd r(3 * q.rows());
  for (int i = 0; i < q.rows(); ++i) r.segment<3>(3 * i) = ab.residual.row(i).transpose();
  for (const ControllerParameter& p : ab.parameters) {
    const double h = p.unit == "mm" ? 1e-4 : 1e-7;
    const Eigen::MatrixXd d = (ToolPoints(m, ab.theta + h * p.column, q) -
                               ToolPoints(m, ab.theta - h * p.column, q)) / (2 * h);
    Eigen::VectorXd col(3 * q.rows());
    for (int i = 0; i < q.rows(); ++i) col.segment<3>(3 * i) = d.row(i).transpose();
    EXPECT_LT(std::abs(col.dot(r)) / (col.norm() * r.norm()), 1e-7) << p.label;
  }
}

TEST(Controllers, TrtModelCarriesThePinsAndLeavesTheirMap) {
  const Machine m = TableTable();
  const Eigen::MatrixXd q = Poses(m, 60, 3);
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.03}, {"EY0A", -0.02}, {"EA0C", 2e-5}});
  const Absorption ab = Absorb(m, ControllerModel::kXyzacTrt, th, q);
  ASSERT_TRUE(ab.trt.has_value());
  EXPECT_NEAR(ab.rms, ab.trt->rms, 1e-9);
  EXPECT_NEAR(ab.max, ab.trt->max, 1e-9);
}

TEST(Controllers, ModelsRefuseMachinesThatDoNotFit) {
  EXPECT_THROW(ParseControllerModel("fanuc"), std::invalid_argument);
  try {
    ControllerParameters(TableTable(), ControllerModel::kHeadHead);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("is table-table"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ControllerParameters(TableTable(), ControllerModel::kFiveAxis), std::invalid_argument);
  EXPECT_THROW(ControllerParameters(HeadHead(), ControllerModel::kXyzacTrt), std::invalid_argument);
}

TEST(Controllers, FiveAxisKinsIsTheNominalHeadAndPivotLengthAbsorbsTheSpindle) {
  const Machine m = HeadHead();
  const FiveAxisMapping map = MatchFiveAxis(m);
  EXPECT_EQ(map.pivot_length, 250.0);
  const Eigen::MatrixXd q = Poses(m, 40, 3);
  const Eigen::MatrixXd j = FiveAxisJoints(m, map, q);
  Eigen::MatrixXd w = FiveAxisForward(map.pivot_length, j);
  const Eigen::MatrixXd p = ToolPoints(m, Eigen::VectorXd::Zero(m.num_parameters()), q);
  for (int i = 0; i < q.rows(); ++i)
    EXPECT_LT((w.row(i).transpose() + map.origin - p.row(i).transpose()).norm(), 1e-9);
  Eigen::MatrixXd world(q.rows(), 5);
  world << w, j.rightCols<2>();
  EXPECT_LT((FiveAxisInverse(map.pivot_length, world) - j).cwiseAbs().maxCoeff(), 1e-9);
  const Absorption ab = Absorb(m, ControllerModel::kFiveAxis, Theta(m, {{"EZ0S", -0.02}}), q);
  ASSERT_EQ(ab.parameters.size(), 1u);
  EXPECT_NEAR(ab.values[0], 0.02, 1e-9);
  EXPECT_LT(ab.max, 1e-9);
}

TEST(Controllers, BatchedCompensationReachesTheTargets) {
  const Machine m = TableTable();
  const Eigen::MatrixXd q = Poses(m, 30, 3);
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.03}, {"EA0C", 4e-5}, {"EXX1", 2e-5}});
  Eigen::MatrixXd P, A;
  ToolPoses(m, Eigen::VectorXd::Zero(m.num_parameters()), q, nullptr, &P, &A);
  const CompensatedCommands c = CompensateCommands(m, th, P, &A, q, nullptr, true, 0.1);
  Eigen::MatrixXd P1, A1;
  ToolPoses(m, th, c.commands, nullptr, &P1, &A1);
  EXPECT_LT((P1 - P).cwiseAbs().maxCoeff(), 1e-9);
  int oriented = 0;
  for (bool b : c.oriented) oriented += b;
  EXPECT_GT(oriented, 0);
  P(2, 1) = 1e9;
  try {
    CompensateCommands(m, th, P, &A, q, nullptr, true, 0.1);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()).rfind("pose 2: ", 0), 0u) << e.what();
  }
}

TEST(Controllers, KinematicsTableReproducesTheToolPoints) {
  // Location errors and tip offsets are what a table holds: its own screw
  // kinematics gives fivecal's tool points (in the part frame it states).
  for (const Machine& m : {TableTable(), HeadHead()}) {
    const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.03}, {"EA0C", 4e-5}, {"EC0Y", 5e-5}, {"tip.z", 0.02},
                                         {"EB0C", -2e-5}, {"EY0X", 0.01}});
    const KinematicsTable t = MakeKinematicsTable(m, th);
    const Eigen::MatrixXd q = Poses(m, 30, 3);
    Eigen::MatrixXd qt(q.rows(), Eigen::Index(t.axes.size()));
    for (size_t k = 0; k < t.axes.size(); ++k) qt.col(Eigen::Index(k)) = q.col(m.AxisIndex(t.axes[k].axis));
    EXPECT_LT((TableToolPoints(t, qt) - ToolPoints(m, th, q)).cwiseAbs().maxCoeff(), 1e-9) << m.name();
  }
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
