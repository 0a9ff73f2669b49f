// Virtual machine: the dataset a real machine with known errors would record.
//
// Probe touches: the nominal tip-centre target is the touch point plus one
// tip radius along the surface normal; the linear axes for it come from the
// nominal inverse kinematics at the planned rotary indexation; the probe then
// approaches along the nominal normal (a straight line in linear-axis command
// space) and the readings are taken where the erroneous machine's tip really
// touches the true (offset) facet or sphere. Noise is added to the trigger
// position along the approach. The approach direction of every linear axis
// is recorded (backlash), the rotary directions come from the plan.
//
// DBB and ball3d samples: the reading is what the erroneous machine shows at
// the planned axis values, plus noise.
#ifndef FIVECAL_SIMULATE_H_
#define FIVECAL_SIMULATE_H_

#include <cstdint>
#include <map>
#include <string>

#include "fivecal/dataset.h"

namespace fivecal {

struct NoiseLevels {
  double probe = 0.0;   // mm, along the approach
  double dbb = 0.0;     // mm, on the reading
  double ball3d = 0.0;  // mm, per component
};

// spec JSON:
// {"machine": {...}, "errors": {"EX0C": 0.01, ...},
//  "setup": {"facet.F3": 0.002, "sphere.S1.x": 0.001, "dbb.length": 0.003, ...},
//  "probe": {"tip_radius": 3.0}, "artefact": {...},
//  "plan": [{"type": "facet", "target": "F3", "axes": {"B": 30, "C": -90, "S": 0},
//            "point": [x,y,z] (optional), "direction": {"B": 1, "C": -1} (optional)},
//           {"type": "sphere", "target": "S1", "axes": {...}, "normal": [vx,vy,vz]},
//           {"type": "dbb", "setup": "A1", "axes": {...}, "length": 100,
//            "tool_ball": [...], "table_ball": [...]},
//           {"type": "ball3d", "setup": "R1", "axes": {...}, "tool_ball": [...], "table_ball": [...]}],
//  "sigma": 0.0006 | {"probe": .., "dbb": .., "ball3d": ..}, "seed": 1}
// Scale bar lengths are set to the true distance of the true sphere centres.
Dataset Simulate(const std::string& spec_json);

}  // namespace fivecal

#endif  // FIVECAL_SIMULATE_H_
