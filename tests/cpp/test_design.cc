// Test design (design.h), the machine-as-CMM sphere test (sphere_test.h) and
// machining tests (machining_test.h).
//
//  * AssessPlan's condition number is the one Identify reports on the same
//    data; a rank-deficient plan has an infinite one and names the group.
//  * The search: exchange is never worse than greedy, the chosen plan's exact
//    condition number matches the search's, and it beats every one of many
//    random subsets of the same size.
//  * FitSphere recovers a sphere exactly; errors that move the point cloud
//    rigidly (EC0C, EZ0C on wCBXfZYSt) leave the out of sphericity at zero,
//    others do not (Table 6-1).
//  * Machining tests: the automatic-derivative sensitivities equal central
//    differences of PredictMachining; the prediction agrees with Zhang &
//    Zhang's first-order equations to second order; the tilt-axis errors are
//    recovered from noisy simulated machining errors within 3 sigma.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "fivecal/observations/dataset.h"
#include "fivecal/design/design.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/model/machine.h"
#include "fivecal/procedures/machining_test.h"
#include "fivecal/observations/simulate.h"
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

// A small TANGO-like artefact on the HU40T-like machine: top and side facets
// of a 400 mm table and a scale bar.
json Artefact() {
  json facets = json::array();
  int id = 0;
  for (double x : {-150.0, 0.0, 150.0})
    for (double y : {-150.0, 0.0, 150.0})
      facets.push_back({{"id", "T" + std::to_string(id++)}, {"point", {x, y, 0.0}}, {"normal", {0, 0, 1}}});
  const double s = std::sqrt(0.5);
  const std::vector<std::array<double, 2>> dirs = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}, {s, s}, {-s, s}, {-s, -s}, {s, -s}};
  for (const auto& d : dirs)
    facets.push_back({{"id", "F" + std::to_string(id++)},
                      {"point", {180 * d[0] + 60 * d[1], 180 * d[1] - 60 * d[0], -20.0}},
                      {"normal", {d[0], d[1], 0.0}}});
  return {{"facets", facets},
          {"spheres", {{{"id", "S1"}, {"center", {-150.0, -80.0, 50.0}}, {"radius", 12.7}},
                       {{"id", "S2"}, {"center", {150.0, -80.0, 50.0}}, {"radius", 12.7}}}},
          {"scale_bars", {{{"spheres", {"S1", "S2"}}, {"length", 300.0}}}}};
}

// Candidate indexations (B, C, S) in degrees.
std::vector<std::array<double, 3>> Indexations() {
  std::vector<std::array<double, 3>> out;
  for (double b : {-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0})
    for (double c : {-180.0, -90.0, 0.0, 90.0}) out.push_back({b, c, 0.0});
  for (double s : {90.0, 180.0, 270.0}) out.push_back({0.0, 0.0, s});
  return out;
}

// The candidate pool: every accessible facet at every indexation, the bar
// balls from five directions, simulated noise-free on the nominal machine.
struct Pool {
  Dataset ds;
  std::vector<int> group;
};

Pool MakePool(double sigma = 0.0, const json& errors = json::object(), int seed = 1) {
  const json m = MachineJson("hu40t");
  const json base = {{"machine", m}, {"probe", {{"tip_radius", 3.0}}}, {"artefact", Artefact()},
                     {"observations", json::array()}};
  const Dataset setup = Dataset::FromJson(base.dump(), false);
  const auto idx = Indexations();
  const int na = setup.machine().num_axes();
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(idx.size(), na);
  Eigen::MatrixXi dir = Eigen::MatrixXi::Zero(idx.size(), na);
  for (size_t i = 0; i < idx.size(); ++i) {
    q(i, setup.machine().AxisIndex('B')) = idx[i][0];
    q(i, setup.machine().AxisIndex('C')) = idx[i][1];
    q(i, setup.machine().AxisIndex('S')) = idx[i][2];
    dir(i, setup.machine().AxisIndex('B')) = (i / 4) % 2 ? 1 : -1;
    dir(i, setup.machine().AxisIndex('C')) = i % 2 ? 1 : -1;
  }
  const double s = std::sqrt(0.5);
  const std::vector<Eigen::Vector3d> normals = {{0, 0, 1}, {s, 0, s}, {-s, 0, s}, {0, s, s}, {0, -s, s}};
  Accessibility access;
  access.min_dot = 0.0;
  Pool pool{Dataset(setup.machine()), {}};
  const std::string plan = CandidatePlan(setup, q, &dir, normals, access, &pool.group);
  json spec = base;
  spec["plan"] = json::parse(plan);
  spec["errors"] = errors;
  spec["sigma"] = sigma;
  spec["seed"] = seed;
  pool.ds = Simulate(spec.dump());
  return pool;
}

const std::vector<std::string> kLocation = {"EA0B", "EC0B", "EX0C", "EA0C", "EB0C", "EB0Z",
                                            "EA0Y", "EC0Y", "EX0S", "EY0S", "EXX1", "EYY1", "EZZ1"};

TEST(Design, CandidatePlanFacesTheProbe) {
  const Pool pool = MakePool();
  ASSERT_GT(pool.ds.observations.size(), 100u);
  // Every facet touch faces the probe: n . a >= min_dot (0 here), a the
  // nominal tool axis in the table frame at the touch.
  const Machine& m = pool.ds.machine();
  for (const Observation& o : pool.ds.observations) {
    if (o.type != ObservationType::kFacet) continue;
    Eigen::MatrixXd P, A;
    ToolPoses(m, Eigen::VectorXd::Zero(m.num_parameters()), o.axes.transpose(), nullptr, &P, &A);
    const std::string& target = o.data<TouchData>().target;
    const Facet& f = pool.ds.artefact.facets[pool.ds.artefact.FacetIndex(target)];
    EXPECT_GE(f.normal.dot(A.row(0).transpose()), -1e-12) << target;
  }
  // Axis limits remove touches.
  const json base = {{"machine", MachineJson("hu40t")}, {"probe", {{"tip_radius", 3.0}}},
                     {"artefact", Artefact()}, {"observations", json::array()}};
  const Dataset setup = Dataset::FromJson(base.dump(), false);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(1, setup.machine().num_axes());
  Accessibility all, limited;
  limited.limits['X'] = {-100.0, 100.0};
  const json a = json::parse(CandidatePlan(setup, q, nullptr, {}, all));
  const json l = json::parse(CandidatePlan(setup, q, nullptr, {}, limited));
  EXPECT_EQ(a.size(), 17u);  // every facet at B = C = 0
  EXPECT_LT(l.size(), a.size());
  EXPECT_GT(l.size(), 0u);
  limited.limits['Q'] = {0, 1};
  EXPECT_THROW(CandidatePlan(setup, q, nullptr, {}, limited), std::invalid_argument);
}

TEST(Design, ConditionNumberIsIdentifys) {
  const Pool pool = MakePool();
  DesignOptions opt;
  opt.estimate = kLocation;
  const PlanQuality q = AssessPlan(pool.ds, opt);
  IdentifyOptions io;
  io.estimate = kLocation;
  const Result r = Identify(pool.ds, io);
  EXPECT_NEAR(q.condition_number / r.condition_number, 1.0, 1e-6);
  EXPECT_EQ(q.rank, q.n_parameters);
  EXPECT_EQ(q.n_machine, static_cast<int>(kLocation.size()) + 3);  // + tip.x|y|z
  EXPECT_TRUE(std::isfinite(q.d_criterion));
  for (int i = 0; i < q.predicted_std.size(); ++i) EXPECT_GT(q.predicted_std[i], 0.0);
}

TEST(Design, RankDeficientPlanNamesTheGroup) {
  const Pool pool = MakePool();
  // Only the B = 0, S = 0 indexations: B-axis errors and spindle offsets
  // cannot be separated; and no scale bar when the balls are left out.
  std::vector<int> sub;
  const int b = pool.ds.machine().AxisIndex('B'), s = pool.ds.machine().AxisIndex('S');
  for (size_t i = 0; i < pool.ds.observations.size(); ++i) {
    const Observation& o = pool.ds.observations[i];
    if (o.axes[b] == 0 && o.axes[s] == 0 && o.type == ObservationType::kFacet) sub.push_back(i);
  }
  DesignOptions opt;
  opt.estimate = kLocation;
  const PlanQuality q = AssessPlan(pool.ds, opt, &sub);
  EXPECT_TRUE(std::isinf(q.condition_number));
  EXPECT_LT(q.rank, q.n_parameters);
  ASSERT_FALSE(q.confounded.empty());
  EXPECT_TRUE(std::isinf(q.d_std));
}

TEST(Design, ExchangeBeatsGreedyAndRandomSubsets) {
  const Pool pool = MakePool();
  DesignOptions opt;
  opt.estimate = kLocation;
  SearchOptions s;
  s.k = 8;
  s.method = "greedy";
  const DesignResult g = DesignPlan(pool.ds, pool.group, opt, s);
  s.method = "exchange";
  int calls = 0;
  s.progress = [&](const std::string&, int, int, double) { return ++calls > 0; };
  const DesignResult e = DesignPlan(pool.ds, pool.group, opt, s);
  EXPECT_GT(calls, 0);
  ASSERT_EQ(e.groups.size(), 8u);
  EXPECT_LE(e.quality.condition_number, g.quality.condition_number * (1 + 1e-9));
  // The search's criterion (from information matrices) is the exact one.
  EXPECT_NEAR(e.history.back() / e.quality.condition_number, 1.0, 1e-6);
  const int G = *std::max_element(pool.group.begin(), pool.group.end()) + 1;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 30; ++trial) {
    std::vector<int> all(G);
    for (int i = 0; i < G; ++i) all[i] = i;
    std::shuffle(all.begin(), all.end(), rng);
    std::vector<int> obs;
    for (size_t i = 0; i < pool.group.size(); ++i)
      if (std::find(all.begin(), all.begin() + 8, pool.group[i]) != all.begin() + 8) obs.push_back(i);
    const PlanQuality q = AssessPlan(pool.ds, opt, &obs);
    EXPECT_LE(e.quality.condition_number, q.condition_number);
  }
}

TEST(Design, StopsWhenProgressSaysSoAndChecksArguments) {
  const Pool pool = MakePool();
  DesignOptions opt;
  opt.estimate = kLocation;
  SearchOptions s;
  s.k = 6;
  s.progress = [](const std::string&, int done, int, double) { return done < 2; };
  const DesignResult r = DesignPlan(pool.ds, pool.group, opt, s);
  EXPECT_TRUE(r.stopped);
  s.progress = nullptr;
  s.k = 0;
  EXPECT_THROW(DesignPlan(pool.ds, pool.group, opt, s), std::invalid_argument);
  s.k = 3;
  s.criterion = "A";
  EXPECT_THROW(DesignPlan(pool.ds, pool.group, opt, s), std::invalid_argument);
  s.criterion = "condition";
  std::vector<int> short_groups(pool.group.begin(), pool.group.end() - 1);
  EXPECT_THROW(DesignPlan(pool.ds, short_groups, opt, s), std::invalid_argument);
}

TEST(Design, TouchBudget) {
  const Pool pool = MakePool();
  DesignOptions opt;
  opt.estimate = kLocation;
  SearchOptions s;
  s.k = 6;
  const DesignResult all = DesignPlan(pool.ds, pool.group, opt, s);
  s.max_touches = static_cast<int>(all.observations.size()) - 12;
  const DesignResult r = DesignPlan(pool.ds, pool.group, opt, s);
  EXPECT_EQ(static_cast<int>(r.observations.size()), s.max_touches);
  // Dropping a touch may even improve the conditioning (it is not monotone
  // in the data); the removals are chosen on the exact criterion.
  EXPECT_NEAR(r.history.back() / r.quality.condition_number, 1.0, 1e-6);
  EXPECT_LT(r.quality.condition_number, 2 * all.quality.condition_number);
  EXPECT_TRUE(std::isfinite(r.quality.condition_number));
}

TEST(Design, FastDCriterionIsTheEigenOne) {
  // The search scores full-rank D-criterion candidates by an elimination
  // certified against the step's reference instead of an eigen-decomposition:
  // same value, same rank verdict, on random selections (additions of a group,
  // removals of a touch, including ones that (de)activate facets, spheres and
  // the scale bar).
  const Pool pool = MakePool();
  for (const std::vector<std::string>& estimate : {kLocation, std::vector<std::string>{"S3"}}) {
    DesignOptions opt;
    opt.estimate = estimate;
    const auto checks = internal::CheckDesignScores(pool.ds, pool.group, opt, 40, 3);
    int full[2] = {0, 0}, fast[2] = {0, 0}, deficient = 0;
    for (const auto& c : checks) {
      ASSERT_EQ(c.fast_deficiency, c.exact_deficiency);
      if (c.exact_deficiency > 0) {
        ++deficient;
        EXPECT_FALSE(c.fast_path);
        EXPECT_TRUE(std::isinf(c.fast) && c.fast < 0);
        continue;
      }
      EXPECT_NEAR(c.fast, c.exact, 1e-9 * std::max(1.0, std::abs(c.exact)));
      ++full[c.removal];
      fast[c.removal] += c.fast_path;
    }
    EXPECT_GT(deficient, 0);
    // The certificate is not so cautious that the fast path is rarely taken.
    EXPECT_GT(full[0], 50);
    EXPECT_GT(full[1], 50);
    EXPECT_GE(fast[0], 0.8 * full[0]) << fast[0] << " of " << full[0] << " additions";
    EXPECT_GE(fast[1], 0.8 * full[1]) << fast[1] << " of " << full[1] << " removals";
  }
  // And the whole search: its last criterion is the chosen plan's exact one.
  DesignOptions opt;
  opt.estimate = kLocation;
  SearchOptions s;
  s.k = 6;
  s.criterion = "d";
  const DesignResult all = DesignPlan(pool.ds, pool.group, opt, s);
  EXPECT_NEAR(all.history.back(), all.quality.d_criterion, 1e-6 * std::abs(all.quality.d_criterion));
  s.max_touches = static_cast<int>(all.observations.size()) - 12;
  const DesignResult r = DesignPlan(pool.ds, pool.group, opt, s);
  EXPECT_EQ(static_cast<int>(r.observations.size()), s.max_touches);
  EXPECT_NEAR(r.history.back(), r.quality.d_criterion, 1e-6 * std::abs(r.quality.d_criterion));
  EXPECT_LE(r.quality.d_criterion, all.quality.d_criterion);
}

TEST(Design, CharacteristicScale) {
  const Machine m = Machine::FromJson(MachineJson("hu40t").dump());
  EXPECT_EQ(CharacteristicScale(m, "EX0C", 400), 1.0);
  EXPECT_EQ(CharacteristicScale(m, "EA0C", 400), 400.0);
  EXPECT_EQ(CharacteristicScale(m, "EXX1", 400), 400.0);
  EXPECT_EQ(CharacteristicScale(m, "EXX2", 400), 160000.0);
  EXPECT_EQ(CharacteristicScale(m, "EAX1", 400), 160000.0);
  EXPECT_EQ(CharacteristicScale(m, "EXC2", 400), 1.0);   // rotary axis, linear component, per rad^2
  EXPECT_EQ(CharacteristicScale(m, "ECC1", 400), 400.0);
  EXPECT_EQ(CharacteristicScale(m, "ECCb", 400), 400.0);
  EXPECT_EQ(CharacteristicScale(m, "EXXb", 400), 1.0);
  EXPECT_EQ(CharacteristicScale(m, "facet.F3", 400), 1.0);
}

// ---- sphere test -------------------------------------------------------------

TEST(SphereTest, PointDistribution) {
  const auto p = SpherePoints();
  ASSERT_EQ(p.size(), 33u);  // 12 + 8 + 8 + 4 + 1 (thesis §6.3)
  int equator = 0;
  for (const auto& v : p) {
    EXPECT_NEAR(v.norm(), 1.0, 1e-12);
    if (std::abs(v.z()) < 1e-12) ++equator;
  }
  EXPECT_EQ(equator, 12);
  EXPECT_NEAR(p.back().z(), 1.0, 1e-15);
  EXPECT_THROW(SpherePoints({{95.0, 3}}), std::invalid_argument);
}

TEST(SphereTest, FitRecoversSphere) {
  const Eigen::Vector3d c(12.5, -40.0, 77.0);
  const double R = 12.525;
  const auto dirs = SpherePoints();
  Eigen::MatrixXd P(dirs.size(), 3);
  for (size_t i = 0; i < dirs.size(); ++i) P.row(i) = (c + R * dirs[i]).transpose();
  SphereFit f = FitSphere(P);
  EXPECT_TRUE(f.converged);
  EXPECT_NEAR((f.center - c).norm(), 0.0, 1e-10);
  EXPECT_NEAR(f.radius, R, 1e-10);
  EXPECT_LT(f.out_of_sphericity, 1e-10);
  // A bump of 5 um on one point: the out of sphericity sees it.
  P.row(3) += 0.005 * dirs[3].transpose();
  f = FitSphere(P);
  EXPECT_GT(f.out_of_sphericity, 0.004);
  EXPECT_LT(f.out_of_sphericity, 0.0055);
  EXPECT_THROW(FitSphere(P.topRows(3)), std::invalid_argument);
  Eigen::MatrixXd flat = P;
  flat.col(2).setZero();
  EXPECT_THROW(FitSphere(flat), std::invalid_argument);
}

TEST(SphereTest, KnownRadiusCentreFromACap) {
  // Five touches on a 40 deg cap: a free radius is poorly determined there,
  // the known one pins the centre.
  const Eigen::Vector3d c(80.2, 49.9, 60.05);
  const double R = 15.5;
  Eigen::MatrixXd P(5, 3);
  const double th[5] = {0, 30, 40, 35, 20}, az[5] = {0, 0, 90, 200, 290};
  for (int i = 0; i < 5; ++i) {
    const double t = th[i] * M_PI / 180, a = az[i] * M_PI / 180;
    P.row(i) = (c + R * Eigen::Vector3d(std::sin(t) * std::cos(a), std::sin(t) * std::sin(a), std::cos(t)))
                   .transpose();
  }
  const SphereCentreFit f = FitSphereCentre(P, R, Eigen::Vector3d(80, 50, 60));
  EXPECT_TRUE(f.converged);
  EXPECT_NEAR((f.center - c).norm(), 0.0, 1e-10);
  EXPECT_LT(f.rms, 1e-10);
  auto message = [&](const Eigen::MatrixXd& pts, double r, const Eigen::Vector3d& start) {
    try {
      FitSphereCentre(pts, r, start);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no throw");
  };
  EXPECT_NE(message(P.topRows(2), R, c).find("points: need at least 3"), std::string::npos);
  Eigen::MatrixXd bad = P;
  bad(2, 1) = std::nan("");
  EXPECT_NE(message(bad, R, c).find("points[2]"), std::string::npos);
  EXPECT_NE(message(P, 0.0, c).find("radius"), std::string::npos);
  EXPECT_NE(message(P, R, Eigen::Vector3d(0, std::nan(""), 0)).find("start"), std::string::npos);
  // three points on one line through the start: the centre is free about it
  Eigen::MatrixXd line(3, 3);
  line << 0, 0, 1, 0, 0, 2, 0, 0, -3;
  EXPECT_NE(message(line, 2.0, Eigen::Vector3d::Zero()).find("do not determine the centre"), std::string::npos);
}

TEST(SphereTest, RigidErrorsLeaveTheSphereRound) {
  const json m = MachineJson("hu40t");
  const json art = {{"spheres", {{{"id", "P"}, {"center", {100.0, -50.0, 60.0}}, {"radius", 9.525}}}}};
  const Dataset setup =
      Dataset::FromJson(json({{"machine", m}, {"probe", {{"tip_radius", 3.0}}}, {"artefact", art},
                              {"observations", json::array()}}).dump(), false);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(6, setup.machine().num_axes());
  const int b = setup.machine().AxisIndex('B'), c = setup.machine().AxisIndex('C');
  const double bc[6][2] = {{0, 0}, {30, -90}, {60, -180}, {-30, 90}, {-60, 180}, {0, 90}};
  for (int i = 0; i < 6; ++i) {
    q(i, b) = bc[i][0];
    q(i, c) = bc[i][1];
  }
  Accessibility access;
  access.min_dot = 0.0;
  const std::string plan = CandidatePlan(setup, q, nullptr, SpherePoints(), access);
  const auto rows = SphereSensitivity(setup, plan, "P", {"EC0C", "EZ0C", "EX0C", "EX0S", "EA0Y"});
  ASSERT_EQ(rows.size(), 6u);
  EXPECT_EQ(rows[0].name, "");
  EXPECT_LT(rows[0].out_of_sphericity, 1e-10);
  EXPECT_LT(std::abs(rows[0].size_error), 1e-10);
  EXPECT_LT(rows[1].out_of_sphericity, 1e-10);  // EC0C: a rotation of the whole cloud
  EXPECT_LT(rows[2].out_of_sphericity, 1e-10);  // EZ0C: a translation of it
  for (int i = 3; i < 6; ++i) EXPECT_GT(rows[i].out_of_sphericity, 1e-4) << rows[i].name;
  EXPECT_NEAR(rows[3].value, 1e-3, 1e-15);
  EXPECT_NEAR(rows[5].value, 2.5e-6, 1e-18);
}

TEST(SphereTest, ModelValuesRefuseUnknownNames) {
  // A result's setup parameters are skipped; a misspelt machine parameter
  // would otherwise leave the model nominal without a word.
  const json m = MachineJson("hu40t");
  const json art = {{"spheres", {{{"id", "P"}, {"center", {100.0, -50.0, 60.0}}, {"radius", 9.525}}}}};
  const json obs = {{{"type", "sphere"}, {"target", "P"},
                     {"axes", {{"X", 0.0}, {"Y", 0.0}, {"Z", 0.0}, {"B", 0.0}, {"C", 0.0}}}}};
  const Dataset ds = Dataset::FromJson(
      json({{"machine", m}, {"probe", {{"tip_radius", 3.0}}}, {"artefact", art}, {"observations", obs}}).dump());
  EXPECT_NO_THROW(TablePoints(ds, {{"EX0C", 0.01}, {"tip.x", 0.1}, {"sphere.P.x", 0.2}, {"facet.F1", 0.3},
                                   {"dbb.A1.length", 0.1}}, {0}));
  for (const auto& [bad, hint] : std::vector<std::pair<std::string, std::string>>{
           {"tpi.x", "did you mean \"tip.x\""}, {"EX0C.x", "unknown parameter"}, {"EXOC", "EX0C"}}) {
    try {
      TablePoints(ds, {{bad, 0.01}}, {0});
      ADD_FAILURE() << bad << " was accepted";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("values." + bad), std::string::npos) << what;
      EXPECT_NE(what.find(hint), std::string::npos) << what;
    }
  }
  EXPECT_THROW(SphereTest(ds, "", {{"tpi.z", 1.0}}), std::invalid_argument);
}

// ---- machining tests -------------------------------------------------------------

Machine C600U() { return Machine::FromJson(MachineJson("c600u").dump()); }

TEST(MachiningTest, SensitivitiesMatchFiniteDifferences) {
  const Machine m = C600U();
  const auto tests = ZhangZhangTests(m, 150.0, 60.0);
  const std::vector<std::string> names = {"EA0C", "EB0C", "EY0C", "EZ0C", "EXX1", "EB0A",
                                          "tip.z", "workpiece.y", "workpiece.a"};
  std::map<std::string, double> at = {{"EA0C", 3e-5}, {"EY0C", 0.01}, {"EX0C", -0.02},
                                      {"EZZ1", 2e-5}, {"workpiece.x", 0.01}};
  const Eigen::MatrixXd J = MachiningJacobian(m, tests, names, at);
  ASSERT_EQ(J.rows(), 3);
  ASSERT_EQ(J.cols(), static_cast<long>(names.size()));
  for (size_t j = 0; j < names.size(); ++j) {
    const bool angular = names[j] == "EA0C" || names[j] == "EB0C" || names[j] == "EB0A" ||
                         names[j] == "workpiece.a" || names[j] == "EXX1";
    const double h = angular ? 1e-6 : 1e-4;
    auto plus = at, minus = at;
    plus[names[j]] += h;
    minus[names[j]] -= h;
    const Eigen::VectorXd fd = (PredictMachining(m, tests, plus) - PredictMachining(m, tests, minus)) / (2 * h);
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(J(i, j), fd[i], 1e-6 * std::max(1.0, std::abs(fd[i]))) << names[j] << " test " << i;
  }
}

TEST(MachiningTest, FirstOrderEquationsOfThePaper) {
  const Machine m = C600U();
  const double L = 150, H = 60;
  const auto tests = ZhangZhangTests(m, L, H);
  const Eigen::Vector3d Ad(0.012, -0.025, 0.018), Ax(35e-6, -22e-6, 41e-6);
  const Eigen::Vector3d Cd(0.015, -0.020, 0.0), Cx(-28e-6, 17e-6, 30e-6);
  auto values = [&](double s) {
    return std::map<std::string, double>{
        {"EX0C", s * Ad[0]}, {"EY0C", s * Ad[1]}, {"EZ0C", s * Ad[2]}, {"EA0C", s * Ax[0]},
        {"EB0C", s * Ax[1]}, {"EC0C", s * Ax[2]}, {"workpiece.x", s * Cd[0]}, {"workpiece.y", s * Cd[1]},
        {"workpiece.a", s * Cx[0]}, {"workpiece.b", s * Cx[1]}, {"workpiece.c", s * Cx[2]}};
  };
  const Eigen::VectorXd e1 = PredictMachining(m, tests, values(1.0));
  const Eigen::VectorXd e2 = PredictMachining(m, tests, values(0.5));
  const Eigen::Vector3d p1 = ZhangZhangFirstOrder(L, H, Ad, Ax, Cd, Cx);
  const Eigen::Vector3d p2 = ZhangZhangFirstOrder(L, H, 0.5 * Ad, 0.5 * Ax, 0.5 * Cd, 0.5 * Cx);
  for (int i = 0; i < 3; ++i) {
    EXPECT_GT(std::abs(p1[i]), 1e-3);
    const double d1 = e1[i] - p1[i], d2 = e2[i] - p2[i];
    EXPECT_LT(std::abs(d1), 1e-3 * std::abs(p1[i]));
    EXPECT_NEAR(d2 / d1, 0.25, 0.02) << "test " << i;  // second order
  }
  // Nominal machine: no machining error.
  EXPECT_LT(PredictMachining(m, tests, {}).norm(), 1e-12);
}

TEST(MachiningTest, IdentifiesTheTiltAxisErrors) {
  const Machine m = C600U();
  auto tests = ZhangZhangTests(m, 150.0, 60.0);
  const std::map<std::string, double> setup = {{"workpiece.x", 0.015}, {"workpiece.y", -0.02},
                                               {"workpiece.a", -28e-6}};
  std::map<std::string, double> truth = {{"EA0C", 35e-6}, {"EY0C", -0.025}, {"EZ0C", 0.018},
                                         {"EX0C", 0.012}, {"EB0C", -22e-6}, {"EC0C", 41e-6},
                                         {"EY0A", 0.02}, {"EZ0A", -0.01}};
  truth.insert(setup.begin(), setup.end());
  const Eigen::VectorXd e = PredictMachining(m, tests, truth);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(0.0, 0.001);
  for (size_t i = 0; i < tests.size(); ++i) tests[i].measured = e[i] + noise(rng);
  MachiningOptions opt;
  opt.values = setup;
  opt.sigma = 0.001;
  const MachiningResult r = IdentifyMachining(m, tests, opt);
  EXPECT_TRUE(r.converged);
  ASSERT_EQ(r.estimated.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LT(std::abs(r.values[i] - truth[r.estimated[i]]), 3 * r.std[i]) << r.estimated[i];
    EXPECT_GT(r.std[i], 0);
  }
  EXPECT_LT(r.residuals.norm(), 1e-9);  // three tests, three unknowns
  // EZ0C and the workpiece's y set-up enter T2 and T3 only as a sum.
  opt.estimate = {"EA0C", "EZ0C", "workpiece.y"};
  EXPECT_THROW(IdentifyMachining(m, tests, opt), std::invalid_argument);
  // A machine without A and C axes.
  EXPECT_THROW(ZhangZhangTests(Machine::FromJson(MachineJson("hu40t").dump()), 150, 60), std::invalid_argument);
}

}  // namespace
}  // namespace fivecal
