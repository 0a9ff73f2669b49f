// Identifiability of a parameter set from the Jacobian of the residuals.
//
// Columns are scaled to unit norm first, so the condition number does not
// depend on the parameters' units (mm, rad, mm/mm^3 ...). Parameters whose
// scaled columns are (numerically) linearly dependent are confounded: the
// null space of the scaled Jacobian names them.
#ifndef FIVECAL_IDENTIFIABILITY_H_
#define FIVECAL_IDENTIFIABILITY_H_

#include <Eigen/Core>
#include <vector>

namespace fivecal {

struct Identifiability {
  double condition_number = 0.0;    // sigma_max / sigma_min of the scaled Jacobian
  int rank = 0;
  Eigen::VectorXd singular_values;  // scaled Jacobian, descending
  Eigen::VectorXd column_norms;     // the scaling used
  // Groups of column indices that are confounded with each other (from the
  // null-space vectors; a zero column forms a group of one).
  std::vector<std::vector<int>> confounded;
  // Scaled-space pseudo-inverse of J^T J, unscaled: (J^T J)^+ in parameter units.
  Eigen::MatrixXd inverse_normal;
  // D-optimality figure: log det of the scaled J^T J / p (per parameter).
  double log_det_per_parameter = 0.0;
};

// rank_tolerance: singular values below rank_tolerance * sigma_max count as zero.
Identifiability AnalyzeJacobian(const Eigen::MatrixXd& J, double rank_tolerance = 1e-9);

// AnalyzeJacobian(J, rank_tolerance).condition_number without the singular
// vectors and the inverse.
double ConditionNumber(const Eigen::MatrixXd& J, double rank_tolerance = 1e-9);

// A tall J reduced to the p x p upper triangular R of its QR (J itself when it
// has no more rows than columns): R^T R = J^T J, so every analysis here gives
// the same for R as for J (and R D is the factor of J D for a diagonal D), at
// O(p^3) instead of O(n p^2) each.
Eigen::MatrixXd TriangularFactor(const Eigen::MatrixXd& J);

// Cheap screen before a fit: true when the column-scaled Jacobian is clearly
// of full column rank (smallest |R_ii| of its QR factor, taken from the
// Cholesky factor of the normal matrix, above `margin` times the largest).
// False means "run AnalyzeJacobian to be sure".
bool ClearlyFullRank(const Eigen::MatrixXd& J, double margin = 1e-6);

// Greedy selection of a maximal identifiable subset: `forced` columns first
// (all must be independent), then `candidates` in order, each kept when its
// scaled column is not explained by the kept ones to within `tolerance`
// (relative residual norm after projection).
std::vector<int> SelectIdentifiable(const Eigen::MatrixXd& J, const std::vector<int>& forced,
                                    const std::vector<int>& candidates, double tolerance = 1e-4);

// What the data determine, measured against the priors.
//
// Jw: the Jacobian with every row divided by its declared noise (so a unit
// change of a residual is one noise sigma); prior: one sigma per column. In
// the scaled coordinates t_j = theta_j / prior_j the data-only covariance is
// (Js^T Js)^+ with Js = Jw diag(prior), and
//   ratio_j = sqrt([(Js^T Js)^+]_jj)  =  data-only sigma_j / prior_j
// (infinite when the data leave a direction of t_j free). Parameter j is
// determined when ratio_j < threshold (priors.h kDeterminedRatio): the
// tolerance is tied to the noise and to the plausible size, not to machine
// epsilon or to the parameters' units.
struct Determination {
  Eigen::VectorXd ratio;            // per column; +inf when not determined at all
  Eigen::VectorXd singular_values;  // of Js, descending
  int rank = 0;                     // singular values > 1 / threshold
  std::vector<int> undetermined;    // columns with ratio >= threshold
  // Undetermined columns grouped by the weakly determined directions
  // (singular values <= 1 / threshold) they share (UndeterminedGroups).
  std::vector<std::vector<int>> groups;
};

Determination AnalyzeDetermination(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior,
                                   double threshold);

// True when AnalyzeDetermination(Jw, prior, threshold) certainly leaves a
// column undetermined; false says nothing (run AnalyzeDetermination). For a
// caller that needs only whether everything is determined: one Cholesky of
// the scaled normal matrix instead of a QR and an SVD.
bool CertainlyUndetermined(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior, double threshold);

// CertainlyUndetermined(Jw, prior, threshold) ||
// !AnalyzeDetermination(Jw, prior, threshold).undetermined.empty(), with one
// normal matrix of the rows for both where the quick paths decide (a
// determined start of a fit: no QR of the rows).
bool AnyUndetermined(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior, double threshold);

// The groups of AnalyzeDetermination from an SVD of Js (s descending, V its
// right singular vectors): the `bad` columns joined when they share a weak
// direction (s <= weak; exactly free when s <= zero). Depends on the
// subspaces of equal singular values only, not on the basis an SVD picks in
// them (a degenerate free space mixed by any rotation gives the same groups).
std::vector<std::vector<int>> UndeterminedGroups(const Eigen::VectorXd& s, const Eigen::MatrixXd& V,
                                                 const std::vector<bool>& bad, double zero, double weak);

// The data-only ratio (as above) of every column of the subset `cols` of a
// prior-scaled, noise-weighted Jacobian Js; +inf when the subset is singular.
Eigen::VectorXd SubsetRatios(const Eigen::MatrixXd& Js, const std::vector<int>& cols);

// (Js^T Js + I)^-1 with Js = Jw diag(s): the posterior covariance of a MAP
// fit with prior sigmas s, in units of those priors.
Eigen::MatrixXd ScaledPosterior(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& s);

}  // namespace fivecal

#endif  // FIVECAL_IDENTIFIABILITY_H_
