// Verify after loading: the comparison of verify.h.
#include "fivecal/controllers/verify.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <stdexcept>
#include <tuple>
#include <utility>

#include "fivecal/procedures/sphere_check.h"
#include "fivecal/uncertainty/gum.h"

namespace fivecal {
namespace controllers {

namespace {

std::string Join(const std::vector<std::string>& v) {
  std::string s;
  for (const std::string& x : v) s += (s.empty() ? "" : ", ") + x;
  return s;
}

std::string Num(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.3g", v);
  return b;
}

// The estimate checked (sizes, finite, symmetric positive semi-definite) and
// put under the check's names: a name that is the spindle's under another
// name becomes the spindle's, with the sign SpindleNames gives; names that
// meet add up, and so do their covariances (x' = T x, C' = T C T^T).
NamedEstimate ToCheckNames(const Machine& m, const NamedEstimate& e, const std::string& field) {
  const Eigen::Index n = static_cast<Eigen::Index>(e.names.size());
  if (e.values.size() != n)
    throw std::invalid_argument(field + ": " + std::to_string(e.names.size()) + " names but " +
                                std::to_string(e.values.size()) + " values");
  Eigen::MatrixXd C = e.covariance.size() ? e.covariance : Eigen::MatrixXd::Zero(n, n);
  if (C.rows() != n || C.cols() != n)
    throw std::invalid_argument(field + ".covariance: expected " + std::to_string(n) + " x " + std::to_string(n) +
                                ", got " + std::to_string(C.rows()) + " x " + std::to_string(C.cols()));
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::string& name = e.names[size_t(i)];
    if (std::count(e.names.begin(), e.names.end(), name) > 1)
      throw std::invalid_argument(field + ": " + name + " named twice");
    if (C(i, i) < 0) throw std::invalid_argument(field + "." + name + ": negative variance");  // NaN passes: checked if compared
  }
  NamedEstimate out;
  std::vector<std::pair<Eigen::Index, double>> to;  // per input: (output row, sign)
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto mapped = SpindleNames(m, {{e.names[size_t(i)], 1.0}});
    const std::string& name = mapped.empty() ? e.names[size_t(i)] : mapped[0].first;
    const double sign = mapped.empty() ? 1.0 : mapped[0].second;
    auto it = std::find(out.names.begin(), out.names.end(), name);
    if (it == out.names.end()) {
      out.names.push_back(name);
      it = out.names.end() - 1;
    }
    to.emplace_back(static_cast<Eigen::Index>(it - out.names.begin()), sign);
  }
  // x' = T x, C' = T C T^T summed entry by entry: a NaN (a value not given)
  // stays in its own row, where only a comparison that reads it refuses it
  const Eigen::Index m2 = static_cast<Eigen::Index>(out.names.size());
  out.values = Eigen::VectorXd::Zero(m2);
  out.covariance = Eigen::MatrixXd::Zero(m2, m2);
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto [a, sa] = to[size_t(i)];
    out.values[a] += sa * e.values[i];
    for (Eigen::Index j = 0; j < n; ++j) {
      const auto [b, sb] = to[size_t(j)];
      out.covariance(a, b) += sa * sb * C(i, j);
    }
  }
  return out;
}

Eigen::VectorXd Pick(const NamedEstimate& e, const std::vector<Eigen::Index>& idx) {
  Eigen::VectorXd v(static_cast<Eigen::Index>(idx.size()));
  for (size_t i = 0; i < idx.size(); ++i) v[Eigen::Index(i)] = e.values[idx[i]];
  return v;
}

Eigen::MatrixXd Pick2(const NamedEstimate& e, const std::vector<Eigen::Index>& idx) {
  const Eigen::Index n = static_cast<Eigen::Index>(idx.size());
  Eigen::MatrixXd C(n, n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (Eigen::Index j = 0; j < n; ++j) C(i, j) = e.covariance(idx[size_t(i)], idx[size_t(j)]);
  return C;
}

// The compared rows of one estimate: finite, and a covariance that is one
// (symmetric, positive semi-definite); the rows not compared are not read.
void CheckCompared(const std::vector<std::string>& names, const Eigen::VectorXd& v, const Eigen::MatrixXd& C,
                   const std::string& field, bool covariance = true) {
  const Eigen::Index n = v.size();
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::string& name = names[size_t(i)];
    if (!std::isfinite(v[i])) throw std::invalid_argument(field + "." + name + ": value is not finite");
    if (!covariance) continue;
    for (Eigen::Index j = 0; j < n; ++j)
      if (!std::isfinite(C(i, j)))
        throw std::invalid_argument(field + "." + name + ": covariance with " + names[size_t(j)] +
                                    " is not finite (no uncertainty given?)");
  }
  if (!covariance) return;
  const double scale = n ? C.cwiseAbs().maxCoeff() : 0.0;
  if (n && (C - C.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale)
    throw std::invalid_argument(field + ".covariance: not symmetric");
  if (n && scale > 0) {
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (C + C.transpose()), Eigen::EigenvaluesOnly);
    if (es.eigenvalues().minCoeff() < -1e-9 * scale)
      throw std::invalid_argument(field + ".covariance: not positive semi-definite (a correlation above 1?)");
  }
}

// (r^T S^-1 r); S must be positive definite.
double Quad(const Eigen::MatrixXd& S, const Eigen::VectorXd& r, const std::string& what) {
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(S);
  const double scale = S.diagonal().cwiseAbs().maxCoeff();
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 1e-14 * scale) || !(scale > 0))
    throw std::invalid_argument(what + ": the combined covariance of the checks is singular (a check or "
                                "a change with zero uncertainty?)");
  return r.dot(ldlt.solve(r));
}

struct Factor {
  ChangeCause cause;
  double f;
};

const std::vector<Factor>& ScalarHypotheses() {
  static const std::vector<Factor> h = {
      {ChangeCause::kTookEffect, 1.0},   {ChangeCause::kNotApplied, 0.0},   {ChangeCause::kSignReversed, -1.0},
      {ChangeCause::kAppliedTwice, 2.0}, {ChangeCause::kMicronAsMm, 1000.0}, {ChangeCause::kMmAsMicron, 0.001},
      {ChangeCause::kMmAsInch, 25.4},    {ChangeCause::kInchAsMm, 1.0 / 25.4}};
  return h;
}

std::vector<Hypothesis> Hypotheses(const std::vector<std::string>& names, bool components) {
  const Eigen::Index n = static_cast<Eigen::Index>(names.size());
  std::vector<Hypothesis> hs;
  for (const Factor& s : ScalarHypotheses()) {
    Hypothesis h;
    h.cause = s.cause;
    h.factors = Eigen::VectorXd::Constant(n, s.f);
    hs.push_back(h);
  }
  if (components && n >= 2)
    for (Eigen::Index j = 0; j < n; ++j) {
      Hypothesis h;
      h.cause = ChangeCause::kComponentSign;
      h.component = names[size_t(j)];
      h.factors = Eigen::VectorXd::Ones(n);
      h.factors[j] = -1;
      hs.push_back(h);
    }
  return hs;
}

std::string List(const std::vector<Hypothesis>& hs) {
  std::vector<std::string> t;
  for (const Hypothesis& h : hs) t.push_back(h.Text());
  return Join(t);
}

// The decision of verify.h over hypotheses whose chi2 is set. S1 = S_d + C_c
// measures how far apart two hypotheses' predictions lie.
ChangeOutcome Decide(const std::vector<Hypothesis>& hs, const Eigen::VectorXd& c, const Eigen::MatrixXd& S1,
                     double limit, double k, double ratio, double ratio_std) {
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(S1);
  const auto dist = [&](size_t i, size_t j) {
    const Eigen::VectorXd dm = (hs[i].factors - hs[j].factors).cwiseProduct(c);
    return std::sqrt(std::max(0.0, dm.dot(ldlt.solve(dm))));
  };
  size_t best = 0;
  for (size_t i = 1; i < hs.size(); ++i)
    if (hs[i].chi2 < hs[best].chi2) best = i;
  const std::string numbers = "observed / expected change " + Num(ratio) + " ± " + Num(ratio_std) + " (1σ)";
  ChangeOutcome out;
  if (!(hs[best].chi2 <= limit)) {
    out.verdict = ChangeVerdict::kDiffers;
    out.message = "differs, not one of these: " + numbers + "; the closest, " + hs[best].Text() + ", misses by chi2 " +
                  Num(hs[best].chi2) + " > " + Num(limit);
    return out;
  }
  std::vector<size_t> A;
  for (size_t i = 0; i < hs.size(); ++i)
    if (hs[i].chi2 - hs[best].chi2 <= k * k) A.push_back(i);
  const bool took = std::find(A.begin(), A.end(), size_t(0)) != A.end();  // hs[0]: took effect
  if (took) {
    // a whole-change alternative left standing means the check cannot
    // confirm the change at all (a change below its resolution is one
    // "not applied" cannot be told from); only one component's sign on a
    // component too small to see is left untested, and said so
    for (size_t i : A) {
      if (i == 0) continue;
      const bool small = hs[i].cause == ChangeCause::kComponentSign && dist(i, 0) < k;
      (small ? out.unresolved : out.causes).push_back(hs[i]);
    }
    if (out.causes.empty()) {
      out.verdict = ChangeVerdict::kTookEffect;
      out.message = "took effect as predicted (" + numbers + ")";
      if (!out.unresolved.empty())
        out.message += "; too small for this check to see: " + List(out.unresolved);
    } else {
      out.verdict = ChangeVerdict::kCannotTell;
      out.message = "this check cannot tell: the change may have taken effect, or " + List(out.causes) + " (" +
                    numbers + "); repeat the check with more positions or a larger change";
    }
    return out;
  }
  bool one_group = true, resolved = true;
  for (size_t i : A) {
    out.causes.push_back(hs[i]);
    one_group = one_group && dist(i, best) < k;
    resolved = resolved && dist(i, 0) >= k;
  }
  if (!resolved) {
    // excluded by these numbers, yet a cause left standing lies within the
    // check's resolution of "took effect": the check cannot tell them apart
    out.verdict = ChangeVerdict::kCannotTell;
    out.message = "this check cannot tell: the numbers lean to " + List(out.causes) +
                  ", which it cannot resolve from a change that took effect (" + numbers +
                  "); repeat the check with more positions or after a larger change";
    return out;
  }
  out.verdict = one_group ? ChangeVerdict::kCause : ChangeVerdict::kOneOf;
  if (one_group && A.size() == 1)
    out.message = "did not take effect as predicted: " + hs[A[0]].Text() + " (" + numbers + ")";
  else if (one_group)
    out.message = "did not take effect as predicted: " + out.causes[0].Text() + " (or " +
                  List(std::vector<Hypothesis>(out.causes.begin() + 1, out.causes.end())) +
                  ": this check cannot tell these apart; " + numbers + ")";
  else
    out.message = "did not take effect as predicted: one of " + List(out.causes) + "; this check cannot tell which (" +
                  numbers + ")";
  return out;
}

// Weighted least squares of d on c: ratio and its sigma, the change's own
// covariance entering at the ratio found (two passes).
std::pair<double, double> Ratio(const Eigen::VectorXd& d, const Eigen::MatrixXd& Sd, const Eigen::VectorXd& c,
                                const Eigen::MatrixXd& Sc) {
  double f = 1.0, s = std::numeric_limits<double>::quiet_NaN();
  for (int pass = 0; pass < 3; ++pass) {
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(Sd + f * f * Sc);
    const Eigen::VectorXd Wc = ldlt.solve(c);
    const double cwc = c.dot(Wc);
    if (!(cwc > 0)) return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
    f = Wc.dot(d) / cwc;
    s = 1.0 / std::sqrt(cwc);
  }
  return {f, s};
}

}  // namespace

std::string ChangeCauseText(ChangeCause cause) {
  switch (cause) {
    case ChangeCause::kTookEffect: return "took effect";
    case ChangeCause::kNotApplied: return "not applied";
    case ChangeCause::kSignReversed: return "sign reversed";
    case ChangeCause::kAppliedTwice: return "applied twice";
    case ChangeCause::kMicronAsMm: return "unit: a µm value read as mm (x1000)";
    case ChangeCause::kMmAsMicron: return "unit: a mm value read as µm (x0.001)";
    case ChangeCause::kMmAsInch: return "unit: a mm value read as inch (x25.4)";
    case ChangeCause::kInchAsMm: return "unit: an inch value read as mm (x1/25.4)";
    case ChangeCause::kComponentSign: return "sign of one component";
  }
  return "?";
}

std::string ChangeVerdictName(ChangeVerdict v) {
  switch (v) {
    case ChangeVerdict::kTookEffect: return "took effect";
    case ChangeVerdict::kCause: return "cause";
    case ChangeVerdict::kOneOf: return "one of";
    case ChangeVerdict::kCannotTell: return "cannot tell";
    case ChangeVerdict::kDiffers: return "differs";
  }
  return "?";
}

std::string Hypothesis::Text() const {
  if (cause == ChangeCause::kComponentSign) return "sign of " + component + " reversed (the others took effect)";
  return ChangeCauseText(cause);
}

ChangeVerification VerifyChange(const Machine& m, const NamedEstimate& previous_in, const NamedEstimate& change_in,
                                const NamedEstimate& now_in, const VerifyOptions& options) {
  if (!(options.k > 0) || !std::isfinite(options.k))
    throw std::invalid_argument("k: expected a finite number of sigmas > 0");
  const NamedEstimate previous = ToCheckNames(m, previous_in, "previous");
  const NamedEstimate change = ToCheckNames(m, change_in, "expect");
  const NamedEstimate now = ToCheckNames(m, now_in, "check");
  const auto index = [](const NamedEstimate& e, const std::string& n) -> Eigen::Index {
    const auto it = std::find(e.names.begin(), e.names.end(), n);
    return it == e.names.end() ? -1 : static_cast<Eigen::Index>(it - e.names.begin());
  };

  ChangeVerification out;
  out.k = options.k;
  std::vector<Eigen::Index> ic, ip, in;
  std::vector<std::string> names, unmeasured, missing;
  for (size_t j = 0; j < change.names.size(); ++j) {
    const std::string& n = change.names[j];
    const Eigen::Index jj = static_cast<Eigen::Index>(j);
    if (change.values[jj] == 0) {  // nothing loaded there: nothing to verify, whatever its uncertainty
      out.not_compared.push_back(n);
      continue;
    }
    const Eigen::Index a = index(now, n), b = index(previous, n);
    if (a < 0) unmeasured.push_back(n);
    else if (b < 0) missing.push_back(n);
    ic.push_back(jj);
    in.push_back(a);
    ip.push_back(b);
    names.push_back(n);
  }
  std::vector<std::string> measured;  // the machine's errors among them (not the set-up: sphere.*, tip.*)
  for (const std::string& n : now.names)
    if (m.ParameterIndex(n) >= 0 && n.rfind("tip.", 0) != 0) measured.push_back(n);
  if (!unmeasured.empty())
    throw std::invalid_argument("expect: " + Join(unmeasured) + (unmeasured.size() > 1 ? " are" : " is") +
                                " not measured by this check (it measures: " + Join(measured) +
                                "); verify that change with a check that moves those axes, or leave it out");
  if (!missing.empty())
    throw std::invalid_argument("previous: has no " + Join(missing) + " (the change names " +
                                (missing.size() > 1 ? "them" : "it") + "; give the check the export was made from)");
  if (names.empty())
    throw std::invalid_argument("expect: every change is 0: nothing to verify");

  const Eigen::VectorXd c = Pick(change, ic), p = Pick(previous, ip), q = Pick(now, in);
  const Eigen::MatrixXd Sc = Pick2(change, ic), Sp = Pick2(previous, ip), Sq = Pick2(now, in);
  CheckCompared(names, c, Sc, "expect", options.change_covariance);
  CheckCompared(names, p, Sp, "previous");
  CheckCompared(names, q, Sq, "check");
  const Eigen::VectorXd d = p - q;
  const Eigen::MatrixXd Sd = Sp + Sq;
  const Eigen::Index n = d.size();
  const double P = std::erf(options.k / std::sqrt(2.0));

  // the loaded numbers are exact unless asked otherwise (verify.h)
  const Eigen::MatrixXd Su = options.change_covariance ? Sc : Eigen::MatrixXd::Zero(n, n);
  out.hypotheses = Hypotheses(names, true);
  for (Hypothesis& h : out.hypotheses) {
    const Eigen::MatrixXd F = h.factors.asDiagonal();
    h.chi2 = Quad(Sd + F * Su * F, d - h.factors.cwiseProduct(c), "check");
  }
  out.chi2_limit = ChiSquareQuantile(P, double(n));
  std::tie(out.ratio, out.ratio_std) = Ratio(d, Sd, c, Su);
  out.outcome = Decide(out.hypotheses, c, Sd + Su, out.chi2_limit, options.k, out.ratio, out.ratio_std);

  const double limit1 = ChiSquareQuantile(P, 1.0);
  for (Eigen::Index i = 0; i < n; ++i) {
    ParameterChange r;
    r.name = names[size_t(i)];
    r.previous = p[i];
    r.previous_std = std::sqrt(Sp(i, i));
    r.expected = c[i];
    r.expected_std = std::sqrt(Sc(i, i));
    r.now = q[i];
    r.now_std = std::sqrt(Sq(i, i));
    r.predicted = p[i] - c[i];
    r.predicted_std = std::sqrt(Sp(i, i) + Su(i, i) + Sq(i, i));
    r.observed = d[i];
    r.observed_std = std::sqrt(Sd(i, i));
    r.z = (q[i] - r.predicted) / r.predicted_std;
    r.as_predicted = std::abs(r.z) <= options.k;
    const Eigen::VectorXd d1 = d.segment(i, 1), c1 = c.segment(i, 1);
    const Eigen::MatrixXd Sd1 = Sd.block(i, i, 1, 1), Sc1 = Su.block(i, i, 1, 1);
    std::tie(r.ratio, r.ratio_std) = Ratio(d1, Sd1, c1, Sc1);
    std::vector<Hypothesis> hs = Hypotheses({r.name}, false);
    for (Hypothesis& h : hs) {
      const double f = h.factors[0];
      h.chi2 = Quad(Sd1 + f * f * Sc1, d1 - f * c1, "check." + r.name);
    }
    r.outcome = Decide(hs, c1, Sd1 + Sc1, limit1, options.k, r.ratio, r.ratio_std);
    out.parameters.push_back(r);
  }
  return out;
}

}  // namespace controllers
}  // namespace fivecal
