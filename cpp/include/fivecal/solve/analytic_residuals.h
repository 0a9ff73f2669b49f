// AnalyticResiduals: every residual row of a dataset as ONE Ceres cost
// function with analytic derivatives from KinematicModel. Same residual
// definitions as the kinds' templated functors (observations/<kind>.h) and
// the same row order (observations in order, then the artefact rows: the
// scale bars whose balls were probed); the functors stay the reference the
// tests compare against. One block lets the kinematic constants be prepared
// once per evaluation instead of once per touch, and avoids Jets entirely.
//
// Each kind prepares its rows (ObservationKind::PrepareAnalytic) and
// evaluates a run of consecutive rows of its own (EvaluateAnalytic), with
// the chain rule through the tool point shared here (AnalyticEval): per row,
// with P the tool point and J = dP/dtheta, a kind gives the gradients G of
// its residual rows in P and the derivatives in its setup parameters.
//
// An observation of a kind without the analytic batch (analytic() false:
// point, pose, distance, machined) takes its place in the same row order as
// its templated functor, recorded through a ResidualBuilder at construction
// and evaluated with automatic derivatives; so every dataset, mixed ones
// too, is one batch, and the streaming fit (normal_equations.h) runs on any
// data. That costs one Ceres cost function per such observation: fine for
// those kinds (tracker, camera and CMM data: thousands of rows, not the
// millions of samples of an R-test or ball-bar trace, which are analytic).
#ifndef FIVECAL_ANALYTIC_RESIDUALS_H_
#define FIVECAL_ANALYTIC_RESIDUALS_H_

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

class ObservationKind;

// One observation (or artefact constraint) prepared for the batch. The
// fields mean what the kind that prepared it says.
struct AnalyticRow {
  const ObservationKind* kind = nullptr;
  int variant = 0;         // 0: an observation; else an artefact row of the kind
  std::vector<double> q;   // internal units
  std::vector<int> dir;
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
  Eigen::Vector3d tool_ball = Eigen::Vector3d::Zero(), measured = Eigen::Vector3d::Zero();
  double constant = 0;
  int idx[8] = {-1, -1, -1, -1, -1, -1, -1, -1};  // setup parameter indices
  // Probe touches: the trigger model (observations/probe_trigger.h), the
  // table index of probe.pretravel (-1: none) and the rotation M.
  int probe0 = -1;
  Eigen::Matrix3d probe_rotation = Eigen::Matrix3d::Identity();
  // A kind without the analytic batch: its recorded templated pieces
  // [piece_begin, piece_end) (AnalyticResiduals), -1: an analytic row.
  int piece_begin = -1, piece_end = -1;
};

// One evaluation of the batch, as the kinds see it.
class AnalyticEval {
 public:
  AnalyticEval(const Machine& m, const Eigen::VectorXd& v, const KinematicModel& model,
               const std::vector<int>& estimated, const std::vector<int>& block_of, double* residuals,
               double** jacobians);

  const Eigen::VectorXd& v;  // every parameter's value
  double* const residuals;
  double** const jacobians;  // null: residuals only
  int row = 0;               // the current observation's first residual row

  // d(row)/d(parameter index) += value, when that parameter is estimated.
  void Put(int r, int index, double value) const {
    if (!jacobians || index < 0) return;
    const int b = block_of_[index];
    if (b >= 0 && jacobians[b]) jacobians[b][r] += value;
  }
  // The tool point of a row's pose for a tool tip at `tip` (F, zero pose),
  // with dP/dtheta kept for Chain when derivatives are wanted.
  void ToolPoint(const AnalyticRow& r, const Eigen::Vector3d& tip, Eigen::Vector3d* P) {
    if (jacobians) model_.ToolPointJacobian(r.q.data(), r.dir.data(), tip, P, J_.data());
    else *P = model_.ToolPoint(r.q.data(), r.dir.data(), tip);
  }
  // The probe tip at the current values.
  const Eigen::Vector3d& probe_tip() const { return model_.tip(); }
  // Machine columns of the n rows from `row` on, with G (rows: gradients of
  // the residual rows in P). `tool` (3 parameter indices) when the tool
  // point is a ball at tool_ball + tool: those act like a tip, and the probe
  // tip offsets tip.x|y|z do not enter.
  void Chain(const Eigen::Matrix3d& G, int n, const int* tool) const {
    if (!jacobians) return;
    for (int k = 0; k < n; ++k) {
      const Eigen::RowVector3d g = G.row(k);
      for (const auto& [b, idx] : machine_blocks_) {
        if (!jacobians[b]) continue;
        const bool is_tip = idx >= tip0_ && idx < tip0_ + 3;
        if (tool && is_tip) continue;  // the probe tip does not carry the ball
        jacobians[b][row + k] += g.dot(J_.col(idx));
      }
      if (tool)  // the tool ball's offsets act like a tip: dP/dtip
        for (int c = 0; c < 3; ++c) Put(row + k, tool[c], g.dot(J_.col(tip0_ + c)));
    }
  }

 private:
  const KinematicModel& model_;
  const std::vector<int>& block_of_;
  std::vector<std::pair<int, int>> machine_blocks_;  // (block, theta index)
  int tip0_;
  Eigen::Matrix<double, 3, Eigen::Dynamic> J_;
};

// Prepared rows alive in this process: those every batch holds, plus those
// a per-chunk evaluation holds for the moment; and the most there were at
// once since the last ResetPreparedRowsPeak(). What tests and benchmarks read
// to see that the streaming fit of long data holds a chunk of prepared rows
// per thread, not one per sample.
int64_t PreparedRowsAlive();
int64_t PreparedRowsPeak();
void ResetPreparedRowsPeak();

// How a batch holds the rows of the observations of analytic kinds.
//   kAll:      prepared once, all held (the dense path: its Jacobian is
//              data-sized anyway, and Refit compares rows across refreshes);
//   kPerChunk: prepared from the dataset at each evaluation, a chunk of at
//              most kPreparedChunk rows at a time, and dropped after it (the
//              streaming fit of long data: a prepared row is ~0.35 kB, which
//              at 10^7 samples is more than the data itself). Rows of the
//              templated kinds and the artefact rows are held in both.
enum class RowStorage { kAll, kPerChunk };
constexpr int kPreparedChunk = 256;

class AnalyticResiduals : public ceres::CostFunction {
 public:
  ~AnalyticResiduals() override;

  // values: every parameter of the table (constants for the fixed ones);
  // estimated: the table indices that are the parameter blocks, in order.
  // With kPerChunk, `table` is read at every evaluation: it must outlive
  // the batch.
  AnalyticResiduals(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                    const std::vector<int>& estimated, RowStorage storage = RowStorage::kAll);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  // Refresh for a dataset whose observations changed in their axis values
  // alone (a Monte Carlo trial moves each touch along its approach line):
  // each observation row's axis values are read again and the rest of the
  // row is kept; the artefact rows are made again. The caller knows that
  // the rows depend on nothing else that changed (Refit::Session checks it
  // against Refresh on its first trials).
  void RefreshAxes(const ParameterTable& table);
  // The held rows: with kAll one per observation, then the artefact rows
  // (kPerChunk: those of the templated kinds and the artefact rows only).
  const std::vector<AnalyticRow>& rows() const { return rows_; }
  RowStorage storage() const { return storage_; }

  // Per row: the observation index, or -(1 + scale bar index).
  const std::vector<int>& row_source() const { return row_source_; }

  // Prepares the observation rows again from the dataset (edited in place
  // since, same structure) and takes `values` as the fixed parameters' values
  // (the templated observations are recorded again: their functors hold the
  // readings and the fixed values).
  void Refresh(const ParameterTable& table, const Eigen::VectorXd& values);

  // The streaming fit (solve/normal_equations.h) evaluates the prepared rows
  // (one per observation, then the artefact rows) a chunk at a time instead
  // of all rows at once: rows [begin, end) at every parameter's value `v`,
  // with `model` built at `v` (RestrictJacobian to the estimated set when
  // jacobians are wanted). Residual rows are written from residuals[0],
  // column b of the estimated set at jacobians[b][0..] (zeroed by the
  // caller; null: residuals only). Returns the number of residual rows.
  // Safe to call from several threads at once (it writes only its outputs
  // and `scratch`, the caller's buffer for rows prepared per chunk, kept
  // between calls so that their buffers are reused; null: one of the call).
  int num_prepared() const { return num_prepared_; }
  int EvaluateRows(const KinematicModel& model, const Eigen::VectorXd& v, int begin, int end,
                   double* residuals, double** jacobians, std::vector<AnalyticRow>* scratch = nullptr) const;

 private:
  // A templated residual of an observation without the analytic batch, as
  // its kind adds it through a ResidualBuilder: a cost function over the
  // table entries `index` (each a block of size 1), or, when nothing
  // estimated enters it, a constant evaluation.
  struct Piece {
    std::unique_ptr<ceres::CostFunction> cost;
    std::vector<int> index;
    std::function<void(double*)> constant;
    int rows = 0;
  };
  class Recorder;
  // Observation i's row, of `kind`; `prev`: the row just prepared for
  // observation i - 1, of the same kind (null: none).
  void PrepareRow(const ParameterTable& table, const ObservationKind& kind, int observation,
                  const AnalyticRow* prev, AnalyticRow* r) const;
  void RemakeArtefactRows(const ParameterTable& table);
  // Records observation i's templated pieces into *pieces (row r points at them).
  std::unique_ptr<Recorder> NewRecorder(const ParameterTable& table);
  void RecordRow(Recorder& recorder, int observation, AnalyticRow* r) const;
  void EvaluateTemplated(AnalyticEval& e, const AnalyticRow* rows, int count) const;
  struct Run {  // consecutive rows of one kind and variant
    const ObservationKind* kind;
    int begin, end;
    bool templated;
    int held;  // rows_ index of row `begin`; -1: prepared per chunk
  };
  void EvaluateRun(AnalyticEval& e, const Run& run, int begin, int end, std::vector<AnalyticRow>* scratch) const;
  void CountHeld(int64_t rows);
  const Dataset& ds_;
  const ParameterTable* table_;  // kPerChunk: read at every evaluation
  RowStorage storage_;
  int num_prepared_ = 0;
  int held_observations_ = 0;  // rows_ of observations (the artefact rows follow)
  int64_t counted_ = 0;  // held rows counted in PreparedRowsAlive
  Eigen::VectorXd values_;
  std::vector<int> estimated_;
  std::vector<int> block_of_;  // per table index: block or -1
  std::vector<AnalyticRow> rows_;  // the held rows (rows())
  std::vector<Piece> pieces_;      // of the templated rows, in row order
  std::vector<Run> runs_;
  std::vector<int> row_source_;
};

}  // namespace fivecal

#endif  // FIVECAL_ANALYTIC_RESIDUALS_H_
