// The test-only kind of stylus3d.cc through what every kind goes through:
// registration, load and save, its Jacobian against finite differences,
// simulate, identify (truth within 4 sigma over repeated noisy simulations)
// and the report pieces of the result. Nothing outside tests/cpp/kind_plugin
// names the kind. Its own executable (fivecal_kind_plugin_tests): registered
// in fivecal_tests it would be one more kind the per-kind tables there do not
// list.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/problem.h"
#include "stylus3d.h"

namespace fivecal {
namespace {

using nlohmann::json;

// ---- step 5: test it ------------------------------------------------------------------------------------
// C600U-like: A about -X, C about -Z on the table.
const char* kMachine = R"({"name": "c600u", "topology": "wCAfXYZSt", "axes": {
  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
  "A": {"type": "rotary", "direction": [-1, 0, 0], "point": [0, 0, 0]},
  "X": {"type": "linear", "direction": [1, 0, 0]}, "Y": {"type": "linear", "direction": [0, 1, 0]},
  "Z": {"type": "linear", "direction": [0, 0, 1]},
  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}}, "tool": {"tip": [0, 0, 150]}})";

// Poses over A and C, two mountings; the truth: location errors of A and C
// and the stylus offsets.
json Spec(double sigma, int seed) {
  json plan = json::array();
  for (int a : {-60, -30, 0, 30})
    for (int c = 0; c < 360; c += 45)
      plan.push_back({{"type", "stylus3d"}, {"setup", (c / 45) % 2 ? "M1" : "M2"},
                      {"axes", {{"A", a}, {"C", c}, {"X", 50 + c / 10.0}, {"Y", -20}, {"Z", 10 - a / 3.0}}}});
  return {{"machine", json::parse(kMachine)},
          {"plan", plan},
          {"errors", {{"EY0C", 0.02}, {"EZ0C", -0.01}, {"EB0C", 4e-5}, {"EXX1", 2e-5}}},
          {"setup", {{"stylus3d.M1.x", 0.03}, {"stylus3d.M1.z", -0.05}, {"stylus3d.M2.y", 0.02}}},
          {"sigma", {{"stylus3d", sigma}}},
          {"seed", seed}};
}

// A tool-side offset is a translation of the tool point in F: errors that
// act as one (A's position, C's along A's axis) are confounded with the
// stylus offsets, so the fit estimates those that are not.
const std::vector<std::string> kEstimate = {"EY0C", "EZ0C", "EB0C", "EXX1"};

TEST(KindPlugin, RegistersFromItsOwnFile) {
  EXPECT_TRUE(kStylus3dRegistered);
  ASSERT_EQ(FindKind("stylus3d"), &TheStylus3dKind());
  EXPECT_EQ(&KindOf(TheStylus3dKind().type()), &TheStylus3dKind());
  EXPECT_NE(KindList().find("stylus3d"), std::string::npos);
  const std::vector<std::string> classes = NoiseClasses();
  EXPECT_NE(std::find(classes.begin(), classes.end(), "stylus3d"), classes.end());
  EXPECT_TRUE(IsSetupParameterName("stylus3d.M1.x"));
  EXPECT_FALSE(IsSetupParameterName("stylus3d.M1.w"));
  // Registering again is a no-op; a second kind of the name or type code is refused.
  EXPECT_FALSE(RegisterObservationKind(TheStylus3dKind()));
  const auto same_name = MakeStylus3dKind(UnusedObservationType());
  EXPECT_THROW(RegisterObservationKind(*same_name), std::invalid_argument);
}

TEST(KindPlugin, LoadsAndSavesThroughTheDatasetFile) {
  const Dataset ds = Simulate(Spec(0.0, 1).dump());
  ASSERT_EQ(ds.observations.size(), 32u);
  const std::string saved = ds.ToJson();
  const json j = json::parse(saved);
  EXPECT_EQ(j["observations"][0]["type"], "stylus3d");
  const Dataset back = Dataset::FromJson(saved);
  EXPECT_EQ(back.ToJson(), saved);
  // The loader's own checks apply to it: an unknown key, a missing field.
  json bad = j;
  bad["observations"][2]["reading"] = 1;
  try {
    Dataset::FromJson(bad.dump());
    ADD_FAILURE() << "unknown key accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("dataset.observations[2]: unknown key \"reading\""), std::string::npos)
        << e.what();
  }
  bad = j;
  bad["observations"][3].erase("measured");
  try {
    Dataset::FromJson(bad.dump());
    ADD_FAILURE() << "missing measured accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("dataset.observations[3].measured"), std::string::npos) << e.what();
  }
}

TEST(KindPlugin, JacobianMatchesFiniteDifferences) {
  const Dataset ds = Simulate(Spec(0.0, 1).dump());
  const ParameterTable table(ds);
  ASSERT_EQ(table.size(), table.num_machine() + 6);  // M1 and M2: x y z each
  std::vector<int> all(table.size());
  for (int i = 0; i < table.size(); ++i) all[i] = i;
  // Every parameter at a random plausible size (an error motion of degree d
  // over a travel of 300 mm or 3 rad).
  const Machine& m = ds.machine();
  Eigen::VectorXd values(table.size()), size(table.size());
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < table.size(); ++i) {
    double s = 1e-3;
    if (i < m.num_parameters()) {
      const ParameterInfo& p = m.parameters()[i];
      const double range = p.axis >= 0 && m.axis(p.axis).rotary() ? 3.0 : 300.0;
      s = (p.angular() ? 1e-5 : 1e-3) / (p.kind == ParameterKind::kMotion ? std::pow(range, p.degree) : 1.0);
    }
    size[i] = s;
    values[i] = s * n(rng);
  }
  Problem jet(ds, table, values, all, "", 0.0, false);
  Eigen::VectorXd r0;
  Eigen::MatrixXd J;
  jet.Evaluate(&r0, &J);
  ASSERT_EQ(r0.size(), 3 * 32);
  int setup_columns = 0;
  for (int c = 0; c < table.size(); ++c) {
    const double scale = J.col(c).cwiseAbs().maxCoeff();
    if (c >= table.num_machine() && scale > 0) ++setup_columns;
    // a step moving the rows by about 1e-4 mm and at most a tenth of the
    // parameter's size, so that the curvature does not show
    const double h = scale > 0 ? std::min(1e-4 / scale, 0.1 * size[c]) : 0.1 * size[c];
    Eigen::VectorXd vp = values, vm = values;
    vp[c] += h;
    vm[c] -= h;
    Problem pp(ds, table, vp, all, "", 0.0, false), pm(ds, table, vm, all, "", 0.0, false);
    Eigen::VectorXd rp, rm;
    pp.Evaluate(&rp, nullptr);
    pm.Evaluate(&rm, nullptr);
    const Eigen::VectorXd fd = (rp - rm) / (2 * h);
    for (int r = 0; r < J.rows(); ++r)
      ASSERT_NEAR(fd[r], J(r, c), 1e-5 * scale + 1e-7 + 1e-13 / h) << table.names()[c] << " row " << r;
  }
  EXPECT_EQ(setup_columns, 6);  // every offset enters the residual
}

TEST(KindPlugin, IdentifyRecoversTheTruthAndReportsItsRows) {
  // Repeated noisy simulations: each estimate within 4 sigma of the truth,
  // and the sigmas cover (about 95 % within 2 sigma).
  const json truth = Spec(0.0, 1)["errors"];
  int inside = 0, total = 0;
  for (int seed = 1; seed <= 12; ++seed) {
    const Dataset ds = Simulate(Spec(0.002, seed).dump());
    IdentifyOptions o;
    o.estimate = kEstimate;
    const Result r = Identify(ds, o);
    ASSERT_TRUE(r.converged) << r.message;
    for (size_t k = 0; k < r.estimated.size(); ++k) {
      const std::string& name = r.estimated[k];
      const auto at = std::find(r.names.begin(), r.names.end(), name) - r.names.begin();
      const double want = truth.contains(name) ? truth[name].get<double>()
                          : name == "stylus3d.M1.x" ? 0.03 : name == "stylus3d.M1.z" ? -0.05
                          : name == "stylus3d.M2.y" ? 0.02 : 0.0;
      const double z = (r.values[at] - want) / r.std[k];
      EXPECT_LT(std::abs(z), 4.0) << name << " seed " << seed << ": " << r.values[at] << " vs " << want;
      inside += std::abs(z) < 2.0;
      ++total;
    }
    // The default setup brought the kind's offsets into the fit.
    EXPECT_NE(std::find(r.estimated.begin(), r.estimated.end(), "stylus3d.M1.x"), r.estimated.end());
    // The report pieces: one residual vector and point per observation,
    // the residual rows in the kind's unit; the result document names them.
    ASSERT_EQ(r.residual_vectors.rows(), 32);
    ASSERT_EQ(r.residuals.size(), 96);
    EXPECT_NEAR(r.residual_vectors(5, 1), r.residuals[16], 1e-12);
    EXPECT_NE(r.ToJson().find("stylus3d.M2.y"), std::string::npos);
    if (seed == 1) {
      EXPECT_GT(r.chi2_p, 1e-3) << "the fit at the truth's noise is adequate";
    }
  }
  EXPECT_GE(inside, 0.85 * total) << inside << " of " << total << " within 2 sigma";
}

}  // namespace
}  // namespace fivecal
