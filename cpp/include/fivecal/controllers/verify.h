// Verify after loading (docs/controllers.md, "Verify after loading"): did a
// change loaded into a controller take effect as predicted?
//
// Three estimates of the same machine errors meet here, each with its
// covariance: the check before loading (`previous`), the change the export
// said the controller's new values compensate (`change`: the machine's
// apparent error in these parameters drops by it), and the check after
// loading (`now`). Every name is first put under the check's names
// (SpindleNames: an export's EX0C is a check's EX0S with its sign turned).
//
//   d   = previous - now                      the drop the check observed
//   S_d = C_previous + C_now                  (independent checks)
//   H_F : d = F c,  S_F = S_d (+ F C_c F)     F = diag(f_1 .. f_n), one per hypothesis
//   chi2_F = (d - F c)^T S_F^-1 (d - F c)
//
// The change's own covariance C_c says how well the change corrects the
// machine, not how well it was loaded: the controller runs the exported
// numbers exactly, so what was loaded is previous - now up to the checks'
// noise, and C_c does not enter by default (VerifyOptions::
// change_covariance adds it: a wider, weaker test).
//
// The hypotheses: the change took effect (F = 1), not applied (0), sign
// reversed (-1), applied twice (2), a unit (1000: a µm value read as mm;
// 0.001: a mm value read as µm; 25.4: a mm value read as inch; 1/25.4: an
// inch value read as mm), and, with two or more parameters, the sign of one
// component (F = 1 but -1 at j). With best the smallest chi2:
//
//   none fits        chi2_best > chi2_n(P_k)       "differs, not one of these"
//   not excluded     A = {H : chi2_H - chi2_best <= k^2}
//   unresolvable     two hypotheses whose predictions differ by less than
//                    k sigma (Mahalanobis, S_d + C_c) are one to this check
//   took effect      A = {F = 1}, but for one component's sign on a
//                    component too small to see (unresolvable: listed as
//                    not tested)
//   cannot tell      F = 1 in A beside any other alternative (a change
//                    below the check's resolution cannot be told from
//                    "not applied")
//                    or F = 1 not in A but a member of A unresolvable from it
//   a named cause    F = 1 not in A, and A one group of unresolvable causes
//                    (named together: "not applied" and "x 0.001" are one
//                    for a change of micrometres)
//   one of           F = 1 not in A, A holds causes the check resolves
//
// So a cause is named only when the numbers put every resolvable
// alternative more than k sigma (likelihood ratio k^2) away, and a check too
// noisy to tell says so. Per parameter the same test runs on its own row
// (the scalar hypotheses only). The ratio observed / expected change is
// reported with its sigma (weighted least squares over the rows).
//
// Units: each parameter in its own (mm, rad); the ratio is dimensionless.
#ifndef FIVECAL_CONTROLLERS_VERIFY_H_
#define FIVECAL_CONTROLLERS_VERIFY_H_

#include <Eigen/Core>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

// Named values with their covariance (n x n; an empty matrix: none given, 0).
struct NamedEstimate {
  std::vector<std::string> names;
  Eigen::VectorXd values;
  Eigen::MatrixXd covariance;
};

enum class ChangeCause {
  kTookEffect,
  kNotApplied,
  kSignReversed,
  kAppliedTwice,
  kMicronAsMm,      // x 1000
  kMmAsMicron,      // x 0.001
  kMmAsInch,        // x 25.4
  kInchAsMm,        // x 1 / 25.4
  kComponentSign,   // one parameter's sign turned, the others took effect
};

// "took effect", "not applied", "sign reversed", "applied twice",
// "unit: a µm value read as mm (x1000)", ...
std::string ChangeCauseText(ChangeCause cause);

enum class ChangeVerdict {
  kTookEffect,   // as predicted within its uncertainty
  kCause,        // took effect excluded; causes = one group the check cannot tell apart
  kOneOf,        // took effect excluded; causes = several the check could tell apart but these data do not
  kCannotTell,   // took effect not excluded, nor a resolvable alternative: this check cannot tell
  kDiffers,      // no hypothesis fits: differs, not one of these
};

std::string ChangeVerdictName(ChangeVerdict v);  // "took effect", "cause", "one of", "cannot tell", "differs"

struct Hypothesis {
  ChangeCause cause = ChangeCause::kTookEffect;
  std::string component;  // kComponentSign: the parameter whose sign turned
  Eigen::VectorXd factors;
  double chi2 = 0;
  std::string Text() const;  // ChangeCauseText, with the component for kComponentSign
};

struct ChangeOutcome {
  ChangeVerdict verdict = ChangeVerdict::kCannotTell;
  std::vector<Hypothesis> causes;      // kCause / kOneOf: the causes named; kCannotTell: the alternatives
  std::vector<Hypothesis> unresolved;  // kTookEffect: one component's sign, too small a component to see
  std::string message;                 // one line a person reads
};

struct ParameterChange {
  std::string name;                      // the check's name
  double previous = 0, previous_std = 0;
  double expected = 0, expected_std = 0;  // the change (the drop expected); std NaN when not given
  double now = 0, now_std = 0;
  double predicted = 0, predicted_std = 0;  // previous - expected; std of previous and now (and expected
                                            // with VerifyOptions::change_covariance)
  double observed = 0, observed_std = 0;    // previous - now
  double z = 0;                            // (now - predicted) / predicted_std
  bool as_predicted = false;               // |z| <= k
  double ratio = 0, ratio_std = 0;         // observed / expected (NaN for a zero expected change)
  ChangeOutcome outcome;                   // this row alone (scalar hypotheses)
};

struct ChangeVerification {
  std::vector<ParameterChange> parameters;
  std::vector<std::string> not_compared;   // names whose change is 0 (nothing loaded there)
  std::vector<Hypothesis> hypotheses;      // every hypothesis, chi2 over all rows
  double chi2_limit = 0;                   // chi2_n(P_k): the fit a hypothesis must meet
  double ratio = 0, ratio_std = 0;         // weighted least squares of observed on expected
  double k = 3;
  ChangeOutcome outcome;
  bool took_effect() const { return outcome.verdict == ChangeVerdict::kTookEffect; }
};

struct VerifyOptions {
  double k = 3;  // sigmas; the probability P_k = erf(k / sqrt 2)
  bool change_covariance = false;  // add F C_c F to each hypothesis' covariance
};

// Throws std::invalid_argument naming the field: sizes that disagree, a value
// or covariance of a compared parameter that is not finite, a covariance not symmetric positive
// semi-definite, a name repeated; `change` naming a parameter the check
// (`now`) does not measure ("expect: ... not measured by this check ...",
// with the names it measures) or `previous` lacks; nothing to compare (every
// change 0); a combined covariance that is singular.
ChangeVerification VerifyChange(const Machine& m, const NamedEstimate& previous, const NamedEstimate& change,
                                const NamedEstimate& now, const VerifyOptions& options = VerifyOptions());

}  // namespace controllers
}  // namespace fivecal

#endif  // FIVECAL_CONTROLLERS_VERIFY_H_
