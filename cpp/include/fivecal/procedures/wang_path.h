// The Wang et al. (2013) double ball bar path (shared/seeds/003_*): the two
// rotary axes of a tilting table move together, the linear axes stand
// still, and the table ball travels a horizontal circle around the
// stationary spindle ball.
//
// Geometry (nominal machine, F at the zero pose). Both rotary axes pass
// through one point O (their intersection). A table ball w (workpiece frame)
// therefore stays on the sphere |B - O| = |w - O| whatever the axes do
// (Section 3: "part of a spherical surface"). A horizontal circle on that
// sphere has its centre on the vertical through O:
//
//   centre  = O + z_c n,  z_c = sign((w - O).n) sqrt(|w - O|^2 - rho^2)
//   B(phi)  = centre + rho (cos phi e1 + sin phi e2)          phi: tracking angle
//   spindle ball M = centre + H n,   bar length L = sqrt(rho^2 + H^2)
//
// with n the spindle direction (vertical), e1 = X, e2 = n x e1 for n = Z.
// For each phi the rotary commands solve
//
//   B(phi) - O = Rot(u_1, q_1) Rot(u_2, q_2) (w - O)
//
// (u_1 the axis next to the foundation, A; u_2 the table axis, C): the
// Paden-Kahan subproblem 2, two solutions in general. Each angle is
// unwrapped by 360 deg to the equivalent nearest the previous sample and
// the solution with the smallest squared move is kept (the paper's "the one
// with smallest distance to go will be selected"); the first sample is
// measured from `start_pose`. With the table ball off the C axis the path
// reproduces the paper's description: A reverses at phi = 90, 270 deg and C
// at phi = 180, 360 deg (Table 1).
#ifndef FIVECAL_WANG_PATH_H_
#define FIVECAL_WANG_PATH_H_

#include <Eigen/Core>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {

struct WangPathOptions {
  Eigen::Vector3d table_ball = Eigen::Vector3d(0, 150, 130);  // workpiece frame (mm)
  double radius = 80.0;     // rho, radius of the horizontal circle (mm)
  double height = 60.0;     // H, spindle ball above the circle plane (mm): a 100 mm bar
  double start = 0.0, end = 540.0, step = 1.0;  // tracking angle (deg)
  double start_tilt = 0.0, start_rotary = 0.0;  // pose before the path (deg)
};

struct WangPath {
  char tilt_axis = 'A', rotary_axis = 'C';  // foundation side, table side
  Eigen::VectorXd tracking;                 // phi (deg)
  Eigen::VectorXd tilt, rotary;             // commands (deg), smallest-move branch
  Eigen::VectorXd other_tilt, other_rotary; // the other solution, unwrapped the same way
  Eigen::VectorXi tilt_direction, rotary_direction;  // sign of the move into each sample
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();   // O (F, mm)
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // circle centre (F, mm)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(), e1 = Eigen::Vector3d::UnitX(),
                  e2 = Eigen::Vector3d::UnitY();
  Eigen::Vector3d spindle_ball = Eigen::Vector3d::Zero();  // M (F, mm)
  double radius = 0.0, height = 0.0, bar_length = 0.0;
  // max_i |B_i - B(phi_i)| with B_i from the forward kinematics (kinematics.h)
  // of the nominal machine at the computed commands (mm).
  double max_circle_error = 0.0;
};

// Throws std::invalid_argument naming the option when the machine has not
// exactly two intersecting rotary axes on the workpiece side, or the circle
// is not on the table ball's sphere.
WangPath ComputeWangPath(const Machine& m, const WangPathOptions& options = {});

// The paper's four-point extraction (Section 5.1: the readings where the
// trace crosses the two diagonals, four equations for four errors) analysed
// instead of trusted. The readings are linear in the errors, so the
// equations are S e = r with S (m x p) the reading change (mm) per unit of
// each error at the m tracking angles (the single-error patterns there).
// With `scale` (p) a plausible size of each error, the judgement is made on
// Ss = S diag(scale), unit-free:
//   singular values of Ss, descending, divided by the largest;
//   rank: those above max(m, p) eps 1e6 (of the largest);
//   null space: the right singular vectors past the rank (p x (p - rank),
//     per unit of scale), each signed so that its largest component is
//     positive: error combinations the readings cannot see;
//   estimable: the errors with no component above 1e-6 in the null space;
//   values: the least-squares solution of S e = r, only with `readings` (m)
//     and full column rank (rank == p); otherwise none.
// Throws std::invalid_argument naming the field for non-finite entries, a
// scale not > 0, or sizes that do not match.
struct WangFourPoint {
  Eigen::VectorXd singular_values;
  int rank = 0;
  Eigen::MatrixXd null_space;
  std::vector<int> estimable;  // column indices of S
  bool solved = false;
  Eigen::VectorXd values;      // per error, in its unit (mm, rad), when solved
};

WangFourPoint AnalyzeWangFourPoint(const Eigen::MatrixXd& sensitivity, const Eigen::VectorXd& scale,
                                   const Eigen::VectorXd* readings = nullptr);

}  // namespace fivecal

#endif  // FIVECAL_WANG_PATH_H_
