#include "fivecal/design/design.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <tuple>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

constexpr double kInf = std::numeric_limits<double>::infinity();

json Finite(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

IdentifyOptions ResolveOptions(const DesignOptions& o) {
  IdentifyOptions io;
  io.estimate = o.estimate;
  io.fix = o.fix;
  io.initial = o.values;
  io.include_default_setup = o.include_default_setup;
  io.rank_tolerance = o.rank_tolerance;
  return io;
}

// Sum of the logs of positive numbers for the price of one log (a log costs
// as much as a column of the elimination): their product, renormalised to
// mantissa and binary exponent before it could overflow or underflow.
struct LogSum {
  double m = 1.0;
  long e = 0;
  void Add(double x) {
    int ex;
    if (x > 1e-150 && x < 1e150) {
      m *= x;
      if (m > 1e-150 && m < 1e150) return;
    } else {
      m *= std::frexp(x, &ex);
      e += ex;
    }
    m = std::frexp(m, &ex);
    e += ex;
  }
  double Get() const { return std::log(m) + static_cast<double>(e) * 0.69314718055994530942; }
};

// Criterion of one information matrix A = J^T J over the active columns.
struct Score {
  int deficiency = 0;     // active columns minus numerical rank
  double cond = kInf;     // column-scaled condition number of J
  double dcrit = -kInf;   // Ds-optimality, characteristic units
  double nonnull = 0;     // sum of log of the non-null scaled eigenvalues / p (ranking when deficient)
};

// A: p x p information matrix; active: columns in use; machine: flags (per
// column of A) of the machine parameters; scale: characteristic scale per column.
Score Evaluate(const Eigen::MatrixXd& A, const std::vector<int>& active, const std::vector<bool>& machine,
               const Eigen::VectorXd& scale, double tol, bool want_d) {
  Score s;
  const int pa = static_cast<int>(active.size());
  if (pa == 0) return s;
  Eigen::VectorXd d(pa);
  std::vector<int> live;
  for (int i = 0; i < pa; ++i) {
    d[i] = A(active[i], active[i]);
    if (d[i] > 0) live.push_back(i);
  }
  const int pl = static_cast<int>(live.size());
  s.deficiency = pa - pl;
  if (pl == 0) return s;
  Eigen::MatrixXd Ms(pl, pl);
  Eigen::VectorXd inv_sqrt(pl);
  for (int i = 0; i < pl; ++i) inv_sqrt[i] = 1.0 / std::sqrt(d[live[i]]);
  for (int i = 0; i < pl; ++i)
    for (int j = 0; j < pl; ++j)
      Ms(i, j) = A(active[live[i]], active[live[j]]) * inv_sqrt[i] * inv_sqrt[j];
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ms, Eigen::EigenvaluesOnly);
  const Eigen::VectorXd& lam = es.eigenvalues();  // ascending
  const double lmax = lam[pl - 1];
  const double cut = tol * tol * lmax;
  int null = 0;
  double logsum = 0;
  for (int i = 0; i < pl; ++i) {
    if (lam[i] > cut) logsum += std::log(lam[i]);
    else ++null;
  }
  s.deficiency += null;
  s.nonnull = logsum / pa;
  if (s.deficiency > 0) return s;
  s.cond = std::sqrt(lmax / lam[0]);
  if (!want_d) return s;
  // log det of the Schur complement on the machine columns:
  // log det(A) - log det(A_ss), in scaled form, plus the characteristic units.
  std::vector<int> setup;
  double shift = 0;  // sum over machine columns of log(d_i) + 2 log(scale_i)
  int pm = 0;
  for (int i = 0; i < pa; ++i) {
    if (machine[active[i]]) {
      shift += std::log(d[i]) + 2.0 * std::log(scale[active[i]]);
      ++pm;
    } else {
      setup.push_back(i);
    }
  }
  if (pm == 0) {
    s.dcrit = 0;
    return s;
  }
  double logdet_all = logsum;  // scaled, all eigenvalues positive here
  double logdet_ss = 0;
  if (!setup.empty()) {
    Eigen::MatrixXd Ss(setup.size(), setup.size());
    for (size_t i = 0; i < setup.size(); ++i)
      for (size_t j = 0; j < setup.size(); ++j) Ss(i, j) = Ms(setup[i], setup[j]);
    Eigen::LLT<Eigen::MatrixXd> llt(Ss);
    if (llt.info() != Eigen::Success) return s;
    for (int i = 0; i < Ss.rows(); ++i) logdet_ss += 2.0 * std::log(llt.matrixL()(i, i));
  }
  s.dcrit = (logdet_all - logdet_ss + shift) / pm;
  return s;
}

// The estimated parameter set of a dataset, machine errors first.
struct Columns {
  std::vector<std::string> names;
  std::vector<int> table_index;
  int n_machine = 0;
};

Columns ResolveColumns(const Dataset& given_ds, const ParameterTable& table, const DesignOptions& opt) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const std::vector<std::string> names = ResolveEstimate(ds, ResolveOptions(opt));
  Columns c;
  for (int pass = 0; pass < 2; ++pass)
    for (const std::string& n : names) {
      const int i = table.Require(n);
      const bool machine = i < table.num_machine();
      if (machine != (pass == 0)) continue;
      c.names.push_back(n);
      c.table_index.push_back(i);
      if (machine) ++c.n_machine;
    }
  return c;
}

Eigen::VectorXd ValueVector(const ParameterTable& table, const DesignOptions& opt) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : opt.values) {
    RequireFinite(value, "values." + name);
    v[table.Require(name)] = value;
  }
  return v;
}

void CheckOptions(const DesignOptions& o) {
  if (!(o.sigma > 0) || !std::isfinite(o.sigma))
    throw std::invalid_argument("design: sigma must be > 0 mm");
  if (!(o.characteristic_length > 0) || !std::isfinite(o.characteristic_length))
    throw std::invalid_argument("design: characteristic_length must be > 0 mm");
  if (!(o.rank_tolerance > 0) || o.rank_tolerance >= 1)
    throw std::invalid_argument("design: rank_tolerance must be in (0, 1)");
}

}  // namespace

// ---- Characteristic scales ---------------------------------------------------

double CharacteristicScale(const Machine& m, const std::string& name, double L) {
  const int i = m.ParameterIndex(name);
  if (i < 0) return 1.0;  // setup parameters are all mm
  const ParameterInfo& p = m.parameters()[i];
  switch (p.kind) {
    case ParameterKind::kTip:
      return 1.0;
    case ParameterKind::kBacklash:
      return m.axis(p.axis).rotary() ? L : 1.0;
    case ParameterKind::kLocation:
      return p.component >= 3 ? L : 1.0;
    case ParameterKind::kMotion: {
      const bool angular = p.component >= 3;
      if (m.axis(p.axis).rotary()) return angular ? L : 1.0;
      return std::pow(L, p.degree + (angular ? 1 : 0));
    }
  }
  return 1.0;
}

// ---- PlanQuality ---------------------------------------------------------------

std::string PlanQuality::ToJson() const {
  json j;
  j["parameters"] = parameters;
  j["n_observations"] = n_observations;
  j["n_rows"] = n_rows;
  j["n_parameters"] = n_parameters;
  j["n_machine"] = n_machine;
  j["condition_number"] = Finite(condition_number);
  j["rank"] = rank;
  j["log_det_per_parameter"] = Finite(log_det_per_parameter);
  j["d_criterion"] = Finite(d_criterion);
  j["d_std"] = Finite(d_std);
  json s = json::object();
  for (int i = 0; i < predicted_std.size() && i < static_cast<int>(parameters.size()); ++i)
    s[parameters[i]] = Finite(predicted_std[i]);
  j["predicted_std"] = s;
  j["confounded"] = confounded;
  return j.dump();
}

std::string DesignResult::ToJson() const {
  json j;
  j["groups"] = groups;
  j["observations"] = observations;
  j["quality"] = json::parse(quality.ToJson());
  j["reference"] = json::parse(reference.ToJson());
  json h = json::array();
  for (double x : history) h.push_back(Finite(x));
  j["history"] = h;
  j["evaluations"] = evaluations;
  j["stopped"] = stopped;
  return j.dump();
}

// ---- AssessPlan ------------------------------------------------------------------

namespace {

PlanQuality AssessColumns(const Dataset& given_ds, const DesignOptions& opt, const Columns& cols,
                          const ParameterTable& table) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  PlanQuality q;
  q.parameters = cols.names;
  q.n_parameters = static_cast<int>(cols.names.size());
  q.n_machine = cols.n_machine;
  q.n_observations = static_cast<int>(ds.observations.size());
  const Eigen::VectorXd values = ValueVector(table, opt);
  Problem problem(ds, table, values, cols.table_index);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  problem.Evaluate(&r, &J);
  q.n_rows = static_cast<int>(J.rows());
  const Identifiability id = AnalyzeJacobian(J, opt.rank_tolerance);
  q.condition_number = id.condition_number;
  q.rank = id.rank;
  q.log_det_per_parameter = id.log_det_per_parameter;
  // identify weights each row by its declared noise: a touch that declares a
  // sigma keeps it, an undeclared touch gets opt.sigma (the plan's assumed probe
  // noise), a scale bar its own (its length is calibrated, not probed). Predicted
  // uncertainties must use the same weights to be the ones identify reports.
  Eigen::VectorXd row_sigma = problem.row_sigma();
  for (int i = 0; i < row_sigma.size(); ++i) {
    const int s = problem.row_source()[i];
    if (s >= 0 && ds.observations[s].sigma.size() == 0) row_sigma[i] = opt.sigma;
  }
  const Eigen::MatrixXd Jw = row_sigma.cwiseInverse().asDiagonal() * J;
  q.predicted_std = AnalyzeJacobian(Jw, opt.rank_tolerance).inverse_normal.diagonal().cwiseMax(0.0).cwiseSqrt();
  // A pseudo-inverse says nothing about confounded parameters.
  for (const auto& g : id.confounded) {
    std::vector<std::string> names;
    for (int c : g) {
      names.push_back(cols.names[c]);
      q.predicted_std[c] = kInf;
    }
    q.confounded.push_back(names);
  }
  std::vector<int> active(q.n_parameters);
  std::vector<bool> machine(q.n_parameters);
  Eigen::VectorXd scale(q.n_parameters);
  for (int i = 0; i < q.n_parameters; ++i) {
    active[i] = i;
    machine[i] = i < cols.n_machine;
    scale[i] = CharacteristicScale(ds.machine(), cols.names[i], opt.characteristic_length);
  }
  if (id.rank == q.n_parameters) {
    const Eigen::MatrixXd A = J.transpose() * J;
    const Score s = Evaluate(A, active, machine, scale, opt.rank_tolerance, true);
    q.d_criterion = s.dcrit;
  } else {
    q.d_criterion = -kInf;
  }
  q.d_std = std::isfinite(q.d_criterion) ? opt.sigma * std::exp(-0.5 * q.d_criterion) : kInf;
  return q;
}

}  // namespace

PlanQuality AssessPlan(const Dataset& given_ds, const DesignOptions& opt, const std::vector<int>* subset) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  CheckOptions(opt);
  if (subset) {
    const Dataset sub = ds.Subset(*subset);
    return AssessPlan(sub, opt, nullptr);
  }
  ds.Validate();
  const ParameterTable table(ds);
  const Columns cols = ResolveColumns(ds, table, opt);
  return AssessColumns(ds, opt, cols, table);
}

// ---- DesignPlan ------------------------------------------------------------------

namespace {

// The candidate pool: Jacobian rows per observation over every column the
// pool's estimated set has, and what each observation activates.
class Pool {
 public:
  Pool(const Dataset& ds, const DesignOptions& opt) : ds_(ds), table_(ds) {
    cols_ = ResolveColumns(ds, table_, opt);
    p_ = static_cast<int>(cols_.names.size());
    const Eigen::VectorXd values = ValueVector(table_, opt);
    Problem problem(ds, table_, values, cols_.table_index);
    Eigen::VectorXd r;
    problem.Evaluate(&r, &J_);
    const int n = static_cast<int>(ds.observations.size());
    rows_.assign(n, {});
    bars_.assign(ds.artefact.scale_bars.size(), {});
    const auto& src = problem.row_source();
    for (int row = 0; row < static_cast<int>(src.size()); ++row) {
      if (src[row] >= 0) rows_[src[row]].push_back(row);
      else bars_[-1 - src[row]].push_back(row);
    }
    machine_.assign(p_, false);
    scale_.resize(p_);
    std::map<std::string, int> col_of;
    for (int c = 0; c < p_; ++c) {
      machine_[c] = c < cols_.n_machine;
      scale_[c] = CharacteristicScale(ds.machine(), cols_.names[c], opt.characteristic_length);
      col_of[cols_.names[c]] = c;
    }
    // Activation: the default-setup columns a lone observation implies (same
    // rule as ParameterTable::DefaultSetup), cached per (type, target, setup).
    std::set<int> default_full;
    for (int i : table_.DefaultSetup(ds)) default_full.insert(i);
    core_.clear();
    for (int c = 0; c < p_; ++c)
      if (!default_full.count(cols_.table_index[c])) core_.push_back(c);
    // A setup column no row shares with another setup column (a facet) has
    // J^T J zero against every other setup column in any selection.
    isolated_.assign(p_, false);
    std::vector<int> shared(p_, 0);
    for (int row = 0; row < J_.rows(); ++row) {
      int nz = 0;
      for (int c = cols_.n_machine; c < p_; ++c) nz += J_(row, c) != 0;
      if (nz > 1)
        for (int c = cols_.n_machine; c < p_; ++c)
          if (J_(row, c) != 0) shared[c] = 1;
    }
    for (int c = cols_.n_machine; c < p_; ++c) isolated_[c] = !shared[c];
    activates_.assign(n, {});
    sphere_of_.assign(n, -1);
    std::map<std::tuple<int, std::string, std::string>, std::vector<int>> cache;
    for (int i = 0; i < n; ++i) {
      const Observation& o = ds.observations[i];
      if (o.type == ObservationType::kSphere) sphere_of_[i] = ds.artefact.SphereIndex(o.data<TouchData>().target);
      const auto key = std::make_tuple(static_cast<int>(o.type), PayloadTarget(o), o.setup);
      auto it = cache.find(key);
      if (it == cache.end()) {
        const Dataset one = ds.Subset({i});
        const ParameterTable t1(one);
        std::vector<int> act;
        for (int k : t1.DefaultSetup(one)) {
          auto c = col_of.find(t1.names()[k]);
          if (c != col_of.end() && default_full.count(cols_.table_index[c->second])) act.push_back(c->second);
        }
        it = cache.emplace(key, act).first;
      }
      activates_[i] = it->second;
    }
    bar_M_.resize(bars_.size());
    for (size_t b = 0; b < bars_.size(); ++b) {
      const ScaleBar& bar = ds.artefact.scale_bars[b];
      bar_spheres_.push_back({ds.artefact.SphereIndex(bar.sphere1), ds.artefact.SphereIndex(bar.sphere2)});
      bar_M_[b] = Info(bars_[b]);
    }
  }

  Eigen::MatrixXd Info(const std::vector<int>& rows) const {
    Eigen::MatrixXd Jr(rows.size(), p_);
    for (size_t k = 0; k < rows.size(); ++k) Jr.row(k) = J_.row(rows[k]);
    return Jr.transpose() * Jr;
  }
  Eigen::MatrixXd ObsInfo(int i) const { return Info(rows_[i]); }

  const Dataset& ds_;
  ParameterTable table_;
  Columns cols_;
  int p_ = 0;
  Eigen::MatrixXd J_;
  std::vector<std::vector<int>> rows_, bars_;
  std::vector<bool> machine_;
  Eigen::VectorXd scale_;
  std::vector<int> core_;
  std::vector<bool> isolated_;
  std::vector<std::vector<int>> activates_;
  std::vector<int> sphere_of_;
  std::vector<Eigen::MatrixXd> bar_M_;
  std::vector<std::pair<int, int>> bar_spheres_;
};

// A selection: its information matrix (bars included when both balls are
// probed) and the activation counts.
struct State {
  Eigen::MatrixXd M;
  std::vector<int> col_count;
  std::vector<int> sphere_count;
  std::vector<bool> bar_in;
};

// What the fast D-criterion path needs from the selection a step's candidates
// are built on (the greedy state, the exchange state without one group, the
// touch-budget state): computed once per step, so that a candidate's score
// costs one sparse elimination instead of an eigen-decomposition.
struct Reference {
  bool usable = false;       // full rank with a margin: candidates can be certified
  std::vector<int> pos;      // column -> position in `active`, -1 if inactive
  std::vector<int> active;   // ascending
  Eigen::VectorXd d;         // diagonal of M on `active`
  double lmin = 0;           // lower bound on the smallest eigenvalue of the scaled M
  double logdet = 0;         // log det of the scaled M
  Eigen::MatrixXd inv;       // inverse of the scaled M (removals only)
};

class Selection {
 public:
  Selection(const Pool& pool, const DesignOptions& opt, const SearchOptions& search)
      : pool_(pool), tol_(std::max(opt.rank_tolerance, 1e-7)), want_d_(search.criterion == "d") {
    is_core_.assign(pool_.p_, false);
    for (int c : pool_.core_) is_core_[c] = true;
    log_scale2_.resize(pool_.p_);
    for (int c = 0; c < pool_.p_; ++c) log_scale2_[c] = 2.0 * std::log(pool_.scale_[c]);
  }

  State Empty() const {
    State s;
    s.M = Eigen::MatrixXd::Zero(pool_.p_, pool_.p_);
    s.col_count.assign(pool_.p_, 0);
    s.sphere_count.assign(pool_.ds_.artefact.spheres.size(), 0);
    s.bar_in.assign(pool_.bars_.size(), false);
    return s;
  }

  // Adds (sign +1) or removes (-1) observations; `info` is their summed J^T J.
  void Apply(State* s, const std::vector<int>& obs, const Eigen::MatrixXd& info, int sign) const {
    s->M += sign * info;
    for (int i : obs) {
      for (int c : pool_.activates_[i]) s->col_count[c] += sign;
      if (pool_.sphere_of_[i] >= 0) s->sphere_count[pool_.sphere_of_[i]] += sign;
    }
    for (size_t b = 0; b < pool_.bars_.size(); ++b) {
      const auto [s1, s2] = pool_.bar_spheres_[b];
      const bool in = s->sphere_count[s1] > 0 && s->sphere_count[s2] > 0;
      if (in != s->bar_in[b]) {
        s->M += (in ? 1.0 : -1.0) * pool_.bar_M_[b];
        s->bar_in[b] = in;
      }
    }
  }

  std::vector<int> Active(const std::vector<int>& col_count) const {
    std::vector<int> active = pool_.core_;
    for (int c = 0; c < pool_.p_; ++c)
      if (col_count[c] > 0) active.push_back(c);
    std::sort(active.begin(), active.end());
    return active;
  }

  // The exact score: eigenvalues of the scaled information matrix.
  Score Eval(const State& s) const {
    ++evaluations;
    return Evaluate(s.M, Active(s.col_count), pool_.machine_, pool_.scale_, tol_, want_d_);
  }

  // `removals`: the step's candidates remove observations (else they add).
  Reference Refer(const State& s, bool removals) const {
    Reference r;
    if (!want_d_) return r;
    r.active = Active(s.col_count);
    const int n = static_cast<int>(r.active.size());
    if (n == 0) return r;
    r.pos.assign(pool_.p_, -1);
    r.d.resize(n);
    for (int i = 0; i < n; ++i) {
      r.pos[r.active[i]] = i;
      r.d[i] = s.M(r.active[i], r.active[i]);
      if (!(r.d[i] > 0) || !std::isfinite(r.d[i])) return r;
    }
    Eigen::MatrixXd Ms(n, n);
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        Ms(i, j) = s.M(r.active[i], r.active[j]) / std::sqrt(r.d[i] * r.d[j]);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ms, Eigen::EigenvaluesOnly);
    const Eigen::VectorXd& lam = es.eigenvalues();
    // The computed eigenvalues are within a few n eps lambda_max of the true ones.
    r.lmin = lam[0] - 64.0 * n * std::numeric_limits<double>::epsilon() * lam[n - 1];
    if (!(r.lmin > tol_ * tol_ * lam[n - 1]) || !std::isfinite(lam[n - 1])) return r;
    r.logdet = lam.array().log().sum();
    if (removals) {
      Eigen::LLT<Eigen::MatrixXd> llt(Ms);
      if (llt.info() != Eigen::Success) return r;
      r.inv = llt.solve(Eigen::MatrixXd::Identity(n, n));
    }
    r.usable = true;
    return r;
  }

  // The score of `base` changed by `obs` (sign +1 added, -1 removed; `info`
  // their summed J^T J), equal to Eval of that selection; `fast` says whether
  // the eigen-decomposition was avoided.
  Score Candidate(const State& base, const Reference& ref, const std::vector<int>& obs,
                  const Eigen::MatrixXd& info, int sign, bool* fast = nullptr) const {
    Score s;
    const bool ok = want_d_ && ref.usable && FastD(base, ref, obs, info, sign, &s);
    if (fast) *fast = ok;
    if (ok) {
      ++evaluations;
      return s;
    }
    State t = base;
    Apply(&t, obs, info, sign);
    return Eval(t);
  }

  // Strict ordering: lower is better.
  double Value(const Score& s) const { return want_d_ ? -s.dcrit : std::log(s.cond); }
  bool Better(const Score& a, const Score& b) const {
    if (a.deficiency != b.deficiency) return a.deficiency < b.deficiency;
    if (a.deficiency > 0) return a.nonnull > b.nonnull + 1e-12;
    const double va = Value(a), vb = Value(b);
    return va < vb - 1e-9 * std::max(1.0, std::abs(vb));
  }
  double Report(const Score& s) const {
    if (s.deficiency > 0) return want_d_ ? -kInf : kInf;
    return want_d_ ? s.dcrit : s.cond;
  }

  const Pool& pool_;
  double tol_;
  bool want_d_;
  mutable int evaluations = 0;

 private:
  // The D-criterion of a full-rank candidate without an eigen-decomposition,
  // and without copying the state.
  //
  // With the active columns ordered setup first, the pivots of an LDL^T
  // elimination of the scaled information matrix Ms give both log det(Ms)
  // and log det(Ms_ss) (the leading ones), so the log det of the Schur
  // complement on the machine columns is the sum of the log machine pivots:
  // Evaluate's log det(Ms) - log det(Ms_ss) without either. Most setup
  // columns are isolated (a facet: no row touches another setup column), so
  // they are eliminated first, together, as one rank update of the machine
  // block; the coupled ones (sphere centres, joined by the scale bar) and the
  // machine block are eliminated densely.
  //
  // Evaluate counts an eigenvalue below tol^2 lambda_max as a null direction;
  // positive pivots do not show that, so full rank is certified by a lower
  // bound on lambda_min (from the step's reference, whose eigenvalues are
  // known) above tol^2 ||Ms||_F >= tol^2 lambda_max, with a factor 2 and a
  // 1e-10 ||Ms||_F margin, far above the rounding of either computation.
  // Returns false (the caller then takes the eigen path) when the bound does
  // not certify, a pivot is not positive or a column has no information.
  bool FastD(const State& base, const Reference& ref, const std::vector<int>& obs, const Eigen::MatrixXd& info,
             int sign, Score* out) const {
    const int p = pool_.p_;
    cnt_ = base.col_count;
    sph_ = base.sphere_count;
    for (int i : obs) {
      for (int c : pool_.activates_[i]) cnt_[c] += sign;
      if (pool_.sphere_of_[i] >= 0) sph_[pool_.sphere_of_[i]] += sign;
    }
    bars_.clear();
    for (size_t b = 0; b < pool_.bars_.size(); ++b) {
      const auto [s1, s2] = pool_.bar_spheres_[b];
      const bool in = sph_[s1] > 0 && sph_[s2] > 0;
      if (in != base.bar_in[b]) bars_.push_back({static_cast<int>(b), in ? 1.0 : -1.0});
    }
    // Entries of the candidate's matrix, summed in Apply's order.
    auto entry = [&](int r, int c) {
      double v = base.M(r, c) + sign * info(r, c);
      for (const auto& [b, w] : bars_) v += w * pool_.bar_M_[b](r, c);
      return v;
    };
    // Isolated setup columns first, the other setup columns, the machine ones.
    order_.clear();
    int pm = 0, nd = 0;
    for (int pass = 0; pass < 3; ++pass)
      for (int c = 0; c < p; ++c) {
        if (!(is_core_[c] || cnt_[c] > 0)) continue;
        const int kind = pool_.machine_[c] ? 2 : pool_.isolated_[c] ? 0 : 1;
        if (kind != pass) continue;
        order_.push_back(c);
        if (kind == 0) ++nd;
        if (kind == 2) ++pm;
      }
    const int n = static_cast<int>(order_.size());
    const int ns = n - pm;
    if (pm == 0) return false;
    dv_.resize(n);
    sv_.resize(n);
    LogSum log_d;
    double shift = 0;
    for (int k = 0; k < n; ++k) {
      dv_[k] = entry(order_[k], order_[k]);
      if (!(dv_[k] > 0) || !std::isfinite(dv_[k])) return false;
      sv_[k] = 1.0 / std::sqrt(dv_[k]);
      if (k >= ns) {
        log_d.Add(dv_[k]);
        shift += log_scale2_[order_[k]];
      }
    }
    shift += log_d.Get();
    // Scaled entries of the isolated columns: only their diagonals and machine
    // rows are nonzero. X holds the machine rows divided by sqrt(pivot).
    LogSum log_s, log_m;
    double fro2 = 0;
    X_.resize(pm, nd);
    const int* om = &order_[ns];
    const double* sm = &sv_[ns];
    const double sg = sign;
    // The machine columns come first in the pool: usually all active, rows 0..pm-1.
    const bool dense = om[pm - 1] == pm - 1;
    for (int t = 0; t < nd; ++t) {
      const int c = order_[t];
      const double* m = &base.M(0, c);
      const double* a = &info(0, c);
      double* x = &X_(0, t);
      if (dense) {
        for (int i = 0; i < pm; ++i) x[i] = m[i] + sg * a[i];
      } else {
        for (int i = 0; i < pm; ++i) x[i] = m[om[i]] + sg * a[om[i]];
      }
      for (const auto& [bar, w] : bars_) {
        const double* e = &pool_.bar_M_[bar](0, c);
        for (int i = 0; i < pm; ++i) x[i] += w * e[om[i]];
      }
      const double piv = dv_[t] * sv_[t] * sv_[t];
      if (!(piv > 0)) return false;
      log_s.Add(piv);
      const double st = sv_[t];
      for (int i = 0; i < pm; ++i) x[i] = x[i] * sm[i] * st;
      fro2 += piv * piv + 2.0 * X_.col(t).squaredNorm();
      X_.col(t) /= std::sqrt(piv);
    }
    // The other setup columns and the machine ones: lower triangle, column-major.
    const int nr = n - nd;
    W_.resize(nr, nr);
    for (int j = 0; j < nr; ++j) {
      const int c = order_[nd + j];
      const int* o = &order_[nd];
      const double* m = &base.M(0, c);
      const double* a = &info(0, c);
      double* wj = &W_(0, j);
      for (int i = j; i < nr; ++i) wj[i] = m[o[i]] + sg * a[o[i]];
      for (const auto& [bar, w] : bars_) {
        const double* e = &pool_.bar_M_[bar](0, c);
        for (int i = j; i < nr; ++i) wj[i] += w * e[o[i]];
      }
      const double* sv = &sv_[nd];
      const double sj = sv[j];
      for (int i = j; i < nr; ++i) wj[i] = wj[i] * sv[i] * sj;
      fro2 += 2.0 * W_.col(j).segment(j + 1, nr - j - 1).squaredNorm() + wj[j] * wj[j];
    }
    // The isolated columns' rank-1 updates reach only the machine block (and
    // do not change each other's pivots): one rank update.
    const int nc = nr - pm;
    if (nd > 0) W_.block(nc, nc, pm, pm).selfadjointView<Eigen::Lower>().rankUpdate(X_, -1.0);
    for (int k = 0; k < nr; ++k) {
      const double* wk = &W_(0, k);
      const double piv = wk[k];
      if (!(piv > 0) || !std::isfinite(piv)) return false;
      (k >= nc ? log_m : log_s).Add(piv);
      for (int j = k + 1; j < nr; ++j) {
        if (wk[j] == 0) continue;
        const double f = wk[j] / piv;
        double* wj = &W_(0, j);
        for (int i = j; i < nr; ++i) wj[i] -= f * wk[i];
      }
    }
    const double logdet_m = log_m.Get(), logdet_all = log_s.Get() + logdet_m;
    const double bound = sign > 0 ? AddedBound(base, ref, info) : RemovedBound(ref, logdet_all);
    const double fro = std::sqrt(fro2);
    if (!(0.5 * bound > (tol_ * tol_ + 1e-10) * fro)) return false;
    out->deficiency = 0;
    out->dcrit = (logdet_m + shift) / pm;
    return true;
  }

  // Candidate = reference + B (B >= 0: the added rows and bars), on the
  // reference's columns plus new ones N. With [N, old] blocks and candidate
  // scaling, Ms = T^T diag(P, S) T, T = [I K; 0 I], K = P^-1 Q, and the Schur
  // complement S >= E Ms_ref E, E^2 = d_ref / d (B's own Schur complement is
  // >= 0). So lambda_min(Ms) >= min(lambda_min(P), lambda_min(Ms_ref) min E^2)
  // / (1 + ||K||)^2, less the norm of what the reference holds on N (rounding
  // left by earlier removals; zero in exact arithmetic for touch columns).
  double AddedBound(const State& base, const Reference& ref, const Eigen::MatrixXd& info) const {
    const int n = static_cast<int>(order_.size());
    double ratio = kInf;
    newk_.clear();
    oldk_.clear();
    for (int k = 0; k < n; ++k) {
      const int i = ref.pos[order_[k]];
      if (i < 0) {
        newk_.push_back(k);
      } else {
        oldk_.push_back(k);
        ratio = std::min(ratio, ref.d[i] / dv_[k]);
      }
    }
    double b = ref.lmin * ratio;
    if (newk_.empty()) return b;
    // Read down the new columns (contiguous: the matrices are symmetric).
    auto added = [&](int r, int c) {
      double v = info(r, c);
      for (const auto& [bar, w] : bars_) v += w * pool_.bar_M_[bar](r, c);
      return v;
    };
    const int nn = static_cast<int>(newk_.size()), no = static_cast<int>(oldk_.size());
    P_.resize(nn, nn);
    Q_.resize(nn, no);
    double e2 = 0;
    for (int a = 0; a < nn; ++a) {
      const int ka = newk_[a], ca = order_[ka];
      for (int c = 0; c < nn; ++c) {
        const int kc = newk_[c];
        const double s = sv_[ka] * sv_[kc];
        P_(a, c) = added(order_[kc], ca) * s;
        const double e = base.M(order_[kc], ca) * s;
        e2 += e * e;
      }
      for (int c = 0; c < no; ++c) {
        const int kc = oldk_[c];
        const double s = sv_[ka] * sv_[kc];
        Q_(a, c) = added(order_[kc], ca) * s;
        const double e = base.M(order_[kc], ca) * s;
        e2 += 2.0 * e * e;
      }
    }
    Eigen::LLT<Eigen::MatrixXd> llt(P_);
    if (llt.info() != Eigen::Success) return 0;
    Eigen::MatrixXd Linv = Eigen::MatrixXd::Identity(nn, nn);
    llt.matrixL().solveInPlace(Linv);
    const double lmin_p = 1.0 / Linv.squaredNorm();  // 1 / trace(P^-1) <= lambda_min(P)
    const double k = llt.solve(Q_).norm();            // ||K||_F >= ||K||_2
    b = std::min(b, lmin_p) / ((1.0 + k) * (1.0 + k));
    return b - std::sqrt(e2);
  }

  // Candidate = reference - B (B >= 0) on a subset of the reference's columns
  // (R dropped). In the reference's scaling Y <= Ms_ref restricted, so every
  // eigenvalue of Y is at most the restriction's, and
  //   lambda_min(Y) >= det(Y) lambda_min(Ms_ref) / det(Ms_ref restricted),
  //   det(Ms_ref restricted) = det(Ms_ref) det((Ms_ref^-1)_RR);
  // the candidate's scaling multiplies lambda_min by at least min d_ref / d.
  double RemovedBound(const Reference& ref, double logdet) const {
    const int n = static_cast<int>(order_.size());
    double log_ratio = 0, ratio = kInf;
    std::vector<bool> kept(ref.active.size(), false);
    for (int k = 0; k < n; ++k) {
      const int i = ref.pos[order_[k]];
      if (i < 0) return 0;  // a removal cannot activate a column
      kept[i] = true;
      log_ratio += std::log(dv_[k] / ref.d[i]);
      ratio = std::min(ratio, ref.d[i] / dv_[k]);
    }
    std::vector<int> dropped;
    for (size_t i = 0; i < kept.size(); ++i)
      if (!kept[i]) dropped.push_back(static_cast<int>(i));
    double logdet_rr = 0;
    if (!dropped.empty()) {
      if (ref.inv.rows() != static_cast<int>(ref.active.size())) return 0;
      const int nr = static_cast<int>(dropped.size());
      Eigen::MatrixXd Rr(nr, nr);
      for (int a = 0; a < nr; ++a)
        for (int c = 0; c < nr; ++c) Rr(a, c) = ref.inv(dropped[a], dropped[c]);
      Eigen::LLT<Eigen::MatrixXd> llt(Rr);
      if (llt.info() != Eigen::Success) return 0;
      for (int a = 0; a < nr; ++a) logdet_rr += 2.0 * std::log(llt.matrixL()(a, a));
    }
    const double lb = logdet + log_ratio + std::log(ref.lmin) - ref.logdet - logdet_rr + std::log(ratio);
    return std::isfinite(lb) ? std::exp(lb) : 0;
  }

  std::vector<bool> is_core_;
  std::vector<double> log_scale2_;
  // Workspace of FastD (one search at a time per Selection).
  mutable std::vector<int> cnt_, sph_, order_, newk_, oldk_;
  mutable std::vector<std::pair<int, double>> bars_;
  mutable Eigen::VectorXd dv_, sv_;
  mutable Eigen::MatrixXd W_, X_, P_, Q_;
};

}  // namespace

DesignResult DesignPlan(const Dataset& given_ds, const std::vector<int>& group, const DesignOptions& opt,
                        const SearchOptions& search) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  CheckOptions(opt);
  ds.Validate();
  const int n = static_cast<int>(ds.observations.size());
  if (static_cast<int>(group.size()) != n)
    throw std::invalid_argument("design: " + std::to_string(group.size()) + " group labels for " +
                                std::to_string(n) + " candidate observations");
  int G = 0;
  for (int i = 0; i < n; ++i) {
    if (group[i] < 0)
      throw std::invalid_argument("design: group of observation " + std::to_string(i) + " is negative");
    G = std::max(G, group[i] + 1);
  }
  std::vector<std::vector<int>> members(G);
  for (int i = 0; i < n; ++i) members[group[i]].push_back(i);
  for (int g = 0; g < G; ++g)
    if (members[g].empty()) throw std::invalid_argument("design: group " + std::to_string(g) + " has no observation");
  if (search.k < 1 || search.k > G)
    throw std::invalid_argument("design: k = " + std::to_string(search.k) + " must be between 1 and the " +
                                std::to_string(G) + " candidate indexations");
  if (search.criterion != "condition" && search.criterion != "d")
    throw std::invalid_argument("design: criterion '" + search.criterion + "' (condition or d)");
  if (search.method != "greedy" && search.method != "exchange")
    throw std::invalid_argument("design: method '" + search.method + "' (greedy or exchange)");
  if (search.max_touches < 0) throw std::invalid_argument("design: max_touches must be >= 0");
  std::set<int> required(search.required.begin(), search.required.end());
  for (int g : required)
    if (g < 0 || g >= G) throw std::invalid_argument("design: required group " + std::to_string(g) + " out of range");
  if (static_cast<int>(required.size()) > search.k)
    throw std::invalid_argument("design: more required indexations than k");

  const Pool pool(ds, opt);
  const Selection sel(pool, opt, search);
  std::vector<Eigen::MatrixXd> info(G);
  for (int g = 0; g < G; ++g) info[g] = pool.Info([&] {
    std::vector<int> rows;
    for (int i : members[g]) rows.insert(rows.end(), pool.rows_[i].begin(), pool.rows_[i].end());
    return rows;
  }());

  DesignResult res;
  auto report = [&](const std::string& phase, int done, int total, double best) {
    if (search.progress && !search.progress(phase, done, total, best)) res.stopped = true;
    return !res.stopped;
  };

  // Forward greedy.
  std::vector<bool> chosen(G, false);
  State state = sel.Empty();
  for (int g : required) {
    sel.Apply(&state, members[g], info[g], +1);
    chosen[g] = true;
  }
  Score best = sel.Eval(state);
  int count = static_cast<int>(required.size());
  while (count < search.k && !res.stopped) {
    int pick = -1;
    Score pick_score;
    const Reference ref = sel.Refer(state, false);
    for (int g = 0; g < G; ++g) {
      if (chosen[g]) continue;
      const Score s = sel.Candidate(state, ref, members[g], info[g], +1);
      if (pick < 0 || sel.Better(s, pick_score)) {
        pick = g;
        pick_score = s;
      }
    }
    sel.Apply(&state, members[pick], info[pick], +1);
    chosen[pick] = true;
    best = pick_score;
    ++count;
    res.history.push_back(sel.Report(best));
    report("greedy", count, search.k, sel.Report(best));
  }

  // Exchange passes.
  if (search.method == "exchange") {
    for (int pass = 0; pass < search.max_passes && !res.stopped; ++pass) {
      int out = -1, in = -1;
      Score swap_score = best;
      for (int g = 0; g < G && !res.stopped; ++g) {
        if (!chosen[g] || required.count(g)) continue;
        State without = state;
        sel.Apply(&without, members[g], info[g], -1);
        const Reference ref = sel.Refer(without, false);
        for (int h = 0; h < G; ++h) {
          if (chosen[h]) continue;
          const Score s = sel.Candidate(without, ref, members[h], info[h], +1);
          if (sel.Better(s, swap_score)) {
            out = g;
            in = h;
            swap_score = s;
          }
        }
      }
      if (out < 0) break;
      sel.Apply(&state, members[out], info[out], -1);
      sel.Apply(&state, members[in], info[in], +1);
      chosen[out] = false;
      chosen[in] = true;
      best = swap_score;
      res.history.push_back(sel.Report(best));
      report("exchange", pass + 1, search.max_passes, sel.Report(best));
    }
  }

  std::vector<int> obs;
  for (int g = 0; g < G; ++g)
    if (chosen[g]) {
      res.groups.push_back(g);
      obs.insert(obs.end(), members[g].begin(), members[g].end());
    }

  // Touch budget: drop the touch whose removal hurts least, one at a time.
  if (search.max_touches > 0 && static_cast<int>(obs.size()) > search.max_touches) {
    std::vector<Eigen::MatrixXd> oinfo(n);
    for (int i : obs) oinfo[i] = pool.ObsInfo(i);
    const int total = static_cast<int>(obs.size()) - search.max_touches;
    int done = 0;
    while (static_cast<int>(obs.size()) > search.max_touches && !res.stopped) {
      int drop = -1;
      Score drop_score;
      const Reference ref = sel.Refer(state, true);
      for (size_t k = 0; k < obs.size(); ++k) {
        const Score s = sel.Candidate(state, ref, {obs[k]}, oinfo[obs[k]], -1);
        if (drop < 0 || sel.Better(s, drop_score)) {
          drop = static_cast<int>(k);
          drop_score = s;
        }
      }
      sel.Apply(&state, {obs[drop]}, oinfo[obs[drop]], -1);
      obs.erase(obs.begin() + drop);
      best = drop_score;
      res.history.push_back(sel.Report(best));
      report("touches", ++done, total, sel.Report(best));
    }
    // An indexation may have lost all its touches.
    std::set<int> left;
    for (int i : obs) left.insert(group[i]);
    res.groups.assign(left.begin(), left.end());
  }
  std::sort(obs.begin(), obs.end());
  res.observations = obs;
  res.evaluations = sel.evaluations;

  // Exact assessment of the chosen plan and of the pool, on the pool's
  // resolved parameter set (machine part) so both are comparable.
  DesignOptions fixed = opt;
  fixed.estimate.assign(pool.cols_.names.begin(), pool.cols_.names.begin() + pool.cols_.n_machine);
  fixed.fix.clear();
  {
    // keep explicitly requested non-default setup parameters too
    std::set<int> default_full;
    for (int i : pool.table_.DefaultSetup(ds)) default_full.insert(i);
    for (int c = pool.cols_.n_machine; c < pool.p_; ++c)
      if (!default_full.count(pool.cols_.table_index[c])) fixed.estimate.push_back(pool.cols_.names[c]);
    // and the pool's exclusions of default setup parameters, the probe tip's
    // offsets among them although the table counts them as machine columns
    // (filtering on the setup part let a fixed tip back in)
    fixed.fix = opt.fix;
  }
  res.quality = AssessPlan(ds, fixed, &res.observations);
  res.reference = AssessPlan(ds, fixed, nullptr);
  return res;
}

namespace internal {

std::vector<ScoreCheck> CheckDesignScores(const Dataset& given_ds, const std::vector<int>& group, const DesignOptions& opt,
                                          int states, unsigned seed) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  CheckOptions(opt);
  ds.Validate();
  if (group.size() != ds.observations.size() || std::any_of(group.begin(), group.end(), [](int g) { return g < 0; }))
    throw std::invalid_argument("design: one group label >= 0 per candidate observation");
  const Pool pool(ds, opt);
  SearchOptions search;
  search.criterion = "d";
  const Selection sel(pool, opt, search);
  int G = 0;
  for (int g : group) G = std::max(G, g + 1);
  std::vector<std::vector<int>> members(G);
  for (size_t i = 0; i < group.size(); ++i) members[group[i]].push_back(static_cast<int>(i));
  std::vector<Eigen::MatrixXd> info(G);
  for (int g = 0; g < G; ++g) {
    std::vector<int> rows;
    for (int i : members[g]) rows.insert(rows.end(), pool.rows_[i].begin(), pool.rows_[i].end());
    info[g] = pool.Info(rows);
  }
  std::mt19937 rng(seed);
  std::vector<ScoreCheck> out;
  auto record = [&](const Score& f, bool fast, const Score& e, bool removal) {
    ScoreCheck c;
    c.fast = f.deficiency > 0 ? -kInf : f.dcrit;
    c.exact = e.deficiency > 0 ? -kInf : e.dcrit;
    c.fast_deficiency = f.deficiency;
    c.exact_deficiency = e.deficiency;
    c.fast_path = fast;
    c.removal = removal;
    out.push_back(c);
  };
  for (int t = 0; t < states; ++t) {
    std::vector<int> order(G);
    for (int g = 0; g < G; ++g) order[g] = g;
    std::shuffle(order.begin(), order.end(), rng);
    const int k = std::uniform_int_distribution<int>(1, std::max(1, std::min(G - 3, 12)))(rng);
    // Two extra groups added and removed again leave the rounding an exchange leaves.
    State state = sel.Empty();
    for (int i = 0; i < k + 2 && i < G; ++i) sel.Apply(&state, members[order[i]], info[order[i]], +1);
    for (int i = k; i < k + 2 && i < G; ++i) sel.Apply(&state, members[order[i]], info[order[i]], -1);
    const Reference add = sel.Refer(state, false);
    for (int i = k; i < std::min(G, k + 6); ++i) {
      const int g = order[i];
      bool fast = false;
      const Score f = sel.Candidate(state, add, members[g], info[g], +1, &fast);
      State x = state;
      sel.Apply(&x, members[g], info[g], +1);
      record(f, fast, sel.Eval(x), false);
    }
    std::vector<int> obs;
    for (int i = 0; i < k; ++i) obs.insert(obs.end(), members[order[i]].begin(), members[order[i]].end());
    std::shuffle(obs.begin(), obs.end(), rng);
    const Reference rem = sel.Refer(state, true);
    for (size_t i = 0; i < obs.size() && i < 6; ++i) {
      const Eigen::MatrixXd oi = pool.ObsInfo(obs[i]);
      bool fast = false;
      const Score f = sel.Candidate(state, rem, {obs[i]}, oi, -1, &fast);
      State x = state;
      sel.Apply(&x, {obs[i]}, oi, -1);
      record(f, fast, sel.Eval(x), true);
    }
  }
  return out;
}

}  // namespace internal

// ---- Candidate plans ------------------------------------------------------------------

std::string CandidatePlan(const Dataset& setup, const Eigen::MatrixXd& indexations, const Eigen::MatrixXi* directions,
                          const std::vector<Eigen::Vector3d>& sphere_normals, const Accessibility& access,
                          std::vector<int>* group) {
  const Machine& m = setup.machine();
  const int na = m.num_axes();
  if (indexations.cols() != na)
    throw std::invalid_argument("candidate_plan: indexations need " + std::to_string(na) + " columns (axes " +
                                m.axis_names() + "), got " + std::to_string(indexations.cols()));
  if (directions && (directions->rows() != indexations.rows() || directions->cols() != na))
    throw std::invalid_argument("candidate_plan: directions must have the shape of indexations");
  if (!(setup.tip_radius > 0)) throw std::invalid_argument("candidate_plan: probe.tip_radius missing or zero");
  for (const auto& [axis, lim] : access.limits) {
    if (m.AxisIndex(axis) < 0)
      throw std::invalid_argument(std::string("candidate_plan.limits: machine has no axis '") + axis + "'");
    if (!(lim.first <= lim.second))
      throw std::invalid_argument(std::string("candidate_plan.limits.") + axis + ": min > max");
  }
  std::set<std::string> wanted(access.targets.begin(), access.targets.end());
  for (const std::string& t : wanted)
    if (setup.artefact.FacetIndex(t) < 0 && setup.artefact.SphereIndex(t) < 0 &&
        setup.artefact.CylinderIndex(t) < 0)
      throw std::invalid_argument("candidate_plan.targets: no facet, sphere or cylinder '" + t + "'");
  auto use = [&](const std::string& id) { return wanted.empty() || wanted.count(id); };
  std::vector<Eigen::Vector3d> normals;
  for (size_t i = 0; i < sphere_normals.size(); ++i)
    normals.push_back(UnitDirection(sphere_normals[i], "candidate_plan.sphere_normals[" + std::to_string(i) + "]"));
  const Eigen::VectorXd theta0 = Eigen::VectorXd::Zero(m.num_parameters());
  const double r = setup.tip_radius;
  json plan = json::array();
  if (group) group->clear();

  for (int row = 0; row < indexations.rows(); ++row) {
    Eigen::VectorXd start = indexations.row(row).transpose();
    for (int k = 0; k < na; ++k) {
      if (!m.axis(k).rotary()) start[k] = 0;
      RequireFinite(start[k], "candidate_plan.indexations[" + std::to_string(row) + "]");
    }
    auto rotary_ok = [&] {
      for (const auto& [axis, lim] : access.limits) {
        const int k = m.AxisIndex(axis);
        if (m.axis(k).rotary() && (start[k] < lim.first - 1e-9 || start[k] > lim.second + 1e-9)) return false;
      }
      return true;
    };
    if (!rotary_ok()) continue;
    Eigen::MatrixXd pose = start.transpose();
    Eigen::MatrixXd P, A;
    ToolPoses(m, theta0, pose, nullptr, &P, &A);
    const Eigen::Vector3d a = A.row(0).transpose().normalized();
    json axes = json::object(), dir = json::object();
    for (int k = 0; k < na; ++k)
      if (m.axis(k).rotary()) {
        axes[std::string(1, m.axis(k).name)] = start[k];
        if (directions && (*directions)(row, k) != 0)
          dir[std::string(1, m.axis(k).name)] = (*directions)(row, k);
      }
    auto reachable = [&](const Eigen::Vector3d& c) {
      Eigen::MatrixXd target = c.transpose();
      const Eigen::MatrixXd cmd = InverseKinematics(m, theta0, target, nullptr, start);
      for (const auto& [axis, lim] : access.limits) {
        const double v = cmd(0, m.AxisIndex(axis));
        if (v < lim.first - 1e-9 || v > lim.second + 1e-9) return false;
      }
      return true;
    };
    for (const Facet& f : setup.artefact.facets) {
      if (!use(f.id) || f.normal.dot(a) < access.min_dot) continue;
      if (!reachable(f.point + r * f.normal)) continue;
      json e = {{"type", "facet"}, {"target", f.id}, {"axes", axes}, {"point", Array3(f.point)}};
      if (!dir.empty()) e["direction"] = dir;
      plan.push_back(e);
      if (group) group->push_back(row);
    }
    for (const Sphere& s : setup.artefact.spheres) {
      if (!use(s.id)) continue;
      for (const Eigen::Vector3d& nrm : normals) {
        if (nrm.dot(a) < access.min_dot) continue;
        if (!reachable(s.center + (s.radius + r) * nrm)) continue;
        json e = {{"type", "sphere"}, {"target", s.id}, {"axes", axes}, {"normal", Array3(nrm)}};
        if (!dir.empty()) e["direction"] = dir;
        plan.push_back(e);
        if (group) group->push_back(row);
      }
    }
    // A cylinder: touches at its point's section, in the radial directions
    // of the sphere normals (those not nearly along its axis), once each.
    for (const Cylinder& c : setup.artefact.cylinders) {
      if (!use(c.id)) continue;
      std::vector<Eigen::Vector3d> done;
      for (const Eigen::Vector3d& nrm : normals) {
        Eigen::Vector3d e = nrm - c.axis * c.axis.dot(nrm);
        if (e.norm() < 0.5) continue;
        e.normalize();
        if (std::any_of(done.begin(), done.end(), [&](const Eigen::Vector3d& d) { return d.dot(e) > 1 - 1e-9; }))
          continue;
        done.push_back(e);
        const Eigen::Vector3d n = c.inside ? Eigen::Vector3d(-e) : e;  // into the free space
        if (n.dot(a) < access.min_dot) continue;
        const Eigen::Vector3d point = c.point + c.radius * e;
        if (!reachable(point + r * n)) continue;
        json j = {{"type", "cylinder"}, {"target", c.id}, {"axes", axes}, {"point", Array3(point)}};
        if (!dir.empty()) j["direction"] = dir;
        plan.push_back(j);
        if (group) group->push_back(row);
      }
    }
  }
  return plan.dump();
}

}  // namespace fivecal
