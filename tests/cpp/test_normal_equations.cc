// The normal-equation fit path for long data (solve/normal_equations.h)
// against the dense path on the same datasets: the accumulated J^T J and
// J^T r, their independence of the thread count, the identical fit, and the
// refusal of an undetermined request.
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>

#include "fivecal/solve/identify.h"
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
    o.setup = "R1";
    o.axes = Eigen::VectorXd::Zero(m.num_axes());
    o.direction = Eigen::VectorXi::Zero(m.num_axes());
    o.axes[m.AxisIndex('A')] = -90 + 180 * u(rng);
    o.axes[m.AxisIndex('C')] = fixed_c ? 0.0 : 360 * u(rng);
    o.axes[m.AxisIndex('X')] = -20 + 40 * u(rng);
    o.axes[m.AxisIndex('Y')] = -20 + 40 * u(rng);
    o.axes[m.AxisIndex('Z')] = -20 + 40 * u(rng);
    o.tool_ball = Eigen::Vector3d(0, 0, 150);
    o.table_ball = Eigen::Vector3d(50, 0, 80);
    // Two declared noises: the unweighted J^T J is then not a multiple of the weighted one.
    if (second_instrument && i % 3 == 0) o.sigma = Eigen::VectorXd::Constant(3, 0.002);
    ds.observations.push_back(o);
  }
  std::vector<int> src;
  const Eigen::VectorXd r = PredictResiduals(ds, truth, &src);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) ds.observations[i].measured[c] = r[3 * i + c] + noise(rng);
  return ds;
}

const std::map<std::string, double> kTruth = {
    {"EB0A", 3e-5}, {"EA0C", 4e-5}, {"EB0C", -2e-5}, {"EY0C", -0.012}, {"ball3d.R1.table.x", 0.003}};

std::vector<int> Indices(const ParameterTable& t, const std::vector<std::string>& names) {
  std::vector<int> out;
  for (const std::string& n : names) out.push_back(t.Require(n));
  return out;
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
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    dense.Evaluate(&r, &J);
    const Eigen::VectorXd w = dense.row_sigma().cwiseInverse();
    const Eigen::MatrixXd Jw = w.asDiagonal() * J;
    const Eigen::VectorXd rw = w.asDiagonal() * r;
    const NormalEquationProblem ne(ds, table, v, est, 2);
    ASSERT_EQ(ne.num_rows(), dense.num_rows());
    const NormalEquations acc = ne.Accumulate(v, true);
    const Eigen::MatrixXd N = Jw.transpose() * Jw;
    const Eigen::MatrixXd Nu = J.transpose() * J;
    EXPECT_LT((acc.JtJ - N).norm(), 1e-12 * N.norm());
    EXPECT_LT((acc.JtJ_unweighted - Nu).norm(), 1e-12 * Nu.norm());
    EXPECT_LT((acc.Jtr - Jw.transpose() * rw).norm(), 1e-11 * (Jw.transpose() * rw).norm());
    EXPECT_NEAR(acc.cost, 0.5 * rw.squaredNorm(), 1e-12 * rw.squaredNorm());
    EXPECT_LT((ne.Residuals(v) - r).cwiseAbs().maxCoeff(), 1e-12);
    // The factor the analyses see: R^T R = N.
    const Eigen::MatrixXd R = NormalFactor(acc.JtJ);
    EXPECT_LT((R.transpose() * R - N).norm(), 1e-10 * N.norm());
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
  // own position does. Refused on the normal-equation path as on the dense one.
  const Dataset ds = RTest(20000, true, {{"EB0A", 3e-5}, {"EY0C", -0.012}}, 6);
  IdentifyOptions o;
  o.estimate = {"EB0A", "EY0C"};
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
