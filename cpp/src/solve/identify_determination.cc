#include "fivecal/solve/identify_determination.h"

#include <algorithm>
#include <stdexcept>

#include "fivecal/observations/registry.h"
#include "fivecal/solve/priors.h"

namespace fivecal {
namespace {

std::string GroupText(std::vector<std::string> g) {
  // Machine errors (what the user asked for) before the setup parameters.
  std::stable_partition(g.begin(), g.end(), [](const std::string& n) { return n[0] == 'E'; });
  std::string s = "{";
  const size_t shown = std::min<size_t>(g.size(), 8);
  for (size_t i = 0; i < shown; ++i) s += (i ? ", " : "") + g[i];
  if (g.size() > shown) s += ", ... (" + std::to_string(g.size() - shown) + " more)";
  return s + "}";
}

}  // namespace

std::string GroupCause(const Dataset& ds, const std::vector<std::string>& group) {
  const Machine& m = ds.machine();
  int gains = 0, setup = 0, machine = 0;
  for (const std::string& n : group) {
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) ++setup;
    else ++machine;
    if (i >= 0 && PriorClassOf(m, n) == "scale_gain") ++gains;
  }
  // Isotropic pretravel shortens every touch alike, as a smaller tip radius
  // would: the facet offsets and the cylinder and sphere radii absorb it.
  if (std::find(group.begin(), group.end(), "probe.pretravel") != group.end() && machine == 0)
    return "probe.pretravel acts exactly like a tip radius error, which the facet offsets and the "
           "cylinder and sphere radii also absorb: fix probe.pretravel (or qualify the probe on a "
           "calibrated sphere with its radius fixed)";
  if (gains > 0 && !HasLengthReference(ds))
    return "no length reference (no data of a kind that carries one: scale bar, ball-bar length, "
           "tracker, camera or interferometer): only relative scale can be found";
  if (machine > 0 && setup > 0)
    return "confounded with the setup (stylus tip, facet offsets, sphere centres, mounts, instrument poses or stations)";
  // A single parameter is confounded with nothing: it is seen too weakly.
  if (machine == 1 && group.size() == 1)
    return "too weakly seen at these poses for its plausible size (its prior)";
  if (machine > 0)
    return "confounded with each other or too weakly seen at these poses for their plausible size";
  return "setup parameters the data do not separate";
}

std::string UndeterminedMessage(const Dataset& ds, std::vector<std::vector<std::string>> groups) {
  // What the user asked for first: groups with machine errors; then the
  // spheres' centres (the length reference rides on them), the stylus tip,
  // and the facets and mounts, so that a capped message keeps the cause.
  const Machine& m = ds.machine();
  auto rank = [&](const std::vector<std::string>& g) {
    int r = 3;
    for (const std::string& n : g) {
      const int i = m.ParameterIndex(n);
      if (i >= 0 && m.parameters()[i].kind != ParameterKind::kTip) return 0;
      // probe.* are only estimated on request: say first why they cannot be
      if (n.rfind("probe.", 0) == 0) return 0;
      if (n.rfind("sphere.", 0) == 0) r = std::min(r, 1);
      else if (n.rfind("tip.", 0) == 0) r = std::min(r, 2);
    }
    return r;
  };
  std::stable_sort(groups.begin(), groups.end(),
                   [&](const auto& a, const auto& b) { return rank(a) < rank(b); });
  std::string msg =
      "identify: not determined by this data (confounded, or seen more weakly than their "
      "plausible size): ";
  // A refusal stays one readable line however many parameters it is about
  // (a plan missing most of its touches leaves hundreds undetermined): the
  // first groups, about kShownNames names, then how many more.
  constexpr size_t kShownNames = 10;
  size_t total = 0, listed = 0, shown = 0;
  for (const auto& g : groups) total += g.size();
  size_t i = 0;
  std::string cause;  // consecutive groups of one cause share it
  for (; i < groups.size(); ++i) {
    if (i > 0 && shown + std::min<size_t>(groups[i].size(), 8) > kShownNames) break;
    const std::string c = GroupCause(ds, groups[i]);
    if (i > 0) msg += c == cause ? ", " : ": " + cause + "; ";
    msg += GroupText(groups[i]);
    cause = c;
    shown += std::min<size_t>(groups[i].size(), 8);
    listed += groups[i].size();
  }
  msg += ": " + cause;
  if (i < groups.size())
    msg += "; and " + std::to_string(total - listed) + " more parameter" + (total - listed == 1 ? "" : "s") +
           " in " + std::to_string(groups.size() - i) + " more group" + (groups.size() - i == 1 ? "" : "s");
  return msg + ". Fix one parameter of each group, add measurements that separate them, or use "
               "estimate 'auto' (every error under its prior, the undetermined ones listed).";
}

std::vector<std::vector<std::string>> GroupNames(const Determination& d, const std::vector<std::string>& estimated) {
  std::vector<std::vector<std::string>> groups;
  for (const auto& g : d.groups) {
    std::vector<std::string> names;
    for (int c : g) names.push_back(estimated[c]);
    groups.push_back(names);
  }
  return groups;
}

IdentifyDetermination DetermineAtSolution(const Dataset& ds, const IdentifyOptions& opt,
                                          const IdentifyRequest& rq, const IdentifyFit& fit) {
  IdentifyDetermination out;
  out.determination = AnalyzeDetermination(fit.factor, rq.prior, kDeterminedRatio);
  out.groups = GroupNames(out.determination, rq.estimated);
  if (!rq.map && !out.determination.undetermined.empty() && !opt.allow_unidentifiable) {
    // "location" chose its set at the declared noise; variance components
    // may find the noise larger, and a chosen candidate too weakly seen at
    // the noise the data show. That is the selection's call, not the user's
    // error: Identify leaves it out, says why, and fits the rest.
    if (rq.location && opt.variance_components)
      for (int c : out.determination.undetermined)
        if (std::find(rq.candidates.begin(), rq.candidates.end(), rq.est[c]) != rq.candidates.end())
          out.drop.push_back(c);
    if (out.drop.empty() || out.drop.size() == rq.est.size())
      throw std::invalid_argument(UndeterminedMessage(ds, out.groups));
  }
  return out;
}

}  // namespace fivecal
