// Machined feature (docs/formats.md, observation type "machined"): a
// machining test in the manner of Zhang & Zhang (error-sensitive directions):
// faces of a test part are cut at chosen poses of the rotary axes, the part
// is measured (on a CMM) and each measured deviation of a face along its
// normal, or of one face relative to another, is one observation. The
// machining tests thereby join a fit with probing, ball-bar or R-test data.
#ifndef FIVECAL_OBSERVATIONS_MACHINED_H_
#define FIVECAL_OBSERVATIONS_MACHINED_H_

#include "fivecal/observations/kind.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// One face of a machined feature: the commands it was cut at (internal
// units), its nominal point W and outward unit normal n in the part frame.
struct MachinedFace {
  std::vector<double> q;
  std::vector<int> dir;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
};

// The part's datum as a residual sees it: machined.<part>.x|y|z (mm) and
// .a|b|c (rad).
struct PartRefs {
  SetupRef position[3];
  SetupRef angle[3];
};

// Residual (1 row, mm). The cutter cuts a face at commands q where the
// machine's tool point (the machine file's tool tip, no probe offsets: the
// cutter is not the probe) really is,
//
//     P(q) = inv(T_fw(q)) T_ft(q) tip          (workpiece frame, kinematics.h)
//
// while the program put the nominal tool point on the face's nominal point
// W. The CMM measures the part in its own datum frame, which sits in the
// workpiece frame at  x_w = d + R x_part,  R = Rz(c) Ry(b) Rx(a), with
// (d; a, b, c) = machined.<part>.x|y|z|a|b|c. The face's deviation along
// its outward normal (> 0: the face stands proud, material left) is
//
//     u(q, W, n) = n . (R^T (P(q) - d) - W)
//
// and the residual of a feature is
//
//     face:  r = u(q, W, n) - measured
//     step:  r = u(q, W, n) - u(q', W', n') - measured
//
// (a step: the face cut at `axes` relative to the face cut at
// `reference_axes`, as Zhang & Zhang's differences of two cuts). With both
// faces at one point and normal, d drops out of a step and R enters only
// through P(q) - P(q') (second order): the datum is then not needed.
//
// Relation to Zhang & Zhang (and to the procedure, procedures/machining_test.h):
// with a sensitive direction r_F in the machine frame at a pose q, n is
// R0(q)^T r_F (R0: the nominal orientation of the workpiece frame at q), and
// their machining error e(pose) - e(reference) is minus the step's u - u'.
//
// Derivatives: automatic only (ObservationKind::analytic() is false): a
// feature needs two tool points at two poses, and machining-test sets are
// small.
template <typename T>
T MachinedDeviation(const Machine& m, const T* theta, const MachinedFace& f, const Vec3<T>& d,
                    const Mat3<T>& R) {
  Vec3<T> P;
  ToolInWorkpiece<T>(m, theta, f.q.data(), f.dir.data(), m.tip().template cast<T>(), &P);
  return f.normal.template cast<T>().dot(Vec3<T>(R.transpose() * (P - d)) - f.point.template cast<T>());
}

class MachinedResidual {
 public:
  // `reference` null: a face.
  MachinedResidual(std::shared_ptr<const ResidualContext> ctx, MachinedFace face,
                   std::shared_ptr<const MachinedFace> reference, double measured, const PartRefs& refs)
      : access_(ctx), face_(std::move(face)), reference_(std::move(reference)), measured_(measured),
        refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    Vec3<T> d;
    T ang[3];
    for (int i = 0; i < 3; ++i) {
      d[i] = access_.Setup(p, refs_.position[i]);
      ang[i] = access_.Setup(p, refs_.angle[i]);
    }
    const Mat3<T> R = RotZYX(ang[0], ang[1], ang[2]);
    const Machine& m = access_.machine();
    T u = MachinedDeviation<T>(m, theta.data(), face_, d, R);
    if (reference_) u -= MachinedDeviation<T>(m, theta.data(), *reference_, d, R);
    residual[0] = u - T(measured_);
    return true;
  }

 private:
  const ParameterAccess access_;
  const MachinedFace face_;
  const std::shared_ptr<const MachinedFace> reference_;
  const double measured_;
  const PartRefs refs_;
};

const ObservationKind& MachinedKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_MACHINED_H_
