#include "fivecal/procedures/wang_path.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/procedures/dbb_setup.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace {

constexpr double kDeg = 180.0 / 3.14159265358979323846;

// Angle (rad) of the rotation about unit w taking p to q (Paden-Kahan
// subproblem 1, on the components normal to w). The copy in inverse.cc is
// private to the tool-orientation solver.
double Subproblem1(const Eigen::Vector3d& w, const Eigen::Vector3d& p, const Eigen::Vector3d& q) {
  const Eigen::Vector3d pp = p - w * w.dot(p), qq = q - w * w.dot(q);
  return std::atan2(w.dot(pp.cross(qq)), pp.dot(qq));
}

// All (t1, t2) with Rot(w1, t1) Rot(w2, t2) p = q (subproblem 2): the
// intermediate point z = Rot(w2, t2) p = Rot(w1, -t1) q lies on both circles,
// z = alpha w1 + beta w2 + gamma (w1 x w2).
std::vector<Eigen::Vector2d> Subproblem2(const Eigen::Vector3d& w1, const Eigen::Vector3d& w2,
                                         const Eigen::Vector3d& p, const Eigen::Vector3d& q) {
  const double c = w1.dot(w2);
  const Eigen::Vector3d n = w1.cross(w2);
  const double d = 1.0 - c * c;
  const double alpha = (w1.dot(q) - c * w2.dot(p)) / d;
  const double beta = (w2.dot(p) - c * w1.dot(q)) / d;
  const double g2 = (p.squaredNorm() - alpha * alpha - beta * beta - 2 * alpha * beta * c) / n.squaredNorm();
  std::vector<Eigen::Vector2d> out;
  if (g2 < -1e-9 * p.squaredNorm()) return out;
  const double g = std::sqrt(std::max(g2, 0.0));
  for (double s : {1.0, -1.0}) {
    const Eigen::Vector3d z = alpha * w1 + beta * w2 + s * g * n;
    out.emplace_back(Subproblem1(w1, z, q), Subproblem1(w2, p, z));
  }
  return out;
}

double Unwrap(double deg, double current) { return deg + 360.0 * std::round((current - deg) / 360.0); }

int Sign(double x) { return x > 1e-12 ? 1 : (x < -1e-12 ? -1 : 0); }

}  // namespace

WangPath ComputeWangPath(const Machine& m, const WangPathOptions& o) {
  const std::string w = "wang path";
  const std::vector<int>& chain = m.workpiece_chain();
  if (chain.size() != 2 || !m.axis(chain[0]).rotary() || !m.axis(chain[1]).rotary())
    throw std::invalid_argument(w + ": machine '" + m.name() + "' (" + m.topology() +
                                ") needs exactly two rotary axes on the workpiece side (a tilting "
                                "rotary table, e.g. wCAf...)");
  for (double x : {o.radius, o.height, o.start, o.end, o.step, o.start_tilt, o.start_rotary})
    RequireFinite(x, w);
  // Within the machine-size bound: the path takes norms of these (1e308 would overflow).
  for (int i = 0; i < 3; ++i)
    RequireBounded(o.table_ball[i], kMaxLinear, w + ".table_ball[" + std::to_string(i) + "]");
  RequireBounded(o.radius, kMaxLinear, w + ".radius");
  RequireBounded(o.height, kMaxLinear, w + ".height");
  if (!(o.radius > 0)) throw std::invalid_argument(w + ".radius: must be > 0 mm");
  if (!(o.step > 0)) throw std::invalid_argument(w + ".step: must be > 0 deg");
  if (!(o.end > o.start)) throw std::invalid_argument(w + ".end: must exceed start");
  // Bounded before any allocation: a tiny step would ask for billions of poses.
  constexpr double kMaxSamples = 1e6;
  const double count = std::floor((o.end - o.start) / o.step + 1e-9) + 1;
  if (!(count <= kMaxSamples)) {
    std::ostringstream s;
    s << w << ".step: " << o.step << " deg gives " << count << " samples from " << o.start << " to " << o.end
      << " deg; at most 1000000 (use a larger step)";
    throw std::invalid_argument(s.str());
  }

  const Axis& a1 = m.axis(chain[0]);
  const Axis& a2 = m.axis(chain[1]);
  WangPath P;
  P.tilt_axis = a1.name;
  P.rotary_axis = a2.name;
  // O: the common point of the two nominal axis lines (closest points).
  const Eigen::Vector3d u1 = a1.direction, u2 = a2.direction;
  const Eigen::Vector3d cr = u1.cross(u2);
  if (cr.norm() < 1e-9) throw std::invalid_argument(w + ": the two rotary axes are parallel");
  const Eigen::Vector3d dp = a2.point - a1.point;
  const double gap = std::abs(dp.dot(cr.normalized()));
  if (gap > 1e-9) {
    std::ostringstream s;
    s << w << ": the nominal " << a1.name << " and " << a2.name << " axes miss each other by " << gap
      << " mm; the table ball stays on a sphere only when they intersect";
    throw std::invalid_argument(s.str());
  }
  // Intersection: a1.point + s u1 with s from the planar solve.
  const double s1 = dp.cross(u2).dot(cr) / cr.squaredNorm();
  P.pivot = a1.point + s1 * u1;

  P.normal = m.tool_axis().normalized();
  Eigen::Vector3d e1 = Eigen::Vector3d::UnitX() - P.normal * P.normal.x();
  if (e1.norm() < 1e-6) e1 = Eigen::Vector3d::UnitY() - P.normal * P.normal.y();
  P.e1 = e1.normalized();
  P.e2 = P.normal.cross(P.e1);

  const Eigen::Vector3d wr = o.table_ball - P.pivot;  // table ball at the zero pose, from O
  const double R2 = wr.squaredNorm();
  if (o.radius * o.radius >= R2) {
    std::ostringstream s;
    s << w << ".radius: " << o.radius << " mm; the table ball is " << std::sqrt(R2)
      << " mm from the axes' intersection, so the circle radius must be smaller";
    throw std::invalid_argument(s.str());
  }
  const double zc = (wr.dot(P.normal) >= 0 ? 1.0 : -1.0) * std::sqrt(R2 - o.radius * o.radius);
  P.radius = o.radius;
  P.height = o.height;
  P.centre = P.pivot + zc * P.normal;
  P.spindle_ball = P.centre + o.height * P.normal;
  P.bar_length = std::hypot(o.radius, o.height);

  const int n = static_cast<int>(std::floor((o.end - o.start) / o.step + 1e-9)) + 1;
  P.tracking.resize(n);
  P.tilt.resize(n);
  P.rotary.resize(n);
  P.other_tilt.resize(n);
  P.other_rotary.resize(n);
  double prev1 = o.start_tilt, prev2 = o.start_rotary;
  const int k1 = chain[0], k2 = chain[1];
  for (int i = 0; i < n; ++i) {
    const double phi = o.start + o.step * i;
    P.tracking[i] = phi;
    const Eigen::Vector3d B =
        P.centre + o.radius * (std::cos(phi / kDeg) * P.e1 + std::sin(phi / kDeg) * P.e2);
    const std::vector<Eigen::Vector2d> sol = Subproblem2(u1, u2, wr, B - P.pivot);
    if (sol.empty()) {
      std::ostringstream s;
      s << w << ": tracking angle " << phi << " deg cannot be reached by " << a1.name << " and "
        << a2.name;
      throw std::invalid_argument(s.str());
    }
    double best = 1e300;
    int bi = 0;
    Eigen::Vector2d cand[2];
    for (size_t j = 0; j < sol.size(); ++j) {
      cand[j] = Eigen::Vector2d(Unwrap(sol[j][0] * kDeg, prev1), Unwrap(sol[j][1] * kDeg, prev2));
      const double cost = std::pow(cand[j][0] - prev1, 2) + std::pow(cand[j][1] - prev2, 2);
      if (cost < best) {
        best = cost;
        bi = static_cast<int>(j);
      }
    }
    const Eigen::Vector2d other = cand[sol.size() > 1 ? 1 - bi : bi];
    P.tilt[i] = cand[bi][0];
    P.rotary[i] = cand[bi][1];
    P.other_tilt[i] = other[0];
    P.other_rotary[i] = other[1];
    prev1 = P.tilt[i];
    prev2 = P.rotary[i];
  }
  // Direction of the move into each sample (the first: as the path leaves it).
  P.tilt_direction.resize(n);
  P.rotary_direction.resize(n);
  for (int i = 0; i < n; ++i) {
    const int j = i == 0 ? 1 : i;
    P.tilt_direction[i] = n > 1 ? Sign(P.tilt[j] - P.tilt[j - 1]) : 0;
    P.rotary_direction[i] = n > 1 ? Sign(P.rotary[j] - P.rotary[j - 1]) : 0;
    // At a reversal sample the move into it still has the old sign; a zero
    // step (exact extremum on the grid) keeps the previous direction.
    if (P.tilt_direction[i] == 0 && i > 0) P.tilt_direction[i] = P.tilt_direction[i - 1];
    if (P.rotary_direction[i] == 0 && i > 0) P.rotary_direction[i] = P.rotary_direction[i - 1];
  }
  // Independent check through the machine's own forward kinematics.
  Eigen::VectorXd pose = Eigen::VectorXd::Zero(m.num_axes());
  for (int i = 0; i < n; ++i) {
    pose[k1] = P.tilt[i];
    pose[k2] = P.rotary[i];
    const Eigen::Vector3d B = NominalTableBallInF(m, pose, o.table_ball);
    const double phi = P.tracking[i] / kDeg;
    const Eigen::Vector3d target = P.centre + o.radius * (std::cos(phi) * P.e1 + std::sin(phi) * P.e2);
    P.max_circle_error = std::max(P.max_circle_error, (B - target).norm());
  }
  return P;
}

WangFourPoint AnalyzeWangFourPoint(const Eigen::MatrixXd& S, const Eigen::VectorXd& scale,
                                   const Eigen::VectorXd* readings) {
  const std::string w = "wang four-point";
  const Eigen::Index m = S.rows(), p = S.cols();
  if (m < 1 || p < 1) throw std::invalid_argument(w + ": sensitivity is empty");
  for (Eigen::Index i = 0; i < m; ++i)
    for (Eigen::Index j = 0; j < p; ++j)
      if (!std::isfinite(S(i, j)))
        throw std::invalid_argument(w + ": sensitivity[" + std::to_string(i) + "][" + std::to_string(j) +
                                    "] is not finite");
  if (scale.size() != p)
    throw std::invalid_argument(w + ": scale has " + std::to_string(scale.size()) + " entries, the sensitivity " +
                                std::to_string(p) + " columns (one per error)");
  for (Eigen::Index j = 0; j < p; ++j)
    if (!(scale[j] > 0) || !std::isfinite(scale[j]))
      throw std::invalid_argument(w + ": scale[" + std::to_string(j) + "] must be a finite size > 0");
  if (readings) {
    if (readings->size() != m)
      throw std::invalid_argument(w + ": readings has " + std::to_string(readings->size()) +
                                  " entries, the sensitivity " + std::to_string(m) + " rows (one per angle)");
    for (Eigen::Index i = 0; i < m; ++i)
      if (!std::isfinite((*readings)[i]))
        throw std::invalid_argument(w + ": readings[" + std::to_string(i) + "] is not finite");
  }
  const Eigen::MatrixXd Ss = S * scale.asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Ss, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  WangFourPoint out;
  const double top = sv.size() ? sv[0] : 0.0;
  const double tol = static_cast<double>(std::max(m, p)) * std::numeric_limits<double>::epsilon() * 1e6 * top;
  for (Eigen::Index k = 0; k < sv.size(); ++k) out.rank += sv[k] > tol;
  out.singular_values = top > 0 ? Eigen::VectorXd(sv / top) : Eigen::VectorXd(sv);
  out.null_space = svd.matrixV().rightCols(p - out.rank);
  for (Eigen::Index k = 0; k < out.null_space.cols(); ++k) {
    Eigen::Index at;
    out.null_space.col(k).cwiseAbs().maxCoeff(&at);
    if (out.null_space(at, k) < 0) out.null_space.col(k) *= -1.0;
  }
  for (Eigen::Index j = 0; j < p; ++j)
    if (out.null_space.cols() == 0 || out.null_space.row(j).cwiseAbs().maxCoeff() < 1e-6)
      out.estimable.push_back(static_cast<int>(j));
  if (readings && out.rank == p) {
    out.values = S.colPivHouseholderQr().solve(*readings);
    out.solved = true;
  }
  return out;
}

}  // namespace fivecal
