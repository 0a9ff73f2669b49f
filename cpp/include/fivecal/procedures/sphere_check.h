// Quick sphere check, in the style of the controller cycles (Heidenhain
// KinematicsOpt, Siemens CYCLE996, AxiSet): one calibrated sphere on the
// table, a calibrated stylus, a few positions of each rotary axis in turn,
// each reached from both sides. The evaluation:
//
//   moved axes   = the rotary axes (spindle aside) whose command varies
//                  over the touches (range > 1e-6 deg)
//   estimate     = PivotParameters(axis, backlash) of every moved axis;
//                  backlash by default when the axis was reached from both
//                  directions (+1 and -1 in its recorded directions)
//   fit          = Identify(estimate, fix tip.* when the stylus is
//                  calibrated; the sphere's place is in the default set-up)
//   change_n     = value_n - previous_n,  std = hypot(std_n, std_previous_n)
//   per position = the touches of the sphere at one rotary pose (>= 3),
//                  stylus centres in the table frame (TablePoints) with the
//                  nominal and the fitted model, each fitted by a sphere of
//                  KNOWN radius R + r (FitSphereCentre from the nominal centre)
//   dispersion   = max_k |c_k - mean_k c_k| over the positions
//
// The spindle naming rule lives here too (SpindleEquivalent): an offset of a
// rotary axis that is a constant tool-part offset is named as the spindle's,
// so every procedure names the same error alike.
//
// Units: mm, degrees for commands, rad for angular errors.
#ifndef FIVECAL_PROCEDURES_SPHERE_CHECK_H_
#define FIVECAL_PROCEDURES_SPHERE_CHECK_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/model/machine.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"

namespace fivecal {

// The name every fivecal command gives the position error `name`
// (E<X|Y|Z>0<axis> of a rotary axis): the spindle's E<d>0S when the two are
// the same error, else `name` itself. A rotary axis' offset along d is a
// constant tool-part offset when every rotary axis between it and the
// foundation turns about d (or there is none); the spindle's offset across
// its own line is the same constant (exactly for the first axis from the
// foundation, to first order beyond), so no data can tell them apart.
// Names of other shapes, and axes the machine lacks, are returned unchanged.
std::string SpindleEquivalent(const Machine& m, const std::string& name);

// `errors` (name, value) under the names every command reports them, in the
// order of first appearance: a rotary offset that is the spindle's becomes
// the spindle's, minus its value when the axis is on the workpiece side;
// equal names add up.
std::vector<std::pair<std::string, double>> SpindleNames(
    const Machine& m, const std::vector<std::pair<std::string, double>>& errors);

// The rotary axes a sphere check or an R-test turns: every rotary axis but
// the spindle, in topology order.
std::vector<char> CheckedRotaryAxes(const Machine& m);

// The pivot parameters of rotary `axis`: the position of its line across
// the axis (two E<X|Y|Z>0<axis>, spindle-named by SpindleEquivalent), its
// tilt (two E<A|B|C>0<axis>) and, with `backlash`, E<axis><axis>b. The two
// machine directions are those with the smallest components of the axis
// direction (ties to the lower index), in X Y Z order.
std::vector<std::string> PivotParameters(const Machine& m, char axis, bool backlash);

struct SphereCheckOptions {
  std::string sphere;             // the sphere's id; "" = the first touched (by id)
  bool calibrated_stylus = true;  // tip.x|y|z fixed
  int backlash = -1;              // -1: where reached from both directions; 0 never; 1 always
  // The previous check: parameter name -> (value, std), finite, std >= 0.
  // A name that is the spindle's under SpindleEquivalent also counts under
  // the spindle's name (a check written before the spindle names).
  std::map<std::string, std::pair<double, double>> previous;
};

struct SphereCheckValue {
  std::string name;
  double value = 0, std = 0;  // std NaN when the parameter was not estimated
};

struct SphereCheckAxis {
  char axis = 'C';
  std::vector<SphereCheckValue> pivot;  // PivotParameters(axis, false)
  bool has_backlash = false;            // its reversal error was estimated
  SphereCheckValue backlash;            // E<axis><axis>b, rad
};

struct SphereCheckResult {
  Result fit;
  std::string sphere;
  std::vector<std::string> estimate;    // the pivot parameters asked for
  std::vector<SphereCheckAxis> axes;    // the moved axes, topology order
  std::vector<SphereCheckValue> change; // value = change, std = its std; pivots found in `previous`
  // Per position (>= 3 touches of the sphere): the moved axes' commands
  // (rounded to 1e-6 deg, the grouping key) and the stylus-centre sphere's
  // centre with the nominal and the fitted model (workpiece frame, mm).
  Eigen::MatrixXd positions, centres_before, centres_after;
  double dispersion_before = 0, dispersion_after = 0;
  double condition_number = 0;
  std::vector<std::pair<std::string, double>> informed;  // estimate names -> posterior / prior sigma
};

// Throws std::invalid_argument naming the field: no touches of a sphere, an
// unknown `sphere`, no rotary axis moved, `backlash` not -1/0/1, a previous
// value of a checked parameter not finite or its std not finite and >= 0
// (the entries the check does not compare with are not read); a
// per-position centre that does not converge; and whatever Identify refuses.
SphereCheckResult EvaluateSphereCheck(const Dataset& ds, const SphereCheckOptions& options);

// The positions of a sphere check's plan: `n` commands (degrees) of each
// rotary axis (CheckedRotaryAxes order) spread evenly over its range,
// `limits` axis -> (min, max) or, for an axis it does not name, a full turn
// (-180, 180) for C and (-90, 90) for any other (a tilting axis). A range of
// a full turn or more takes n positions without its end (the start again):
//   min + i (max - min) / n,        i = 0 .. n-1
// and a shorter one both ends:
//   min + i (max - min) / (n - 1),  i = 0 .. n-1  (the last exactly max)
// Throws std::invalid_argument naming the field: n outside 3 (a pivot needs
// three) .. kMaxSphereCheckPositions, limits.<axis> not a range (max > min).
constexpr int kMaxSphereCheckPositions = 360;
std::vector<std::pair<char, std::vector<double>>> SphereCheckPositions(
    const Machine& m, int n, const std::map<std::string, std::pair<double, double>>& limits);

}  // namespace fivecal

#endif  // FIVECAL_PROCEDURES_SPHERE_CHECK_H_
