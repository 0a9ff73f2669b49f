// Statistics of repeated probing (thesis §4.6, eqs. 4-9 to 4-16; ch. 7,
// eq. 7-1): how much of the scatter of repeated touches is probe
// repeatability, how much the surface and how much machine drift.
//
// Grid data of one probing direction k: P(i, j), i = 1..n grid points of a
// small patch, j = 1..m cycles (the whole grid measured once per cycle, in
// time order), in mm along the approach.
//
//   total (4-9, 4-10):    s_T = sqrt( sum_ij (P_ij - P^)^2 / (n m - 1) ),
//                         P^ the grand mean; and the range of P_ij
//   repeatability (4-11, 4-12): for each point i, the cycles are cut into
//                         consecutive windows of r cycles (the last one may
//                         be shorter; a window of one cycle carries no
//                         information and is dropped), then
//                         s^2_pooled,i = sum_l (r_l - 1) s^2_il / sum_l (r_l - 1)
//                         Table 4-3 reports the maximum over i; the pool over
//                         all points is reported too. Windows remove the
//                         slow drift, the per-point pooling the surface.
//   surface (4-13..4-15): S = std over i of the point means P^_i (over the
//                         m cycles), and their range
//   drift (4-16):         std and range over j of the cycle means P^_j (over
//                         the n points)
//   per point (Table 7-5): std of each point over the cycles, and their pool
//
// Plus a variance-component decomposition under the additive model
//   P_ij = mu + s_i (surface) + d_j (drift) + e_ij (repeatability)
// from the two-way ANOVA without replication:
//   MS_e = sum (P_ij - P^_i - P^_j + P^)^2 / ((n-1)(m-1)),
//   MS_points = m sum_i (P^_i - P^)^2 / (n-1),  MS_cycles = n sum_j (P^_j - P^)^2 / (m-1),
//   sigma_e^2 = MS_e, sigma_s^2 = max(0, (MS_points - MS_e) / m),
//   sigma_d^2 = max(0, (MS_cycles - MS_e) / n).
// The thesis' S_k (surface) and the drift std still contain sigma_e^2/m and
// sigma_e^2/n; the components do not.
#ifndef FIVECAL_PROBING_STATS_H_
#define FIVECAL_PROBING_STATS_H_

#include <Eigen/Core>
#include <string>
#include <vector>

namespace fivecal {

struct PooledStd {
  double pooled_std = 0;           // sqrt of the pooled variance
  int dof = 0;                     // sum (n_l - 1)
  std::vector<double> group_std;   // per group (window)
  std::vector<int> group_size;
};

// Eq. 7-1: pooled over groups (each with >= 1 value; groups of one value
// contribute nothing). Throws if no group has two values.
PooledStd PooledStandardDeviation(const std::vector<std::vector<double>>& groups);

// Eq. 7-1 on a time series cut into consecutive windows of `window` values
// (the last window holds the remainder; thesis ch. 7: 12 windows of 25 of
// 300 touches).
PooledStd WindowPooledStd(const Eigen::VectorXd& series, int window);

struct GridStatistics {
  int points = 0, cycles = 0, window = 0;
  double mean = 0;                    // P^ (4-10)
  double total_std = 0;               // s_T (4-9)
  double total_range = 0;
  Eigen::VectorXd point_pooled_std;   // s_pooled,i (4-11, 4-12)
  double max_pooled_std = 0;          // Table 4-3: max over i
  double pooled_std = 0;              // pooled over every point's windows
  int pooled_dof = 0;
  Eigen::VectorXd point_means;        // P^_i (4-13)
  double surface_std = 0;             // S_k (4-14, 4-15)
  double surface_range = 0;
  Eigen::VectorXd cycle_means;        // P^_j (4-16)
  double drift_std = 0;
  double drift_range = 0;
  Eigen::VectorXd point_std;          // Table 7-5: std of each point over the cycles
  double point_std_pooled = 0;        // Table 7-5 "Pooled standard"
  // Variance components (two-way ANOVA).
  double repeatability = 0;           // sigma_e
  double surface_component = 0;       // sigma_s
  double drift_component = 0;         // sigma_d
  std::string ToJson() const;
};

// P: n points x m cycles (mm). window: cycles per window for the pooled
// repeatability (thesis: 5). Needs n >= 2, m >= 2, window >= 2.
GridStatistics AnalyzeGrid(const Eigen::MatrixXd& P, int window = 5);

}  // namespace fivecal

#endif  // FIVECAL_PROBING_STATS_H_
