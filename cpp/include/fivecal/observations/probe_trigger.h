// The trigger model of a touch probe, shared by every probe-touch kind
// (facet, sphere, cylinder): pretravel and lobing (docs/identification.md,
// "Probe pretravel and lobing").
//
// A touch-trigger probe does not report the tip centre at the geometric
// contact: the stylus deflects by the pretravel before the switch opens, so
// the recorded tip centre lies p(u) beyond the contact along the inward
// contact normal u (unit, pointing from the tip into the surface). With
// gap(P) the signed distance of a tip centre P from the surface (zero at the
// contact, positive in free space), P_contact = P - p(u) u and, for a plane,
// a sphere and a cylinder exactly,
//
//     gap(P - p(u) u) = gap(P) + p(u).
//
// So every probe-touch residual gains + p(u). The pretravel depends on the
// direction of u in the probe frame (u_p = M u, M the nominal rotation from
// the workpiece frame to the probe frame at the touch's pose), modelled with
// six terms, each a setup parameter:
//
//     p(u_p) = probe.pretravel                          1
//            + probe.axial   * uz^2                     axial minus lateral pretravel
//            + probe.lobe.c2 * (ux^2 - uy^2)            two-fold lateral lobing
//            + probe.lobe.s2 * 2 ux uy
//            + probe.lobe.c3 * (ux^3 - 3 ux uy^2)       three-fold lateral lobing
//            + probe.lobe.s3 * (3 ux^2 uy - uy^3)       (kinematic resistive probes)
//
// Probe frame: z along the machine's tool axis (pointing from the stylus
// ball to the spindle), x along F's x projected off z (F's y when the tool
// axis is along x), y = z x x; it turns with the spindle axis S, as the
// probe does. No degree-one term: a pretravel a . u_p moves every touch like
// a stylus offset, it is tip.x|y|z exactly.
//
// The parameters are opt-in (named in the estimate set; never in the default
// setup): probe.pretravel acts exactly like a smaller tip radius, so with
// facet offsets, cylinder radii or sphere radii estimated it is not
// determined.
#ifndef FIVECAL_OBSERVATIONS_PROBE_TRIGGER_H_
#define FIVECAL_OBSERVATIONS_PROBE_TRIGGER_H_

#include <Eigen/Core>
#include <string>

#include "fivecal/model/kinematics.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

class ParameterTable;

constexpr int kProbeTerms = 6;
// "probe.pretravel", "probe.axial", "probe.lobe.c2", ... in the order above.
extern const char* const kProbeParameterNames[kProbeTerms];

// Whether `name` is one of kProbeParameterNames.
bool IsProbeParameterName(const std::string& name);

// The basis b_k(u_p) of the model above.
template <typename T>
void ProbeBasis(const Vec3<T>& u, T* b) {
  const T x = u[0], y = u[1], z = u[2];
  b[0] = T(1.0);
  b[1] = z * z;
  b[2] = x * x - y * y;
  b[3] = T(2.0) * x * y;
  b[4] = x * x * x - T(3.0) * x * y * y;
  b[5] = T(3.0) * x * x * y - y * y * y;
}

// The basis and its gradients in u_p (rows of `grad`).
void ProbeBasisGradient(const Eigen::Vector3d& u, double* b, Eigen::Matrix<double, kProbeTerms, 3>* grad);

// M: the nominal rotation taking a direction in the workpiece frame to the
// probe frame at the pose of observation `o`.
Eigen::Matrix3d ProbeFrameRotation(const Machine& m, const Observation& o);

// The table index of probe.pretravel (the kProbeTerms parameters follow it
// in order), or -1 when the table has none.
int ProbeParameterIndex(const ParameterTable& t);

// The pretravel term of one probe-touch residual (templated functors).
struct ProbeTrigger {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // M
  SetupRef ref[kProbeTerms];

  // p(M u_work); u_work: the inward contact normal, unit, workpiece frame.
  template <typename T>
  T Pretravel(const ParameterAccess& access, T const* const* p, const Vec3<T>& u_work) const {
    if (ref[0].index < 0) return T(0.0);
    const Vec3<T> u = rotation.template cast<T>() * u_work;
    T b[kProbeTerms];
    ProbeBasis<T>(u, b);
    T s = T(0.0);
    for (int k = 0; k < kProbeTerms; ++k) s += b[k] * access.Setup(p, ref[k]);
    return s;
  }
};

// The trigger term of observation `o` for a residual being built (its
// parameters' blocks are added to the residual when estimated).
ProbeTrigger MakeProbeTrigger(ResidualBuilder& b, const Observation& o);

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_PROBE_TRIGGER_H_
