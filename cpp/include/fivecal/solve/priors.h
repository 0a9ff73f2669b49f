// Priors: the plausible size (one sigma) of every parameter, by class.
//
// A prior scale s_j says "before any measurement, parameter j is 0 +- s_j".
// It serves three things:
//  * identifiability: the Jacobian, weighted by 1/(declared noise), is scaled
//    by the priors, so a parameter counts as determined by the data only when
//    its data-only standard deviation is well below its plausible size
//    (kDeterminedRatio), whatever its unit;
//  * the MAP fit of estimate="auto": one prior row (theta_j - 0) / s_j per
//    estimated parameter;
//  * plausibility: values beyond kImplausibleSigmas prior sigmas are flagged.
//
// Defaults (PriorClasses) follow ISO 230-1 style tolerances of a mid-size
// machining centre (travels ~500 mm, rotary axes); setup parameters (facet
// offsets, sphere centres, stylus, ball-bar mounts) get mm-sized priors since
// a setup is poorly known before it is measured. Overrides: the machine
// file's "priors" and IdentifyOptions::priors, each a map from a parameter
// name or "class:<class name>" to a positive sigma; precedence (last wins):
// default, machine class, machine name, call class, call name.
#ifndef FIVECAL_PRIORS_H_
#define FIVECAL_PRIORS_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {

struct PriorClass {
  std::string name;         // used as "class:<name>"
  double sigma;             // default one-sigma scale, in `unit`
  std::string unit;
  std::string description;  // what it covers and why this size
};

// Placement uncertainty of the set-up quantities a person places (a ball on
// its nest, a ball bar's calibrated length, a sphere's certified radius, a
// tracker on its tripod): one sigma about the nominal the dataset gives, in
// the parameter's unit. Unlike the plausible size above (which scales the
// identifiability analysis and the MAP rows of "auto"), it is what the user
// knows of the set-up, and it enters EVERY fit that estimates the parameter
// as one prior row (theta_j - 0) / u_j: least squares becomes a MAP fit in
// the set-up parameters only. A machine error confounded with a placement
// then gets the sigma the placement allows instead of being fitted as if the
// set-up were exact (or refused as confounded). Defaults come from each
// observation kind (ObservationKind::DefaultPlacement; docs/setup_uncertainty.md
// lists and argues them); a dataset overrides them in "setup_uncertainty"
// (parameter name or "class:<prior class>" -> sigma), a name beating its class.
// 0: the quantity is not a placement (the data find it), no prior row.
double PlacementSigma(const Machine& m, const std::string& name,
                      const std::map<std::string, double>& dataset_overrides);
std::vector<double> PlacementScales(const Machine& m, const std::vector<std::string>& names,
                                    const std::map<std::string, double>& dataset_overrides);

// Throws std::invalid_argument naming `where` and the key unless every key is
// a set-up parameter among `names` (not a machine error: their priors belong
// in the machine file) or "class:<class>" of a set-up parameter class, and
// every value is finite and > 0 (a quantity known exactly is fixed, not given
// a zero uncertainty).
// The prior rows of a least-squares fit: per table entry the placement sigma
// of each estimated parameter that has one and +inf (no row) elsewhere;
// empty when no estimated parameter has one (the plain fit, no per-row or
// per-parameter cost).
Eigen::VectorXd PlacementRows(const Eigen::VectorXd& placement_all, const std::vector<int>& est);
// Jw (weighted Jacobian, or any factor R with R^T R = Jw^T Jw) with one row
// e_j / u_j appended per column j whose u_j > 0: the placement rows as the
// analyses (rank, determination, covariance) see them.
Eigen::MatrixXd WithPlacementRows(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& u);

void ValidateSetupUncertainty(const Machine& m, const std::map<std::string, double>& u, const std::string& where,
                              const std::vector<std::string>& names);

// The documented default table (docs/identification.md lists the same).
const std::vector<PriorClass>& PriorClasses();

// Reference travels that size the error-motion priors: a coefficient of
// degree d has sigma = effect / travel^d, the effect being the class's size
// over the reference travel (250 mm from the axis zero; 1 rad).
constexpr double kLinearReferenceTravel = 250.0;  // mm
constexpr double kRotaryReferenceTravel = 1.0;    // rad

// A parameter is determined by the data when its data-only standard deviation
// is below kDeterminedRatio x its prior sigma: the data then carry at least
// 1/kDeterminedRatio^2 = 4 times the prior's information about it. With the
// prior added, posterior sigma / prior sigma = 1 / sqrt(1 + 1/ratio^2), so the
// same criterion on the MAP result is informed < kInformedThreshold.
constexpr double kDeterminedRatio = 0.5;
constexpr double kInformedThreshold = 0.4472135954999579;  // 1 / sqrt(5)
// Estimate "auto": a class of machine errors whose evidence scale (the
// hierarchical prior's factor) ends below this shows no sign in the data; the
// point estimates of its parameters are held near 0 by that scale, so even a
// determined one is no measured value.
constexpr double kAbsentClassScale = 0.01;
// A determined machine error is identified when the data narrowed its
// plausible range tenfold (posterior sigma at most kIdentifiedRatio x prior
// sigma) or found it beyond kSignificantSigmas of 0; an imprecise value that
// does not differ from 0 tells nothing. A fit for machine errors that
// identified none is not usable.
constexpr double kIdentifiedRatio = 0.1;
constexpr double kSignificantSigmas = 2.0;
// Values beyond this many prior sigmas are flagged as implausible.
constexpr double kImplausibleSigmas = 5.0;

// Class name of a parameter (machine parameter or setup parameter name as in
// ParameterTable). Throws std::invalid_argument for a name of neither kind.
std::string PriorClassOf(const Machine& m, const std::string& parameter);

// Throws std::invalid_argument (naming `where` and the key, with a
// did-you-mean for class names) unless every key is a known class
// ("class:<name>") or a parameter `is_known` accepts, and every value is
// finite and > 0.
void ValidatePriors(const std::map<std::string, double>& priors, const std::string& where,
                    const std::vector<std::string>& known_names);

// Prior sigma of each of `names` after the overrides (machine file, then call).
std::vector<double> PriorScales(const Machine& m, const std::vector<std::string>& names,
                                const std::map<std::string, double>& machine_priors,
                                const std::map<std::string, double>& call_priors);

}  // namespace fivecal

#endif  // FIVECAL_PRIORS_H_
