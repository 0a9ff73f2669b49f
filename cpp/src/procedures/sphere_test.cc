#include "fivecal/procedures/sphere_test.h"

#include <Eigen/Dense>
#include <cmath>
#include <set>
#include <stdexcept>

#include "fivecal/design/design.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

// Machine parameter vector from a name -> value map. Setup parameters of an
// identification result (facet.F1, sphere.S1.x, dbb.A1.length, ...) are
// ignored, so a result's values can be passed whole; any other name must be
// a parameter of the machine: a typo (tpi.x, EX0C.x, EXOC) is refused with a
// did-you-mean instead of leaving the model nominal without a word.
Eigen::VectorXd MachineTheta(const Machine& m, const std::map<std::string, double>& values) {
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  for (const auto& [name, v] : values) {
    if (m.ParameterIndex(name) < 0 && IsSetupParameterName(name)) continue;
    int k;
    try {
      k = m.RequireParameter(name);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("values." + name + ": " + e.what());
    }
    RequireFinite(v, "values." + name);
    theta[k] = v;
  }
  return theta;
}

}  // namespace

std::vector<Eigen::Vector3d> SpherePoints(const std::vector<std::pair<double, int>>& rings_in,
                                          const Eigen::Vector3d& pole_in) {
  std::vector<std::pair<double, int>> rings = rings_in;
  if (rings.empty()) rings = {{0.0, 12}, {30.0, 8}, {-30.0, 8}, {60.0, 4}, {90.0, 1}};
  const Eigen::Vector3d w = UnitDirection(pole_in, "sphere_points: pole");
  const Eigen::Vector3d ref = std::abs(w.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d u = (ref - w * w.dot(ref)).normalized();
  const Eigen::Vector3d v = w.cross(u);
  std::vector<Eigen::Vector3d> out;
  for (size_t i = 0; i < rings.size(); ++i) {
    const double lat = rings[i].first;
    const int count = rings[i].second;
    const std::string where = "sphere_points.rings[" + std::to_string(i) + "]";
    if (!(std::abs(lat) <= 90.0)) throw std::invalid_argument(where + ": latitude must be within +-90 deg");
    if (count < 1) throw std::invalid_argument(where + ": count must be >= 1");
    const double phi = lat * M_PI / 180.0;
    if (std::abs(std::abs(lat) - 90.0) < 1e-12) {
      out.push_back(lat > 0 ? w : Eigen::Vector3d(-w));
      continue;
    }
    for (int k = 0; k < count; ++k) {
      const double az = 2.0 * M_PI * k / count;
      out.push_back(std::cos(phi) * (std::cos(az) * u + std::sin(az) * v) + std::sin(phi) * w);
    }
  }
  return out;
}

SphereFit FitSphere(const Eigen::MatrixXd& P, int max_iterations, double tolerance) {
  const int n = static_cast<int>(P.rows());
  if (P.cols() != 3) throw std::invalid_argument("fit_sphere: points must be N x 3");
  if (n < 4) throw std::invalid_argument("fit_sphere: need at least 4 points, got " + std::to_string(n));
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) RequireFinite(P(i, c), "fit_sphere: point " + std::to_string(i));
  // Algebraic start: |p|^2 = 2 c.p + (R^2 - |c|^2), linear in (c, k).
  const Eigen::Vector3d mean = P.colwise().mean().transpose();
  Eigen::MatrixXd A(n, 4);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = P.row(i).transpose() - mean;
    A.row(i) << 2 * p.x(), 2 * p.y(), 2 * p.z(), 1.0;
    b[i] = p.squaredNorm();
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  if (qr.rank() < 4) throw std::invalid_argument("fit_sphere: degenerate points (coplanar or repeated)");
  const Eigen::Vector4d s = qr.solve(b);
  SphereFit f;
  f.center = mean + s.head<3>();
  f.radius = std::sqrt(std::max(s[3] + s.head<3>().squaredNorm(), 0.0));

  // Gauss-Newton on e_i = |P_i - c| - R.
  Eigen::MatrixXd J(n, 4);
  Eigen::VectorXd e(n);
  auto residuals = [&](const Eigen::Vector3d& c, double R, bool jac) {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d d = P.row(i).transpose() - c;
      const double dist = d.norm();
      e[i] = dist - R;
      if (jac) {
        const Eigen::Vector3d u = dist > 0 ? Eigen::Vector3d(d / dist) : Eigen::Vector3d::Zero();
        J.row(i) << -u.x(), -u.y(), -u.z(), -1.0;
      }
    }
  };
  for (f.iterations = 0; f.iterations < max_iterations;) {
    residuals(f.center, f.radius, true);
    const Eigen::Vector4d step = J.colPivHouseholderQr().solve(-e);
    f.center += step.head<3>();
    f.radius += step[3];
    ++f.iterations;
    if (step.norm() < tolerance * std::max(1.0, f.radius)) {
      f.converged = true;
      break;
    }
  }
  residuals(f.center, f.radius, false);
  f.residuals = e;
  f.max_residual = e.maxCoeff();
  f.min_residual = e.minCoeff();
  f.out_of_sphericity = f.max_residual - f.min_residual;
  const double m = e.mean();
  f.std_residual = n > 1 ? std::sqrt((e.array() - m).square().sum() / (n - 1)) : 0.0;
  f.rms = std::sqrt(e.squaredNorm() / n);
  return f;
}

SphereCentreFit FitSphereCentre(const Eigen::MatrixXd& P, double radius, const Eigen::Vector3d& start,
                                int max_iterations, double tolerance) {
  const std::string w = "fit_sphere_centre";
  const int n = static_cast<int>(P.rows());
  if (P.cols() != 3) throw std::invalid_argument(w + ": points must be N x 3");
  if (n < 3)
    throw std::invalid_argument(w + ": points: need at least 3 for a centre of known radius, got " +
                                std::to_string(n));
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) RequireFinite(P(i, c), w + ": points[" + std::to_string(i) + "]");
  if (!(radius > 0) || !std::isfinite(radius))
    throw std::invalid_argument(w + ": radius must be a finite length > 0 mm");
  for (int c = 0; c < 3; ++c) RequireFinite(start[c], w + ": start");
  if (max_iterations < 1) throw std::invalid_argument(w + ": max_iterations must be >= 1");
  if (!(tolerance > 0)) throw std::invalid_argument(w + ": tolerance must be > 0 mm");
  SphereCentreFit f;
  f.center = start;
  Eigen::MatrixXd J(n, 3);
  Eigen::VectorXd e(n);
  auto residuals = [&](bool jac) {
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d d = P.row(i).transpose() - f.center;
      const double dist = d.norm();
      if (jac && !(dist > 0))
        throw std::invalid_argument(w + ": points[" + std::to_string(i) +
                                    "] sits on the centre; the points do not determine it");
      e[i] = dist - radius;
      if (jac) J.row(i) = -(d / dist).transpose();
    }
  };
  for (f.iterations = 0; f.iterations < max_iterations;) {
    residuals(true);
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(J);
    if (qr.rank() < 3)
      throw std::invalid_argument(w + ": points do not determine the centre (all on one line through it)");
    const Eigen::Vector3d step = qr.solve(-e);
    f.center += step;
    ++f.iterations;
    if (step.cwiseAbs().maxCoeff() < tolerance) {
      f.converged = true;
      break;
    }
  }
  residuals(false);
  f.residuals = e;
  f.rms = std::sqrt(e.squaredNorm() / n);
  return f;
}

Eigen::MatrixXd TablePoints(const Dataset& given_ds, const std::map<std::string, double>& values,
                            const std::vector<int>& indices) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const Machine& m = ds.machine();
  const Eigen::VectorXd theta = MachineTheta(m, values);
  const Eigen::Vector3d tip = TipWithOffsets<double>(m, theta.data());
  Eigen::MatrixXd out(indices.size(), 3);
  std::vector<double> q(m.num_axes());
  std::vector<int> dir(m.num_axes());
  for (size_t k = 0; k < indices.size(); ++k) {
    const int i = indices[k];
    if (i < 0 || i >= static_cast<int>(ds.observations.size()))
      throw std::invalid_argument("table_points: observation index " + std::to_string(i) + " out of range");
    const Observation& o = ds.observations[i];
    AxisValuesToInternal(m, o.axes.data(), q.data());
    for (int a = 0; a < m.num_axes(); ++a) dir[a] = o.direction.size() ? o.direction[a] : 0;
    Eigen::Vector3d p;
    ToolInWorkpiece<double>(m, theta.data(), q.data(), dir.data(), tip, &p);
    out.row(k) = p.transpose();
  }
  return out;
}

std::string SphereTestResult::ToJson() const {
  json j;
  j["sphere"] = sphere;
  j["n_points"] = observations.size();
  j["center"] = Array3(fit.center);
  j["radius"] = fit.radius;
  j["size_error"] = size_error;
  j["out_of_sphericity"] = fit.out_of_sphericity;
  j["max_residual"] = fit.max_residual;
  j["min_residual"] = fit.min_residual;
  j["std_residual"] = fit.std_residual;
  j["rms"] = fit.rms;
  j["converged"] = fit.converged;
  j["iterations"] = fit.iterations;
  return j.dump();
}

SphereTestResult SphereTest(const Dataset& given_ds, const std::string& sphere,
                            const std::map<std::string, double>& values) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  ds.Validate();
  std::set<std::string> touched;
  for (const Observation& o : ds.observations)
    if (o.type == ObservationType::kSphere) touched.insert(o.data<TouchData>().target);
  SphereTestResult r;
  r.sphere = sphere;
  if (r.sphere.empty()) {
    if (touched.size() != 1)
      throw std::invalid_argument("sphere_test: the dataset touches " + std::to_string(touched.size()) +
                                  " spheres; name the one to test");
    r.sphere = *touched.begin();
  }
  const int si = ds.artefact.SphereIndex(r.sphere);
  if (si < 0) throw std::invalid_argument("sphere_test: no sphere '" + r.sphere + "' in the artefact");
  for (int i = 0; i < static_cast<int>(ds.observations.size()); ++i) {
    const Observation& o = ds.observations[i];
    if (o.type == ObservationType::kSphere && o.data<TouchData>().target == r.sphere) r.observations.push_back(i);
  }
  if (r.observations.size() < 4)
    throw std::invalid_argument("sphere_test: sphere '" + r.sphere + "' has " +
                                std::to_string(r.observations.size()) + " touches; at least 4 are needed");
  r.points = TablePoints(ds, values, r.observations);
  r.fit = FitSphere(r.points);
  r.size_error = r.fit.radius - (ds.artefact.spheres[si].radius + ds.tip_radius);
  return r;
}

std::vector<SensitivityRow> SphereSensitivity(const Dataset& setup, const std::string& plan_json,
                                              const std::string& sphere, const std::vector<std::string>& names,
                                              const std::map<std::string, double>& values,
                                              double characteristic_length) {
  const Machine& m = setup.machine();
  if (!(characteristic_length > 0)) throw std::invalid_argument("sphere_sensitivity: characteristic_length must be > 0");
  for (const auto& [name, v] : values) {
    m.RequireParameter(name);
    RequireFinite(v, "sphere_sensitivity.values." + name);
  }
  const json base = json::parse(setup.ToJson());
  json spec = {{"machine", base["machine"]},
               {"probe", base["probe"]},
               {"artefact", base["artefact"]},
               {"plan", Parse(plan_json, "sphere_sensitivity.plan")}};
  std::vector<SensitivityRow> rows;
  std::vector<std::string> all = {""};
  all.insert(all.end(), names.begin(), names.end());
  for (const std::string& name : all) {
    SensitivityRow row;
    row.name = name;
    json errors = json::object();
    if (!name.empty()) {
      m.RequireParameter(name);
      auto it = values.find(name);
      row.value = it != values.end() ? it->second
                                     : 1e-3 / CharacteristicScale(m, name, characteristic_length);
      errors[name] = row.value;
    }
    spec["errors"] = errors;
    const Dataset ds = Simulate(spec.dump());
    const SphereTestResult t = SphereTest(ds, sphere, {});
    row.size_error = t.size_error;
    row.out_of_sphericity = t.fit.out_of_sphericity;
    row.max_residual = t.fit.max_residual;
    row.min_residual = t.fit.min_residual;
    rows.push_back(row);
  }
  return rows;
}

}  // namespace fivecal
