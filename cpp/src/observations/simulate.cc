#include "fivecal/observations/simulate.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {

using namespace json_util;

Eigen::Vector3d ToolAtCommand(const Machine& m, const Eigen::VectorXd& theta, const Eigen::VectorXd& cmd,
                              const std::vector<int>& dir, const Eigen::Vector3d& tip) {
  std::vector<double> q(m.num_axes());
  AxisValuesToInternal(m, cmd.data(), q.data());
  Eigen::Vector3d p;
  ToolInWorkpiece<double>(m, theta.data(), q.data(), dir.data(), tip, &p);
  return p;
}

void AddPlanInput(SimulationPlan* plan, int obs, int component, double sensitivity, double sigma) {
  plan->input_observation.push_back(obs);
  plan->input_component.push_back(component);
  const int n = plan->num_inputs();
  plan->sensitivity.conservativeResize(n);
  plan->input_sigma.conservativeResize(n);
  plan->sensitivity[n - 1] = sensitivity;
  plan->input_sigma[n - 1] = sigma;
}

namespace {
SimulationPlan PlanSpec(const json& spec);

// Per-observation slots of a plan, filled with the dataset's own readings.
void InitSlots(SimulationPlan* plan) {
  const size_t n = plan->base.observations.size();
  plan->start.resize(n);
  plan->approach.assign(n, Eigen::VectorXd());
  plan->s0.assign(n, 0.0);
  for (size_t i = 0; i < n; ++i) plan->start[i] = plan->base.observations[i].axes;
}

// The calibrated length of every scale bar the fit has a row for (the
// sphere kind's rule: both spheres probed), after the observation inputs and
// in bar order, as the fit's rows come. The bar row is |c1 - c2| - L, so
// d residual / d L = -1. Without any noise the plan stays noise-free.
void AddScaleBarInputs(SimulationPlan* plan) {
  const Dataset& ds = plan->base;
  std::vector<int> bars;
  for (const ObservationKind* k : ObservationKinds())
    for (int b : k->ScaleBarRows(ds)) bars.push_back(b);
  std::sort(bars.begin(), bars.end());
  bool noisy = false;
  for (const auto& kv : plan->noise.level) noisy = noisy || kv.second > 0;
  for (int b : bars) AddPlanInput(plan, -1 - b, 0, -1.0, noisy ? kScaleBarSigma : 0.0);
}

// Observation i of `ds` with input values `x` (one per input of i, in the
// input's own unit, added to the noise-free value); a scale bar input adds
// to the bar's length.
// Into a dataset of the plan's structure (a copy of plan.base, possibly
// realised before): each observation with inputs is reset to its noise-free
// reading first (a kind may compose its inputs onto the current reading),
// the others were never changed.
template <typename Draw>
void RealizeInto(const SimulationPlan& plan, Draw&& draw, Dataset* ds) {
  if (ds->observations.size() != plan.base.observations.size())
    throw std::invalid_argument("simulate: the dataset has " + std::to_string(ds->observations.size()) +
                                " observations, the plan " + std::to_string(plan.base.observations.size()));
  const int n_in = plan.num_inputs();
  int last = -1;
  for (int k = 0; k < n_in; ++k) {
    const int i = plan.input_observation[k];
    if (i < 0) {
      const int b = -1 - i;
      ds->artefact.scale_bars[b].length = plan.base.artefact.scale_bars[b].length + draw(k);
      continue;
    }
    Observation& o = ds->observations[i];
    // Copy-assignment into an observation of the same shape reuses its buffers.
    if (i != last) o = plan.base.observations[i];
    last = i;
    KindOf(o).ApplyInput(plan, i, plan.input_component[k], draw(k), &o);
  }
}

template <typename Draw>
Dataset Realize(const SimulationPlan& plan, Draw&& draw) {
  Dataset ds = plan.base;
  RealizeInto(plan, std::forward<Draw>(draw), &ds);
  return ds;
}
}  // namespace

SimulationPlan BuildSimulationPlan(const std::string& spec_text) {
  return Guard("simulate", [&] { return PlanSpec(Parse(spec_text, "simulate")); });
}

Dataset Simulate(const std::string& spec_text) {
  const SimulationPlan plan = BuildSimulationPlan(spec_text);
  return AddNoise(plan, plan.seed);
}

Dataset AddNoise(const SimulationPlan& plan, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  // One draw per input, in input order (the order Simulate has always used).
  return Realize(plan, [&](int k) { return plan.input_sigma[k] * normal(rng); });
}

Dataset ApplyInputDeviations(const SimulationPlan& plan, const Eigen::VectorXd& deviation) {
  Dataset ds = plan.base;
  ApplyInputDeviationsInto(plan, deviation, &ds);
  return ds;
}

void AddNoiseInto(const SimulationPlan& plan, uint64_t seed, Dataset* ds) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  RealizeInto(plan, [&](int k) { return plan.input_sigma[k] * normal(rng); }, ds);
}

void ApplyInputDeviationsInto(const SimulationPlan& plan, const Eigen::VectorXd& deviation, Dataset* ds) {
  if (deviation.size() != plan.num_inputs())
    throw std::invalid_argument("input deviations: " + std::to_string(deviation.size()) +
                                " values for " + std::to_string(plan.num_inputs()) + " inputs");
  RealizeInto(plan, [&](int k) { return deviation[k] / plan.sensitivity[k]; }, ds);
}

namespace {
SimulationPlan PlanSpec(const json& spec) {
  if (!spec.is_object()) throw std::invalid_argument("simulate: expected a JSON object");
  CheckKeys(spec, {"machine", "errors", "setup", "probe", "artefact", "plan", "sigma", "seed", "$schema",
                   "_comment", "observations"}, "simulate");
  // A dataset skeleton turned into a spec may keep its empty observation list.
  if (spec.contains("observations") && !(spec["observations"].is_array() && spec["observations"].empty()))
    throw std::invalid_argument("simulate.observations: a spec plans its observations in \"plan\"; "
                                "remove \"observations\"");
  if (!spec.contains("machine")) throw std::invalid_argument("simulate.machine: missing");
  json base = {{"machine", spec["machine"]},
               {"probe", spec.value("probe", json::object())},
               {"artefact", spec.value("artefact", json::object())},
               {"observations", json::array()}};
  Dataset ds = [&] {
    try {
      return Dataset::FromJson(base.dump(), false);
    } catch (const std::invalid_argument& e) {
      // The dataset parser's "dataset.<field>" is the spec's "simulate.<field>".
      std::string msg = e.what();
      if (msg.rfind("dataset.", 0) == 0) msg = "simulate." + msg.substr(8);
      throw std::invalid_argument(msg);
    }
  }();
  const Machine& m = ds.machine();
  const int na = m.num_axes();

  Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  if (spec.contains("errors")) {
    if (!spec["errors"].is_object())
      throw std::invalid_argument("simulate.errors: expected an object parameter name -> value");
    ErrorModel e(m);
    for (auto& [k, v] : spec["errors"].items()) {
      if (!v.is_number()) throw std::invalid_argument("simulate.errors." + k + ": expected a number");
      try {
        e.Set(k, v.get<double>());
      } catch (const std::invalid_argument& ex) {
        std::string msg = ex.what();
        if (msg.rfind("errors.", 0) == 0) msg = msg.substr(7 + k.size());  // ": ... implausible"
        throw std::invalid_argument("simulate.errors." + k + (msg.rfind(":", 0) == 0 ? "" : ": ") + msg +
                                    (k.find('.') != std::string::npos && k.rfind("tip.", 0) != 0
                                         ? " (setup parameters go in simulate.setup)"
                                         : ""));
      }
    }
    theta = e.values();
  }
  std::map<std::string, double> setup;
  if (spec.contains("setup")) {
    if (!spec["setup"].is_object()) throw std::invalid_argument("simulate.setup: expected an object");
    for (auto& [k, v] : spec["setup"].items()) {
      if (!v.is_number()) throw std::invalid_argument("simulate.setup." + k + ": expected a number");
      setup[k] = v.get<double>();
      RequireBounded(setup[k], kMaxErrorValue, "simulate.setup." + k);
    }
  }
  auto S = [&](const std::string& n) {
    auto it = setup.find(n);
    return it == setup.end() ? 0.0 : it->second;
  };
  NoiseLevels noise;
  if (spec.contains("sigma")) {
    const json& s = spec["sigma"];
    auto level = [](const json& v, const std::string& where) {
      if (!v.is_number()) throw std::invalid_argument(where + ": expected a number (mm)");
      const double x = v.get<double>();
      if (!(x >= 0 && x <= kMaxSigma)) throw std::invalid_argument(where + ": must be >= 0 and <= 1e3 mm");
      return x;
    };
    // The noise classes come from the registered kinds (NoiseClasses()).
    const std::vector<std::string> classes = NoiseClasses();
    std::string list;
    for (const std::string& c : classes) list += (list.empty() ? "" : ", ") + c;
    // Classes of rows in rad (a pose's orientation rows): a number in mm
    // does not set them.
    auto angular = [](const std::string& c) { return NoiseClassUnit(c) == "rad"; };
    if (s.is_number()) {
      const double x = level(s, "simulate.sigma");
      for (const std::string& c : classes)
        if (!angular(c)) noise.level[c] = x;
    } else if (s.is_object()) {
      std::vector<const char*> keys;
      for (const std::string& c : classes) keys.push_back(c.c_str());
      CheckKeys(s, keys, "simulate.sigma");
      for (const std::string& c : classes) {
        if (!s.contains(c)) continue;
        if (!angular(c)) {
          noise.level[c] = level(s[c], "simulate.sigma." + c);
          continue;
        }
        const std::string w = "simulate.sigma." + c;
        if (!s[c].is_number()) throw std::invalid_argument(w + ": expected a number (rad)");
        const double x = s[c].get<double>();
        if (!(x >= 0 && x <= 1.0)) throw std::invalid_argument(w + ": must be >= 0 and <= 1 rad");
        noise.level[c] = x;
      }
    } else {
      throw std::invalid_argument("simulate.sigma: expected a number or an object {" + list + "}");
    }
    for (const auto& [c, x] : noise.level)
      if (x > 0 && x < kMinSigma) throw std::invalid_argument("simulate.sigma: 0 (no noise) or >= 1e-9 mm");
  }
  const uint64_t seed = spec.contains("seed") ? ReadSeed(spec["seed"], "simulate.seed") : 0;
  // Per observation: the noise directions.
  std::vector<PlanSlot> slots;

  if (!spec.contains("plan") || !spec["plan"].is_array() || spec["plan"].empty())
    throw std::invalid_argument("simulate.plan: empty; give at least one planned touch or sample");
  PlanTruth truth;
  truth.dataset = &ds;
  truth.theta = theta;
  truth.tip = TipWithOffsets<double>(m, theta.data());
  truth.setup = S;
  const json& plan = spec["plan"];

  for (size_t i = 0; i < plan.size(); ++i) {
    const std::string w = "simulate.plan[" + std::to_string(i) + "]";
    const json& e = plan[i];
    if (!e.is_object()) throw std::invalid_argument(w + ": expected an object");
    if (!e.contains("type") || !e["type"].is_string())
      throw std::invalid_argument(w + ".type: missing (" + KindList() + ")");
    const std::string type = e["type"].get<std::string>();
    // The type first: an unknown one must be named as such, not reported
    // as whatever the other checks trip on.
    const ObservationKind* kind = FindKind(type);
    if (!kind)
      throw std::invalid_argument(w + ".type: unknown type " + Quote(type) + " (" + KindList() + ")" +
                                  DidYouMean(type, KindNames()));
    CheckKeys(e, kind->plan_keys(), w);
    Observation ob;
    ob.type = kind->type();
    ob.payload = kind->NewPayload();
    ob.axes = Eigen::VectorXd::Zero(na);
    ob.direction = Eigen::VectorXi::Zero(na);
    if (e.contains("id")) ob.id = ReadString(e, "id", w);
    std::vector<bool> given(na, false);
    if (e.contains("axes")) ReadAxes(m, e["axes"], w + ".axes", &ob.axes, &given);
    if (e.contains("direction")) ReadDirections(m, e["direction"], w + ".direction", &ob.direction);
    // A touch's linear axes (and those of any kind that says so) are the simulator's to find.
    const bool linear_optional = kind->plan_finds_linear_axes();
    for (int k = 0; k < na; ++k)
      if (!given[k] && m.axis(k).name != 'S' && (m.axis(k).rotary() || !linear_optional))
        throw std::invalid_argument(w + ".axes: missing axis '" + std::string(1, m.axis(k).name) +
                                    "' (machine axes " + m.axis_names() + ")");
    PlanSlot slot;
    kind->SimulateEntry(e, w, truth, &ob, &slot);
    slots.push_back(slot);
    ds.observations.push_back(ob);
  }
  for (ScaleBar& b : ds.artefact.scale_bars) {
    auto true_center = [&](const std::string& id) {
      const Sphere& s = ds.artefact.spheres.at(ds.artefact.SphereIndex(id));
      return Eigen::Vector3d(s.center + Eigen::Vector3d(S("sphere." + id + ".x"), S("sphere." + id + ".y"),
                                                        S("sphere." + id + ".z")));
    };
    b.length = (true_center(b.sphere1) - true_center(b.sphere2)).norm();
  }
  try {
    ds.Validate();  // what load_dataset would refuse in the written dataset
  } catch (const std::invalid_argument& e) {
    // Observation i is plan entry i.
    std::string msg = e.what();
    if (msg.rfind("observations[", 0) == 0) msg = "simulate.plan[" + msg.substr(13);
    throw std::invalid_argument(msg);
  }
  const ParameterTable table(ds);
  for (const auto& kv : setup) {
    const int idx = table.Index(kv.first);
    if (idx < 0 || idx < table.num_machine()) {
      std::vector<std::string> setup_names(table.names().begin() + table.num_machine(), table.names().end());
      throw std::invalid_argument("simulate.setup." + kv.first + ": not a setup parameter of this plan" +
                                  (idx >= 0 ? " (machine errors go in simulate.errors)"
                                            : DidYouMean(kv.first, setup_names)));
    }
  }

  SimulationPlan out(std::move(ds));
  out.noise = noise;
  out.seed = seed;
  const Machine& mm = out.base.machine();  // `ds` (and `m`) moved into `out`
  for (int i = 0; i < mm.num_parameters(); ++i)
    if (theta[i] != 0.0) out.values[mm.parameters()[i].name] = theta[i];
  for (const auto& kv : setup) out.values[kv.first] = kv.second;
  InitSlots(&out);
  for (size_t i = 0; i < out.base.observations.size(); ++i) {
    Observation& o = out.base.observations[i];
    const int oi = static_cast<int>(i);
    // The noise drawn is the noise declared: a simulated dataset carries its
    // sigma, so fitting it weighs the rows as they were made.
    const ObservationKind& kind = KindOf(o);
    // A row without a noise level declares its kind's default.
    Eigen::VectorXd declared(kind.rows());
    for (int k = 0; k < kind.rows(); ++k) declared[k] = kind.NoiseLevelRow(noise, k);
    if (declared.maxCoeff() > 0) {
      for (int k = 0; k < kind.rows(); ++k)
        if (!(declared[k] > 0)) declared[k] = kind.default_sigma_row(k);
      o.sigma = declared;
    }
    kind.AddInputs(&out, oi, &slots[i], nullptr);
  }
  // A simulated bar's certificate is off by its calibration error too: the
  // spec's seed draws it after all observation noise (so a spec's
  // observations read as they did before bars were inputs).
  AddScaleBarInputs(&out);
  return out;
}

}  // namespace

SimulationPlan PlanFromDataset(const Dataset& given_ds, const std::map<std::string, double>& values,
                               const NoiseLevels& noise) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  ds.Validate();
  const Machine& m = ds.machine();
  const ParameterTable table(ds);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : values) {
    RequireFinite(value, "values." + name);
    v[table.Require(name)] = value;
  }
  RecordedContext rec;
  rec.dataset = &ds;
  rec.table = &table;
  rec.values = v;
  rec.theta = v.head(m.num_parameters());
  rec.tip = TipWithOffsets<double>(m, rec.theta.data());

  SimulationPlan plan(ds);
  plan.noise = noise;
  plan.values = values;
  InitSlots(&plan);
  for (size_t i = 0; i < ds.observations.size(); ++i)
    KindOf(ds.observations[i]).AddInputs(&plan, static_cast<int>(i), nullptr, &rec);
  AddScaleBarInputs(&plan);
  return plan;
}

}  // namespace fivecal
