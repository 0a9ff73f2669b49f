#include "fivecal/procedures/circular_test.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <tuple>
#include <utility>

#include "fivecal/procedures/circle_fit.h"

namespace fivecal {
namespace {

constexpr double kRad = 3.14159265358979323846 / 180.0;

int Sgn(double x) { return x > 1e-12 ? 1 : (x < -1e-12 ? -1 : 0); }

void ValidateRun(const CircularRun& r, int idx) {
  const std::string w = "circular test: run " + std::to_string(idx);
  if (r.angles.size() != r.readings.size())
    throw std::invalid_argument(w + ": angles and readings differ in length (" +
                                std::to_string(r.angles.size()) + " vs " +
                                std::to_string(r.readings.size()) + ")");
  if (r.angles.size() < 8)
    throw std::invalid_argument(w + ": " + std::to_string(r.angles.size()) +
                                " samples; at least 8 are needed");
  for (int i = 0; i < r.angles.size(); ++i) {
    if (!std::isfinite(r.angles[i]))
      throw std::invalid_argument(w + ".angles[" + std::to_string(i) + "]: not finite");
    if (!std::isfinite(r.readings[i]))
      throw std::invalid_argument(w + ".readings[" + std::to_string(i) + "]: not finite");
  }
  if (std::abs(r.direction) > 1)
    throw std::invalid_argument(w + ".direction: must be +1 (CCW), -1 (CW) or 0 (from the angles)");
  // A ball bar records at most a few thousand samples per revolution; the
  // bound keeps the design matrix of the diagnosis in memory.
  constexpr Eigen::Index kMaxSamples = 1000000;
  if (r.angles.size() > kMaxSamples)
    throw std::invalid_argument(w + ": " + std::to_string(r.angles.size()) +
                                " samples; at most 1000000 per run");
  // Angles read in radians sweep at most 6.3 "degrees": refuse rather than
  // analyse a full circle as a 6 degree arc.
  const double sweep = r.angles.maxCoeff() - r.angles.minCoeff();
  if (sweep < 10.0) {
    std::ostringstream s;
    s << w << ".angles: sweep only " << sweep << " deg; a circular test needs at least 10 deg "
      << "(angles must be in degrees, not radians)";
    throw std::invalid_argument(s.str());
  }
}

int RunDirection(const CircularRun& r, int idx) {
  if (r.direction != 0) return r.direction;
  const int s = Sgn(r.angles[r.angles.size() - 1] - r.angles[0]);
  if (s == 0)
    throw std::invalid_argument("circular test: run " + std::to_string(idx) +
                                ": cannot tell CW from CCW (first and last angle equal); give the direction");
  return s;
}

// Periodic (full turn) or bounded linear interpolation of (a, v) at x (deg).
struct Interpolator {
  std::vector<double> a, v;
  bool periodic = false;
  Interpolator(const Eigen::VectorXd& ang, const Eigen::VectorXd& val) {
    std::vector<int> idx(ang.size());
    std::iota(idx.begin(), idx.end(), 0);
    auto wrap = [](double x) { return x - 360.0 * std::floor(x / 360.0); };
    std::sort(idx.begin(), idx.end(), [&](int i, int j) { return wrap(ang[i]) < wrap(ang[j]); });
    for (int i : idx) {
      a.push_back(wrap(ang[i]));
      v.push_back(val[i]);
    }
    periodic = (ang.maxCoeff() - ang.minCoeff()) >= 355.0;
  }
  bool At(double x, double* out) const {
    x -= 360.0 * std::floor(x / 360.0);
    const size_t n = a.size();
    auto hi = std::upper_bound(a.begin(), a.end(), x);
    double x0, x1, v0, v1;
    if (hi == a.begin() || hi == a.end()) {
      if (!periodic) {
        if (hi == a.begin() && std::abs(x - a.front()) < 1e-9) { *out = v.front(); return true; }
        if (hi == a.end() && std::abs(x - a.back()) < 1e-9) { *out = v.back(); return true; }
        return false;
      }
      x0 = a[n - 1] - (hi == a.begin() ? 360.0 : 0.0);
      v0 = v[n - 1];
      x1 = a[0] + (hi == a.end() ? 360.0 : 0.0);
      v1 = v[0];
    } else {
      const size_t j = hi - a.begin();
      x0 = a[j - 1];
      v0 = v[j - 1];
      x1 = a[j];
      v1 = v[j];
    }
    const double t = x1 > x0 ? (x - x0) / (x1 - x0) : 0.0;
    *out = v0 + t * (v1 - v0);
    return true;
  }
};

// [1, cos phi, sin phi, ..., cos K phi, sin K phi] at the angles (deg).
Eigen::MatrixXd HarmonicBasis(const Eigen::VectorXd& angles_deg, int max_order) {
  Eigen::MatrixXd A(angles_deg.size(), 2 * max_order + 1);
  for (int i = 0; i < angles_deg.size(); ++i) {
    const double phi = angles_deg[i] * kRad;
    A(i, 0) = 1.0;
    for (int k = 1; k <= max_order; ++k) {
      A(i, 2 * k - 1) = std::cos(k * phi);
      A(i, 2 * k) = std::sin(k * phi);
    }
  }
  return A;
}

}  // namespace

TrimmedRun TrimOvershoot(const CircularRun& run, double data_arc, double feed_in, double tolerance) {
  const std::string w = "overshoot trimming";
  if (run.angles.size() != run.readings.size())
    throw std::invalid_argument(w + ": angles and readings differ in length");
  if (!(data_arc > 0 && data_arc <= 360.0))
    throw std::invalid_argument(w + ": data_arc must be in (0, 360] deg");
  if (!(tolerance >= 0)) throw std::invalid_argument(w + ": tolerance must be >= 0 deg");
  const int n = static_cast<int>(run.angles.size());
  TrimmedRun out;
  out.run = run;
  if (n < 2) return out;
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(run.angles[i]))
      throw std::invalid_argument(w + ": angles[" + std::to_string(i) + "] is not finite");
  // Unwrap: a recorder may print the angle modulo 360.
  Eigen::VectorXd u(n);
  u[0] = run.angles[0];
  for (int i = 1; i < n; ++i) {
    double step = run.angles[i] - run.angles[i - 1];
    step -= 360.0 * std::round(step / 360.0);
    u[i] = u[i - 1] + step;
  }
  int dir = run.direction;
  if (dir == 0) dir = Sgn(u[n - 1] - u[0]);
  if (dir == 0) throw std::invalid_argument(w + ": cannot tell CW from CCW; give the direction");
  // Samples at either end going against the run (the bar settling, a
  // back-off) are not part of the circle.
  int first = 0, last = n - 1;
  while (first + 1 < n && dir * (u[first + 1] - u[first]) <= 0) ++first;
  while (last - 1 > first && dir * (u[last] - u[last - 1]) <= 0) --last;
  const double sweep = dir * (u[last] - u[first]);
  double lo = dir * u[first], hi = dir * u[last];  // in the direction of travel
  if (sweep > data_arc + tolerance) {
    const double excess = sweep - data_arc;
    double fi = std::isnan(feed_in) ? 0.5 * excess : feed_in;
    if (!(fi >= 0) || fi > excess + tolerance) {
      std::ostringstream m;
      m << w << ": feed_in " << feed_in << " deg; the run sweeps " << sweep << " deg, so the feed-in arc "
        << "must be between 0 and " << excess << " deg";
      throw std::invalid_argument(m.str());
    }
    fi = std::min(fi, excess);
    lo += fi;
    hi = lo + data_arc;
  }
  // A tolerance on the angle keeps the sample that sits on the arc's end.
  const double eps = std::max(tolerance, 1e-9);
  std::vector<int> idx;
  for (int i = first; i <= last; ++i) {
    const double a = dir * u[i];
    if (a >= lo - eps && a <= hi + eps) idx.push_back(i);
  }
  if (idx.empty()) throw std::invalid_argument(w + ": no sample left in the data arc");
  out.run.angles.resize(idx.size());
  out.run.readings.resize(idx.size());
  for (size_t j = 0; j < idx.size(); ++j) {
    out.run.angles[j] = u[idx[j]];
    out.run.readings[j] = run.readings[idx[j]];
  }
  out.run.direction = dir;
  out.removed_start = idx.front();
  out.removed_end = n - 1 - idx.back();
  out.arc_start = std::abs(u[idx.front()] - u[0]);
  out.arc_end = std::abs(u[n - 1] - u[idx.back()]);
  out.data_first = u[idx.front()];
  out.data_last = u[idx.back()];
  return out;
}

double CircularDiagnosis::Get(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return values[i];
  throw std::invalid_argument("circular diagnosis: '" + name + "' was not fitted");
}

bool CircularDiagnosis::Has(const std::string& name) const {
  return std::find(names.begin(), names.end(), name) != names.end();
}

namespace {

// The column of diagnosis `nm` (the header's list) at path angle deg on a run
// in direction s: the radial deviation per unit of its value.
double TermColumn(const std::string& nm, double deg, int s, double R, const CircularDiagnosisOptions& o) {
  const double phi = deg * kRad, c = std::cos(phi), sn = std::sin(phi);
  // Motion signs on the circle x1 = R cos phi, x2 = R sin phi traversed in direction s.
  const double v1 = -s * Sgn(sn), v2 = s * Sgn(c);
  if (nm == "radius") return 1.0;
  if (nm == "centre.1") return c;
  if (nm == "centre.2") return sn;
  if (nm == "scale_mismatch") return 0.5 * R * std::cos(2 * phi);
  if (nm == "squareness") return -0.5 * R * std::sin(2 * phi);
  if (nm == "servo_mismatch") return 0.5 * s * std::sin(2 * phi);
  const size_t dot = nm.find('.');
  if (dot == std::string::npos || dot + 1 >= nm.size() || (nm[dot + 1] != '1' && nm[dot + 1] != '2'))
    throw std::invalid_argument("circular diagnosis: unknown diagnosis '" + nm + "'");
  const int ax = nm[dot + 1] == '1' ? 1 : 2;
  const char end = nm.back();  // '+' or '-' for the split diagnoses
  const double along = ax == 1 ? c : sn;
  const bool split = end == '+' || end == '-';
  if (split && !(end == '+' ? along > 0 : along < 0) && nm.rfind("reversal_spike", 0) != 0) return 0.0;
  const std::string kind = nm.substr(0, dot);
  if (kind == "backlash" && split) return ax == 1 ? c * v1 : sn * v2;
  if (kind == "reversal_spike" && split) {
    // Angle travelled since the last reversal of the axis (axis 1 at
    // 0/180 deg, axis 2 at 90/270 deg) and where that reversal was.
    const double phi0 = ax == 1 ? 0.0 : 90.0;
    const double t = s * (deg - phi0);
    const double dphi = t - 180.0 * std::floor(t / 180.0);
    const double rev = (deg - s * dphi) * kRad;
    const int at = ax == 1 ? Sgn(std::cos(rev)) : Sgn(std::sin(rev));
    if (at != (end == '+' ? 1 : -1)) return 0.0;
    return along * at * std::exp(-dphi / o.spike_width);
  }
  if (kind == "lateral_play" && !split) return ax == 1 ? c * v2 : sn * v1;
  if (kind == "straightness" && !split) return ax == 1 ? sn * c * c : c * sn * sn;
  if (kind == "radial_play" && !split) return std::abs(along);
  if (kind == "cyclic_error") {
    const double pitch = ax == 1 ? o.cyclic_pitch1 : o.cyclic_pitch2;
    if (!(pitch > 0)) throw std::invalid_argument("circular diagnosis: " + nm + " needs the cyclic pitch");
    const double arg = 2.0 * 3.14159265358979323846 * R * along / pitch;
    if (nm.size() > 4 && nm.compare(nm.size() - 4, 4, ".cos") == 0) return along * std::cos(arg);
    if (nm.size() > 4 && nm.compare(nm.size() - 4, 4, ".sin") == 0) return along * std::sin(arg);
  }
  throw std::invalid_argument("circular diagnosis: unknown diagnosis '" + nm + "'");
}

// The analysis with the cyclic pitches as given in options (no search).
CircularTestResult AnalyzeGivenPitches(const std::vector<CircularRun>& runs, double R, double feed,
                                       const CircularDiagnosisOptions& options) {
  if (runs.empty() || runs.size() > 2)
    throw std::invalid_argument("circular test: give one or two runs (CW and CCW), got " +
                                std::to_string(runs.size()));
  if (!(R > 0) || !std::isfinite(R))
    throw std::invalid_argument("circular test: nominal radius must be > 0 mm");
  if (!(feed >= 0) || !std::isfinite(feed))
    throw std::invalid_argument("circular test: feed must be >= 0 mm/min");
  CircularTestResult res;
  res.nominal_radius = R;
  std::vector<int> dirs;
  for (size_t k = 0; k < runs.size(); ++k) {
    ValidateRun(runs[k], static_cast<int>(k));
    dirs.push_back(RunDirection(runs[k], static_cast<int>(k)));
  }
  if (runs.size() == 2 && dirs[0] == dirs[1])
    throw std::invalid_argument("circular test: both runs go the same way; give one CW and one CCW run");

  // ISO 230-4 per run.
  for (size_t k = 0; k < runs.size(); ++k) {
    const CircularRun& r = runs[k];
    const int n = static_cast<int>(r.angles.size());
    Eigen::MatrixXd P(n, 2);
    for (int i = 0; i < n; ++i) {
      const double rad = R + r.readings[i], phi = r.angles[i] * kRad;
      P(i, 0) = rad * std::cos(phi);
      P(i, 1) = rad * std::sin(phi);
    }
    const CircleFit lsc = FitCircleGeometric(P, "circular test: least-squares circle");
    CircularRunResult rr;
    rr.direction = dirs[k];
    rr.centre = lsc.centre;
    rr.mean_radius = lsc.radius;
    rr.radial = lsc.residuals;
    rr.circular_deviation = lsc.residuals.maxCoeff() - lsc.residuals.minCoeff();
    rr.radial_deviation_max = r.readings.maxCoeff();
    rr.radial_deviation_min = r.readings.minCoeff();
    res.runs.push_back(rr);
  }
  if (runs.size() == 2) {
    const int cw = dirs[0] < 0 ? 0 : 1, ccw = 1 - cw;
    const Interpolator other(runs[ccw].angles, runs[ccw].readings);
    for (int i = 0; i < runs[cw].angles.size(); ++i) {
      double v;
      if (!other.At(runs[cw].angles[i], &v)) continue;
      res.hysteresis = std::max(res.hysteresis, std::abs(v - runs[cw].readings[i]));
      res.has_hysteresis = true;
    }
  }

  // Diagnosis: columns as documented in the header. The base set first (its
  // rank is required), then each extended diagnosis only if the samples can
  // separate it from what is already in.
  int total = 0;
  for (const CircularRun& r : runs) total += static_cast<int>(r.angles.size());
  const CircularDiagnosisOptions& o = options;
  if (!(o.significance >= 0) || !std::isfinite(o.significance))
    throw std::invalid_argument("circular test: significance must be >= 0 (0 = keep every diagnosis)");
  if (o.reversal_spikes && !(o.spike_width > 0 && std::isfinite(o.spike_width)))
    throw std::invalid_argument("circular test: spike_width must be > 0 deg");
  for (double p : {o.cyclic_pitch1, o.cyclic_pitch2})
    if (!(p >= 0) || !std::isfinite(p))
      throw std::invalid_argument("circular test: cyclic_pitch must be >= 0 mm (0 = not fitted)");
  std::vector<std::string> names = {"radius", "centre.1", "centre.2", "scale_mismatch", "squareness",
                                    "servo_mismatch", "backlash.1+", "backlash.1-", "backlash.2+",
                                    "backlash.2-"};
  const int n_base = static_cast<int>(names.size());
  if (o.reversal_spikes)
    names.insert(names.end(), {"reversal_spike.1+", "reversal_spike.1-", "reversal_spike.2+", "reversal_spike.2-"});
  if (o.lateral_play) names.insert(names.end(), {"lateral_play.1", "lateral_play.2"});
  if (o.straightness) names.insert(names.end(), {"straightness.1", "straightness.2"});
  if (o.radial_play) names.insert(names.end(), {"radial_play.1", "radial_play.2"});
  if (o.cyclic_pitch1 > 0) names.insert(names.end(), {"cyclic_error.1.cos", "cyclic_error.1.sin"});
  if (o.cyclic_pitch2 > 0) names.insert(names.end(), {"cyclic_error.2.cos", "cyclic_error.2.sin"});
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(total, names.size());
  // Motion signs of both axes per row: a reversal-dependent term needs both
  // signs inside the data.
  Eigen::MatrixXi motion(total, 2);
  Eigen::VectorXd y(total);
  std::vector<int> run_of(total);
  int row = 0;
  for (size_t k = 0; k < runs.size(); ++k) {
    const int s = dirs[k];
    for (int i = 0; i < runs[k].angles.size(); ++i, ++row) {
      const double deg = runs[k].angles[i], phi = deg * kRad;
      motion(row, 0) = -s * Sgn(std::sin(phi));
      motion(row, 1) = s * Sgn(std::cos(phi));
      for (size_t j = 0; j < names.size(); ++j) A(row, j) = TermColumn(names[j], deg, s, R, o);
      y[row] = runs[k].readings[i];
      run_of[row] = static_cast<int>(k);
    }
  }
  CircularDiagnosis& d = res.diagnosis;
  // Whether the axis moves both ways inside the data; with a column, only
  // on the rows where that column is not zero (a split backlash' half).
  auto reverses = [&](int axis, int col = -1) {
    bool pos = false, neg = false;
    for (int i = 0; i < total; ++i) {
      if (col >= 0 && A(i, col) == 0.0) continue;
      pos |= motion(i, axis - 1) > 0;
      neg |= motion(i, axis - 1) < 0;
    }
    return pos && neg;
  };
  std::vector<int> keep;
  for (int j = 0; j < n_base; ++j) {
    if (names[j] == "servo_mismatch" && runs.size() < 2) {
      d.not_fitted.push_back("servo_mismatch (needs a CW and a CCW run: with one direction it cannot be told from squareness)");
      continue;
    }
    if (names[j].rfind("backlash", 0) == 0 && !reverses(names[j][9] - '0', j)) {
      d.not_fitted.push_back(names[j] + " (the axis never reverses at that end of its travel inside the data)");
      continue;
    }
    keep.push_back(j);
  }
  auto full_rank = [&](const std::vector<int>& cols) {
    // Columns scaled to unit norm: the rank test must not depend on R.
    Eigen::MatrixXd M(total, cols.size());
    for (size_t j = 0; j < cols.size(); ++j) {
      const double nrm = A.col(cols[j]).norm();
      if (nrm < 1e-300) return false;
      M.col(j) = A.col(cols[j]) / nrm;
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> q(M);
    q.setThreshold(1e-8);
    return q.rank() == static_cast<int>(cols.size());
  };
  if (!full_rank(keep))
    throw std::invalid_argument("circular test: the samples cover too little of the circle to separate "
                                "centre offset, scale mismatch, squareness and backlash at each end of the axes");
  for (size_t j = n_base; j < names.size(); ++j) {
    const std::string& nm = names[j];
    const int ax = nm[nm.find('.') + 1] == '1' ? 1 : 2;
    const bool is_cyc = nm.rfind("cyclic_error", 0) == 0;
    if (is_cyc && nm.back() == 'n') continue;  // the .sin column goes in with its .cos
    std::vector<int> cols = {static_cast<int>(j)};
    if (is_cyc) cols.push_back(static_cast<int>(j) + 1);
    const std::string label = is_cyc ? nm.substr(0, nm.size() - 4) : nm;
    if (nm.rfind("lateral_play", 0) == 0) {
      if (runs.size() < 2) {
        d.not_fitted.push_back(label + " (needs a CW and a CCW run: with one direction it cannot be told from radial play)");
        continue;
      }
      if (!reverses(3 - ax)) {
        d.not_fitted.push_back(label + " (the other axis never reverses inside the data)");
        continue;
      }
    }
    if (nm.rfind("reversal_spike", 0) == 0) {
      int near = 0;
      for (int i = 0; i < total; ++i) near += std::abs(A(i, j)) > 0.05;
      if (near < 2) {
        d.not_fitted.push_back(label + " (no reversal of the axis inside the data)");
        continue;
      }
    }
    std::vector<int> trial = keep;
    trial.insert(trial.end(), cols.begin(), cols.end());
    if (!full_rank(trial)) {
      d.not_fitted.push_back(label + " (the samples cannot separate it from the other diagnoses)");
      continue;
    }
    keep = trial;
  }
  Eigen::MatrixXd Ak;
  Eigen::VectorXd x, res_v;
  Eigen::MatrixXd cov;
  auto fit = [&]() {
    Ak.resize(total, keep.size());
    for (size_t j = 0; j < keep.size(); ++j) Ak.col(j) = A.col(keep[j]);
    x = Ak.colPivHouseholderQr().solve(y);
    res_v = y - Ak * x;
    const int dof = std::max(1, total - static_cast<int>(keep.size()));
    cov = res_v.squaredNorm() / dof * (Ak.transpose() * Ak).inverse();
  };
  fit();
  // Backward elimination of the extended diagnoses that the data do not
  // show: each costs the classic ones precision (radial play shares cos 2phi
  // with scale mismatch), so one below the threshold is dropped, the least
  // significant first, and the fit repeated. A cyclic error is judged by its
  // two components together (Mahalanobis norm).
  std::vector<double> dropped_v, dropped_s;
  if (o.significance > 0) {
    for (;;) {
      double worst = std::numeric_limits<double>::infinity();
      int at = -1;
      for (size_t j = 0; j < keep.size(); ++j) {
        if (keep[j] < n_base) continue;
        const std::string& nm = names[keep[j]];
        double z;
        if (nm.rfind("cyclic_error", 0) == 0) {
          if (nm.back() == 'n') continue;
          const Eigen::Vector2d v(x[j], x[j + 1]);
          const Eigen::Matrix2d c = cov.block<2, 2>(j, j);
          z = std::sqrt(std::max(0.0, v.dot(c.ldlt().solve(v))));
        } else {
          z = std::abs(x[j]) / std::max(std::sqrt(std::max(cov(j, j), 0.0)), 1e-300);
        }
        if (z < worst) {
          worst = z;
          at = static_cast<int>(j);
        }
      }
      if (at < 0 || worst >= o.significance) break;
      const std::string& nm = names[keep[at]];
      const bool is_cyc = nm.rfind("cyclic_error", 0) == 0;
      const double sd_at = std::sqrt(std::max(cov(at, at), 0.0));
      dropped_v.push_back(is_cyc ? std::hypot(x[at], x[at + 1]) : std::abs(x[at]));
      dropped_s.push_back(is_cyc ? std::max(sd_at, std::sqrt(std::max(cov(at + 1, at + 1), 0.0))) : sd_at);
      d.dropped_names.push_back(is_cyc ? nm.substr(0, nm.size() - 4) : nm);
      std::ostringstream m;
      m.precision(2);
      m << (is_cyc ? nm.substr(0, nm.size() - 4) : nm) << " (" << worst << " sigma)";
      d.not_significant.push_back(m.str());
      keep.erase(keep.begin() + at, keep.begin() + at + (is_cyc ? 2 : 1));
      fit();
    }
  }
  d.dropped_values = Eigen::Map<Eigen::VectorXd>(dropped_v.data(), dropped_v.size());
  d.dropped_std = Eigen::Map<Eigen::VectorXd>(dropped_s.data(), dropped_s.size());
  d.rms = std::sqrt(res_v.squaredNorm() / total);
  for (size_t j = 0; j < keep.size(); ++j) d.names.push_back(names[keep[j]]);
  d.values = x;
  d.std = cov.diagonal().cwiseMax(0.0).cwiseSqrt();

  // Ranking: the circular deviation of each fitted term alone.
  std::vector<std::pair<double, std::string>> contrib;
  for (size_t j = 0; j < keep.size(); ++j) {
    const std::string& nm = names[keep[j]];
    if (nm == "radius" || nm.rfind("centre", 0) == 0) continue;
    const bool is_cyc = nm.rfind("cyclic_error", 0) == 0;
    if (is_cyc && nm.back() == 'n') continue;
    Eigen::VectorXd t = Ak.col(j) * x[j];
    if (is_cyc) t += Ak.col(j + 1) * x[j + 1];
    double worst = 0.0;
    for (size_t k = 0; k < runs.size(); ++k) {
      std::vector<int> rows;
      for (int i = 0; i < total; ++i)
        if (run_of[i] == static_cast<int>(k)) rows.push_back(i);
      Eigen::MatrixXd B(rows.size(), 3);
      Eigen::VectorXd tk(rows.size());
      for (size_t i = 0; i < rows.size(); ++i) {
        B.row(i) << A(rows[i], 0), A(rows[i], 1), A(rows[i], 2);
        tk[i] = t[rows[i]];
      }
      // About the term's own least-squares circle (first order), as G is.
      const Eigen::VectorXd r = tk - B * B.colPivHouseholderQr().solve(tk);
      worst = std::max(worst, r.maxCoeff() - r.minCoeff());
    }
    contrib.emplace_back(worst, is_cyc ? nm.substr(0, nm.size() - 4) : nm);
  }
  std::stable_sort(contrib.begin(), contrib.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  d.contribution.resize(contrib.size());
  for (size_t j = 0; j < contrib.size(); ++j) {
    d.ranking.push_back(contrib[j].second);
    d.contribution[j] = contrib[j].first;
  }
  for (const CircularRunResult& r : res.runs) d.circularity = std::max(d.circularity, r.circular_deviation);
  d.contribution_percent = d.circularity > 0 ? Eigen::VectorXd(d.contribution * (100.0 / d.circularity))
                                             : Eigen::VectorXd::Zero(d.contribution.size());
  // backlash.k: the mean of its two ends, for comparison with one E11b.
  std::vector<double> dv, ds;
  for (int ax = 1; ax <= 2; ++ax) {
    const std::string b = "backlash." + std::to_string(ax);
    const auto p = std::find(d.names.begin(), d.names.end(), b + "+");
    const auto m = std::find(d.names.begin(), d.names.end(), b + "-");
    if (p == d.names.end() || m == d.names.end()) continue;
    const Eigen::Index ip = p - d.names.begin(), im = m - d.names.begin();
    d.derived_names.push_back(b);
    dv.push_back(0.5 * (x[ip] + x[im]));
    ds.push_back(0.5 * std::sqrt(std::max(0.0, cov(ip, ip) + cov(im, im) + 2.0 * cov(ip, im))));
  }
  d.derived_values = Eigen::Map<Eigen::VectorXd>(dv.data(), dv.size());
  d.derived_std = Eigen::Map<Eigen::VectorXd>(ds.data(), ds.size());
  (void)feed;  // the feed only converts servo_mismatch to a time (dtau = l / v), done by callers
  res.cyclic_pitch1 = o.cyclic_pitch1;
  res.cyclic_pitch2 = o.cyclic_pitch2;
  return res;
}

// The pitch (mm) of the strongest periodic error of plane axis `axis` and the
// number of frequencies tried (options.search_cyclic_pitch1 in the header).
std::pair<double, int> SearchCyclicPitch(const std::vector<CircularRun>& runs, double R, int axis, double feed,
                                         const CircularDiagnosisOptions& options) {
  std::vector<double> x, proj, rest;
  double spacing = 0.0;
  for (const CircularRun& r : runs) {
    const Eigen::MatrixXd B = HarmonicBasis(r.angles, 8);
    // minimum norm, so a run with fewer samples than shape terms leaves no remainder
    const Eigen::VectorXd coef = B.completeOrthogonalDecomposition().solve(r.readings);
    const Eigen::VectorXd res = r.readings - B * coef;
    for (int i = 0; i < r.angles.size(); ++i) {
      const double phi = r.angles[i] * kRad, p = axis == 1 ? std::cos(phi) : std::sin(phi);
      if (i > 0) spacing = std::max(spacing, std::abs(R * p - x.back()));
      x.push_back(R * p);
      proj.push_back(p);
      rest.push_back(res[i]);
    }
  }
  const double p_min = 4.0 * spacing, p_max = R / 2.0;
  if (!(p_min < p_max)) {
    char buf[320];
    std::snprintf(buf, sizeof buf,
                  "cyclic_pitch auto: the samples are %.3g mm apart along the axis; too sparse to find a "
                  "pitch below R/2 = %g mm (sample more densely or give the pitch)",
                  spacing, p_max);
    throw std::invalid_argument(buf);
  }
  // The grid numpy.arange(1/p_max, 1/p_min + df, df) builds: the same
  // frequencies as the Python this replaced, so the same one wins a near tie.
  const double df = 1.0 / (16.0 * R), f0 = 1.0 / p_max, f1 = 1.0 / p_min + df;
  const int n_tried = static_cast<int>(std::ceil((f1 - f0) / df));
  const double delta = (f0 + df) - f0;
  const double two_pi = 2.0 * 3.14159265358979323846;
  const size_t n = x.size();
  double best = f0, power = -1.0;
  for (int j = 0; j < n_tried; ++j) {
    const double f = f0 + j * delta;
    double cc = 0, ss = 0, cs = 0, cr = 0, sr = 0;
    for (size_t i = 0; i < n; ++i) {
      const double arg = two_pi * (f * x[i]);
      const double c = proj[i] * std::cos(arg), sn = proj[i] * std::sin(arg);
      cc += c * c;
      ss += sn * sn;
      cs += c * sn;
      cr += c * rest[i];
      sr += sn * rest[i];
    }
    const double det = cc * ss - cs * cs;
    const double pw = det > 0 ? (ss * cr * cr - 2 * cs * cr * sr + cc * sr * sr) / det : 0.0;
    if (pw > power) {
      power = pw;
      best = f;
    }
  }
  CircularDiagnosisOptions o = options;
  o.search_cyclic_pitch1 = o.search_cyclic_pitch2 = false;
  o.significance = 0.0;
  double best_rms = std::numeric_limits<double>::infinity(), pitch = 1.0 / best;
  // numpy.linspace(best - df, best + df, 9), as the Python this replaced
  const double lo = best - df, step = ((best + df) - lo) / 8.0;
  for (int i = 0; i < 9; ++i) {
    const double f = i == 8 ? best + df : lo + i * step;
    if (!(f > 0)) continue;
    o.cyclic_pitch1 = axis == 1 ? 1.0 / f : 0.0;
    o.cyclic_pitch2 = axis == 2 ? 1.0 / f : 0.0;
    const double rms = AnalyzeGivenPitches(runs, R, feed, o).diagnosis.rms;
    if (rms < best_rms) {
      best_rms = rms;
      pitch = 1.0 / f;
    }
  }
  return {pitch, n_tried};
}

}  // namespace

CircularTestResult AnalyzeCircularTest(const std::vector<CircularRun>& runs, double R, double feed,
                                       const CircularDiagnosisOptions& options) {
  const bool search[2] = {options.search_cyclic_pitch1, options.search_cyclic_pitch2};
  if (!search[0] && !search[1]) return AnalyzeGivenPitches(runs, R, feed, options);
  if (runs.empty() || runs.size() > 2)
    throw std::invalid_argument("circular test: give one or two runs (CW and CCW), got " +
                                std::to_string(runs.size()));
  if (!(R > 0) || !std::isfinite(R))
    throw std::invalid_argument("circular test: nominal radius must be > 0 mm");
  for (size_t k = 0; k < runs.size(); ++k) ValidateRun(runs[k], static_cast<int>(k));
  CircularDiagnosisOptions o = options;
  o.search_cyclic_pitch1 = o.search_cyclic_pitch2 = false;
  double* pitch[2] = {&o.cyclic_pitch1, &o.cyclic_pitch2};
  int tried[2] = {0, 0};
  for (int k = 0; k < 2; ++k)
    if (search[k]) std::tie(*pitch[k], tried[k]) = SearchCyclicPitch(runs, R, k + 1, feed, options);
  CircularTestResult res = AnalyzeGivenPitches(runs, R, feed, o);
  std::vector<std::string> dropped;
  if (options.significance > 0) {
    CircularDiagnosisOptions all = o;
    all.significance = 0.0;
    const CircularDiagnosis d = AnalyzeGivenPitches(runs, R, feed, all).diagnosis;
    const double tail = std::erfc(options.significance / std::sqrt(2.0));
    for (int k = 0; k < 2; ++k) {
      if (!search[k]) continue;
      const std::string c = "cyclic_error." + std::to_string(k + 1);
      double z = 0.0;
      if (d.Has(c + ".cos")) {
        double v[2], s[2];
        for (int j = 0; j < 2; ++j) {
          const std::string nm = c + (j == 0 ? ".cos" : ".sin");
          const size_t at = std::find(d.names.begin(), d.names.end(), nm) - d.names.begin();
          v[j] = d.values[at];
          s[j] = d.std[at];
        }
        z = std::hypot(v[0] / s[0], v[1] / s[1]);
      }
      const double need = std::sqrt(-2.0 * std::log(tail / tried[k]));
      if (z < need) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "%s (pitch %.4g mm searched among %d: %.2g sigma, %.2g needed)",
                      c.c_str(), *pitch[k], tried[k], z, need);
        dropped.push_back(buf);
        *pitch[k] = 0.0;
      }
    }
    if (!dropped.empty()) res = AnalyzeGivenPitches(runs, R, feed, o);
  }
  auto& ns = res.diagnosis.not_significant;
  ns.insert(ns.end(), dropped.begin(), dropped.end());
  res.cyclic_pitches_tried1 = tried[0];
  res.cyclic_pitches_tried2 = tried[1];
  return res;
}

double DiagnosisContribution(const std::string& name, double value, double R,
                             const CircularDiagnosisOptions& options) {
  if (!(R > 0) || !std::isfinite(R))
    throw std::invalid_argument("diagnosis contribution: nominal radius must be > 0 mm");
  if (!std::isfinite(value))
    throw std::invalid_argument("diagnosis contribution: " + name + ": value is not finite");
  // A cyclic error's value is its amplitude: the .cos column carries it.
  const std::string col = name.rfind("cyclic_error", 0) == 0 && name.size() == 14 ? name + ".cos" : name;
  CircularDiagnosisOptions o = options;
  if (col.rfind("cyclic_error.1", 0) == 0 && !(o.cyclic_pitch1 > 0)) o.cyclic_pitch1 = R / 10.0;
  if (col.rfind("cyclic_error.2", 0) == 0 && !(o.cyclic_pitch2 > 0)) o.cyclic_pitch2 = R / 10.0;
  if (col == "radius" || col.rfind("centre", 0) == 0) return 0.0;
  // Dense enough for a reversal spike of spike_width and a cyclic pitch of R / 10.
  const int n = 7200;
  double worst = 0.0;
  for (int s : {1, -1}) {
    Eigen::MatrixXd B(n, 3);
    Eigen::VectorXd t(n);
    for (int i = 0; i < n; ++i) {
      const double deg = s * 360.0 * i / n, phi = deg * kRad;
      B.row(i) << 1.0, std::cos(phi), std::sin(phi);
      t[i] = value * TermColumn(col, deg, s, R, o);
    }
    const Eigen::VectorXd r = t - B * B.colPivHouseholderQr().solve(t);
    worst = std::max(worst, r.maxCoeff() - r.minCoeff());
  }
  return worst;
}

Eigen::VectorXd CompensateBarTemperature(const Eigen::VectorXd& readings, double L, const BarThermal& th) {
  const std::string w = "thermal compensation: ";
  if (!(L > 0) || !std::isfinite(L)) throw std::invalid_argument(w + "nominal length must be > 0 mm");
  auto alpha = [&](double a, const char* field) {
    if (!std::isfinite(a) || std::abs(a) > 1e-4) {
      std::ostringstream m;
      m << w << field << " = " << a << " /K; a thermal expansion coefficient is a few 1e-6 /K "
        << "(steel 11.5e-6, invar 1e-6): give it in 1/K, not ppm/K";
      throw std::invalid_argument(m.str());
    }
  };
  auto temp = [&](double t, const char* field) {
    if (!std::isfinite(t) || t < -20.0 || t > 60.0) {
      std::ostringstream m;
      m << w << field << " = " << t << " deg C; expected -20 .. 60 deg C (a workshop temperature in deg C)";
      throw std::invalid_argument(m.str());
    }
  };
  alpha(th.alpha_bar, "bar expansion coefficient");
  alpha(th.alpha_machine, "machine expansion coefficient");
  temp(th.t_bar, "bar temperature");
  temp(th.t_machine, "machine temperature");
  temp(th.t_ref, "reference temperature");
  const double bar = L * (1.0 + th.alpha_bar * (th.t_bar - th.t_ref));
  const double scale = 1.0 + th.alpha_machine * (th.t_machine - th.t_ref);
  Eigen::VectorXd out(readings.size());
  for (Eigen::Index i = 0; i < readings.size(); ++i) {
    if (!std::isfinite(readings[i]))
      throw std::invalid_argument(w + "readings[" + std::to_string(i) + "] is not finite");
    out[i] = (bar + readings[i]) / scale - L;
  }
  return out;
}

Eigen::MatrixXd TraceHarmonics(const Eigen::VectorXd& angles_deg, const Eigen::VectorXd& values,
                               int max_order) {
  if (angles_deg.size() != values.size())
    throw std::invalid_argument("trace harmonics: angles and values differ in length");
  if (max_order < 0) throw std::invalid_argument("trace harmonics: max_order must be >= 0");
  const int n = static_cast<int>(values.size()), p = 2 * max_order + 1;
  if (n < p)
    throw std::invalid_argument("trace harmonics: " + std::to_string(n) + " samples cannot carry " +
                                std::to_string(max_order) + " harmonics");
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(angles_deg[i]) || !std::isfinite(values[i]))
      throw std::invalid_argument("trace harmonics: sample " + std::to_string(i) + " is not finite");
  const Eigen::VectorXd x = HarmonicBasis(angles_deg, max_order).colPivHouseholderQr().solve(values);
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(max_order + 1, 2);
  out(0, 0) = x[0];
  for (int k = 1; k <= max_order; ++k) out.row(k) << x[2 * k - 1], x[2 * k];
  return out;
}

}  // namespace fivecal
