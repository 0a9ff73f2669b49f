// Refit: a fit prepared once and repeated on datasets that differ from a
// reference only in their readings (Monte Carlo trials, repeated measurement
// cycles). The estimated set, the fixed values and the robust scale are those
// of `reference_fit` (a Result of Identify on `reference`); every fit starts
// from its values and skips the identifiability checks of Identify. Fit() is
// const and thread-safe (each call builds its own Ceres problem). A Session
// fits without Ceres where it can (one analytic batch, no robust loss): the
// same trust-region steps and stopping rules, so the same values to rounding.
#ifndef FIVECAL_REFIT_H_
#define FIVECAL_REFIT_H_

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"

namespace fivecal {

class Problem;

struct RefitResult {
  Eigen::VectorXd values;   // estimated parameters, in Result::estimated order
  Eigen::VectorXd std;      // one-sigma as Identify reports it (only with_std)
  double sigma = 0;         // residual standard deviation (only with_std)
  bool converged = false;
  int iterations = 0;
  double final_cost = 0;
  bool ceres = true;  // solved by Ceres (false: by Session's own loop)
  double initial_cost = 0;  // only SolveWithoutCeres
  std::string message;      // why it stopped (only SolveWithoutCeres)
  // SolveWithoutCeres with keep_jacobian: the residuals (mm) and the
  // weighted Jacobian (rows / sigma, estimated order) at `values`, from the
  // evaluation the fit made there (empty when it made none with derivatives).
  Eigen::VectorXd residuals_mm;
  Eigen::MatrixXd weighted_jacobian;
};

// Residuals (mm) and weighted Jacobian already evaluated at `at` (estimated
// values, in the problem's estimated order): a fit starting there takes its
// first evaluation from them.
struct EvaluatedAt {
  Eigen::VectorXd at, residuals_mm;
  Eigen::MatrixXd weighted_jacobian;
};

// Solves `problem` from its values as Ceres does with
// Problem::SolverOptions(max_iterations, 1), with the trust-region loop of
// Refit::Session, when the problem is one analytic batch (no robust loss).
// prior_all: the sigmas of MAP prior rows (per table index, mean 0; empty:
// none), which the loop adds itself (not through Problem::AddPriors). False,
// the problem unchanged, where the loop does not reproduce Ceres (robust
// loss, iteration limit, a failed step): solve it with Ceres then. True: the
// problem holds the solution; out->values in estimated() order.
// keep_jacobian: out holds the residuals and weighted Jacobian at the
// solution. first: an evaluation at the problem's values, used instead of
// evaluating there again.
bool SolveWithoutCeres(Problem& problem, const Eigen::VectorXd& prior_all, int max_iterations, RefitResult* out,
                       bool keep_jacobian = false, const EvaluatedAt* first = nullptr);

class Refit {
 public:
  Refit(const Dataset& reference, const IdentifyOptions& options, const Result& reference_fit);
  ~Refit();
  Refit(const Refit&) = delete;
  Refit& operator=(const Refit&) = delete;

  const std::vector<std::string>& estimated() const;
  // Throws std::invalid_argument if `ds` does not have the reference's
  // observation structure (count, types, targets, setups).
  RefitResult Fit(const Dataset& ds, bool with_std = false) const;

  // One thread's state for many fits: a copy of the reference dataset, to be
  // edited in place (readings and axis values only), and the problem prepared
  // once on it; each Fit re-reads the edited observations and starts again
  // from the reference values. Same results as Refit::Fit on the edited
  // dataset, without copying the dataset or rebuilding the problem per fit.
  // One Session per thread; the Refit must outlive it.
  class Session {
   public:
    explicit Session(const Refit& refit);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
    Dataset& dataset();
    RefitResult Fit(bool with_std = false);
    // The caller's word that every edit changes the observations' axis
    // values only (a Monte Carlo trial moving touches along their approach
    // lines; scale bar lengths may change too). After two fits that bear it
    // out (their rows differ from the previous ones in axis values alone),
    // a fit then re-reads the axis values instead of preparing the rows
    // again; results are the same.
    void set_axes_only(bool on);

   private:
    struct State;
    std::unique_ptr<State> s_;
  };

 private:
  std::unique_ptr<Problem> MakeProblem(const Dataset& ds) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fivecal

#endif  // FIVECAL_REFIT_H_
