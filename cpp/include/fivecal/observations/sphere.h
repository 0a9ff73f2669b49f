// Sphere touch: a probe touch on a sphere of the artefact (docs/formats.md,
// observation type "sphere"); and the artefact's scale bars, which join two
// spheres' centres and are rows of this kind that belong to the artefact.
#ifndef FIVECAL_OBSERVATIONS_SPHERE_H_
#define FIVECAL_OBSERVATIONS_SPHERE_H_

#include <memory>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/probe_trigger.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// The tip centre P is R + r from the true sphere centre c + dc:
//
//     |P - (c + dc)| - (R + sphere.<id>.r + r) + p(-u) = 0
//
// with u = (P - c - dc) / |P - c - dc| and p the probe's pretravel along the
// inward normal -u (probe_trigger.h). Derivatives (analytic batch), with
// g = dp/du (the trigger model's gradient in the workpiece frame, zero when
// the probe terms are all zero) and D = (I - u u^T) / |P - c - dc|:
//   dr/dtheta = (u^T - g^T D) dP/dtheta,  dr/ddc = -(u^T - g^T D),
//   dr/dR = -1,  dr/dprobe_k = b_k(M (-u)).
class SphereResidual {
 public:
  SphereResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const Sphere& s,
                 double tip_radius, const SetupRef (&center)[3], SetupRef radius, const ProbeTrigger& trigger)
      : access_(ctx), pose_(*ctx->machine, o), center_(s.center), radius_(s.radius),
        tip_radius_(tip_radius), dc_{center[0], center[1], center[2]}, dr_(radius), trigger_(trigger) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(),
                       TipWithOffsets<T>(m, theta.data()), &P);
    const Vec3<T> c = center_.template cast<T>() +
                      Vec3<T>(access_.Setup(p, dc_[0]), access_.Setup(p, dc_[1]), access_.Setup(p, dc_[2]));
    using std::sqrt;
    const T len = sqrt((P - c).squaredNorm());
    residual[0] = len - (T(radius_ + tip_radius_) + access_.Setup(p, dr_)) +
                  trigger_.Pretravel<T>(access_, p, Vec3<T>((c - P) / len));
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d center_;
  const double radius_, tip_radius_;
  const SetupRef dc_[3];
  const SetupRef dr_;
  const ProbeTrigger trigger_;
};

// Scale bar: the distance between the two estimated sphere centres equals
// the calibrated length L:
//
//     |c1 + dc1 - c2 - dc2| - L = 0
//
// Derivatives, u the unit vector of the distance: dr/ddc1 = u^T, dr/ddc2 = -u^T.
// Its declared noise is kScaleBarSigma (solve/problem.h).
class ScaleBarResidual {
 public:
  ScaleBarResidual(std::shared_ptr<const ResidualContext> ctx, const Sphere& s1, const Sphere& s2,
                   double length, const SetupRef (&d1)[3], const SetupRef (&d2)[3])
      : access_(ctx), c1_(s1.center), c2_(s2.center), length_(length),
        d1_{d1[0], d1[1], d1[2]}, d2_{d2[0], d2[1], d2[2]} {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    Vec3<T> d = (c1_ - c2_).template cast<T>();
    for (int i = 0; i < 3; ++i) d[i] += access_.Setup(p, d1_[i]) - access_.Setup(p, d2_[i]);
    using std::sqrt;
    residual[0] = sqrt(d.squaredNorm()) - T(length_);
    return true;
  }

 private:
  const ParameterAccess access_;
  const Eigen::Vector3d c1_, c2_;
  const double length_;
  const SetupRef d1_[3], d2_[3];
};

const ObservationKind& SphereKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_SPHERE_H_
