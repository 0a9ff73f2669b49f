// FANUC tool centre point parameters: the transformation written from the
// manual reproduces fivecal's absorbed tool points on every topology the
// controller has (table, tool and mixed rotation types), the values go back
// to the table they came from, the nominal machines give their own
// geometry, and what the manual does not decide is refused.
#include <gtest/gtest.h>

#include <random>

#include "fivecal/controllers/absorb.h"
#include "fivecal/controllers/fanuc.h"
#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {
namespace {

Machine Example(const std::string& name) {
  return Machine::Load(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/" + name + ".json");
}

Machine HeadHead() {  // C carries B in the spindle head; B 40 mm off the C axis, spindle 15 mm off B
  return Machine::FromJson(R"({"name": "hh", "topology": "wXYfZCBSt", "axes": {
    "X": {"type": "linear", "direction": [-1,0,0]}, "Y": {"type": "linear", "direction": [0,-1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [40,0,260]},
    "S": {"type": "rotary", "direction": [0,0,1], "point": [15,0,0]}}, "tool": {"tip": [15,0,60]}})");
}

Machine TableHead() {  // B tilts the head, C turns the table
  return Machine::FromJson(R"({"name": "th", "topology": "wCXYfZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1], "point": [30,-20,0]},
    "X": {"type": "linear", "direction": [-1,0,0]}, "Y": {"type": "linear", "direction": [0,-1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,350]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,120]}})");
}

VendorOptions Options(const std::string& axis_order) {
  return {{"increment", "IS-C"}, {"tool-length", "100"}, {"holder-offset", "5"}, {"axis-order", axis_order}};
}

Eigen::MatrixXd Poses(const Machine& m, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-300, 300), tilt(-110, 110), rot(-180, 180);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < m.num_axes(); ++k) {
      const char a = m.axis(k).name;
      q(i, k) = a == 'S' ? 0.0 : a == 'C' ? rot(rng) : (a == 'A' || a == 'B') ? tilt(rng) : lin(rng);
    }
  return q;
}

// Tens of µm and tens of µrad on every location error and the tip.
Eigen::VectorXd RandomErrors(const Machine& m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> mm(0, 0.03), rad(0, 3e-5);
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (const std::string& p : m.parameter_names()) {
    const bool location = p.size() == 4 && p[0] == 'E' && p[2] == '0';
    if (location && std::string("XYZ").find(p[1]) != std::string::npos) th[m.RequireParameter(p)] = mm(rng);
    if (location && std::string("ABC").find(p[1]) != std::string::npos) th[m.RequireParameter(p)] = rad(rng);
    if (p.rfind("tip.", 0) == 0) th[m.RequireParameter(p)] = mm(rng);
  }
  return th;
}

// max |a - b - c| over the rows, c the mean difference (the work offset).
double MaxUpToOffset(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const Eigen::MatrixXd d = a - b;
  const Eigen::RowVector3d c = d.colwise().mean();
  return (d.rowwise() - c).rowwise().norm().maxCoeff();
}

struct Case {
  Machine m;
  std::string axis_order;
  ControllerModel model;
};

std::vector<Case> Cases() {
  return {{Example("c600u"), "XYZAC", ControllerModel::kTableTable},
          {Example("vmc0656"), "XYZAC", ControllerModel::kTableTable},
          {Example("hu40t"), "XYZBC", ControllerModel::kTableTable},
          {HeadHead(), "XYZCB", ControllerModel::kHeadHead},
          {TableHead(), "XYZBC", ControllerModel::kTableHead}};
}

// The manual's conventions on a hand-worked table rotation type: No. 19684
// = 1 turns the carriage left-handed about the axis of No. 19682 ("clockwise
// as viewed from the negative to positive direction ... (right-hand thread
// rotation)" is 0, sheet 75/88); the rotary table position runs from the
// machine origin to point A (sheet 59/88). The manual prints no numeric
// example; this one is worked by hand.
TEST(VendorFanuc, ManualConventionsByHand) {
  const Machine m = Example("c600u");  // A along -x carries C along -z, both pivots at 0, tip at z 150
  const FanucVendor f;
  const VendorOptions o = Options("XYZAC");
  //                 19680 19681 19682 19684 19686 19687 19689  rotary table position  19703-05
  Eigen::VectorXd values(13);
  values << 12, 4, 1, 1, 5, 3, 1, 0, 0, -300, 0, 0, 0;
  EXPECT_THROW(f.ToolPoints(m, values.head(12), Eigen::MatrixXd::Zero(1, 6), o), std::invalid_argument);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(1, m.num_axes());
  q(0, m.AxisIndex('A')) = 90;
  // Controlled point at the machine origin, tool tip L = 100 below it:
  // T = (0, 0, -100); A turns left-handed about +x, so the table frame sees
  // Rx(+90) (T - A) + A = Rx(90) (0, 0, 200) + (0, 0, -300) = (0, -200, -300);
  // fivecal's frame puts the machine origin at tip + L k = (0, 0, 250).
  const Eigen::MatrixXd p = f.ToolPoints(m, values, q, o);
  EXPECT_NEAR(p(0, 0), 0, 1e-12);
  EXPECT_NEAR(p(0, 1), -200, 1e-12);
  EXPECT_NEAR(p(0, 2), -50, 1e-12);
  // fivecal's machine with A at z = 0: the table at A 90 puts the tool, 150 above the pivot, at y = -150.
  const Eigen::MatrixXd p0 = ToolPoints(m, Eigen::VectorXd::Zero(m.num_parameters()), q);
  EXPECT_NEAR(p0(0, 1), -150, 1e-9);
  // The same machine's own values: rotary table position (0, 0, -250) puts A at z = 0.
  const Eigen::VectorXd nominal = f.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
  EXPECT_EQ(nominal[3], 1);  // the manual: "normally ... 1 for a table rotation axis"
  EXPECT_EQ(nominal[6], 1);
  EXPECT_LT((f.ToolPoints(m, nominal, q, o) - p0).norm(), 1e-9);
}

TEST(VendorFanuc, NominalMachinesGiveTheirOwnGeometry) {
  const FanucVendor f;
  {
    const Machine m = Example("vmc0656");  // A (-x) at 0 carries C (-z) at z 100, tip at z 250
    const VendorOptions o = Options("XYZAC");
    const Eigen::VectorXd v = f.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
    Eigen::VectorXd expect(13);
    expect << 12, 4, 1, 1, 5, 3, 1, 0, 0, -350, 0, 0, 100;
    EXPECT_LT((v - expect).norm(), 1e-12) << v.transpose();
    const std::vector<VendorValue> names = f.Values(m, o);
    ASSERT_EQ(names.size(), 13u);
    EXPECT_EQ(names[0].name, "19680");
    EXPECT_TRUE(names[0].fixed);
    EXPECT_EQ(names[7].name, "rotary table position X");
    EXPECT_EQ(names[10].name, "19703");
    EXPECT_EQ(names[12].unit, "mm");
    EXPECT_FALSE(names[12].fixed);
    EXPECT_NE(names[12].source.find("sheet 82/88"), std::string::npos);
  }
  {
    const Machine m = HeadHead();  // C (+z) at (0,0,300) carries B (+y) at (40,0,260), tip (15,0,60)
    const VendorOptions o = Options("XYZCB");
    const Eigen::VectorXd v = f.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
    // D = tip + 100 z = (15, 0, 160); E on B nearest its point (40, 0, 260); F = (0, 0, 300).
    Eigen::VectorXd expect(14);
    expect << 2, 4, 3, 0, 5, 2, 0, 5, 25, 0, 100, -40, 0, 40;
    EXPECT_LT((v - expect).norm(), 1e-12) << v.transpose();
    EXPECT_EQ(f.Values(m, o)[7].name, "19666");
    EXPECT_EQ(f.Values(m, o)[13].name, "19714");
  }
  {
    const Machine m = TableHead();  // B (-y) in the head at (0,0,350), C (-z) on the table at (30,-20,0)
    const VendorOptions o = Options("XYZBC");
    const Eigen::VectorXd v = f.Map(m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())), o);
    Eigen::VectorXd expect(14);
    expect << 21, 4, 2, 1, 5, 3, 1, 5, 0, 0, 130, 30, -20, -350;
    EXPECT_LT((v - expect).norm(), 1e-12) << v.transpose();
    EXPECT_EQ(f.Values(m, o)[11].name, "rotary table position X");
  }
}

// The round trip of the export: errors -> absorbed model -> table -> values
// -> the manual's transformation == the absorbed model's tool points, up to
// the work offset, over poses spanning the volume.
TEST(VendorFanuc, RoundTripOnEveryTopology) {
  const FanucVendor f;
  for (Case& c : Cases()) {
    const VendorOptions o = Options(c.axis_order);
    const VendorModel vm = f.Model(c.m, o);
    EXPECT_EQ(vm.model, c.model) << c.m.name();
    EXPECT_FALSE(vm.directions);
    for (unsigned seed = 1; seed <= 4; ++seed) {
      const Eigen::MatrixXd q = Poses(c.m, 150, seed);
      const Eigen::VectorXd th = RandomErrors(c.m, seed);
      AbsorbOptions ao;
      ao.directions = vm.directions;
      ao.tool_length = vm.tool_length;
      const Absorption ab = Absorb(c.m, vm.model, th, q, ao);
      const KinematicsTable table = MakeKinematicsTable(c.m, ab.theta);
      const Eigen::VectorXd values = f.Map(c.m, table, o);
      const Eigen::MatrixXd fanuc = f.ToolPoints(c.m, values, q, o);
      const Eigen::MatrixXd absorbed = ToolPoints(c.m, ab.theta, q);
      EXPECT_LT(MaxUpToOffset(fanuc, absorbed), 1e-9) << c.m.name() << " seed " << seed;
      // The values moved: the errors were not zero, the round trip is not a nominal one.
      const Eigen::VectorXd nominal = f.Map(c.m, MakeKinematicsTable(c.m, Eigen::VectorXd::Zero(c.m.num_parameters())), o);
      EXPECT_GT((values - nominal).cwiseAbs().maxCoeff(), 1e-3) << c.m.name();
      // And against the erroneous machine itself: what is left is the absorption's residual.
      const Eigen::MatrixXd truth = ToolPoints(c.m, th, q);
      EXPECT_NEAR(MaxUpToOffset(fanuc + Eigen::MatrixXd::Ones(q.rows(), 1) * ab.workpiece_shift.transpose(), truth),
                  MaxUpToOffset(truth - ab.residual, truth), 1e-9)
          << c.m.name();
    }
  }
}

// The round trip can fail: 10 µm more on one offset is seen (along the
// axis's own line it is the same line, and rightly not seen).
TEST(VendorFanuc, RoundTripSeesAWrongValue) {
  const FanucVendor f;
  const Machine m = Example("c600u");
  const VendorOptions o = Options("XYZAC");
  const Eigen::MatrixXd q = Poses(m, 50, 9);
  const Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::VectorXd v = f.Map(m, MakeKinematicsTable(m, th), o);
  EXPECT_LT(MaxUpToOffset(f.ToolPoints(m, v, q, o), ToolPoints(m, th, q)), 1e-9);
  v[12] += 0.01;  // 19705: C's point 10 µm further along C's own line: the same line
  EXPECT_LT(MaxUpToOffset(f.ToolPoints(m, v, q, o), ToolPoints(m, th, q)), 1e-9);
  v[11] += 0.01;  // 19704: C's line 10 µm off A's
  EXPECT_GT(MaxUpToOffset(f.ToolPoints(m, v, q, o), ToolPoints(m, th, q)), 5e-3);
}

TEST(VendorFanuc, TableOfMapIsTheTable) {
  const FanucVendor f;
  for (Case& c : Cases()) {
    const VendorOptions o = Options(c.axis_order);
    const VendorModel vm = f.Model(c.m, o);
    const Eigen::MatrixXd q = Poses(c.m, 120, 5);
    AbsorbOptions ao;
    ao.directions = vm.directions;
    const Absorption ab = Absorb(c.m, vm.model, RandomErrors(c.m, 5), q, ao);
    for (const Eigen::VectorXd& theta : {Eigen::VectorXd(Eigen::VectorXd::Zero(c.m.num_parameters())), ab.theta}) {
      const KinematicsTable t = MakeKinematicsTable(c.m, theta);
      const KinematicsTable back = f.Table(c.m, f.Map(c.m, t, o), o);
      ASSERT_EQ(back.axes.size(), t.axes.size());
      // The values fix the chain up to where the machine origin sits: one translation.
      const Eigen::Vector3d shift = back.tool_tip - t.tool_tip;
      for (std::size_t i = 0; i < t.axes.size(); ++i) {
        EXPECT_EQ(back.axes[i].axis, t.axes[i].axis);
        EXPECT_LT((back.axes[i].direction - t.axes[i].direction).norm(), 1e-12) << c.m.name() << " " << t.axes[i].axis;
        if (t.axes[i].rotary) {
          EXPECT_LT((back.axes[i].point - t.axes[i].point - shift).norm(), 1e-9) << c.m.name() << " " << t.axes[i].axis;
        }
      }
      EXPECT_LT((back.tool_axis - t.tool_axis).norm(), 1e-12);
      if (theta.isZero()) {
        EXPECT_LT(shift.norm(), 1e-12) << c.m.name();
      }
      // Map of the way back is the values again.
      EXPECT_LT((f.Map(c.m, back, o) - f.Map(c.m, t, o)).norm(), 1e-9)
          << c.m.name() << "\n" << f.Map(c.m, back, o).transpose() << "\n" << f.Map(c.m, t, o).transpose();
      // The table the values describe, through the neutral screw kinematics,
      // is the manual's transformation (two implementations, one answer).
      Eigen::MatrixXd qt(q.rows(), back.axes.size());
      for (std::size_t j = 0; j < back.axes.size(); ++j)
        for (int k = 0; k < c.m.num_axes(); ++k)
          if (c.m.axis(k).name == back.axes[j].axis) qt.col(j) = q.col(k);
      EXPECT_LT((TableToolPoints(back, qt) - f.ToolPoints(c.m, f.Map(c.m, t, o), q, o)).rowwise().norm().maxCoeff(),
                1e-9)
          << c.m.name();
    }
  }
}

void ExpectRefusal(const std::function<void()>& call, const std::string& words) {
  try {
    call();
    ADD_FAILURE() << "no refusal, expected one saying: " << words;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
  }
}

TEST(VendorFanuc, RefusesWhatTheManualDoesNotDecide) {
  const FanucVendor f;
  const Machine tt = Example("c600u");
  const Machine hh = HeadHead();
  // An inclined rotary axis: No. 19683's definition is not public here.
  ExpectRefusal([&] { f.Model(Example("kx8"), Options("XYZAC")); }, "inclined rotary axis");
  // One rotary axis.
  ExpectRefusal(
      [&] {
        f.Model(Machine::FromJson(R"({"name": "4ax", "topology": "wAXfYZSt", "axes": {
          "A": {"type": "rotary", "direction": [1,0,0]}, "X": {"type": "linear", "direction": [1,0,0]},
          "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
          "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})"),
                Options("XYZA"));
      },
      "takes two");
  // A linear axis carried by a rotary axis.
  ExpectRefusal(
      [&] {
        f.Model(Machine::FromJson(R"({"name": "odd", "topology": "wXCAfYZSt", "axes": {
          "A": {"type": "rotary", "direction": [1,0,0]}, "C": {"type": "rotary", "direction": [0,0,1]},
          "X": {"type": "linear", "direction": [1,0,0]},
          "Y": {"type": "linear", "direction": [0,1,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
          "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,100]}})"),
                Options("XYZAC"));
      },
      "linear axis X is carried by a rotary axis");
  VendorOptions o = Options("XYZAC");
  o.erase("increment");
  ExpectRefusal([&] { f.Values(tt, o); }, "option increment is required");
  o = Options("XYZAC");
  o["increment"] = "IS-A";
  ExpectRefusal([&] { f.Values(tt, o); }, "expected IS-B or IS-C");
  o = Options("XYZAC");
  o.erase("tool-length");
  ExpectRefusal([&] { f.Model(tt, o); }, "option tool-length is required");
  o = Options("XYZAC");
  o["tool-length"] = "12mm";
  ExpectRefusal([&] { f.Model(tt, o); }, "tool-length=12mm: expected a number");
  o = Options("XYZCB");
  o.erase("holder-offset");
  ExpectRefusal([&] { f.Values(hh, o); }, "option holder-offset is required");
  o = Options("XYZAC");
  o["sign"] = "+";
  ExpectRefusal([&] { f.Model(tt, o); }, "unknown option 'sign'");
  ExpectRefusal([&] { f.Model(tt, Options("XYZA")); }, "lacks rotary axis C");
  ExpectRefusal([&] { f.Model(tt, Options("XYZAAC")); }, "appears twice");
  EXPECT_EQ(f.Map(tt, MakeKinematicsTable(tt, Eigen::VectorXd::Zero(tt.num_parameters())), Options("xyzac"))[1], 4);
  o = Options("XYZAC");
  o["path"] = "99999999999";
  ExpectRefusal([&] { f.Model(tt, o); }, "expected a path number");
  // A direction change has no Fanuc parameter: Map refuses to drop it.
  Eigen::VectorXd th = Eigen::VectorXd::Zero(tt.num_parameters());
  th[tt.RequireParameter("EB0C")] = 5e-5;
  ExpectRefusal([&] { f.Map(tt, MakeKinematicsTable(tt, th), Options("XYZAC")); }, "cannot be written");
  // Values that say another mechanism than the machine file.
  Eigen::VectorXd v = f.Map(tt, MakeKinematicsTable(tt, Eigen::VectorXd::Zero(tt.num_parameters())), Options("XYZAC"));
  v[6] = 0;
  ExpectRefusal([&] { f.Table(tt, v, Options("XYZAC")); }, "No. 19689 = 0 in the values");
  Eigen::VectorXd w = f.Map(hh, MakeKinematicsTable(hh, Eigen::VectorXd::Zero(hh.num_parameters())), Options("XYZCB"));
  w[7] = 7;
  ExpectRefusal([&] { f.ToolPoints(hh, w, Eigen::MatrixXd::Zero(1, hh.num_axes()), Options("XYZCB")); },
                "No. 19666 = 7 in the values, but --set holder-offset=5");
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
