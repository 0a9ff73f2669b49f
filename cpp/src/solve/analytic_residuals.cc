#include "fivecal/solve/analytic_residuals.h"

#include <algorithm>

#include "fivecal/model/kinematics.h"
#include "fivecal/observations/registry.h"

#include <stdexcept>

namespace fivecal {

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
                                     const Eigen::VectorXd& values, const std::vector<int>& estimated)
    : ds_(ds), values_(values), estimated_(estimated) {
  block_of_.assign(table.size(), -1);
  for (size_t b = 0; b < estimated_.size(); ++b) {
    block_of_[estimated_[b]] = static_cast<int>(b);
    mutable_parameter_block_sizes()->push_back(1);
  }
  rows_.reserve(ds.observations.size());
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const ObservationKind& kind = KindOf(ds.observations[i]);
    rows_.emplace_back();
    PrepareRow(table, static_cast<int>(i), &rows_.back());
    for (int k = 0; k < kind.rows(); ++k) row_source_.push_back(static_cast<int>(i));
  }
  for (const ObservationKind* kind : ObservationKinds())
    kind->AddArtefactAnalyticRows(ds, table, &rows_, &row_source_);
  for (int i = 0; i < static_cast<int>(rows_.size()); ++i) {
    const AnalyticRow& r = rows_[i];
    if (runs_.empty() || runs_.back().kind != r.kind || rows_[runs_.back().begin].variant != r.variant)
      runs_.push_back({r.kind, i, i});
    runs_.back().end = i + 1;
  }
  set_num_residuals(static_cast<int>(row_source_.size()));
}

void AnalyticResiduals::PrepareRow(const ParameterTable& table, int i, AnalyticRow* r) const {
  const Machine& m = ds_.machine();
  const Observation& o = ds_.observations[i];
  const ObservationKind& kind = KindOf(o);
  // A fresh row keeping its buffers (a refresh allocates nothing here).
  std::vector<double> q = std::move(r->q);
  std::vector<int> dir = std::move(r->dir);
  *r = AnalyticRow();
  r->kind = &kind;
  q.resize(m.num_axes());
  AxisValuesToInternal(m, o.axes.data(), q.data());
  dir.assign(o.direction.data(), o.direction.data() + o.direction.size());
  r->q = std::move(q);
  r->dir = std::move(dir);
  kind.PrepareAnalytic(ds_, table, o, r);
}

void AnalyticResiduals::Refresh(const ParameterTable& table, const Eigen::VectorXd& values) {
  if (values.size() != values_.size()) throw std::invalid_argument("analytic residuals: wrong number of values");
  values_ = values;
  // The observation rows come first, one per observation; the artefact rows
  // after them are made again too: a Monte Carlo trial draws the scale bars'
  // calibrated lengths, which those rows hold.
  const size_t n = ds_.observations.size();
  for (size_t i = 0; i < n; ++i) PrepareRow(table, static_cast<int>(i), &rows_[i]);
  const size_t before = rows_.size();
  rows_.resize(n);
  std::vector<int> source;
  for (const ObservationKind* kind : ObservationKinds()) kind->AddArtefactAnalyticRows(ds_, table, &rows_, &source);
  if (rows_.size() != before)
    throw std::invalid_argument("analytic residuals: the dataset's artefact rows changed since it was prepared");
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
  for (const Run& run : runs_) run.kind->EvaluateAnalytic(e, rows_.data() + run.begin, run.end - run.begin);
  return true;
}

int AnalyticResiduals::EvaluateRows(const KinematicModel& model, const Eigen::VectorXd& v, int begin, int end,
                                    double* residuals, double** jacobians) const {
  AnalyticEval e(ds_.machine(), v, model, estimated_, block_of_, residuals, jacobians);
  // Interleaved kinds make as many runs as rows: find the first one, do not scan.
  auto run = std::partition_point(runs_.begin(), runs_.end(), [&](const Run& r) { return r.end <= begin; });
  for (; run != runs_.end() && run->begin < end; ++run) {
    const int b = std::max(begin, run->begin), f = std::min(end, run->end);
    if (b < f) run->kind->EvaluateAnalytic(e, rows_.data() + b, f - b);
  }
  return e.row;
}

void AnalyticResiduals::RefreshAxes(const ParameterTable& table) {
  const Machine& m = ds_.machine();
  const size_t n = ds_.observations.size();
  for (size_t i = 0; i < n; ++i) {
    rows_[i].q.resize(m.num_axes());
    AxisValuesToInternal(m, ds_.observations[i].axes.data(), rows_[i].q.data());
  }
  const size_t before = rows_.size();
  rows_.resize(n);
  std::vector<int> source;
  for (const ObservationKind* kind : ObservationKinds()) kind->AddArtefactAnalyticRows(ds_, table, &rows_, &source);
  if (rows_.size() != before)
    throw std::invalid_argument("analytic residuals: the dataset's artefact rows changed since it was prepared");
}

}  // namespace fivecal
