// The payload of a ball-mounting sample (dbb, ball3d: ball_mount.h). One
// struct for both kinds, because the mounting's code (the column block of a
// trace, the analytic rows, the arrays of Dataset.balls) reads both alike;
// the fields a kind does not record stay zero (dbb: measured; ball3d:
// length and reading).
#ifndef FIVECAL_OBSERVATIONS_BALL_MOUNT_DATA_H_
#define FIVECAL_OBSERVATIONS_BALL_MOUNT_DATA_H_

#include <Eigen/Core>

namespace fivecal {

struct BallMountData {
  static constexpr const char* kName = "BallMountData";
  Eigen::Vector3d tool_ball = Eigen::Vector3d::Zero();   // in F at the zero pose, mm
  Eigen::Vector3d table_ball = Eigen::Vector3d::Zero();  // workpiece frame, mm
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();    // ball3d: the displacement, mm
  double length = 0.0;   // dbb: nominal bar length, mm
  double reading = 0.0;  // dbb: length change, mm
};
inline bool operator==(const BallMountData& a, const BallMountData& b) {
  return a.tool_ball == b.tool_ball && a.table_ball == b.table_ball && a.measured == b.measured &&
         a.length == b.length && a.reading == b.reading;
}

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_BALL_MOUNT_DATA_H_
