// The fit path for long data: the normal equations Jw^T Jw, Jw^T rw of the
// noise-weighted rows accumulated chunk by chunk from the batch of every row
// (analytic_residuals.h: analytic derivatives, and the templated functors of
// the kinds without them, in the dense path's row order), never the
// rows x parameters Jacobian. Any dataset, of any mix of kinds, runs here.
// An R-test or ball-bar trace at 1 kHz has millions of rows and a handful of
// unknowns: the dense Jacobian then costs memory and traffic out of all
// proportion to the p x p system that decides the fit. Memory is O(p^2) plus
// the data, the residual rows and their sigmas (and one cost function per
// observation of a templated kind): the analytic kinds' prepared rows are
// made a chunk at a time during each pass (RowStorage::kPerChunk), so a
// pass holds a chunk of them per thread, not one per observation.
//
// The sums run over a fixed partition of the rows (kBlocks blocks, each
// summed in row order, then the blocks in order), so the result does not
// depend on the number of threads.
#ifndef FIVECAL_NORMAL_EQUATIONS_H_
#define FIVECAL_NORMAL_EQUATIONS_H_

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/model/kinematic_model.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

class AnalyticResiduals;
class LongRun;

// The normal equations of the data rows at one point.
struct NormalEquations {
  Eigen::MatrixXd JtJ;             // Jw^T Jw, rows divided by their declared sigma
  Eigen::VectorXd Jtr;             // Jw^T rw
  Eigen::MatrixXd JtJ_unweighted;  // J^T J in mm (only when asked for)
  double cost = 0;                 // 0.5 sum rw^2
  // Jw^T Jw of the rows of each unit but mm (NormalEquationProblem::
  // other_units(), same order): a pose's rotation rows. The residual
  // summary per unit needs each unit's share of the parameters,
  // trace(hat N_unit), which the dense path takes row by row.
  std::vector<Eigen::MatrixXd> JtJ_units;
};

class NormalEquationProblem {
 public:
  // values: every table entry (constants for the fixed ones: the fits
  // change only the estimated ones); estimated: table indices, in
  // covariance order.
  NormalEquationProblem(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                        const std::vector<int>& estimated, int num_threads);
  ~NormalEquationProblem();

  int num_rows() const { return static_cast<int>(row_sigma_.size()); }
  int num_parameters() const { return static_cast<int>(estimated_.size()); }
  const std::vector<int>& estimated() const { return estimated_; }
  const std::vector<int>& row_source() const;
  const Eigen::VectorXd& row_sigma() const { return row_sigma_; }
  // The row units other than mm in this data, in order of first row
  // (empty for data of lengths only).
  const std::vector<std::string>& other_units() const { return other_units_; }
  // Each row's unit: 0 mm, else 1 + its index in other_units(); empty when every row is in mm.
  const std::vector<unsigned char>& row_unit() const { return row_unit_; }

  // At `values` (every table entry): residuals only (mm, data-sized), or the
  // normal equations (unweighted J^T J too when `unweighted`).
  // The last accumulation is kept, with its residual rows: the analyses and
  // the fit that follows them start at the same point, the report's
  // residuals are those of the fit's last point, and one pass serves both.
  Eigen::VectorXd Residuals(const Eigen::VectorXd& values) const;
  NormalEquations Accumulate(const Eigen::VectorXd& values, bool unweighted = false) const;
  // 0.5 sum rw^2 at `values`: a pass without derivatives.
  double Cost(const Eigen::VectorXd& values) const;

  // Whether the passes run on the kinds' column blocks (long_kernel.h).
  bool columnar() const { return !long_runs_.empty(); }
  // Passes over the data so far (a pass with the Jacobian counts in both).
  int jacobian_passes() const { return jacobian_passes_; }
  int residual_passes() const { return residual_passes_; }

 private:
  struct Block {
    int begin, end;  // prepared rows
    int row;         // first residual row
    int rows;        // residual rows
  };
  void Pass(const Eigen::VectorXd& values, bool jacobian, bool unweighted, double* residuals,
            std::vector<NormalEquations>* partial) const;
  // Block B's sums through the kinds' column kernels (long_runs_).
  void LongBlock(const KinematicModel& model, const Eigen::VectorXd& values, const Block& B, bool jacobian,
                 bool unweighted, double* residuals, NormalEquations* ne) const;

  const Dataset& ds_;
  std::vector<int> estimated_;
  std::unique_ptr<AnalyticResiduals> batch_;
  Eigen::VectorXd row_sigma_;
  std::vector<std::string> other_units_;
  std::vector<unsigned char> row_unit_;  // per row: 0 mm, else 1 + other unit; empty when none
  double uniform_sigma_ = 0;  // every row's sigma when they are all equal, else 0
  std::vector<Block> blocks_;
  // Long traces: when every observation is of a kind with a column kernel
  // (ObservationKind::MakeLongRun) and the data have no artefact rows, the
  // runs of consecutive observations of one kind as column blocks, and the
  // passes take them instead of the prepared rows (long_kernel.h).
  struct Run {
    int begin, end;  // observations
    std::unique_ptr<LongRun> run;
  };
  std::vector<Run> long_runs_;
  int num_threads_;
  mutable int jacobian_passes_ = 0, residual_passes_ = 0;
  mutable Eigen::VectorXd cached_values_;
  mutable NormalEquations cached_;
  mutable Eigen::VectorXd cached_residuals_;  // rows (mm) of the last accumulation
  mutable bool cached_unweighted_ = false;
};

// Outcome of one fit on the normal equations, as identify's Solve.
struct NormalEquationFit {
  Eigen::VectorXd values;  // every table entry
  bool converged = false;
  int iterations = 0;
  std::string message;
  double initial_cost = 0, final_cost = 0;
  NormalEquations at_solution;  // data rows only (no prior rows), with J^T J in mm
};

// Levenberg-Marquardt on the accumulated normal equations with the
// convergence tests and tolerances of the dense path (Problem::SolverOptions:
// function, parameter and gradient tolerances; a trust region so large that
// the first steps are Gauss-Newton steps). prior_all: per table entry, the
// prior sigma of a MAP fit (rows (theta_j - 0) / sigma_j), empty for none.
NormalEquationFit FitNormalEquations(const NormalEquationProblem& pr, const Eigen::VectorXd& start,
                                     const Eigen::VectorXd& prior_all, int max_iterations);

// A p x p factor R with R^T R = N, from the eigen-decomposition of the
// column-scaled N (the scaled J^T J): what the dense analyses of a Jacobian
// (identifiability.h, the posterior of a MAP fit) see of it, since they
// depend on J only through J^T J. Eigenvalues below the rounding level of
// the scaled N (p eps times the largest) are taken as exactly zero: the
// normal equations cannot resolve singular values below about sqrt(p eps)
// (1e-7) of the largest, so such directions count as free.
Eigen::MatrixXd NormalFactor(const Eigen::MatrixXd& N);

// Whether identify takes the normal-equation path by default: rows x p above
// kNormalEquationElements.
//
// Below, the dense Jacobian is at most 16 MB, the dense fit is as fast (the
// chunked evaluation saves memory traffic, not arithmetic) and its rank
// decisions resolve singular values to the rank tolerance (1e-9) rather than
// the 1e-7 of the normal equations. Above, the dense path's copies of J
// (the Jacobian Ceres holds, the weighted copy, the column-scaled copies of
// the analyses) dominate time and memory: at 3e6 rows x 4 unknowns the dense
// fit takes seconds for a tenth of a second of arithmetic.
constexpr double kNormalEquationElements = 2e6;

// Traces whose every observation is of a kind with a column kernel
// (ObservationKind::MakeLongRun: R-test and ball-bar samples) take the
// normal equations from rows x p above kColumnarElements: a pass then costs
// the fused kernel alone, several times less than the dense fit's
// evaluation and copies of J (a 10^4-sample R-test, 1.2e5 elements).
constexpr double kColumnarElements = 1e5;

// kColumnarElements for such data, else kNormalEquationElements (what
// identify's automatic fit path compares rows x p with).
double NormalEquationElements(const Dataset& ds);

}  // namespace fivecal

#endif  // FIVECAL_NORMAL_EQUATIONS_H_
