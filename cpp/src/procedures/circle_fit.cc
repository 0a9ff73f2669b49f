#include "fivecal/procedures/circle_fit.h"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <string>

namespace fivecal {
namespace {

void Validate(const Eigen::MatrixXd& p, const char* what) {
  if (p.cols() != 2) throw std::invalid_argument(std::string(what) + ": points must be N x 2");
  if (p.rows() < 3)
    throw std::invalid_argument(std::string(what) + ": needs at least 3 points, got " +
                                std::to_string(p.rows()));
  for (int i = 0; i < p.rows(); ++i)
    if (!std::isfinite(p(i, 0)) || !std::isfinite(p(i, 1)))
      throw std::invalid_argument(std::string(what) + ": point " + std::to_string(i) +
                                  " is not finite");
}

// Residuals and first-order covariance of (cx, cy, R) at a solution.
void Finish(const Eigen::MatrixXd& p, CircleFit* f) {
  const int n = static_cast<int>(p.rows());
  f->residuals.resize(n);
  Eigen::MatrixXd J(n, 3);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d d = p.row(i).transpose() - f->centre;
    const double r = d.norm();
    f->residuals[i] = r - f->radius;
    const Eigen::Vector2d u = r > 0 ? Eigen::Vector2d(d / r) : Eigen::Vector2d::Zero();
    J.row(i) << -u.x(), -u.y(), -1.0;
  }
  f->rms = std::sqrt(f->residuals.squaredNorm() / n);
  const double s2 = n > 3 ? f->residuals.squaredNorm() / (n - 3) : 0.0;
  const Eigen::Matrix3d N = J.transpose() * J;
  f->covariance = s2 * N.completeOrthogonalDecomposition().pseudoInverse();
}

}  // namespace

CircleFit FitCircleAlgebraic(const Eigen::MatrixXd& points, const char* what) {
  Validate(points, what);
  const Eigen::RowVector2d mean = points.colwise().mean();
  const Eigen::MatrixXd p = points.rowwise() - mean;
  const int n = static_cast<int>(p.rows());
  // Normal equations of eq. 7 (eq. 8, with the sign of the right-hand side).
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    const double y = p(i, 0), z = p(i, 1), s = y * y + z * z;
    const Eigen::Vector3d row(y, z, 1.0);
    M += row * row.transpose();
    rhs -= s * row;
  }
  Eigen::FullPivLU<Eigen::Matrix3d> lu(M);
  // Relative threshold: collinear points make M singular.
  lu.setThreshold(1e-12);
  if (lu.rank() < 3) throw std::invalid_argument(std::string(what) + ": the points lie on a line");
  const Eigen::Vector3d abc = lu.solve(rhs);
  CircleFit f;
  f.centre = Eigen::Vector2d(-abc[0] / 2, -abc[1] / 2) + mean.transpose();  // eqs. 15-16
  const double r2 = abc[0] * abc[0] + abc[1] * abc[1] - 4 * abc[2];
  if (!(r2 > 0)) throw std::invalid_argument(std::string(what) + ": no real circle fits the points");
  f.radius = 0.5 * std::sqrt(r2);  // eq. 17
  Finish(points, &f);
  return f;
}

CircleFit FitCircleGeometric(const Eigen::MatrixXd& points, const char* what) {
  CircleFit f = FitCircleAlgebraic(points, what);
  const int n = static_cast<int>(points.rows());
  for (int it = 0; it < 50; ++it) {
    Eigen::MatrixXd J(n, 3);
    Eigen::VectorXd r(n);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector2d d = points.row(i).transpose() - f.centre;
      const double dist = d.norm();
      r[i] = dist - f.radius;
      const Eigen::Vector2d u = dist > 0 ? Eigen::Vector2d(d / dist) : Eigen::Vector2d::Zero();
      J.row(i) << -u.x(), -u.y(), -1.0;
    }
    const Eigen::Vector3d step = J.colPivHouseholderQr().solve(-r);
    f.centre += step.head<2>();
    f.radius += step[2];
    f.iterations = it + 1;
    if (step.norm() < 1e-13 * (1.0 + f.radius)) break;
  }
  Finish(points, &f);
  return f;
}

}  // namespace fivecal
