// Identify's fits without Ceres (SolveWithoutCeres, the trust-region loop of
// Refit::Session) against Ceres on the full HU40T TANGO plan, and the
// Cholesky certificate of an undetermined set against AnalyzeDetermination.
#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"
#include "fivecal/solve/refit.h"
#include "test_files.h"

namespace fivecal {
namespace {

// The 388 touches of the thesis plan, with the S4 errors or (s3) the S3 ones.
Dataset Tango(bool s3) {
  const std::string data = std::string(FIVECAL_SOURCE_DIR) + "/tests/data/";
  nlohmann::json spec = nlohmann::json::parse(ReadFile(data + "tango_hu40t_spec.json"));
  // the S3 errors sit in a file of their own: a spec file holds only the spec's keys
  if (s3) spec["errors"] = nlohmann::json::parse(ReadFile(data + "errors_tango_hu40t_s3.json"));
  return Simulate(spec.dump());
}

std::vector<int> Indices(const ParameterTable& table, const std::vector<std::string>& names) {
  std::vector<int> out;
  for (const std::string& n : names) out.push_back(table.Require(n));
  return out;
}

Eigen::VectorXd MachinePriorScales(const Dataset& ds, const ParameterTable& table) {
  const std::vector<double> p = PriorScales(ds.machine(), table.names(), ds.machine().priors, {});
  return Eigen::Map<const Eigen::VectorXd>(p.data(), static_cast<Eigen::Index>(p.size()));
}

struct CeresFit {
  Eigen::VectorXd values;  // estimated order
  int iterations = 0;
  bool converged = false;
  double initial_cost = 0, final_cost = 0;
};

// What Identify ran before: Ceres on the problem, with the prior rows added
// (prior empty: none).
CeresFit SolveWithCeres(const Dataset& ds, const ParameterTable& table, const std::vector<int>& est,
                        const Eigen::VectorXd& prior) {
  Problem pr(ds, table, Eigen::VectorXd::Zero(table.size()), est);
  if (prior.size()) pr.AddPriors(prior, Eigen::VectorXd::Zero(table.size()));
  ceres::Solver::Summary summary;
  ceres::Solve(Problem::SolverOptions(100, 1), &pr.ceres_problem(), &summary);
  CeresFit out;
  out.values.resize(est.size());
  for (size_t b = 0; b < est.size(); ++b) out.values[b] = pr.values()[est[b]];
  out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.initial_cost = summary.initial_cost;
  out.final_cost = summary.final_cost;
  return out;
}

// The loop's fit equals Ceres's: each value within 1e-6 of its one-sigma
// uncertainty `std`, the same iterations, verdict and costs.
void ExpectSameFit(const Dataset& ds, const std::vector<int>& est, const Eigen::VectorXd& prior,
                   const Eigen::VectorXd& std, const std::string& what) {
  const ParameterTable table(ds);
  Problem pr(ds, table, Eigen::VectorXd::Zero(table.size()), est);
  RefitResult own;
  ASSERT_TRUE(SolveWithoutCeres(pr, prior, 100, &own)) << what;
  const CeresFit ref = SolveWithCeres(ds, table, est, prior);
  EXPECT_FALSE(own.ceres) << what;
  ASSERT_EQ(own.values.size(), ref.values.size()) << what;
  for (size_t b = 0; b < est.size(); ++b) {
    EXPECT_LE(std::abs(own.values[b] - ref.values[b]), 1e-6 * std[b]) << what << " " << table.names()[est[b]];
    EXPECT_EQ(pr.values()[est[b]], own.values[b]) << what << ": the problem holds the solution";
  }
  EXPECT_EQ(own.iterations, ref.iterations) << what;
  EXPECT_EQ(own.converged, ref.converged) << what;
  EXPECT_NEAR(own.initial_cost, ref.initial_cost, 1e-12 * ref.initial_cost) << what;
  EXPECT_NEAR(own.final_cost, ref.final_cost, 1e-9 * ref.final_cost) << what;
  EXPECT_FALSE(own.message.empty()) << what;
}

Eigen::VectorXd StdOf(const Result& r) { return r.std; }

TEST(IdentifyWithoutCeres, LeastSquaresAndMapFitsEqualCeresOnTangoS3AndS4) {
  for (const std::string subset : {"S3", "S4"}) {
    const Dataset ds = Tango(subset == "S3");
    const ParameterTable table(ds);
    IdentifyOptions opt;
    opt.estimate = {subset};
    opt.allow_unidentifiable = true;  // S4: some errors undetermined on this plan
    const std::vector<int> est = Indices(table, ResolveEstimate(ds, opt));
    ASSERT_EQ(est.size(), subset == "S3" ? 52u : 121u);
    // Identify's final fit (from the nominal: S4's MAP pre-fit point is no
    // better determined, S3's start is determined) and the MAP pre-fit.
    const Result ls = Identify(ds, opt);
    ExpectSameFit(ds, est, Eigen::VectorXd(), StdOf(ls), subset + " least squares");
    opt.prior = true;
    const Result map = Identify(ds, opt);
    ExpectSameFit(ds, est, MachinePriorScales(ds, table), StdOf(map), subset + " MAP");
    // Identify end to end: its values are the Ceres least-squares fit's.
    const CeresFit ref = SolveWithCeres(ds, table, est, Eigen::VectorXd());
    for (size_t b = 0; b < est.size(); ++b)
      EXPECT_LE(std::abs(ls.values[est[b]] - ref.values[b]), 1e-6 * ls.std[b]) << subset << " " << ls.estimated[b];
    EXPECT_EQ(ls.iterations, ref.iterations) << subset;
    EXPECT_EQ(ls.converged, ref.converged) << subset;
    EXPECT_EQ(ls.rank, 0 + static_cast<int>(est.size())) << subset;
    EXPECT_EQ(ls.undetermined.empty(), subset == "S3") << subset;
  }
}

TEST(IdentifyWithoutCeres, IterationLimitLeavesTheFitToCeres) {
  // One iteration does not converge: the loop declines, the problem unchanged.
  const Dataset ds = Tango(true);
  const ParameterTable table(ds);
  IdentifyOptions opt;
  opt.estimate = {"S3"};
  const std::vector<int> est = Indices(table, ResolveEstimate(ds, opt));
  Problem pr(ds, table, Eigen::VectorXd::Zero(table.size()), est);
  RefitResult own;
  EXPECT_FALSE(SolveWithoutCeres(pr, Eigen::VectorXd(), 1, &own));
  EXPECT_TRUE(pr.values().isZero(0));
  opt.max_iterations = 1;
  const Result r = Identify(ds, opt);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.iterations, 1);
}

TEST(CertainlyUndetermined, NeverWhereAnalyzeDeterminationFindsEverythingDetermined) {
  // Orthogonal columns of norms d: ratio 1 / d, undetermined from d < 2 at
  // the threshold 0.5; the certificate fires below 0.99 of that (squared).
  const Eigen::VectorXd prior = Eigen::VectorXd::Ones(3);
  for (double d : {0.5, 1.9, 1.99, 2.01, 2.1, 10.0}) {
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(5, 3);
    J(0, 0) = 10;
    J(1, 1) = d;
    J(2, 2) = 10;
    const bool undetermined = !AnalyzeDetermination(J, prior, kDeterminedRatio).undetermined.empty();
    EXPECT_EQ(undetermined, d < 2.0) << d;
    EXPECT_EQ(CertainlyUndetermined(J, prior, kDeterminedRatio), d * d < 0.99 * 4.0) << d;
  }
  // An exactly dependent column (the Cholesky fails) and a zero column.
  Eigen::MatrixXd J = Eigen::MatrixXd::Random(20, 4) * 100;
  J.col(3) = J.col(0) - 2 * J.col(1);
  EXPECT_TRUE(CertainlyUndetermined(J, Eigen::VectorXd::Ones(4), kDeterminedRatio));
  J.col(3).setZero();
  EXPECT_TRUE(CertainlyUndetermined(J, Eigen::VectorXd::Ones(4), kDeterminedRatio));
  // TANGO: S4 at the nominal is undetermined, and certainly so; S3 is determined.
  for (bool s3 : {true, false}) {
    const Dataset ds = Tango(s3);
    const ParameterTable table(ds);
    IdentifyOptions opt;
    opt.estimate = {s3 ? "S3" : "S4"};
    const std::vector<int> est = Indices(table, ResolveEstimate(ds, opt));
    Problem pr(ds, table, Eigen::VectorXd::Zero(table.size()), est);
    Eigen::VectorXd r;
    Eigen::MatrixXd Jw;
    pr.Evaluate(&r, &Jw);
    Jw = pr.row_sigma().cwiseInverse().asDiagonal() * Jw;
    Eigen::VectorXd p(est.size());
    const Eigen::VectorXd all = MachinePriorScales(ds, table);
    for (size_t b = 0; b < est.size(); ++b) p[b] = all[est[b]];
    EXPECT_EQ(AnalyzeDetermination(Jw, p, kDeterminedRatio).undetermined.empty(), s3);
    EXPECT_EQ(CertainlyUndetermined(Jw, p, kDeterminedRatio), !s3);
  }
}

}  // namespace
}  // namespace fivecal
