#include "fivecal/observations/registry.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/ball3d.h"
#include "fivecal/observations/cylinder.h"
#include "fivecal/observations/dbb.h"
#include "fivecal/observations/distance.h"
#include "fivecal/observations/facet.h"
#include "fivecal/observations/machined.h"
#include "fivecal/observations/point.h"
#include "fivecal/observations/probe_trigger.h"
#include "fivecal/observations/pose.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/observations/sphere.h"

namespace fivecal {

namespace {

// The built-in kinds, then those registered by RegisterObservationKind.
std::vector<const ObservationKind*>& Kinds() {
  // THE list of built-in observation kinds. A new kind: its file pair, one
  // line here, one ObservationType value (docs/adding_an_observation_kind.md);
  // or, outside the core (a test's kind), RegisterObservationKind.
  static std::vector<const ObservationKind*> kinds = {
      &FacetKind(),
      &SphereKind(),
      &DbbKind(),
      &Ball3dKind(),
      &PointKind(),
      &PoseKind(), &DistanceKind(),
      &CylinderKind(),
      &MachinedKind(),
  };
  return kinds;
}

// KindOf's table, indexed by type code; rebuilt when a kind registers.
std::vector<const ObservationKind*> ByType() {
  std::vector<const ObservationKind*> v;
  for (const ObservationKind* k : Kinds()) {
    const size_t i = static_cast<size_t>(k->type());
    if (v.size() <= i) v.resize(i + 1, nullptr);
    v[i] = k;
  }
  return v;
}

std::vector<const ObservationKind*>& ByTypeTable() {
  static std::vector<const ObservationKind*> v = ByType();
  return v;
}

}  // namespace

const std::vector<const ObservationKind*>& ObservationKinds() { return Kinds(); }

ObservationType UnusedObservationType() {
  int next = 0;
  for (const ObservationKind* k : Kinds()) next = std::max(next, static_cast<int>(k->type()) + 1);
  return static_cast<ObservationType>(next);
}

bool RegisterObservationKind(const ObservationKind& kind) {
  const std::string name = kind.name();
  if (name.empty() || name.find('.') != std::string::npos)
    throw std::invalid_argument("observation kind '" + name + "': a name must be non-empty and have no '.'");
  for (const ObservationKind* k : Kinds()) {
    if (k == &kind) return false;
    if (name == k->name())
      throw std::invalid_argument("observation kind '" + name + "' is registered already");
    if (k->type() == kind.type())
      throw std::invalid_argument("observation kind '" + name + "': its type code " +
                                  std::to_string(static_cast<int>(kind.type())) + " is " + k->name() + "'s");
  }
  if (name == "probe" || name == "instrument")
    throw std::invalid_argument("observation kind '" + name + "': the name prefixes other set-up parameters");
  Kinds().push_back(&kind);
  ByTypeTable() = ByType();
  return true;
}

const ObservationKind& KindOf(ObservationType t) {
  const std::vector<const ObservationKind*>& by_type = ByTypeTable();
  const size_t i = static_cast<size_t>(t);
  if (i >= by_type.size() || !by_type[i])
    throw std::logic_error("observation type " + std::to_string(i) + " is not registered");
  return *by_type[i];
}

const ObservationKind* FindKind(const std::string& name) {
  for (const ObservationKind* k : ObservationKinds())
    if (name == k->name()) return k;
  return nullptr;
}

std::vector<std::string> KindNames() {
  std::vector<std::string> out;
  for (const ObservationKind* k : ObservationKinds()) out.push_back(k->name());
  return out;
}

std::string KindList() {
  std::string out;
  for (const ObservationKind* k : ObservationKinds()) out += (out.empty() ? "" : ", ") + std::string(k->name());
  return out;
}

std::vector<std::string> NoiseClasses() {
  std::vector<std::string> out;
  for (const ObservationKind* k : ObservationKinds())
    for (const std::string& c : k->noise_classes())
      if (std::find(out.begin(), out.end(), c) == out.end()) out.push_back(c);
  return out;
}

std::string NoiseClassUnit(const std::string& c) {
  for (const ObservationKind* k : ObservationKinds())
    for (int r = 0; r < k->rows(); ++r)
      if (c == k->noise_class_row(r)) return k->unit_row(r);
  throw std::invalid_argument("noise class '" + c + "': no observation kind draws on it");
}

double ObservationKind::NoiseLevel(const NoiseLevels& n) const { return n.Of(noise_class()); }

double ObservationKind::NoiseLevelRow(const NoiseLevels& n, int k) const { return n.Of(noise_class_row(k)); }

std::vector<std::string> ObservationKind::noise_classes() const {
  std::vector<std::string> out;
  for (int r = 0; r < rows(); ++r)
    if (std::find(out.begin(), out.end(), noise_class_row(r)) == out.end()) out.push_back(noise_class_row(r));
  return out;
}

void ObservationKind::PrepareAnalytic(const Dataset&, const ParameterTable&, const Observation&,
                                      AnalyticRow*) const {
  throw std::logic_error(std::string(name()) + ": no analytic batch (analytic() is false)");
}

void ObservationKind::EvaluateAnalytic(AnalyticEval&, const AnalyticRow*, int) const {
  throw std::logic_error(std::string(name()) + ": no analytic batch (analytic() is false)");
}

bool HasLengthReference(const Dataset& ds) {
  for (const Observation& o : ds.observations)
    if (KindOf(o).LengthReference()) return true;
  for (const TraceBlock& b : ds.blocks)
    if (KindOf(b.type).LengthReference()) return true;
  for (const ObservationKind* k : ObservationKinds())
    if (k->ArtefactLengthReference(ds)) return true;
  return false;
}

bool PlannedContact(const Dataset& ds, const std::string& entry_json, Eigen::Vector3d* point,
                    Eigen::Vector3d* normal) {
  const nlohmann::json e = nlohmann::json::parse(entry_json);
  const ObservationKind* k = e.is_object() && e.contains("type") && e["type"].is_string()
                                 ? FindKind(e["type"].get<std::string>())
                                 : nullptr;
  return k && k->PlannedContact(ds, e, "plan entry", point, normal);
}

bool IsSetupParameterName(const std::string& name) {
  const size_t dot = name.find('.');
  if (dot == std::string::npos || dot + 1 >= name.size()) return false;
  const std::string kind = name.substr(0, dot), rest = name.substr(dot + 1);
  if (const ObservationKind* k = FindKind(kind)) return k->IsParameterName(rest);
  if (kind == "probe") return IsProbeParameterName(name);
  if (kind == "instrument") {
    const size_t d = rest.find('.');
    return d != std::string::npos && d > 0 && rest.find('.', d + 1) == std::string::npos;
  }
  return false;
}

}  // namespace fivecal
