#include "fivecal/dataset.h"

#include <cmath>
#include <set>
#include <stdexcept>

#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

}  // namespace

const char* ObservationTypeName(ObservationType t) {
  switch (t) {
    case ObservationType::kFacet: return "facet";
    case ObservationType::kSphere: return "sphere";
    case ObservationType::kDbb: return "dbb";
    case ObservationType::kBall3d: return "ball3d";
  }
  return "?";
}

int Artefact::FacetIndex(const std::string& id) const {
  for (size_t i = 0; i < facets.size(); ++i)
    if (facets[i].id == id) return static_cast<int>(i);
  return -1;
}

int Artefact::SphereIndex(const std::string& id) const {
  for (size_t i = 0; i < spheres.size(); ++i)
    if (spheres[i].id == id) return static_cast<int>(i);
  return -1;
}

namespace {
Dataset ParseDataset(const json& j, bool require_observations);
}

Dataset Dataset::FromJson(const std::string& text, bool require_observations) {
  return Guard("dataset", [&] { return ParseDataset(Parse(text, "dataset"), require_observations); });
}

namespace {
Dataset ParseDataset(const json& j, bool require_observations) {
  if (!j.is_object()) throw std::invalid_argument("dataset: expected a JSON object");
  if (!j.contains("machine")) throw std::invalid_argument("dataset.machine: missing");
  Dataset ds(Machine::FromJson(j["machine"].dump()));
  const Machine& m = ds.machine();

  if (j.contains("probe")) {
    const json& p = j["probe"];
    if (!p.is_object()) throw std::invalid_argument("dataset.probe: expected an object");
    if (p.contains("tip_radius")) ds.tip_radius = ReadNumber(p, "tip_radius", "probe");
    if (ds.tip_radius < 0) throw std::invalid_argument("probe.tip_radius: must be >= 0 mm");
  }
  if (j.contains("artefact")) {
    const json& a = j["artefact"];
    if (!a.is_object()) throw std::invalid_argument("dataset.artefact: expected an object");
    std::set<std::string> ids;
    if (a.contains("facets")) {
      const json& fs = a["facets"];
      if (!fs.is_array()) throw std::invalid_argument("artefact.facets: expected an array");
      for (size_t i = 0; i < fs.size(); ++i) {
        const std::string w = "artefact.facets[" + std::to_string(i) + "]";
        Facet f;
        f.id = ReadString(fs[i], "id", w);
        if (!ids.insert(f.id).second) throw std::invalid_argument(w + ".id: duplicate id '" + f.id + "'");
        f.point = ReadVector3(fs[i].value("point", json()), w + ".point");
        f.normal = ReadVector3(fs[i].value("normal", json()), w + ".normal");
        double n = f.normal.norm();
        if (n < 1e-12) throw std::invalid_argument(w + ".normal: zero vector");
        if (std::abs(n - 1.0) > 1e-6)
          throw std::invalid_argument(w + ".normal: not a unit vector (norm " + std::to_string(n) + ")");
        f.normal /= n;
        ds.artefact.facets.push_back(f);
      }
    }
    if (a.contains("spheres")) {
      const json& ss = a["spheres"];
      if (!ss.is_array()) throw std::invalid_argument("artefact.spheres: expected an array");
      for (size_t i = 0; i < ss.size(); ++i) {
        const std::string w = "artefact.spheres[" + std::to_string(i) + "]";
        Sphere s;
        s.id = ReadString(ss[i], "id", w);
        if (!ids.insert(s.id).second) throw std::invalid_argument(w + ".id: duplicate id '" + s.id + "'");
        s.center = ReadVector3(ss[i].value("center", json()), w + ".center");
        s.radius = ReadNumber(ss[i], "radius", w);
        if (s.radius <= 0) throw std::invalid_argument(w + ".radius: must be > 0 mm");
        ds.artefact.spheres.push_back(s);
      }
    }
    if (a.contains("scale_bars")) {
      const json& bs = a["scale_bars"];
      if (!bs.is_array()) throw std::invalid_argument("artefact.scale_bars: expected an array");
      for (size_t i = 0; i < bs.size(); ++i) {
        const std::string w = "artefact.scale_bars[" + std::to_string(i) + "]";
        if (!bs[i].contains("spheres") || !bs[i]["spheres"].is_array() || bs[i]["spheres"].size() != 2)
          throw std::invalid_argument(w + ".spheres: expected two sphere ids");
        ScaleBar b;
        b.sphere1 = bs[i]["spheres"][0].get<std::string>();
        b.sphere2 = bs[i]["spheres"][1].get<std::string>();
        b.length = ReadNumber(bs[i], "length", w);
        if (b.length <= 0) throw std::invalid_argument(w + ".length: must be > 0 mm");
        ds.artefact.scale_bars.push_back(b);
      }
    }
  }
  if (!j.contains("observations") || !j["observations"].is_array())
    throw std::invalid_argument("dataset.observations: missing (an array)");
  const json& obs = j["observations"];
  for (size_t i = 0; i < obs.size(); ++i) {
    const std::string w = "observations[" + std::to_string(i) + "]";
    const json& o = obs[i];
    if (!o.is_object()) throw std::invalid_argument(w + ": expected an object");
    Observation ob;
    const std::string type = ReadString(o, "type", w);
    if (type == "facet") ob.type = ObservationType::kFacet;
    else if (type == "sphere") ob.type = ObservationType::kSphere;
    else if (type == "dbb") ob.type = ObservationType::kDbb;
    else if (type == "ball3d") ob.type = ObservationType::kBall3d;
    else throw std::invalid_argument(w + ".type: unknown type '" + type +
                                     "' (facet, sphere, dbb, ball3d)");
    if (!o.contains("axes") || !o["axes"].is_object())
      throw std::invalid_argument(w + ".axes: missing (an object axis letter -> reading)");
    ob.axes = Eigen::VectorXd::Zero(m.num_axes());
    ob.direction = Eigen::VectorXi::Zero(m.num_axes());
    std::vector<bool> given(m.num_axes(), false);
    for (auto& [key, val] : o["axes"].items()) {
      const int k = AxisOfKey(m, key, w + ".axes." + key);
      if (!val.is_number()) throw std::invalid_argument(w + ".axes." + key + ": expected a number");
      ob.axes[k] = val.get<double>();
      RequireFinite(ob.axes[k], w + ".axes." + key);
      given[k] = true;
    }
    for (int k = 0; k < m.num_axes(); ++k)
      if (!given[k] && m.axis(k).name != 'S')
        throw std::invalid_argument(w + ".axes: missing axis '" + std::string(1, m.axis(k).name) +
                                    "' (machine axes " + m.axis_names() + ")");
    if (o.contains("direction")) {
      if (!o["direction"].is_object())
        throw std::invalid_argument(w + ".direction: expected an object axis letter -> +1/-1");
      for (auto& [key, val] : o["direction"].items()) {
        const int k = AxisOfKey(m, key, w + ".direction." + key);
        if (!val.is_number_integer() || std::abs(val.get<int>()) > 1)
          throw std::invalid_argument(w + ".direction." + key + ": must be -1, 0 or +1");
        ob.direction[k] = val.get<int>();
      }
    }
    switch (ob.type) {
      case ObservationType::kFacet:
      case ObservationType::kSphere: {
        ob.target = ReadString(o, "target", w);
        bool facet = ob.type == ObservationType::kFacet;
        int idx = facet ? ds.artefact.FacetIndex(ob.target) : ds.artefact.SphereIndex(ob.target);
        if (idx < 0)
          throw std::invalid_argument(w + ".target: unknown " + type + " '" + ob.target +
                                      "' (not in artefact." + (facet ? "facets" : "spheres") + ")");
        break;
      }
      case ObservationType::kDbb:
        ob.reading = ReadNumber(o, "reading", w);
        ob.length = ReadNumber(o, "length", w);
        if (ob.length <= 0) throw std::invalid_argument(w + ".length: must be > 0 mm");
        [[fallthrough]];
      case ObservationType::kBall3d:
        if (o.contains("setup")) ob.setup = ReadString(o, "setup", w);
        if (ob.setup.find('.') != std::string::npos)
          throw std::invalid_argument(w + ".setup: '" + ob.setup + "' must not contain '.'");
        ob.tool_ball = ReadVector3(o.value("tool_ball", json()), w + ".tool_ball");
        ob.table_ball = ReadVector3(o.value("table_ball", json()), w + ".table_ball");
        if (ob.type == ObservationType::kBall3d)
          ob.measured = ReadVector3(o.value("measured", json()), w + ".measured");
        break;
    }
    ds.observations.push_back(ob);
  }
  if (require_observations || !ds.observations.empty()) ds.Validate();
  return ds;
}
}  // namespace

void Dataset::Validate() const {
  if (observations.empty()) throw std::invalid_argument("dataset.observations: empty; nothing to fit");
  for (size_t i = 0; i < artefact.scale_bars.size(); ++i) {
    const ScaleBar& b = artefact.scale_bars[i];
    for (const std::string& s : {b.sphere1, b.sphere2})
      if (artefact.SphereIndex(s) < 0)
        throw std::invalid_argument("artefact.scale_bars[" + std::to_string(i) +
                                    "].spheres: unknown sphere '" + s + "'");
  }
  for (size_t i = 0; i < observations.size(); ++i) {
    const Observation& o = observations[i];
    const std::string w = "observations[" + std::to_string(i) + "]";
    if (o.axes.size() != machine_.num_axes() || o.direction.size() != machine_.num_axes())
      throw std::invalid_argument(w + ".axes: expected " + std::to_string(machine_.num_axes()) +
                                  " axis values (" + machine_.axis_names() + ")");
    for (int k = 0; k < o.axes.size(); ++k) {
      RequireFinite(o.axes[k], w + ".axes." + std::string(1, machine_.axis(k).name));
      if (std::abs(o.direction[k]) > 1)
        throw std::invalid_argument(w + ".direction: must be -1, 0 or +1");
    }
    if ((o.type == ObservationType::kFacet || o.type == ObservationType::kSphere) && tip_radius <= 0)
      throw std::invalid_argument("probe.tip_radius: missing or zero but the dataset has probe touches");
    if (o.type == ObservationType::kFacet && artefact.FacetIndex(o.target) < 0)
      throw std::invalid_argument(w + ".target: unknown facet '" + o.target + "'");
    if (o.type == ObservationType::kSphere && artefact.SphereIndex(o.target) < 0)
      throw std::invalid_argument(w + ".target: unknown sphere '" + o.target + "'");
  }
}

void Dataset::AppendBallSamples(ObservationType type, const std::string& setup,
                                const Eigen::MatrixXd& axes, const Eigen::MatrixXi* dirs,
                                const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball,
                                double length, const Eigen::MatrixXd& values) {
  const int n = static_cast<int>(axes.rows()), na = machine_.num_axes();
  if (type != ObservationType::kDbb && type != ObservationType::kBall3d)
    throw std::invalid_argument("ball samples: type must be dbb or ball3d");
  const int width = type == ObservationType::kDbb ? 1 : 3;
  if (axes.cols() != na)
    throw std::invalid_argument("ball samples: axes must have " + std::to_string(na) + " columns (" +
                                machine_.axis_names() + ")");
  if (values.rows() != n || values.cols() != width)
    throw std::invalid_argument(std::string("ball samples: ") +
                                (width == 1 ? "readings" : "measured") + " must be " +
                                std::to_string(n) + " x " + std::to_string(width));
  if (dirs && (dirs->rows() != n || dirs->cols() != na))
    throw std::invalid_argument("ball samples: directions must match axes");
  if (setup.find('.') != std::string::npos)
    throw std::invalid_argument("ball samples: setup '" + setup + "' must not contain '.'");
  for (int i = 0; i < 3; ++i) {
    RequireFinite(tool_ball[i], "ball samples: tool_ball");
    RequireFinite(table_ball[i], "ball samples: table_ball");
  }
  if (type == ObservationType::kDbb && !(length > 0))
    throw std::invalid_argument("ball samples: length must be > 0 mm");
  observations.reserve(observations.size() + n);
  for (int r = 0; r < n; ++r) {
    Observation o;
    o.type = type;
    o.setup = setup;
    o.axes = axes.row(r).transpose();
    o.direction = dirs ? Eigen::VectorXi(dirs->row(r).transpose()) : Eigen::VectorXi::Zero(na);
    for (int k = 0; k < na; ++k) {
      RequireFinite(o.axes[k], "ball samples: axes." + std::string(1, machine_.axis(k).name) + "[" +
                                   std::to_string(r) + "]");
      if (std::abs(o.direction[k]) > 1)
        throw std::invalid_argument("ball samples: directions must be -1, 0 or +1");
    }
    o.tool_ball = tool_ball;
    o.table_ball = table_ball;
    if (type == ObservationType::kDbb) {
      o.length = length;
      o.reading = values(r, 0);
      RequireFinite(o.reading, "ball samples: readings[" + std::to_string(r) + "]");
    } else {
      o.measured = values.row(r).transpose();
      for (int c = 0; c < 3; ++c) RequireFinite(o.measured[c], "ball samples: measured[" + std::to_string(r) + "]");
    }
    observations.push_back(std::move(o));
  }
}

Dataset Dataset::Subset(const std::vector<int>& indices) const {
  Dataset d(machine_);
  d.tip_radius = tip_radius;
  d.artefact = artefact;
  for (int i : indices) {
    if (i < 0 || i >= static_cast<int>(observations.size()))
      throw std::invalid_argument("subset: observation index " + std::to_string(i) + " out of range");
    d.observations.push_back(observations[i]);
  }
  return d;
}

std::string Dataset::ToJson() const {
  json j;
  j["machine"] = json::parse(machine_.ToJson());
  j["probe"] = {{"tip_radius", tip_radius}};
  json facets = json::array(), spheres = json::array(), bars = json::array();
  for (const Facet& f : artefact.facets)
    facets.push_back({{"id", f.id}, {"point", Array3(f.point)}, {"normal", Array3(f.normal)}});
  for (const Sphere& s : artefact.spheres)
    spheres.push_back({{"id", s.id}, {"center", Array3(s.center)}, {"radius", s.radius}});
  for (const ScaleBar& b : artefact.scale_bars)
    bars.push_back({{"spheres", {b.sphere1, b.sphere2}}, {"length", b.length}});
  j["artefact"] = {{"facets", facets}, {"spheres", spheres}, {"scale_bars", bars}};
  json obs = json::array();
  for (const Observation& o : observations) {
    json jo;
    jo["type"] = ObservationTypeName(o.type);
    if (!o.target.empty()) jo["target"] = o.target;
    if (!o.setup.empty()) jo["setup"] = o.setup;
    json ax = json::object(), dir = json::object();
    for (int k = 0; k < machine_.num_axes(); ++k) {
      const std::string a(1, machine_.axis(k).name);
      ax[a] = o.axes[k];
      if (o.direction[k] != 0) dir[a] = o.direction[k];
    }
    jo["axes"] = ax;
    if (!dir.empty()) jo["direction"] = dir;
    if (o.type == ObservationType::kDbb) {
      jo["reading"] = o.reading;
      jo["length"] = o.length;
    }
    if (o.type == ObservationType::kDbb || o.type == ObservationType::kBall3d) {
      jo["tool_ball"] = Array3(o.tool_ball);
      jo["table_ball"] = Array3(o.table_ball);
    }
    if (o.type == ObservationType::kBall3d) jo["measured"] = Array3(o.measured);
    obs.push_back(jo);
  }
  j["observations"] = obs;
  return j.dump();
}

}  // namespace fivecal
