// The Heidenhain kinematics description export: the manual's reading of the
// rows (its printed example, ISO senses), the round trip fivecal errors ->
// absorbed model -> rows -> the rows' own kinematics == the absorbed model's
// tool points on every topology, the way back, the nominal rows, refusals.
#include <gtest/gtest.h>

#include <random>

#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/heidenhain.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {
namespace {

// A message contains a phrase (gmock is not a dependency).
#define EXPECT_HAS(text, phrase)                                                      \
  do {                                                                                 \
    const std::string t_ = (text);                                                     \
    EXPECT_NE(t_.find(phrase), std::string::npos) << "\"" << t_ << "\" lacks: " << (phrase); \
  } while (0)

std::string Src(const std::string& rel) { return std::string(FIVECAL_SOURCE_DIR) + "/" + rel; }

Machine HeadHead() {  // B on C in the spindle head
  return Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [5,0,300]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,50]}})");
}

Machine TableHead() {  // C table, B head (the manual's p. 670 kind of machine)
  return Machine::FromJson(R"({"name": "th", "topology": "wCfXYZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1], "point": [-298.9,200.2,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [0,0,250]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,20]}})");
}

Machine SpindleAlongY() {  // a horizontal spindle along +Y (ToolAxis Y), B and A table
  return Machine::FromJson(R"({"name": "hy", "topology": "wABfXYZSt", "axes": {
    "A": {"type": "rotary", "direction": [-1,0,0], "point": [0,0,-80]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [10,0,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,1,0]}}, "tool": {"tip": [0,150,0]}})");
}

Machine FourAxis() {
  return Machine::FromJson(R"({"name": "4ax", "topology": "wCfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})");
}

VendorOptions Iso(double L = 100) { return {{"table-axis-sign", "iso"}, {"tool-length", std::to_string(L)}}; }

// A pose grid spanning the working volume: every rotary axis over its range,
// linear axes across +-200 mm.
Eigen::MatrixXd Grid(const Machine& m, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-200, 200), tilt(-110, 110), rot(-180, 180);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < m.num_axes(); ++k) {
      const char a = m.axis(k).name;
      q(i, k) = a == 'S' ? 0.0 : a == 'C' ? rot(rng) : (a == 'A' || a == 'B') ? tilt(rng) : lin(rng);
    }
  return q;
}

// Random errors the controller's model represents and some it does not:
// pivot offsets (tens of um), tilts (tens of urad), the tool length.
Eigen::VectorXd RandomErrors(const Machine& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> um(0, 0.03), urad(0, 3e-5);
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (int k = 0; k < m.num_axes(); ++k) {
    if (!m.axis(k).rotary() || m.axis(k).name == 'S') continue;
    for (int c = 0; c < 3; ++c) th[m.location_index(k, c)] = um(rng);
    for (int c = 3; c < 6; ++c) th[m.location_index(k, c)] = urad(rng);
  }
  th[m.tip_index() + 2] = um(rng);
  return th;
}

void ExpectTablesEqual(const KinematicsTable& a, const KinematicsTable& b, double tol) {
  ASSERT_EQ(a.axes.size(), b.axes.size());
  for (size_t r = 0; r < a.axes.size(); ++r) {
    SCOPED_TRACE(std::string("axis ") + a.axes[r].axis);
    EXPECT_EQ(a.axes[r].axis, b.axes[r].axis);
    EXPECT_EQ(a.axes[r].tool_chain, b.axes[r].tool_chain);
    EXPECT_EQ(a.axes[r].rotary, b.axes[r].rotary);
    EXPECT_LT((a.axes[r].direction - b.axes[r].direction).norm(), tol);
    EXPECT_LT((a.axes[r].point - b.axes[r].point).norm(), tol);
  }
  EXPECT_LT((a.tool_tip - b.tool_tip).norm(), tol);
  EXPECT_LT((a.tool_axis - b.tool_axis).norm(), tol);
}

// (a) The manual's own table (iTNC 530 HSCI technical manual, July 2013,
// p. 670): the rows place the B pivot 250.051 mm above the tool reference
// point (0.016 in X) and the C axis at X -298.923, Y 200.172 from it. The
// manual prints no tool point; what the rows give under the manual's reading
// is checked: the tool reference point seen from the C table at the zero
// pose, +B turning the tool right-handed about +Y (ISO 841), and +C
// (table-axis-sign=iso) turning the tool about +Z relative to the part.
TEST(VendorHeidenhain, ManualExampleTable) {
  std::vector<HeidenhainRow> rows;
  const auto row = [&](const std::string& key, char axis, bool tool_side) {
    rows.push_back(HeidenhainRow{key, axis, key == "Trans", false, tool_side, ""});
  };
  row("Trans", 'X', true);
  row("Trans", 'Z', true);
  row("MachAxis", 'B', true);
  row("MachAxis", 'Y', true);
  row("MachAxis", 'X', true);
  row("MachBase", 0, false);
  row("MachAxis", 'Z', false);
  row("Trans", 'X', false);
  row("Trans", 'Y', false);
  row("MachAxis", 'C', false);
  Eigen::VectorXd coord = Eigen::VectorXd::Zero(10);
  coord << 0.016, 250.051, 0, 0, 0, 0, 0, -298.923, 200.172, 0;
  const auto at = [&](double b, double c, double x = 0, double L = 0) {
    return HeidenhainToolPoint(rows, coord, {{'B', b}, {'C', c}, {'X', x}, {'Y', 0}, {'Z', 0}}, L, 'Z', 1);
  };
  // Zero pose: the tool reference point relative to the C axis.
  EXPECT_LT((at(0, 0) - Eigen::Vector3d(298.907, -200.172, -250.051)).norm(), 1e-12);
  // B = +90: the tool reference point, at (-0.016, 0, -250.051) from the
  // pivot, swings to (-250.051, 0, 0.016) of it (Rot_y(+90) (0,0,-1) = (-1,0,0)).
  EXPECT_LT((at(90, 0) - at(0, 0) - Eigen::Vector3d(-250.051 + 0.016, 0, 250.051 + 0.016)).norm(), 1e-9);
  // A 100 mm tool: its tip 100 mm below the reference point at B = 0, 100 mm
  // towards -X at B = +90.
  EXPECT_LT((at(0, 0, 0, 100) - at(0, 0) - Eigen::Vector3d(0, 0, -100)).norm(), 1e-9);
  EXPECT_LT((at(90, 0, 0, 100) - at(90, 0) - Eigen::Vector3d(-100, 0, 0)).norm(), 1e-9);
  // X = +10 (an axis before MachBase): the tool moves +10 in X.
  EXPECT_LT((at(0, 0, 10) - at(0, 0) - Eigen::Vector3d(10, 0, 0)).norm(), 1e-12);
  // C = +90, iso: the tool point turns +90 about +Z around the C axis.
  const Eigen::Vector3d p0 = at(0, 0), p90 = at(0, 90);
  EXPECT_LT((p90 - Eigen::Vector3d(-p0.y(), p0.x(), p0.z())).norm(), 1e-9);
  // carriage: the other way round.
  const Eigen::Vector3d pc = HeidenhainToolPoint(rows, coord, {{'B', 0}, {'C', 90}, {'X', 0}, {'Y', 0}, {'Z', 0}},
                                                 0, 'Z', -1);
  EXPECT_LT((pc - Eigen::Vector3d(p0.y(), -p0.x(), p0.z())).norm(), 1e-9);
}

struct Case {
  std::string name;
  Machine machine;
  ControllerModel model;
};

std::vector<Case> Cases() {
  return {{"hu40t", Machine::Load(Src("examples/machines/hu40t.json")), ControllerModel::kTableTable},
          {"c600u", Machine::Load(Src("examples/machines/c600u.json")), ControllerModel::kTableTable},
          {"kx8", Machine::Load(Src("examples/machines/kx8.json")), ControllerModel::kTableTable},
          {"vmc0656", Machine::Load(Src("examples/machines/vmc0656.json")), ControllerModel::kTableTable},
          {"head-head", HeadHead(), ControllerModel::kHeadHead},
          {"table-head", TableHead(), ControllerModel::kTableHead},
          {"spindle along +Y", SpindleAlongY(), ControllerModel::kTableTable}};
}

// (b) The round trip: random errors -> Absorb into the model the rows can
// represent -> neutral table -> rows -> the rows' own kinematics over a pose
// grid == the absorbed model's tool points, in both table senses.
TEST(VendorHeidenhain, RoundTripEveryTopology) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  for (const Case& c : Cases()) {
    for (const std::string sense : {"iso", "carriage"}) {
      SCOPED_TRACE(c.name + " " + sense);
      const VendorOptions o = {{"table-axis-sign", sense}, {"tool-length", "87.5"}};
      const VendorModel vm = h.Model(c.machine, o);
      EXPECT_EQ(vm.model, c.model);
      for (unsigned seed : {1u, 2u, 3u}) {
        const Eigen::VectorXd th = RandomErrors(c.machine, seed);
        const Eigen::MatrixXd q = Grid(c.machine, 60, seed + 10);
        AbsorbOptions ao;
        ao.directions = vm.directions;
        ao.tool_length = vm.tool_length;
        const Absorption ab = Absorb(c.machine, vm.model, th, q, ao);
        const Eigen::VectorXd values = h.Map(c.machine, MakeKinematicsTable(c.machine, ab.theta), o);
        ASSERT_EQ(values.size(), Eigen::Index(h.Values(c.machine, o).size()));
        const Eigen::MatrixXd mine = h.ToolPoints(c.machine, values, q, o);
        // fivecal's tool points in the controller's workpiece frame (vendor.h).
        const KinematicsTable at = MakeKinematicsTable(c.machine, ab.theta);
        const Eigen::MatrixXd theirs = Eigen::MatrixXd(
            (ToolPoints(c.machine, ab.theta, q) * at.part_rotation.transpose()).rowwise() + at.part_origin.transpose());
        EXPECT_LT((mine - theirs).rowwise().norm().maxCoeff(), 1e-9);
        // The errors the rows represent did change the tool points.
        const Eigen::MatrixXd nominal = ToolPoints(c.machine, Eigen::VectorXd::Zero(c.machine.num_parameters()), q);
        EXPECT_GT((theirs - nominal).rowwise().norm().maxCoeff(), 1e-3);
      }
    }
  }
}

// The common export path with the registered vendor: the round trip it
// reports, a change where the errors are, its covariance, the old values.
TEST(VendorHeidenhain, ExportThroughTheRegistry) {
  const ControllerVendor& v = FindVendor("heidenhain");
  EXPECT_EQ(&v, &HeidenhainVendor::Instance());
  const Machine m = Machine::Load(Src("examples/machines/c600u.json"));
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  th[m.RequireParameter("EY0A")] = 0.02;   // A's pivot 20 um in y
  th[m.RequireParameter("EX0C")] = -0.015;  // C's 15 um in x
  const Eigen::MatrixXd cov = 1e-6 * Eigen::MatrixXd::Identity(m.num_parameters(), m.num_parameters());
  const VendorExport ex = ExportToVendor(m, v, th, cov, Grid(m, 50, 9), Iso(100));
  EXPECT_LT(ex.round_trip_max, 1e-9);
  EXPECT_LT(ex.absorption.max, 1e-6);
  ASSERT_EQ(ex.values.size(), size_t(ex.change.size()));
  double moved = 0;
  for (size_t i = 0; i < ex.values.size(); ++i) {
    EXPECT_TRUE(std::isfinite(ex.sigma[Eigen::Index(i)])) << ex.values[i].name;
    if (ex.values[i].fixed) EXPECT_EQ(ex.sigma[Eigen::Index(i)], 0) << ex.values[i].name;
    moved = std::max(moved, std::abs(ex.change[Eigen::Index(i)]));
  }
  EXPECT_NEAR(moved, 0.02, 1e-6);
  // Old values given: new = old + change, and a fixed row that differs is refused.
  Eigen::VectorXd old = ex.old_values;
  old[6] += 0.5;  // row 6 Trans X (to the machine datum)
  const VendorExport ex2 = ExportToVendor(m, v, th, cov, Grid(m, 50, 9), Iso(100), old);
  EXPECT_LT((ex2.new_values - old - ex.change).norm(), 1e-12);
  Eigen::VectorXd bad = ex.old_values;
  bad[0] = 1;  // row 0 ToolAxis
  EXPECT_THROW(ExportToVendor(m, v, th, cov, Grid(m, 50, 9), Iso(100), bad), std::invalid_argument);
}

// (c) The way back: Table(Map(t)) == t.
TEST(VendorHeidenhain, TableOfMapIsTheTable) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  for (const Case& c : Cases()) {
    for (const std::string sense : {"iso", "carriage"}) {
      SCOPED_TRACE(c.name + " " + sense);
      const VendorOptions o = {{"table-axis-sign", sense}, {"tool-length", "42"}};
      const VendorModel vm = h.Model(c.machine, o);
      AbsorbOptions ao;
      ao.directions = true;
      const Absorption ab = Absorb(c.machine, vm.model, RandomErrors(c.machine, 7), Grid(c.machine, 40, 5), ao);
      const KinematicsTable t = MakeKinematicsTable(c.machine, ab.theta);
      const KinematicsTable back = h.Table(c.machine, h.Map(c.machine, t, o), o);
      ExpectTablesEqual(back, t, 1e-9);
      // The rows end in the machine frame: the part's frame is the preset's.
      EXPECT_EQ(back.part_origin, Eigen::Vector3d::Zero());
      EXPECT_EQ(back.part_rotation, Eigen::Matrix3d::Identity());
      const KinematicsTable n = MakeKinematicsTable(c.machine, Eigen::VectorXd::Zero(c.machine.num_parameters()));
      ExpectTablesEqual(h.Table(c.machine, h.Map(c.machine, n, o), o), n, 1e-12);
    }
  }
}

double ValueOf(const std::vector<VendorValue>& names, const Eigen::VectorXd& v, const std::string& name) {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i].name == name) return v[Eigen::Index(i)];
  ADD_FAILURE() << "no value " << name;
  return NAN;
}

// (d) The nominal machine: hu40t's rows are its machine file's geometry.
TEST(VendorHeidenhain, NominalRowsAreTheMachineFile) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  const Machine m = Machine::Load(Src("examples/machines/hu40t.json"));  // wCBXfZYSt, B at (0,0,-120), tip z 100
  const VendorOptions o = Iso(100);
  const std::vector<VendorValue> names = h.Values(m, o);
  const Eigen::VectorXd v = h.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  std::vector<std::string> got;
  for (const VendorValue& n : names) got.push_back(n.name);
  const std::vector<std::string> want = {
      "row 0 ToolAxis Z", "row 1 Trans B", "row 2 Trans A", "row 3 MachAxis Y", "row 4 MachAxis Z",
      "row 5 Trans X", "row 6 Trans Y", "row 7 Trans Z", "row 8 MachBase", "row 9 MachAxis X",
      "row 10 Trans X", "row 11 Trans Y", "row 12 Trans Z", "row 13 Trans C", "row 14 Trans A",
      "row 15 MachAxis B", "row 16 Trans A", "row 17 Trans C",
      "row 18 Trans X", "row 19 Trans Y", "row 20 Trans Z", "row 21 Trans A", "row 22 Trans B",
      "row 23 MachAxis C", "row 24 Trans B", "row 25 Trans A",
      "row 26 Trans X", "row 27 Trans Y", "row 28 Trans Z"};
  EXPECT_EQ(got, want);
  // The tool reference point is 100 mm above the tip (0,0,100): the datum row goes back down.
  EXPECT_NEAR(ValueOf(names, v, "row 7 Trans Z"), -200, 1e-12);
  // B's pivot as the file states it, C's relative to B's.
  EXPECT_NEAR(ValueOf(names, v, "row 12 Trans Z"), -120, 1e-12);
  EXPECT_NEAR(ValueOf(names, v, "row 20 Trans Z"), 120, 1e-12);
  // iso: B along -y and C along -z are the table's reversed +B, +C: no turn.
  for (const char* r : {"row 13 Trans C", "row 14 Trans A", "row 21 Trans A", "row 22 Trans B"})
    EXPECT_NEAR(ValueOf(names, v, r), 0, 1e-12) << r;
  // The last rows go back from C's pivot (0,0,0) to the machine datum.
  EXPECT_NEAR(ValueOf(names, v, "row 28 Trans Z"), 0, 1e-12);
  EXPECT_EQ(names[15].unit, "");
  EXPECT_TRUE(names[15].fixed);
  EXPECT_EQ(names[13].unit, "deg");
  EXPECT_EQ(names[10].unit, "mm");
  EXPECT_HAS(names[10].source, "p. 722");
  EXPECT_HAS(names[10].source, "Cycle 451");
  // carriage: the table's B and C are the carriage's, turned half a turn.
  const VendorOptions oc = {{"table-axis-sign", "carriage"}, {"tool-length", "100"}};
  const Eigen::VectorXd vc = h.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), oc);
  const std::vector<VendorValue> nc = h.Values(m, oc);
  // (X, along -x, is reversed there too: two more rows before B's.)
  EXPECT_EQ(nc[9].name, "row 9 Trans B");
  EXPECT_TRUE(nc[9].fixed);
  EXPECT_NEAR(vc[9], 180, 0);
  EXPECT_EQ(nc[17].name, "row 17 MachAxis B");
  EXPECT_NEAR(std::abs(vc[15]), 180, 1e-12);
  // kx8's nutating A (45 deg between X and -Z): a 45 degree turn about B.
  const Machine kx8 = Machine::Load(Src("examples/machines/kx8.json"));
  const std::vector<VendorValue> nk = h.Values(kx8, o);
  const Eigen::VectorXd vk = h.Map(kx8, MakeKinematicsTable(kx8, Eigen::VectorXd::Zero(kx8.num_parameters())), o);
  double turn = NAN;
  for (size_t i = 0; i + 2 < nk.size(); ++i)
    if (nk[i + 2].name.find("MachAxis A") != std::string::npos) turn = vk[Eigen::Index(i)];
  EXPECT_NEAR(turn, 45, 1e-9);
}

// A 180 degree row does not jump by 360 with the sign of a small error, so
// that the change of a value is the small change.
TEST(VendorHeidenhain, HalfTurnRowsChangeByTheSmallError) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  const Machine m = Machine::Load(Src("examples/machines/hu40t.json"));
  const VendorOptions o = {{"table-axis-sign", "carriage"}, {"tool-length", "100"}};
  const Eigen::VectorXd n = h.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  for (double e : {-2e-5, 2e-5}) {
    Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
    th[m.RequireParameter("EC0B")] = e;
    th[m.RequireParameter("EA0B")] = -e;
    const Eigen::VectorXd v = h.Map(m, MakeKinematicsTable(m, th), o);
    EXPECT_LT((v - n).cwiseAbs().maxCoeff(), 0.01);
  }
}

// A wrong convention is not silently the same: the rows written for iso and
// run as carriage put the tool elsewhere (the verification recipe sees it).
TEST(VendorHeidenhain, WrongSenseMovesTheTool) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  const Machine m = Machine::Load(Src("examples/machines/vmc0656.json"));
  const Eigen::VectorXd v = h.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), Iso());
  const Eigen::MatrixXd q = Grid(m, 20, 4);
  const Eigen::MatrixXd a = h.ToolPoints(m, v, q, Iso());
  const Eigen::MatrixXd b = h.ToolPoints(m, v, q, {{"table-axis-sign", "carriage"}, {"tool-length", "100"}});
  EXPECT_GT((a - b).rowwise().norm().maxCoeff(), 10);
}

template <class F>
std::string ErrorOf(F f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(no error)";
}

// (e) Refusals.
TEST(VendorHeidenhain, Refusals) {
  const HeidenhainVendor& h = HeidenhainVendor::Instance();
  const Machine m = Machine::Load(Src("examples/machines/c600u.json"));
  const KinematicsTable t = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
  EXPECT_HAS(ErrorOf([&] { h.Model(FourAxis(), Iso()); }), "two rotary axes");
  EXPECT_HAS(ErrorOf([&] { h.Values(FourAxis(), Iso()); }), "has 1");
  EXPECT_HAS(ErrorOf([&] { h.Map(m, t, {{"tool-length", "100"}}); }), "--set table-axis-sign=iso");
  EXPECT_HAS(ErrorOf([&] { h.Values(m, {{"tool-length", "100"}}); }), "table-axis-sign");
  EXPECT_HAS(ErrorOf([&] { h.Map(m, t, {{"table-axis-sign", "iso"}}); }), "--set tool-length=<mm>");
  EXPECT_HAS(ErrorOf([&] { h.Map(m, t, {{"table-axis-sign", "iso"}, {"tool-length", "1OO"}}); }), "option tool-length: expected a length in mm, got \"1OO\"");
  EXPECT_HAS(ErrorOf([&] { h.Map(m, t, {{"table-axis-sign", "ISO"}, {"tool-length", "100"}}); }), "expected iso or carriage, got \"ISO\"");
  VendorOptions unknown = Iso();
  unknown["tool-lenght"] = "100";
  EXPECT_HAS(ErrorOf([&] { h.Map(m, t, unknown); }), "unknown option \"tool-lenght\"");
  // A machine with every axis on the tool side: the sense is not asked for.
  const Machine all_tool = Machine::FromJson(R"({"name": "ht", "topology": "wfXYZCBSt", "axes": {
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]}, "C": {"type": "rotary", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,1,0]}, "S": {"type": "rotary", "direction": [0,0,1]}},
    "tool": {"tip": [0,0,50]}})");
  EXPECT_NO_THROW(h.Values(all_tool, {{"tool-length", "100"}}));
  // A tool axis the ToolAxis row cannot name.
  const Machine down = Machine::FromJson(R"({"name": "dn", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1]}, "A": {"type": "rotary", "direction": [-1,0,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]}, "S": {"type": "rotary", "direction": [0,0,-1]}},
    "tool": {"tip": [0,0,-100]}})");
  EXPECT_HAS(ErrorOf([&] { h.Model(down, Iso()); }), "is not +X, +Y or +Z");
  // A table of another machine, wrong value counts, a tilted linear axis.
  const Machine hu = Machine::Load(Src("examples/machines/hu40t.json"));
  EXPECT_HAS(ErrorOf([&] { h.Map(m, MakeKinematicsTable(hu, Eigen::VectorXd::Zero(hu.num_parameters())), Iso()); }), "kinematics table row");
  EXPECT_HAS(ErrorOf([&] { h.ToolPoints(m, Eigen::VectorXd::Zero(3), Grid(m, 2, 1), Iso()); }), "3 values");
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  th[m.RequireParameter("EB0X")] = 1e-3;
  EXPECT_HAS(ErrorOf([&] { h.Map(m, MakeKinematicsTable(m, th), Iso()); }), "is tilted");
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
