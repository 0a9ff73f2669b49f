#include "fivecal/solve/identify_fit.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

#include "fivecal/observations/registry.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify_determination.h"
#include "fivecal/solve/priors.h"

namespace fivecal {
namespace {

// The hierarchical prior of estimate "auto". Each class of machine errors
// (location offsets, scale gains, rotary tilts of degree 2, ...) gets a scale
// factor lambda in [kMinClassScale, 1] on its documented prior, found by
// maximising the evidence (MacKay's fixed point, the type-II maximum
// likelihood of sparse Bayesian learning):
//   lambda_k^2 = sum_j (theta_j / s_j)^2 / sum_j gamma_j,
//   gamma_j = 1 - posterior var_j / prior var_j   (j in class k),
// theta at the MAP point of the current scales. A class the data show no sign
// of shrinks towards zero, so it no longer spreads the noise over dozens of
// weakly seen errors; this is what lets "auto" predict held-out poses as well
// as the right hand-picked subset. The documented prior stays the ceiling
// (lambda <= 1): the data may say an error class is smaller than plausible,
// never larger. Only the point estimate uses the adapted scales; the
// uncertainty and the informed/undetermined judgement use the documented
// priors, so a class shrunk by the data of its siblings is never presented
// as measured for a member the data cannot see.
struct Hyper {
  Eigen::VectorXd prior;                 // per table entry, after the class scales
  std::map<std::string, double> scale;   // class -> lambda
  Eigen::VectorXd values;                // MAP point under `prior` and `noise`
  std::vector<VarianceComponent> noise;  // estimated instrument groups (variance components)
  int rounds = 0;
  int iterations = 0;                    // solver iterations over every round
};

constexpr double kMinClassScale = 1e-3;
// A group needs this much redundancy (rows minus what the fit used of them)
// before its noise is estimated from its residuals.
constexpr double kMinRedundancy = 5.0;

// The instrument group of residual row `row` of an observation: the variance
// component it shares, the simulator's noise class (every probe touch:
// "probe"). Rows in another unit than the kind's first row (a pose's
// rotation rows, rad) form their own group, "<class>_<unit>": one factor
// cannot scale micrometres and microradians alike. Two trackers of one kind
// are two instruments of their own noise: when a class holds observations of
// more than one instrument id (`several`), each id is its own group,
// "<class>.<id>" ("point.T1", "pose_rad.CAM"); a single instrument keeps the
// plain class name, and kinds without an id are grouped by class alone.
std::string NoiseGroup(const Observation& o, int row, const std::set<std::string>& several) {
  const ObservationKind& k = KindOf(o);
  const std::string unit = k.unit_row(row);
  std::string g = unit == k.unit_row(0) ? k.noise_class() : std::string(k.noise_class()) + "_" + unit;
  const std::string* id = InstrumentId(o);
  if (id && several.count(k.noise_class())) g += "." + *id;
  return g;
}

// The noise classes whose observations name more than one instrument id.
std::set<std::string> ClassesOfSeveralInstruments(const Dataset& ds) {
  std::map<std::string, std::set<std::string>> ids;
  for (const Observation& o : ds.observations)
    if (const std::string* id = InstrumentId(o)) ids[KindOf(o).noise_class()].insert(*id);
  std::set<std::string> out;
  for (const auto& [cls, set] : ids)
    if (set.size() > 1) out.insert(cls);
  return out;
}

// Every residual row's declared sigma (ObservationSigma, as the problem weighs it).
Eigen::VectorXd DeclaredSigma(const Dataset& ds, const Observation& o) {
  Eigen::VectorXd s(KindOf(o).rows());
  for (int k = 0; k < s.size(); ++k) s[k] = ObservationSigma(ds, o, k);
  return s;
}

// Variance components (Helmert / Foerstner's iterative estimator, the REML
// fixed point for independent groups): with the hat matrix H of the weighted
// (and prior-augmented) problem, group g's redundancy is
//   r_g = sum_{i in g} (1 - H_ii),
// and its noise factor is updated by f_g^2 <- f_g^2 * sum_{i in g} (e_i/s_i)^2 / r_g,
// e the residuals, s the current sigmas. At the fixed point every group's
// weighted residuals have the chi-square their redundancy predicts, so a
// probe declared at 1 um and a ball bar at 0.5 um are weighed by what the
// data show, not by a guess.
//
// Both hyperparameters (class scales of "auto", noise factors) are
// evidence maximisations of the same model; they are iterated together.
Hyper AdaptHyperparameters(const Dataset& ds, Dataset* scaled, const ParameterTable& table,
                           const Eigen::VectorXd& start, const std::vector<int>& est,
                           const IdentifyOptions& opt, const Eigen::VectorXd& prior_all, bool classes,
                           bool map, const Eigen::VectorXd& place) {
  std::map<std::string, std::vector<int>> members;  // class -> positions in est
  const Machine& m = ds.machine();
  if (classes)
    for (size_t j = 0; j < est.size(); ++j) {
      const std::string& n = table.names()[est[j]];
      if (m.ParameterIndex(n) < 0) continue;  // setup parameters keep their prior
      const std::string cls = PriorClassOf(m, n);
      if (cls != "tip") members[cls].push_back(static_cast<int>(j));
    }
  Hyper out;
  out.prior = prior_all;
  out.values = start;
  for (const auto& kv : members) out.scale[kv.first] = 1.0;
  // Noise groups: the observations and declared sigmas of each.
  std::map<std::string, double> factor;
  // Per observation, the group of each of its rows.
  std::vector<std::vector<std::string>> group_of(ds.observations.size());
  if (opt.variance_components) {
    const std::set<std::string> several = ClassesOfSeveralInstruments(ds);
    for (size_t i = 0; i < ds.observations.size(); ++i) {
      const Observation& o = ds.observations[i];
      for (int k = 0; k < KindOf(o).rows(); ++k)
        factor[group_of[i].emplace_back(NoiseGroup(o, k, several))] = 1.0;
    }
  }
  auto apply_noise = [&]() {
    for (size_t i = 0; i < ds.observations.size(); ++i) {
      Eigen::VectorXd s = DeclaredSigma(ds, ds.observations[i]);
      for (int k = 0; k < s.size(); ++k) s[k] *= factor[group_of[i][k]];
      scaled->observations[i].sigma = s;
    }
  };
  std::map<std::string, VarianceComponent> comp;
  if (members.empty() && factor.empty()) return out;
  for (int round = 0; round < 60; ++round) {
    for (const auto& [cls, js] : members)
      for (int j : js) out.prior[est[j]] = out.scale[cls] * prior_all[est[j]];
    if (!factor.empty()) apply_noise();
    std::unique_ptr<Problem> pr;
    const SingleFit fit = RunFit(*scaled, table, out.values, est, opt, out.prior, &pr);
    out.values = fit.values;
    out.rounds = round + 1;
    out.iterations += fit.iterations;
    Eigen::VectorXd r;
    Eigen::MatrixXd Jw;
    WeightedJacobian(pr.get(), &r, &Jw);
    Eigen::MatrixXd Ninv;
    Eigen::VectorXd cur;
    if (map) {
      cur = Gather(out.prior, est);
      Ninv = cur.asDiagonal() * ScaledPosterior(Jw, cur) * cur.asDiagonal();
    } else {
      Ninv = AnalyzeJacobian(WithPlacementRows(Jw, place), opt.rank_tolerance).inverse_normal;
    }
    double change = 0;
    for (const auto& [cls, js] : members) {
      double m2 = 0, gamma = 0;
      for (int j : js) {
        const double t = out.values[est[j]] / prior_all[est[j]];
        m2 += t * t;
        gamma += std::clamp(1.0 - Ninv(j, j) / (cur[j] * cur[j]), 0.0, 1.0);
      }
      double lambda = gamma > 1e-9 ? std::sqrt(m2 / gamma) : kMinClassScale;
      if (!std::isfinite(lambda)) lambda = 1.0;
      lambda = std::clamp(lambda, kMinClassScale, 1.0);
      change = std::max(change, std::abs(std::log(lambda / out.scale[cls])));
      out.scale[cls] = lambda;
    }
    if (!factor.empty()) {
      const Eigen::VectorXd h = (Jw * Ninv).cwiseProduct(Jw).rowwise().sum();
      const Eigen::VectorXd sig = pr->row_sigma();
      const std::vector<int>& src = pr->row_source();
      comp.clear();
      std::map<std::string, double> declared2;
      int k = 0;  // row of its observation: an observation's rows are consecutive
      for (int i = 0; i < r.size(); ++i) {
        k = i > 0 && src[i] == src[i - 1] ? k + 1 : 0;
        if (src[i] < 0) continue;  // a scale bar's length: a reference, not an instrument group
        const std::string& g = group_of[src[i]][k];
        VarianceComponent& c = comp[g];
        c.group = g;
        c.rows += 1;
        c.redundancy += std::clamp(1.0 - h[i], 0.0, 1.0);
        c.chi2 += (r[i] / sig[i]) * (r[i] / sig[i]);
        declared2[g] += (sig[i] / factor[g]) * (sig[i] / factor[g]);
      }
      for (auto& [g, c] : comp) {
        c.declared = std::sqrt(declared2[g] / c.rows);
        c.estimated = c.redundancy >= kMinRedundancy;
        if (!c.estimated) continue;
        double f = factor[g] * std::sqrt(c.chi2 / c.redundancy);
        if (!std::isfinite(f) || !(f > 0)) f = factor[g];
        change = std::max(change, std::abs(std::log(f / factor[g])));
        factor[g] = f;
      }
    }
    if (change < (factor.empty() ? 0.01 : 1e-3)) break;
  }
  for (const auto& [cls, js] : members)
    for (int j : js) out.prior[est[j]] = out.scale[cls] * prior_all[est[j]];
  if (!factor.empty()) {
    apply_noise();
    for (auto& [g, c] : comp) {
      c.factor = factor[g];
      c.sigma = c.declared * c.factor;
      out.noise.push_back(c);
    }
  }
  return out;
}

}  // namespace

IdentifyFit FitRequest(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq,
                       IdentifyProblem* problem) {
  const std::vector<int>& est = rq.est;
  const Eigen::VectorXd& prior = rq.prior;
  const Eigen::VectorXd& place = rq.place;
  const int p = static_cast<int>(est.size());
  Eigen::VectorXd values = rq.start;
  IdentifyFit out;

  if (!rq.map) {
    // A plain least-squares request must be determined by the data: judged
    // at the start and, when the start says no, again near the solution
    // (after a MAP fit, well posed whatever the start), so that a rough
    // nominal neither drops nor admits parameters wrongly.
    Eigen::MatrixXd Jw = WithPlacementRows(problem->WeightedJacobianAt(values), place);
    const int num_rows = problem->normal_equations()
                             ? problem->nep()->num_rows() + static_cast<int>((place.array() > 0).count())
                             : static_cast<int>(Jw.rows());
    if (num_rows < p && !opt.allow_unidentifiable)
      throw std::invalid_argument("identify: " + std::to_string(p) + " parameters but only " +
                                  std::to_string(num_rows) + " residuals");
    // Here only whether everything is determined matters (the groups only
    // for a refusal): the Cholesky certificate settles most undetermined
    // sets without the QR and SVD of AnalyzeDetermination.
    auto undetermined = [&](const Eigen::MatrixXd& J) { return AnyUndetermined(J, prior, kDeterminedRatio); };
    const bool start_undetermined = undetermined(Jw);
    if (start_undetermined) {
      const SingleFit pre = problem->FitFrom(values, rq.map_prior_all);
      const Eigen::MatrixXd Jpre = WithPlacementRows(problem->WeightedJacobianAfter(pre), place);
      const bool pre_undetermined = undetermined(Jpre);
      if (!pre_undetermined) {
        values = pre.values;
      } else if (!opt.allow_unidentifiable) {
        // The MAP point may still sit where a weakly seen setup parameter
        // (a sphere with few touches) looks free; the least-squares point
        // decides. Refuse only when it too leaves the set undetermined.
        const SingleFit ls = problem->FitFrom(pre.values, rq.ls_rows);
        if (undetermined(WithPlacementRows(problem->WeightedJacobianAfter(ls), place)))
          throw std::invalid_argument(UndeterminedMessage(
              ds, GroupNames(AnalyzeDetermination(Jpre, prior, kDeterminedRatio), rq.estimated)));
        values = ls.values;
      }
    }
  }

  // The prior rows of the fit: none (least squares), the documented priors
  // (prior=true), or the hierarchical one of "auto".
  out.fit_prior = rq.map ? rq.map_prior_all : rq.ls_rows;
  // With variance components the fit runs on a copy whose sigmas are the
  // estimated ones; everything below (covariance, chi-square) uses them.
  // (A copy only then: long data would double their memory.)
  out.weighted = &ds;
  // The rounds that set the class scales and noise move the values from the
  // start too: the reported iterations are every one the solver made.
  if (rq.automatic || opt.variance_components) {
    out.weighted_copy = std::make_unique<Dataset>(ds);
    out.weighted = out.weighted_copy.get();
    const Hyper hy = AdaptHyperparameters(ds, out.weighted_copy.get(), rq.table, values, est, opt, out.fit_prior,
                                          rq.automatic, rq.map, place);
    out.fit_prior = hy.prior;
    values = hy.values;
    out.adapt_iterations = hy.iterations;
    out.class_scales = hy.scale;
    out.variance_components = hy.noise;
  }
  out.fit = problem->FinalFit(*out.weighted, values, out.fit_prior, &out.problem, &out.nfit);

  // Residual rows (mm) and the weighted Jacobian at the solution; on the
  // normal-equation path its factor, from the pass the fit ended with, and
  // the residuals from one more pass without derivatives.
  if (problem->normal_equations()) {
    const NormalEquationProblem& nep = *problem->nep();
    out.r = nep.Residuals(out.fit.values);
    out.Jw = NormalFactor(out.nfit.at_solution.JtJ);
    out.row_sigma = &nep.row_sigma();
    out.row_source = &nep.row_source();
    out.num_rows = nep.num_rows();
    out.normal_equations = true;
    out.other_units = nep.other_units();
    out.row_unit = &nep.row_unit();
  } else {
    if (out.fit.Jw.size()) {
      // The fit's own evaluation at its solution: what WeightedJacobian
      // would compute there again.
      out.r = out.fit.r;
      out.Jw = out.fit.Jw;
    } else {
      WeightedJacobian(out.problem.get(), &out.r, &out.Jw);
    }
    out.row_sigma = &out.problem->row_sigma();
    out.row_source = &out.problem->row_source();
    out.num_rows = out.problem->num_rows();
  }
  // Every analysis of Jw below depends on it only through Jw^T Jw (and is
  // invariant to column scaling): one QR serves them all.
  out.factor = TriangularFactor(rq.placed ? WithPlacementRows(out.Jw, place) : out.Jw);
  return out;
}

}  // namespace fivecal
