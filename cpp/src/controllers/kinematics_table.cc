#include "fivecal/controllers/kinematics_table.h"

#include <cmath>
#include <stdexcept>

#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {

namespace {

// I + sin(q) K + (1 - cos(q)) K^2 about the unit vector along u.
Eigen::Matrix3d Rodrigues(const Eigen::Vector3d& direction, double q) {
  const Eigen::Vector3d u = direction / direction.norm();
  Eigen::Matrix3d K;
  K << 0, -u.z(), u.y(), u.z(), 0, -u.x(), -u.y(), u.x(), 0;
  return Eigen::Matrix3d::Identity() + std::sin(q) * K + (1 - std::cos(q)) * K * K;
}

}  // namespace

KinematicsTable MakeKinematicsTable(const Machine& m, const Eigen::VectorXd& theta) {
  if (theta.size() != m.num_parameters())
    throw std::invalid_argument("theta: " + std::to_string(theta.size()) + " values, machine has " +
                                std::to_string(m.num_parameters()) + " parameters");
  for (Eigen::Index i = 0; i < theta.size(); ++i)
    RequireFinite(theta[i], "theta[" + std::to_string(i) + "]");
  KinematicsTable table;
  Eigen::Matrix3d Rc[2];
  Eigen::Vector3d tc[2], pc[2];
  for (int side = 0; side < 2; ++side) {
    const std::vector<int>& chain = side == 0 ? m.workpiece_chain() : m.tool_chain();
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d t = Eigen::Vector3d::Zero(), parent = Eigen::Vector3d::Zero();
    for (int k : chain) {
      const Axis& ax = m.axis(k);
      const double* loc = theta.data() + m.location_index(k, 0);
      t = t + R * (Eigen::Vector3d(loc[0], loc[1], loc[2]) + ax.point - parent);
      R = R * RotZYX(loc[3], loc[4], loc[5]);
      parent = ax.point;
      if (ax.name == 'S') continue;  // the spindle's frame counts, its row does not
      TableAxis row;
      row.axis = ax.name;
      row.tool_chain = side == 1;
      row.rotary = ax.rotary();
      row.direction = R * ax.direction;
      row.point = t;
      if (ax.rotary()) row.point = t + ((ax.point - t).dot(row.direction)) * row.direction;
      else row.point = Eigen::Vector3d::Zero();
      table.axes.push_back(row);
    }
    Rc[side] = R;
    tc[side] = t;
    pc[side] = parent;
  }
  // The part frame at the zero pose: W0 = F_last . Trans(-p_last).
  table.part_origin = tc[0] - Rc[0] * pc[0];
  table.part_rotation = Rc[0];
  const Eigen::Vector3d tip = m.tip() + theta.segment<3>(m.tip_index());
  table.tool_tip = tc[1] + Rc[1] * (tip - pc[1]);
  table.tool_axis = Rc[1] * m.tool_axis();
  return table;
}

Eigen::MatrixXd TableToolPoints(const KinematicsTable& table, const Eigen::MatrixXd& q) {
  const Eigen::Index na = Eigen::Index(table.axes.size());
  if (q.cols() != na)
    throw std::invalid_argument("axes: " + std::to_string(q.cols()) + " columns, the table has " +
                                std::to_string(na) + " axes");
  for (Eigen::Index i = 0; i < q.rows(); ++i)
    for (Eigen::Index k = 0; k < na; ++k)
      RequireFinite(q(i, k), "axes[" + std::to_string(i) + "]." + std::string(1, table.axes[k].axis));
  Eigen::MatrixXd out(q.rows(), 3);
  const double deg = M_PI / 180.0;
  for (Eigen::Index i = 0; i < q.rows(); ++i) {
    // Screw of one row applied to x (inverse: the opposite motion).
    const auto screw = [&](Eigen::Index k, const Eigen::Vector3d& x, bool inverse) -> Eigen::Vector3d {
      const TableAxis& r = table.axes[k];
      const double v = q(i, k);
      if (!r.rotary) return inverse ? Eigen::Vector3d(x - v * r.direction) : Eigen::Vector3d(x + v * r.direction);
      const Eigen::Matrix3d R = Rodrigues(r.direction, (inverse ? -v : v) * deg);
      return r.point + R * (x - r.point);
    };
    // Tool chain forward, innermost (last listed) first.
    Eigen::Vector3d p = table.tool_tip;
    for (Eigen::Index k = na - 1; k >= 0; --k)
      if (table.axes[k].tool_chain) p = screw(k, p, false);
    // Workpiece chain inverse, from the foundation outward.
    for (Eigen::Index k = 0; k < na; ++k)
      if (!table.axes[k].tool_chain) p = screw(k, p, true);
    out.row(i) = (table.part_rotation.transpose() * (p - table.part_origin)).transpose();
  }
  return out;
}

}  // namespace controllers
}  // namespace fivecal
