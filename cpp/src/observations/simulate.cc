#include "fivecal/observations/simulate.h"

#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

Eigen::Vector3d ToolAt(const Machine& m, const Eigen::VectorXd& theta, const Eigen::VectorXd& cmd,
                       const std::vector<int>& dir, const Eigen::Vector3d& tip) {
  std::vector<double> q(m.num_axes());
  AxisValuesToInternal(m, cmd.data(), q.data());
  Eigen::Vector3d p;
  ToolInWorkpiece<double>(m, theta.data(), q.data(), dir.data(), tip, &p);
  return p;
}

}  // namespace

namespace {
SimulationPlan PlanSpec(const json& spec);

void AddInput(SimulationPlan* plan, int obs, int component, double sensitivity, double sigma) {
  plan->input_observation.push_back(obs);
  plan->input_component.push_back(component);
  const int n = plan->num_inputs();
  plan->sensitivity.conservativeResize(n);
  plan->input_sigma.conservativeResize(n);
  plan->sensitivity[n - 1] = sensitivity;
  plan->input_sigma[n - 1] = sigma;
}

// Per-observation slots of a plan, filled with the dataset's own readings.
void InitSlots(SimulationPlan* plan) {
  const size_t n = plan->base.observations.size();
  plan->start.resize(n);
  plan->approach.assign(n, Eigen::VectorXd());
  plan->s0.assign(n, 0.0);
  plan->reading0.assign(n, 0.0);
  plan->measured0.assign(n, Eigen::Vector3d::Zero());
  for (size_t i = 0; i < n; ++i) {
    const Observation& o = plan->base.observations[i];
    plan->start[i] = o.axes;
    plan->reading0[i] = o.reading;
    plan->measured0[i] = o.measured;
  }
}

// Observation i of `ds` with input values `x` (one per input of i, in the
// input's own unit, added to the noise-free value).
template <typename Draw>
Dataset Realize(const SimulationPlan& plan, Draw&& draw) {
  Dataset ds = plan.base;
  const int n_in = plan.num_inputs();
  for (int k = 0; k < n_in; ++k) {
    const int i = plan.input_observation[k];
    Observation& o = ds.observations[i];
    const double x = draw(k);
    switch (o.type) {
      case ObservationType::kFacet:
      case ObservationType::kSphere: {
        const double s = plan.s0[i] + x;
        o.axes = plan.start[i] + s * plan.approach[i];
        break;
      }
      case ObservationType::kDbb:
        o.reading = plan.reading0[i] + x;
        break;
      case ObservationType::kBall3d: {
        const int c = plan.input_component[k];
        o.measured[c] = plan.measured0[i][c] + x;
        break;
      }
    }
  }
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
  if (deviation.size() != plan.num_inputs())
    throw std::invalid_argument("input deviations: " + std::to_string(deviation.size()) +
                                " values for " + std::to_string(plan.num_inputs()) + " inputs");
  return Realize(plan, [&](int k) { return deviation[k] / plan.sensitivity[k]; });
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
    if (s.is_number()) {
      noise.probe = noise.dbb = noise.ball3d = level(s, "simulate.sigma");
    } else if (s.is_object()) {
      CheckKeys(s, {"probe", "dbb", "ball3d"}, "simulate.sigma");
      if (s.contains("probe")) noise.probe = level(s["probe"], "simulate.sigma.probe");
      if (s.contains("dbb")) noise.dbb = level(s["dbb"], "simulate.sigma.dbb");
      if (s.contains("ball3d")) noise.ball3d = level(s["ball3d"], "simulate.sigma.ball3d");
    } else {
      throw std::invalid_argument("simulate.sigma: expected a number or an object {probe, dbb, ball3d}");
    }
    for (double x : {noise.probe, noise.dbb, noise.ball3d})
      if (x > 0 && x < kMinSigma) throw std::invalid_argument("simulate.sigma: 0 (no noise) or >= 1e-9 mm");
  }
  const uint64_t seed = spec.contains("seed") ? ReadSeed(spec["seed"], "simulate.seed") : 0;
  // Per observation: the noise-free readings and the noise directions.
  struct Slot {
    Eigen::VectorXd start, approach;
    double s0 = 0, sensitivity = -1;
  };
  std::vector<Slot> slots;

  if (!spec.contains("plan") || !spec["plan"].is_array() || spec["plan"].empty())
    throw std::invalid_argument("simulate.plan: empty; give at least one planned touch or sample");
  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());
  const Eigen::Vector3d tip_true = TipWithOffsets<double>(m, theta.data());
  const json& plan = spec["plan"];

  for (size_t i = 0; i < plan.size(); ++i) {
    const std::string w = "simulate.plan[" + std::to_string(i) + "]";
    const json& e = plan[i];
    if (!e.is_object()) throw std::invalid_argument(w + ": expected an object");
    if (!e.contains("type") || !e["type"].is_string())
      throw std::invalid_argument(w + ".type: missing (facet, sphere, dbb, ball3d)");
    const std::string type = e["type"].get<std::string>();
    // The type first: an unknown one must be named as such, not reported
    // as whatever the other checks trip on.
    if (type == "facet") CheckKeys(e, {"type", "target", "axes", "point", "direction", "id"}, w);
    else if (type == "sphere") CheckKeys(e, {"type", "target", "axes", "normal", "direction", "id"}, w);
    else if (type == "dbb")
      CheckKeys(e, {"type", "setup", "axes", "length", "tool_ball", "table_ball", "direction", "id"}, w);
    else if (type == "ball3d")
      CheckKeys(e, {"type", "setup", "axes", "tool_ball", "table_ball", "direction", "id"}, w);
    else
      throw std::invalid_argument(w + ".type: unknown type " + Quote(type) + " (facet, sphere, dbb, ball3d)" +
                                  DidYouMean(type, {"facet", "sphere", "dbb", "ball3d"}));
    Observation ob;
    ob.axes = Eigen::VectorXd::Zero(na);
    ob.direction = Eigen::VectorXi::Zero(na);
    if (e.contains("id")) ob.id = ReadString(e, "id", w);
    std::vector<bool> given(na, false);
    if (e.contains("axes")) ReadAxes(m, e["axes"], w + ".axes", &ob.axes, &given);
    if (e.contains("direction")) ReadDirections(m, e["direction"], w + ".direction", &ob.direction);
    const bool probe = type == "facet" || type == "sphere";
    for (int k = 0; k < na; ++k)
      if (!given[k] && m.axis(k).name != 'S' && (m.axis(k).rotary() || !probe))
        throw std::invalid_argument(w + ".axes: missing axis '" + std::string(1, m.axis(k).name) +
                                    "' (machine axes " + m.axis_names() + ")");

    if (probe) {
      if (ds.tip_radius <= 0)
        throw std::invalid_argument("simulate.probe.tip_radius: missing or zero, but " + w + " is a probe touch");
      const double r = ds.tip_radius;
      if (!e.contains("target") || !e["target"].is_string())
        throw std::invalid_argument(w + ".target: missing");
      ob.target = e["target"].get<std::string>();
      Eigen::Vector3d n, c;
      std::function<double(const Eigen::Vector3d&)> gap;
      if (type == "facet") {
        ob.type = ObservationType::kFacet;
        const int fi = ds.artefact.FacetIndex(ob.target);
        if (fi < 0) throw std::invalid_argument(w + ".target: unknown facet " + Quote(ob.target));
        const Facet& f = ds.artefact.facets[fi];
        n = f.normal;
        Eigen::Vector3d p = e.contains("point") ? ReadVector3(e["point"], w + ".point") : f.point;
        p -= n * n.dot(p - f.point);  // onto the nominal plane
        c = p + r * n;
        const Eigen::Vector3d a_true = f.point + S("facet." + f.id) * n;
        gap = [=](const Eigen::Vector3d& P) { return n.dot(P - a_true) - r; };
      } else {
        ob.type = ObservationType::kSphere;
        const int si = ds.artefact.SphereIndex(ob.target);
        if (si < 0) throw std::invalid_argument(w + ".target: unknown sphere " + Quote(ob.target));
        const Sphere& s = ds.artefact.spheres[si];
        if (!e.contains("normal")) throw std::invalid_argument(w + ".normal: missing (touch direction from the centre)");
        n = ReadVector3(e["normal"], w + ".normal");
        if (n.norm() < 1e-12) throw std::invalid_argument(w + ".normal: zero vector");
        n.normalize();
        c = s.center + (s.radius + r) * n;
        const std::string id = s.id;
        const Eigen::Vector3d c_true = s.center + Eigen::Vector3d(S("sphere." + id + ".x"), S("sphere." + id + ".y"),
                                                                  S("sphere." + id + ".z"));
        const double R_true = s.radius + S("sphere." + id + ".r");
        gap = [=](const Eigen::Vector3d& P) { return (P - c_true).norm() - (R_true + r); };
      }
      // Nominal linear commands for the tip-centre target and the approach line.
      Eigen::MatrixXd target(2, 3);
      target.row(0) = c.transpose();
      target.row(1) = (c - n).transpose();
      const Eigen::MatrixXd cmds = InverseKinematics(m, nominal, target, nullptr, ob.axes);
      const Eigen::VectorXd c0 = cmds.row(0).transpose();
      const Eigen::VectorXd d = (cmds.row(1) - cmds.row(0)).transpose();  // per mm of approach
      std::vector<int> dir(ob.direction.data(), ob.direction.data() + na);
      for (int k = 0; k < na; ++k)
        if (!m.axis(k).rotary()) dir[k] = d[k] > 1e-12 ? 1 : (d[k] < -1e-12 ? -1 : 0);
      auto g = [&](double s) { return gap(ToolAt(m, theta, c0 + s * d, dir, tip_true)); };
      double s = 0;
      for (int it = 0; it < 60; ++it) {
        const double h = 1e-4;
        const double gs = g(s), gp = (g(s + h) - g(s - h)) / (2 * h);
        if (!(std::abs(gp) > 1e-6))
          throw std::invalid_argument(w + ": the approach does not reach the surface");
        const double ds_ = -gs / gp;
        s += ds_;
        if (std::abs(ds_) < 1e-13) break;
      }
      if (std::abs(s) > 50.0)
        throw std::invalid_argument(w + ": the erroneous machine touches " + std::to_string(s) +
                                    " mm away from the nominal point; errors far too large?");
      const double h = 1e-4;
      Slot slot;
      slot.start = c0;
      slot.approach = d;
      slot.s0 = s;
      slot.sensitivity = (g(s + h) - g(s - h)) / (2 * h);
      slots.push_back(slot);
      ob.axes = c0 + s * d;
      for (int k = 0; k < na; ++k) ob.direction[k] = dir[k];
    } else if (type == "dbb" || type == "ball3d") {
      ob.type = type == "dbb" ? ObservationType::kDbb : ObservationType::kBall3d;
      ob.setup = ReadSetup(e, w);
      ob.tool_ball = ReadVector3(e.value("tool_ball", json()), w + ".tool_ball");
      ob.table_ball = ReadVector3(e.value("table_ball", json()), w + ".table_ball");
      const std::string prefix = std::string(type) + (ob.setup.empty() ? "" : "." + ob.setup);
      const Eigen::Vector3d tool_true =
          ob.tool_ball + Eigen::Vector3d(S(prefix + ".tool.x"), S(prefix + ".tool.y"), S(prefix + ".tool.z"));
      const Eigen::Vector3d table_true =
          ob.table_ball + Eigen::Vector3d(S(prefix + ".table.x"), S(prefix + ".table.y"), S(prefix + ".table.z"));
      std::vector<int> dir(ob.direction.data(), ob.direction.data() + na);
      const Eigen::Vector3d P = ToolAt(m, theta, ob.axes, dir, tool_true);
      if (ob.type == ObservationType::kDbb) {
        if (!e.contains("length")) throw std::invalid_argument(w + ".length: missing (nominal bar length, mm)");
        ob.length = ReadBounded(e, "length", w, kMaxLinear);
        if (!(ob.length > 0)) throw std::invalid_argument(w + ".length: must be > 0 mm");
        ob.reading = (P - table_true).norm() - ob.length - S(prefix + ".length");
        // What the loader would refuse, refused here, naming the plan entry.
        if (!(std::abs(ob.reading) <= kMaxDbbReading))
          throw std::invalid_argument(w + ": the simulated reading " + std::to_string(ob.reading) +
                                      " mm is beyond a ball bar's range (|reading| <= 100 mm); is the "
                                      "bar length the ball distance at these axes?");
      } else {
        ob.measured = P - table_true;
      }
      slots.push_back(Slot());
    } else {
      throw std::invalid_argument(w + ".type: unknown type '" + type + "' (facet, sphere, dbb, ball3d)");
    }
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
    const double declared = o.type == ObservationType::kDbb      ? noise.dbb
                            : o.type == ObservationType::kBall3d ? noise.ball3d
                                                                 : noise.probe;
    if (declared > 0) o.sigma = Eigen::VectorXd::Constant(ResidualRows(o.type), declared);
    switch (o.type) {
      case ObservationType::kFacet:
      case ObservationType::kSphere:
        out.start[i] = slots[i].start;
        out.approach[i] = slots[i].approach;
        out.s0[i] = slots[i].s0;
        AddInput(&out, oi, 0, slots[i].sensitivity, noise.probe);
        break;
      case ObservationType::kDbb:
        AddInput(&out, oi, 0, -1.0, noise.dbb);
        break;
      case ObservationType::kBall3d:
        for (int c = 0; c < 3; ++c) AddInput(&out, oi, c, -1.0, noise.ball3d);
        break;
    }
  }
  return out;
}

}  // namespace

SimulationPlan PlanFromDataset(const Dataset& ds, const std::map<std::string, double>& values,
                               const NoiseLevels& noise) {
  ds.Validate();
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  const ParameterTable table(ds);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : values) {
    RequireFinite(value, "values." + name);
    v[table.Require(name)] = value;
  }
  const Eigen::VectorXd theta = v.head(m.num_parameters());
  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());
  const Eigen::Vector3d tip = TipWithOffsets<double>(m, theta.data());
  const Eigen::Vector3d tip0 = m.tip();

  SimulationPlan plan(ds);
  plan.noise = noise;
  plan.values = values;
  InitSlots(&plan);
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation& o = ds.observations[i];
    const int oi = static_cast<int>(i);
    const std::string w = "observations[" + std::to_string(i) + "]";
    std::vector<int> dir(o.direction.data(), o.direction.data() + na);
    switch (o.type) {
      case ObservationType::kFacet:
      case ObservationType::kSphere: {
        // Nominal approach: along minus the nominal surface normal at the
        // nominal tool point, as a line in linear-axis command space.
        const Eigen::Vector3d P0 = ToolAt(m, nominal, o.axes, dir, tip0);
        Eigen::Vector3d n;
        std::function<double(const Eigen::Vector3d&)> gap;
        if (o.type == ObservationType::kFacet) {
          const int fi = ds.artefact.FacetIndex(o.target);
          const Facet& f = ds.artefact.facets[fi];
          n = f.normal;
          const double off = v[table.facet(fi)];
          gap = [=](const Eigen::Vector3d& P) { return n.dot(P - f.point) - off; };
        } else {
          const int si = ds.artefact.SphereIndex(o.target);
          const Sphere& sp = ds.artefact.spheres[si];
          n = P0 - sp.center;
          if (n.norm() < 1e-9) throw std::invalid_argument(w + ": touch at the sphere centre");
          n.normalize();
          const auto& ix = table.sphere(si);
          const Eigen::Vector3d c = sp.center + Eigen::Vector3d(v[ix[0]], v[ix[1]], v[ix[2]]);
          gap = [=](const Eigen::Vector3d& P) { return (P - c).norm(); };
        }
        Eigen::MatrixXd target(2, 3);
        target.row(0) = P0.transpose();
        target.row(1) = (P0 - n).transpose();
        const Eigen::MatrixXd cmds = InverseKinematics(m, nominal, target, nullptr, o.axes);
        Eigen::VectorXd d = (cmds.row(1) - cmds.row(0)).transpose();
        for (int k = 0; k < na; ++k)
          if (m.axis(k).rotary()) d[k] = 0.0;
        plan.start[i] = o.axes;
        plan.approach[i] = d;
        plan.s0[i] = 0.0;
        const double h = 1e-4;
        const double sens = (gap(ToolAt(m, theta, o.axes + h * d, dir, tip)) -
                             gap(ToolAt(m, theta, o.axes - h * d, dir, tip))) / (2 * h);
        if (!(std::abs(sens) > 1e-6))
          throw std::invalid_argument(w + ": the nominal approach does not move the tip off the surface");
        AddInput(&plan, oi, 0, sens, noise.probe);
        break;
      }
      case ObservationType::kDbb:
        AddInput(&plan, oi, 0, -1.0, noise.dbb);
        break;
      case ObservationType::kBall3d:
        for (int c = 0; c < 3; ++c) AddInput(&plan, oi, c, -1.0, noise.ball3d);
        break;
    }
  }
  return plan;
}

}  // namespace fivecal
