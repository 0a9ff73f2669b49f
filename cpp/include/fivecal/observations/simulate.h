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

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

// The simulator's noise (one sigma, mm, per noise input) by noise class:
// "probe" for every probe-touch kind (along the approach), otherwise the
// kind's own name (ObservationKind::noise_class(); NoiseClasses() lists them).
// Keyed by name so that a new kind needs no field here; a class not named
// has no noise.
struct NoiseLevels {
  std::map<std::string, double> level;
  double Of(const std::string& noise_class) const {
    const auto it = level.find(noise_class);
    return it == level.end() ? 0.0 : it->second;
  }
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
//  "sigma": 0.0006 | {"probe": .., "dbb": .., "ball3d": .., <any noise class>: ..}, "seed": 1}
// Scale bar lengths are set to the true distance of the true sphere centres,
// plus (with noise) a calibration error drawn after every observation's noise
// (the written length is the bar's certificate, the truth is the distance).
Dataset Simulate(const std::string& spec_json);

// A measurement plan resolved once, for re-drawing the noise many times
// (Monte Carlo). `base` holds the noise-free readings (a kind's ApplyInput
// reads its own from base's payload); every noisy dataset
// differs from it only in the readings, along each observation's noise
// direction:
//   probe touch: the trigger position s along the nominal approach line,
//                axes = start + s * approach (s0: the noise-free touch);
//   dbb:         the reading;     ball3d: the three measured components.
// One *input* per noise coordinate, in observation order: 1 per touch or DBB
// sample, 3 per ball3d sample. `sensitivity` is d(residual row)/d(input) at
// the plan's parameter values: about -1 for a touch (the approach moves the
// tip into the surface), -1 for a DBB reading or a ball3d component.
// After the observation inputs, one input per scale bar that has a residual
// row (both its spheres probed), in bar order: the bar's calibrated length
// (sensitivity -1, sigma kScaleBarSigma, the sigma the fit weighs the bar
// row with; 0 in a plan without noise). Its input_observation is -1 - b, as
// the bar row's Problem::row_source(). `base` holds the bar's true length; a
// draw writes the certificate length = true + calibration error into the
// dataset, so the fit sees a bar whose declared length is off by the draw.
struct SimulationPlan {
  explicit SimulationPlan(Dataset d) : base(std::move(d)) {}
  Dataset base;
  NoiseLevels noise;
  uint64_t seed = 0;                       // the spec's seed (Simulate uses it)
  std::map<std::string, double> values;    // parameter values the readings follow (truth / fit)
  std::vector<Eigen::VectorXd> start;      // per observation (touches; else the axes)
  std::vector<Eigen::VectorXd> approach;   // per observation, per mm of approach (touches; else empty)
  std::vector<double> s0;                  // per observation: noise-free trigger position (touches)
  std::vector<int> input_observation;      // per input: observation index, or -1 - b for scale bar b
  std::vector<int> input_component;        // per input: 0 (touch, dbb, bar) or 0..2 (ball3d)
  Eigen::VectorXd sensitivity;             // per input: d residual / d input
  Eigen::VectorXd input_sigma;             // per input: its noise level (mm), from `noise`
  int num_inputs() const { return static_cast<int>(input_observation.size()); }
};

// Parses and solves a Simulate spec once (noise-free touches).
SimulationPlan BuildSimulationPlan(const std::string& spec_json);

// A plan around recorded data: `base` = the dataset itself (its readings are
// the noise-free values), approach lines along the nominal surface normals at
// the recorded rotary indexations, sensitivities evaluated at `values`
// (unnamed parameters are 0), noise `noise`.
SimulationPlan PlanFromDataset(const Dataset& ds, const std::map<std::string, double>& values,
                               const NoiseLevels& noise);

// The dataset of one noise draw: std::mt19937_64(seed), one standard normal
// per input in input order, scaled by the input's sigma. With the spec's seed
// this is exactly Simulate(spec_json). The scale bar inputs come last, so a
// seed draws the same observation noise as before bars were inputs.
Dataset AddNoise(const SimulationPlan& plan, uint64_t seed);

// The dataset with the given input deviations, expressed along the residual
// (mm): input i moves by deviation[i] / sensitivity[i] in its own unit.
Dataset ApplyInputDeviations(const SimulationPlan& plan, const Eigen::VectorXd& deviation);

// The same draws into `ds`, a dataset of the plan's structure (a copy of
// plan.base, possibly realised before): only the observations with inputs
// are written, with no dataset copied (Monte Carlo trials).
void AddNoiseInto(const SimulationPlan& plan, uint64_t seed, Dataset* ds);
void ApplyInputDeviationsInto(const SimulationPlan& plan, const Eigen::VectorXd& deviation, Dataset* ds);

// For the observation kinds (observations/kind.h): the tool point (workpiece
// frame) at axis commands `cmd` (mm / degrees) for machine parameters theta
// and a tip at `tip`; and one more noise input of observation `obs`.
Eigen::Vector3d ToolAtCommand(const Machine& m, const Eigen::VectorXd& theta, const Eigen::VectorXd& cmd,
                              const std::vector<int>& dir, const Eigen::Vector3d& tip);
void AddPlanInput(SimulationPlan* plan, int obs, int component, double sensitivity, double sigma);

}  // namespace fivecal

#endif  // FIVECAL_SIMULATE_H_
