#include "fivecal/controllers/vendor.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "fivecal/controllers/fanuc.h"
#include "fivecal/controllers/siemens.h"
#include "fivecal/controllers/heidenhain.h"
#include "fivecal/controllers/beckhoff.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {

const std::vector<const ControllerVendor*>& ControllerVendors() {
  // THE list of controller vendors: one line per vendor (vendor.h).
  static const SiemensVendor siemens;
  static const std::vector<const ControllerVendor*> vendors = {
      &Fanuc(),
      &siemens,
      &HeidenhainVendor(),
      &BeckhoffVendor(),
  };
  return vendors;
}

const ControllerVendor& FindVendor(const std::string& name) {
  std::string all;
  for (const ControllerVendor* v : ControllerVendors()) {
    if (v->Name() == name) return *v;
    all += (all.empty() ? "" : ", ") + v->Name();
  }
  throw std::invalid_argument("controller: '" + name + "' (expected one of " +
                              (all.empty() ? std::string("none registered") : all) + ")");
}

namespace {

AbsorbOptions OptionsOf(const VendorModel& vm) {
  AbsorbOptions o;
  o.directions = vm.directions;
  o.tool_length = vm.tool_length;
  return o;
}

Eigen::VectorXd CheckedMap(const ControllerVendor& vendor, const Machine& m, const KinematicsTable& t,
                           const VendorOptions& o, size_t expected) {
  Eigen::VectorXd v = vendor.Map(m, t, o);
  if (size_t(v.size()) != expected)
    throw std::logic_error("controller " + vendor.Name() + ": Map gave " + std::to_string(v.size()) +
                           " values, Values names " + std::to_string(expected));
  if (!v.allFinite()) throw std::invalid_argument("controller " + vendor.Name() + ": a value is not finite");
  return v;
}

// Controller-frame points (vendor.h, ToolPoints) in the part frame of `t`.
Eigen::MatrixXd InPartFrame(const KinematicsTable& t, const Eigen::MatrixXd& points) {
  if (points.cols() != 3) throw std::logic_error("controller ToolPoints: expected N x 3 points");
  return (points.rowwise() - t.part_origin.transpose()) * t.part_rotation;
}

}  // namespace

VendorExport ExportToVendor(const Machine& m, const ControllerVendor& vendor, const Eigen::VectorXd& theta_e,
                            const Eigen::MatrixXd& theta_covariance, const Eigen::MatrixXd& poses,
                            const VendorOptions& options, const Eigen::VectorXd& old_values) {
  const int nt = m.num_parameters();
  const bool have_cov = theta_covariance.size() > 0;
  if (have_cov && (theta_covariance.rows() != nt || theta_covariance.cols() != nt))
    throw std::invalid_argument("covariance: expected " + std::to_string(nt) + " x " + std::to_string(nt) +
                                " (the machine's parameters), got " + std::to_string(theta_covariance.rows()) +
                                " x " + std::to_string(theta_covariance.cols()));
  if (have_cov && !theta_covariance.allFinite()) throw std::invalid_argument("covariance: not all finite");

  VendorExport ex;
  ex.vendor = vendor.Name();
  ex.model = vendor.Model(m, options);
  ex.values = vendor.Values(m, options);
  const size_t nv = ex.values.size();
  // A vendor that takes the error motions as they are (MapMotions: tables)
  // gets them; its kinematics absorb the rest, never both.
  const Eigen::VectorXd motions = vendor.MapMotions(m, theta_e, options);
  const bool takes_motions = motions.size() > 0;
  if (takes_motions && size_t(motions.size()) != nv)
    throw std::logic_error("controller " + vendor.Name() + ": MapMotions gave " + std::to_string(motions.size()) +
                           " values, Values names " + std::to_string(nv));
  std::vector<int> motion_params;
  Eigen::VectorXd theta_k = theta_e, theta_m = Eigen::VectorXd::Zero(nt);
  if (takes_motions)
    for (int i = 0; i < nt; ++i)
      if (m.parameters()[size_t(i)].kind == ParameterKind::kMotion) {
        motion_params.push_back(i);
        theta_m[i] = theta_e[i];
        theta_k[i] = 0;
      }
  ex.absorption = Absorb(m, ex.model.model, theta_k, poses, OptionsOf(ex.model));
  const Absorption& ab = ex.absorption;

  const Eigen::VectorXd nominal = CheckedMap(vendor, m, MakeKinematicsTable(m, Eigen::VectorXd::Zero(nt)),
                                             options, nv);
  const Eigen::VectorXd absorbed = CheckedMap(vendor, m, MakeKinematicsTable(m, ab.theta), options, nv);
  ex.change = absorbed - nominal;
  if (takes_motions) ex.change += motions;
  for (size_t i = 0; i < nv; ++i)
    if (ex.values[i].fixed && ex.change[Eigen::Index(i)] != 0.0)
      throw std::logic_error("controller " + vendor.Name() + ": fixed value " + ex.values[i].name +
                             " changed with the errors");
  if (old_values.size() > 0) {
    if (size_t(old_values.size()) != nv)
      throw std::invalid_argument("old values: expected " + std::to_string(nv) + " (" + vendor.Name() +
                                  "'s values), got " + std::to_string(old_values.size()));
    if (!old_values.allFinite()) throw std::invalid_argument("old values: not all finite");
    for (size_t i = 0; i < nv; ++i)
      if (ex.values[i].fixed && old_values[Eigen::Index(i)] != nominal[Eigen::Index(i)])
        throw std::invalid_argument("old values: " + ex.values[i].name + " is " +
                                    std::to_string(old_values[Eigen::Index(i)]) + " but the machine file's " +
                                    "topology needs " + std::to_string(nominal[Eigen::Index(i)]) +
                                    " (is the machine file the controller's machine?)");
    ex.old_values = old_values;
  } else {
    ex.old_values = nominal;
  }
  ex.old_minus_nominal = ex.old_values - nominal;
  ex.new_values = ex.old_values + ex.change;

  // Covariance of the change: G = d Map(table(B phi)) / d phi by central
  // differences (Map is closed-form and smooth; steps far above rounding, far
  // below the curvature), times d phi / d theta_e from the absorption.
  const Eigen::Index k = Eigen::Index(ab.parameters.size());
  Eigen::MatrixXd G = Eigen::MatrixXd::Zero(Eigen::Index(nv), k);
  for (Eigen::Index c = 0; c < k; ++c) {
    const double h = ab.parameters[size_t(c)].unit == "rad" ? 1e-7 : 1e-5;
    const Eigen::VectorXd col = ab.parameters[size_t(c)].column;
    const Eigen::VectorXd up =
        CheckedMap(vendor, m, MakeKinematicsTable(m, ab.theta + h * col), options, nv);
    const Eigen::VectorXd down =
        CheckedMap(vendor, m, MakeKinematicsTable(m, ab.theta - h * col), options, nv);
    G.col(c) = (up - down) / (2 * h);
  }
  for (size_t i = 0; i < nv; ++i)
    if (ex.values[i].fixed) G.row(Eigen::Index(i)).setZero();
  if (have_cov) {
    Eigen::MatrixXd GS = G * ab.sensitivity;
    // The motions reach the values through MapMotions (linear in the
    // coefficients: central differences are exact), not through Absorb.
    for (int i : motion_params) {
      Eigen::VectorXd up = theta_e, down = theta_e;
      up[i] += 1e-6;
      down[i] -= 1e-6;
      GS.col(i) = (vendor.MapMotions(m, up, options) - vendor.MapMotions(m, down, options)) / 2e-6;
    }
    ex.covariance = GS * theta_covariance * GS.transpose();
    ex.sigma = ex.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  } else {
    ex.covariance = Eigen::MatrixXd::Constant(Eigen::Index(nv), Eigen::Index(nv),
                                              std::numeric_limits<double>::quiet_NaN());
    ex.sigma = Eigen::VectorXd::Constant(Eigen::Index(nv), std::numeric_limits<double>::quiet_NaN());
  }

  // The round trip, up to a constant (the work offset absorbs one, as it
  // absorbs the workpiece shift): the vendor's own kinematics with the values
  // of the absorbed model against fivecal's tool points of that model.
  const Eigen::VectorXd with_motions = takes_motions ? Eigen::VectorXd(absorbed + motions) : absorbed;
  ex.round_trip =
      InPartFrame(MakeKinematicsTable(m, ab.theta), vendor.ToolPoints(m, with_motions, poses, options)) -
      ToolPoints(m, ab.theta + theta_m, poses);
  if (ex.round_trip.rows() != poses.rows() || ex.round_trip.cols() != 3)
    throw std::logic_error("controller " + vendor.Name() + ": ToolPoints gave the wrong shape");
  const Eigen::RowVector3d mean = ex.round_trip.colwise().mean();
  ex.round_trip.rowwise() -= mean;
  ex.round_trip_max = ex.round_trip.rows() ? ex.round_trip.rowwise().norm().maxCoeff() : 0.0;
  return ex;
}

Eigen::MatrixXd AbsorbedCovariance(const VendorExport& ex, const Eigen::MatrixXd& theta_covariance) {
  const Absorption& ab = ex.absorption;
  const Eigen::Index nt = ab.theta.size(), k = Eigen::Index(ab.parameters.size());
  if (theta_covariance.size() == 0)
    return Eigen::MatrixXd::Constant(nt, nt, std::numeric_limits<double>::quiet_NaN());
  Eigen::MatrixXd B(nt, k);
  for (Eigen::Index c = 0; c < k; ++c) B.col(c) = ab.parameters[size_t(c)].column;
  const Eigen::MatrixXd BS = B * ab.sensitivity;
  return BS * theta_covariance * BS.transpose();
}

Absorption VendorToTheta(const Machine& m, const ControllerVendor& vendor, const Eigen::VectorXd& values,
                         const Eigen::MatrixXd& poses, const VendorOptions& options) {
  const VendorModel vm = vendor.Model(m, options);
  const size_t nv = vendor.Values(m, options).size();
  if (size_t(values.size()) != nv)
    throw std::invalid_argument("values: expected " + std::to_string(nv) + " (" + vendor.Name() +
                                "'s values), got " + std::to_string(values.size()));
  if (!values.allFinite()) throw std::invalid_argument("values: not all finite");
  const Eigen::MatrixXd points = vendor.ToolPoints(m, values, poses, options);
  if (points.rows() != poses.rows() || points.cols() != 3)
    throw std::logic_error("controller " + vendor.Name() + ": ToolPoints gave the wrong shape");
  // Fitted in the controller's frame: fivecal's tool points moved out of the
  // part frame of the model being fitted (the part frame moves with a table
  // axis's location errors), so the frame's own derivative enters the
  // Jacobian; central differences over the model's few columns, started
  // from the part-frame absorption (which also names the held columns).
  const AbsorbOptions ao = OptionsOf(vm);
  Absorption ab = AbsorbToolPoints(m, vm.model, points, poses, ao);
  const auto controller_frame = [&](const Eigen::VectorXd& theta) {
    const KinematicsTable t = MakeKinematicsTable(m, theta);
    return Eigen::MatrixXd((ToolPoints(m, theta, poses) * t.part_rotation.transpose()).rowwise() +
                           t.part_origin.transpose());
  };
  std::vector<Eigen::Index> cols;
  for (size_t c = 0; c < ab.parameters.size(); ++c)
    if (std::find(ab.held.begin(), ab.held.end(), ab.parameters[c].label) == ab.held.end())
      cols.push_back(Eigen::Index(c));
  const Eigen::Index n = poses.rows(), kc = Eigen::Index(cols.size());
  Eigen::VectorXd phi = ab.values;
  Eigen::Vector3d shift = ab.workpiece_shift;
  Eigen::MatrixXd B(m.num_parameters(), Eigen::Index(ab.parameters.size()));
  for (size_t c = 0; c < ab.parameters.size(); ++c) B.col(Eigen::Index(c)) = ab.parameters[c].column;
  const auto stack = [](const Eigen::MatrixXd& r) {
    Eigen::MatrixXd rt = r.transpose();
    return Eigen::VectorXd(Eigen::Map<Eigen::VectorXd>(rt.data(), rt.size()));
  };
  Eigen::MatrixXd model_points;
  for (int it = 0; it < 6; ++it) {
    model_points = controller_frame(B * phi);
    Eigen::MatrixXd r = points - model_points;
    r.rowwise() -= shift.transpose();
    Eigen::MatrixXd J(3 * n, kc + 3);
    for (Eigen::Index j = 0; j < kc; ++j) {
      const double h = ab.parameters[size_t(cols[size_t(j)])].unit == "rad" ? 1e-7 : 1e-5;
      Eigen::VectorXd up = phi, down = phi;
      up[cols[size_t(j)]] += h;
      down[cols[size_t(j)]] -= h;
      J.col(j) = stack(controller_frame(B * up) - controller_frame(B * down)) / (2 * h);
    }
    for (Eigen::Index i = 0; i < n; ++i) J.block(3 * i, kc, 3, 3).setIdentity();
    const Eigen::VectorXd x = J.colPivHouseholderQr().solve(stack(r));
    for (Eigen::Index j = 0; j < kc; ++j) phi[cols[size_t(j)]] += x[j];
    shift += x.tail<3>();
    if (x.cwiseAbs().maxCoeff() < 1e-12) break;
  }
  ab.values = phi;
  ab.theta = B * phi;
  ab.workpiece_shift = shift;
  ab.residual = points - controller_frame(ab.theta);
  ab.residual.rowwise() -= shift.transpose();
  const Eigen::VectorXd norms = ab.residual.rowwise().norm();
  ab.rms = n ? std::sqrt(norms.squaredNorm() / double(n)) : 0.0;
  ab.max = n ? norms.maxCoeff() : 0.0;
  return ab;
}

}  // namespace controllers
}  // namespace fivecal
