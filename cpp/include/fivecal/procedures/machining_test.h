// Machining tests in error-sensitive directions (Zhang & Zhang, shared/seeds/004_*):
// a feature of a test piece is cut at one pose of the rotary axes and again
// (or its counterpart) at another; the difference of the two cuts along an
// error-sensitive direction, measured on the finished part, is a machining
// error that depends on a few kinematic errors of the tilting table.
//
// Model (full machine model, kinematics.h). A feature point W_N (workpiece
// frame at the zero pose, i.e. the table frame {C}) is cut at a pose q whose
// rotary commands are given and whose linear commands put the nominal tool
// point on W_N (nominal inverse kinematics). The real tool point then lies at
// P(q) = inv(T_fw) T_ft 0 in the workpiece frame, while the material point the
// program meant is at W = d + Rz(c) Ry(b) Rx(a) W_N, with (d, a, b, c) =
// workpiece.x|y|z|a|b|c the set-up error of the test piece (the paper's C_delta,
// C_xi). With R0 the nominal rotation of the workpiece frame at q, the pose's
// deviation along the sensitive direction r (machine frame F) is
//
//   e(q) = r . R0(q) (W - P(q))       (mm)
//
// which to first order is the paper's r . (F_W - F_W nominal), F_W = T_fw W
// (eq. 5: the table displaces the workpiece point by R0 (W - P) relative to a
// tool that sits where the program put it). A test's machining error is
// e(pose) - e(reference), or e(pose) without a reference. It is zero on the
// nominal machine.
//
// Zhang & Zhang's three tests on an A/C tilting table (A about +-X, C about
// +-Z; paper angles alpha, gamma about +X, +Z; W_N = (0, L, H)):
//   T1  r = (0,-1, 0), (alpha, gamma) = (90, 180) minus (90, 0)    eq. (6)
//   T2  r = (0, 0, 1), (90, 180) minus (0, 0)                     eq. (10)/(11)
//   T3  r = (0,-1, 0), (90, 180) minus (0, 0)                     eq. (15)/(16)
// To first order, with A_delta = (EX0C, EY0C, EZ0C), A_xi = (EA0C, EB0C, EC0C)
// (the C axis located relative to the A axis: the paper's "kinematic errors of
// the tilt axis"), C_delta, C_xi the workpiece set-up:
//   T1 = -2 A_xi_x (C_delta_y + L) + 2 A_xi_y C_delta_x                    eq. (6)
//   T2 = A_delta_y - A_delta_z - C_delta_y + (H - L) C_xi_x - (H + L) A_xi_x
//        (the printed eq. (11) has (H - L)(C_xi_x - A_xi_x); its A_xi_x
//        coefficient contradicts its own eq. (10) and eq. (16))
//   T3 = A_delta_y + A_delta_z + C_delta_y + (L - H) C_xi_x - (H + L) A_xi_x  eq. (16)
// so EA0C, EY0C and EZ0C follow from T1..T3 once the set-up is known.
//
// Units: mm, degrees for rotary commands, rad for angular errors.
#ifndef FIVECAL_MACHINING_TEST_H_
#define FIVECAL_MACHINING_TEST_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {

struct MachiningTest {
  std::string id;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();      // W_N, workpiece frame, mm
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ(); // r, machine frame F (normalised on use)
  Eigen::VectorXd pose;       // num_axes commands (mm / deg); linear ones are recomputed
  Eigen::VectorXd reference;  // same, or empty: no reference cut
  double measured = 0.0;      // mm, for identification
};

// Names of the workpiece set-up parameters: workpiece.x|y|z (mm), workpiece.a|b|c (rad).
std::vector<std::string> WorkpieceSetupNames();

// Zhang & Zhang's tests T1..T3 on machine m (needs rotary A along +-X and C
// along +-Z at the zero pose; commands are signed so that the table turns by
// the paper's alpha, gamma about +X, +Z). Throws std::invalid_argument otherwise.
std::vector<MachiningTest> ZhangZhangTests(const Machine& m, double L, double H);

// The paper's first-order machining errors T1..T3 (eq. 6, corrected eq. 11, eq. 16).
// a_delta, a_xi, c_delta, c_xi as in the header comment.
Eigen::Vector3d ZhangZhangFirstOrder(double L, double H, const Eigen::Vector3d& a_delta,
                                     const Eigen::Vector3d& a_xi, const Eigen::Vector3d& c_delta,
                                     const Eigen::Vector3d& c_xi);

// Linear commands of every test pose (tests x 2 rows: pose, reference; a
// missing reference gives a row of NaN): the programme the test piece is cut with.
Eigen::MatrixXd MachiningPoses(const Machine& m, const std::vector<MachiningTest>& tests);

// Machining errors predicted by the full model with `values` (machine
// parameters and workpiece.*; unnamed = 0).
Eigen::VectorXd PredictMachining(const Machine& m, const std::vector<MachiningTest>& tests,
                                 const std::map<std::string, double>& values);

// Sensitivities d e_i / d p_j of the machining errors to the parameters
// `names` (machine and workpiece.*) at `values`: tests x names, from the
// automatic derivatives the identification uses (mm per parameter unit).
Eigen::MatrixXd MachiningJacobian(const Machine& m, const std::vector<MachiningTest>& tests,
                                  const std::vector<std::string>& names,
                                  const std::map<std::string, double>& values);

struct MachiningOptions {
  std::vector<std::string> estimate = {"EA0C", "EY0C", "EZ0C"};  // machine and/or workpiece.* names
  std::map<std::string, double> values;  // fixed values and starting values
  double sigma = 0.0;     // mm, measurement uncertainty; 0: from the residuals (needs more tests than unknowns)
  int max_iterations = 50;
  double rank_tolerance = 1e-9;
};

struct MachiningResult {
  std::vector<std::string> estimated;
  Eigen::VectorXd values;      // estimated values
  Eigen::VectorXd std;         // one sigma (NaN when sigma is unknown)
  Eigen::MatrixXd covariance;
  Eigen::VectorXd predicted;   // machining errors at the solution
  Eigen::VectorXd residuals;   // predicted - measured
  double sigma = 0;            // the sigma used
  double condition_number = 0;
  int rank = 0;
  bool converged = false;
  int iterations = 0;
  std::string ToJson() const;
};

// Fits the `estimate` parameters to the measured machining errors (Ceres,
// Levenberg-Marquardt, automatic derivatives through the full kinematics).
// Throws std::invalid_argument for unknown names, no tests, or a rank-deficient
// request (the message names the confounded parameters).
MachiningResult IdentifyMachining(const Machine& m, const std::vector<MachiningTest>& tests,
                                  const MachiningOptions& options);

}  // namespace fivecal

#endif  // FIVECAL_MACHINING_TEST_H_
