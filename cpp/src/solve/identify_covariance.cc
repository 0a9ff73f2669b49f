#include "fivecal/solve/identify_covariance.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Cholesky>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/priors.h"
#include "fivecal/uncertainty/gum.h"
#include "solve/dense.h"
#include "solve/residual_units.h"

namespace fivecal {
namespace {

// Above this the condition number is taken from the rows themselves: one
// formed from J^T J carries a relative error of about eps kappa^2.
constexpr double kNormalConditionBound = 1e6;

// The condition number of the unweighted Jacobian J = S Jw (S the rows'
// sigmas) without another pass over the rows: with s0 the sigma of most
// rows and R the fit's factor (R^T R = Jw^T Jw),
//   J^T J = s0^2 R^T R + sum_{i: s_i != s0} (s_i^2 - s0^2) jw_i^T jw_i,
// a few rank-one terms (TANGO: the scale bar's row). ConditionNumber reads
// J through J^T J only (column norms, eigenvalues or the singular values of
// a triangular factor), so the Cholesky factor of that sum serves for it.
// The rows themselves where many differ, where the sum is not numerically
// positive definite, or where it is too ill-conditioned for J^T J.
double UnweightedConditionNumber(const Eigen::MatrixXd& R, const Eigen::MatrixXd& Jw, const Eigen::VectorXd& sig,
                                 double rank_tolerance) {
  const Eigen::Index p = Jw.cols(), n = Jw.rows();
  auto rows = [&] { return ConditionNumber(Eigen::MatrixXd(sig.asDiagonal() * Jw), rank_tolerance); };
  if (p == 0 || n != sig.size() || R.cols() != p) return rows();
  const double s0 = sig[0];
  std::vector<Eigen::Index> other;
  for (Eigen::Index i = 0; i < n; ++i)
    if (sig[i] != s0) other.push_back(i);
  if (4 * static_cast<Eigen::Index>(other.size()) > n) return rows();
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(p, p);
  N.selfadjointView<Eigen::Lower>().rankUpdate(R.transpose(), s0 * s0);
  for (Eigen::Index i : other)
    N.selfadjointView<Eigen::Lower>().rankUpdate(Jw.row(i).transpose(), sig[i] * sig[i] - s0 * s0);
  const dense::Cholesky llt = dense::Llt(N);
  if (!llt.ok) return rows();
  const double c = ConditionNumber(llt.L.triangularView<Eigen::Lower>().transpose(), rank_tolerance);
  return c < kNormalConditionBound ? c : rows();
}

}  // namespace

IdentifyCovariance CovarianceAtSolution(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq,
                                        const IdentifyFit& fit, const IdentifyDetermination& det) {
  // The determination is this stage's input so that a covariance taken from
  // its SVD (bench/NOTES.md, S4) would change no caller; not read today.
  (void)det;
  IdentifyCovariance out;
  const std::vector<int>& est = rq.est;
  const Eigen::VectorXd& prior = rq.prior;
  const Eigen::VectorXd& place = rq.place;
  const int p = static_cast<int>(est.size());
  const Eigen::VectorXd& r = fit.r;
  const Eigen::VectorXd& sig = *fit.row_sigma;
  const Eigen::MatrixXd& Rw = fit.factor;
  const bool nep = fit.normal_equations;

  out.rms = r.size() ? std::sqrt(r.squaredNorm() / r.size()) : 0.0;
  out.max_abs = r.size() ? r.cwiseAbs().maxCoeff() : 0.0;
  if (fit.fit.robust_scale > 0)
    out.outliers = RobustOutliers(PositionScaledResiduals(ds, r, sig, *fit.row_source), fit.fit.robust_scale);

  // chi^2 of the data rows against the declared noise (rows the robust loss
  // flagged are left out: they are reported as outliers instead).
  std::vector<bool> outlier(r.size(), false);
  for (int i : out.outliers) outlier[i] = true;
  double chi2 = 0;
  int rows = 0;
  for (int i = 0; i < r.size(); ++i)
    if (!outlier[i]) chi2 += (r[i] / sig[i]) * (r[i] / sig[i]), ++rows;
  out.chi2 = chi2;
  out.chi2_rows = rows;

  const Identifiability id = AnalyzeJacobian(Rw, opt.rank_tolerance);
  out.rank = id.rank;
  // MAP: the posterior in prior units under the documented priors; it gives
  // the covariance and how far the data narrowed each prior.
  if (rq.map) out.scaled_posterior = ScaledPosterior(Rw, prior);
  const Eigen::MatrixXd& Cs = out.scaled_posterior;
  Eigen::MatrixXd hat;  // (Jw^T Jw + P)^-1 of the fit that made the residuals
  int sigma_dof = 0;
  if (rq.map) {
    // Posterior covariance (Jw^T Jw + P)^-1, P = diag(1 / prior^2), in the
    // declared noise; inflated by chi2/dof when the residuals exceed it.
    // The covariance uses the documented priors (identify_fit.cc,
    // AdaptHyperparameters); the degrees of freedom those of the fit that
    // made the residuals.
    const Eigen::MatrixXd C = prior.asDiagonal() * Cs * prior.asDiagonal();
    // Effective number of parameters: trace of the hat matrix = p - trace(Cs).
    const Eigen::VectorXd used = Gather(fit.fit_prior, est);
    const Eigen::MatrixXd Cu = rq.automatic ? ScaledPosterior(Rw, used) : Cs;
    const double p_eff = p - Cu.trace();
    const Eigen::VectorXd& cu_scale = rq.automatic ? used : prior;
    hat = cu_scale.asDiagonal() * Cu * cu_scale.asDiagonal();
    out.dof = std::max(1, rows - static_cast<int>(std::lround(p_eff)));
    const double k2 = std::max(1.0, chi2 / out.dof);
    out.covariance = k2 * C;
    // Condition number of what the data determined (the rest is the prior's).
    std::vector<int> informed_cols;
    for (int j = 0; j < p; ++j)
      if (std::sqrt(std::max(Cs(j, j), 0.0)) < kInformedThreshold) informed_cols.push_back(j);
    Eigen::MatrixXd Ri(Rw.rows(), informed_cols.size());
    for (size_t k = 0; k < informed_cols.size(); ++k) Ri.col(k) = Rw.col(informed_cols[k]);
    out.condition_number = informed_cols.empty() ? 0.0 : ConditionNumber(Ri, opt.rank_tolerance);
    sigma_dof = out.dof;
  } else {
    out.dof = std::max(0, rows - id.rank);
    if (rq.placed) {
      // The placement rows are not data: the parameters the data used are
      // the rank less the placements' share, sum_j C_jj / u_j^2.
      double prior_share = 0;
      for (int j = 0; j < p; ++j)
        if (place[j] > 0) prior_share += id.inverse_normal(j, j) / (place[j] * place[j]);
      out.dof = std::max(0, rows - static_cast<int>(std::lround(id.rank - prior_share)));
    }
    // Without redundancy the residuals (zero) say nothing about the noise:
    // the declared noise stands, an exactly determined fit is not exact.
    const double s2 = out.dof > 0 ? chi2 / out.dof : 1.0;
    out.covariance = s2 * id.inverse_normal;
    // The condition number of the column-scaled Jacobian in mm, as before the
    // weighting and as the plan design reports it.
    // Every row of one declared noise (a plan of probe touches): the mm
    // Jacobian is Jw times that noise, its column-scaled form Jw's, and the
    // condition number id's.
    // With placement rows, the condition number of the problem they make
    // well posed (the data's alone is infinite where a placement is confounded).
    const bool one_noise = rq.placed || (sig.size() > 0 && (sig.array() == sig[0]).all());
    out.condition_number =
        one_noise ? id.condition_number
                  : nep ? ConditionNumber(NormalFactor(fit.nfit.at_solution.JtJ_unweighted), opt.rank_tolerance)
                        : UnweightedConditionNumber(Rw, fit.Jw, sig, opt.rank_tolerance);
    sigma_dof = rq.placed ? out.dof : fit.num_rows - id.rank;
    hat = id.inverse_normal;
  }
  out.sigma = sigma_dof > 0 ? std::sqrt(r.squaredNorm() / sigma_dof) : 0.0;
  // On the normal-equation path Jw is the p x p factor, not rows: a unit's
  // share of the parameters is trace(hat Jw_u^T Jw_u) from its rows' sums.
  if (nep) {
    std::map<std::string, double> share;
    const std::vector<std::string>& units = fit.other_units;
    for (size_t u = 0; u < units.size(); ++u)
      share[units[u]] = hat.cwiseProduct(fit.nfit.at_solution.JtJ_units[u]).sum();
    out.residual_units = ResidualsByUnit(r, *fit.row_unit, units, share, sigma_dof);
  } else {
    out.residual_units = ResidualsByUnit(ds, r, *fit.row_source, fit.Jw, hat, sigma_dof);
  }
  if (out.residual_units.size() > 1) {
    out.rms = out.residual_units[0].rms;
    out.max_abs = out.residual_units[0].max_abs;
    out.sigma = out.residual_units[0].sigma;
  }
  out.chi2_p = out.dof > 0 ? ChiSquareSurvival(chi2, out.dof) : 1.0;
  out.std = out.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  out.correlation = Eigen::MatrixXd::Zero(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) {
      const double d = out.std[i] * out.std[j];
      out.correlation(i, j) = d > 0 ? out.covariance(i, j) / d : (i == j ? 1.0 : 0.0);
    }
  return out;
}

}  // namespace fivecal
