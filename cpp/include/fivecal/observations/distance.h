// Distance (docs/formats.md, observation type "distance"): a tracking
// interferometer or laser tracer standing at a station fixed in the machine
// frame F reads the distance to a target carried by the machine;
// multilateration from several stations.
#ifndef FIVECAL_OBSERVATIONS_DISTANCE_H_
#define FIVECAL_OBSERVATIONS_DISTANCE_H_

#include "fivecal/observations/point.h"

namespace fivecal {

// The station's parameters as a residual sees them: its position correction
// instrument.<station>.x|y|z (mm), its dead length instrument.<station>.length
// (mm) and the target offset instrument.<tracer>.tool_x|y|z (or work_x|y|z).
struct StationRefs {
  SetupRef position[3];
  SetupRef length;
  SetupRef target[3];
};

// Residual (1 row, mm):
//
//     r = |P_F - s| - (d0 + l + reading)
//
//   P_F  the target in F, as the point kind's (tool or workpiece side, target
//        point plus the tracer's target offset);
//   s    the station in F: station_position + (x, y, z);
//   d0   the file's nominal dead length, l its correction (the estimated
//        dead length instrument.<station>.length); `reading` the
//        instrument's reading.
// Derivatives (the automatic ones): d r / d s = -u, d r / d P_F = u with
// u = (P_F - s) / |P_F - s|, d r / d l = -1. Only the templated form exists.

class DistanceResidual {
 public:
  DistanceResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const StationRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), target_point_(o.data<DistanceData>().target_point),
        station_(o.data<DistanceData>().station),
        distance_(o.data<DistanceData>().dead_length + o.data<DistanceData>().reading),
        on_tool_(o.data<DistanceData>().on_tool), refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Vec3<T> target = WithCorrections<T>(access_, p, target_point_, refs_.target);
    const Vec3<T> station = WithCorrections<T>(access_, p, station_, refs_.position);
    const Vec3<T> P = TargetInF<T>(access_.machine(), theta.data(), pose_.q.data(), pose_.dir.data(), on_tool_,
                                   target);
    // The target never sits on the station (validated readings are
    // distances of a tracer to a reflector hundreds of mm away), so the norm
    // is differentiable here.
    residual[0] = (P - station).norm() - (T(distance_) + access_.Setup(p, refs_.length));
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d target_point_, station_;
  const double distance_;  // the file's dead length plus the reading
  const bool on_tool_;
  const StationRefs refs_;
};

const ObservationKind& DistanceKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_DISTANCE_H_
