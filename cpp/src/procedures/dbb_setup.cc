#include "fivecal/procedures/dbb_setup.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace {

std::vector<double> Internal(const Machine& m, const Eigen::VectorXd& cmd) {
  if (cmd.size() != m.num_axes())
    throw std::invalid_argument("axis commands: expected " + std::to_string(m.num_axes()) +
                                " values (" + m.axis_names() + ")");
  std::vector<double> q(m.num_axes());
  AxisValuesToInternal(m, cmd.data(), q.data());
  return q;
}

}  // namespace

Eigen::Vector3d NominalToolBallInF(const Machine& m, const Eigen::VectorXd& cmd,
                                   const Eigen::Vector3d& tool_ball) {
  const std::vector<double> q = Internal(m, cmd);
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::Vector3d p_last;
  const Frame<double> Ft = ChainFrame<double>(m, m.tool_chain(), theta.data(), q.data(), nullptr, &p_last);
  return Ft * Eigen::Vector3d(tool_ball - p_last);
}

Eigen::Vector3d NominalTableBallInF(const Machine& m, const Eigen::VectorXd& cmd,
                                    const Eigen::Vector3d& table_ball) {
  const std::vector<double> q = Internal(m, cmd);
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::Vector3d p_last;
  const Frame<double> Fw =
      ChainFrame<double>(m, m.workpiece_chain(), theta.data(), q.data(), nullptr, &p_last);
  // T_fw = Fw . Trans(-p_last) (kinematics.h).
  return Fw * Eigen::Vector3d(table_ball - p_last);
}

Eigen::VectorXd ToolBallCommands(const Machine& m, const Eigen::Vector3d& tool_ball,
                                 const Eigen::Vector3d& target, const Eigen::VectorXd& pose) {
  std::vector<int> linear;
  for (int k : m.tool_chain())
    if (!m.axis(k).rotary()) linear.push_back(k);
  Eigen::VectorXd base = pose;
  for (int k : linear) base[k] = 0.0;
  const Eigen::Vector3d s0 = NominalToolBallInF(m, base, tool_ball);
  Eigen::MatrixXd J(3, linear.size());
  for (size_t j = 0; j < linear.size(); ++j) {
    Eigen::VectorXd c = base;
    c[linear[j]] = 1.0;  // affine: the unit step gives the exact column
    J.col(j) = NominalToolBallInF(m, c, tool_ball) - s0;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(J);
  if (linear.size() < 3 || qr.rank() < 3)
    throw std::invalid_argument("machine '" + m.name() + "' (" + m.topology() +
                                "): the DBB spindle ball needs three independent linear axes on "
                                "the tool side");
  const Eigen::VectorXd x = qr.solve(Eigen::Vector3d(target - s0));
  Eigen::VectorXd out = base;
  for (size_t j = 0; j < linear.size(); ++j) out[linear[j]] = x[j];
  return out;
}

Eigen::Vector3d NominalToolBallInWorkpiece(const Machine& m, const Eigen::VectorXd& cmd,
                                           const Eigen::Vector3d& tool_ball) {
  const std::vector<double> q = Internal(m, cmd);
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::Vector3d p;
  ToolInWorkpiece<double>(m, theta.data(), q.data(), nullptr, tool_ball, &p);
  return p;
}

Eigen::MatrixXd BarLengthCommands(const Machine& m, const Eigen::Vector3d& tool_ball,
                                  const Eigen::Vector3d& table_ball, double length,
                                  const Eigen::MatrixXd& poses) {
  const std::string w = "bar length commands";
  if (!(length > 0) || !std::isfinite(length))
    throw std::invalid_argument(w + ": length must be a finite length > 0 mm");
  for (int c = 0; c < 3; ++c) {
    RequireFinite(tool_ball[c], w + ": tool_ball");
    RequireFinite(table_ball[c], w + ": table_ball");
  }
  if (poses.cols() != m.num_axes())
    throw std::invalid_argument(w + ": poses: expected N x " + std::to_string(m.num_axes()) + " (" +
                                m.axis_names() + ")");
  for (Eigen::Index i = 0; i < poses.rows(); ++i)
    for (int k = 0; k < m.num_axes(); ++k)
      RequireFinite(poses(i, k), w + ": poses[" + std::to_string(i) + "]." + std::string(1, m.axis(k).name));
  std::vector<int> linear;
  for (int k = 0; k < m.num_axes(); ++k)
    if (!m.axis(k).rotary()) linear.push_back(k);
  Eigen::MatrixXd out = poses;
  Eigen::MatrixXd J(3, linear.size());
  for (Eigen::Index i = 0; i < poses.rows(); ++i) {
    Eigen::VectorXd q = poses.row(i).transpose();
    for (int it = 0; it < 4; ++it) {
      const Eigen::Vector3d p = NominalToolBallInWorkpiece(m, q, tool_ball);
      const Eigen::Vector3d d = p - table_ball;
      const double r = d.norm();
      if (!(r > 0))
        throw std::invalid_argument(w + ": poses[" + std::to_string(i) +
                                    "]: the balls coincide; the bar has no direction");
      const double err = r - length;
      if (std::abs(err) < 1e-12) break;
      for (size_t j = 0; j < linear.size(); ++j) {
        Eigen::VectorXd c = q;
        c[linear[j]] += 1.0;  // affine: the unit step gives the exact column
        J.col(j) = NominalToolBallInWorkpiece(m, c, tool_ball) - p;
      }
      const Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(J);
      if (cod.rank() < 3)
        throw std::invalid_argument("machine '" + m.name() + "' (" + m.topology() +
                                    "): the linear axes cannot move the DBB tool ball in three "
                                    "independent directions");
      const Eigen::VectorXd step = cod.solve(Eigen::Vector3d(-(err / r) * d));
      for (size_t j = 0; j < linear.size(); ++j) q[linear[j]] += step[j];
    }
    out.row(i) = q.transpose();
  }
  return out;
}

}  // namespace fivecal
