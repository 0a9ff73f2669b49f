// Residual, Problem and identification tests.
//
//  1. Every residual type (facet, sphere, scale bar, DBB, ball3d) has the
//     Jacobian of its Ceres cost function checked against finite differences
//     with ceres::GradientChecker, at a non-trivial point (every machine error
//     non-zero and realistic, backlash active in both directions, tip and
//     setup offsets non-zero) on the HU40T-like wCBXfZYSt machine and on a
//     wCAfXYZSt tilting rotary table. The dense Jacobian of Problem::Evaluate
//     is checked against central differences of Problem::Evaluate itself.
//  2. On a noise-free simulated dataset the residuals vanish at the true
//     parameter values and not at the nominal ones.
//  3. Identify() recovers location errors from noise-free probing and DBB
//     data, and refuses a confounded request, naming the parameter.
//
// Finite differences and parameter scales
// ---------------------------------------
// The machine parameters span ten orders of magnitude in their own units: a
// location error is ~1e-2 mm or ~1e-4 rad, a cubic error-motion coefficient
// of a linear axis ~1e-3 mm / (300 mm)^3 ~ 4e-11 mm/mm^3. Ceres' numeric
// differentiation takes a step relative to |x| with an absolute floor
// (sqrt(eps) for CENTRAL, ridders_relative_initial_step_size for RIDDERS,
// which GradientChecker uses), so no single NumericDiffOptions suits them all:
// a floor of 1e-2 moves EAX3 by 1e-2 * 300^3 = 2.7e5 rad at X = 300 mm. We
// therefore probe each cost function through a thin wrapper that
// reparametrises every scalar block as theta = s * u, with s the parameter's
// natural scale (1 / R^d for a degree-d error-motion coefficient over an axis
// range R of 300 mm or pi rad, 1 otherwise). The wrapper calls the library's
// cost function unchanged and multiplies its Jacobian column by s, so the
// check compares exactly J * s with d r / d u. In u-space every parameter is
// O(1e-2) or smaller and a unit change moves the tool point by <= ~300 mm.
//
// Ridders (GradientChecker's method) starts from an absolute step of
// ridders_relative_initial_step_size (|u| < 1) and halves it. We use 1e-3:
// at 1e-2 the sphere residual (a norm of a ~15 mm vector, moved ~1 mm by the
// first step of an angular error) makes Ridders' early exit (tableau error
// > 2x the best error) return estimates off by ~1e-3 relative; at 1e-4 the
// round-off of the smallest steps grows. At 1e-3 the worst entry uses ~20 %
// of its allowance (printed by the test as "worst error / allowed").
// The Jacobians are checked at 80 % of the true values (ProbePoint), where
// the residuals are ~um rather than round-off: GradientChecker also compares
// the residuals of its double and Jet evaluations relatively.
//
// Entries: relative precision 1e-6 (GradientChecker's test), except entries
// below ~1e-6 of the largest one of their residual row, which a parameter of
// second-order influence at that pose can have (we see entries at 1e-10 of
// their row, e.g. cubic error motions on a facet touch): for them the absolute
// difference must be below 1e-12 x the row's largest entry, the round-off
// level of any finite difference of residuals computed from ~300 mm vectors.
//
// For the whole-problem check we use our own central differences on the
// same u-scale with one Richardson step (h = 1e-3 and h/2, truncation
// O(h^4)), perturbing the values of a freshly built Problem; per column,
// |J - FD| <= 1e-6 max|column| + 1e-9 (round-off floor for near-zero columns).
#include <gtest/gtest.h>

#include <ceres/gradient_checker.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iomanip>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/model/machine.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/residuals.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kLinearRange = 300.0;  // mm, the error-motion scale of a linear axis
constexpr double kRotaryRange = kPi;    // rad, that of a rotary axis

// The HU40T-like horizontal machine of DESIGN.md.
const char* kHu40tJson = R"({"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})";

// A tilting rotary table: A about +X pivoting 60 mm under the table, C on A,
// all linear axes and the spindle on the tool side.
const char* kTableJson = R"({"name": "tilting table", "topology": "wCAfXYZSt",
 "axes": {"C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]},
          "A": {"type": "rotary", "direction": [1,0,0], "point": [0,0,-60]},
          "X": {"type": "linear", "direction": [1,0,0]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})";

// A cube with five probed faces and two spheres joined by a scale bar
// (workpiece frame; the scale bar length is replaced by the simulator).
const char* kArtefactJson = R"({
 "facets": [{"id": "F1", "point": [0,0,50],   "normal": [0,0,1]},
            {"id": "F2", "point": [35,0,25],  "normal": [1,0,0]},
            {"id": "F3", "point": [0,35,25],  "normal": [0,1,0]},
            {"id": "F4", "point": [-35,0,25], "normal": [-1,0,0]},
            {"id": "F5", "point": [0,-35,25], "normal": [0,-1,0]}],
 "spheres": [{"id": "S1", "center": [90,60,20],   "radius": 12.7},
             {"id": "S2", "center": [-80,-70,30], "radius": 12.7}],
 "scale_bars": [{"spheres": ["S1","S2"], "length": 214.0}]})";

using NamedValues = std::map<std::string, double>;

std::string Num(double x) {
  std::ostringstream s;
  s << std::setprecision(17) << x;
  return s.str();
}

std::string Vec(const Eigen::Vector3d& v) {
  return "[" + Num(v.x()) + "," + Num(v.y()) + "," + Num(v.z()) + "]";
}

std::string Obj(const NamedValues& v) {
  std::string s = "{";
  for (const auto& [k, x] : v) s += (s.size() > 1 ? "," : "") + ("\"" + k + "\": " + Num(x));
  return s + "}";
}

std::string AxesObj(const Machine& m, const Eigen::VectorXd& pose) {
  NamedValues v;
  for (int k = 0; k < m.num_axes(); ++k) v[std::string(1, m.axis(k).name)] = pose[k];
  return Obj(v);
}

Eigen::VectorXd Pose(const Machine& m, const std::map<char, double>& v) {
  Eigen::VectorXd p = Eigen::VectorXd::Zero(m.num_axes());
  for (const auto& [name, x] : v) {
    const int k = m.AxisIndex(name);
    if (k < 0) throw std::logic_error(std::string("no axis ") + name);
    p[k] = x;
  }
  return p;
}

// Nominal commands that put the tool point (machine tip) at `target`
// (workpiece frame) with the rotary axes at the values given in `rotary`.
Eigen::VectorXd NominalPose(const Machine& m, const Eigen::Vector3d& target,
                            const std::map<char, double>& rotary) {
  Eigen::MatrixXd pts(1, 3);
  pts.row(0) = target.transpose();
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  return InverseKinematics(m, theta, pts, nullptr, Pose(m, rotary)).row(0).transpose();
}

// Realistic non-zero values for every machine parameter: location errors
// 1e-2 mm / 1e-4 rad; error motions whose effect over the axis range is a
// few um / tens of urad; backlash 2 um / 20 urad; tip offsets 1e-2 mm. Signs
// and magnitudes (30..100 %) are pseudo-random but fixed.
NamedValues RealisticMachineErrors(const Machine& m, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> mag(0.3, 1.0);
  std::bernoulli_distribution sign(0.5);
  NamedValues out;
  for (const ParameterInfo& p : m.parameters()) {
    const bool rotary_axis = p.axis >= 0 && m.axis(p.axis).rotary();
    double scale = 0;
    switch (p.kind) {
      case ParameterKind::kLocation: scale = p.angular() ? 1e-4 : 1e-2; break;
      case ParameterKind::kMotion:
        scale = (p.angular() ? 2e-5 : 2e-3) /
                std::pow(rotary_axis ? kRotaryRange : kLinearRange, p.degree);
        break;
      case ParameterKind::kBacklash: scale = rotary_axis ? 2e-5 : 2e-3; break;
      case ParameterKind::kTip: scale = 1e-2; break;
    }
    out[p.name] = (sign(rng) ? 1.0 : -1.0) * mag(rng) * scale;
  }
  return out;
}

// Non-zero values for every setup parameter the plans below create.
NamedValues RealisticSetup() {
  NamedValues s = {{"facet.F1", 0.004},      {"facet.F2", -0.003},    {"facet.F3", 0.002},
                   {"facet.F4", -0.005},     {"facet.F5", 0.0035},    {"sphere.S1.x", 0.012},
                   {"sphere.S1.y", -0.008},  {"sphere.S1.z", 0.005},  {"sphere.S1.r", 0.0015},
                   {"sphere.S2.x", -0.006},  {"sphere.S2.y", 0.009},  {"sphere.S2.z", -0.011},
                   {"sphere.S2.r", -0.001},  {"dbb.length", 0.0031}, {"dbb.A1.length", -0.0022}};
  const char* xyz[3] = {"x", "y", "z"};
  for (const std::string prefix : {"dbb", "dbb.A1", "ball3d.R1"})
    for (int c = 0; c < 3; ++c) {
      s[prefix + ".tool." + xyz[c]] = 0.001 * (c + 1) * (prefix == "dbb.A1" ? -1 : 1);
      s[prefix + ".table." + xyz[c]] = 0.0015 * (2 - c) * (prefix == "ball3d.R1" ? -1 : 1) + 0.0005;
    }
  return s;
}

NamedValues OnlySetupOf(const NamedValues& setup, const std::vector<std::string>& prefixes) {
  NamedValues out;
  for (const auto& [k, v] : setup)
    for (const std::string& p : prefixes)
      if (k.rfind(p, 0) == 0) out[k] = v;
  return out;
}

std::string Spec(const char* machine_json, const NamedValues& errors, const NamedValues& setup,
                 const std::vector<std::string>& plan, double sigma = 0.0,
                 const std::string& artefact_json = kArtefactJson) {
  std::string s = std::string("{\"machine\": ") + machine_json +
                  ", \"probe\": {\"tip_radius\": 3.0}, \"artefact\": " + artefact_json +
                  ", \"errors\": " + Obj(errors) + ", \"setup\": " + Obj(setup) + ", \"plan\": [";
  for (size_t i = 0; i < plan.size(); ++i) s += (i ? ",\n" : "\n") + plan[i];
  return s + "], \"sigma\": " + Num(sigma) + ", \"seed\": 7}";
}

std::string FacetTouch(const std::string& id, const std::string& rotary_axes,
                       const std::string& direction, const Eigen::Vector3d* point = nullptr) {
  std::string s = "{\"type\": \"facet\", \"target\": \"" + id + "\", \"axes\": " + rotary_axes;
  if (!direction.empty()) s += ", \"direction\": " + direction;
  if (point) s += ", \"point\": " + Vec(*point);
  return s + "}";
}

std::string SphereTouch(const std::string& id, const std::string& rotary_axes,
                        const std::string& direction, const Eigen::Vector3d& normal) {
  std::string s = "{\"type\": \"sphere\", \"target\": \"" + id + "\", \"axes\": " + rotary_axes +
                  ", \"normal\": " + Vec(normal);
  if (!direction.empty()) s += ", \"direction\": " + direction;
  return s + "}";
}

// A DBB or ball3d sample with the tool ball (= the machine tip) placed by
// the nominal inverse kinematics at table_ball + bar.
std::string BallSample(const Machine& m, const std::string& type, const std::string& setup,
                       const std::map<char, double>& rotary, const Eigen::Vector3d& table_ball,
                       const Eigen::Vector3d& bar, const std::string& direction) {
  const Eigen::VectorXd pose = NominalPose(m, table_ball + bar, rotary);
  std::string s = "{\"type\": \"" + type + "\", \"axes\": " + AxesObj(m, pose) +
                  ", \"tool_ball\": " + Vec(m.tip()) + ", \"table_ball\": " + Vec(table_ball);
  if (!setup.empty()) s += ", \"setup\": \"" + setup + "\"";
  if (type == "dbb") s += ", \"length\": " + Num(bar.norm());
  if (!direction.empty()) s += ", \"direction\": " + direction;
  return s + "}";
}

// A small plan with every observation type, both backlash directions on
// every axis, the spindle indexed, and rotary poses spread over their range.
std::vector<std::string> MixedPlan(const Machine& m) {
  const char r1 = m.axis(m.workpiece_chain().back()).name;   // C on both machines
  const char r2 = m.axis(m.workpiece_chain().size() > 1      // B (HU40T) or A (table)
                             ? m.workpiece_chain()[m.workpiece_chain().size() - 2]
                             : m.workpiece_chain().back()).name;
  auto rot = [&](double a2, double a1, double s) {
    return "{\"" + std::string(1, r2) + "\": " + Num(a2) + ", \"" + std::string(1, r1) +
           "\": " + Num(a1) + ", \"S\": " + Num(s) + "}";
  };
  auto dir = [&](int d2, int d1) {
    return "{\"" + std::string(1, r2) + "\": " + std::to_string(d2) + ", \"" + std::string(1, r1) +
           "\": " + std::to_string(d1) + "}";
  };
  // Every axis' direction, for the ball samples (no approach moves there).
  auto all_dir = [&](int sgn) {
    std::string s = "{";
    int i = 0;
    for (const Axis& a : m.axes()) {
      if (a.name == 'S') continue;
      s += (i ? ", \"" : "\"") + std::string(1, a.name) + "\": " + std::to_string(i % 2 ? sgn : -sgn);
      ++i;
    }
    return s + "}";
  };
  const Eigen::Vector3d p1(8, -6, 50);
  std::vector<std::string> plan = {
      FacetTouch("F1", rot(0, 0, 0), dir(1, -1), &p1),
      FacetTouch("F2", rot(25, 70, 45), dir(-1, 1)),
      FacetTouch("F3", rot(-30, -120, 0), dir(1, 1)),
      FacetTouch("F4", rot(15, 200, 90), dir(-1, -1)),
      FacetTouch("F5", rot(-20, 35, 0), ""),
      SphereTouch("S1", rot(20, 45, 30), dir(1, -1), Eigen::Vector3d(0.3, 0.2, 1.0)),
      SphereTouch("S2", rot(-25, -60, 0), dir(-1, 1), Eigen::Vector3d(-1.0, 0.5, 0.4)),
  };
  const Eigen::Vector3d table_ball(60, -20, 40);
  plan.push_back(BallSample(m, "dbb", "", {{r2, 10}, {r1, 30}}, table_ball,
                            Eigen::Vector3d(60, 80, 0), all_dir(1)));
  plan.push_back(BallSample(m, "dbb", "", {{r2, -20}, {r1, 150}}, table_ball,
                            Eigen::Vector3d(0, -60, 80), all_dir(-1)));
  plan.push_back(BallSample(m, "dbb", "A1", {{r2, -15}, {r1, 250}}, Eigen::Vector3d(-40, 30, 35),
                            Eigen::Vector3d(0, 0, 150), all_dir(1)));
  plan.push_back(BallSample(m, "ball3d", "R1", {{r2, 30}, {r1, -75}, {'S', 60}},
                            Eigen::Vector3d(20, 50, 30), Eigen::Vector3d(0.01, -0.02, 0.005),
                            all_dir(-1)));
  plan.push_back(BallSample(m, "ball3d", "R1", {{r2, -35}, {r1, 110}}, Eigen::Vector3d(20, 50, 30),
                            Eigen::Vector3d(0, 0, 0), all_dir(1)));
  return plan;
}

NamedValues Merge(NamedValues a, const NamedValues& b) {
  a.insert(b.begin(), b.end());
  return a;
}

// Every table parameter's value from a name map (absent names are 0).
Eigen::VectorXd TableValues(const ParameterTable& table, const NamedValues& v) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(table.size());
  for (int i = 0; i < table.size(); ++i) {
    auto it = v.find(table.names()[i]);
    if (it != v.end()) out[i] = it->second;
  }
  return out;
}

// Natural scale of a parameter (see the header comment).
double NaturalScale(const Machine& m, int index) {
  if (index >= m.num_parameters()) return 1.0;
  const ParameterInfo& p = m.parameters()[index];
  if (p.kind != ParameterKind::kMotion) return 1.0;
  return 1.0 / std::pow(m.axis(p.axis).rotary() ? kRotaryRange : kLinearRange, p.degree);
}

// theta_i = s_i * u_i around the library's cost function (scalar blocks).
class ScaledCost : public ceres::CostFunction {
 public:
  ScaledCost(const ceres::CostFunction* f, std::vector<double> s) : f_(f), s_(std::move(s)) {
    set_num_residuals(f->num_residuals());
    *mutable_parameter_block_sizes() = f->parameter_block_sizes();
  }
  bool Evaluate(double const* const* u, double* residuals, double** jacobians) const override {
    const size_t n = s_.size();
    std::vector<double> x(n);
    std::vector<const double*> px(n);
    for (size_t i = 0; i < n; ++i) {
      x[i] = s_[i] * u[i][0];
      px[i] = &x[i];
    }
    if (!f_->Evaluate(px.data(), residuals, jacobians)) return false;
    if (jacobians)
      for (size_t i = 0; i < n; ++i)
        if (jacobians[i])
          for (int r = 0; r < num_residuals(); ++r) jacobians[i][r] *= s_[i];
    return true;
  }

 private:
  const ceres::CostFunction* f_;
  const std::vector<double> s_;
};

std::string KindOfRow(const Dataset& ds, int source) {
  if (source < 0) return "scale_bar";
  return ObservationTypeName(ds.observations[source].type);
}

// The lines of a GradientChecker log that flag a bad entry, with the
// parameter name instead of the block number.
std::string BadEntries(const std::string& log, const std::vector<std::string>& block_names) {
  std::istringstream in(log);
  std::string line, out;
  int shown = 0;
  while (std::getline(in, line)) {
    if (line.find("------") == std::string::npos) continue;
    std::istringstream ls(line);
    int block = -1;
    ls >> block;
    const std::string name =
        block >= 0 && block < static_cast<int>(block_names.size()) ? block_names[block] : "?";
    if (shown++ < 20) out += "  [" + name + "] " + line + "\n";
  }
  if (shown > 20) out += "  ... " + std::to_string(shown - 20) + " more\n";
  return out;
}

struct Fixture {
  Dataset ds;
  ParameterTable table;
  NamedValues truth;
  Eigen::VectorXd values;
};

// A noise-free simulated dataset of MixedPlan on `machine_json`, with every
// machine error and every setup parameter non-zero.
Fixture MixedFixture(const char* machine_json, uint32_t seed) {
  const Machine m = Machine::FromJson(machine_json);
  const NamedValues errors = RealisticMachineErrors(m, seed);
  const NamedValues setup = RealisticSetup();
  Dataset ds = Simulate(Spec(machine_json, errors, setup, MixedPlan(m)));
  ParameterTable table(ds);
  const NamedValues truth = Merge(errors, setup);
  Eigen::VectorXd values = TableValues(table, truth);
  return Fixture{std::move(ds), std::move(table), truth, values};
}

// The Jacobians are checked at 80 % of the true values: every parameter
// still non-zero and realistic, and the residuals (~um) not zero, which
// GradientChecker needs (it compares the residuals of the double and Jet
// evaluations relatively, and at the truth both are round-off, ~1e-15 mm).
Eigen::VectorXd ProbePoint(const Eigen::VectorXd& truth) { return 0.8 * truth; }

constexpr double kRelativePrecision = 1e-6;
constexpr double kTinyEntry = 1e-12;

std::vector<int> AllIndices(int n) {
  std::vector<int> v(n);
  for (int i = 0; i < n; ++i) v[i] = i;
  return v;
}

// ---- 1. Jacobians ---------------------------------------------------------------

void GradientCheckEveryBlock(const char* machine_json, uint32_t seed) {
  const Fixture fx = MixedFixture(machine_json, seed);
  const Machine& m = fx.ds.machine();
  // Every parameter estimated, so every residual sees every machine error,
  // backlash, tip and setup offset as a parameter block.
  const Eigen::VectorXd at = ProbePoint(fx.values);
  // The per-observation functors (the reference implementation); the
  // analytic batch is compared against them in test_analytic_residuals.cc.
  Problem problem(fx.ds, fx.table, at, AllIndices(fx.table.size()), "", 0.0, /*analytic=*/false);
  ASSERT_EQ(problem.values(), at);

  std::vector<ceres::ResidualBlockId> blocks;
  problem.ceres_problem().GetResidualBlocks(&blocks);
  const int n_obs = static_cast<int>(fx.ds.observations.size());
  ASSERT_EQ(static_cast<int>(blocks.size()), n_obs + static_cast<int>(fx.ds.artefact.scale_bars.size()));

  ceres::NumericDiffOptions nd;
  nd.ridders_relative_initial_step_size = 1e-3;  // absolute in u-space (|u| < 1)
  std::map<std::string, int> checked;
  double worst_ratio = 0;
  int total_strict_failures = 0;
  int row = 0;
  for (size_t b = 0; b < blocks.size(); ++b) {
    const ceres::CostFunction* cost = problem.ceres_problem().GetCostFunctionForResidualBlock(blocks[b]);
    std::vector<double*> params;
    problem.ceres_problem().GetParameterBlocksForResidualBlock(blocks[b], &params);
    // With everything estimated no residual is constant, so the blocks are
    // the observations in order, then the scale bars.
    const std::string kind = KindOfRow(fx.ds, problem.row_source()[row]);
    row += cost->num_residuals();
    SCOPED_TRACE("residual block " + std::to_string(b) + " (" + kind + ") on " + m.topology());

    std::vector<double> scale, u;
    std::vector<std::string> names;
    for (double* p : params) {
      const int index = static_cast<int>(p - problem.values().data());
      ASSERT_GE(index, 0);
      ASSERT_LT(index, fx.table.size());
      scale.push_back(NaturalScale(m, index));
      u.push_back(*p / scale.back());
      names.push_back(fx.table.names()[index]);
    }
    // Every block depends on what its type says it depends on.
    if (kind == "scale_bar") {
      EXPECT_EQ(params.size(), 6u);
    } else {
      EXPECT_GT(static_cast<int>(params.size()), m.num_parameters());
    }
    std::vector<const double*> pu(u.size());
    for (size_t i = 0; i < u.size(); ++i) pu[i] = &u[i];

    ScaledCost scaled(cost, scale);
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;  // all Euclidean
    ceres::GradientChecker checker(&scaled, no_manifolds, nd);
    ceres::GradientChecker::ProbeResults results;
    const bool ok = checker.Probe(pu.data(), kRelativePrecision, &results);
    // Probe also fails when the residuals with and without Jacobians differ
    // or an evaluation fails: those must not happen.
    ASSERT_EQ(results.local_jacobians.size(), params.size()) << results.error_log;
    ASSERT_EQ(results.local_numeric_jacobians.size(), params.size()) << results.error_log;
    ASSERT_TRUE(ok || results.error_log.find("Detected") != std::string::npos) << results.error_log;
    // Entry test: relative precision 1e-6, or an absolute difference below
    // kTinyEntry x the largest entry of the residual row. The per-entry
    // relative test alone fails on entries ~1e-10 of the row's largest (a
    // parameter of second-order influence at that pose), where the finite
    // difference itself carries round-off of ~1e-16 of the row (~1e-14 mm).
    const int nr = cost->num_residuals();
    Eigen::VectorXd row_max = Eigen::VectorXd::Zero(nr);
    for (const auto& J : results.local_jacobians)
      for (int i = 0; i < nr; ++i) row_max[i] = std::max(row_max[i], std::abs(J(i, 0)));
    double worst = 0;
    std::string worst_text;
    int strict_failures = 0;
    for (size_t k = 0; k < params.size(); ++k)
      for (int i = 0; i < nr; ++i) {
        const double a = results.local_jacobians[k](i, 0);
        const double n = results.local_numeric_jacobians[k](i, 0);
        const double err = std::abs(a - n);
        const double mag = std::max(std::abs(a), std::abs(n));
        if (err > kRelativePrecision * mag) ++strict_failures;
        const double allowed = std::max(kRelativePrecision * mag, kTinyEntry * row_max[i]);
        if (err / allowed > worst) {
          worst = err / allowed;
          std::ostringstream t;
          t << names[k] << " row " << i << ": analytic " << a << ", numeric " << n
            << ", |diff| " << err << ", row max " << row_max[i];
          worst_text = t.str();
        }
      }
    EXPECT_LE(worst, 1.0) << "worst entry " << worst_text << "\nentries flagged by Ceres:\n"
                          << BadEntries(results.error_log, names);
    worst_ratio = std::max(worst_ratio, worst);
    total_strict_failures += strict_failures;
    // The derivatives are not trivially zero: the tool point moves with the
    // machine errors.
    EXPECT_GT(row_max.maxCoeff(), 0.1);
    ++checked[kind];
  }
  for (const char* kind : {"facet", "sphere", "scale_bar", "dbb", "ball3d"})
    EXPECT_GE(checked[kind], 1) << "no " << kind << " residual was checked";
  std::cout << "[ gradient ] " << m.topology() << ": " << blocks.size()
            << " residual blocks, worst error / allowed = " << worst_ratio << ", "
            << total_strict_failures << " tiny entries outside the plain 1e-6 relative test\n";
}

TEST(ResidualJacobian, GradientCheckerEveryTypeHU40T) { GradientCheckEveryBlock(kHu40tJson, 11); }

TEST(ResidualJacobian, GradientCheckerEveryTypeTiltingTable) { GradientCheckEveryBlock(kTableJson, 23); }

// A mixed estimated set: machine parameters of every kind and setup
// parameters of every kind; everything else fixed at non-zero values.
std::vector<int> MixedEstimate(const ParameterTable& table, const Machine& m) {
  std::vector<std::string> names;
  for (const ParameterInfo& p : m.parameters()) {
    switch (p.kind) {
      case ParameterKind::kLocation:
        if (m.axis(p.axis).rotary() || p.angular()) names.push_back(p.name);
        break;
      case ParameterKind::kMotion:
        if (p.degree != 2 && p.component % 2 == 0) names.push_back(p.name);
        break;
      case ParameterKind::kBacklash:
      case ParameterKind::kTip: names.push_back(p.name); break;
    }
  }
  for (const char* n : {"facet.F1", "facet.F3", "sphere.S1.x", "sphere.S1.r", "sphere.S2.y",
                        "sphere.S2.z", "dbb.length", "dbb.tool.x", "dbb.table.z", "dbb.A1.length",
                        "dbb.A1.tool.z", "ball3d.R1.tool.y", "ball3d.R1.table.x"})
    names.push_back(n);
  std::vector<int> out;
  for (const std::string& n : names) out.push_back(table.Require(n));
  return out;
}

void CheckProblemJacobian(const char* machine_json, uint32_t seed, bool everything) {
  const Fixture fx = MixedFixture(machine_json, seed);
  const Machine& m = fx.ds.machine();
  const std::vector<int> est =
      everything ? AllIndices(fx.table.size()) : MixedEstimate(fx.table, m);
  const Eigen::VectorXd at = ProbePoint(fx.values);
  Problem problem(fx.ds, fx.table, at, est);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  problem.Evaluate(&r, &J);
  ASSERT_EQ(J.rows(), problem.num_rows());
  ASSERT_EQ(J.cols(), static_cast<long>(est.size()));
  ASSERT_EQ(r.size(), problem.num_rows());

  auto residuals_at = [&](int j, double delta) {
    Eigen::VectorXd v = at;
    v[est[j]] += delta;
    Problem p(fx.ds, fx.table, v, est);
    Eigen::VectorXd out;
    p.Evaluate(&out, nullptr);
    return out;
  };
  // Step in u-space; round-off of residuals computed from ~300 mm vectors is
  // ~1e-13 mm, i.e. ~1e-10 on a difference quotient, hence the floor.
  const double h = 1e-3;
  for (size_t j = 0; j < est.size(); ++j) {
    const std::string& name = fx.table.names()[est[j]];
    const double s = NaturalScale(m, est[j]);
    auto central = [&](double hu) {
      return Eigen::VectorXd((residuals_at(j, hu * s) - residuals_at(j, -hu * s)) / (2 * hu));
    };
    // Richardson: (4 D(h/2) - D(h)) / 3, error O(h^4).
    const Eigen::VectorXd fd = (4.0 * central(h / 2) - central(h)) / 3.0;
    const Eigen::VectorXd an = J.col(j) * s;
    const double mag = std::max(an.cwiseAbs().maxCoeff(), fd.cwiseAbs().maxCoeff());
    const double err = (an - fd).cwiseAbs().maxCoeff();
    EXPECT_LE(err, 1e-6 * mag + 1e-9) << name << ": |J - FD| = " << err << " of " << mag;
  }
  // A parameter that everything depends on has a substantial column.
  EXPECT_GT(J.col(std::find(est.begin(), est.end(), fx.table.Require("tip.x")) - est.begin())
                .cwiseAbs()
                .maxCoeff(),
            0.5);
}

// Every parameter estimated, then a mixed subset with the others fixed at
// non-zero values (they enter as constants).
TEST(ResidualJacobian, ProblemEvaluateMatchesCentralDifferencesHU40T) {
  CheckProblemJacobian(kHu40tJson, 5, true);
  CheckProblemJacobian(kHu40tJson, 5, false);
}

TEST(ResidualJacobian, ProblemEvaluateMatchesCentralDifferencesTiltingTable) {
  CheckProblemJacobian(kTableJson, 6, true);
  CheckProblemJacobian(kTableJson, 6, false);
}

// Fixed parameters enter the residuals as the constants given: a problem
// estimating a subset (in any order, or only a few setup parameters so that
// most residuals are constant and evaluated outside Ceres) has the same
// residual rows, and the same Jacobian columns, as one estimating everything.
TEST(ResidualJacobian, FixedParametersAreConstantsOfTheSameModel) {
  for (const char* json : {kHu40tJson, kTableJson}) {
    const Fixture fx = MixedFixture(json, 31);
    const Eigen::VectorXd at = ProbePoint(fx.values);
    Problem full(fx.ds, fx.table, at, AllIndices(fx.table.size()));
    Eigen::VectorXd r_full;
    Eigen::MatrixXd J_full;
    full.Evaluate(&r_full, &J_full);
    ASSERT_GT(r_full.cwiseAbs().maxCoeff(), 1e-4);  // not the trivial point

    const std::vector<int> mixed = MixedEstimate(fx.table, fx.ds.machine());
    const std::vector<int> reversed(mixed.rbegin(), mixed.rend());
    const std::vector<int> sparse = {fx.table.Require("ball3d.R1.table.y"),
                                     fx.table.Require("facet.F3"),
                                     fx.table.Require("sphere.S2.x")};
    for (const std::vector<int>& est : {mixed, reversed, sparse, std::vector<int>{}}) {
      SCOPED_TRACE(std::string(fx.ds.machine().topology()) + ", " + std::to_string(est.size()) +
                   " estimated");
      Problem part(fx.ds, fx.table, at, est);
      Eigen::VectorXd r_part;
      Eigen::MatrixXd J_part;
      part.Evaluate(&r_part, &J_part);
      ASSERT_EQ(r_full.size(), r_part.size());
      ASSERT_EQ(J_part.rows(), r_full.size());
      ASSERT_EQ(J_part.cols(), static_cast<long>(est.size()));
      EXPECT_LT((r_full - r_part).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_EQ(full.row_source(), part.row_source());
      for (size_t j = 0; j < est.size(); ++j)
        EXPECT_LT((J_full.col(est[j]) - J_part.col(j)).cwiseAbs().maxCoeff(),
                  1e-10 * (1 + J_full.col(est[j]).cwiseAbs().maxCoeff()))
            << fx.table.names()[est[j]];
      // The residual rows are also what PredictResiduals reports.
      NamedValues named;
      for (int i = 0; i < fx.table.size(); ++i) named[fx.table.names()[i]] = at[i];
      EXPECT_LT((PredictResiduals(fx.ds, named) - r_part).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
}

// ---- 2. Residual values ---------------------------------------------------------

void CheckZeroAtTruth(const char* machine_json, uint32_t seed) {
  const Fixture fx = MixedFixture(machine_json, seed);
  std::vector<int> source;
  const Eigen::VectorXd r = PredictResiduals(fx.ds, fx.truth, &source);
  ASSERT_EQ(static_cast<size_t>(r.size()), source.size());
  std::map<std::string, double> worst;
  std::map<std::string, int> count;
  for (int i = 0; i < r.size(); ++i) {
    const std::string kind = KindOfRow(fx.ds, source[i]);
    worst[kind] = std::max(worst[kind], std::abs(r[i]));
    ++count[kind];
  }
  for (const char* kind : {"facet", "sphere", "scale_bar", "dbb", "ball3d"}) {
    EXPECT_GE(count[kind], 1) << kind;
    EXPECT_LT(worst[kind], 1e-9) << kind << " residual at the true values on "
                                 << fx.ds.machine().topology();
  }

  // At the nominal values (all zero) the errors show, for every type.
  std::map<std::string, double> nominal_worst;
  const Eigen::VectorXd r0 = PredictResiduals(fx.ds, {}, &source);
  for (int i = 0; i < r0.size(); ++i) {
    const std::string kind = KindOfRow(fx.ds, source[i]);
    nominal_worst[kind] = std::max(nominal_worst[kind], std::abs(r0[i]));
  }
  for (const char* kind : {"facet", "sphere", "scale_bar", "dbb", "ball3d"})
    EXPECT_GT(nominal_worst[kind], 1e-4) << kind << " residual at the nominal values";
  // Machine errors alone (setup at its nominal) also leave clear residuals
  // on the machine-dependent observations.
  const Eigen::VectorXd r1 =
      PredictResiduals(fx.ds, RealisticMachineErrors(fx.ds.machine(), seed), &source);
  double machine_only = 0;
  for (int i = 0; i < r1.size(); ++i)
    if (source[i] >= 0) machine_only = std::max(machine_only, std::abs(r1[i]));
  EXPECT_GT(machine_only, 1e-4);
}

TEST(ResidualValues, ZeroAtTrueValuesNonZeroAtNominalHU40T) { CheckZeroAtTruth(kHu40tJson, 41); }

TEST(ResidualValues, ZeroAtTrueValuesNonZeroAtNominalTiltingTable) {
  CheckZeroAtTruth(kTableJson, 42);
}

// The residual formulas of DESIGN.md, evaluated by hand from predicted tool
// points, on a hand-built dataset: pins down signs and which length the DBB
// reading and dbb.length add to.
TEST(ResidualValues, MatchTheDocumentedFormulas) {
  const Machine m = Machine::FromJson(kTableJson);
  const NamedValues errors = RealisticMachineErrors(m, 3);
  const NamedValues setup = RealisticSetup();
  const NamedValues all = Merge(errors, setup);
  const std::string ds_json =
      std::string("{\"machine\": ") + kTableJson + ", \"probe\": {\"tip_radius\": 3.0}, \"artefact\": " +
      kArtefactJson + R"(, "observations": [
   {"type": "facet", "target": "F2", "axes": {"X": 41, "Y": 2, "Z": -70, "A": -20, "C": 10, "S": 30},
    "direction": {"X": -1, "A": 1, "C": -1}},
   {"type": "sphere", "target": "S1", "axes": {"X": 95, "Y": 30, "Z": -20, "A": 15, "C": -40},
    "direction": {"Y": 1, "Z": -1, "A": -1}},
   {"type": "dbb", "axes": {"X": 110, "Y": -5, "Z": -30, "A": -10, "C": 60}, "reading": 0.0123,
    "length": 100, "tool_ball": [1, 2, 95], "table_ball": [60, -20, 40], "direction": {"C": 1}},
   {"type": "ball3d", "setup": "R1", "axes": {"X": 20, "Y": 40, "Z": -40, "A": 5, "C": 200},
    "measured": [0.01, -0.02, 0.03], "tool_ball": [0, 0, 100], "table_ball": [20, 50, 30],
    "direction": {"X": 1, "A": -1}},
   {"type": "sphere", "target": "S2", "axes": {"X": -80, "Y": -70, "Z": -50, "A": 0, "C": 0}}]})";
  const Dataset ds = Dataset::FromJson(ds_json);
  std::vector<int> source;
  const Eigen::VectorXd r = PredictResiduals(ds, all, &source);
  // facet, sphere, dbb, ball3d (3 rows), sphere, then the scale bar.
  ASSERT_EQ(r.size(), 1 + 1 + 1 + 3 + 1 + 1);
  EXPECT_EQ(source, (std::vector<int>{0, 1, 2, 3, 3, 3, 4, -1}));

  const Eigen::VectorXd theta = TableValues(ParameterTable(ds), all).head(m.num_parameters());
  auto point = [&](int i, const Eigen::Vector3d& tip) {
    Eigen::MatrixXd axes = ds.observations[i].axes.transpose();
    Eigen::MatrixXi dirs = ds.observations[i].direction.transpose();
    // ToolPoints uses the machine tip; shift it by moving the tip offsets.
    Eigen::VectorXd th = theta;
    th.segment<3>(m.tip_index()) = tip - m.tip();
    return Eigen::Vector3d(ToolPoints(m, th, axes, &dirs).row(0).transpose());
  };
  const Eigen::Vector3d tip = m.tip() + Eigen::Vector3d(all.at("tip.x"), all.at("tip.y"), all.at("tip.z"));
  const double rt = 3.0;
  // facet: n.(P - a) - r - facet.F2
  {
    const Eigen::Vector3d P = point(0, tip);
    EXPECT_NEAR(r[0], Eigen::Vector3d(1, 0, 0).dot(P - Eigen::Vector3d(35, 0, 25)) - rt - all.at("facet.F2"),
                1e-11);
  }
  // sphere: |P - (c + dc)| - (R + r + sphere.S1.r)
  {
    const Eigen::Vector3d P = point(1, tip);
    const Eigen::Vector3d c = Eigen::Vector3d(90, 60, 20) +
                              Eigen::Vector3d(all.at("sphere.S1.x"), all.at("sphere.S1.y"), all.at("sphere.S1.z"));
    EXPECT_NEAR(r[1], (P - c).norm() - (12.7 + rt + all.at("sphere.S1.r")), 1e-11);
  }
  // dbb: |P_ball - (table + dt)| - (length + dbb.length + reading)
  {
    const Eigen::Vector3d tb = Eigen::Vector3d(1, 2, 95) +
                               Eigen::Vector3d(all.at("dbb.tool.x"), all.at("dbb.tool.y"), all.at("dbb.tool.z"));
    const Eigen::Vector3d P = point(2, tb);
    const Eigen::Vector3d t = Eigen::Vector3d(60, -20, 40) +
                              Eigen::Vector3d(all.at("dbb.table.x"), all.at("dbb.table.y"), all.at("dbb.table.z"));
    EXPECT_NEAR(r[2], (P - t).norm() - (100 + all.at("dbb.length") + 0.0123), 1e-11);
  }
  // ball3d: P_ball - (table + dt) - measured
  {
    const Eigen::Vector3d tb = Eigen::Vector3d(0, 0, 100) +
                               Eigen::Vector3d(all.at("ball3d.R1.tool.x"), all.at("ball3d.R1.tool.y"),
                                               all.at("ball3d.R1.tool.z"));
    const Eigen::Vector3d P = point(3, tb);
    const Eigen::Vector3d t = Eigen::Vector3d(20, 50, 30) +
                              Eigen::Vector3d(all.at("ball3d.R1.table.x"), all.at("ball3d.R1.table.y"),
                                              all.at("ball3d.R1.table.z"));
    const Eigen::Vector3d e = P - t - Eigen::Vector3d(0.01, -0.02, 0.03);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(r[3 + c], e[c], 1e-11) << c;
  }
  // scale bar: |c1 + dc1 - c2 - dc2| - L
  {
    const Eigen::Vector3d c1 = Eigen::Vector3d(90, 60, 20) +
                               Eigen::Vector3d(all.at("sphere.S1.x"), all.at("sphere.S1.y"), all.at("sphere.S1.z"));
    const Eigen::Vector3d c2 = Eigen::Vector3d(-80, -70, 30) +
                               Eigen::Vector3d(all.at("sphere.S2.x"), all.at("sphere.S2.y"), all.at("sphere.S2.z"));
    EXPECT_NEAR(r[7], (c1 - c2).norm() - 214.0, 1e-11);
  }
  // A scale bar whose spheres were not both probed in this dataset adds no
  // row (problem.cc: it says nothing about the data).
  const Dataset without_s2 = ds.Subset({0, 1, 2, 3});
  const Eigen::VectorXd r2 = PredictResiduals(without_s2, all, &source);
  ASSERT_EQ(r2.size(), 6);
  EXPECT_EQ(std::count(source.begin(), source.end(), -1), 0);
  EXPECT_LT((r2 - r.head(6)).cwiseAbs().maxCoeff(), 1e-12);
}

// ---- 3. Identification end to end ---------------------------------------------

// Location errors of A and C that touch probing can separate from the
// default setup set. The others are confounded with the tip offsets
// tip.x|y|z, which the default setup estimates: on this machine the linear
// axes all sit on the tool side, so moving the first workpiece-side axis A
// (EY0A, EZ0A) moves the whole workpiece chain relative to the tool, and
// moving C along A's own direction (EX0C) is a shift along F x whatever A
// is; both are exactly a tool tip offset (Identify says so: see
// ConfoundedRequestThrows...).
const std::vector<std::string> kTableProbeLocation = {"EB0A", "EC0A", "EY0C", "EA0C", "EB0C"};
const std::vector<std::string> kTableLocation = {"EY0A", "EZ0A", "EB0A", "EC0A",
                                                 "EX0C", "EY0C", "EA0C", "EB0C"};

NamedValues TableLocationTruth() {
  return {{"EY0A", 0.021}, {"EZ0A", -0.013}, {"EB0A", 6e-5},  {"EC0A", -4e-5},
          {"EX0C", -0.017}, {"EY0C", 0.009}, {"EA0C", 8e-5}, {"EB0C", -3e-5}};
}

NamedValues Only(const NamedValues& v, const std::vector<std::string>& names) {
  NamedValues out;
  for (const std::string& n : names) out[n] = v.at(n);
  return out;
}

// Probing of the five facets and the two spheres at 4 x 4 indexations of A
// and C, both rotary directions; the scale bar joins the spheres.
std::vector<std::string> TableProbingPlan() {
  std::vector<std::string> plan;
  int i = 0;
  for (double a : {0.0, -30.0, -60.0, 20.0})
    for (double c : {0.0, 90.0, 180.0, 270.0}) {
      const std::string axes = "{\"A\": " + Num(a) + ", \"C\": " + Num(c) + "}";
      const std::string dir = "{\"A\": " + std::to_string(i % 2 ? 1 : -1) + ", \"C\": " +
                              std::to_string((i / 2) % 2 ? 1 : -1) + "}";
      ++i;
      for (const char* f : {"F1", "F2", "F3", "F4", "F5"}) plan.push_back(FacetTouch(f, axes, dir));
      for (const char* s : {"S1", "S2"})
        for (const Eigen::Vector3d& n : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0.2, 0.5),
                                         Eigen::Vector3d(-0.3, -1, 0.6)})
          plan.push_back(SphereTouch(s, axes, dir, n));
    }
  return plan;
}

TEST(ResidualIdentify, RecoversTableLocationErrorsFromNoiseFreeProbing) {
  const NamedValues truth = Merge(Only(TableLocationTruth(), kTableProbeLocation),
                                  {{"tip.x", 0.004}, {"tip.y", -0.006}, {"tip.z", 0.011}});
  const NamedValues setup = OnlySetupOf(RealisticSetup(), {"facet.", "sphere.S1.x", "sphere.S1.y",
                                                           "sphere.S1.z", "sphere.S2.x",
                                                           "sphere.S2.y", "sphere.S2.z"});
  const Dataset ds = Simulate(Spec(kTableJson, truth, setup, TableProbingPlan()));
  ASSERT_EQ(ds.artefact.scale_bars.size(), 1u);

  IdentifyOptions opt;
  opt.estimate = kTableProbeLocation;
  const Result res = Identify(ds, opt);
  EXPECT_TRUE(res.converged) << res.message;
  EXPECT_EQ(res.rank, res.n_parameters);
  EXPECT_LT(res.rms, 1e-9);
  auto value = [&](const std::string& n) {
    const auto it = std::find(res.names.begin(), res.names.end(), n);
    EXPECT_NE(it, res.names.end()) << n;
    return res.values[it - res.names.begin()];
  };
  for (const std::string& n : kTableProbeLocation) EXPECT_NEAR(value(n), truth.at(n), 1e-7) << n;
  for (const char* n : {"tip.x", "tip.y", "tip.z"}) EXPECT_NEAR(value(n), truth.at(n), 1e-7) << n;
  for (const auto& [n, v] : setup) EXPECT_NEAR(value(n), v, 1e-7) << n;
  // The default setup set was estimated along with the request: tip, 5
  // facets, 2 sphere centres.
  EXPECT_EQ(res.estimated.size(), kTableProbeLocation.size() + 3 + 5 + 6);
  for (const char* n : {"tip.x", "facet.F1", "facet.F5", "sphere.S1.x", "sphere.S2.z"})
    EXPECT_NE(std::find(res.estimated.begin(), res.estimated.end(), n), res.estimated.end()) << n;
}

// The confounding described above kTableProbeLocation: asking for EY0A,
// EZ0A and EX0C along with the tip offsets is refused, naming them.
TEST(ResidualIdentify, TablePivotPositionIsConfoundedWithTipOffsets) {
  const Dataset ds = Simulate(Spec(kTableJson, TableLocationTruth(), {}, TableProbingPlan()));
  IdentifyOptions opt;
  opt.estimate = kTableLocation;
  try {
    Identify(ds, opt);
    ADD_FAILURE() << "accepted";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("confounded"), std::string::npos) << msg;
    for (const char* n : {"EY0A", "EZ0A", "EX0C", "tip.x", "tip.y", "tip.z"})
      EXPECT_NE(msg.find(n), std::string::npos) << n << " not named in: " << msg;
  }
  // With the tip offsets fixed at their (here nominal) values the pivot
  // positions are identifiable, and recovered.
  opt.fix = {"tip.x", "tip.y", "tip.z"};
  const Result res = Identify(ds, opt);
  EXPECT_EQ(res.rank, res.n_parameters);
  for (const std::string& n : kTableLocation) {
    const auto it = std::find(res.names.begin(), res.names.end(), n);
    ASSERT_NE(it, res.names.end());
    EXPECT_NEAR(res.values[it - res.names.begin()], TableLocationTruth().at(n), 1e-7) << n;
  }
}

// DBB samples around three circles of the tilting table, the table ball
// 80 mm off the C axis: C alone with the bar radial on the table, then A and
// C moving together (Wang et al. 2013) with the bar tangential on the table,
// and with the bar vertical in the machine frame.
std::vector<std::string> TableDbbPlan(const Machine& m) {
  const Eigen::Vector3d table_ball(80, 0, 30);
  const double L = 100;
  std::vector<std::string> plan;
  const double deg = kPi / 180;
  for (int circle = 0; circle < 3; ++circle)
    for (int k = 0; k < 24; ++k) {
      const double c = 15.0 * k;
      double a = 0;
      Eigen::Vector3d bar_w;  // bar direction in the workpiece frame
      if (circle == 0) {
        bar_w = Eigen::Vector3d(1, 0, 0);
      } else if (circle == 1) {
        a = -15 - 15 * std::cos(c * deg);
        bar_w = Eigen::Vector3d(0, 1, 0);
      } else {
        a = -20 + 20 * std::sin(c * deg);
        // +Z of F seen from the workpiece: R_fw^T e_z with nominal R_fw = Rx(a) Rz(c).
        const double ca = std::cos(a * deg), sa = std::sin(a * deg);
        const double cc = std::cos(c * deg), sc = std::sin(c * deg);
        const Eigen::Vector3d v(0, sa, ca);  // Rx(-a) e_z
        bar_w = Eigen::Vector3d(cc * v.x() + sc * v.y(), -sc * v.x() + cc * v.y(), v.z());
      }
      const std::string dir = "{\"C\": 1, \"A\": " + std::to_string(k < 12 ? -1 : 1) + "}";
      plan.push_back(BallSample(m, "dbb", "", {{'A', a}, {'C', c}}, table_ball, L * bar_w, dir));
    }
  return plan;
}

TEST(ResidualIdentify, RecoversTableLocationErrorsFromNoiseFreeDbbCircles) {
  const Machine m = Machine::FromJson(kTableJson);
  const NamedValues truth = TableLocationTruth();
  const NamedValues setup = {{"dbb.length", 0.0042}};
  const Dataset ds = Simulate(Spec(kTableJson, truth, setup, TableDbbPlan(m)));
  // The bar length is what the simulated machine reads.
  for (const Observation& o : ds.observations) EXPECT_LT(std::abs(o.data<BallMountData>().reading), 0.1);

  IdentifyOptions opt;
  opt.estimate = kTableLocation;
  // Exact recovery from noise-free data: the bar length (4.2 um off) taken
  // without its placement prior (2 um), which would pull it by design.
  opt.setup_priors = false;
  const Result res = Identify(ds, opt);
  EXPECT_TRUE(res.converged) << res.message;
  EXPECT_EQ(res.rank, res.n_parameters);
  EXPECT_LT(res.rms, 1e-9);
  auto value = [&](const std::string& n) {
    const auto it = std::find(res.names.begin(), res.names.end(), n);
    EXPECT_NE(it, res.names.end()) << n;
    return res.values[it - res.names.begin()];
  };
  for (const std::string& n : kTableLocation) EXPECT_NEAR(value(n), truth.at(n), 1e-7) << n;
  EXPECT_NEAR(value("dbb.length"), 0.0042, 1e-7);
  ASSERT_EQ(res.estimated.size(), kTableLocation.size() + 1);  // + dbb.length by default
}

// EZ0C (C about Z, positioned along its own direction) is the same as moving
// every feature of the workpiece along Z, which the default setup set (facet
// offsets, sphere centres) already does: the request must be refused,
// naming the parameter.
void ExpectConfounded(const char* machine_json, const std::vector<std::string>& estimate,
                      const std::string& culprit, const std::vector<std::string>& plan) {
  const Dataset ds = Simulate(Spec(machine_json, {}, {}, plan));
  IdentifyOptions opt;
  opt.estimate = estimate;
  try {
    Identify(ds, opt);
    ADD_FAILURE() << "Identify accepted the confounded request " << culprit;
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("confounded"), std::string::npos) << msg;
    EXPECT_NE(msg.find(culprit), std::string::npos) << msg;
  }
  // The same request with allow_unidentifiable names the group in the result.
  opt.allow_unidentifiable = true;
  const Result res = Identify(ds, opt);
  EXPECT_LT(res.rank, res.n_parameters);
  bool named = false;
  for (const auto& g : res.unidentifiable)
    named = named || std::find(g.begin(), g.end(), culprit) != g.end();
  EXPECT_TRUE(named) << culprit << " not in any unidentifiable group";
}

TEST(ResidualIdentify, ConfoundedRequestThrowsNamingTheParameterTiltingTable) {
  std::vector<std::string> est = kTableProbeLocation;
  est.push_back("EZ0C");
  ExpectConfounded(kTableJson, est, "EZ0C", TableProbingPlan());
}

TEST(ResidualIdentify, ConfoundedRequestThrowsNamingTheParameterHU40T) {
  const Machine m = Machine::FromJson(kHu40tJson);
  std::vector<std::string> plan;
  for (double b : {0.0, 30.0, -45.0})
    for (double c : {0.0, 90.0, 180.0, 270.0}) {
      const std::string axes = "{\"B\": " + Num(b) + ", \"C\": " + Num(c) + "}";
      for (const char* f : {"F1", "F2", "F3"}) plan.push_back(FacetTouch(f, axes, ""));
      plan.push_back(SphereTouch("S1", axes, "", Eigen::Vector3d(0, 0, 1)));
      plan.push_back(SphereTouch("S1", axes, "", Eigen::Vector3d(1, 0, 0.5)));
    }
  ExpectConfounded(kHu40tJson, {"EX0C", "EA0C", "EB0C", "EZ0C"}, "EZ0C", plan);
}

// A TANGO-like artefact: eight 45-degree chamfer facets around a top facet
// and two spheres. EZ0C is confounded with every facet whose normal has a Z
// component and with every sphere's z, a group of 12 here. The message must
// still name EZ0C, the parameter the user asked for and should drop.
//
// (Regression: identify.cc GroupText() shows the first 8 names of a group;
// before d209170 the default setup parameters came first and the requested
// EZ0C was cut off: "confounded: {facet.TOP, facet.T0, ..., facet.T6, ...
// (4 more)}".)
TEST(ResidualIdentify, ConfoundedMessageNamesTheRequestedParameterOnALargeArtefact) {
  std::string artefact = "{\"facets\": [{\"id\": \"TOP\", \"point\": [0,0,60], \"normal\": [0,0,1]}";
  const double deg = kPi / 180;
  for (int i = 0; i < 8; ++i) {
    const double phi = 45.0 * i * deg, s45 = std::sqrt(0.5);
    const Eigen::Vector3d n(std::cos(phi) * s45, std::sin(phi) * s45, s45);
    artefact += ", {\"id\": \"T" + std::to_string(i) + "\", \"point\": " +
                Vec(Eigen::Vector3d(45 * std::cos(phi), 45 * std::sin(phi), 40)) +
                ", \"normal\": " + Vec(n) + "}";
  }
  artefact += R"(], "spheres": [{"id": "S1", "center": [90,60,20], "radius": 12.7},
                                {"id": "S2", "center": [-80,-70,30], "radius": 12.7}]})";
  std::vector<std::string> plan;
  for (double a : {0.0, -30.0, 20.0})
    for (double c : {0.0, 90.0, 180.0, 270.0}) {
      const std::string axes = "{\"A\": " + Num(a) + ", \"C\": " + Num(c) + "}";
      plan.push_back(FacetTouch("TOP", axes, ""));
      for (int i = 0; i < 8; ++i) plan.push_back(FacetTouch("T" + std::to_string(i), axes, ""));
      for (const char* sph : {"S1", "S2"})
        for (const Eigen::Vector3d& n : {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0.2, 0.5),
                                         Eigen::Vector3d(-0.3, -1, 0.6)})
          plan.push_back(SphereTouch(sph, axes, "", n));
    }
  const Dataset ds = Simulate(Spec(kTableJson, {}, {}, plan, 0.0, artefact));
  IdentifyOptions opt;
  opt.estimate = kTableProbeLocation;
  // Without EZ0C the request is fine.
  EXPECT_NO_THROW(Identify(ds, opt));
  opt.estimate.push_back("EZ0C");
  try {
    Identify(ds, opt);
    ADD_FAILURE() << "Identify accepted the confounded request EZ0C";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("confounded"), std::string::npos) << msg;
    EXPECT_NE(msg.find("EZ0C"), std::string::npos)
        << "the requested parameter is not named: " << msg;
  }
}

}  // namespace
}  // namespace fivecal
