// Forward kinematics of the erroneous machine, templated on the scalar so the
// same code runs on double and on ceres::Jet (Pinocchio style: the Machine is
// the immutable model, these are free functions).
//
// For axis k with parent axis frame origin p_parent (0 for the first axis
// from the foundation):
//
//   T_k(q) = Trans(p_k - p_parent) . E_k . M_k(q + Ekkb.dir) . eps_k(q)
//   E_k    = Trans(EX0k, EY0k, EZ0k) . Rz(EC0k) . Ry(EB0k) . Rx(EA0k)
//   M_k    = Trans(q u_k) (linear) | Rot(u_k, q) (rotary)
//   eps_k  = Trans(EXk(q), EYk(q), EZk(q)) . Rz(ECk(q)) . Ry(EBk(q)) . Rx(EAk(q))
//   EDk(q) = sum_{d=1..3} EDkd q^d            (q in mm or rad)
//
//   T_ft = prod_{tool chain} T_k . Trans(tip - p_last)
//   T_fw = prod_{workpiece chain} T_k . Trans(-p_last)
//   P_w  = inv(T_fw) . T_ft . 0          tool point in the workpiece frame
//   v_w  = R_fw^T R_ft a                 tool axis (a: tool axis at zero pose)
//
// Internal units: axis commands in mm and rad. The public double API at the
// bottom takes degrees for rotary axes.
#ifndef FIVECAL_KINEMATICS_H_
#define FIVECAL_KINEMATICS_H_

#include <Eigen/Core>
#include <cmath>

#include "fivecal/model/machine.h"

namespace fivecal {

template <typename T>
using Vec3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Mat3 = Eigen::Matrix<T, 3, 3>;

// A rigid transform (R, t): x -> R x + t.
template <typename T>
struct Frame {
  Mat3<T> R = Mat3<T>::Identity();
  Vec3<T> t = Vec3<T>::Zero();

  Frame operator*(const Frame& o) const { return Frame{R * o.R, R * o.t + t}; }
  Vec3<T> operator*(const Vec3<T>& p) const { return R * p + t; }
  Frame inverse() const {
    Frame f;
    f.R = R.transpose();
    f.t = -(f.R * t);
    return f;
  }
};

// Rz(c) . Ry(b) . Rx(a).
template <typename T>
Mat3<T> RotZYX(const T& a, const T& b, const T& c) {
  using std::cos;
  using std::sin;
  const T ca = cos(a), sa = sin(a), cb = cos(b), sb = sin(b), cc = cos(c), sc = sin(c);
  Mat3<T> R;
  R << cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa,
       sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa,
       -sb, cb * sa, cb * ca;
  return R;
}

// Rotation by angle q (rad) about the unit vector u (Rodrigues).
template <typename T>
Mat3<T> AxisAngle(const Eigen::Vector3d& u, const T& q) {
  using std::cos;
  using std::sin;
  const T c = cos(q), s = sin(q), v = T(1.0) - c;
  const double x = u.x(), y = u.y(), z = u.z();
  Mat3<T> R;
  R << c + v * (x * x), v * (x * y) - s * z, v * (x * z) + s * y,
       v * (x * y) + s * z, c + v * (y * y), v * (y * z) - s * x,
       v * (x * z) - s * y, v * (y * z) + s * x, c + v * (z * z);
  return R;
}

// The six error motions of axis k at the command q (mm or rad): e[0..2] =
// EXk EYk EZk (mm), e[3..5] = EAk EBk ECk (rad), each EDk(q) = sum_d EDkd q^d.
// The one evaluation of the polynomials: the chain below and whatever
// tabulates them (Beckhoff's volumetric compensation tables) call it.
template <typename T>
void ErrorMotions(const Machine& m, int k, const T* theta, double q, T e[6]) {
  for (int c = 0; c < 6; ++c) {
    const T* poly = theta + m.motion_index(k, c, 1);
    e[c] = ((poly[2] * q + poly[1]) * q + poly[0]) * q;  // Horner
  }
}

// T_k(q) for axis k; theta is the full machine parameter vector, q the command
// in mm or rad, dir the direction of the last move (+1, -1, or 0 = no backlash).
template <typename T>
Frame<T> AxisFrame(const Machine& m, int k, const Eigen::Vector3d& p_parent, const T* theta,
                   double q, int dir) {
  const Axis& ax = m.axis(k);
  const T* loc = theta + m.location_index(k, 0);
  Frame<T> E;
  E.R = RotZYX(loc[3], loc[4], loc[5]);
  E.t = Vec3<T>(loc[0], loc[1], loc[2]) + (ax.point - p_parent).template cast<T>();

  T qm = T(q);
  const int b = m.backlash_index(k);
  if (b >= 0 && dir != 0) qm = qm + theta[b] * double(dir);

  T e[6];
  ErrorMotions(m, k, theta, q, e);
  Frame<T> eps;
  eps.R = RotZYX(e[3], e[4], e[5]);
  eps.t = Vec3<T>(e[0], e[1], e[2]);

  Frame<T> M;
  if (ax.rotary()) M.R = AxisAngle(ax.direction, qm);
  else M.t = ax.direction.template cast<T>() * qm;
  return E * M * eps;
}

// Product of the axis frames along a chain (foundation outward).
template <typename T>
Frame<T> ChainFrame(const Machine& m, const std::vector<int>& chain, const T* theta,
                    const double* q, const int* dir, Eigen::Vector3d* p_last) {
  Frame<T> F;
  Eigen::Vector3d p_parent = Eigen::Vector3d::Zero();
  for (int k : chain) {
    F = F * AxisFrame<T>(m, k, p_parent, theta, q[k], dir ? dir[k] : 0);
    p_parent = m.axis(k).point;
  }
  *p_last = p_parent;
  return F;
}

// The nominal tip (in F at the zero pose) plus the tip.x|y|z setup offsets.
template <typename T>
Vec3<T> TipWithOffsets(const Machine& m, const T* theta) {
  const T* d = theta + m.tip_index();
  return m.tip().template cast<T>() + Vec3<T>(d[0], d[1], d[2]);
}

// Tool point (and optionally tool axis) in the workpiece frame for a tool
// point `tip` given in F at the zero pose. q and dir are in machine axis order
// (Machine::axes()), q in mm / rad; dir may be null.
template <typename T>
void ToolInWorkpiece(const Machine& m, const T* theta, const double* q, const int* dir,
                     const Vec3<T>& tip, Vec3<T>* point, Vec3<T>* axis = nullptr) {
  Eigen::Vector3d p_tool, p_work;
  const Frame<T> Ft = ChainFrame<T>(m, m.tool_chain(), theta, q, dir, &p_tool);
  const Frame<T> Fw = ChainFrame<T>(m, m.workpiece_chain(), theta, q, dir, &p_work);
  // T_fw carries a final Trans(-p_last): its origin sits at Fw * (-p_work).
  const Vec3<T> tool_in_f = Ft * Vec3<T>(tip - p_tool.template cast<T>());
  const Vec3<T> work_origin = Fw * Vec3<T>((-p_work).template cast<T>());
  *point = Fw.R.transpose() * (tool_in_f - work_origin);
  if (axis) *axis = Fw.R.transpose() * (Ft.R * m.tool_axis().template cast<T>());
}

// ---- Public double API (rotary axes in degrees) ---------------------------

// Converts one row of public axis values (mm / degrees) to internal units.
void AxisValuesToInternal(const Machine& m, const double* in, double* out);

// Validates theta, the axes matrix (N x num_axes, machine axis order) and the
// optional direction matrix (N x num_axes, entries -1/0/+1); throws
// std::invalid_argument naming the row and axis.
void ValidatePoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
                   const Eigen::MatrixXi* dirs);

// Tool points (N x 3, mm, workpiece frame) for N poses.
Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& theta,
                           const Eigen::MatrixXd& axes, const Eigen::MatrixXi* dirs = nullptr);

using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixXi = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixX3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// ToolPoses on row-major data (numpy's layout, no copies at the Python
// boundary): points and tool_axes (may be null) are N x 3 row-major buffers.
// Validates as ValidatePoses does.
void ToolPosesRowMajor(const Machine& m, const Eigen::VectorXd& theta,
                       const Eigen::Ref<const RowMatrixXd>& axes,
                       const RowMatrixXi* dirs, double* points, double* tool_axes,
                       const Eigen::Vector3d* tip = nullptr);

// Tool points and unit tool axis directions (both N x 3, workpiece frame).
// `tip`, when given, replaces the machine tip and its tip.x|y|z offsets (a
// ball-bar tool ball, in F at the zero pose).
void ToolPoses(const Machine& m, const Eigen::VectorXd& theta, const Eigen::MatrixXd& axes,
               const Eigen::MatrixXi* dirs, Eigen::MatrixXd* points, Eigen::MatrixXd* tool_axes,
               const Eigen::Vector3d* tip = nullptr);

}  // namespace fivecal

#endif  // FIVECAL_KINEMATICS_H_
