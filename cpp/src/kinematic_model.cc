#include "fivecal/kinematic_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

#include "fivecal/kinematics.h"

namespace fivecal {
namespace {

// sin and cos; error-motion angles are micro-radians, where the Taylor
// series to x^9 / x^10 is exact to double precision (the first omitted term
// is below 1e-18 relative for |x| < 0.1) and several times cheaper than libm.
inline void SinCos(double x, double* s, double* c) {
  if (std::abs(x) < 0.1) {
    const double x2 = x * x;
    *s = x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0))));
    *c = 1.0 - x2 / 2.0 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0))));
  } else {
    *s = std::sin(x);
    *c = std::cos(x);
  }
}

// R <- R . Rot_k(angle) for a coordinate axis k: two columns change.
inline void RotateAbout(Eigen::Matrix3d* R, int k, double s, double c) {
  const int i = (k + 1) % 3, j = (k + 2) % 3;
  const Eigen::Vector3d ci = R->col(i), cj = R->col(j);
  R->col(i) = c * ci + s * cj;
  R->col(j) = c * cj - s * ci;
}

// Rz(c) Ry(b) Rx(a) and the local axes of its three factors (see header).
void Euler(double a, double b, double c, Eigen::Matrix3d* R, Eigen::Vector3d axes[3]) {
  R->setIdentity();
  double s, co;
  SinCos(c, &s, &co);
  RotateAbout(R, 2, s, co);
  axes[2] = Eigen::Vector3d::UnitZ();
  axes[1] = R->col(1);  // Rz(c) y
  SinCos(b, &s, &co);
  RotateAbout(R, 1, s, co);
  axes[0] = R->col(0);  // Rz(c) Ry(b) x
  SinCos(a, &s, &co);
  RotateAbout(R, 0, s, co);
}

}  // namespace

KinematicModel::KinematicModel(const Machine& m, const double* theta) : machine_(&m) {
  axes_.resize(m.num_axes());
  auto prepare = [&](const std::vector<int>& chain) {
    if (chain.size() > static_cast<size_t>(kMaxChain))
      throw std::invalid_argument("machine: more than 8 axes on one side");
    Eigen::Vector3d p_parent = Eigen::Vector3d::Zero();
    for (int k : chain) {
      AxisConstants& A = axes_[k];
      const Axis& ax = m.axis(k);
      A.offset = m.location_index(k, 0);
      const double* loc = theta + A.offset;
      Euler(loc[3], loc[4], loc[5], &A.RE, A.eAxes);
      A.RE_identity = loc[3] == 0.0 && loc[4] == 0.0 && loc[5] == 0.0;
      A.tE = ax.point - p_parent + Eigen::Vector3d(loc[0], loc[1], loc[2]);
      A.direction = ax.direction;
      A.rotary = ax.rotary();
      for (int i = 0; i < 3; ++i)
        if (std::abs(ax.direction[i]) == 1.0 && ax.direction.squaredNorm() == 1.0) {
          A.unit_axis = i;
          A.unit_sign = ax.direction[i];
        }
      A.poly = theta + m.motion_index(k, 0, 1);
      for (int i = 0; i < 9; ++i) A.motion_t |= A.poly[i] != 0.0;
      for (int i = 9; i < 18; ++i) A.motion_r |= A.poly[i] != 0.0;
      for (int c = 0; c < 6; ++c)
        for (int d = 1; d <= 3; ++d) A.motion_index[c][d] = m.motion_index(k, c, d);
      A.backlash_index = m.backlash_index(k);
      A.backlash = A.backlash_index >= 0 ? theta[A.backlash_index] : 0.0;
      p_parent = ax.point;
    }
  };
  prepare(m.workpiece_chain());
  prepare(m.tool_chain());
  tip_ = TipWithOffsets<double>(m, theta);
}

void KinematicModel::RestrictJacobian(const std::vector<int>& wanted) {
  const Machine& m = *machine_;
  for (AxisConstants& A : axes_) A.want_location = A.want_motion = false;
  for (int i : wanted) {
    if (i < 0 || i >= m.num_parameters()) continue;  // setup parameters have no machine column
    const ParameterInfo& p = m.parameters()[i];
    if (p.axis < 0) continue;  // tip: always written
    AxisConstants& A = axes_[p.axis];
    if (p.kind == ParameterKind::kMotion) A.want_motion = true;
    else A.want_location = true;  // location and backlash share the E frame
  }
}

template <bool kRecord>
void KinematicModel::Chain(const std::vector<int>& chain, const double* q, const int* dir,
                           Eigen::Matrix3d* R, Eigen::Vector3d* t, Eigen::Vector3d* p_last,
                           Factor* factors) const {
  R->setIdentity();
  t->setZero();
  int i = 0;
  const Machine& m = *machine_;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    Factor* F = kRecord ? &factors[i++] : nullptr;
    if (kRecord) F->R_before = *R;
    *t += *R * A.tE;
    if (kRecord) F->oE = *t;
    if (!A.RE_identity) *R = *R * A.RE;
    if (kRecord) F->backlash_w = *R * A.direction;
    const double qk = q[k];
    const double qm = (dir && dir[k] != 0) ? qk + A.backlash * dir[k] : qk;
    if (A.rotary) {
      if (A.unit_axis >= 0) {
        double s, c;
        SinCos(A.unit_sign * qm, &s, &c);
        RotateAbout(R, A.unit_axis, s, c);
      } else {
        *R = *R * AxisAngle<double>(A.direction, qm);
      }
    } else if (A.unit_axis >= 0) {
      *t += R->col(A.unit_axis) * (A.unit_sign * qm);
    } else {
      *t += *R * (A.direction * qm);
    }
    if (kRecord) {
      F->R_afterM = *R;
      F->qpow[0] = 1.0;
      F->qpow[1] = qk;
      F->qpow[2] = qk * qk;
      F->qpow[3] = qk * qk * qk;
    }
    if (A.motion_t || A.motion_r) {
      double e[6];
      for (int c = 0; c < 6; ++c) {
        const double* p = A.poly + 3 * c;
        e[c] = ((p[2] * qk + p[1]) * qk + p[0]) * qk;
      }
      if (A.motion_t) *t += *R * Eigen::Vector3d(e[0], e[1], e[2]);
      if (kRecord) F->oEps = *t;
      if (A.motion_r) {
        // R . Rz(e5) Ry(e4) Rx(e3), recording each factor's axis on the way.
        double s, c;
        if (kRecord) F->epsW[2] = R->col(2);
        SinCos(e[5], &s, &c);
        RotateAbout(R, 2, s, c);
        if (kRecord) F->epsW[1] = R->col(1);
        SinCos(e[4], &s, &c);
        RotateAbout(R, 1, s, c);
        if (kRecord) F->epsW[0] = R->col(0);
        SinCos(e[3], &s, &c);
        RotateAbout(R, 0, s, c);
      } else if (kRecord) {
        for (int c = 0; c < 3; ++c) F->epsW[c] = R->col(c);
      }
    } else if (kRecord) {
      F->oEps = *t;
      for (int c = 0; c < 3; ++c) F->epsW[c] = R->col(c);
    }
    *p_last = m.axis(k).point;
  }
  if (chain.empty()) p_last->setZero();
}

Eigen::Vector3d KinematicModel::ToolPoint(const double* q, const int* dir,
                                          const Eigen::Vector3d& tip) const {
  Eigen::Vector3d p;
  ToolPose(q, dir, tip, &p, nullptr);
  return p;
}

void KinematicModel::ToolPose(const double* q, const int* dir, const Eigen::Vector3d& tip,
                              Eigen::Vector3d* point, Eigen::Vector3d* axis) const {
  Eigen::Matrix3d Rt, Rw;
  Eigen::Vector3d tt, tw, pt, pw;
  Chain<false>(machine_->tool_chain(), q, dir, &Rt, &tt, &pt, nullptr);
  Chain<false>(machine_->workpiece_chain(), q, dir, &Rw, &tw, &pw, nullptr);
  const Eigen::Vector3d P = Rt * (tip - pt) + tt;
  const Eigen::Vector3d O = tw - Rw * pw;
  *point = Rw.transpose() * (P - O);
  if (axis) *axis = Rw.transpose() * (Rt * machine_->tool_axis());
}

// Every column is out * (a twist at P) with `out` = R_w^T a rotation, so
// out (a x b) = (out a) x (out b): the axes and lever arms are mapped once
// per axis and the columns are then plain vectors and cross products.
void KinematicModel::Columns(const std::vector<int>& chain, const Factor* factors, const int* dir,
                             const Eigen::Vector3d& P, const Eigen::Matrix3d& out, double sign,
                             double* J) const {
  auto col = [&](int index) { return Eigen::Map<Eigen::Vector3d>(J + 3 * index); };
  int i = 0;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    const Factor& F = factors[i++];
    if (A.want_location) {
      const Eigen::Matrix3d Qb = sign * (out * F.R_before);
      const Eigen::Vector3d dE = out * (P - F.oE);
      for (int c = 0; c < 3; ++c) {
        col(A.offset + c) = Qb.col(c);
        col(A.offset + 3 + c) = (Qb * A.eAxes[c]).cross(dE);
      }
      // Backlash: a shift of the command along or about the axis.
      if (A.backlash_index >= 0) {
        const int d = dir ? dir[k] : 0;
        const Eigen::Vector3d w = (sign * d) * (out * F.backlash_w);
        col(A.backlash_index) = A.rotary ? Eigen::Vector3d(w.cross(dE)) : w;
      }
    }
    if (A.want_motion) {
      // Error motions: the unit effect of each component times q^d.
      const Eigen::Matrix3d Qm = sign * (out * F.R_afterM);
      const Eigen::Vector3d dEps = out * (P - F.oEps);
      for (int c = 0; c < 6; ++c) {
        const Eigen::Vector3d unit =
            c < 3 ? Eigen::Vector3d(Qm.col(c))
                  : Eigen::Vector3d((sign * (out * F.epsW[c - 3])).cross(dEps));
        for (int d = 1; d <= 3; ++d) col(A.motion_index[c][d]) = unit * F.qpow[d];
      }
    }
  }
}

void KinematicModel::ToolPointJacobian(const double* q, const int* dir, const Eigen::Vector3d& tip,
                                       Eigen::Vector3d* point, double* J) const {
  const Machine& m = *machine_;
  Factor tf[kMaxChain], wf[kMaxChain];
  Eigen::Matrix3d Rt, Rw;
  Eigen::Vector3d tt, tw, pt, pw;
  Chain<true>(m.tool_chain(), q, dir, &Rt, &tt, &pt, tf);
  Chain<true>(m.workpiece_chain(), q, dir, &Rw, &tw, &pw, wf);
  const Eigen::Vector3d P = Rt * (tip - pt) + tt;
  const Eigen::Vector3d O = tw - Rw * pw;
  const Eigen::Matrix3d RwT = Rw.transpose();
  *point = RwT * (P - O);
  Columns(m.tool_chain(), tf, dir, P, RwT, 1.0, J);
  Columns(m.workpiece_chain(), wf, dir, P, RwT, -1.0, J);
  const Eigen::Matrix3d dtip = RwT * Rt;
  Eigen::Map<Eigen::Matrix3d>(J + 3 * m.tip_index()) = dtip;
}

}  // namespace fivecal
