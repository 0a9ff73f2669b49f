// The sphere check and the R-test evaluation as core procedures
// (procedures/sphere_check.h, procedures/rtest.h): the spindle naming rule,
// and end to end: a machine with known pivot errors is simulated with probe
// or R-test noise, evaluated, and the recovered errors are within 3 sigma of
// the truth under the names every command reports them.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "fivecal/design/design.h"
#include "fivecal/model/inverse.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/procedures/rtest.h"
#include "fivecal/procedures/sphere_check.h"
#include "fivecal/procedures/sphere_test.h"

namespace fivecal {
namespace {

using nlohmann::json;

json MachineJson(const std::string& name) {
  std::ifstream f(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/" + name + ".json");
  std::stringstream ss;
  ss << f.rdbuf();
  return json::parse(ss.str());
}

std::string Message(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "no throw";
}

// Truth of a random machine: every pivot parameter of every checked axis.
std::map<std::string, double> RandomPivots(const Machine& m, unsigned seed) {
  std::mt19937 gen(seed);
  std::normal_distribution<double> n(0.0, 1.0);
  std::map<std::string, double> truth;
  for (char a : CheckedRotaryAxes(m))
    for (const std::string& p : PivotParameters(m, a, true)) {
      // a spindle-named offset is simulated as the table axis' own error
      std::string name = p;
      if (p[3] == 'S') name = p.substr(0, 3) + a;
      truth[name] = (p[1] == 'A' || p[1] == 'B' || p[1] == 'C' || p.back() == 'b') ? 2e-5 * n(gen) : 0.015 * n(gen);
    }
  return truth;
}

std::map<std::string, double> Seen(const Machine& m, const std::map<std::string, double>& truth) {
  std::vector<std::pair<std::string, double>> in(truth.begin(), truth.end());
  std::map<std::string, double> out;
  for (const auto& [n, v] : SpindleNames(m, in)) out[n] = v;
  return out;
}

// Each rotary axis in turn through `n` positions, up then down (the others
// at 0), the sphere touched along every normal that faces the probe.
Dataset SimulateSphereCheck(const std::string& machine, const std::map<std::string, double>& truth, int n,
                            unsigned seed, double sigma = 0.001) {
  const json art = {{"spheres", {{{"id", "S1"}, {"center", {80.0, 50.0, 60.0}}, {"radius", 12.5}}}}};
  const Dataset setup = Dataset::FromJson(json({{"machine", MachineJson(machine)},
                                                {"probe", {{"tip_radius", 3.0}}},
                                                {"artefact", art},
                                                {"observations", json::array()}})
                                              .dump(),
                                          false);
  const Machine& m = setup.machine();
  std::vector<Eigen::VectorXd> rows;
  std::vector<Eigen::VectorXi> dirs;
  for (char a : CheckedRotaryAxes(m)) {
    const int i = m.AxisIndex(a);
    std::vector<double> v;
    const bool full = a == 'C';
    for (int k = 0; k < n; ++k)
      v.push_back(full ? -180.0 + 360.0 * k / n : -90.0 + 180.0 * k / (n - 1));
    std::vector<double> sweep = v;
    sweep.insert(sweep.end(), v.rbegin(), v.rend());
    double prev = 0.0;
    for (double x : sweep) {
      Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_axes());
      Eigen::VectorXi d = Eigen::VectorXi::Zero(m.num_axes());
      q[i] = x;
      d[i] = x >= prev ? 1 : -1;
      prev = x;
      rows.push_back(q);
      dirs.push_back(d);
    }
  }
  Eigen::MatrixXd Q(rows.size(), m.num_axes());
  Eigen::MatrixXi D(rows.size(), m.num_axes());
  for (size_t k = 0; k < rows.size(); ++k) {
    Q.row(k) = rows[k].transpose();
    D.row(k) = dirs[k].transpose();
  }
  Accessibility access;
  access.min_dot = 0.0;
  const std::string plan = CandidatePlan(setup, Q, &D, SpherePoints(), access);
  const json spec = {{"machine", MachineJson(machine)}, {"errors", truth}, {"probe", {{"tip_radius", 3.0}}},
                     {"artefact", art}, {"plan", json::parse(plan)}, {"sigma", sigma}, {"seed", seed}};
  return Simulate(spec.dump());
}

TEST(SphereCheck, SpindleNamingRule) {
  // A/C trunnion (C on A, A from the foundation along X): EX0C and EY0A are
  // constant tool-part offsets, named as the spindle's, minus their value.
  const Machine m = Machine::FromJson(MachineJson("c600u").dump());
  EXPECT_EQ(SpindleEquivalent(m, "EX0C"), "EX0S");
  EXPECT_EQ(SpindleEquivalent(m, "EY0A"), "EY0S");
  EXPECT_EQ(SpindleEquivalent(m, "EY0C"), "EY0C");  // A turns about X: C's Y offset is not constant
  EXPECT_EQ(SpindleEquivalent(m, "EZ0A"), "EZ0A");  // along the spindle line: not the spindle's across
  EXPECT_EQ(SpindleEquivalent(m, "EA0C"), "EA0C");
  EXPECT_EQ(SpindleEquivalent(m, "EX0Q"), "EX0Q");  // no such axis: unchanged, not a throw
  EXPECT_EQ(SpindleEquivalent(m, "tip.x"), "tip.x");
  const auto named = SpindleNames(m, {{"EX0C", 0.01}, {"EY0C", 0.02}, {"EX0S", 0.003}});
  ASSERT_EQ(named.size(), 2u);
  EXPECT_EQ(named[0].first, "EX0S");
  EXPECT_DOUBLE_EQ(named[0].second, -0.01 + 0.003);
  EXPECT_EQ(named[1].first, "EY0C");
  EXPECT_EQ(PivotParameters(m, 'C', true), (std::vector<std::string>{"EX0S", "EY0C", "EA0C", "EB0C", "ECCb"}));
  EXPECT_EQ(PivotParameters(m, 'A', false), (std::vector<std::string>{"EY0S", "EZ0A", "EB0A", "EC0A"}));
  EXPECT_EQ(RTestLocationErrors(m), (std::vector<std::string>{"EX0S", "EY0C", "EA0C", "EB0C", "EY0S", "EZ0A",
                                                               "EB0A", "EC0A"}));
  EXPECT_NE(Message([&] { PivotParameters(m, 'X', true); }).find("axis: machine"), std::string::npos);
}

TEST(SphereCheck, RecoversPivotsAndReversalWithin3Sigma) {
  for (const std::string name : {"c600u", "hu40t"}) {
    const Machine m = Machine::FromJson(MachineJson(name).dump());
    const auto truth = RandomPivots(m, 5);
    const Dataset ds = SimulateSphereCheck(name, truth, 5, 17);
    SphereCheckOptions o;
    o.previous = {{"EY0C", {0.0, 0.0}}};
    const SphereCheckResult r = EvaluateSphereCheck(ds, o);
    const auto seen = Seen(m, truth);
    ASSERT_EQ(r.fit.verdict(), "ok") << name;
    ASSERT_EQ(r.axes.size(), 2u) << name;
    for (const SphereCheckAxis& ax : r.axes) {
      ASSERT_EQ(ax.pivot.size(), 4u);
      for (const SphereCheckValue& v : ax.pivot) {
        ASSERT_TRUE(seen.count(v.name)) << v.name;
        EXPECT_LT(std::abs(v.value - seen.at(v.name)), 3 * v.std) << name << " " << v.name;
        EXPECT_GT(v.std, 0.0);
      }
      ASSERT_TRUE(ax.has_backlash) << name;
      const std::string b = std::string("E") + ax.axis + ax.axis + "b";
      EXPECT_LT(std::abs(ax.backlash.value - truth.at(b)), 3 * ax.backlash.std) << name << " " << b;
    }
    // the per-position centres scatter by the pivot errors before, by the noise after
    EXPECT_GT(r.dispersion_before, 0.01) << name;
    EXPECT_LT(r.dispersion_after, 0.001) << name;
    EXPECT_EQ(r.positions.rows(), r.centres_before.rows());
    EXPECT_EQ(r.positions.cols(), 2);
    // the change since a previous EY0C of 0, under the name the check reports
    // it (on hu40t, a B/C table, C's Y offset is the spindle's EY0S)
    const std::string ey = SpindleEquivalent(m, "EY0C");
    ASSERT_EQ(r.change.size(), 1u) << name;
    EXPECT_EQ(r.change[0].name, ey) << name;
    EXPECT_LT(std::abs(r.change[0].value - seen.at(ey)), 3 * r.change[0].std) << name;
  }
}

TEST(SphereCheck, RefusesBadInputNamingTheField) {
  const Machine m = Machine::FromJson(MachineJson("c600u").dump());
  const Dataset ds = SimulateSphereCheck("c600u", {{"EX0C", 0.01}}, 4, 3);
  SphereCheckOptions o;
  o.sphere = "S2";
  EXPECT_EQ(Message([&] { EvaluateSphereCheck(ds, o); }).rfind("sphere: no touches of sphere 'S2'", 0), 0u);
  o = {};
  o.backlash = 3;
  EXPECT_EQ(Message([&] { EvaluateSphereCheck(ds, o); }).rfind("backlash: 3", 0), 0u);
  o = {};
  o.previous = {{"EA0C", {std::nan(""), 0.0}}};
  EXPECT_EQ(Message([&] { EvaluateSphereCheck(ds, o); }).rfind("previous.EA0C: value", 0), 0u);
  o.previous = {{"EA0C", {0.0, -1e-6}}};
  EXPECT_EQ(Message([&] { EvaluateSphereCheck(ds, o); }).rfind("previous.EA0C: std", 0), 0u);
  // an entry the check does not compare with is not read
  o.previous = {{"sphere.S1.x", {std::nan(""), 0.0}}, {"EX0C", {0.0, 0.0}}};
  const SphereCheckResult r = EvaluateSphereCheck(ds, o);
  ASSERT_EQ(r.change.size(), 1u);
  EXPECT_EQ(r.change[0].name, "EX0S");  // the previous EX0C under the spindle's name
  // no rotary motion: nothing to check
  Dataset still = ds;
  for (Observation& ob : still.observations) {
    ob.axes[m.AxisIndex('C')] = 0;
    ob.axes[m.AxisIndex('A')] = 0;
  }
  EXPECT_NE(Message([&] { EvaluateSphereCheck(still, {}); }).find("no rotary axis moved"), std::string::npos);
}

// One K test's ball3d plan: the rotary poses, the linear axes from the
// nominal inverse so that the ball stays centred on the nominal machine.
json KTestPlan(const Machine& m, const std::string& test, const Eigen::Vector3d& ball) {
  const RTestRoles roles = RTestAxisRoles(m);
  const int c = m.AxisIndex(roles.turn), a = m.AxisIndex(roles.tilt);
  json plan = json::array();
  Eigen::VectorXd prev = Eigen::VectorXd::Zero(m.num_axes());
  const Eigen::MatrixXd seq = RTestSequence(m, test, test == "K2" ? 7.5 : 15.0, -45.0, -90.0, 90.0);
  for (int k = 0; k < seq.rows(); ++k) {
    const double cv = seq(k, 0), av = seq(k, 1);
    Eigen::VectorXd start = prev;
    start[c] = cv;
    start[a] = av;
    const Eigen::MatrixXd q = InverseKinematics(m, Eigen::VectorXd::Zero(m.num_parameters()), ball.transpose(),
                                                nullptr, start);
    json axes, dir;
    for (int i = 0; i < m.num_axes(); ++i) axes[std::string(1, m.axis(i).name)] = q(0, i);
    dir[std::string(1, roles.turn)] = cv >= prev[c] ? 1 : -1;
    dir[std::string(1, roles.tilt)] = av >= prev[a] ? 1 : -1;
    plan.push_back({{"type", "ball3d"}, {"setup", test}, {"axes", axes}, {"direction", dir},
                    {"tool_ball", {m.tip().x(), m.tip().y(), m.tip().z()}},
                    {"table_ball", {ball.x(), ball.y(), ball.z()}}});
    prev = q.row(0).transpose();
  }
  return plan;
}

TEST(RTest, KTestPoses) {
  const Machine m = Machine::FromJson(MachineJson("c600u").dump());
  const RTestRoles r = RTestAxisRoles(m);
  EXPECT_EQ(r.turn, 'C');  // C along -Z: the table's normal
  EXPECT_EQ(r.tilt, 'A');
  const Eigen::MatrixXd k1 = RTestSequence(m, "K1", 30.0, -45.0, -90.0, 90.0);
  ASSERT_EQ(k1.rows(), 13);  // 0, 30, ... 360: the full turn closes
  EXPECT_DOUBLE_EQ(k1(12, 0), 360.0);
  EXPECT_EQ(k1.col(1).cwiseAbs().maxCoeff(), 0.0);
  const Eigen::MatrixXd k2 = RTestSequence(m, "K2", 15.0, -45.0, -60.0, 30.0);
  ASSERT_EQ(k2.rows(), 7);
  EXPECT_DOUBLE_EQ(k2(0, 1), -60.0);
  EXPECT_DOUBLE_EQ(k2(6, 1), 30.0);
  EXPECT_EQ(k2.col(0).cwiseAbs().maxCoeff(), 0.0);
  const Eigen::MatrixXd k4 = RTestSequence(m, "K4", 15.0, -30.0, -90.0, 90.0);
  EXPECT_NEAR(k4.col(1).minCoeff(), -30.0, 1e-12);
  EXPECT_NEAR(k4.col(1).maxCoeff(), 30.0, 1e-12);
  EXPECT_NEAR(k4(6, 1), -30.0, 1e-12);  // C = 90
  EXPECT_EQ(Message([&] { RTestSequence(m, "K5", 15, 0, -90, 90); }).rfind("test: 'K5'", 0), 0u);
  EXPECT_EQ(Message([&] { RTestSequence(m, "K1", 0.001, 0, -90, 90); }).rfind("step: ", 0), 0u);
  EXPECT_EQ(Message([&] { RTestSequence(m, "K2", 15, 0, 90, -90); }).rfind("tilt_range: ", 0), 0u);
  const Machine three = Machine::FromJson(
      R"({"name": "3ax", "topology": "wfXYZt", "axes": {"X": {"type": "linear", "direction": [1, 0, 0]},
          "Y": {"type": "linear", "direction": [0, 1, 0]}, "Z": {"type": "linear", "direction": [0, 0, 1]}},
          "tool": {"tip": [0, 0, 100]}})");
  EXPECT_NE(Message([&] { RTestAxisRoles(three); }).find("the tests are defined for two"), std::string::npos);
}

TEST(RTest, RangesAndLocationErrorsWithin3Sigma) {
  const json mj = MachineJson("c600u");
  const Machine m = Machine::FromJson(mj.dump());
  const std::map<std::string, double> truth = {{"EX0C", 0.007}, {"EY0C", 0.016}, {"EA0C", 1e-5},
                                               {"EB0C", -4e-5}, {"EY0A", 0.009}, {"EZ0A", -0.011},
                                               {"EB0A", 1.7e-5}, {"EC0A", 1.1e-5}};
  const Eigen::Vector3d ball(120.0, -40.0, 80.0);
  json plan = json::array();
  for (const std::string t : {"K1", "K2", "K3", "K4"})
    for (const json& e : KTestPlan(m, t, ball)) plan.push_back(e);
  const auto make = [&](double sigma, unsigned seed) {
    return Simulate(json({{"machine", mj}, {"errors", truth}, {"plan", plan},
                          {"sigma", {{"ball3d", sigma}}}, {"seed", seed}}).dump());
  };
  // the nominal machine keeps the ball centred: the plan is right
  const Dataset nominal =
      Simulate(json({{"machine", mj}, {"errors", json::object()}, {"plan", plan}, {"sigma", {{"ball3d", 0.0}}}}).dump());
  RTestOptions only;
  only.identify = false;
  for (const RTestGroup& g : EvaluateRTest(nominal, only).tests) EXPECT_LT(g.ranges.maxCoeff(), 1e-9) << g.name;

  const RTestResult clean = EvaluateRTest(make(0.0, 1), only);
  const RTestResult r = EvaluateRTest(make(0.0005, 2), {});
  ASSERT_EQ(r.tests.size(), 4u);
  EXPECT_FALSE(clean.identified);
  for (size_t i = 0; i < r.tests.size(); ++i) {
    EXPECT_EQ(r.tests[i].name, clean.tests[i].name);
    EXPECT_EQ(r.tests[i].observations.size(), 25u);
    EXPECT_LT((r.tests[i].ranges - clean.tests[i].ranges).cwiseAbs().maxCoeff(), 6 * 0.0005);
    EXPECT_GT(r.tests[i].ranges.maxCoeff(), 0.005);
  }
  ASSERT_TRUE(r.identified);
  ASSERT_EQ(r.fit.verdict(), "ok");
  EXPECT_EQ(r.estimated, RTestLocationErrors(m));
  const auto seen = Seen(m, truth);
  for (size_t k = 0; k < r.fit.estimated.size(); ++k) {
    const std::string& n = r.fit.estimated[k];
    if (!seen.count(n)) continue;  // the mountings' set-up
    double v = 0;
    for (size_t j = 0; j < r.fit.names.size(); ++j)
      if (r.fit.names[j] == n) v = r.fit.values[j];
    EXPECT_LT(std::abs(v - seen.at(n)), 3 * r.fit.std[k]) << n;
  }
  for (const std::string& n : RTestLocationErrors(m))
    EXPECT_NE(std::find(r.fit.estimated.begin(), r.fit.estimated.end(), n), r.fit.estimated.end()) << n;
}

TEST(RTest, RefusesBadInputNamingTheField) {
  const Dataset touches = SimulateSphereCheck("c600u", {}, 3, 1);
  EXPECT_NE(Message([&] { EvaluateRTest(touches, {}); }).find("no ball3d observations"), std::string::npos);
  const Machine m = Machine::FromJson(MachineJson("c600u").dump());
  const Dataset ds = Simulate(json({{"machine", MachineJson("c600u")}, {"errors", json::object()},
                                    {"plan", KTestPlan(m, "K1", Eigen::Vector3d(120, -40, 80))}})
                                  .dump());
  RTestOptions o;
  o.estimate = {"EX0S", ""};
  EXPECT_EQ(Message([&] { EvaluateRTest(ds, o); }).rfind("estimate[1]: an empty parameter name", 0), 0u);
}

}  // namespace
}  // namespace fivecal
