// Identify, stage 3 of 6 (identify_request.h lists them): the fit, and the
// one factor of the weighted Jacobian at its solution that the determination
// and the covariance share.
//
// A plain least-squares request must be determined by the data: judged at
// the start and, when the start says no, again near the solution (after a MAP
// fit, well posed whatever the start), so that a rough nominal neither drops
// nor admits parameters wrongly. "auto" and variance components then set
// their hyperparameters (class scales, noise factors) and the final fit runs.
#ifndef FIVECAL_SOLVE_IDENTIFY_FIT_H_
#define FIVECAL_SOLVE_IDENTIFY_FIT_H_

#include <Eigen/Core>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_problem.h"
#include "fivecal/solve/identify_request.h"
#include "fivecal/solve/normal_equations.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

// An estimated noise beyond this many times the declared one is not taken
// for noise (the plain chi-square test flags sqrt(2) x already).
constexpr double kMaxNoiseFactor = 3.0;

struct IdentifyFit {
  SingleFit fit;                       // the final fit; fit.values every table entry
  int adapt_iterations = 0;            // solver iterations of the hyperparameter rounds
  Eigen::VectorXd fit_prior;           // prior rows of the final fit (per table entry; empty: none)
  std::map<std::string, double> class_scales;         // estimate "auto"
  std::vector<VarianceComponent> variance_components;  // variance_components=true
  // The dataset the final fit weighed its rows by: `ds`, or (variance
  // components) a copy with the estimated noise, owned here.
  std::unique_ptr<Dataset> weighted_copy;
  const Dataset* weighted = nullptr;

  // At the solution: residual rows (mm), the weighted Jacobian (dense: rows x
  // p; normal equations: its p x p factor), and the declared sigma and source
  // of every row (held by the problem, not copied: long data).
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  const Eigen::VectorXd* row_sigma = nullptr;
  const std::vector<int>* row_source = nullptr;
  int num_rows = 0;
  // The one factor every analysis below shares: the p x p upper triangular R
  // of the QR of Jw with the placement rows appended (R^T R = Jw^T Jw + U^-2).
  Eigen::MatrixXd factor;
  // Normal equations only: the pass at the solution (J^T J in mm, per unit)
  // and the units of its rows other than mm (NormalEquationProblem::other_units,
  // row_unit; held by the problem).
  bool normal_equations = false;
  NormalEquationFit nfit;
  std::vector<std::string> other_units;
  const std::vector<unsigned char>* row_unit = nullptr;
  std::unique_ptr<Problem> problem;    // dense: the problem at the solution
};

// Runs the fit of a resolved request on its problem. Throws the refusal of a
// least-squares request the data do not determine (unless allow_unidentifiable).
IdentifyFit FitRequest(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq,
                       IdentifyProblem* problem);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_FIT_H_
