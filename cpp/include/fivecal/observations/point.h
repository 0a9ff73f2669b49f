// Point (docs/formats.md, observation type "point"): a fixed-frame 3D
// measurement -- a laser tracker, a camera, a CMM -- of a target carried by
// the machine. The instrument stands still in the machine frame F and
// reports the target's position in its own frame.
#ifndef FIVECAL_OBSERVATIONS_POINT_H_
#define FIVECAL_OBSERVATIONS_POINT_H_

#include "fivecal/observations/kind.h"
#include "fivecal/observations/residuals.h"

#include <functional>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

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
// The erroneous frame of the chain that carries a target (tool side or
// workpiece side) and its last axis point p_last: a target point t sits at
// F (t - p_last) in F. Every fixed-frame kind (point, pose, distance) finds
// its target through it; q in internal units.
template <typename T>
Frame<T> TargetChainFrame(const Machine& m, const T* theta, const double* q, const int* dir, bool on_tool,
                          Eigen::Vector3d* p_last) {
  return ChainFrame<T>(m, on_tool ? m.tool_chain() : m.workpiece_chain(), theta, q, dir, p_last);
}

// The target in F (P_F above).
template <typename T>
Vec3<T> TargetInF(const Machine& m, const T* theta, const double* q, const int* dir, bool on_tool,
                  const Vec3<T>& target) {
  Eigen::Vector3d p_last;
  const Frame<T> F = TargetChainFrame<T>(m, theta, q, dir, on_tool, &p_last);
  return F * Vec3<T>(target - p_last.template cast<T>());
}

// A nominal vector of the file plus its three setup corrections (a target
// point and its offsets, an instrument origin or station and its position
// correction, nominal angles and theirs).
template <typename T>
Vec3<T> WithCorrections(const ParameterAccess& a, T const* const* p, const Eigen::Vector3d& nominal,
                        const SetupRef (&refs)[3]) {
  return nominal.template cast<T>() + Vec3<T>(a.Setup(p, refs[0]), a.Setup(p, refs[1]), a.Setup(p, refs[2]));
}

// The target in the instrument frame (see above).
template <typename T>
Vec3<T> PointInInstrument(const Machine& m, const T* theta, const double* q, const int* dir, bool on_tool,
                          const Vec3<T>& target, const Vec3<T>& origin, const T* angles) {
  return RotZYX(angles[0], angles[1], angles[2]).transpose() * (TargetInF<T>(m, theta, q, dir, on_tool, target) - origin);
}

// What the fixed-frame kinds (point, pose, distance) share: an instrument
// id (Observation::setup) whose parameters are named instrument.<id>.*, and
// a target on the tool or the workpiece side whose offsets
// instrument.<id>.tool_x|y|z / .work_x|y|z are one group per id and side,
// whichever kind brings it (a tracker's point and pose observations of one
// target share them).
namespace fixed_frame {
// "target" ("tool" or "work", into the payload's target and on_tool) and
// "target_point" of a file's observation; `where` names it.
void ReadTarget(const nlohmann::json& o, const std::string& where, FixedTargetData* d);
void ValidateTarget(const FixedTargetData& d, const std::function<std::string()>& where);
void WriteTarget(const FixedTargetData& d, nlohmann::json* out);
// "instrument" (a name without '.') into Observation::setup, and the nominal
// pose "instrument_origin" (mm) and "instrument_angles" (degrees in the file)
// into `d`, the payload of `ob`.
void ReadInstrument(const nlohmann::json& o, const std::string& where, Observation* ob, PointData* d);
// The instrument table of a fixed instrument following a target (point,
// pose): id, the measured coordinates and the joint layout's columns (one
// joint moved per row); `sigma`: whether a sigma column weighs its rows.
KindTable InstrumentTable(bool sigma);
void ValidateInstrument(const Observation& o, const PointData& d, const std::function<std::string()>& where);
void WriteInstrument(const Observation& o, const PointData& d, nlohmann::json* out);
// The instrument pose instrument.<id>.x|y|z|a|b|c (one group per id).
const std::vector<int>& AddInstrumentPose(const std::string& id, ParameterTable* t);
const std::vector<int>& InstrumentPose(const ParameterTable& t, const std::string& id);
// The target offsets instrument.<id>.<side>_x|y|z.
const std::vector<int>& AddTargetOffsets(const std::string& id, const std::string& side, ParameterTable* t);
const std::vector<int>& TargetOffsets(const ParameterTable& t, const std::string& id, const std::string& side);
// The point kind's report: residual rows r[0..2] (instrument frame) turned
// into F, at the measured target's place.
void ReportPoint(const ReportContext& c, const Observation& o, const PointData& d, const double* r,
                 Eigen::Vector3d* point, Eigen::Vector3d* vector);
// The prior class of any instrument.<id>.<field> name (nullptr otherwise).
const char* PriorClassOfName(const std::string& name);
// The placement uncertainty of an instrument's pose (point, pose and distance
// share it): docs/setup_uncertainty.md.
double DefaultPlacement(const std::string& name);
// The refusal of an id two kinds would give different parameters under one
// name (a station and a tracker both called "L1").
[[noreturn]] void IdClash(const std::string& id);
}  // namespace fixed_frame

class PointResidual {
 public:
  // `d`: the payload of `o` (a point's, or a pose's point part).
  PointResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const PointData& d,
                const InstrumentRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), target_point_(d.target_point), origin_(d.instrument_origin),
        angles_(d.instrument_angles), measured_(d.measured), on_tool_(d.on_tool), refs_(refs) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Vec3<T> target = WithCorrections<T>(access_, p, target_point_, refs_.target);
    const Vec3<T> origin = WithCorrections<T>(access_, p, origin_, refs_.position);
    const Vec3<T> ang = WithCorrections<T>(access_, p, angles_, refs_.angle);
    const Vec3<T> r = PointInInstrument<T>(access_.machine(), theta.data(), pose_.q.data(), pose_.dir.data(),
                                           on_tool_, target, origin, ang.data()) -
                      measured_.template cast<T>();
    for (int i = 0; i < 3; ++i) residual[i] = r[i];
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d target_point_, origin_, angles_, measured_;
  const bool on_tool_;
  const InstrumentRefs refs_;
};

const ObservationKind& PointKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_POINT_H_
