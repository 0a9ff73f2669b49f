#include "fivecal/observations/dataset.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdint>
#include <tuple>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <set>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/columns.h"
#include "fivecal/observations/dataset_reader.h"
#include "fivecal/observations/registry.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"
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

void Observation::WrongPayload(const char* wanted) const {
  std::string type_name;
  try {
    type_name = ObservationTypeName(type);
  } catch (const std::exception&) {
    type_name = "code " + std::to_string(static_cast<int>(type));
  }
  throw std::invalid_argument("observation" + (id.empty() ? std::string() : " " + Quote(id)) + " of type " +
                              Quote(type_name) + " holds " + PayloadName(payload) + ", not " + wanted);
}

const std::string& PayloadTarget(const Observation& o) {
  static const std::string none;
  struct Visitor {
    const std::string& operator()(const TouchData& d) const { return d.target; }
    const std::string& operator()(const FixedTargetData& d) const { return d.target; }
    const std::string& operator()(const MachinedData& d) const { return d.feature; }
    const std::string& operator()(const BallMountData&) const { return none; }
    const std::string& operator()(const KindOwnData&) const { return none; }
  };
  return std::visit(Visitor(), o.payload);
}

const std::string* InstrumentId(const Observation& o) {
  return KindOf(o).instrument_key() ? &o.setup : nullptr;
}

int Artefact::CylinderIndex(const std::string& id) const {
  for (size_t i = 0; i < cylinders.size(); ++i)
    if (cylinders[i].id == id) return static_cast<int>(i);
  return -1;
}

namespace {
// Whether every residual row of a kind has the same unit (then one number
// may declare the noise of all of them).
bool OneUnit(const ObservationKind& k) {
  for (int r = 1; r < k.rows(); ++r)
    if (std::string(k.unit_row(r)) != k.unit_row(0)) return false;
  return true;
}

std::string RowUnits(const ObservationKind& k) {
  if (OneUnit(k)) return k.unit_row(0);
  std::string u;
  for (int r = 0; r < k.rows(); ++r) u += (r ? ", " : "") + std::string(k.unit_row(r));
  return "[" + u + "]";
}

// `where()` names the field; called only to build a message (the check runs
// on every observation that declares its sigma).
template <typename Where>
void CheckSigmaOf(const Eigen::VectorXd& sigma, ObservationType t, const Where& where) {
  if (sigma.size() == 0) return;
  const ObservationKind& k = KindOf(t);
  if (sigma.size() != k.rows())
    throw std::invalid_argument(where() + ": expected " + (OneUnit(k) ? "a number or " : "") +
                                std::to_string(k.rows()) + (k.rows() == 1 ? " value" : " values") +
                                " (one per residual row of a " + k.name() +
                                " observation, " + RowUnits(k) + "), got " + std::to_string(sigma.size()));
  for (int r = 0; r < sigma.size(); ++r)
    if (!(sigma[r] >= kMinSigma && sigma[r] <= kMaxSigma))
      throw std::invalid_argument(where() + (sigma.size() > 1 ? "[" + std::to_string(r) + "]" : "") +
                                  ": must be a finite number > 0 " + k.unit_row(r) + " (1e-9 to 1e3)");
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

template <typename Where>
Eigen::VectorXd ReadSigmaOf(const json& j, ObservationType t, const Where& where) {
  const ObservationKind& k = KindOf(t);
  const int rows = k.rows();
  Eigen::VectorXd s;
  if (j.is_number()) {
    if (!OneUnit(k))
      throw std::invalid_argument(where() + ": a " + std::string(k.name()) + " observation's rows are in " +
                                  RowUnits(k) + ": give " + std::to_string(rows) + " values, not one number");
    s = Eigen::VectorXd::Constant(rows, j.get<double>());
    if (!(s[0] >= kMinSigma && s[0] <= kMaxSigma))
      throw std::invalid_argument(where() + ": must be a finite number > 0 " + k.unit_row(0) + " (1e-9 to 1e3)");
    return s;
  }
  if (!j.is_array())
    throw std::invalid_argument(where() + ": expected " + (OneUnit(k) ? "a number (" + RowUnits(k) + ") or " : "") +
                                "an array of " + std::to_string(rows) + " (" + RowUnits(k) + ")");
  s.resize(static_cast<Eigen::Index>(j.size()));
  for (size_t r = 0; r < j.size(); ++r) {
    if (!j[r].is_number())
      throw std::invalid_argument(where() + "[" + std::to_string(r) + "]: expected a number");
    s[static_cast<Eigen::Index>(r)] = j[r].get<double>();
  }
  CheckSigmaOf(s, t, where);
  return s;
}

// "instruments": {"<id>": {"sigma": number | [per row]}}. Read raw here (the
// observations decide which kind, hence how many rows, each id has) and
// checked once they are read (CheckInstruments).
std::map<std::string, Eigen::VectorXd> ReadInstruments(const json& j) {
  const std::string w = "dataset.instruments";
  if (!j.is_object()) throw std::invalid_argument(w + ": expected an object (instrument id -> {\"sigma\": ...})");
  std::map<std::string, Eigen::VectorXd> out;
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string wi = w + "." + it.key();
    if (!it->is_object()) throw std::invalid_argument(wi + ": expected an object {\"sigma\": ...}");
    CheckKeys(*it, {"sigma"}, wi);
    if (!it->contains("sigma")) throw std::invalid_argument(wi + ".sigma: missing");
    const json& sj = (*it)["sigma"];
    Eigen::VectorXd s;
    if (sj.is_number()) {
      s = Eigen::VectorXd::Constant(1, sj.get<double>());
    } else if (sj.is_array() && !sj.empty()) {
      s.resize(static_cast<Eigen::Index>(sj.size()));
      for (size_t r = 0; r < sj.size(); ++r) {
        if (!sj[r].is_number())
          throw std::invalid_argument(wi + ".sigma[" + std::to_string(r) + "]: expected a number");
        s[static_cast<Eigen::Index>(r)] = sj[r].get<double>();
      }
    } else {
      throw std::invalid_argument(wi + ".sigma: expected a number or an array (one per residual row)");
    }
    for (int r = 0; r < s.size(); ++r)
      if (!(s[r] >= kMinSigma && s[r] <= kMaxSigma))
        throw std::invalid_argument(wi + ".sigma" + (sj.is_array() ? "[" + std::to_string(r) + "]" : "") +
                                    ": must be a finite number > 0 (1e-9 to 1e3)");
    out[it.key()] = s;
  }
  return out;
}

// Every instrument sigma fits the kinds of the observations naming it: one
// value per row (or one number when the rows share a unit). `loaded`: also
// refuse an id no observation names (a typo in a file would otherwise leave
// the instrument at its kind's default without a word).
void CheckInstruments(const Dataset& ds, bool loaded) {
  if (ds.instrument_sigma.empty()) return;
  std::map<std::string, std::set<const ObservationKind*>> kinds;
  std::vector<std::string> ids;
  auto note = [&](const Observation& o) {
    if (const std::string* id = InstrumentId(o))
      if (kinds[*id].insert(&KindOf(o)).second && kinds[*id].size() == 1) ids.push_back(*id);
  };
  for (const Observation& o : ds.observations) note(o);
  // A block's rows share their set-up: its first row stands for all.
  Observation first;
  for (const TraceBlock& b : ds.blocks)
    if (b.size()) {
      ds.FillRow(b, 0, &first);
      note(first);
    }
  for (const auto& [id, s] : ds.instrument_sigma) {
    const std::string w = "dataset.instruments." + id + ".sigma";
    auto it = kinds.find(id);
    if (it == kinds.end()) {
      if (!loaded) continue;
      throw std::invalid_argument("dataset.instruments." + id + ": no observation names this instrument" +
                                  (ids.empty() ? std::string(" (no observation has an instrument or station)")
                                               : " (instruments and stations: " + [&] {
                                                   std::string l;
                                                   for (const std::string& x : ids) l += (l.empty() ? "" : ", ") + x;
                                                   return l;
                                                 }() + ")" + DidYouMean(id, ids)));
    }
    for (const ObservationKind* k : it->second) {
      if (s.size() == 1 && OneUnit(*k)) continue;
      if (s.size() != k->rows())
        throw std::invalid_argument(w + ": " + std::to_string(s.size()) + " value" + (s.size() == 1 ? "" : "s") +
                                    " for a " + k->name() + " instrument, whose observations have " +
                                    std::to_string(k->rows()) + " residual rows (" + RowUnits(*k) + ")" +
                                    (OneUnit(*k) ? ": give one number or one per row" : ": give one per row"));
    }
  }
}
}  // namespace

namespace {
const json* Find(const json& obj, const char* key) {
  auto it = obj.find(key);
  return it == obj.end() ? nullptr : &*it;
}

// Everything but the observations: machine, probe and artefact, checked in
// the order the messages promise (unknown top-level keys first).
Dataset ParseHead(const json& j) {
  if (!j.is_object()) throw std::invalid_argument("dataset: expected a JSON object");
  CheckKeys(j, {"machine", "probe", "artefact", "instruments", "setup_uncertainty", "observations", "$schema", "_comment"},
            "dataset");
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
    CheckKeys(a, {"facets", "spheres", "scale_bars", "cylinders"}, "dataset.artefact");
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
    if (a.contains("cylinders")) {
      const json& cs = a["cylinders"];
      if (!cs.is_array()) throw std::invalid_argument("dataset.artefact.cylinders: expected an array");
      for (size_t i = 0; i < cs.size(); ++i) {
        const std::string w = "dataset.artefact.cylinders[" + std::to_string(i) + "]";
        const json& cj = item(cs, i, "cylinders");
        CheckKeys(cj, {"id", "point", "axis", "radius", "inside"}, w);
        Cylinder c;
        c.id = ReadString(cj, "id", w);
        if (!ids.insert(c.id).second) throw std::invalid_argument(w + ".id: duplicate id " + Quote(c.id));
        c.point = ReadVector3(cj.value("point", json()), w + ".point");
        c.axis = ReadVector3(cj.value("axis", json()), w + ".axis");
        const double n = c.axis.stableNorm();
        if (n < 1e-12) throw std::invalid_argument(w + ".axis: zero vector");
        if (std::abs(n - 1.0) > 1e-6)
          throw std::invalid_argument(w + ".axis: not a unit vector (norm " + std::to_string(n) + ")");
        c.axis /= n;
        c.radius = ReadBounded(cj, "radius", w, kMaxLinear);
        if (c.radius <= 0) throw std::invalid_argument(w + ".radius: must be > 0 mm");
        if (cj.contains("inside")) {
          if (!cj["inside"].is_boolean()) throw std::invalid_argument(w + ".inside: expected true or false");
          c.inside = cj["inside"].get<bool>();
        }
        ds.artefact.cylinders.push_back(c);
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
  if (j.contains("instruments")) ds.instrument_sigma = ReadInstruments(j["instruments"]);
  if (j.contains("setup_uncertainty")) {
    // The names are checked against the dataset's set-up parameters once the
    // observations are read (Validate).
    const std::string w = "dataset.setup_uncertainty";
    const json& u = j["setup_uncertainty"];
    if (!u.is_object())
      throw std::invalid_argument(w + ": expected an object (set-up parameter or class:<class> -> sigma, "
                                      "in the parameter's unit)");
    for (auto it = u.begin(); it != u.end(); ++it) {
      if (!it->is_number())
        throw std::invalid_argument(w + "['" + it.key() + "']: expected a number (one sigma, mm or rad)");
      ds.setup_uncertainty[it.key()] = it->get<double>();
    }
  }
  return ds;
}

// The name of observation i in messages, built only when one is needed: the
// checks below run on every one of 10^6 observations, and on their common
// path (a valid field) each does the test inline; only a field that fails it
// goes through the json_util reader, which names what is wrong (or accepts a
// rarer valid form).
//
// The kinds' Read takes the name as a string, so it is built for every
// observation: into one buffer per thread, which after the first
// observation allocates nothing (one observation is parsed at a time per
// thread; a message copies the name before it is thrown).
class ObservationName {
 public:
  explicit ObservationName(size_t i) : i_(i) {}
  const std::string& operator()() {
    static thread_local std::string buffer;
    if (!built_) {
      char digits[24];
      const int n = std::snprintf(digits, sizeof digits, "%zu", i_);
      buffer.assign("dataset.observations[");
      buffer.append(digits, static_cast<size_t>(n));
      buffer.push_back(']');
      built_ = true;
    }
    return buffer;
  }

 private:
  size_t i_;
  bool built_ = false;
};

void CheckKeysOf(const json& o, const std::vector<const char*>& allowed, ObservationName& w) {
  for (auto it = o.begin(); it != o.end(); ++it) {
    const std::string& key = it.key();
    if (std::none_of(allowed.begin(), allowed.end(), [&](const char* a) { return key == a; }))
      CheckKeys(o, allowed, w());  // throws, naming the key
  }
}

std::string StringOf(const json& o, const char* key, ObservationName& w) {
  const json* v = Find(o, key);
  if (v && v->is_string()) return v->get<std::string>();
  return ReadString(o, key, w());
}

// Observation i of dataset `ds` (its machine and artefact are read; the
// artefact resolves the targets of probe touches). `given` is scratch space
// shared by the calls. The common fields (axes, direction) take a fast path;
// each kind reads its own fields (ObservationKind::Read).
Observation ParseObservation(const Dataset& ds, const json& o, size_t i, std::vector<bool>* given) {
  const Machine& m = ds.machine();
  ObservationName w(i);
  if (!o.is_object()) throw std::invalid_argument(w() + ": expected an object");
  Observation ob;
  const json* tj = Find(o, "type");
  if (!tj || !tj->is_string()) throw std::invalid_argument(w() + ".type: missing (a string)");
  const std::string& type = tj->get_ref<const std::string&>();
  const ObservationKind* kind = FindKind(type);
  if (!kind)
    throw std::invalid_argument(w() + ".type: unknown type " + Quote(type) + " (" + KindList() + ")" +
                                DidYouMean(type, KindNames()));
  ob.type = kind->type();
  ob.payload = kind->NewPayload();
  CheckKeysOf(o, kind->json_keys(), w);
  const json* axes = Find(o, "axes");
  if (!axes || !axes->is_object())
    throw std::invalid_argument(w() + ".axes: missing (an object axis letter -> reading)");
  const int na = m.num_axes();
  ob.axes = Eigen::VectorXd::Zero(na);
  ob.direction = Eigen::VectorXi::Zero(na);
  given->assign(na, false);
  bool plain = true;
  for (auto it = axes->begin(); plain && it != axes->end(); ++it) {
    const std::string& key = it.key();
    const int k = key.size() == 1 ? m.AxisIndex(key[0]) : -1;  // "C1" and errors: ReadAxes
    plain = k >= 0 && !(*given)[k] && it->is_number();
    if (plain) {
      const double x = it->get<double>();
      plain = std::abs(x) <= (m.axis(k).rotary() ? kMaxRotaryDeg : kMaxLinear);
      ob.axes[k] = x;
      (*given)[k] = true;
    }
  }
  if (!plain) ReadAxes(m, *axes, w() + ".axes", &ob.axes, given);
  for (int k = 0; k < na; ++k)
    if (!(*given)[k] && m.axis(k).name != 'S')
      throw std::invalid_argument(w() + ".axes: missing axis '" + std::string(1, m.axis(k).name) +
                                  "' (machine axes " + m.axis_names() + ")");
  if (const json* d = Find(o, "direction")) {
    plain = d->is_object();
    std::vector<bool>& seen = *given;  // free again: the axes are read
    seen.assign(na, false);
    for (auto it = d->begin(); plain && it != d->end(); ++it) {
      const std::string& key = it.key();
      const int k = key.size() == 1 ? m.AxisIndex(key[0]) : -1;
      int64_t x = 0;
      plain = k >= 0 && !seen[k] && IntegralValue(*it, &x) && x >= -1 && x <= 1;
      if (plain) {
        ob.direction[k] = static_cast<int>(x);
        seen[k] = true;
      }
    }
    if (!plain) {
      ob.direction.setZero();
      ReadDirections(m, *d, w() + ".direction", &ob.direction);
    }
  }
  kind->Read(o, w(), ds, &ob);
  if (const json* sj = Find(o, "sigma")) ob.sigma = ReadSigmaOf(*sj, ob.type, [&] { return w() + ".sigma"; });
  if (o.contains("id")) ob.id = StringOf(o, "id", w);
  return ob;
}

void Finish(Dataset* ds, bool require_observations) {
  if (require_observations || !ds->observations.empty()) ds->Validate();
  else ValidateScaleBars(ds->artefact);
  CheckInstruments(*ds, !ds->observations.empty());
}

Dataset ParseDataset(const json& j, bool require_observations) {
  Dataset ds = ParseHead(j);
  if (!j.contains("observations") || !j["observations"].is_array())
    throw std::invalid_argument("dataset.observations: missing (an array)");
  const json& obs = j["observations"];
  ds.observations.reserve(obs.size());
  std::vector<bool> given;
  for (size_t i = 0; i < obs.size(); ++i)
    ds.observations.push_back(ParseObservation(ds, obs[i], i, &given));
  Finish(&ds, require_observations);
  return ds;
}

// One JSON value built from SAX events, as json::parse builds it (a repeated
// key keeps its last value).
class ValueBuilder {
 public:
  json root;
  void Reset() {
    root = json();
    stack_.clear();
  }
  template <typename V>
  void Put(V&& v) {
    if (stack_.empty()) {
      root = std::forward<V>(v);
    } else if (stack_.back()->is_array()) {
      stack_.back()->emplace_back(std::forward<V>(v));
    } else {
      *slot_ = std::forward<V>(v);
    }
  }
  void Open(json empty) {
    json* p;
    if (stack_.empty()) {
      root = std::move(empty);
      p = &root;
    } else if (stack_.back()->is_array()) {
      p = &stack_.back()->emplace_back(std::move(empty));
    } else {
      *slot_ = std::move(empty);
      p = slot_;
    }
    stack_.push_back(p);
  }
  void Key(const std::string& k) { slot_ = &(*stack_.back())[k]; }
  void Close() { stack_.pop_back(); }

 private:
  std::vector<json*> stack_;
  json* slot_ = nullptr;
};

// Reads a dataset text without building the JSON document of its
// observations: each one is built alone, converted and dropped. A document of
// 10^6 observations is ~10^7 heap nodes whose allocation and release cost more
// than the rest of the load; streaming keeps memory flat and the load linear.
// Only the common layout streams (machine, and artefact when probe touches
// need it, before the observations; no repeated top-level key; valid JSON);
// anything else returns with fallback set and the document parser decides, so
// every message is the one the document path gives.
// The SAX events of one observation, recorded into reused storage (no heap
// traffic once warm): the common observation converts straight from them;
// any other is replayed into a JSON value for ParseObservation, whose checks
// and messages are the reference.
struct Event {
  enum Kind : unsigned char { kNull, kBool, kInt, kUint, kFloat, kString, kKey, kObject, kEndObject, kArray, kEndArray };
  Kind kind = kNull;
  bool b = false;
  int64_t i = 0;
  uint64_t u = 0;
  double d = 0;
  std::string s;  // a key or a string value
  bool number() const { return kind == kInt || kind == kUint || kind == kFloat; }
  // As json::get<double> converts.
  double value() const { return kind == kInt ? static_cast<double>(i) : kind == kUint ? static_cast<double>(u) : d; }
};

class EventList {
 public:
  Event& Add(Event::Kind k) {
    if (n_ == ev_.size()) ev_.emplace_back();
    Event& e = ev_[n_++];
    e.kind = k;
    return e;
  }
  void Clear() { n_ = 0; }
  size_t size() const { return n_; }
  const Event& operator[](size_t k) const { return ev_[k]; }
  void Replay(ValueBuilder* b) const {
    b->Reset();
    for (size_t k = 0; k < n_; ++k) {
      const Event& e = ev_[k];
      switch (e.kind) {
        case Event::kNull: b->Put(json(nullptr)); break;
        case Event::kBool: b->Put(json(e.b)); break;
        case Event::kInt: b->Put(json(e.i)); break;
        case Event::kUint: b->Put(json(e.u)); break;
        case Event::kFloat: b->Put(json(e.d)); break;
        case Event::kString: b->Put(json(e.s)); break;
        case Event::kKey: b->Key(e.s); break;
        case Event::kObject: b->Open(json::object()); break;
        case Event::kArray: b->Open(json::array()); break;
        case Event::kEndObject:
        case Event::kEndArray: b->Close(); break;
      }
    }
  }

 private:
  std::vector<Event> ev_;
  size_t n_ = 0;
};

// The observation the events describe, when it is of the common form every
// check of ParseObservation and Dataset::Validate accepts outright: one flat
// object of the known keys, each once, of its plain type (axes and direction
// objects of single machine axis letters, vectors of three numbers, sigma a
// number), within the bounds. The loader reads the common keys (type, axes,
// direction, sigma, id) and collects the others, which must be the kind's
// flat keys (ObservationKind::flat_keys), into a FlatObservation the kind
// reads (ObservationKind::ReadFlat). Anything else (an error, "C1", a sigma
// per row, a repeated key, a kind without ReadFlat) returns false and goes
// the reference way: only a speed-up for the kinds long traces come in
// (LoaderStreaming tests compare).
bool FastObservation(const EventList& ev, const Machine& m, const Artefact& artefact, Observation* ob) {
  // The common keys, then the kind's flat keys (slot + kNumCommon).
  enum Common { kType, kId, kAxes, kDirection, kSigma, kNumCommon };
  static const char* const kCommon[kNumCommon] = {"type", "id", "axes", "direction", "sigma"};
  const size_t n = ev.size();
  if (n < 2 || ev[0].kind != Event::kObject || ev[n - 1].kind != Event::kEndObject) return false;
  // The kind first (the writers put "type" first): its keys are the others'.
  const std::string* type = nullptr;
  if (ev[1].kind == Event::kKey && ev[1].s == "type") {
    if (ev[2].kind != Event::kString) return false;
    type = &ev[2].s;
  } else {
    int depth = 0;
    for (size_t k = 1; k + 1 < n && !type; ++k) {
      const Event::Kind e = ev[k].kind;
      if (e == Event::kObject || e == Event::kArray) ++depth;
      else if (e == Event::kEndObject || e == Event::kEndArray) --depth;
      else if (depth == 0 && e == Event::kKey && ev[k].s == "type") type = ev[k + 1].kind == Event::kString ? &ev[k + 1].s : nullptr;
    }
    if (!type) return false;
  }
  // The kind of the previous observation first: a trace is one kind.
  static thread_local const ObservationKind* last = nullptr;
  const ObservationKind* kind = last && *type == last->name() ? last : FindKind(*type);
  if (!kind) return false;
  const std::vector<FlatKey>& keys = kind->flat_keys();
  const int num_flat = static_cast<int>(keys.size());
  if (num_flat == 0 || num_flat > FlatObservation::kMaxKeys) return false;
  const int na = m.num_axes();
  unsigned seen = 0;
  const std::string* id = nullptr;
  double sigma = 0;
  FlatObservation flat;
  ob->axes = Eigen::VectorXd::Zero(na);
  ob->direction = Eigen::VectorXi::Zero(na);
  unsigned given = 0, dir_given = 0;
  size_t k = 1;
  while (k < n - 1) {
    if (ev[k].kind != Event::kKey) return false;
    const std::string& name = ev[k++].s;
    int key = 0;
    while (key < kNumCommon && name != kCommon[key]) ++key;
    if (key == kNumCommon)
      while (key < kNumCommon + num_flat && name != keys[key - kNumCommon].name) ++key;
    if (key == kNumCommon + num_flat || (seen & (1u << key))) return false;
    seen |= 1u << key;
    const Event& v = ev[k];
    switch (key) {
      case kType:
        ++k;  // read above
        break;
      case kId:
        if (v.kind != Event::kString) return false;
        id = &v.s;
        ++k;
        break;
      case kSigma:
        if (!v.number()) return false;
        sigma = v.value();
        ++k;
        break;
      case kAxes:
      case kDirection: {
        if (v.kind != Event::kObject) return false;
        unsigned& mask = key == kAxes ? given : dir_given;
        for (++k; ev[k].kind == Event::kKey; k += 2) {
          const std::string& a = ev[k].s;
          const int ax = a.size() == 1 ? m.AxisIndex(a[0]) : -1;
          if (ax < 0 || ax >= 32 || (mask & (1u << ax))) return false;
          mask |= 1u << ax;
          const Event& x = ev[k + 1];
          if (key == kAxes) {
            if (!x.number()) return false;
            const double q = x.value();
            if (!(std::abs(q) <= (m.axis(ax).rotary() ? kMaxRotaryDeg : kMaxLinear))) return false;
            ob->axes[ax] = q;
          } else {
            // -1, 0 or +1, integral floats too (IntegralValue)
            int dv;
            if (x.kind == Event::kInt && x.i >= -1 && x.i <= 1) dv = static_cast<int>(x.i);
            else if (x.kind == Event::kUint && x.u <= 1) dv = static_cast<int>(x.u);
            else if (x.kind == Event::kFloat && (x.d == -1.0 || x.d == 0.0 || x.d == 1.0)) dv = static_cast<int>(x.d);
            else return false;
            ob->direction[ax] = dv;
          }
        }
        if (ev[k].kind != Event::kEndObject) return false;
        ++k;
        break;
      }
      default: {  // one of the kind's flat keys
        const int slot = key - kNumCommon;
        switch (keys[slot].shape) {
          case FlatKey::kText:
            if (v.kind != Event::kString) return false;
            flat.set_text(slot, &v.s);
            ++k;
            break;
          case FlatKey::kNumber:
            if (!v.number()) return false;
            flat.set_number(slot, v.value());
            ++k;
            break;
          case FlatKey::kVector:
            if (v.kind != Event::kArray || k + 4 >= n || ev[k + 4].kind != Event::kEndArray) return false;
            for (int c = 0; c < 3; ++c) {
              const Event& e = ev[k + 1 + c];
              if (!e.number() || !(std::abs(e.value()) <= kMaxLinear)) return false;
              flat.values[slot][c] = e.value();
            }
            flat.seen |= 1u << slot;
            k += 5;
            break;
        }
        break;
      }
    }
  }
  if (k != n - 1 || !(seen & (1u << kAxes))) return false;
  for (int a = 0; a < na; ++a)
    if (!(given & (1u << a)) && m.axis(a).name != 'S') return false;
  ob->payload = kind->NewPayload();
  if (!kind->ReadFlat(flat, artefact, ob)) return false;
  last = kind;
  ob->type = kind->type();
  if (seen & (1u << kSigma)) {
    if (!(sigma >= kMinSigma && sigma <= kMaxSigma)) return false;
    ob->sigma = Eigen::VectorXd::Constant(kind->rows(), sigma);
  }
  if (id) ob->id = *id;
  return true;
}

// Reads a dataset text without building the JSON document of its
// observations: each one is recorded alone, converted and dropped. A document
// of 10^6 observations is ~10^7 heap nodes whose allocation and release cost
// more than the rest of the load; streaming keeps memory flat and the load
// linear. Only the common layout streams (machine, and artefact when probe
// touches need it, before the observations; no repeated top-level key; valid
// JSON); anything else returns with fallback set and the document parser
// decides, so every message is the one the document path gives.
class DatasetStream : public nlohmann::json_sax<json> {
 public:
  bool fallback = false;
  bool streamed = false;  // an observations array went through the stream
  json head = json::object();
  std::vector<Observation> observations;
  std::exception_ptr error;  // the first bad observation (reported after the head)

  bool null() override {
    if (InObservation()) return Scalar(ev_.Add(Event::kNull));
    return Value(json(nullptr));
  }
  bool boolean(bool v) override {
    if (InObservation()) return Scalar(ev_.Add(Event::kBool), [&](Event& e) { e.b = v; });
    return Value(json(v));
  }
  bool number_integer(number_integer_t v) override {
    if (InObservation()) return Scalar(ev_.Add(Event::kInt), [&](Event& e) { e.i = v; });
    return Value(json(v));
  }
  bool number_unsigned(number_unsigned_t v) override {
    if (InObservation()) return Scalar(ev_.Add(Event::kUint), [&](Event& e) { e.u = v; });
    return Value(json(v));
  }
  bool number_float(number_float_t v, const string_t&) override {
    if (InObservation()) return Scalar(ev_.Add(Event::kFloat), [&](Event& e) { e.d = v; });
    return Value(json(v));
  }
  bool string(string_t& v) override {
    if (InObservation()) return Scalar(ev_.Add(Event::kString), [&](Event& e) { e.s = v; });
    return Value(json(v));
  }
  bool binary(binary_t&) override { return Abort(); }
  bool start_object(std::size_t) override { return Open(true); }
  bool start_array(std::size_t) override {
    if (depth_ == 1 && key_ == "observations") return StartObservations();
    return Open(false);
  }
  bool end_object() override { return Close(true); }
  bool end_array() override {
    if (in_observations_ && depth_ == 2) {
      in_observations_ = false;
      depth_ = 1;
      return true;
    }
    return Close(false);
  }
  bool key(string_t& k) override {
    if (depth_ == 1) {
      if (head.contains(k) || (k == "observations" && streamed)) return Abort();  // repeated key
      key_ = k;
    } else if (InObservation()) {
      ev_.Add(Event::kKey).s = k;
    } else {
      b_.Key(k);
    }
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return Abort();
  }

 private:
  bool Abort() {
    fallback = true;
    return false;
  }
  // Inside the observations array: every event belongs to an observation.
  bool InObservation() const { return in_observations_ && depth_ >= 2; }
  template <typename F = void (*)(Event&)>
  bool Scalar(Event& e, F set = [](Event&) {}) {
    if (depth_ == 2) {  // a whole observation that is not an object
      Event copy = e;
      ev_.Clear();
      set(ev_.Add(copy.kind));
      Convert();
      return !fallback;
    }
    set(e);
    return true;
  }
  bool Open(bool object) {
    if (depth_ == 0) {
      if (!object) return Abort();
      depth_ = 1;
      return true;
    }
    if (InObservation()) {
      if (depth_ == 2) ev_.Clear();
      ev_.Add(object ? Event::kObject : Event::kArray);
      return ++depth_ <= kMaxDepth || Abort();
    }
    if (depth_ == 1) b_.Reset();
    if (++depth_ > kMaxDepth) return Abort();
    b_.Open(object ? json::object() : json::array());
    return true;
  }
  bool Close(bool object) {
    if (--depth_ == 0) return true;
    if (in_observations_ && depth_ >= 2) {
      ev_.Add(object ? Event::kEndObject : Event::kEndArray);
      if (depth_ == 2) Convert();
      return !fallback;
    }
    b_.Close();
    if (depth_ == 1) head[key_] = std::move(b_.root);
    return true;
  }
  bool Value(json v) {
    if (depth_ == 0) return Abort();
    if (depth_ == 1) {
      head[key_] = std::move(v);
      return true;
    }
    b_.Put(std::move(v));
    return true;
  }
  bool StartObservations() {
    if (!head.contains("machine")) return Abort();
    try {
      ds_ = std::make_unique<Dataset>(ParseHead(head));
    } catch (...) {
      return Abort();  // the document path names what is wrong, in order
    }
    artefact_known_ = head.contains("artefact");
    streamed = in_observations_ = true;
    depth_ = 2;
    return true;
  }
  void Convert() {
    const size_t i = index_++;
    if (error) return;
    if (!artefact_known_) {
      // A probe touch's target (a facet, sphere, cylinder: any probe-touch
      // kind) may be defined further on: the document decides.
      for (size_t k = 1; k + 1 < ev_.size(); ++k) {
        if (ev_[k].kind != Event::kKey || ev_[k].s != "type" || ev_[k + 1].kind != Event::kString) continue;
        const ObservationKind* kind = FindKind(ev_[k + 1].s);
        if (kind && kind->probe_touch()) {
          fallback = true;
          return;
        }
      }
    }
    Observation ob;
    if (FastObservation(ev_, ds_->machine(), ds_->artefact, &ob)) {
      observations.push_back(std::move(ob));
      return;
    }
    try {
      ev_.Replay(&b_);
      observations.push_back(ParseObservation(*ds_, b_.root, i, &given_));
    } catch (...) {
      error = std::current_exception();
    }
  }

  int depth_ = 0;  // open containers, the document's object included
  bool in_observations_ = false;
  bool artefact_known_ = false;
  std::string key_;
  ValueBuilder b_;
  EventList ev_;
  size_t index_ = 0;
  std::unique_ptr<Dataset> ds_;
  std::vector<bool> given_;
};

// About how many observations a text holds (every one has a "type"; the
// machine's axes add a few): reserving them spares the copies and page faults
// of a vector growing to 10^6 elements. No observation is shorter than 48
// bytes, which bounds what a text of repeated keys can make us reserve
// (untouched, the reserved pages cost address space only).
size_t CountTypeKeys(const std::string& text) {
  const size_t most = text.size() / 48;
  static const std::string needle = "\"type\"";
  const std::boyer_moore_horspool_searcher search(needle.begin(), needle.end());
  size_t n = 0;
  for (auto it = text.begin(); n < most; ++n) {
    it = std::search(it, text.end(), search);
    if (it == text.end()) return n;
    it += static_cast<std::ptrdiff_t>(needle.size());
  }
  return most;
}
// ---------------------------------------------------------------- fast text

// A JSON reader for the common layout of dataset files, faster than the
// SAX parser for long traces: numbers go through std::from_chars (no
// locale, no temporary string), keys and strings are copied into the event
// list's reused storage, and nothing is allocated per observation but the
// Observation itself. It reads the text as it is, or a file piece by piece
// (a buffer refilled as it goes, whatever the file's size). Anything it
// does not handle (a \u escape, a byte outside ASCII in a string, a number
// beyond 64 bits, invalid JSON, an uncommon layout) makes it give up
// (Status::kGiveUp) and the caller takes the reference path, so its result
// and messages are never its own.
class FastText {
 public:
  enum class Status { kOk, kMore, kGiveUp };

  // Over a whole text (no refill).
  FastText(const char* data, size_t size) : begin_(data), p_(data), end_(data + size), eof_(true) {}
  // Over a file, read in pieces of at least `chunk` bytes.
  FastText(std::FILE* f, size_t chunk) : file_(f), chunk_(chunk), eof_(false) {
    own_.resize(chunk_);
    begin_ = p_ = end_ = own_.data();
  }

  // The text from `keep` on stays in the buffer, followed by more of the
  // file (eof() once it is all read); `keep` and the cursor move with it.
  void Refill(const char** keep) {
    if (eof_) return;
    const size_t kept = static_cast<size_t>(end_ - *keep), at = static_cast<size_t>(p_ - *keep);
    if (kept + chunk_ > own_.size()) {
      std::vector<char> bigger(kept + chunk_);
      std::memcpy(bigger.data(), *keep, kept);
      own_.swap(bigger);
    } else {
      std::memmove(own_.data(), *keep, kept);
    }
    const size_t got = std::fread(own_.data() + kept, 1, own_.size() - kept, file_);
    if (got < own_.size() - kept) eof_ = true;
    begin_ = own_.data();
    *keep = begin_;
    p_ = begin_ + at;
    end_ = begin_ + kept + got;
  }

  const char*& cursor() { return p_; }
  const char* end() const { return end_; }
  bool eof() const { return eof_; }
  // Kept in the buffer across a refill by the caller.
  const char* begin() const { return begin_; }

  // Skips white space; kMore at the buffer's end (the caller refills).
  Status SkipSpace() {
    while (p_ < end_ && (*p_ == ' ' || *p_ == '\n' || *p_ == '\r' || *p_ == '\t')) ++p_;
    return p_ < end_ ? Status::kOk : More();
  }

  // One string (the cursor on its quote) into `out`.
  Status String(std::string* out) {
    const char* s = p_ + 1;
    const char* q = s;
    while (q < end_) {
      const auto c = static_cast<unsigned char>(*q);
      if (c == '"') {
        out->assign(s, q);
        p_ = q + 1;
        return Status::kOk;
      }
      if (c == '\\' || c < 0x20 || c >= 0x80) break;
      ++q;
    }
    if (q == end_) return More();
    // Escapes, spelled out (\u and bytes beyond ASCII: the reference path).
    out->assign(s, q);
    while (q < end_) {
      const auto c = static_cast<unsigned char>(*q);
      if (c == '"') {
        p_ = q + 1;
        return Status::kOk;
      }
      if (c < 0x20 || c >= 0x80) return Status::kGiveUp;
      if (c != '\\') {
        out->push_back(*q++);
        continue;
      }
      if (q + 1 >= end_) return More();
      switch (q[1]) {
        case '"': out->push_back('"'); break;
        case '\\': out->push_back('\\'); break;
        case '/': out->push_back('/'); break;
        case 'b': out->push_back('\b'); break;
        case 'f': out->push_back('\f'); break;
        case 'n': out->push_back('\n'); break;
        case 'r': out->push_back('\r'); break;
        case 't': out->push_back('\t'); break;
        default: return Status::kGiveUp;
      }
      q += 2;
    }
    return More();
  }

  // One number (the cursor on its first character) as an event: an integer
  // as kInt (negative) or kUint, as the SAX parser gives them, else kFloat.
  Status Number(Event* e) {
    const char* s = p_;
    const char* q = s;
    // The JSON grammar: -?(0|[1-9][0-9]*)(.[0-9]+)?([eE][+-]?[0-9]+)?
    auto digits = [&] {
      const char* d = q;
      while (q < end_ && *q >= '0' && *q <= '9') ++q;
      return q - d;
    };
    if (q < end_ && *q == '-') ++q;
    if (q < end_ && *q == '0') ++q;
    else if (digits() == 0) return q == end_ ? More() : Status::kGiveUp;
    bool integral = true;
    if (q < end_ && *q == '.') {
      ++q;
      integral = false;
      if (digits() == 0) return q == end_ ? More() : Status::kGiveUp;
    }
    if (q < end_ && (*q == 'e' || *q == 'E')) {
      ++q;
      integral = false;
      if (q < end_ && (*q == '+' || *q == '-')) ++q;
      if (digits() == 0) return q == end_ ? More() : Status::kGiveUp;
    }
    if (q == end_) return More();  // the number may go on
    if (integral) {
      if (*s == '-') {
        e->kind = Event::kInt;
        if (std::from_chars(s, q, e->i).ec != std::errc()) return Status::kGiveUp;
      } else {
        e->kind = Event::kUint;
        if (std::from_chars(s, q, e->u).ec != std::errc()) return Status::kGiveUp;
      }
    } else {
      e->kind = Event::kFloat;
      const auto r = std::from_chars(s, q, e->d);
      if (r.ec != std::errc() || r.ptr != q || !std::isfinite(e->d)) return Status::kGiveUp;
    }
    p_ = q;
    return Status::kOk;
  }

  // One value into `ev` (depth: containers open around it).
  Status Value(EventList* ev, int depth) {
    Status st = SkipSpace();
    if (st != Status::kOk) return st;
    const char c = *p_;
    if (c == '{' || c == '[') {
      if (depth + 1 > kMaxDepth) return Status::kGiveUp;
      const bool object = c == '{';
      ev->Add(object ? Event::kObject : Event::kArray);
      ++p_;
      if ((st = SkipSpace()) != Status::kOk) return st;
      if (*p_ == (object ? '}' : ']')) {
        ++p_;
        ev->Add(object ? Event::kEndObject : Event::kEndArray);
        return Status::kOk;
      }
      for (;;) {
        if (object) {
          if ((st = SkipSpace()) != Status::kOk) return st;
          if (*p_ != '"') return Status::kGiveUp;
          if ((st = String(&ev->Add(Event::kKey).s)) != Status::kOk) return st;
          if ((st = SkipSpace()) != Status::kOk) return st;
          if (*p_ != ':') return Status::kGiveUp;
          ++p_;
        }
        if ((st = Value(ev, depth + 1)) != Status::kOk) return st;
        if ((st = SkipSpace()) != Status::kOk) return st;
        if (*p_ == ',') {
          ++p_;
          continue;
        }
        if (*p_ != (object ? '}' : ']')) return Status::kGiveUp;
        ++p_;
        ev->Add(object ? Event::kEndObject : Event::kEndArray);
        return Status::kOk;
      }
    }
    if (c == '"') return String(&ev->Add(Event::kString).s);
    if (c == '-' || (c >= '0' && c <= '9')) return Number(&ev->Add(Event::kFloat));
    for (const auto& [word, kind, truth] : {std::make_tuple("true", Event::kBool, true),
                                            std::make_tuple("false", Event::kBool, false),
                                            std::make_tuple("null", Event::kNull, false)}) {
      const size_t len = std::strlen(word);
      if (c != word[0]) continue;
      if (static_cast<size_t>(end_ - p_) < len + 1) return More();
      if (std::memcmp(p_, word, len) != 0) return Status::kGiveUp;
      p_ += len;
      ev->Add(kind).b = truth;
      return Status::kOk;
    }
    return Status::kGiveUp;
  }

  // Skips one value (the head's members: parsed by the reference parser
  // from the span), without checking it beyond its nesting and strings.
  Status Skip() {
    Status st = SkipSpace();
    if (st != Status::kOk) return st;
    int depth = 0;
    const char* q = p_;
    while (q < end_) {
      const char c = *q;
      if (c == '"') {
        for (++q; q < end_ && *q != '"'; ++q)
          if (*q == '\\' && ++q == end_) break;
        if (q >= end_) return More();
        ++q;
        if (depth == 0) break;
        continue;
      }
      if (c == '{' || c == '[') {
        if (++depth > kMaxDepth) return Status::kGiveUp;
      } else if (c == '}' || c == ']') {
        if (depth == 0) break;  // the end of the object that holds the value
        if (--depth == 0) {
          ++q;
          break;
        }
      } else if (depth == 0 && (c == ',' || c == ' ' || c == '\n' || c == '\r' || c == '\t')) {
        break;
      }
      ++q;
    }
    if (q >= end_) return More();
    p_ = q;
    return Status::kOk;
  }

 private:
  Status More() const { return eof_ ? Status::kGiveUp : Status::kMore; }

  const char* begin_ = nullptr;
  const char* p_ = nullptr;
  const char* end_ = nullptr;
  std::FILE* file_ = nullptr;
  size_t chunk_ = 0;
  bool eof_ = true;
  std::vector<char> own_;
};

// A dataset text of the common layout through FastText: the head's members
// (each parsed by the reference parser from its span), then the
// observations one by one, then what follows them. Messages and results are
// those of the SAX stream (DatasetStream), which it mirrors; anything it
// does not handle gives up and the caller takes that path.
class FastDataset {
 public:
  enum class Step { kObservation, kEnd, kGiveUp };
  using Status = FastText::Status;

  FastDataset(FastText* t, bool whole) : t_(t), whole_(whole) {}

  json head = json::object();
  std::exception_ptr error;  // the first bad observation (whole text: reported after the head)

  // Everything up to the observations' '['; false: give up.
  bool Start() {
    for (;;) {
      const char* keep = t_->begin();
      t_->cursor() = keep;
      head = json::object();
      const Status st = Head();
      if (st == Status::kOk) break;
      if (st == Status::kGiveUp) return false;
      t_->Refill(&keep);  // kMore comes only before the file's end: a retry sees more, or its end
    }
    if (!head.contains("machine")) return false;
    try {
      ds_ = std::make_unique<Dataset>(ParseHead(head));
    } catch (...) {
      return false;  // the document path names what is wrong, in order
    }
    artefact_known_ = head.contains("artefact");
    return true;
  }
  const Dataset& dataset() const { return *ds_; }
  size_t index() const { return index_; }

  // The next observation into `ob`.
  Step Next(Observation* ob) {
    for (;;) {
      const char* keep = t_->cursor();
      bool end = false;
      const Status st = Lex(&end);
      if (st == Status::kMore) {
        t_->Refill(&keep);
        t_->cursor() = keep;
        continue;
      }
      if (st == Status::kGiveUp) return Step::kGiveUp;
      if (end) return Step::kEnd;
      if (!Convert(ob)) return Step::kGiveUp;
      return Step::kObservation;
    }
  }

  // After the observations: the members that follow (whole text only: a
  // piece reader has handed out the head already) and the end of the text.
  bool Finish() {
    for (;;) {
      const char* keep = t_->cursor();
      const Status st = Tail();
      if (st == Status::kOk) return true;
      if (st == Status::kGiveUp) return false;
      t_->Refill(&keep);  // the cursor stays where Tail left it
    }
  }

 private:
  Status Head() {
    const char*& p = t_->cursor();
    if (t_->end() - p < 3) return t_->eof() ? Status::kGiveUp : Status::kMore;
    if (std::memcmp(p, "\xEF\xBB\xBF", 3) == 0) p += 3;  // a byte order mark, as the SAX parser skips it
    Status st = t_->SkipSpace();
    if (st != Status::kOk) return st;
    if (*p++ != '{') return Status::kGiveUp;
    for (;;) {
      if ((st = Member(true)) != Status::kOk) return st;
      if (in_observations_) return Status::kOk;
      if ((st = t_->SkipSpace()) != Status::kOk) return st;
      if (*p != ',') return Status::kGiveUp;  // no observations: the document decides
      ++p;
    }
  }
  // One member of the dataset object; the observations' '[' opens them.
  Status Member(bool before) {
    const char*& p = t_->cursor();
    Status st = t_->SkipSpace();
    if (st != Status::kOk) return st;
    if (*p != '"') return Status::kGiveUp;
    if ((st = t_->String(&key_)) != Status::kOk) return st;
    if ((st = t_->SkipSpace()) != Status::kOk) return st;
    if (*p++ != ':') return Status::kGiveUp;
    if ((st = t_->SkipSpace()) != Status::kOk) return st;
    if (key_ == "observations") {
      if (!before || *p != '[') return Status::kGiveUp;
      ++p;
      in_observations_ = true;
      return Status::kOk;
    }
    if (head.contains(key_)) return Status::kGiveUp;  // repeated key
    const char* v = p;
    if ((st = t_->Skip()) != Status::kOk) return st;
    try {
      head[key_] = json::parse(v, p);
    } catch (...) {
      return Status::kGiveUp;
    }
    return Status::kOk;
  }
  // Up to the next observation (recorded in ev_) or the array's end.
  Status Lex(bool* end) {
    const char*& p = t_->cursor();
    Status st = t_->SkipSpace();
    if (st != Status::kOk) return st;
    if (!first_) {
      if (*p == ']') {
        ++p;
        *end = true;
        return Status::kOk;
      }
      if (*p != ',') return Status::kGiveUp;
      ++p;
    } else if (*p == ']') {
      ++p;
      *end = true;
      return Status::kOk;
    }
    ev_.Clear();
    if ((st = t_->Value(&ev_, 2)) != Status::kOk) return st;
    first_ = false;
    return Status::kOk;
  }
  Status Tail() {
    const char*& p = t_->cursor();
    while (!closed_) {
      Status st = t_->SkipSpace();
      if (st != Status::kOk) return st;
      if (*p == '}') {
        ++p;
        closed_ = true;
        break;
      }
      if (*p != ',' || !whole_) return Status::kGiveUp;
      const char* keep = p++;
      if ((st = Member(false)) != Status::kOk) {
        p = keep;
        return st;
      }
    }
    for (;;) {
      while (p < t_->end() && (*p == ' ' || *p == '\n' || *p == '\r' || *p == '\t')) ++p;
      if (p < t_->end()) return Status::kGiveUp;  // more than white space after the document
      if (t_->eof()) return Status::kOk;
      return Status::kMore;
    }
  }
  bool Convert(Observation* ob) {
    const size_t i = index_++;
    if (error) return true;  // the rest is only parsed (a syntax error further on wins)
    if (!artefact_known_) {
      // A probe touch's target may be defined further on: the document decides.
      for (size_t k = 1; k + 1 < ev_.size(); ++k) {
        if (ev_[k].kind != Event::kKey || ev_[k].s != "type" || ev_[k + 1].kind != Event::kString) continue;
        const ObservationKind* kind = FindKind(ev_[k + 1].s);
        if (kind && kind->probe_touch()) return false;
      }
    }
    *ob = Observation();
    if (FastObservation(ev_, ds_->machine(), ds_->artefact, ob)) return true;
    try {
      ev_.Replay(&b_);
      *ob = ParseObservation(*ds_, b_.root, i, &given_);
    } catch (...) {
      error = std::current_exception();
    }
    return true;
  }

  FastText* t_;
  bool whole_;
  bool in_observations_ = false, first_ = true, closed_ = false;
  bool artefact_known_ = false;
  std::string key_;
  EventList ev_;
  ValueBuilder b_;
  size_t index_ = 0;
  std::unique_ptr<Dataset> ds_;
  std::vector<bool> given_;
};

// "observations[k]" of a piece's message as the file's index k + offset.
std::string ShiftRows(const std::string& msg, size_t offset) {
  static const std::string needle = "observations[";
  std::string out;
  size_t at = 0;
  for (size_t hit; (hit = msg.find(needle, at)) != std::string::npos;) {
    const size_t digits = hit + needle.size();
    size_t stop = digits;
    while (stop < msg.size() && std::isdigit(static_cast<unsigned char>(msg[stop]))) ++stop;
    out.append(msg, at, digits - at);
    if (stop > digits && stop < msg.size() && msg[stop] == ']') {
      out += std::to_string(std::stoull(msg.substr(digits, stop - digits)) + offset);
      at = stop;
    } else {
      at = digits;
    }
  }
  out.append(msg, at, std::string::npos);
  return out;
}

}  // namespace

Dataset Dataset::FromJson(const std::string& text, bool require_observations) {
  return Guard("dataset", [&] {
    {
      FastText t(text.data(), text.size());
      FastDataset f(&t, true);
      if (f.Start()) {
        std::vector<Observation> observations;
        observations.reserve(CountTypeKeys(text));
        FastDataset::Step step;
        for (Observation ob; (step = f.Next(&ob)) == FastDataset::Step::kObservation;)
          if (!f.error) observations.push_back(std::move(ob));
        if (step == FastDataset::Step::kEnd && f.Finish()) {
          Dataset ds = ParseHead(f.head);
          if (f.error) std::rethrow_exception(f.error);
          ds.observations = std::move(observations);
          Finish(&ds, require_observations);
          return ds;
        }
      }
    }
    // Not the fast reader's: the SAX stream, which gives up to the document.
    DatasetStream s;
    s.observations.reserve(CountTypeKeys(text));
    const bool parsed = json::sax_parse(text, &s);
    if (!parsed || s.fallback || !s.streamed)
      return ParseDataset(Parse(text, "dataset"), require_observations);
    Dataset ds = ParseHead(s.head);
    if (s.error) std::rethrow_exception(s.error);
    ds.observations = std::move(s.observations);
    Finish(&ds, require_observations);
    return ds;
  });
}

struct DatasetFileReader::Impl {
  std::FILE* file = nullptr;
  std::unique_ptr<FastText> text;
  std::unique_ptr<FastDataset> reader;
  // Per instrument id: the file key that named it first, and where (the
  // check Dataset::Validate makes within a piece, across pieces).
  std::map<std::string, const char*> instrument_ids;
  ~Impl() {
    if (file) std::fclose(file);
  }
};

DatasetFileReader::DatasetFileReader(const std::string& path, size_t buffer_bytes) : impl_(new Impl) {
  impl_->file = std::fopen(path.c_str(), "rb");
  if (!impl_->file)
    throw std::invalid_argument(path + ": cannot read dataset (" + std::strerror(errno) + ")");
  impl_->text = std::make_unique<FastText>(impl_->file, std::max<size_t>(buffer_bytes, 4096));
  impl_->reader = std::make_unique<FastDataset>(impl_->text.get(), false);
  streamable_ = impl_->reader->Start();
}

DatasetFileReader::~DatasetFileReader() = default;

std::string DatasetFileReader::head_json() const { return impl_->reader->head.dump(); }

std::optional<Dataset> DatasetFileReader::Next(size_t rows) {
  if (!streamable_ || done_) return std::nullopt;
  const bool got = Guard("dataset", [&] {
    FastDataset& f = *impl_->reader;
    Dataset d = f.dataset();
    d.observations.reserve(std::min<size_t>(rows, size_t{1} << 20));
    while (d.observations.size() < rows) {
      Observation ob;
      const FastDataset::Step step = f.Next(&ob);
      if (step == FastDataset::Step::kGiveUp) return streamable_ = false;
      if (f.error) std::rethrow_exception(f.error);
      if (step == FastDataset::Step::kEnd) {
        if (!f.Finish()) return streamable_ = false;
        done_ = true;
        break;
      }
      d.observations.push_back(std::move(ob));
    }
    if (!d.observations.empty()) {
      try {
        d.Validate();
        CheckInstruments(d, false);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(ShiftRows(e.what(), read_));
      }
      for (const Observation& o : d.observations)
        if (const char* key = KindOf(o).instrument_key())
          if (std::strcmp(impl_->instrument_ids.emplace(o.setup, key).first->second, key) != 0)
            return streamable_ = false;  // the whole file's check names both
    }
    read_ += d.observations.size();
    if (done_) {
      // No observation, or an instrument declared and never used: the whole
      // file's messages.
      if (read_ == 0) return streamable_ = false;
      for (const auto& kv : d.instrument_sigma)
        if (!impl_->instrument_ids.count(kv.first)) return streamable_ = false;
    }
    if (d.observations.empty()) return false;
    piece_.emplace(std::move(d));
    return true;
  });
  if (!got) return std::nullopt;
  std::optional<Dataset> out = std::move(piece_);
  piece_.reset();
  return out;
}

void Dataset::Validate() const {
  if (observations.empty() && block_rows() == 0)
    throw std::invalid_argument("dataset.observations: empty; nothing to fit");
  ValidateScaleBars(artefact);
  if (!(std::isfinite(tip_radius) && tip_radius >= 0 && tip_radius <= kMaxLinear))
    throw std::invalid_argument("dataset.probe.tip_radius: must be >= 0 and <= 1e5 mm");
  const int na = machine_.num_axes();
  // Per instrument id: the file key that named it first, and where.
  std::map<std::string, std::pair<const char*, size_t>> instrument_ids;
  auto check = [&](size_t i, const Observation& o) {
    // Built only for a message: this runs over every sample of a trace.
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
    if (o.sigma.size() > 0) CheckSigmaOf(o.sigma, o.type, [&] { return w() + ".sigma"; });
    if (const char* key = KindOf(o).instrument_key()) {
      const auto first = instrument_ids.emplace(o.setup, std::make_pair(key, i)).first->second;
      if (std::strcmp(first.first, key) != 0)
        throw std::invalid_argument(w() + "." + key + ": " + Quote(o.setup) + " is also the " + first.first +
                                    " of observations[" + std::to_string(first.second) +
                                    "]; its parameters instrument." + o.setup +
                                    ".* would mean two things: give them different names");
    }
  };
  for (size_t i = 0; i < observations.size(); ++i) check(i, observations[i]);
  // Blocks: the first row through the kind (set-up and shared payload,
  // which every row has), then column by column; a row a column check
  // refuses goes through the per-row check for the same message a
  // per-object observation would give.
  size_t base = observations.size();
  Observation scratch;
  for (size_t bi = 0; bi < blocks.size(); ++bi) {
    const TraceBlock& b = blocks[bi];
    const size_t n = b.size();
    const ObservationKind& kind = KindOf(b.type);
    const int nv = kind.block_values(), rows = kind.rows();
    const std::string wb = "dataset block " + std::to_string(bi) + " (" + kind.name() + ")";
    if (nv <= 0) throw std::invalid_argument(wb + ": a " + kind.name() + " observation is not kept in columns");
    if (static_cast<int>(b.axes.size()) != na || static_cast<int>(b.values.size()) != nv ||
        !(b.direction.empty() || static_cast<int>(b.direction.size()) == na) ||
        !(b.sigma.empty() || static_cast<int>(b.sigma.size()) == rows) || !(b.ids.empty() || b.ids.size() == n))
      throw std::invalid_argument(wb + ": columns do not match the machine's axes and the kind's values");
    for (const auto& c : b.axes)
      if (c.size() != n) throw std::invalid_argument(wb + ": axis columns of different lengths");
    for (const auto& c : b.values)
      if (c.size() != n) throw std::invalid_argument(wb + ": value columns of different lengths");
    for (const auto& c : b.direction)
      if (c.size() != n) throw std::invalid_argument(wb + ": direction columns of different lengths");
    for (const auto& c : b.sigma)
      if (c.size() != n && c.size() != 1) throw std::invalid_argument(wb + ": sigma columns of different lengths");
    if (n == 0) continue;
    FillRow(b, 0, &scratch);
    check(base, scratch);
    auto row_check = [&](size_t r) {
      FillRow(b, r, &scratch);
      check(base + r, scratch);
      throw std::logic_error(wb + ": row " + std::to_string(r) + " refused by a column check only");
    };
    for (int k = 0; k < na; ++k) {
      const double bound = machine_.axis(k).rotary() ? kMaxRotaryDeg : kMaxLinear;
      const double* x = b.axes[k].data();
      for (size_t r = 0; r < n; ++r)
        if (!(std::abs(x[r]) <= bound)) row_check(r);
    }
    for (const auto& c : b.direction)
      for (size_t r = 0; r < n; ++r)
        if (c[r] < -1 || c[r] > 1) row_check(r);
    for (int v = 0; v < nv; ++v) {
      const double bound = kind.block_value_bound(v);
      const double* x = b.values[v].data();
      for (size_t r = 0; r < n; ++r)
        if (!(std::abs(x[r]) <= bound)) row_check(r);
    }
    for (const auto& c : b.sigma)
      for (size_t r = 0; r < c.size(); ++r)
        if (!(std::isnan(c[r]) || (c[r] >= kMinSigma && c[r] <= kMaxSigma))) row_check(r);
    if (!b.sigma.empty())
      // A row declares all its rows' noise or none.
      for (size_t r = 0; r < n; ++r) {
        const bool none = std::isnan(b.sigma_at(0, r));
        for (int k = 1; k < rows; ++k)
          if (std::isnan(b.sigma_at(k, r)) != none)
            throw std::invalid_argument("observations[" + std::to_string(base + r) +
                                        "].sigma: give every residual row's noise or none");
      }
    base += n;
  }
  CheckInstruments(*this, false);
  if (!setup_uncertainty.empty())
    ValidateSetupUncertainty(machine_, setup_uncertainty, "dataset.setup_uncertainty", ParameterTable(*this).names());
}

const Observation& Dataset::Row(size_t i, Observation* scratch) const {
  if (i < observations.size()) return observations[i];
  size_t r = i - observations.size();
  // Rows are mostly asked in order (a writer, a walk): the block of the
  // previous call on this dataset is tried first, so that a dataset of
  // many blocks is not searched from the start for every row.
  thread_local const Dataset* hint_ds = nullptr;
  thread_local const TraceBlock* hint_data = nullptr;
  thread_local size_t hint_block = 0, hint_start = 0;
  size_t k = 0, start = 0;
  if (hint_ds == this && hint_data == blocks.data() && hint_block < blocks.size() && hint_start <= r) {
    k = hint_block;
    start = hint_start;
  }
  for (; k < blocks.size(); ++k) {
    const TraceBlock& b = blocks[k];
    if (r - start < b.size()) {
      hint_ds = this;
      hint_data = blocks.data();
      hint_block = k;
      hint_start = start;
      FillRow(b, r - start, scratch);
      return *scratch;
    }
    start += b.size();
  }
  throw std::out_of_range("dataset: observation " + std::to_string(i) + " of " + std::to_string(size()));
}

void Dataset::FillRowSigma(const TraceBlock& b, size_t r, Observation* o) {
  if (b.sigma.empty() || std::isnan(b.sigma_at(0, r))) {
    o->sigma.resize(0);
  } else {
    o->sigma.resize(static_cast<Eigen::Index>(b.sigma.size()));
    for (size_t k = 0; k < b.sigma.size(); ++k) o->sigma[static_cast<Eigen::Index>(k)] = b.sigma_at(static_cast<int>(k), r);
  }
}

void Dataset::FillRow(const TraceBlock& b, size_t r, Observation* o) const {
  const int na = static_cast<int>(b.axes.size());
  const ObservationKind& kind = KindOf(b.type);
  o->type = b.type;
  if (b.ids.empty()) o->id.clear();
  else o->id = b.ids[r];
  o->setup = b.setup;
  o->axes.resize(na);
  o->direction.resize(na);
  for (int k = 0; k < na; ++k) {
    o->axes[k] = b.axes[k][r];
    o->direction[k] = b.direction.empty() ? 0 : b.direction[k][r];
  }
  FillRowSigma(b, r, o);
  o->payload = b.common;
  double v[16];
  const int nv = static_cast<int>(b.values.size());
  for (int c = 0; c < nv && c < 16; ++c) v[c] = b.values[c][r];
  kind.SetBlockValues(v, o);
}

void Dataset::ExpandBlocks() {
  if (blocks.empty()) return;
  observations.reserve(size());
  for (const TraceBlock& b : blocks)
    for (size_t r = 0, n = b.size(); r < n; ++r) {
      Observation o;
      FillRow(b, r, &o);
      observations.push_back(std::move(o));
    }
  blocks.clear();
  blocks.shrink_to_fit();
}

Dataset Dataset::Expanded() const {
  Dataset d = *this;
  d.ExpandBlocks();
  return d;
}

void Dataset::AppendBlockRow(const Observation& o) {
  const ObservationKind& kind = KindOf(o);
  const int nv = kind.block_values(), na = machine_.num_axes(), rows = kind.rows();
  if (nv <= 0) throw std::invalid_argument(std::string("dataset: a ") + kind.name() + " observation is not kept in columns");
  if (o.axes.size() != na || o.direction.size() != na)
    throw std::invalid_argument("dataset: a block row needs " + std::to_string(na) + " axes and directions");
  if (blocks.empty() || blocks.back().type != o.type || blocks.back().setup != o.setup ||
      !kind.BlockShares(blocks.back().common, o)) {
    TraceBlock b;
    b.type = o.type;
    b.setup = o.setup;
    b.common = kind.BlockCommon(o);
    b.axes.resize(na);
    b.values.resize(nv);
    blocks.push_back(std::move(b));
  }
  double v[16];
  kind.BlockValues(o, v);
  PushBlockRow(&blocks.back(), na, o.axes.data(), o.direction.data(), v, rows, o.sigma.size() ? o.sigma.data() : nullptr,
               &o.id);
}

size_t Dataset::PackTraces(size_t min_rows) {
  size_t j = observations.size();
  while (j > 0 && KindOf(observations[j - 1]).block_values() > 0) --j;
  const size_t moved = observations.size() - j;
  if (moved == 0 || moved < min_rows) return 0;
  std::vector<TraceBlock> later;
  later.swap(blocks);
  for (size_t i = j; i < observations.size(); ++i) AppendBlockRow(observations[i]);
  observations.resize(j);
  observations.shrink_to_fit();
  for (TraceBlock& b : later) blocks.push_back(std::move(b));
  return moved;
}

Dataset Dataset::Subset(const std::vector<int>& indices) const {
  Dataset d(machine_);
  d.tip_radius = tip_radius;
  d.artefact = artefact;
  d.instrument_sigma = instrument_sigma;
  d.setup_uncertainty = setup_uncertainty;
  // Block rows stay in blocks unless a per-object row follows one (the
  // order of `indices` is the subset's, and block rows follow the others).
  const size_t n = size(), n_obj = observations.size();
  bool object_after_block = false, seen_block = false;
  for (int i : indices) {
    if (i < 0 || static_cast<size_t>(i) >= n)
      throw std::invalid_argument("subset: observation index " + std::to_string(i) + " out of range");
    if (static_cast<size_t>(i) >= n_obj) seen_block = true;
    else if (seen_block) object_after_block = true;
  }
  Observation scratch;
  for (int i : indices) {
    const Observation& o = Row(static_cast<size_t>(i), &scratch);
    if (static_cast<size_t>(i) < n_obj || object_after_block) d.observations.push_back(o);
    else d.AppendBlockRow(o);
  }
  if (!d.setup_uncertainty.empty() && d.size() > 0) {
    // A subset keeps the declared placements of the set-ups it still has.
    const ParameterTable t(d);
    for (auto it = d.setup_uncertainty.begin(); it != d.setup_uncertainty.end();)
      it = it->first.rfind("class:", 0) != 0 && t.Index(it->first) < 0 ? d.setup_uncertainty.erase(it) : std::next(it);
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
  if (!instrument_sigma.empty()) {
    json ins = json::object();
    for (const auto& [id, s] : instrument_sigma) {
      if (s.size() == 1) {
        ins[id] = {{"sigma", s[0]}};
      } else {
        json a = json::array();
        for (int r = 0; r < s.size(); ++r) a.push_back(s[r]);
        ins[id] = {{"sigma", a}};
      }
    }
    j["instruments"] = ins;
  }
  if (!setup_uncertainty.empty()) {
    json u = json::object();
    for (const auto& [name, s] : setup_uncertainty) u[name] = s;
    j["setup_uncertainty"] = u;
  }
  if (!artefact.cylinders.empty()) {
    json cyls = json::array();
    for (const Cylinder& c : artefact.cylinders) {
      json jc = {{"id", c.id}, {"point", Array3(c.point)}, {"axis", Array3(c.axis)}, {"radius", c.radius}};
      if (c.inside) jc["inside"] = true;
      cyls.push_back(jc);
    }
    j["artefact"]["cylinders"] = cyls;
  }
  json obs = json::array();
  ForEachRow([&](size_t, const Observation& o) {
    json jo;
    jo["type"] = ObservationTypeName(o.type);
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
    KindOf(o).WriteOnMachine(machine_, o, &jo);
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
  });
  j["observations"] = obs;
  return j.dump();
}

}  // namespace fivecal
