// Identification: fit the chosen error and setup parameters to a dataset by
// nonlinear least squares (Ceres, Levenberg-Marquardt), after checking that
// the data can identify them, and report values, uncertainties and residuals.
#ifndef FIVECAL_IDENTIFY_H_
#define FIVECAL_IDENTIFY_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

struct IdentifyOptions {
  // Parameter names and/or presets: S1 S2 S3 S4 (thesis subsets on
  // wCBXfZYSt), "location" (the location errors this data determines,
  // selected on the prior-scaled, noise-weighted Jacobian at the solution),
  // "auto" (every candidate machine error -- location, backlash, error
  // motions -- estimated under its prior by a MAP fit; the result says which
  // ones the data informed). The default setup set is always added (see
  // ParameterTable).
  std::vector<std::string> estimate;
  std::vector<std::string> fix;            // removed from the estimated set
  std::map<std::string, double> initial;   // start values / fixed values
  std::string robust;                      // "", "huber" or "cauchy"
  // mm; 0 = 3 x the MAD-based sigma of a plain fit. A row in another unit
  // (a pose's rotation rows, rad) is held to the same multiple of its
  // declared noise as its observation's position rows.
  double robust_scale = 0.0;
  int max_iterations = 200;
  bool include_default_setup = true;
  // Fit even when the set is rank deficient (minimum-norm steps); the result
  // then names the confounded groups. Otherwise such a request throws.
  bool allow_unidentifiable = false;
  double rank_tolerance = 1e-9;
  double selection_tolerance = 1e-2;       // for "location", in (0, 1)
  // 0: automatic (the normal-equation path of long data on every core, the
  // dense fit, whose problems are small, on one); else that many threads.
  int num_threads = 0;
  // Prior sigma overrides (priors.h): parameter name or "class:<name>" ->
  // sigma; applied after the machine file's "priors".
  std::map<std::string, double> priors;
  // MAP fit (prior rows) for explicit lists too; "auto" always fits under the
  // priors, explicit lists and "location" are plain least squares by default.
  bool prior = false;
  // Placement priors on the estimated set-up quantities (priors.h
  // PlacementSigma, the dataset's "setup_uncertainty"). false: every set-up
  // quantity is taken as exact where it is not estimated freely -- what a
  // set-up measured beforehand allows, and what an identifiability analysis
  // of the path alone ("which errors can this test separate") wants.
  bool setup_priors = true;
  // Estimate the noise of each instrument group (probe touches, ball bar,
  // ball3d) from the residuals (variance components) instead of trusting the
  // declared sigmas; the covariance then uses the estimated noise.
  bool variance_components = false;
  // Which fit runs: "auto" (the normal equations accumulated chunk by chunk,
  // solve/normal_equations.h, for long data: rows x estimated parameters
  // above kNormalEquationElements, when the options allow it), "dense" (the
  // dense Jacobian) or "normal_equations" (throws when the options or the
  // kinds do not allow it).
  std::string fit_path = "auto";
};

// One instrument group's noise, estimated from its residuals.
struct VarianceComponent {
  std::string group;       // "probe", "dbb", "ball3d"
  int rows = 0;
  double redundancy = 0;   // rows minus what the fit used of them
  double chi2 = 0;         // of the group's residuals at its current sigma
  double declared = 0;     // rms declared sigma (mm)
  double factor = 1;       // estimated / declared
  double sigma = 0;        // estimated rms sigma (mm)
  bool estimated = false;  // false: too little redundancy, the declared noise is kept
};

// The residual rows of one unit (a pose's position rows, mm, and rotation
// rows, rad, are summarised apart: one figure over both would be in no unit).
struct UnitResiduals {
  std::string unit;                     // "mm", "rad"
  int rows = 0;
  double rms = 0, max_abs = 0, sigma = 0;  // in `unit`; sigma a posteriori
  double dof = 0;                       // the unit's share of the degrees of freedom
};

// What the data could not tell, for one family of parameters (the prior
// classes gathered as a reader names them: location offsets, location angles,
// scale gains, error motions of one degree, backlash, set-up), with the
// likely cause and the measurement that would tell it.
struct NotDetermined {
  std::string family;               // "location offsets", "error motions of degree 2", "set-up" ...
  bool machine = true;              // machine errors (false: set-up quantities)
  int estimated = 0;                // the family's estimated parameters
  std::vector<std::string> names;   // those of them the data did not determine
  std::string why;                  // likely cause: the measurement that would determine them
};

// What a candidate the "location" selection left out would do to the
// estimates if it were not 0: d(estimate)/d(candidate) at the solution (first
// order, the data's weighted least squares) for each estimate it moves, and
// its plausible size (prior sigma), at which the report states the moves.
struct LeftOutMoves {
  std::string name;
  double plausible = 0;
  std::map<std::string, double> moves;
};

struct Result {
  std::vector<std::string> names;     // every parameter of the problem
  Eigen::VectorXd values;             // every parameter (fitted or fixed)
  std::vector<std::string> estimated; // estimated names, in covariance order
  Eigen::VectorXd std;                // one-sigma, estimated parameters
  Eigen::MatrixXd covariance;         // estimated x estimated
  Eigen::MatrixXd correlation;
  Eigen::VectorXd residuals;          // one per residual row (mm)
  std::vector<int> residual_source;   // observation index or -(1 + scale bar)
  Eigen::MatrixXd residual_vectors;   // per observation, workpiece frame (mm)
  Eigen::MatrixXd points;             // per observation: predicted tool point
  double rms = 0, max_abs = 0, sigma = 0;  // of the mm rows
  std::vector<UnitResiduals> residual_units;  // per unit, "mm" first
  double condition_number = 0;
  int rank = 0;
  std::vector<std::vector<std::string>> unidentifiable;
  bool converged = false;
  int iterations = 0;
  std::string message;
  int n_observations = 0;
  int n_parameters = 0;
  std::vector<int> outliers;          // residual rows beyond the robust scale (at their declared noise)
  double robust_scale = 0;
  double initial_cost = 0, final_cost = 0;

  // Priors and statistical guards (priors.h). Per estimated parameter:
  std::vector<double> prior_std;      // prior sigma used (scaling, MAP rows)
  std::vector<double> informed;       // std / prior_std; < kInformedThreshold: informed by the data
  // Placement uncertainty of each estimated set-up quantity (priors.h
  // PlacementSigma; 0: none, and for every machine error): its prior row in
  // this fit (a MAP fit's prior_std already holds it, combined).
  std::vector<double> placement;
  std::vector<std::string> undetermined;  // estimated, but not determined by this data
  std::vector<std::string> implausible;   // |value| > kImplausibleSigmas prior sigmas
  // estimate "auto": the factor (0.001-1) the data put on each machine-error
  // class's prior for the point estimate (small: the data show no sign of it).
  std::map<std::string, double> class_scales;
  // variance_components=true: the noise of each instrument group.
  std::vector<VarianceComponent> variance_components;
  bool map_fit = false;               // prior rows in the fit (estimate "auto" or prior=true)
  double chi2 = 0;                    // sum (r_i / declared sigma_i)^2 over the data rows
  int dof = 0;                        // rows - effective number of parameters
  double chi2_p = 1;                  // P(chi2_dof >= chi2): small = residuals too large for the noise
  bool adequate = true;
  std::string adequacy;               // the likely cause when not adequate
  bool finite = true;                 // every value and std finite
  // Machine errors the data determined far beyond their plausible size
  // (implausible, undetermined ones left out): a 100 mm pivot is the machine
  // file's nominal geometry, not the machine. Not usable ("implausible");
  // `plausibility` names the values and the likely cause.
  bool plausible = true;
  std::string plausibility;
  bool explicit_request = false;      // no "auto": undetermined parameters make the verdict
  // The fit was to find machine errors (some were estimated, or "auto" /
  // "location" was asked for); with none of them determined it identified
  // nothing, and the verdict says so ("undetermined").
  bool seeks_machine_errors = false;
  int identified_machine_errors = 0;  // determined, not `held`, and precise or significant (kIdentifiedRatio)
  // Estimate "auto": parameters the data determined in a class they show no
  // sign of (kAbsentClassScale): their values are held near 0, not measured.
  std::vector<std::string> held;
  // Estimate "location": the candidates its selection left out, each with why
  // (too weakly seen for its prior, or confounded with those chosen).
  std::vector<std::pair<std::string, std::string>> left_out;
  // For each candidate left out, what its value would do to the estimates
  // (LeftOutMoves): a value a left-out error really has is carried into the
  // estimates it moves, whatever their sigma says.
  std::vector<LeftOutMoves> left_out_moves;
  std::vector<NotDetermined> not_determined;  // one per family with undetermined parameters
  std::string fit_path;               // the path that ran: "dense" or "normal_equations"
  // "ok", "not_converged", "implausible", "inadequate", "non_finite" or
  // "undetermined" (requested parameters undetermined, or no machine error
  // determined).
  std::string verdict() const;

  std::string ToJson() const;
};

Result Identify(const Dataset& ds, const IdentifyOptions& options);

// Residual rows of a dataset for given parameter values (unnamed ones are 0):
// the prediction check for held-out observations.
Eigen::VectorXd PredictResiduals(const Dataset& ds, const std::map<std::string, double>& values,
                                 std::vector<int>* source = nullptr);

// Names of the parameters the `estimate` list resolves to (presets
// expanded, "location"/"auto" selected on the data), without fitting.
std::vector<std::string> ResolveEstimate(const Dataset& ds, const IdentifyOptions& options);

}  // namespace fivecal

#endif  // FIVECAL_IDENTIFY_H_
