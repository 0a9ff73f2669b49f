// Identify's stages, each on its typed output (identify_request.h lists
// them), on the HU40T TANGO plan: S3 (determined) and S4 (some errors
// undetermined), and the stages chained give what Identify gives.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_covariance.h"
#include "fivecal/solve/identify_determination.h"
#include "fivecal/solve/identify_fit.h"
#include "fivecal/solve/identify_problem.h"
#include "fivecal/solve/identify_request.h"
#include "fivecal/solve/identify_verdict.h"
#include "fivecal/solve/priors.h"
#include "test_files.h"

namespace fivecal {
namespace {

Dataset Tango(bool s3) {
  const std::string data = std::string(FIVECAL_SOURCE_DIR) + "/tests/data/";
  nlohmann::json spec = nlohmann::json::parse(ReadFile(data + "tango_hu40t_spec.json"));
  if (s3) spec["errors"] = nlohmann::json::parse(ReadFile(data + "errors_tango_hu40t_s3.json"));
  return Simulate(spec.dump());
}

IdentifyOptions Options(const std::string& estimate, bool allow = false) {
  IdentifyOptions opt;
  opt.estimate = {estimate};
  opt.allow_unidentifiable = allow;
  return opt;
}

TEST(IdentifyStages, RequestResolvesTheEstimatedSetAndItsPriors) {
  const Dataset ds = Tango(true);
  const IdentifyOptions opt = Options("S3");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  ASSERT_EQ(rq.est.size(), 52u);
  ASSERT_EQ(rq.estimated.size(), rq.est.size());
  EXPECT_FALSE(rq.map);
  EXPECT_FALSE(rq.automatic);
  EXPECT_EQ(rq.est, rq.forced);
  for (size_t j = 0; j < rq.est.size(); ++j) {
    EXPECT_EQ(rq.estimated[j], rq.table.names()[rq.est[j]]);
    EXPECT_EQ(rq.prior[j], rq.prior_all[rq.est[j]]);  // least squares: the plausible size
    EXPECT_GT(rq.prior[j], 0.0);
    EXPECT_EQ(rq.place[j], rq.placement_all[rq.est[j]]);
  }
  EXPECT_EQ(rq.placed, rq.ls_rows.size() > 0);
  EXPECT_EQ(rq.start.size(), rq.table.size());
  EXPECT_EQ(ResolveEstimate(ds, opt), rq.estimated);

  // "auto": every candidate under its prior, the MAP prior narrowed by the placement.
  const IdentifyRequest au = ResolveRequest(ds, Options("auto"));
  EXPECT_TRUE(au.map && au.automatic);
  EXPECT_EQ(au.est.size(), au.forced.size() + au.candidates.size());
  EXPECT_EQ(au.ls_rows.size(), 0);
  for (size_t j = 0; j < au.est.size(); ++j) {
    EXPECT_EQ(au.prior[j], au.map_prior_all[au.est[j]]);
    EXPECT_LE(au.prior[j], au.prior_all[au.est[j]]);
    EXPECT_EQ(au.place[j], 0.0);
  }

  // Nothing left: refused, naming why.
  IdentifyOptions none = Options("EX0C");
  none.include_default_setup = false;
  none.fix = {"EX0C"};
  EXPECT_THROW(
      {
        try {
          ResolveRequest(ds, none);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find("nothing to estimate"), std::string::npos) << e.what();
          throw;
        }
      },
      std::invalid_argument);
}

TEST(IdentifyStages, ProblemGivesTheWeightedJacobianOrItsFactor) {
  const Dataset ds = Tango(true);
  IdentifyOptions opt = Options("S3");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem dense(ds, opt, rq);
  ASSERT_FALSE(dense.normal_equations());  // 388 touches: short data
  const Eigen::MatrixXd Jw = dense.WeightedJacobianAt(rq.start);
  ASSERT_EQ(Jw.cols(), static_cast<Eigen::Index>(rq.est.size()));
  EXPECT_GT(Jw.rows(), Jw.cols());
  const SingleFit fit = dense.FitFrom(rq.start, rq.ls_rows);
  EXPECT_TRUE(fit.converged);
  EXPECT_LT(fit.final_cost, fit.initial_cost);
  EXPECT_EQ(fit.values.size(), rq.table.size());

  // The normal-equation path hands on a p x p factor of the same J^T J.
  opt.fit_path = "normal_equations";
  IdentifyProblem ne(ds, opt, rq);
  ASSERT_TRUE(ne.normal_equations());
  const Eigen::MatrixXd R = ne.WeightedJacobianAt(rq.start);
  ASSERT_EQ(R.rows(), R.cols());
  const Eigen::MatrixXd N = Jw.transpose() * Jw;
  EXPECT_LE((R.transpose() * R - N).norm(), 1e-9 * N.norm());
}

TEST(IdentifyStages, FitHandsOnOneTriangularFactorAtTheSolution) {
  const Dataset ds = Tango(true);
  const IdentifyOptions opt = Options("S3");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
  const int p = static_cast<int>(rq.est.size());
  EXPECT_TRUE(fit.fit.converged);
  ASSERT_EQ(fit.factor.rows(), p);
  ASSERT_EQ(fit.factor.cols(), p);
  EXPECT_TRUE(fit.factor.triangularView<Eigen::StrictlyLower>().toDenseMatrix().isZero(0));
  Eigen::MatrixXd J = WithPlacementRows(fit.Jw, rq.place);
  const Eigen::MatrixXd N = J.transpose() * J;
  EXPECT_LE((fit.factor.transpose() * fit.factor - N).norm(), 1e-10 * N.norm());
  EXPECT_EQ(fit.r.size(), fit.num_rows);
  ASSERT_NE(fit.row_sigma, nullptr);
  EXPECT_EQ(fit.row_sigma->size(), fit.num_rows);
  EXPECT_EQ(fit.weighted, &ds);  // no variance components: no copy
  EXPECT_FALSE(fit.normal_equations);
}

TEST(IdentifyStages, FitRefusesALeastSquaresRequestTheDataDoNotDetermine) {
  const Dataset ds = Tango(false);
  const IdentifyOptions opt = Options("S4");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  try {
    FitRequest(ds, opt, rq, &problem);
    FAIL() << "S4 on this plan is not determined";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("not determined by this data"), std::string::npos) << e.what();
  }
}

TEST(IdentifyStages, DeterminationNamesTheUndeterminedGroups) {
  const Dataset ds = Tango(false);
  const IdentifyOptions opt = Options("S4", true);
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
  const IdentifyDetermination det = DetermineAtSolution(ds, opt, rq, fit);
  ASSERT_FALSE(det.determination.undetermined.empty());
  ASSERT_FALSE(det.groups.empty());
  // Every undetermined column is in exactly one group, by its name.
  std::multiset<std::string> grouped;
  for (const auto& g : det.groups) grouped.insert(g.begin(), g.end());
  ASSERT_EQ(grouped.size(), det.determination.undetermined.size());
  for (int c : det.determination.undetermined) EXPECT_EQ(grouped.count(rq.estimated[c]), 1u);
  for (int c : det.determination.undetermined) EXPECT_FALSE(det.determination.ratio[c] < kDeterminedRatio);
  // Without allow_unidentifiable the same analysis is the refusal.
  IdentifyOptions strict = opt;
  strict.allow_unidentifiable = false;
  EXPECT_THROW(DetermineAtSolution(ds, strict, rq, fit), std::invalid_argument);

  // S3: everything determined, no group.
  const Dataset d3 = Tango(true);
  const IdentifyOptions o3 = Options("S3");
  const IdentifyRequest r3 = ResolveRequest(d3, o3);
  IdentifyProblem p3(d3, o3, r3);
  const IdentifyFit f3 = FitRequest(d3, o3, r3, &p3);
  const IdentifyDetermination det3 = DetermineAtSolution(d3, o3, r3, f3);
  EXPECT_TRUE(det3.determination.undetermined.empty());
  EXPECT_TRUE(det3.groups.empty());
  EXPECT_EQ(det3.determination.rank, static_cast<int>(r3.est.size()));
}

// S4 at its solution: the determination (which takes the eigenvectors of the
// normal matrix where its decisions clear their rounding bound) names the
// undetermined columns and groups a one-sided Jacobi SVD of the prior-scaled
// factor names; and the fit's residuals and Jacobian at its solution, taken
// from its own last evaluation, are those a fresh evaluation there gives.
TEST(IdentifyStages, S4DeterminationIsTheJacobiSvdsAndTheFitsJacobianAFreshOne) {
  const Dataset ds = Tango(false);
  const IdentifyOptions opt = Options("S4", true);
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
  const IdentifyDetermination det = DetermineAtSolution(ds, opt, rq, fit);
  const int p = static_cast<int>(rq.est.size());

  Eigen::JacobiSVD<Eigen::MatrixXd> svd(fit.factor * rq.prior.asDiagonal(), Eigen::ComputeFullV);
  const Eigen::VectorXd s = svd.singularValues();
  const Eigen::MatrixXd& V = svd.matrixV();
  const double zero = 1e-12 * std::max(s[0], 1.0), weak = 1.0 / kDeterminedRatio;
  Eigen::VectorXd ratio2 = Eigen::VectorXd::Zero(p), free2 = Eigen::VectorXd::Zero(p);
  for (int k = 0; k < p; ++k)
    for (int j = 0; j < p; ++j) {
      if (s[k] > zero) ratio2[j] += std::abs(V(j, k)) >= 1e-9 ? V(j, k) * V(j, k) / (s[k] * s[k]) : 0.0;
      else free2[j] += V(j, k) * V(j, k);
    }
  std::vector<int> undetermined;
  std::vector<bool> bad(p, false);
  for (int j = 0; j < p; ++j)
    if (free2[j] >= 1e-18 || !(std::sqrt(ratio2[j]) < kDeterminedRatio)) undetermined.push_back(j), bad[j] = true;
  ASSERT_FALSE(undetermined.empty());
  EXPECT_EQ(det.determination.undetermined, undetermined);
  EXPECT_EQ(det.determination.groups, UndeterminedGroups(s, V, bad, zero, weak));

  Problem fresh(ds, rq.table, fit.fit.values, rq.est);
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(&fresh, &r, &Jw);
  ASSERT_EQ(fit.Jw.rows(), Jw.rows());
  EXPECT_EQ((fit.Jw - Jw).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((fit.r - r).cwiseAbs().maxCoeff(), 0.0);
}

TEST(IdentifyStages, CovarianceIsTheScaledInverseOfTheFactorsNormalMatrix) {
  const Dataset ds = Tango(true);
  const IdentifyOptions opt = Options("S3");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
  const IdentifyDetermination det = DetermineAtSolution(ds, opt, rq, fit);
  const IdentifyCovariance cov = CovarianceAtSolution(ds, opt, rq, fit, det);
  const int p = static_cast<int>(rq.est.size());
  EXPECT_EQ(cov.rank, p);
  EXPECT_TRUE(std::isfinite(cov.condition_number));
  EXPECT_GT(cov.condition_number, 1.0);
  // Least squares of full rank: C = chi2/dof (R^T R)^-1.
  EXPECT_EQ(cov.dof, cov.chi2_rows - p);
  const Eigen::MatrixXd N = fit.factor.transpose() * fit.factor;
  const Eigen::MatrixXd C = (cov.chi2 / cov.dof) * N.inverse();
  EXPECT_LE((cov.covariance - C).norm(), 1e-8 * C.norm());
  for (int j = 0; j < p; ++j) {
    EXPECT_NEAR(cov.std[j], std::sqrt(C(j, j)), 1e-8 * std::sqrt(C(j, j)));
    EXPECT_NEAR(cov.correlation(j, j), 1.0, 1e-12);
  }
  EXPECT_GT(cov.chi2_p, 1e-3);  // the simulated noise is the declared one
  EXPECT_EQ(cov.scaled_posterior.size(), 0);  // least squares: no posterior in prior units

  // MAP: the posterior in prior units, (Js^T Js + I)^-1.
  const IdentifyOptions ao = Options("auto");
  const IdentifyRequest ar = ResolveRequest(ds, ao);
  IdentifyProblem ap(ds, ao, ar);
  const IdentifyFit af = FitRequest(ds, ao, ar, &ap);
  const IdentifyCovariance ac = CovarianceAtSolution(ds, ao, ar, af, DetermineAtSolution(ds, ao, ar, af));
  ASSERT_EQ(ac.scaled_posterior.rows(), static_cast<Eigen::Index>(ar.est.size()));
  for (Eigen::Index j = 0; j < ac.scaled_posterior.rows(); ++j) {
    EXPECT_GT(ac.scaled_posterior(j, j), 0.0);
    EXPECT_LE(ac.scaled_posterior(j, j), 1.0 + 1e-12);  // the data never widen a prior
  }
}

TEST(IdentifyStages, VerdictOfTheChainedStagesIsIdentifys) {
  for (const bool s3 : {true, false}) {
    const Dataset ds = Tango(s3);
    const IdentifyOptions opt = Options(s3 ? "S3" : "S4", true);
    const IdentifyRequest rq = ResolveRequest(ds, opt);
    IdentifyProblem problem(ds, opt, rq);
    const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
    const IdentifyDetermination det = DetermineAtSolution(ds, opt, rq, fit);
    const IdentifyCovariance cov = CovarianceAtSolution(ds, opt, rq, fit, det);
    const Result chained = JudgeResult(ds, opt, rq, fit, det, cov);
    const Result whole = Identify(ds, opt);
    EXPECT_EQ(chained.ToJson(), whole.ToJson());
    EXPECT_EQ(chained.verdict(), s3 ? "ok" : "undetermined");
    EXPECT_EQ(chained.unidentifiable, det.groups);
  }
}


// The start's determinacy from one normal matrix (AnyUndetermined) is the
// certificate-or-analysis it replaces: determined (S3), undetermined (S4),
// and a column no row sees.
TEST(IdentifyStages, AnyUndeterminedIsTheCertificateOrTheAnalysis) {
  for (const bool s3 : {true, false}) {
    const Dataset ds = Tango(s3);
    const IdentifyOptions opt = Options(s3 ? "S3" : "S4", true);
    const IdentifyRequest rq = ResolveRequest(ds, opt);
    IdentifyProblem problem(ds, opt, rq);
    Eigen::MatrixXd J = problem.WeightedJacobianAt(rq.start);
    auto old = [&](const Eigen::MatrixXd& A) {
      return CertainlyUndetermined(A, rq.prior, kDeterminedRatio) ||
             !AnalyzeDetermination(A, rq.prior, kDeterminedRatio).undetermined.empty();
    };
    EXPECT_EQ(AnyUndetermined(J, rq.prior, kDeterminedRatio), !s3);
    EXPECT_EQ(AnyUndetermined(J, rq.prior, kDeterminedRatio), old(J));
    J.col(3).setZero();
    EXPECT_TRUE(AnyUndetermined(J, rq.prior, kDeterminedRatio));
    EXPECT_EQ(AnyUndetermined(J, rq.prior, kDeterminedRatio), old(J));
    // Fewer rows than columns: undetermined, as before.
    const Eigen::MatrixXd few = J.topRows(J.cols() / 2);
    EXPECT_TRUE(AnyUndetermined(few, rq.prior, kDeterminedRatio));
  }
}

// The unweighted condition number (the scale bar's row has another sigma
// than the touches) taken from the fit's factor and that row is the one of
// the rows themselves, and an unweighted Jacobian of dependent columns is
// still infinitely ill-conditioned.
TEST(IdentifyStages, UnweightedConditionNumberFromTheFactorIsTheRowsOne) {
  for (const bool s3 : {true, false}) {
    const Dataset ds = Tango(s3);
    const IdentifyOptions opt = Options(s3 ? "S3" : "S4", true);
    const IdentifyRequest rq = ResolveRequest(ds, opt);
    IdentifyProblem problem(ds, opt, rq);
    const IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
    ASSERT_FALSE(rq.placed);
    const Eigen::VectorXd& sig = *fit.row_sigma;
    ASSERT_FALSE((sig.array() == sig[0]).all());  // else the weighted one is reported
    const IdentifyCovariance cov = CovarianceAtSolution(ds, opt, rq, fit, DetermineAtSolution(ds, opt, rq, fit));
    const double rows = ConditionNumber(Eigen::MatrixXd(sig.asDiagonal() * fit.Jw), opt.rank_tolerance);
    EXPECT_NEAR(cov.condition_number, rows, 1e-9 * rows);
  }
  // Two equal columns: rank deficient whichever way it is computed.
  const Dataset ds = Tango(true);
  IdentifyOptions opt = Options("S3");
  const IdentifyRequest rq = ResolveRequest(ds, opt);
  IdentifyProblem problem(ds, opt, rq);
  IdentifyFit fit = FitRequest(ds, opt, rq, &problem);
  fit.Jw.col(1) = fit.Jw.col(0);
  fit.factor = TriangularFactor(fit.Jw);
  opt.allow_unidentifiable = true;
  const IdentifyCovariance cov = CovarianceAtSolution(ds, opt, rq, fit, DetermineAtSolution(ds, opt, rq, fit));
  EXPECT_FALSE(std::isfinite(cov.condition_number)) << cov.condition_number;
}

}  // namespace
}  // namespace fivecal
