// The machine as a CMM (thesis ch. 6): a precision sphere on the table is
// probed at many rotary indexations; every touch's stylus-ball centre is
// expressed in the table (workpiece) frame with a machine model (nominal, or
// the identified one), a sphere is fitted to all of them by Gauss-Newton, and
// the residuals say how well the machine measures in five-axis mode:
//
//   P_i = inv(T_fw(q_i)) T_ft(q_i) 0        (kinematics.h, model `values`)
//   fit: min over (c, R) of sum_i (|P_i - c| - R)^2
//   out of sphericity = max_i e_i - min_i e_i,  e_i = |P_i - c| - R
//   size error        = R - (sphere radius + stylus ball radius)
//
// The point distribution follows ISO 230-10 / thesis §6.3: equally spaced on
// parallels, 12 on the equator, 8 at +30 and 8 at -30 deg latitude, 4 at
// +60 deg and one at the pole (33 points); at each indexation only the points
// whose normal faces the probe are touched (design.h, CandidatePlan).
//
// The one-error-at-a-time table (thesis Table 6-1): the probing plan is
// simulated on a machine with a single error (default size: 1 um at the
// characteristic length L = 400 mm, i.e. 1 um, 2.5 urad, 2.5 um/m), the
// readings are processed with the nominal model, and the size error and out
// of sphericity of the fit are listed. Errors that move the whole point cloud
// rigidly (e.g. EC0C and EZ0C on a wCBXfZYSt machine whose C axis is the last
// workpiece axis) give zero.
//
// Units: mm, degrees for rotary commands, rad for angular errors.
#ifndef FIVECAL_SPHERE_TEST_H_
#define FIVECAL_SPHERE_TEST_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

// Unit vectors on the sphere: for each (latitude in degrees, count) ring,
// `count` points equally spaced in azimuth (the first at azimuth 0; a ring of
// latitude +-90 is the pole). Latitude and azimuth are taken about `pole`
// (workpiece frame; azimuth 0 along the component of +X, or +Y when the pole
// is along X, normal to it). Empty `rings`: the thesis distribution
// {(0, 12), (30, 8), (-30, 8), (60, 4), (90, 1)}.
std::vector<Eigen::Vector3d> SpherePoints(const std::vector<std::pair<double, int>>& rings = {},
                                          const Eigen::Vector3d& pole = Eigen::Vector3d::UnitZ());

struct SphereFit {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius = 0;
  Eigen::VectorXd residuals;  // |P_i - c| - R, mm
  double out_of_sphericity = 0, max_residual = 0, min_residual = 0;
  double std_residual = 0;    // sample standard deviation of the residuals
  double rms = 0;
  int iterations = 0;
  bool converged = false;
};

// Gauss-Newton least-squares sphere (N >= 4 points, N x 3), started from the
// algebraic (linear) fit. Throws std::invalid_argument for fewer than 4 points,
// non-finite or coplanar/degenerate points.
SphereFit FitSphere(const Eigen::MatrixXd& points, int max_iterations = 50, double tolerance = 1e-13);

// Least-squares centre of a sphere of KNOWN radius (the stylus-centre
// radius: sphere + stylus ball) through N >= 3 points (N x 3):
//   min over c of sum_i (|P_i - c| - radius)^2,
// Gauss-Newton from `start` (a nominal centre), stopping when no component
// of a step exceeds `tolerance` (mm). A few touches on a cap leave a free
// radius (FitSphere) undetermined; a known radius needs three. Throws
// std::invalid_argument naming the field (points, radius, start) for
// non-finite values, fewer than 3 points, a radius not > 0, or points that
// do not determine the centre (all on one line through it, a point on it).
struct SphereCentreFit {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::VectorXd residuals;  // |P_i - c| - radius, mm
  double rms = 0;
  int iterations = 0;
  bool converged = false;
};

SphereCentreFit FitSphereCentre(const Eigen::MatrixXd& points, double radius, const Eigen::Vector3d& start,
                                int max_iterations = 50, double tolerance = 1e-12);

// Stylus-ball centres (N x 3, workpiece frame) of the observations `indices`
// of ds computed from their readings with the machine model `values` (machine
// parameter name -> value, tip.x|y|z included; setup names such as facet.F3
// are ignored, so an identification result's values can be passed whole;
// unknown machine names throw).
Eigen::MatrixXd TablePoints(const Dataset& ds, const std::map<std::string, double>& values,
                            const std::vector<int>& indices);

struct SphereTestResult {
  std::string sphere;
  std::vector<int> observations;
  Eigen::MatrixXd points;
  SphereFit fit;
  double size_error = 0;  // fitted radius - (nominal sphere radius + stylus ball radius)
  std::string ToJson() const;
};

// The sphere test on the touches of sphere `sphere` in ds ("" = the only
// sphere touched) with the model `values` (empty map = nominal model).
SphereTestResult SphereTest(const Dataset& ds, const std::string& sphere,
                            const std::map<std::string, double>& values);

struct SensitivityRow {
  std::string name;       // "" for the error-free row ("No parameters")
  double value = 0;       // the error set, in the parameter's unit
  double size_error = 0;  // mm
  double out_of_sphericity = 0;
  double max_residual = 0, min_residual = 0;
};

// Thesis Table 6-1 on the probing plan `plan_json` (a JSON array of plan
// entries as `simulate` takes, touching sphere `sphere` of setup's artefact):
// the error-free row, then one row per name in `names` with that error alone
// set to `values[name]` if given, else 1e-3 / CharacteristicScale(name, L).
std::vector<SensitivityRow> SphereSensitivity(const Dataset& setup, const std::string& plan_json,
                                              const std::string& sphere,
                                              const std::vector<std::string>& names,
                                              const std::map<std::string, double>& values = {},
                                              double characteristic_length = 400.0);

}  // namespace fivecal

#endif  // FIVECAL_SPHERE_TEST_H_
