#include "fivecal/kinematic_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

#include "fivecal/kinematics.h"

namespace fivecal {
namespace {

// Rz(c) Ry(b) Rx(a) and the local axes of its three factors (see header).
void Euler(double a, double b, double c, Eigen::Matrix3d* R, Eigen::Vector3d axes[3]) {
  if (a == 0.0 && b == 0.0 && c == 0.0) {
    R->setIdentity();
    axes[0] = Eigen::Vector3d::UnitX();
    axes[1] = Eigen::Vector3d::UnitY();
    axes[2] = Eigen::Vector3d::UnitZ();
    return;
  }
  *R = RotZYX<double>(a, b, c);
  const double cc = std::cos(c), sc = std::sin(c), cb = std::cos(b), sb = std::sin(b);
  axes[2] = Eigen::Vector3d::UnitZ();
  axes[1] = Eigen::Vector3d(-sc, cc, 0.0);              // Rz(c) y
  axes[0] = Eigen::Vector3d(cc * cb, sc * cb, -sb);     // Rz(c) Ry(b) x
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
      A.offset = m.location_index(k, 0);
      const double* loc = theta + A.offset;
      Euler(loc[3], loc[4], loc[5], &A.RE, A.eAxes);
      A.tE = m.axis(k).point - p_parent + Eigen::Vector3d(loc[0], loc[1], loc[2]);
      A.poly = theta + m.motion_index(k, 0, 1);
      for (int i = 0; i < 9; ++i) A.motion_t |= A.poly[i] != 0.0;
      for (int i = 9; i < 18; ++i) A.motion_r |= A.poly[i] != 0.0;
      A.backlash_index = m.backlash_index(k);
      A.backlash = A.backlash_index >= 0 ? theta[A.backlash_index] : 0.0;
      p_parent = m.axis(k).point;
    }
  };
  prepare(m.workpiece_chain());
  prepare(m.tool_chain());
  tip_ = TipWithOffsets<double>(m, theta);
}

void KinematicModel::Chain(const std::vector<int>& chain, const double* q, const int* dir,
                           Eigen::Matrix3d* R, Eigen::Vector3d* t, Eigen::Vector3d* p_last,
                           Factor* factors) const {
  R->setIdentity();
  t->setZero();
  p_last->setZero();
  int i = 0;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    const Axis& ax = machine_->axis(k);
    Factor* F = factors ? &factors[i++] : nullptr;
    if (F) F->R_before = *R;
    *t += *R * A.tE;
    if (F) F->oE = *t;
    *R = *R * A.RE;
    if (F) F->R_afterE = *R;
    const double qk = q[k];
    const double qm = (dir && dir[k] != 0) ? qk + A.backlash * dir[k] : qk;
    if (ax.rotary()) *R = *R * AxisAngle<double>(ax.direction, qm);
    else *t += *R * (ax.direction * qm);
    if (F) {
      F->R_afterM = *R;
      F->qpow[0] = 1.0;
      F->qpow[1] = qk;
      F->qpow[2] = qk * qk;
      F->qpow[3] = qk * qk * qk;
    }
    double e[6] = {0, 0, 0, 0, 0, 0};
    if (A.motion_t || A.motion_r)
      for (int c = 0; c < 6; ++c) {
        const double* p = A.poly + 3 * c;
        e[c] = ((p[2] * qk + p[1]) * qk + p[0]) * qk;
      }
    if (A.motion_t) *t += *R * Eigen::Vector3d(e[0], e[1], e[2]);
    if (F) F->oEps = *t;
    if (A.motion_r) {
      Eigen::Matrix3d Re;
      Eigen::Vector3d axes[3];
      Euler(e[3], e[4], e[5], &Re, F ? F->epsAxes : axes);
      *R = *R * Re;
    } else if (F) {
      F->epsAxes[0] = Eigen::Vector3d::UnitX();
      F->epsAxes[1] = Eigen::Vector3d::UnitY();
      F->epsAxes[2] = Eigen::Vector3d::UnitZ();
    }
    *p_last = ax.point;
  }
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
  Chain(machine_->tool_chain(), q, dir, &Rt, &tt, &pt, nullptr);
  Chain(machine_->workpiece_chain(), q, dir, &Rw, &tw, &pw, nullptr);
  const Eigen::Vector3d P = Rt * (tip - pt) + tt;
  const Eigen::Vector3d O = tw - Rw * pw;
  *point = Rw.transpose() * (P - O);
  if (axis) *axis = Rw.transpose() * (Rt * machine_->tool_axis());
}

void KinematicModel::Columns(const std::vector<int>& chain, const Factor* factors, const int* dir,
                             const Eigen::Vector3d& P, const Eigen::Matrix3d& out, double sign,
                             double* J) const {
  auto col = [&](int index) { return Eigen::Map<Eigen::Vector3d>(J + 3 * index); };
  int i = 0;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    const Factor& F = factors[i++];
    const Axis& ax = machine_->axis(k);
    const Eigen::Matrix3d S = sign * out;
    // Location errors.
    for (int c = 0; c < 3; ++c) col(A.offset + c) = S * F.R_before.col(c);
    const Eigen::Vector3d dE = P - F.oE;
    for (int c = 0; c < 3; ++c) col(A.offset + 3 + c) = S * (F.R_before * A.eAxes[c]).cross(dE);
    // Backlash: a shift of the command along or about the axis.
    if (A.backlash_index >= 0) {
      const int d = dir ? dir[k] : 0;
      const Eigen::Vector3d w = F.R_afterE * ax.direction;
      col(A.backlash_index) = d == 0 ? Eigen::Vector3d::Zero()
                                     : Eigen::Vector3d(d * (S * (ax.rotary() ? w.cross(dE) : w)));
    }
    // Error motions: the unit effect of each component times q^d.
    const Eigen::Vector3d dEps = P - F.oEps;
    for (int c = 0; c < 6; ++c) {
      const Eigen::Vector3d unit =
          c < 3 ? Eigen::Vector3d(S * F.R_afterM.col(c))
                : Eigen::Vector3d(S * (F.R_afterM * F.epsAxes[c - 3]).cross(dEps));
      for (int d = 1; d <= 3; ++d) col(machine_->motion_index(k, c, d)) = unit * F.qpow[d];
    }
  }
}

void KinematicModel::ToolPointJacobian(const double* q, const int* dir, const Eigen::Vector3d& tip,
                                       Eigen::Vector3d* point, double* J) const {
  const Machine& m = *machine_;
  Factor tf[kMaxChain], wf[kMaxChain];
  Eigen::Matrix3d Rt, Rw;
  Eigen::Vector3d tt, tw, pt, pw;
  Chain(m.tool_chain(), q, dir, &Rt, &tt, &pt, tf);
  Chain(m.workpiece_chain(), q, dir, &Rw, &tw, &pw, wf);
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
