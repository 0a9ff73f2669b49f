#include "fivecal/procedures/probing_stats.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "json_util.h"

namespace fivecal {
namespace {

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

// Sample standard deviation (n - 1).
double Std(const std::vector<double>& v) {
  if (v.size() < 2) return 0.0;
  const double m = Mean(v);
  double ss = 0;
  for (double x : v) ss += (x - m) * (x - m);
  return std::sqrt(ss / (static_cast<double>(v.size()) - 1));
}

double Range(const Eigen::VectorXd& v) { return v.maxCoeff() - v.minCoeff(); }

std::vector<double> ToStd(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

std::vector<std::vector<double>> Windows(const Eigen::VectorXd& s, int window) {
  std::vector<std::vector<double>> g;
  for (int start = 0; start < s.size(); start += window) {
    const int len = std::min<int>(window, static_cast<int>(s.size()) - start);
    g.emplace_back(s.data() + start, s.data() + start + len);
  }
  return g;
}

}  // namespace

PooledStd PooledStandardDeviation(const std::vector<std::vector<double>>& groups) {
  PooledStd out;
  double num = 0;
  for (size_t g = 0; g < groups.size(); ++g) {
    for (double x : groups[g])
      if (!std::isfinite(x)) throw std::invalid_argument("pooled std: group " + std::to_string(g) + " has a non-finite value");
    const int n = static_cast<int>(groups[g].size());
    const double s = Std(groups[g]);
    out.group_std.push_back(s);
    out.group_size.push_back(n);
    if (n >= 2) {
      num += (n - 1) * s * s;
      out.dof += n - 1;
    }
  }
  if (out.dof < 1) throw std::invalid_argument("pooled std: no group has two or more values");
  out.pooled_std = std::sqrt(num / out.dof);
  return out;
}

PooledStd WindowPooledStd(const Eigen::VectorXd& series, int window) {
  if (window < 2) throw std::invalid_argument("pooled std: window must be >= 2");
  return PooledStandardDeviation(Windows(series, window));
}

GridStatistics AnalyzeGrid(const Eigen::MatrixXd& P, int window) {
  const int n = static_cast<int>(P.rows()), m = static_cast<int>(P.cols());
  if (n < 2 || m < 2)
    throw std::invalid_argument("probing grid: need at least 2 points x 2 cycles, got " + std::to_string(n) +
                                " x " + std::to_string(m));
  if (window < 2) throw std::invalid_argument("probing grid: window must be >= 2 cycles");
  if (!P.allFinite()) throw std::invalid_argument("probing grid: values are not finite");
  GridStatistics g;
  g.points = n;
  g.cycles = m;
  g.window = window;
  // Total (4-9, 4-10).
  g.mean = P.mean();
  g.total_std = std::sqrt((P.array() - g.mean).square().sum() / (n * m - 1.0));
  g.total_range = P.maxCoeff() - P.minCoeff();
  // Repeatability (4-11, 4-12).
  g.point_pooled_std.resize(n);
  std::vector<std::vector<double>> all;
  for (int i = 0; i < n; ++i) {
    const auto w = Windows(P.row(i).transpose(), window);
    g.point_pooled_std[i] = PooledStandardDeviation(w).pooled_std;
    all.insert(all.end(), w.begin(), w.end());
  }
  g.max_pooled_std = g.point_pooled_std.maxCoeff();
  const PooledStd pooled = PooledStandardDeviation(all);
  g.pooled_std = pooled.pooled_std;
  g.pooled_dof = pooled.dof;
  // Surface (4-13..4-15).
  g.point_means = P.rowwise().mean();
  g.surface_std = Std(ToStd(g.point_means));
  g.surface_range = Range(g.point_means);
  // Drift (4-16).
  g.cycle_means = P.colwise().mean().transpose();
  g.drift_std = Std(ToStd(g.cycle_means));
  g.drift_range = Range(g.cycle_means);
  // Per point (Table 7-5).
  g.point_std.resize(n);
  double var = 0;
  for (int i = 0; i < n; ++i) {
    g.point_std[i] = Std(ToStd(P.row(i).transpose()));
    var += g.point_std[i] * g.point_std[i];
  }
  g.point_std_pooled = std::sqrt(var / n);
  // Two-way ANOVA variance components.
  double sse = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < m; ++j) {
      const double e = P(i, j) - g.point_means[i] - g.cycle_means[j] + g.mean;
      sse += e * e;
    }
  const double ms_e = sse / ((n - 1.0) * (m - 1.0));
  const double ms_points = m * (g.point_means.array() - g.mean).square().sum() / (n - 1.0);
  const double ms_cycles = n * (g.cycle_means.array() - g.mean).square().sum() / (m - 1.0);
  g.repeatability = std::sqrt(ms_e);
  g.surface_component = std::sqrt(std::max(0.0, (ms_points - ms_e) / m));
  g.drift_component = std::sqrt(std::max(0.0, (ms_cycles - ms_e) / n));
  return g;
}

std::string GridStatistics::ToJson() const {
  using json_util::json;
  json j;
  j["points"] = points;
  j["cycles"] = cycles;
  j["window"] = window;
  j["mean"] = mean;
  j["total_std"] = total_std;
  j["total_range"] = total_range;
  j["point_pooled_std"] = ToStd(point_pooled_std);
  j["max_pooled_std"] = max_pooled_std;
  j["pooled_std"] = pooled_std;
  j["pooled_dof"] = pooled_dof;
  j["point_means"] = ToStd(point_means);
  j["surface_std"] = surface_std;
  j["surface_range"] = surface_range;
  j["cycle_means"] = ToStd(cycle_means);
  j["drift_std"] = drift_std;
  j["drift_range"] = drift_range;
  j["point_std"] = ToStd(point_std);
  j["point_std_pooled"] = point_std_pooled;
  j["repeatability"] = repeatability;
  j["surface_component"] = surface_component;
  j["drift_component"] = drift_component;
  return j.dump(1);
}

}  // namespace fivecal
