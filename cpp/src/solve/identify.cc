// Identify as a pipeline of stages, each a file of its own with a typed
// input and output (identify_request.h ... identify_verdict.h); the fit's
// one factor of the weighted Jacobian at the solution is handed on to the
// determination and the covariance.
#include "fivecal/solve/identify.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>

#include "fivecal/solve/identify_covariance.h"
#include "fivecal/solve/identify_determination.h"
#include "fivecal/solve/identify_fit.h"
#include "fivecal/solve/identify_problem.h"
#include "fivecal/solve/identify_request.h"
#include "fivecal/solve/identify_verdict.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {

using json_util::json;

namespace {

// Built with -DFIVECAL_IDENTIFY_TIMING, Identify prints the wall time of each
// stage to stderr (bench/NOTES.md: where S4's time goes); otherwise nothing.
class StageClock {
 public:
#ifdef FIVECAL_IDENTIFY_TIMING
  void operator()(const char* stage) {
    const auto now = std::chrono::steady_clock::now();
    char buf[64];
    std::snprintf(buf, sizeof buf, " %s %.3f ms", stage, std::chrono::duration<double, std::milli>(now - t_).count());
    line_ += buf;
    t_ = now;
  }
  ~StageClock() { std::fprintf(stderr, "identify stages:%s\n", line_.c_str()); }

 private:
  std::chrono::steady_clock::time_point t_ = std::chrono::steady_clock::now();
  std::string line_;
#else
  void operator()(const char*) {}
#endif
};

}  // namespace

Result Identify(const Dataset& ds, const IdentifyOptions& opt) {
  StageClock clock;
  ds.Validate();
  // Requests that select on the dense Jacobian ("location", "auto") build
  // a per-observation problem while resolving: blocks expanded first.
  if (!ds.blocks.empty())
    for (const std::string& n : opt.estimate)
      if (n == "location" || n == "auto") return Identify(ds.Expanded(), opt);
  const IdentifyRequest request = ResolveRequest(ds, opt);
  clock("request");
  // Column blocks (dataset.h TraceBlock) are fitted where they lie only by
  // the column kernels on the normal equations; a fit that needs a
  // per-observation problem (dense Jacobian, templated functors, prepared
  // rows) gets the blocks expanded, the one place it happens.
  if (!ds.blocks.empty() &&
      (!DenseReason(ds, opt, request).empty() || NormalEquationElements(ds) != kColumnarElements))
    return Identify(ds.Expanded(), opt);
  IdentifyProblem problem(ds, opt, request);
  clock("problem");
  const IdentifyFit fit = FitRequest(ds, opt, request, &problem);
  clock("fit");
  const IdentifyDetermination determination = DetermineAtSolution(ds, opt, request, fit);
  clock("determination");
  if (!determination.drop.empty()) {
    // The candidates "location" chose at the declared noise that the
    // estimated noise leaves too weakly seen: fit the rest as an explicit
    // set, and say what was left out and why.
    IdentifyOptions again = opt;
    again.estimate.clear();
    again.include_default_setup = false;
    for (size_t c = 0; c < request.est.size(); ++c)
      if (std::find(determination.drop.begin(), determination.drop.end(), static_cast<int>(c)) ==
          determination.drop.end())
        again.estimate.push_back(request.estimated[c]);
    Result out = Identify(ds, again);
    out.left_out = request.left_out;
    out.left_out_moves = request.left_out_moves;
    for (int c : determination.drop)
      out.left_out.emplace_back(request.estimated[c],
                                "too weakly seen at the noise estimated from the residuals (variance components): "
                                "chosen at the declared noise, left out at the estimated one");
    out.explicit_request = !request.automatic;
    return out;
  }
  const IdentifyCovariance covariance = CovarianceAtSolution(ds, opt, request, fit, determination);
  clock("covariance");
  Result result = JudgeResult(ds, opt, request, fit, determination, covariance);
  clock("verdict");
  return result;
}

std::string Result::verdict() const {
  if (!finite) return "non_finite";
  if (!converged) return "not_converged";
  // Before adequacy: a misfit that follows from a wrong nominal geometry is
  // best told by its cause.
  if (!plausible) return "implausible";
  if (!adequate) return "inadequate";
  if (explicit_request && !undetermined.empty()) return "undetermined";
  // Set-up quantities alone (a stylus tip, a sphere centre) are no
  // calibration: a fit for machine errors that determined none of them is
  // not usable, whatever it says of the set-up.
  if (seeks_machine_errors && identified_machine_errors == 0) return "undetermined";
  return "ok";
}

Eigen::VectorXd PredictResiduals(const Dataset& given_ds, const std::map<std::string, double>& values,
                                 std::vector<int>* source) {
  const ExpandedView expanded_ds(given_ds);  // a functor per observation
  const Dataset& ds = *expanded_ds;
  ds.Validate();
  const ParameterTable table(ds);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : values) {
    const int i = table.Index(name);
    if (i >= 0) v[i] = value;  // other datasets' setup parameters do not apply here
    else if (!IsSetupParameterName(name))
      table.Require(name);  // throws: a machine name typo or a malformed dotted name
  }
  Problem problem(ds, table, v, {});
  Eigen::VectorXd r;
  problem.Evaluate(&r, nullptr);
  if (source) *source = problem.row_source();
  return r;
}

namespace {
// JSON has no inf or NaN: such a number is written as null.
json Finite(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }
}  // namespace

std::string Result::ToJson() const {
  json j;
  json params = json::object();
  for (size_t i = 0; i < estimated.size(); ++i) {
    const auto it = std::find(names.begin(), names.end(), estimated[i]);
    json entry = {{"value", Finite(values[it - names.begin()])}, {"std", Finite(this->std[i])}};
    if (i < prior_std.size()) {
      entry["prior_std"] = Finite(prior_std[i]);
      entry["informed"] = Finite(informed[i]);
    }
    if (i < placement.size() && placement[i] > 0) entry["placement_std"] = Finite(placement[i]);
    params[estimated[i]] = entry;
  }
  for (size_t i = 0; i < names.size(); ++i)
    if (!params.contains(names[i]) && values[i] != 0.0)
      params[names[i]] = {{"value", Finite(values[i])}, {"fixed", true}};
  j["parameters"] = params;
  j["residual_rms"] = Finite(rms);
  j["residual_max"] = Finite(max_abs);
  j["sigma"] = Finite(sigma);
  if (residual_units.size() > 1) {
    json units = json::object();
    for (const UnitResiduals& u : residual_units)
      units[u.unit] = {{"rows", u.rows}, {"rms", Finite(u.rms)}, {"max", Finite(u.max_abs)},
                       {"sigma", Finite(u.sigma)}};
    j["residual_units"] = units;
  }
  j["n_observations"] = n_observations;
  j["n_parameters"] = n_parameters;
  j["condition_number"] = std::isfinite(condition_number) ? json(condition_number) : json(nullptr);
  j["rank"] = rank;
  j["unidentifiable"] = unidentifiable;
  j["converged"] = converged;
  j["iterations"] = iterations;
  j["estimated"] = estimated;
  j["undetermined"] = undetermined;
  j["identified_machine_errors"] = identified_machine_errors;
  j["held"] = held;
  json lo = json::array();
  for (const auto& [name, why] : left_out) lo.push_back({name, why});
  j["left_out"] = lo;
  if (!left_out_moves.empty()) {
    json moves = json::object();
    for (const LeftOutMoves& m : left_out_moves) {
      json e = json::object();
      for (const auto& [est, a] : m.moves) e[est] = a;
      moves[m.name] = {{"plausible", m.plausible}, {"moves", e}};
    }
    j["left_out_moves"] = moves;
  }
  json nd = json::array();
  for (const NotDetermined& f : not_determined)
    nd.push_back({{"family", f.family}, {"machine", f.machine}, {"estimated", f.estimated},
                  {"names", f.names}, {"why", f.why}});
  j["not_determined"] = nd;
  j["implausible"] = implausible;
  j["map_fit"] = map_fit;
  if (!variance_components.empty()) {
    nlohmann::json vc = nlohmann::json::array();
    for (const VarianceComponent& c : variance_components)
      vc.push_back({{"group", c.group}, {"rows", c.rows}, {"redundancy", Finite(c.redundancy)},
                    {"declared_sigma", Finite(c.declared)}, {"factor", Finite(c.factor)},
                    {"sigma", Finite(c.sigma)}, {"estimated", c.estimated}});
    j["variance_components"] = vc;
  }
  if (!class_scales.empty()) {
    nlohmann::json cs = nlohmann::json::object();
    for (const auto& [cls, v] : class_scales) cs[cls] = Finite(v);
    j["class_scales"] = cs;
  }
  j["chi2"] = {{"value", Finite(chi2)}, {"dof", dof}, {"p", Finite(chi2_p)}};
  j["adequate"] = adequate;
  j["adequacy"] = adequacy;
  j["plausible"] = plausible;
  j["plausibility"] = plausibility;
  j["finite"] = finite;
  j["verdict"] = verdict();
  json corr = json::array();
  for (int i = 0; i < correlation.rows(); ++i) {
    json row = json::array();
    for (int k = 0; k < correlation.cols(); ++k) row.push_back(Finite(correlation(i, k)));
    corr.push_back(row);
  }
  j["correlation"] = corr;
  json res_rows = json::array();
  for (int i = 0; i < residuals.size(); ++i) res_rows.push_back(Finite(residuals[i]));
  j["residuals"] = res_rows;
  j["outliers"] = outliers;
  return j.dump(1);
}

}  // namespace fivecal
