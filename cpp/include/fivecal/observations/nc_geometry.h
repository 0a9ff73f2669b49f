// What the NC program writers (python/fivecal/io/nc_programs.py, io/
// plan_readings.py) ask of a plan's kinds, through the registry: which
// program family runs a kind's entries, where a planned touch meets its
// target and from which side, the solids the moves keep out of, and where a
// probe line first reaches a target (a simulated probe's trip). Each kind
// answers for itself (ProbeTouchKind, BallMountKind), so the writers name no
// kind and a new probe-touch kind gets a probing program for free.
#ifndef FIVECAL_OBSERVATIONS_NC_GEOMETRY_H_
#define FIVECAL_OBSERVATIONS_NC_GEOMETRY_H_

#include <optional>
#include <string>
#include <vector>

#include "fivecal/observations/probe_touch.h"

namespace fivecal {

// The program family of kind `k`'s plan entries ("probing", "sphere",
// "rtest", "dbb"), nullptr when no program runs them.
const char* NcProgram(const ObservationKind& k);

// Per entry of `plan_json` (a JSON array of plan entries): a probe touch's
// contact geometry (ProbeTouchKind::PlannedTouchContact), nullopt for an
// entry of any other kind. Throws std::invalid_argument naming
// "plan[i]...": an unknown target, a bad normal or point.
std::vector<std::optional<TouchContact>> PlannedTouchContacts(const Dataset& ds, const std::string& plan_json);

// Every ball the moves keep out of, of every kind's targets in `ds` (kinds in
// registry order).
std::vector<ClearanceBall> ArtefactClearanceBalls(const Dataset& ds);

// ProbeTouchKind::CrossProbeLine of the probe-touch kind named `type`
// (std::invalid_argument for another).
ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& type, const std::string& target,
                             const Eigen::Vector3d& p, const Eigen::Vector3d& d);

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_NC_GEOMETRY_H_
