#include "fivecal/controllers/compensate.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "fivecal/model/inverse.h"

namespace fivecal {
namespace controllers {

CompensatedCommands CompensateCommands(const Machine& m, const Eigen::VectorXd& theta,
                                       const Eigen::MatrixXd& points, const Eigen::MatrixXd* tool_axes,
                                       const Eigen::MatrixXd& nominal, const Eigen::MatrixXi* dirs,
                                       bool orientation, double max_rotary_correction) {
  const Eigen::Index n = nominal.rows();
  const int na = m.num_axes();
  if (nominal.cols() != na)
    throw std::invalid_argument("nominal: " + std::to_string(nominal.cols()) + " columns, machine has " +
                                std::to_string(na) + " axes");
  if (points.rows() != n || points.cols() != 3)
    throw std::invalid_argument("points: expected " + std::to_string(n) + " x 3");
  if (tool_axes && (tool_axes->rows() != n || tool_axes->cols() != 3))
    throw std::invalid_argument("tool_axes: expected " + std::to_string(n) + " x 3");
  if (dirs && (dirs->rows() != n || dirs->cols() != na))
    throw std::invalid_argument("directions: expected " + std::to_string(n) + " x " + std::to_string(na));
  std::vector<int> rot;  // the orientation axes a correction limit applies to (not the spindle)
  for (int k = 0; k < na; ++k) {
    const char a = m.axis(k).name;
    if (a == 'A' || a == 'B' || a == 'C') rot.push_back(k);
  }
  CompensatedCommands out;
  out.commands.resize(n, na);
  out.oriented.assign(size_t(n), false);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::MatrixXd p = points.row(i);
    const Eigen::VectorXd start = nominal.row(i).transpose();
    Eigen::MatrixXi d;
    if (dirs) d = dirs->row(i);
    const Eigen::MatrixXi* di = dirs ? &d : nullptr;
    bool solved = false;
    if (orientation && tool_axes) {
      try {
        const Eigen::MatrixXd a = tool_axes->row(i);
        const Eigen::VectorXd c = InverseKinematics(m, theta, p, &a, start, di).row(0).transpose();
        double worst = 0;
        for (int k : rot) worst = std::max(worst, std::abs(c[k] - start[k]));
        if (rot.empty() || worst <= max_rotary_correction) {
          out.commands.row(i) = c.transpose();
          out.oriented[size_t(i)] = true;
          solved = true;
        }
      } catch (const std::invalid_argument&) {
        solved = false;
      }
    }
    if (!solved) {
      try {
        out.commands.row(i) = InverseKinematics(m, theta, p, nullptr, start, di).row(0);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("pose " + std::to_string(i) + ": " + e.what());
      }
    }
  }
  return out;
}

}  // namespace controllers
}  // namespace fivecal
