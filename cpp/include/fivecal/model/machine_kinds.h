// What kind of machine a machine file describes, and the default plausible
// sizes (prior classes, one sigma) that go with it.
//
// fivecal's prior classes (solve/priors.h) default to a mid-size machining
// centre's ISO 230-1 tolerances. A positioning table, a robot or a CMM errs
// on another scale: judged against a machining centre's priors, a
// positioner's millimetre-sized pivot errors count as "not determined" and a
// preset silently leaves them out. The machine file's optional "kind" picks
// the kind's class priors; its own "priors" still win, key by key.
#ifndef FIVECAL_MACHINE_KINDS_H_
#define FIVECAL_MACHINE_KINDS_H_

#include <map>
#include <string>
#include <vector>

namespace fivecal {

struct MachineKindInfo {
  std::string name;         // machining_centre, positioner, robot, cmm
  std::string description;  // what it is and where its sizes come from
  // "class:<prior class>" -> one sigma (mm or rad ...) replacing the default
  std::map<std::string, double> priors;
};

const std::vector<MachineKindInfo>& MachineKinds();

// The canonical name of a kind as a file may spell it ("machining centre",
// "Machining-Center", "CMM"); throws std::invalid_argument naming `where`
// and the kinds when it is none of them.
std::string CanonicalMachineKind(const std::string& text, const std::string& where);

// The class priors of a kind ("" = machining_centre: none replaced).
const std::map<std::string, double>& MachineKindPriors(const std::string& kind);

}  // namespace fivecal

#endif  // FIVECAL_MACHINE_KINDS_H_
