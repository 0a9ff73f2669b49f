// Monte Carlo propagation of the measurement noise through the nonlinear
// identification (JCGM 101:2008 propagation of distributions, JCGM 102 for
// the multivariate output; thesis ch. 5 and 8).
//
// A trial re-draws the noise of every input of a SimulationPlan (the trigger
// position along each approach line, DBB readings, ball3d components) and
// re-fits the model with the reference fit's parameter set, starting from its
// values (Refit). The trials run on all cores (std::thread); trial t draws its
// noise from its own generator seeded with TrialSeed(seed, t), and the
// statistics are reduced in trial order after all trials finished, so the
// result is bit-identical whatever the number of threads.
//
// Results (JCGM 101 §7.6-7.7, §8):
//   sample mean and covariance of the M' usable trials (converged fits);
//   shortest coverage interval for probability p per parameter: with the
//     sorted values y_(1..M') and q = round(p M'), the shortest of
//     [y_(r), y_(r+q)], r = 1..M'-q; and the probabilistically symmetric one;
//   the GUM (linearised) covariance U_y = C U_x C^T at the reference fit
//     (gum.h), the GUM interval y +- k u(y) with k the normal quantile, and the
//     validation of §8.2: the numerical tolerance delta = 1/2 10^l with
//     u(y) = c x 10^l, c an n_dig-digit integer; d_low = |y - U_p - y_low|,
//     d_high = |y + U_p - y_high|; the GUM is validated when both <= delta;
//   the stability of the Monte Carlo results themselves (§7.9.4 applied to
//     the trials split into h blocks): 2 s <= delta for the mean, the standard
//     uncertainty and both interval ends, s the standard deviation of the
//     block means over sqrt(h). When a parameter is not stable the verdict
//     says more trials are needed rather than that the GUM failed.
#ifndef FIVECAL_MONTE_CARLO_H_
#define FIVECAL_MONTE_CARLO_H_

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/uncertainty/gum.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/refit.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {

struct MonteCarloOptions {
  int trials = 10000;           // 2 .. 10^7 (the trials x p samples are allocated up front)
  int threads = 0;              // 0: all cores (std::thread::hardware_concurrency); at most 1024
  uint64_t seed = 1;            // master seed
  double probability = 0.95;    // coverage probability
  int significant_digits = 2;   // n_dig of the numerical tolerance (JCGM 101 §7.9.2), 1 .. 17
  int blocks = 10;              // h for the stability estimate
  // Optional input covariance (inputs x inputs, mm^2, along the residuals as
  // in gum.h; one row per plan input: the observations' noise, then the scale
  // bars' lengths). Empty: independent inputs with the plan's noise levels.
  Eigen::MatrixXd input_covariance;
  // Also record each trial's one-sigma uncertainties as Identify reports them
  // (residual sigma x sqrt(diag (J^T J)^-1)): coverage checks of a single fit.
  bool trial_std = false;
  bool keep_samples = true;     // keep the M x p trial values in the result
};

struct MonteCarloResult {
  std::vector<std::string> estimated;
  Eigen::VectorXd reference;       // fit of the plan's noise-free data: the GUM estimate y
  Eigen::VectorXd truth;           // the plan's parameter values (0 where unnamed)
  int trials = 0, used = 0, not_converged = 0, failed = 0;
  int threads = 0;
  uint64_t seed = 0;
  double seconds = 0;
  double probability = 0.95;
  Eigen::VectorXd mean, std;
  Eigen::MatrixXd covariance, correlation;
  Eigen::VectorXd low, high;                  // shortest coverage interval
  Eigen::VectorXd symmetric_low, symmetric_high;
  // GUM comparison (§8)
  Eigen::MatrixXd gum_covariance;
  Eigen::VectorXd gum_std, gum_low, gum_high; // y -+ k u(y)
  double gum_k = 0;
  Eigen::VectorXd tolerance, d_low, d_high;   // delta, |y - U_p - y_low|, |y + U_p - y_high|
  std::vector<bool> validated;                // d_low <= delta && d_high <= delta
  std::vector<bool> stable;                   // Monte Carlo results within delta (2 s <= delta)
  Eigen::VectorXd stability;                  // 2 max(s_y, s_u, s_low, s_high) per parameter
  Eigen::VectorXd std_ratio;                  // u_MC / u_GUM
  int significant_digits = 2;
  // Optional
  Eigen::MatrixXd samples;                    // trials x p (NaN rows for unusable trials)
  Eigen::MatrixXd trial_std;                  // trials x p (trial_std)
  std::vector<int> usable;                    // per trial: 1 used, 0 not converged, -1 failed
  std::string ToJson(bool include_samples = false) const;
};

// Seed of trial t: splitmix64 of the master seed and the trial index.
uint64_t TrialSeed(uint64_t seed, uint64_t trial);

// The shortest interval containing round(p M) + 1 of the sorted values, and
// the probabilistically symmetric one (JCGM 101 §7.7).
void CoverageInterval(std::vector<double> values, double p, double* low, double* high,
                      double* sym_low = nullptr, double* sym_high = nullptr);

// JCGM 101 §7.9.2: delta = 1/2 10^l with u = c 10^l, c an n_dig-digit integer.
// Throws std::invalid_argument unless 1 <= significant_digits <= 17.
double NumericalTolerance(double u, int significant_digits);

// Progress: called from the calling thread every ~0.1 s and at the end with
// (completed trials, total); return false to cancel (MonteCarlo then throws
// std::runtime_error("monte carlo: cancelled") after stopping the workers).
using ProgressCallback = std::function<bool(int, int)>;

// `identify` chooses the parameter set (as for Identify on plan.base).
MonteCarloResult MonteCarlo(const SimulationPlan& plan, const IdentifyOptions& identify,
                            const MonteCarloOptions& options, const ProgressCallback& progress = {});

}  // namespace fivecal

#endif  // FIVECAL_MONTE_CARLO_H_
