// Machine: the immutable description of a multi-axis machine tool.
//
// Conventions (README, "Concepts"; docs/formats.md, "Machine"):
//  * The topology string is read from workpiece to tool, e.g. "wCBXfZYSt":
//    axes between 'w' and 'f' (or 'b') form the workpiece branch, axes between
//    'f' and 't' the tool branch. "(C1)" is accepted for the spindle 'S'.
//  * Chains are built from the foundation outward on both sides, so for
//    "wCBXfZYSt" the workpiece chain is X, B, C and the tool chain Z, Y, S.
//  * Every axis frame is parallel to the machine frame F at the zero pose,
//    with its origin at the axis point p_k. Directions and points are in F.
//  * Linear quantities are mm; rotary commands cross the public boundary in
//    degrees; angular error parameters are rad.
//
// Every error parameter of the model has an exact name (E{XYZABC}0{axis},
// E{dir}{axis}{1..3}, E{axis}{axis}b, tip.x|y|z) and a fixed index in the
// machine parameter vector "theta" that the kinematics consume.
#ifndef FIVECAL_MACHINE_H_
#define FIVECAL_MACHINE_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

namespace fivecal {

enum class AxisType { kLinear, kRotary };

struct Axis {
  char name = 'X';  // X Y Z (linear), A B C (rotary), S (spindle, rotary)
  AxisType type = AxisType::kLinear;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  // unit, in F
  Eigen::Vector3d point = Eigen::Vector3d::Zero();       // p_k, mm, in F
  bool rotary() const { return type == AxisType::kRotary; }
};

enum class ParameterKind { kLocation, kMotion, kBacklash, kTip };

// Error component letters in parameter names: index 0..5 = X Y Z A B C.
inline constexpr char kComponentLetters[6] = {'X', 'Y', 'Z', 'A', 'B', 'C'};

struct ParameterInfo {
  std::string name;
  ParameterKind kind = ParameterKind::kLocation;
  int axis = -1;       // index into Machine::axes(), -1 for tip
  int component = 0;   // 0..5 (X Y Z A B C); for tip 0..2
  int degree = 0;      // 1..3 for error motions
  bool angular() const { return component >= 3 && kind != ParameterKind::kTip; }
};

class Machine {
 public:
  // Parses the machine JSON of docs/formats.md. Throws std::invalid_argument naming
  // the offending field.
  static Machine FromJson(const std::string& json_text);
  static Machine Load(const std::string& path);

  // axes may be given in any order; each topology letter must have one entry.
  // tool_axis defaults to the spindle direction, or +Z without a spindle.
  Machine(std::string name, std::string topology, std::vector<Axis> axes,
          Eigen::Vector3d tip, const Eigen::Vector3d* tool_axis = nullptr);

  std::string ToJson() const;

  // Per-parameter prior scales (one sigma) from the machine file's "priors":
  // a machine parameter name or "class:<name>" -> a positive finite value.
  // Only stored and kept here; their meaning belongs to the fit.
  std::map<std::string, double> priors;

  const std::string& name() const { return name_; }
  const std::string& topology() const { return topology_; }
  int num_axes() const { return static_cast<int>(axes_.size()); }
  // Axes in topology order (workpiece to tool).
  const std::vector<Axis>& axes() const { return axes_; }
  const Axis& axis(int i) const { return axes_.at(i); }
  int AxisIndex(char name) const;  // -1 if the machine has no such axis
  std::string axis_names() const;  // e.g. "CBXZYS"
  // Axis indices from the foundation outward.
  const std::vector<int>& workpiece_chain() const { return workpiece_chain_; }
  const std::vector<int>& tool_chain() const { return tool_chain_; }
  bool on_tool_side(int axis) const;
  const Eigen::Vector3d& tip() const { return tip_; }
  const Eigen::Vector3d& tool_axis() const { return tool_axis_; }

  int num_parameters() const { return static_cast<int>(params_.size()); }
  const std::vector<ParameterInfo>& parameters() const { return params_; }
  std::vector<std::string> parameter_names() const;
  int ParameterIndex(const std::string& name) const;  // -1 if unknown
  // Like ParameterIndex but throws std::invalid_argument with a hint.
  int RequireParameter(const std::string& name) const;

  // Offsets into theta.
  int location_index(int axis, int component) const {
    return axis_offset_[axis] + component;
  }
  int motion_index(int axis, int component, int degree) const {
    return axis_offset_[axis] + 6 + 3 * component + (degree - 1);
  }
  int backlash_index(int axis) const;  // -1 for the spindle
  int tip_index() const { return tip_offset_; }

 private:
  void BuildChains();
  void BuildParameters();

  std::string name_;
  std::string topology_;
  std::vector<Axis> axes_;
  std::vector<int> workpiece_chain_;
  std::vector<int> tool_chain_;
  Eigen::Vector3d tip_;
  Eigen::Vector3d tool_axis_;
  std::vector<ParameterInfo> params_;
  std::vector<int> axis_offset_;
  int tip_offset_ = 0;
  std::map<std::string, int> index_;
};

// Values of every machine parameter, set and read by name.
class ErrorModel {
 public:
  explicit ErrorModel(const Machine& machine);
  // JSON object {"EX0C": 0.01, ...}; unknown names throw.
  static ErrorModel FromJson(const Machine& machine, const std::string& text);

  void Set(const std::string& name, double value);
  double Get(const std::string& name) const;
  const Eigen::VectorXd& values() const { return values_; }
  Eigen::VectorXd& mutable_values() { return values_; }
  const Machine& machine() const { return machine_; }

 private:
  Machine machine_;
  Eigen::VectorXd values_;
};

// Throws std::invalid_argument unless x is finite; `what` names the field.
void RequireFinite(double x, const std::string& what);

// v as a unit vector. Throws std::invalid_argument naming `what` (and the
// component) unless every component is finite and one is non-zero. Any such
// vector is a direction, whatever its scale: it is divided by its largest
// component before the norm is taken, so neither [1e308, 1e308, 0] (whose
// squared norm overflows to inf) nor [5e-324, 0, 0] (which underflows to 0)
// becomes a zero vector.
Eigen::Vector3d UnitDirection(const Eigen::Vector3d& v, const std::string& what);

// Plausibility bounds of every file and API value. A value outside them is a
// typing or unit mistake (1e308, a length in nm), never a measurement: it is
// refused naming the field, so no inf or NaN can reach a fit or a report.
inline constexpr double kMaxLinear = 1e5;        // mm: coordinates, points, lengths, radii,
                                                 // linear axis commands (100 m)
inline constexpr double kMaxRotaryDeg = 1e5;     // degrees: rotary axis commands (~280 turns)
inline constexpr double kMaxDbbReading = 100.0;  // mm: a ball-bar reading (the instrument
                                                 // travels about +-1 mm; synthetic plans go further)
inline constexpr double kMaxBall3d = 100.0;      // mm: a 3D ball displacement (R-test range ~ +-2 mm)
inline constexpr double kMaxErrorValue = 1e3;    // mm or rad: any error or setup parameter
inline constexpr double kMinSigma = 1e-9;        // mm: a declared noise (1 pm) ...
inline constexpr double kMaxSigma = 1e3;         // ... up to 1 m

// Throws std::invalid_argument naming `what` unless x is finite and |x| <= bound.
void RequireBounded(double x, double bound, const std::string& what, const char* unit = "mm");

}  // namespace fivecal

#endif  // FIVECAL_MACHINE_H_
