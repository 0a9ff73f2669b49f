// The payload of a machined feature (machined.h): the part is the common
// header's `setup` (dataset.h Observation).
#ifndef FIVECAL_OBSERVATIONS_MACHINED_DATA_H_
#define FIVECAL_OBSERVATIONS_MACHINED_DATA_H_

#include <Eigen/Core>
#include <optional>
#include <string>

namespace fivecal {

struct MachinedData {
  static constexpr const char* kName = "MachinedData";
  std::string feature;  // "face" or "step"
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // the face's nominal point, part frame, mm
  // Its outward normal as written (a file round trip changes no bit; the
  // residual normalises it); zero until read.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double measured = 0.0;  // the measured deviation along the normal, mm
  // A step's other cut: its axes (machine axis order, mm / degrees; empty
  // for a face), point and normal (absent for a face).
  Eigen::VectorXd reference_axes;
  std::optional<Eigen::Vector3d> reference_point, reference_normal;
  bool step() const { return feature == "step"; }
};
inline bool operator==(const MachinedData& a, const MachinedData& b) {
  return a.feature == b.feature && a.point == b.point && a.normal == b.normal && a.measured == b.measured &&
         a.reference_axes.size() == b.reference_axes.size() && a.reference_axes == b.reference_axes &&
         a.reference_point == b.reference_point && a.reference_normal == b.reference_normal;
}

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_MACHINED_DATA_H_
