#include "fivecal/model/inverse.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace {

constexpr double kDeg = 180.0 / M_PI;

// Angle (rad) of the rotation about unit w taking p to q, both projected on
// the plane normal to w. Returns false when p or q lies on w (angle free).
bool Subproblem1(const Eigen::Vector3d& w, const Eigen::Vector3d& p, const Eigen::Vector3d& q,
                 double* angle) {
  const Eigen::Vector3d pp = p - w * w.dot(p), qq = q - w * w.dot(q);
  if (pp.norm() < 1e-12 || qq.norm() < 1e-12) return false;
  *angle = std::atan2(w.dot(pp.cross(qq)), pp.dot(qq));
  return true;
}

struct AnglePair {
  double t1, t2;
  bool free1, free2;
};

// All (t1, t2) with Rot(w1, t1) Rot(w2, t2) p = q (Paden-Kahan subproblem 2).
std::vector<AnglePair> Subproblem2(const Eigen::Vector3d& w1, const Eigen::Vector3d& w2,
                                   const Eigen::Vector3d& p, const Eigen::Vector3d& q) {
  const double c = w1.dot(w2);
  const Eigen::Vector3d n = w1.cross(w2);
  if (n.norm() < 1e-9) throw std::invalid_argument("inverse: the two orientation axes are parallel");
  const double d = 1.0 - c * c;
  const double alpha = (w1.dot(q) - c * w2.dot(p)) / d;
  const double beta = (w2.dot(p) - c * w1.dot(q)) / d;
  double g2 = (p.squaredNorm() - alpha * alpha - beta * beta - 2 * alpha * beta * c) / n.squaredNorm();
  std::vector<AnglePair> out;
  if (g2 < -1e-9) return out;
  g2 = std::max(g2, 0.0);
  const double g = std::sqrt(g2);
  for (double s : {1.0, -1.0}) {
    const Eigen::Vector3d z = alpha * w1 + beta * w2 + s * g * n;
    AnglePair a{0, 0, false, false};
    a.free2 = !Subproblem1(w2, p, z, &a.t2);
    a.free1 = !Subproblem1(w1, z, q, &a.t1);
    out.push_back(a);
    if (g == 0.0) break;
  }
  return out;
}

// The equivalent of `deg` (mod 360) nearest to `current`.
double Unwrap(double deg, double current) {
  return deg + 360.0 * std::round((current - deg) / 360.0);
}

void Pose(const Machine& m, const Eigen::VectorXd& theta, const Eigen::VectorXd& cmd,
          const int* dir, Eigen::Vector3d* p, Eigen::Vector3d* v) {
  std::vector<double> q(m.num_axes());
  AxisValuesToInternal(m, cmd.data(), q.data());
  ToolInWorkpiece<double>(m, theta.data(), q.data(), dir, TipWithOffsets(m, theta.data()), p, v);
}

}  // namespace

Eigen::MatrixXd InverseKinematics(const Machine& m, const Eigen::VectorXd& theta,
                                  const Eigen::MatrixXd& points, const Eigen::MatrixXd* tool_axes,
                                  const Eigen::VectorXd& start, const Eigen::MatrixXi* dirs,
                                  const InverseOptions& options) {
  const int na = m.num_axes(), n = static_cast<int>(points.rows());
  if (points.cols() != 3) throw std::invalid_argument("inverse: points must be N x 3");
  if (tool_axes && (tool_axes->rows() != n || tool_axes->cols() != 3))
    throw std::invalid_argument("inverse: tool_axes must be N x 3 like points");
  if (start.size() != na)
    throw std::invalid_argument("inverse: start must have " + std::to_string(na) + " values (" +
                                m.axis_names() + ")");
  for (int k = 0; k < na; ++k)
    RequireFinite(start[k], "inverse: start." + std::string(1, m.axis(k).name));
  ValidatePoses(m, theta, Eigen::MatrixXd(start.transpose()), nullptr);
  if (dirs && (dirs->rows() != n || dirs->cols() != na))
    throw std::invalid_argument("inverse: directions must be N x " + std::to_string(na));
  // A target 1e308 mm away is a unit mistake, not a pose to solve for; the
  // tool axes are directions of any scale (normalised below, overflow-safe).
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < 3; ++c)
      RequireBounded(points(r, c), kMaxLinear, "inverse: points[" + std::to_string(r) + "][" + std::to_string(c) + "]");
    if (tool_axes) (void)UnitDirection(tool_axes->row(r).transpose(), "inverse: tool_axes[" + std::to_string(r) + "]");
  }

  std::vector<int> linear, orient;
  for (int k = 0; k < na; ++k) {
    if (!m.axis(k).rotary()) linear.push_back(k);
    else if (m.axis(k).name != 'S') orient.push_back(k);
  }
  if (tool_axes && orient.size() > 2)
    throw std::invalid_argument("inverse: more than two orientation axes; the tool axis does not "
                                "fix them, give their values in start and no tool_axes");
  const int spindle = m.AxisIndex('S');
  if (tool_axes && spindle >= 0 && !orient.empty() &&
      !(m.on_tool_side(spindle) && m.tool_chain().back() == spindle))
    throw std::invalid_argument("inverse: the spindle S must be the last tool-side axis");

  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(theta.size());
  const bool with_errors = theta.cwiseAbs().maxCoeff() > 0.0;
  Eigen::MatrixXd out(n, na);
  Eigen::VectorXd current = start;
  std::vector<int> dir_row(na, 0);

  for (int r = 0; r < n; ++r) {
    if (dirs) for (int k = 0; k < na; ++k) dir_row[k] = (*dirs)(r, k);
    const int* dir = dirs ? dir_row.data() : nullptr;
    const Eigen::Vector3d target = points.row(r).transpose();
    Eigen::Vector3d vt = Eigen::Vector3d::Zero();
    Eigen::VectorXd cmd = current;

    if (tool_axes && !orient.empty()) {
      vt = UnitDirection(tool_axes->row(r).transpose(), "inverse: tool_axes[" + std::to_string(r) + "]");
      // Tool axis after the spindle rotation (the spindle is last on the tool chain).
      Eigen::Vector3d a = m.tool_axis();
      if (spindle >= 0)
        a = AxisAngle<double>(m.axis(spindle).direction, current[spindle] / kDeg) * a;
      std::vector<Eigen::Vector3d> w;
      for (int k : orient) w.push_back(m.axis(k).direction);
      std::vector<std::vector<double>> candidates;  // orientation angles in degrees
      auto pick = [&](double t, bool free, int k) { return free ? current[k] : t * kDeg; };
      if (orient.size() == 1) {
        const int k = orient[0];
        // wp side: Rot(u, -q) a = v ; tool side: Rot(u, q) a = v.
        double t = 0;
        bool free = !Subproblem1(w[0], a, vt, &t);
        if (!m.on_tool_side(k)) t = -t;
        Eigen::Vector3d check = AxisAngle<double>(w[0], m.on_tool_side(k) ? t : -t) * a;
        if (!free && (check - vt).norm() > 1e-9)
          throw std::invalid_argument("inverse: tool_axes[" + std::to_string(r) +
                                      "] cannot be reached with the single rotary axis");
        candidates.push_back({pick(t, free, k)});
      } else {
        const int k1 = orient[0], k2 = orient[1];
        const bool t1 = m.on_tool_side(k1), t2 = m.on_tool_side(k2);
        // orient is in topology order: on the workpiece side that is from the
        // workpiece inward, so the chain order (foundation outward) is reversed.
        if (!t1 && !t2) {
          // Rot(u_f, q_f) Rot(u_o, q_o) v = a, u_f nearer the foundation.
          for (const auto& s : Subproblem2(w[1], w[0], vt, a))
            candidates.push_back({pick(s.t2, s.free2, k1), pick(s.t1, s.free1, k2)});
        } else if (t1 && t2) {
          // v = Rot(u1, q1) Rot(u2, q2) a.
          for (const auto& s : Subproblem2(w[0], w[1], a, vt))
            candidates.push_back({pick(s.t1, s.free1, k1), pick(s.t2, s.free2, k2)});
        } else {
          // k1 on the workpiece side, k2 on the tool side:
          // Rot(u_t, -q_t) Rot(u_w, q_w) v = a.
          for (const auto& s : Subproblem2(w[1], w[0], vt, a))
            candidates.push_back({pick(s.t2, s.free2, k1), s.free1 ? current[k2] : -s.t1 * kDeg});
        }
      }
      if (candidates.empty())
        throw std::invalid_argument("inverse: tool_axes[" + std::to_string(r) +
                                    "] cannot be reached by the rotary axes");
      double best = INFINITY;
      for (auto& c : candidates) {
        double cost = 0;
        for (size_t i = 0; i < orient.size(); ++i) {
          c[i] = Unwrap(c[i], current[orient[i]]);
          cost += std::pow(c[i] - current[orient[i]], 2);
        }
        if (cost < best - 1e-9) {
          best = cost;
          for (size_t i = 0; i < orient.size(); ++i) cmd[orient[i]] = c[i];
        }
      }
    }

    // Linear axes: the nominal tool point is affine in them.
    if (!linear.empty()) {
      Eigen::Vector3d p0, p1, v;
      Pose(m, nominal, cmd, dir, &p0, &v);
      Eigen::MatrixXd J(3, linear.size());
      for (size_t j = 0; j < linear.size(); ++j) {
        Eigen::VectorXd c1 = cmd;
        c1[linear[j]] += 1.0;
        Pose(m, nominal, c1, dir, &p1, &v);
        J.col(j) = p1 - p0;
      }
      Eigen::VectorXd dx = J.colPivHouseholderQr().solve(target - p0);
      for (size_t j = 0; j < linear.size(); ++j) cmd[linear[j]] += dx[j];
    }

    // Gauss-Newton on the erroneous model (finite-difference Jacobian in the
    // commands; the nominal solution is within microns so this converges fast).
    std::vector<int> unknowns = linear;
    if (tool_axes) unknowns.insert(unknowns.end(), orient.begin(), orient.end());
    const int nr = tool_axes && !orient.empty() ? 6 : 3;
    auto residual = [&](const Eigen::VectorXd& c) {
      Eigen::Vector3d p, v;
      Pose(m, with_errors ? theta : nominal, c, dir, &p, &v);
      Eigen::VectorXd e(nr);
      e.head<3>() = p - target;
      if (nr == 6) e.tail<3>() = v - vt;
      return e;
    };
    if (with_errors && !unknowns.empty()) {
      for (int it = 0; it < options.max_iterations; ++it) {
        Eigen::VectorXd e = residual(cmd);
        Eigen::MatrixXd J(nr, unknowns.size());
        for (size_t j = 0; j < unknowns.size(); ++j) {
          const double h = 1e-5;  // mm or degrees
          Eigen::VectorXd cp = cmd, cm = cmd;
          cp[unknowns[j]] += h;
          cm[unknowns[j]] -= h;
          J.col(j) = (residual(cp) - residual(cm)) / (2 * h);
        }
        Eigen::VectorXd dx = J.colPivHouseholderQr().solve(-e);
        for (size_t j = 0; j < unknowns.size(); ++j) cmd[unknowns[j]] += dx[j];
        if (dx.cwiseAbs().maxCoeff() < options.tolerance) break;
      }
    }
    const Eigen::VectorXd e = residual(cmd);
    if (e.head<3>().norm() > 1e-6 || (nr == 6 && e.tail<3>().norm() > 1e-8))
      throw std::invalid_argument("inverse: points[" + std::to_string(r) +
                                  "] cannot be reached (remaining error " +
                                  std::to_string(e.norm()) + " mm); check axis count and target");
    out.row(r) = cmd.transpose();
    current = cmd;
  }
  return out;
}

}  // namespace fivecal
