#include "fivecal/simulate.h"

#include <cmath>
#include <random>
#include <stdexcept>

#include "fivecal/inverse.h"
#include "fivecal/kinematics.h"
#include "fivecal/problem.h"
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
Dataset SimulateSpec(const json& spec);
}

Dataset Simulate(const std::string& spec_text) {
  return Guard("simulate", [&] { return SimulateSpec(Parse(spec_text, "simulate")); });
}

namespace {
Dataset SimulateSpec(const json& spec) {
  if (!spec.is_object() || !spec.contains("machine"))
    throw std::invalid_argument("simulate: missing 'machine'");
  json base = {{"machine", spec["machine"]},
               {"probe", spec.value("probe", json::object())},
               {"artefact", spec.value("artefact", json::object())},
               {"observations", json::array()}};
  Dataset ds = Dataset::FromJson(base.dump(), false);
  const Machine& m = ds.machine();
  const int na = m.num_axes();

  Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  if (spec.contains("errors")) theta = ErrorModel::FromJson(m, spec["errors"].dump()).values();
  std::map<std::string, double> setup;
  if (spec.contains("setup")) {
    if (!spec["setup"].is_object()) throw std::invalid_argument("simulate.setup: expected an object");
    for (auto& [k, v] : spec["setup"].items()) {
      if (!v.is_number()) throw std::invalid_argument("setup." + k + ": expected a number");
      setup[k] = v.get<double>();
      RequireFinite(setup[k], "setup." + k);
    }
  }
  auto S = [&](const std::string& n) {
    auto it = setup.find(n);
    return it == setup.end() ? 0.0 : it->second;
  };
  NoiseLevels noise;
  if (spec.contains("sigma")) {
    const json& s = spec["sigma"];
    if (s.is_number()) noise.probe = noise.dbb = noise.ball3d = s.get<double>();
    else if (s.is_object()) {
      noise.probe = s.value("probe", 0.0);
      noise.dbb = s.value("dbb", 0.0);
      noise.ball3d = s.value("ball3d", 0.0);
    } else throw std::invalid_argument("simulate.sigma: expected a number or an object");
    for (double x : {noise.probe, noise.dbb, noise.ball3d})
      if (!(x >= 0) || !std::isfinite(x)) throw std::invalid_argument("simulate.sigma: must be >= 0 mm");
  }
  const uint64_t seed = spec.value("seed", uint64_t{0});
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);

  if (!spec.contains("plan") || !spec["plan"].is_array() || spec["plan"].empty())
    throw std::invalid_argument("simulate.plan: empty; give at least one planned touch or sample");
  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());
  const Eigen::Vector3d tip_true = TipWithOffsets<double>(m, theta.data());
  const json& plan = spec["plan"];

  for (size_t i = 0; i < plan.size(); ++i) {
    const std::string w = "plan[" + std::to_string(i) + "]";
    const json& e = plan[i];
    if (!e.is_object() || !e.contains("type") || !e["type"].is_string())
      throw std::invalid_argument(w + ".type: missing");
    const std::string type = e["type"].get<std::string>();
    Observation ob;
    ob.axes = Eigen::VectorXd::Zero(na);
    ob.direction = Eigen::VectorXi::Zero(na);
    std::vector<bool> given(na, false);
    if (e.contains("axes")) {
      if (!e["axes"].is_object()) throw std::invalid_argument(w + ".axes: expected an object");
      for (auto& [key, v] : e["axes"].items()) {
        const int k = AxisOfKey(m, key, w + ".axes." + key);
        if (!v.is_number()) throw std::invalid_argument(w + ".axes." + key + ": expected a number");
        ob.axes[k] = v.get<double>();
        RequireFinite(ob.axes[k], w + ".axes." + key);
        given[k] = true;
      }
    }
    if (e.contains("direction")) {
      for (auto& [key, v] : e["direction"].items()) {
        const int k = AxisOfKey(m, key, w + ".direction." + key);
        if (!v.is_number_integer() || std::abs(v.get<int>()) > 1)
          throw std::invalid_argument(w + ".direction." + key + ": must be -1, 0 or +1");
        ob.direction[k] = v.get<int>();
      }
    }
    const bool probe = type == "facet" || type == "sphere";
    for (int k = 0; k < na; ++k)
      if (!given[k] && m.axis(k).name != 'S' && (m.axis(k).rotary() || !probe))
        throw std::invalid_argument(w + ".axes: missing axis '" + std::string(1, m.axis(k).name) + "'");

    if (probe) {
      if (ds.tip_radius <= 0) throw std::invalid_argument("probe.tip_radius: missing or zero");
      const double r = ds.tip_radius;
      if (!e.contains("target") || !e["target"].is_string())
        throw std::invalid_argument(w + ".target: missing");
      ob.target = e["target"].get<std::string>();
      Eigen::Vector3d n, c;
      std::function<double(const Eigen::Vector3d&)> gap;
      if (type == "facet") {
        ob.type = ObservationType::kFacet;
        const int fi = ds.artefact.FacetIndex(ob.target);
        if (fi < 0) throw std::invalid_argument(w + ".target: unknown facet '" + ob.target + "'");
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
        if (si < 0) throw std::invalid_argument(w + ".target: unknown sphere '" + ob.target + "'");
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
      s += noise.probe * normal(rng);
      ob.axes = c0 + s * d;
      for (int k = 0; k < na; ++k) ob.direction[k] = dir[k];
    } else if (type == "dbb" || type == "ball3d") {
      ob.type = type == "dbb" ? ObservationType::kDbb : ObservationType::kBall3d;
      if (e.contains("setup")) ob.setup = e["setup"].get<std::string>();
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
        ob.length = e["length"].get<double>();
        ob.reading = (P - table_true).norm() - ob.length - S(prefix + ".length") + noise.dbb * normal(rng);
      } else {
        ob.measured = P - table_true;
        for (int c = 0; c < 3; ++c) ob.measured[c] += noise.ball3d * normal(rng);
      }
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
  ds.Validate();
  const ParameterTable table(ds);
  for (const auto& kv : setup) {
    const int idx = table.Index(kv.first);
    if (idx < 0 || idx < table.num_machine())
      throw std::invalid_argument("setup." + kv.first + ": not a setup parameter of this dataset");
  }
  return ds;
}

}  // namespace
}  // namespace fivecal
