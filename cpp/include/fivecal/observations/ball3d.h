// Ball3d sample (docs/formats.md, observation type "ball3d"): the 3D
// displacement of a tool ball from its nest, as an R-test, a CapBall or a
// tracker measures it.
#ifndef FIVECAL_OBSERVATIONS_BALL3D_H_
#define FIVECAL_OBSERVATIONS_BALL3D_H_

#include "fivecal/observations/ball_mount.h"

namespace fivecal {

// The tool ball (tip tool_ball + ball3d.tool, F at the zero pose) minus the
// nest at table_ball + dt, workpiece frame, is the measured displacement
// (3 rows):
//
//     P_ball - (table_ball + dt) - measured = 0
//
// Derivatives (analytic batch): dr/dtheta = dP/dtheta (the probe tip
// offsets do not enter), dr/dtool = dP/dtip, dr/ddt = -I.
class Ball3dResidual {
 public:
  Ball3dResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const MountRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), tool_ball_(o.data<BallMountData>().tool_ball),
        table_ball_(o.data<BallMountData>().table_ball), measured_(o.data<BallMountData>().measured), refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    const Vec3<T> d = BallDistance<T>(access_, pose_, p, tool_ball_, table_ball_, refs_);
    for (int i = 0; i < 3; ++i) residual[i] = d[i] - T(measured_[i]);
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d tool_ball_, table_ball_, measured_;
  const MountRefs refs_;
};

const ObservationKind& Ball3dKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_BALL3D_H_
