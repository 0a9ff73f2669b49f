#include "fivecal/procedures/dbb_setup.h"

#include <Eigen/Dense>
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

}  // namespace fivecal
