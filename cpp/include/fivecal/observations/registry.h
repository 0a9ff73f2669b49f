// The observation kinds, in one table (observations/registry.cc). Generic
// code asks the registry for the kind of an observation instead of
// switching on its type.
#ifndef FIVECAL_OBSERVATIONS_REGISTRY_H_
#define FIVECAL_OBSERVATIONS_REGISTRY_H_

#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/observations/kind.h"

namespace fivecal {

// Every kind, in registration order (the order of the parameter table's
// artefact parameters and of the names in messages).
const std::vector<const ObservationKind*>& ObservationKinds();

// Adds a kind defined outside the core's table (a test's kind, a plug-in):
// from then on it loads, fits, simulates and reports like a built-in one.
// Its type() must be a code no other kind has (UnusedObservationType()),
// its name() a new one. Returns false when `kind` is registered already;
// throws std::invalid_argument for a name or type code taken by another.
// Not thread-safe: register before loading or fitting anything (a static
// initialiser of the kind's own file).
bool RegisterObservationKind(const ObservationKind& kind);
// The lowest type code no registered kind has.
ObservationType UnusedObservationType();

// The kind of a type (every ObservationType is registered).
const ObservationKind& KindOf(ObservationType t);
inline const ObservationKind& KindOf(const Observation& o) { return KindOf(o.type); }

// The kind whose file name is `name`, or nullptr.
const ObservationKind* FindKind(const std::string& name);

// The file names of every kind ("facet", "sphere", ...).
std::vector<std::string> KindNames();
// "facet, sphere, dbb, ball3d": for messages.
std::string KindList();

// The simulator's noise classes (ObservationKind::noise_class()), each
// once, in registration order: the keys of a spec's "sigma" object.
std::vector<std::string> NoiseClasses();
// The unit of a noise class's levels: that of the residual rows that draw on
// it ("mm"; "rad" for a pose's rotation rows). Throws std::invalid_argument
// for a class no kind has.
std::string NoiseClassUnit(const std::string& noise_class);

// Whether `name` has the shape of a setup parameter name (facet.<id>,
// sphere.<id>.x|y|z|r, dbb[.<setup>].length|tool.x|...|table.z,
// ball3d.<setup>.tool.x|..., probe.*, instrument.<id>.<field>), whatever
// dataset it belongs to. A dotted name of any other shape (EX0C.x) is a
// mistake, never a set-up quantity to skip.
bool IsSetupParameterName(const std::string& name);

// Whether the data fix the length scale: an observation of a kind that does
// (ball bar, 3D ball displacement), or an artefact length (a scale bar whose
// balls were probed).
bool HasLengthReference(const Dataset& ds);

// The contact point and outward surface normal (workpiece frame) of a
// planned touch, a plan entry given as JSON text: its kind's
// PlannedContact. False for an entry of a kind that touches no surface.
bool PlannedContact(const Dataset& ds, const std::string& entry_json, Eigen::Vector3d* point,
                    Eigen::Vector3d* normal);

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_REGISTRY_H_
