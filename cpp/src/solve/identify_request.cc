#include "fivecal/solve/identify_request.h"

#include <Eigen/QR>
#include <algorithm>
#include <cstdio>
#include <cmath>
#include <set>
#include <stdexcept>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify_problem.h"
#include "fivecal/solve/priors.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

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

// The "location" selection at given values (no fit).
std::vector<int> SelectAt(const Dataset& ds, const IdentifyRequest& s, const Eigen::VectorXd& values,
                          const IdentifyOptions& opt,
                          std::vector<std::pair<std::string, std::string>>* left_out = nullptr) {
  std::vector<int> all = s.forced;
  all.insert(all.end(), s.candidates.begin(), s.candidates.end());
  Problem probe(ds, s.table, values, all);
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(&probe, &r, &Jw);
  std::vector<std::string> why;
  const std::vector<int> cols = SelectDetermined(Jw, Gather(s.prior_all, all),
                                                 static_cast<int>(s.forced.size()),
                                                 opt.selection_tolerance, &why);
  std::vector<int> out;
  for (int c : cols) out.push_back(all[c]);
  if (left_out) {
    left_out->clear();
    for (size_t c = s.forced.size(); c < all.size(); ++c)
      if (!why[c].empty()) left_out->emplace_back(s.table.names()[all[c]], why[c]);
  }
  return out;
}

// What each left-out candidate would do to the estimates if it were not 0:
// the least-squares change of the estimated set that absorbs its column,
// d(est)/d(c) = (Je^T Je)^-1 Je^T Jc on the weighted data rows at `at`.
// Entries below 1e-12 of the largest are dropped (they move nothing).
std::vector<LeftOutMoves> MovesOfLeftOut(const Dataset& ds, const IdentifyRequest& s, const Eigen::VectorXd& at,
                                         const std::vector<int>& est) {
  std::vector<LeftOutMoves> out;
  std::vector<int> left;
  for (const auto& lo : s.left_out) left.push_back(s.table.Require(lo.first));
  if (left.empty() || est.empty()) return out;
  std::vector<int> all = est;
  all.insert(all.end(), left.begin(), left.end());
  Problem probe(ds, s.table, at, all);
  Eigen::VectorXd r;
  Eigen::MatrixXd Jw;
  WeightedJacobian(&probe, &r, &Jw);
  const Eigen::Index p = static_cast<Eigen::Index>(est.size());
  // Column-pivoted QR: the chosen set is determined by construction, but a
  // rank-deficient one must not give infinities here.
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Jw.leftCols(p));
  const Eigen::MatrixXd A = qr.solve(Jw.rightCols(Jw.cols() - p));
  for (size_t k = 0; k < left.size(); ++k) {
    LeftOutMoves m;
    m.name = s.left_out[k].first;
    m.plausible = s.prior_all[left[k]];
    const double big = A.col(static_cast<Eigen::Index>(k)).cwiseAbs().maxCoeff();
    for (Eigen::Index e = 0; e < p; ++e) {
      const double a = A(e, static_cast<Eigen::Index>(k));
      if (std::isfinite(a) && std::abs(a) > 1e-12 * big) m.moves[s.table.names()[est[e]]] = a;
    }
    out.push_back(std::move(m));
  }
  return out;
}

}  // namespace

Eigen::VectorXd Gather(const Eigen::VectorXd& all, const std::vector<int>& idx) {
  Eigen::VectorXd v(idx.size());
  for (size_t i = 0; i < idx.size(); ++i) v[i] = all[idx[i]];
  return v;
}

IdentifyRequest PrepareRequest(const Dataset& ds, const IdentifyOptions& opt) {
  IdentifyRequest rq(ds);
  const ParameterTable& table = rq.table;
  ValidateOptions(opt);
  rq.initial = InitialValues(table, opt);
  // The machine file's "priors" (name or class:<name> -> sigma), then the call's.
  ValidatePriors(ds.machine().priors, "machine priors", table.names());
  ValidatePriors(opt.priors, "priors", table.names());
  const std::vector<double> p = PriorScales(ds.machine(), table.names(), ds.machine().priors, opt.priors);
  rq.prior_all = Eigen::Map<const Eigen::VectorXd>(p.data(), static_cast<Eigen::Index>(p.size()));
  ValidateSetupUncertainty(ds.machine(), ds.setup_uncertainty, "dataset.setup_uncertainty", table.names());
  const std::vector<double> u = PlacementScales(ds.machine(), table.names(), ds.setup_uncertainty);
  rq.placement_all = Eigen::Map<const Eigen::VectorXd>(u.data(), static_cast<Eigen::Index>(u.size()));
  if (!opt.setup_priors) rq.placement_all.setZero();
  rq.map_prior_all = rq.prior_all;
  for (int i = 0; i < rq.prior_all.size(); ++i)
    if (rq.placement_all[i] > 0)
      rq.map_prior_all[i] = 1.0 / std::sqrt(1.0 / (rq.prior_all[i] * rq.prior_all[i]) +
                                            1.0 / (rq.placement_all[i] * rq.placement_all[i]));
  Request q = Classify(ds, table, opt);
  rq.forced = std::move(q.forced);
  rq.candidates = std::move(q.candidates);
  rq.location = q.location;
  rq.automatic = q.automatic;
  rq.map = rq.automatic || opt.prior;
  rq.start = rq.initial;
  return rq;
}

IdentifyRequest ResolveRequest(const Dataset& ds, const IdentifyOptions& opt) {
  IdentifyRequest rq = PrepareRequest(ds, opt);
  const ParameterTable& table = rq.table;
  std::vector<int>& est = rq.est;
  if (rq.automatic) {
    est = rq.forced;
    est.insert(est.end(), rq.candidates.begin(), rq.candidates.end());
  } else if (rq.location) {
    // Judge the selection near the solution, not at a possibly rough
    // nominal: a MAP fit over every candidate first (always well posed),
    // then select, refit, and select again until the set is stable.
    std::vector<int> all = rq.forced;
    all.insert(all.end(), rq.candidates.begin(), rq.candidates.end());
    const SingleFit pre = RunFit(ds, table, rq.initial, all, opt, rq.map_prior_all, nullptr);
    Eigen::VectorXd at = rq.initial;
    for (int i : all) at[i] = pre.values[i];
    est = SelectAt(ds, rq, at, opt);
    for (int round = 0; round < 4; ++round) {
      Eigen::VectorXd start = rq.initial;
      for (int i : est) start[i] = at[i];
      const SingleFit fit = RunFit(ds, table, start, est, opt,
                                   rq.map ? rq.map_prior_all : PlacementRows(rq.placement_all, est), nullptr);
      std::vector<int> again = SelectAt(ds, rq, fit.values, opt, &rq.left_out);
      at = fit.values;
      if (again == est) break;
      est = again;
    }
    for (int i : est) rq.start[i] = at[i];
    rq.left_out_moves = MovesOfLeftOut(ds, rq, at, est);
  } else {
    est = rq.forced;
  }
  if (est.empty())
    throw std::invalid_argument("identify: nothing to estimate (every parameter is fixed)");
  for (int i : est) rq.estimated.push_back(table.names()[i]);
  const int p = static_cast<int>(est.size());
  rq.prior = Gather(rq.map ? rq.map_prior_all : rq.prior_all, est);
  rq.place = rq.map ? Eigen::VectorXd::Zero(p) : Gather(rq.placement_all, est);
  if (!rq.map) rq.ls_rows = PlacementRows(rq.placement_all, est);
  rq.placed = rq.ls_rows.size() > 0;
  return rq;
}

std::vector<std::string> ResolveEstimate(const Dataset& ds, const IdentifyOptions& options) {
  ds.Validate();
  const IdentifyRequest s = PrepareRequest(ds, options);
  std::vector<int> idx = s.forced;
  if (s.automatic) idx.insert(idx.end(), s.candidates.begin(), s.candidates.end());
  else if (s.location) idx = SelectAt(ds, s, s.initial, options);
  std::vector<std::string> out;
  for (int i : idx) out.push_back(s.table.names()[i]);
  return out;
}

}  // namespace fivecal
