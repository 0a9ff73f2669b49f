// Identify, stage 4 of 6 (identify_request.h lists them): what the data
// determine at the solution, measured against the priors
// (identifiability.h AnalyzeDetermination), on the fit's shared factor.
#ifndef FIVECAL_SOLVE_IDENTIFY_DETERMINATION_H_
#define FIVECAL_SOLVE_IDENTIFY_DETERMINATION_H_

#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_fit.h"
#include "fivecal/solve/identify_request.h"

namespace fivecal {

struct IdentifyDetermination {
  Determination determination;  // columns in estimated order
  // determination.groups by name (Result::unidentifiable).
  std::vector<std::vector<std::string>> groups;
  // "location" with variance components: chosen candidates (columns) too
  // weakly seen at the estimated noise; Identify fits again without them.
  std::vector<int> drop;
};

// Throws the refusal (UndeterminedMessage) when a least-squares request
// leaves parameters undetermined, unless allow_unidentifiable or all that
// is undetermined are "location" candidates under variance components
// (then `drop` names them).
IdentifyDetermination DetermineAtSolution(const Dataset& ds, const IdentifyOptions& opt,
                                          const IdentifyRequest& rq, const IdentifyFit& fit);

// The groups of `d` by the names of the estimated set.
std::vector<std::vector<std::string>> GroupNames(const Determination& d, const std::vector<std::string>& estimated);

// Plain words for why a group of parameters is not determined.
std::string GroupCause(const Dataset& ds, const std::vector<std::string>& group);

// The refusal of a request the data do not determine: the groups (machine
// errors first), their causes, one readable line however many.
std::string UndeterminedMessage(const Dataset& ds, std::vector<std::vector<std::string>> groups);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_DETERMINATION_H_
