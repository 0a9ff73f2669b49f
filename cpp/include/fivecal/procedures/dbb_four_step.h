// The Jiang & Cripps (2015) four-step double ball bar test of the A and C
// axes of a tilting rotary table (shared/seeds/000_*), implemented as the
// paper does it, so its results can be set beside the general engine's.
//
// Machines: the paper's class, a table whose C axis (about Z) sits on an A
// axis (about X), the linear axes on the tool side: topology w C A f ... with
// A along +-X and C along +-Z (C600U-like, VMC0656-like).
//
// The four steps (setup ids in the dataset, one ball-bar mounting each):
//   A1  A sweeps (-20..70 deg), spindle ball S on the nominal A axis, the
//       pivot (table ball) one bar length away in the plane normal to A.
//   A2  the same pivot, bar + 50 mm extension, spindle ball S' moved along
//       the axis (-X) by |S'O'| = sqrt(L_e^2 - L^2): the bar sweeps a cone.
//   C1  C sweeps 360 deg (A = 0), S on the nominal C axis, pivot along X.
//   C2  the extension, S' moved along the axis (+Z).
//
// Per step, with plane basis (e1, e2) normal to the axis (A: Y, Z; C: X, Y):
//   d_e = atan(P0P0'.j / (P0P0'.i + R))                         eq. 1
//   theta_i = i/N theta (optional; default: the recorded commands) eq. 2
//   Y_i = (R_n + d_i) cos(theta_i + d_e),
//   Z_i = (R_n + d_i) sin(theta_i + d_e)                          eqs. 3-4
//   extended steps: R_n + d_i -> EP_i = sqrt(L_i^2 - |S'O'|^2)    eq. 11
//   circle fit (Kasa) -> centre, radius                           eqs. 5-8, 12-17
// The centre of step 1 is O'P (the real axis relative to the ideal centre O'
// = S); the centre of step 2 is EP (relative to E, the foot of S' on the
// cone base), so the axis tilt shows as
//   O'E = O'P - EP        ("O'E ~ EP + PO'", eqs. 18-19)
//   tilt = O'E / |S'O'|   -> orientation errors (atan, eqs. 18-19)
//   Delta = PO' (1/cos(tilt_1) - 1)                               eq. 20
//
// What this implementation adds to the paper, each switchable:
//  * signs and names follow fivecal's (E = Trans . Rz . Ry . Rx): the paper's
//    eq. 18 gives E_B0A with the opposite sign to fivecal's Ry;
//  * refer_positions: the centre is measured in the plane of the pivot,
//    which lies a distance x0 along the axis from the axis point p_A (p_C);
//    the position errors are moved there along the measured (tilted) axis,
//    "separated once the orientation PIGEs are determined" (Section 3.3);
//  * a_removal: the C axis rides on A, so the measured C line includes A's
//    position and orientation errors; kFull expresses the C line in the
//    (erroneous) A frame, kPositionOnly subtracts A's position only (the
//    paper's text: "position errors in the Y direction of A"), kNone keeps
//    the C line as measured in F.
// The section "Four-step approximations" of docs/dbb.md lists the size of
// every approximation and where it breaks, measured against the exact model.
#ifndef FIVECAL_DBB_FOUR_STEP_H_
#define FIVECAL_DBB_FOUR_STEP_H_

#include <Eigen/Core>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

enum class ARemoval { kFull, kPositionOnly, kNone };

struct FourStepOptions {
  std::string a_setup = "A1", a_extended_setup = "A2";
  std::string c_setup = "C1", c_extended_setup = "C2";
  // Calibrated length minus nominal length (mm) per setup (the paper's
  // R_c - R_n, Table 1); missing setups use 0.
  std::map<std::string, double> length_offsets;
  // Start-position error P0P0' of the pivot (mm), in the plane basis of the
  // axis (A: Y, Z; C: X, Y), from the planar test around the start position
  // (Section 3.2, eq. 1). Used for both steps of that axis.
  Eigen::Vector2d a_pivot_offset = Eigen::Vector2d::Zero();
  Eigen::Vector2d c_pivot_offset = Eigen::Vector2d::Zero();
  bool uniform_angles = false;   // eq. 2 instead of the recorded commands
  bool refer_positions = true;
  ARemoval a_removal = ARemoval::kFull;
};

struct FourStepStep {
  std::string setup;
  char axis = 'A';
  bool extended = false;
  Eigen::Vector3d spindle_ball = Eigen::Vector3d::Zero();  // S or S' in F (mm)
  Eigen::Vector3d e1, e2, normal;                          // plane basis in F
  double nominal_radius = 0.0;     // in-plane pivot distance from O' (mm)
  double start_angle_error = 0.0;  // d_e (rad), eq. 1
  double arm = 0.0;                // |S'O'| (mm), extended steps; 0 otherwise
  Eigen::VectorXd angles;          // theta_i + d_e (rad)
  Eigen::MatrixXd points;          // N x 2 (mm), eqs. 3-4 or 11
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // eqs. 7-8 / 14-16 (mm)
  double radius = 0.0;
  Eigen::VectorXd residuals;       // radial, mm
  double rms = 0.0;
  Eigen::Matrix2d centre_covariance = Eigen::Matrix2d::Zero();
  std::vector<int> observations;   // dataset indices
};

struct FourStepResult {
  std::vector<FourStepStep> steps;  // A1, A2, C1, C2
  Eigen::Vector2d a_oe = Eigen::Vector2d::Zero(), c_oe = Eigen::Vector2d::Zero();  // O'E (mm)
  Eigen::Vector3d a_direction, c_direction;  // measured axis directions in F (unit)
  Eigen::Vector3d a_point, c_point;          // measured axis points in F (mm)
  double a_delta = 0.0, c_delta = 0.0;       // eq. 20 (mm)
  // EY0A EZ0A EB0A EC0A EX0C EY0C EA0C EB0C (mm, rad), their first-order
  // standard uncertainties from the circle-fit scatter, and covariance.
  std::vector<std::string> names;
  Eigen::VectorXd values, std;
  Eigen::MatrixXd covariance;
  double Get(const std::string& name) const;
};

FourStepResult AnalyzeFourStep(const Dataset& ds, const FourStepOptions& options = {});

// Plan of the four steps for fivecal::Simulate / a real test: one sample per
// `step` degrees of the moving axis, the spindle ball placed by the nominal
// inverse of the tool-side linear axes.
struct FourStepPlanOptions {
  double length = 100.0;           // bar without the extension (mm)
  double extended_length = 150.0;  // with the 50 mm extension (mm)
  double a_start = -20.0, a_end = 70.0;  // deg (Section 3.1)
  double c_start = 0.0, c_end = 359.0;   // deg
  double step = 1.0;                     // deg between samples
  // Pivots (table balls, workpiece frame). NaN = defaults: A pivot at
  // (100, L, 0) relative to the A axis point (one bar length along +Y, at
  // A = 0, 100 mm along the axis), C pivot at (L, 0, 0) from the C point.
  Eigen::Vector3d a_pivot = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d c_pivot = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  // Spindle ball in F at the zero pose (NaN = the machine tip).
  Eigen::Vector3d tool_ball = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  double a_extension_sign = -1.0;  // S' = S + sign |S'O'| X   ("X driven negative")
  double c_extension_sign = +1.0;  // S' = S + sign |S'O'| Z   (above the table)
  std::string a_setup = "A1", a_extended_setup = "A2", c_setup = "C1", c_extended_setup = "C2";
};

// JSON array of plan entries ({"type": "dbb", "setup", "axes", "direction",
// "length", "tool_ball", "table_ball"}), in the format of simulate.h.
std::string FourStepPlanJson(const Machine& m, const FourStepPlanOptions& options = {});

// The eight PIGE names in output order.
const std::vector<std::string>& FourStepParameterNames();

}  // namespace fivecal

#endif  // FIVECAL_DBB_FOUR_STEP_H_
