#include "fivecal/model/kinematics.h"

#include "fivecal/model/kinematic_model.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace fivecal {

void AxisValuesToInternal(const Machine& m, const double* in, double* out) {
  for (int k = 0; k < m.num_axes(); ++k)
    out[k] = m.axis(k).rotary() ? in[k] * (M_PI / 180.0) : in[k];
}

namespace {

// KinematicModel allows 8 axes on each side.
constexpr int kMaxAxes = 16;

void ValidateTheta(const Machine& m, const Eigen::VectorXd& theta) {
  if (theta.size() != m.num_parameters())
    throw std::invalid_argument("errors: expected " + std::to_string(m.num_parameters()) +
                                " machine parameter values, got " + std::to_string(theta.size()));
  for (int i = 0; i < theta.size(); ++i)
    if (!(std::abs(theta[i]) <= kMaxErrorValue))
      RequireBounded(theta[i], kMaxErrorValue, "errors." + m.parameters()[i].name, "(mm or rad)");
}

void ValidateColumns(const Machine& m, Eigen::Index cols) {
  if (cols != m.num_axes())
    throw std::invalid_argument("axes: expected " + std::to_string(m.num_axes()) +
                                " columns (" + m.axis_names() + "), got " + std::to_string(cols));
}

// The plausibility bound of each axis command (mm or degrees).
double AxisBound(const Machine& m, int k) { return m.axis(k).rotary() ? kMaxRotaryDeg : kMaxLinear; }

[[noreturn]] void NotFinite(const Machine& m, Eigen::Index r, int k, double x) {
  const std::string where = "axes." + std::string(1, m.axis(k).name) + "[" + std::to_string(r) + "]";
  RequireBounded(x, AxisBound(m, k), where, m.axis(k).rotary() ? "degrees" : "mm");
  throw std::invalid_argument(where + ": value is not finite (NaN or inf)");
}

void ValidateDirectionsShape(Eigen::Index dir_rows, Eigen::Index dir_cols, Eigen::Index rows,
                             Eigen::Index cols) {
  if (dir_rows != rows || dir_cols != cols)
    throw std::invalid_argument("directions: shape must match axes (" + std::to_string(rows) + " x " +
                                std::to_string(cols) + ")");
}

[[noreturn]] void BadDirection(const Machine& m, Eigen::Index r, int k, int d) {
  throw std::invalid_argument("directions." + std::string(1, m.axis(k).name) + "[" +
                              std::to_string(r) + "]: must be -1, 0 or +1, got " + std::to_string(d));
}

}  // namespace

void ValidatePoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
                   const Eigen::MatrixXi* dirs) {
  ValidateTheta(m, theta);
  ValidateColumns(m, axes.cols());
  for (Eigen::Index r = 0; r < axes.rows(); ++r)
    for (int k = 0; k < axes.cols(); ++k)
      if (!(std::abs(axes(r, k)) <= AxisBound(m, k))) NotFinite(m, r, k, axes(r, k));
  if (dirs) {
    ValidateDirectionsShape(dirs->rows(), dirs->cols(), axes.rows(), axes.cols());
    for (Eigen::Index r = 0; r < dirs->rows(); ++r)
      for (int k = 0; k < dirs->cols(); ++k)
        if ((*dirs)(r, k) < -1 || (*dirs)(r, k) > 1) BadDirection(m, r, k, (*dirs)(r, k));
  }
}

void ToolPosesRowMajor(const Machine& m, const Eigen::VectorXd& theta,
                       const Eigen::Ref<const RowMatrixXd>& axes,
                       const RowMatrixXi* dirs, double* points, double* tool_axes,
                       const Eigen::Vector3d* tip) {
  if (tip)
    for (int i = 0; i < 3; ++i) RequireBounded((*tip)[i], kMaxLinear, "tip[" + std::to_string(i) + "]");
  ValidateTheta(m, theta);
  ValidateColumns(m, axes.cols());
  if (dirs) ValidateDirectionsShape(dirs->rows(), dirs->cols(), axes.rows(), axes.cols());
  const Eigen::Index n = axes.rows();
  const int na = m.num_axes();
  const KinematicModel model(m, theta.data());
  const Eigen::Vector3d t = tip ? *tip : model.tip();
  // AxisValuesToInternal's conversion with the per-axis factor hoisted out of
  // the pose loop: calling it per pose costs a fifth of the throughput.
  double scale[kMaxAxes], bound[kMaxAxes];
  for (int k = 0; k < na; ++k) {
    scale[k] = m.axis(k).rotary() ? M_PI / 180.0 : 1.0;
    bound[k] = AxisBound(m, k);
  }
  double q[kMaxAxes];
  int dir[kMaxAxes];
  // Validation is folded into the pass over the poses: one read of the data.
  for (Eigen::Index r = 0; r < n; ++r) {
    const double* row = axes.data() + r * axes.outerStride();
    for (int k = 0; k < na; ++k) {
      if (!(std::abs(row[k]) <= bound[k])) NotFinite(m, r, k, row[k]);
      q[k] = row[k] * scale[k];
    }
    if (dirs) {
      const int* d = dirs->data() + r * na;
      for (int k = 0; k < na; ++k) {
        if (d[k] < -1 || d[k] > 1) BadDirection(m, r, k, d[k]);
        dir[k] = d[k];
      }
    }
    Eigen::Vector3d p, a;
    model.ToolPose(q, dirs ? dir : nullptr, t, &p, tool_axes ? &a : nullptr);
    for (int c = 0; c < 3; ++c) points[3 * r + c] = p[c];
    if (tool_axes)
      for (int c = 0; c < 3; ++c) tool_axes[3 * r + c] = a[c];
  }
}

void ToolPoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
               const Eigen::MatrixXi* dirs, Eigen::MatrixXd* points, Eigen::MatrixXd* tool_axes,
               const Eigen::Vector3d* tip) {
  const RowMatrixXd ax = axes;
  RowMatrixXi d;
  if (dirs) d = *dirs;
  RowMatrixX3d p(axes.rows(), 3), a(tool_axes ? axes.rows() : 0, 3);
  ToolPosesRowMajor(m, theta, ax, dirs ? &d : nullptr, p.data(), tool_axes ? a.data() : nullptr, tip);
  *points = p;
  if (tool_axes) *tool_axes = a;
}

Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& theta,
                           const Eigen::MatrixXd& axes, const Eigen::MatrixXi* dirs) {
  Eigen::MatrixXd points;
  ToolPoses(m, theta, axes, dirs, &points, nullptr);
  return points;
}

}  // namespace fivecal
