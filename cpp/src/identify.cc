#include "fivecal/identify.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

#include "fivecal/identifiability.h"
#include "fivecal/kinematic_model.h"
#include "fivecal/kinematics.h"
#include "fivecal/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

bool IsPreset(const std::string& s) {
  return s == "S1" || s == "S2" || s == "S3" || s == "S4" || s == "location" || s == "auto";
}

Eigen::VectorXd InitialValues(const ParameterTable& table, const IdentifyOptions& opt) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : opt.initial) {
    RequireFinite(value, "initial." + name);
    v[table.Require(name)] = value;
  }
  return v;
}

std::string GroupText(std::vector<std::string> g) {
  // Machine errors (what the user asked for) before the setup parameters.
  std::stable_partition(g.begin(), g.end(), [](const std::string& n) { return n[0] == 'E'; });
  std::string s = "{";
  const size_t shown = std::min<size_t>(g.size(), 8);
  for (size_t i = 0; i < shown; ++i) s += (i ? ", " : "") + g[i];
  if (g.size() > shown) s += ", ... (" + std::to_string(g.size() - shown) + " more)";
  return s + "}";
}

// The estimated index set: explicit names and presets plus the default setup,
// minus the fixed ones; "location"/"auto" are selected greedily on the
// Jacobian at the initial values.
std::vector<int> ResolveIndices(const Dataset& ds, const ParameterTable& table,
                                const Eigen::VectorXd& values, const IdentifyOptions& opt) {
  std::set<int> fixed;
  for (const std::string& n : opt.fix) {
    if (IsPreset(n)) {
      for (const std::string& p : ThesisSubset(ds.machine(), n)) fixed.insert(table.Require(p));
    } else {
      fixed.insert(table.Require(n));
    }
  }
  std::vector<int> forced;
  std::set<int> seen;
  auto add = [&](int i, std::vector<int>* list) {
    if (fixed.count(i) || seen.count(i)) return;
    seen.insert(i);
    list->push_back(i);
  };
  if (opt.include_default_setup)
    for (int i : table.DefaultSetup(ds)) add(i, &forced);
  bool location = false, automatic = false;
  for (const std::string& n : opt.estimate) {
    if (n == "location") location = true;
    else if (n == "auto") automatic = true;
    else if (IsPreset(n))
      for (const std::string& p : ThesisSubset(ds.machine(), n)) add(table.Require(p), &forced);
    else add(table.Require(n), &forced);
  }
  if (!location && !automatic) return forced;

  std::vector<int> candidates;
  for (const std::string& n : LocationCandidates(ds.machine())) add(table.Require(n), &candidates);
  if (automatic)
    for (const std::string& n : MotionCandidates(ds.machine()))
      if (table.Index(n) >= 0) add(table.Index(n), &candidates);
  std::vector<int> all = forced;
  all.insert(all.end(), candidates.begin(), candidates.end());
  Problem probe(ds, table, values, all);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  probe.Evaluate(&r, &J);
  std::vector<int> forced_cols(forced.size()), cand_cols(candidates.size());
  for (size_t i = 0; i < forced.size(); ++i) forced_cols[i] = static_cast<int>(i);
  for (size_t i = 0; i < candidates.size(); ++i)
    cand_cols[i] = static_cast<int>(forced.size() + i);
  // Forced parameters are kept whatever happens (a confounded explicit request
  // is reported by the rank check), candidates only when independent.
  std::vector<int> chosen = SelectIdentifiable(J, forced_cols, cand_cols, opt.selection_tolerance);
  std::vector<int> out = forced;
  for (int c : chosen)
    if (c >= static_cast<int>(forced.size())) out.push_back(all[c]);
  return out;
}

void FillResiduals(const Dataset& ds, const Eigen::VectorXd& values, const ParameterTable& table,
                   const Eigen::VectorXd& r, Result* res) {
  const Machine& m = ds.machine();
  const int n = static_cast<int>(ds.observations.size());
  res->residual_vectors = Eigen::MatrixXd::Zero(n, 3);
  res->points = Eigen::MatrixXd::Zero(n, 3);
  const KinematicModel model(m, values.data());
  const Eigen::Vector3d tip = model.tip();
  int row = 0;
  for (int i = 0; i < n; ++i) {
    const Observation& o = ds.observations[i];
    const PoseData pose(m, o);
    Eigen::Vector3d P;
    Eigen::Vector3d t = tip;
    Eigen::Vector3d table_ball = o.table_ball;
    if (o.type == ObservationType::kDbb || o.type == ObservationType::kBall3d) {
      const auto& mt = table.mount(o.type, o.setup);
      for (int c = 0; c < 3; ++c) {
        t[c] = o.tool_ball[c] + values[mt[1 + c]];
        table_ball[c] += values[mt[4 + c]];
      }
    }
    P = model.ToolPoint(pose.q.data(), pose.dir.data(), t);
    res->points.row(i) = P.transpose();
    Eigen::Vector3d dir = Eigen::Vector3d::Zero();
    switch (o.type) {
      case ObservationType::kFacet:
        dir = ds.artefact.facets[ds.artefact.FacetIndex(o.target)].normal;
        break;
      case ObservationType::kSphere: {
        const int si = ds.artefact.SphereIndex(o.target);
        const auto& sp = table.sphere(si);
        const Eigen::Vector3d c = ds.artefact.spheres[si].center +
                                  Eigen::Vector3d(values[sp[0]], values[sp[1]], values[sp[2]]);
        dir = (P - c).normalized();
        break;
      }
      case ObservationType::kDbb:
        dir = (P - table_ball).normalized();
        break;
      case ObservationType::kBall3d:
        res->residual_vectors.row(i) = r.segment<3>(row).transpose();
        row += 3;
        continue;
    }
    res->residual_vectors.row(i) = (r[row] * dir).transpose();
    row += 1;
  }
}

}  // namespace

std::vector<std::string> ResolveEstimate(const Dataset& ds, const IdentifyOptions& options) {
  ds.Validate();
  const ParameterTable table(ds);
  const Eigen::VectorXd values = InitialValues(table, options);
  std::vector<std::string> out;
  for (int i : ResolveIndices(ds, table, values, options)) out.push_back(table.names()[i]);
  return out;
}

Result Identify(const Dataset& ds, const IdentifyOptions& opt) {
  ds.Validate();
  const ParameterTable table(ds);
  Eigen::VectorXd values = InitialValues(table, opt);
  const std::vector<int> est = ResolveIndices(ds, table, values, opt);
  if (est.empty())
    throw std::invalid_argument("identify: nothing to estimate (every parameter is fixed)");

  Result res;
  res.names = table.names();
  for (int i : est) res.estimated.push_back(table.names()[i]);
  const int p = static_cast<int>(est.size());

  // Identifiability at the starting point: refuse to return garbage.
  std::unique_ptr<Problem> problem = std::make_unique<Problem>(ds, table, values, est);
  {
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    problem->Evaluate(&r, &J);
    if (problem->num_rows() < p && !opt.allow_unidentifiable)
      throw std::invalid_argument("identify: " + std::to_string(p) + " parameters but only " +
                                  std::to_string(problem->num_rows()) + " residuals");
    // The SVD (which names confounded groups) only when a QR screen is not
    // conclusive: most requests are well posed and this halves the cost.
    Identifiability id;
    id.rank = p;
    if (!ClearlyFullRank(J)) id = AnalyzeJacobian(J, opt.rank_tolerance);
    for (const auto& g : id.confounded) {
      std::vector<std::string> names;
      for (int c : g) names.push_back(res.estimated[c]);
      res.unidentifiable.push_back(names);
    }
    if (id.rank < p && !opt.allow_unidentifiable) {
      std::string msg = "identify: the data cannot identify the requested parameters (rank " +
                        std::to_string(id.rank) + " of " + std::to_string(p) + "); confounded: ";
      for (size_t i = 0; i < res.unidentifiable.size(); ++i)
        msg += (i ? "; " : "") + GroupText(res.unidentifiable[i]);
      msg += ". Fix one parameter of each group, or use estimate 'auto'.";
      throw std::invalid_argument(msg);
    }
  }

  const ceres::Solver::Options so = Problem::SolverOptions(opt.max_iterations, opt.num_threads);

  auto run = [&](Problem* pr) {
    ceres::Solver::Summary summary;
    ceres::Solve(so, &pr->ceres_problem(), &summary);
    values = pr->values();
    res.converged = summary.termination_type == ceres::CONVERGENCE;
    res.iterations += static_cast<int>(summary.iterations.size()) - 1;
    res.message = summary.message;
    if (res.initial_cost == 0) res.initial_cost = summary.initial_cost;
    res.final_cost = summary.final_cost;
  };
  run(problem.get());
  if (!opt.robust.empty() && opt.robust != "none") {
    double scale = opt.robust_scale;
    if (!(scale > 0)) {
      Eigen::VectorXd r;
      problem->Evaluate(&r, nullptr);
      std::vector<double> a(r.data(), r.data() + r.size());
      for (double& x : a) x = std::abs(x);
      std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
      scale = 3.0 * 1.4826 * a[a.size() / 2];
      if (!(scale > 0)) scale = 1e-6;
    }
    res.robust_scale = scale;
    problem = std::make_unique<Problem>(ds, table, values, est, opt.robust, scale);
    run(problem.get());
  }

  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  problem->Evaluate(&r, &J);
  const Identifiability id = AnalyzeJacobian(J, opt.rank_tolerance);
  res.values = values;
  res.residuals = r;
  res.residual_source = problem->row_source();
  res.n_observations = problem->num_rows();
  res.n_parameters = p;
  res.rank = id.rank;
  res.condition_number = id.condition_number;
  res.rms = r.size() ? std::sqrt(r.squaredNorm() / r.size()) : 0.0;
  res.max_abs = r.size() ? r.cwiseAbs().maxCoeff() : 0.0;
  const int dof = res.n_observations - id.rank;
  res.sigma = dof > 0 ? std::sqrt(r.squaredNorm() / dof) : 0.0;
  // Covariance: s^2 (J^T J)^-1 from the column-scaled SVD (robust to the
  // parameters' very different units; pseudo-inverse when rank deficient).
  res.covariance = res.sigma * res.sigma * id.inverse_normal;
  res.std = res.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  res.correlation = Eigen::MatrixXd::Zero(p, p);
  for (int i = 0; i < p; ++i)
    for (int j = 0; j < p; ++j) {
      const double d = res.std[i] * res.std[j];
      res.correlation(i, j) = d > 0 ? res.covariance(i, j) / d : (i == j ? 1.0 : 0.0);
    }
  if (res.robust_scale > 0)
    for (int i = 0; i < r.size(); ++i)
      if (std::abs(r[i]) > res.robust_scale) res.outliers.push_back(i);
  FillResiduals(ds, values, table, r, &res);
  return res;
}

Eigen::VectorXd PredictResiduals(const Dataset& ds, const std::map<std::string, double>& values,
                                 std::vector<int>* source) {
  ds.Validate();
  const ParameterTable table(ds);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : values) {
    const int i = table.Index(name);
    if (i >= 0) v[i] = value;  // other datasets' setup parameters do not apply here
    else if (!json_util::IsSetupParameterName(name))
      table.Require(name);  // throws: a machine name typo or a malformed dotted name
  }
  Problem problem(ds, table, v, {});
  Eigen::VectorXd r;
  problem.Evaluate(&r, nullptr);
  if (source) *source = problem.row_source();
  return r;
}

std::string Result::ToJson() const {
  json j;
  json params = json::object();
  for (size_t i = 0; i < estimated.size(); ++i) {
    const auto it = std::find(names.begin(), names.end(), estimated[i]);
    params[estimated[i]] = {{"value", values[it - names.begin()]}, {"std", this->std[i]}};
  }
  for (size_t i = 0; i < names.size(); ++i)
    if (!params.contains(names[i]) && values[i] != 0.0)
      params[names[i]] = {{"value", values[i]}, {"fixed", true}};
  j["parameters"] = params;
  j["residual_rms"] = rms;
  j["residual_max"] = max_abs;
  j["sigma"] = sigma;
  j["n_observations"] = n_observations;
  j["n_parameters"] = n_parameters;
  j["condition_number"] = std::isfinite(condition_number) ? json(condition_number) : json(nullptr);
  j["rank"] = rank;
  j["unidentifiable"] = unidentifiable;
  j["converged"] = converged;
  j["iterations"] = iterations;
  j["estimated"] = estimated;
  json corr = json::array();
  for (int i = 0; i < correlation.rows(); ++i) {
    json row = json::array();
    for (int k = 0; k < correlation.cols(); ++k) row.push_back(correlation(i, k));
    corr.push_back(row);
  }
  j["correlation"] = corr;
  j["residuals"] = std::vector<double>(residuals.data(), residuals.data() + residuals.size());
  j["outliers"] = outliers;
  return j.dump(1);
}

}  // namespace fivecal
