// The normal-equation fit path for long data (solve/normal_equations.h)
// against the dense path on the same datasets: the accumulated J^T J and
// J^T r, their independence of the thread count, the identical fit, and the
// refusal of an undetermined request.
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>

#include "fivecal/solve/identify.h"
#include "fivecal/solve/long_kernel.h"
#include "fivecal/solve/normal_equations.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

// R-test samples on the c600u (wCAfXYZSt): at random (A, C) the linear axes
// near the nest, displacements simulated at `truth` with noise.
// fixed_c: every sample at C = 0 (the C axis never turns).
Dataset RTest(int n, bool fixed_c, const std::map<std::string, double>& truth, unsigned seed = 1,
              bool second_instrument = false) {
  Dataset ds(Machine::Load(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/c600u.json"));
  const Machine& m = ds.machine();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 5e-4);
  for (int i = 0; i < n; ++i) {
    Observation o;
    o.type = ObservationType::kBall3d;
    o.payload = BallMountData{};
    o.setup = "R1";
    o.axes = Eigen::VectorXd::Zero(m.num_axes());
    o.direction = Eigen::VectorXi::Zero(m.num_axes());
    o.axes[m.AxisIndex('A')] = -90 + 180 * u(rng);
    o.axes[m.AxisIndex('C')] = fixed_c ? 0.0 : 360 * u(rng);
    o.axes[m.AxisIndex('X')] = -20 + 40 * u(rng);
    o.axes[m.AxisIndex('Y')] = -20 + 40 * u(rng);
    o.axes[m.AxisIndex('Z')] = -20 + 40 * u(rng);
    o.data<BallMountData>().tool_ball = Eigen::Vector3d(0, 0, 150);
    o.data<BallMountData>().table_ball = Eigen::Vector3d(50, 0, 80);
    // Two declared noises: the unweighted J^T J is then not a multiple of the weighted one.
    if (second_instrument && i % 3 == 0) o.sigma = Eigen::VectorXd::Constant(3, 0.002);
    ds.observations.push_back(o);
  }
  std::vector<int> src;
  const Eigen::VectorXd r = PredictResiduals(ds, truth, &src);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) ds.observations[i].data<BallMountData>().measured[c] = r[3 * i + c] + noise(rng);
  return ds;
}

const std::map<std::string, double> kTruth = {
    {"EB0A", 3e-5}, {"EA0C", 4e-5}, {"EB0C", -2e-5}, {"EY0C", -0.012}, {"ball3d.R1.table.x", 0.003}};

std::vector<int> Indices(const ParameterTable& t, const std::vector<std::string>& names) {
  std::vector<int> out;
  for (const std::string& n : names) out.push_back(t.Require(n));
  return out;
}

// The dense reference of an accumulation: residuals, Jacobian and weighted
// normal equations of the same rows from a Problem.
struct DenseSums {
  Eigen::VectorXd r, rw;
  Eigen::MatrixXd J, Jw, N;
};

DenseSums DenseReference(Problem& dense) {
  DenseSums d;
  dense.Evaluate(&d.r, &d.J);
  const Eigen::VectorXd w = dense.row_sigma().cwiseInverse();
  d.Jw = w.asDiagonal() * d.J;
  d.rw = w.asDiagonal() * d.r;
  d.N = d.Jw.transpose() * d.Jw;
  return d;
}

// The accumulated sums are the dense ones to rounding.
void ExpectSameSums(const NormalEquations& acc, const DenseSums& d) {
  const Eigen::MatrixXd Nu = d.J.transpose() * d.J;
  const Eigen::VectorXd g = d.Jw.transpose() * d.rw;
  EXPECT_LT((acc.JtJ - d.N).norm(), 1e-12 * d.N.norm());
  EXPECT_LT((acc.JtJ_unweighted - Nu).norm(), 1e-12 * Nu.norm());
  EXPECT_LT((acc.Jtr - g).norm(), 1e-11 * g.norm());
  EXPECT_NEAR(acc.cost, 0.5 * d.rw.squaredNorm(), 1e-12 * d.rw.squaredNorm());
}

TEST(NormalEquations, AccumulationEqualsDenseNormalMatrix) {
  for (bool two : {false, true}) {
    const Dataset ds = RTest(3000, false, kTruth, 2, two);
    const ParameterTable table(ds);
    const std::vector<int> est = Indices(
        table, {"EB0A", "EA0C", "EB0C", "EY0C", "EX0A", "ball3d.R1.table.x", "ball3d.R1.table.y", "ball3d.R1.table.z"});
    Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
    v[table.Require("EA0C")] = 1e-4;  // away from zero: a point of nonzero residuals
    v[table.Require("EY0C")] = 0.01;
    Problem dense(ds, table, v, est);
    const DenseSums d = DenseReference(dense);
    const NormalEquationProblem ne(ds, table, v, est, 2);
    ASSERT_EQ(ne.num_rows(), dense.num_rows());
    const NormalEquations acc = ne.Accumulate(v, true);
    ExpectSameSums(acc, d);
    EXPECT_LT((ne.Residuals(v) - d.r).cwiseAbs().maxCoeff(), 1e-12);
    // The factor the analyses see: R^T R = N.
    const Eigen::MatrixXd R = NormalFactor(acc.JtJ);
    EXPECT_LT((R.transpose() * R - d.N).norm(), 1e-10 * d.N.norm());
    // One Jacobian pass per accumulation, one residual pass per residual call.
    EXPECT_EQ(ne.jacobian_passes(), 1);
  }
}

TEST(NormalEquations, ThreadCountDoesNotChangeTheSums) {
  const Dataset ds = RTest(20000, false, kTruth, 3);
  const ParameterTable table(ds);
  const std::vector<int> est = Indices(table, {"EB0A", "EA0C", "EB0C", "EY0C", "ball3d.R1.table.x"});
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  v[table.Require("EB0C")] = 2e-5;
  const NormalEquations one = NormalEquationProblem(ds, table, v, est, 1).Accumulate(v);
  for (int threads : {2, 3, 7}) {
    const NormalEquations many = NormalEquationProblem(ds, table, v, est, threads).Accumulate(v);
    // Bitwise: the blocks and their order do not depend on the threads.
    EXPECT_EQ((many.JtJ - one.JtJ).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ((many.Jtr - one.Jtr).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ(many.cost, one.cost) << threads;
  }
}

// The same request both ways: values, sigma, covariance, chi2, verdict and
// residual statistics. cov: the relative tolerance of sigma and covariance.
void ExpectSameFit(const Result& d, const Result& s, double cov = 1e-8) {
  ASSERT_EQ(d.fit_path, "dense");
  ASSERT_EQ(s.fit_path, "normal_equations");
  ASSERT_EQ(d.estimated, s.estimated);
  const int p = static_cast<int>(d.estimated.size());
  for (int j = 0; j < p; ++j) {
    const int i = static_cast<int>(std::find(d.names.begin(), d.names.end(), d.estimated[j]) - d.names.begin());
    EXPECT_LT(std::abs(d.values[i] - s.values[i]), 1e-9 * d.std[j]) << d.estimated[j];
    EXPECT_NEAR(s.std[j], d.std[j], cov * d.std[j]) << d.estimated[j];
  }
  const Eigen::MatrixXd dc = d.covariance, sc = s.covariance;
  for (int a = 0; a < p; ++a)
    for (int b = 0; b < p; ++b)
      EXPECT_LT(std::abs(dc(a, b) - sc(a, b)), cov * std::sqrt(dc(a, a) * dc(b, b))) << a << "," << b;
  EXPECT_NEAR(s.chi2, d.chi2, 1e-9 * d.chi2);
  EXPECT_EQ(s.dof, d.dof);
  EXPECT_EQ(s.rank, d.rank);
  EXPECT_EQ(s.verdict(), d.verdict());
  EXPECT_EQ(s.converged, d.converged);
  EXPECT_NEAR(s.rms, d.rms, 1e-9 * d.rms);
  EXPECT_NEAR(s.max_abs, d.max_abs, 1e-9 * d.max_abs);
  EXPECT_NEAR(s.sigma, d.sigma, 1e-9 * d.sigma);
  EXPECT_NEAR(s.condition_number, d.condition_number, 1e-6 * d.condition_number);
  EXPECT_EQ(s.n_observations, d.n_observations);
  EXPECT_EQ(s.residual_source, d.residual_source);
  EXPECT_LT((s.residuals - d.residuals).cwiseAbs().maxCoeff(), 1e-9 * d.rms);
  EXPECT_EQ(s.undetermined, d.undetermined);
  EXPECT_NEAR(s.final_cost, d.final_cost, 1e-9 * d.final_cost);
  EXPECT_NEAR(s.initial_cost, d.initial_cost, 1e-9 * d.initial_cost);
}

TEST(NormalEquations, SameFitAsTheDensePath) {
  for (bool two : {false, true}) {
    const Dataset ds = RTest(10000, false, kTruth, 4, two);
    IdentifyOptions o;
    o.estimate = {"EB0A", "EA0C", "EB0C", "EY0C"};
    o.fit_path = "dense";
    const Result d = Identify(ds, o);
    o.fit_path = "normal_equations";
    o.num_threads = 2;
    const Result s = Identify(ds, o);
    EXPECT_EQ(d.verdict(), "ok");
    ExpectSameFit(d, s);
  }
}

TEST(NormalEquations, SameMapFitAsTheDensePath) {
  // prior = true: the prior rows join the normal equations. EZ0C and the
  // nest's z are exactly confounded here, so the posterior in that direction
  // is the prior's; the normal matrix carries rounding of about eps |N|
  // (prior units, |N| ~ rows (prior / noise)^2) into it, where the dense QR
  // carries eps |Jw|: 1e-7 relative at these 30000 rows, hence 1e-6 here.
  const Dataset ds = RTest(10000, false, kTruth, 5);
  IdentifyOptions o;
  o.estimate = {"EB0A", "EA0C", "EB0C", "EY0C", "EX0A", "EZ0C"};
  o.prior = true;
  o.fit_path = "dense";
  const Result d = Identify(ds, o);
  o.fit_path = "normal_equations";
  const Result s = Identify(ds, o);
  ExpectSameFit(d, s, 1e-6);
  EXPECT_TRUE(s.map_fit);
}

TEST(NormalEquations, AutomaticallyForLongDataOnly) {
  IdentifyOptions o;
  o.estimate = {"EB0A", "EA0C", "EB0C", "EY0C"};
  EXPECT_EQ(Identify(RTest(2000, false, kTruth), o).fit_path, "dense");
  // 200000 samples x 3 rows x 7 unknowns (with the nest) = 4.2e6 > kNormalEquationElements.
  EXPECT_EQ(Identify(RTest(200000, false, kTruth), o).fit_path, "normal_equations");
  // What it cannot do falls back (auto) or is refused (forced).
  o.robust = "huber";
  const Dataset ds = RTest(2000, false, kTruth);
  EXPECT_EQ(Identify(ds, o).fit_path, "dense");
  o.fit_path = "normal_equations";
  EXPECT_THROW(Identify(ds, o), std::invalid_argument);
}

TEST(NormalEquations, UndeterminedLongDataRefused) {
  // The C axis never turns: its position EY0C moves the nest as the nest's
  // own position does. With the nest's placement prior (50 um) EY0C is known
  // only as well as the placement, half its plausible size: not determined,
  // refused on both paths. With the set-up taken as exact the refusal names
  // the nest too, on the normal-equation path as on the dense one.
  const Dataset ds = RTest(20000, true, {{"EB0A", 3e-5}, {"EY0C", -0.012}}, 6);
  IdentifyOptions o;
  o.estimate = {"EB0A", "EY0C"};
  for (const char* path : {"dense", "normal_equations"}) {
    o.fit_path = path;
    try {
      Identify(ds, o);
      ADD_FAILURE() << path << ": EY0C, known only to the nest's placement, was fitted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("{EY0C}"), std::string::npos) << path << ": " << e.what();
    }
  }
  o.setup_priors = false;
  for (const char* path : {"dense", "normal_equations"}) {
    o.fit_path = path;
    try {
      Identify(ds, o);
      ADD_FAILURE() << path << ": an undetermined request was fitted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("EY0C"), std::string::npos) << path << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find("ball3d.R1.table.y"), std::string::npos) << path << ": " << e.what();
    }
  }
  // Allowed: the fit runs and names the group; both paths agree on it.
  o.allow_unidentifiable = true;
  o.fit_path = "dense";
  const Result d = Identify(ds, o);
  o.fit_path = "normal_equations";
  const Result s = Identify(ds, o);
  EXPECT_EQ(s.verdict(), "undetermined");
  EXPECT_EQ(s.undetermined, d.undetermined);
  EXPECT_EQ(s.unidentifiable, d.unidentifiable);
  EXPECT_LT(s.rank, static_cast<int>(s.estimated.size()));
}

}  // namespace
}  // namespace fivecal

namespace fivecal {
namespace {

TEST(NormalEquations, DerivativesOnlyAtAcceptedPoints) {
  // The dense fit of a nearly linear problem evaluated the whole Jacobian at
  // every candidate and again for the analyses; here a pass with derivatives
  // is made only where the fit steps from, candidates get their cost alone.
  const Dataset ds = RTest(5000, false, kTruth, 7);
  const ParameterTable table(ds);
  const std::vector<int> est = Indices(table, {"EB0A", "EA0C", "EB0C", "EY0C", "ball3d.R1.table.x",
                                               "ball3d.R1.table.y", "ball3d.R1.table.z"});
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(table.size());
  const NormalEquationProblem pr(ds, table, zero, est, 2);
  const NormalEquationFit f = FitNormalEquations(pr, zero, Eigen::VectorXd(), 200);
  EXPECT_TRUE(f.converged) << f.message;
  // Every step is a good one here: derivatives at the start and at each
  // taken candidate, the cost alone at each candidate; at most one pass of
  // each per iteration.
  EXPECT_LE(f.iterations, 4);
  EXPECT_GE(pr.jacobian_passes(), 2);
  EXPECT_LE(pr.jacobian_passes(), f.iterations);
  EXPECT_LE(pr.residual_passes() - pr.jacobian_passes(), f.iterations);
  EXPECT_NEAR(f.values[table.Require("EY0C")], -0.012, 1e-4);
}

}  // namespace
}  // namespace fivecal

#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

// A Monte Carlo trial's edit of the readings of any kind's observation (its
// payload's recorded values moved by draws).
template <class Draw>
void MoveReadings(Observation* o, Draw&& draw) {
  std::visit(
      [&](auto& d) {
        using D = std::decay_t<decltype(d)>;
        if constexpr (std::is_same_v<D, BallMountData>) {
          d.reading += draw();
          for (int c = 0; c < 3; ++c) d.measured[c] += draw();
        } else if constexpr (std::is_same_v<D, PointData>) {
          for (int c = 0; c < 3; ++c) d.measured[c] += draw();
        } else if constexpr (std::is_same_v<D, PoseTargetData>) {
          for (int c = 0; c < 3; ++c) d.measured[c] += draw(), d.measured_rotation[c] += 0.01 * draw();
        } else if constexpr (std::is_same_v<D, DistanceData>) {
          d.reading += draw();
        } else if constexpr (std::is_same_v<D, MachinedData>) {
          d.measured += draw();
        }
      },
      o->payload);
}

// Observations of every registered kind on the c600u, several of each,
// interleaved (analytic and templated rows alternate), with the scale bar
// whose rows follow the observations.
Dataset EveryKind() {
  std::ifstream f(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/c600u.json");
  nlohmann::json spec;
  f >> spec["machine"];
  spec["probe"] = {{"tip_radius", 3.0}};
  spec["artefact"] = nlohmann::json::parse(R"({
    "spheres": [{"id": "S1", "center": [60, 40, 30], "radius": 12.5},
                {"id": "S2", "center": [-60, 40, 30], "radius": 12.5}],
    "scale_bars": [{"spheres": ["S1", "S2"], "length": 120}],
    "facets": [{"id": "F1", "point": [0, 0, 0], "normal": [0, 0, 1]}],
    "cylinders": [{"id": "K1", "point": [0, 0, 0], "axis": [0, 0, 1], "radius": 80}]})");
  spec["errors"] = {{"EX0C", 0.01}, {"EA0C", 2e-5}, {"EB0A", -3e-5}};
  spec["sigma"] = {{"probe", 0.001}, {"dbb", 0.0005}, {"ball3d", 0.001}, {"point", 0.005},
                   {"pose", 0.01},   {"pose_angle", 1e-4}, {"distance", 0.001}, {"machined", 0.003}};
  spec["seed"] = 3;
  nlohmann::json plan = nlohmann::json::array();
  // The tool tip on (100, 0, 0) of the workpiece at A = -20 i, C = 40 i
  // (Machine.inverse): the ball bar's balls 150 mm apart there.
  const double xyz[4][3] = {{100, 0, -150}, {76.6044, -60.4023, -171.9846}, {17.3648, -75.4407, -213.3022},
                            {-50, -43.3013, -225}};
  for (int i = 0; i < 4; ++i) {
    const double a = -20.0 * i, c = 40.0 * i;
    const nlohmann::json rot = {{"A", a}, {"C", c}, {"S", 0}};
    const nlohmann::json full = {{"X", xyz[i][0]}, {"Y", xyz[i][1]}, {"Z", xyz[i][2]}, {"A", a}, {"C", c}, {"S", 0}};
    plan.push_back({{"type", "sphere"}, {"target", i % 2 ? "S1" : "S2"}, {"axes", rot}, {"normal", {0.3 * i, 0, 1}}});
    plan.push_back({{"type", "point"}, {"instrument", "T1"}, {"target", "work"}, {"target_point", {100, 0, 20}},
                    {"axes", full}, {"instrument_origin", {1500, -800, 300}}, {"instrument_angles", {0.5, -1, 30}}});
    plan.push_back({{"type", "facet"}, {"target", "F1"}, {"axes", rot}, {"point", {10.0 + 5 * i, 5, 0}}});
    plan.push_back({{"type", "pose"}, {"instrument", "CAM"}, {"target", "work"}, {"target_point", {100, 0, 20}},
                    {"target_rotation", {0.1, 0, 0}}, {"axes", full}, {"instrument_origin", {0, -900, 300}},
                    {"instrument_angles", {0, 0, 90}}});
    plan.push_back({{"type", "cylinder"}, {"target", "K1"}, {"axes", rot}, {"point", {80, 0, 10.0 + i}}});
    plan.push_back({{"type", "distance"}, {"station", "L1"}, {"instrument", "LT2"}, {"target", "tool"},
                    {"target_point", {0, 0, 150}}, {"axes", full}, {"station_position", {900, -700, 150}},
                    {"dead_length", 200.0}});
    plan.push_back({{"type", "dbb"}, {"setup", "D1"}, {"axes", full}, {"length", 150.0}, {"tool_ball", {0, 0, 150}},
                    {"table_ball", {100, 0, 150}}});
    plan.push_back({{"type", "machined"}, {"part", "P1"}, {"feature", "face"}, {"axes", rot},
                    {"point", {0, 150, 60}}, {"normal", {0, 0, 1}}});
    plan.push_back({{"type", "ball3d"}, {"setup", "R1"}, {"axes", full}, {"tool_ball", {0, 0, 150}},
                    {"table_ball", {100, 0, 0}}});
  }
  spec["plan"] = plan;
  return Simulate(spec.dump());
}

TEST(NormalEquations, EveryKindAccumulatesTheDenseNormalEquations) {
  const Dataset ds = EveryKind();
  // A kind registered later without a sample here fails.
  std::set<const ObservationKind*> present;
  for (const Observation& o : ds.observations) present.insert(&KindOf(o));
  for (const ObservationKind* k : ObservationKinds()) EXPECT_TRUE(present.count(k)) << "no sample of " << k->name();
  const ParameterTable table(ds);
  // Every parameter estimated, at a point away from zero: every column of
  // every kind (machine, setup, artefact) is compared.
  std::mt19937 rng(2);
  std::normal_distribution<double> n01(0.0, 1.0);
  Eigen::VectorXd v(table.size());
  for (int i = 0; i < table.size(); ++i) v[i] = (i < ds.machine().num_parameters() ? 1e-6 : 1e-3) * n01(rng);
  std::vector<int> all(table.size());
  for (int i = 0; i < table.size(); ++i) all[i] = i;
  // The dense reference: the templated functors, one Ceres block each.
  Problem dense(ds, table, v, all, "", 0.0, false);
  const DenseSums d = DenseReference(dense);
  const Eigen::VectorXd& r = d.r;
  const Eigen::MatrixXd& Jw = d.Jw;
  const Eigen::MatrixXd& N = d.N;
  const NormalEquationProblem one(ds, table, v, all, 1);
  ASSERT_EQ(one.num_rows(), dense.num_rows());
  EXPECT_EQ(one.row_source(), dense.row_source());
  EXPECT_LT((one.row_sigma() - dense.row_sigma()).cwiseAbs().maxCoeff(), 1e-15);
  const NormalEquations acc = one.Accumulate(v, true);
  ExpectSameSums(acc, d);
  EXPECT_LT((one.Residuals(v) - r).cwiseAbs().maxCoeff(), 1e-12);
  // The pose's rotation rows: their own J^T J, for the residual summary per unit.
  ASSERT_EQ(one.other_units(), std::vector<std::string>{"rad"});
  Eigen::MatrixXd Nrad = Eigen::MatrixXd::Zero(N.rows(), N.cols());
  int rad_rows = 0;
  for (int i = 0, k = 0; i < r.size(); ++i) {
    const int s = dense.row_source()[i];
    k = (i > 0 && s == dense.row_source()[i - 1]) ? k + 1 : 0;
    if (s >= 0 && std::string(KindOf(ds.observations[s]).unit_row(k)) == "rad") {
      Nrad += Jw.row(i).transpose() * Jw.row(i);
      ++rad_rows;
    }
  }
  EXPECT_EQ(rad_rows, 12);
  EXPECT_LT((acc.JtJ_units[0] - Nrad).norm(), 1e-12 * Nrad.norm());
  // Threads: the same sums, bitwise (the templated rows evaluate on each thread).
  for (int threads : {2, 3}) {
    const NormalEquations many = NormalEquationProblem(ds, table, v, all, threads).Accumulate(v, true);
    EXPECT_EQ((many.JtJ - acc.JtJ).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ((many.Jtr - acc.Jtr).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ((many.JtJ_units[0] - acc.JtJ_units[0]).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ(many.cost, acc.cost) << threads;
  }
}

TEST(NormalEquations, MixedKindsSameFitAsTheDensePath) {
  // A well-posed fit of interleaved touches, tracker points, poses and
  // distances: values, covariance, costs, residuals and per-unit sigma.
  const Dataset ds = EveryKind();
  IdentifyOptions o;
  o.estimate = {"EX0C", "EA0C", "EB0A"};
  o.include_default_setup = false;
  o.fit_path = "dense";
  const Result d = Identify(ds, o);
  ASSERT_EQ(d.residual_units.size(), 2u);
  for (int threads : {1, 2}) {
    o.fit_path = "normal_equations";
    o.num_threads = threads;
    const Result s = Identify(ds, o);
    ExpectSameFit(d, s);
    ASSERT_EQ(s.residual_units.size(), 2u);
    for (size_t u = 0; u < 2; ++u) {
      EXPECT_EQ(s.residual_units[u].unit, d.residual_units[u].unit);
      EXPECT_NEAR(s.residual_units[u].dof, d.residual_units[u].dof, 1e-9 * d.residual_units[u].dof);
      EXPECT_NEAR(s.residual_units[u].sigma, d.residual_units[u].sigma, 1e-9 * d.residual_units[u].sigma);
    }
  }
}

TEST(NormalEquations, TheBatchOfEveryKindRefreshes) {
  // The dense path's Problem holds the same batch: a Monte Carlo trial edits
  // the readings in place and refreshes it, templated kinds included (their
  // functors captured the readings, so they are recorded again).
  Dataset ds = EveryKind();
  const ParameterTable table(ds);
  std::vector<int> est;
  for (const char* n : {"EX0C", "EA0C", "EB0A", "instrument.T1.x", "instrument.CAM.c", "instrument.L1.length",
                        "machined.P1.z", "facet.F1", "dbb.D1.length", "ball3d.R1.table.x"})
    est.push_back(table.Require(n));
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  Problem pr(ds, table, v, est);
  std::mt19937 rng(4);
  std::normal_distribution<double> n01(0.0, 1e-3);
  for (Observation& o : ds.observations) {
    MoveReadings(&o, [&] { return n01(rng); });
    o.axes[0] += n01(rng);
  }
  for (int i : est) v[i] = n01(rng);
  ASSERT_TRUE(pr.Refresh(v));
  Problem fresh(ds, table, v, est);
  Eigen::VectorXd r1, r2;
  Eigen::MatrixXd J1, J2;
  pr.Evaluate(&r1, &J1);
  fresh.Evaluate(&r2, &J2);
  EXPECT_EQ((r1 - r2).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((J1 - J2).cwiseAbs().maxCoeff(), 0.0);
}

TEST(NormalEquations, LongTrackerDataTakeTheStreamingPath) {
  // A tracker stream (the templated point kind), rows x unknowns above
  // kNormalEquationElements: "auto" takes the normal equations. One
  // simulated reading per target copied over random poses.
  nlohmann::json spec;
  std::ifstream f(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/c600u.json");
  f >> spec["machine"];
  spec["plan"] = nlohmann::json::parse(R"([{"type": "point", "instrument": "T1", "target": "work",
    "target_point": [100, 0, 20], "axes": {"X": 0, "Y": 0, "Z": 0, "A": 0, "C": 0, "S": 0},
    "instrument_origin": [1500, -800, 300], "instrument_angles": [0.01, -0.02, 0.5]},
    {"type": "point", "instrument": "T1", "target": "tool",
    "target_point": [0, 0, 150], "axes": {"X": 0, "Y": 0, "Z": 0, "A": 0, "C": 0, "S": 0},
    "instrument_origin": [1500, -800, 300], "instrument_angles": [0.01, -0.02, 0.5]}])");
  Dataset ds = Simulate(spec.dump());
  const Observation work = ds.observations[0], tool = ds.observations[1];
  const Machine& m = ds.machine();
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 0.005);
  const int n = 60000;
  ds.observations.assign(n, work);
  for (int i = 1; i < n; i += 2) ds.observations[i] = tool;
  for (Observation& o : ds.observations) {
    o.axes[m.AxisIndex('A')] = -90 * u(rng);
    o.axes[m.AxisIndex('C')] = 360 * u(rng);
    for (char a : {'X', 'Y', 'Z'}) o.axes[m.AxisIndex(a)] = -100 + 200 * u(rng);
    o.data<PointData>().measured.setZero();
  }
  const std::map<std::string, double> truth = {{"EB0A", 3e-5}, {"EA0C", 4e-5}, {"EY0C", -0.012},
                                               {"instrument.T1.x", 0.2}};
  std::vector<int> src;
  const Eigen::VectorXd r = PredictResiduals(ds, truth, &src);  // predicted - 0
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) ds.observations[i].data<PointData>().measured[c] = r[3 * i + c] + noise(rng);
  IdentifyOptions o;
  o.estimate = {"EB0A", "EA0C", "EY0C"};
  // The tool reflector's offsets move it as the tracker's position does
  // (no rotary axis carries the tool): known.
  o.fix = {"instrument.T1.tool_x", "instrument.T1.tool_y", "instrument.T1.tool_z"};
  o.num_threads = 2;
  const Result s = Identify(ds, o);  // auto
  EXPECT_GT(3.0 * n * s.estimated.size(), kNormalEquationElements);
  EXPECT_EQ(s.fit_path, "normal_equations");
  EXPECT_EQ(s.verdict(), "ok");
  // (The same fit as the dense path's is shown on short data of every kind
  // above and in test_long_data_fit.py; the dense fit here would take twice
  // as long as this one.)
  for (size_t j = 0; j < s.estimated.size(); ++j) {
    const auto it = truth.find(s.estimated[j]);
    const double want = it == truth.end() ? 0.0 : it->second;
    const int k = static_cast<int>(std::find(s.names.begin(), s.names.end(), s.estimated[j]) - s.names.begin());
    EXPECT_LT(std::abs(s.values[k] - want), 4 * s.std[j]) << s.estimated[j];
  }
}

}  // namespace
}  // namespace fivecal

#include "fivecal/solve/analytic_residuals.h"

namespace fivecal {
namespace {

// A batch evaluated whole (AnalyticResiduals::Evaluate, as Ceres calls it).
void EvaluateBatch(const AnalyticResiduals& b, const Eigen::VectorXd& v, const std::vector<int>& est,
                   Eigen::VectorXd* r, Eigen::MatrixXd* J) {
  std::vector<const double*> params;
  for (int i : est) params.push_back(&v[i]);
  r->resize(b.num_residuals());
  *J = Eigen::MatrixXd::Zero(b.num_residuals(), est.size());
  std::vector<double*> cols;
  for (size_t c = 0; c < est.size(); ++c) cols.push_back(J->col(c).data());
  ASSERT_TRUE(b.Evaluate(params.data(), r->data(), cols.data()));
}

// The held and the per-chunk batch evaluate the same rows to the same bits.
void ExpectSameRows(const AnalyticResiduals& all, const AnalyticResiduals& chunk, const Eigen::VectorXd& v,
                    const std::vector<int>& est, int round) {
  Eigen::VectorXd r1, r2;
  Eigen::MatrixXd J1, J2;
  EvaluateBatch(all, v, est, &r1, &J1);
  EvaluateBatch(chunk, v, est, &r2, &J2);
  EXPECT_EQ((r1 - r2).cwiseAbs().maxCoeff(), 0.0) << round;
  EXPECT_EQ((J1 - J2).cwiseAbs().maxCoeff(), 0.0) << round;
}

TEST(NormalEquations, PassesHoldAChunkOfPreparedRowsPerThread) {
  // Interleaved kinds of every sort, then a long R-test trace: the streaming
  // passes prepare the analytic rows a chunk at a time, so the prepared rows
  // alive never exceed the held ones (templated kinds, scale bar) plus a
  // chunk per thread, whatever the data's length.
  Dataset ds = EveryKind();
  const int templated_and_artefact = [&] {
    int k = 0;
    for (const Observation& o : ds.observations) k += KindOf(o).analytic() ? 0 : 1;
    return k + 1;  // the scale bar
  }();
  const Dataset trace = RTest(20000, false, kTruth, 5);
  ds.observations.insert(ds.observations.end(), trace.observations.begin(), trace.observations.end());
  const ParameterTable table(ds);
  std::vector<int> est;
  for (const char* n : {"EX0C", "EA0C", "EB0A", "EB0C", "EY0C", "instrument.T1.x", "instrument.CAM.c",
                        "instrument.L1.length", "machined.P1.z", "facet.F1", "dbb.D1.length", "ball3d.R1.table.x",
                        "sphere.S1.x"})
    est.push_back(table.Require(n));
  std::mt19937 rng(6);
  std::normal_distribution<double> n01(0.0, 1e-5);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (int i : est) v[i] = n01(rng);

  const int64_t before = PreparedRowsAlive();
  ResetPreparedRowsPeak();
  {
    const NormalEquationProblem ne(ds, table, v, est, 2);
    EXPECT_EQ(PreparedRowsAlive() - before, templated_and_artefact);
    const NormalEquations acc = ne.Accumulate(v, true);
    Eigen::VectorXd w = v;
    w[est[0]] += 1e-6;
    ne.Cost(w);
    ne.Residuals(w);
    const int64_t peak = PreparedRowsPeak() - before;
    EXPECT_GT(peak, templated_and_artefact);  // rows were prepared, and counted
    EXPECT_LE(peak, templated_and_artefact + 2 * kPreparedChunk);
    // The sums are those of the dense path, which holds every row.
    ResetPreparedRowsPeak();
    Problem dense(ds, table, v, est);
    EXPECT_GE(PreparedRowsPeak() - before, static_cast<int64_t>(ds.observations.size()));
    ExpectSameSums(acc, DenseReference(dense));
  }
  EXPECT_EQ(PreparedRowsAlive(), before);

  // Both storages evaluate the same rows to the same bits, and refresh alike.
  AnalyticResiduals all(ds, table, v, est, RowStorage::kAll);
  AnalyticResiduals chunk(ds, table, v, est, RowStorage::kPerChunk);
  EXPECT_EQ(static_cast<int>(all.rows().size()), static_cast<int>(ds.observations.size()) + 1);
  EXPECT_EQ(static_cast<int>(chunk.rows().size()), templated_and_artefact);
  EXPECT_EQ(all.num_prepared(), chunk.num_prepared());
  EXPECT_EQ(all.row_source(), chunk.row_source());
  for (int round = 0; round < 2; ++round) {
    ExpectSameRows(all, chunk, v, est, round);
    // Readings and axes edited in place, then refreshed.
    for (Observation& o : ds.observations) {
      MoveReadings(&o, [&] { return n01(rng); });
      o.axes[0] += n01(rng);
    }
    all.Refresh(table, v);
    chunk.Refresh(table, v);
  }
}

TEST(NormalEquations, PerChunkRowsFollowTheSetupOfEachSample) {
  // Rows prepared per chunk take a sample's mounting from the row before
  // when the setup id is the same: with the setup changing inside chunks,
  // and again after the setups are edited in place and refreshed, the rows
  // are those of the held batch, which looks every one up.
  Dataset ds = RTest(1500, false, kTruth, 7);
  const char* setups[3] = {"R1", "R2", ""};
  std::mt19937 rng(8);
  std::uniform_int_distribution<int> pick(0, 2);
  std::bernoulli_distribution change(0.2);
  int s = 0;
  for (Observation& o : ds.observations) {
    if (change(rng)) s = pick(rng);
    o.setup = setups[s];
  }
  const ParameterTable table(ds);
  std::vector<int> est;
  for (const char* n : {"EB0A", "EA0C", "ball3d.R1.table.x", "ball3d.R1.table.y", "ball3d.R2.table.x",
                        "ball3d.R2.tool.y", "ball3d.tool.z", "ball3d.table.z"})
    est.push_back(table.Require(n));
  std::normal_distribution<double> n01(0.0, 1e-2);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (int i = 0; i < table.size(); ++i) v[i] = 1e-3 * n01(rng);  // fixed ones too: every offset enters
  for (int i : est) v[i] = n01(rng);
  AnalyticResiduals all(ds, table, v, est, RowStorage::kAll);
  AnalyticResiduals chunk(ds, table, v, est, RowStorage::kPerChunk);
  for (int round = 0; round < 2; ++round) {
    ExpectSameRows(all, chunk, v, est, round);
    // The streaming sums see the same rows.
    const NormalEquationProblem ne(ds, table, v, est, 2);
    Problem dense(ds, table, v, est);
    ExpectSameSums(ne.Accumulate(v, true), DenseReference(dense));
    // Setups edited in place (same ids: the table stays), then refreshed.
    for (size_t i = 0; i < ds.observations.size(); i += 3) {
      std::string& id = ds.observations[i].setup;
      id = id == "R1" ? "R2" : id == "R2" ? "" : "R1";
    }
    all.Refresh(table, v);
    chunk.Refresh(table, v);
  }
}

}  // namespace
}  // namespace fivecal

namespace fivecal {
namespace {

// A trace of ball-bar samples and one of R-test samples, each over two
// mountings, some samples with recorded move directions (the backlash).
Dataset TwoTraces(int n) {
  Dataset ds(Machine::Load(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/c600u.json"));
  const Machine& m = ds.machine();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int kind = 0; kind < 2; ++kind)
    for (int i = 0; i < n; ++i) {
      Observation o;
      o.type = kind == 0 ? ObservationType::kDbb : ObservationType::kBall3d;
      o.payload = BallMountData{};
      o.setup = i < n / 2 ? "A" : "B";
      o.axes = Eigen::VectorXd::Zero(m.num_axes());
      o.direction = Eigen::VectorXi::Zero(m.num_axes());
      o.axes[m.AxisIndex('A')] = -90 + 180 * u(rng);
      o.axes[m.AxisIndex('C')] = 360 * u(rng);
      o.axes[m.AxisIndex('X')] = -20 + 40 * u(rng);
      o.axes[m.AxisIndex('Y')] = -20 + 40 * u(rng);
      o.axes[m.AxisIndex('Z')] = -20 + 40 * u(rng);
      if (i % 4 == 1) o.direction[m.AxisIndex('C')] = i % 8 == 1 ? 1 : -1;
      BallMountData& b = o.data<BallMountData>();
      b.tool_ball = Eigen::Vector3d(0, 0, 150);
      b.table_ball = o.setup == "A" ? Eigen::Vector3d(50, 0, 80) : Eigen::Vector3d(0, 60, 70);
      b.length = 100.0;
      b.reading = 1e-3 * u(rng);
      b.measured = Eigen::Vector3d(1e-3 * u(rng), 0, -1e-3);
      if (i % 5 == 0) o.sigma = Eigen::VectorXd::Constant(ResidualRows(o.type), 0.002);
      ds.observations.push_back(o);
    }
  return ds;
}

// The column kernels' derivatives against central differences of their own
// residuals, at a point away from zero, for machine, tool-ball, table-ball
// and bar-length columns and a backlash.
TEST(LongKernel, JacobianMatchesFiniteDifferences) {
  const Dataset ds = TwoTraces(400);
  const ParameterTable table(ds);
  const std::vector<int> est = Indices(
      table, {"EB0A", "EA0C", "EB0C", "EY0C", "ECCb", "EXX1", "tip.x", "dbb.A.length", "dbb.B.tool.z",
              "dbb.A.table.x", "ball3d.B.tool.x", "ball3d.A.table.y", "ball3d.B.table.z"});
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  std::mt19937 rng(9);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (int i : est) v[i] = (i < ds.machine().num_parameters() ? 1e-4 : 1e-2) * n01(rng);
  const NormalEquationProblem ne(ds, table, v, est, 2);
  ASSERT_TRUE(ne.columnar());
  const NormalEquations acc = ne.Accumulate(v, true);
  const int p = static_cast<int>(est.size());
  Eigen::MatrixXd J(ne.num_rows(), p);
  for (int j = 0; j < p; ++j) {
    const double h = est[j] < ds.machine().num_parameters() ? 1e-7 : 1e-6;
    Eigen::VectorXd a = v, b = v;
    a[est[j]] += h;
    b[est[j]] -= h;
    J.col(j) = (ne.Residuals(a) - ne.Residuals(b)) / (2 * h);
  }
  const Eigen::VectorXd w = ne.row_sigma().cwiseInverse();
  const Eigen::MatrixXd Jw = w.asDiagonal() * J;
  const Eigen::MatrixXd N = Jw.transpose() * Jw;
  const Eigen::VectorXd g = Jw.transpose() * (w.asDiagonal() * ne.Residuals(v));
  // Column by column (relative to the column's scale): a wrong or missing
  // column shows however small its neighbours are.
  // The probe tip does not carry a ball: its column is zero (index 6).
  EXPECT_EQ(N(6, 6), 0.0);
  EXPECT_EQ(acc.JtJ.row(6).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(acc.Jtr[6], 0.0);
  for (int j = 0; j < p; ++j) {
    if (j == 6) continue;
    const double s = std::sqrt(N(j, j));
    ASSERT_GT(s, 0.0) << table.names()[est[j]];
    for (int k = 0; k < p; ++k) {
      if (k == 6) continue;
      const double sk = s * std::sqrt(N(k, k));
      EXPECT_NEAR(acc.JtJ(j, k) / sk, N(j, k) / sk, 1e-6) << table.names()[est[j]] << " x " << table.names()[est[k]];
    }
    EXPECT_NEAR(acc.Jtr[j] / s, g[j] / s, 1e-6 * (1 + std::abs(g[j] / s))) << table.names()[est[j]];
  }
  // The unweighted sums (two declared noises): J^T J in mm.
  EXPECT_LT((acc.JtJ_unweighted - J.transpose() * J).norm(), 1e-6 * (J.transpose() * J).norm());
}

// Threads change which thread sums a block, not the sums.
TEST(LongKernel, ThreadCountDoesNotChangeTheSums) {
  const Dataset ds = TwoTraces(30000);
  const ParameterTable table(ds);
  const std::vector<int> est = Indices(table, {"EB0A", "EA0C", "EB0C", "EY0C", "dbb.A.length", "ball3d.B.table.z"});
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  v[table.Require("EB0C")] = 2e-5;
  const NormalEquationProblem one(ds, table, v, est, 1);
  ASSERT_TRUE(one.columnar());
  const NormalEquations a = one.Accumulate(v, true);
  for (int threads : {2, 3, 8}) {
    const NormalEquations b = NormalEquationProblem(ds, table, v, est, threads).Accumulate(v, true);
    EXPECT_EQ((b.JtJ - a.JtJ).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ((b.Jtr - a.Jtr).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ((b.JtJ_unweighted - a.JtJ_unweighted).cwiseAbs().maxCoeff(), 0.0) << threads;
    EXPECT_EQ(b.cost, a.cost) << threads;
  }
}

// The SIMD accumulation against the plain sums, at every padded width.
TEST(LongKernel, AccumulateNormalEqualsPlainSums) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n01(0.0, 1.0);
  for (int p : {1, 4, 8, 9, 17, 30, 33}) {
    const int ld = PaddedWidth(p), m = 77;
    std::vector<double> J(static_cast<size_t>(m) * ld, 0.0), r(m), N(static_cast<size_t>(p) * ld, 0.0), g(p, 0.0);
    Eigen::MatrixXd Je(m, p);
    for (int i = 0; i < m; ++i) {
      r[i] = n01(rng);
      for (int j = 0; j < p; ++j) Je(i, j) = J[static_cast<size_t>(i) * ld + j] = n01(rng);
    }
    AccumulateNormal(J.data(), r.data(), m, p, ld, N.data(), g.data());
    const Eigen::MatrixXd Ne = Je.transpose() * Je;
    const Eigen::VectorXd ge = Je.transpose() * Eigen::Map<Eigen::VectorXd>(r.data(), m);
    for (int a = 0; a < p; ++a) {
      for (int b = 0; b < p; ++b) EXPECT_NEAR(N[static_cast<size_t>(a) * ld + b], Ne(a, b), 1e-12 * m) << p;
      for (int b = p; b < ld; ++b) EXPECT_EQ(N[static_cast<size_t>(a) * ld + b], 0.0) << p;
      EXPECT_NEAR(g[a], ge[a], 1e-12 * m) << p;
    }
  }
  EXPECT_NE(std::string(NormalKernelIsa()), "");
}

// Data with a kind that has no column kernel keep the prepared rows.
TEST(LongKernel, MixedDataKeepThePreparedRows) {
  const Dataset traces = TwoTraces(50);
  const ParameterTable t0(traces);
  EXPECT_TRUE(NormalEquationProblem(traces, t0, Eigen::VectorXd::Zero(t0.size()), Indices(t0, {"EB0A"}), 1).columnar());
  const Dataset mixed = EveryKind();
  const ParameterTable t1(mixed);
  EXPECT_FALSE(NormalEquationProblem(mixed, t1, Eigen::VectorXd::Zero(t1.size()), Indices(t1, {"EB0A"}), 1).columnar());
}

}  // namespace
}  // namespace fivecal
