#include "fivecal/observations/nc_geometry.h"

#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/ball_mount.h"
#include "fivecal/observations/registry.h"

namespace fivecal {

namespace {

const ProbeTouchKind* AsTouch(const ObservationKind* k) { return dynamic_cast<const ProbeTouchKind*>(k); }

}  // namespace

const char* NcProgram(const ObservationKind& k) {
  if (const ProbeTouchKind* t = AsTouch(&k)) return t->nc_program();
  if (const auto* b = dynamic_cast<const BallMountKind*>(&k)) return b->nc_program();
  return nullptr;
}

std::vector<std::optional<TouchContact>> PlannedTouchContacts(const Dataset& ds, const std::string& plan_json) {
  nlohmann::json plan;
  try {
    plan = nlohmann::json::parse(plan_json);
  } catch (const nlohmann::json::exception&) {
    throw std::invalid_argument("plan: not JSON");
  }
  if (!plan.is_array()) throw std::invalid_argument("plan: expected a list of plan entries");
  std::vector<std::optional<TouchContact>> out;
  out.reserve(plan.size());
  for (size_t i = 0; i < plan.size(); ++i) {
    const nlohmann::json& e = plan[i];
    const ObservationKind* k = e.is_object() && e.contains("type") && e["type"].is_string()
                                   ? FindKind(e["type"].get<std::string>())
                                   : nullptr;
    const ProbeTouchKind* t = AsTouch(k);
    if (t)
      out.emplace_back(t->PlannedTouchContact(ds, e, "plan[" + std::to_string(i) + "]"));
    else
      out.emplace_back(std::nullopt);
  }
  return out;
}

std::vector<ClearanceBall> ArtefactClearanceBalls(const Dataset& ds) {
  std::vector<ClearanceBall> out;
  for (const ObservationKind* k : ObservationKinds())
    if (const ProbeTouchKind* t = AsTouch(k))
      for (ClearanceBall& b : t->ClearanceBalls(ds)) out.push_back(std::move(b));
  return out;
}

ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& type, const std::string& target,
                             const Eigen::Vector3d& p, const Eigen::Vector3d& d) {
  const ProbeTouchKind* t = AsTouch(FindKind(type));
  if (!t) throw std::invalid_argument("type: '" + type + "' is not a probe touch (" + KindList() + ")");
  return t->CrossProbeLine(ds, target, p, d);
}

}  // namespace fivecal
