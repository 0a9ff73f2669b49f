#include "fivecal/solve/identify_problem.h"

#include <algorithm>
#include <stdexcept>
#include <thread>

#include "fivecal/observations/registry.h"
#include "fivecal/solve/refit.h"
#include "solve/residual_units.h"

namespace fivecal {

void WeightedJacobian(Problem* pr, Eigen::VectorXd* r, Eigen::MatrixXd* Jw) {
  pr->Evaluate(r, Jw);
  const Eigen::VectorXd w = pr->row_sigma().cwiseInverse();
  *Jw = w.asDiagonal() * *Jw;
}

SingleFit RunFit(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                 const std::vector<int>& est, const IdentifyOptions& opt, const Eigen::VectorXd& prior_all,
                 std::unique_ptr<Problem>* final_problem, std::unique_ptr<Problem> prepared,
                 const EvaluatedAt* first) {
  const ceres::Solver::Options so = Problem::SolverOptions(opt.max_iterations, opt.num_threads);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(table.size());
  SingleFit out;
  out.values = values;
  // Invalid prior sigmas are left to AddPriors, which names them (+inf: no
  // row, the estimated parameters without a placement in a least-squares fit).
  bool valid_priors = true;
  for (int i : est) valid_priors = valid_priors && (!prior_all.size() || prior_all[i] > 0);
  bool first_pass = true;
  auto run = [&](Problem* pr) {
    // The loop Ceres would run, without Ceres's per-solve overhead (most of
    // a fit's time on a few hundred rows); Ceres where it does not apply.
    RefitResult own;
    // The evaluation made before the fit applies to its first pass only.
    const EvaluatedAt* at_start = first_pass ? first : nullptr;
    first_pass = false;
    if (valid_priors && SolveWithoutCeres(*pr, prior_all, opt.max_iterations, &own, true, at_start)) {
      out.values = pr->values();
      out.r.swap(own.residuals_mm);
      out.Jw.swap(own.weighted_jacobian);
      out.converged = own.converged;
      out.iterations += own.iterations;
      out.message = own.message;
      if (out.initial_cost == 0) out.initial_cost = own.initial_cost;
      out.final_cost = own.final_cost;
      return;
    }
    if (prior_all.size()) pr->AddPriors(prior_all, zero);
    ceres::Solver::Summary summary;
    ceres::Solve(so, &pr->ceres_problem(), &summary);
    out.values = pr->values();
    out.r.resize(0);
    out.Jw.resize(0, 0);
    out.converged = summary.termination_type == ceres::CONVERGENCE;
    out.iterations += std::max(0, static_cast<int>(summary.iterations.size()) - 1);
    out.message = summary.message;
    if (out.initial_cost == 0) out.initial_cost = summary.initial_cost;
    out.final_cost = summary.final_cost;
  };
  std::unique_ptr<Problem> problem = prepared ? std::move(prepared) : std::make_unique<Problem>(ds, table, values, est);
  run(problem.get());
  if (!opt.robust.empty() && opt.robust != "none") {
    double scale = opt.robust_scale;
    if (!(scale > 0)) {
      Eigen::VectorXd r;
      problem->Evaluate(&r, nullptr);
      scale = DefaultRobustScale(PositionScaledResiduals(ds, r, problem->row_sigma(), problem->row_source()));
    }
    out.robust_scale = scale;
    problem = std::make_unique<Problem>(ds, table, out.values, est, opt.robust, scale);
    run(problem.get());
  }
  if (final_problem) *final_problem = std::move(problem);
  return out;
}

// Whether the fit runs on the accumulated normal equations
// (normal_equations.h); empty = yes, else why not. What needs more of the
// Jacobian than J^T J stays dense: "location" (the greedy selection projects
// the columns), "auto" and variance components (the hyperparameter loop
// takes per-row leverages from the hat matrix), robust losses (Ceres
// reweights each row). Every kind can: those without analytic derivatives
// enter through their templated functors.
std::string DenseReason(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq) {
  const size_t p = rq.est.size();
  if (opt.fit_path == "dense") return "fit_path 'dense' requested";
  std::string why;
  if (rq.location || rq.automatic) why = "estimate 'location' and 'auto' select on the dense Jacobian";
  else if (opt.variance_components) why = "variance components need the per-row leverages";
  else if (!opt.robust.empty() && opt.robust != "none") why = "a robust loss reweights every row";
  if (!why.empty()) {
    if (opt.fit_path == "normal_equations")
      throw std::invalid_argument("identify: fit_path 'normal_equations' is not available here: " + why);
    return why;
  }
  if (opt.fit_path == "normal_equations") return "";
  double rows = 0;
  for (const Observation& o : ds.observations) rows += KindOf(o).rows();
  for (const TraceBlock& b : ds.blocks) rows += static_cast<double>(b.size()) * KindOf(b.type).rows();
  return rows * static_cast<double>(p) > NormalEquationElements(ds) ? "" : "short data";
}

namespace {

bool SameValues(const Eigen::VectorXd& a, const Eigen::VectorXd& b) { return a.size() == b.size() && a == b; }

SingleFit ToSingleFit(const NormalEquationFit& f) {
  SingleFit s;
  s.values = f.values;
  s.converged = f.converged;
  s.iterations = f.iterations;
  s.message = f.message;
  s.initial_cost = f.initial_cost;
  s.final_cost = f.final_cost;
  return s;
}

}  // namespace

IdentifyProblem::IdentifyProblem(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq)
    : ds_(ds), opt_(opt), rq_(rq) {
  if (DenseReason(ds, opt, rq).empty())
    nep_ = std::make_unique<NormalEquationProblem>(
        ds, rq.table, rq.start, rq.est,
        opt.num_threads > 0 ? opt.num_threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency())));
}

Eigen::MatrixXd IdentifyProblem::WeightedJacobianAt(const Eigen::VectorXd& at) {
  if (nep_) return NormalFactor(nep_->Accumulate(at, true).JtJ);  // true: the fit reuses it
  kept_ = std::make_unique<Problem>(ds_, rq_.table, at, rq_.est);
  kept_at_ = at;
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(kept_.get(), &r, &Jw);
  start_eval_.at = Gather(at, rq_.est);
  start_eval_.residuals_mm = r;
  start_eval_.weighted_jacobian = Jw;
  start_eval_values_ = at;
  return Jw;
}

// A dense fit leaves its problem kept (at its solution) when that is one
// analytic batch, as a fresh problem there would be.
SingleFit IdentifyProblem::FitFrom(const Eigen::VectorXd& start, const Eigen::VectorXd& prior_all) {
  if (nep_) return ToSingleFit(FitNormalEquations(*nep_, start, prior_all, opt_.max_iterations));
  std::unique_ptr<Problem> prepared = kept_ && kept_at_ == start ? std::move(kept_) : nullptr;
  std::unique_ptr<Problem> fitted;
  const SingleFit fit = RunFit(ds_, rq_.table, start, rq_.est, opt_, prior_all, &fitted, std::move(prepared),
                               SameValues(start_eval_values_, start) ? &start_eval_ : nullptr);
  kept_.reset();
  if (fitted && fitted->analytic_batch()) {
    kept_ = std::move(fitted);
    kept_at_ = fit.values;
  }
  return fit;
}

Eigen::MatrixXd IdentifyProblem::WeightedJacobianAfter(const SingleFit& fit) {
  if (!nep_ && fit.Jw.size()) return fit.Jw;  // the fit's own evaluation at its solution
  if (nep_ || !kept_ || kept_at_ != fit.values) return WeightedJacobianAt(fit.values);
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(kept_.get(), &r, &Jw);
  return Jw;
}

SingleFit IdentifyProblem::FinalFit(const Dataset& weighted, const Eigen::VectorXd& start,
                                    const Eigen::VectorXd& prior_all, std::unique_ptr<Problem>* problem,
                                    NormalEquationFit* nfit) {
  if (nep_) {
    *nfit = FitNormalEquations(*nep_, start, prior_all, opt_.max_iterations);
    return ToSingleFit(*nfit);
  }
  const bool same = &weighted == &ds_;
  return RunFit(weighted, rq_.table, start, rq_.est, opt_, prior_all, problem,
                same && kept_ && kept_at_ == start ? std::move(kept_) : nullptr,
                same && SameValues(start_eval_values_, start) ? &start_eval_ : nullptr);
}

}  // namespace fivecal
