// Least-squares circles through planar points (mm).
//
// Algebraic fit (Kasa), Jiang & Cripps 2015 eqs. 5-8 (and 12-17 for the cone
// base of the extension-bar tests): with a = -2 y0, b = -2 z0,
// c = y0^2 + z0^2 - R^2 it minimises
//
//   f(a, b, c) = sum_i (Y_i^2 + Z_i^2 + a Y_i + b Z_i + c)^2          (eq. 7)
//
// whose normal equations are eq. 8:
//
//   | sum Y^2   sum YZ   sum Y | |a|     | sum(Y^3 + Y Z^2) |
//   | sum YZ    sum Z^2  sum Z | |b| = - | sum(Y^2 Z + Z^3) |
//   | sum Y     sum Z    N     | |c|     | sum(Y^2 + Z^2)   |
//
// (the paper prints the right-hand side without the minus sign; with it the
// solution satisfies a = -2 y0 as eq. 7 defines). Then y0 = -a/2, z0 = -b/2,
// R = sqrt(a^2 + b^2 - 4c)/2 (eqs. 15-17). The fit is solved on points
// shifted to their mean, which leaves the minimiser unchanged (the objective
// only depends on distances) and keeps the 3x3 system well conditioned.
//
// Geometric fit (the ISO 230-4 least-squares circle): minimises
// sum_i (|p_i - c| - R)^2 by Gauss-Newton from the algebraic solution.
//
// Both report the radial residuals |p_i - c| - R and the first-order
// covariance of (c, R) from the geometric model,
//   r_i = -u_i . dc - dR,  u_i = (p_i - c)/|p_i - c|,  cov = s^2 (J^T J)^-1,
// with s^2 = sum r_i^2 / (N - 3): what the scatter of the points says about
// the centre (partial arcs give larger, correlated centre uncertainties).
#ifndef FIVECAL_CIRCLE_FIT_H_
#define FIVECAL_CIRCLE_FIT_H_

#include <Eigen/Core>

namespace fivecal {

struct CircleFit {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // mm
  double radius = 0.0;                               // mm
  Eigen::VectorXd residuals;                         // |p_i - c| - R, mm
  double rms = 0.0;                                  // of the residuals, mm
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // (cx, cy, R), mm^2
  int iterations = 0;                                // geometric fit only
};

// points: N x 2 (N >= 3, not all on one line). Throws std::invalid_argument
// naming `what` otherwise.
CircleFit FitCircleAlgebraic(const Eigen::MatrixXd& points, const char* what = "circle fit");
CircleFit FitCircleGeometric(const Eigen::MatrixXd& points, const char* what = "circle fit");

}  // namespace fivecal

#endif  // FIVECAL_CIRCLE_FIT_H_
