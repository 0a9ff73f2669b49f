#include "fivecal/model/kinematic_model.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
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
// The chain's small helpers must be inlined into its clones: called out of
// line they are default-ISA functions, and when this file grew (the lane
// kernel) GCC stopped inlining RotateAbout into Chain on its own, which made
// the forward kinematics 15 % slower (bench/versus.py against d499e5f).
#if defined(__GNUC__)
#define FIVECAL_CHAIN_INLINE __attribute__((always_inline)) inline
#else
#define FIVECAL_CHAIN_INLINE inline
#endif

namespace fivecal {
namespace {

// sin and cos. Error-motion angles are micro-radians, where a few Taylor
// terms are exact to double precision and several times cheaper than libm:
// below 1e-3 the first omitted terms (x^7/5040, x^6/720) are under 1e-20
// relative, below 0.1 (to x^9 / x^10) under 1e-18.
FIVECAL_CHAIN_INLINE void SinCos(double x, double* s, double* c) {
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
FIVECAL_CHAIN_INLINE void SinCosCommand(double x, double* s, double* c) {
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
FIVECAL_CHAIN_INLINE void RotateAbout(Eigen::Matrix3d* R, double s, double c) {
  constexpr int i = (k + 1) % 3, j = (k + 2) % 3;
  const Eigen::Vector3d ci = R->col(i), cj = R->col(j);
  R->col(i) = c * ci + s * cj;
  R->col(j) = c * cj - s * ci;
}

FIVECAL_CHAIN_INLINE void RotateAbout(Eigen::Matrix3d* R, int k, double s, double c) {
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

// ---- ToolPointLanes: the same chain and columns, kLanes samples at a time ----------

// The batched kernel is cloned for AVX-512 as well: its loops run over the
// kLanes = 8 samples, one AVX-512 register of doubles (two AVX2 ones).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) && \
    !defined(__SANITIZE_ADDRESS__)
#define FIVECAL_LANE_CLONES __attribute__((target_clones("avx512f", "arch=x86-64-v3", "default")))
#define FIVECAL_LANE_INLINE __attribute__((always_inline)) inline
#define FIVECAL_LANE_ALWAYS __attribute__((always_inline))
#else
#define FIVECAL_LANE_ALWAYS
#define FIVECAL_LANE_CLONES
#define FIVECAL_LANE_INLINE inline
#endif

namespace {

constexpr int W = KinematicModel::kLanes;

// One number per sample of the batch, with element-wise operators. With
// GCC and Clang a vector type: every operation is one instruction over all
// the lanes, so a sample's result does not depend on its lane (loops over
// lane arrays were vectorised in part, and a multiply-add fused in one lane
// and not in another changed the last bit with the batch's position).
#if defined(__GNUC__)
typedef double LaneVector __attribute__((vector_size(W * sizeof(double))));
struct LV {
  LaneVector v;
  static FIVECAL_LANE_INLINE LV All(double x) {
    LV r;
    r.v = x - LaneVector{};
    return r;
  }
  static FIVECAL_LANE_INLINE LV Load(const double* p) {
    LV r;
    std::memcpy(&r.v, p, sizeof r.v);
    return r;
  }
  FIVECAL_LANE_INLINE void Store(double* p) const { std::memcpy(p, &v, sizeof v); }
};
FIVECAL_LANE_INLINE LV operator+(LV a, const LV& b) { return {a.v + b.v}; }
FIVECAL_LANE_INLINE LV operator-(LV a, const LV& b) { return {a.v - b.v}; }
FIVECAL_LANE_INLINE LV operator*(LV a, const LV& b) { return {a.v * b.v}; }
FIVECAL_LANE_INLINE LV operator*(LV a, double s) { return {a.v * s}; }
FIVECAL_LANE_INLINE LV operator+(LV a, double s) { return {a.v + s}; }
#else
struct LV {
  double v[W];
  static FIVECAL_LANE_INLINE LV All(double x) {
    LV r;
    for (int l = 0; l < W; ++l) r.v[l] = x;
    return r;
  }
  static FIVECAL_LANE_INLINE LV Load(const double* p) {
    LV r;
    for (int l = 0; l < W; ++l) r.v[l] = p[l];
    return r;
  }
  FIVECAL_LANE_INLINE void Store(double* p) const {
    for (int l = 0; l < W; ++l) p[l] = v[l];
  }
};
FIVECAL_LANE_INLINE LV operator+(LV a, const LV& b) {
  for (int l = 0; l < W; ++l) a.v[l] += b.v[l];
  return a;
}
FIVECAL_LANE_INLINE LV operator-(LV a, const LV& b) {
  for (int l = 0; l < W; ++l) a.v[l] -= b.v[l];
  return a;
}
FIVECAL_LANE_INLINE LV operator*(LV a, const LV& b) {
  for (int l = 0; l < W; ++l) a.v[l] *= b.v[l];
  return a;
}
FIVECAL_LANE_INLINE LV operator*(LV a, double s) {
  for (int l = 0; l < W; ++l) a.v[l] *= s;
  return a;
}
FIVECAL_LANE_INLINE LV operator+(LV a, double s) {
  for (int l = 0; l < W; ++l) a.v[l] += s;
  return a;
}
#endif
FIVECAL_LANE_INLINE LV operator*(double s, LV a) { return a * s; }

struct LVec {
  LV c[3];
  static FIVECAL_LANE_INLINE LVec All(const Eigen::Vector3d& x) { return {{LV::All(x[0]), LV::All(x[1]), LV::All(x[2])}}; }
};
FIVECAL_LANE_INLINE LVec operator-(const LVec& a, const LVec& b) { return {{a.c[0] - b.c[0], a.c[1] - b.c[1], a.c[2] - b.c[2]}}; }
FIVECAL_LANE_INLINE LVec operator*(const LVec& a, const LV& s) { return {{a.c[0] * s, a.c[1] * s, a.c[2] * s}}; }
FIVECAL_LANE_INLINE LVec Cross(const LVec& a, const LVec& b) {
  return {{a.c[1] * b.c[2] - a.c[2] * b.c[1], a.c[2] * b.c[0] - a.c[0] * b.c[2], a.c[0] * b.c[1] - a.c[1] * b.c[0]}};
}

// A rotation per sample, column by column: col[i].c[j] = R(j, i).
struct LMat {
  LVec col[3];
  static FIVECAL_LANE_INLINE LMat All(const Eigen::Matrix3d& R) {
    LMat m;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) m.col[i].c[j] = LV::All(R(j, i));
    return m;
  }
  // R x for a constant x.
  FIVECAL_LANE_INLINE LVec Times(const Eigen::Vector3d& x) const {
    LVec r;
    for (int j = 0; j < 3; ++j) r.c[j] = col[0].c[j] * x[0] + col[1].c[j] * x[1] + col[2].c[j] * x[2];
    return r;
  }
  // R^T x.
  FIVECAL_LANE_INLINE LVec TransposeTimes(const LVec& x) const {
    LVec r;
    for (int j = 0; j < 3; ++j) r.c[j] = col[j].c[0] * x.c[0] + col[j].c[1] * x.c[1] + col[j].c[2] * x.c[2];
    return r;
  }
  // R . Rot_k(angle): two columns change (RotateAbout).
  template <typename S>
  FIVECAL_LANE_INLINE void Rotate(int k, const S& s, const S& c) {
    const int i = (k + 1) % 3, j = (k + 2) % 3;
    const LVec ci = col[i], cj = col[j];
    for (int r = 0; r < 3; ++r) {
      col[i].c[r] = ci.c[r] * c + cj.c[r] * s;
      col[j].c[r] = cj.c[r] * c - ci.c[r] * s;
    }
  }
};

// SinCosCommand over the lanes: the same reduction and polynomials, the
// quadrant chosen by selects so that the loop vectorises.
FIVECAL_LANE_INLINE void SinCosCommandLanes(const LV& x, LV* s, LV* c) {
  bool small = true;
  for (int l = 0; l < W; ++l) small &= std::abs(x.v[l]) < 1e5;
  if (!small) {
    for (int l = 0; l < W; ++l) {
      double sl, cl;
      SinCosCommand(x.v[l], &sl, &cl);
      s->v[l] = sl;
      c->v[l] = cl;
    }
    return;
  }
  constexpr double kTwoOverPi = 6.36619772367581382433e-01;
  constexpr double kPio2_1 = 1.57079632673412561417e+00;
  constexpr double kPio2_2 = 6.07710050630396597660e-11;
  constexpr double kPio2_3 = 2.02226624871116645580e-21;
  const LV t = x * kTwoOverPi;
  LV kd, quad;
  for (int l = 0; l < W; ++l) {  // exact: the rounding to the nearest quadrant
    kd.v[l] = std::trunc(t.v[l] + (t.v[l] >= 0 ? 0.5 : -0.5));
    quad.v[l] = kd.v[l] - 4.0 * std::floor(kd.v[l] * 0.25);  // 0..3
  }
  const LV r = ((x - kd * kPio2_1) - kd * kPio2_2) - kd * kPio2_3;
  const LV r2 = r * r;
  // SinCosCommand's polynomials, by Horner's rule from the highest term.
  static constexpr double kSin[7] = {-1.0 / 6, 1.0 / 120, -1.0 / 5040, 1.0 / 362880, -1.0 / 39916800,
                                     1.0 / 6227020800, -1.0 / 1307674368000.0};
  static constexpr double kCos[9] = {1.0, -0.5, 1.0 / 24, -1.0 / 720, 1.0 / 40320, -1.0 / 3628800,
                                     1.0 / 479001600, -1.0 / 87178291200.0, 1.0 / 20922789888000.0};
  LV ps = LV::All(kSin[6]), pc = LV::All(kCos[8]);
  for (int i = 5; i >= 0; --i) ps = ps * r2 + kSin[i];
  for (int i = 7; i >= 0; --i) pc = pc * r2 + kCos[i];
  const LV sr = r + r * r2 * ps, cr = pc;
  for (int l = 0; l < W; ++l) {  // exact: the quadrant's swap and signs
    const double q = quad.v[l];
    const bool odd = q == 1.0 || q == 3.0;
    const double a = odd ? cr.v[l] : sr.v[l], b = odd ? sr.v[l] : cr.v[l];
    s->v[l] = q >= 2.0 ? -a : a;
    c->v[l] = (q == 1.0 || q == 2.0) ? -b : b;
  }
}

// SinCos of small angles (error motions), lane by lane.
FIVECAL_LANE_INLINE void SinCosLanes(const LV& x, LV* s, LV* c) {
  for (int l = 0; l < W; ++l) {
    double sl, cl;
    SinCos(x.v[l], &sl, &cl);
    s->v[l] = sl;
    c->v[l] = cl;
  }
}

}  // namespace

struct KinematicModel::LaneFrame {
  // The frame is one matrix for every sample until the first commanded
  // rotation (the chain's start, the constant location rotations, linear
  // axes): R then lives in Ru, and R is filled when the samples part.
  bool uniform = true;
  Eigen::Matrix3d Ru = Eigen::Matrix3d::Identity();
  LMat R;
  LVec t;
  FIVECAL_LANE_INLINE void Spread() {
    if (!uniform) return;
    R = LMat::All(Ru);
    uniform = false;
  }
  FIVECAL_LANE_INLINE LMat Rotation() const { return uniform ? LMat::All(Ru) : R; }
};

struct KinematicModel::LaneFactor {
  LMat R_before, R_afterM;
  LVec oE, backlash_w, oEps, epsW[3];
  LV qpow[4];
};

template <bool kRecord>
FIVECAL_LANE_INLINE void KinematicModel::ChainLanes(const std::vector<int>& chain, const double* q, const double* dir,
                                                     LaneFrame* f, LaneFactor* factors) const {
  int i = 0;
  for (int k : chain) {
    const AxisConstants& A = axes_[k];
    LaneFactor* F = kRecord ? &factors[i] : nullptr;
    const bool rec_loc = kRecord && A.want_location, rec_motion = kRecord && A.want_motion;
    if (i++ == 0) {
      f->uniform = true;
      f->Ru = A.RE;
      f->t = LVec::All(A.tE);
      if (rec_loc) F->R_before = LMat::All(Eigen::Matrix3d::Identity());
    } else {
      if (rec_loc) F->R_before = f->Rotation();
      if (f->uniform) {
        const Eigen::Vector3d d = f->Ru * A.tE;
        for (int j = 0; j < 3; ++j) f->t.c[j] = f->t.c[j] + d[j];
      } else {
        const LVec d = f->R.Times(A.tE);
        for (int j = 0; j < 3; ++j) f->t.c[j] = f->t.c[j] + d.c[j];
      }
      for (int c = 2; c >= 0; --c) {
        if (!A.loc_rot[c]) continue;
        if (f->uniform) RotateAbout(&f->Ru, c, A.loc_sin[c], A.loc_cos[c]);
        else f->R.Rotate(c, A.loc_sin[c], A.loc_cos[c]);
      }
    }
    if (rec_loc) F->oE = f->t;
    if (rec_loc && (A.location_mask & (1u << 6))) {
      if (f->uniform) F->backlash_w = LVec::All(f->Ru * A.direction);
      else F->backlash_w = f->R.Times(A.direction);
    }
    const LV qk = LV::Load(q + k * W);
    const LV qm = (dir && A.backlash != 0.0) ? qk + LV::Load(dir + k * W) * A.backlash : qk;
    if (A.rotary) {
      f->Spread();
      if (A.unit_axis >= 0) {
        LV s, c;
        SinCosCommandLanes(qm * A.unit_sign, &s, &c);
        f->R.Rotate(A.unit_axis, s, c);
      } else {
        for (int l = 0; l < W; ++l) {
          Eigen::Matrix3d Rl;
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) Rl(b, a) = f->R.col[a].c[b].v[l];
          Rl = Rl * AxisAngle<double>(A.direction, qm.v[l]);
          for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) f->R.col[a].c[b].v[l] = Rl(b, a);
        }
      }
    } else {
      // A linear axis moves along a column of the frame (one vector per
      // sample set when the frame is shared).
      Eigen::Vector3d u = A.direction;
      if (A.unit_axis >= 0) u = Eigen::Vector3d::Unit(A.unit_axis) * A.unit_sign;
      if (f->uniform) {
        const Eigen::Vector3d d = f->Ru * u;
        for (int j = 0; j < 3; ++j) f->t.c[j] = f->t.c[j] + qm * d[j];
      } else {
        const LVec d = f->R.Times(u);
        for (int j = 0; j < 3; ++j) f->t.c[j] = f->t.c[j] + qm * d.c[j];
      }
    }
    if (rec_motion) {
      F->R_afterM = f->Rotation();
      F->qpow[0] = LV::All(1.0);
      F->qpow[1] = qk;
      F->qpow[2] = qk * qk;
      F->qpow[3] = qk * qk * qk;
    }
    if (A.motion_t || A.motion_r) {
      LV e[6];
      for (int c = 0; c < 6; ++c) {
        const double* p = A.poly + 3 * c;
        e[c] = ((qk * p[2] + p[1]) * qk + p[0]) * qk;
      }
      if (A.motion_t) {
        const LMat R = f->Rotation();
        for (int j = 0; j < 3; ++j) f->t.c[j] = f->t.c[j] + R.col[0].c[j] * e[0] + R.col[1].c[j] * e[1] + R.col[2].c[j] * e[2];
      }
      if (rec_motion) F->oEps = f->t;
      if (A.motion_r) {
        f->Spread();
        LV s, c;
        if (rec_motion) F->epsW[2] = f->R.col[2];
        if (A.motion[5]) {
          SinCosLanes(e[5], &s, &c);
          f->R.Rotate(2, s, c);
        }
        if (rec_motion) F->epsW[1] = f->R.col[1];
        if (A.motion[4]) {
          SinCosLanes(e[4], &s, &c);
          f->R.Rotate(1, s, c);
        }
        if (rec_motion) F->epsW[0] = f->R.col[0];
        if (A.motion[3]) {
          SinCosLanes(e[3], &s, &c);
          f->R.Rotate(0, s, c);
        }
      } else if (rec_motion) {
        const LMat R = f->Rotation();
        for (int c = 0; c < 3; ++c) F->epsW[c] = R.col[c];
      }
    } else if (rec_motion) {
      F->oEps = f->t;
      const LMat R = f->Rotation();
      for (int c = 0; c < 3; ++c) F->epsW[c] = R.col[c];
    }
  }
  if (chain.empty()) {
    f->uniform = true;
    f->Ru.setIdentity();
    f->t = LVec::All(Eigen::Vector3d::Zero());
  }
}

FIVECAL_LANE_CLONES void KinematicModel::ToolPointLanes(const double* q, const double* dir, const double* tip,
                                                         double* P_out, const int* columns, int num_columns,
                                                         double* J, double* dtip) const {
  const Machine& m = *machine_;
  const std::vector<int>& tc = m.tool_chain();
  const std::vector<int>& wc = m.workpiece_chain();
  LaneFrame ft, fw;
  // Recorded only with J: 2.5 kB a factor, left uninitialised otherwise.
  LaneFactor tf[kMaxChain], wf[kMaxChain];
  if (J) {
    ChainLanes<true>(tc, q, dir, &ft, tf);
    ChainLanes<true>(wc, q, dir, &fw, wf);
  } else {
    ChainLanes<false>(tc, q, dir, &ft, nullptr);
    ChainLanes<false>(wc, q, dir, &fw, nullptr);
  }
  const Eigen::Vector3d pt = tc.empty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(m.axis(tc.back()).point);
  const Eigen::Vector3d pw = wc.empty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(m.axis(wc.back()).point);
  // P = Rt (tip - pt) + tt, O = tw - Rw pw, point = Rw^T (P - O).
  LVec arm;
  for (int c = 0; c < 3; ++c) arm.c[c] = LV::Load(tip + c * W) + (-pt[c]);
  const LMat Rt = ft.Rotation(), Rw = fw.Rotation();
  LVec P;
  for (int j = 0; j < 3; ++j)
    P.c[j] = ft.t.c[j] + Rt.col[0].c[j] * arm.c[0] + Rt.col[1].c[j] * arm.c[1] + Rt.col[2].c[j] * arm.c[2];
  const LVec wpw = Rw.Times(pw);
  LVec D;
  for (int j = 0; j < 3; ++j) D.c[j] = P.c[j] - (fw.t.c[j] - wpw.c[j]);
  const LVec point = Rw.TransposeTimes(D);
  for (int c = 0; c < 3; ++c) point.c[c].Store(P_out + c * W);
  if (!J) return;
  // Chain position of every axis, for the columns.
  int pos[32];
  const bool fits = m.num_axes() <= 32;
  if (!fits) throw std::logic_error("kinematic model: more than 32 axes");
  for (size_t i = 0; i < tc.size(); ++i) pos[tc[i]] = static_cast<int>(i);
  for (size_t i = 0; i < wc.size(); ++i) pos[wc[i]] = static_cast<int>(i);
  // sign R_w^T v: the column in the workpiece frame (inlined: as a call it
  // took a fifth of the function's time).
  auto put = [&](int j, const LVec& v, double sign) FIVECAL_LANE_ALWAYS {
    const LVec o = Rw.TransposeTimes(v);
    for (int c = 0; c < 3; ++c) (o.c[c] * sign).Store(J + (3 * j + c) * W);
  };
  const int tip0 = m.tip_index();
  for (int j = 0; j < num_columns; ++j) {
    const int index = columns[j];
    if (index >= tip0 && index < tip0 + 3) {
      put(j, Rt.col[index - tip0], 1.0);
      continue;
    }
    const ParameterInfo& pi = m.parameters()[index];
    const AxisConstants& A = axes_[pi.axis];
    const bool tool = m.on_tool_side(pi.axis);
    const LaneFactor& F = (tool ? tf : wf)[pos[pi.axis]];
    const double sign = tool ? 1.0 : -1.0;
    if (pi.kind == ParameterKind::kLocation) {
      if (!A.want_location || !(A.location_mask & (1u << pi.component)))
        throw std::logic_error("kinematic model: column " + pi.name + " not wanted by RestrictJacobian");
      const int c = pi.component;
      if (c < 3) put(j, F.R_before.col[c], sign);
      else put(j, Cross(F.R_before.Times(A.eAxes[c - 3]), P - F.oE), sign);
    } else if (pi.kind == ParameterKind::kBacklash) {
      if (!A.want_location || !(A.location_mask & (1u << 6)))
        throw std::logic_error("kinematic model: column " + pi.name + " not wanted by RestrictJacobian");
      const LV d = dir ? LV::Load(dir + pi.axis * W) : LV::All(0.0);
      const LVec& w = F.backlash_w;
      put(j, (A.rotary ? Cross(w, P - F.oE) : w) * d, sign);
    } else if (pi.kind == ParameterKind::kMotion) {
      const int c = pi.component, d = pi.degree;
      if (!A.want_motion || !(A.motion_mask & (1u << (3 * c + d - 1))))
        throw std::logic_error("kinematic model: column " + pi.name + " not wanted by RestrictJacobian");
      const LVec unit = c < 3 ? F.R_afterM.col[c] : Cross(F.epsW[c - 3], P - F.oEps);
      put(j, unit * F.qpow[d], sign);
    } else {
      throw std::logic_error("kinematic model: no lane column for " + pi.name);
    }
  }
  if (dtip)
    for (int c = 0; c < 3; ++c) {
      const LVec o = Rw.TransposeTimes(Rt.col[c]);
      for (int r = 0; r < 3; ++r) o.c[r].Store(dtip + (3 * r + c) * W);
    }
}

}  // namespace fivecal
