#include "solve/residual_units.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>

#include "fivecal/observations/registry.h"

namespace fivecal {
namespace {

// The unit of every row ("mm" for a scale bar row), from the kinds.
std::vector<const char*> RowUnits(const Dataset& ds, const std::vector<int>& source) {
  std::vector<const char*> unit(source.size(), "mm");
  const int n = static_cast<int>(ds.size());  // column-block rows too
  std::vector<int> seen(static_cast<size_t>(n), 0);
  // The kind of observation s: a block's from a cursor that follows the
  // rows (they come in order), not a search over the blocks per row.
  const size_t n_obj = ds.observations.size();
  size_t block = 0, block_start = n_obj;
  auto kind_at = [&](size_t s) -> const ObservationKind& {
    if (s < n_obj) return KindOf(ds.observations[s]);
    if (s < block_start) block = 0, block_start = n_obj;
    while (s - block_start >= ds.blocks[block].size()) block_start += ds.blocks[block++].size();
    return KindOf(ds.blocks[block].type);
  };
  const ObservationKind* kind = nullptr;
  int last = -1;
  for (size_t i = 0; i < source.size(); ++i) {
    const int s = source[i];
    if (s < 0 || s >= n) continue;
    if (s != last) kind = &kind_at(static_cast<size_t>(s)), last = s;
    unit[i] = kind->unit_row(seen[s]++);
  }
  return unit;
}

bool SameUnit(const char* a, const char* b) { return std::strcmp(a, b) == 0; }

}  // namespace

Eigen::VectorXd PositionScaledResiduals(const Dataset& ds, const Eigen::VectorXd& r, const Eigen::VectorXd& sigma,
                                        const std::vector<int>& source) {
  const std::vector<const char*> unit = RowUnits(ds, source);
  const int n_obs = static_cast<int>(ds.size());
  auto own = [&](int s) { return s >= 0 && s < n_obs; };
  // The observation's position noise: its rows of the first unit.
  std::vector<double> ref(static_cast<size_t>(n_obs), 0.0);
  const char* first_unit = "";
  for (size_t i = 0; i < source.size(); ++i) {
    const int s = source[i];
    if (!own(s)) continue;
    // An observation's rows are consecutive: its first row has its kind's
    // first unit (no kind lookup per row).
    if (i == 0 || source[i - 1] != s) first_unit = unit[i];
    if (SameUnit(unit[i], first_unit)) ref[s] = std::max(ref[s], sigma[i]);
  }
  Eigen::VectorXd out = r;
  for (size_t i = 0; i < source.size(); ++i) {
    const int s = source[i];
    if (own(s) && ref[s] > 0 && sigma[i] > 0) out[i] = r[i] * (ref[s] / sigma[i]);
  }
  return out;
}

double DefaultRobustScale(const Eigen::VectorXd& scaled) {
  if (scaled.size() == 0) return 1e-6;
  std::vector<double> a(scaled.data(), scaled.data() + scaled.size());
  for (double& x : a) x = std::abs(x);
  std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
  const double scale = 3.0 * 1.4826 * a[a.size() / 2];
  return scale > 0 ? scale : 1e-6;
}

std::vector<int> RobustOutliers(const Eigen::VectorXd& scaled, double scale) {
  std::vector<int> out;
  for (int i = 0; i < scaled.size(); ++i)
    if (std::abs(scaled[i]) > scale) out.push_back(i);
  return out;
}

namespace {

// row_share(i): row i's share Jw_i hat Jw_i^T, asked for rows of units
// other than mm only; unit_share: a whole unit's instead.
// out: the units, "mm" first; group(i): row i's index into out.
std::vector<UnitResiduals> ByUnit(const Eigen::VectorXd& r, std::vector<UnitResiduals> out,
                                  const std::function<int(size_t)>& group,
                                  const std::function<double(size_t)>& row_share,
                                  const std::map<std::string, double>* unit_share, int dof) {
  std::vector<double> ss(out.size(), 0.0), used(out.size(), 0.0);
  for (Eigen::Index i = 0; i < r.size(); ++i) {
    const int g = group(static_cast<size_t>(i));
    UnitResiduals& u = out[g];
    ++u.rows;
    ss[g] += r[i] * r[i];
    u.max_abs = std::max(u.max_abs, std::abs(r[i]));
    if (g > 0 && row_share) used[g] += row_share(static_cast<size_t>(i));
  }
  if (unit_share)
    for (size_t g = 1; g < out.size(); ++g) {
      auto it = unit_share->find(out[g].unit);
      if (it != unit_share->end()) used[g] = it->second;
    }
  double other_dof = 0;
  for (size_t g = 1; g < out.size(); ++g) other_dof += out[g].rows - used[g];
  for (size_t g = 0; g < out.size(); ++g) {
    UnitResiduals& u = out[g];
    u.rms = u.rows ? std::sqrt(ss[g] / u.rows) : 0.0;
    u.dof = g == 0 ? dof - other_dof : u.rows - used[g];
    u.sigma = u.dof > 0 ? std::sqrt(ss[g] / u.dof) : 0.0;
  }
  if (out[0].rows == 0) out.erase(out.begin());
  return out;
}

}  // namespace

std::vector<UnitResiduals> ResidualsByUnit(const Dataset& ds, const Eigen::VectorXd& r,
                                           const std::vector<int>& source, const Eigen::MatrixXd& Jw,
                                           const Eigen::MatrixXd& hat, int dof) {
  const std::vector<const char*> unit = RowUnits(ds, source);
  // "mm" first: every kind's first row is a length.
  std::vector<UnitResiduals> out(1);
  out[0].unit = "mm";
  std::vector<int> group(unit.size());
  for (size_t i = 0; i < unit.size(); ++i) {
    size_t g = 0;
    while (g < out.size() && out[g].unit != unit[i]) ++g;
    if (g == out.size()) out.emplace_back().unit = unit[i];
    group[i] = static_cast<int>(g);
  }
  std::function<double(size_t)> share;
  if (hat.rows() == Jw.cols() && Jw.rows() == r.size())
    share = [&](size_t i) { return Jw.row(i).dot(hat * Jw.row(i).transpose()); };
  return ByUnit(r, std::move(out), [&](size_t i) { return group[i]; }, share, nullptr, dof);
}

std::vector<UnitResiduals> ResidualsByUnit(const Eigen::VectorXd& r, const std::vector<unsigned char>& row_unit,
                                           const std::vector<std::string>& other_units,
                                           const std::map<std::string, double>& share, int dof) {
  if (!row_unit.empty() && row_unit.size() != static_cast<size_t>(r.size()))
    throw std::logic_error("residual units: one unit per residual row expected");
  // other_units are in the order their first rows come, as RowUnits finds them.
  std::vector<UnitResiduals> out(1 + other_units.size());
  out[0].unit = "mm";
  for (size_t u = 0; u < other_units.size(); ++u) out[1 + u].unit = other_units[u];
  std::function<int(size_t)> group = [](size_t) { return 0; };
  if (!row_unit.empty()) group = [&](size_t i) { return static_cast<int>(row_unit[i]); };
  return ByUnit(r, std::move(out), group, nullptr, &share, dof);
}

}  // namespace fivecal
