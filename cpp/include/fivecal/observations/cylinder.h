// Cylinder touch: a probe touch on a cylinder section of the artefact
// (docs/formats.md, observation type "cylinder"), e.g. the periphery of a
// round machine table or a bore.
#ifndef FIVECAL_OBSERVATIONS_CYLINDER_H_
#define FIVECAL_OBSERVATIONS_CYLINDER_H_

#include <memory>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/probe_trigger.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// The cylinder's own frame: x, y perpendicular to its axis a with
// x cross y = a; x is the workpiece X made perpendicular to a (the
// workpiece Y when a is nearly along X). For an axis along Z, x and y are
// the workpiece X and Y.
void CylinderFrame(const Eigen::Vector3d& a, Eigen::Vector3d* x, Eigen::Vector3d* y);

// The probe tip centre P (tool point, workpiece frame) and the true axis
// line through c' = c + sx x + sy y along a' = (a + ry x - rx y) / |...|
// (sx, sy: cylinder.<id>.x|y, mm; rx, ry: cylinder.<id>.rx|ry, small
// rotations of the axis about x and y, rad), w = P - c',
// d = w - (w . a') a', rho = |d|, e = d / rho (radial unit):
//
//     s (rho - (R + cylinder.<id>.r)) - r + p(-s e) = 0
//
//   s = +1 touching from outside, -1 from inside (a bore); r the tip radius;
//   p the probe's pretravel along the inward normal -s e (probe_trigger.h).
// Derivatives (analytic batch), g = dp/du (workpiece frame), D = (I - e e^T
// - a' a'^T) / rho, G = s (e - D g) (the gradient in P):
//   dr/dtheta = G^T dP/dtheta,  dr/dsx = -G . x,  dr/dsy = -G . y,
//   dr/dR = -s,  dr/dprobe_k = b_k(M (-s e)),
//   dr/da' = s (-(w.a') e + (w.a') (g - e (e.g)) / rho + (g.a') w / rho)^T,
//   then da'/drx = -(I - a' a'^T) y / |v|, da'/dry = (I - a' a'^T) x / |v|.
class CylinderResidual {
 public:
  // setup: cylinder.<id>.r, x, y, rx, ry.
  CylinderResidual(std::shared_ptr<const ResidualContext> ctx, const Observation& o, const Cylinder& c,
                   double tip_radius, const SetupRef (&setup)[5], const ProbeTrigger& trigger)
      : access_(ctx), pose_(*ctx->machine, o), point_(c.point), axis_(c.axis), radius_(c.radius),
        tip_radius_(tip_radius), side_(c.inside ? -1.0 : 1.0),
        setup_{setup[0], setup[1], setup[2], setup[3], setup[4]}, trigger_(trigger) {
    CylinderFrame(axis_, &x_, &y_);
  }

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> theta;
    access_.Theta(p, &theta);
    const Machine& m = access_.machine();
    Vec3<T> P;
    ToolInWorkpiece<T>(m, theta.data(), pose_.q.data(), pose_.dir.data(),
                       TipWithOffsets<T>(m, theta.data()), &P);
    const T dR = access_.Setup(p, setup_[0]), sx = access_.Setup(p, setup_[1]),
            sy = access_.Setup(p, setup_[2]), rx = access_.Setup(p, setup_[3]), ry = access_.Setup(p, setup_[4]);
    const Vec3<T> c = point_.template cast<T>() + x_.template cast<T>() * sx + y_.template cast<T>() * sy;
    Vec3<T> a = axis_.template cast<T>() + x_.template cast<T>() * ry - y_.template cast<T>() * rx;
    using std::sqrt;
    a = a / sqrt(a.squaredNorm());
    const Vec3<T> w = P - c;
    const Vec3<T> d = w - a * w.dot(a);
    const T rho = sqrt(d.squaredNorm());
    const T s = T(side_);
    residual[0] = s * (rho - (T(radius_) + dR)) - T(tip_radius_) +
                  trigger_.Pretravel<T>(access_, p, Vec3<T>(d * (-s / rho)));
    return true;
  }

 private:
  const ParameterAccess access_;
  const PoseData pose_;
  const Eigen::Vector3d point_, axis_;
  const double radius_, tip_radius_, side_;
  const SetupRef setup_[5];
  const ProbeTrigger trigger_;
  Eigen::Vector3d x_, y_;
};

const ObservationKind& CylinderKind();

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_CYLINDER_H_
