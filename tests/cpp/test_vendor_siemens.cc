// The Siemens swivel data record (siemens.h): the manual's own worked example,
// the round trip errors -> Absorb -> record -> the record's own
// transformation on every topology the record supports (P: the four example
// machines; T: a head-head machine; M: a table-head machine), the way back,
// the nominal machine's record, and the refusals.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/controllers/siemens.h"
#include "fivecal/model/kinematics.h"
#include "test_files.h"

namespace fivecal {
namespace controllers {
namespace {

const VendorOptions kRecord1 = {{"record", "1"}};

Machine Example(const std::string& name) {
  return Machine::FromJson(ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/" + name + ".json"));
}

Machine HeadHead() {  // C carrying B in the spindle head (type T)
  return Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [-1,0,0]}, "Y": {"type": "linear", "direction": [0,-1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [4,0,310]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
}

Machine NutatingHead() {  // C carrying a B inclined 45 degrees (type T, a nutating head)
  return Machine::FromJson(R"({"name": "nh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [-1,0,0]}, "Y": {"type": "linear", "direction": [0,-1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,400]},
    "B": {"type": "rotary", "direction": [0,0.7071067811865476,0.7071067811865476], "point": [0,-60,340]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,-60,120]}})");
}

Machine TableHead() {  // a table C under a head B (type M)
  return Machine::FromJson(R"({"name": "th", "topology": "wCYfXZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1], "point": [5,-3,0]},
    "Y": {"type": "linear", "direction": [0,-1,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [0,0,250]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,80]}})");
}

// The machine of the W1 example (§4.1 p. 4-3): A carrying B on the table, B
// about +y ("the rotary axis of the table is pointing in the positive Y
// direction", p. 2-98), a 13 mm tool (tip 13 mm below the adapter).
Machine W1Example() {
  return Machine::FromJson(R"({"name": "w1", "topology": "wBAfXYZSt", "axes": {
    "B": {"type": "rotary", "direction": [0,1,0]}, "A": {"type": "rotary", "direction": [1,0,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,-13]}})");
}

// Poses over a working volume: linear +-200 mm, tilts -90..60, turns a full circle.
Eigen::MatrixXd Poses(const Machine& m, int n, unsigned seed = 5) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-200, 200), tilt(-90, 60), rot(-180, 180);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < m.num_axes(); ++k) {
      const char a = m.axis(k).name;
      q(i, k) = a == 'S' ? 0.0 : a == 'C' ? rot(rng) : (a == 'A' || a == 'B') ? tilt(rng) : lin(rng);
    }
  return q;
}

// Pivot errors of tens of um and direction errors of tens of urad on both
// rotary axes, drawn in the directions the record's model represents (the
// absorber's columns: pivots across and tilts of each axis); anything else
// (a turn of the part about its own axis, a squareness) is not the record's.
Eigen::VectorXd RandomPivotErrors(const Machine& m, ControllerModel model, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> mm(0, 0.03), rad(0, 3e-5);
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (const ControllerParameter& p : ControllerParameters(m, model, true, false))
    th += (p.unit == "mm" ? mm(rng) : rad(rng)) * p.column;
  return th;
}

// The controller's tool points are the model's up to the work offset the
// user probes: the record carries no part frame, so the part frame of the
// table mapped (origin, rotation at the zero pose) maps fivecal's onto them.
Eigen::MatrixXd InTableFrame(const KinematicsTable& t, const Eigen::MatrixXd& part) {
  Eigen::MatrixXd out = (t.part_rotation * part.transpose()).transpose();
  out.rowwise() += t.part_origin.transpose();
  return out;
}

double MaxNorm(const Eigen::MatrixXd& d) { return d.rowwise().norm().maxCoeff(); }

// The machine's commands as a table's columns (one per row, by axis name).
Eigen::MatrixXd TableQ(const Machine& m, const KinematicsTable& t, const Eigen::MatrixXd& q) {
  Eigen::MatrixXd qt(q.rows(), Eigen::Index(t.axes.size()));
  for (size_t k = 0; k < t.axes.size(); ++k) qt.col(Eigen::Index(k)) = q.col(m.AxisIndex(t.axes[k].axis));
  return qt;
}

TEST(VendorSiemens, TheW1ExampleApproachesThePrintedPosition) {
  // W1 08/2005 §4.1 p. 4-3: I4 = (0, 0, 15), A0 B45, T1 13 mm long, WCS
  // X0 Y10 Z0 is approached at machine X10.607 Y10.000 Z8.607: the zero
  // offset X 15 sin 45, Z -15 (1 - cos 45) plus the tool length. The point
  // lies on the B axis, so the table's rotation leaves it where it is.
  const Machine m = W1Example();
  const SiemensVendor s;
  ASSERT_EQ(SiemensVendor::KinematicsType(m), 'P');
  Eigen::VectorXd v(16);
  // I2, I3, I4, V1 (A: at 0 in the example), V2, type
  v << 0, 0, 0, 0, 0, 0, 0, 0, 15, 1, 0, 0, 0, 1, 0, 'P';
  const int iX = m.AxisIndex('X'), iY = m.AxisIndex('Y'), iZ = m.AxisIndex('Z'), iB = m.AxisIndex('B');
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(2, m.num_axes());
  const double r = std::sqrt(0.5);
  q(0, iX) = 15 * r;
  q(0, iY) = 10;
  q(0, iZ) = 13 - 15 * (1 - r);
  q(0, iB) = 45;
  q.row(1) = q.row(0);
  q(1, iX) = 10.607;  // as printed
  q(1, iZ) = 8.607;
  const Eigen::MatrixXd y = s.ToolPoints(m, v, q, kRecord1);
  EXPECT_LT((y.row(0) - Eigen::RowVector3d(0, 10, 0)).norm(), 1e-12) << y.row(0);
  EXPECT_LT((y.row(1) - Eigen::RowVector3d(0, 10, 0)).norm(), 1e-3) << y.row(1);
  // The other rotation sense (or the table vector's other sign) misses by 15 mm.
  Eigen::VectorXd w = v;
  w[13] = -1;
  EXPECT_GT((s.ToolPoints(m, w, q, kRecord1).row(0) - Eigen::RowVector3d(0, 10, 0)).norm(), 10.0);
  // The same record through the neutral table's screws.
  const KinematicsTable t = s.Table(m, v, kRecord1);
  EXPECT_LT(MaxNorm(y - TableToolPoints(t, TableQ(m, t, q))), 1e-12);
}

struct Case {
  std::string name;
  Machine m;
  char type;
};

std::vector<Case> Cases() {
  return {{"hu40t", Example("hu40t"), 'P'}, {"c600u", Example("c600u"), 'P'}, {"kx8", Example("kx8"), 'P'},
          {"vmc0656", Example("vmc0656"), 'P'}, {"head-head", HeadHead(), 'T'},
          {"nutating head", NutatingHead(), 'T'}, {"table-head", TableHead(), 'M'}};
}

TEST(VendorSiemens, RoundTripOnEveryTopology) {
  const SiemensVendor s;
  for (const Case& c : Cases()) {
    const Machine& m = c.m;
    ASSERT_EQ(SiemensVendor::KinematicsType(m), c.type) << c.name;
    const VendorModel vm = s.Model(m, kRecord1);
    const Eigen::MatrixXd q = Poses(m, 120);
    for (unsigned seed : {1u, 2u, 3u}) {
      const Eigen::VectorXd truth = RandomPivotErrors(m, vm.model, seed);
      AbsorbOptions ao;
      ao.directions = vm.directions;
      ao.tool_length = vm.tool_length;
      const Absorption ab = Absorb(m, vm.model, truth, q, ao);
      // what the record represents is absorbed whole
      EXPECT_LT(ab.max, 1e-9) << c.name << " seed " << seed;
      EXPECT_GT(ab.max_old, 5e-3) << c.name;
      const KinematicsTable t = MakeKinematicsTable(m, ab.theta);
      const Eigen::VectorXd v = s.Map(m, t, kRecord1);
      ASSERT_EQ(v.size(), Eigen::Index(s.Values(m, kRecord1).size()));
      const Eigen::MatrixXd sie = s.ToolPoints(m, v, q, kRecord1);
      const Eigen::MatrixXd model = ToolPoints(m, ab.theta, q);
      EXPECT_LT(MaxNorm(sie - InTableFrame(t, model)), 1e-9) << c.name << " seed " << seed;
      // Without a turning table there is no part frame to map; with one,
      // comparing in fivecal's part frame directly would miss by its turn.
      if (c.type == 'T')
        EXPECT_LT(MaxNorm(sie - model), 1e-9) << c.name;
      else
        EXPECT_GT(MaxNorm(sie - model), 1e-3) << c.name;
      // and the erroneous machine, through the absorber's work offset
      Eigen::MatrixXd shifted = ToolPoints(m, truth, q);
      shifted.rowwise() -= ab.workpiece_shift.transpose();
      EXPECT_LT(MaxNorm(sie - InTableFrame(t, shifted)), 1e-8) << c.name << " seed " << seed;
      // the nominal record leaves the errors
      const Eigen::VectorXd v0 = s.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), kRecord1);
      EXPECT_GT(MaxNorm(s.ToolPoints(m, v0, q, kRecord1) - InTableFrame(t, model)), 5e-3) << c.name;
    }
  }
}

TEST(VendorSiemens, WhatTheRecordCannotRepresentIsLeftNotHidden) {
  // A squareness of the linear axes: the record's tool points are still the
  // absorbed model's, the residual is the absorber's.
  const Machine m = Example("c600u");
  const SiemensVendor s;
  const Eigen::MatrixXd q = Poses(m, 100);
  Eigen::VectorXd truth = RandomPivotErrors(m, ControllerModel::kTableTable, 7);
  truth[m.RequireParameter("EC0C")] = 5e-5;  // the part turned on C: a work offset's rotation
  truth[m.RequireParameter("EC0Y")] = 8e-5;
  AbsorbOptions ao;
  ao.directions = true;
  ao.tool_length = false;
  const Absorption ab = Absorb(m, s.Model(m, kRecord1).model, truth, q, ao);
  EXPECT_GT(ab.max, 1e-3);
  const KinematicsTable t = MakeKinematicsTable(m, ab.theta);
  const Eigen::MatrixXd sie = s.ToolPoints(m, s.Map(m, t, kRecord1), q, kRecord1);
  EXPECT_LT(MaxNorm(sie - InTableFrame(t, ToolPoints(m, ab.theta, q))), 1e-9);
}

TEST(VendorSiemens, TheWayBackGivesTheTable) {
  const SiemensVendor s;
  for (const Case& c : Cases()) {
    const Machine& m = c.m;
    const Eigen::MatrixXd q = Poses(m, 60);
    AbsorbOptions ao;
    ao.directions = true;
    ao.tool_length = false;
    const Absorption ab = Absorb(m, s.Model(m, kRecord1).model, RandomPivotErrors(m, s.Model(m, kRecord1).model, 11), q, ao);
    const KinematicsTable t = MakeKinematicsTable(m, ab.theta);
    const KinematicsTable back = s.Table(m, s.Map(m, t, kRecord1), kRecord1);
    ASSERT_EQ(back.axes.size(), t.axes.size()) << c.name;
    for (size_t k = 0; k < t.axes.size(); ++k) {
      EXPECT_EQ(back.axes[k].axis, t.axes[k].axis);
      EXPECT_LT((back.axes[k].direction - t.axes[k].direction).norm(), 1e-12) << c.name << " " << t.axes[k].axis;
      // a point anywhere on the same line
      const Eigen::Vector3d d = back.axes[k].point - t.axes[k].point;
      EXPECT_LT((d - d.dot(t.axes[k].direction) * t.axes[k].direction).norm(), 1e-12) << c.name << " " << t.axes[k].axis;
    }
    EXPECT_LT((back.tool_tip - t.tool_tip).norm(), 1e-12) << c.name;
    // the part frame is the work offset's, not the record's
    EXPECT_LT(back.part_origin.norm(), 1e-15);
    EXPECT_LT((back.part_rotation - Eigen::Matrix3d::Identity()).norm(), 1e-15);
    // a table without a part frame comes back whole
    KinematicsTable reset = t;
    reset.part_origin.setZero();
    reset.part_rotation.setIdentity();
    const Eigen::VectorXd v = s.Map(m, reset, kRecord1);
    EXPECT_LT((s.Map(m, s.Table(m, v, kRecord1), kRecord1) - v).norm(), 1e-12) << c.name;
  }
}

TEST(VendorSiemens, ItsTransformationAndTheNeutralTablesAgreeOnAnyRecord) {
  // Records that do not close their vector chains (as a controller may hold
  // them): the record's chain and the table's screws are two implementations.
  const SiemensVendor s;
  std::mt19937 rng(17);
  std::normal_distribution<double> mm(0, 80), unit(0, 1);
  for (const Case& c : Cases()) {
    const Machine& m = c.m;
    Eigen::VectorXd v = s.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), kRecord1);
    // offsets by tens of mm, axis vectors tilted by ~0.1 (the last 6 before the type)
    const Eigen::Index nv = v.size();
    for (Eigen::Index i = 0; i < nv - 7; ++i) v[i] += mm(rng);
    for (Eigen::Index i = nv - 7; i < nv - 1; ++i) v[i] += 0.1 * unit(rng);
    const Eigen::MatrixXd q = Poses(m, 50, 23);
    const KinematicsTable t = s.Table(m, v, kRecord1);
    EXPECT_LT(MaxNorm(s.ToolPoints(m, v, q, kRecord1) - TableToolPoints(t, TableQ(m, t, q))), 1e-9) << c.name;
  }
}

TEST(VendorSiemens, TheNominalRecordIsTheMachineFile) {
  const SiemensVendor s;
  const Machine hu = Example("hu40t");  // B (0,-1,0) at (0,0,-120) carrying C (0,0,-1) at 0
  const Eigen::VectorXd v = s.Map(hu, MakeKinematicsTable(hu, Eigen::VectorXd::Zero(hu.num_parameters())), kRecord1);
  Eigen::VectorXd want(16);
  want << 0, 0, -120, 0, 0, 120, 0, 0, 0, 0, -1, 0, 0, 0, -1, 'P';
  EXPECT_LT((v - want).norm(), 1e-12) << v.transpose();
  const std::vector<VendorValue> names = s.Values(hu, {{"record", "3"}});
  ASSERT_EQ(names.size(), 16u);
  EXPECT_EQ(names[0].name, "$TC_CARR4[3]");
  EXPECT_EQ(names[3].name, "$TC_CARR15[3]");
  EXPECT_EQ(names[6].name, "$TC_CARR18[3]");
  EXPECT_EQ(names[9].name, "$TC_CARR7[3]");
  EXPECT_EQ(names[14].name, "$TC_CARR12[3]");
  EXPECT_EQ(names[15].name, "$TC_CARR23[3]");
  EXPECT_TRUE(names[15].fixed);
  EXPECT_EQ(names[0].unit, "mm");
  EXPECT_NE(names[0].source.find("p. 568"), std::string::npos);
  const Eigen::MatrixXd q = Poses(hu, 30);
  EXPECT_LT(MaxNorm(s.ToolPoints(hu, v, q, kRecord1) - ToolPoints(hu, Eigen::VectorXd::Zero(hu.num_parameters()), q)),
            1e-9);

  const Machine hh = HeadHead();  // C at (0,0,300) carrying B at (4,0,310), tip (0,0,50)
  const Eigen::VectorXd h = s.Map(hh, MakeKinematicsTable(hh, Eigen::VectorXd::Zero(hh.num_parameters())), kRecord1);
  Eigen::VectorXd hwant(16);
  // I1 = -p1, I2 = p1 - p2, I3 = p2 (adapter at the origin), V1, V2
  hwant << 0, 0, -300, -4, 0, -10, 4, 0, 310, 0, 0, 1, 0, -1, 0, 'T';
  EXPECT_LT((h - hwant).norm(), 1e-12) << h.transpose();
  const std::vector<VendorValue> hn = s.Values(hh, kRecord1);
  EXPECT_EQ(hn[0].name, "$TC_CARR1[1]");
  EXPECT_EQ(hn[6].name, "$TC_CARR15[1]");
  EXPECT_EQ(s.Values(TableHead(), kRecord1).size(), 19u);
}

TEST(VendorSiemens, TheCommonExportPathRoundTripsAndPropagatesTheCovariance) {
  const ControllerVendor& s = FindVendor("siemens");
  EXPECT_EQ(s.Name(), "siemens");
  for (const Case& c : Cases()) {
    const Machine& m = c.m;
    const Eigen::MatrixXd q = Poses(m, 80);
    const Eigen::VectorXd truth = RandomPivotErrors(m, s.Model(m, kRecord1).model, 29);
    // an identification's covariance: 5 um / 5 urad on every location parameter
    Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(m.num_parameters(), m.num_parameters());
    for (int k = 0; k < m.num_axes(); ++k)
      for (int j = 0; j < 6; ++j) cov(m.location_index(k, j), m.location_index(k, j)) = j < 3 ? 2.5e-5 : 2.5e-11;
    const VendorExport ex = ExportToVendor(m, s, truth, cov, q, kRecord1);
    EXPECT_LT(ex.round_trip_max, 1e-9) << c.name;
    EXPECT_LT(ex.absorption.max, 1e-9) << c.name;
    for (size_t i = 0; i < ex.values.size(); ++i) {
      const Eigen::Index j = Eigen::Index(i);
      if (ex.values[i].fixed) {
        EXPECT_EQ(ex.sigma[j], 0.0);
        continue;
      }
      EXPECT_TRUE(std::isfinite(ex.sigma[j])) << c.name << " " << ex.values[i].name;
      // sizes: a pivot known to 5 um gives offsets known to some um, not mm
      EXPECT_LT(ex.sigma[j], ex.values[i].unit == "mm" ? 0.05 : 1e-3) << c.name << " " << ex.values[i].name;
    }
    // the new record, through the controller's own transformation, is the
    // erroneous machine up to the work offset
    const KinematicsTable t = MakeKinematicsTable(m, ex.absorption.theta);
    Eigen::MatrixXd truth_points = ToolPoints(m, truth, q);
    truth_points.rowwise() -= ex.absorption.workpiece_shift.transpose();
    EXPECT_LT(MaxNorm(s.ToolPoints(m, ex.new_values, q, kRecord1) - InTableFrame(t, truth_points)), 1e-8) << c.name;
    // and what a controller running it does comes back as the same errors
    const Absorption back = VendorToTheta(m, s, ex.new_values, q, kRecord1);
    EXPECT_LT(back.max, 1e-8) << c.name;
  }
}

void ExpectThrow(const std::function<void()>& f, const std::string& text) {
  try {
    f();
    ADD_FAILURE() << "no exception, expected: " << text;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
  }
}

TEST(VendorSiemens, Refusals) {
  const SiemensVendor s;
  const Machine hu = Example("hu40t");
  // the record number is not guessed
  ExpectThrow([&] { s.Values(hu, {}); }, "option record");
  ExpectThrow([&] { s.Values(hu, {{"record", "0"}}); }, "not a swivel data record number");
  ExpectThrow([&] { s.Values(hu, {{"record", "1x"}}); }, "not a swivel data record number");
  ExpectThrow([&] { s.Model(hu, {{"record", "1"}, {"sign", "+"}}); }, "option 'sign'");
  ExpectThrow([&] { s.Map(hu, MakeKinematicsTable(hu, Eigen::VectorXd::Zero(hu.num_parameters())), {{"recrod", "1"}}); },
              "option 'recrod'");
  // topologies without a two-axis record
  const Machine one = Machine::FromJson(R"({"name": "4ax", "topology": "wCfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]}, "X": {"type": "linear", "direction": [1,0,0]},
    "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})");
  ExpectThrow([&] { s.Model(one, kRecord1); }, "has 1 rotary axes");
  const Machine carried = Machine::FromJson(R"({"name": "xc", "topology": "wCXBfYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]}, "X": {"type": "linear", "direction": [-1,0,0]},
    "B": {"type": "rotary", "direction": [0,-1,0]},
    "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})");
  ExpectThrow([&] { s.Model(carried, kRecord1); }, "linear axis X is carried by a rotary axis");
  const Machine lefty = Machine::FromJson(R"({"name": "lx", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]}, "A": {"type": "rotary", "direction": [-1,0,0]},
    "X": {"type": "linear", "direction": [-1,0,0]},
    "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})");
  ExpectThrow([&] { s.Values(lefty, kRecord1); }, "a positive X moves the tool relative to the part along (-1");
  // values that are not this machine's record
  Eigen::VectorXd v = s.Map(hu, MakeKinematicsTable(hu, Eigen::VectorXd::Zero(hu.num_parameters())), kRecord1);
  const Eigen::MatrixXd q = Poses(hu, 3);
  Eigen::VectorXd t = v;
  t[15] = 'T';
  ExpectThrow([&] { s.ToolPoints(hu, t, q, kRecord1); }, "kinematics type 'T' is not the machine's 'P'");
  t[15] = 1e300;  // not a character code: said as the number it is
  ExpectThrow([&] { s.ToolPoints(hu, t, q, kRecord1); }, "kinematics type '1000000");
  Eigen::VectorXd z = v;
  z.segment<3>(9).setZero();
  ExpectThrow([&] { s.Table(hu, z, kRecord1); }, "V1 ($TC_CARR7..9): a zero vector");
  ExpectThrow([&] { s.ToolPoints(hu, v.head(15), q, kRecord1); }, "15 values, a type P record has 16");
  // a table whose tool moved has no swivel table record
  KinematicsTable moved = MakeKinematicsTable(hu, Eigen::VectorXd::Zero(hu.num_parameters()));
  moved.tool_tip.z() += 0.01;
  ExpectThrow([&] { s.Map(hu, moved, kRecord1); }, "carries no tool offset");
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
