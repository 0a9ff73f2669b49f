#include "fivecal/observations/dataset.h"

#include <cmath>
#include <set>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

}  // namespace

const char* ObservationTypeName(ObservationType t) { return KindOf(t).name(); }

int ResidualRows(ObservationType t) { return KindOf(t).rows(); }

double DefaultSigma(ObservationType t) { return KindOf(t).default_sigma(); }

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

void CheckSigma(const Eigen::VectorXd& sigma, ObservationType t, const std::string& where) {
  if (sigma.size() == 0) return;
  if (sigma.size() != ResidualRows(t))
    throw std::invalid_argument(where + ": expected a number or " + std::to_string(ResidualRows(t)) +
                                " values (one per residual row of a " + ObservationTypeName(t) +
                                " observation), got " + std::to_string(sigma.size()));
  for (int r = 0; r < sigma.size(); ++r)
    if (!(sigma[r] >= kMinSigma && sigma[r] <= kMaxSigma))
      throw std::invalid_argument(where + (sigma.size() > 1 ? "[" + std::to_string(r) + "]" : "") +
                                  ": must be a finite number > 0 mm (1e-9 to 1e3 mm)");
}

void ValidateScaleBars(const Artefact& artefact) {
  for (size_t i = 0; i < artefact.scale_bars.size(); ++i) {
    const ScaleBar& b = artefact.scale_bars[i];
    const std::string w = "dataset.artefact.scale_bars[" + std::to_string(i) + "]";
    for (const std::string& s : {b.sphere1, b.sphere2})
      if (artefact.SphereIndex(s) < 0)
        throw std::invalid_argument(w + ".spheres: unknown sphere " + Quote(s));
    if (b.sphere1 == b.sphere2)
      throw std::invalid_argument(w + ".spheres: joins sphere " + Quote(b.sphere1) +
                                  " to itself; a scale bar joins two different spheres");
    if (!(std::isfinite(b.length) && b.length > 0 && b.length <= kMaxLinear))
      throw std::invalid_argument(w + ".length: must be > 0 and <= 1e5 mm");
  }
}

Eigen::VectorXd ReadSigma(const json& j, ObservationType t, const std::string& where) {
  const int rows = ResidualRows(t);
  Eigen::VectorXd s;
  if (j.is_number()) {
    s = Eigen::VectorXd::Constant(rows, j.get<double>());
    if (!(s[0] >= kMinSigma && s[0] <= kMaxSigma))
      throw std::invalid_argument(where + ": must be a finite number > 0 mm (1e-9 to 1e3 mm)");
    return s;
  }
  if (!j.is_array())
    throw std::invalid_argument(where + ": expected a number (mm) or an array of " + std::to_string(rows));
  s.resize(static_cast<Eigen::Index>(j.size()));
  for (size_t r = 0; r < j.size(); ++r) {
    if (!j[r].is_number())
      throw std::invalid_argument(where + "[" + std::to_string(r) + "]: expected a number (mm)");
    s[static_cast<Eigen::Index>(r)] = j[r].get<double>();
  }
  CheckSigma(s, t, where);
  return s;
}
}  // namespace

Dataset Dataset::FromJson(const std::string& text, bool require_observations) {
  return Guard("dataset", [&] { return ParseDataset(Parse(text, "dataset"), require_observations); });
}

namespace {
const json* Find(const json& obj, const char* key) {
  auto it = obj.find(key);
  return it == obj.end() ? nullptr : &*it;
}

Dataset ParseDataset(const json& j, bool require_observations) {
  if (!j.is_object()) throw std::invalid_argument("dataset: expected a JSON object");
  CheckKeys(j, {"machine", "probe", "artefact", "observations", "$schema", "_comment"}, "dataset");
  if (!j.contains("machine")) throw std::invalid_argument("dataset.machine: missing");
  Dataset ds = [&] {
    try {
      return Dataset(Machine::FromJson(j["machine"].dump()));
    } catch (const std::invalid_argument& e) {
      // The machine parser names its fields "machine....", which inside a
      // dataset is "dataset.machine....".
      throw std::invalid_argument(std::string("dataset.") + e.what());
    }
  }();
  const Machine& m = ds.machine();

  if (j.contains("probe")) {
    const json& p = j["probe"];
    if (!p.is_object()) throw std::invalid_argument("dataset.probe: expected an object");
    CheckKeys(p, {"tip_radius"}, "dataset.probe");
    if (p.contains("tip_radius")) ds.tip_radius = ReadBounded(p, "tip_radius", "dataset.probe", kMaxLinear);
    if (ds.tip_radius < 0) throw std::invalid_argument("dataset.probe.tip_radius: must be >= 0 mm");
  }
  if (j.contains("artefact")) {
    const json& a = j["artefact"];
    if (!a.is_object()) throw std::invalid_argument("dataset.artefact: expected an object");
    CheckKeys(a, {"facets", "spheres", "scale_bars"}, "dataset.artefact");
    std::set<std::string> ids;
    auto item = [&](const json& list, size_t i, const char* what) -> const json& {
      const json& x = list[i];
      if (!x.is_object())
        throw std::invalid_argument("dataset.artefact." + std::string(what) + "[" + std::to_string(i) +
                                    "]: expected an object");
      return x;
    };
    if (a.contains("facets")) {
      const json& fs = a["facets"];
      if (!fs.is_array()) throw std::invalid_argument("dataset.artefact.facets: expected an array");
      for (size_t i = 0; i < fs.size(); ++i) {
        const std::string w = "dataset.artefact.facets[" + std::to_string(i) + "]";
        const json& fj = item(fs, i, "facets");
        CheckKeys(fj, {"id", "point", "normal"}, w);
        Facet f;
        f.id = ReadString(fj, "id", w);
        if (!ids.insert(f.id).second) throw std::invalid_argument(w + ".id: duplicate id " + Quote(f.id));
        f.point = ReadVector3(fj.value("point", json()), w + ".point");
        f.normal = ReadVector3(fj.value("normal", json()), w + ".normal");
        double n = f.normal.stableNorm();
        if (n < 1e-12) throw std::invalid_argument(w + ".normal: zero vector");
        if (std::abs(n - 1.0) > 1e-6)
          throw std::invalid_argument(w + ".normal: not a unit vector (norm " + std::to_string(n) + ")");
        f.normal /= n;
        ds.artefact.facets.push_back(f);
      }
    }
    if (a.contains("spheres")) {
      const json& ss = a["spheres"];
      if (!ss.is_array()) throw std::invalid_argument("dataset.artefact.spheres: expected an array");
      for (size_t i = 0; i < ss.size(); ++i) {
        const std::string w = "dataset.artefact.spheres[" + std::to_string(i) + "]";
        const json& sj = item(ss, i, "spheres");
        CheckKeys(sj, {"id", "center", "radius"}, w);
        Sphere s;
        s.id = ReadString(sj, "id", w);
        if (!ids.insert(s.id).second) throw std::invalid_argument(w + ".id: duplicate id " + Quote(s.id));
        s.center = ReadVector3(sj.value("center", json()), w + ".center");
        s.radius = ReadBounded(sj, "radius", w, kMaxLinear);
        if (s.radius <= 0) throw std::invalid_argument(w + ".radius: must be > 0 mm");
        ds.artefact.spheres.push_back(s);
      }
    }
    if (a.contains("scale_bars")) {
      const json& bs = a["scale_bars"];
      if (!bs.is_array()) throw std::invalid_argument("dataset.artefact.scale_bars: expected an array");
      for (size_t i = 0; i < bs.size(); ++i) {
        const std::string w = "dataset.artefact.scale_bars[" + std::to_string(i) + "]";
        const json& bj = item(bs, i, "scale_bars");
        CheckKeys(bj, {"spheres", "length"}, w);
        if (!bj.contains("spheres") || !bj["spheres"].is_array() || bj["spheres"].size() != 2)
          throw std::invalid_argument(w + ".spheres: expected two sphere ids");
        for (int k = 0; k < 2; ++k)
          if (!bj["spheres"][k].is_string())
            throw std::invalid_argument(w + ".spheres[" + std::to_string(k) + "]: expected a sphere id (a string)");
        ScaleBar b;
        b.sphere1 = bj["spheres"][0].get<std::string>();
        b.sphere2 = bj["spheres"][1].get<std::string>();
        b.length = ReadBounded(bj, "length", w, kMaxLinear);
        if (b.length <= 0) throw std::invalid_argument(w + ".length: must be > 0 mm");
        ds.artefact.scale_bars.push_back(b);
      }
    }
  }
  if (!j.contains("observations") || !j["observations"].is_array())
    throw std::invalid_argument("dataset.observations: missing (an array)");
  const json& obs = j["observations"];
  ds.observations.reserve(obs.size());
  std::vector<bool> given;
  for (size_t i = 0; i < obs.size(); ++i) {
    const std::string w = "dataset.observations[" + std::to_string(i) + "]";
    const json& o = obs[i];
    if (!o.is_object()) throw std::invalid_argument(w + ": expected an object");
    Observation ob;
    const json* tj = Find(o, "type");
    if (!tj || !tj->is_string()) throw std::invalid_argument(w + ".type: missing (a string)");
    const std::string& type = tj->get_ref<const std::string&>();
    const ObservationKind* kind = FindKind(type);
    if (!kind)
      throw std::invalid_argument(w + ".type: unknown type " + Quote(type) + " (" + KindList() + ")" +
                                  DidYouMean(type, KindNames()));
    ob.type = kind->type();
    CheckKeys(o, kind->json_keys(), w);
    const json* axes = Find(o, "axes");
    if (!axes || !axes->is_object())
      throw std::invalid_argument(w + ".axes: missing (an object axis letter -> reading)");
    ob.axes = Eigen::VectorXd::Zero(m.num_axes());
    ob.direction = Eigen::VectorXi::Zero(m.num_axes());
    ReadAxes(m, *axes, w + ".axes", &ob.axes, &given);
    for (int k = 0; k < m.num_axes(); ++k)
      if (!given[k] && m.axis(k).name != 'S')
        throw std::invalid_argument(w + ".axes: missing axis '" + std::string(1, m.axis(k).name) +
                                    "' (machine axes " + m.axis_names() + ")");
    if (const json* d = Find(o, "direction")) ReadDirections(m, *d, w + ".direction", &ob.direction);
    kind->Read(o, w, ds, &ob);
    if (const json* sj = Find(o, "sigma")) ob.sigma = ReadSigma(*sj, ob.type, w + ".sigma");
    if (o.contains("id")) ob.id = ReadString(o, "id", w);
    ds.observations.push_back(std::move(ob));
  }
  if (require_observations || !ds.observations.empty()) ds.Validate();
  else ValidateScaleBars(ds.artefact);
  return ds;
}
}  // namespace

void Dataset::Validate() const {
  if (observations.empty()) throw std::invalid_argument("dataset.observations: empty; nothing to fit");
  ValidateScaleBars(artefact);
  if (!(std::isfinite(tip_radius) && tip_radius >= 0 && tip_radius <= kMaxLinear))
    throw std::invalid_argument("dataset.probe.tip_radius: must be >= 0 and <= 1e5 mm");
  const int na = machine_.num_axes();
  for (size_t i = 0; i < observations.size(); ++i) {
    const Observation& o = observations[i];
    // Built only for a message: this loop runs over every sample of a trace.
    auto w = [i] { return "observations[" + std::to_string(i) + "]"; };
    if (o.axes.size() != na || o.direction.size() != na)
      throw std::invalid_argument(w() + ".axes: expected " + std::to_string(na) + " axis values (" +
                                  machine_.axis_names() + ")");
    for (int k = 0; k < na; ++k) {
      const bool rot = machine_.axis(k).rotary();
      if (!(std::abs(o.axes[k]) <= (rot ? kMaxRotaryDeg : kMaxLinear)))
        RequireBounded(o.axes[k], rot ? kMaxRotaryDeg : kMaxLinear,
                       w() + ".axes." + std::string(1, machine_.axis(k).name), rot ? "degrees" : "mm");
      if (o.direction[k] < -1 || o.direction[k] > 1)
        throw std::invalid_argument(w() + ".direction." + std::string(1, machine_.axis(k).name) +
                                    ": must be -1, 0 or +1");
    }
    KindOf(o).Validate(*this, o, w);
    if (o.sigma.size() > 0) CheckSigma(o.sigma, o.type, w() + ".sigma");
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
    KindOf(o).Write(o, &jo);
    if (o.sigma.size() > 0) {
      // One number when every row shares it (the usual file form).
      if ((o.sigma.array() == o.sigma[0]).all()) {
        jo["sigma"] = o.sigma[0];
      } else {
        json s = json::array();
        for (int r = 0; r < o.sigma.size(); ++r) s.push_back(o.sigma[r]);
        jo["sigma"] = s;
      }
    }
    if (!o.id.empty()) jo["id"] = o.id;
    obs.push_back(jo);
  }
  j["observations"] = obs;
  return j.dump();
}

}  // namespace fivecal
