// What the residuals of every observation kind share (the kinds' own
// functors are in observations/<kind>.h).
//
// Every residual sees the problem's full parameter vector (machine theta,
// then setup parameters) through a ParameterAccess: estimated parameters come
// from the residual's Ceres parameter blocks (one scalar block each), fixed
// ones are constants. The machine parameters that are estimated form the
// first blocks of every machine-dependent residual, in one shared order.
#ifndef FIVECAL_RESIDUALS_H_
#define FIVECAL_RESIDUALS_H_

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {

class ParameterTable;

// What every residual of one problem shares.
struct ResidualContext {
  const Machine* machine = nullptr;
  Eigen::VectorXd values;              // all parameters; constants for the fixed ones
  std::vector<int> machine_block;      // per machine parameter: block number or -1
  int num_machine_blocks = 0;

  // The context of a problem estimating `estimated` (table indices, in block
  // order) at `values`: the estimated machine parameters numbered in order.
  static std::shared_ptr<const ResidualContext> Make(const Machine& m, const Eigen::VectorXd& values,
                                                     const std::vector<int>& estimated) {
    auto ctx = std::make_shared<ResidualContext>();
    ctx->machine = &m;
    ctx->values = values;
    ctx->machine_block.assign(m.num_parameters(), -1);
    for (int i : estimated)
      if (i < m.num_parameters()) ctx->machine_block[i] = ctx->num_machine_blocks++;
    return ctx;
  }
};

// One setup parameter as seen by a residual: its full index and its block
// number in that residual (-1 when fixed).
struct SetupRef {
  int index = -1;
  int block = -1;
};

class ParameterAccess {
 public:
  explicit ParameterAccess(std::shared_ptr<const ResidualContext> ctx) : ctx_(std::move(ctx)) {}

  template <typename T>
  void Theta(T const* const* p, std::vector<T>* theta) const {
    const int n = ctx_->machine->num_parameters();
    theta->resize(n);
    for (int i = 0; i < n; ++i) {
      const int b = ctx_->machine_block[i];
      (*theta)[i] = b >= 0 ? p[b][0] : T(ctx_->values[i]);
    }
  }
  template <typename T>
  T Setup(T const* const* p, const SetupRef& s) const {
    return s.block >= 0 ? p[s.block][0] : T(ctx_->values[s.index]);
  }
  const Machine& machine() const { return *ctx_->machine; }

 private:
  std::shared_ptr<const ResidualContext> ctx_;
};

// Axis readings of one observation converted to internal units once.
struct PoseData {
  PoseData(const Machine& m, const Observation& o);
  std::vector<double> q;
  std::vector<int> dir;
};

// What a kind's AddResidual uses to add its templated residual to a problem:
// Ref() turns a parameter index into a SetupRef (adding the parameter's block
// when it is estimated), Add() wraps the functor for automatic derivatives.
class ResidualBuilder {
 public:
  ResidualBuilder(const Dataset& ds, const ParameterTable& table, std::shared_ptr<const ResidualContext> ctx)
      : dataset(ds), table(table), context(std::move(ctx)) {}
  virtual ~ResidualBuilder() = default;

  const Dataset& dataset;
  const ParameterTable& table;
  const std::shared_ptr<const ResidualContext> context;

  // Starts the next residual: its rows belong to `source` (an observation
  // index, or -(1 + index) of an artefact constraint); `machine`: it depends
  // on the estimated machine parameters (their blocks come first).
  void Start(int source, bool machine) {
    source_ = source;
    ptrs_.clear();
    if (machine) ptrs_ = machine_ptrs_;
  }
  SetupRef Ref(int index) {
    SetupRef r{index, -1};
    if (index >= 0) {
      double* p = Block(index);
      if (p) {
        r.block = static_cast<int>(ptrs_.size());
        ptrs_.push_back(p);
      }
    }
    return r;
  }
  // Takes ownership of `f`.
  template <typename Functor>
  void Add(Functor* f, int num_residuals) {
    if (ptrs_.empty()) {
      // Nothing estimated influences this residual: keep it out of the solver
      // but evaluate it for the report.
      std::shared_ptr<Functor> keep(f);
      AddConstant(num_residuals, [keep](double* r) { (*keep)(static_cast<double const* const*>(nullptr), r); },
                  source_);
      return;
    }
    auto* cost = new ceres::DynamicAutoDiffCostFunction<Functor, kStride>(f);
    for (size_t i = 0; i < ptrs_.size(); ++i) cost->AddParameterBlock(1);
    cost->SetNumResiduals(num_residuals);
    AddCost(cost, num_residuals, ptrs_, source_);
  }

 protected:
  static constexpr int kStride = 4;
  // The storage of an estimated parameter's block, or nullptr when fixed.
  virtual double* Block(int index) = 0;
  virtual void AddCost(ceres::CostFunction* cost, int num_residuals, const std::vector<double*>& ptrs,
                       int source) = 0;
  virtual void AddConstant(int num_residuals, std::function<void(double*)> eval, int source) = 0;
  std::vector<double*> machine_ptrs_;

 private:
  std::vector<double*> ptrs_;
  int source_ = 0;
};

}  // namespace fivecal

#endif  // FIVECAL_RESIDUALS_H_
