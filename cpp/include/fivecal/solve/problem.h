// Problem: a dataset turned into a Ceres least-squares problem over a chosen
// set of estimated parameters (machine errors and setup parameters).
//
// Parameter names (README, "Concepts"): the machine's (E..., tip.x|y|z) followed by
// the setup parameters the dataset implies, named by each observation kind
// (observations/<kind>.h): facet.<id>, sphere.<id>.x|y|z|r, dbb.length,
// dbb.tool.x|y|z, dbb.table.x|y|z (or dbb.<setup>.… for a named mounting),
// ball3d.<setup>.tool.x|y|z, ball3d.<setup>.table.x|y|z.
#ifndef FIVECAL_PROBLEM_H_
#define FIVECAL_PROBLEM_H_

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

class ParameterTable {
 public:
  // The machine's parameters, then every kind's artefact parameters (in
  // registry order), then the parameters observations bring, in order of
  // first appearance (observations/kind.h).
  explicit ParameterTable(const Dataset& ds);

  int size() const { return static_cast<int>(names_.size()); }
  int num_machine() const { return num_machine_; }
  const std::vector<std::string>& names() const { return names_; }
  int Index(const std::string& name) const;    // -1 if unknown
  int Require(const std::string& name) const;  // throws naming the parameter

  // The parameters a kind registered under `key` (a facet or sphere id, a
  // mounting's setup id), in the kind's order; throws std::out_of_range when
  // absent.
  const std::vector<int>& group(ObservationType kind, const std::string& key) const {
    return groups_.at({kind, key});
  }
  bool has_group(ObservationType kind, const std::string& key) const {
    return groups_.count({kind, key}) > 0;
  }

  // Setup parameters estimated by default (README, identify): each kind
  // names those of its observations (ObservationKind::DefaultSetup).
  std::vector<int> DefaultSetup(const Dataset& ds) const;

  // For the kinds building the table: a new parameter, and a group.
  int Add(const std::string& name);
  void AddGroup(ObservationType kind, const std::string& key, std::vector<int> indices) {
    groups_[{kind, key}] = std::move(indices);
  }

 private:
  std::vector<std::string> names_;
  std::map<std::string, int> index_;
  int num_machine_ = 0;
  std::map<std::pair<ObservationType, std::string>, std::vector<int>> groups_;
};

// Expands presets (S1 S2 S3 S4 for wCBXfZYSt, "location", "auto") are
// resolved by the identification; this lists a thesis subset's machine
// parameters (throws for an unknown preset or another topology).
std::vector<std::string> ThesisSubset(const Machine& m, const std::string& preset);

// Location-error candidates in conventional priority order (rotary axis
// orientations, spindle offsets, rotary axis positions, linear-axis
// squareness, spindle orientation), for the greedy `location` selection.
std::vector<std::string> LocationCandidates(const Machine& m);

// All error-motion and backlash candidates after the location errors, for `auto`.
std::vector<std::string> MotionCandidates(const Machine& m);

class AnalyticResiduals;

// Declared noise of a scale bar's length row (mm): a calibrated bar's length
// uncertainty, of the order of a probe touch.
constexpr double kScaleBarSigma = 0.001;

// Declared noise of residual row k of an observation (mm, or rad for a
// rotation row): its own sigma, else its instrument's (Dataset::
// instrument_sigma), else its kind's default.
double ObservationSigma(const Dataset& ds, const Observation& o, int k);

class Problem {
 public:
  // `values`: every parameter's value (initial for the estimated ones, the
  // fixed value for the others). `estimated`: indices into the table.
  //
  // analytic: evaluate all rows in one AnalyticResiduals block (fast; the
  // kinds without analytic derivatives enter it through their functors). A
  // robust loss needs one block per observation, so it uses the templated
  // functors with automatic derivatives, as does analytic = false.
  Problem(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
          const std::vector<int>& estimated, const std::string& robust = "",
          double robust_scale = 0.0, bool analytic = true);

  // The solver settings every fit of a Problem uses (Identify, Refit).
  static ceres::Solver::Options SolverOptions(int max_iterations, int num_threads);

  ceres::Problem& ceres_problem() { return *problem_; }
  const Eigen::VectorXd& values() const { return values_; }
  const std::vector<int>& estimated() const { return estimated_; }
  int num_rows() const { return num_rows_; }
  // Per residual row: the observation index, or -(1 + scale bar index).
  const std::vector<int>& row_source() const { return row_source_; }

  // Residuals (mm) and dense Jacobian (rows x estimated) of the data rows at
  // the current values, unweighted (the prior rows are not included).
  void Evaluate(Eigen::VectorXd* residuals, Eigen::MatrixXd* jacobian);

  // Declared noise (one sigma, mm) of every data row: the observation's
  // "sigma", else its kind's default; scale bars kScaleBarSigma. The solver
  // sees every data row divided by it.
  const Eigen::VectorXd& row_sigma() const { return row_sigma_; }

  // Adds one prior row (theta_j - mean_j) / sigma_j per estimated parameter
  // (indexed like the table): the MAP fit. Call once, before solving.
  void AddPriors(const Eigen::VectorXd& prior_sigma, const Eigen::VectorXd& prior_mean);
  bool has_priors() const { return !prior_blocks_.empty(); }

  // Re-reads the observations of the dataset (whose readings and axis values
  // were edited in place since; types, targets and setups unchanged) and
  // sets every parameter's value, so that the prepared problem serves the
  // next fit (Monte Carlo trials). False, changing nothing, when the rows are
  // not one batch (robust loss, analytic = false: the per-observation
  // functors captured the readings at construction): build a new Problem then.
  bool Refresh(const Eigen::VectorXd& values);

  // The one block of every row when the problem is a single analytic batch
  // (no robust loss), else null: for a solver other than Ceres (refit.h),
  // which then hands its solution back through SetEstimated.
  AnalyticResiduals* analytic_batch() { return analytic_; }
  // Sets the estimated parameters' values (in estimated() order).
  void SetEstimated(const Eigen::VectorXd& v);

 private:
  friend class ProblemBuilder;
  void AddCostBlock(ceres::CostFunction* cost, int num_residuals, const std::vector<double*>& ptrs,
                    int source);
  void AddConstantRows(int num_residuals, std::function<void(double*)> eval, int source);
  double SigmaOfRow(int source, int k) const;

  const Dataset& ds_;
  const ParameterTable& table_;
  Eigen::VectorXd values_;  // storage of the Ceres parameter blocks
  std::vector<int> estimated_;
  std::vector<int> block_of_;  // per parameter: position in estimated_ or -1
  std::shared_ptr<const ResidualContext> ctx_;
  std::unique_ptr<ceres::Problem> problem_;
  std::vector<ceres::ResidualBlockId> blocks_;
  std::vector<int> block_row_;  // first residual row of each block
  std::vector<std::pair<int, std::function<void(double*)>>> constant_;
  std::string robust_;
  double robust_scale_ = 0.0;  // mm; each block's loss gets it in its weighted units
  Eigen::VectorXd row_sigma_;
  std::vector<ceres::ResidualBlockId> prior_blocks_;
  int num_rows_ = 0;
  std::vector<int> row_source_;
  AnalyticResiduals* analytic_ = nullptr;  // the single block when analytic (owned by problem_)
};

}  // namespace fivecal

#endif  // FIVECAL_PROBLEM_H_
