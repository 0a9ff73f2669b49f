// The payload of a probe touch (facet, sphere, cylinder: probe_touch.h):
// what one touch records beyond the common header (dataset.h Observation).
#ifndef FIVECAL_OBSERVATIONS_TOUCH_DATA_H_
#define FIVECAL_OBSERVATIONS_TOUCH_DATA_H_

#include <string>

namespace fivecal {

struct TouchData {
  static constexpr const char* kName = "TouchData";
  std::string target;  // the id of the artefact's facet, sphere or cylinder touched
};
inline bool operator==(const TouchData& a, const TouchData& b) { return a.target == b.target; }

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_TOUCH_DATA_H_
