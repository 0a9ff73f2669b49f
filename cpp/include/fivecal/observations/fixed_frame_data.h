// The payloads of the fixed-frame kinds (point, pose, distance: point.h,
// pose.h, distance.h). The instrument or station id is the common header's
// `setup` (dataset.h Observation).
#ifndef FIVECAL_OBSERVATIONS_FIXED_FRAME_DATA_H_
#define FIVECAL_OBSERVATIONS_FIXED_FRAME_DATA_H_

#include <Eigen/Core>
#include <string>

namespace fivecal {

// The target every fixed-frame observation follows: the side that carries
// it and where (tool side: in F at the zero pose; workpiece side: in the
// workpiece frame, mm). A base, not an alternative of the payload variant:
// fixed_frame:: reads and writes it for each kind.
struct FixedTargetData {
  std::string target;  // "tool" or "work", as the file says it
  bool on_tool = true;
  Eigen::Vector3d target_point = Eigen::Vector3d::Zero();
};
inline bool SameTarget(const FixedTargetData& a, const FixedTargetData& b) {
  return a.target == b.target && a.on_tool == b.on_tool && a.target_point == b.target_point;
}

// point: the measured target in the instrument frame, and the instrument's
// nominal pose in F (origin mm; angles a b c rad: Rz(c) Ry(b) Rx(a)).
struct PointData : FixedTargetData {
  static constexpr const char* kName = "PointData";
  Eigen::Vector3d instrument_origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d instrument_angles = Eigen::Vector3d::Zero();
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();
};
inline bool operator==(const PointData& a, const PointData& b) {
  return SameTarget(a, b) && a.instrument_origin == b.instrument_origin &&
         a.instrument_angles == b.instrument_angles && a.measured == b.measured;
}

// pose: a point plus the measured orientation of the target frame in the
// instrument frame and the target frame's nominal orientation on its
// carrying side (rotation vectors, rad).
struct PoseTargetData : PointData {
  static constexpr const char* kName = "PoseTargetData";
  Eigen::Vector3d measured_rotation = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_rotation = Eigen::Vector3d::Zero();
};
inline bool operator==(const PoseTargetData& a, const PoseTargetData& b) {
  return static_cast<const PointData&>(a) == static_cast<const PointData&>(b) &&
         a.measured_rotation == b.measured_rotation && a.target_rotation == b.target_rotation;
}

// distance: the station's nominal position in F and dead length (mm), the
// distance reading (mm), and the tracer whose target offsets every one of
// its stations shares.
struct DistanceData : FixedTargetData {
  static constexpr const char* kName = "DistanceData";
  std::string tracer;
  Eigen::Vector3d station = Eigen::Vector3d::Zero();
  double dead_length = 0.0;
  double reading = 0.0;
};
inline bool operator==(const DistanceData& a, const DistanceData& b) {
  return SameTarget(a, b) && a.tracer == b.tracer && a.station == b.station && a.dead_length == b.dead_length &&
         a.reading == b.reading;
}

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_FIXED_FRAME_DATA_H_
