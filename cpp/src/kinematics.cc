#include "fivecal/kinematics.h"

#include "fivecal/kinematic_model.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace fivecal {

void AxisValuesToInternal(const Machine& m, const double* in, double* out) {
  for (int k = 0; k < m.num_axes(); ++k)
    out[k] = m.axis(k).rotary() ? in[k] * (M_PI / 180.0) : in[k];
}

void ValidatePoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
                   const Eigen::MatrixXi* dirs) {
  if (theta.size() != m.num_parameters())
    throw std::invalid_argument("errors: expected " + std::to_string(m.num_parameters()) +
                                " machine parameter values, got " + std::to_string(theta.size()));
  for (int i = 0; i < theta.size(); ++i)
    RequireFinite(theta[i], "errors." + m.parameters()[i].name);
  if (axes.cols() != m.num_axes())
    throw std::invalid_argument("axes: expected " + std::to_string(m.num_axes()) +
                                " columns (" + m.axis_names() + "), got " +
                                std::to_string(axes.cols()));
  for (int r = 0; r < axes.rows(); ++r)
    for (int k = 0; k < axes.cols(); ++k)
      if (!std::isfinite(axes(r, k)))
        throw std::invalid_argument("axes." + std::string(1, m.axis(k).name) + "[" +
                                    std::to_string(r) + "]: value is not finite (NaN or inf)");
  if (dirs) {
    if (dirs->rows() != axes.rows() || dirs->cols() != axes.cols())
      throw std::invalid_argument("directions: shape must match axes (" +
                                  std::to_string(axes.rows()) + " x " +
                                  std::to_string(axes.cols()) + ")");
    for (int r = 0; r < dirs->rows(); ++r)
      for (int k = 0; k < dirs->cols(); ++k) {
        int d = (*dirs)(r, k);
        if (d < -1 || d > 1)
          throw std::invalid_argument("directions." + std::string(1, m.axis(k).name) + "[" +
                                      std::to_string(r) + "]: must be -1, 0 or +1, got " +
                                      std::to_string(d));
      }
  }
}

void ToolPoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
               const Eigen::MatrixXi* dirs, Eigen::MatrixXd* points, Eigen::MatrixXd* tool_axes,
               const Eigen::Vector3d* tip) {
  if (tip)
    for (int i = 0; i < 3; ++i) RequireFinite((*tip)[i], "tip[" + std::to_string(i) + "]");
  ValidatePoses(m, theta, axes, dirs);
  const int n = static_cast<int>(axes.rows()), na = m.num_axes();
  points->resize(n, 3);
  if (tool_axes) tool_axes->resize(n, 3);
  const KinematicModel model(m, theta.data());
  const Eigen::Vector3d t = tip ? *tip : model.tip();
  std::vector<double> row(na), q(na);
  std::vector<int> dir(na, 0);
  for (int r = 0; r < n; ++r) {
    for (int k = 0; k < na; ++k) {
      row[k] = axes(r, k);
      if (dirs) dir[k] = (*dirs)(r, k);
    }
    AxisValuesToInternal(m, row.data(), q.data());
    Eigen::Vector3d p, a;
    model.ToolPose(q.data(), dirs ? dir.data() : nullptr, t, &p, tool_axes ? &a : nullptr);
    points->row(r) = p.transpose();
    if (tool_axes) tool_axes->row(r) = a.transpose();
  }
}

Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& theta,
                           const Eigen::MatrixXd& axes, const Eigen::MatrixXi* dirs) {
  Eigen::MatrixXd points;
  ToolPoses(m, theta, axes, dirs, &points, nullptr);
  return points;
}

}  // namespace fivecal
