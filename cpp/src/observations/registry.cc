#include "fivecal/observations/registry.h"

#include <algorithm>
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

const std::vector<const ObservationKind*>& ObservationKinds() {
  // THE list of observation kinds. A new kind: its file pair, one line here,
  // one ObservationType value (docs/adding_an_observation_kind.md).
  static const std::vector<const ObservationKind*> kinds = {
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

const ObservationKind& KindOf(ObservationType t) {
  static const std::vector<const ObservationKind*> by_type = [] {
    std::vector<const ObservationKind*> v;
    for (const ObservationKind* k : ObservationKinds()) {
      const size_t i = static_cast<size_t>(k->type());
      if (v.size() <= i) v.resize(i + 1, nullptr);
      v[i] = k;
    }
    return v;
  }();
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
  for (const ObservationKind* k : ObservationKinds())
    if (k->ArtefactLengthReference(ds)) return true;
  return false;
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
