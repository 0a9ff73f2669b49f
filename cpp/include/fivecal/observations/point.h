// Point (docs/formats.md, observation type "point"): a fixed-frame 3D
// measurement -- a laser tracker, a camera, a CMM -- of a target carried by
// the machine. The instrument stands still in the machine frame F and
// reports the target's position in its own frame.
#ifndef FIVECAL_OBSERVATIONS_POINT_H_
#define FIVECAL_OBSERVATIONS_POINT_H_

#include "fivecal/observations/kind.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// The instrument's parameters as a residual sees them: pose corrections
// (instrument.<id>.x|y|z mm, .a|b|c rad) and the target offset
// (instrument.<id>.tool_x|y|z or .work_x|y|z mm).
struct InstrumentRefs {
  SetupRef position[3];
  SetupRef angle[3];
  SetupRef target[3];
};

// Residual (3 rows, instrument frame, mm):
//
//     r = R_I^T (P_F - o_I) - measured
//
//   P_F  the target in F: on the tool side  P_F = T_t(q) (target + dt - p_t),
//        on the workpiece side  P_F = T_w(q) (target + dt - p_w), with T_t,
//        T_w the erroneous chain frames from the foundation (kinematics.h,
//        ChainFrame) and p_t, p_w the last axis points of each chain (the
//        chain frames carry a final Trans(-p_last)); dt the target offset;
//   o_I  the instrument origin in F: origin + (x, y, z);
//   R_I  its orientation: Rz(c0 + c) Ry(b0 + b) Rx(a0 + a), with the nominal
//        angles (a0, b0, c0) of the file and the corrections (a, b, c).
//
// Only this templated form exists (ObservationKind::analytic() is false):
// the analytic batch has the tool point in the workpiece frame, not a point
// in F, and a tracker dataset is small enough for automatic derivatives.
// The target in the instrument frame (see above); q in internal units.
template <typename T>
Vec3<T> PointInInstrument(const Machine& m, const T* theta, const double* q, const int* dir, bool on_tool,
                          const Vec3<T>& target, const Vec3<T>& origin, const T* angles) {
  Eigen::Vector3d p_last;
  const Frame<T> F = ChainFrame<T>(m, on_tool ? m.tool_chain() : m.workpiece_chain(), theta, q, dir, &p_last);
  const Vec3<T> P = F * Vec3<T>(target - p_last.template cast<T>());
  return RotZYX(angles[0], angles[1], angles[2]).transpose() * (P - origin);
}

class PointResidual {
 public:
  PointResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const InstrumentRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), o_(o), refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    Vec3<T> target = o_.target_point.template cast<T>();
    Vec3<T> origin = o_.instrument_origin.template cast<T>();
    T ang[3];
    for (int i = 0; i < 3; ++i) {
      target[i] += access_.Setup(p, refs_.target[i]);
      origin[i] += access_.Setup(p, refs_.position[i]);
      ang[i] = T(o_.instrument_angles[i]) + access_.Setup(p, refs_.angle[i]);
    }
    const Vec3<T> r = PointInInstrument<T>(access_.machine(), theta.data(), pose_.q.data(), pose_.dir.data(),
                                           o_.on_tool, target, origin, ang) -
                      o_.measured.template cast<T>();
    for (int i = 0; i < 3; ++i) residual[i] = r[i];
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Observation o_;
  const InstrumentRefs refs_;
};

const ObservationKind& PointKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_POINT_H_
