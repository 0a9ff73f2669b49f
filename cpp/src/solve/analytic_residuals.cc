#include "fivecal/solve/analytic_residuals.h"

#include <algorithm>
#include <atomic>

#include "fivecal/model/kinematics.h"
#include "fivecal/observations/registry.h"
#include "fivecal/observations/residuals.h"

#include <limits>
#include <stdexcept>
#include <string>

namespace fivecal {

// Records what a kind's AddResidual adds: the cost function and the table
// entries of its parameter blocks. A block's "storage" is a slot of a
// private array indexed like the table, so the pointer names the entry; the
// values are supplied at each evaluation.
class AnalyticResiduals::Recorder : public ResidualBuilder {
 public:
  Recorder(const Dataset& ds, const ParameterTable& table, std::shared_ptr<const ResidualContext> ctx,
           const std::vector<int>& estimated, const std::vector<int>& block_of, std::vector<Piece>* out)
      : ResidualBuilder(ds, table, std::move(ctx)), block_of_(block_of), slots_(table.size()), out_(out) {
    // The estimated machine parameters in the order ResidualContext numbers
    // them (as Problem's builder does).
    for (int i : estimated)
      if (i < ds.machine().num_parameters()) machine_ptrs_.push_back(slots_.data() + i);
  }

 protected:
  double* Block(int index) override { return block_of_[index] >= 0 ? slots_.data() + index : nullptr; }
  void AddCost(ceres::CostFunction* cost, int num_residuals, const std::vector<double*>& ptrs, int) override {
    Piece p;
    p.cost.reset(cost);
    for (double* q : ptrs) p.index.push_back(static_cast<int>(q - slots_.data()));
    p.rows = num_residuals;
    out_->push_back(std::move(p));
  }
  void AddConstant(int num_residuals, std::function<void(double*)> eval, int) override {
    Piece p;
    p.constant = std::move(eval);
    p.rows = num_residuals;
    out_->push_back(std::move(p));
  }

 private:
  const std::vector<int>& block_of_;
  std::vector<double> slots_;
  std::vector<Piece>* out_;
};

namespace {

bool AnyTemplated(const Dataset& ds) {
  for (const Observation& o : ds.observations)
    if (!KindOf(o).analytic()) return true;
  return false;
}

std::atomic<int64_t> g_alive{0}, g_peak{0};

void CountAlive(int64_t k) {
  const int64_t a = g_alive.fetch_add(k) + k;
  int64_t p = g_peak.load();
  while (a > p && !g_peak.compare_exchange_weak(p, a)) {
  }
}

// Rows prepared for one chunk's evaluation, counted while they are in use.
struct ChunkCount {
  explicit ChunkCount(int64_t k) : k(k) { CountAlive(k); }
  ~ChunkCount() { CountAlive(-k); }
  int64_t k;
};

}  // namespace

int64_t PreparedRowsAlive() { return g_alive.load(); }
int64_t PreparedRowsPeak() { return g_peak.load(); }
void ResetPreparedRowsPeak() { g_peak.store(g_alive.load()); }

AnalyticResiduals::~AnalyticResiduals() { CountAlive(-counted_); }

void AnalyticResiduals::CountHeld(int64_t rows) {
  CountAlive(rows - counted_);
  counted_ = rows;
}

AnalyticEval::AnalyticEval(const Machine& m, const Eigen::VectorXd& values, const KinematicModel& model,
                           const std::vector<int>& estimated, const std::vector<int>& block_of,
                           double* res, double** jac)
    : v(values), residuals(res), jacobians(jac), model_(model), block_of_(block_of),
      tip0_(m.tip_index()), J_(3, m.num_parameters()) {
  const int np = m.num_parameters();
  for (size_t b = 0; b < estimated.size(); ++b)
    if (estimated[b] < np) machine_blocks_.emplace_back(static_cast<int>(b), estimated[b]);
}

AnalyticResiduals::AnalyticResiduals(const Dataset& ds, const ParameterTable& table,
                                     const Eigen::VectorXd& values, const std::vector<int>& estimated,
                                     RowStorage storage)
    : ds_(ds), table_(&table), storage_(storage), values_(values), estimated_(estimated) {
  block_of_.assign(table.size(), -1);
  for (size_t b = 0; b < estimated_.size(); ++b) {
    block_of_[estimated_[b]] = static_cast<int>(b);
    mutable_parameter_block_sizes()->push_back(1);
  }
  const bool all = storage_ == RowStorage::kAll;
  const int n = static_cast<int>(ds.observations.size());
  if (all) rows_.reserve(n);
  row_source_.reserve(n);  // a row or more per observation; not a walk over the data to count them
  std::unique_ptr<Recorder> recorder;
  if (AnyTemplated(ds)) recorder = NewRecorder(table);
  for (int i = 0; i < n; ++i) {
    const ObservationKind& kind = KindOf(ds.observations[i]);
    const bool templated = !kind.analytic();
    const bool held = all || templated;
    if (runs_.empty() || runs_.back().kind != &kind)
      runs_.push_back({&kind, i, i, templated, held ? static_cast<int>(rows_.size()) : -1});
    runs_.back().end = i + 1;
    if (held) {
      rows_.emplace_back();
      if (templated) RecordRow(*recorder, i, &rows_.back());
      else PrepareRow(table, kind, i, nullptr, &rows_.back());
    }
    for (int k = 0; k < kind.rows(); ++k) row_source_.push_back(i);
  }
  // Column-block rows (dataset.h TraceBlock) are never prepared here: their
  // kind's column kernel evaluates them (NormalEquationProblem). Only the
  // bookkeeping of their rows.
  int n_all = n;
  for (const TraceBlock& b : ds.blocks) {
    const ObservationKind& kind = KindOf(b.type);
    if (all || !kind.analytic())
      throw std::logic_error("analytic residuals: column blocks need the column kernel (Dataset::Expanded first)");
    const int nb = static_cast<int>(b.size());
    if (runs_.empty() || runs_.back().kind != &kind) runs_.push_back({&kind, n_all, n_all, false, -1});
    runs_.back().end = n_all + nb;
    for (int r = 0; r < nb; ++r)
      for (int k = 0; k < kind.rows(); ++k) row_source_.push_back(n_all + r);
    n_all += nb;
  }
  held_observations_ = static_cast<int>(rows_.size());
  for (const ObservationKind* kind : ObservationKinds())
    kind->AddArtefactAnalyticRows(ds, table, &rows_, &row_source_);
  // The artefact rows: runs of their own after the observations'.
  for (int j = held_observations_; j < static_cast<int>(rows_.size()); ++j) {
    const AnalyticRow& r = rows_[j];
    const int i = n_all + (j - held_observations_);
    if (j == held_observations_ || runs_.back().kind != r.kind || rows_[runs_.back().held].variant != r.variant)
      runs_.push_back({r.kind, i, i, r.piece_begin >= 0, j});
    runs_.back().end = i + 1;
  }
  num_prepared_ = n_all + static_cast<int>(rows_.size()) - held_observations_;
  set_num_residuals(static_cast<int>(row_source_.size()));
  CountHeld(static_cast<int64_t>(rows_.size()));
}

void AnalyticResiduals::PrepareRow(const ParameterTable& table, const ObservationKind& kind, int i,
                                   const AnalyticRow* prev, AnalyticRow* r) const {
  const Machine& m = ds_.machine();
  const Observation& o = ds_.observations[i];
  // A fresh row keeping its buffers (a refresh, and the per-chunk rows of
  // every pass, allocate nothing here): copied from a default row, not
  // built per row, and a vector assigned an empty one keeps its storage.
  static const AnalyticRow kFresh;
  *r = kFresh;
  r->kind = &kind;
  r->q.resize(m.num_axes());
  AxisValuesToInternal(m, o.axes.data(), r->q.data());
  r->dir.assign(o.direction.data(), o.direction.data() + o.direction.size());
  if (prev) kind.PrepareAnalyticAfter(ds_, table, ds_.observations[i - 1], *prev, o, r);
  else kind.PrepareAnalytic(ds_, table, o, r);
}

// The templated pieces are recorded afresh (at the current fixed values).
std::unique_ptr<AnalyticResiduals::Recorder> AnalyticResiduals::NewRecorder(const ParameterTable& table) {
  pieces_.clear();
  return std::make_unique<Recorder>(ds_, table, ResidualContext::Make(ds_.machine(), values_, estimated_),
                                    estimated_, block_of_, &pieces_);
}

void AnalyticResiduals::RecordRow(Recorder& recorder, int i, AnalyticRow* r) const {
  const Observation& o = ds_.observations[i];
  const ObservationKind& kind = KindOf(o);
  *r = AnalyticRow();
  r->kind = &kind;
  r->piece_begin = static_cast<int>(pieces_.size());
  recorder.Start(i, true);
  kind.AddResidual(recorder, o);
  r->piece_end = static_cast<int>(pieces_.size());
  int rows = 0;
  for (int k = r->piece_begin; k < r->piece_end; ++k) rows += pieces_[k].rows;
  if (rows != kind.rows())
    throw std::logic_error(std::string(kind.name()) + ": templated residual rows differ from the kind's rows()");
}

void AnalyticResiduals::EvaluateTemplated(AnalyticEval& e, const AnalyticRow* rows, int count) const {
  // Per call: the parameter pointers go into the caller's values, the
  // Jacobian into a buffer of this call; the cost functions are const.
  std::vector<const double*> params;
  std::vector<double> jac;
  std::vector<double*> jac_ptrs;
  for (const AnalyticRow* r = rows; r != rows + count; ++r)
    for (int k = r->piece_begin; k < r->piece_end; ++k) {
      const Piece& p = pieces_[k];
      double* out = e.residuals + e.row;
      if (!p.cost) {
        p.constant(out);
        e.row += p.rows;
        continue;
      }
      const int nb = static_cast<int>(p.index.size());
      params.resize(nb);
      for (int b = 0; b < nb; ++b) params[b] = e.v.data() + p.index[b];
      if (e.jacobians) {
        jac.assign(static_cast<size_t>(nb) * p.rows, 0.0);
        jac_ptrs.resize(nb);
        for (int b = 0; b < nb; ++b) jac_ptrs[b] = jac.data() + static_cast<size_t>(b) * p.rows;
      }
      if (!p.cost->Evaluate(params.data(), out, e.jacobians ? jac_ptrs.data() : nullptr)) {
        // As Ceres takes a failed evaluation: the step is not taken.
        std::fill(out, out + p.rows, std::numeric_limits<double>::quiet_NaN());
      } else if (e.jacobians) {
        // Each block is one scalar: its Jacobian is the column of its rows.
        for (int b = 0; b < nb; ++b)
          for (int i = 0; i < p.rows; ++i) e.Put(e.row + i, p.index[b], jac_ptrs[b][i]);
      }
      e.row += p.rows;
    }
}

void AnalyticResiduals::Refresh(const ParameterTable& table, const Eigen::VectorXd& values) {
  if (values.size() != values_.size()) throw std::invalid_argument("analytic residuals: wrong number of values");
  values_ = values;
  table_ = &table;
  // The observation rows come first, one per held observation; the artefact
  // rows after them are made again too: a Monte Carlo trial draws the scale
  // bars' calibrated lengths, which those rows hold. Rows prepared per chunk
  // are read from the dataset at each evaluation anyway.
  const size_t n = ds_.observations.size();
  const bool all = storage_ == RowStorage::kAll;
  std::unique_ptr<Recorder> recorder;
  if (!pieces_.empty() || AnyTemplated(ds_)) recorder = NewRecorder(table);
  for (size_t i = 0, h = 0; i < n; ++i) {
    if (!KindOf(ds_.observations[i]).analytic()) RecordRow(*recorder, static_cast<int>(i), &rows_[h++]);
    else if (all) PrepareRow(table, KindOf(ds_.observations[i]), static_cast<int>(i), nullptr, &rows_[h++]);
  }
  RemakeArtefactRows(table);
}

bool AnalyticResiduals::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  const Machine& m = ds_.machine();
  const int nb = static_cast<int>(estimated_.size());
  Eigen::VectorXd v = values_;
  for (int b = 0; b < nb; ++b) v[estimated_[b]] = parameters[b][0];
  KinematicModel model(m, v.data());
  if (jacobians) model.RestrictJacobian(estimated_);
  const int nr = num_residuals();
  if (jacobians)
    for (int b = 0; b < nb; ++b)
      if (jacobians[b]) std::fill(jacobians[b], jacobians[b] + nr, 0.0);
  AnalyticEval e(m, v, model, estimated_, block_of_, residuals, jacobians);
  std::vector<AnalyticRow> scratch;
  for (const Run& run : runs_) EvaluateRun(e, run, run.begin, run.end, &scratch);
  return true;
}

void AnalyticResiduals::EvaluateRun(AnalyticEval& e, const Run& run, int begin, int end,
                                    std::vector<AnalyticRow>* scratch) const {
  if (run.held >= 0) {
    const AnalyticRow* rows = rows_.data() + run.held + (begin - run.begin);
    if (run.templated) EvaluateTemplated(e, rows, end - begin);
    else run.kind->EvaluateAnalytic(e, rows, end - begin);
    return;
  }
  // Rows of an analytic kind prepared per chunk: from the observations,
  // into the caller's buffer (whose rows keep their vectors' storage).
  for (int s = begin; s < end; s += kPreparedChunk) {
    const int c = std::min(end, s + kPreparedChunk) - s;
    if (static_cast<int>(scratch->size()) < c) scratch->resize(c);
    const ChunkCount count(c);
    // Each row after the chunk's first follows its observation's
    // predecessor (of this run's kind) in the chunk.
    AnalyticRow* rows = scratch->data();
    for (int k = 0; k < c; ++k) PrepareRow(*table_, *run.kind, s + k, k > 0 ? rows + k - 1 : nullptr, rows + k);
    run.kind->EvaluateAnalytic(e, rows, c);
  }
}

int AnalyticResiduals::EvaluateRows(const KinematicModel& model, const Eigen::VectorXd& v, int begin, int end,
                                    double* residuals, double** jacobians, std::vector<AnalyticRow>* scratch) const {
  AnalyticEval e(ds_.machine(), v, model, estimated_, block_of_, residuals, jacobians);
  std::vector<AnalyticRow> local;
  if (!scratch) scratch = &local;
  // Interleaved kinds make as many runs as rows: find the first one, do not scan.
  auto run = std::partition_point(runs_.begin(), runs_.end(), [&](const Run& r) { return r.end <= begin; });
  for (; run != runs_.end() && run->begin < end; ++run) {
    const int b = std::max(begin, run->begin), f = std::min(end, run->end);
    if (b < f) EvaluateRun(e, *run, b, f, scratch);
  }
  return e.row;
}

// The artefact rows (scale bars) read their lengths from the dataset, which a
// Monte Carlo trial edits: made again after the observation rows.
void AnalyticResiduals::RemakeArtefactRows(const ParameterTable& table) {
  const size_t before = rows_.size();
  rows_.resize(held_observations_);
  std::vector<int> source;
  for (const ObservationKind* kind : ObservationKinds()) kind->AddArtefactAnalyticRows(ds_, table, &rows_, &source);
  if (rows_.size() != before)
    throw std::invalid_argument("analytic residuals: the dataset's artefact rows changed since it was prepared");
}

void AnalyticResiduals::RefreshAxes(const ParameterTable& table) {
  // Rows prepared per chunk read the axes at each evaluation.
  if (storage_ == RowStorage::kAll) {
    const Machine& m = ds_.machine();
    const size_t n = ds_.observations.size();
    for (size_t i = 0; i < n; ++i) {
      rows_[i].q.resize(m.num_axes());
      AxisValuesToInternal(m, ds_.observations[i].axes.data(), rows_[i].q.data());
    }
  }
  RemakeArtefactRows(table);
}

}  // namespace fivecal
