#include "fivecal/solve/priors.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "fivecal/observations/registry.h"

namespace fivecal {
namespace {

constexpr double kLinearEffect = 0.010;   // mm over the reference travel
constexpr double kAngularEffect = 50e-6;  // rad over the reference travel

double Pow(double x, int d) { return std::pow(x, d); }

std::vector<PriorClass> MakeClasses() {
  const double L = kLinearReferenceTravel, R = kRotaryReferenceTravel;
  std::vector<PriorClass> c = {
      {"location_offset", 0.1, "mm",
       "position of a rotary axis line or the spindle (EX0C, EY0S ...): pivot points "
       "are set up to about 0.1 mm before calibration"},
      {"location_angle", 1e-4, "rad",
       "orientation / squareness of an axis (EA0B, EC0Y ...): 100 urad, ISO 230-1 "
       "squareness tolerances of 0.02-0.05 mm over 500 mm"},
      {"scale_gain", 1e-4, "mm/mm",
       "linear positioning gain EXX1, EYY1, EZZ1: 100 um/m, an uncompensated scale"},
  };
  for (int d = 1; d <= 3; ++d)
    c.push_back({"linear_motion_" + std::to_string(d), kLinearEffect / Pow(L, d),
                 "mm/mm^" + std::to_string(d),
                 "translational error motion of a linear axis, degree " + std::to_string(d) +
                     " (straightness, positioning non-linearity): 10 um over 250 mm"});
  for (int d = 1; d <= 3; ++d)
    c.push_back({"linear_tilt_" + std::to_string(d), kAngularEffect / Pow(L, d),
                 "rad/mm^" + std::to_string(d),
                 "angular error motion of a linear axis, degree " + std::to_string(d) +
                     " (roll, pitch, yaw): 50 urad over 250 mm"});
  for (int d = 1; d <= 3; ++d)
    c.push_back({"rotary_motion_" + std::to_string(d), kLinearEffect / Pow(R, d),
                 "mm/rad^" + std::to_string(d),
                 "radial / axial error motion of a rotary axis, degree " + std::to_string(d) +
                     ": 10 um over 1 rad"});
  for (int d = 1; d <= 3; ++d)
    c.push_back({"rotary_tilt_" + std::to_string(d), kAngularEffect / Pow(R, d),
                 "rad/rad^" + std::to_string(d),
                 "tilt / angular positioning error motion of a rotary axis, degree " +
                     std::to_string(d) + ": 50 urad over 1 rad"});
  const std::vector<PriorClass> rest = {
      {"backlash_linear", 0.005, "mm", "reversal error of a linear axis (EXXb): 5 um"},
      {"backlash_rotary", 2e-5, "rad", "reversal error of a rotary axis (ECCb): 20 urad"},
      {"tip", 1.0, "mm", "stylus / tool tip offset tip.x|y|z: a stylus length is poorly known"},
  };
  c.insert(c.end(), rest.begin(), rest.end());
  // The setup parameters' classes, from their observation kinds (a class two
  // kinds share is listed once).
  for (const ObservationKind* kind : ObservationKinds())
    for (const PriorClass& k : kind->prior_classes())
      if (std::none_of(c.begin(), c.end(), [&](const PriorClass& x) { return x.name == k.name; }))
        c.push_back(k);
  return c;
}

bool StartsWith(const std::string& s, const std::string& p) { return s.rfind(p, 0) == 0; }

int Distance(const std::string& a, const std::string& b) {
  std::vector<int> prev(b.size() + 1), cur(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) prev[j] = static_cast<int>(j);
  for (size_t i = 1; i <= a.size(); ++i) {
    cur[0] = static_cast<int>(i);
    for (size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

const PriorClass* FindClass(const std::string& name) {
  for (const PriorClass& c : PriorClasses())
    if (c.name == name) return &c;
  return nullptr;
}

}  // namespace

const std::vector<PriorClass>& PriorClasses() {
  static const std::vector<PriorClass> classes = MakeClasses();
  return classes;
}

std::string PriorClassOf(const Machine& m, const std::string& name) {
  const int i = m.ParameterIndex(name);
  if (i >= 0) {
    const ParameterInfo& p = m.parameters()[i];
    switch (p.kind) {
      case ParameterKind::kTip: return "tip";
      case ParameterKind::kLocation: return p.angular() ? "location_angle" : "location_offset";
      case ParameterKind::kBacklash:
        return m.axis(p.axis).rotary() ? "backlash_rotary" : "backlash_linear";
      case ParameterKind::kMotion: {
        const bool rotary = m.axis(p.axis).rotary();
        const std::string d = std::to_string(p.degree);
        // The axis's own translational component of degree 1 is its scale gain.
        if (!rotary && p.degree == 1 && !p.angular() &&
            std::abs(m.axis(p.axis).direction[p.component]) > 0.5)
          return "scale_gain";
        if (rotary) return (p.angular() ? "rotary_tilt_" : "rotary_motion_") + d;
        return (p.angular() ? "linear_tilt_" : "linear_motion_") + d;
      }
    }
  }
  for (const ObservationKind* kind : ObservationKinds())
    if (const char* c = kind->PriorClassOfName(name)) return c;
  throw std::invalid_argument("prior: no prior class for parameter '" + name + "'");
}

void ValidatePriors(const std::map<std::string, double>& priors, const std::string& where,
                    const std::vector<std::string>& known_names) {
  for (const auto& [key, value] : priors) {
    if (!std::isfinite(value) || !(value > 0))
      throw std::invalid_argument(where + "['" + key + "']: a prior sigma must be finite and > 0, got " +
                                  std::to_string(value));
    if (StartsWith(key, "class:")) {
      const std::string cls = key.substr(6);
      if (FindClass(cls)) continue;
      std::string best;
      int best_d = 1 << 30;
      for (const PriorClass& c : PriorClasses()) {
        const int d = Distance(cls, c.name);
        if (d < best_d) best_d = d, best = c.name;
      }
      std::string msg = where + ": unknown prior class '" + cls + "'";
      if (best_d <= std::max<int>(3, static_cast<int>(cls.size()) / 3))
        msg += "; did you mean 'class:" + best + "'?";
      msg += " (classes:";
      for (const PriorClass& c : PriorClasses()) msg += " " + c.name;
      throw std::invalid_argument(msg + ")");
    }
    if (std::find(known_names.begin(), known_names.end(), key) != known_names.end()) continue;
    std::string best;
    int best_d = 1 << 30;
    for (const std::string& n : known_names) {
      const int d = Distance(key, n);
      if (d < best_d) best_d = d, best = n;
    }
    std::string msg = where + ": unknown parameter '" + key + "'";
    if (best_d <= 2) msg += "; did you mean '" + best + "'?";
    throw std::invalid_argument(msg + " (a parameter name, or class:<name> for a whole class)");
  }
}

std::vector<double> PriorScales(const Machine& m, const std::vector<std::string>& names,
                                const std::map<std::string, double>& machine_priors,
                                const std::map<std::string, double>& call_priors) {
  std::vector<double> out;
  out.reserve(names.size());
  for (const std::string& n : names) {
    const std::string cls = PriorClassOf(m, n);
    double s = FindClass(cls)->sigma;
    for (const auto* src : {&machine_priors, &call_priors}) {
      auto c = src->find("class:" + cls);
      if (c != src->end()) s = c->second;
      auto p = src->find(n);
      if (p != src->end()) s = p->second;
    }
    out.push_back(s);
  }
  return out;
}

namespace {

// The kind a set-up parameter name belongs to (nullptr: none, or a machine
// parameter).
const ObservationKind* KindOfSetupName(const std::string& name) {
  for (const ObservationKind* kind : ObservationKinds())
    if (kind->PriorClassOfName(name)) return kind;
  return nullptr;
}

bool IsSetupClass(const std::string& cls) {
  for (const ObservationKind* kind : ObservationKinds())
    for (const PriorClass& c : kind->prior_classes())
      if (c.name == cls) return true;
  return false;
}

}  // namespace

Eigen::VectorXd PlacementRows(const Eigen::VectorXd& placement_all, const std::vector<int>& est) {
  bool any = false;
  for (int i : est) any = any || placement_all[i] > 0;
  if (!any) return Eigen::VectorXd();
  Eigen::VectorXd out = Eigen::VectorXd::Constant(placement_all.size(), std::numeric_limits<double>::infinity());
  for (int i : est)
    if (placement_all[i] > 0) out[i] = placement_all[i];
  return out;
}

Eigen::MatrixXd WithPlacementRows(const Eigen::MatrixXd& Jw, const Eigen::VectorXd& u) {
  int n = 0;
  for (int j = 0; j < u.size(); ++j) n += u[j] > 0;
  if (n == 0) return Jw;
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(Jw.rows() + n, Jw.cols());
  out.topRows(Jw.rows()) = Jw;
  int row = static_cast<int>(Jw.rows());
  for (int j = 0; j < u.size(); ++j)
    if (u[j] > 0) out(row++, j) = 1.0 / u[j];
  return out;
}

double PlacementSigma(const Machine& m, const std::string& name,
                      const std::map<std::string, double>& overrides) {
  if (m.ParameterIndex(name) >= 0) return 0.0;  // machine errors: priors.h PriorScales
  const ObservationKind* kind = KindOfSetupName(name);
  if (!kind) return 0.0;
  auto p = overrides.find(name);
  if (p != overrides.end()) return p->second;
  auto c = overrides.find(std::string("class:") + kind->PriorClassOfName(name));
  if (c != overrides.end()) return c->second;
  return kind->DefaultPlacement(name);
}

std::vector<double> PlacementScales(const Machine& m, const std::vector<std::string>& names,
                                    const std::map<std::string, double>& overrides) {
  std::vector<double> out;
  out.reserve(names.size());
  for (const std::string& n : names) out.push_back(PlacementSigma(m, n, overrides));
  return out;
}

void ValidateSetupUncertainty(const Machine& m, const std::map<std::string, double>& u, const std::string& where,
                              const std::vector<std::string>& names) {
  for (const auto& [key, value] : u) {
    const std::string w = where + "['" + key + "']";
    if (!std::isfinite(value) || !(value > 0))
      throw std::invalid_argument(w + ": a placement uncertainty must be finite and > 0 (in the parameter's "
                                  "unit, mm or rad); a quantity known exactly is fixed instead");
    if (StartsWith(key, "class:")) {
      const std::string cls = key.substr(6);
      if (IsSetupClass(cls)) continue;
      std::string msg = w + ": unknown set-up class '" + cls + "' (set-up classes:";
      std::set<std::string> listed;
      for (const ObservationKind* kind : ObservationKinds())
        for (const PriorClass& c : kind->prior_classes())
          if (listed.insert(c.name).second) msg += " " + c.name;
      throw std::invalid_argument(msg + ")");
    }
    if (m.ParameterIndex(key) >= 0)
      throw std::invalid_argument(w + ": '" + key +
                                  "' is a machine error, not a set-up quantity (its prior belongs in the "
                                  "machine file's \"priors\")");
    if (std::find(names.begin(), names.end(), key) != names.end() && KindOfSetupName(key)) continue;
    std::string best;
    int best_d = 1 << 30;
    for (const std::string& n : names) {
      if (m.ParameterIndex(n) >= 0) continue;
      const int d = Distance(key, n);
      if (d < best_d) best_d = d, best = n;
    }
    std::string msg = w + ": unknown set-up parameter '" + key + "' (not among this dataset's set-up parameters";
    if (!best.empty() && best_d <= 3) msg += "; did you mean '" + best + "'?";
    throw std::invalid_argument(msg + ")");
  }
}

}  // namespace fivecal
