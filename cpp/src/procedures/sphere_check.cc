#include "fivecal/procedures/sphere_check.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <stdexcept>

#include "fivecal/procedures/sphere_test.h"

namespace fivecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool RotaryLetter(char a) { return a == 'A' || a == 'B' || a == 'C' || a == 'S'; }

// Indices 0..2 of `d`'s components in increasing size, ties to the lower
// index (numpy's stable argsort, which the rule was first written with).
std::array<int, 3> StableOrder(const Eigen::Vector3d& d) {
  std::array<int, 3> k = {0, 1, 2};
  std::stable_sort(k.begin(), k.end(), [&](int a, int b) { return d[a] < d[b]; });
  return k;
}

bool OnChain(const Machine& m, const std::vector<int>& chain, char axis) {
  for (int i : chain)
    if (m.axis(i).name == axis) return true;
  return false;
}

double ValueOf(const Result& r, const std::string& name) {
  for (size_t i = 0; i < r.names.size(); ++i)
    if (r.names[i] == name) return r.values[i];
  return 0.0;
}

int EstimatedIndex(const Result& r, const std::string& name) {
  for (size_t i = 0; i < r.estimated.size(); ++i)
    if (r.estimated[i] == name) return static_cast<int>(i);
  return -1;
}

SphereCheckValue Estimate(const Result& r, const std::string& name) {
  const int k = EstimatedIndex(r, name);
  return {name, ValueOf(r, name), k >= 0 ? r.std[k] : kNaN};
}

double Spread(const Eigen::MatrixXd& c) {
  if (c.rows() == 0) return 0.0;
  const Eigen::RowVector3d mean = c.colwise().mean();
  return (c.rowwise() - mean).rowwise().norm().maxCoeff();
}

}  // namespace

std::string SpindleEquivalent(const Machine& m, const std::string& name) {
  if (name.size() != 4 || name[0] != 'E' || name[2] != '0') return name;
  const size_t k = std::string("XYZ").find(name[1]);
  if (k == std::string::npos) return name;
  const char axis = name[3];
  const int s = m.AxisIndex('S');
  const int ai = m.AxisIndex(axis);
  if (s < 0 || ai < 0 || !RotaryLetter(axis) || axis == 'S') return name;
  const std::vector<int>& chain = OnChain(m, m.workpiece_chain(), axis) ? m.workpiece_chain() : m.tool_chain();
  for (int i : chain) {
    if (i == ai) break;
    if (RotaryLetter(m.axis(i).name) && std::abs(m.axis(i).direction[k]) < 1.0 - 1e-9) return name;
  }
  // the spindle's location candidates are its two positions most across its line
  const std::array<int, 3> across = StableOrder(m.axis(s).direction.cwiseAbs());
  if (across[0] == static_cast<int>(k) || across[1] == static_cast<int>(k))
    return std::string("E") + name[1] + "0S";
  return name;
}

std::vector<std::pair<std::string, double>> SpindleNames(
    const Machine& m, const std::vector<std::pair<std::string, double>>& errors) {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& [name, v] : errors) {
    const std::string c = SpindleEquivalent(m, name);
    // the spindle's offset is minus a workpiece-side axis' (README, sign conventions)
    const double signed_v = (c == name || !OnChain(m, m.workpiece_chain(), name[3])) ? v : -v;
    auto it = std::find_if(out.begin(), out.end(), [&](const auto& p) { return p.first == c; });
    if (it == out.end())
      out.emplace_back(c, signed_v);
    else
      it->second += signed_v;
  }
  return out;
}

std::vector<char> CheckedRotaryAxes(const Machine& m) {
  std::vector<char> out;
  for (const Axis& a : m.axes())
    if (RotaryLetter(a.name) && a.name != 'S') out.push_back(a.name);
  return out;
}

std::vector<std::string> PivotParameters(const Machine& m, char axis, bool backlash) {
  const int ai = m.AxisIndex(axis);
  if (ai < 0 || !m.axis(ai).rotary())
    throw std::invalid_argument(std::string("axis: machine '") + m.name() + "' has no rotary axis '" + axis + "'");
  // the two machine directions most across the axis: their position and tilt
  // errors move the axis line; the third is along it
  const std::array<int, 3> order = StableOrder(m.axis(ai).direction.cwiseAbs());
  const int a = std::min(order[0], order[1]), b = std::max(order[0], order[1]);
  std::vector<std::string> out;
  for (int k : {a, b}) out.push_back(SpindleEquivalent(m, std::string("E") + "XYZ"[k] + "0" + axis));
  for (int k : {a, b}) out.push_back(std::string("E") + "ABC"[k] + "0" + axis);
  if (backlash) out.push_back(std::string("E") + axis + axis + "b");
  return out;
}

SphereCheckResult EvaluateSphereCheck(const Dataset& given_ds, const SphereCheckOptions& options) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const Machine& m = ds.machine();
  const auto& obs = ds.observations;
  if (options.backlash < -1 || options.backlash > 1)
    throw std::invalid_argument("backlash: " + std::to_string(options.backlash) +
                                " (expected -1: where reached from both sides, 0: no, 1: yes)");
  std::set<std::string> spheres;
  for (const Observation& o : obs)
    if (o.type == ObservationType::kSphere) spheres.insert(o.data<TouchData>().target);
  if (spheres.empty()) throw std::invalid_argument("sphere check: the dataset has no sphere touches");
  SphereCheckResult out;
  out.sphere = options.sphere.empty() ? *spheres.begin() : options.sphere;
  if (!spheres.count(out.sphere)) {
    std::string touched;
    for (const std::string& s : spheres) touched += (touched.empty() ? "" : ", ") + s;
    throw std::invalid_argument("sphere: no touches of sphere '" + out.sphere + "' (touched: " + touched + ")");
  }
  const int si = ds.artefact.SphereIndex(out.sphere);
  if (si < 0) throw std::invalid_argument("sphere: no sphere '" + out.sphere + "' in the artefact");

  // the rotary axes that moved, and whether each was reached from both sides
  std::vector<int> moved;
  for (char a : CheckedRotaryAxes(m)) {
    const int i = m.AxisIndex(a);
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const Observation& o : obs) {
      lo = std::min(lo, o.axes[i]);
      hi = std::max(hi, o.axes[i]);
    }
    if (hi - lo > 1e-6) moved.push_back(i);
  }
  if (moved.empty())
    throw std::invalid_argument("sphere check: no rotary axis moved between the touches; nothing to check");
  for (int i : moved) {
    bool up = false, down = false;
    for (const Observation& o : obs) {
      const int d = o.direction.size() ? o.direction[i] : 0;
      up |= d == 1;
      down |= d == -1;
    }
    const bool backlash = options.backlash < 0 ? (up && down) : options.backlash == 1;
    for (const std::string& n : PivotParameters(m, m.axis(i).name, backlash)) out.estimate.push_back(n);
  }

  // the previous values this check compares with must be numbers; others
  // (a previous identify's set-up, its other errors) are not read
  for (const auto& [name, p] : options.previous) {
    const auto used = [&](const std::string& n) {
      return std::find(out.estimate.begin(), out.estimate.end(), n) != out.estimate.end();
    };
    if (!used(name) && !used(SpindleEquivalent(m, name))) continue;
    if (!std::isfinite(p.first)) throw std::invalid_argument("previous." + name + ": value is not finite");
    if (!(p.second >= 0) || !std::isfinite(p.second))
      throw std::invalid_argument("previous." + name + ": std must be a finite number >= 0");
  }

  IdentifyOptions io;
  io.estimate = out.estimate;
  if (options.calibrated_stylus) io.fix = {"tip.x", "tip.y", "tip.z"};
  out.fit = Identify(ds, io);
  const Result& r = out.fit;

  for (int i : moved) {
    SphereCheckAxis ax;
    ax.axis = m.axis(i).name;
    for (const std::string& n : PivotParameters(m, ax.axis, false)) ax.pivot.push_back(Estimate(r, n));
    const std::string b = std::string("E") + ax.axis + ax.axis + "b";
    if (EstimatedIndex(r, b) >= 0) {
      ax.has_backlash = true;
      ax.backlash = Estimate(r, b);
    }
    out.axes.push_back(ax);
  }

  // the previous check, with a table-axis name that is the spindle's also under the spindle's name
  std::map<std::string, std::pair<double, double>> prev = options.previous;
  for (const auto& [name, p] : options.previous) {
    const std::string c = SpindleEquivalent(m, name);
    if (c != name && !prev.count(c)) prev[c] = {SpindleNames(m, {{name, p.first}})[0].second, p.second};
  }
  for (const SphereCheckAxis& ax : out.axes)
    for (const SphereCheckValue& v : ax.pivot) {
      auto it = prev.find(v.name);
      if (it != prev.end()) out.change.push_back({v.name, v.value - it->second.first, std::hypot(v.std, it->second.second)});
    }

  // per rotary pose, the sphere's centre from its touches with the nominal and the fitted model
  std::vector<std::vector<long long>> keys;
  std::vector<std::vector<int>> members;
  for (size_t j = 0; j < obs.size(); ++j) {
    std::vector<long long> key;
    for (int i : moved) key.push_back(std::llround(obs[j].axes[i] * 1e6));
    auto it = std::find(keys.begin(), keys.end(), key);
    if (it == keys.end()) {
      keys.push_back(key);
      members.emplace_back();
      it = keys.end() - 1;
    }
    if (obs[j].type == ObservationType::kSphere && obs[j].data<TouchData>().target == out.sphere)
      members[it - keys.begin()].push_back(static_cast<int>(j));
  }
  const Sphere& sphere = ds.artefact.spheres[si];
  const double R = sphere.radius + ds.tip_radius;
  std::map<std::string, double> fitted;
  for (size_t i = 0; i < r.names.size(); ++i) fitted[r.names[i]] = r.values[i];
  std::vector<int> kept;
  for (size_t g = 0; g < keys.size(); ++g)
    if (members[g].size() >= 3) kept.push_back(static_cast<int>(g));
  out.positions.resize(kept.size(), moved.size());
  out.centres_before.resize(kept.size(), 3);
  out.centres_after.resize(kept.size(), 3);
  for (size_t k = 0; k < kept.size(); ++k) {
    const int g = kept[k];
    for (size_t a = 0; a < moved.size(); ++a) out.positions(k, a) = static_cast<double>(keys[g][a]) / 1e6;
    for (int pass = 0; pass < 2; ++pass) {
      const Eigen::MatrixXd P = TablePoints(ds, pass ? fitted : std::map<std::string, double>{}, members[g]);
      const SphereCentreFit f = FitSphereCentre(P, R, sphere.center);
      if (!f.converged)
        throw std::invalid_argument("fit_sphere_centre: Gauss-Newton did not converge in " +
                                    std::to_string(f.iterations) +
                                    " iterations (points far from a sphere of that radius, or start far from the centre)");
      (pass ? out.centres_after : out.centres_before).row(k) = f.center.transpose();
    }
  }
  out.dispersion_before = Spread(out.centres_before);
  out.dispersion_after = Spread(out.centres_after);
  out.condition_number = r.condition_number;
  for (size_t i = 0; i < r.estimated.size(); ++i)
    if (std::find(out.estimate.begin(), out.estimate.end(), r.estimated[i]) != out.estimate.end() &&
        i < r.informed.size())
      out.informed.emplace_back(r.estimated[i], r.informed[i]);
  return out;
}

std::vector<std::pair<char, std::vector<double>>> SphereCheckPositions(
    const Machine& m, int n, const std::map<std::string, std::pair<double, double>>& limits) {
  if (n < 3 || n > kMaxSphereCheckPositions)
    throw std::invalid_argument("n: " + std::to_string(n) + " positions per axis; expected a whole number from 3 (a "
                                "pivot needs at least 3) to " + std::to_string(kMaxSphereCheckPositions));
  std::vector<std::pair<char, std::vector<double>>> out;
  for (char a : CheckedRotaryAxes(m)) {
    const auto it = limits.find(std::string(1, a));
    // a table's or a head's C turns a full turn; a tilting axis +-90 deg
    const std::pair<double, double> range =
        it != limits.end() ? it->second : (a == 'C' ? std::make_pair(-180.0, 180.0) : std::make_pair(-90.0, 90.0));
    const double lo = range.first, hi = range.second;
    if (!(hi > lo)) {
      char buf[96];
      std::snprintf(buf, sizeof buf, "(%g, %g)", lo, hi);
      throw std::invalid_argument(std::string("limits.") + a + ": " + buf + " is not a range");
    }
    const bool full = hi - lo >= 360.0 - 1e-9;
    // numpy's linspace: i * step + lo, the end point set exactly
    const double step = (hi - lo) / (full ? n : n - 1);
    std::vector<double> v(n);
    for (int i = 0; i < n; ++i) v[i] = i * step + lo;
    if (!full) v[n - 1] = hi;
    out.emplace_back(a, std::move(v));
  }
  return out;
}

}  // namespace fivecal
