// The test-only observation kind "stylus3d" (stylus3d.cc).
#ifndef FIVECAL_TESTS_KIND_PLUGIN_STYLUS3D_H_
#define FIVECAL_TESTS_KIND_PLUGIN_STYLUS3D_H_

#include <memory>

#include "fivecal/observations/kind.h"

namespace fivecal {

// The registered instance, and whether registering it from its file's static
// initialiser succeeded.
const ObservationKind& TheStylus3dKind();
extern const bool kStylus3dRegistered;
// Another instance with type code `t` (the registry must refuse a second
// kind of the same name).
std::unique_ptr<ObservationKind> MakeStylus3dKind(ObservationType t);

}  // namespace fivecal

#endif  // FIVECAL_TESTS_KIND_PLUGIN_STYLUS3D_H_
