// Forward and inverse kinematics tests.
//
//  1. Nominal forward kinematics against closed forms derived by hand from
//     the convention of DESIGN.md ("Machine model"), on a tilting rotary
//     table and on the horizontal B/C machine.
//  2. Each error parameter does what its ISO 230-1 name says.
//  3. The Jet instantiation equals the double one, and its derivatives equal
//     central finite differences, for every parameter.
//  4. Inverse kinematics round-trips, takes the smallest move, and
//     compensates an erroneous machine.
#include <gtest/gtest.h>

#include <ceres/jet.h>

#include <Eigen/Core>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <memory>
#include <ostream>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/model/machine.h"

namespace fivecal {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRad = kPi / 180.0;

// (a) Tilting rotary table: A about +X pivoting at pA, C about +Z through pC
// (pC deliberately off the origin so Trans(p_k - p_parent) and the final
// Trans(-p_last) are exercised), all linear axes and the spindle on the tool
// side. The tip is off the spindle axis so the spindle angle matters.
const char* kTableJson = R"({"name": "table", "topology": "wCAfXYZSt",
 "axes": {"C": {"type": "rotary", "direction": [0,0,1], "point": [4,7,0]},
          "A": {"type": "rotary", "direction": [1,0,0], "point": [0,0,-50]},
          "X": {"type": "linear", "direction": [1,0,0]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [3,-2,100]}})";
const Eigen::Vector3d kTablePA(0, 0, -50), kTablePC(4, 7, 0), kTableTip(3, -2, 100);

// (b) The HU40T-like horizontal machine of DESIGN.md.
const char* kHu40tJson = R"({"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})";
const Eigen::Vector3d kHuPB(0, 0, -120), kHuPC(0, 0, 0), kHuTip(0, 0, 100);

// (c) KX8-like: A tilted 45 deg about Y (nutating table), Y under the table.
const char* kKx8Json = R"({"name": "KX8-like", "topology": "wCAYbXZSt",
 "axes": {"C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]},
          "A": {"type": "rotary", "direction": [0.7071067811865476,0,-0.7071067811865476],
                "point": [0,0,-80]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "X": {"type": "linear", "direction": [1,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "S": {"type": "rotary", "direction": [0,0,1]}},
 "tool": {"tip": [0,0,150]}})";

// (d) Table C + swivelling head B (mixed), (e) head-head C/A. Used to cover
// the other branches of the inverse kinematics; their spindle points are not
// at the origin, so Trans(tip - p_last) is exercised.
const char* kMixedJson = R"({"name": "mixed", "topology": "wCfXYZBSt",
 "axes": {"C": {"direction": [0,0,1], "point": [10,-5,0]},
          "X": {"direction": [1,0,0]}, "Y": {"direction": [0,1,0]}, "Z": {"direction": [0,0,1]},
          "B": {"direction": [0,1,0], "point": [0,0,250]},
          "S": {"direction": [0,0,1], "point": [0,0,250]}},
 "tool": {"tip": [0,0,120]}})";
const char* kHeadHeadJson = R"({"name": "head-head", "topology": "wfXYZCASt",
 "axes": {"X": {"direction": [1,0,0]}, "Y": {"direction": [0,1,0]}, "Z": {"direction": [0,0,1]},
          "C": {"direction": [0,0,1], "point": [0,0,300]},
          "A": {"direction": [1,0,0], "point": [0,0,260]},
          "S": {"direction": [0,0,1], "point": [0,0,260]}},
 "tool": {"tip": [0,0,100]}})";

using Values = std::map<char, double>;

// One pose row in machine axis order (mm / degrees); unnamed axes are 0.
Eigen::RowVectorXd Row(const Machine& m, const Values& v) {
  Eigen::RowVectorXd r = Eigen::RowVectorXd::Zero(m.num_axes());
  for (const auto& [name, value] : v) {
    const int k = m.AxisIndex(name);
    EXPECT_GE(k, 0) << name;
    if (k >= 0) r[k] = value;
  }
  return r;
}

Eigen::Vector3d Point(const Machine& m, const Eigen::VectorXd& theta, const Eigen::RowVectorXd& row,
                      const Eigen::MatrixXi* dirs = nullptr) {
  return ToolPoints(m, theta, Eigen::MatrixXd(row), dirs).row(0).transpose();
}

// Rotations written out by hand (independent of the library's helpers).
Eigen::Vector3d Rx(double t, const Eigen::Vector3d& v) {
  return {v.x(), std::cos(t) * v.y() - std::sin(t) * v.z(),
          std::sin(t) * v.y() + std::cos(t) * v.z()};
}
Eigen::Vector3d Ry(double t, const Eigen::Vector3d& v) {
  return {std::cos(t) * v.x() + std::sin(t) * v.z(), v.y(),
          -std::sin(t) * v.x() + std::cos(t) * v.z()};
}
Eigen::Vector3d Rz(double t, const Eigen::Vector3d& v) {
  return {std::cos(t) * v.x() - std::sin(t) * v.y(), std::sin(t) * v.x() + std::cos(t) * v.y(),
          v.z()};
}

// ---- Closed forms -------------------------------------------------------------
//
// (a) wCAfXYZSt. Workpiece chain from the foundation: A then C.
//   T_A = Trans(pA) . Rx(a),  T_C = Trans(pC - pA) . Rz(c),
//   T_fw = T_A . T_C . Trans(-pC)
//   so a workpiece point P sits in F at  pA + Rx(a) (pC - pA + Rz(c) (P - pC)).
// Tool chain X, Y, Z, S (all points 0, spindle through the origin):
//   T_ft = Trans(x ex) Trans(y ey) Trans(z ez) Rz(s) Trans(tip)
//   so the tool point in F is  y_F = (x, y, z) + Rz(s) tip.
// Equating and solving for P:
//   P = pC + Rz(-c) (Rx(-a) (y_F - pA) - (pC - pA)).
// Tool axis (spindle +Z, unchanged by Rz(s)):
//   v = Rz(-c) Rx(-a) ez = (sin c sin a, cos c sin a, cos a).
// Written out with explicit sines and cosines:
Eigen::Vector3d TableClosedForm(double c_deg, double a_deg, double x, double y, double z,
                                double s_deg, const Eigen::Vector3d& tip, Eigen::Vector3d* axis) {
  const double a = a_deg * kRad, c = c_deg * kRad, s = s_deg * kRad;
  const double ca = std::cos(a), sa = std::sin(a), cc = std::cos(c), sc = std::sin(c);
  const double cs = std::cos(s), ss = std::sin(s);
  // y_F - pA
  const double ux = x + cs * tip.x() - ss * tip.y() - kTablePA.x();
  const double uy = y + ss * tip.x() + cs * tip.y() - kTablePA.y();
  const double uz = z + tip.z() - kTablePA.z();
  // Rx(-a) u - (pC - pA)
  const double wx = ux - (kTablePC.x() - kTablePA.x());
  const double wy = ca * uy + sa * uz - (kTablePC.y() - kTablePA.y());
  const double wz = -sa * uy + ca * uz - (kTablePC.z() - kTablePA.z());
  if (axis) *axis = Eigen::Vector3d(sc * sa, cc * sa, ca);
  // pC + Rz(-c) w
  return {kTablePC.x() + cc * wx + sc * wy, kTablePC.y() - sc * wx + cc * wy,
          kTablePC.z() + wz};
}

// (b) wCBXfZYSt. Workpiece chain from the foundation: X, B, C, with
// u_X = -ex, u_B = -ey (so Rot(u_B, b) = Ry(-b)), u_C = -ez (Rot = Rz(-c)):
//   T_fw = Trans(-x ex) . Trans(pB) Ry(-b) . Trans(pC - pB) Rz(-c) . Trans(-pC)
//   so P sits in F at  -x ex + pB + Ry(-b) (pC - pB + Rz(-c) (P - pC)).
// The table moves along -X for positive x, so relative to the table the tool
// moves along +X. Tool chain Z, Y, S: y_F = (0, y, z) + Rz(s) tip.
//   P = pC + Rz(c) (Ry(b) (y_F + x ex - pB) - (pC - pB))
//   v = Rz(c) Ry(b) ez = (cos c sin b, sin c sin b, cos b).
Eigen::Vector3d Hu40tClosedForm(double c_deg, double b_deg, double x, double z, double y,
                                double s_deg, const Eigen::Vector3d& tip, Eigen::Vector3d* axis) {
  const double b = b_deg * kRad, c = c_deg * kRad, s = s_deg * kRad;
  const double cb = std::cos(b), sb = std::sin(b), cc = std::cos(c), sc = std::sin(c);
  const double cs = std::cos(s), ss = std::sin(s);
  // y_F + x ex - pB
  const double ux = cs * tip.x() - ss * tip.y() + x - kHuPB.x();
  const double uy = y + ss * tip.x() + cs * tip.y() - kHuPB.y();
  const double uz = z + tip.z() - kHuPB.z();
  // Ry(b) u - (pC - pB)
  const double wx = cb * ux + sb * uz - (kHuPC.x() - kHuPB.x());
  const double wy = uy - (kHuPC.y() - kHuPB.y());
  const double wz = -sb * ux + cb * uz - (kHuPC.z() - kHuPB.z());
  if (axis) *axis = Eigen::Vector3d(cc * sb, sc * sb, cb);
  // pC + Rz(c) w
  return {kHuPC.x() + cc * wx - sc * wy, kHuPC.y() + sc * wx + cc * wy, kHuPC.z() + wz};
}

TEST(Kinematics, ZeroPoseGivesNominalTip) {
  // Every frame is F at the zero pose, so the tool point is the nominal tip.
  for (const char* json : {kTableJson, kHu40tJson, kKx8Json, kMixedJson, kHeadHeadJson}) {
    const Machine m = Machine::FromJson(json);
    SCOPED_TRACE(m.name());
    const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
    Eigen::MatrixXd p, v;
    ToolPoses(m, theta, Eigen::MatrixXd::Zero(1, m.num_axes()), nullptr, &p, &v);
    EXPECT_NEAR((p.row(0).transpose() - m.tip()).norm(), 0, 1e-12);
    EXPECT_NEAR((v.row(0).transpose() - m.tool_axis()).norm(), 0, 1e-15);
  }
}

TEST(Kinematics, TiltingTableMatchesClosedForm) {
  const Machine m = Machine::FromJson(kTableJson);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> lin(-300, 300), rot(-400, 400), tilt(-110, 110);
  const int n = 200;
  Eigen::MatrixXd axes(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    axes.row(i) = Row(m, {{'C', rot(rng)}, {'A', tilt(rng)}, {'X', lin(rng)}, {'Y', lin(rng)},
                          {'Z', lin(rng)}, {'S', rot(rng)}});
  Eigen::MatrixXd p, v;
  ToolPoses(m, Eigen::VectorXd::Zero(m.num_parameters()), axes, nullptr, &p, &v);
  const Eigen::MatrixXd p_only = ToolPoints(m, Eigen::VectorXd::Zero(m.num_parameters()), axes);
  auto at = [&](int i, char a) { return axes(i, m.AxisIndex(a)); };
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d va;
    const Eigen::Vector3d expected = TableClosedForm(at(i, 'C'), at(i, 'A'), at(i, 'X'),
                                                     at(i, 'Y'), at(i, 'Z'), at(i, 'S'),
                                                     kTableTip, &va);
    EXPECT_LT((p.row(i).transpose() - expected).norm(), 1e-9) << "pose " << i;
    EXPECT_LT((p_only.row(i).transpose() - expected).norm(), 1e-9) << "pose " << i;
    EXPECT_LT((v.row(i).transpose() - va).norm(), 1e-12) << "pose " << i;
  }
}

TEST(Kinematics, Hu40tMatchesClosedForm) {
  const Machine m = Machine::FromJson(kHu40tJson);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> lin(-300, 300), rot(-400, 400), tilt(-150, 150);
  const int n = 200;
  Eigen::MatrixXd axes(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    axes.row(i) = Row(m, {{'C', rot(rng)}, {'B', tilt(rng)}, {'X', lin(rng)}, {'Z', lin(rng)},
                          {'Y', lin(rng)}, {'S', rot(rng)}});
  Eigen::MatrixXd p, v;
  ToolPoses(m, Eigen::VectorXd::Zero(m.num_parameters()), axes, nullptr, &p, &v);
  auto at = [&](int i, char a) { return axes(i, m.AxisIndex(a)); };
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d va;
    const Eigen::Vector3d expected = Hu40tClosedForm(at(i, 'C'), at(i, 'B'), at(i, 'X'),
                                                     at(i, 'Z'), at(i, 'Y'), at(i, 'S'), kHuTip,
                                                     &va);
    EXPECT_LT((p.row(i).transpose() - expected).norm(), 1e-9) << "pose " << i;
    EXPECT_LT((v.row(i).transpose() - va).norm(), 1e-12) << "pose " << i;
  }
  // Sign conventions spelled out: table-side X along -X moves the tool along
  // +X relative to the table; B = +90 about -Y tips the tool axis to +X
  // (v = (sin b, 0, cos b) at c = 0); C = +90 about -Z turns +X into +Y.
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.num_parameters());
  EXPECT_NEAR(Point(m, zero, Row(m, {{'X', 10}})).x(), 10.0, 1e-12);
  ToolPoses(m, zero, Eigen::MatrixXd(Row(m, {{'B', 90}})), nullptr, &p, &v);
  EXPECT_NEAR((v.row(0).transpose() - Eigen::Vector3d(1, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((Point(m, zero, Row(m, {{'C', 90}, {'X', 10}, {'Z', -100}})) -
               Eigen::Vector3d(0, 10, 0)).norm(), 0, 1e-12);
}

TEST(Kinematics, RotaryOffsetMovesPivot) {
  // A rotary table C whose axis passes through (30, 20): the workpiece turns
  // about that line, so a tool standing on it does not move relative to the
  // workpiece, and a tool r away from it circles it (at -c: the table turns
  // by +c under a fixed tool).
  const Machine m = Machine::FromJson(R"({"topology": "wCfXYZt",
    "axes": {"C": {"direction": [0,0,1], "point": [30,20,0]}, "X": {"direction": [1,0,0]},
             "Y": {"direction": [0,1,0]}, "Z": {"direction": [0,0,1]}}})");
  const Machine m0 = Machine::FromJson(R"({"topology": "wCfXYZt",
    "axes": {"C": {"direction": [0,0,1]}, "X": {"direction": [1,0,0]},
             "Y": {"direction": [0,1,0]}, "Z": {"direction": [0,0,1]}}})");
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.num_parameters());
  const double r = 15;
  for (double c : {0.0, 37.0, 90.0, 180.0, -123.0}) {
    SCOPED_TRACE(c);
    EXPECT_NEAR((Point(m, zero, Row(m, {{'C', c}, {'X', 30}, {'Y', 20}, {'Z', 5}})) -
                 Eigen::Vector3d(30, 20, 5)).norm(), 0, 1e-12);
    const Eigen::Vector3d expected(30 + r * std::cos(c * kRad), 20 - r * std::sin(c * kRad), 5);
    EXPECT_NEAR((Point(m, zero, Row(m, {{'C', c}, {'X', 30 + r}, {'Y', 20}, {'Z', 5}})) -
                 expected).norm(), 0, 1e-12);
    // Without the offset the same commands circle the origin instead.
    const Eigen::Vector3d about_origin = Rz(-c * kRad, Eigen::Vector3d(30 + r, 20, 5));
    EXPECT_NEAR((Point(m0, zero, Row(m0, {{'C', c}, {'X', 30 + r}, {'Y', 20}, {'Z', 5}})) -
                 about_origin).norm(), 0, 1e-12);
  }
}

TEST(Kinematics, RotaryPointMaySlideAlongItsAxis) {
  // Only the axis line matters: moving C's point (on the workpiece side) and
  // the spindle's point (last on the tool side, so it is p_last in
  // Trans(tip - p_last)) along their own directions leaves the kinematics
  // unchanged.
  const Machine m = Machine::FromJson(kTableJson);
  std::string moved = kTableJson;
  for (const auto& [from, to] : {std::make_pair(R"("point": [4,7,0])", R"("point": [4,7,33])"),
                                 std::make_pair(R"("point": [0,0,0])", R"("point": [0,0,-40])")})
    moved.replace(moved.find(from), std::string(from).size(), to);
  const Machine m2 = Machine::FromJson(moved);
  ASSERT_EQ(m2.axis(m2.AxisIndex('C')).point, Eigen::Vector3d(4, 7, 33));
  ASSERT_EQ(m2.axis(m2.AxisIndex('S')).point, Eigen::Vector3d(0, 0, -40));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> lin(-300, 300), rot(-180, 180);
  Eigen::MatrixXd axes(50, 6);
  for (int i = 0; i < 50; ++i)
    for (int k = 0; k < 6; ++k) axes(i, k) = m.axis(k).rotary() ? rot(rng) : lin(rng);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.num_parameters());
  EXPECT_LT((ToolPoints(m, zero, axes) - ToolPoints(m2, zero, axes)).cwiseAbs().maxCoeff(), 1e-9);
}

// ---- 2. What each error parameter does ------------------------------------------

class ErrorEffects : public ::testing::Test {
 protected:
  Machine table = Machine::FromJson(kTableJson);
  Machine hu = Machine::FromJson(kHu40tJson);
  // Deviation of the tool point (workpiece frame) caused by one parameter.
  Eigen::Vector3d Dev(const Machine& m, const std::string& name, double value,
                      const Eigen::RowVectorXd& row, const Eigen::MatrixXi* dirs = nullptr) {
    ErrorModel e(m);
    e.Set(name, value);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.num_parameters());
    return Point(m, e.values(), row, dirs) - Point(m, zero, row, dirs);
  }
  std::mt19937 rng{4};
  std::uniform_real_distribution<double> lin{-250, 250}, rot{-180, 180};
  Eigen::RowVectorXd RandomTablePose(bool spindle = true) {
    return Row(table, {{'C', rot(rng)}, {'A', rot(rng) / 2}, {'X', lin(rng)}, {'Y', lin(rng)},
                       {'Z', lin(rng)}, {'S', spindle ? rot(rng) : 0.0}});
  }
};

TEST_F(ErrorEffects, PositionErrorOfCPivot) {
  // EX0C / EY0C translate the C axis frame (with the table on it) by
  // d = (EX0C, EY0C, 0) in A's frame:
  //   P = pC + Rz(-c) (Rx(-a) (y_F - pA) - (pC - pA) - d)
  // so the deviation is exactly -Rz(-c) d: -EX0C (cos c, -sin c, 0) and
  // -EY0C (sin c, cos c, 0), whatever A and the linear axes do.
  const double d = 1e-3;
  for (int i = 0; i < 50; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    const double c = row[table.AxisIndex('C')] * kRad;
    EXPECT_NEAR((Dev(table, "EX0C", d, row) - (-d) * Eigen::Vector3d(std::cos(c), -std::sin(c), 0))
                    .norm(), 0, 1e-11);
    EXPECT_NEAR((Dev(table, "EY0C", d, row) - (-d) * Eigen::Vector3d(std::sin(c), std::cos(c), 0))
                    .norm(), 0, 1e-11);
  }
  // The classic reversal pattern: measured at C = 0 and C = 180, the X
  // deviation changes by 2 EX0C.
  const Eigen::Vector3d d0 = Dev(table, "EX0C", d, Row(table, {{'Z', -40}}));
  const Eigen::Vector3d d180 = Dev(table, "EX0C", d, Row(table, {{'C', 180}, {'Z', -40}}));
  EXPECT_NEAR(d0.x(), -d, 1e-12);
  EXPECT_NEAR(d180.x(), d, 1e-12);
  EXPECT_NEAR(d180.x() - d0.x(), 2 * d, 1e-12);
}

TEST_F(ErrorEffects, TiltOfCAboutX) {
  // EA0C tilts C about X inside A's frame: T_C = Trans(pC - pA) Rx(e) Rz(c),
  //   P = pC + Rz(-c) Rx(-e) g,  g = Rx(-a) (y_F - pA) - (pC - pA),
  // and Rx(-e) g = g + e (0, g_z, -g_y) + O(e^2 |g|), so to first order
  //   dP = e Rz(-c) (0, g_z, -g_y) = e (sin c g_z, cos c g_z, -g_y):
  // a deviation that turns with the C angle.
  const double e = 1e-5;
  for (int i = 0; i < 50; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    const double c = row[table.AxisIndex('C')] * kRad, a = row[table.AxisIndex('A')] * kRad;
    const double s = row[table.AxisIndex('S')] * kRad;
    const Eigen::Vector3d yF = Eigen::Vector3d(row[table.AxisIndex('X')], row[table.AxisIndex('Y')],
                                               row[table.AxisIndex('Z')]) + Rz(s, kTableTip);
    const Eigen::Vector3d g = Rx(-a, yF - kTablePA) - (kTablePC - kTablePA);
    const Eigen::Vector3d expected =
        e * Eigen::Vector3d(std::sin(c) * g.z(), std::cos(c) * g.z(), -g.y());
    const Eigen::Vector3d dev = Dev(table, "EA0C", e, row);
    EXPECT_GT(dev.norm(), 1e-4 * e * g.norm());  // not trivially zero
    EXPECT_NEAR((dev - expected).norm(), 0, e * e * g.norm() + 1e-12) << "pose " << i;
  }
  // Tool on the C axis, 100 mm above the pivot: the deviation has constant
  // length e*100 and its direction follows C.
  for (double c : {0.0, 90.0, 180.0, 270.0}) {
    const Eigen::Vector3d dev = Dev(table, "EA0C", e, Row(table, {{'C', c}, {'X', 1}, {'Y', 9},
                                                                   {'Z', 0}}));
    // y_F = (1, 9, 0) + (3, -2, 100) = (4, 7, 100) = pC + 100 ez.
    EXPECT_NEAR((dev - e * 100 * Eigen::Vector3d(std::sin(c * kRad), std::cos(c * kRad), 0))
                    .norm(), 0, 1e-12 + e * e * 100);
  }
}

TEST_F(ErrorEffects, SquarenessOfZAboutY) {
  // EB0Z tilts Z (and everything it carries) about Y: with a = c = 0,
  //   P = y_F = (x, y, 0) + Ry(b) v,  v = z ez + Rz(s) tip,
  // so dP = b (v_z, 0, -v_x) + O(b^2 |v|): Z travel produces an X deviation
  // b*z (plus the constant b*tip_z from the tool length).
  const double b = 1e-5;
  for (double z : {-200.0, -50.0, 0.0, 80.0, 300.0}) {
    const Eigen::RowVectorXd row = Row(table, {{'X', 12}, {'Y', -7}, {'Z', z}});
    const Eigen::Vector3d v(kTableTip.x(), kTableTip.y(), z + kTableTip.z());
    const Eigen::Vector3d expected = b * Eigen::Vector3d(v.z(), 0, -v.x());
    EXPECT_NEAR((Dev(table, "EB0Z", b, row) - expected).norm(), 0, b * b * v.norm() + 1e-12) << z;
  }
  const double dx_300 = Dev(table, "EB0Z", b, Row(table, {{'Z', 300}})).x();
  const double dx_m200 = Dev(table, "EB0Z", b, Row(table, {{'Z', -200}})).x();
  EXPECT_NEAR(dx_300 - dx_m200, b * 500, 1e-11);
}

TEST_F(ErrorEffects, SquarenessOfYAboutZ) {
  // EC0Y turns Y (and Z, S, tip) about Z: with a = c = 0
  //   P = x ex + Rz(g) v,  v = y ey + z ez + Rz(s) tip,
  //   dP = g (-v_y, v_x, 0) + O(g^2 |v|): Y travel gives an X deviation -g*y.
  const double g = 1e-5;
  for (double y : {-250.0, 0.0, 175.0}) {
    const Eigen::RowVectorXd row = Row(table, {{'X', 40}, {'Y', y}, {'Z', 60}});
    const Eigen::Vector3d v(kTableTip.x(), y + kTableTip.y(), 60 + kTableTip.z());
    const Eigen::Vector3d expected = g * Eigen::Vector3d(-v.y(), v.x(), 0);
    EXPECT_NEAR((Dev(table, "EC0Y", g, row) - expected).norm(), 0, g * g * v.norm() + 1e-12) << y;
  }
}

TEST_F(ErrorEffects, ScaleErrorOfPositiveLinearAxis) {
  // Tool-side X along +X: eps_X = Trans(EXX1 x, 0, 0), so the tool point in F
  // moves by EXX1 x ex exactly, seen from the table as Rz(-c) Rx(-a) ex.
  const double k = 1e-5;
  for (int i = 0; i < 20; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    const double x = row[table.AxisIndex('X')], a = row[table.AxisIndex('A')] * kRad,
                 c = row[table.AxisIndex('C')] * kRad;
    const Eigen::Vector3d expected = k * x * Rz(-c, Rx(-a, Eigen::Vector3d::UnitX()));
    EXPECT_NEAR((Dev(table, "EXX1", k, row) - expected).norm(), 0, 1e-11);
  }
  // Travel from x = 0 to x = 200 becomes (1 + EXX1) * 200: longer.
  ErrorModel e(table);
  e.Set("EXX1", k);
  const double travel = Point(table, e.values(), Row(table, {{'X', 200}})).x() -
                        Point(table, e.values(), Row(table, {})).x();
  EXPECT_NEAR(travel, 200 * (1 + k), 1e-11);
}

TEST_F(ErrorEffects, ScaleErrorOfNegativeLinearAxisShortensTravel) {
  // HU40T X runs along -X on the table side: T_X = Trans(-x ex) Trans(EXX1 x ex),
  // so the table moves by -(1 - EXX1) x ex and, relative to the table, the
  // tool travels (1 - EXX1) x: a positive EXX1 shortens the travel
  // (DESIGN.md). In general dP = Rz(c) Ry(b) (-EXX1 x ex).
  const double k = 1e-5;
  ErrorModel e(hu);
  e.Set("EXX1", k);
  const double travel = Point(hu, e.values(), Row(hu, {{'X', 200}})).x() -
                        Point(hu, e.values(), Row(hu, {})).x();
  EXPECT_NEAR(travel, 200 * (1 - k), 1e-11);
  for (int i = 0; i < 20; ++i) {
    const double b = rot(rng) / 2, c = rot(rng), x = lin(rng);
    const Eigen::RowVectorXd row = Row(hu, {{'C', c}, {'B', b}, {'X', x}, {'Z', lin(rng)},
                                            {'Y', lin(rng)}, {'S', rot(rng)}});
    const Eigen::Vector3d expected = Rz(c * kRad, Ry(b * kRad, -k * x * Eigen::Vector3d::UnitX()));
    EXPECT_NEAR((Dev(hu, "EXX1", k, row) - expected).norm(), 0, 1e-11);
  }
}

TEST_F(ErrorEffects, LinearAxisErrorMotionsActAtTheCarriage) {
  // T_X = Trans(x ex) . eps_X(x): the error motions of X act at the moved X
  // carriage and are carried by Y, Z, S and the tip. With a = c = 0:
  //   y_F = x ex + eps_X(x) v,  v = y ey + z ez + Rz(s) tip.
  // Straightness EYX2: eps_X = Trans(0, EYX2 x^2, 0), dP = EYX2 x^2 ey exactly.
  // Yaw ECX1: eps_X = Rz(ECX1 x), dP = Rz(ECX1 x) v - v, which to first order
  // is ECX1 x (-v_y, v_x, 0): the Abbe offset is v, measured from the
  // carriage, not from the machine origin.
  for (double x : {-220.0, 35.0, 260.0}) {
    const double y = 40, z = -75, s = 30;
    const Eigen::RowVectorXd row = Row(table, {{'X', x}, {'Y', y}, {'Z', z}, {'S', s}});
    EXPECT_NEAR((Dev(table, "EYX2", 2e-8, row) - 2e-8 * x * x * Eigen::Vector3d::UnitY()).norm(),
                0, 1e-12) << x;
    const double k = 5e-8;  // rad/mm: 1e-5 rad at x = 200
    const Eigen::Vector3d v = Eigen::Vector3d(0, y, z) + Rz(s * kRad, kTableTip);
    const Eigen::Vector3d dev = Dev(table, "ECX1", k, row);
    EXPECT_NEAR((dev - (Rz(k * x, v) - v)).norm(), 0, 1e-12) << x;
    EXPECT_NEAR((dev - k * x * Eigen::Vector3d(-v.y(), v.x(), 0)).norm(), 0,
                std::pow(k * x, 2) * v.norm()) << x;
  }
}

TEST_F(ErrorEffects, RotaryAxisErrorMotionsTurnWithTheTable) {
  // T_C = Trans(pC - pA) . Rz(c) . eps_C(c): the error motions of C are
  // expressed in the turned table frame. A radial motion EXC1 (c in rad):
  //   P sits in F at pA + Rx(a) (pC - pA + Rz(c) (EXC1 c ex + P - pC)),
  // so dP = -EXC1 c ex exactly, along the table's own -X whatever c is.
  const double k = 1e-4;  // mm/rad
  for (int i = 0; i < 20; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    const double c = row[table.AxisIndex('C')] * kRad;
    EXPECT_NEAR((Dev(table, "EXC1", k, row) - (-k * c) * Eigen::Vector3d::UnitX()).norm(), 0,
                1e-11) << "pose " << i;
  }
  // An angular positioning error ECC1: Rz(c) Rz(ECC1 c) = Rz((1 + ECC1) c),
  // exactly the closed form at the scaled angle.
  ErrorModel e(table);
  e.Set("ECC1", 3e-5);
  for (int i = 0; i < 20; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    auto at = [&](char a) { return row[table.AxisIndex(a)]; };
    const Eigen::Vector3d expected = TableClosedForm(at('C') * (1 + 3e-5), at('A'), at('X'),
                                                     at('Y'), at('Z'), at('S'), kTableTip, nullptr);
    EXPECT_NEAR((Point(table, e.values(), row) - expected).norm(), 0, 1e-9);
  }
}

TEST_F(ErrorEffects, LinearBacklashShiftsAlongTheAxis) {
  // The displacement in M_X becomes x + EXXb dir. Tool-side X along +X: the
  // tool point moves by EXXb dir ex. Direction 0 means no backlash term.
  const double bl = 1e-3;
  const Eigen::RowVectorXd row = Row(table, {{'X', 50}, {'Y', 20}, {'Z', -30}});
  const int kx = table.AxisIndex('X');
  for (int dir : {1, -1, 0}) {
    Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(1, table.num_axes());
    dirs(0, kx) = dir;
    EXPECT_NEAR((Dev(table, "EXXb", bl, row, &dirs) - bl * dir * Eigen::Vector3d::UnitX()).norm(),
                0, 1e-12) << "dir " << dir;
  }
  // No direction matrix at all: no backlash either.
  EXPECT_NEAR(Dev(table, "EXXb", bl, row).norm(), 0, 1e-15);
  // The other axes' directions do not matter for EXXb.
  Eigen::MatrixXi others = Eigen::MatrixXi::Ones(1, table.num_axes());
  others(0, kx) = 0;
  EXPECT_NEAR(Dev(table, "EXXb", bl, row, &others).norm(), 0, 1e-15);

  // HU40T table-side X along -X: the carriage goes EXXb dir further along
  // -ex, so relative to the table the tool goes EXXb dir further along +ex.
  const Eigen::RowVectorXd hrow = Row(hu, {{'X', 50}, {'Y', 20}, {'Z', -30}});
  for (int dir : {1, -1}) {
    Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(1, hu.num_axes());
    dirs(0, hu.AxisIndex('X')) = dir;
    EXPECT_NEAR((Dev(hu, "EXXb", bl, hrow, &dirs) - bl * dir * Eigen::Vector3d::UnitX()).norm(), 0,
                1e-12) << "dir " << dir;
  }
}

TEST_F(ErrorEffects, BacklashDoesNotEnterErrorMotionPolynomials) {
  // DESIGN.md: the error-motion polynomials use the command q itself, not
  // q + backlash. With EYX1 and EXXb together the Y deviation is EYX1 * x.
  ErrorModel e(table);
  e.Set("EYX1", 1e-4);
  e.Set("EXXb", 0.5);  // large on purpose, so EYX1*(x+b) would be visible
  Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(1, table.num_axes());
  dirs(0, table.AxisIndex('X')) = 1;
  const Eigen::RowVectorXd row = Row(table, {{'X', 100}});
  const Eigen::Vector3d dev =
      Point(table, e.values(), row, &dirs) -
      Point(table, Eigen::VectorXd::Zero(table.num_parameters()), row, &dirs);
  EXPECT_NEAR(dev.x(), 0.5, 1e-12);
  EXPECT_NEAR(dev.y(), 1e-4 * 100, 1e-12);
}

TEST_F(ErrorEffects, RotaryBacklashActsOnTheAngle) {
  // ECCb (rad) adds ECCb dir to the C angle inside M_C: exactly the closed
  // form at c + ECCb dir.
  const double bl = 2e-5;
  const int kc = table.AxisIndex('C');
  ErrorModel e(table);
  e.Set("ECCb", bl);
  for (int i = 0; i < 20; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    for (int dir : {1, -1}) {
      Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(1, table.num_axes());
      dirs(0, kc) = dir;
      auto at = [&](char a) { return row[table.AxisIndex(a)]; };
      const Eigen::Vector3d expected =
          TableClosedForm(at('C') + bl * dir / kRad, at('A'), at('X'), at('Y'), at('Z'), at('S'),
                          kTableTip, nullptr);
      EXPECT_NEAR((Point(table, e.values(), row, &dirs) - expected).norm(), 0, 1e-9);
    }
  }
}

TEST_F(ErrorEffects, TipOffsetsAddToTheNominalTip) {
  // tip.x|y|z add to the tip in the tool frame: the closed form with
  // tip + (dx, dy, dz), which rotates with S, A and C.
  ErrorModel e(table);
  const Eigen::Vector3d d(1e-3, -2e-3, 3e-3);
  e.Set("tip.x", d.x());
  e.Set("tip.y", d.y());
  e.Set("tip.z", d.z());
  EXPECT_NEAR((Point(table, e.values(), Row(table, {})) - (kTableTip + d)).norm(), 0, 1e-12);
  for (int i = 0; i < 50; ++i) {
    const Eigen::RowVectorXd row = RandomTablePose();
    auto at = [&](char a) { return row[table.AxisIndex(a)]; };
    const Eigen::Vector3d expected = TableClosedForm(at('C'), at('A'), at('X'), at('Y'), at('Z'),
                                                     at('S'), kTableTip + d, nullptr);
    EXPECT_NEAR((Point(table, e.values(), row) - expected).norm(), 0, 1e-9);
  }
}

// ---- 3. Jets ------------------------------------------------------------------------

// Realistic magnitude of each parameter: 1e-2 mm and 1e-4 rad for location
// errors and tip offsets, error-motion coefficients scaled by 1/range^d
// (range 500 mm or pi rad), backlash 1e-3 mm / 1e-5 rad.
double Scale(const Machine& m, int i) {
  const ParameterInfo& p = m.parameters()[i];
  const double base = p.angular() ? 1e-4 : 1e-2;
  switch (p.kind) {
    case ParameterKind::kLocation: return base;
    case ParameterKind::kTip: return 1e-2;
    case ParameterKind::kBacklash: return m.axis(p.axis).rotary() ? 1e-5 : 1e-3;
    case ParameterKind::kMotion: {
      const double range = m.axis(p.axis).rotary() ? kPi : 500.0;
      return base / std::pow(range, p.degree);
    }
  }
  return 0;
}

Eigen::VectorXd RandomTheta(const Machine& m, std::mt19937* rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd theta(m.num_parameters());
  for (int i = 0; i < m.num_parameters(); ++i) {
    double x = u(*rng);
    // Keep every value clearly non-zero.
    theta[i] = Scale(m, i) * (x >= 0 ? 0.2 + 0.8 * x : -0.2 + 0.8 * x);
  }
  return theta;
}

constexpr int kNumParams = 152;  // every parameter of a 6-axis machine with a spindle
using Jet = ceres::Jet<double, kNumParams>;

void CheckJetAgainstDouble(const char* json, unsigned seed) {
  const Machine m = Machine::FromJson(json);
  ASSERT_EQ(m.num_parameters(), kNumParams);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-300, 300), rot(-180, 180);
  std::bernoulli_distribution coin(0.5);
  const Eigen::VectorXd theta = RandomTheta(m, &rng);
  std::vector<Jet> theta_j(kNumParams);
  for (int i = 0; i < kNumParams; ++i) theta_j[i] = Jet(theta[i], i);

  for (int pose = 0; pose < 4; ++pose) {
    Eigen::MatrixXd axes(1, m.num_axes());
    Eigen::MatrixXi dirs(1, m.num_axes());
    for (int k = 0; k < m.num_axes(); ++k) {
      axes(0, k) = m.axis(k).rotary() ? rot(rng) : lin(rng);
      dirs(0, k) = coin(rng) ? 1 : -1;  // every backlash parameter active
    }
    std::vector<double> q(m.num_axes());
    AxisValuesToInternal(m, axes.data(), q.data());
    std::vector<int> dir(dirs.data(), dirs.data() + m.num_axes());

    Vec3<Jet> pj, vj;
    ToolInWorkpiece<Jet>(m, theta_j.data(), q.data(), dir.data(),
                         TipWithOffsets<Jet>(m, theta_j.data()), &pj, &vj);
    Eigen::MatrixXd p, v;
    ToolPoses(m, theta, axes, &dirs, &p, &v);
    for (int r = 0; r < 3; ++r) {
      EXPECT_NEAR(pj[r].a, p(0, r), 1e-12);
      EXPECT_NEAR(vj[r].a, v(0, r), 1e-12);
    }

    int nonzero = 0;
    for (int i = 0; i < kNumParams; ++i) {
      const double h = Scale(m, i);
      Eigen::VectorXd tp = theta, tm = theta;
      tp[i] += h;
      tm[i] -= h;
      Eigen::MatrixXd pp, vp, pm, vm;
      ToolPoses(m, tp, axes, &dirs, &pp, &vp);
      ToolPoses(m, tm, axes, &dirs, &pm, &vm);
      const Eigen::Vector3d dp_fd = (pp - pm).row(0).transpose() / (2 * h);
      const Eigen::Vector3d dv_fd = (vp - vm).row(0).transpose() / (2 * h);
      Eigen::Vector3d dp_jet, dv_jet;
      for (int r = 0; r < 3; ++r) {
        dp_jet[r] = pj[r].v[i];
        dv_jet[r] = vj[r].v[i];
      }
      // Relative 1e-6, plus the round-off floor of a central difference
      // (eps * |f| / h, with |f| <= ~1000 mm for points and 1 for axes).
      const double eps = 2.3e-16;
      EXPECT_LE((dp_jet - dp_fd).norm(), 1e-6 * dp_fd.norm() + 100 * eps * 1000 / h)
          << m.parameters()[i].name << " point: jet " << dp_jet.transpose() << " fd "
          << dp_fd.transpose();
      EXPECT_LE((dv_jet - dv_fd).norm(), 1e-6 * dv_fd.norm() + 100 * eps / h)
          << m.parameters()[i].name << " axis: jet " << dv_jet.transpose() << " fd "
          << dv_fd.transpose();
      if (dp_fd.norm() > 1e-6) ++nonzero;
    }
    // Sanity: nearly every parameter moves the tool point at a generic pose.
    EXPECT_GT(nonzero, kNumParams - 10);
  }
}

TEST(Kinematics, JetMatchesDoubleAndFiniteDifferencesTable) {
  CheckJetAgainstDouble(kTableJson, 5);
}

TEST(Kinematics, JetMatchesDoubleAndFiniteDifferencesHu40t) {
  CheckJetAgainstDouble(kHu40tJson, 6);
}

// Each parameter set alone (the others exactly 0, as when a user sets one
// error) moves the double forward kinematics by its Jet derivative at the
// nominal machine times its value, up to second order. This catches a double
// path that skips a component which is the only non-zero one.
void CheckEachParameterAlone(const char* json, unsigned seed) {
  const Machine m = Machine::FromJson(json);
  ASSERT_EQ(m.num_parameters(), kNumParams);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-300, 300), rot(-180, 180);
  std::bernoulli_distribution coin(0.5);
  std::vector<Jet> zero_j(kNumParams);
  for (int i = 0; i < kNumParams; ++i) zero_j[i] = Jet(0.0, i);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(kNumParams);
  for (int pose = 0; pose < 3; ++pose) {
    Eigen::MatrixXd axes(1, m.num_axes());
    Eigen::MatrixXi dirs(1, m.num_axes());
    for (int k = 0; k < m.num_axes(); ++k) {
      axes(0, k) = m.axis(k).rotary() ? rot(rng) : lin(rng);
      dirs(0, k) = coin(rng) ? 1 : -1;
    }
    std::vector<double> q(m.num_axes());
    AxisValuesToInternal(m, axes.data(), q.data());
    std::vector<int> dir(dirs.data(), dirs.data() + m.num_axes());
    Vec3<Jet> pj, vj;
    ToolInWorkpiece<Jet>(m, zero_j.data(), q.data(), dir.data(),
                         TipWithOffsets<Jet>(m, zero_j.data()), &pj, &vj);
    Eigen::MatrixXd p0, v0;
    ToolPoses(m, zero, axes, &dirs, &p0, &v0);
    for (int i = 0; i < kNumParams; ++i) {
      const double value = 0.1 * Scale(m, i);
      Eigen::VectorXd theta = zero;
      theta[i] = value;
      Eigen::MatrixXd p, v;
      ToolPoses(m, theta, axes, &dirs, &p, &v);
      Eigen::Vector3d dp_lin, dv_lin;
      for (int r = 0; r < 3; ++r) {
        dp_lin[r] = pj[r].v[i] * value;
        dv_lin[r] = vj[r].v[i] * value;
      }
      const Eigen::Vector3d dp = (p - p0).row(0).transpose(), dv = (v - v0).row(0).transpose();
      EXPECT_LE((dp - dp_lin).norm(), 1e-3 * dp_lin.norm() + 1e-12)
          << m.parameters()[i].name << ": moved " << dp.transpose() << ", expected "
          << dp_lin.transpose();
      EXPECT_LE((dv - dv_lin).norm(), 1e-3 * dv_lin.norm() + 1e-14) << m.parameters()[i].name;
    }
  }
}

TEST(Kinematics, EachParameterAloneMatchesItsDerivativeTable) {
  CheckEachParameterAlone(kTableJson, 14);
}

TEST(Kinematics, EachParameterAloneMatchesItsDerivativeHu40t) {
  CheckEachParameterAlone(kHu40tJson, 15);
}

// Rotary axes on the tool side and a spindle point off the origin (p_last in
// Trans(tip - p_last)).
TEST(Kinematics, JetMatchesDoubleAndFiniteDifferencesMixed) {
  CheckJetAgainstDouble(kMixedJson, 12);
}

TEST(Kinematics, JetMatchesDoubleAndFiniteDifferencesHeadHead) {
  CheckJetAgainstDouble(kHeadHeadJson, 13);
}

// ---- 4. Inverse kinematics ---------------------------------------------------------

struct IkCase {
  const char* json;
  char tilt;     // the rotary axis whose zero is the orientation singularity
  char turn;     // the other orientation axis (a C)
  bool flip;     // (tilt, turn) ~ (-tilt, turn + 180) is the second solution
  double tilt_lo, tilt_hi;  // |tilt| range sampled (deg), away from singularities
};

// Readable test output: the gtest default prints the raw bytes.
void PrintTo(const IkCase& c, std::ostream* os) { *os << Machine::FromJson(c.json).name(); }

const IkCase kIkCases[] = {
    {kTableJson, 'A', 'C', true, 8, 110},
    {kHu40tJson, 'B', 'C', true, 8, 150},
    {kKx8Json, 'A', 'C', false, 15, 165},
    {kMixedJson, 'B', 'C', true, 8, 110},
    {kHeadHeadJson, 'A', 'C', true, 8, 110},
};

class InverseKinematicsTest : public ::testing::TestWithParam<IkCase> {
 protected:
  void SetUp() override { m = std::make_unique<Machine>(Machine::FromJson(GetParam().json)); }
  Eigen::RowVectorXd RandomPose(std::mt19937* rng) {
    std::uniform_real_distribution<double> lin(-300, 300), turn(-400, 400), spin(-180, 180),
        tilt(GetParam().tilt_lo, GetParam().tilt_hi);
    std::bernoulli_distribution coin(0.5);
    Eigen::RowVectorXd r(m->num_axes());
    for (int k = 0; k < m->num_axes(); ++k) {
      const char a = m->axis(k).name;
      if (!m->axis(k).rotary()) r[k] = lin(*rng);
      else if (a == GetParam().tilt) r[k] = coin(*rng) ? tilt(*rng) : -tilt(*rng);
      else if (a == GetParam().turn) r[k] = turn(*rng);
      else r[k] = spin(*rng);
    }
    return r;
  }
  std::unique_ptr<Machine> m;
};

double Wrap180(double deg) { return deg - 360.0 * std::round(deg / 360.0); }

TEST_P(InverseKinematicsTest, RoundTripsNominalTargets) {
  std::mt19937 rng(7);
  const int n = 200;
  Eigen::MatrixXd poses(n, m->num_axes());
  for (int i = 0; i < n; ++i) poses.row(i) = RandomPose(&rng);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m->num_parameters());
  Eigen::MatrixXd targets, target_axes;
  ToolPoses(*m, zero, poses, nullptr, &targets, &target_axes);

  // As one path from the zero pose.
  const Eigen::MatrixXd cmd = InverseKinematics(*m, zero, targets, &target_axes,
                                                Eigen::VectorXd::Zero(m->num_axes()));
  ASSERT_EQ(cmd.rows(), n);
  ASSERT_EQ(cmd.cols(), m->num_axes());
  Eigen::MatrixXd p, v;
  ToolPoses(*m, zero, cmd, nullptr, &p, &v);
  for (int i = 0; i < n; ++i) {
    EXPECT_LT((p.row(i) - targets.row(i)).norm(), 1e-9) << "target " << i;
    EXPECT_LT((v.row(i) - target_axes.row(i)).norm(), 1e-9) << "target " << i;
  }

  // From the generating pose, the smallest move is no move at all: the
  // solution is that pose itself (not merely equal modulo 360).
  for (int i = 0; i < n; ++i) {
    const Eigen::VectorXd start = poses.row(i).transpose();
    const Eigen::MatrixXd ti = targets.row(i), ai = target_axes.row(i);
    const Eigen::MatrixXd one = InverseKinematics(*m, zero, ti, &ai, start);
    for (int k = 0; k < m->num_axes(); ++k)
      EXPECT_NEAR(one(0, k), poses(i, k), m->axis(k).rotary() ? 1e-7 : 1e-9)
          << "target " << i << " axis " << m->axis(k).name;
  }
}

TEST_P(InverseKinematicsTest, TakesTheSmallestMove) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> nudge(-100, 100);
  std::uniform_int_distribution<int> turns(-2, 2);
  std::bernoulli_distribution coin(0.5);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m->num_parameters());
  const int kt = m->AxisIndex(GetParam().tilt), kc = m->AxisIndex(GetParam().turn);
  int flipped = 0, kept = 0;
  for (int i = 0; i < 200; ++i) {
    const Eigen::RowVectorXd pose = RandomPose(&rng);
    Eigen::MatrixXd target, target_axis;
    ToolPoses(*m, zero, Eigen::MatrixXd(pose), nullptr, &target, &target_axis);
    // Start somewhere else, whole turns away on the turning axis; for the
    // machines with a known second solution, half of the starts lie near it.
    Eigen::VectorXd start = pose.transpose();
    if (GetParam().flip && coin(rng)) {
      start[kt] = -pose[kt];
      start[kc] = pose[kc] + 180.0;
    }
    start[kt] += nudge(rng) / 2;
    start[kc] += nudge(rng) + 360.0 * turns(rng);
    const Eigen::MatrixXd cmd = InverseKinematics(*m, zero, target, &target_axis, start);
    Eigen::MatrixXd p, v;
    ToolPoses(*m, zero, cmd, nullptr, &p, &v);
    EXPECT_LT((p - target).norm(), 1e-9);
    EXPECT_LT((v - target_axis).norm(), 1e-9);
    // The orientation axes may not be more than half a turn from the start.
    EXPECT_LE(std::abs(cmd(0, kc) - start[kc]), 180.0 + 1e-9);
    EXPECT_LE(std::abs(cmd(0, kt) - start[kt]), 180.0 + 1e-9);
    // Candidate solutions, each unwrapped to the nearest equivalent of the
    // start; the one with the smaller squared move must be returned.
    auto nearest = [](double deg, double cur) { return cur + Wrap180(deg - cur); };
    auto cost = [&](double t, double c) {
      return std::pow(t - start[kt], 2) + std::pow(c - start[kc], 2);
    };
    const double t1 = nearest(pose[kt], start[kt]), c1 = nearest(pose[kc], start[kc]);
    const double cost_cmd = cost(cmd(0, kt), cmd(0, kc));
    EXPECT_LE(cost_cmd, cost(t1, c1) + 1e-6) << "pose " << i;
    if (GetParam().flip) {
      const double t2 = nearest(-pose[kt], start[kt]), c2 = nearest(pose[kc] + 180, start[kc]);
      const bool second = cost(t2, c2) < cost(t1, c1);
      (second ? flipped : kept)++;
      EXPECT_NEAR(cmd(0, kt), second ? t2 : t1, 1e-7) << "pose " << i;
      EXPECT_NEAR(cmd(0, kc), second ? c2 : c1, 1e-7) << "pose " << i;
    }
  }
  if (GetParam().flip) {
    // Both branches were exercised, so the choice was really tested.
    EXPECT_GT(flipped, 10);
    EXPECT_GT(kept, 10);
  }
}

TEST_P(InverseKinematicsTest, SingularToolAxisKeepsTheTurningAxis) {
  // With the tilt at 0 the tool axis is parallel to the turning axis, which
  // then cannot change it: the smallest move leaves the turning axis alone.
  std::mt19937 rng(11);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m->num_parameters());
  const int kt = m->AxisIndex(GetParam().tilt), kc = m->AxisIndex(GetParam().turn);
  for (int i = 0; i < 20; ++i) {
    Eigen::RowVectorXd pose = RandomPose(&rng);
    pose[kt] = 0;
    Eigen::MatrixXd target, target_axis;
    ToolPoses(*m, zero, Eigen::MatrixXd(pose), nullptr, &target, &target_axis);
    Eigen::VectorXd start = pose.transpose();
    start[kt] = 3.0;
    start[kc] = pose[kc] + 77.7;
    const Eigen::MatrixXd cmd = InverseKinematics(*m, zero, target, &target_axis, start);
    EXPECT_NEAR(cmd(0, kt), 0.0, 1e-7);
    EXPECT_NEAR(cmd(0, kc), start[kc], 1e-9);
    Eigen::MatrixXd p, v;
    ToolPoses(*m, zero, cmd, nullptr, &p, &v);
    EXPECT_LT((p - target).norm(), 1e-9);
    EXPECT_LT((v - target_axis).norm(), 1e-9);
  }
}

TEST_P(InverseKinematicsTest, WithoutToolAxisKeepsOrientation) {
  // No target tool axis: the orientation axes keep their current values and
  // only the linear axes move.
  std::mt19937 rng(9);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m->num_parameters());
  for (int i = 0; i < 20; ++i) {
    const Eigen::RowVectorXd pose = RandomPose(&rng), other = RandomPose(&rng);
    Eigen::VectorXd start = other.transpose();
    for (int k = 0; k < m->num_axes(); ++k)
      if (m->axis(k).rotary()) start[k] = pose[k];
    const Eigen::MatrixXd target = ToolPoints(*m, zero, Eigen::MatrixXd(pose));
    const Eigen::MatrixXd cmd = InverseKinematics(*m, zero, target, nullptr, start);
    for (int k = 0; k < m->num_axes(); ++k)
      EXPECT_NEAR(cmd(0, k), pose[k], m->axis(k).rotary() ? 1e-12 : 1e-9) << m->axis(k).name;
  }
}

TEST_P(InverseKinematicsTest, CompensatesErrors) {
  // With errors, the commands returned must put the erroneous machine's tool
  // on the (nominal) target; the nominal commands must visibly miss it, or
  // the test would not show anything.
  std::mt19937 rng(10);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m->num_parameters());
  const Eigen::VectorXd theta = RandomTheta(*m, &rng);
  const int n = 50;
  Eigen::MatrixXd poses(n, m->num_axes());
  Eigen::MatrixXi dirs(n, m->num_axes());
  std::bernoulli_distribution coin(0.5);
  for (int i = 0; i < n; ++i) {
    poses.row(i) = RandomPose(&rng);
    for (int k = 0; k < m->num_axes(); ++k) dirs(i, k) = coin(rng) ? 1 : -1;
  }
  Eigen::MatrixXd targets, target_axes;
  ToolPoses(*m, zero, poses, nullptr, &targets, &target_axes);
  const Eigen::VectorXd start = poses.row(0).transpose();

  const Eigen::MatrixXd cmd = InverseKinematics(*m, theta, targets, &target_axes, start, &dirs);
  Eigen::MatrixXd p, v;
  ToolPoses(*m, theta, cmd, &dirs, &p, &v);
  for (int i = 0; i < n; ++i) {
    EXPECT_LT((p.row(i) - targets.row(i)).norm(), 1e-6) << "target " << i;
    EXPECT_LT((v.row(i) - target_axes.row(i)).norm(), 1e-8) << "target " << i;
  }

  const Eigen::MatrixXd nominal_cmd = InverseKinematics(*m, zero, targets, &target_axes, start);
  ToolPoses(*m, theta, nominal_cmd, &dirs, &p, &v);
  EXPECT_GT((p - targets).rowwise().norm().minCoeff(), 1e-3);
  // Compensated commands differ from nominal ones by about the error size.
  const double diff = (cmd - nominal_cmd).cwiseAbs().maxCoeff();
  EXPECT_GT(diff, 1e-4);
  EXPECT_LT(diff, 5.0);
}

INSTANTIATE_TEST_SUITE_P(Machines, InverseKinematicsTest, ::testing::ValuesIn(kIkCases),
                         [](const ::testing::TestParamInfo<IkCase>& info) {
                           std::string n = Machine::FromJson(info.param.json).name();
                           std::string out;
                           for (char ch : n)
                             if (std::isalnum(static_cast<unsigned char>(ch))) out += ch;
                           return out;
                         });

}  // namespace
}  // namespace fivecal
