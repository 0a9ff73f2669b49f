// Beckhoff TwinCAT CNC: the universal kinematics (ID 91) as its manual
// states it, and the TF5280 tables for the error motions. The export is
// checked by its own kinematics, written apart from fivecal's chain code:
// fivecal's errors -> absorbed model -> values -> Beckhoff's tool points ==
// fivecal's tool points of that model, on every topology it supports.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "controller_fixtures.h"
#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/beckhoff.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/model/kinematics.h"

#ifndef FIVECAL_SOURCE_DIR
#define FIVECAL_SOURCE_DIR "."
#endif

namespace fivecal {
namespace controllers {
namespace {

using test_fixtures::Theta;

const BeckhoffVendor& V() { return BeckhoffVendor::Instance(); }

Machine Example(const std::string& name) {
  return Machine::Load(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/" + name + ".json");
}

Machine HeadHead() {  // B on C in the spindle head
  return Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,300]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
}

Machine TableHead() {  // C table, B head
  return Machine::FromJson(R"({"name": "th", "topology": "wCYfXZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1], "point": [15,-10,0]},
    "Y": {"type": "linear", "direction": [0,-1,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [0,0,220]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,40]}})");
}

std::string Letters(const Machine& m) {  // a channel order: X Y Z, then the rotaries as listed
  std::string lin, rot;
  for (const Axis& a : m.axes())
    if (a.name != 'S') (a.rotary() ? rot : lin) += a.name;
  std::sort(lin.begin(), lin.end());
  return lin + rot;
}

VendorOptions Opts(const Machine& m, double tool_length = 0) {
  return {{"syntax", "kinematik"}, {"axes", Letters(m)}, {"tool_length", std::to_string(tool_length)}};
}

VendorOptions VolOpts(const Machine& m, const std::string& mode = "error", const std::string& units = "mm,rad",
                      double lin_step = 5, double rot_step = 2) {
  VendorOptions o = Opts(m);
  o["volcomp"] = mode;
  o["volcomp_units"] = units;
  o["volcomp_frame"] = "carriage";
  for (const Axis& a : m.axes()) {
    if (a.name == 'S') continue;
    if (!a.rotary()) o[std::string("grid.") + a.name] = "-200:200:" + std::to_string(lin_step);
    else if (a.name == 'C') o[std::string("grid.") + a.name] = "-180:180:" + std::to_string(rot_step);
    else o[std::string("grid.") + a.name] = "-100:100:" + std::to_string(rot_step);
  }
  return o;
}

// Poses spanning the working volume (degrees for rotary axes).
Eigen::MatrixXd Poses(const Machine& m, int n, unsigned seed = 5) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-190, 190), tilt(-95, 95), rot(-179, 179);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < m.num_axes(); ++k) {
      const char a = m.axis(k).name;
      q(i, k) = a == 'S' ? 0.0 : a == 'C' ? rot(rng) : m.axis(k).rotary() ? tilt(rng) : lin(rng);
    }
  return q;
}

// Random location errors of every rotary axis (tens of um, tens of urad),
// the tool tip, and squareness of the linear axes (which ID 91 also takes:
// it stores every axis's orientation).
Eigen::VectorXd RandomLocation(const Machine& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> um(0, 0.03), urad(0, 3e-5);
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (int i = 0; i < m.num_parameters(); ++i) {
    const ParameterInfo& p = m.parameters()[size_t(i)];
    if (p.kind == ParameterKind::kTip) th[i] = um(rng);
    if (p.kind != ParameterKind::kLocation || m.axis(p.axis).name == 'S') continue;
    if (m.axis(p.axis).rotary()) th[i] = p.angular() ? urad(rng) : um(rng);
  }
  th[m.RequireParameter("EB0X")] = urad(rng);  // squareness of X to Z (on the machine's chain)
  return th;
}

// Random errors the absorbed model represents: per rotary axis (along a
// machine axis) its pivot and direction perpendicular to it, and the tool
// tip (only its length on a head: the kinematics has no sideways tool offset).
Eigen::VectorXd RandomRepresented(const Machine& m, unsigned seed) {
  Eigen::VectorXd th = RandomLocation(m, seed);
  th[m.RequireParameter("EB0X")] = 0;
  bool head = false;
  for (int k = 0; k < m.num_axes(); ++k) {
    const Axis& a = m.axis(k);
    if (!a.rotary() || a.name == 'S') continue;
    head = head || m.on_tool_side(k);
    for (int c = 0; c < 6; ++c)
      if (std::abs(a.direction[c % 3]) > 0.99) th[m.location_index(k, c)] = 0;
  }
  if (head) th[m.tip_index()] = th[m.tip_index() + 1] = 0;
  return th;
}

// Random error motions (polynomials) of the linear and rotary axes.
Eigen::VectorXd RandomMotions(const Machine& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> z(0, 1);
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (int i = 0; i < m.num_parameters(); ++i) {
    const ParameterInfo& p = m.parameters()[size_t(i)];
    if (p.kind != ParameterKind::kMotion || m.axis(p.axis).name == 'S') continue;
    // Sizes that give tens of um / urad over the travel (q up to 200 mm or ~3 rad).
    const double range = m.axis(p.axis).rotary() ? 3.0 : 200.0;
    const double size = p.angular() ? 2e-5 : 0.02;
    th[i] = z(rng) * size / std::pow(range, p.degree);
  }
  return th;
}

double MaxNorm(const Eigen::MatrixXd& d) { return d.rowwise().norm().maxCoeff(); }

// Controller-frame points (vendor.h: the machine frame at the zero pose,
// carried by the workpiece chain) in the part frame of the model theta,
// where fivecal's tool points are.
Eigen::MatrixXd InPart(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& points) {
  const KinematicsTable t = MakeKinematicsTable(m, theta);
  return (points.rowwise() - t.part_origin.transpose()) * t.part_rotation;
}

Eigen::VectorXd Named(const std::vector<VendorValue>& names, const std::map<std::string, double>& set) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(Eigen::Index(names.size()));
  std::map<std::string, double> left = set;
  for (size_t i = 0; i < names.size(); ++i) {
    const auto it = left.find(names[i].name);
    if (it != left.end()) v[Eigen::Index(i)] = it->second, left.erase(it);
  }
  EXPECT_TRUE(left.empty()) << "unknown value " << (left.empty() ? "" : left.begin()->first);
  return v;
}

// (a) The manual's configurations, with the tool points worked by hand (the
// pages print the parameters, not tool points).
TEST(VendorBeckhoff, ClassicCaModeAsTheManualStatesIt) {
  // 'Classic programming modes' (278765451), CA mode 17: tool zero position
  // 0, zero orientation +Z, chain XYZCA, every axis through the origin.
  const Machine m = Machine::FromJson(R"({"name": "ca", "topology": "wfXYZCASt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]}, "C": {"type": "rotary", "direction": [0,0,1]},
    "A": {"type": "rotary", "direction": [1,0,0]}, "S": {"type": "rotary", "direction": [0,0,1]}},
    "tool": {"tip": [0,0,0]}})");
  VendorOptions o = Opts(m, 100);  // a 100 mm tool: TCP = zero_position - 100 * zero_orientation
  o["axes"] = "XYZCA";
  const std::string P = "kinematik[91].";
  const Eigen::VectorXd v = Named(V().Values(m, o), {
      {P + "number_of_axes", 5}, {P + "chain[0]", 0}, {P + "chain[1]", 1}, {P + "chain[2]", 2}, {P + "chain[3]", 3},
      {P + "chain[4]", 4}, {P + "zero_orientation[2]", 1},
      {P + "axis[0].type", 1}, {P + "axis[0].orientation[0]", 1}, {P + "axis[1].type", 1}, {P + "axis[1].orientation[1]", 1},
      {P + "axis[2].type", 1}, {P + "axis[2].orientation[2]", 1}, {P + "axis[3].type", 2}, {P + "axis[3].orientation[2]", 1},
      {P + "axis[4].type", 2}, {P + "axis[4].orientation[0]", 1}});
  Eigen::MatrixXd q(3, 6);
  //      X    Y   Z   C   A   S
  q << 0, 0, 0, 0, 0, 0,     //
      0, 0, 0, 90, 90, 0,    // A turns the tool (0,0,-100) to (0,100,0), then C to (-100,0,0)
      10, 20, 30, 0, 90, 0;  // A alone: (0,100,0), plus the linear axes
  const Eigen::MatrixXd p = V().ToolPoints(m, v, q, o);
  EXPECT_LT((p.row(0) - Eigen::RowVector3d(0, 0, -100)).norm(), 1e-12);
  EXPECT_LT((p.row(1) - Eigen::RowVector3d(-100, 0, 0)).norm(), 1e-12);
  EXPECT_LT((p.row(2) - Eigen::RowVector3d(10, 120, 30)).norm(), 1e-12);
}

TEST(VendorBeckhoff, FlangeAndToolAsTheManualStatesIt) {
  // 'Description of flange and tool' (556386059): the flange rests at
  // (12000, 3200, 500) in 0.1 um; the tool at 45 deg to Y and Z given as
  // (0, 1, 1) without normalisation; TCP = zero_position - L * orientation.
  const Machine m = HeadHead();
  VendorOptions o = Opts(m, 10);
  const std::string P = "kinematik[91].";
  const Eigen::VectorXd nominal = V().Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  const std::vector<VendorValue> names = V().Values(m, o);
  Eigen::VectorXd v = nominal;
  for (size_t i = 0; i < names.size(); ++i) {
    const std::map<std::string, double> set = {{P + "zero_position[0]", 12000}, {P + "zero_position[1]", 3200},
                                               {P + "zero_position[2]", 500},   {P + "zero_orientation[0]", 0},
                                               {P + "zero_orientation[1]", 1},  {P + "zero_orientation[2]", 1}};
    if (set.count(names[i].name)) v[Eigen::Index(i)] = set.at(names[i].name);
  }
  const Eigen::MatrixXd p = V().ToolPoints(m, v, Eigen::MatrixXd::Zero(1, m.num_axes()), o);
  const double s = 10 / std::sqrt(2.0);
  EXPECT_LT((p.row(0) - Eigen::RowVector3d(1.2, 0.32 - s, 0.05 - s)).norm(), 1e-12);
}

// (b) Round trip per topology: absorbed model -> values -> Beckhoff's tool
// points == fivecal's tool points of the absorbed model.
TEST(VendorBeckhoff, RoundTripOnEveryTopology) {
  for (const Machine& m : {Example("hu40t"), Example("c600u"), Example("kx8"), Example("vmc0656"), HeadHead(),
                           TableHead()}) {
    const VendorOptions o = Opts(m, 87.5);
    const VendorModel vm = V().Model(m, o);
    const Eigen::MatrixXd q = Poses(m, 150);
    for (unsigned seed : {1u, 2u, 3u}) {
      const Eigen::VectorXd th = RandomLocation(m, seed);
      AbsorbOptions ao;
      ao.directions = vm.directions;
      ao.tool_length = vm.tool_length;
      const Absorption ab = Absorb(m, vm.model, th, q, ao);
      const Eigen::VectorXd v = V().Map(m, MakeKinematicsTable(m, ab.theta), o);
      const Eigen::MatrixXd mine = InPart(m, ab.theta, V().ToolPoints(m, v, q, o));
      const Eigen::MatrixXd theirs = fivecal::ToolPoints(m, ab.theta, q);
      EXPECT_LT(MaxNorm(mine - theirs), 1e-9) << m.name() << " seed " << seed;
      // What the model cannot represent is the absorption's residual.
      Eigen::MatrixXd truth = fivecal::ToolPoints(m, th, q);
      truth.rowwise() -= ab.workpiece_shift.transpose();
      EXPECT_LT(MaxNorm(mine - truth + ab.residual), 1e-9) << m.name() << " seed " << seed;
      EXPECT_GT(MaxNorm(fivecal::ToolPoints(m, th, q) - fivecal::ToolPoints(m, 0 * th, q)), 1e-2);
      // The errors it represents are all absorbed: the values reproduce the
      // erroneous machine up to the work offset.
      if (m.name() == "KX8-like") continue;  // its A is at 45 deg: RandomRepresented is for machine axes
      const Eigen::VectorXd rep = RandomRepresented(m, seed);
      const Absorption ar = Absorb(m, vm.model, rep, q, ao);
      Eigen::MatrixXd real = fivecal::ToolPoints(m, rep, q);
      real.rowwise() -= ar.workpiece_shift.transpose();
      EXPECT_LT(MaxNorm(InPart(m, ar.theta, V().ToolPoints(m, V().Map(m, MakeKinematicsTable(m, ar.theta), o), q, o)) -
                        real), 1e-6)
          << m.name() << " seed " << seed;
    }
  }
}

TEST(VendorBeckhoff, NewSyntaxGivesTheSameKinematics) {
  const Machine m = Example("hu40t");
  VendorOptions o = Opts(m, 20), o3 = o;
  o3["syntax"] = "trafo[1]";
  const Eigen::VectorXd th = RandomLocation(m, 7);
  const KinematicsTable t = MakeKinematicsTable(m, th);
  const Eigen::VectorXd v = V().Map(m, t, o), v3 = V().Map(m, t, o3);
  const std::vector<VendorValue> n3 = V().Values(m, o3);
  ASSERT_EQ(v3.size(), v.size() + 1);
  EXPECT_EQ(n3[0].name, "trafo[1].id");
  EXPECT_EQ(v3[0], 91);
  EXPECT_TRUE(n3[0].fixed);
  EXPECT_EQ(n3[1].name, "trafo[1].number_of_axes");
  const Eigen::MatrixXd q = Poses(m, 30);
  EXPECT_LT(MaxNorm(V().ToolPoints(m, v, q, o) - V().ToolPoints(m, v3, q, o3)), 1e-12);
}

// (b) with the TF5280 tables: the error motions tabulated and linearly
// interpolated; the kinematics take the rest (no double counting).
TEST(VendorBeckhoff, TablesCarryTheErrorMotions) {
  for (const Machine& m : {Example("hu40t"), HeadHead(), TableHead()}) {
    const VendorModel vm = V().Model(m, Opts(m));
    const Eigen::MatrixXd q = Poses(m, 150, 9);
    const Eigen::VectorXd motions = RandomMotions(m, 4);
    const Eigen::VectorXd th = RandomRepresented(m, 4) + motions;
    ASSERT_EQ(WithoutErrorMotions(m, th), th - motions);
    AbsorbOptions ao;
    ao.directions = vm.directions;
    const Absorption ab = Absorb(m, vm.model, WithoutErrorMotions(m, th), q, ao);
    Eigen::MatrixXd truth = fivecal::ToolPoints(m, th, q);
    truth.rowwise() -= ab.workpiece_shift.transpose();
    const Eigen::MatrixXd model = fivecal::ToolPoints(m, ab.theta + motions, q);
    for (const char* mode : {"error", "correction"})
      for (const char* units : {"mm,rad", "um,urad"}) {
        const VendorOptions o = VolOpts(m, mode, units, 10, 5);
        const Eigen::VectorXd v = V().Map(m, MakeKinematicsTable(m, ab.theta), o) + V().MapMotions(m, th, o);
        const Eigen::MatrixXd mine = InPart(m, ab.theta, V().ToolPoints(m, v, q, o));
        // Linear interpolation (10 mm, 5 deg) of cubics of tens of um, plus the
        // second-order terms of two small errors: well under 0.1 um.
        EXPECT_LT(MaxNorm(mine - model), 1e-4) << m.name() << " " << mode << " " << units;
        EXPECT_LT(MaxNorm(mine - truth), 1e-4) << m.name() << " " << mode << " " << units;
      }
    // The tables matter: without them the error motions are left, and a
    // table of the wrong sign doubles them.
    const VendorOptions o = VolOpts(m, "error", "mm,rad", 10, 5);
    const Eigen::VectorXd kin = V().Map(m, MakeKinematicsTable(m, ab.theta), o);
    const auto part = [&](const Eigen::VectorXd& v) { return InPart(m, ab.theta, V().ToolPoints(m, v, q, o)); };
    EXPECT_GT(MaxNorm(part(kin) - truth), 5e-3) << m.name();
    const Eigen::VectorXd flipped = kin - V().MapMotions(m, th, o);
    EXPECT_GT(MaxNorm(part(flipped) - truth), 1.5 * MaxNorm(part(kin) - truth));
  }
}

TEST(VendorBeckhoff, TableValuesAreTheErrorMotionsOnTheGrid) {
  const Machine m = Example("hu40t");
  const VendorOptions o = VolOpts(m, "error", "um,urad", 50, 20);
  const Eigen::VectorXd th = Theta(m, {{"EXX1", 2e-5}, {"ECC2", 1e-6}, {"EYZ3", 1e-9}});
  const Eigen::VectorXd v = V().MapMotions(m, th, o);
  const std::vector<VendorValue> names = V().Values(m, o);
  std::map<std::string, std::pair<double, std::string>> at;
  for (size_t i = 0; i < names.size(); ++i) at[names[i].name] = {v[Eigen::Index(i)], names[i].unit};
  // Grid X -200:200:50: X[0] = -200 (its value sits in Map, fixed).
  EXPECT_NEAR(at.at("EXX[0]").first, 2e-5 * -200 * 1e3, 1e-9);
  EXPECT_EQ(at.at("EXX[0]").second, "um");
  EXPECT_NEAR(at.at("EYZ[8]").first, 1e-9 * 200 * 200 * 200 * 1e3, 1e-9);
  const double c = -180 * M_PI / 180;
  EXPECT_NEAR(at.at("ECC[0]").first, 1e-6 * c * c * 1e6, 1e-9);
  EXPECT_EQ(at.at("ECC[0]").second, "urad");
  EXPECT_EQ(at.at("EYX[3]").first, 0.0);
  const Eigen::VectorXd mapped = V().Map(m, MakeKinematicsTable(m, th), o);
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i].name == "X[0]") EXPECT_EQ(mapped[Eigen::Index(i)], -200);
    if (names[i].name == "C[18]") EXPECT_EQ(mapped[Eigen::Index(i)], 180);
  }
  const Eigen::VectorXd corr = V().MapMotions(m, th, VolOpts(m, "correction", "um,urad", 50, 20));
  EXPECT_LT((corr + v).cwiseAbs().maxCoeff(), 1e-15);
}

// (c) The way back.
TEST(VendorBeckhoff, TableOfMapIsTheTable) {
  for (const Machine& m : {Example("hu40t"), Example("kx8"), HeadHead(), TableHead()}) {
    const VendorOptions o = Opts(m, 33);
    const KinematicsTable t = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
    const KinematicsTable back = V().Table(m, V().Map(m, t, o), o);
    ASSERT_EQ(back.axes.size(), t.axes.size());
    for (size_t i = 0; i < t.axes.size(); ++i) {
      EXPECT_EQ(back.axes[i].axis, t.axes[i].axis);
      EXPECT_EQ(back.axes[i].tool_chain, t.axes[i].tool_chain);
      EXPECT_LT((back.axes[i].direction - t.axes[i].direction).norm(), 1e-12);
      EXPECT_LT((back.axes[i].point - t.axes[i].point).norm(), 1e-12);
    }
    EXPECT_LT((back.tool_tip - t.tool_tip).norm(), 1e-12);
    EXPECT_LT((back.tool_axis - t.tool_axis).norm(), 1e-12);
    // An erroneous table (its part frame moved by the table axes' errors)
    // comes back in the machine frame: the same tool points up to the part frame.
    const KinematicsTable te = MakeKinematicsTable(m, RandomLocation(m, 11));
    const Eigen::MatrixXd q = Poses(m, 40);
    Eigen::MatrixXd qt(q.rows(), Eigen::Index(te.axes.size()));
    for (size_t i = 0; i < te.axes.size(); ++i) qt.col(Eigen::Index(i)) = q.col(m.AxisIndex(te.axes[i].axis));
    const Eigen::MatrixXd back_points = TableToolPoints(V().Table(m, V().Map(m, te, o), o), qt);
    EXPECT_LT(MaxNorm(TableToolPoints(te, qt) - (back_points.rowwise() - te.part_origin.transpose()) * te.part_rotation),
              1e-9);
  }
}

// (d) The nominal machine: the machine file's geometry, in the manual's units.
TEST(VendorBeckhoff, NominalMachineGivesTheMachineFilesGeometry) {
  const Machine m = Example("hu40t");  // wCBXfZYSt: C, B, X on the workpiece side
  VendorOptions o = Opts(m, 25);
  o["axes"] = "XYZBC";
  const Eigen::VectorXd v = V().Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  const std::vector<VendorValue> names = V().Values(m, o);
  std::map<std::string, double> at;
  for (size_t i = 0; i < names.size(); ++i) at[names[i].name] = v[Eigen::Index(i)];
  const std::string P = "kinematik[91].";
  // Chain from the workpiece: C, B, X, then Z, Y (channel indices 4 3 0 2 1).
  const std::vector<int> chain = {4, 3, 0, 2, 1};
  for (int c = 0; c < 5; ++c) EXPECT_EQ(at.at(P + "chain[" + std::to_string(c) + "]"), chain[size_t(c)]);
  EXPECT_EQ(at.at(P + "number_of_axes"), 5);
  // B: direction (0,-1,0), pivot (0,0,-120) on the workpiece side -> (0,1,0), point -1200000.
  EXPECT_EQ(at.at(P + "axis[3].type"), 2);
  EXPECT_NEAR(at.at(P + "axis[3].orientation[1]"), 1, 1e-15);
  EXPECT_NEAR(at.at(P + "axis[3].point[2]"), -1200000, 1e-9);
  EXPECT_NEAR(at.at(P + "axis[4].orientation[2]"), 1, 1e-15);  // C (0,0,-1) on the workpiece side
  EXPECT_NEAR(at.at(P + "axis[0].orientation[0]"), 1, 1e-15);  // X (-1,0,0) on the workpiece side
  EXPECT_NEAR(at.at(P + "axis[2].orientation[2]"), 1, 1e-15);  // Z on the tool side
  EXPECT_NEAR(at.at(P + "axis[1].orientation[1]"), 1, 1e-15);  // Y on the tool side
  EXPECT_EQ(at.count(P + "axis[0].point[0]"), 0u);               // linear axes have no point
  // Tip (0,0,100) with a 25 mm tool in the table: the flange at z = 125 mm.
  EXPECT_NEAR(at.at(P + "zero_position[2]"), 1250000, 1e-9);
  EXPECT_NEAR(at.at(P + "zero_orientation[2]"), 1, 1e-15);
  for (const VendorValue& val : names) {
    EXPECT_NE(val.source.find("infosys.beckhoff.com"), std::string::npos) << val.name;
    if (val.name.find("zero_position") != std::string::npos || val.name.find("point") != std::string::npos) {
      EXPECT_EQ(val.unit, "0.0001mm");  // 0.1 um, as the export guard names it
    }
  }
}

// (e) Refusals, each naming what is wrong.
void ExpectThrow(const std::function<void()>& f, const std::string& part) {
  try {
    f();
    ADD_FAILURE() << "no exception, expected one mentioning '" << part << "'";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
  }
}

TEST(VendorBeckhoff, RefusesWhatItCannotStateOrSupport) {
  const Machine m = Example("hu40t");
  const Machine four = Machine::FromJson(R"({"name": "4ax", "topology": "wCfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]}, "X": {"type": "linear", "direction": [1,0,0]},
    "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
  ExpectThrow([&] { V().Model(four, Opts(four)); }, "not supported");
  ExpectThrow([&] { V().Values(four, Opts(four)); }, "two rotary axes");
  VendorOptions o = Opts(m);
  o.erase("syntax");
  ExpectThrow([&] { V().Values(m, o); }, "--set syntax=");
  o = Opts(m);
  o.erase("axes");
  ExpectThrow([&] { V().Values(m, o); }, "--set axes=");
  o = Opts(m);
  o.erase("tool_length");
  ExpectThrow([&] { V().Values(m, o); }, "--set tool_length=");
  o = Opts(m);
  o["colour"] = "red";
  ExpectThrow([&] { V().Values(m, o); }, "'colour': not a beckhoff option");
  o = Opts(m);
  o["axes"] = "XYZB";
  ExpectThrow([&] { V().Values(m, o); }, "axes=XYZB");
  o = Opts(m);
  o["syntax"] = "kinematics";
  ExpectThrow([&] { V().Values(m, o); }, "syntax=kinematics");
  o = Opts(m);
  o["tool_length"] = "12mm";
  ExpectThrow([&] { V().Values(m, o); }, "tool_length=12mm: expected a number");
  o = VolOpts(m);
  o.erase("grid.B");
  ExpectThrow([&] { V().Values(m, o); }, "--set grid.B=");
  o = VolOpts(m);
  o.erase("volcomp_units");
  ExpectThrow([&] { V().Values(m, o); }, "--set volcomp_units=");
  o = VolOpts(m);
  o.erase("volcomp_frame");
  ExpectThrow([&] { V().Values(m, o); }, "--set volcomp_frame=");
  o = VolOpts(m);
  o["volcomp_frame"] = "relative";
  ExpectThrow([&] { V().Values(m, o); }, "volcomp_frame=relative");
  o = VolOpts(m);
  o["grid.X"] = "-200:200:7";
  ExpectThrow([&] { V().Values(m, o); }, "whole number");
  o = VolOpts(m);
  o["volcomp"] = "yes";
  ExpectThrow([&] { V().Values(m, o); }, "volcomp=yes");
  o = Opts(m);
  o["grid.X"] = "-200:200:10";
  ExpectThrow([&] { V().Values(m, o); }, "only with volcomp");
  o = Opts(m);
  o["grid.S"] = "0:1:1";
  ExpectThrow([&] { V().Values(m, o); }, "no NC axis S");
  // Values of another machine or axis order are refused, naming the value.
  o = Opts(m);
  Eigen::VectorXd v = V().Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  v[1] = 0;  // chain[0]: X instead of C
  ExpectThrow([&] { V().Table(m, v, o); }, "kinematik[91].chain[0]");
  ExpectThrow([&] { V().ToolPoints(m, v.head(4), Poses(m, 2), o); }, "values: 4 given");
  // A pose outside the table grid.
  o = VolOpts(m);
  const Eigen::VectorXd vt = V().Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  Eigen::MatrixXd q = Poses(m, 1);
  q(0, m.AxisIndex('X')) = 250;
  ExpectThrow([&] { V().ToolPoints(m, vt, q, o); }, "outside the volumetric table's grid");
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal

namespace fivecal {
namespace controllers {
namespace {

// The common export path with the tables: the kinematics absorb the location
// errors, the tables take the error motions, their sigma comes from the
// motions' covariance, and the round trip holds with both.
TEST(VendorBeckhoff, ExportCarriesTheTablesThroughTheCommonPath) {
  EXPECT_EQ(&FindVendor("beckhoff"), &BeckhoffVendor::Instance());
  const Machine m = Example("hu40t");
  // 10 mm and 5 deg: the interpolation stays far below 1 um, and the
  // change's covariance (values x values) stays small.
  const VendorOptions o = VolOpts(m, "error", "um,urad", 10, 5);
  const Eigen::VectorXd motions = RandomMotions(m, 8);
  Eigen::VectorXd th = RandomRepresented(m, 8) + motions;
  // a tool offset across the spindle is the stylus's: no export takes it (vendor.h)
  th[m.tip_index()] = th[m.tip_index() + 1] = 0;
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(m.num_parameters(), m.num_parameters());
  const int exx1 = m.RequireParameter("EXX1"), ex0c = m.RequireParameter("EX0C");
  cov(exx1, exx1) = 1e-12;  // 1e-6 mm/mm
  cov(ex0c, ex0c) = 1e-6;   // 1 um
  const Eigen::MatrixXd q = Poses(m, 120, 12);
  const VendorExport ex = ExportToVendor(m, BeckhoffVendor::Instance(), th, cov, q, o);
  EXPECT_LT(ex.round_trip_max, 1e-4);
  const Eigen::VectorXd tables = BeckhoffVendor::Instance().MapMotions(m, th, o);
  const Eigen::VectorXd kin = BeckhoffVendor::Instance().Map(m, MakeKinematicsTable(m, ex.absorption.theta), o) -
                              BeckhoffVendor::Instance().Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  EXPECT_LT((ex.change - tables - kin).cwiseAbs().maxCoeff(), 1e-9);
  for (size_t i = 0; i < ex.values.size(); ++i) {
    const std::string& n = ex.values[i].name;
    if (n == "EXX[0]") EXPECT_NEAR(ex.sigma[Eigen::Index(i)], 200 * 1e-6 * 1e3, 1e-9);  // X[0] = -200 mm, in um
    if (n == "EYX[0]" || n == "ECC[3]") EXPECT_EQ(ex.sigma[Eigen::Index(i)], 0.0);
    if (n == "kinematik[91].axis[3].point[0]") EXPECT_GT(ex.sigma[Eigen::Index(i)], 1.0);  // C pivot: 0.1 um units
  }
  // The truth, through Beckhoff's kinematics with the new values.
  Eigen::MatrixXd truth = fivecal::ToolPoints(m, th, q);
  truth.rowwise() -= ex.absorption.workpiece_shift.transpose();
  const Eigen::MatrixXd mine = InPart(m, ex.absorption.theta, BeckhoffVendor::Instance().ToolPoints(m, ex.new_values, q, o));
  EXPECT_LT(MaxNorm(mine - truth), 1e-4);
}

// The tables' sigma without their values x values covariance: every
// value's sigma is still its definition (the change differentiated
// numerically, through the identification's covariance), the covariance is
// kept for the kinematics values only, and the table entries say so.
TEST(VendorBeckhoff, TableSigmaIsItsDefinitionWithoutTheTablesCovariance) {
  const Machine m = Example("hu40t");
  const VendorOptions o = VolOpts(m, "error", "um,urad", 20, 10);
  const Eigen::VectorXd th = RandomRepresented(m, 3) + RandomMotions(m, 3);
  const int nt = m.num_parameters();
  const std::vector<int> uncertain = {m.RequireParameter("EXX1"), m.RequireParameter("EYX2"),
                                      m.RequireParameter("EX0C"), m.RequireParameter("EZ0B")};
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(nt, nt);
  const Eigen::Vector4d s(2e-6, 1e-8, 1e-3, 2e-3);
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) cov(uncertain[a], uncertain[b]) = (a == b ? 1.0 : 0.3) * s[a] * s[b];
  const Eigen::MatrixXd q = Poses(m, 60, 12);
  const VendorExport ex = ExportToVendor(m, BeckhoffVendor::Instance(), th, cov, q, o);
  Eigen::MatrixXd D(ex.change.size(), 4);
  for (int a = 0; a < 4; ++a) {
    Eigen::VectorXd up = th, down = th;
    const double h = 1e-6;
    up[uncertain[a]] += h;
    down[uncertain[a]] -= h;
    D.col(a) = (ExportToVendor(m, BeckhoffVendor::Instance(), up, Eigen::MatrixXd(), q, o).change -
                ExportToVendor(m, BeckhoffVendor::Instance(), down, Eigen::MatrixXd(), q, o).change) / (2 * h);
  }
  Eigen::Matrix4d c4;
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) c4(a, b) = cov(uncertain[a], uncertain[b]);
  const Eigen::VectorXd want = (D * c4 * D.transpose()).diagonal().cwiseSqrt();
  EXPECT_LT((ex.sigma - want).cwiseAbs().maxCoeff(), 1e-5 * want.maxCoeff());
  size_t tables = 0;
  for (const VendorValue& v : ex.values) tables += v.motion;
  EXPECT_GT(tables, 100u);
  ASSERT_EQ(ex.covariance_index.size(), ex.values.size() - tables);
  for (Eigen::Index r = 0; r < Eigen::Index(ex.covariance_index.size()); ++r) {
    EXPECT_FALSE(ex.values[size_t(ex.covariance_index[size_t(r)])].motion);
    EXPECT_NEAR(std::sqrt(std::max(0.0, ex.covariance(r, r))), ex.sigma[ex.covariance_index[size_t(r)]],
                1e-9 * want.maxCoeff());
  }
  EXPECT_GT(want.maxCoeff(), 0.0);
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
