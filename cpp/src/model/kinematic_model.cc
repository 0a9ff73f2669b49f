#include "fivecal/model/kinematic_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

#include "fivecal/model/kinematics.h"

// The chain and Jacobian loops are scalar 3x3 algebra with long dependency
// chains; with FMA and AVX2 (x86-64-v3) they run about 20% faster. Cloned
// per ISA level and dispatched at load time, so the binary still runs on any
// x86-64 (and other architectures build the plain version).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__)
#define FIVECAL_ISA_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define FIVECAL_ISA_CLONES
#endif

namespace fivecal {
namespace {

// sin and cos. Error-motion angles are micro-radians, where a few Taylor
// terms are exact to double precision and several times cheaper than libm:
// below 1e-3 the first omitted terms (x^7/5040, x^6/720) are under 1e-20
// relative, below 0.1 (to x^9 / x^10) under 1e-18.
inline void SinCos(double x, double* s, double* c) {
  const double x2 = x * x;
  if (x2 < 1e-6) {
    *s = x + x * x2 * (-1.0 / 6 + x2 * (1.0 / 120));
    *c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24));
  } else if (x2 < 1e-2) {
    *s = x + x * x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880))));
    *c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24 + x2 * (-1.0 / 720 + x2 * (1.0 / 40320 + x2 * (-1.0 / 3628800)))));
  } else {
    *s = std::sin(x);
    *c = std::cos(x);
  }
}

// sin and cos of an axis command (any size): Cody-Waite reduction by pi/2
// in three parts (exact for |k| < 2^20) and Taylor polynomials on
// |r| <= pi/4 to r^15 / r^16 (first omitted terms below 7e-17 relative), so
// within an ulp or two of libm at a third of its cost.
inline void SinCosCommand(double x, double* s, double* c) {
  if (!(std::abs(x) < 1e5)) {
    *s = std::sin(x);
    *c = std::cos(x);
    return;
  }
  constexpr double kTwoOverPi = 6.36619772367581382433e-01;
  constexpr double kPio2_1 = 1.57079632673412561417e+00;  // 33 bits
  constexpr double kPio2_2 = 6.07710050630396597660e-11;
  constexpr double kPio2_3 = 2.02226624871116645580e-21;
  const double t = x * kTwoOverPi;
  const long long k = static_cast<long long>(t + (t >= 0 ? 0.5 : -0.5));
  const double kd = static_cast<double>(k);
  const double r = ((x - kd * kPio2_1) - kd * kPio2_2) - kd * kPio2_3;
  const double r2 = r * r;
  const double sr =
      r + r * r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880 +
      r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800 + r2 * (-1.0 / 1307674368000.0)))))));
  const double cr =
      1.0 + r2 * (-0.5 + r2 * (1.0 / 24 + r2 * (-1.0 / 720 + r2 * (1.0 / 40320 + r2 * (-1.0 / 3628800 +
      r2 * (1.0 / 479001600 + r2 * (-1.0 / 87178291200.0 + r2 * (1.0 / 20922789888000.0))))))));
  // Quadrant without branches (random commands would mispredict them).
  const double v[2] = {sr, cr};
  const double sign[2] = {1.0, -1.0};
  const int odd = static_cast<int>(k & 1);
  *s = v[odd] * sign[(k >> 1) & 1];
  *c = v[odd ^ 1] * sign[((k + 1) >> 1) & 1];
}

// R <- R . Rot_k(angle) for a coordinate axis k: two columns change.
template <int k>
inline void RotateAbout(Eigen::Matrix3d* R, double s, double c) {
  constexpr int i = (k + 1) % 3, j = (k + 2) % 3;
  const Eigen::Vector3d ci = R->col(i), cj = R->col(j);
  R->col(i) = c * ci + s * cj;
  R->col(j) = c * cj - s * ci;
}

inline void RotateAbout(Eigen::Matrix3d* R, int k, double s, double c) {
  switch (k) {
    case 0: RotateAbout<0>(R, s, c); break;
    case 1: RotateAbout<1>(R, s, c); break;
    default: RotateAbout<2>(R, s, c); break;
  }
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
      for (int c = 0; c < 3; ++c) {
        A.loc_rot[c] = loc[3 + c] != 0.0;
        SinCos(loc[3 + c], &A.loc_sin[c], &A.loc_cos[c]);
      }
      A.tE = ax.point - p_parent + Eigen::Vector3d(loc[0], loc[1], loc[2]);
      A.direction = ax.direction;
      A.rotary = ax.rotary();
      for (int i = 0; i < 3; ++i)
        if (std::abs(ax.direction[i]) == 1.0 && ax.direction.squaredNorm() == 1.0) {
          A.unit_axis = i;
          A.unit_sign = ax.direction[i];
        }
      A.poly = theta + m.motion_index(k, 0, 1);
      for (int c = 0; c < 6; ++c)
        A.motion[c] = A.poly[3 * c] != 0.0 || A.poly[3 * c + 1] != 0.0 || A.poly[3 * c + 2] != 0.0;
      A.motion_t = A.motion[0] || A.motion[1] || A.motion[2];
      A.motion_r = A.motion[3] || A.motion[4] || A.motion[5];
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
  for (AxisConstants& A : axes_) {
    A.want_location = A.want_motion = false;
    A.location_mask = A.motion_mask = 0;
  }
  for (int i : wanted) {
    if (i < 0 || i >= m.num_parameters()) continue;  // setup parameters have no machine column
    const ParameterInfo& p = m.parameters()[i];
    if (p.axis < 0) continue;  // tip: always written
    AxisConstants& A = axes_[p.axis];
    if (p.kind == ParameterKind::kMotion) {
      A.want_motion = true;
      A.motion_mask |= 1u << (3 * p.component + p.degree - 1);
    } else {
      A.want_location = true;  // location and backlash share the E frame
      A.location_mask |= p.kind == ParameterKind::kBacklash ? 1u << 6 : 1u << p.component;
    }
  }
}

template <bool kRecord>
FIVECAL_ISA_CLONES void KinematicModel::Chain(const std::vector<int>& chain, const double* q, const int* dir,
                           Eigen::Matrix3d* R, Eigen::Vector3d* t, Eigen::Vector3d* p_last,
                           Factor* factors) const {
  int i = 0;
  const Machine& m = *machine_;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    Factor* F = kRecord ? &factors[i] : nullptr;
    // Only the frames a written column reads are recorded (Columns skips an
    // axis without wanted columns): a fit of a few location errors records
    // one or two axes, not the whole chain, per sample.
    const bool rec_loc = kRecord && A.want_location, rec_motion = kRecord && A.want_motion;
    if (i++ == 0) {
      // The chain starts at F: its first frame is E itself.
      if (rec_loc) F->R_before.setIdentity();
      *t = A.tE;
      *R = A.RE;
    } else {
      if (rec_loc) F->R_before = *R;
      *t += *R * A.tE;
      // R . Rz(EC0) Ry(EB0) Rx(EA0), skipping the zero angles.
      if (A.loc_rot[2]) RotateAbout<2>(R, A.loc_sin[2], A.loc_cos[2]);
      if (A.loc_rot[1]) RotateAbout<1>(R, A.loc_sin[1], A.loc_cos[1]);
      if (A.loc_rot[0]) RotateAbout<0>(R, A.loc_sin[0], A.loc_cos[0]);
    }
    if (rec_loc) F->oE = *t;
    if (rec_loc && (A.location_mask & (1u << 6))) F->backlash_w = *R * A.direction;
    const double qk = q[k];
    const double qm = (dir && dir[k] != 0) ? qk + A.backlash * dir[k] : qk;
    if (A.rotary) {
      if (A.unit_axis >= 0) {
        double s, c;
        SinCosCommand(A.unit_sign * qm, &s, &c);
        RotateAbout(R, A.unit_axis, s, c);
      } else {
        *R = *R * AxisAngle<double>(A.direction, qm);
      }
    } else if (A.unit_axis >= 0) {
      *t += R->col(A.unit_axis) * (A.unit_sign * qm);
    } else {
      *t += *R * (A.direction * qm);
    }
    if (rec_motion) {
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
      if (A.motion_t) *t += R->col(0) * e[0] + R->col(1) * e[1] + R->col(2) * e[2];
      if (rec_motion) F->oEps = *t;
      if (A.motion_r) {
        // R . Rz(e5) Ry(e4) Rx(e3), recording each factor's axis on the way.
        double s, c;
        if (rec_motion) F->epsW[2] = R->col(2);
        if (A.motion[5]) {
          SinCos(e[5], &s, &c);
          RotateAbout<2>(R, s, c);
        }
        if (rec_motion) F->epsW[1] = R->col(1);
        if (A.motion[4]) {
          SinCos(e[4], &s, &c);
          RotateAbout<1>(R, s, c);
        }
        if (rec_motion) F->epsW[0] = R->col(0);
        if (A.motion[3]) {
          SinCos(e[3], &s, &c);
          RotateAbout<0>(R, s, c);
        }
      } else if (rec_motion) {
        for (int c = 0; c < 3; ++c) F->epsW[c] = R->col(c);
      }
    } else if (rec_motion) {
      F->oEps = *t;
      for (int c = 0; c < 3; ++c) F->epsW[c] = R->col(c);
    }
  }
  if (chain.empty()) {
    R->setIdentity();
    t->setZero();
    p_last->setZero();
  } else {
    *p_last = m.axis(chain.back()).point;
  }
}

Eigen::Vector3d KinematicModel::ToolPoint(const double* q, const int* dir,
                                          const Eigen::Vector3d& tip) const {
  Eigen::Vector3d p;
  ToolPose(q, dir, tip, &p, nullptr);
  return p;
}

FIVECAL_ISA_CLONES void KinematicModel::ToolPose(const double* q, const int* dir, const Eigen::Vector3d& tip,
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

// Every column is out * (a twist at P), out = +-R_w^T. Lever-arm cross
// products are taken in the chain's base frame before mapping: an error with
// no effect (axis through P) then gives an exactly zero column, which the
// identifiability analysis reports as "no effect".
FIVECAL_ISA_CLONES void KinematicModel::Columns(const std::vector<int>& chain, const Factor* factors, const int* dir,
                             const Eigen::Vector3d& P, const Eigen::Matrix3d& out, double sign,
                             double* J) const {
  auto col = [&](int index) { return Eigen::Map<Eigen::Vector3d>(J + 3 * index); };
  const Eigen::Matrix3d S = sign * out;
  int i = 0;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    const Factor& F = factors[i++];
    if (A.want_location) {
      const Eigen::Vector3d dE = P - F.oE;
      for (int c = 0; c < 3; ++c) {
        if (A.location_mask & (1u << c)) col(A.offset + c) = S * F.R_before.col(c);
        if (A.location_mask & (8u << c)) col(A.offset + 3 + c) = S * (F.R_before * A.eAxes[c]).cross(dE);
      }
      // Backlash: a shift of the command along or about the axis.
      if (A.backlash_index >= 0 && (A.location_mask & (1u << 6))) {
        const int d = dir ? dir[k] : 0;
        const Eigen::Vector3d& w = F.backlash_w;
        col(A.backlash_index) = d * (S * (A.rotary ? Eigen::Vector3d(w.cross(dE)) : w));
      }
    }
    if (A.want_motion) {
      // Error motions: the unit effect of each component times q^d.
      const Eigen::Vector3d dEps = P - F.oEps;
      for (int c = 0; c < 6; ++c) {
        if (!((A.motion_mask >> (3 * c)) & 7u)) continue;
        const Eigen::Vector3d unit =
            c < 3 ? Eigen::Vector3d(S * F.R_afterM.col(c)) : Eigen::Vector3d(S * F.epsW[c - 3].cross(dEps));
        for (int d = 1; d <= 3; ++d)
          if (A.motion_mask & (1u << (3 * c + d - 1))) col(A.motion_index[c][d]) = unit * F.qpow[d];
      }
    }
  }
}

FIVECAL_ISA_CLONES void KinematicModel::ToolPointJacobian(const double* q, const int* dir, const Eigen::Vector3d& tip,
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
