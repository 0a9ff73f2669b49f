// Identify, stage 2 of 6 (identify_request.h lists them): the problem the
// request is solved on, and the one fit everything else repeats.
//
// A dense problem (the Jacobian rows of the data, solve/problem.h) or, for
// long data, the normal equations accumulated chunk by chunk
// (solve/normal_equations.h). Every analysis of the noise-weighted Jacobian
// Jw depends on it only through Jw^T Jw, so on the normal-equation path Jw is
// handed on as a p x p factor of that (NormalFactor).
#ifndef FIVECAL_SOLVE_IDENTIFY_PROBLEM_H_
#define FIVECAL_SOLVE_IDENTIFY_PROBLEM_H_

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_request.h"
#include "fivecal/solve/normal_equations.h"
#include "fivecal/solve/problem.h"
#include "fivecal/solve/refit.h"

namespace fivecal {

// One solver run.
struct SingleFit {
  Eigen::VectorXd values;  // every table entry
  bool converged = false;
  int iterations = 0;
  std::string message;
  double initial_cost = 0, final_cost = 0, robust_scale = 0;
  // Dense fits without Ceres: the residuals (mm) and weighted Jacobian at
  // `values`, from the fit's own evaluation there (empty otherwise).
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
};

// One fit of `est` from `values`: plain least squares, or MAP with
// `prior_all` (per table index; empty = no prior rows); with the robust loss
// a plain pass first sets the loss scale. `prepared`: a Problem(ds, table,
// values, est) already made, for the first pass; `final_problem` receives the
// problem at the solution.
// `first`: residuals and weighted Jacobian already evaluated at `values`.
SingleFit RunFit(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                 const std::vector<int>& est, const IdentifyOptions& opt, const Eigen::VectorXd& prior_all,
                 std::unique_ptr<Problem>* final_problem, std::unique_ptr<Problem> prepared = nullptr,
                 const EvaluatedAt* first = nullptr);

// Residuals (mm) and the Jacobian with rows divided by their declared noise.
void WeightedJacobian(Problem* pr, Eigen::VectorXd* r, Eigen::MatrixXd* Jw);

// Why the fit runs on the dense Jacobian ("" = on the normal equations).
std::string DenseReason(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq);

// The problem of a resolved request. It keeps the dense problem it made last
// (at `kept_at`), so that a fit or a Jacobian there does not make it again.
class IdentifyProblem {
 public:
  IdentifyProblem(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq);
  IdentifyProblem(const IdentifyProblem&) = delete;
  IdentifyProblem& operator=(const IdentifyProblem&) = delete;

  bool normal_equations() const { return nep_ != nullptr; }
  const NormalEquationProblem* nep() const { return nep_.get(); }

  // The weighted Jacobian at `at` (normal equations: its p x p factor).
  Eigen::MatrixXd WeightedJacobianAt(const Eigen::VectorXd& at);
  // A fit of the estimated set from `start` under `prior_all` (empty: none).
  SingleFit FitFrom(const Eigen::VectorXd& start, const Eigen::VectorXd& prior_all);
  // The weighted Jacobian at a fit's solution, from its problem when kept.
  Eigen::MatrixXd WeightedJacobianAfter(const SingleFit& fit);

  // The final fit, on `weighted` (the dataset, or its copy with estimated
  // noise). Dense: `problem` receives the problem at the solution; normal
  // equations: `nfit` the accumulated fit (its pass at the solution).
  SingleFit FinalFit(const Dataset& weighted, const Eigen::VectorXd& start, const Eigen::VectorXd& prior_all,
                     std::unique_ptr<Problem>* problem, NormalEquationFit* nfit);

 private:
  const Dataset& ds_;
  const IdentifyOptions& opt_;
  const IdentifyRequest& rq_;
  std::unique_ptr<NormalEquationProblem> nep_;
  std::unique_ptr<Problem> kept_;
  Eigen::VectorXd kept_at_;
  // The last dense evaluation at a start (WeightedJacobianAt): every fit
  // from there takes its first evaluation from it.
  EvaluatedAt start_eval_;
  Eigen::VectorXd start_eval_values_;  // every table entry
};

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_PROBLEM_H_
