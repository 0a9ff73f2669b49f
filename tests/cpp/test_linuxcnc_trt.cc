// LinuxCNC's trt kinematics as a controller model: its inverse inverts its
// forward, a matching fivecal machine maps onto its pins exactly, location
// errors of the rotary axes' positions are absorbed and their tilts are not.
#include <gtest/gtest.h>

#include <random>

#include "controller_fixtures.h"
#include "fivecal/controllers/linuxcnc_trt.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {
namespace {

using test_fixtures::Poses;

Machine Xyzac(double c_sign = 1.0) {
  return Machine::FromJson(R"({"name": "trt-ac", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,)" + std::to_string(c_sign) + R"(], "point": [12,-7,30]},
    "A": {"type": "rotary", "direction": [1,0,0], "point": [0,20,-45]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,150]}})");
}

Machine Xyzbc() {
  return Machine::FromJson(R"({"name": "trt-bc", "topology": "wCBYfXZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,1], "point": [4,9,0]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [-30,0,-60]},
    "Y": {"type": "linear", "direction": [0,-1,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [1,2,100]}})");
}

TEST(LinuxcncTrt, InverseInvertsForward) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-50, 50), ang(-180, 180);
  for (TrtKins kins : {TrtKins::kXyzac, TrtKins::kXyzbc}) {
    TrtPins p{u(rng), u(rng), u(rng), u(rng), u(rng), u(rng), u(rng)};
    for (int i = 0; i < 20; ++i) {
      Eigen::Matrix<double, 5, 1> j;
      j << u(rng), u(rng), u(rng), ang(rng), ang(rng);
      const Eigen::Vector3d w = TrtForward(kins, p, j);
      const Eigen::Vector3d back = TrtInverse(kins, p, w, j[3], j[4]);
      EXPECT_LT((back - j.head<3>()).norm(), 1e-10) << TrtKinsName(kins);
    }
  }
}

TEST(LinuxcncTrt, NominalMachineMapsExactlyOntoPins) {
  const Machine m = Xyzac();
  const Eigen::MatrixXd q = Poses(m, 60, 3);
  const TrtFit fit = FitTrtPins(m, TrtKins::kXyzac, Eigen::VectorXd::Zero(m.num_parameters()), q,
                                TrtPins{});
  EXPECT_LT(fit.max, 1e-9);
  // C through (12,-7), A through (y,z) = (20,-45); world = point - tip.
  EXPECT_NEAR(fit.pins.x_rot_point, 12.0, 1e-9);
  EXPECT_NEAR(fit.pins.y_rot_point, -7.0, 1e-9);
  EXPECT_NEAR(fit.pins.y_rot_point + fit.pins.y_offset, 20.0, 1e-9);
  EXPECT_NEAR(fit.pins.z_rot_point + fit.pins.z_offset, -45.0 - 150.0, 1e-9);
  EXPECT_GT(fit.max_held, 1.0);  // all-zero pins are far off this machine
}

TEST(LinuxcncTrt, WorkpieceSideLinearAxisAndXyzbc) {
  const Machine m = Xyzbc();
  const TrtMapping map = MatchTrt(m, TrtKins::kXyzbc);
  EXPECT_EQ(map.sign[1], 1.0);  // table Y along -y: the tool moves +y relative to it
  const TrtFit fit = FitTrtPins(m, TrtKins::kXyzbc, Eigen::VectorXd::Zero(m.num_parameters()),
                                Poses(m, 60, 3), TrtPins{});
  EXPECT_LT(fit.max, 1e-9);
  EXPECT_NEAR(fit.pins.x_rot_point, 4.0 - 1.0, 1e-9);
  EXPECT_NEAR(fit.pins.y_rot_point, 9.0 - 2.0, 1e-9);
  EXPECT_NEAR(fit.pins.x_rot_point + fit.pins.x_offset, -30.0 - 1.0, 1e-9);
}

TEST(LinuxcncTrt, ReversedRotaryDirectionNegatesJoint) {
  const Machine m = Xyzac(-1.0);
  const TrtMapping map = MatchTrt(m, TrtKins::kXyzac);
  EXPECT_EQ(map.sign[4], -1.0);
  const TrtFit fit = FitTrtPins(m, TrtKins::kXyzac, Eigen::VectorXd::Zero(m.num_parameters()),
                                Poses(m, 40, 3), TrtPins{});
  EXPECT_LT(fit.max, 1e-9);
}

TEST(LinuxcncTrt, PivotErrorsAbsorbedTiltsNot) {
  const Machine m = Xyzac();
  const Eigen::MatrixXd q = Poses(m, 80, 3);
  ErrorModel e(m);
  e.Set("EX0C", 0.03);
  e.Set("EY0C", -0.02);
  e.Set("EY0A", 0.015);
  e.Set("EZ0A", -0.04);
  const TrtFit nominal = FitTrtPins(m, TrtKins::kXyzac, Eigen::VectorXd::Zero(m.num_parameters()),
                                    q, TrtPins{});
  const TrtFit fit = FitTrtPins(m, TrtKins::kXyzac, e.values(), q, nominal.pins);
  EXPECT_LT(fit.max, 1e-9);
  EXPECT_GT(fit.max_held, 0.02);  // the nominal pins leave the pivot errors
  // A is the first table axis: its location errors move its line; C's are
  // relative to A (chain-relative), so C's line moves by EY0A + EY0C in y,
  // and the table carries the workpiece frame along by the sum of both.
  EXPECT_NEAR(fit.pins.x_rot_point - nominal.pins.x_rot_point, 0.03, 1e-9);
  EXPECT_NEAR(fit.pins.y_rot_point - nominal.pins.y_rot_point, 0.015 - 0.02, 1e-9);
  EXPECT_NEAR(fit.pins.y_rot_point + fit.pins.y_offset -
                  (nominal.pins.y_rot_point + nominal.pins.y_offset), 0.015, 1e-9);
  EXPECT_NEAR(fit.pins.z_rot_point - nominal.pins.z_rot_point, -0.04, 1e-9);
  EXPECT_LT((fit.workpiece_shift - Eigen::Vector3d(-0.03, 0.005, 0.04)).norm(), 1e-9);

  e.Set("EB0C", 1e-4);  // C tilted: not representable
  const TrtFit tilted = FitTrtPins(m, TrtKins::kXyzac, e.values(), q, nominal.pins);
  EXPECT_GT(tilted.max, 1e-3);
  EXPECT_LT(tilted.rms, tilted.rms_held);
}

TEST(LinuxcncTrt, RefusesMachinesItCannotRepresent) {
  const Machine hu40t = Machine::FromJson(R"({"name": "hu40t", "topology": "wCBXfZYSt", "axes": {
    "X": {"type": "linear", "direction": [-1,0,0]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
    "C": {"type": "rotary", "direction": [0,0,-1]},
    "Z": {"type": "linear", "direction": [0,0,1]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})");
  // X sits between B and the foundation, so it is below the table: fine;
  // but this machine has C rotating about -z with B about -y: it maps.
  EXPECT_NO_THROW(MatchTrt(hu40t, TrtKins::kXyzbc));
  EXPECT_THROW(MatchTrt(hu40t, TrtKins::kXyzac), std::invalid_argument);
  const Machine head = Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCASt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1]}, "A": {"type": "rotary", "direction": [1,0,0]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
  EXPECT_THROW(MatchTrt(head, TrtKins::kXyzac), std::invalid_argument);
  const Machine m = Xyzac();
  Eigen::MatrixXd q = Poses(m, 10, 3);
  q.col(m.AxisIndex('A')).setZero();
  EXPECT_THROW(FitTrtPins(m, TrtKins::kXyzac, Eigen::VectorXd::Zero(m.num_parameters()), q,
                          TrtPins{}),
               std::invalid_argument);
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
