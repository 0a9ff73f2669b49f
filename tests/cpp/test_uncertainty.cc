// Uncertainty tests: simulation plans (noise re-draws), Monte Carlo
// determinism, coverage intervals and numerical tolerance (JCGM 101),
// distribution quantiles, pooled covariance and GUM propagation (hand
// computed), the sensitivity matrix against re-fits, and the probing
// statistics of thesis eqs. 4-9 to 4-16 and 7-1 on a hand-computed grid.
#include <gtest/gtest.h>

#include "test_files.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "fivecal/uncertainty/gum.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/refit.h"
#include "fivecal/solve/problem.h"
#include "fivecal/uncertainty/monte_carlo.h"
#include "fivecal/procedures/probing_stats.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

// TANGO-style HU40T spec: 95 facet touches + 10 scale-bar touches (see the
// file's _comment).
std::string TangoSpec() { return ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/tests/data/tango_thin_spec.json"); }

// A few location errors estimated on the thin TANGO plan: small and fast.
IdentifyOptions SmallFit() {
  IdentifyOptions o;
  o.estimate = {"EX0C", "EA0C", "EB0C", "EX0S", "EY0S", "EB0Z"};
  return o;
}

void ExpectSameReadings(const Dataset& a, const Dataset& b) {
  ASSERT_EQ(a.observations.size(), b.observations.size());
  for (size_t i = 0; i < a.observations.size(); ++i) {
    const Observation& x = a.observations[i];
    const Observation& y = b.observations[i];
    for (int k = 0; k < x.axes.size(); ++k) EXPECT_EQ(x.axes[k], y.axes[k]) << i;
    EXPECT_TRUE(x.payload == y.payload) << i;
    for (int k = 0; k < x.direction.size(); ++k) EXPECT_EQ(x.direction[k], y.direction[k]) << i;
  }
}

// ---- Simulation plans ------------------------------------------------------------

TEST(SimulationPlan, AddNoiseWithTheSpecSeedIsSimulate) {
  const std::string spec = TangoSpec();
  const SimulationPlan plan = BuildSimulationPlan(spec);
  EXPECT_EQ(plan.num_inputs(), 106);  // 105 touches, then the scale bar's length
  EXPECT_EQ(plan.input_observation.back(), -1);
  ExpectSameReadings(Simulate(spec), AddNoise(plan, plan.seed));
  // Another seed gives other readings.
  const Dataset other = AddNoise(plan, plan.seed + 1);
  EXPECT_NE(other.observations[0].axes, Simulate(spec).observations[0].axes);
}

TEST(SimulationPlan, TouchSensitivityIsMinusOneAlongTheApproach) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  for (int k = 0; k < plan.num_inputs(); ++k) {
    EXPECT_NEAR(plan.sensitivity[k], -1.0, 1e-3) << k;  // the erroneous machine tilts the approach by < 1e-3
    // The last input is the bar length, weighed as the fit weighs its row.
    EXPECT_EQ(plan.input_sigma[k], plan.input_observation[k] < 0 ? kScaleBarSigma : 0.0006) << k;
  }
}

TEST(SimulationPlan, ScaleBarInputMovesOnlyTheBarRowByItsSensitivity) {
  // Finite difference of the bar row in the bar length: the plan's
  // sensitivity, and the length written is true + the drawn error.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  const int n = plan.num_inputs(), kb = n - 1;
  ASSERT_EQ(plan.input_observation[kb], -1);
  const double h = 1e-3;
  Eigen::VectorXd dev = Eigen::VectorXd::Zero(n);
  dev[kb] = h;  // along the residual: the length moves by h / sensitivity
  const Dataset moved = ApplyInputDeviations(plan, dev);
  EXPECT_NEAR(moved.artefact.scale_bars[0].length - plan.base.artefact.scale_bars[0].length,
              h / plan.sensitivity[kb], 1e-12);
  std::vector<int> src;
  const Eigen::VectorXd r0 = PredictResiduals(plan.base, plan.values, &src);
  const Eigen::VectorXd r = PredictResiduals(moved, plan.values);
  int bar_rows = 0;
  for (int row = 0; row < r.size(); ++row) {
    if (src[row] == -1) {
      ++bar_rows;
      const double dlength = moved.artefact.scale_bars[0].length - plan.base.artefact.scale_bars[0].length;
      EXPECT_NEAR((r[row] - r0[row]) / dlength, plan.sensitivity[kb], 1e-9);
    } else {
      EXPECT_NEAR(r[row], r0[row], 1e-12) << row;
    }
  }
  EXPECT_EQ(bar_rows, 1);
  // GUM sees the bar as its last input, as the plan does.
  const Result fit = Identify(plan.base, SmallFit());
  const Sensitivity s = SensitivityMatrix(plan.base, fit);
  ASSERT_EQ(static_cast<int>(s.input_source.size()), n);
  EXPECT_EQ(s.input_source.back(), -1);
}

TEST(SimulationPlan, InputDeviationsMoveTheirResidualRowsOnly) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  const int n = plan.num_inputs();
  const Eigen::VectorXd r0 = PredictResiduals(plan.base, plan.values);
  EXPECT_LT(r0.cwiseAbs().maxCoeff(), 1e-9);  // noise-free data fit the truth
  Eigen::VectorXd dev = Eigen::VectorXd::Zero(n);
  dev[3] = 0.002;
  dev[50] = -0.001;
  std::vector<int> src;
  const Eigen::VectorXd r = PredictResiduals(ApplyInputDeviations(plan, dev), plan.values, &src);
  for (int row = 0; row < r.size(); ++row) {
    const double expect = src[row] == 3 ? 0.002 : (src[row] == 50 ? -0.001 : 0.0);
    EXPECT_NEAR(r[row], expect, 1e-9) << row;
  }
}

TEST(SimulationPlan, FromDatasetKeepsTheReadingsAndAddsNoiseAlongTheNormals) {
  const Dataset ds = Simulate(TangoSpec());
  const SimulationPlan truth_plan = BuildSimulationPlan(TangoSpec());
  NoiseLevels noise;
  noise.level["probe"] = 0.001;
  const SimulationPlan plan = PlanFromDataset(ds, truth_plan.values, noise);
  EXPECT_EQ(plan.num_inputs(), truth_plan.num_inputs());
  ExpectSameReadings(plan.base, ds);
  Eigen::VectorXd dev = Eigen::VectorXd::Zero(plan.num_inputs());
  dev[7] = 0.003;
  std::vector<int> src;
  const Eigen::VectorXd r0 = PredictResiduals(ds, plan.values, &src);
  const Eigen::VectorXd r1 = PredictResiduals(ApplyInputDeviations(plan, dev), plan.values);
  for (int row = 0; row < r0.size(); ++row)
    EXPECT_NEAR(r1[row] - r0[row], src[row] == 7 ? 0.003 : 0.0, 1e-9) << row;
}

// ---- Monte Carlo ------------------------------------------------------------------

TEST(MonteCarlo, TrialSeedsAreDistinctAndStable) {
  EXPECT_NE(TrialSeed(1, 0), TrialSeed(1, 1));
  EXPECT_NE(TrialSeed(1, 0), TrialSeed(2, 0));
  EXPECT_EQ(TrialSeed(7, 123), TrialSeed(7, 123));
}

TEST(MonteCarlo, BitIdenticalWithOneAndTwoThreads) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  MonteCarloOptions o;
  o.trials = 24;
  o.seed = 42;
  o.blocks = 4;
  o.threads = 1;
  const MonteCarloResult a = MonteCarlo(plan, SmallFit(), o);
  o.threads = 2;
  int calls = 0;
  const MonteCarloResult b = MonteCarlo(plan, SmallFit(), o, [&](int done, int total) {
    EXPECT_LE(done, total);
    ++calls;
    return true;
  });
  EXPECT_GE(calls, 1);
  EXPECT_EQ(a.threads, 1);
  EXPECT_EQ(b.threads, 2);
  EXPECT_EQ(a.used, 24);
  ASSERT_EQ(a.samples.rows(), 24);
  for (int t = 0; t < a.samples.rows(); ++t)
    for (int j = 0; j < a.samples.cols(); ++j) EXPECT_EQ(a.samples(t, j), b.samples(t, j)) << t << "," << j;
  for (int j = 0; j < a.mean.size(); ++j) {
    EXPECT_EQ(a.mean[j], b.mean[j]);
    EXPECT_EQ(a.std[j], b.std[j]);
    EXPECT_EQ(a.low[j], b.low[j]);
    EXPECT_EQ(a.high[j], b.high[j]);
  }
  // A different master seed gives different trials.
  o.seed = 43;
  const MonteCarloResult c = MonteCarlo(plan, SmallFit(), o);
  EXPECT_NE(a.samples(0, 0), c.samples(0, 0));
}

TEST(MonteCarlo, CancelledByTheProgressCallback) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  MonteCarloOptions o;
  o.trials = 20000;  // far more than can finish before the first poll (0.1 s)
  o.threads = 2;
  EXPECT_THROW(MonteCarlo(plan, SmallFit(), o, [](int, int) { return false; }), std::runtime_error);
}

TEST(MonteCarlo, RejectsBadOptions) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  MonteCarloOptions o;
  o.trials = 1;
  EXPECT_THROW(MonteCarlo(plan, SmallFit(), o), std::invalid_argument);
  o.trials = 10;
  o.input_covariance = Eigen::MatrixXd::Identity(3, 3);
  EXPECT_THROW(MonteCarlo(plan, SmallFit(), o), std::invalid_argument);
}

TEST(MonteCarlo, ShortestAndSymmetricCoverageIntervals) {
  double lo, hi, slo, shi;
  // Skewed sample, M = 8, p = 0.5: q = 4; [y1, y5] = [0, 1] is the shortest,
  // the symmetric one starts at r = (8 - 4) / 2 = 2: [y2, y6] = [0.1, 2].
  CoverageInterval({8, 0.3, 0, 2, 0.1, 4, 1, 0.2}, 0.5, &lo, &hi, &slo, &shi);
  EXPECT_EQ(lo, 0.0);
  EXPECT_EQ(hi, 1.0);
  EXPECT_EQ(slo, 0.1);
  EXPECT_EQ(shi, 2.0);
  // M = 20, p = 0.9: q = 18, r = 1..2, both of length 18: the first.
  std::vector<double> v;
  for (int i = 1; i <= 20; ++i) v.push_back(i);
  CoverageInterval(v, 0.9, &lo, &hi, &slo, &shi);
  EXPECT_EQ(lo, 1.0);
  EXPECT_EQ(hi, 19.0);
  EXPECT_EQ(slo, 1.0);
  EXPECT_EQ(shi, 19.0);
}

TEST(MonteCarlo, NumericalToleranceOfJcgm101) {
  // u = 1.6e-3 with two significant digits: 16 x 10^-4, delta = 0.5e-4 (§7.9.2).
  EXPECT_DOUBLE_EQ(NumericalTolerance(1.6e-3, 2), 0.5e-4);
  EXPECT_DOUBLE_EQ(NumericalTolerance(0.000123, 2), 0.5e-5);
  EXPECT_DOUBLE_EQ(NumericalTolerance(0.000123, 1), 0.5e-4);
  EXPECT_DOUBLE_EQ(NumericalTolerance(1.0, 2), 0.05);
  EXPECT_DOUBLE_EQ(NumericalTolerance(0.99, 1), 0.5);  // 0.99 ~ 1 x 10^0 to one digit
}

// ---- Distributions, pooled covariance, propagation -------------------------------------

// With 2 degrees of freedom the chi-square tail is exp(-x/2) exactly: the
// survival function must keep its digits far into the tail (the p-value of
// an inadequate fit), where 1 - Cdf is 0.
TEST(Gum, ChiSquareSurvivalKeepsTinyTails) {
  for (double x : {0.5, 1.0, 2.9, 3.0, 10.0, 200.0, 1400.0})
    EXPECT_NEAR(ChiSquareSurvival(x, 2) / std::exp(-x / 2), 1.0, 1e-10) << x;
  for (double k : {1.0, 5.0, 37.0, 270.0})
    for (double x : {0.3 * k, k, 1.5 * k})
      EXPECT_NEAR(ChiSquareSurvival(x, k) + ChiSquareCdf(x, k), 1.0, 1e-12) << k << " " << x;
  EXPECT_EQ(ChiSquareSurvival(0.0, 3), 1.0);
  EXPECT_THROW(ChiSquareSurvival(1.0, 0), std::invalid_argument);
}

TEST(Gum, QuantilesMatchTables) {
  EXPECT_NEAR(NormalQuantile(0.975), 1.959963984540054, 1e-12);
  EXPECT_NEAR(NormalQuantile(0.001), -3.090232306167814, 1e-10);
  EXPECT_NEAR(StudentTQuantile(0.975, 10), 2.228138851986274, 1e-9);
  EXPECT_NEAR(StudentTQuantile(0.975, 1), 12.706204736174698, 1e-7);
  EXPECT_NEAR(StudentTQuantile(0.025, 25), -2.059538552753294, 1e-9);
  EXPECT_NEAR(ChiSquareQuantile(0.95, 10), 18.307038053275146, 1e-8);
  EXPECT_NEAR(ChiSquareQuantile(0.95, 2), 5.991464547107979, 1e-9);
  EXPECT_NEAR(FQuantile(0.95, 3, 20), 3.0983912121407795, 1e-8);
}

TEST(Gum, CoverageFactorIsStated) {
  const CoverageFactor n = MakeCoverageFactor(0.95, std::numeric_limits<double>::infinity(), 2);
  EXPECT_NEAR(n.k, 1.959963984540054, 1e-12);
  EXPECT_NEAR(n.k_joint, std::sqrt(5.991464547107979), 1e-9);
  const CoverageFactor t = MakeCoverageFactor(0.95, 25, 1);
  EXPECT_NEAR(t.k, 2.059538552753294, 1e-9);
  EXPECT_NE(t.method.find("Student t"), std::string::npos);
  EXPECT_NE(t.method.find("25"), std::string::npos);
  // One output: Hotelling's region is the t interval, k_joint = t.
  EXPECT_NEAR(t.k_joint, t.k, 1e-8);
  EXPECT_EQ(MakeCoverageFactor(0.95, 25, 3, 2.6).k, 2.6);
}

TEST(Gum, PooledCovarianceHandComputed) {
  // Two groups of two cycles: A = {[1,2],[3,4]}, B = {[0,0],[2,-2]}.
  // Deviations from the group means: A: +-[1,1], B: +-[1,-1]; sum of outer
  // products [[4,0],[0,4]]; dof = 4 - 2 = 2.
  Eigen::MatrixXd X(4, 2);
  X << 1, 2, 0, 0, 3, 4, 2, -2;
  const PooledCovariance p = PoolCovariance(X, {7, 9, 7, 9});
  EXPECT_EQ(p.dof, 2);
  EXPECT_NEAR(p.covariance(0, 0), 2.0, 1e-15);
  EXPECT_NEAR(p.covariance(1, 1), 2.0, 1e-15);
  EXPECT_NEAR(p.covariance(0, 1), 0.0, 1e-15);
  EXPECT_EQ(p.group_labels, (std::vector<int>{7, 9}));
  EXPECT_NEAR(p.group_means(0, 1), 3.0, 1e-15);
  EXPECT_NEAR(p.group_means(1, 1), -1.0, 1e-15);
  // Every cycle its own group: no degrees of freedom.
  EXPECT_THROW(PoolCovariance(X, {0, 1, 2, 3}), std::invalid_argument);
}

TEST(Gum, PropagationHandComputed) {
  // C = [[1,2,0],[0,1,-1]], U_x = [[4,1,0],[1,9,0],[0,0,1]]:
  // C U_x = [[6,19,0],[1,9,-1]], C U_x C^T = [[44,19],[19,10]].
  Eigen::MatrixXd C(2, 3), U(3, 3);
  C << 1, 2, 0, 0, 1, -1;
  U << 4, 1, 0, 1, 9, 0, 0, 0, 1;
  const CoverageFactor cf = MakeCoverageFactor(0.95, 10, 2);
  const GumResult g = PropagateCovariance(C, U, {"a", "b"}, Eigen::Vector2d(5, 6), cf);
  EXPECT_NEAR(g.covariance(0, 0), 44, 1e-12);
  EXPECT_NEAR(g.covariance(0, 1), 19, 1e-12);
  EXPECT_NEAR(g.covariance(1, 0), 19, 1e-12);
  EXPECT_NEAR(g.covariance(1, 1), 10, 1e-12);
  EXPECT_NEAR(g.std[0], std::sqrt(44.0), 1e-12);
  EXPECT_NEAR(g.correlation(0, 1), 19 / std::sqrt(440.0), 1e-12);
  EXPECT_NEAR(g.expanded[1], 2.228138851986274 * std::sqrt(10.0), 1e-8);
  EXPECT_THROW(PropagateCovariance(C, Eigen::MatrixXd::Identity(2, 2), {"a", "b"}, Eigen::Vector2d(0, 0), cf),
               std::invalid_argument);
}

TEST(Gum, SensitivityMatrixMatchesRefits) {
  // C = d(estimate)/d(input): compare with central differences of re-fits.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  const IdentifyOptions opt = SmallFit();
  const Result fit = Identify(plan.base, opt);
  const Sensitivity s = SensitivityMatrix(plan.base, fit);
  ASSERT_EQ(s.C.cols(), plan.num_inputs());
  const Refit refit(plan.base, opt, fit);
  const double h = 1e-3;  // mm
  for (int k : {0, 20, 60, 100}) {
    Eigen::VectorXd dev = Eigen::VectorXd::Zero(plan.num_inputs());
    dev[k] = h;
    const Eigen::VectorXd up = refit.Fit(ApplyInputDeviations(plan, dev)).values;
    dev[k] = -h;
    const Eigen::VectorXd dn = refit.Fit(ApplyInputDeviations(plan, dev)).values;
    const Eigen::VectorXd fd = (up - dn) / (2 * h);
    for (int j = 0; j < fd.size(); ++j)
      EXPECT_NEAR(s.C(j, k), fd[j], 1e-4 * s.C.row(j).cwiseAbs().maxCoeff() + 1e-12) << s.names[j] << " input " << k;
  }
}

// The session's fit (its own trust-region loop on the analytic batch) equals
// the Ceres refit of a freshly drawn dataset: each value within 1e-6 of its
// one-sigma uncertainty, the same iteration count and verdict.
void ExpectSameRefit(const RefitResult& a, const RefitResult& b, const std::string& what) {
  ASSERT_EQ(a.values.size(), b.values.size()) << what;
  ASSERT_EQ(b.std.size(), b.values.size()) << what;
  for (int j = 0; j < a.values.size(); ++j)
    EXPECT_LE(std::abs(a.values[j] - b.values[j]), 1e-6 * b.std[j] + 1e-15) << what << " parameter " << j;
  EXPECT_EQ(a.iterations, b.iterations) << what;
  EXPECT_EQ(a.converged, b.converged) << what;
  EXPECT_NEAR(a.sigma, b.sigma, 1e-9 * b.sigma) << what;
  for (int j = 0; j < a.std.size(); ++j) EXPECT_NEAR(a.std[j], b.std[j], 1e-6 * b.std[j]) << what << " std " << j;
}

TEST(Refit, SessionEditedInPlaceIsAFreshRefit) {
  // Monte Carlo trials edit one dataset per thread and refresh the problem
  // prepared on it: each trial must be the refit of a freshly drawn dataset.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  const IdentifyOptions opt = SmallFit();
  const Result fit = Identify(plan.base, opt);
  const Refit refit(plan.base, opt, fit);
  Refit::Session session(refit);
  for (uint64_t seed : {11u, 12u, 13u}) {
    AddNoiseInto(plan, seed, &session.dataset());
    const Dataset fresh = AddNoise(plan, seed);
    ExpectSameReadings(session.dataset(), fresh);
    const RefitResult a = session.Fit(true);
    const RefitResult b = refit.Fit(fresh, true);
    ExpectSameRefit(a, b, "seed " + std::to_string(seed));
    EXPECT_TRUE(a.converged);
  }
}

TEST(Refit, SessionEqualsCeresOnTheThesisSubsetAndMapFits) {
  // TANGO S3 (machine errors, tip, facets, spheres, backlashes) and the MAP
  // fit of `auto`, each over many trials with 10x and 100x the noise too:
  // the session's trust-region loop stops where Ceres stops, on the same point.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  IdentifyOptions s3;
  s3.estimate = {"S3"};
  IdentifyOptions map;
  map.estimate = {"auto"};
  for (const IdentifyOptions& opt : {s3, map}) {
    const Result fit = Identify(plan.base, opt);
    const Refit refit(plan.base, opt, fit);
    Refit::Session session(refit);
    for (double gain : {1.0, 10.0, 100.0}) {
      SimulationPlan noisy = plan;
      noisy.input_sigma *= gain;
      for (uint64_t seed = 100; seed < 120; ++seed) {
        AddNoiseInto(noisy, seed, &session.dataset());
        const RefitResult a = session.Fit(true);
        const RefitResult b = refit.Fit(AddNoise(noisy, seed), true);
        EXPECT_FALSE(a.ceres);  // the session's own loop, not its Ceres fallback
        EXPECT_TRUE(b.ceres);
        ExpectSameRefit(a, b, opt.estimate[0] + " gain " + std::to_string(gain) + " seed " + std::to_string(seed));
      }
    }
  }
}

TEST(Refit, SessionOnAxesOnlyReReadsAxesAndFallsBackWhenMoreChanged) {
  // set_axes_only: after two trials that change axis values only, the
  // session re-reads them alone; same values as the Ceres refit either way.
  // A trial that changes more (here a touch's approach direction, which the
  // prepared row holds) before the switch keeps the full preparation for good.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  IdentifyOptions opt;
  opt.estimate = {"S3"};  // with the backlashes, which the directions enter
  const Result fit = Identify(plan.base, opt);
  const Refit refit(plan.base, opt, fit);
  for (bool edit_direction : {false, true}) {
    Refit::Session session(refit);
    session.set_axes_only(true);
    for (uint64_t seed = 31; seed < 37; ++seed) {
      AddNoiseInto(plan, seed, &session.dataset());
      Dataset fresh = AddNoise(plan, seed);
      if (edit_direction && seed >= 32) {
        // Flip a touch's last move directions (which select the backlash;
        // the row holds them, the axes-only refresh would miss them) from
        // the second trial on.
        Observation& o = session.dataset().observations[3];
        ASSERT_FALSE(o.direction.size() == 0);
        o.direction.setConstant(seed % 2 ? 1 : -1);
        fresh.observations[3].direction = o.direction;
      }
      const RefitResult a = session.Fit(true);
      const RefitResult b = refit.Fit(fresh, true);
      ExpectSameRefit(a, b, std::string(edit_direction ? "direction edited" : "axes only") + " seed " +
                                std::to_string(seed));
    }
  }
}

TEST(Refit, SessionAtTheIterationLimitIsTheCeresRefit) {
  // A fit that reaches max_iterations is left to Ceres: its verdict (not
  // converged) and its values, bit for bit.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  IdentifyOptions opt = SmallFit();
  const Result fit = Identify(plan.base, opt);
  opt.max_iterations = 1;
  const Refit refit(plan.base, opt, fit);
  Refit::Session session(refit);
  AddNoiseInto(plan, 41, &session.dataset());
  const RefitResult a = session.Fit();
  const RefitResult b = refit.Fit(AddNoise(plan, 41));
  EXPECT_TRUE(a.ceres);
  EXPECT_FALSE(a.converged);
  EXPECT_EQ(a.values, b.values);
  EXPECT_EQ(a.iterations, b.iterations);
}

TEST(Refit, SessionWithARobustLossIsTheCeresRefit) {
  // A robust loss is left to Ceres: bit-identical to Refit::Fit.
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  IdentifyOptions opt = SmallFit();
  opt.robust = "huber";
  opt.robust_scale = 0.002;
  const Result fit = Identify(plan.base, opt);
  const Refit refit(plan.base, opt, fit);
  Refit::Session session(refit);
  for (uint64_t seed : {21u, 22u}) {
    AddNoiseInto(plan, seed, &session.dataset());
    const RefitResult a = session.Fit(true);
    const RefitResult b = refit.Fit(AddNoise(plan, seed), true);
    EXPECT_TRUE(a.ceres);
    EXPECT_EQ(a.values, b.values) << seed;
    EXPECT_EQ(a.std, b.std) << seed;
    EXPECT_EQ(a.iterations, b.iterations) << seed;
  }
}

TEST(Gum, CyclesPooledByDaysRemovesTheChangeBetweenDays) {
  // Four cycles on each of three days; each day the machine's EX0C is 5 um
  // off (a change between days), the noise is 0.6 um. Pooling by days removes
  // the day effect: the GUM uncertainty is the noise's, close to Identify's;
  // with a single group ("none") the 5 um day change inflates it.
  const nlohmann::json spec = nlohmann::json::parse(TangoSpec());
  std::vector<Dataset> cycles;
  std::vector<int> day, cycle;
  for (int d = 0; d < 3; ++d)
    for (int c = 0; c < 4; ++c) {
      nlohmann::json s = spec;
      s["errors"]["EX0C"] = s["errors"]["EX0C"].get<double>() + 0.005 * (d - 1);
      s["seed"] = 100 + 10 * d + c;
      cycles.push_back(Simulate(s.dump()));
      day.push_back(d);
      cycle.push_back(c);
    }
  CyclesOptions by_days;
  by_days.pooling = "days";
  const CyclesUncertainty u = GumFromCycles(cycles, day, cycle, SmallFit(), by_days);
  EXPECT_EQ(u.inputs.dof, 12 - 3);
  EXPECT_NEAR(u.gum.coverage.k, StudentTQuantile(0.975, 9), 1e-12);
  const Result one = Identify(cycles[0], SmallFit());
  const int j = static_cast<int>(std::find(u.estimated.begin(), u.estimated.end(), "EX0C") - u.estimated.begin());
  ASSERT_LT(j, static_cast<int>(u.estimated.size()));
  ASSERT_EQ(one.estimated[j], "EX0C");
  // The noise alone would give sigma * sqrt(diag C C^T) (the fit's own std
  // is larger: the six location errors leave the other S3 errors as misfit,
  // the same in every cycle, which the pooling rightly ignores).
  const Sensitivity sens = SensitivityMatrix(cycles[0], one);
  const double noise_only = 0.0006 * sens.C.row(j).norm();
  // 9 degrees of freedom: the pooled std scatters by ~25 %.
  EXPECT_GT(u.gum.std[j], 0.5 * noise_only);
  EXPECT_LT(u.gum.std[j], 1.6 * noise_only);
  CyclesOptions none;
  none.pooling = "none";
  const CyclesUncertainty all = GumFromCycles(cycles, day, cycle, SmallFit(), none);
  EXPECT_GT(all.gum.std[j], 3 * u.gum.std[j]);
  // The pooled scatter of the cycles' own estimates agrees with the propagation.
  EXPECT_NEAR(std::sqrt(all.output_pooled(j, j)) / all.gum.std[j], 1.0, 0.05);
}

// ---- Probing statistics ----------------------------------------------------------------

// P = surface + drift + repeatability on 3 points x 4 cycles (values in um):
// surface s = (0, 2, -2), drift d = (0, 1, 3, 4), e = (1,-1,1,-1; -1,1,1,-1; 0,0,-2,2).
Eigen::MatrixXd HandGrid() {
  Eigen::MatrixXd P(3, 4);
  P << 1, 0, 4, 3,
       1, 4, 6, 5,
      -2, -1, -1, 4;
  return P;
}

TEST(ProbingStats, GridReproducesHandComputedValues) {
  const GridStatistics g = AnalyzeGrid(HandGrid(), 2);
  // 4-9, 4-10: grand mean 24 / 12 = 2, sum of squares 10 + 30 + 38 = 78.
  EXPECT_DOUBLE_EQ(g.mean, 2.0);
  EXPECT_DOUBLE_EQ(g.total_std, std::sqrt(78.0 / 11.0));
  EXPECT_DOUBLE_EQ(g.total_range, 8.0);
  // 4-11, 4-12 with windows of 2 cycles: variances (0.5, 0.5), (4.5, 0.5), (0.5, 12.5).
  EXPECT_DOUBLE_EQ(g.point_pooled_std[0], std::sqrt(0.5));
  EXPECT_DOUBLE_EQ(g.point_pooled_std[1], std::sqrt(2.5));
  EXPECT_DOUBLE_EQ(g.point_pooled_std[2], std::sqrt(6.5));
  EXPECT_DOUBLE_EQ(g.max_pooled_std, std::sqrt(6.5));
  EXPECT_DOUBLE_EQ(g.pooled_std, std::sqrt(19.0 / 6.0));
  EXPECT_EQ(g.pooled_dof, 6);
  // 4-13..4-15: point means (2, 4, 0): S = 2, range 4.
  EXPECT_DOUBLE_EQ(g.point_means[1], 4.0);
  EXPECT_DOUBLE_EQ(g.surface_std, 2.0);
  EXPECT_DOUBLE_EQ(g.surface_range, 4.0);
  // 4-16: cycle means (0, 1, 3, 4) = the drift: std sqrt(10/3), range 4.
  EXPECT_DOUBLE_EQ(g.cycle_means[2], 3.0);
  EXPECT_DOUBLE_EQ(g.drift_std, std::sqrt(10.0 / 3.0));
  EXPECT_DOUBLE_EQ(g.drift_range, 4.0);
  // Table 7-5: per-point variances 10/3, 14/3, 22/3.
  EXPECT_DOUBLE_EQ(g.point_std[2], std::sqrt(22.0 / 3.0));
  EXPECT_DOUBLE_EQ(g.point_std_pooled, std::sqrt(46.0 / 9.0));
  // ANOVA: residuals = e, SSE 16, MS_e = 16 / 6; MS_points = 16, MS_cycles = 10.
  EXPECT_NEAR(g.repeatability, std::sqrt(8.0 / 3.0), 1e-14);
  EXPECT_NEAR(g.surface_component, std::sqrt(10.0 / 3.0), 1e-14);
  EXPECT_NEAR(g.drift_component, std::sqrt(22.0) / 3.0, 1e-14);
}

TEST(ProbingStats, WindowPooledStdOfEquation7_1) {
  // Windows of 3: [1,2,3] var 1, [5,5,5] var 0, [9] alone carries nothing:
  // s_p^2 = (2 x 1 + 2 x 0) / 4.
  Eigen::VectorXd s(7);
  s << 1, 2, 3, 5, 5, 5, 9;
  const PooledStd p = WindowPooledStd(s, 3);
  EXPECT_DOUBLE_EQ(p.pooled_std, std::sqrt(0.5));
  EXPECT_EQ(p.dof, 4);
  EXPECT_EQ(p.group_size, (std::vector<int>{3, 3, 1}));
  EXPECT_THROW(WindowPooledStd(s, 1), std::invalid_argument);
  EXPECT_THROW(AnalyzeGrid(Eigen::MatrixXd::Zero(1, 5)), std::invalid_argument);
}

}  // namespace
}  // namespace fivecal
