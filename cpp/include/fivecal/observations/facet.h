// Facet touch: a probe touch on a plane facet of the artefact
// (docs/formats.md, observation type "facet").
#ifndef FIVECAL_OBSERVATIONS_FACET_H_
#define FIVECAL_OBSERVATIONS_FACET_H_

#include <memory>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/probe_trigger.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// The probe tip centre P (tool point, workpiece frame) sits one tip radius r
// off the facet plane, which may be offset along its normal:
//
//     n^ . (P - a) - r - facet.<id> + p(-n^) = 0
//
//   a: nominal facet point, n^: unit outward normal (workpiece frame),
//   p: the probe's pretravel along the inward normal -n^ (probe_trigger.h).
// Derivatives (analytic batch): dr/dtheta = n^T dP/dtheta, dr/dfacet = -1,
// dr/dprobe_k = b_k(M (-n^)).
class FacetResidual {
 public:
  FacetResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const Facet& f,
                double tip_radius, SetupRef offset, const ProbeTrigger& trigger)
      : access_(ctx), pose_(*ctx->machine, o), point_(f.point), normal_(f.normal),
        tip_radius_(tip_radius), offset_(offset), trigger_(trigger) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(),
                       TipWithOffsets<T>(m, theta.data()), &P);
    residual[0] = normal_.template cast<T>().dot(P - point_.template cast<T>()) - T(tip_radius_) -
                  access_.Setup(p, offset_) + trigger_.Pretravel<T>(access_, p, (-normal_).template cast<T>());
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d point_, normal_;
  const double tip_radius_;
  const SetupRef offset_;
  const ProbeTrigger trigger_;
};

const ObservationKind& FacetKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_FACET_H_
