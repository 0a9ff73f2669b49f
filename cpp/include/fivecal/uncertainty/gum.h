// GUM uncertainty framework for the identified parameters (JCGM 100 / 102,
// thesis ch. 5 and 8).
//
// The identification is a multi-input, multi-output model y = f(x): the
// inputs x are the observation readings (one per residual row of an
// observation: a probe touch, a DBB reading, a ball3d component), the outputs
// y the estimated parameters. An input is expressed *along its residual*: its
// deviation is the change it causes in its residual row (mm). Linearising the
// least-squares estimate at the fit,
//
//     y(x + dx) ~ y - (J^T J)^-1 J_in^T dx      so  C = -(J^T J)^-1 J_in^T,
//
// with J the residual Jacobian (rows x estimated parameters) and J_in its
// input rows (scale-bar rows have no input). The output covariance is then
//
//     U_y = C U_x C^T                                      (thesis eq. 8-3)
//
// for any input covariance U_x: sigma^2 I for independent touches, or a
// covariance pooled from repeated measurement cycles (thesis §5.6):
//   pooled by cycles: cycle k of every day forms a group; the within-group
//     scatter keeps the measurement process and the day-to-day changes and
//     removes the machine's change through the day;
//   pooled by days: the cycles of one day form a group; removes the changes
//     between days, keeps the change through the day and the measurement
//     process (larger on the thesis' machines).
// The pooled covariance has nu = (number of cycles - number of groups)
// degrees of freedom; the coverage factor is stated with how it was chosen.
#ifndef FIVECAL_GUM_H_
#define FIVECAL_GUM_H_

#include <Eigen/Core>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"

namespace fivecal {

// ---- Distributions (for coverage factors) ---------------------------------

double NormalQuantile(double p);                      // Phi^-1(p)
double StudentTQuantile(double p, double dof);        // dof = inf -> normal
double ChiSquareQuantile(double p, double dof);
double FQuantile(double p, double dof1, double dof2); // dof2 = inf -> chi2(dof1) / dof1
double StudentTCdf(double t, double dof);
double ChiSquareCdf(double x, double dof);
// 1 - ChiSquareCdf, computed directly: the p-value of a chi-square test keeps
// its digits when it is tiny.
double ChiSquareSurvival(double x, double dof);
double FCdf(double x, double dof1, double dof2);

struct CoverageFactor {
  double probability = 0.95;
  double dof = std::numeric_limits<double>::infinity();  // of the covariance
  // Per parameter (interval y_i +- k u_i): Student t_{(1+p)/2, dof} (the
  // normal quantile for infinite dof), or the user's value.
  double k = 1.959963984540054;
  // Joint hyper-ellipsoidal region of all m outputs (JCGM 102 §6.5.2):
  // (y - Y)^T U_y^-1 (y - Y) <= k_joint^2, k_joint^2 = chi2_m(p) for infinite
  // dof, m nu / (nu - m + 1) F_{m, nu-m+1}(p) (Hotelling) otherwise (nan when
  // nu < m: the pooled covariance is too poor for a joint region).
  double k_joint = 0;
  int outputs = 0;
  std::string method;  // how k was chosen, in words
};

// k from p and dof (explicit_k > 0 overrides the per-parameter factor).
CoverageFactor MakeCoverageFactor(double probability, double dof, int outputs, double explicit_k = 0);

// ---- Pooled covariance -----------------------------------------------------

struct PooledCovariance {
  Eigen::MatrixXd covariance;    // n x n: sum_g sum_(c in g) (x_c - m_g)(x_c - m_g)^T / dof
  Eigen::VectorXd mean;          // grand mean
  Eigen::MatrixXd group_means;   // groups x n, in order of first appearance
  std::vector<int> group_labels; // the label of each group
  std::vector<int> group_sizes;
  int dof = 0;                   // samples - groups
};

// samples: K x n (one row per cycle); group[c]: the group label of row c.
// Throws if dof < 1.
PooledCovariance PoolCovariance(const Eigen::MatrixXd& samples, const std::vector<int>& group);

// ---- Propagation -------------------------------------------------------------

struct GumResult {
  std::vector<std::string> names;  // outputs
  Eigen::VectorXd values;          // estimates
  Eigen::MatrixXd covariance;      // U_y
  Eigen::VectorXd std;             // sqrt(diag U_y)
  Eigen::MatrixXd correlation;
  CoverageFactor coverage;
  Eigen::VectorXd expanded;        // k * std
  std::string ToJson() const;
};

// U_y = C U_x C^T (+ prior_term, p x p, when given) with the stated coverage
// factor.
GumResult PropagateCovariance(const Eigen::MatrixXd& C, const Eigen::MatrixXd& Ux,
                              const std::vector<std::string>& names, const Eigen::VectorXd& values,
                              const CoverageFactor& coverage,
                              const Eigen::MatrixXd& prior_term = Eigen::MatrixXd());

// C = -(J^T J)^+ J_in^T of a fit (Result of Identify on `ds`), evaluated at
// its values; input_rows lists, per input (column of C), its residual row.
struct Sensitivity {
  std::vector<std::string> names;  // the fit's estimated parameters
  Eigen::VectorXd values;
  Eigen::MatrixXd C;               // p x inputs
  std::vector<int> input_rows;     // residual row of each input
  std::vector<int> input_source;   // observation index of each input; -1 - b for scale bar b
                                   // (its calibrated length; the bars come after the observations)
  // After a MAP fit (Result::map_fit) the prior is one more input: the
  // estimate is y = -N^-1 (J_in^T W dx - P theta0) with N = J^T W J + P,
  // P = diag(1 / prior_std^2), so C = -N^-1 J_in^T W and the prior adds
  // N^-1 P N^-1 (p x p) to U_y; with U_x = the declared noise the sum is the
  // posterior covariance N^-1. Empty after a plain least-squares fit.
  Eigen::MatrixXd prior_term;
};
Sensitivity SensitivityMatrix(const Dataset& ds, const Result& fit);

// ---- Repeated cycles (thesis §5.6, §8.4.4) ----------------------------------

struct CyclesOptions {
  std::string pooling = "cycles";  // "cycles", "days" or "none" (one group)
  double probability = 0.95;
  double coverage_factor = 0;      // > 0: use this k instead of Student t
  int reference = 0;               // cycle whose fit gives C and the input reference
};

struct CyclesUncertainty {
  GumResult gum;                   // U_y = C U_x C^T, U_x pooled from the cycles
  PooledCovariance inputs;         // U_x (residual units, mm^2)
  std::vector<std::string> estimated;
  Eigen::MatrixXd cycle_values;    // cycles x p: each cycle's own estimate
  Eigen::MatrixXd output_pooled;   // p x p: the same pooling applied to cycle_values
  std::vector<int> day, cycle;
  std::string pooling;
  std::string ToJson() const;
};

// Every cycle is a dataset of the same plan (same observations in the same
// order); day[c] and cycle[c] label cycle c (cycle = its rank within the day).
// Inputs per cycle: the residual rows of its observations at the reference
// fit's values. Each cycle is re-fitted (its own estimate) from the reference.
CyclesUncertainty GumFromCycles(const std::vector<Dataset>& cycles, const std::vector<int>& day,
                                const std::vector<int>& cycle, const IdentifyOptions& identify,
                                const CyclesOptions& options);

}  // namespace fivecal

#endif  // FIVECAL_GUM_H_
