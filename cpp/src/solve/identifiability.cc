#include "fivecal/solve/identifiability.h"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "solve/dense.h"

namespace fivecal {
namespace {

// N = Js^T Js (both triangles) of the column-scaled Jacobian. The dense
// decompositions below run on the widest instruction set the CPU has
// (solve/dense.h).
Eigen::MatrixXd ScaledNormal(const Eigen::MatrixXd& Js) { return dense::Gram(Js); }

// Below this condition number the singular values are taken from the
// eigenvalues of the scaled normal matrix N = Js^T Js: their relative error is
// about p eps kappa^2 (1e-6 at the bound), and forming N plus a symmetric
// eigensolver costs a fifth of a QR and SVD of a 400 x 100 Jacobian. Above
// the bound, the QR and SVD.
constexpr double kEigenConditionBound = 1e4;

// Full-rank, well-conditioned case: rank, condition, log det and
// (J^T J)^-1 (unscaled) from N without an SVD. False: use the SVD.
bool WellConditioned(const Eigen::MatrixXd& Js, double rank_tolerance, bool inverse, Identifiability* out,
                     Eigen::VectorXd* eigenvalues) {
  const int p = static_cast<int>(Js.cols());
  if (p == 0 || Js.rows() < p) return false;
  const Eigen::MatrixXd N = ScaledNormal(Js);
  Eigen::VectorXd lambda;  // ascending
  if (!dense::SymmetricEigen(N, false, &lambda, nullptr)) return false;
  *eigenvalues = lambda;
  if (!(lambda[0] > 0) || lambda[p - 1] > kEigenConditionBound * kEigenConditionBound * lambda[0] ||
      std::sqrt(lambda[0]) <= rank_tolerance * std::sqrt(lambda[p - 1]))
    return false;
  dense::Cholesky llt;
  if (inverse) {
    llt = dense::Llt(N);
    if (!llt.ok) return false;
  }
  out->singular_values = lambda.reverse().cwiseSqrt();
  out->rank = p;
  out->condition_number = out->singular_values[0] / out->singular_values[p - 1];
  double logdet = 0;
  for (int i = 0; i < p; ++i) logdet += std::log(lambda[i]);
  out->log_det_per_parameter = logdet / p;
  if (!inverse) return true;
  const Eigen::VectorXd inv_scale = out->column_norms.cwiseInverse();
  out->inverse_normal = llt.Inverse();
  out->inverse_normal = inv_scale.asDiagonal() * out->inverse_normal * inv_scale.asDiagonal();
  return true;
}

Identifiability Analyze(const Eigen::MatrixXd& J, double rank_tolerance, bool full);

}  // namespace

Eigen::MatrixXd TriangularFactor(const Eigen::MatrixXd& A) {
  const Eigen::Index p = A.cols();
  if (A.rows() <= p) return A;
  return dense::QrR(A);
}

Identifiability AnalyzeJacobian(const Eigen::MatrixXd& J, double rank_tolerance) {
  return Analyze(J, rank_tolerance, true);
}

double ConditionNumber(const Eigen::MatrixXd& J, double rank_tolerance) {
  return Analyze(J, rank_tolerance, false).condition_number;
}

namespace {

// full: also V's products (inverse_normal, confounded); without, only what
// the singular values give.
Identifiability Analyze(const Eigen::MatrixXd& J, double rank_tolerance, bool full) {
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
  Eigen::VectorXd lambda;  // of Js^T Js, ascending (empty: not computed)
  if (zero_columns.empty() && WellConditioned(Js, rank_tolerance, full, &out, &lambda)) return out;
  const Eigen::MatrixXd reduced = TriangularFactor(Js);
  // The singular values first, without vectors (less than half the cost):
  // of full rank, (Js^T Js)^-1 = R^-1 R^-T needs no V. Where the eigenvalues
  // already put sigma_min below 1e-6 sigma_max (their rounding, p eps
  // lambda_max, is far below that) the set is rank deficient or nearly so and
  // V will be needed: one SVD with V instead of two (the singular values are
  // the same to rounding, 1e-13 relative, either way).
  const bool vectors = full && (!zero_columns.empty() ||
                                (lambda.size() == p && p > 0 && lambda[0] < 1e-12 * lambda[p - 1]));
  Eigen::BDCSVD<Eigen::MatrixXd> svd(reduced, vectors ? Eigen::ComputeFullV : 0);
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
  if (!full) return out;
  if (out.rank == p && reduced.rows() == p && reduced.triangularView<Eigen::StrictlyLower>().toDenseMatrix().isZero(0)) {
    const Eigen::MatrixXd X = reduced.triangularView<Eigen::Upper>().solve(Eigen::MatrixXd::Identity(p, p));
    out.inverse_normal = inv_scale.asDiagonal() * (X * X.transpose()) * inv_scale.asDiagonal();
    return out;  // nothing confounded
  }
  if (!vectors) svd.compute(reduced, Eigen::ComputeFullV);

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

}  // namespace

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
  const dense::Cholesky llt = dense::Llt(ScaledNormal(J * inv_scale.asDiagonal()));
  if (!llt.ok) return false;
  const Eigen::VectorXd d = llt.Diagonal();
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

namespace {

// A basis of the span of the orthonormal columns Vc that depends on the
// subspace only: the pivoted Cholesky factor of its projector P = Vc Vc^T,
// pivots by largest remaining diagonal (ties to the lower index). Any
// orthonormal basis of the span gives the same P, hence the same vectors (up
// to rounding), and a span that splits into pieces on disjoint parameters
// gives vectors each inside one piece (the Schur complements of a block
// diagonal P stay block diagonal). A one-column Vc comes back as itself, up
// to sign.
Eigen::MatrixXd SubspaceBasis(const Eigen::MatrixXd& Vc) {
  const Eigen::Index p = Vc.rows(), m = Vc.cols();
  if (m <= 1) return Vc;
  const Eigen::MatrixXd P = Vc * Vc.transpose();
  Eigen::VectorXd d = P.diagonal();
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(p, m);
  for (Eigen::Index t = 0; t < m; ++t) {
    const double dmax = d.maxCoeff();
    if (!(dmax > 1e-12)) {
      L.conservativeResize(p, t);
      break;
    }
    // Ties within rounding go to the lower index, so that two bases of one
    // subspace pick the same pivots.
    Eigen::Index piv = 0;
    while (d[piv] < dmax * (1 - 1e-8)) ++piv;
    Eigen::VectorXd col = P.col(piv);
    if (t) col -= L.leftCols(t) * L.row(piv).head(t).transpose();
    col /= std::sqrt(d[piv]);
    L.col(t) = col;
    d -= col.cwiseAbs2();
    d[piv] = 0;
  }
  return L;
}

}  // namespace

std::vector<std::vector<int>> UndeterminedGroups(const Eigen::VectorXd& s, const Eigen::MatrixXd& V,
                                                 const std::vector<bool>& bad, double zero, double weak) {
  const int p = static_cast<int>(V.rows());
  std::vector<int> parent(p);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // The weak directions in clusters of equal singular values (every exactly
  // free one in one cluster): inside a cluster the singular vectors are any
  // orthonormal basis of its subspace, which the SVD picks at will (Jacobi
  // keeps separate free directions apart, divide and conquer mixes them), so
  // each cluster is read through SubspaceBasis.
  const double smax = s.size() ? std::max(s.maxCoeff(), 1.0) : 1.0;
  const double tie = 1e-10 * smax;
  // A thin SVD of a wide matrix has fewer singular values than V has columns:
  // the rest are zero.
  auto sv = [&](int k) { return k < s.size() ? s[k] : 0.0; };
  const int nv = static_cast<int>(V.cols());
  int k = 0;
  while (k < nv && sv(k) > weak) ++k;
  while (k < nv) {
    const bool exact = sv(k) <= zero;
    int end = k + 1;
    if (exact)
      end = nv;
    else
      while (end < nv && sv(end) > zero && sv(end - 1) - sv(end) <= tie) ++end;
    const Eigen::MatrixXd basis = SubspaceBasis(V.middleCols(k, end - k));
    for (int c = 0; c < basis.cols(); ++c) {
      const auto v = basis.col(c);
      double vmax = 0;
      for (int j = 0; j < p; ++j)
        if (bad[j]) vmax = std::max(vmax, std::abs(v[j]));
      // An exactly free direction binds every parameter it touches, however
      // lightly (their sigmas are all infinite); a weak one its main members.
      int first = -1;
      for (int j = 0; j < p; ++j) {
        if (!bad[j] || std::abs(v[j]) < (exact ? 1e-2 : 0.1) * vmax) continue;
        if (first < 0) first = j;
        else parent[find(j)] = find(first);
      }
    }
    k = end;
  }
  std::vector<std::vector<int>> groups(p);
  for (int j = 0; j < p; ++j)
    if (bad[j]) groups[find(j)].push_back(j);
  std::vector<std::vector<int>> out;
  for (auto& g : groups)
    if (!g.empty()) out.push_back(std::move(g));
  return out;
}

namespace {

// CertainlyUndetermined on N = Js^T Js. Pivot j of its Cholesky factor,
// L_jj^2, is the squared distance d_j^2 of column j from the span of the
// columns before it. With x the combination that leaves that distance
// (x_j = 1), ratio_j^2 = e_j^T N^+ e_j >= x_j^2 / x^T N x = 1 / d_j^2 (or
// e_j leans on a free direction: ratio_j infinite). So d_j < 1 / threshold
// makes column j undetermined. The margin covers the pivots' rounding, about
// p eps lambda_max <= p eps trace(N) in absolute terms; a failed Cholesky (a
// pivot at or below zero) is the same certificate for its column.
bool PivotCertificate(const dense::Cholesky& llt, double trace, double threshold) {
  const double weak2 = 1.0 / (threshold * threshold);
  const double slack = 1e-10 * trace;
  if (!std::isfinite(slack) || !(slack < 0.5 * weak2)) return false;
  if (!llt.ok) return true;
  return llt.Diagonal().cwiseAbs2().minCoeff() < 0.99 * weak2 - slack;
}

}  // namespace

namespace {

// AnalyzeDetermination from the eigenvectors of N = Js^T Js instead of the
// SVD of Js (Js = `reduced`, N formed from it): a third of the cost on S4's
// 121 columns (bench/NOTES.md, S4). The eigenpairs of the formed N carry more
// rounding than Js's singular pairs, so every decision read off them (each
// ratio against the threshold, each direction's side of `weak`, each weak
// direction's tie with its neighbour, each group member's side of the
// 0.1 vmax cut) is accepted only when it stands clear of an error bound: the
// residual of the eigenpairs against Js itself, |Js^T (Js V) - V Lambda|_F
// (which holds the forming of N and the eigensolver's error), plus the
// rounding of that residual. Then the SVD, whose own error is far smaller,
// takes the same decisions and the groups are that path's. False, `out`
// untouched: some decision is within the bound, or a direction is (nearly)
// exactly free; use the SVD.
bool EigenDetermination(const Eigen::MatrixXd& reduced, const Eigen::MatrixXd& N, double threshold,
                        Determination* out) {
  const int p = static_cast<int>(N.cols());
  Eigen::VectorXd ascending;
  Eigen::MatrixXd vectors;
  if (!dense::SymmetricEigen(N, true, &ascending, &vectors)) return false;
  const Eigen::VectorXd lambda = ascending.reverse();  // descending, as s
  const Eigen::MatrixXd V = vectors.rowwise().reverse();
  const double weak = 1.0 / threshold;
  const Eigen::MatrixXd JV = dense::Product(reduced, V);
  const double residual = (dense::TransposeProduct(reduced, JV) - V * lambda.asDiagonal()).norm();
  const double err = 2.0 * residual + 2.0 * (p + 1) * std::numeric_limits<double>::epsilon() * lambda[0];
  if (!(err > 0) || !std::isfinite(err)) return false;
  // Exactly free (or rounding-level) directions: only the SVD resolves them.
  if (!(lambda[p - 1] > 100.0 * err)) return false;
  const Eigen::VectorXd s = lambda.cwiseSqrt();
  const double tie = 1e-10 * std::max(s[0], 1.0);  // UndeterminedGroups' tie
  // Each singular value's uncertainty from lambda's: |ds| <= err / (2 s).
  auto ds = [&](int k) { return err / (2.0 * s[k]) + 1e-12 * s[0]; };
  int rank = 0;
  for (int k = 0; k < p; ++k) {
    if (std::abs(s[k] - weak) <= 2.0 * ds(k)) return false;
    if (s[k] > weak) ++rank;
  }
  // The weak directions (s <= weak) must be single (no tie with a neighbour,
  // which the SVD could see as a cluster) and their vectors' rounding is
  // err / (their eigenvalue gap) (Davis-Kahan).
  Eigen::VectorXd verr = Eigen::VectorXd::Zero(p);
  for (int k = rank; k < p; ++k) {
    double gap = INFINITY;
    if (k > 0) gap = std::min(gap, lambda[k - 1] - lambda[k]);
    if (k + 1 < p) gap = std::min(gap, lambda[k] - lambda[k + 1]);
    if (k > rank && s[k - 1] - s[k] <= tie + 2.0 * (ds(k) + ds(k - 1))) return false;
    if (!(gap > 4.0 * err)) return false;
    verr[k] = 2.0 * err / gap + 1e-12;
  }
  // ratio_j^2 = [N^-1]_jj and its first-order sensitivity |N^-1 e_j|^2 |E|.
  Eigen::VectorXd ratio2 = Eigen::VectorXd::Zero(p), col2 = Eigen::VectorXd::Zero(p);
  for (int k = 0; k < p; ++k) {
    const double inv = 1.0 / lambda[k];
    for (int j = 0; j < p; ++j) {
      const double v2 = V(j, k) * V(j, k);
      if (std::abs(V(j, k)) >= 1e-9) ratio2[j] += v2 * inv;
      col2[j] += v2 * inv * inv;
    }
  }
  const double t2 = threshold * threshold;
  std::vector<bool> bad(p, false);
  std::vector<int> undetermined;
  for (int j = 0; j < p; ++j) {
    if (std::abs(ratio2[j] - t2) <= 4.0 * err * col2[j] + 1e-12 * ratio2[j]) return false;
    if (!(ratio2[j] < t2)) {
      bad[j] = true;
      undetermined.push_back(j);
    }
  }
  // Each weak direction's members: |v_j| against 0.1 max |v_bad| clear of
  // both vectors' rounding (UndeterminedGroups' cut for a weak direction).
  for (int k = rank; k < p; ++k) {
    double vmax = 0;
    for (int j = 0; j < p; ++j)
      if (bad[j]) vmax = std::max(vmax, std::abs(V(j, k)));
    for (int j = 0; j < p; ++j)
      if (bad[j] && std::abs(std::abs(V(j, k)) - 0.1 * vmax) <= 2.0 * verr[k]) return false;
  }
  out->singular_values = s;
  out->rank = rank;
  out->ratio = ratio2.cwiseSqrt();
  out->undetermined = undetermined;
  out->groups = UndeterminedGroups(s, V, bad, 1e-12 * std::max(s[0], 1.0), weak);
  return true;
}

}  // namespace

bool CertainlyUndetermined(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior, double threshold) {
  if (Jw.cols() == 0) return false;
  const Eigen::MatrixXd N = ScaledNormal(Jw * prior.asDiagonal());
  return PivotCertificate(dense::Llt(N), N.trace(), threshold);
}

namespace {

// AnalyzeDetermination's quick answer on N = Js^T Js and its Cholesky
// factor: true when every direction is clearly above `weak` and every ratio
// below the threshold (the usual case); `ratio` and `lambda` (ascending)
// then hold the ratios and eigenvalues. False: the quick path cannot say.
bool QuickDetermined(const Eigen::MatrixXd& N, const dense::Cholesky& llt, bool certainly_undetermined,
                     double threshold, Eigen::VectorXd* ratio, Eigen::VectorXd* lambda) {
  const int p = static_cast<int>(N.cols());
  const double weak = 1.0 / threshold;
  // A column the pivots already show undetermined would fail the ratio
  // check below: the eigenvalues are of no use then.
  if (certainly_undetermined) return false;
  if (!dense::SymmetricEigen(N, false, lambda, nullptr)) return false;
  if (!(lambda->size() == p && (*lambda)[0] > 1.01 * weak * weak + 1e-12 * (*lambda)[p - 1])) return false;
  *ratio = llt.ok ? Eigen::VectorXd(llt.Inverse().diagonal().cwiseMax(0.0).cwiseSqrt())
                  : Eigen::VectorXd::Constant(p, INFINITY);
  return (ratio->array() < threshold).all();
}

}  // namespace

bool AnyUndetermined(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior, double threshold) {
  const int p = static_cast<int>(Jw.cols());
  if (p == 0) return false;
  // CertainlyUndetermined's N, which AnalyzeDetermination's quick path
  // would form again from a QR factor of the same Js: the same matrix to
  // rounding, without the QR of all the rows.
  const Eigen::MatrixXd N = ScaledNormal(Jw * prior.asDiagonal());
  const dense::Cholesky llt = dense::Llt(N);
  if (PivotCertificate(llt, N.trace(), threshold)) return true;
  Eigen::VectorXd ratio, lambda;
  if (Jw.rows() >= p && QuickDetermined(N, llt, false, threshold, &ratio, &lambda)) return false;
  return !AnalyzeDetermination(Jw, prior, threshold).undetermined.empty();
}

Determination AnalyzeDetermination(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& prior,
                                   double threshold) {
  Determination out;
  const int p = static_cast<int>(Jw.cols());
  out.ratio = Eigen::VectorXd::Zero(p);
  if (p == 0) return out;
  const Eigen::MatrixXd reduced = TriangularFactor(Jw * prior.asDiagonal());
  const double weak = 1.0 / threshold;
  // Every direction clearly above `weak` (the usual case): no singular
  // vectors. The eigenvalues of N = Js^T Js carry an absolute rounding of
  // about p eps lambda_max, far inside the margin; then every ratio is below
  // 1 / sigma_min < threshold, and they come from the Cholesky factor of N.
  if (reduced.rows() >= p) {
    const Eigen::MatrixXd N = ScaledNormal(reduced);
    const dense::Cholesky llt = dense::Llt(N);
    Eigen::VectorXd ratio, lambda;
    if (QuickDetermined(N, llt, PivotCertificate(llt, N.trace(), threshold), threshold, &ratio, &lambda)) {
      out.singular_values = lambda.reverse().cwiseSqrt();
      out.rank = p;
      out.ratio = ratio;
      return out;
    }
    if (EigenDetermination(reduced, N, threshold, &out)) return out;
  }
  // Divide and conquer (6x faster than Jacobi on S4's 121 columns): what is
  // read off V below depends on its subspaces only, not on the basis the
  // SVD picks inside them.
  Eigen::BDCSVD<Eigen::MatrixXd> svd(reduced, Eigen::ComputeFullV);
  out.singular_values = Eigen::VectorXd::Zero(p);
  const Eigen::VectorXd s = svd.singularValues();
  out.singular_values.head(s.size()) = s;
  const Eigen::MatrixXd& V = svd.matrixV();
  const double smax = s.size() ? s[0] : 0.0;
  // Directions below this are exactly free (rounding level): infinite variance.
  const double zero = 1e-12 * std::max(smax, 1.0);
  // ratio_j^2 = [(Js^T Js)^+]_jj over the determined directions; infinite
  // when the projection of e_j on the free subspace is beyond rounding
  // (|P0 e_j| with P0 its projector: the same for any basis of it).
  Eigen::VectorXd free2 = Eigen::VectorXd::Zero(p);
  for (int k = 0; k < p; ++k) {
    const double sk = out.singular_values[k];
    if (sk > weak) ++out.rank;
    if (sk > zero) {
      // Entries at rounding level say nothing (and 1e-18 / sk^2 can be large).
      for (int j = 0; j < p; ++j)
        if (std::abs(V(j, k)) >= 1e-9) out.ratio[j] += V(j, k) * V(j, k) / (sk * sk);
    } else {
      free2 += V.col(k).cwiseAbs2();
    }
  }
  out.ratio = out.ratio.cwiseSqrt();
  std::vector<bool> bad(p, false);
  for (int j = 0; j < p; ++j) {
    if (free2[j] >= 1e-18) out.ratio[j] = INFINITY;
    if (!(out.ratio[j] < threshold)) {
      bad[j] = true;
      out.undetermined.push_back(j);
    }
  }
  out.groups = UndeterminedGroups(out.singular_values, V, bad, zero, weak);
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

Eigen::MatrixXd ScaledPosterior(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& s) {
  const Eigen::MatrixXd Js = Jw * s.asDiagonal();
  Eigen::MatrixXd N = Js.transpose() * Js;
  N.diagonal().array() += 1.0;
  return N.ldlt().solve(Eigen::MatrixXd::Identity(N.rows(), N.cols()));
}

}  // namespace fivecal
