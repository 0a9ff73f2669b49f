#include "fivecal/model/machine_kinds.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <stdexcept>

namespace fivecal {
namespace {

// Every class's default scaled by one factor, then the classes whose size a
// kind sets on its own. Reference travels as in priors.cc: 250 mm, 1 rad.
std::map<std::string, double> Scaled(double offset_mm, double angle_rad, double gain, double linear_mm,
                                     double tilt_rad, double backlash_mm, double backlash_rad) {
  constexpr double L = 250.0, R = 1.0;
  std::map<std::string, double> p = {{"class:location_offset", offset_mm},
                                     {"class:location_angle", angle_rad},
                                     {"class:scale_gain", gain},
                                     {"class:backlash_linear", backlash_mm},
                                     {"class:backlash_rotary", backlash_rad}};
  for (int d = 1; d <= 3; ++d) {
    const std::string s = std::to_string(d);
    p["class:linear_motion_" + s] = linear_mm / std::pow(L, d);
    p["class:linear_tilt_" + s] = tilt_rad / std::pow(L, d);
    p["class:rotary_motion_" + s] = linear_mm / std::pow(R, d);
    p["class:rotary_tilt_" + s] = tilt_rad / std::pow(R, d);
  }
  return p;
}

std::vector<MachineKindInfo> Make() {
  return {
      {"machining_centre",
       "a mid-size machining centre (the default): ISO 230-1 tolerances, pivots set up to 0.1 mm, "
       "squareness 100 urad, scales 100 um/m, error motions 10 um / 50 urad over 250 mm or 1 rad",
       {}},
      {"positioner",
       "a positioning table or two-axis welding / measuring positioner: bearings and pivots set to about "
       "1 mm, axis tilts and squareness 1 mrad, scales 1000 um/m, error motions 0.1 mm / 500 urad over "
       "250 mm or 1 rad, reversal 50 um / 200 urad (ten times a machining centre's)",
       Scaled(1.0, 1e-3, 1e-3, 0.1, 5e-4, 0.05, 2e-4)},
      {"robot",
       "an industrial serial robot before calibration: link offsets about 2 mm, joint axis tilts 5 mrad "
       "(0.3 deg), scales 2000 um/m, error motions 0.2 mm / 1 mrad over 250 mm or 1 rad, reversal 0.1 mm "
       "/ 500 urad",
       Scaled(2.0, 5e-3, 2e-3, 0.2, 1e-3, 0.1, 5e-4)},
      {"cmm",
       "a coordinate measuring machine: squareness 20 urad, scales 20 um/m, error motions 2 um / 10 urad "
       "over 250 mm or 1 rad, reversal 1 um / 5 urad (a fifth of a machining centre's; pivots of a rotary "
       "table 20 um)",
       Scaled(0.02, 2e-5, 2e-5, 0.002, 1e-5, 0.001, 5e-6)},
  };
}

}  // namespace

const std::vector<MachineKindInfo>& MachineKinds() {
  static const std::vector<MachineKindInfo> kinds = Make();
  return kinds;
}

std::string CanonicalMachineKind(const std::string& text, const std::string& where) {
  std::string s;
  for (char c : text) s += (c == ' ' || c == '-') ? '_' : static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (s == "machining_center") s = "machining_centre";
  for (const MachineKindInfo& k : MachineKinds())
    if (k.name == s) return s;
  std::string msg = where + ": unknown kind of machine '" + text + "' (kinds:";
  for (const MachineKindInfo& k : MachineKinds()) msg += " " + k.name;
  throw std::invalid_argument(msg + ")");
}

const std::map<std::string, double>& MachineKindPriors(const std::string& kind) {
  for (const MachineKindInfo& k : MachineKinds())
    if (k.name == kind) return k.priors;
  return MachineKinds().front().priors;  // "" or unknown (refused at load): the default
}

}  // namespace fivecal
