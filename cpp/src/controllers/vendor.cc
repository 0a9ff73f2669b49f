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
  static const std::vector<const ControllerVendor*> vendors = {
      &FanucVendor::Instance(),
      &SiemensVendor::Instance(),
      &HeidenhainVendor::Instance(),
      &BeckhoffVendor::Instance(),
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
  if (theta_e.size() != nt)
    throw std::invalid_argument("theta: expected " + std::to_string(nt) + " values (the machine's parameters), got " +
                                std::to_string(theta_e.size()));

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
  // The tool offset: its length along the tool axis for a model that holds
  // the tool length, nothing otherwise (vendor.h); the same projection
  // carries the covariance (through the sensitivity below).
  Eigen::MatrixXd P = Eigen::MatrixXd::Identity(nt, nt);
  const Eigen::Vector3d axis = m.tool_axis().normalized();
  P.block<3, 3>(m.tip_index(), m.tip_index()) =
      ex.model.tool_length ? Eigen::Matrix3d(axis * axis.transpose()) : Eigen::Matrix3d(Eigen::Matrix3d::Zero());
  Eigen::VectorXd theta_k = P * theta_e, theta_m = Eigen::VectorXd::Zero(nt);
  if (takes_motions)
    for (int i = 0; i < nt; ++i)
      if (m.parameters()[size_t(i)].kind == ParameterKind::kMotion) {
        motion_params.push_back(i);
        theta_m[i] = theta_e[i];
        theta_k[i] = 0;
      }
  ex.absorption = Absorb(m, ex.model.model, theta_k, poses, OptionsOf(ex.model));
  ex.absorption.sensitivity = ex.absorption.sensitivity * P;
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
  for (size_t i = 0; i < nv; ++i)
    if (!ex.values[i].motion) ex.covariance_index.push_back(Eigen::Index(i));
  const Eigen::Index nc = Eigen::Index(ex.covariance_index.size());
  if (have_cov) {
    Eigen::MatrixXd GS = G * ab.sensitivity;
    // The motions reach the values through MapMotions (nearly linear in
    // the coefficients: central differences are exact to rounding), not through Absorb.
    for (int i : motion_params) {
      Eigen::VectorXd up = theta_e, down = theta_e;
      up[i] += 1e-6;
      down[i] -= 1e-6;
      GS.col(i) = (vendor.MapMotions(m, up, options) - vendor.MapMotions(m, down, options)) / 2e-6;
    }
    // diag(GS C GS^T) row by row: nv x nt work, never nv x nv
    const Eigen::MatrixXd GSC = GS * theta_covariance;
    ex.sigma = GSC.cwiseProduct(GS).rowwise().sum().cwiseMax(0.0).cwiseSqrt();
    Eigen::MatrixXd GSk(nc, nt);
    for (Eigen::Index r = 0; r < nc; ++r) GSk.row(r) = GS.row(ex.covariance_index[size_t(r)]);
    ex.covariance = GSk * theta_covariance * GSk.transpose();
  } else {
    ex.covariance = Eigen::MatrixXd::Constant(nc, nc, std::numeric_limits<double>::quiet_NaN());
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
  // Fitted in the controller's frame (vendor.h, ToolPoints): the part frame
  // of the model being fitted moves with a table axis's location errors.
  return AbsorbToolPoints(m, vm.model, points, poses, OptionsOf(vm), PointFrame::kController);
}

}  // namespace controllers
}  // namespace fivecal
