// Double ball bar sample (docs/formats.md, observation type "dbb"): the
// bar's length change between a tool ball and a table ball.
#ifndef FIVECAL_OBSERVATIONS_DBB_H_
#define FIVECAL_OBSERVATIONS_DBB_H_

#include "fivecal/observations/ball_mount.h"

namespace fivecal {

// The tool ball is the tool point of a tool whose tip is tool_ball +
// dbb.tool (F at the zero pose); the table ball sits at table_ball + dt in
// the workpiece frame:
//
//     |P_ball - (table_ball + dt)| - (length + dbb.length + reading) = 0
//
// Derivatives (analytic batch), u the unit vector of P_ball - table:
//   dr/dtheta = u^T dP/dtheta (the probe tip offsets do not enter),
//   dr/dtool = u^T dP/dtip,  dr/ddt = -u^T,  dr/ddbb.length = -1.
class DbbResidual {
 public:
  DbbResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const MountRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), tool_ball_(o.data<BallMountData>().tool_ball),
        table_ball_(o.data<BallMountData>().table_ball),
        target_length_(o.data<BallMountData>().length + o.data<BallMountData>().reading), refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    const Vec3<T> d = BallDistance<T>(access_, pose_, p, tool_ball_, table_ball_, refs_);
    using std::sqrt;
    residual[0] = sqrt(d.squaredNorm()) - (T(target_length_) + access_.Setup(p, refs_.length));
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d tool_ball_, table_ball_;
  const double target_length_;
  const MountRefs refs_;
};

const ObservationKind& DbbKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_DBB_H_
