#include "fivecal/controllers/absorb.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "fivecal/controllers/kinematics_table.h"
#include "fivecal/controllers/linuxcnc_5axis.h"
#include "fivecal/model/kinematic_model.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {

namespace {

const std::vector<std::string>& Names() {
  static const std::vector<std::string> names = {"table-table", "head-head", "table-head",
                                                 "xyzac-trt",   "xyzbc-trt", "5axiskins"};
  return names;
}

std::vector<int> Rotaries(const Machine& m) {
  std::vector<int> out;
  for (int i = 0; i < m.num_axes(); ++i)
    if (m.axis(i).rotary() && m.axis(i).name != 'S') out.push_back(i);
  return out;
}

std::string Side(const Machine& m, int axis) { return m.on_tool_side(axis) ? "tool" : "workpiece"; }

void CheckTopology(const Machine& m, ControllerModel model) {
  const std::vector<int> rot = Rotaries(m);
  if (rot.size() != 2)
    throw std::invalid_argument("machine '" + m.name() + "' (" + m.topology() +
                                "): a 5-axis controller model needs two rotary axes, found " +
                                std::to_string(rot.size()));
  std::vector<std::string> sides = {Side(m, rot[0]), Side(m, rot[1])};
  std::sort(sides.begin(), sides.end());
  const auto kind_of = [](const std::vector<std::string>& s) -> std::string {
    if (s[0] == "workpiece" && s[1] == "workpiece") return "table-table";
    if (s[0] == "tool" && s[1] == "tool") return "head-head";
    return "table-head";
  };
  const bool generic = model == ControllerModel::kTableTable || model == ControllerModel::kHeadHead ||
                       model == ControllerModel::kTableHead;
  const std::string name = ControllerModelName(model);
  if (generic && kind_of(sides) != name)
    throw std::invalid_argument("model " + name + ": machine '" + m.name() + "' (" + m.topology() +
                                ") is " + kind_of(sides) + " (rotary axes " +
                                std::string(1, m.axis(rot[0]).name) + ", " +
                                std::string(1, m.axis(rot[1]).name) + " on the " + sides[0] + " and " +
                                sides[1] + " side)");
  if (model == ControllerModel::kXyzacTrt) MatchTrt(m, TrtKins::kXyzac);
  if (model == ControllerModel::kXyzbcTrt) MatchTrt(m, TrtKins::kXyzbc);
  if (model == ControllerModel::kFiveAxis) MatchFiveAxis(m);
}

// Two unit vectors perpendicular to u: the machine axes least along u, made
// orthogonal to it (exactly x and y for u along z), so that a pivot's two
// components are the machine coordinates a kinematics table lists.
std::vector<Eigen::Vector3d> Perpendicular(const Eigen::Vector3d& direction) {
  const Eigen::Vector3d u = direction.normalized();
  std::array<int, 3> order = {0, 1, 2};
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return std::abs(u[a]) < std::abs(u[b]); });
  std::array<int, 2> pick = {order[0], order[1]};
  std::sort(pick.begin(), pick.end());
  std::vector<Eigen::Vector3d> out;
  for (int i : pick) {
    const Eigen::Vector3d ei = Eigen::Vector3d::Unit(i);
    Eigen::Vector3d e = ei - ei.dot(u) * u;
    for (const Eigen::Vector3d& f : out) e = e - e.dot(f) * f;
    out.push_back(e / e.norm());
  }
  return out;
}

char Label(const Eigen::Vector3d& e) {
  int k = 0;
  for (int i = 1; i < 3; ++i)
    if (std::abs(e[i]) > std::abs(e[k])) k = i;
  return "xyz"[k];
}

void Stats(const Eigen::MatrixXd& r, double* rms, double* max) {
  const Eigen::VectorXd n = r.rowwise().norm();
  *rms = n.size() ? std::sqrt(n.squaredNorm() / double(n.size())) : 0.0;
  *max = n.size() ? n.maxCoeff() : 0.0;
}

// dP/dphi (3N x k) at theta for the columns B (num_parameters x k).
Eigen::MatrixXd Jacobian(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& B,
                         const Eigen::MatrixXd& poses) {
  const int nt = m.num_parameters(), na = m.num_axes();
  const Eigen::Index n = poses.rows(), k = B.cols();
  KinematicModel model(m, theta.data());
  std::vector<int> wanted;
  for (int i = 0; i < nt; ++i)
    if (B.row(i).cwiseAbs().maxCoeff() > 0.0) wanted.push_back(i);
  model.RestrictJacobian(wanted);
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jt = Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, nt);
  Eigen::MatrixXd J(3 * n, k);
  std::vector<double> row(na), q(na);
  Eigen::Vector3d p;
  for (Eigen::Index i = 0; i < n; ++i) {
    for (int a = 0; a < na; ++a) row[a] = poses(i, a);
    AxisValuesToInternal(m, row.data(), q.data());
    model.ToolPointJacobian(q.data(), nullptr, model.tip(), &p, Jt.data());
    J.middleRows(3 * i, 3) = Jt * B;
  }
  return J;
}

// Rows of N x 3 stacked as a 3N vector (x0 y0 z0 x1 ...).
Eigen::VectorXd Stack(const Eigen::MatrixXd& r) {
  Eigen::VectorXd v(3 * r.rows());
  for (Eigen::Index i = 0; i < r.rows(); ++i) v.segment<3>(3 * i) = r.row(i).transpose();
  return v;
}

}  // namespace

ControllerModel ParseControllerModel(const std::string& name) {
  const std::vector<std::string>& n = Names();
  for (size_t i = 0; i < n.size(); ++i)
    if (n[i] == name) return ControllerModel(i);
  std::string all;
  for (const std::string& s : n) all += (all.empty() ? "" : ", ") + s;
  throw std::invalid_argument("model: '" + name + "' (expected one of " + all + ")");
}

std::string ControllerModelName(ControllerModel model) { return Names().at(size_t(model)); }

std::vector<std::string> ControllerModelNames() { return Names(); }

std::vector<ControllerParameter> ControllerParameters(const Machine& m, ControllerModel model,
                                                      bool directions, bool tool_length) {
  CheckTopology(m, model);
  const int nt = m.num_parameters();
  bool pivots = true;
  if (model == ControllerModel::kFiveAxis) {
    directions = false;
    pivots = false;
    tool_length = true;
  } else if (model == ControllerModel::kXyzacTrt || model == ControllerModel::kXyzbcTrt) {
    directions = false;
    tool_length = false;
  }
  std::vector<ControllerParameter> out;
  const std::vector<int> rot = Rotaries(m);
  // component 0..2: EX0 EY0 EZ0 (pivots), 3..5: EA0 EB0 EC0 (directions)
  const auto add = [&](bool on, int first, const char* what, const char* unit) {
    if (!on) return;
    for (int r : rot)
      for (const Eigen::Vector3d& e : Perpendicular(m.axis(r).direction)) {
        ControllerParameter p;
        p.label = std::string(1, m.axis(r).name) + what + Label(e);
        p.unit = unit;
        p.column = Eigen::VectorXd::Zero(nt);
        for (int c = 0; c < 3; ++c) p.column[m.location_index(r, first + c)] = e[c];
        out.push_back(p);
      }
  };
  add(pivots, 0, " pivot ", "mm");
  add(directions, 3, " direction about ", "rad");
  if (tool_length) {
    Eigen::MatrixXd points, axes;
    ToolPoses(m, Eigen::VectorXd::Zero(nt), Eigen::MatrixXd::Zero(1, m.num_axes()), nullptr, &points, &axes);
    ControllerParameter p;
    p.label = "tool length";
    p.unit = "mm";
    p.column = Eigen::VectorXd::Zero(nt);
    for (int c = 0; c < 3; ++c) p.column[m.tip_index() + c] = -axes(0, c);
    out.push_back(p);
  }
  return out;
}

namespace {

// The absorption of `truth` (N x 3, in `frame`) with the columns it kept
// (parameters first then the shift, as indices into [phi, shift]) and their
// Jacobian at the solution, for the sensitivity.
Absorption AbsorbPoints(const Machine& m, ControllerModel model, const Eigen::MatrixXd& truth,
                        const Eigen::MatrixXd& poses, const AbsorbOptions& options, PointFrame frame,
                        std::vector<Eigen::Index>* kept, Eigen::MatrixXd* jacobian_kept) {
  Absorption ab;
  ab.model = model;
  ab.parameters = ControllerParameters(m, model, options.directions, options.tool_length);
  if (poses.rows() < 1) throw std::invalid_argument("poses: none given");
  if (truth.rows() != poses.rows() || truth.cols() != 3)
    throw std::invalid_argument("tool points: expected " + std::to_string(poses.rows()) +
                                " x 3 (one row per pose), got " + std::to_string(truth.rows()) + " x " +
                                std::to_string(truth.cols()));
  if (!truth.allFinite()) throw std::invalid_argument("tool points: not all finite");
  const int nt = m.num_parameters();
  const Eigen::Index n = poses.rows(), k = Eigen::Index(ab.parameters.size());
  Eigen::MatrixXd B(nt, k);
  for (Eigen::Index c = 0; c < k; ++c) B.col(c) = ab.parameters[c].column;
  const Eigen::VectorXd th0 = Eigen::VectorXd::Zero(nt);
  const bool controller = frame == PointFrame::kController;

  const auto model_points = [&](const Eigen::VectorXd& theta) -> Eigen::MatrixXd {
    Eigen::MatrixXd p = ToolPoints(m, theta, poses);
    if (!controller) return p;
    const KinematicsTable t = MakeKinematicsTable(m, theta);
    return (p * t.part_rotation.transpose()).rowwise() + t.part_origin.transpose();
  };
  Eigen::MatrixXd J(3 * n, k + 3);
  const auto jacobian = [&](const Eigen::VectorXd& phi) {
    const Eigen::VectorXd theta = th0 + B * phi;
    J.leftCols(k) = Jacobian(m, theta, B, poses);
    if (controller) {
      // d(R p + o) = R dp + dR p + do; the part frame is closed-form in
      // theta, so central differences over the few columns are exact enough
      const Eigen::MatrixXd p = ToolPoints(m, theta, poses);
      const Eigen::Matrix3d R = MakeKinematicsTable(m, theta).part_rotation;
      for (Eigen::Index c = 0; c < k; ++c) {
        const double h = ab.parameters[size_t(c)].unit == "rad" ? 1e-7 : 1e-5;
        const KinematicsTable up = MakeKinematicsTable(m, theta + h * B.col(c));
        const KinematicsTable down = MakeKinematicsTable(m, theta - h * B.col(c));
        const Eigen::Matrix3d dR = (up.part_rotation - down.part_rotation) / (2 * h);
        const Eigen::Vector3d dO = (up.part_origin - down.part_origin) / (2 * h);
        for (Eigen::Index i = 0; i < n; ++i)
          J.block(3 * i, c, 3, 1) = R * J.block(3 * i, c, 3, 1) + dR * p.row(i).transpose() + dO;
      }
    }
    for (Eigen::Index i = 0; i < n; ++i) J.block(3 * i, k, 3, 3).setIdentity();
  };
  Eigen::VectorXd phi = Eigen::VectorXd::Zero(k);
  jacobian(phi);

  // Columns the poses cannot tell apart from earlier ones (the shift first,
  // then the parameters in order) are held at 0: sequential projection.
  std::vector<Eigen::Index> order, keep;
  for (Eigen::Index c = k; c < k + 3; ++c) order.push_back(c);
  for (Eigen::Index c = 0; c < k; ++c) order.push_back(c);
  std::vector<Eigen::VectorXd> basis;
  for (Eigen::Index c : order) {
    Eigen::VectorXd v = J.col(c);
    for (const Eigen::VectorXd& b : basis) v -= b.dot(v) * b;
    if (v.norm() > 1e-8 * std::max(J.col(c).norm(), 1e-300)) {
      keep.push_back(c);
      basis.push_back(v / v.norm());
    }
  }
  for (Eigen::Index c = 0; c < k; ++c)
    if (std::find(keep.begin(), keep.end(), c) == keep.end()) ab.held.push_back(ab.parameters[c].label);

  Eigen::Vector3d shift = Eigen::Vector3d::Zero();
  Eigen::MatrixXd Jk(3 * n, Eigen::Index(keep.size()));
  // Nearly linear: two or three steps converge; the cap only stops a cycle.
  for (int it = 0; it < 6; ++it) {
    Eigen::MatrixXd r = truth - model_points(th0 + B * phi);
    r.rowwise() -= shift.transpose();
    for (size_t j = 0; j < keep.size(); ++j) Jk.col(Eigen::Index(j)) = J.col(keep[j]);
    const Eigen::VectorXd x = Jk.colPivHouseholderQr().solve(Stack(r));
    Eigen::VectorXd step = Eigen::VectorXd::Zero(k + 3);
    for (size_t j = 0; j < keep.size(); ++j) step[keep[j]] = x[Eigen::Index(j)];
    phi += step.head(k);
    shift += step.tail<3>();
    if (step.cwiseAbs().maxCoeff() < 1e-12) break;
    jacobian(phi);
  }
  ab.values = phi;
  ab.theta = th0 + B * phi;
  ab.workpiece_shift = shift;
  ab.residual = truth - model_points(ab.theta);
  ab.residual.rowwise() -= shift.transpose();
  ab.residual_old = truth - model_points(th0);
  const Eigen::RowVector3d mean = ab.residual_old.colwise().mean();
  ab.residual_old.rowwise() -= mean;
  Stats(ab.residual, &ab.rms, &ab.max);
  Stats(ab.residual_old, &ab.rms_old, &ab.max_old);
  if (kept) *kept = keep;
  if (jacobian_kept) {
    jacobian(phi);
    for (size_t j = 0; j < keep.size(); ++j) Jk.col(Eigen::Index(j)) = J.col(keep[j]);
    *jacobian_kept = Jk;
  }
  return ab;
}

}  // namespace

Absorption Absorb(const Machine& m, ControllerModel model, const Eigen::VectorXd& theta_true,
                  const Eigen::MatrixXd& poses, const AbsorbOptions& options) {
  if (poses.rows() < 1) throw std::invalid_argument("poses: none given");
  const Eigen::MatrixXd truth = ToolPoints(m, theta_true, poses);  // validates theta and poses
  std::vector<Eigen::Index> keep;
  Eigen::MatrixXd Jk;
  Absorption ab = AbsorbPoints(m, model, truth, poses, options, PointFrame::kPart, &keep, &Jk);
  // Gauss-Newton at the solution: d[phi_kept, shift_kept] = pinv(Jk) dP/dtheta d theta_true.
  const int nt = m.num_parameters();
  const Eigen::MatrixXd Jt = Jacobian(m, theta_true, Eigen::MatrixXd::Identity(nt, nt), poses);
  const Eigen::MatrixXd S = Jk.colPivHouseholderQr().solve(Jt);
  const Eigen::Index k = Eigen::Index(ab.parameters.size());
  ab.sensitivity = Eigen::MatrixXd::Zero(k, nt);
  for (size_t j = 0; j < keep.size(); ++j)
    if (keep[j] < k) ab.sensitivity.row(keep[j]) = S.row(Eigen::Index(j));
  if (model == ControllerModel::kXyzacTrt || model == ControllerModel::kXyzbcTrt)
    ab.trt = FitTrtPins(m, model == ControllerModel::kXyzacTrt ? TrtKins::kXyzac : TrtKins::kXyzbc,
                        theta_true, poses, options.held_pins);
  return ab;
}

Absorption AbsorbToolPoints(const Machine& m, ControllerModel model, const Eigen::MatrixXd& truth,
                            const Eigen::MatrixXd& poses, const AbsorbOptions& options, PointFrame frame) {
  return AbsorbPoints(m, model, truth, poses, options, frame, nullptr, nullptr);
}

}  // namespace controllers
}  // namespace fivecal
