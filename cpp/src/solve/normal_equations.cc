#include "fivecal/solve/normal_equations.h"

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <limits>
#include <stdexcept>
#include <thread>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/registry.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/long_kernel.h"

namespace fivecal {
namespace {

// The fixed partition of the observations: enough blocks for two to eight
// threads to share evenly, few enough that the per-block p x p partial sums
// stay small (64 x 50^2 doubles = 1.3 MB). It depends on the data only, so
// the sums, and the fit, do not depend on the thread count.
constexpr int kBlocks = 64;
// Prepared rows per chunk: the chunk's Jacobian (256 x 3 rows x p) stays in
// the cache between its evaluation and its rank update.
constexpr int kChunk = 256;

using ChunkMatrix = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;

}  // namespace

NormalEquationProblem::NormalEquationProblem(const Dataset& ds, const ParameterTable& table,
                                             const Eigen::VectorXd& values, const std::vector<int>& estimated,
                                             int num_threads)
    : ds_(ds), estimated_(estimated), num_threads_(std::max(1, num_threads)) {
  if (values.size() != table.size())
    throw std::invalid_argument("identify: expected " + std::to_string(table.size()) + " values");
  // Rows prepared per chunk: the passes hold a chunk of prepared rows per
  // thread, not one per sample (analytic_residuals.h, RowStorage).
  batch_ = std::make_unique<AnalyticResiduals>(ds, table, values, estimated_, RowStorage::kPerChunk);
  const int nr = batch_->num_residuals();
  // Every observation, per-object and column-block rows (dataset.h).
  const int n = static_cast<int>(ds.size());
  const int nb = std::max(1, std::min(kBlocks, (n + kChunk - 1) / kChunk));
  // One walk over the observations (of long data, hundreds of MB): each
  // row's sigma as Problem weighs it, the row units as the residual summary
  // groups them, and the blocks' rows. A byte per row only for data holding
  // a kind of rows in another unit (a pose), not for every R-test sample.
  row_sigma_.resize(nr);
  int row = 0, b = 0;
  Block B{0, static_cast<int>((static_cast<long long>(n) * 1) / nb), 0, 0};
  const ObservationKind* last = nullptr;
  std::vector<std::string> unit_of;  // of `last`'s rows
  ds.ForEachRowNoise([&](size_t row_index, const Observation& o) {
    const int i = static_cast<int>(row_index);
    const ObservationKind* kind = &KindOf(o);
    const int rows = kind->rows();
    if (kind != last) {
      last = kind;
      unit_of.clear();
      for (int k = 0; k < rows; ++k) unit_of.push_back(kind->unit_row(k));
    }
    for (int k = 0; k < rows; ++k) {
      row_sigma_[row + k] = ObservationSigma(ds, o, k);
      if (unit_of[k] == "mm") continue;
      auto it = std::find(other_units_.begin(), other_units_.end(), unit_of[k]);
      if (it == other_units_.end()) {
        if (other_units_.size() >= 255) throw std::logic_error("normal equations: too many row units");
        it = other_units_.insert(other_units_.end(), unit_of[k]);
      }
      if (row_unit_.empty()) row_unit_.assign(nr, 0);
      row_unit_[row + k] = static_cast<unsigned char>(1 + (it - other_units_.begin()));
    }
    row += rows;
    B.rows += rows;
    // The fixed partition of the observations (kBlocks).
    while (i + 1 == B.end) {
      if (B.end > B.begin) blocks_.push_back(B);
      if (++b == nb) break;
      B = Block{B.end, static_cast<int>((static_cast<long long>(n) * (b + 1)) / nb), row, 0};
    }
  });
  // As Problem weighs them: a scale bar's length row at kScaleBarSigma.
  for (int r = row; r < nr; ++r) row_sigma_[r] = kScaleBarSigma;
  uniform_sigma_ = nr > 0 && row_sigma_.maxCoeff() == row_sigma_.minCoeff() ? row_sigma_[0] : 0.0;
  // The artefact rows (scale bars) after the observations: one block, one chunk.
  if (batch_->num_prepared() > n) blocks_.push_back({n, batch_->num_prepared(), row, nr - row});
  else if (row != nr)
    throw std::logic_error("normal equations: residual rows do not add up");
  // The column kernels, when every observation has one (mixed and small
  // data keep the prepared rows: a probe touch, a tracker reading).
  // A column block is a run of its own, which borrows its columns.
  const int n_obj = static_cast<int>(ds.observations.size());
  if (batch_->num_prepared() == n && row_unit_.empty() && n > 0) {
    size_t block = 0;
    for (int i = 0; i < n;) {
      const ObservationKind* kind;
      int j = i + 1;
      if (i < n_obj) {
        kind = &KindOf(ds.observations[i]);
        while (j < n_obj && &KindOf(ds.observations[j]) == kind) ++j;
      } else {
        kind = &KindOf(ds.blocks[block].type);
        j = i + static_cast<int>(ds.blocks[block++].size());
      }
      std::unique_ptr<LongRun> run = kind->MakeLongRun(ds, table, estimated_, i, j);
      if (!run) {
        if (!ds.blocks.empty())
          throw std::logic_error("normal equations: a column block of a kind without a column kernel");
        long_runs_.clear();
        break;
      }
      long_runs_.push_back({i, j, std::move(run)});
      i = j;
    }
  }
  // Column blocks have no prepared rows: the column kernels are their only
  // evaluation (Identify expands the blocks of data that cannot use them).
  if (!ds.blocks.empty() && long_runs_.empty())
    throw std::logic_error("normal equations: column blocks need every observation on a column kernel");
}

void NormalEquationProblem::LongBlock(const KinematicModel& model, const Eigen::VectorXd& values, const Block& B,
                                      bool jacobian, bool unweighted, double* residuals, NormalEquations* ne) const {
  const int p = num_parameters();
  const int ld = PaddedWidth(p);
  int max_rows = 1;
  for (const Run& run : long_runs_) max_rows = std::max(max_rows, run.run->rows_per_sample());
  const int cap = kChunk * max_rows;
  // The chunk's rows, row-major; the padding columns stay zero.
  std::vector<double> r(cap), J(jacobian ? static_cast<size_t>(cap) * ld : 0, 0.0);
  std::vector<double> N(jacobian ? static_cast<size_t>(p) * ld : 0, 0.0), g(p, 0.0);
  std::vector<double> Nu(jacobian && unweighted ? static_cast<size_t>(p) * ld : 0, 0.0), gu(p, 0.0);
  auto run = std::partition_point(long_runs_.begin(), long_runs_.end(), [&](const Run& x) { return x.end <= B.begin; });
  int row = B.row;
  double cost = 0;
  for (; run != long_runs_.end() && run->begin < B.end; ++run) {
    const int rps = run->run->rows_per_sample();
    for (int s = std::max(B.begin, run->begin), stop = std::min(B.end, run->end); s < stop;) {
      const int e = std::min(stop, s + kChunk);
      const int m = (e - s) * rps;
      run->run->Evaluate(model, values, s - run->begin, e - run->begin, r.data(), jacobian ? J.data() : nullptr, ld);
      if (residuals) std::copy(r.begin(), r.begin() + m, residuals + row);
      if (jacobian && unweighted) AccumulateNormal(J.data(), r.data(), m, p, ld, Nu.data(), gu.data());
      const double* sig = row_sigma_.data() + row;
      for (int i = 0; i < m; ++i) {
        const double w = 1.0 / sig[i];
        r[i] *= w;
        cost += r[i] * r[i];
        if (jacobian) {
          double* jr = J.data() + static_cast<size_t>(i) * ld;
          for (int c = 0; c < p; ++c) jr[c] *= w;
        }
      }
      if (jacobian) AccumulateNormal(J.data(), r.data(), m, p, ld, N.data(), g.data());
      row += m;
      s = e;
    }
  }
  if (row != B.row + B.rows) throw std::logic_error("normal equations: block rows do not add up");
  ne->cost = 0.5 * cost;
  if (!jacobian) return;
  ne->JtJ.resize(p, p);
  ne->Jtr = Eigen::Map<const Eigen::VectorXd>(g.data(), p);
  for (int a = 0; a < p; ++a)
    for (int b = 0; b < p; ++b) ne->JtJ(a, b) = N[static_cast<size_t>(a) * ld + b];
  if (unweighted) {
    ne->JtJ_unweighted.resize(p, p);
    for (int a = 0; a < p; ++a)
      for (int b = 0; b < p; ++b) ne->JtJ_unweighted(a, b) = Nu[static_cast<size_t>(a) * ld + b];
  }
  ne->JtJ_units.clear();
}

NormalEquationProblem::~NormalEquationProblem() = default;

const std::vector<int>& NormalEquationProblem::row_source() const { return batch_->row_source(); }

void NormalEquationProblem::Pass(const Eigen::VectorXd& values, bool jacobian, bool unweighted,
                                 double* residuals, std::vector<NormalEquations>* partial) const {
  const int p = num_parameters();
  KinematicModel model(ds_.machine(), values.data());
  if (jacobian) model.RestrictJacobian(estimated_);
  const int nb = static_cast<int>(blocks_.size());
  partial->assign(nb, NormalEquations{});
  int max_kind_rows = 1;
  for (const ObservationKind* k : ObservationKinds()) max_kind_rows = std::max(max_kind_rows, k->rows());
  std::atomic<int> next{0};
  std::exception_ptr error;
  std::atomic<bool> failed{false};
  auto work = [&]() {
    try {
      std::vector<double> r, jac;
      std::vector<double*> cols(p);
      std::vector<AnalyticRow> prepared;  // the thread's chunk of prepared rows
      for (int b; !failed && (b = next++) < nb;) {
        const Block& B = blocks_[b];
        if (!long_runs_.empty()) {
          LongBlock(model, values, B, jacobian, unweighted, residuals, &(*partial)[b]);
          continue;
        }
        const bool tail = B.begin >= static_cast<int>(ds_.size());
        const int ld = tail ? B.rows : std::min(B.rows, kChunk * max_kind_rows);
        r.resize(ld);
        if (jacobian) {
          jac.resize(static_cast<size_t>(ld) * p);
          for (int c = 0; c < p; ++c) cols[c] = jac.data() + static_cast<size_t>(c) * ld;
        }
        NormalEquations& ne = (*partial)[b];
        if (jacobian) {
          ne.JtJ = Eigen::MatrixXd::Zero(p, p);
          ne.Jtr = Eigen::VectorXd::Zero(p);
          if (unweighted) ne.JtJ_unweighted = Eigen::MatrixXd::Zero(p, p);
          ne.JtJ_units.assign(other_units_.size(), Eigen::MatrixXd::Zero(p, p));
        }
        int row = B.row;
        for (int s = B.begin; s < B.end;) {
          const int e = tail ? B.end : std::min(B.end, s + kChunk);
          if (jacobian) std::fill(jac.begin(), jac.end(), 0.0);
          const int m = batch_->EvaluateRows(model, values, s, e, r.data(), jacobian ? cols.data() : nullptr, &prepared);
          if (m > ld || row + m > num_rows()) throw std::logic_error("normal equations: chunk overflow");
          if (residuals) std::copy(r.begin(), r.begin() + m, residuals + row);
          const Eigen::Map<const Eigen::VectorXd> sig(row_sigma_.data() + row, m);
          Eigen::Map<Eigen::VectorXd> rw(r.data(), m);
          rw.array() /= sig.array();
          ne.cost += 0.5 * rw.squaredNorm();
          if (jacobian) {
            ChunkMatrix J(jac.data(), m, p, Eigen::OuterStride<>(ld));
            if (unweighted) ne.JtJ_unweighted.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
            J = sig.cwiseInverse().asDiagonal() * J;
            ne.JtJ.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
            ne.Jtr.noalias() += J.transpose() * rw;
            if (!row_unit_.empty())
              for (int i = 0; i < m; ++i)
                if (const int u = row_unit_[row + i])
                  ne.JtJ_units[u - 1].selfadjointView<Eigen::Lower>().rankUpdate(J.row(i).transpose());
          }
          row += m;
          s = e;
        }
        if (row != B.row + B.rows) throw std::logic_error("normal equations: block rows do not add up");
      }
    } catch (...) {
      if (!failed.exchange(true)) error = std::current_exception();
    }
  };
  const int T = std::min(num_threads_, nb);
  if (T <= 1) {
    work();
  } else {
    std::vector<std::thread> pool;
    for (int t = 0; t < T; ++t) pool.emplace_back(work);
    for (std::thread& t : pool) t.join();
  }
  if (error) std::rethrow_exception(error);
}

Eigen::VectorXd NormalEquationProblem::Residuals(const Eigen::VectorXd& values) const {
  // The fit ends where it last took derivatives: that pass kept its rows.
  if (cached_values_.size() == values.size() && cached_values_ == values) return cached_residuals_;
  Eigen::VectorXd r(num_rows());
  std::vector<NormalEquations> partial;
  Pass(values, false, false, r.data(), &partial);
  ++residual_passes_;
  return r;
}

double NormalEquationProblem::Cost(const Eigen::VectorXd& values) const {
  std::vector<NormalEquations> partial;
  Pass(values, false, false, nullptr, &partial);
  ++residual_passes_;
  double cost = 0;
  for (const NormalEquations& ne : partial) cost += ne.cost;  // in block order
  return cost;
}

NormalEquations NormalEquationProblem::Accumulate(const Eigen::VectorXd& values, bool unweighted) const {
  if (cached_values_.size() == values.size() && cached_values_ == values && (cached_unweighted_ || !unweighted))
    return cached_;
  const int p = num_parameters();
  std::vector<NormalEquations> partial;
  // One declared noise for every row (one instrument): J^T J in mm is the
  // weighted one times sigma^2, no second rank update needed.
  const bool scaled = unweighted && uniform_sigma_ > 0;
  cached_values_.resize(0);
  cached_residuals_.resize(num_rows());
  Pass(values, true, unweighted && !scaled, cached_residuals_.data(), &partial);
  ++jacobian_passes_;
  ++residual_passes_;
  NormalEquations out;
  out.JtJ = Eigen::MatrixXd::Zero(p, p);
  out.Jtr = Eigen::VectorXd::Zero(p);
  if (unweighted) out.JtJ_unweighted = Eigen::MatrixXd::Zero(p, p);
  out.JtJ_units.assign(other_units_.size(), Eigen::MatrixXd::Zero(p, p));
  // In block order, whatever thread summed which block.
  for (const NormalEquations& ne : partial) {
    out.JtJ += ne.JtJ;
    out.Jtr += ne.Jtr;
    out.cost += ne.cost;
    if (unweighted && !scaled) out.JtJ_unweighted += ne.JtJ_unweighted;
    for (size_t u = 0; u < other_units_.size(); ++u) out.JtJ_units[u] += ne.JtJ_units[u];
  }
  for (Eigen::MatrixXd& Nu : out.JtJ_units) Nu = Eigen::MatrixXd(Nu.selfadjointView<Eigen::Lower>());
  out.JtJ = Eigen::MatrixXd(out.JtJ.selfadjointView<Eigen::Lower>());
  if (scaled) out.JtJ_unweighted = (uniform_sigma_ * uniform_sigma_) * out.JtJ;
  else if (unweighted) out.JtJ_unweighted = Eigen::MatrixXd(out.JtJ_unweighted.selfadjointView<Eigen::Lower>());
  cached_values_ = values;
  cached_ = out;
  cached_unweighted_ = unweighted;
  return out;
}

double NormalEquationElements(const Dataset& ds) {
  if (ds.size() == 0) return kNormalEquationElements;
  // Each kind present asked once, on a dataset of no observations (an empty
  // run costs nothing to make).
  const Dataset none(ds.machine());
  const ParameterTable table(none);
  const ObservationKind* last = nullptr;
  std::vector<const ObservationKind*> asked;
  std::vector<const ObservationKind*> kinds;
  for (const Observation& o : ds.observations) kinds.push_back(&KindOf(o));
  for (const TraceBlock& b : ds.blocks) kinds.push_back(&KindOf(b.type));
  for (const ObservationKind* kind : kinds) {
    if (kind == last || std::find(asked.begin(), asked.end(), kind) != asked.end()) continue;
    last = kind;
    asked.push_back(kind);
    if (!kind->MakeLongRun(none, table, {}, 0, 0)) return kNormalEquationElements;
  }
  return kColumnarElements;
}

Eigen::MatrixXd NormalFactor(const Eigen::MatrixXd& N) {
  const int p = static_cast<int>(N.rows());
  Eigen::VectorXd d(p), inv(p);
  for (int j = 0; j < p; ++j) {
    d[j] = N(j, j) > 0 ? std::sqrt(N(j, j)) : 0.0;
    inv[j] = d[j] > 0 ? 1.0 / d[j] : 0.0;
  }
  const Eigen::MatrixXd S = inv.asDiagonal() * N * inv.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(S);
  if (eig.info() != Eigen::Success) throw std::runtime_error("normal equations: eigen-decomposition failed");
  Eigen::VectorXd lambda = eig.eigenvalues();
  const double top = std::max(lambda.size() ? lambda.maxCoeff() : 0.0, 0.0);
  // Rounding of the scaled N is about p eps of its largest eigenvalue: below
  // that an eigenvalue is noise of either sign, not information.
  const double floor = 4.0 * p * std::numeric_limits<double>::epsilon() * top;
  for (int k = 0; k < p; ++k) lambda[k] = lambda[k] > floor ? std::sqrt(lambda[k]) : 0.0;
  // R = Lambda^(1/2) V^T D: R^T R = D V Lambda V^T D = N.
  return lambda.asDiagonal() * eig.eigenvectors().transpose() * d.asDiagonal();
}

NormalEquationFit FitNormalEquations(const NormalEquationProblem& pr, const Eigen::VectorXd& start,
                                     const Eigen::VectorXd& prior_all, int max_iterations) {
  // The tolerances of Problem::SolverOptions, so that both paths stop alike.
  constexpr double kFunctionTolerance = 1e-10, kParameterTolerance = 1e-12, kGradientTolerance = 1e-16;
  constexpr double kMinRelativeDecrease = 1e-3;
  const std::vector<int>& est = pr.estimated();
  const int p = static_cast<int>(est.size());
  Eigen::VectorXd inv_prior2 = Eigen::VectorXd::Zero(p);
  if (prior_all.size())
    for (int j = 0; j < p; ++j) {
      const double s = prior_all[est[j]];
      if (!(s > 0))
        throw std::invalid_argument("problem: prior sigma of parameter " + std::to_string(est[j]) + " must be > 0");
      inv_prior2[j] = 1.0 / (s * s);  // +inf: 0, no prior row (priors.h PlacementRows)
    }
  auto theta = [&](const Eigen::VectorXd& v) {
    Eigen::VectorXd t(p);
    for (int j = 0; j < p; ++j) t[j] = v[est[j]];
    return t;
  };
  // The MAP fit's prior rows theta_j / s_j (mean 0) join the data rows.
  auto with_prior = [&](NormalEquations ne, const Eigen::VectorXd& v) {
    const Eigen::VectorXd t = theta(v);
    ne.JtJ.diagonal() += inv_prior2;
    ne.Jtr += inv_prior2.cwiseProduct(t);
    ne.cost += 0.5 * t.cwiseProduct(t).dot(inv_prior2);
    return ne;
  };

  NormalEquationFit out;
  out.values = start;
  NormalEquations data = pr.Accumulate(start, true);
  NormalEquations cur = with_prior(data, start);
  out.initial_cost = cur.cost;
  // Levenberg-Marquardt as Ceres runs it: the step solves
  // (N + D / radius) dx = -g with D = diag(N) clamped to [1e-6, 1e32], the
  // radius grows after a good step and shrinks after a bad one.
  double radius = 1e12, decrease_factor = 2.0;
  out.message = "maximum iterations reached";
  for (int it = 0; it < max_iterations; ++it) {
    if (!cur.Jtr.allFinite() || !cur.JtJ.allFinite()) {
      out.message = "residuals or Jacobian not finite";
      break;
    }
    if (cur.Jtr.lpNorm<Eigen::Infinity>() <= kGradientTolerance) {
      out.converged = true;
      out.message = "gradient tolerance reached";
      break;
    }
    Eigen::MatrixXd A = cur.JtJ;
    A.diagonal() += cur.JtJ.diagonal().cwiseMax(1e-6).cwiseMin(1e32) / radius;
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
    Eigen::VectorXd dx = ldlt.solve(-cur.Jtr);
    out.iterations = it + 1;
    if (ldlt.info() != Eigen::Success || !dx.allFinite()) {
      radius /= decrease_factor;
      decrease_factor *= 2;
      continue;
    }
    const Eigen::VectorXd t = theta(out.values);
    if (dx.norm() <= kParameterTolerance * (t.norm() + kParameterTolerance)) {
      out.converged = true;
      out.message = "parameter tolerance reached";
      break;
    }
    Eigen::VectorXd trial = out.values;
    for (int j = 0; j < p; ++j) trial[est[j]] += dx[j];
    // The candidate's cost without derivatives (about a third of a pass
    // with them): the last candidate of a converging fit is not taken, and a
    // rejected one needs no Jacobian either.
    const Eigen::VectorXd tt = theta(trial);
    const double next_cost = pr.Cost(trial) + 0.5 * tt.cwiseProduct(tt).dot(inv_prior2);
    const double model_decrease = -(cur.Jtr.dot(dx) + 0.5 * dx.dot(cur.JtJ * dx));
    const double actual = cur.cost - next_cost;
    // As Ceres: a relative cost change this small ends the fit at the
    // current point, the candidate not taken.
    if (std::isfinite(next_cost) && std::abs(actual) <= kFunctionTolerance * cur.cost) {
      out.converged = true;
      out.message = "function tolerance reached";
      break;
    }
    const double rho = model_decrease > 0 ? actual / model_decrease : -1.0;
    if (std::isfinite(next_cost) && rho > kMinRelativeDecrease) {
      out.values = trial;
      data = pr.Accumulate(trial, true);
      cur = with_prior(data, trial);
      radius = radius / std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * rho - 1.0, 3));
      radius = std::min(radius, 1e16);
      decrease_factor = 2.0;
    } else {
      radius /= decrease_factor;
      decrease_factor *= 2.0;
      if (radius < 1e-32) {
        out.message = "trust region too small";
        break;
      }
    }
  }
  out.final_cost = cur.cost;
  out.at_solution = std::move(data);
  return out;
}

}  // namespace fivecal
