#include "fivecal/solve/identify.h"

#include <algorithm>
#include <cstdio>
#include <memory>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "fivecal/uncertainty/gum.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/model/kinematic_model.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/solve/normal_equations.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"
#include "fivecal/solve/refit.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"
#include "solve/residual_units.h"

namespace fivecal {
namespace {

using namespace json_util;

// The machine file's "priors" (name or class:<name> -> sigma).
std::map<std::string, double> MachinePriors(const Machine& m) { return m.priors; }

bool IsPreset(const std::string& s) {
  return s == "S1" || s == "S2" || s == "S3" || s == "S4" || s == "location" || s == "auto";
}

Eigen::VectorXd InitialValues(const ParameterTable& table, const IdentifyOptions& opt) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : opt.initial) {
    RequireFinite(value, "initial." + name);
    v[table.Require(name)] = value;
  }
  return v;
}

std::string GroupText(std::vector<std::string> g) {
  // Machine errors (what the user asked for) before the setup parameters.
  std::stable_partition(g.begin(), g.end(), [](const std::string& n) { return n[0] == 'E'; });
  std::string s = "{";
  const size_t shown = std::min<size_t>(g.size(), 8);
  for (size_t i = 0; i < shown; ++i) s += (i ? ", " : "") + g[i];
  if (g.size() > shown) s += ", ... (" + std::to_string(g.size() - shown) + " more)";
  return s + "}";
}

void ValidateOptions(const IdentifyOptions& o) {
  if (o.max_iterations < 1 || o.max_iterations > 100000)
    throw std::invalid_argument("identify: max_iterations must be in 1..100000, got " +
                                std::to_string(o.max_iterations));
  if (!(o.selection_tolerance > 0) || !(o.selection_tolerance < 1))
    throw std::invalid_argument("identify: selection_tolerance must be in (0, 1), got " +
                                std::to_string(o.selection_tolerance));
  if (!(o.rank_tolerance > 0) || !(o.rank_tolerance < 1))
    throw std::invalid_argument("identify: rank_tolerance must be in (0, 1), got " +
                                std::to_string(o.rank_tolerance));
  if (!o.robust.empty() && o.robust != "none" && o.robust != "huber" && o.robust != "cauchy")
    throw std::invalid_argument("identify: robust must be 'huber', 'cauchy' or 'none', got '" +
                                o.robust + "'");
  if (!std::isfinite(o.robust_scale) || o.robust_scale < 0)
    throw std::invalid_argument("identify: robust_scale must be finite and >= 0 mm");
  if (o.fit_path != "auto" && o.fit_path != "dense" && o.fit_path != "normal_equations")
    throw std::invalid_argument("identify: fit_path must be 'auto', 'dense' or 'normal_equations', got '" +
                                o.fit_path + "'");
  if (o.num_threads < 0 || o.num_threads > 1024)
    throw std::invalid_argument("identify: num_threads must be in 0..1024 (0 = automatic), got " +
                                std::to_string(o.num_threads));
}

struct Request {
  std::vector<int> forced;      // explicit names, presets, default setup
  std::vector<int> candidates;  // "location" / "auto" candidates, in priority order
  bool location = false, automatic = false;
};

Request Classify(const Dataset& ds, const ParameterTable& table, const IdentifyOptions& opt) {
  Request q;
  std::set<int> fixed;
  for (const std::string& n : opt.fix) {
    if (IsPreset(n)) {
      for (const std::string& p : ThesisSubset(ds.machine(), n)) fixed.insert(table.Require(p));
    } else {
      fixed.insert(table.Require(n));
    }
  }
  std::set<int> seen;
  auto add = [&](int i, std::vector<int>* list) {
    if (fixed.count(i) || seen.count(i)) return;
    seen.insert(i);
    list->push_back(i);
  };
  if (opt.include_default_setup)
    for (int i : table.DefaultSetup(ds)) add(i, &q.forced);
  for (const std::string& n : opt.estimate) {
    if (n == "location") q.location = true;
    else if (n == "auto") q.automatic = true;
    else if (IsPreset(n))
      for (const std::string& p : ThesisSubset(ds.machine(), n)) add(table.Require(p), &q.forced);
    else add(table.Require(n), &q.forced);
  }
  if (q.location || q.automatic)
    for (const std::string& n : LocationCandidates(ds.machine())) add(table.Require(n), &q.candidates);
  if (q.automatic)
    for (const std::string& n : MotionCandidates(ds.machine()))
      if (table.Index(n) >= 0) add(table.Index(n), &q.candidates);
  return q;
}

Eigen::VectorXd Gather(const Eigen::VectorXd& all, const std::vector<int>& idx) {
  Eigen::VectorXd v(idx.size());
  for (size_t i = 0; i < idx.size(); ++i) v[i] = all[idx[i]];
  return v;
}

// Residuals (mm) and the Jacobian with rows divided by their declared noise.
void WeightedJacobian(Problem* pr, Eigen::VectorXd* r, Eigen::MatrixXd* Jw) {
  pr->Evaluate(r, Jw);
  const Eigen::VectorXd w = pr->row_sigma().cwiseInverse();
  *Jw = w.asDiagonal() * *Jw;
}

// (Js^T Js + I)^-1 with Js = Jw diag(s): the posterior covariance of a MAP
// fit with prior sigmas s, in units of those priors.
Eigen::MatrixXd ScaledPosterior(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& s) {
  const Eigen::MatrixXd Js = Jw * s.asDiagonal();
  Eigen::MatrixXd N = Js.transpose() * Js;
  N.diagonal().array() += 1.0;
  return N.ldlt().solve(Eigen::MatrixXd::Identity(N.rows(), N.cols()));
}

struct Solve {
  Eigen::VectorXd values;
  bool converged = false;
  int iterations = 0;
  std::string message;
  double initial_cost = 0, final_cost = 0, robust_scale = 0;
};

// One fit of `est` from `values`: plain least squares, or MAP with
// `prior_all` (per table index; empty = no prior rows); with the robust loss a
// plain pass first sets the loss scale. `prepared`: a Problem(ds, table,
// values, est) already made, for the first pass.
Solve RunFit(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
             const std::vector<int>& est, const IdentifyOptions& opt, const Eigen::VectorXd& prior_all,
             std::unique_ptr<Problem>* final_problem, std::unique_ptr<Problem> prepared = nullptr) {
  const ceres::Solver::Options so = Problem::SolverOptions(opt.max_iterations, opt.num_threads);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(table.size());
  Solve out;
  out.values = values;
  // Invalid prior sigmas are left to AddPriors, which names them (+inf: no
  // row, the estimated parameters without a placement in a least-squares fit).
  bool valid_priors = true;
  for (int i : est) valid_priors = valid_priors && (!prior_all.size() || prior_all[i] > 0);
  auto run = [&](Problem* pr) {
    // The loop Ceres would run, without Ceres's per-solve overhead (most of
    // a fit's time on a few hundred rows); Ceres where it does not apply.
    RefitResult own;
    if (valid_priors && SolveWithoutCeres(*pr, prior_all, opt.max_iterations, &own)) {
      out.values = pr->values();
      out.converged = own.converged;
      out.iterations += own.iterations;
      out.message = own.message;
      if (out.initial_cost == 0) out.initial_cost = own.initial_cost;
      out.final_cost = own.final_cost;
      return;
    }
    if (prior_all.size()) pr->AddPriors(prior_all, zero);
    ceres::Solver::Summary summary;
    ceres::Solve(so, &pr->ceres_problem(), &summary);
    out.values = pr->values();
    out.converged = summary.termination_type == ceres::CONVERGENCE;
    out.iterations += std::max(0, static_cast<int>(summary.iterations.size()) - 1);
    out.message = summary.message;
    if (out.initial_cost == 0) out.initial_cost = summary.initial_cost;
    out.final_cost = summary.final_cost;
  };
  std::unique_ptr<Problem> problem = prepared ? std::move(prepared) : std::make_unique<Problem>(ds, table, values, est);
  run(problem.get());
  if (!opt.robust.empty() && opt.robust != "none") {
    double scale = opt.robust_scale;
    if (!(scale > 0)) {
      Eigen::VectorXd r;
      problem->Evaluate(&r, nullptr);
      scale = DefaultRobustScale(PositionScaledResiduals(ds, r, problem->row_sigma(), problem->row_source()));
    }
    out.robust_scale = scale;
    problem = std::make_unique<Problem>(ds, table, out.values, est, opt.robust, scale);
    run(problem.get());
  }
  if (final_problem) *final_problem = std::move(problem);
  return out;
}

// Whether the fit runs on the accumulated normal equations
// (normal_equations.h); empty = yes, else why not. What needs more of the
// Jacobian than J^T J stays dense: "location" (the greedy selection projects
// the columns), "auto" and variance components (the hyperparameter loop
// takes per-row leverages from the hat matrix), robust losses (Ceres
// reweights each row). Every kind can: those without analytic derivatives
// enter through their templated functors.
std::string DenseReason(const Dataset& ds, const IdentifyOptions& opt, const Request& rq, size_t p) {
  if (opt.fit_path == "dense") return "fit_path 'dense' requested";
  std::string why;
  if (rq.location || rq.automatic) why = "estimate 'location' and 'auto' select on the dense Jacobian";
  else if (opt.variance_components) why = "variance components need the per-row leverages";
  else if (!opt.robust.empty() && opt.robust != "none") why = "a robust loss reweights every row";
  if (!why.empty()) {
    if (opt.fit_path == "normal_equations")
      throw std::invalid_argument("identify: fit_path 'normal_equations' is not available here: " + why);
    return why;
  }
  if (opt.fit_path == "normal_equations") return "";
  double rows = 0;
  for (const Observation& o : ds.observations) rows += KindOf(o).rows();
  return rows * static_cast<double>(p) > kNormalEquationElements ? "" : "short data";
}

// "location": the forced set, then each candidate in priority order while
// every kept parameter stays determined (data-only sigma below
// kDeterminedRatio x prior) and the candidate's unit-norm column is not
// within selection_tolerance of the span of the kept ones.
// `why` (optional, per column): why a candidate was left out.
std::vector<int> SelectDetermined(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior,
                                  int num_forced, double tolerance, std::vector<std::string>* why = nullptr) {
  if (why) why->assign(Jw.cols(), "");
  const Eigen::MatrixXd Js = Jw * prior.asDiagonal();
  std::vector<int> kept;
  for (int c = 0; c < num_forced; ++c) kept.push_back(c);
  Eigen::VectorXd before = kept.empty() ? Eigen::VectorXd() : SubsetRatios(Js, kept);
  Eigen::MatrixXd Q(Jw.rows(), 0);
  auto unit_residual = [&](int c) {
    const double norm = Jw.col(c).norm();
    if (!(norm > 0)) return 0.0;
    Eigen::VectorXd v = Jw.col(c) / norm;
    for (int pass = 0; pass < 2; ++pass)
      if (Q.cols()) v -= Q * (Q.transpose() * v);
    return v.norm();
  };
  auto push_q = [&](int c) {
    const double norm = Jw.col(c).norm();
    if (!(norm > 0)) return;
    Eigen::VectorXd v = Jw.col(c) / norm;
    for (int pass = 0; pass < 2; ++pass)
      if (Q.cols()) v -= Q * (Q.transpose() * v);
    if (v.norm() > 1e-12) {
      Q.conservativeResize(Eigen::NoChange, Q.cols() + 1);
      Q.col(Q.cols() - 1) = v / v.norm();
    }
  };
  for (int c = 0; c < num_forced; ++c) push_q(c);
  for (int c = num_forced; c < Jw.cols(); ++c) {
    if (unit_residual(c) < tolerance) {
      if (why) (*why)[c] = "its effect on this data is (nearly) that of the parameters already chosen";
      continue;
    }
    std::vector<int> trial = kept;
    trial.push_back(c);
    const Eigen::VectorXd after = SubsetRatios(Js, trial);
    const double own = after[trial.size() - 1];
    bool ok = own < kDeterminedRatio;
    for (size_t i = 0; ok && i < kept.size(); ++i)
      if (before[i] < kDeterminedRatio && !(after[i] < kDeterminedRatio)) ok = false;
    if (!ok) {
      if (why) {
        char buf[160];
        if (own < kDeterminedRatio)
          std::snprintf(buf, sizeof buf, "it would leave parameters already chosen undetermined");
        else
          std::snprintf(buf, sizeof buf, "too weakly seen: the data would pin it to %.2g times its plausible size "
                        "(prior %.3g)", own, prior[c]);
        (*why)[c] = buf;
      }
      continue;
    }
    kept = trial;
    before = after;
    push_q(c);
  }
  return kept;
}

// Plain words for why a group of parameters is not determined.
std::string GroupCause(const Dataset& ds, const std::vector<std::string>& group) {
  const Machine& m = ds.machine();
  int gains = 0, setup = 0, machine = 0;
  for (const std::string& n : group) {
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) ++setup;
    else ++machine;
    if (i >= 0 && PriorClassOf(m, n) == "scale_gain") ++gains;
  }
  // Isotropic pretravel shortens every touch alike, as a smaller tip radius
  // would: the facet offsets and the cylinder and sphere radii absorb it.
  if (std::find(group.begin(), group.end(), "probe.pretravel") != group.end() && machine == 0)
    return "probe.pretravel acts exactly like a tip radius error, which the facet offsets and the "
           "cylinder and sphere radii also absorb: fix probe.pretravel (or qualify the probe on a "
           "calibrated sphere with its radius fixed)";
  if (gains > 0 && !HasLengthReference(ds))
    return "no length reference (no data of a kind that carries one: scale bar, ball-bar length, "
           "tracker, camera or interferometer): only relative scale can be found";
  if (machine > 0 && setup > 0)
    return "confounded with the setup (stylus tip, facet offsets, sphere centres, mounts, instrument poses or stations)";
  // A single parameter is confounded with nothing: it is seen too weakly.
  if (machine == 1 && group.size() == 1)
    return "too weakly seen at these poses for its plausible size (its prior)";
  if (machine > 0)
    return "confounded with each other or too weakly seen at these poses for their plausible size";
  return "setup parameters the data do not separate";
}

std::string UndeterminedMessage(const Dataset& ds, std::vector<std::vector<std::string>> groups) {
  // What the user asked for first: groups with machine errors; then the
  // spheres' centres (the length reference rides on them), the stylus tip,
  // and the facets and mounts, so that a capped message keeps the cause.
  const Machine& m = ds.machine();
  auto rank = [&](const std::vector<std::string>& g) {
    int r = 3;
    for (const std::string& n : g) {
      const int i = m.ParameterIndex(n);
      if (i >= 0 && m.parameters()[i].kind != ParameterKind::kTip) return 0;
      // probe.* are only estimated on request: say first why they cannot be
      if (n.rfind("probe.", 0) == 0) return 0;
      if (n.rfind("sphere.", 0) == 0) r = std::min(r, 1);
      else if (n.rfind("tip.", 0) == 0) r = std::min(r, 2);
    }
    return r;
  };
  std::stable_sort(groups.begin(), groups.end(),
                   [&](const auto& a, const auto& b) { return rank(a) < rank(b); });
  std::string msg =
      "identify: not determined by this data (confounded, or seen more weakly than their "
      "plausible size): ";
  // A refusal stays one readable line however many parameters it is about
  // (a plan missing most of its touches leaves hundreds undetermined): the
  // first groups, about kShownNames names, then how many more.
  constexpr size_t kShownNames = 10;
  size_t total = 0, listed = 0, shown = 0;
  for (const auto& g : groups) total += g.size();
  size_t i = 0;
  std::string cause;  // consecutive groups of one cause share it
  for (; i < groups.size(); ++i) {
    if (i > 0 && shown + std::min<size_t>(groups[i].size(), 8) > kShownNames) break;
    const std::string c = GroupCause(ds, groups[i]);
    if (i > 0) msg += c == cause ? ", " : ": " + cause + "; ";
    msg += GroupText(groups[i]);
    cause = c;
    shown += std::min<size_t>(groups[i].size(), 8);
    listed += groups[i].size();
  }
  msg += ": " + cause;
  if (i < groups.size())
    msg += "; and " + std::to_string(total - listed) + " more parameter" + (total - listed == 1 ? "" : "s") +
           " in " + std::to_string(groups.size() - i) + " more group" + (groups.size() - i == 1 ? "" : "s");
  return msg + ". Fix one parameter of each group, add measurements that separate them, or use "
               "estimate 'auto' (every error under its prior, the undetermined ones listed).";
}

// -- What the data could not tell, per family -------------------------------
// Families are the prior classes gathered as a reader names them (motions and
// tilts of one degree together); they come in this order.
const char* const kFamilies[] = {"location offsets", "location angles", "scale gains",
                                 "error motions of degree 1", "error motions of degree 2",
                                 "error motions of degree 3", "backlash", "set-up"};

std::string FamilyOf(const Machine& m, const std::string& n) {
  const int i = m.ParameterIndex(n);
  if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) return "set-up";
  const std::string c = PriorClassOf(m, n);
  if (c == "location_offset") return "location offsets";
  if (c == "location_angle") return "location angles";
  if (c == "scale_gain") return "scale gains";
  if (c.rfind("backlash_", 0) == 0) return "backlash";
  return "error motions of degree " + std::to_string(m.parameters()[i].degree);
}

// How each axis was seen by the data: distinct positions (capped: only
// "fewer than needed" matters) and the move directions recorded.
struct AxisSeen {
  int positions = 0;
  bool forward = false, backward = false;
};

std::vector<AxisSeen> SeenAxes(const Dataset& ds) {
  constexpr size_t kEnough = 8;
  const int na = ds.machine().num_axes();
  std::vector<std::set<long long>> at(na);
  std::vector<AxisSeen> seen(na);
  for (const Observation& o : ds.observations)
    for (int k = 0; k < na && k < o.axes.size(); ++k) {
      if (at[k].size() < kEnough) at[k].insert(std::llround(o.axes[k] * 1000.0));  // 1 um, 0.001 deg
      if (k < o.direction.size()) {
        seen[k].forward = seen[k].forward || o.direction[k] > 0;
        seen[k].backward = seen[k].backward || o.direction[k] < 0;
      }
    }
  for (int k = 0; k < na; ++k) seen[k].positions = static_cast<int>(at[k].size());
  return seen;
}

std::string JoinAnd(const std::vector<std::string>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i == 0 ? "" : i + 1 == v.size() ? " and " : ", ") + v[i];
  return s;
}

// The positions an axis must take for the data to tell a family's parameter
// of it apart from the others: a rotary axis line needs three indexations
// (two fix a circle's chord, not its centre), a degree-d error motion d + 1
// positions of a linear axis and d + 2 of a rotary one (its constant and
// location take one more), a squareness or gain two positions.
int PositionsNeeded(const Machine& m, const ParameterInfo& p) {
  const bool rotary = m.axis(p.axis).rotary();
  if (p.kind == ParameterKind::kLocation) return rotary ? 3 : 2;
  if (p.kind == ParameterKind::kMotion) return rotary ? p.degree + 2 : p.degree + 1;
  return 2;
}

// Why a family's parameters were not determined, and what would determine
// them: from how the data saw the axes they belong to (too few positions or
// indexations, one move direction), the length reference, and the groups
// the determination analysis found them confounded in (GroupCause).
std::string WhyNotDetermined(const Dataset& ds, const std::vector<AxisSeen>& seen, const std::string& family,
                             const std::vector<std::string>& names,
                             const std::vector<std::vector<std::string>>& groups) {
  const Machine& m = ds.machine();
  if (family == "scale gains" && !HasLengthReference(ds))
    return "no length reference (no scale bar or ball-bar length in the data): add a scale bar between two "
           "spheres, or a ball bar of calibrated length";
  std::map<int, int> need;  // axis -> positions needed
  for (const std::string& n : names) {
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) continue;
    const ParameterInfo& p = m.parameters()[i];
    need[p.axis] = std::max(need[p.axis], PositionsNeeded(m, p));
  }
  if (family == "backlash") {
    std::vector<std::string> one_way;
    for (const auto& [k, _] : need)
      if (!(seen[k].forward && seen[k].backward)) one_way.push_back(std::string(1, m.axis(k).name));
    if (!one_way.empty())
      return JoinAnd(one_way) + (one_way.size() == 1 ? " was" : " were") +
             " approached from one direction only (or none recorded): approach each axis from both "
             "sides and record the direction of the last move";
  } else {
    for (const bool rotary : {true, false}) {
      std::vector<std::string> axes, counts;
      int needed = 0;
      for (const auto& [k, n] : need)
        if (m.axis(k).rotary() == rotary && seen[k].positions < n) {
          axes.push_back(std::string(1, m.axis(k).name));
          counts.push_back(std::to_string(seen[k].positions));
          needed = std::max(needed, n);
        }
      if (axes.empty()) continue;
      const bool one = axes.size() == 1;
      const bool same =
          std::all_of(counts.begin(), counts.end(), [&](const std::string& c) { return c == counts[0]; });
      const std::string what = rotary ? " indexation" : " position";
      const std::string seen_at = " seen at " + (same ? counts[0] : JoinAnd(counts)) + what +
                                  (same && counts[0] == "1" ? "" : "s") + (same && !one ? " each" : "");
      if (rotary)
        return JoinAnd(axes) + seen_at + ": measure at " + std::to_string(needed) + " or more indexations of " +
               (one ? "it" : "each") + " (probe a sphere, or take R-test or ball-bar samples, at each)";
      return JoinAnd(axes) + seen_at + ": measure at " + std::to_string(needed) +
             " or more positions spread along " + (one ? "its" : "each one's") + " travel";
    }
  }
  // Every axis was seen enough: the parameters are confounded (with the
  // set-up, with each other) or seen too weakly for their plausible size.
  std::set<std::string> mine(names.begin(), names.end());
  std::vector<std::string> with;
  for (const auto& g : groups)
    if (std::any_of(g.begin(), g.end(), [&](const std::string& n) { return mine.count(n) > 0; }))
      with.insert(with.end(), g.begin(), g.end());
  if (with.empty()) with = names;
  const std::string cause = GroupCause(ds, with);
  if (family == "set-up")
    return cause + ": measure them apart (a qualified stylus, a calibrated sphere or mount) and fix them, or "
                   "add measurements from other directions and set-ups";
  if (cause.rfind("confounded with the setup", 0) == 0)
    return cause + ": add measurements that move them differently (a second artefact position, another "
                   "set-up), or fix set-up values measured apart";
  return cause + ": add poses that move them differently, over a longer travel or a larger radius";
}

std::vector<NotDetermined> NotDeterminedFamilies(const Dataset& ds, const std::vector<std::string>& estimated,
                                                 const std::vector<std::string>& undetermined,
                                                 const std::vector<std::vector<std::string>>& groups) {
  const Machine& m = ds.machine();
  const std::set<std::string> und(undetermined.begin(), undetermined.end());
  std::vector<NotDetermined> out;
  const std::vector<AxisSeen> seen = SeenAxes(ds);
  for (const char* family : kFamilies) {
    NotDetermined f;
    f.family = family;
    f.machine = f.family != "set-up";
    for (const std::string& n : estimated)
      if (FamilyOf(m, n) == f.family) {
        ++f.estimated;
        if (und.count(n)) f.names.push_back(n);
      }
    if (f.names.empty()) continue;
    f.why = WhyNotDetermined(ds, seen, f.family, f.names, groups);
    out.push_back(std::move(f));
  }
  return out;
}

// The machine errors the data put far beyond their plausible size
// (kImplausibleSigmas prior sigmas), undetermined ones left out (their
// values are arbitrary), and the likely cause: no machine is 100 mm off its
// drawing, so its nominal geometry in the machine file is wrong (or a unit).
// Empty when every determined machine error is plausible. Set-up values far
// off stay flags: a person placed them, the machine file did not.
std::string ImplausibleCause(const Machine& m, const Result& res, const Eigen::VectorXd& values,
                             const std::vector<int>& est, const Eigen::VectorXd& prior) {
  constexpr size_t kShown = 4;
  std::vector<std::string> shown;
  std::vector<std::string> axes;
  size_t count = 0;
  for (size_t j = 0; j < res.estimated.size(); ++j) {
    const std::string& n = res.estimated[j];
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) continue;
    if (std::find(res.undetermined.begin(), res.undetermined.end(), n) != res.undetermined.end()) continue;
    const double v = values[est[j]];
    if (!(std::abs(v) > kImplausibleSigmas * prior[j])) continue;
    const ParameterInfo& p = m.parameters()[i];
    const std::string axis(1, m.axis(p.axis).name);
    if (std::find(axes.begin(), axes.end(), axis) == axes.end()) axes.push_back(axis);
    if (++count > kShown) continue;
    char buf[160];
    if (p.kind == ParameterKind::kLocation)
      std::snprintf(buf, sizeof buf, "%s = %.6g %s (%.3g times its plausible size, %.3g %s)", n.c_str(),
                    v * 1e6 * (p.angular() ? 1.0 : 1e-3), p.angular() ? "urad" : "um", std::abs(v) / prior[j],
                    prior[j] * 1e6 * (p.angular() ? 1.0 : 1e-3), p.angular() ? "urad" : "um");
    else
      std::snprintf(buf, sizeof buf, "%s = %.4g (%.3g times its plausible size)", n.c_str(), v,
                    std::abs(v) / prior[j]);
    shown.push_back(buf);
  }
  if (count == 0) return "";
  std::string list;
  for (size_t k = 0; k < shown.size(); ++k) list += (k ? ", " : "") + shown[k];
  if (count > kShown) list += " and " + std::to_string(count - kShown) + " more";
  const bool one = axes.size() == 1;
  // The placed set-ups of the fit (an instrument started from the wrong pose
  // turns the machine as well): named as the other place to look.
  std::vector<std::string> placed;
  for (size_t j = 0; j < res.estimated.size() && j < res.placement.size(); ++j) {
    if (!(res.placement[j] > 0.0)) continue;
    const std::string& n = res.estimated[j];
    const size_t a = n.find('.'), b = a == std::string::npos ? a : n.find('.', a + 1);
    const std::string owner = n.substr(0, b);
    if (std::find(placed.begin(), placed.end(), owner) == placed.end()) placed.push_back(owner);
  }
  return list + ": likely cause: the machine file (machine \"" + m.name() + "\"): its nominal geometry of " +
         (one ? "axis " : "axes ") + JoinAnd(axes) + " (" + (one ? "its point or direction" :
                                                             "their points or directions") +
         ") is not the machine's, or a value is in the wrong unit; correct the machine file and fit again" +
         (placed.empty() ? std::string()
                         : "; if the machine file is right, a set-up is far from where the dataset places it (" +
                               JoinAnd(placed) + ")");
}

void FillResiduals(const Dataset& ds, const Eigen::VectorXd& values, const ParameterTable& table,
                   const Eigen::VectorXd& r, Result* res) {
  const Machine& m = ds.machine();
  const int n = static_cast<int>(ds.observations.size());
  res->residual_vectors = Eigen::MatrixXd::Zero(n, 3);
  res->points = Eigen::MatrixXd::Zero(n, 3);
  const KinematicModel model(m, values.data());
  const ReportContext ctx{&ds, &table, &values, &model};
  int row = 0;
  for (int i = 0; i < n; ++i) {
    const Observation& o = ds.observations[i];
    const ObservationKind& kind = KindOf(o);
    Eigen::Vector3d P, v;
    kind.ReportVector(ctx, o, r.data() + row, &P, &v);
    res->points.row(i) = P.transpose();
    res->residual_vectors.row(i) = v.transpose();
    row += kind.rows();
  }
}

}  // namespace

namespace {

struct Setup {
  ParameterTable table;
  Eigen::VectorXd values;  // initial, every table entry
  Eigen::VectorXd prior;   // prior sigma (plausible size), every table entry
  // Placement uncertainty of the set-up quantities (priors.h PlacementSigma;
  // 0: none), and the prior of a MAP fit: the plausible size, narrowed by the
  // placement where there is one (1/s^2 = 1/prior^2 + 1/placement^2).
  Eigen::VectorXd placement, map_prior;
  Request request;
  explicit Setup(const Dataset& ds, const IdentifyOptions& opt) : table(ds) {
    ValidateOptions(opt);
    values = InitialValues(table, opt);
    std::vector<std::string> machine_names = ds.machine().parameter_names();
    ValidatePriors(MachinePriors(ds.machine()), "machine priors", table.names());
    ValidatePriors(opt.priors, "priors", table.names());
    const std::vector<double> p =
        PriorScales(ds.machine(), table.names(), MachinePriors(ds.machine()), opt.priors);
    prior = Eigen::Map<const Eigen::VectorXd>(p.data(), static_cast<Eigen::Index>(p.size()));
    ValidateSetupUncertainty(ds.machine(), ds.setup_uncertainty, "dataset.setup_uncertainty", table.names());
    const std::vector<double> u = PlacementScales(ds.machine(), table.names(), ds.setup_uncertainty);
    placement = Eigen::Map<const Eigen::VectorXd>(u.data(), static_cast<Eigen::Index>(u.size()));
    if (!opt.setup_priors) placement.setZero();
    map_prior = prior;
    for (int i = 0; i < prior.size(); ++i)
      if (placement[i] > 0)
        map_prior[i] = 1.0 / std::sqrt(1.0 / (prior[i] * prior[i]) + 1.0 / (placement[i] * placement[i]));
    request = Classify(ds, table, opt);
  }
};

// The hierarchical prior of estimate "auto". Each class of machine errors
// (location offsets, scale gains, rotary tilts of degree 2, ...) gets a scale
// factor lambda in [kMinClassScale, 1] on its documented prior, found by
// maximising the evidence (MacKay's fixed point, the type-II maximum
// likelihood of sparse Bayesian learning):
//   lambda_k^2 = sum_j (theta_j / s_j)^2 / sum_j gamma_j,
//   gamma_j = 1 - posterior var_j / prior var_j   (j in class k),
// theta at the MAP point of the current scales. A class the data show no sign
// of shrinks towards zero, so it no longer spreads the noise over dozens of
// weakly seen errors; this is what lets "auto" predict held-out poses as well
// as the right hand-picked subset. The documented prior stays the ceiling
// (lambda <= 1): the data may say an error class is smaller than plausible,
// never larger. Only the point estimate uses the adapted scales; the
// uncertainty and the informed/undetermined judgement use the documented
// priors, so a class shrunk by the data of its siblings is never presented
// as measured for a member the data cannot see.
struct Hyper {
  Eigen::VectorXd prior;                 // per table entry, after the class scales
  std::map<std::string, double> scale;   // class -> lambda
  Eigen::VectorXd values;                // MAP point under `prior` and `noise`
  std::vector<VarianceComponent> noise;  // estimated instrument groups (variance components)
  int rounds = 0;
  int iterations = 0;                    // solver iterations over every round
};

constexpr double kMinClassScale = 1e-3;
// A group needs this much redundancy (rows minus what the fit used of them)
// before its noise is estimated from its residuals.
constexpr double kMinRedundancy = 5.0;
// An estimated noise beyond this many times the declared one is not taken
// for noise (the plain chi-square test flags sqrt(2) x already).
constexpr double kMaxNoiseFactor = 3.0;

// The instrument group of residual row `row` of an observation: the variance
// component it shares, the simulator's noise class (every probe touch:
// "probe"). Rows in another unit than the kind's first row (a pose's
// rotation rows, rad) form their own group, "<class>_<unit>": one factor
// cannot scale micrometres and microradians alike. Two trackers of one kind
// are two instruments of their own noise: when a class holds observations of
// more than one instrument id (`several`), each id is its own group,
// "<class>.<id>" ("point.T1", "pose_rad.CAM"); a single instrument keeps the
// plain class name, and kinds without an id are grouped by class alone.
std::string NoiseGroup(const Observation& o, int row, const std::set<std::string>& several) {
  const ObservationKind& k = KindOf(o);
  const std::string unit = k.unit_row(row);
  std::string g = unit == k.unit_row(0) ? k.noise_class() : std::string(k.noise_class()) + "_" + unit;
  const std::string* id = InstrumentId(o);
  if (id && several.count(k.noise_class())) g += "." + *id;
  return g;
}

// The noise classes whose observations name more than one instrument id.
std::set<std::string> ClassesOfSeveralInstruments(const Dataset& ds) {
  std::map<std::string, std::set<std::string>> ids;
  for (const Observation& o : ds.observations)
    if (const std::string* id = InstrumentId(o)) ids[KindOf(o).noise_class()].insert(*id);
  std::set<std::string> out;
  for (const auto& [cls, set] : ids)
    if (set.size() > 1) out.insert(cls);
  return out;
}

// A group's sigma x 1e3 is in um; a group of rad rows (NoiseGroup: its class
// part, before any ".<id>", ends in "_rad") is shown in urad, x 1e6.
bool RadGroup(const std::string& group) {
  const std::string cls = group.substr(0, group.find('.'));
  return cls.size() > 4 && cls.compare(cls.size() - 4, 4, "_rad") == 0;
}
const char* MicroUnit(const std::string& group) { return RadGroup(group) ? "urad" : "um"; }
double MicroScale(const std::string& group) { return RadGroup(group) ? 1e3 : 1.0; }

// Every residual row's declared sigma (ObservationSigma, as the problem weighs it).
Eigen::VectorXd DeclaredSigma(const Dataset& ds, const Observation& o) {
  Eigen::VectorXd s(KindOf(o).rows());
  for (int k = 0; k < s.size(); ++k) s[k] = ObservationSigma(ds, o, k);
  return s;
}

// Variance components (Helmert / Foerstner's iterative estimator, the REML
// fixed point for independent groups): with the hat matrix H of the weighted
// (and prior-augmented) problem, group g's redundancy is
//   r_g = sum_{i in g} (1 - H_ii),
// and its noise factor is updated by f_g^2 <- f_g^2 * sum_{i in g} (e_i/s_i)^2 / r_g,
// e the residuals, s the current sigmas. At the fixed point every group's
// weighted residuals have the chi-square their redundancy predicts, so a
// probe declared at 1 um and a ball bar at 0.5 um are weighed by what the
// data show, not by a guess.
//
// Both hyperparameters (class scales of "auto", noise factors) are
// evidence maximisations of the same model; they are iterated together.
Hyper AdaptHyperparameters(const Dataset& ds, Dataset* scaled, const ParameterTable& table,
                           const Eigen::VectorXd& start, const std::vector<int>& est,
                           const IdentifyOptions& opt, const Eigen::VectorXd& prior_all, bool classes,
                           bool map, const Eigen::VectorXd& place) {
  std::map<std::string, std::vector<int>> members;  // class -> positions in est
  const Machine& m = ds.machine();
  if (classes)
    for (size_t j = 0; j < est.size(); ++j) {
      const std::string& n = table.names()[est[j]];
      if (m.ParameterIndex(n) < 0) continue;  // setup parameters keep their prior
      const std::string cls = PriorClassOf(m, n);
      if (cls != "tip") members[cls].push_back(static_cast<int>(j));
    }
  Hyper out;
  out.prior = prior_all;
  out.values = start;
  for (const auto& kv : members) out.scale[kv.first] = 1.0;
  // Noise groups: the observations and declared sigmas of each.
  std::map<std::string, double> factor;
  // Per observation, the group of each of its rows.
  std::vector<std::vector<std::string>> group_of(ds.observations.size());
  if (opt.variance_components) {
    const std::set<std::string> several = ClassesOfSeveralInstruments(ds);
    for (size_t i = 0; i < ds.observations.size(); ++i) {
      const Observation& o = ds.observations[i];
      for (int k = 0; k < KindOf(o).rows(); ++k)
        factor[group_of[i].emplace_back(NoiseGroup(o, k, several))] = 1.0;
    }
  }
  auto apply_noise = [&]() {
    for (size_t i = 0; i < ds.observations.size(); ++i) {
      Eigen::VectorXd s = DeclaredSigma(ds, ds.observations[i]);
      for (int k = 0; k < s.size(); ++k) s[k] *= factor[group_of[i][k]];
      scaled->observations[i].sigma = s;
    }
  };
  std::map<std::string, VarianceComponent> comp;
  if (members.empty() && factor.empty()) return out;
  for (int round = 0; round < 60; ++round) {
    for (const auto& [cls, js] : members)
      for (int j : js) out.prior[est[j]] = out.scale[cls] * prior_all[est[j]];
    if (!factor.empty()) apply_noise();
    std::unique_ptr<Problem> pr;
    const Solve fit = RunFit(*scaled, table, out.values, est, opt, out.prior, &pr);
    out.values = fit.values;
    out.rounds = round + 1;
    out.iterations += fit.iterations;
    Eigen::VectorXd r;
    Eigen::MatrixXd Jw;
    WeightedJacobian(pr.get(), &r, &Jw);
    Eigen::MatrixXd Ninv;
    Eigen::VectorXd cur;
    if (map) {
      cur = Gather(out.prior, est);
      Ninv = cur.asDiagonal() * ScaledPosterior(Jw, cur) * cur.asDiagonal();
    } else {
      Ninv = AnalyzeJacobian(WithPlacementRows(Jw, place), opt.rank_tolerance).inverse_normal;
    }
    double change = 0;
    for (const auto& [cls, js] : members) {
      double m2 = 0, gamma = 0;
      for (int j : js) {
        const double t = out.values[est[j]] / prior_all[est[j]];
        m2 += t * t;
        gamma += std::clamp(1.0 - Ninv(j, j) / (cur[j] * cur[j]), 0.0, 1.0);
      }
      double lambda = gamma > 1e-9 ? std::sqrt(m2 / gamma) : kMinClassScale;
      if (!std::isfinite(lambda)) lambda = 1.0;
      lambda = std::clamp(lambda, kMinClassScale, 1.0);
      change = std::max(change, std::abs(std::log(lambda / out.scale[cls])));
      out.scale[cls] = lambda;
    }
    if (!factor.empty()) {
      const Eigen::VectorXd h = (Jw * Ninv).cwiseProduct(Jw).rowwise().sum();
      const Eigen::VectorXd sig = pr->row_sigma();
      const std::vector<int>& src = pr->row_source();
      comp.clear();
      std::map<std::string, double> declared2;
      int k = 0;  // row of its observation: an observation's rows are consecutive
      for (int i = 0; i < r.size(); ++i) {
        k = i > 0 && src[i] == src[i - 1] ? k + 1 : 0;
        if (src[i] < 0) continue;  // a scale bar's length: a reference, not an instrument group
        const std::string& g = group_of[src[i]][k];
        VarianceComponent& c = comp[g];
        c.group = g;
        c.rows += 1;
        c.redundancy += std::clamp(1.0 - h[i], 0.0, 1.0);
        c.chi2 += (r[i] / sig[i]) * (r[i] / sig[i]);
        declared2[g] += (sig[i] / factor[g]) * (sig[i] / factor[g]);
      }
      for (auto& [g, c] : comp) {
        c.declared = std::sqrt(declared2[g] / c.rows);
        c.estimated = c.redundancy >= kMinRedundancy;
        if (!c.estimated) continue;
        double f = factor[g] * std::sqrt(c.chi2 / c.redundancy);
        if (!std::isfinite(f) || !(f > 0)) f = factor[g];
        change = std::max(change, std::abs(std::log(f / factor[g])));
        factor[g] = f;
      }
    }
    if (change < (factor.empty() ? 0.01 : 1e-3)) break;
  }
  for (const auto& [cls, js] : members)
    for (int j : js) out.prior[est[j]] = out.scale[cls] * prior_all[est[j]];
  if (!factor.empty()) {
    apply_noise();
    for (auto& [g, c] : comp) {
      c.factor = factor[g];
      c.sigma = c.declared * c.factor;
      out.noise.push_back(c);
    }
  }
  return out;
}

// The "location" selection at given values (no fit).
std::vector<int> SelectAt(const Dataset& ds, const Setup& s, const Eigen::VectorXd& values,
                          const IdentifyOptions& opt,
                          std::vector<std::pair<std::string, std::string>>* left_out = nullptr) {
  std::vector<int> all = s.request.forced;
  all.insert(all.end(), s.request.candidates.begin(), s.request.candidates.end());
  Problem probe(ds, s.table, values, all);
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(&probe, &r, &Jw);
  std::vector<std::string> why;
  const std::vector<int> cols = SelectDetermined(Jw, Gather(s.prior, all),
                                                 static_cast<int>(s.request.forced.size()),
                                                 opt.selection_tolerance, &why);
  std::vector<int> out;
  for (int c : cols) out.push_back(all[c]);
  if (left_out) {
    left_out->clear();
    for (size_t c = s.request.forced.size(); c < all.size(); ++c)
      if (!why[c].empty()) left_out->emplace_back(s.table.names()[all[c]], why[c]);
  }
  return out;
}

}  // namespace

std::vector<std::string> ResolveEstimate(const Dataset& ds, const IdentifyOptions& options) {
  ds.Validate();
  const Setup s(ds, options);
  std::vector<int> idx = s.request.forced;
  if (s.request.automatic) idx.insert(idx.end(), s.request.candidates.begin(), s.request.candidates.end());
  else if (s.request.location) idx = SelectAt(ds, s, s.values, options);
  std::vector<std::string> out;
  for (int i : idx) out.push_back(s.table.names()[i]);
  return out;
}

Result Identify(const Dataset& ds, const IdentifyOptions& opt) {
  ds.Validate();
  const Setup setup(ds, opt);
  const ParameterTable& table = setup.table;
  const Request& rq = setup.request;
  Eigen::VectorXd values = setup.values;
  const bool map = rq.automatic || opt.prior;
  const Eigen::VectorXd no_prior;

  std::vector<int> est;
  std::vector<std::pair<std::string, std::string>> left_out;
  if (rq.automatic) {
    est = rq.forced;
    est.insert(est.end(), rq.candidates.begin(), rq.candidates.end());
  } else if (rq.location) {
    // Judge the selection near the solution, not at a possibly rough
    // nominal: a MAP fit over every candidate first (always well posed),
    // then select, refit, and select again until the set is stable.
    std::vector<int> all = rq.forced;
    all.insert(all.end(), rq.candidates.begin(), rq.candidates.end());
    const Solve pre = RunFit(ds, table, values, all, opt, setup.map_prior, nullptr);
    Eigen::VectorXd at = setup.values;
    for (int i : all) at[i] = pre.values[i];
    est = SelectAt(ds, setup, at, opt);
    for (int round = 0; round < 4; ++round) {
      Eigen::VectorXd start = setup.values;
      for (int i : est) start[i] = at[i];
      const Solve fit = RunFit(ds, table, start, est, opt,
                               map ? setup.map_prior : PlacementRows(setup.placement, est), nullptr);
      std::vector<int> again = SelectAt(ds, setup, fit.values, opt, &left_out);
      at = fit.values;
      if (again == est) break;
      est = again;
    }
    for (int i : est) values[i] = at[i];
  } else {
    est = rq.forced;
  }
  if (est.empty())
    throw std::invalid_argument("identify: nothing to estimate (every parameter is fixed)");

  Result res;
  res.names = table.names();
  for (int i : est) res.estimated.push_back(table.names()[i]);
  res.left_out = left_out;
  res.map_fit = map;
  res.explicit_request = !rq.automatic;
  const int p = static_cast<int>(est.size());
  // The prior of each estimated parameter: in a MAP fit that of its rows (a
  // set-up quantity's narrowed by its placement); in a least-squares fit the
  // plausible size that scales the determination, the placements entering
  // as rows of their own (`place`, `ls_rows`).
  const Eigen::VectorXd prior = Gather(map ? setup.map_prior : setup.prior, est);
  const Eigen::VectorXd place = map ? Eigen::VectorXd::Zero(p) : Gather(setup.placement, est);
  const Eigen::VectorXd ls_rows = map ? no_prior : PlacementRows(setup.placement, est);
  const bool placed = ls_rows.size() > 0;
  res.placement = std::vector<double>(place.data(), place.data() + p);
  if (map)
    for (int j = 0; j < p; ++j) res.placement[j] = setup.placement[est[j]];

  auto undetermined_groups = [&](const Determination& d) {
    std::vector<std::vector<std::string>> groups;
    for (const auto& g : d.groups) {
      std::vector<std::string> names;
      for (int c : g) names.push_back(res.estimated[c]);
      groups.push_back(names);
    }
    return groups;
  };

  // Long data: the fits and the analyses below on the accumulated normal
  // equations. Every analysis of the weighted Jacobian Jw depends on it only
  // through Jw^T Jw, so there it is replaced by a p x p factor of that
  // (NormalFactor).
  std::unique_ptr<NormalEquationProblem> nep;
  if (DenseReason(ds, opt, rq, est.size()).empty())
    nep = std::make_unique<NormalEquationProblem>(
        ds, table, values, est,
        opt.num_threads > 0 ? opt.num_threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency())));
  res.fit_path = nep ? "normal_equations" : "dense";
  // The dense path's last problem made at `kept_at`: a fit from there
  // starts on it instead of making it again.
  std::unique_ptr<Problem> kept;
  Eigen::VectorXd kept_at;
  auto weighted_jacobian_at = [&](const Eigen::VectorXd& at) {
    if (nep) return NormalFactor(nep->Accumulate(at, true).JtJ);  // true: the fit reuses it
    kept = std::make_unique<Problem>(ds, table, at, est);
    kept_at = at;
    Eigen::VectorXd r;
    Eigen::MatrixXd Jw;
    WeightedJacobian(kept.get(), &r, &Jw);
    return Jw;
  };
  auto to_solve = [](const NormalEquationFit& f) {
    Solve s;
    s.values = f.values;
    s.converged = f.converged;
    s.iterations = f.iterations;
    s.message = f.message;
    s.initial_cost = f.initial_cost;
    s.final_cost = f.final_cost;
    return s;
  };
  // A dense fit leaves its problem in `kept` (at its solution) when that is
  // one analytic batch, as a fresh problem there would be.
  auto fit_from = [&](const Eigen::VectorXd& start, const Eigen::VectorXd& prior_all) {
    if (nep) return to_solve(FitNormalEquations(*nep, start, prior_all, opt.max_iterations));
    std::unique_ptr<Problem> prepared = kept && kept_at == start ? std::move(kept) : nullptr;
    std::unique_ptr<Problem> fitted;
    const Solve fit = RunFit(ds, table, start, est, opt, prior_all, &fitted, std::move(prepared));
    kept.reset();
    if (fitted && fitted->analytic_batch()) {
      kept = std::move(fitted);
      kept_at = fit.values;
    }
    return fit;
  };
  // The weighted Jacobian at a dense fit's solution, from its problem.
  auto weighted_jacobian_after = [&](const Solve& fit) {
    if (nep || !kept || kept_at != fit.values) return weighted_jacobian_at(fit.values);
    Eigen::VectorXd r;
    Eigen::MatrixXd Jw;
    WeightedJacobian(kept.get(), &r, &Jw);
    return Jw;
  };

  if (!map) {
    // A plain least-squares request must be determined by the data: judged
    // at the start and, when the start says no, again near the solution
    // (after a MAP fit, well posed whatever the start), so that a rough
    // nominal neither drops nor admits parameters wrongly.
    Eigen::MatrixXd Jw = WithPlacementRows(weighted_jacobian_at(values), place);
    const int num_rows = nep ? nep->num_rows() + static_cast<int>((place.array() > 0).count())
                             : static_cast<int>(Jw.rows());
    if (num_rows < p && !opt.allow_unidentifiable)
      throw std::invalid_argument("identify: " + std::to_string(p) + " parameters but only " +
                                  std::to_string(num_rows) + " residuals");
    // Here only whether everything is determined matters (the groups only
    // for a refusal): the Cholesky certificate settles most undetermined
    // sets without the QR and SVD of AnalyzeDetermination.
    auto undetermined = [&](const Eigen::MatrixXd& J) {
      return CertainlyUndetermined(J, prior, kDeterminedRatio) ||
             !AnalyzeDetermination(J, prior, kDeterminedRatio).undetermined.empty();
    };
    const bool start_undetermined = undetermined(Jw);
    if (start_undetermined) {
      const Solve pre = fit_from(values, setup.map_prior);
      const Eigen::MatrixXd Jpre = WithPlacementRows(weighted_jacobian_after(pre), place);
      const bool pre_undetermined = undetermined(Jpre);
      if (!pre_undetermined) {
        values = pre.values;
      } else if (!opt.allow_unidentifiable) {
        // The MAP point may still sit where a weakly seen setup parameter
        // (a sphere with few touches) looks free; the least-squares point
        // decides. Refuse only when it too leaves the set undetermined.
        const Solve ls = fit_from(pre.values, ls_rows);
        if (undetermined(WithPlacementRows(weighted_jacobian_after(ls), place)))
          throw std::invalid_argument(
              UndeterminedMessage(ds, undetermined_groups(AnalyzeDetermination(Jpre, prior, kDeterminedRatio))));
        values = ls.values;
      }
    }
  }

  // The prior rows of the fit: none (least squares), the documented priors
  // (prior=true), or the hierarchical one of "auto".
  Eigen::VectorXd fit_prior = map ? setup.map_prior : ls_rows;
  // With variance components the fit runs on a copy whose sigmas are the
  // estimated ones; everything below (covariance, chi-square) uses them.
  // (A copy only then: long data would double their memory.)
  std::unique_ptr<Dataset> weighted_copy;
  const Dataset* weighted = &ds;
  // The rounds that set the class scales and noise move the values from the
  // start too: the reported iterations are every one the solver made.
  int adapt_iterations = 0;
  if (rq.automatic || opt.variance_components) {
    weighted_copy = std::make_unique<Dataset>(ds);
    weighted = weighted_copy.get();
    const Hyper hy =
        AdaptHyperparameters(ds, weighted_copy.get(), table, values, est, opt, fit_prior, rq.automatic, map, place);
    fit_prior = hy.prior;
    values = hy.values;
    adapt_iterations = hy.iterations;
    res.class_scales = hy.scale;
    res.variance_components = hy.noise;
  }
  std::unique_ptr<Problem> problem;
  NormalEquationFit nfit;
  const Solve fit = nep ? to_solve(nfit = FitNormalEquations(*nep, values, fit_prior, opt.max_iterations))
                        : RunFit(*weighted, table, values, est, opt, fit_prior, &problem,
                                 weighted == &ds && kept && kept_at == values ? std::move(kept) : nullptr);
  values = fit.values;
  res.converged = fit.converged;
  res.iterations = fit.iterations + adapt_iterations;
  res.message = fit.message;
  res.initial_cost = fit.initial_cost;
  res.final_cost = fit.final_cost;
  res.robust_scale = fit.robust_scale;

  // Residual rows (mm) and the weighted Jacobian at the solution; on the
  // normal-equation path its factor, from the pass the fit ended with, and
  // the residuals from one more pass without derivatives.
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  if (nep) {
    r = nep->Residuals(values);
    Jw = NormalFactor(nfit.at_solution.JtJ);
  } else {
    WeightedJacobian(problem.get(), &r, &Jw);
  }
  const Eigen::VectorXd& sig = nep ? nep->row_sigma() : problem->row_sigma();  // no copy of a data-sized vector
  // Every analysis of Jw below depends on it only through Jw^T Jw (and is
  // invariant to column scaling): one QR serves them all.
  const Eigen::MatrixXd Rw = TriangularFactor(placed ? WithPlacementRows(Jw, place) : Jw);
  const Determination det = AnalyzeDetermination(Rw, prior, kDeterminedRatio);
  if (!map && !det.undetermined.empty() && !opt.allow_unidentifiable) {
    // "location" chose its set at the declared noise; variance components
    // may find the noise larger, and a chosen candidate too weakly seen at
    // the noise the data show. That is the selection's call, not the user's
    // error: leave it out, say why, and fit the rest.
    std::set<int> dropped;
    if (rq.location && opt.variance_components)
      for (int c : det.undetermined)
        if (std::find(rq.candidates.begin(), rq.candidates.end(), est[c]) != rq.candidates.end())
          dropped.insert(c);
    if (dropped.empty() || dropped.size() == est.size())
      throw std::invalid_argument(UndeterminedMessage(ds, undetermined_groups(det)));
    IdentifyOptions again = opt;
    again.estimate.clear();
    again.include_default_setup = false;
    for (size_t c = 0; c < est.size(); ++c)
      if (!dropped.count(static_cast<int>(c))) again.estimate.push_back(table.names()[est[c]]);
    Result out = Identify(ds, again);
    out.left_out = left_out;
    for (int c : dropped)
      out.left_out.emplace_back(table.names()[est[c]],
                                "too weakly seen at the noise estimated from the residuals (variance components): "
                                "chosen at the declared noise, left out at the estimated one");
    out.explicit_request = res.explicit_request;
    return out;
  }

  res.values = values;
  res.residuals = r;
  res.residual_source = nep ? nep->row_source() : problem->row_source();
  res.n_observations = nep ? nep->num_rows() : problem->num_rows();
  res.n_parameters = p;
  res.rms = r.size() ? std::sqrt(r.squaredNorm() / r.size()) : 0.0;
  res.max_abs = r.size() ? r.cwiseAbs().maxCoeff() : 0.0;
  if (res.robust_scale > 0)
    res.outliers = RobustOutliers(PositionScaledResiduals(ds, r, sig, res.residual_source), res.robust_scale);

  // chi^2 of the data rows against the declared noise (rows the robust loss
  // flagged are left out: they are reported as outliers instead).
  std::vector<bool> outlier(r.size(), false);
  for (int i : res.outliers) outlier[i] = true;
  double chi2 = 0;
  int rows = 0;
  for (int i = 0; i < r.size(); ++i)
    if (!outlier[i]) chi2 += (r[i] / sig[i]) * (r[i] / sig[i]), ++rows;

  const Identifiability id = AnalyzeJacobian(Rw, opt.rank_tolerance);
  res.rank = id.rank;
  // MAP: the posterior in prior units under the documented priors; it gives
  // the covariance and how far the data narrowed each prior.
  const Eigen::MatrixXd Cs = map ? ScaledPosterior(Rw, prior) : Eigen::MatrixXd();
  Eigen::MatrixXd hat;  // (Jw^T Jw + P)^-1 of the fit that made the residuals
  int sigma_dof = 0;
  if (map) {
    // Posterior covariance (Jw^T Jw + P)^-1, P = diag(1 / prior^2), in the
    // declared noise; inflated by chi2/dof when the residuals exceed it.
    // The covariance uses the documented priors (see AdaptHyperparameters); the
    // degrees of freedom those of the fit that made the residuals.
    const Eigen::MatrixXd C = prior.asDiagonal() * Cs * prior.asDiagonal();
    // Effective number of parameters: trace of the hat matrix = p - trace(Cs).
    const Eigen::VectorXd used = Gather(fit_prior, est);
    const Eigen::MatrixXd Cu = rq.automatic ? ScaledPosterior(Rw, used) : Cs;
    const double p_eff = p - Cu.trace();
    const Eigen::VectorXd& cu_scale = rq.automatic ? used : prior;
    hat = cu_scale.asDiagonal() * Cu * cu_scale.asDiagonal();
    res.dof = std::max(1, rows - static_cast<int>(std::lround(p_eff)));
    const double k2 = std::max(1.0, chi2 / res.dof);
    res.covariance = k2 * C;
    // Condition number of what the data determined (the rest is the prior's).
    std::vector<int> informed_cols;
    for (int j = 0; j < p; ++j)
      if (std::sqrt(std::max(Cs(j, j), 0.0)) < kInformedThreshold) informed_cols.push_back(j);
    Eigen::MatrixXd Ri(Rw.rows(), informed_cols.size());
    for (size_t k = 0; k < informed_cols.size(); ++k) Ri.col(k) = Rw.col(informed_cols[k]);
    res.condition_number = informed_cols.empty() ? 0.0 : ConditionNumber(Ri, opt.rank_tolerance);
    sigma_dof = res.dof;
  } else {
    res.dof = std::max(0, rows - id.rank);
    if (placed) {
      // The placement rows are not data: the parameters the data used are
      // the rank less the placements' share, sum_j C_jj / u_j^2.
      double prior_share = 0;
      for (int j = 0; j < p; ++j)
        if (place[j] > 0) prior_share += id.inverse_normal(j, j) / (place[j] * place[j]);
      res.dof = std::max(0, rows - static_cast<int>(std::lround(id.rank - prior_share)));
    }
    // Without redundancy the residuals (zero) say nothing about the noise:
    // the declared noise stands, an exactly determined fit is not exact.
    const double s2 = res.dof > 0 ? chi2 / res.dof : 1.0;
    res.covariance = s2 * id.inverse_normal;
    // The condition number of the column-scaled Jacobian in mm, as before the
    // weighting and as the plan design reports it.
    // Every row of one declared noise (a plan of probe touches): the mm
    // Jacobian is Jw times that noise, its column-scaled form Jw's, and the
    // condition number id's.
    // With placement rows, the condition number of the problem they make
    // well posed (the data's alone is infinite where a placement is confounded).
    const bool one_noise = placed || (sig.size() > 0 && (sig.array() == sig[0]).all());
    res.condition_number =
        one_noise ? id.condition_number
                  : ConditionNumber(nep ? NormalFactor(nfit.at_solution.JtJ_unweighted)
                                        : Eigen::MatrixXd(sig.asDiagonal() * Jw),
                                    opt.rank_tolerance);
    sigma_dof = placed ? res.dof : res.n_observations - id.rank;
    hat = id.inverse_normal;
  }
  res.sigma = sigma_dof > 0 ? std::sqrt(r.squaredNorm() / sigma_dof) : 0.0;
  // On the normal-equation path Jw is the p x p factor, not rows: a unit's
  // share of the parameters is trace(hat Jw_u^T Jw_u) from its rows' sums.
  if (nep) {
    std::map<std::string, double> share;
    for (size_t u = 0; u < nep->other_units().size(); ++u)
      share[nep->other_units()[u]] = hat.cwiseProduct(nfit.at_solution.JtJ_units[u]).sum();
    res.residual_units = ResidualsByUnit(ds, r, res.residual_source, share, sigma_dof);
  } else {
    res.residual_units = ResidualsByUnit(ds, r, res.residual_source, Jw, hat, sigma_dof);
  }
  if (res.residual_units.size() > 1) {
    res.rms = res.residual_units[0].rms;
    res.max_abs = res.residual_units[0].max_abs;
    res.sigma = res.residual_units[0].sigma;
  }
  res.chi2 = chi2;
  res.chi2_p = res.dof > 0 ? ChiSquareSurvival(chi2, res.dof) : 1.0;
  res.std = res.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  res.correlation = Eigen::MatrixXd::Zero(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) {
      const double d = res.std[i] * res.std[j];
      res.correlation(i, j) = d > 0 ? res.covariance(i, j) / d : (i == j ? 1.0 : 0.0);
    }

  // What the data determined.
  for (const auto& g : undetermined_groups(det)) res.unidentifiable.push_back(g);
  for (int j = 0; j < p; ++j) {
    res.prior_std.push_back(prior[j]);
    res.informed.push_back(res.std[j] / prior[j]);
    const double v = values[est[j]];
    if (std::abs(v) > kImplausibleSigmas * prior[j]) res.implausible.push_back(res.estimated[j]);
  }
  if (map) {
    // The posterior ratio without the chi2 inflation: how much the data, at
    // the declared noise, narrowed the prior.
    for (int j = 0; j < p; ++j)
      if (!(std::sqrt(std::max(Cs(j, j), 0.0)) < kInformedThreshold))
        res.undetermined.push_back(res.estimated[j]);
  } else {
    for (int c : det.undetermined) res.undetermined.push_back(res.estimated[c]);
  }
  // The machine errors the data identified (kIdentifiedRatio). A MAP fit's
  // data-only groups are no verdict on their members: the posterior,
  // `undetermined`, says which ones the data, with the others' priors,
  // narrowed; one in a class the data show no sign of is held near 0.
  res.seeks_machine_errors = rq.location || rq.automatic;
  for (int j = 0; j < p; ++j) {
    const std::string& n = res.estimated[j];
    if (std::find(res.undetermined.begin(), res.undetermined.end(), n) != res.undetermined.end()) continue;
    const int i = ds.machine().ParameterIndex(n);
    const bool machine = i >= 0 && ds.machine().parameters()[i].kind != ParameterKind::kTip;
    const auto scale = machine ? res.class_scales.find(PriorClassOf(ds.machine(), n)) : res.class_scales.end();
    if (scale != res.class_scales.end() && scale->second < kAbsentClassScale) res.held.push_back(n);
    else if (machine && (!(res.informed[j] > kIdentifiedRatio) ||
                         std::abs(values[est[j]]) >= kSignificantSigmas * res.std[j]))
      ++res.identified_machine_errors;
  }
  for (const std::string& n : res.estimated) {
    const int i = ds.machine().ParameterIndex(n);
    if (i >= 0 && ds.machine().parameters()[i].kind != ParameterKind::kTip) res.seeks_machine_errors = true;
  }
  res.not_determined = NotDeterminedFamilies(ds, res.estimated, res.undetermined, res.unidentifiable);
  res.plausibility = ImplausibleCause(ds.machine(), res, values, est, prior);
  res.plausible = res.plausibility.empty();

  // Adequacy: residuals against the declared noise.
  const double ratio = res.dof > 0 ? chi2 / res.dof : 0.0;
  res.adequate = !(res.chi2_p < 1e-3 && ratio > 2.0);
  bool mounts = false, mount_estimated = false;
  for (const Observation& o : ds.observations)
    for (int c : KindOf(o).MountPositions(table, o)) {
      mounts = true;
      if (std::find(est.begin(), est.end(), c) != est.end()) mount_estimated = true;
    }
  bool cause_named = false;  // the residuals name the cause: a set-up left fixed, a unit
  if (!res.adequate) {
    const double x = std::sqrt(ratio);
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3g", x);
    cause_named = (mounts && !mount_estimated) || (x > 200 && x < 5000);
    if (mounts && !mount_estimated)
      res.adequacy = "instrument setup not estimated (ball3d/dbb mount: estimate its tool and "
                     "table ball positions, e.g. ball3d.<setup>.table.x|y|z); residuals are " +
                     std::string(buf) + "x the declared noise";
    else if (x > 200 && x < 5000)
      res.adequacy = "unit mistake (residuals ~" + std::string(buf) +
                     "x the declared noise: readings in um where mm are expected, or a wrong sigma)";
    else if (!HasLengthReference(ds))
      res.adequacy = "no length reference (no scale bar / dbb length) and residuals " +
                     std::string(buf) + "x the declared noise: the model misses errors the data show";
    else
      res.adequacy = "residuals " + std::string(buf) +
                     "x the declared noise: the model misses errors the data show (estimate more, "
                     "e.g. 'auto') or the declared noise is too small";
  }

  // A misfit whose cause the residuals name (a set-up left fixed, a unit
  // mistake) is told by that cause: the values it drives far off are its
  // symptom, and "the machine file" would send the user to the wrong file.
  if (cause_named && !res.plausible) {
    res.adequacy += "; it drives values beyond their plausible size: " + res.plausibility;
    res.plausible = true;
  }

  // With the noise estimated the chi-square passes by construction; what is
  // left to judge is how far each group's noise is from its declaration.
  // Variance components would otherwise absorb any misfit as "noise": beyond
  // kMaxNoiseFactor it is a misfit or a unit mistake, not the instrument.
  for (const VarianceComponent& c : res.variance_components)
    if (c.estimated && res.adequate && c.factor > kMaxNoiseFactor) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "the %s residuals are %.3gx their declared noise even with the noise estimated "
                    "(%.3g %s against %.3g %s declared): ",
                    c.group.c_str(), c.factor, c.sigma * 1e3 * MicroScale(c.group), MicroUnit(c.group),
                    c.declared * 1e3 * MicroScale(c.group), MicroUnit(c.group));
      res.adequate = false;
      res.adequacy = std::string(buf) +
                     (c.group != "probe" && mounts && !mount_estimated
                          ? "instrument setup not estimated (ball3d/dbb mount: estimate its tool and "
                            "table ball positions, e.g. ball3d.<setup>.table.x|y|z)"
                          : "the model misses errors this instrument sees, or its readings are in other "
                            "units; if the noise really is this large, declare it (sigma)");
    }

  // Never hand out NaN or inf.
  res.finite = values.allFinite() && res.std.allFinite() && res.covariance.allFinite();
  if (!res.finite) {
    for (int i = 0; i < res.values.size(); ++i)
      if (!std::isfinite(res.values[i])) res.values[i] = setup.values[i];
    for (int i = 0; i < res.std.size(); ++i)
      if (!std::isfinite(res.std[i])) res.std[i] = 0.0;
    res.covariance = res.covariance.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
    res.correlation = res.correlation.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
    for (double& x : res.informed)
      if (!std::isfinite(x)) x = 0.0;
  }
  res.residuals = res.residuals.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
  if (!std::isfinite(res.rms)) res.rms = 0, res.finite = false;
  if (!std::isfinite(res.max_abs)) res.max_abs = 0;
  if (!std::isfinite(res.sigma)) res.sigma = 0;
  FillResiduals(ds, res.values, table, res.residuals, &res);
  return res;
}

std::string Result::verdict() const {
  if (!finite) return "non_finite";
  if (!converged) return "not_converged";
  // Before adequacy: a misfit that follows from a wrong nominal geometry is
  // best told by its cause.
  if (!plausible) return "implausible";
  if (!adequate) return "inadequate";
  if (explicit_request && !undetermined.empty()) return "undetermined";
  // Set-up quantities alone (a stylus tip, a sphere centre) are no
  // calibration: a fit for machine errors that determined none of them is
  // not usable, whatever it says of the set-up.
  if (seeks_machine_errors && identified_machine_errors == 0) return "undetermined";
  return "ok";
}

Eigen::VectorXd PredictResiduals(const Dataset& ds, const std::map<std::string, double>& values,
                                 std::vector<int>* source) {
  ds.Validate();
  const ParameterTable table(ds);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : values) {
    const int i = table.Index(name);
    if (i >= 0) v[i] = value;  // other datasets' setup parameters do not apply here
    else if (!IsSetupParameterName(name))
      table.Require(name);  // throws: a machine name typo or a malformed dotted name
  }
  Problem problem(ds, table, v, {});
  Eigen::VectorXd r;
  problem.Evaluate(&r, nullptr);
  if (source) *source = problem.row_source();
  return r;
}

namespace {
// JSON has no inf or NaN: such a number is written as null.
json Finite(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }
}  // namespace

std::string Result::ToJson() const {
  json j;
  json params = json::object();
  for (size_t i = 0; i < estimated.size(); ++i) {
    const auto it = std::find(names.begin(), names.end(), estimated[i]);
    json entry = {{"value", Finite(values[it - names.begin()])}, {"std", Finite(this->std[i])}};
    if (i < prior_std.size()) {
      entry["prior_std"] = Finite(prior_std[i]);
      entry["informed"] = Finite(informed[i]);
    }
    if (i < placement.size() && placement[i] > 0) entry["placement_std"] = Finite(placement[i]);
    params[estimated[i]] = entry;
  }
  for (size_t i = 0; i < names.size(); ++i)
    if (!params.contains(names[i]) && values[i] != 0.0)
      params[names[i]] = {{"value", Finite(values[i])}, {"fixed", true}};
  j["parameters"] = params;
  j["residual_rms"] = Finite(rms);
  j["residual_max"] = Finite(max_abs);
  j["sigma"] = Finite(sigma);
  if (residual_units.size() > 1) {
    json units = json::object();
    for (const UnitResiduals& u : residual_units)
      units[u.unit] = {{"rows", u.rows}, {"rms", Finite(u.rms)}, {"max", Finite(u.max_abs)},
                       {"sigma", Finite(u.sigma)}};
    j["residual_units"] = units;
  }
  j["n_observations"] = n_observations;
  j["n_parameters"] = n_parameters;
  j["condition_number"] = std::isfinite(condition_number) ? json(condition_number) : json(nullptr);
  j["rank"] = rank;
  j["unidentifiable"] = unidentifiable;
  j["converged"] = converged;
  j["iterations"] = iterations;
  j["estimated"] = estimated;
  j["undetermined"] = undetermined;
  j["identified_machine_errors"] = identified_machine_errors;
  j["held"] = held;
  json nd = json::array();
  for (const NotDetermined& f : not_determined)
    nd.push_back({{"family", f.family}, {"machine", f.machine}, {"estimated", f.estimated},
                  {"names", f.names}, {"why", f.why}});
  j["not_determined"] = nd;
  j["implausible"] = implausible;
  j["map_fit"] = map_fit;
  if (!variance_components.empty()) {
    nlohmann::json vc = nlohmann::json::array();
    for (const VarianceComponent& c : variance_components)
      vc.push_back({{"group", c.group}, {"rows", c.rows}, {"redundancy", Finite(c.redundancy)},
                    {"declared_sigma", Finite(c.declared)}, {"factor", Finite(c.factor)},
                    {"sigma", Finite(c.sigma)}, {"estimated", c.estimated}});
    j["variance_components"] = vc;
  }
  if (!class_scales.empty()) {
    nlohmann::json cs = nlohmann::json::object();
    for (const auto& [cls, v] : class_scales) cs[cls] = Finite(v);
    j["class_scales"] = cs;
  }
  j["chi2"] = {{"value", Finite(chi2)}, {"dof", dof}, {"p", Finite(chi2_p)}};
  j["adequate"] = adequate;
  j["adequacy"] = adequacy;
  j["plausible"] = plausible;
  j["plausibility"] = plausibility;
  j["finite"] = finite;
  j["verdict"] = verdict();
  json corr = json::array();
  for (int i = 0; i < correlation.rows(); ++i) {
    json row = json::array();
    for (int k = 0; k < correlation.cols(); ++k) row.push_back(Finite(correlation(i, k)));
    corr.push_back(row);
  }
  j["correlation"] = corr;
  json res_rows = json::array();
  for (int i = 0; i < residuals.size(); ++i) res_rows.push_back(Finite(residuals[i]));
  j["residuals"] = res_rows;
  j["outliers"] = outliers;
  return j.dump(1);
}

}  // namespace fivecal
