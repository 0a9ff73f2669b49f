#include "fivecal/solve/identifiability.h"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numeric>

namespace fivecal {
namespace {

// N = Js^T Js (both triangles) of the column-scaled Jacobian.
Eigen::MatrixXd ScaledNormal(const Eigen::MatrixXd& Js) {
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(Js.cols(), Js.cols());
  N.selfadjointView<Eigen::Lower>().rankUpdate(Js.transpose());
  return N.selfadjointView<Eigen::Lower>();
}

// Below this condition number the singular values are taken from the
// eigenvalues of the scaled normal matrix N = Js^T Js: their relative error is
// about p eps kappa^2 (1e-6 at the bound), and forming N plus a symmetric
// eigensolver costs a fifth of a QR and SVD of a 400 x 100 Jacobian. Above
// the bound, the QR and SVD.
constexpr double kEigenConditionBound = 1e4;

// Full-rank, well-conditioned case: rank, condition, log det and
// (J^T J)^-1 (unscaled) from N without an SVD. False: use the SVD.
bool WellConditioned(const Eigen::MatrixXd& Js, double rank_tolerance, Identifiability* out) {
  const int p = static_cast<int>(Js.cols());
  if (p == 0 || Js.rows() < p) return false;
  const Eigen::MatrixXd N = ScaledNormal(Js);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(N, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success) return false;
  const Eigen::VectorXd lambda = eig.eigenvalues();  // ascending
  if (!(lambda[0] > 0) || lambda[p - 1] > kEigenConditionBound * kEigenConditionBound * lambda[0] ||
      std::sqrt(lambda[0]) <= rank_tolerance * std::sqrt(lambda[p - 1]))
    return false;
  const Eigen::LLT<Eigen::MatrixXd> llt(N);
  if (llt.info() != Eigen::Success) return false;
  out->singular_values = lambda.reverse().cwiseSqrt();
  out->rank = p;
  out->condition_number = out->singular_values[0] / out->singular_values[p - 1];
  double logdet = 0;
  for (int i = 0; i < p; ++i) logdet += std::log(lambda[i]);
  out->log_det_per_parameter = logdet / p;
  const Eigen::VectorXd inv_scale = out->column_norms.cwiseInverse();
  out->inverse_normal = llt.solve(Eigen::MatrixXd::Identity(p, p));
  out->inverse_normal = inv_scale.asDiagonal() * out->inverse_normal * inv_scale.asDiagonal();
  return true;
}

// A tall matrix reduced to its p x p triangular QR factor: same singular
// values and right singular vectors, so an SVD after it costs O(p^3), not O(n p^2).
Eigen::MatrixXd TriangularFactor(const Eigen::MatrixXd& A) {
  const Eigen::Index p = A.cols();
  if (A.rows() <= p) return A;
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(A);
  return qr.matrixQR().topRows(p).triangularView<Eigen::Upper>();
}

}  // namespace

Identifiability AnalyzeJacobian(const Eigen::MatrixXd& J, double rank_tolerance) {
  Identifiability out;
  const int p = static_cast<int>(J.cols());
  out.column_norms = J.colwise().norm().transpose();
  Eigen::VectorXd inv_scale(p);
  std::vector<int> zero_columns;
  for (int i = 0; i < p; ++i) {
    if (out.column_norms[i] > 0) {
      inv_scale[i] = 1.0 / out.column_norms[i];
    } else {
      inv_scale[i] = 0.0;
      zero_columns.push_back(i);
    }
  }
  const Eigen::MatrixXd Js = J * inv_scale.asDiagonal();
  if (zero_columns.empty() && WellConditioned(Js, rank_tolerance, &out)) return out;
  const Eigen::MatrixXd reduced = TriangularFactor(Js);
  Eigen::BDCSVD<Eigen::MatrixXd> svd(reduced, Eigen::ComputeFullV);
  const Eigen::VectorXd s = svd.singularValues();
  // Thin SVD of an n x p matrix with n < p has only n singular values.
  out.singular_values = Eigen::VectorXd::Zero(p);
  out.singular_values.head(s.size()) = s;
  const double smax = s.size() ? s[0] : 0.0;
  const double cutoff = rank_tolerance * smax;
  out.rank = 0;
  for (int i = 0; i < s.size(); ++i)
    if (s[i] > cutoff) ++out.rank;
  out.condition_number = (out.rank == p && p > 0) ? smax / s[p - 1] : INFINITY;

  double logdet = 0;
  for (int i = 0; i < p; ++i) logdet += 2.0 * std::log(std::max(out.singular_values[i], 1e-300));
  out.log_det_per_parameter = p ? logdet / p : 0.0;

  // (J^T J)^+ = D V S^-2 V^T D over the retained singular values.
  const Eigen::MatrixXd& V = svd.matrixV();
  Eigen::VectorXd inv_s2 = Eigen::VectorXd::Zero(V.cols());
  for (int i = 0; i < out.rank; ++i) inv_s2[i] = 1.0 / (s[i] * s[i]);
  out.inverse_normal = inv_scale.asDiagonal() * (V * inv_s2.asDiagonal() * V.transpose()) *
                       inv_scale.asDiagonal();

  // Confounded groups: union of the significant entries of each null vector.
  std::vector<int> parent(p);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::vector<bool> involved(p, false);
  Eigen::MatrixXd null_space(p, 0);
  if (out.rank < p) null_space = V.rightCols(p - out.rank);  // beyond the rank (full V)
  for (int c = 0; c < null_space.cols(); ++c) {
    const Eigen::VectorXd v = null_space.col(c);
    const double vmax = v.cwiseAbs().maxCoeff();
    int first = -1;
    for (int i = 0; i < p; ++i) {
      if (std::abs(v[i]) < 0.05 * vmax) continue;
      involved[i] = true;
      if (first < 0) first = i;
      else parent[find(i)] = find(first);
    }
  }
  for (int i : zero_columns) involved[i] = true;
  std::vector<std::vector<int>> groups(p);
  for (int i = 0; i < p; ++i)
    if (involved[i]) groups[find(i)].push_back(i);
  for (auto& g : groups)
    if (!g.empty()) out.confounded.push_back(g);
  return out;
}

bool ClearlyFullRank(const Eigen::MatrixXd& J, double margin) {
  const int p = static_cast<int>(J.cols());
  if (J.rows() < p) return false;
  if (p == 0) return true;
  Eigen::VectorXd inv_scale(p);
  for (int i = 0; i < p; ++i) {
    const double n = J.col(i).norm();
    if (!(n > 0)) return false;
    inv_scale[i] = 1.0 / n;
  }
  // L_jj of the scaled normal matrix is |R_jj| of the QR of the scaled J: the
  // distance of column j from the span of the columns before it. An exactly
  // dependent set always makes one of them vanish; sigma_min can hide below
  // min |R_jj| only for pathological (Kahan-like) matrices, by far less than
  // the 1e-3 between margin and the rank tolerance. L_jj^2 carries an
  // absolute rounding error of about p eps, far below margin^2. A third of
  // the cost of a pivoted QR.
  const Eigen::LLT<Eigen::MatrixXd> llt(ScaledNormal(J * inv_scale.asDiagonal()));
  if (llt.info() != Eigen::Success) return false;
  const Eigen::VectorXd d = llt.matrixLLT().diagonal();
  return d.minCoeff() > margin * d.maxCoeff();
}

std::vector<int> SelectIdentifiable(const Eigen::MatrixXd& J, const std::vector<int>& forced,
                                    const std::vector<int>& candidates, double tolerance) {
  const int n = static_cast<int>(J.rows());
  std::vector<int> kept;
  Eigen::MatrixXd Q(n, 0);  // orthonormal basis of the kept scaled columns
  auto try_add = [&](int c) {
    const double norm = J.col(c).norm();
    if (!(norm > 0)) return false;
    Eigen::VectorXd v = J.col(c) / norm;
    // Two passes of Gram-Schmidt for numerical safety.
    for (int pass = 0; pass < 2; ++pass)
      if (Q.cols()) v -= Q * (Q.transpose() * v);
    const double r = v.norm();
    if (r < tolerance) return false;
    Q.conservativeResize(n, Q.cols() + 1);
    Q.col(Q.cols() - 1) = v / r;
    kept.push_back(c);
    return true;
  };
  for (int c : forced) try_add(c);
  for (int c : candidates) try_add(c);
  return kept;
}

Determination AnalyzeDetermination(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior,
                                   double threshold) {
  Determination out;
  const int p = static_cast<int>(Jw.cols());
  out.ratio = Eigen::VectorXd::Zero(p);
  if (p == 0) return out;
  const Eigen::MatrixXd Js = Jw * prior.asDiagonal();
  const Eigen::MatrixXd reduced = TriangularFactor(Js);
  // One-sided Jacobi, not divide and conquer (3x faster on S4): the groups
  // below are read off the null-space basis, and Jacobi's keeps separate
  // free directions apart (120 free sphere y's: 120 groups) where BDCSVD's
  // mixes them into one (test_guards: refusal of many groups).
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(reduced, Eigen::ComputeFullV);
  out.singular_values = Eigen::VectorXd::Zero(p);
  const Eigen::VectorXd s = svd.singularValues();
  out.singular_values.head(s.size()) = s;
  const Eigen::MatrixXd& V = svd.matrixV();
  const double smax = s.size() ? s[0] : 0.0;
  // Directions below this are exactly free (rounding level): infinite variance.
  const double zero = 1e-12 * std::max(smax, 1.0);
  const double weak = 1.0 / threshold;
  for (int k = 0; k < p; ++k) {
    const double sk = out.singular_values[k];
    if (sk > weak) ++out.rank;
    for (int j = 0; j < p; ++j) {
      if (std::abs(V(j, k)) < 1e-9) continue;
      out.ratio[j] += sk > zero ? V(j, k) * V(j, k) / (sk * sk) : INFINITY;
    }
  }
  out.ratio = out.ratio.cwiseSqrt();
  std::vector<int> parent(p);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::vector<bool> bad(p, false);
  for (int j = 0; j < p; ++j)
    if (!(out.ratio[j] < threshold)) {
      bad[j] = true;
      out.undetermined.push_back(j);
    }
  for (int k = 0; k < p; ++k) {
    if (out.singular_values[k] > weak) continue;
    const Eigen::VectorXd v = V.col(k);
    double vmax = 0;
    for (int j = 0; j < p; ++j)
      if (bad[j]) vmax = std::max(vmax, std::abs(v[j]));
    // An exactly free direction binds every parameter it touches, however
    // lightly (their sigmas are all infinite); a weak one its main members.
    const bool exact = out.singular_values[k] <= zero;
    int first = -1;
    for (int j = 0; j < p; ++j) {
      if (!bad[j] || std::abs(v[j]) < (exact ? 1e-2 : 0.1) * vmax) continue;
      if (first < 0) first = j;
      else parent[find(j)] = find(first);
    }
  }
  std::vector<std::vector<int>> groups(p);
  for (int j : out.undetermined) groups[find(j)].push_back(j);
  for (auto& g : groups)
    if (!g.empty()) out.groups.push_back(g);
  return out;
}

Eigen::VectorXd SubsetRatios(const Eigen::MatrixXd& Js, const std::vector<int>& cols) {
  const int k = static_cast<int>(cols.size());
  Eigen::MatrixXd N(k, k);
  for (int a = 0; a < k; ++a)
    for (int b = a; b < k; ++b) N(a, b) = N(b, a) = Js.col(cols[a]).dot(Js.col(cols[b]));
  Eigen::LDLT<Eigen::MatrixXd> ldlt(N);
  Eigen::VectorXd out = Eigen::VectorXd::Constant(k, INFINITY);
  if (ldlt.info() != Eigen::Success) return out;
  // A (near) singular subset: the smallest pivot at rounding level of the largest.
  const Eigen::VectorXd d = ldlt.vectorD();
  if (!(d.minCoeff() > 1e-13 * std::max(d.maxCoeff(), 1.0))) return out;
  const Eigen::MatrixXd inv = ldlt.solve(Eigen::MatrixXd::Identity(k, k));
  for (int a = 0; a < k; ++a) out[a] = std::sqrt(std::max(inv(a, a), 0.0));
  return out;
}

}  // namespace fivecal
