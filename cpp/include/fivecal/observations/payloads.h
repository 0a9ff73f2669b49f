// The payload collection: every kind's data struct, one alternative each of
// the variant an Observation carries (dataset.h), as Pinocchio lists its
// joint models in one JointCollection. A kind's code reads its own struct
// through Observation::data<T>(); code that is not about one kind reads
// none of them. A new built-in kind's struct is added here (at the end, so
// the alternatives' indices stay); a kind defined outside the core uses
// KindOwnData.
#ifndef FIVECAL_OBSERVATIONS_PAYLOADS_H_
#define FIVECAL_OBSERVATIONS_PAYLOADS_H_

#include <variant>

#include "fivecal/observations/ball_mount_data.h"
#include "fivecal/observations/fixed_frame_data.h"
#include "fivecal/observations/kind_own_data.h"
#include "fivecal/observations/machined_data.h"
#include "fivecal/observations/touch_data.h"

namespace fivecal {

// The first alternative is what a default Observation (a facet touch) holds.
using ObservationPayload =
    std::variant<TouchData, BallMountData, PointData, PoseTargetData, DistanceData, MachinedData, KindOwnData>;

// The name of the struct a payload holds ("BallMountData"), for messages.
inline const char* PayloadName(const ObservationPayload& p) {
  return std::visit([](const auto& d) { return std::decay_t<decltype(d)>::kName; }, p);
}

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_PAYLOADS_H_
