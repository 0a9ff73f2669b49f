#include "fivecal/solve/identify_verdict.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <string>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/registry.h"
#include "fivecal/solve/priors.h"

namespace fivecal {
namespace {

// -- What the data could not tell, per family -------------------------------
// Families are the prior classes gathered as a reader names them (motions and
// tilts of one degree together); they come in this order.
const char* const kFamilies[] = {"location offsets", "location angles", "scale gains",
                                 "error motions of degree 1", "error motions of degree 2",
                                 "error motions of degree 3", "backlash", "set-up"};

std::string FamilyOf(const Machine& m, const std::string& n) {
  const int i = m.ParameterIndex(n);
  if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) return "set-up";
  const std::string c = PriorClassOf(m, n);
  if (c == "location_offset") return "location offsets";
  if (c == "location_angle") return "location angles";
  if (c == "scale_gain") return "scale gains";
  if (c.rfind("backlash_", 0) == 0) return "backlash";
  return "error motions of degree " + std::to_string(m.parameters()[i].degree);
}

// How each axis was seen by the data: distinct positions (capped: only
// "fewer than needed" matters) and the move directions recorded.
struct AxisSeen {
  int positions = 0;
  bool forward = false, backward = false;
};

std::vector<AxisSeen> SeenAxes(const Dataset& ds) {
  constexpr size_t kEnough = 8;
  const int na = ds.machine().num_axes();
  std::vector<std::set<long long>> at(na);
  std::vector<AxisSeen> seen(na);
  for (const Observation& o : ds.observations)
    for (int k = 0; k < na && k < o.axes.size(); ++k) {
      if (at[k].size() < kEnough) at[k].insert(std::llround(o.axes[k] * 1000.0));  // 1 um, 0.001 deg
      if (k < o.direction.size()) {
        seen[k].forward = seen[k].forward || o.direction[k] > 0;
        seen[k].backward = seen[k].backward || o.direction[k] < 0;
      }
    }
  // Column blocks column by column (dataset.h TraceBlock).
  for (const TraceBlock& b : ds.blocks)
    for (int k = 0; k < na && k < static_cast<int>(b.axes.size()); ++k) {
      for (size_t r = 0; r < b.axes[k].size() && at[k].size() < kEnough; ++r)
        at[k].insert(std::llround(b.axes[k][r] * 1000.0));
      if (k < static_cast<int>(b.direction.size()))
        for (const int8_t d : b.direction[k]) {
          seen[k].forward = seen[k].forward || d > 0;
          seen[k].backward = seen[k].backward || d < 0;
        }
    }
  for (int k = 0; k < na; ++k) seen[k].positions = static_cast<int>(at[k].size());
  return seen;
}

std::string JoinAnd(const std::vector<std::string>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) s += (i == 0 ? "" : i + 1 == v.size() ? " and " : ", ") + v[i];
  return s;
}

// The positions an axis must take for the data to tell a family's parameter
// of it apart from the others: a rotary axis line needs three indexations
// (two fix a circle's chord, not its centre), a degree-d error motion d + 1
// positions of a linear axis and d + 2 of a rotary one (its constant and
// location take one more), a squareness or gain two positions.
int PositionsNeeded(const Machine& m, const ParameterInfo& p) {
  const bool rotary = m.axis(p.axis).rotary();
  if (p.kind == ParameterKind::kLocation) return rotary ? 3 : 2;
  if (p.kind == ParameterKind::kMotion) return rotary ? p.degree + 2 : p.degree + 1;
  return 2;
}

// Why a family's parameters were not determined, and what would determine
// them: from how the data saw the axes they belong to (too few positions or
// indexations, one move direction), the length reference, and the groups
// the determination analysis found them confounded in (GroupCause).
std::string WhyNotDetermined(const Dataset& ds, const std::vector<AxisSeen>& seen, const std::string& family,
                             const std::vector<std::string>& names,
                             const std::vector<std::vector<std::string>>& groups) {
  const Machine& m = ds.machine();
  if (family == "scale gains" && !HasLengthReference(ds))
    return "no length reference (no scale bar or ball-bar length in the data): add a scale bar between two "
           "spheres, or a ball bar of calibrated length";
  std::map<int, int> need;  // axis -> positions needed
  for (const std::string& n : names) {
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) continue;
    const ParameterInfo& p = m.parameters()[i];
    need[p.axis] = std::max(need[p.axis], PositionsNeeded(m, p));
  }
  if (family == "backlash") {
    std::vector<std::string> one_way;
    for (const auto& [k, _] : need)
      if (!(seen[k].forward && seen[k].backward)) one_way.push_back(std::string(1, m.axis(k).name));
    if (!one_way.empty())
      return JoinAnd(one_way) + (one_way.size() == 1 ? " was" : " were") +
             " approached from one direction only (or none recorded): approach each axis from both "
             "sides and record the direction of the last move";
  } else {
    for (const bool rotary : {true, false}) {
      std::vector<std::string> axes, counts;
      int needed = 0;
      for (const auto& [k, n] : need)
        if (m.axis(k).rotary() == rotary && seen[k].positions < n) {
          axes.push_back(std::string(1, m.axis(k).name));
          counts.push_back(std::to_string(seen[k].positions));
          needed = std::max(needed, n);
        }
      if (axes.empty()) continue;
      const bool one = axes.size() == 1;
      const bool same =
          std::all_of(counts.begin(), counts.end(), [&](const std::string& c) { return c == counts[0]; });
      const std::string what = rotary ? " indexation" : " position";
      const std::string seen_at = " seen at " + (same ? counts[0] : JoinAnd(counts)) + what +
                                  (same && counts[0] == "1" ? "" : "s") + (same && !one ? " each" : "");
      if (rotary)
        return JoinAnd(axes) + seen_at + ": measure at " + std::to_string(needed) + " or more indexations of " +
               (one ? "it" : "each") + " (probe a sphere, or take R-test or ball-bar samples, at each)";
      return JoinAnd(axes) + seen_at + ": measure at " + std::to_string(needed) +
             " or more positions spread along " + (one ? "its" : "each one's") + " travel";
    }
  }
  // Every axis was seen enough: the parameters are confounded (with the
  // set-up, with each other) or seen too weakly for their plausible size.
  std::set<std::string> mine(names.begin(), names.end());
  std::vector<std::string> with;
  for (const auto& g : groups)
    if (std::any_of(g.begin(), g.end(), [&](const std::string& n) { return mine.count(n) > 0; }))
      with.insert(with.end(), g.begin(), g.end());
  if (with.empty()) with = names;
  const std::string cause = GroupCause(ds, with);
  if (family == "set-up")
    return cause + ": measure them apart (a qualified stylus, a calibrated sphere or mount) and fix them, or "
                   "add measurements from other directions and set-ups";
  if (cause.rfind("confounded with the setup", 0) == 0)
    return cause + ": add measurements that move them differently (a second artefact position, another "
                   "set-up), or fix set-up values measured apart";
  return cause + ": add poses that move them differently, over a longer travel or a larger radius";
}

std::vector<NotDetermined> NotDeterminedFamilies(const Dataset& ds, const std::vector<std::string>& estimated,
                                                 const std::vector<std::string>& undetermined,
                                                 const std::vector<std::vector<std::string>>& groups) {
  const Machine& m = ds.machine();
  const std::set<std::string> und(undetermined.begin(), undetermined.end());
  std::vector<NotDetermined> out;
  const std::vector<AxisSeen> seen = SeenAxes(ds);
  for (const char* family : kFamilies) {
    NotDetermined f;
    f.family = family;
    f.machine = f.family != "set-up";
    for (const std::string& n : estimated)
      if (FamilyOf(m, n) == f.family) {
        ++f.estimated;
        if (und.count(n)) f.names.push_back(n);
      }
    if (f.names.empty()) continue;
    f.why = WhyNotDetermined(ds, seen, f.family, f.names, groups);
    out.push_back(std::move(f));
  }
  return out;
}

// The machine errors the data put far beyond their plausible size
// (kImplausibleSigmas prior sigmas), undetermined ones left out (their
// values are arbitrary), and the likely cause: no machine is 100 mm off its
// drawing, so its nominal geometry in the machine file is wrong (or a unit).
// Empty when every determined machine error is plausible. Set-up values far
// off stay flags: a person placed them, the machine file did not.
std::string ImplausibleCause(const Machine& m, const Result& res, const Eigen::VectorXd& values,
                             const std::vector<int>& est, const Eigen::VectorXd& prior) {
  constexpr size_t kShown = 4;
  std::vector<std::string> shown;
  std::vector<std::string> axes;
  size_t count = 0;
  for (size_t j = 0; j < res.estimated.size(); ++j) {
    const std::string& n = res.estimated[j];
    const int i = m.ParameterIndex(n);
    if (i < 0 || m.parameters()[i].kind == ParameterKind::kTip) continue;
    if (std::find(res.undetermined.begin(), res.undetermined.end(), n) != res.undetermined.end()) continue;
    const double v = values[est[j]];
    if (!(std::abs(v) > kImplausibleSigmas * prior[j])) continue;
    const ParameterInfo& p = m.parameters()[i];
    const std::string axis(1, m.axis(p.axis).name);
    if (std::find(axes.begin(), axes.end(), axis) == axes.end()) axes.push_back(axis);
    if (++count > kShown) continue;
    char buf[160];
    if (p.kind == ParameterKind::kLocation)
      std::snprintf(buf, sizeof buf, "%s = %.6g %s (%.3g times its plausible size, %.3g %s)", n.c_str(),
                    v * 1e6 * (p.angular() ? 1.0 : 1e-3), p.angular() ? "urad" : "um", std::abs(v) / prior[j],
                    prior[j] * 1e6 * (p.angular() ? 1.0 : 1e-3), p.angular() ? "urad" : "um");
    else
      std::snprintf(buf, sizeof buf, "%s = %.4g (%.3g times its plausible size)", n.c_str(), v,
                    std::abs(v) / prior[j]);
    shown.push_back(buf);
  }
  if (count == 0) return "";
  std::string list;
  for (size_t k = 0; k < shown.size(); ++k) list += (k ? ", " : "") + shown[k];
  if (count > kShown) list += " and " + std::to_string(count - kShown) + " more";
  const bool one = axes.size() == 1;
  // The placed set-ups of the fit (an instrument started from the wrong pose
  // turns the machine as well): named as the other place to look.
  std::vector<std::string> placed;
  for (size_t j = 0; j < res.estimated.size() && j < res.placement.size(); ++j) {
    if (!(res.placement[j] > 0.0)) continue;
    const std::string& n = res.estimated[j];
    const size_t a = n.find('.'), b = a == std::string::npos ? a : n.find('.', a + 1);
    const std::string owner = n.substr(0, b);
    if (std::find(placed.begin(), placed.end(), owner) == placed.end()) placed.push_back(owner);
  }
  return list + ": likely cause: the machine file (machine \"" + m.name() + "\"): its nominal geometry of " +
         (one ? "axis " : "axes ") + JoinAnd(axes) + " (" + (one ? "its point or direction" :
                                                             "their points or directions") +
         ") is not the machine's, or a value is in the wrong unit; correct the machine file and fit again" +
         (placed.empty() ? std::string()
                         : "; if the machine file is right, a set-up is far from where the dataset places it (" +
                               JoinAnd(placed) + ")");
}

void FillResiduals(const Dataset& ds, const Eigen::VectorXd& values, const ParameterTable& table,
                   const Eigen::VectorXd& r, Result* res) {
  const Machine& m = ds.machine();
  const int n = static_cast<int>(ds.size());  // column-block rows too
  res->residual_vectors = Eigen::MatrixXd::Zero(n, 3);
  res->points = Eigen::MatrixXd::Zero(n, 3);
  const KinematicModel model(m, values.data());
  const ReportContext ctx{&ds, &table, &values, &model};
  int row = 0;
  ds.ForEachRow([&](size_t i, const Observation& o) {
    const ObservationKind& kind = KindOf(o);
    Eigen::Vector3d P, v;
    kind.ReportVector(ctx, o, r.data() + row, &P, &v);
    res->points.row(static_cast<Eigen::Index>(i)) = P.transpose();
    res->residual_vectors.row(static_cast<Eigen::Index>(i)) = v.transpose();
    row += kind.rows();
  });
}

// A group's sigma x 1e3 is in um; a group of rad rows (NoiseGroup: its class
// part, before any ".<id>", ends in "_rad") is shown in urad, x 1e6.
bool RadGroup(const std::string& group) {
  const std::string cls = group.substr(0, group.find('.'));
  return cls.size() > 4 && cls.compare(cls.size() - 4, 4, "_rad") == 0;
}
const char* MicroUnit(const std::string& group) { return RadGroup(group) ? "urad" : "um"; }
double MicroScale(const std::string& group) { return RadGroup(group) ? 1e3 : 1.0; }

}  // namespace

Result JudgeResult(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq, const IdentifyFit& fit,
                   const IdentifyDetermination& dt, const IdentifyCovariance& cov) {
  (void)opt;
  const ParameterTable& table = rq.table;
  const std::vector<int>& est = rq.est;
  const Eigen::VectorXd& prior = rq.prior;
  const Eigen::VectorXd& values = fit.fit.values;
  const Determination& det = dt.determination;
  const Eigen::MatrixXd& Cs = cov.scaled_posterior;
  const bool map = rq.map;
  const int p = static_cast<int>(est.size());
  const double chi2 = cov.chi2;

  Result res;
  res.names = table.names();
  res.estimated = rq.estimated;
  res.map_fit = map;
  res.explicit_request = !rq.automatic;
  res.left_out = rq.left_out;
  res.left_out_moves = rq.left_out_moves;
  res.placement = std::vector<double>(rq.place.data(), rq.place.data() + p);
  if (map)
    for (int j = 0; j < p; ++j) res.placement[j] = rq.placement_all[est[j]];
  res.fit_path = fit.normal_equations ? "normal_equations" : "dense";
  res.converged = fit.fit.converged;
  res.iterations = fit.fit.iterations + fit.adapt_iterations;
  res.message = fit.fit.message;
  res.initial_cost = fit.fit.initial_cost;
  res.final_cost = fit.fit.final_cost;
  res.robust_scale = fit.fit.robust_scale;
  res.class_scales = fit.class_scales;
  res.variance_components = fit.variance_components;

  res.values = values;
  res.residuals = fit.r;
  res.residual_source = *fit.row_source;
  res.n_observations = fit.num_rows;
  res.n_parameters = p;
  res.rms = cov.rms;
  res.max_abs = cov.max_abs;
  res.outliers = cov.outliers;
  res.rank = cov.rank;
  res.dof = cov.dof;
  res.covariance = cov.covariance;
  res.condition_number = cov.condition_number;
  res.sigma = cov.sigma;
  res.residual_units = cov.residual_units;
  res.chi2 = chi2;
  res.chi2_p = cov.chi2_p;
  res.std = cov.std;
  res.correlation = cov.correlation;

  // What the data determined.
  res.unidentifiable = dt.groups;
  for (int j = 0; j < p; ++j) {
    res.prior_std.push_back(prior[j]);
    res.informed.push_back(res.std[j] / prior[j]);
    const double v = values[est[j]];
    if (std::abs(v) > kImplausibleSigmas * prior[j]) res.implausible.push_back(res.estimated[j]);
  }
  if (map) {
    // The posterior ratio without the chi2 inflation: how much the data, at
    // the declared noise, narrowed the prior.
    for (int j = 0; j < p; ++j)
      if (!(std::sqrt(std::max(Cs(j, j), 0.0)) < kInformedThreshold))
        res.undetermined.push_back(res.estimated[j]);
  } else {
    for (int c : det.undetermined) res.undetermined.push_back(res.estimated[c]);
  }
  // The machine errors the data identified (kIdentifiedRatio). A MAP fit's
  // data-only groups are no verdict on their members: the posterior,
  // `undetermined`, says which ones the data, with the others' priors,
  // narrowed; one in a class the data show no sign of is held near 0.
  res.seeks_machine_errors = rq.location || rq.automatic;
  for (int j = 0; j < p; ++j) {
    const std::string& n = res.estimated[j];
    if (std::find(res.undetermined.begin(), res.undetermined.end(), n) != res.undetermined.end()) continue;
    const int i = ds.machine().ParameterIndex(n);
    const bool machine = i >= 0 && ds.machine().parameters()[i].kind != ParameterKind::kTip;
    const auto scale = machine ? res.class_scales.find(PriorClassOf(ds.machine(), n)) : res.class_scales.end();
    if (scale != res.class_scales.end() && scale->second < kAbsentClassScale) res.held.push_back(n);
    else if (machine && (!(res.informed[j] > kIdentifiedRatio) ||
                         std::abs(values[est[j]]) >= kSignificantSigmas * res.std[j]))
      ++res.identified_machine_errors;
  }
  for (const std::string& n : res.estimated) {
    const int i = ds.machine().ParameterIndex(n);
    if (i >= 0 && ds.machine().parameters()[i].kind != ParameterKind::kTip) res.seeks_machine_errors = true;
  }
  res.not_determined = NotDeterminedFamilies(ds, res.estimated, res.undetermined, res.unidentifiable);
  res.plausibility = ImplausibleCause(ds.machine(), res, values, est, prior);
  res.plausible = res.plausibility.empty();

  // Adequacy: residuals against the declared noise.
  const double ratio = res.dof > 0 ? chi2 / res.dof : 0.0;
  res.adequate = !(res.chi2_p < 1e-3 && ratio > 2.0);
  bool mounts = false, mount_estimated = false;
  auto mount_of = [&](const Observation& o) {
    for (int c : KindOf(o).MountPositions(table, o)) {
      mounts = true;
      if (std::find(est.begin(), est.end(), c) != est.end()) mount_estimated = true;
    }
  };
  for (const Observation& o : ds.observations) mount_of(o);
  Observation first;  // a column block's rows share one mounting
  for (const TraceBlock& b : ds.blocks)
    if (b.size()) {
      ds.FillRow(b, 0, &first);
      mount_of(first);
    }
  bool cause_named = false;  // the residuals name the cause: a set-up left fixed, a unit
  if (!res.adequate) {
    const double x = std::sqrt(ratio);
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.3g", x);
    cause_named = (mounts && !mount_estimated) || (x > 200 && x < 5000);
    if (mounts && !mount_estimated)
      res.adequacy = "instrument setup not estimated (ball3d/dbb mount: estimate its tool and "
                     "table ball positions, e.g. ball3d.<setup>.table.x|y|z); residuals are " +
                     std::string(buf) + "x the declared noise";
    else if (x > 200 && x < 5000)
      res.adequacy = "unit mistake (residuals ~" + std::string(buf) +
                     "x the declared noise: readings in um where mm are expected, or a wrong sigma)";
    else if (!HasLengthReference(ds))
      res.adequacy = "no length reference (no scale bar / dbb length) and residuals " +
                     std::string(buf) + "x the declared noise: the model misses errors the data show";
    else
      res.adequacy = "residuals " + std::string(buf) +
                     "x the declared noise: the model misses errors the data show (estimate more, "
                     "e.g. 'auto') or the declared noise is too small";
  }

  // A misfit whose cause the residuals name (a set-up left fixed, a unit
  // mistake) is told by that cause: the values it drives far off are its
  // symptom, and "the machine file" would send the user to the wrong file.
  if (cause_named && !res.plausible) {
    res.adequacy += "; it drives values beyond their plausible size: " + res.plausibility;
    res.plausible = true;
  }

  // With the noise estimated the chi-square passes by construction; what is
  // left to judge is how far each group's noise is from its declaration.
  // Variance components would otherwise absorb any misfit as "noise": beyond
  // kMaxNoiseFactor it is a misfit or a unit mistake, not the instrument.
  for (const VarianceComponent& c : res.variance_components)
    if (c.estimated && res.adequate && c.factor > kMaxNoiseFactor) {
      char buf[200];
      std::snprintf(buf, sizeof buf,
                    "the %s residuals are %.3gx their declared noise even with the noise estimated "
                    "(%.3g %s against %.3g %s declared): ",
                    c.group.c_str(), c.factor, c.sigma * 1e3 * MicroScale(c.group), MicroUnit(c.group),
                    c.declared * 1e3 * MicroScale(c.group), MicroUnit(c.group));
      res.adequate = false;
      res.adequacy = std::string(buf) +
                     (c.group != "probe" && mounts && !mount_estimated
                          ? "instrument setup not estimated (ball3d/dbb mount: estimate its tool and "
                            "table ball positions, e.g. ball3d.<setup>.table.x|y|z)"
                          : "the model misses errors this instrument sees, or its readings are in other "
                            "units; if the noise really is this large, declare it (sigma)");
    }

  // Never hand out NaN or inf.
  res.finite = values.allFinite() && res.std.allFinite() && res.covariance.allFinite();
  if (!res.finite) {
    for (int i = 0; i < res.values.size(); ++i)
      if (!std::isfinite(res.values[i])) res.values[i] = rq.initial[i];
    for (int i = 0; i < res.std.size(); ++i)
      if (!std::isfinite(res.std[i])) res.std[i] = 0.0;
    res.covariance = res.covariance.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
    res.correlation = res.correlation.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
    for (double& x : res.informed)
      if (!std::isfinite(x)) x = 0.0;
  }
  res.residuals = res.residuals.unaryExpr([](double x) { return std::isfinite(x) ? x : 0.0; });
  if (!std::isfinite(res.rms)) res.rms = 0, res.finite = false;
  if (!std::isfinite(res.max_abs)) res.max_abs = 0;
  if (!std::isfinite(res.sigma)) res.sigma = 0;
  FillResiduals(ds, res.values, table, res.residuals, &res);
  return res;
}

}  // namespace fivecal
