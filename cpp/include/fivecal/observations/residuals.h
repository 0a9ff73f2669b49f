// Ceres residuals of the observation types of docs/formats.md.
//
// Every residual sees the problem's full parameter vector (machine theta,
// then setup parameters) through a ParameterAccess: estimated parameters come
// from the residual's Ceres parameter blocks (one scalar block each), fixed
// ones are constants. The machine parameters that are estimated form the
// first blocks of every machine-dependent residual, in one shared order.
#ifndef FIVECAL_RESIDUALS_H_
#define FIVECAL_RESIDUALS_H_

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {

// What every residual of one problem shares.
struct ResidualContext {
  const Machine* machine = nullptr;
  Eigen::VectorXd values;              // all parameters; constants for the fixed ones
  std::vector<int> machine_block;      // per machine parameter: block number or -1
  int num_machine_blocks = 0;
};

// One setup parameter as seen by a residual: its full index and its block
// number in that residual (-1 when fixed).
struct SetupRef {
  int index = -1;
  int block = -1;
};

class ParameterAccess {
 public:
  explicit ParameterAccess(std::shared_ptr<const ResidualContext> ctx) : ctx_(std::move(ctx)) {}

  template <typename T>
  void Theta(T const* const* p, std::vector<T>* theta) const {
    const int n = ctx_->machine->num_parameters();
    theta->resize(n);
    for (int i = 0; i < n; ++i) {
      const int b = ctx_->machine_block[i];
      (*theta)[i] = b >= 0 ? p[b][0] : T(ctx_->values[i]);
    }
  }
  template <typename T>
  T Setup(T const* const* p, const SetupRef& s) const {
    return s.block >= 0 ? p[s.block][0] : T(ctx_->values[s.index]);
  }
  const Machine& machine() const { return *ctx_->machine; }

 private:
  std::shared_ptr<const ResidualContext> ctx_;
};

// Axis readings of one observation converted to internal units once.
struct PoseData {
  PoseData(const Machine& m, const Observation& o);
  std::vector<double> q;
  std::vector<int> dir;
};

// Facet touch. The probe tip centre P (tool point, workpiece frame) sits one
// tip radius r off the facet plane, which may be offset along its normal:
//
//     n^ . (P - a) - r - facet.<id> = 0
//
//   a: nominal facet point, n^: unit outward normal (workpiece frame).
class FacetResidual {
 public:
  FacetResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const Facet& f,
                double tip_radius, SetupRef offset)
      : access_(ctx), pose_(*ctx->machine, o), point_(f.point), normal_(f.normal),
        tip_radius_(tip_radius), offset_(offset) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(),
                       TipWithOffsets<T>(m, theta.data()), &P);
    residual[0] = normal_.template cast<T>().dot(P - point_.template cast<T>()) - T(tip_radius_) -
                  access_.Setup(p, offset_);
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d point_, normal_;
  const double tip_radius_;
  const SetupRef offset_;
};

// Sphere touch: the tip centre is R + r from the true sphere centre c + dc:
//
//     |P - (c + dc)| - (R + sphere.<id>.r + r) = 0
class SphereResidual {
 public:
  SphereResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const Sphere& s,
                 double tip_radius, const SetupRef (&center)[3], SetupRef radius)
      : access_(ctx), pose_(*ctx->machine, o), center_(s.center), radius_(s.radius),
        tip_radius_(tip_radius), dc_{center[0], center[1], center[2]}, dr_(radius) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(),
                       TipWithOffsets<T>(m, theta.data()), &P);
    const Vec3<T> c = center_.template cast<T>() +
                      Vec3<T>(access_.Setup(p, dc_[0]), access_.Setup(p, dc_[1]), access_.Setup(p, dc_[2]));
    using std::sqrt;
    residual[0] = sqrt((P - c).squaredNorm()) - (T(radius_ + tip_radius_) + access_.Setup(p, dr_));
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d center_;
  const double radius_, tip_radius_;
  const SetupRef dc_[3];
  const SetupRef dr_;
};

// Scale bar: the distance between the two estimated sphere centres equals
// the calibrated length L:   |c1 + dc1 - c2 - dc2| - L = 0
class ScaleBarResidual {
 public:
  ScaleBarResidual(std::shared_ptr<const ResidualContext> ctx, const Sphere& s1, const Sphere& s2,
                   double length, const SetupRef (&d1)[3], const SetupRef (&d2)[3])
      : access_(ctx), c1_(s1.center), c2_(s2.center), length_(length),
        d1_{d1[0], d1[1], d1[2]}, d2_{d2[0], d2[1], d2[2]} {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    Vec3<T> d = (c1_ - c2_).template cast<T>();
    for (int i = 0; i < 3; ++i) d[i] += access_.Setup(p, d1_[i]) - access_.Setup(p, d2_[i]);
    using std::sqrt;
    residual[0] = sqrt(d.squaredNorm()) - T(length_);
    return true;
  }

 private:
  const ParameterAccess access_;
  const Eigen::Vector3d c1_, c2_;
  const double length_;
  const SetupRef d1_[3], d2_[3];
};

// Ball-bar setup parameters: length offset, tool-ball and table-ball offsets.
struct MountRefs {
  SetupRef length;
  SetupRef tool[3];
  SetupRef table[3];
};

// Double ball bar sample. The tool ball is the tool point of a tool whose
// tip is tool_ball + dbb.tool (F at the zero pose); the table ball sits at
// table_ball + dt in the workpiece frame:
//
//     |P_ball - (table_ball + dt)| - (length + dbb.length + reading) = 0
//
// Ball3d sample (R-test, CapBall, tracker): the 3D displacement of the tool
// ball from its nest, workpiece frame (3 rows):
//
//     P_ball - (table_ball + dt) - measured = 0
class BallResidual {
 public:
  BallResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const MountRefs& refs)
      : access_(ctx), pose_(*ctx->machine, o), three_d_(o.type == ObservationType::kBall3d),
        tool_ball_(o.tool_ball), table_ball_(o.table_ball), measured_(o.measured),
        target_length_(o.length + o.reading), refs_(refs) {}

  int num_residuals() const { return three_d_ ? 3 : 1; }

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> tip = tool_ball_.template cast<T>(), table = table_ball_.template cast<T>();
    for (int i = 0; i < 3; ++i) {
      tip[i] += access_.Setup(p, refs_.tool[i]);
      table[i] += access_.Setup(p, refs_.table[i]);
    }
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(), tip, &P);
    const Vec3<T> d = P - table;
    if (three_d_) {
      for (int i = 0; i < 3; ++i) residual[i] = d[i] - T(measured_[i]);
    } else {
      using std::sqrt;
      residual[0] = sqrt(d.squaredNorm()) - (T(target_length_) + access_.Setup(p, refs_.length));
    }
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const bool three_d_;
  const Eigen::Vector3d tool_ball_, table_ball_, measured_;
  const double target_length_;
  const MountRefs refs_;
};

}  // namespace fivecal

#endif  // FIVECAL_RESIDUALS_H_
