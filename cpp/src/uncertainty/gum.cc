#include "fivecal/uncertainty/gum.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/problem.h"
#include "fivecal/solve/refit.h"
#include "json_util.h"

namespace fivecal {
namespace {

using json_util::json;

constexpr double kInf = std::numeric_limits<double>::infinity();

// Continued fraction of the regularized incomplete beta (modified Lentz).
double BetaContinuedFraction(double a, double b, double x) {
  const double tiny = 1e-300, eps = 1e-16;
  double c = 1.0, d = 1.0 - (a + b) * x / (a + 1.0);
  if (std::abs(d) < tiny) d = tiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 10000; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((a + m2 - 1.0) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0));
    d = 1.0 + aa * d;
    if (std::abs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < eps) break;
  }
  return h;
}

// I_x(a, b).
double IncompleteBeta(double a, double b, double x) {
  if (x <= 0) return 0.0;
  if (x >= 1) return 1.0;
  const double lbt = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
                     b * std::log1p(-x);
  if (x < (a + 1.0) / (a + b + 2.0)) return std::exp(lbt) * BetaContinuedFraction(a, b, x) / a;
  return 1.0 - std::exp(lbt) * BetaContinuedFraction(b, a, 1.0 - x) / b;
}

// Both tails of the regularised incomplete gamma function, P(a, x) and
// Q(a, x) = 1 - P: the series below a + 1, Lentz's continued fraction above.
// Each method yields one tail directly, so a small tail (a chi-square p-value
// of 1e-30) keeps its digits instead of vanishing in 1 - P.
struct GammaTails {
  double p, q;
};

GammaTails IncompleteGamma(double a, double x) {
  if (!(x > 0)) return {0.0, 1.0};
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (std::abs(del) < std::abs(sum) * 1e-17) break;
    }
    const double p = std::min(1.0, sum * std::exp(-x + a * std::log(x) - gln));
    return {p, 1.0 - p};
  }
  const double tiny = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < 1e-16) break;
  }
  const double q = std::min(1.0, std::exp(-x + a * std::log(x) - gln) * h);
  return {1.0 - q, q};
}

double IncompleteGammaP(double a, double x) { return IncompleteGamma(a, x).p; }

// Inverts a continuous increasing CDF on [lo, inf) by bracketing and bisection.
template <typename Cdf>
double Invert(Cdf cdf, double p, double lo, double guess) {
  double hi = std::max(guess, lo + 1.0);
  while (cdf(hi) < p) {
    lo = hi;
    hi *= 2.0;
    if (hi > 1e300) return kInf;
  }
  for (int it = 0; it < 400 && hi - lo > 1e-15 * std::max(1.0, std::abs(hi)); ++it) {
    const double mid = 0.5 * (lo + hi);
    (cdf(mid) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

void RequireProbability(double p, const char* what) {
  if (!(p > 0 && p < 1)) throw std::invalid_argument(std::string(what) + ": probability must be in (0, 1)");
}

json MatrixJson(const Eigen::MatrixXd& m) {
  json a = json::array();
  for (int i = 0; i < m.rows(); ++i) {
    json row = json::array();
    for (int j = 0; j < m.cols(); ++j) row.push_back(m(i, j));
    a.push_back(row);
  }
  return a;
}

json VectorJson(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

json NumberOrNull(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

Eigen::MatrixXd Correlation(const Eigen::MatrixXd& cov) {
  const int p = static_cast<int>(cov.rows());
  Eigen::MatrixXd r(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) {
      const double d = std::sqrt(std::max(0.0, cov(i, i)) * std::max(0.0, cov(j, j)));
      r(i, j) = d > 0 ? cov(i, j) / d : (i == j ? 1.0 : 0.0);
    }
  return r;
}

}  // namespace

// ---- Distributions ------------------------------------------------------------

double NormalQuantile(double p) {
  RequireProbability(p, "normal quantile");
  // Acklam's rational approximation, then one Halley step on erfc.
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                             1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01, -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  double x;
  if (p < 0.02425) {
    const double q = std::sqrt(-2 * std::log(p));
    x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else if (p > 1 - 0.02425) {
    const double q = std::sqrt(-2 * std::log1p(-p));
    x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else {
    const double q = p - 0.5, r = q * q;
    x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
  }
  for (int it = 0; it < 2; ++it) {
    const double e = 0.5 * std::erfc(-x / std::sqrt(2.0)) - p;
    const double u = e * std::sqrt(2 * M_PI) * std::exp(x * x / 2);
    x = x - u / (1 + x * u / 2);
  }
  return x;
}

double StudentTCdf(double t, double dof) {
  if (!(dof > 0)) throw std::invalid_argument("Student t: degrees of freedom must be > 0");
  if (std::isinf(dof)) return 0.5 * std::erfc(-t / std::sqrt(2.0));
  const double tail = 0.5 * IncompleteBeta(dof / 2, 0.5, dof / (dof + t * t));
  return t >= 0 ? 1.0 - tail : tail;
}

double StudentTQuantile(double p, double dof) {
  RequireProbability(p, "Student t quantile");
  if (!(dof > 0)) throw std::invalid_argument("Student t: degrees of freedom must be > 0");
  if (std::isinf(dof) || dof > 1e7) return NormalQuantile(p);
  if (p < 0.5) return -StudentTQuantile(1 - p, dof);
  if (p == 0.5) return 0.0;
  return Invert([&](double t) { return StudentTCdf(t, dof); }, p, 0.0, NormalQuantile(p));
}

double ChiSquareCdf(double x, double dof) {
  if (!(dof > 0)) throw std::invalid_argument("chi-square: degrees of freedom must be > 0");
  return IncompleteGammaP(dof / 2, x / 2);
}

double ChiSquareSurvival(double x, double dof) {
  if (!(dof > 0)) throw std::invalid_argument("chi-square: degrees of freedom must be > 0");
  return IncompleteGamma(dof / 2, x / 2).q;
}

double ChiSquareQuantile(double p, double dof) {
  RequireProbability(p, "chi-square quantile");
  return Invert([&](double x) { return ChiSquareCdf(x, dof); }, p, 0.0, dof);
}

double FCdf(double x, double d1, double d2) {
  if (!(d1 > 0 && d2 > 0)) throw std::invalid_argument("F: degrees of freedom must be > 0");
  if (x <= 0) return 0.0;
  if (std::isinf(d2)) return ChiSquareCdf(d1 * x, d1);
  return IncompleteBeta(d1 / 2, d2 / 2, d1 * x / (d1 * x + d2));
}

double FQuantile(double p, double d1, double d2) {
  RequireProbability(p, "F quantile");
  if (std::isinf(d2)) return ChiSquareQuantile(p, d1) / d1;
  return Invert([&](double x) { return FCdf(x, d1, d2); }, p, 0.0, 1.0);
}

CoverageFactor MakeCoverageFactor(double probability, double dof, int outputs, double explicit_k) {
  RequireProbability(probability, "coverage");
  if (!(dof > 0)) throw std::invalid_argument("coverage: degrees of freedom must be > 0");
  CoverageFactor cf;
  cf.probability = probability;
  cf.dof = dof;
  cf.outputs = outputs;
  char buf[256];
  if (explicit_k > 0) {
    cf.k = explicit_k;
    std::snprintf(buf, sizeof buf, "k = %.4g as given", explicit_k);
  } else if (std::isinf(dof)) {
    cf.k = NormalQuantile(0.5 * (1 + probability));
    std::snprintf(buf, sizeof buf, "k = %.4f: normal quantile for p = %.4g (known input covariance)",
                  cf.k, probability);
  } else {
    cf.k = StudentTQuantile(0.5 * (1 + probability), dof);
    std::snprintf(buf, sizeof buf,
                  "k = %.4f: Student t quantile for p = %.4g with %.6g degrees of freedom (pooled covariance)",
                  cf.k, probability, dof);
  }
  cf.method = buf;
  if (outputs > 0) {
    if (std::isinf(dof)) {
      cf.k_joint = std::sqrt(ChiSquareQuantile(probability, outputs));
    } else if (dof - outputs + 1 >= 1) {
      const double d2 = dof - outputs + 1;
      cf.k_joint = std::sqrt(outputs * dof / d2 * FQuantile(probability, outputs, d2));
    } else {
      cf.k_joint = std::numeric_limits<double>::quiet_NaN();
    }
  }
  return cf;
}

// ---- Pooled covariance ------------------------------------------------------------

PooledCovariance PoolCovariance(const Eigen::MatrixXd& X, const std::vector<int>& group) {
  const int K = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  if (static_cast<int>(group.size()) != K)
    throw std::invalid_argument("pooled covariance: " + std::to_string(group.size()) + " group labels for " +
                                std::to_string(K) + " samples");
  if (!X.allFinite()) throw std::invalid_argument("pooled covariance: samples are not finite");
  PooledCovariance out;
  std::map<int, int> index;
  std::vector<int> g_of(K);
  for (int c = 0; c < K; ++c) {
    auto it = index.find(group[c]);
    if (it == index.end()) {
      it = index.emplace(group[c], static_cast<int>(out.group_labels.size())).first;
      out.group_labels.push_back(group[c]);
      out.group_sizes.push_back(0);
    }
    g_of[c] = it->second;
    ++out.group_sizes[it->second];
  }
  const int G = static_cast<int>(out.group_labels.size());
  out.dof = K - G;
  if (out.dof < 1)
    throw std::invalid_argument("pooled covariance: " + std::to_string(K) + " samples in " + std::to_string(G) +
                                " groups leave no degrees of freedom (need a group with two or more)");
  out.group_means = Eigen::MatrixXd::Zero(G, n);
  for (int c = 0; c < K; ++c) out.group_means.row(g_of[c]) += X.row(c);
  for (int g = 0; g < G; ++g) out.group_means.row(g) /= out.group_sizes[g];
  out.mean = X.colwise().mean().transpose();
  Eigen::MatrixXd D(K, n);
  for (int c = 0; c < K; ++c) D.row(c) = X.row(c) - out.group_means.row(g_of[c]);
  out.covariance = D.transpose() * D / static_cast<double>(out.dof);
  return out;
}

// ---- Propagation -----------------------------------------------------------------

GumResult PropagateCovariance(const Eigen::MatrixXd& C, const Eigen::MatrixXd& Ux,
                              const std::vector<std::string>& names, const Eigen::VectorXd& values,
                              const CoverageFactor& coverage, const Eigen::MatrixXd& prior_term) {
  if (Ux.rows() != Ux.cols() || Ux.rows() != C.cols())
    throw std::invalid_argument("GUM: input covariance is " + std::to_string(Ux.rows()) + " x " +
                                std::to_string(Ux.cols()) + ", the sensitivity matrix has " +
                                std::to_string(C.cols()) + " inputs");
  if (static_cast<int>(names.size()) != C.rows() || values.size() != C.rows())
    throw std::invalid_argument("GUM: names/values do not match the sensitivity matrix rows");
  if (!Ux.allFinite() || !C.allFinite()) throw std::invalid_argument("GUM: non-finite input covariance or sensitivity");
  GumResult g;
  g.names = names;
  g.values = values;
  g.covariance = C * Ux.selfadjointView<Eigen::Upper>() * C.transpose();
  if (prior_term.size()) {
    if (prior_term.rows() != C.rows() || prior_term.cols() != C.rows() || !prior_term.allFinite())
      throw std::invalid_argument("GUM: the prior term must be a finite " + std::to_string(C.rows()) + " x " +
                                  std::to_string(C.rows()) + " matrix");
    g.covariance += prior_term;
  }
  g.covariance = 0.5 * (g.covariance + g.covariance.transpose()).eval();
  g.std = g.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  g.correlation = Correlation(g.covariance);
  g.coverage = coverage;
  g.expanded = coverage.k * g.std;
  return g;
}

std::string GumResult::ToJson() const {
  json j;
  json params = json::object();
  for (size_t i = 0; i < names.size(); ++i)
    params[names[i]] = {{"value", values[i]}, {"std", std[i]}, {"expanded", expanded[i]}};
  j["parameters"] = params;
  j["names"] = names;
  j["covariance"] = MatrixJson(covariance);
  j["coverage"] = {{"probability", coverage.probability}, {"k", coverage.k},
                   {"dof", NumberOrNull(coverage.dof)}, {"k_joint", NumberOrNull(coverage.k_joint)},
                   {"outputs", coverage.outputs}, {"method", coverage.method}};
  return j.dump(1);
}

Sensitivity SensitivityMatrix(const Dataset& given_ds, const Result& fit) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  ds.Validate();
  const ParameterTable table(ds);
  if (fit.names != table.names())
    throw std::invalid_argument("sensitivity: the result belongs to another dataset");
  std::vector<int> est;
  for (const std::string& n : fit.estimated) est.push_back(table.Require(n));
  Problem problem(ds, table, fit.values, est);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  problem.Evaluate(&r, &J);
  // The fit minimises sum (r_i / sigma_i)^2 (+ the prior rows of a MAP fit):
  // C = -(J^T W J + P)^+ J^T W, W = diag(1 / sigma^2).
  const Eigen::VectorXd w = problem.row_sigma().cwiseInverse();
  const bool map = fit.map_fit && fit.prior_std.size() == est.size();
  Eigen::MatrixXd inverse_normal;
  Eigen::VectorXd prior_precision;
  if (map) {
    // The documented priors, as the fit's reported covariance uses them.
    prior_precision.resize(est.size());
    for (size_t i = 0; i < est.size(); ++i) prior_precision[i] = 1.0 / (fit.prior_std[i] * fit.prior_std[i]);
    const Eigen::MatrixXd Jw = w.asDiagonal() * J;
    Eigen::MatrixXd N = Jw.transpose() * Jw;
    N.diagonal() += prior_precision;
    inverse_normal = N.ldlt().solve(Eigen::MatrixXd::Identity(N.rows(), N.cols()));
  } else {
    inverse_normal = AnalyzeJacobian(w.asDiagonal() * J).inverse_normal;
  }
  Sensitivity s;
  s.names = fit.estimated;
  s.values.resize(est.size());
  for (size_t i = 0; i < est.size(); ++i) s.values[i] = fit.values[est[i]];
  // Every residual row is an input: an observation's noise, or a scale bar's
  // calibrated length (source -1 - b, after the observations), an input with
  // an uncertainty as much as a reading is (JCGM 101 propagates all inputs).
  const std::vector<int>& src = problem.row_source();
  for (int row = 0; row < static_cast<int>(src.size()); ++row) {
    s.input_rows.push_back(row);
    s.input_source.push_back(src[row]);
  }
  Eigen::MatrixXd Jin(s.input_rows.size(), J.cols());
  for (size_t k = 0; k < s.input_rows.size(); ++k)
    Jin.row(k) = J.row(s.input_rows[k]) * (w[s.input_rows[k]] * w[s.input_rows[k]]);
  s.C = -inverse_normal * Jin.transpose();
  if (map) s.prior_term = inverse_normal * prior_precision.asDiagonal() * inverse_normal;
  return s;
}

// ---- Repeated cycles -----------------------------------------------------------------

CyclesUncertainty GumFromCycles(const std::vector<Dataset>& cycles, const std::vector<int>& day,
                                const std::vector<int>& cycle, const IdentifyOptions& identify,
                                const CyclesOptions& options) {
  const int K = static_cast<int>(cycles.size());
  if (K < 2) throw std::invalid_argument("GUM from cycles: need at least two measurement cycles");
  if (static_cast<int>(day.size()) != K || static_cast<int>(cycle.size()) != K)
    throw std::invalid_argument("GUM from cycles: one day label and one cycle label per dataset");
  if (options.reference < 0 || options.reference >= K)
    throw std::invalid_argument("GUM from cycles: reference cycle out of range");
  std::vector<int> group(K);
  if (options.pooling == "cycles") group = cycle;
  else if (options.pooling == "days") group = day;
  else if (options.pooling == "none") group.assign(K, 0);
  else throw std::invalid_argument("GUM from cycles: pooling must be 'cycles', 'days' or 'none'");

  const Dataset& ref = cycles[options.reference];
  const Result fit = Identify(ref, identify);
  const Sensitivity sens = SensitivityMatrix(ref, fit);
  const ParameterTable table(ref);
  std::map<std::string, double> at;
  for (int i = 0; i < table.size(); ++i) at[table.names()[i]] = fit.values[i];

  // Only the observations' residuals are pooled: a scale bar is the same
  // physical bar in every cycle, so its calibration error is common to all
  // cycles and their scatter says nothing about it. Its columns are left out
  // (the result is the repeatability over the cycles, as the pooled scatter
  // of the cycles' own fits, output_pooled, is).
  std::vector<int> obs_inputs;
  for (int k = 0; k < static_cast<int>(sens.input_source.size()); ++k)
    if (sens.input_source[k] >= 0) obs_inputs.push_back(k);
  const int n = static_cast<int>(obs_inputs.size());
  Eigen::MatrixXd C_obs(sens.C.rows(), n);
  for (int k = 0; k < n; ++k) C_obs.col(k) = sens.C.col(obs_inputs[k]);
  Eigen::MatrixXd X(K, n);
  const Refit refit(ref, identify, fit);
  CyclesUncertainty out;
  out.estimated = fit.estimated;
  out.cycle_values.resize(K, fit.estimated.size());
  for (int c = 0; c < K; ++c) {
    std::vector<int> src;
    Eigen::VectorXd r;
    try {
      r = PredictResiduals(cycles[c], at, &src);
      const RefitResult rf = refit.Fit(cycles[c]);
      out.cycle_values.row(c) = rf.values.transpose();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("cycle " + std::to_string(c) + ": " + e.what());
    }
    int k = 0;
    for (int row = 0; row < r.size(); ++row) {
      if (src[row] < 0) continue;
      if (k >= n || src[row] != sens.input_source[obs_inputs[k]])
        throw std::invalid_argument("cycle " + std::to_string(c) +
                                    ": its observations differ from the reference cycle's");
      X(c, k++) = r[row];
    }
    if (k != n)
      throw std::invalid_argument("cycle " + std::to_string(c) + ": its observations differ from the reference cycle's");
  }
  out.inputs = PoolCovariance(X, group);
  out.output_pooled = PoolCovariance(out.cycle_values, group).covariance;
  const CoverageFactor cf = MakeCoverageFactor(options.probability, out.inputs.dof,
                                               static_cast<int>(fit.estimated.size()), options.coverage_factor);
  out.gum = PropagateCovariance(C_obs, out.inputs.covariance, sens.names, sens.values, cf, sens.prior_term);
  out.day = day;
  out.cycle = cycle;
  out.pooling = options.pooling;
  return out;
}

std::string CyclesUncertainty::ToJson() const {
  json j = json::parse(gum.ToJson());
  j["pooling"] = pooling;
  j["input_dof"] = inputs.dof;
  j["groups"] = inputs.group_labels;
  j["day"] = day;
  j["cycle"] = cycle;
  j["cycle_values"] = MatrixJson(cycle_values);
  j["output_pooled_std"] = VectorJson(output_pooled.diagonal().cwiseMax(0.0).cwiseSqrt());
  return j.dump(1);
}

}  // namespace fivecal
