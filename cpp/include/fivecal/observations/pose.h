// Pose (docs/formats.md, observation type "pose"): a fixed-frame 6D
// measurement -- a camera seeing a fiducial, a 6D tracker probe -- of a
// target frame carried by the machine: the point kind's position plus the
// target frame's orientation in the instrument frame.
#ifndef FIVECAL_OBSERVATIONS_POSE_H_
#define FIVECAL_OBSERVATIONS_POSE_H_

#include <ceres/rotation.h>

#include "fivecal/observations/point.h"

namespace fivecal {

// Residual (6 rows, instrument frame): rows 0-2 as the point kind's (mm),
//
//     r_p = R_I^T (P_F - o_I) - measured,
//
// rows 3-5 the rotation vector (rad) of the orientation misfit,
//
//     r_R = log(R_m^T R_p),   R_p = R_I^T R_F R_t,
//
//   R_F  the rotation of the carrying chain frame (tool or workpiece side) at
//        the pose, as the point kind's T_t, T_w;
//   R_t  the target frame on its side: exp(target_rotation) Rz(c) Ry(b) Rx(a),
//        the nominal orientation of the file and the corrections
//        instrument.<id>.tool_a|b|c (or work_a|b|c) in the target's frame;
//   R_m  exp(measured_rotation), the instrument's reading;
//   R_I  the instrument orientation as the point kind's.
// log is ceres::RotationMatrixToAngleAxis, whose small-angle branch keeps
// the value and the Jet derivatives right at and near zero rotation (the fit
// ends there). Only the templated form exists (analytic() is false).
struct PoseRefs {
  InstrumentRefs point;
  SetupRef target_angle[3];
};

template <typename T>
void PoseInInstrument(const Machine& m, const T* theta, const double* q, const int* dir, bool on_tool,
                      const Vec3<T>& target, const Mat3<T>& target_R, const Vec3<T>& origin, const T* angles,
                      Vec3<T>* position, Mat3<T>* R) {
  Eigen::Vector3d p_last;
  const Frame<T> F = TargetChainFrame<T>(m, theta, q, dir, on_tool, &p_last);
  const Mat3<T> RIt = RotZYX(angles[0], angles[1], angles[2]).transpose();
  *position = RIt * (F * Vec3<T>(target - p_last.template cast<T>()) - origin);
  *R = RIt * F.R * target_R;
}

// exp(v) of a rotation vector (rad).
template <typename T>
Mat3<T> RotationOfVector(const Vec3<T>& v) {
  Mat3<T> R;
  ceres::AngleAxisToRotationMatrix(v.data(), R.data());  // column-major, as Eigen's default
  return R;
}

// log(R) as a rotation vector (rad).
template <typename T>
Vec3<T> VectorOfRotation(const Mat3<T>& R) {
  Vec3<T> v;
  ceres::RotationMatrixToAngleAxis(R.data(), v.data());
  return v;
}

class PoseResidual {
 public:
  PoseResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const PoseRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), target_point_(o.data<PoseTargetData>().target_point),
        origin_(o.data<PoseTargetData>().instrument_origin), angles_(o.data<PoseTargetData>().instrument_angles),
        measured_(o.data<PoseTargetData>().measured), on_tool_(o.data<PoseTargetData>().on_tool), refs_(refs),
        measured_RT_(RotationOfVector<double>(o.data<PoseTargetData>().measured_rotation).transpose()),
        target_R0_(RotationOfVector<double>(o.data<PoseTargetData>().target_rotation)) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Vec3<T> target = WithCorrections<T>(access_, p, target_point_, refs_.point.target);
    const Vec3<T> origin = WithCorrections<T>(access_, p, origin_, refs_.point.position);
    const Vec3<T> ang = WithCorrections<T>(access_, p, angles_, refs_.point.angle);
    const Vec3<T> tang = WithCorrections<T>(access_, p, Eigen::Vector3d::Zero(), refs_.target_angle);
    const Mat3<T> target_R = target_R0_.template cast<T>() * RotZYX(tang[0], tang[1], tang[2]);
    Vec3<T> P;
    Mat3<T> R;
    PoseInInstrument<T>(access_.machine(), theta.data(), pose_.q.data(), pose_.dir.data(), on_tool_, target,
                        target_R, origin, ang.data(), &P, &R);
    const Vec3<T> rp = P - measured_.template cast<T>();
    const Mat3<T> misfit = measured_RT_.template cast<T>() * R;
    const Vec3<T> rr = VectorOfRotation<T>(misfit);
    for (int i = 0; i < 3; ++i) {
      residual[i] = rp[i];
      residual[3 + i] = rr[i];
    }
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d target_point_, origin_, angles_, measured_;
  const bool on_tool_;
  const PoseRefs refs_;
  const Eigen::Matrix3d measured_RT_, target_R0_;
};

const ObservationKind& PoseKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_POSE_H_
