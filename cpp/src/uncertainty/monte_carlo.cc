#include "fivecal/uncertainty/monte_carlo.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <random>
#include <stdexcept>
#include <thread>

#include "json_util.h"

namespace fivecal {
namespace {

using json_util::json;

uint64_t SplitMix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

json Vec(const Eigen::VectorXd& v) {
  json a = json::array();
  for (int i = 0; i < v.size(); ++i) a.push_back(std::isfinite(v[i]) ? json(v[i]) : json(nullptr));
  return a;
}

json Mat(const Eigen::MatrixXd& m) {
  json a = json::array();
  for (int i = 0; i < m.rows(); ++i) a.push_back(Vec(m.row(i).transpose()));
  return a;
}

struct Summary {
  double mean = 0, std = 0, low = 0, high = 0;
};

Summary Summarize(const std::vector<double>& v, double p) {
  Summary s;
  const double n = static_cast<double>(v.size());
  for (double x : v) s.mean += x;
  s.mean /= n;
  double ss = 0;
  for (double x : v) ss += (x - s.mean) * (x - s.mean);
  s.std = v.size() > 1 ? std::sqrt(ss / (n - 1)) : 0.0;
  CoverageInterval(v, p, &s.low, &s.high);
  return s;
}

}  // namespace

uint64_t TrialSeed(uint64_t seed, uint64_t trial) {
  return SplitMix64(SplitMix64(seed) + SplitMix64(trial + 0x632be59bd9b4e019ULL));
}

void CoverageInterval(std::vector<double> v, double p, double* low, double* high, double* sym_low,
                      double* sym_high) {
  if (!(p > 0 && p < 1)) throw std::invalid_argument("coverage interval: probability must be in (0, 1)");
  const int M = static_cast<int>(v.size());
  if (M < 2) throw std::invalid_argument("coverage interval: need at least two values");
  std::sort(v.begin(), v.end());
  // JCGM 101 §7.7.1: q = pM if integer, else the integer part of pM + 1/2.
  const double pm = p * M;
  int q = std::abs(pm - std::round(pm)) < 1e-9 ? static_cast<int>(std::round(pm))
                                                 : static_cast<int>(std::floor(pm + 0.5));
  q = std::min(std::max(q, 1), M - 1);
  // Shortest: [y_(r), y_(r+q)], r = 1..M-q (0-based: r = 0..M-q-1).
  int best = 0;
  for (int r = 1; r < M - q; ++r)
    if (v[r + q] - v[r] < v[best + q] - v[best]) best = r;
  *low = v[best];
  *high = v[best + q];
  if (sym_low && sym_high) {
    // Probabilistically symmetric: r = (M - q)/2 (1-based) if integer, else
    // the integer part of (M - q + 1)/2.
    int r = (M - q) % 2 == 0 ? (M - q) / 2 : (M - q + 1) / 2;
    r = std::max(r, 1);
    *sym_low = v[r - 1];
    *sym_high = v[std::min(r - 1 + q, M - 1)];
  }
}

double NumericalTolerance(double u, int significant_digits) {
  // Beyond 17 digits a double has nothing left to compare (and a huge count
  // would overflow the exponent below).
  if (significant_digits < 1 || significant_digits > 17)
    throw std::invalid_argument("significant_digits must be in [1, 17], got " + std::to_string(significant_digits));
  if (!(u > 0) || !std::isfinite(u)) return 0.0;
  const int nd = significant_digits;
  int l = static_cast<int>(std::floor(std::log10(u))) - nd + 1;
  // Guard the rounding of log10 at exact powers of ten: c must have nd digits.
  const double c = std::round(u / std::pow(10.0, l));
  if (c >= std::pow(10.0, nd)) ++l;
  return 0.5 * std::pow(10.0, l);
}

MonteCarloResult MonteCarlo(const SimulationPlan& plan, const IdentifyOptions& identify,
                            const MonteCarloOptions& opt, const ProgressCallback& progress) {
  // The trials x p sample matrix is allocated up front: bound it before.
  constexpr int kMaxTrials = 10000000;
  constexpr int kMaxThreads = 1024;
  if (opt.trials < 2 || opt.trials > kMaxTrials)
    throw std::invalid_argument("monte carlo: trials must be in [2, " + std::to_string(kMaxTrials) + "], got " +
                                std::to_string(opt.trials));
  if (opt.significant_digits < 1 || opt.significant_digits > 17)
    throw std::invalid_argument("monte carlo: significant_digits must be in [1, 17], got " +
                                std::to_string(opt.significant_digits));
  // The GUM interval needs the normal quantile of (1 + p) / 2, which rounds
  // to 1 (an infinite quantile) within an ulp of p = 1: refuse that before
  // the trials run rather than after.
  if (!(opt.probability > 0 && 0.5 * (1 + opt.probability) < 1))
    throw std::invalid_argument("monte carlo: probability must be in (0, 1)");
  if (opt.threads < 0 || opt.threads > kMaxThreads)
    throw std::invalid_argument("monte carlo: threads must be in [0, " + std::to_string(kMaxThreads) +
                                "] (0 = all cores), got " + std::to_string(opt.threads));
  if (opt.blocks < 2) throw std::invalid_argument("monte carlo: blocks must be >= 2");
  const auto t0 = std::chrono::steady_clock::now();

  // Reference fit, re-fit machinery and the linearised (GUM) model.
  const Result ref = Identify(plan.base, identify);
  const Refit refit(plan.base, identify, ref);
  const Sensitivity sens = SensitivityMatrix(plan.base, ref);
  const int n_in = plan.num_inputs();
  if (static_cast<int>(sens.input_rows.size()) != n_in)
    throw std::invalid_argument("monte carlo: the plan has " + std::to_string(n_in) + " inputs, the residuals " +
                                std::to_string(sens.input_rows.size()));
  for (int k = 0; k < n_in; ++k)
    if (sens.input_source[k] != plan.input_observation[k])
      throw std::invalid_argument("monte carlo: input " + std::to_string(k) + " does not match its residual row");
  const bool correlated = opt.input_covariance.size() > 0;
  Eigen::MatrixXd Ux;
  Eigen::MatrixXd L;  // Ux = L L^T
  if (correlated) {
    Ux = opt.input_covariance;
    if (Ux.rows() != n_in || Ux.cols() != n_in)
      throw std::invalid_argument("monte carlo: input_covariance must be " + std::to_string(n_in) + " x " +
                                  std::to_string(n_in) + " (one row per input)");
    if (!Ux.allFinite()) throw std::invalid_argument("monte carlo: input_covariance is not finite");
    if ((Ux - Ux.transpose()).cwiseAbs().maxCoeff() > 1e-12 * std::max(1e-300, Ux.cwiseAbs().maxCoeff()))
      throw std::invalid_argument("monte carlo: input_covariance is not symmetric");
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ux);
    const Eigen::VectorXd lam = es.eigenvalues();
    if (lam.minCoeff() < -1e-9 * std::max(1e-300, lam.cwiseAbs().maxCoeff()))
      throw std::invalid_argument("monte carlo: input_covariance is not positive semi-definite");
    L = es.eigenvectors() * lam.cwiseMax(0.0).cwiseSqrt().asDiagonal();
  } else {
    Ux = (plan.sensitivity.cwiseProduct(plan.input_sigma)).array().square().matrix().asDiagonal();
  }
  const int p = static_cast<int>(ref.estimated.size());
  const CoverageFactor cf = MakeCoverageFactor(opt.probability, std::numeric_limits<double>::infinity(), p);
  const GumResult gum = PropagateCovariance(sens.C, Ux, sens.names, sens.values, cf);

  MonteCarloResult res;
  res.estimated = ref.estimated;
  res.reference = sens.values;
  res.truth = Eigen::VectorXd::Zero(p);
  for (int i = 0; i < p; ++i) {
    auto it = plan.values.find(ref.estimated[i]);
    if (it != plan.values.end()) res.truth[i] = it->second;
  }
  res.trials = opt.trials;
  res.seed = opt.seed;
  res.probability = opt.probability;
  res.significant_digits = opt.significant_digits;

  // ---- Trials -------------------------------------------------------------
  const int M = opt.trials;
  Eigen::MatrixXd samples = Eigen::MatrixXd::Constant(M, p, std::numeric_limits<double>::quiet_NaN());
  Eigen::MatrixXd tstd;
  if (opt.trial_std) tstd = Eigen::MatrixXd::Constant(M, p, std::numeric_limits<double>::quiet_NaN());
  std::vector<int> usable(M, -1);
  int T = opt.threads > 0 ? opt.threads : static_cast<int>(std::thread::hardware_concurrency());
  T = std::max(1, std::min(T, M));
  res.threads = T;

  std::atomic<int> next{0}, done{0};
  std::atomic<bool> cancel{false};
  std::mutex mu;
  std::condition_variable cv;
  // Each worker edits its own copy of the dataset in place and re-fits the
  // problem it prepared once, from the reference solution.
  auto run_trial = [&](Refit::Session& session, int t) {
    const uint64_t s = TrialSeed(opt.seed, static_cast<uint64_t>(t));
    if (!correlated) {
      AddNoiseInto(plan, s, &session.dataset());
    } else {
      std::mt19937_64 rng(s);
      std::normal_distribution<double> normal(0.0, 1.0);
      Eigen::VectorXd z(n_in);
      for (int k = 0; k < n_in; ++k) z[k] = normal(rng);
      ApplyInputDeviationsInto(plan, L * z, &session.dataset());
    }
    const RefitResult rf = session.Fit(opt.trial_std);
    if (!rf.values.allFinite()) return;
    samples.row(t) = rf.values.transpose();
    if (opt.trial_std) tstd.row(t) = rf.std.transpose();
    usable[t] = rf.converged ? 1 : 0;
  };
  // Touches move along their approach lines and scale bars change length:
  // the sessions then need re-read only the axis values.
  bool axes_only = true;
  for (int k = 0; k < n_in; ++k) {
    const int o = plan.input_observation[k];
    if (o >= 0 && (o >= static_cast<int>(plan.approach.size()) || plan.approach[o].size() == 0)) axes_only = false;
  }
  // A worker takes up to 16 consecutive trials at a time: the rows of
  // `samples` (column-major) and `usable` of neighbouring trials share cache
  // lines, which two threads taking every other trial would pass back and
  // forth on every write. Fewer when the trials are few, so that the last
  // batches still spread over the threads. Which thread runs a trial
  // changes nothing in it (its seed is its own).
  const int kTake = std::max(1, std::min(16, M / (8 * T)));
  auto worker = [&] {
    std::unique_ptr<Refit::Session> session;
    for (;;) {
      if (cancel.load()) return;
      const int t0 = next.fetch_add(kTake);
      if (t0 >= M) return;
      const int t1 = std::min(M, t0 + kTake);
      for (int t = t0; t < t1 && !cancel.load(); ++t) {
        try {
          if (!session) {
            session = std::make_unique<Refit::Session>(refit);
            session->set_axes_only(axes_only);
          }
          run_trial(*session, t);
        } catch (const std::exception&) {
          usable[t] = -1;
        }
        if (done.fetch_add(1) + 1 == M) {
          std::lock_guard<std::mutex> lock(mu);
          cv.notify_all();
        }
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(T);
  for (int i = 0; i < T; ++i) pool.emplace_back(worker);
  int reported = -1;
  {
    std::unique_lock<std::mutex> lock(mu);
    while (done.load() < M && !cancel.load()) {
      cv.wait_for(lock, std::chrono::milliseconds(100));
      if (progress) {
        lock.unlock();
        bool go = true;
        try {
          reported = done.load();
          go = progress(reported, M);
        } catch (...) {
          go = false;
        }
        if (!go) cancel.store(true);
        lock.lock();
      }
    }
  }
  for (auto& th : pool) th.join();
  if (cancel.load()) throw std::runtime_error("monte carlo: cancelled");
  if (progress && reported != M) progress(M, M);

  // ---- Statistics, reduced in trial order ------------------------------------
  std::vector<int> used;
  for (int t = 0; t < M; ++t) {
    if (usable[t] == 1) used.push_back(t);
    else if (usable[t] == 0) ++res.not_converged;
    else ++res.failed;
  }
  res.used = static_cast<int>(used.size());
  if (res.used < 2)
    throw std::invalid_argument("monte carlo: fewer than two trials converged (" + std::to_string(res.not_converged) +
                                " did not converge, " + std::to_string(res.failed) + " failed)");
  const int Mu = res.used;
  Eigen::MatrixXd Y(Mu, p);
  for (int i = 0; i < Mu; ++i) Y.row(i) = samples.row(used[i]);
  res.mean = Eigen::VectorXd::Zero(p);
  for (int i = 0; i < Mu; ++i) res.mean += Y.row(i).transpose();
  res.mean /= Mu;
  Eigen::MatrixXd D = Y.rowwise() - res.mean.transpose();
  res.covariance = D.transpose() * D / static_cast<double>(Mu - 1);
  res.std = res.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  res.correlation.resize(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) {
      const double d = res.std[i] * res.std[j];
      res.correlation(i, j) = d > 0 ? res.covariance(i, j) / d : (i == j ? 1.0 : 0.0);
    }
  res.low.resize(p);
  res.high.resize(p);
  res.symmetric_low.resize(p);
  res.symmetric_high.resize(p);
  for (int j = 0; j < p; ++j) {
    std::vector<double> col(Y.col(j).data(), Y.col(j).data() + Mu);
    CoverageInterval(col, opt.probability, &res.low[j], &res.high[j], &res.symmetric_low[j],
                     &res.symmetric_high[j]);
  }

  // ---- GUM comparison (JCGM 101 §8) ----------------------------------------------
  res.gum_covariance = gum.covariance;
  res.gum_std = gum.std;
  res.gum_k = NormalQuantile(0.5 * (1 + opt.probability));
  res.gum_low = res.reference - res.gum_k * res.gum_std;
  res.gum_high = res.reference + res.gum_k * res.gum_std;
  res.tolerance.resize(p);
  res.d_low.resize(p);
  res.d_high.resize(p);
  res.std_ratio.resize(p);
  res.validated.assign(p, false);
  for (int j = 0; j < p; ++j) {
    res.tolerance[j] = NumericalTolerance(res.gum_std[j], opt.significant_digits);
    res.d_low[j] = std::abs(res.gum_low[j] - res.low[j]);
    res.d_high[j] = std::abs(res.gum_high[j] - res.high[j]);
    res.validated[j] = res.d_low[j] <= res.tolerance[j] && res.d_high[j] <= res.tolerance[j];
    res.std_ratio[j] = res.gum_std[j] > 0 ? res.std[j] / res.gum_std[j] : std::numeric_limits<double>::quiet_NaN();
  }

  // ---- Stability of the Monte Carlo results (§7.9.4 on h blocks) -----------------
  const int h = opt.blocks;
  const int per = Mu / h;
  res.stability = Eigen::VectorXd::Constant(p, std::numeric_limits<double>::quiet_NaN());
  res.stable.assign(p, false);
  if (per >= 2) {
    for (int j = 0; j < p; ++j) {
      std::vector<Summary> b;
      for (int r = 0; r < h; ++r) {
        std::vector<double> v(per);
        for (int i = 0; i < per; ++i) v[i] = Y(r * per + i, j);
        b.push_back(Summarize(v, opt.probability));
      }
      auto sd_of_mean = [&](double Summary::*f) {
        double m = 0;
        for (const Summary& s : b) m += s.*f;
        m /= h;
        double ss = 0;
        for (const Summary& s : b) ss += (s.*f - m) * (s.*f - m);
        return std::sqrt(ss / (h * (h - 1.0)));
      };
      const double s = std::max({sd_of_mean(&Summary::mean), sd_of_mean(&Summary::std),
                                 sd_of_mean(&Summary::low), sd_of_mean(&Summary::high)});
      res.stability[j] = 2 * s;
      res.stable[j] = 2 * s <= res.tolerance[j];
    }
  }
  if (opt.keep_samples) {
    res.samples = samples;
    res.usable = usable;
  }
  if (opt.trial_std) res.trial_std = tstd;
  res.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

std::string MonteCarloResult::ToJson(bool include_samples) const {
  json j;
  json params = json::object();
  const int p = static_cast<int>(estimated.size());
  for (int i = 0; i < p; ++i) {
    std::string verdict = validated[i] ? "validated" : "not validated";
    if (!validated[i] && !stable[i]) verdict += " (Monte Carlo not stable at this tolerance: more trials needed)";
    params[estimated[i]] = {
        {"reference", reference[i]}, {"truth", truth[i]},
        {"mean", mean[i]}, {"std", std[i]}, {"low", low[i]}, {"high", high[i]},
        {"symmetric_low", symmetric_low[i]}, {"symmetric_high", symmetric_high[i]},
        {"gum_std", gum_std[i]}, {"gum_low", gum_low[i]}, {"gum_high", gum_high[i]},
        {"std_ratio", std::isfinite(std_ratio[i]) ? json(std_ratio[i]) : json(nullptr)},
        {"tolerance", tolerance[i]}, {"d_low", d_low[i]}, {"d_high", d_high[i]},
        {"validated", static_cast<bool>(validated[i])}, {"stable", static_cast<bool>(stable[i])},
        {"stability", std::isfinite(stability[i]) ? json(stability[i]) : json(nullptr)},
        {"verdict", verdict}};
  }
  j["parameters"] = params;
  j["estimated"] = estimated;
  j["trials"] = trials;
  j["used"] = used;
  j["not_converged"] = not_converged;
  j["failed"] = failed;
  j["seed"] = seed;
  j["threads"] = threads;
  j["seconds"] = seconds;
  j["probability"] = probability;
  j["gum_k"] = gum_k;
  j["significant_digits"] = significant_digits;
  j["covariance"] = Mat(covariance);
  j["gum_covariance"] = Mat(gum_covariance);
  if (include_samples && samples.size()) j["samples"] = Mat(samples);
  return j.dump(1);
}

}  // namespace fivecal
