#include "fivecal/solve/refit.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cstdio>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "fivecal/observations/registry.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

struct Refit::Impl {
  // The reference as Observations (its column blocks expanded): refits
  // run through Problem's functors and the dense batch.
  Impl(const Dataset& ref, const IdentifyOptions& o) : reference(ref.Expanded()), table(reference), options(o) {}
  Dataset reference;
  ParameterTable table;
  IdentifyOptions options;
  std::vector<std::string> estimated;
  std::vector<int> est;
  Eigen::VectorXd start;
  double robust_scale = 0;
  // Per table index: the MAP fit's prior sigmas, or a least-squares fit's
  // placement rows (+inf: no row; priors.h PlacementRows); empty: neither.
  Eigen::VectorXd prior;
};

Refit::Refit(const Dataset& reference, const IdentifyOptions& options, const Result& fit)
    : impl_(std::make_unique<Impl>(reference, options)) {
  reference.Validate();
  Impl& d = *impl_;
  if (fit.names != d.table.names())
    throw std::invalid_argument("refit: the reference result belongs to another dataset");
  d.estimated = fit.estimated;
  for (const std::string& n : fit.estimated) d.est.push_back(d.table.Require(n));
  d.start = fit.values;
  d.robust_scale = fit.robust_scale;
  if (fit.map_fit) {
    // Every refit is the same MAP fit as the reference (its prior rows).
    d.prior = Eigen::VectorXd::Ones(d.table.size());
    for (size_t i = 0; i < d.est.size() && i < fit.prior_std.size(); ++i) d.prior[d.est[i]] = fit.prior_std[i];
  } else {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(d.table.size());
    for (size_t i = 0; i < d.est.size() && i < fit.placement.size(); ++i) u[d.est[i]] = fit.placement[i];
    d.prior = PlacementRows(u, d.est);
  }
  if (!options.robust.empty() && options.robust != "none" && !(d.robust_scale > 0))
    throw std::invalid_argument("refit: robust loss without a robust scale in the reference result");
}

Refit::~Refit() = default;

const std::vector<std::string>& Refit::estimated() const { return impl_->estimated; }

namespace {

// The one-sigma uncertainties as Identify reports them, from the data rows
// at the solution: r (mm), Jw = diag(w) J, w the rows' weights.
void TrialStd(const Eigen::VectorXd& r, const Eigen::MatrixXd& Jw, const Eigen::VectorXd& w,
              const std::vector<int>& est, const Eigen::VectorXd& prior_all, const IdentifyOptions& options,
              RefitResult* out) {
  const int rows = static_cast<int>(r.size());
  const int p = static_cast<int>(est.size());
  // A least-squares fit's placement rows hold +inf where there is no row.
  bool map = prior_all.size() > 0;
  Eigen::VectorXd place = Eigen::VectorXd::Zero(p);
  for (int i = 0; map && i < p; ++i) map = std::isfinite(prior_all[est[i]]);
  if (prior_all.size() && !map)
    for (int i = 0; i < p; ++i) place[i] = std::isfinite(prior_all[est[i]]) ? prior_all[est[i]] : 0.0;
  if (map) {
    // Posterior covariance as Identify's MAP branch.
    Eigen::VectorXd prior(p);
    for (int i = 0; i < p; ++i) prior[i] = prior_all[est[i]];
    const Eigen::MatrixXd Js = Jw * prior.asDiagonal();
    Eigen::MatrixXd N = Js.transpose() * Js;
    N.diagonal().array() += 1.0;
    const Eigen::MatrixXd Cs = N.ldlt().solve(Eigen::MatrixXd::Identity(p, p));
    const int dof = std::max(1, rows - static_cast<int>(std::lround(p - Cs.trace())));
    const double chi2 = r.cwiseProduct(w).squaredNorm();
    const double k2 = std::max(1.0, chi2 / dof);
    out->sigma = std::sqrt(r.squaredNorm() / dof);
    out->std = (k2 * Cs.diagonal()).cwiseMax(0.0).cwiseSqrt().cwiseProduct(prior);
  } else {
    const Identifiability id = AnalyzeJacobian(WithPlacementRows(Jw, place), options.rank_tolerance);
    // As Identify: the placement rows are not data.
    double prior_share = 0;
    for (int j = 0; j < p; ++j)
      if (place[j] > 0) prior_share += id.inverse_normal(j, j) / (place[j] * place[j]);
    const int dof = rows - static_cast<int>(std::lround(id.rank - prior_share));
    out->sigma = dof > 0 ? std::sqrt(r.squaredNorm() / dof) : 0.0;
    const double s2 = dof > 0 ? r.cwiseProduct(w).squaredNorm() / dof : 0.0;
    out->std = (s2 * id.inverse_normal.diagonal()).cwiseMax(0.0).cwiseSqrt();
  }
}

// Solves a prepared refit problem from its current values with Ceres; the
// summary and, with_std, the standard deviations as Identify reports them.
RefitResult SolveRefit(Problem& problem, const std::vector<int>& est,
                       const Eigen::VectorXd& prior_all, const IdentifyOptions& options, bool with_std) {
  const ceres::Solver::Options so = Problem::SolverOptions(options.max_iterations, 1);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem.ceres_problem(), &summary);
  RefitResult out;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.iterations = static_cast<int>(summary.iterations.size()) - 1;
  out.final_cost = summary.final_cost;
  out.values.resize(est.size());
  for (size_t i = 0; i < est.size(); ++i) out.values[i] = problem.values()[est[i]];
  if (with_std) {
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    problem.Evaluate(&r, &J);
    const Eigen::VectorXd w = problem.row_sigma().cwiseInverse();
    TrialStd(r, w.asDiagonal() * J, w, est, prior_all, options, &out);
  }
  return out;
}

// The refit of one analytic batch without Ceres: the same trust-region
// (Levenberg-Marquardt) iteration as Ceres's TrustRegionMinimizer with
// Problem::SolverOptions and a dense normal-equations step (Jacobi scaling
// fixed at the first Jacobian, LM diagonal clamped to [1e-6, 1e32] over the
// radius, step quality, radius updates, the parameter and function
// tolerances checked on each candidate before it is accepted), so it stops
// where Ceres stops and returns the same point, to rounding. On these small
// problems what Ceres adds per solve (program and evaluator setup, option
// checks, the summary, a Jacobian copy, a residual-only evaluation before
// each accepted step's Jacobian) cost about as much as the model itself.
// Solve returns false, leaving the fit to Ceres, on anything this loop does
// not reproduce: an invalid step (Cholesky failure, no model decrease), a
// non-finite residual or Jacobian, the iteration limit.
class DenseRefit {
 public:
  // On a batch of its own (a Session's, refreshed per trial).
  DenseRefit(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& start,
             const std::vector<int>& est, const Eigen::VectorXd& row_sigma, const Eigen::VectorXd& prior_all,
             int max_iterations)
      : DenseRefit(std::make_unique<AnalyticResiduals>(ds, table, start, est), nullptr, start, est, row_sigma,
                   prior_all, max_iterations) {}
  // On a Problem's batch (SolveWithoutCeres), which must outlive it.
  // keep: hand out the residuals and weighted Jacobian at the solution;
  // first: an evaluation at `start` already made.
  DenseRefit(AnalyticResiduals* batch, const Eigen::VectorXd& start, const std::vector<int>& est,
             const Eigen::VectorXd& row_sigma, const Eigen::VectorXd& prior_all, int max_iterations, bool keep,
             const EvaluatedAt* first)
      : DenseRefit(nullptr, batch, start, est, row_sigma, prior_all, max_iterations, keep, first) {}

 private:
  DenseRefit(std::unique_ptr<AnalyticResiduals> own, AnalyticResiduals* batch, const Eigen::VectorXd& start,
             const std::vector<int>& est, const Eigen::VectorXd& row_sigma, const Eigen::VectorXd& prior_all,
             int max_iterations, bool keep = false, const EvaluatedAt* first = nullptr)
      : own_(std::move(own)), batch_(own_ ? *own_ : *batch), start_(est.size()), w_(row_sigma.cwiseInverse()),
        n_(static_cast<int>(row_sigma.size())), p_(static_cast<int>(est.size())), max_iterations_(max_iterations) {
    keep_ = keep;
    if (batch_.num_residuals() != n_) throw std::logic_error("refit: batch rows differ from the problem's");
    for (int b = 0; b < p_; ++b) start_[b] = start[est[b]];
    if (prior_all.size()) {
      // The prior rows of Problem::AddPriors (mean 0): (theta - 0) / sigma.
      prior_inv_.resize(p_);
      for (int b = 0; b < p_; ++b) prior_inv_[b] = 1.0 / prior_all[est[b]];
    }
    const int m = n_ + static_cast<int>(prior_inv_.size());
    J_.setZero(m, p_);
    Jc_.setZero(m, p_);
    r_.resize(m);
    rc_.resize(m);
    cols_.resize(p_);
    ptrs_.resize(p_);
    // The columns of the parameters that enter most rows first, the others
    // (most setup parameters) after them: NormalMatrix then sums a few rows
    // for these. From the Jacobian at the start; only speed depends on it.
    pos_.resize(p_);
    for (int b = 0; b < p_; ++b) pos_[b] = b;
    double cost = 0;
    std::vector<int> dense, sparse;
    const bool reuse = first && first->at.size() == p_ && first->at == start_ &&
                       first->residuals_mm.size() == n_ && first->weighted_jacobian.rows() == n_ &&
                       first->weighted_jacobian.cols() == p_;
    const bool ok = reuse ? FromEvaluated(*first, &cost) : Evaluate(start_, &r_, &J_, &cost, false);
    for (int b = 0; b < p_; ++b) {
      const int nnz = ok ? static_cast<int>((J_.col(b).array().abs() > 0.0).count()) : m;
      (4 * nnz >= m ? dense : sparse).push_back(b);
    }
    nd_ = static_cast<int>(dense.size());
    dense.insert(dense.end(), sparse.begin(), sparse.end());
    for (int c = 0; c < p_; ++c) pos_[dense[c]] = c;
    // That evaluation is the first of Solve, its columns in their new places
    // (each column is computed alone: the same numbers as evaluated there).
    if (ok) {
      const Eigen::MatrixXd first = J_;
      for (int b = 0; b < p_; ++b) J_.col(pos_[b]) = first.col(b);
      start_cost_ = cost;
      at_start_ = true;
    } else {
      J_.setZero();
    }
  }

 public:

  void Refresh(const ParameterTable& table, const Eigen::VectorXd& values) {
    at_start_ = false;
    batch_.Refresh(table, values);
  }
  void RefreshAxes(const ParameterTable& table) {
    at_start_ = false;
    batch_.RefreshAxes(table);
  }
  const std::vector<AnalyticRow>& rows() const { return batch_.rows(); }

  bool Solve(RefitResult* out) {
    constexpr double kFunctionTolerance = 1e-10, kParameterTolerance = 1e-12, kGradientTolerance = 1e-16;
    constexpr double kMinRelativeDecrease = 1e-3, kMinDiagonal = 1e-6, kMaxDiagonal = 1e32;
    constexpr double kMaxRadius = 1e16, kMinRadius = 1e-32;
    Eigen::VectorXd x = start_;
    double x_cost = start_cost_;
    if (!at_start_ && !Evaluate(x, &r_, &J_, &x_cost, false)) return false;
    at_start_ = false;
    const double initial_cost = x_cost;
    char message[160];
    scale_ = (J_.colwise().squaredNorm().array().sqrt() + 1.0).inverse().matrix().transpose();
    J_.array().rowwise() *= scale_.transpose().array();
    double radius = 1e12, decrease_factor = 2;
    double current_cost = x_cost, min_cost = x_cost;  // the step evaluator's, the best accepted
    Eigen::VectorXd best = x;
    bool successful = true;
    int iteration = 0, pushed = 1;
    bool converged = false;
    Eigen::VectorXd diag, lm, step, mr, cand;
    Eigen::MatrixXd lhs(p_, p_);
    bool reuse_diagonal = false;
    Eigen::VectorXd rhs = J_.transpose() * r_;
    for (;;) {
      // Ceres's checks at the end of an iteration (FinalizeIteration...). Its
      // gradient is J^T r before the scaling: rhs over the scale here.
      if (iteration >= max_iterations_) return false;
      double gmax = 0;
      for (int b = 0; b < p_; ++b) {
        const double g = rhs[pos_[b]] / scale_[pos_[b]];
        gmax = std::max(gmax, std::abs(x[b] - (x[b] - g)));
      }
      if (successful && gmax <= kGradientTolerance) {
        std::snprintf(message, sizeof message, "Gradient tolerance reached. Gradient max norm: %e <= %e", gmax,
                      kGradientTolerance);
        converged = true;
        break;
      }
      if (radius <= kMinRadius) {
        std::snprintf(message, sizeof message, "Minimum trust region radius reached. Trust region radius: %e <= %e",
                      radius, kMinRadius);
        converged = true;
        break;
      }
      ++iteration;
      if (!reuse_diagonal) diag = J_.colwise().squaredNorm().transpose().cwiseMax(kMinDiagonal).cwiseMin(kMaxDiagonal);
      reuse_diagonal = true;
      lm = (diag / radius).cwiseSqrt();
      NormalMatrix(&lhs);
      lhs.diagonal() += lm.cwiseAbs2();
      Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>, Eigen::Lower> llt(lhs);
      if (llt.info() != Eigen::Success) return false;
      step = -llt.solve(rhs);
      if (!step.allFinite()) return false;
      mr = J_ * step;
      const double model_cost_change = -mr.dot(r_ + mr / 2.0);
      if (!(model_cost_change > 0.0)) return false;
      cand = x;
      for (int b = 0; b < p_; ++b) cand[b] += step[pos_[b]] * scale_[pos_[b]];
      double cand_cost = 0;
      // Ceres costs the candidate, then evaluates the Jacobian again at it
      // once accepted; here both come from one evaluation, except for a step
      // whose model decrease is within the function tolerance: that one
      // nearly always ends the fit, so its Jacobian would be of no use.
      const bool last = model_cost_change <= 10 * kFunctionTolerance * x_cost;
      if (!Evaluate(cand, &rc_, last ? nullptr : &Jc_, &cand_cost, true, 1)) return false;
      const double step_norm = (x - cand).norm();
      if (step_norm <= kParameterTolerance * (x.norm() + kParameterTolerance)) {
        std::snprintf(message, sizeof message, "Parameter tolerance reached. Relative step_norm: %e <= %e.",
                      step_norm / (x.norm() + kParameterTolerance), kParameterTolerance);
        converged = true;
        break;
      }
      if (std::abs(x_cost - cand_cost) <= kFunctionTolerance * x_cost) {
        std::snprintf(message, sizeof message, "Function tolerance reached. |cost_change|/cost: %e <= %e",
                      std::abs(x_cost - cand_cost) / x_cost, kFunctionTolerance);
        converged = true;
        break;
      }
      const double quality = (current_cost - cand_cost) / model_cost_change;
      if (quality > kMinRelativeDecrease) {
        x = cand;
        if (last) {
          if (!Evaluate(x, &r_, &J_, &x_cost, true)) return false;
        } else {
          J_.swap(Jc_);
          r_.swap(rc_);
          std::swap(snap_[0], snap_[1]);
          x_cost = cand_cost;
        }
        rhs.noalias() = J_.transpose() * r_;
        successful = true;
        radius = std::min(kMaxRadius, radius / std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * quality - 1.0, 3)));
        decrease_factor = 2;
        reuse_diagonal = false;
        current_cost = cand_cost;
        if (x_cost < min_cost) {
          min_cost = x_cost;
          best = x;
        }
      } else {
        successful = false;
        radius /= decrease_factor;
        decrease_factor *= 2;
      }
      ++pushed;
    }
    out->ceres = false;
    out->converged = converged;
    out->iterations = pushed - 1;
    out->final_cost = min_cost;
    out->values = best;
    out->initial_cost = initial_cost;
    out->message = message;
    if (keep_ && snap_[0].at.size() == p_ && snap_[0].at == best) {
      out->residuals_mm.swap(snap_[0].r_mm);
      out->weighted_jacobian.swap(snap_[0].Jw);
    }
    return true;
  }

  // Keep the residuals and weighted Jacobian of the solution (RefitResult).
  void set_keep_jacobian(bool on) { keep_ = on; }

  // Residuals (mm) and Jacobian (unweighted) at `values` (Result::estimated order).
  void EvaluateMm(const Eigen::VectorXd& values, Eigen::VectorXd* r, Eigen::MatrixXd* J) {
    r->resize(n_);
    J->resize(n_, p_);
    for (int b = 0; b < p_; ++b) {
      ptrs_[b] = &values[b];
      cols_[b] = J->col(b).data();
    }
    if (!batch_.Evaluate(ptrs_.data(), r->data(), cols_.data()))
      throw std::runtime_error("refit: residual evaluation failed");
  }

  const Eigen::VectorXd& weights() const { return w_; }

 private:
  // Residuals (and, J not null, Jacobian) of the weighted data rows and the
  // prior rows at x; cost = half their squared norm, summed block by block as
  // Ceres sums it. `scaled`: the Jacobian's columns times scale_ (Ceres's
  // Jacobi scaling, applied after the weights as there). A non-finite
  // Jacobian shows as a non-finite step.
  bool Evaluate(const Eigen::VectorXd& x, Eigen::VectorXd* r, Eigen::MatrixXd* J, double* cost, bool scaled,
                int slot = 0) {
    for (int b = 0; b < p_; ++b) {
      ptrs_[b] = &x[b];
      if (J) cols_[b] = J->col(pos_[b]).data();
    }
    if (!batch_.Evaluate(ptrs_.data(), r->data(), J ? cols_.data() : nullptr)) return false;
    if (J && keep_) {
      // The residuals in mm and the weighted, unscaled Jacobian at x, as
      // WeightedJacobian computes them (the same products), for the caller
      // that would evaluate them again at the solution.
      Snapshot& sn = snap_[slot];
      sn.at = x;
      sn.r_mm = r->head(n_);
      sn.Jw.resize(n_, p_);
      for (int b = 0; b < p_; ++b) sn.Jw.col(b) = J->col(pos_[b]).head(n_).cwiseProduct(w_);
    }
    r->head(n_).array() *= w_.array();
    double c = 0.5 * r->head(n_).squaredNorm();
    const int np = static_cast<int>(prior_inv_.size());
    for (int b = 0; b < np; ++b) {
      (*r)[n_ + b] = x[b] * prior_inv_[b];
      c += 0.5 * (*r)[n_ + b] * (*r)[n_ + b];
    }
    *cost = c;
    if (!std::isfinite(c)) return false;
    if (J) {
      for (int b = 0; b < np; ++b) (*J)(n_ + b, pos_[b]) = prior_inv_[b];
      for (int k = 0; k < p_; ++k) {
        auto col = J->col(k).head(n_).array();
        if (scaled) col = (col * w_.array()) * scale_[k];
        else col *= w_.array();
      }
      if (scaled)
        for (int b = 0; b < np; ++b) (*J)(n_ + b, pos_[b]) *= scale_[pos_[b]];
    }
    return true;
  }

  // Evaluate(start_, &r_, &J_, cost, false) from an evaluation already made
  // there (pos_ still the identity): the same products, in the same order.
  bool FromEvaluated(const EvaluatedAt& e, double* cost) {
    r_.head(n_) = e.residuals_mm;
    r_.head(n_).array() *= w_.array();
    double c = 0.5 * r_.head(n_).squaredNorm();
    const int np = static_cast<int>(prior_inv_.size());
    for (int b = 0; b < np; ++b) {
      r_[n_ + b] = start_[b] * prior_inv_[b];
      c += 0.5 * r_[n_ + b] * r_[n_ + b];
    }
    *cost = c;
    if (!std::isfinite(c)) return false;
    J_.topRows(n_) = e.weighted_jacobian;
    for (int b = 0; b < np; ++b) J_(n_ + b, b) = prior_inv_[b];
    if (keep_) {
      snap_[0].at = start_;
      snap_[0].r_mm = e.residuals_mm;
      snap_[0].Jw = e.weighted_jacobian;
    }
    return true;
  }

  // J_^T J_ (lower triangle). Most setup parameters enter a few rows (a
  // facet's offset its facet's touches): the columns from nd_ on are summed
  // over their nonzero rows only, the first nd_ by one rank update.
  void NormalMatrix(Eigen::MatrixXd* lhs) {
    const int m = static_cast<int>(J_.rows());
    lhs->setZero();
    if (nd_) lhs->topLeftCorner(nd_, nd_).selfadjointView<Eigen::Lower>().rankUpdate(J_.leftCols(nd_).transpose());
    rows_.resize(m);
    a_.resize(m);
    for (int i = nd_; i < p_; ++i) {
      const double* c = J_.col(i).data();
      int k = 0;
      for (int r = 0; r < m; ++r) {  // branch-free: most entries are zero
        rows_[k] = r;
        k += std::abs(c[r]) > 0.0;
      }
      for (int e = 0; e < k; ++e) a_[e] = c[rows_[e]];
      for (int j = 0; j <= i; ++j) {
        const double* cj = J_.col(j).data();
        double sum = 0;
        for (int e = 0; e < k; ++e) sum += a_[e] * cj[rows_[e]];
        (*lhs)(i, j) = sum;
      }
    }
  }

  std::unique_ptr<AnalyticResiduals> own_;
  AnalyticResiduals& batch_;
  Eigen::VectorXd start_, w_, prior_inv_, scale_;
  double start_cost_ = 0;
  bool at_start_ = false;  // r_, J_ (unscaled) and start_cost_ are those at start_
  int n_, p_, max_iterations_;
  Eigen::MatrixXd J_, Jc_;  // at x, at the candidate (weighted; J_ scaled once evaluated)
  Eigen::VectorXd r_, rc_;
  std::vector<const double*> ptrs_;
  std::vector<double*> cols_;
  std::vector<int> pos_;  // column of each estimated parameter in J_
  int nd_ = 0;            // the columns before it enter most rows
  std::vector<int> rows_;  // NormalMatrix's work space
  std::vector<double> a_;
  struct Snapshot {
    Eigen::VectorXd at, r_mm;
    Eigen::MatrixXd Jw;
  };
  bool keep_ = false;
  Snapshot snap_[2];  // at x (with J_), at the candidate (with Jc_)
};

}  // namespace

bool SolveWithoutCeres(Problem& problem, const Eigen::VectorXd& prior_all, int max_iterations, RefitResult* out,
                       bool keep_jacobian, const EvaluatedAt* first) {
  AnalyticResiduals* batch = problem.analytic_batch();
  if (!batch || problem.estimated().empty()) return false;
  DenseRefit fit(batch, problem.values(), problem.estimated(), problem.row_sigma(), prior_all, max_iterations,
                 keep_jacobian, first);
  RefitResult r;
  if (!fit.Solve(&r)) return false;
  problem.SetEstimated(r.values);
  *out = std::move(r);
  return true;
}

std::unique_ptr<Problem> Refit::MakeProblem(const Dataset& ds) const {
  const Impl& d = *impl_;
  const bool robust = !d.options.robust.empty() && d.options.robust != "none";
  auto problem = std::make_unique<Problem>(ds, d.table, d.start, d.est, robust ? d.options.robust : "",
                                           robust ? d.robust_scale : 0.0);
  if (d.prior.size()) problem->AddPriors(d.prior, Eigen::VectorXd::Zero(d.table.size()));
  return problem;
}

RefitResult Refit::Fit(const Dataset& given_ds, bool with_std) const {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const Impl& d = *impl_;
  const auto& a = d.reference.observations;
  const auto& b = ds.observations;
  if (a.size() != b.size())
    throw std::invalid_argument("refit: " + std::to_string(b.size()) + " observations, the reference has " +
                                std::to_string(a.size()));
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].type != b[i].type || PayloadTarget(a[i]) != PayloadTarget(b[i]) || a[i].setup != b[i].setup ||
        a[i].axes.size() != b[i].axes.size())
      throw std::invalid_argument("refit: observations[" + std::to_string(i) +
                                  "] differs from the reference (type, target or setup)");
  const std::unique_ptr<Problem> problem = MakeProblem(ds);
  return SolveRefit(*problem, d.est, d.prior, d.options, with_std);
}

// ---- Session -------------------------------------------------------------------

struct Refit::Session::State {
  explicit State(const Refit& r) : refit(r), ds(r.impl_->reference) {}
  const Refit& refit;
  Dataset ds;
  std::unique_ptr<Problem> problem;  // prepared on ds; rebuilt per fit when it cannot refresh
  // The fit without Ceres when the problem is one analytic batch without a
  // robust loss; null otherwise.
  std::unique_ptr<DenseRefit> dense;
  bool prepared = false;
  // Preparing the rows again (Refresh) costs as much as an evaluation; a
  // trial changes the touches' axis values only. After kAxesChecks trials
  // whose full refresh changed nothing in the rows but their axis values,
  // the session re-reads the axis values alone; one that changed more keeps
  // the full refresh for good.
  static constexpr int kAxesChecks = 2;
  bool axes_only = false;  // set_axes_only
  int axes_checks = 0;    // < 0: full refresh for good
  std::vector<AnalyticRow> before;
};

namespace {

// Everything a row holds but its axis values (a field added to AnalyticRow
// belongs here, or the check would miss a trial that changes it).
bool SameButAxes(const AnalyticRow& a, const AnalyticRow& b) {
  return a.kind == b.kind && a.variant == b.variant && a.dir == b.dir && a.a == b.a && a.n == b.n &&
         a.tool_ball == b.tool_ball && a.measured == b.measured && a.constant == b.constant &&
         std::equal(a.idx, a.idx + 8, b.idx) && a.probe0 == b.probe0 && a.probe_rotation == b.probe_rotation;
}

}  // namespace

Refit::Session::Session(const Refit& refit) : s_(std::make_unique<State>(refit)) {}
Refit::Session::~Session() = default;

Dataset& Refit::Session::dataset() { return s_->ds; }

void Refit::Session::set_axes_only(bool on) {
  s_->axes_only = on;
  if (!on) s_->axes_checks = 0;
}

RefitResult Refit::Session::Fit(bool with_std) {
  State& s = *s_;
  const Impl& d = *s.refit.impl_;
  if (!s.prepared) {
    s.prepared = true;
    s.problem = s.refit.MakeProblem(s.ds);
    // Problem's own rule for one analytic batch (problem.cc), without a robust loss.
    bool analytic = !d.est.empty() && (d.options.robust.empty() || d.options.robust == "none");
    for (const Observation& o : s.ds.observations) analytic = analytic && KindOf(o).analytic();
    if (analytic)
      s.dense = std::make_unique<DenseRefit>(s.ds, d.table, d.start, d.est, s.problem->row_sigma(), d.prior,
                                             d.options.max_iterations);
  } else if (s.dense && s.axes_only && s.axes_checks >= State::kAxesChecks) {
    s.dense->RefreshAxes(d.table);
  } else if (s.dense) {
    const size_t n = s.ds.observations.size();
    const bool check = s.axes_only && s.axes_checks >= 0;
    if (check) s.before.assign(s.dense->rows().begin(), s.dense->rows().begin() + n);
    s.dense->Refresh(d.table, d.start);
    if (check) {
      bool same = true;
      for (size_t i = 0; i < n && same; ++i) same = SameButAxes(s.before[i], s.dense->rows()[i]);
      s.axes_checks = same ? s.axes_checks + 1 : -1;
      if (!same || s.axes_checks >= State::kAxesChecks) s.before = {};
    }
  }
  if (s.dense) {
    RefitResult out;
    if (s.dense->Solve(&out)) {
      if (with_std) {
        Eigen::VectorXd r;
        Eigen::MatrixXd J;
        s.dense->EvaluateMm(out.values, &r, &J);
        const Eigen::VectorXd& w = s.dense->weights();
        TrialStd(r, w.asDiagonal() * J, w, d.est, d.prior, d.options, &out);
      }
      return out;
    }
  }
  if (!s.problem->Refresh(d.start)) s.problem = s.refit.MakeProblem(s.ds);
  return SolveRefit(*s.problem, d.est, d.prior, d.options, with_std);
}

}  // namespace fivecal
