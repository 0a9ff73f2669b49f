#include "fivecal/solve/refit.h"

#include <ceres/ceres.h>

#include <cmath>
#include <stdexcept>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

struct Refit::Impl {
  Impl(const Dataset& ref, const IdentifyOptions& o) : reference(ref), table(ref), options(o) {}
  Dataset reference;
  ParameterTable table;
  IdentifyOptions options;
  std::vector<std::string> estimated;
  std::vector<int> est;
  Eigen::VectorXd start;
  double robust_scale = 0;
  Eigen::VectorXd prior;  // per table index when the reference fit was MAP; empty otherwise
};

Refit::Refit(const Dataset& reference, const IdentifyOptions& options, const Result& fit)
    : impl_(std::make_unique<Impl>(reference, options)) {
  reference.Validate();
  Impl& d = *impl_;
  if (fit.names != d.table.names())
    throw std::invalid_argument("refit: the reference result belongs to another dataset");
  d.estimated = fit.estimated;
  for (const std::string& n : fit.estimated) d.est.push_back(d.table.Require(n));
  d.start = fit.values;
  d.robust_scale = fit.robust_scale;
  if (fit.map_fit) {
    // Every refit is the same MAP fit as the reference (its prior rows).
    d.prior = Eigen::VectorXd::Ones(d.table.size());
    for (size_t i = 0; i < d.est.size() && i < fit.prior_std.size(); ++i) d.prior[d.est[i]] = fit.prior_std[i];
  }
  if (!options.robust.empty() && options.robust != "none" && !(d.robust_scale > 0))
    throw std::invalid_argument("refit: robust loss without a robust scale in the reference result");
}

Refit::~Refit() = default;

const std::vector<std::string>& Refit::estimated() const { return impl_->estimated; }

namespace {

// Solves a prepared refit problem from its current values; the summary and,
// with_std, the standard deviations as Identify reports them.
RefitResult SolveRefit(Problem& problem, const std::vector<int>& est,
                       const Eigen::VectorXd& prior_all, const IdentifyOptions& options, bool with_std) {
  const ceres::Solver::Options so = Problem::SolverOptions(options.max_iterations, 1);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem.ceres_problem(), &summary);
  RefitResult out;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  out.final_cost = summary.final_cost;
  out.values.resize(est.size());
  for (size_t i = 0; i < est.size(); ++i) out.values[i] = problem.values()[est[i]];
  if (with_std) {
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    problem.Evaluate(&r, &J);
    const Eigen::VectorXd w = problem.row_sigma().cwiseInverse();
    const Eigen::MatrixXd Jw = w.asDiagonal() * J;
    if (prior_all.size()) {
      // Posterior covariance as Identify's MAP branch.
      const int p = static_cast<int>(est.size());
      Eigen::VectorXd prior(p);
      for (int i = 0; i < p; ++i) prior[i] = prior_all[est[i]];
      const Eigen::MatrixXd Js = Jw * prior.asDiagonal();
      Eigen::MatrixXd N = Js.transpose() * Js;
      N.diagonal().array() += 1.0;
      const Eigen::MatrixXd Cs = N.ldlt().solve(Eigen::MatrixXd::Identity(p, p));
      const int dof = std::max(1, problem.num_rows() - static_cast<int>(std::lround(p - Cs.trace())));
      const double chi2 = r.cwiseProduct(w).squaredNorm();
      const double k2 = std::max(1.0, chi2 / dof);
      out.sigma = std::sqrt(r.squaredNorm() / dof);
      out.std = (k2 * Cs.diagonal()).cwiseMax(0.0).cwiseSqrt().cwiseProduct(prior);
    } else {
      const Identifiability id = AnalyzeJacobian(Jw, options.rank_tolerance);
      const int dof = problem.num_rows() - id.rank;
      out.sigma = dof > 0 ? std::sqrt(r.squaredNorm() / dof) : 0.0;
      const double s2 = dof > 0 ? r.cwiseProduct(w).squaredNorm() / dof : 0.0;
      out.std = (s2 * id.inverse_normal.diagonal()).cwiseMax(0.0).cwiseSqrt();
    }
  }
  return out;
}

}  // namespace

std::unique_ptr<Problem> Refit::MakeProblem(const Dataset& ds) const {
  const Impl& d = *impl_;
  const bool robust = !d.options.robust.empty() && d.options.robust != "none";
  auto problem = std::make_unique<Problem>(ds, d.table, d.start, d.est, robust ? d.options.robust : "",
                                           robust ? d.robust_scale : 0.0);
  if (d.prior.size()) problem->AddPriors(d.prior, Eigen::VectorXd::Zero(d.table.size()));
  return problem;
}

RefitResult Refit::Fit(const Dataset& ds, bool with_std) const {
  const Impl& d = *impl_;
  const auto& a = d.reference.observations;
  const auto& b = ds.observations;
  if (a.size() != b.size())
    throw std::invalid_argument("refit: " + std::to_string(b.size()) + " observations, the reference has " +
                                std::to_string(a.size()));
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].type != b[i].type || a[i].target != b[i].target || a[i].setup != b[i].setup ||
        a[i].axes.size() != b[i].axes.size())
      throw std::invalid_argument("refit: observations[" + std::to_string(i) +
                                  "] differs from the reference (type, target or setup)");
  const std::unique_ptr<Problem> problem = MakeProblem(ds);
  return SolveRefit(*problem, d.est, d.prior, d.options, with_std);
}

// ---- Session -------------------------------------------------------------------

struct Refit::Session::State {
  explicit State(const Refit& r) : refit(r), ds(r.impl_->reference) {}
  const Refit& refit;
  Dataset ds;
  std::unique_ptr<Problem> problem;  // prepared on ds; rebuilt per fit when it cannot refresh
};

Refit::Session::Session(const Refit& refit) : s_(std::make_unique<State>(refit)) {}
Refit::Session::~Session() = default;

Dataset& Refit::Session::dataset() { return s_->ds; }

RefitResult Refit::Session::Fit(bool with_std) {
  State& s = *s_;
  const Impl& d = *s.refit.impl_;
  if (!s.problem || !s.problem->Refresh(d.start)) s.problem = s.refit.MakeProblem(s.ds);
  return SolveRefit(*s.problem, d.est, d.prior, d.options, with_std);
}

}  // namespace fivecal
