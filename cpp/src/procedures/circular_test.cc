#include "fivecal/procedures/circular_test.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>

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

}  // namespace

double CircularDiagnosis::Get(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return values[i];
  throw std::invalid_argument("circular diagnosis: '" + name + "' was not fitted");
}

bool CircularDiagnosis::Has(const std::string& name) const {
  return std::find(names.begin(), names.end(), name) != names.end();
}

CircularTestResult AnalyzeCircularTest(const std::vector<CircularRun>& runs, double R, double feed) {
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

  // Diagnosis: columns as documented in the header.
  int total = 0;
  for (const CircularRun& r : runs) total += static_cast<int>(r.angles.size());
  std::vector<std::string> names = {"radius", "centre.1", "centre.2", "scale_mismatch", "squareness",
                                    "servo_mismatch", "backlash.1", "backlash.2"};
  Eigen::MatrixXd A(total, names.size());
  Eigen::VectorXd y(total);
  int row = 0;
  for (size_t k = 0; k < runs.size(); ++k) {
    const double s = dirs[k];
    for (int i = 0; i < runs[k].angles.size(); ++i, ++row) {
      const double phi = runs[k].angles[i] * kRad, c = std::cos(phi), sn = std::sin(phi);
      // Motion signs on the circle x1 = R cos phi, x2 = R sin phi traversed in direction s.
      const double v1 = -s * Sgn(sn), v2 = s * Sgn(c);
      A.row(row) << 1.0, c, sn, 0.5 * R * std::cos(2 * phi), -0.5 * R * std::sin(2 * phi),
          0.5 * s * std::sin(2 * phi), c * v1, sn * v2;
      y[row] = runs[k].readings[i];
    }
  }
  CircularDiagnosis& d = res.diagnosis;
  std::vector<int> keep;
  for (size_t j = 0; j < names.size(); ++j) {
    if (names[j] == "servo_mismatch" && runs.size() < 2) {
      d.not_fitted.push_back("servo_mismatch (needs a CW and a CCW run: with one direction it cannot be told from squareness)");
      continue;
    }
    if (names[j].rfind("backlash", 0) == 0) {
      // The motion sign must take both values inside the data.
      const int col = static_cast<int>(j);
      bool pos = false, neg = false;
      for (int i = 0; i < total; ++i) {
        const double basis = names[j] == "backlash.1" ? A(i, 1) : A(i, 2);  // cos / sin phi
        if (std::abs(basis) < 1e-9) continue;
        const double sign = A(i, col) / basis;
        pos |= sign > 0.5;
        neg |= sign < -0.5;
      }
      if (!(pos && neg)) {
        d.not_fitted.push_back(names[j] + " (the axis never reverses inside the data)");
        continue;
      }
    }
    keep.push_back(static_cast<int>(j));
  }
  Eigen::MatrixXd Ak(total, keep.size());
  for (size_t j = 0; j < keep.size(); ++j) Ak.col(j) = A.col(keep[j]);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Ak);
  if (qr.rank() < static_cast<int>(keep.size()))
    throw std::invalid_argument("circular test: the samples cover too little of the circle to separate "
                                "centre offset, scale mismatch, squareness and backlash");
  const Eigen::VectorXd x = qr.solve(y);
  const Eigen::VectorXd res_v = y - Ak * x;
  d.rms = std::sqrt(res_v.squaredNorm() / total);
  const int dof = std::max(1, total - static_cast<int>(keep.size()));
  const double s2 = res_v.squaredNorm() / dof;
  const Eigen::MatrixXd cov = s2 * (Ak.transpose() * Ak).inverse();
  for (size_t j = 0; j < keep.size(); ++j) d.names.push_back(names[keep[j]]);
  d.values = x;
  d.std = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  (void)feed;  // the feed only converts servo_mismatch to a time (dtau = l / v), done by callers
  return res;
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
  Eigen::MatrixXd A(n, p);
  for (int i = 0; i < n; ++i) {
    const double phi = angles_deg[i] * kRad;
    A(i, 0) = 1.0;
    for (int k = 1; k <= max_order; ++k) {
      A(i, 2 * k - 1) = std::cos(k * phi);
      A(i, 2 * k) = std::sin(k * phi);
    }
  }
  const Eigen::VectorXd x = A.colPivHouseholderQr().solve(values);
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(max_order + 1, 2);
  out(0, 0) = x[0];
  for (int k = 1; k <= max_order; ++k) out.row(k) << x[2 * k - 1], x[2 * k];
  return out;
}

}  // namespace fivecal
