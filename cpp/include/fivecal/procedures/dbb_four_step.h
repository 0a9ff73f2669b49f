// The Jiang & Cripps (2015) four-step double ball bar test of the two rotary
// axes of a five-axis machine (shared/seeds/000_*), implemented as the paper
// does it, so its results can be set beside the general engine's.
//
// Machines: any two non-parallel rotary axes along machine axes (X, Y or Z),
// both on the table side (the paper's C600U: C on A; B/C trunnion tables;
// A or B carried by C) or both on the spindle side (head-head). The axis
// nearer the foundation is the carrier, the other is carried by it. The paper
// tests A (carrier) then C (carried); the same four steps, written with the
// two axes' nominal directions n (made positive) and the chain order:
//   K1  the carrier sweeps, the fixed ball S on the nominal carrier axis, the
//       moving ball (pivot) one bar length away in the plane normal to n;
//   K2  the same pivot, bar + 50 mm extension, S' moved along the axis by
//       |S'O'| = sqrt(L_e^2 - L^2): the bar sweeps a cone;
//   J1  the carried axis sweeps at carrier = 0, S on the carried axis;
//   J2  its extension.
// Setup ids default to <carrier>1 <carrier>2 <carried>1 <carried>2 (A1 A2 C1
// C2 on the paper's machine). On the table side the fixed ball is the spindle
// ball and the pivot rides on the table; on the spindle side the roles swap:
// the table ball sits on the head axis and the tool ball is the pivot. All
// positions are taken in the frame that carries the carrier axis (F shifted
// by the linear axes below it), so linear axes on either side are allowed.
//
// Per step, with plane basis (e1, e2) normal to n, cyclic (n = X: Y, Z;
// n = Y: Z, X; n = Z: X, Y):
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
// Results per axis k: E<e1>0k, E<e2>0k (positions), E<rot e1>0k, E<rot e2>0k
// (orientations), carrier first: EY0A EZ0A EB0A EC0A EX0C EY0C EA0C EB0C on
// the paper's machine, EZ0B EX0B EC0B EA0B EX0C EY0C EA0C EB0C on a B/C table.
//
// What this implementation adds to the paper, each switchable:
//  * signs and names follow fivecal's (E = Trans . Rz . Ry . Rx): the paper's
//    eq. 18 gives E_B0A with the opposite sign to fivecal's Ry;
//  * refer_positions: the centre is measured in the plane of the pivot,
//    which lies a distance x0 along the axis from the axis point p_k;
//    the position errors are moved there along the measured (tilted) axis,
//    "separated once the orientation PIGEs are determined" (Section 3.3);
//  * a_removal (carrier removal): the carried axis rides on the carrier, so
//    its measured line includes the carrier's position and orientation
//    errors; kFull expresses the carried line in the (erroneous) carrier
//    frame, kPositionOnly subtracts the carrier's position only (the paper's
//    text: "position errors in the Y direction of A"), kNone keeps the
//    carried line as measured.
// Refused, with the reason: other than two rotary axes besides the spindle;
// one on each side (table-head); an axis not along X, Y or Z (nutating);
// parallel axes; a linear axis carried by a rotary axis of the pair.
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

// The rotary pair the four-step test runs on (RequireFourStepPair).
struct FourStepPair {
  bool tool_side = false;
  int carrier = -1, carried = -1;  // axis indices; the carrier is nearer the foundation
  Eigen::Vector3d n_carrier, n_carried;  // nominal directions made positive (basis vectors)
  std::vector<int> base_chain;  // the chain below the carrier (linear axes only)
  std::vector<std::string> DefaultSetups(const Machine& m) const;
};

// The pair of `m`, or std::invalid_argument saying why the geometry does not
// allow the test (`what` prefixes the message).
FourStepPair RequireFourStepPair(const Machine& m, const std::string& what);

// In the options and results "a" is the carrier (tested first, the paper's A)
// and "c" the carried axis (the paper's C).
struct FourStepOptions {
  // Empty: <carrier>1 <carrier>2 <carried>1 <carried>2.
  std::string a_setup, a_extended_setup;
  std::string c_setup, c_extended_setup;
  // Calibrated length minus nominal length (mm) per setup (the paper's
  // R_c - R_n, Table 1); missing setups use 0.
  std::map<std::string, double> length_offsets;
  // Start-position error P0P0' of the pivot (mm), in the plane basis of the
  // axis (A: Y, Z; C: X, Y), from the planar test around the start position
  // (Section 3.2, eq. 1), in the plane basis of the axis. Used for both
  // steps of that axis.
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
  // S or S' (the fixed ball: the spindle ball on the table side, the table
  // ball on the spindle side) in the frame carrying the pair (mm).
  Eigen::Vector3d spindle_ball = Eigen::Vector3d::Zero();
  Eigen::Vector3d e1, e2, normal;                          // plane basis
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
  std::string carrier, carried;     // axis letters (the paper's A, C)
  bool tool_side = false;
  std::vector<FourStepStep> steps;  // carrier, carrier extended, carried, carried extended
  Eigen::Vector2d a_oe = Eigen::Vector2d::Zero(), c_oe = Eigen::Vector2d::Zero();  // O'E (mm)
  Eigen::Vector3d a_direction, c_direction;  // measured axis directions in F (unit)
  Eigen::Vector3d a_point, c_point;          // measured axis points in F (mm)
  double a_delta = 0.0, c_delta = 0.0;       // eq. 20 (mm)
  // The eight PIGEs (FourStepParameterNames(m); mm, rad), their first-order
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
// "a" = the carrier, "c" = the carried axis, as in FourStepOptions.
struct FourStepPlanOptions {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double length = 100.0;           // bar without the extension (mm)
  double extended_length = 150.0;  // with the 50 mm extension (mm)
  // Sweeps (deg). NaN = defaults: an axis along the tool axis (a rotary
  // table or a head's C axis) turns 0..359, a tilting axis -20..70 (the
  // paper's Section 3.1).
  double a_start = kNaN, a_end = kNaN;
  double c_start = kNaN, c_end = kNaN;
  double step = 1.0;                     // deg between samples
  // Pivots (the moving balls: table balls in the workpiece frame on the
  // table side, tool balls in F at the zero pose on the spindle side). NaN =
  // defaults: carrier pivot at p + 100 n + L e1 (one bar length along the
  // first plane axis, 100 mm along the axis), carried pivot at p + L e1; on a
  // head pair both turned towards the tool tip (+-n, +-e1 or +-e2).
  Eigen::Vector3d a_pivot = Eigen::Vector3d::Constant(kNaN);
  Eigen::Vector3d c_pivot = Eigen::Vector3d::Constant(kNaN);
  // The fixed ball: on the table side the spindle ball in F at the zero pose
  // (NaN = the machine tip); on the spindle side the table ball in the
  // workpiece frame (NaN = on the axis at the step without extension).
  Eigen::Vector3d tool_ball = Eigen::Vector3d::Constant(kNaN);
  // S' = S + sign |S'O'| n. NaN = defaults: towards the tool along an axis
  // parallel to the tool axis (above the table), -1 for a tilting axis ("X
  // driven negative"); the paper's A: -1, C: +1.
  double a_extension_sign = kNaN;
  double c_extension_sign = kNaN;
  std::string a_setup, a_extended_setup, c_setup, c_extended_setup;  // empty = defaults
};

// JSON array of plan entries ({"type": "dbb", "setup", "axes", "direction",
// "length", "tool_ball", "table_ball"}), in the format of simulate.h.
std::string FourStepPlanJson(const Machine& m, const FourStepPlanOptions& options = {});

// The eight PIGE names in output order: of the paper's machine (C on A), and
// of machine `m` (throws as RequireFourStepPair).
const std::vector<std::string>& FourStepParameterNames();
std::vector<std::string> FourStepParameterNames(const Machine& m);

}  // namespace fivecal

#endif  // FIVECAL_DBB_FOUR_STEP_H_
