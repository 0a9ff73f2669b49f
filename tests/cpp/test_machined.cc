// The machined-feature kind (observations/machined.h): its file messages,
// which features bring the part's datum into the default setup, and the
// step of one face cut at two poses against Zhang & Zhang's eq. (6). The
// checks every kind gets (derivatives, truth, round trip) are in
// test_observation_kinds.cc.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

using nlohmann::json;

// C600U-like: A about -X, C about -Z on the table (examples/machines/c600u.json).
const char* kMachine = R"({"name": "c600u", "topology": "wCAfXYZSt", "axes": {
  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
  "A": {"type": "rotary", "direction": [-1, 0, 0], "point": [0, 0, 0]},
  "X": {"type": "linear", "direction": [1, 0, 0]}, "Y": {"type": "linear", "direction": [0, 1, 0]},
  "Z": {"type": "linear", "direction": [0, 0, 1]},
  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}}, "tool": {"tip": [0, 0, 150]}})";

json Spec(const json& plan, const json& errors = json::object(), const json& setup = json::object()) {
  return {{"machine", json::parse(kMachine)}, {"plan", plan}, {"errors", errors}, {"setup", setup}};
}

// Zhang & Zhang's test 1 (sensitive direction -Y_F, alpha = 90 deg, gamma =
// 180 minus 0): on this machine A = -90, C = -180 and 0. The face cut is
// the part's top (+Z of the part) both times, at W = (0, L, H).
json Test1(double L, double H) {
  return {{"type", "machined"}, {"part", "P1"}, {"feature", "step"}, {"axes", {{"A", -90}, {"C", -180}}},
          {"point", {0, L, H}}, {"normal", {0, 0, 1}}, {"reference_axes", {{"A", -90}, {"C", 0}}}};
}

std::string Message(const json& spec) {
  try {
    Simulate(spec.dump());
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(accepted)";
}

std::string LoadMessage(const json& ds) {
  try {
    Dataset::FromJson(ds.dump());
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(accepted)";
}

TEST(MachinedKind, StepOfOneFaceAtTwoTablePositionsIsThePapersEquation6) {
  // h = -2 A_xi_x (C_delta_y + L) + 2 A_xi_y C_delta_x (eq. 6) is the
  // paper's Y2 - Y1 of the workpiece, i.e. minus the face's step; EA0C is
  // A_xi_x (C located relative to A). The paper's C_delta products are a
  // material point's lever arm; the programme cuts where the tool is sent
  // (W, whatever the part's datum), so the step is -2 A_xi_x L and the
  // datum drops out of it altogether (here 2 mm off in y, turned 1 mrad).
  const double L = 150, H = 60, xi = 4e-5;
  const Dataset ds = Simulate(Spec(json::array({Test1(L, H)}), {{"EA0C", xi}}).dump());
  const double h = -2 * xi * L;
  EXPECT_NEAR(-ds.observations[0].data<MachinedData>().measured, h, 1e-3 * std::abs(h));
  const Dataset off = Simulate(
      Spec(json::array({Test1(L, H)}), {{"EA0C", xi}}, {{"machined.P1.y", 2.0}, {"machined.P1.c", 1e-3}}).dump());
  EXPECT_NEAR(off.observations[0].data<MachinedData>().measured, ds.observations[0].data<MachinedData>().measured, 1e-12);
  // The plan's programme put the nominal tool on the point: the commands of
  // the two cuts differ only where the table turned the point.
  EXPECT_NEAR(ds.observations[0].axes[ds.machine().AxisIndex('Y')], -H, 1e-9);
}

TEST(MachinedKind, DatumIsDefaultSetupWhenAFeatureSeesIt) {
  json face = Test1(150, 60);
  face["feature"] = "face";
  face.erase("reference_axes");
  json tilted = Test1(150, 60);
  tilted["reference_normal"] = {0, -1, 0};
  json other = Test1(150, 60);
  other["part"] = "P2";
  for (const auto& [plan, expect] : std::vector<std::pair<json, std::set<std::string>>>{
           {json::array({Test1(150, 60)}), {}},
           {json::array({face}), {"P1"}},
           {json::array({tilted}), {"P1"}},
           {json::array({other, face}), {"P1"}}}) {
    const Dataset ds = Simulate(Spec(plan).dump());
    const ParameterTable t(ds);
    std::set<int> setup;
    for (const Observation& o : ds.observations) KindOf(o).DefaultSetup(ds, t, o, &setup);
    std::set<std::string> parts;
    for (int i : setup) {
      const std::string& n = t.names()[i];
      ASSERT_EQ(n.rfind("machined.", 0), 0u) << n;
      parts.insert(n.substr(9, n.find('.', 9) - 9));
    }
    EXPECT_EQ(parts, expect) << plan.dump();
    EXPECT_EQ(setup.size(), 6 * expect.size());
  }
}

TEST(MachinedKind, BadFieldsAreNamed) {
  auto with = [](const char* key, const json& value) {
    json e = Test1(150, 60);
    if (value.is_null()) e.erase(key);
    else e[key] = value;
    return Message(Spec(json::array({e})));
  };
  EXPECT_NE(with("part", nullptr).find("simulate.plan[0].part: missing"), std::string::npos);
  EXPECT_NE(with("part", "P.1").find("simulate.plan[0].part: 'P.1' must be a non-empty name without '.'"),
            std::string::npos);
  EXPECT_NE(with("feature", "stp").find("simulate.plan[0].feature: 'stp' is neither \"face\" nor \"step\""),
            std::string::npos);
  EXPECT_NE(with("feature", "stp").find("step"), std::string::npos);
  EXPECT_NE(with("normal", {0, 0, 0}).find("simulate.plan[0].normal: zero vector"), std::string::npos);
  EXPECT_NE(with("normal", {0, 1}).find("simulate.plan[0].normal"), std::string::npos);
  EXPECT_NE(with("point", nullptr).find("simulate.plan[0].point"), std::string::npos);
  EXPECT_NE(with("reference_axes", nullptr).find("simulate.plan[0].reference_axes: missing"), std::string::npos);
  EXPECT_NE(with("reference_axes", {{"A", -90}}).find("simulate.plan[0].reference_axes: missing axis 'C'"),
            std::string::npos);
  EXPECT_NE(with("reference_axes", {{"A", -90}, {"C", 0}, {"Q", 1}}).find("simulate.plan[0].reference_axes"),
            std::string::npos);
  EXPECT_NE(with("measured", 0.1).find("simulate.plan[0]: unknown key \"measured\""), std::string::npos);
  json face = Test1(150, 60);
  face["feature"] = "face";
  EXPECT_NE(Message(Spec(json::array({face}))).find("simulate.plan[0].reference_axes: only a step"),
            std::string::npos);

  // A dataset: every axis of both cuts, and a measured value.
  const Dataset ds = Simulate(Spec(json::array({Test1(150, 60)}), {{"EA0C", 2e-5}}).dump());
  const json good = json::parse(ds.ToJson());
  EXPECT_EQ(LoadMessage(good), "(accepted)");
  json bad = good;
  bad["observations"][0]["reference_axes"].erase("X");
  EXPECT_NE(LoadMessage(bad).find("dataset.observations[0].reference_axes: missing axis 'X'"), std::string::npos)
      << LoadMessage(bad);
  bad = good;
  bad["observations"][0].erase("measured");
  EXPECT_NE(LoadMessage(bad).find("dataset.observations[0].measured: missing"), std::string::npos) << LoadMessage(bad);
  bad = good;
  bad["observations"][0]["measured"] = 1e6;
  EXPECT_NE(LoadMessage(bad).find("dataset.observations[0].measured"), std::string::npos) << LoadMessage(bad);
  // A step written back carries its reference cut by axis letter.
  EXPECT_EQ(good["observations"][0]["reference_axes"]["C"], 0.0);
  EXPECT_EQ(good["observations"][0]["part"], "P1");
  EXPECT_FALSE(good["observations"][0].contains("setup"));
}

TEST(MachinedKind, NoiseClassIsItsOwn) {
  json spec = Spec(json::array({Test1(150, 60), Test1(150, 60)}));
  spec["sigma"] = {{"machined", 0.002}};
  spec["seed"] = 5;
  const SimulationPlan plan = BuildSimulationPlan(spec.dump());
  ASSERT_EQ(plan.num_inputs(), 2);
  EXPECT_EQ(plan.input_sigma[0], 0.002);
  EXPECT_EQ(plan.sensitivity[0], -1.0);
  const Dataset a = AddNoise(plan, 5), b = Simulate(spec.dump());
  EXPECT_EQ(a.observations[1].data<MachinedData>().measured, b.observations[1].data<MachinedData>().measured);
  EXPECT_NE(a.observations[0].data<MachinedData>().measured, a.observations[1].data<MachinedData>().measured);
  spec["sigma"] = {{"probe", 0.002}};
  EXPECT_EQ(BuildSimulationPlan(spec.dump()).input_sigma[0], 0.0);
}

}  // namespace
}  // namespace fivecal
