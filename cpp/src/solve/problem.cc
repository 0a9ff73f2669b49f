#include "fivecal/solve/problem.h"

#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

namespace fivecal {
namespace {

// A cost function whose rows are those of `inner` divided by their declared
// noise: the solver then minimises sum (r_i / sigma_i)^2.
class WeightedCost : public ceres::CostFunction {
 public:
  WeightedCost(ceres::CostFunction* inner, std::vector<double> weight)
      : inner_(inner), weight_(std::move(weight)) {
    set_num_residuals(inner->num_residuals());
    *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    if (!inner_->Evaluate(parameters, residuals, jacobians)) return false;
    const int n = num_residuals();
    for (int i = 0; i < n; ++i) residuals[i] *= weight_[i];
    if (jacobians) {
      const auto& sizes = parameter_block_sizes();
      for (size_t b = 0; b < sizes.size(); ++b) {
        if (!jacobians[b]) continue;
        for (int i = 0; i < n; ++i)
          for (int c = 0; c < sizes[b]; ++c) jacobians[b][i * sizes[b] + c] *= weight_[i];
      }
    }
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> inner_;
  std::vector<double> weight_;
};

// (theta - mean) / sigma: one parameter's prior as a residual row.
class PriorCost : public ceres::SizedCostFunction<1, 1> {
 public:
  PriorCost(double mean, double sigma) : mean_(mean), inv_sigma_(1.0 / sigma) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    residuals[0] = (parameters[0][0] - mean_) * inv_sigma_;
    if (jacobians && jacobians[0]) jacobians[0][0] = inv_sigma_;
    return true;
  }

 private:
  const double mean_, inv_sigma_;
};

}  // namespace

PoseData::PoseData(const Machine& m, const Observation& o)
    : q(m.num_axes()), dir(o.direction.data(), o.direction.data() + o.direction.size()) {
  AxisValuesToInternal(m, o.axes.data(), q.data());
}

double ObservationSigma(const Dataset& ds, const Observation& o, int k) {
  if (o.sigma.size() > k) return o.sigma[k];
  if (o.sigma.size() == 1) return o.sigma[0];
  if (!ds.instrument_sigma.empty())
    if (const std::string* id = InstrumentId(o)) {
      auto it = ds.instrument_sigma.find(*id);
      if (it != ds.instrument_sigma.end()) return it->second[it->second.size() > k ? k : 0];
    }
  return KindOf(o).default_sigma_row(k);
}

// ---- ParameterTable ---------------------------------------------------------

int ParameterTable::Add(const std::string& name) {
  index_[name] = static_cast<int>(names_.size());
  names_.push_back(name);
  return static_cast<int>(names_.size()) - 1;
}

ParameterTable::ParameterTable(const Dataset& ds) {
  for (const std::string& n : ds.machine().parameter_names()) Add(n);
  num_machine_ = size();
  for (const ObservationKind* kind : ObservationKinds()) kind->AddArtefactParameters(ds, this);
  for (const Observation& o : ds.observations) KindOf(o).AddObservationParameters(o, this);
  // A column block's rows share their set-up: its first row brings them.
  Observation first;
  for (const TraceBlock& b : ds.blocks)
    if (b.size()) {
      ds.FillRow(b, 0, &first);
      KindOf(first).AddObservationParameters(first, this);
    }
}

int ParameterTable::Index(const std::string& name) const {
  auto it = index_.find(name);
  return it == index_.end() ? -1 : it->second;
}

int ParameterTable::Require(const std::string& name) const {
  int i = Index(name);
  if (i >= 0) return i;
  // A typo (EX0c) gets the closest name; a dotted name of no setup shape
  // (EX0C.x) is said to be malformed rather than "not in this dataset".
  std::string msg = "unknown parameter " + json_util::Quote(name);
  if (name.find('.') != std::string::npos && name.rfind("tip.", 0) != 0 &&
      !IsSetupParameterName(name))
    msg += ": not a parameter name (machine errors have no '.', setup parameters are facet.<id>, "
           "sphere.<id>.x|y|z|r, cylinder.<id>.r|x|y|rx|ry, probe.pretravel|axial|lobe.c2|..., "
           "dbb[.<setup>].length|tool.x|..., ball3d.<setup>.tool.x|..., tip.x|y|z)";
  else
    msg += ": not a machine parameter and not a setup parameter of this dataset (facet.<id>, "
           "sphere.<id>.x|y|z|r, dbb.length, ...)";
  throw std::invalid_argument(msg + json_util::DidYouMean(name, names_));
}

std::vector<int> ParameterTable::DefaultSetup(const Dataset& ds) const {
  std::set<int> s;
  for (const Observation& o : ds.observations) KindOf(o).DefaultSetup(ds, *this, o, &s);
  Observation first;
  for (const TraceBlock& b : ds.blocks)
    if (b.size()) {
      ds.FillRow(b, 0, &first);
      KindOf(first).DefaultSetup(ds, *this, first, &s);
    }
  return std::vector<int>(s.begin(), s.end());
}

// ---- Presets ----------------------------------------------------------------

std::vector<std::string> ThesisSubset(const Machine& m, const std::string& preset) {
  std::vector<std::string> out;
  if (preset == "S1") return out;
  // Scale gains of every linear axis.
  for (const Axis& a : m.axes())
    if (!a.rotary()) out.push_back(std::string("E") + a.name + a.name + "1");
  if (preset == "S2") return out;
  if (preset != "S3" && preset != "S4")
    throw std::invalid_argument("unknown preset '" + preset +
                                "' (S1, S2, S3, S4, location, auto)");
  if (m.topology() != "wCBXfZYSt")
    throw std::invalid_argument("preset '" + preset +
                                "' is the thesis subset for topology wCBXfZYSt (Rahman 2016, "
                                "ch. 4); this machine is '" + m.topology() +
                                "': use 'location' or 'auto'");
  // Eight axis location errors, spindle offsets and backlashes (thesis S3).
  for (const char* n : {"EA0B", "EC0B", "EX0C", "EA0C", "EB0C", "EB0Z", "EA0Y", "EC0Y", "EX0S",
                        "EY0S", "EXXb", "EYYb", "EBBb", "ECCb"})
    out.push_back(n);
  if (preset == "S3") return out;
  // S4: identifiable intra-axis (error motion) coefficients, Table 4-1.
  for (const char* n :
       {"EXX2", "EXX3", "EYY2", "EYY3", "EZZ2", "EZZ3", "EBB1", "EBB2", "EBB3", "ECC1", "ECC2",
        "ECC3", "EYX2", "EYX3", "EZX2", "EZX3", "EAX1", "EAX2", "EAX3", "EBX1", "EBX2", "EBX3",
        "ECX1", "ECX2", "ECX3", "EXB1", "EXB2", "EXB3", "EYB1", "EYB2", "EYB3", "EZB1", "EZB2",
        "EZB3", "EAB1", "EAB2", "EAB3", "ECB1", "ECB2", "ECB3", "EXC1", "EXC2", "EXC3", "EYC1",
        "EYC2", "EYC3", "EZC1", "EZC2", "EZC3", "EAC1", "EAC2", "EAC3", "EBC1", "EBC2", "EBC3",
        "EXZ2", "EXZ3", "EYZ2", "EYZ3", "EAZ1", "EAZ2", "EAZ3", "ECZ1", "ECZ2", "ECZ3", "EXY2",
        "EXY3", "EZY2", "EZY3"})
    out.push_back(n);
  return out;
}

namespace {

// Components (0..5 = X Y Z A B C) perpendicular to an axis direction,
// ordered by how perpendicular they are.
std::vector<int> Perpendicular(const Eigen::Vector3d& u) {
  std::vector<int> c = {0, 1, 2};
  std::sort(c.begin(), c.end(), [&](int a, int b) { return std::abs(u[a]) < std::abs(u[b]); });
  std::vector<int> out = {c[0], c[1]};
  std::sort(out.begin(), out.end());
  return out;
}

std::string Loc(int comp, char axis) { return std::string("E") + kComponentLetters[comp] + "0" + axis; }

}  // namespace

std::vector<std::string> LocationCandidates(const Machine& m) {
  std::vector<int> rotary, linear;
  auto collect = [&](const std::vector<int>& chain) {
    for (int k : chain) {
      if (m.axis(k).name == 'S') continue;
      (m.axis(k).rotary() ? rotary : linear).push_back(k);
    }
  };
  collect(m.workpiece_chain());
  collect(m.tool_chain());
  std::vector<std::string> out;
  for (int k : rotary)
    for (int c : Perpendicular(m.axis(k).direction)) out.push_back(Loc(c + 3, m.axis(k).name));
  const int s = m.AxisIndex('S');
  if (s >= 0)
    for (int c : Perpendicular(m.axis(s).direction)) out.push_back(Loc(c, 'S'));
  for (int k : rotary)
    for (int c : Perpendicular(m.axis(k).direction)) out.push_back(Loc(c, m.axis(k).name));
  // Squareness: outermost tool-side linear axes first, the reference last.
  std::vector<int> lin(linear.rbegin(), linear.rend());
  for (int k : lin)
    for (int c : Perpendicular(m.axis(k).direction)) out.push_back(Loc(c + 3, m.axis(k).name));
  if (s >= 0)
    for (int c : Perpendicular(m.axis(s).direction)) out.push_back(Loc(c + 3, 'S'));
  return out;
}

std::vector<std::string> MotionCandidates(const Machine& m) {
  std::vector<std::string> out;
  for (const Axis& a : m.axes())
    if (a.name != 'S') out.push_back(std::string("E") + a.name + a.name + "b");
  // Scale gains first: the most common and best-determined error motions.
  for (const Axis& a : m.axes())
    if (!a.rotary()) out.push_back(std::string("E") + a.name + a.name + "1");
  for (int d = 1; d <= 3; ++d)
    for (const Axis& a : m.axes())
      for (int c = 0; c < 6; ++c) {
        std::string n = std::string("E") + kComponentLetters[c] + a.name + std::to_string(d);
        if (std::find(out.begin(), out.end(), n) == out.end()) out.push_back(n);
      }
  return out;
}

// ---- Problem ----------------------------------------------------------------

// The kinds add their templated residuals through this (residuals.h).
class ProblemBuilder : public ResidualBuilder {
 public:
  ProblemBuilder(Problem* p, const std::vector<double*>& machine_ptrs)
      : ResidualBuilder(p->ds_, p->table_, p->ctx_), p_(p) {
    machine_ptrs_ = machine_ptrs;
  }

 protected:
  double* Block(int index) override { return p_->block_of_[index] >= 0 ? &p_->values_[index] : nullptr; }
  void AddCost(ceres::CostFunction* cost, int num_residuals, const std::vector<double*>& ptrs,
               int source) override {
    p_->AddCostBlock(cost, num_residuals, ptrs, source);
  }
  void AddConstant(int num_residuals, std::function<void(double*)> eval, int source) override {
    p_->AddConstantRows(num_residuals, std::move(eval), source);
  }

 private:
  Problem* p_;
};

Problem::Problem(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                 const std::vector<int>& estimated, const std::string& robust, double robust_scale,
                 bool analytic)
    : ds_(ds), table_(table), values_(values), estimated_(estimated) {
  if (values_.size() != table.size())
    throw std::invalid_argument("problem: expected " + std::to_string(table.size()) + " values");
  // A residual functor per observation: column blocks must be expanded by
  // the caller first (Dataset::Expanded), never silently left out.
  if (!ds.blocks.empty())
    throw std::logic_error("problem: the dataset holds column blocks; expand them first (Dataset::Expanded)");
  block_of_.assign(table.size(), -1);
  for (size_t i = 0; i < estimated_.size(); ++i) block_of_[estimated_[i]] = static_cast<int>(i);

  const Machine& m = ds.machine();
  ctx_ = ResidualContext::Make(m, values_, estimated_);

  ceres::Problem::Options opts;
  opts.enable_fast_removal = false;
  problem_ = std::make_unique<ceres::Problem>(opts);
  if (robust == "huber" || robust == "cauchy") robust_ = robust;
  else if (!robust.empty() && robust != "none")
    throw std::invalid_argument("robust: unknown loss '" + robust + "' (huber, cauchy or none)");
  robust_scale_ = robust_scale;
  if (!robust_.empty() && !(robust_scale > 0))
    throw std::invalid_argument("robust: the loss scale must be > 0 mm");

  // The batch holds every kind (those without analytic derivatives through
  // their recorded functors), so the dense path and the streaming one
  // (normal_equations.h) see the same rows, and Refresh serves any data.
  if (analytic && robust_.empty() && !estimated_.empty()) {
    auto* cost = new AnalyticResiduals(ds, table, values_, estimated_);
    analytic_ = cost;
    std::vector<double*> ptrs;
    for (int i : estimated_) ptrs.push_back(&values_[i]);
    row_source_ = cost->row_source();
    num_rows_ = cost->num_residuals();
    row_sigma_.resize(num_rows_);
    std::vector<double> w(num_rows_);
    for (int r = 0, k = 0; r < num_rows_; ++r) {
      k = (r > 0 && row_source_[r] == row_source_[r - 1]) ? k + 1 : 0;
      row_sigma_[r] = SigmaOfRow(row_source_[r], k);
      w[r] = 1.0 / row_sigma_[r];
    }
    blocks_.push_back(problem_->AddResidualBlock(new WeightedCost(cost, w), nullptr, ptrs));
    block_row_.push_back(0);
    return;
  }

  // Block pointers of the estimated machine parameters, shared by every
  // machine-dependent residual.
  std::vector<double*> machine_ptrs;
  for (int i : estimated_)
    if (i < m.num_parameters()) machine_ptrs.push_back(&values_[i]);

  ProblemBuilder builder(this, machine_ptrs);
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation& o = ds.observations[i];
    builder.Start(static_cast<int>(i), true);
    KindOf(o).AddResidual(builder, o);
  }
  for (const ObservationKind* kind : ObservationKinds()) kind->AddArtefactResiduals(builder);
  row_sigma_.resize(num_rows_);
  for (int r = 0, k = 0; r < num_rows_; ++r) {
    k = (r > 0 && row_source_[r] == row_source_[r - 1]) ? k + 1 : 0;
    row_sigma_[r] = SigmaOfRow(row_source_[r], k);
  }
  // An estimated parameter no residual depends on still gets a (zero) column,
  // so the identifiability analysis can name it.
  for (int i : estimated_)
    if (!problem_->HasParameterBlock(&values_[i])) problem_->AddParameterBlock(&values_[i], 1);
}

ceres::Solver::Options Problem::SolverOptions(int max_iterations, int num_threads) {
  ceres::Solver::Options so;
  // Normal equations: the problems are small and dense, and with Jacobi
  // scaling the squared condition number stays far from double precision.
  so.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  so.max_num_iterations = max_iterations;
  // The models are nearly linear in the errors, so Gauss-Newton converges in
  // a few steps and the cost then sits at its rounding floor (relative
  // changes of 1e-11 with either sign). A relative cost change of 1e-10
  // leaves the parameters within about 1e-4 sigma of the optimum; a tighter
  // tolerance only adds rejected steps.
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-16;
  so.num_threads = std::max(1, num_threads);
  so.logging_type = ceres::SILENT;
  // Start with a trust region so large that the first steps are Gauss-Newton steps.
  so.initial_trust_region_radius = 1e12;
  return so;
}

void Problem::Evaluate(Eigen::VectorXd* residuals, Eigen::MatrixXd* jacobian) {
  if (analytic_) {
    // One dense block: the cost function writes the columns in place.
    residuals->resize(num_rows_);
    std::vector<const double*> params;
    for (int i : estimated_) params.push_back(&values_[i]);
    std::vector<double*> cols;
    if (jacobian) {
      jacobian->resize(num_rows_, static_cast<Eigen::Index>(estimated_.size()));
      for (size_t b = 0; b < estimated_.size(); ++b) cols.push_back(jacobian->col(b).data());
    }
    if (!analytic_->Evaluate(params.data(), residuals->data(), jacobian ? cols.data() : nullptr))
      throw std::runtime_error("problem: residual evaluation failed");
    return;
  }
  ceres::Problem::EvaluateOptions eo;
  eo.residual_blocks = blocks_;
  for (int i : estimated_) eo.parameter_blocks.push_back(&values_[i]);
  eo.apply_loss_function = false;
  std::vector<double> r;
  ceres::CRSMatrix crs;
  const bool want_j = jacobian != nullptr;
  if (!problem_->Evaluate(eo, nullptr, &r, nullptr, want_j ? &crs : nullptr))
    throw std::runtime_error("problem: residual evaluation failed");
  residuals->setZero(num_rows_);
  if (want_j) jacobian->setZero(num_rows_, estimated_.size());
  // Ceres stacks the rows of the residual blocks in order; map them back.
  int ceres_row = 0;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const int nr = problem_->GetCostFunctionForResidualBlock(blocks_[b])->num_residuals();
    for (int k = 0; k < nr; ++k, ++ceres_row) {
      const int row = block_row_[b] + k;
      (*residuals)[row] = r[ceres_row];
      if (want_j)
        for (int e = crs.rows[ceres_row]; e < crs.rows[ceres_row + 1]; ++e)
          (*jacobian)(row, crs.cols[e]) = crs.values[e];
    }
  }
  for (auto& c : constant_) c.second(residuals->data() + c.first);
  // The solver's rows are weighted; report them in mm.
  for (size_t b = 0; b < blocks_.size(); ++b) {
    const int nr = problem_->GetCostFunctionForResidualBlock(blocks_[b])->num_residuals();
    for (int k = 0; k < nr; ++k) {
      const int row = block_row_[b] + k;
      (*residuals)[row] *= row_sigma_[row];
      if (want_j) jacobian->row(row) *= row_sigma_[row];
    }
  }
}

bool Problem::Refresh(const Eigen::VectorXd& values) {
  if (!analytic_) return false;
  if (values.size() != values_.size())
    throw std::invalid_argument("problem: expected " + std::to_string(values_.size()) + " values");
  // In place: Ceres holds pointers into values_.
  values_ = values;
  analytic_->Refresh(table_, values);
  return true;
}

void Problem::SetEstimated(const Eigen::VectorXd& v) {
  if (v.size() != static_cast<Eigen::Index>(estimated_.size()))
    throw std::invalid_argument("problem: expected " + std::to_string(estimated_.size()) + " estimated values");
  // In place: Ceres holds pointers into values_.
  for (size_t b = 0; b < estimated_.size(); ++b) values_[estimated_[b]] = v[b];
}

double Problem::SigmaOfRow(int source, int k) const {
  if (source < 0) return kScaleBarSigma;
  return ObservationSigma(ds_, ds_.observations[source], k);
}

void Problem::AddPriors(const Eigen::VectorXd& prior_sigma, const Eigen::VectorXd& prior_mean) {
  if (!prior_blocks_.empty()) throw std::logic_error("problem: priors added twice");
  for (int i : estimated_) {
    if (!(prior_sigma[i] > 0))
      throw std::invalid_argument("problem: prior sigma of parameter " + table_.names()[i] + " must be > 0");
    if (std::isinf(prior_sigma[i])) continue;  // no prior row (priors.h PlacementRows)
    prior_blocks_.push_back(
        problem_->AddResidualBlock(new PriorCost(prior_mean[i], prior_sigma[i]), nullptr, &values_[i]));
  }
}

void Problem::AddConstantRows(int num_residuals, std::function<void(double*)> eval, int source) {
  constant_.push_back({num_rows_, std::move(eval)});
  for (int r = 0; r < num_residuals; ++r) row_source_.push_back(source);
  num_rows_ += num_residuals;
}

void Problem::AddCostBlock(ceres::CostFunction* cost, int num_residuals, const std::vector<double*>& ptrs,
                           int source) {
  std::vector<double> w(num_residuals);
  double block_sigma = 0;
  for (int r = 0; r < num_residuals; ++r) {
    const double s = SigmaOfRow(source, r);
    w[r] = 1.0 / s;
    block_sigma = std::max(block_sigma, s);
  }
  // The loss sees weighted rows, so its scale (mm) is carried into the
  // block's units: the same touches are flagged as without weighting.
  ceres::LossFunction* loss = nullptr;
  if (robust_ == "huber") loss = new ceres::HuberLoss(robust_scale_ / block_sigma);
  else if (robust_ == "cauchy") loss = new ceres::CauchyLoss(robust_scale_ / block_sigma);
  blocks_.push_back(problem_->AddResidualBlock(new WeightedCost(cost, w), loss, ptrs));
  block_row_.push_back(num_rows_);
  for (int r = 0; r < num_residuals; ++r) row_source_.push_back(source);
  num_rows_ += num_residuals;
}

}  // namespace fivecal
