// Loader boundary tests: what the machine, dataset and simulation parsers
// accept, keep and refuse. Every refusal must be a std::invalid_argument that
// names the field (an embedder sees these messages, not a Python layer).
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <optional>
#include <cmath>
#include <functional>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/observations/dataset_reader.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/machine.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

using nlohmann::json;

void ExpectInvalid(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
    ADD_FAILURE() << "expected std::invalid_argument, nothing was thrown";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const std::string& n : needles)
      EXPECT_NE(what.find(n), std::string::npos)
          << "message '" << what << "' does not mention '" << n << "'";
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected std::invalid_argument, got another exception type: " << e.what();
  }
}

json Hu40t() {
  return json::parse(R"({"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})");
}

// At the zero pose the tool ball sits at its nominal place: a 100 mm bar to
// (0,0,100) reads about 0, a 3D ball at the origin is displaced by the errors.
json ZeroAxes() { return {{"X", 0.0}, {"Y", 0.0}, {"Z", 0.0}, {"B", 0.0}, {"C", 0.0}, {"S", 0.0}}; }

json Axes() { return {{"X", 10.0}, {"Y", 20.0}, {"Z", -5.0}, {"B", 30.0}, {"C", 0.0}, {"S", 0.0}}; }

// A small valid dataset: one facet touch, one sphere touch, one DBB sample and
// one ball3d sample, a scale bar between two spheres.
json SmallDataset() {
  json d;
  d["machine"] = Hu40t();
  d["probe"] = {{"tip_radius", 3.0}};
  d["artefact"] = {
      {"facets", {{{"id", "F1"}, {"point", {0, 0, 10}}, {"normal", {0, 0, 1}}}}},
      {"spheres", {{{"id", "S1"}, {"center", {0, 0, 50}}, {"radius", 12.7}},
                   {{"id", "S2"}, {"center", {100, 0, 50}}, {"radius", 12.7}}}},
      {"scale_bars", {{{"spheres", {"S1", "S2"}}, {"length", 100.0}}}}};
  d["observations"] = {
      {{"type", "facet"}, {"target", "F1"}, {"axes", Axes()}, {"direction", {{"X", 1}, {"Y", -1}}}},
      {{"type", "sphere"}, {"target", "S1"}, {"axes", Axes()}},
      {{"type", "dbb"}, {"setup", "A1"}, {"axes", Axes()}, {"reading", 0.001}, {"length", 100.0},
       {"tool_ball", {0, 0, 0}}, {"table_ball", {0, 0, 100}}},
      {{"type", "ball3d"}, {"setup", "R1"}, {"axes", Axes()}, {"measured", {0.001, 0.0, -0.002}},
       {"tool_ball", {0, 0, 0}}, {"table_ball", {0, 0, 100}}}};
  return d;
}

Dataset Load(const json& d) { return Dataset::FromJson(d.dump()); }

// ---- Observation sigma and id, machine priors (kept and refused) -----------

TEST(LoaderFields, ObservationSigmaNumberAndArrayAreReadAndKept) {
  json d = SmallDataset();
  d["observations"][0]["sigma"] = 0.002;
  d["observations"][2]["sigma"] = json::array({0.0004});
  d["observations"][3]["sigma"] = {0.001, 0.002, 0.003};
  const Dataset ds = Load(d);
  ASSERT_EQ(ds.observations[0].sigma.size(), 1);
  EXPECT_EQ(ds.observations[0].sigma[0], 0.002);
  EXPECT_EQ(ds.observations[1].sigma.size(), 0);  // the kind's default applies
  EXPECT_EQ(ds.observations[2].sigma[0], 0.0004);
  ASSERT_EQ(ds.observations[3].sigma.size(), 3);
  EXPECT_EQ(ds.observations[3].sigma[2], 0.003);
  // A single number on a ball3d observation applies to its three rows.
  d["observations"][3]["sigma"] = 0.005;
  EXPECT_EQ(Load(d).observations[3].sigma, Eigen::Vector3d::Constant(0.005));

  // Round trip through ToJson, and through Subset.
  d["observations"][3]["sigma"] = {0.001, 0.002, 0.003};
  const Dataset again = Dataset::FromJson(Load(d).ToJson());
  EXPECT_EQ(again.observations[0].sigma, ds.observations[0].sigma);
  EXPECT_EQ(again.observations[1].sigma.size(), 0);
  EXPECT_EQ(again.observations[3].sigma, ds.observations[3].sigma);
  const Dataset sub = ds.Subset({3, 0});
  EXPECT_EQ(sub.observations[0].sigma, ds.observations[3].sigma);
  EXPECT_EQ(sub.observations[1].sigma, ds.observations[0].sigma);
}

TEST(LoaderFields, BadSigmaIsRefusedNamingTheObservation) {
  for (const json& bad : {json(0.0), json(-1e-3), json("0.001"), json::array({0.001, 0.001}),
                          json::array({0.001, -1.0, 0.001}), json(nullptr)}) {
    json d = SmallDataset();
    d["observations"][bad.is_array() && bad.size() == 3 ? 3 : 2]["sigma"] = bad;
    ExpectInvalid([&] { Load(d); }, {"observations[", "].sigma"});
  }
  json d = SmallDataset();
  d["observations"][1]["sigma"] = {0.001, 0.001, 0.001};  // a sphere touch has one row
  ExpectInvalid([&] { Load(d); }, {"observations[1].sigma", "1 value"});
}

TEST(LoaderFields, ObservationIdIsKeptThroughLoadAndSave) {
  json d = SmallDataset();
  d["observations"][1]["id"] = "touch-7 (S1, B=30)";
  const Dataset again = Dataset::FromJson(Load(d).ToJson());
  EXPECT_EQ(again.observations[1].id, "touch-7 (S1, B=30)");
  EXPECT_EQ(again.observations[0].id, "");
  EXPECT_EQ(Load(d).Subset({1}).observations[0].id, "touch-7 (S1, B=30)");
  d["observations"][1]["id"] = 7;
  ExpectInvalid([&] { Load(d); }, {"observations[1].id"});
}

TEST(LoaderFields, DefaultSigmaPerKind) {
  EXPECT_EQ(DefaultSigma(ObservationType::kFacet), 0.001);
  EXPECT_EQ(DefaultSigma(ObservationType::kSphere), 0.001);
  EXPECT_EQ(DefaultSigma(ObservationType::kDbb), 0.0005);
  EXPECT_EQ(DefaultSigma(ObservationType::kBall3d), 0.001);
}

TEST(LoaderFields, BallSamplesCarryTheirSigma) {
  Dataset ds(Machine::FromJson(Hu40t().dump()));
  Eigen::MatrixXd axes = Eigen::MatrixXd::Zero(2, 6);
  ds.AppendBallSamples(ObservationType::kBall3d, "R1", axes, nullptr, Eigen::Vector3d::Zero(),
                       Eigen::Vector3d(0, 0, 100), 0.0, Eigen::MatrixXd::Zero(2, 3), 0.002);
  ds.AppendBallSamples(ObservationType::kDbb, "A1", axes, nullptr, Eigen::Vector3d::Zero(),
                       Eigen::Vector3d(0, 0, 100), 100.0, Eigen::MatrixXd::Zero(2, 1));
  // Array samples are column blocks (dataset.h TraceBlock), read by row.
  ASSERT_EQ(ds.size(), 4u);
  EXPECT_TRUE(ds.observations.empty());
  Observation row;
  EXPECT_EQ(ds.Row(1, &row).sigma, Eigen::Vector3d::Constant(0.002));
  EXPECT_EQ(ds.Row(2, &row).sigma.size(), 0);
  ExpectInvalid([&] {
    ds.AppendBallSamples(ObservationType::kDbb, "A1", axes, nullptr, Eigen::Vector3d::Zero(),
                         Eigen::Vector3d(0, 0, 100), 100.0, Eigen::MatrixXd::Zero(2, 1), -1.0);
  }, {"sigma"});
}

TEST(LoaderFields, MachinePriorsAreReadKeptAndChecked) {
  json mj = Hu40t();
  mj["priors"] = {{"EX0C", 0.05}, {"class:location_angle", 1e-4}};
  const Machine m = Machine::FromJson(mj.dump());
  ASSERT_EQ(m.priors.size(), 2u);
  EXPECT_EQ(m.priors.at("EX0C"), 0.05);
  EXPECT_EQ(m.priors.at("class:location_angle"), 1e-4);
  EXPECT_EQ(Machine::FromJson(m.ToJson()).priors, m.priors);
  // Through a dataset too.
  json d = SmallDataset();
  d["machine"] = mj;
  EXPECT_EQ(Dataset::FromJson(Load(d).ToJson()).machine().priors, m.priors);

  for (const json& bad : {json(0.0), json(-1.0), json("0.05"), json(nullptr)}) {
    mj["priors"] = {{"EX0C", bad}};
    ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.priors.EX0C"});
  }
  mj["priors"] = {{"EX0Q", 0.05}};
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.priors.EX0Q", "unknown parameter"});
  mj["priors"] = {{"class:", 0.05}};
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.priors.class:"});
  mj["priors"] = json::array({0.05});
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.priors"});
}

json SimSpec() {
  json d = SmallDataset();
  json spec;
  spec["machine"] = d["machine"];
  spec["probe"] = d["probe"];
  spec["artefact"] = d["artefact"];
  spec["errors"] = {{"EX0C", 0.01}};
  spec["plan"] = {
      {{"type", "facet"}, {"target", "F1"}, {"axes", {{"B", 0}, {"C", 0}}}},
      {{"type", "sphere"}, {"target", "S1"}, {"axes", {{"B", 0}, {"C", 0}}}, {"normal", {0, 0, 1}}},
      {{"type", "dbb"}, {"setup", "A1"}, {"axes", ZeroAxes()}, {"length", 100.0},
       {"tool_ball", {0, 0, 0}}, {"table_ball", {0, 0, 100}}},
      {{"type", "ball3d"}, {"setup", "R1"}, {"axes", ZeroAxes()}, {"tool_ball", {0, 0, 0}},
       {"table_ball", {0, 0, 0}}}};
  spec["seed"] = 3;
  return spec;
}

TEST(LoaderFields, SimulatedDatasetsCarryTheirDeclaredNoise) {
  json spec = SimSpec();
  spec["sigma"] = {{"probe", 0.0007}, {"dbb", 0.0003}};
  const Dataset ds = Simulate(spec.dump());
  EXPECT_EQ(ds.observations[0].sigma, Eigen::VectorXd::Constant(1, 0.0007));
  EXPECT_EQ(ds.observations[1].sigma, Eigen::VectorXd::Constant(1, 0.0007));
  EXPECT_EQ(ds.observations[2].sigma, Eigen::VectorXd::Constant(1, 0.0003));
  EXPECT_EQ(ds.observations[3].sigma.size(), 0);  // ball3d drawn without noise
  EXPECT_EQ(Dataset::FromJson(ds.ToJson()).observations[2].sigma, ds.observations[2].sigma);
  spec.erase("sigma");
  for (const Observation& o : Simulate(spec.dump()).observations) EXPECT_EQ(o.sigma.size(), 0);
}

// ---- issue 12: silent reinterpretations become named errors -----------------

TEST(LoaderBoundary, BacklashDirectionsOutsideMinusOneToOneAreRefused) {
  // get<int> truncation made 2^32+1 a 1 and INT_MIN went through std::abs (UB).
  for (const char* bad : {"-2147483648", "4294967297", "18446744073709551615", "0.5", "2", "-2", "1e300",
                          "\"1\"", "true", "null"}) {
    std::string text = SmallDataset().dump();
    const std::string from = R"("direction":{"X":1,)";
    const size_t at = text.find(from);
    ASSERT_NE(at, std::string::npos);
    text.replace(at, from.size(), std::string(R"("direction":{"X":)") + bad + ",");
    ExpectInvalid([&] { Dataset::FromJson(text); },
                  {"observations[0].direction.X", "-1, 0 or +1"});
  }
}

TEST(LoaderBoundary, IntegralFloatDirectionsAreAccepted) {
  // numpy writes 1.0; JSON Schema counts it as an integer.
  std::string text = SmallDataset().dump();
  const size_t at = text.find(R"("direction":{"X":1,"Y":-1})");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, std::string(R"("direction":{"X":1,"Y":-1})").size(), R"("direction":{"X":1.0,"Y":-1.0,"Z":0.0})");
  const Dataset ds = Dataset::FromJson(text);
  const Machine& m = ds.machine();
  EXPECT_EQ(ds.observations[0].direction[m.AxisIndex('X')], 1);
  EXPECT_EQ(ds.observations[0].direction[m.AxisIndex('Y')], -1);
  EXPECT_EQ(ds.observations[0].direction[m.AxisIndex('Z')], 0);
}

TEST(LoaderBoundary, SpecSeedIsAnIntegerBelowTwoToThe64) {
  json spec = SimSpec();
  spec["sigma"] = 0.001;
  spec["seed"] = 5;
  const Dataset a = Simulate(spec.dump());
  spec["seed"] = 5.0;  // integral float: the same seed
  const Dataset b = Simulate(spec.dump());
  EXPECT_EQ(a.observations[2].data<BallMountData>().reading, b.observations[2].data<BallMountData>().reading);
  for (const char* bad : {"-1", "18446744073709551616", "1.5", "\"7\"", "1e300"}) {
    std::string text = spec.dump();
    const size_t at = text.find(R"("seed":5.0)");
    ASSERT_NE(at, std::string::npos);
    text.replace(at, std::string(R"("seed":5.0)").size(), std::string(R"("seed":)") + bad);
    ExpectInvalid([&] { Simulate(text); }, {"simulate.seed"});
  }
}

TEST(LoaderBoundary, AxisDirectionWithOverflowingSquaredNormIsNormalisedStably) {
  json mj = Hu40t();
  mj["axes"]["Z"]["direction"] = {0, 0, 1.35e154};  // squaredNorm() overflows to inf
  const Machine m = Machine::FromJson(mj.dump());
  EXPECT_NEAR((m.axis(m.AxisIndex('Z')).direction - Eigen::Vector3d::UnitZ()).norm(), 0.0, 1e-15);
  mj["axes"]["Z"]["direction"] = {0, 0, 0};
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.axes.Z.direction", "zero"});
  Axis z;
  z.name = 'Z';
  z.direction = Eigen::Vector3d(0, 0, 1.35e154);
  const Machine direct("m", "wfZt", {z}, Eigen::Vector3d::Zero());
  EXPECT_NEAR(direct.axis(0).direction.z(), 1.0, 1e-15);
}

TEST(LoaderBoundary, DirectionsOfAnyFiniteScaleAreUnitVectorsOnEveryPath) {
  // [-1e308, -1e308, 0]: even stableNorm() is finite only by luck; 1.7e308 in
  // every component makes the norm itself inf. 5e-324 squares to 0.
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> cases = {
      {{-1e308, -1e308, 0}, {-std::sqrt(0.5), -std::sqrt(0.5), 0}},
      {{1.7e308, 1.7e308, 1.7e308}, Eigen::Vector3d::Constant(1 / std::sqrt(3.0))},
      {{5e-324, 0, 0}, {1, 0, 0}},
      {{0, 0, -1e-200}, {0, 0, -1}}};
  for (const auto& [v, unit] : cases) {
    SCOPED_TRACE(v.transpose());
    json mj = Hu40t();
    mj["axes"]["B"]["direction"] = {v.x(), v.y(), v.z()};
    mj["tool"]["axis"] = {v.x(), v.y(), v.z()};
    const Machine from_json = Machine::FromJson(mj.dump());
    EXPECT_NEAR((from_json.axis(from_json.AxisIndex('B')).direction - unit).norm(), 0.0, 1e-15);
    EXPECT_NEAR((from_json.tool_axis() - unit).norm(), 0.0, 1e-15);
    Axis b;
    b.name = 'B';
    b.type = AxisType::kRotary;
    b.direction = v;
    const Machine direct("m", "wBfXt", {b, Axis{}}, Eigen::Vector3d::Zero(), &v);
    EXPECT_NEAR((direct.axis(direct.AxisIndex('B')).direction - unit).norm(), 0.0, 1e-15);
    EXPECT_NEAR((direct.tool_axis() - unit).norm(), 0.0, 1e-15);
    EXPECT_NEAR((UnitDirection(v, "v") - unit).norm(), 0.0, 1e-15);
  }
  ExpectInvalid([] { UnitDirection(Eigen::Vector3d::Zero(), "axes.X.direction"); },
                {"axes.X.direction", "zero vector"});
  ExpectInvalid([] { UnitDirection(Eigen::Vector3d(0, NAN, 1), "axes.X.direction"); },
                {"axes.X.direction[1]", "not finite"});
  json mj = Hu40t();
  mj["tool"]["axis"] = {0, 0, 0};
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.tool.axis", "zero vector"});
}

TEST(LoaderBoundary, ParallelLinearAxesAndMachinesWithoutAxesAreRefused) {
  json mj = Hu40t();
  mj["axes"]["Y"]["direction"] = {-2, 0, 0};  // along X
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.axes.", "parallel to linear axis"});
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wft", "axes": {}})"); },
                {"machine.topology", "no axes"});
}

TEST(LoaderBoundary, SpindleAndItsAliasC1TogetherAreRefused) {
  json d = SmallDataset();
  d["observations"][1]["axes"]["C1"] = 0.0;
  ExpectInvalid([&] { Load(d); }, {"observations[1].axes", "\"S\"", "\"C1\""});
  d = SmallDataset();
  d["observations"][1]["direction"] = {{"S", 1}, {"C1", -1}};
  ExpectInvalid([&] { Load(d); }, {"observations[1].direction", "\"S\"", "\"C1\""});
  json mj = Hu40t();
  mj["axes"]["C1"] = mj["axes"]["S"];
  ExpectInvalid([&] { Machine::FromJson(mj.dump()); }, {"machine.axes", "\"C1\""});
}

TEST(LoaderBoundary, UnknownKeysAreRefusedWithDidYouMeanAtEveryLevel) {
  struct Case {
    std::function<void(json&)> edit;
    std::vector<std::string> needles;
  };
  const std::vector<Case> cases = {
      {[](json& d) { d["artifact"] = d["artefact"]; }, {"dataset: unknown key \"artifact\"", "did you mean \"artefact\""}},
      {[](json& d) { d["observations"][3]["dirction"] = {{"X", 1}}; },
       {"dataset.observations[3]: unknown key \"dirction\"", "did you mean \"direction\""}},
      {[](json& d) { d["observations"][0]["reading"] = 0.1; }, {"dataset.observations[0]: unknown key \"reading\""}},
      {[](json& d) { d["observations"][2]["lenght"] = 100; }, {"observations[2]: unknown key \"lenght\"", "\"length\""}},
      {[](json& d) { d["probe"]["tip_radus"] = 3; }, {"dataset.probe: unknown key \"tip_radus\"", "\"tip_radius\""}},
      {[](json& d) { d["artefact"]["facets"][0]["normals"] = {0, 0, 1}; },
       {"dataset.artefact.facets[0]: unknown key \"normals\"", "\"normal\""}},
      {[](json& d) { d["artefact"]["spheres"][1]["radious"] = 1; }, {"artefact.spheres[1]: unknown key", "\"radius\""}},
      {[](json& d) { d["artefact"]["scale_bars"][0]["lenght"] = 1; }, {"artefact.scale_bars[0]: unknown key"}},
      {[](json& d) { d["artefact"]["sphere"] = json::array(); }, {"dataset.artefact: unknown key \"sphere\"", "\"spheres\""}},
      {[](json& d) { d["machine"]["topolgy"] = "wfXt"; }, {"machine: unknown key \"topolgy\"", "\"topology\""}},
      {[](json& d) { d["machine"]["axes"]["X"]["directon"] = {1, 0, 0}; },
       {"machine.axes.X: unknown key \"directon\"", "\"direction\""}},
      {[](json& d) { d["machine"]["tool"]["tipp"] = {0, 0, 1}; }, {"machine.tool: unknown key \"tipp\"", "\"tip\""}},
  };
  for (const Case& c : cases) {
    json d = SmallDataset();
    c.edit(d);
    ExpectInvalid([&] { Load(d); }, c.needles);
  }
  // Spec and plan.
  json spec = SimSpec();
  spec["sigmas"] = 0.001;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate: unknown key \"sigmas\"", "\"sigma\""});
  spec = SimSpec();
  spec["plan"][1]["normall"] = {0, 0, 1};
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[1]: unknown key \"normall\"", "\"normal\""});
  spec = SimSpec();
  spec["sigma"] = {{"prob", 0.001}};
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.sigma: unknown key \"prob\"", "\"probe\""});
  spec = SimSpec();
  spec["artefact"]["facets"][0]["pointt"] = {0, 0, 0};
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.artefact.facets[0]: unknown key \"pointt\""});
  // The fields a file may carry are still accepted.
  json d = SmallDataset();
  d["$schema"] = "https://example.org/dataset.schema.json";
  d["observations"][0]["id"] = "t1";
  d["observations"][0]["sigma"] = 0.001;
  EXPECT_NO_THROW(Load(d));
}

TEST(LoaderBoundary, SimulateAppliesTheLoadersChecksNamingThePlanEntry) {
  json spec = SimSpec();
  spec["plan"][2]["length"] = 0.0;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2].length", "> 0"});
  spec["plan"][2]["length"] = -5.0;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2].length"});
  spec["plan"][2]["length"] = "100";
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2].length", "number"});
  spec = SimSpec();
  spec["plan"][2]["setup"] = "A.1";
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2].setup", "'.'"});
  spec["plan"][2]["setup"] = 7;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2].setup", "string"});
  spec = SimSpec();
  spec["plan"][0]["type"] = "facett";
  spec["plan"][0].erase("axes");
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[0].type", "unknown type 'facett'", "\"facet\""});
  spec = SimSpec();
  spec["sigma"] = {{"probe", "0.001"}};
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.sigma.probe", "number"});
  spec = SimSpec();
  spec["plan"][2]["length"] = 300.0;  // the balls are 100 mm apart: a -200 mm "reading"
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.plan[2]", "reading"});
  // What simulate writes, load_dataset reads.
  spec = SimSpec();
  spec["sigma"] = 0.001;
  EXPECT_NO_THROW(Dataset::FromJson(Simulate(spec.dump()).ToJson()));
}

TEST(LoaderBoundary, MalformedAndMistypedParameterNamesAreRefused) {
  const Dataset ds = Load(SmallDataset());
  const ParameterTable table(ds);
  ExpectInvalid([&] { table.Require("EX0c"); }, {"'EX0c'", "did you mean \"EX0C\"?"});
  ExpectInvalid([&] { table.Require("EX0C.x"); }, {"'EX0C.x'", "not a parameter name"});
  ExpectInvalid([&] { table.Require("sphere.S1.q"); }, {"'sphere.S1.q'"});
  EXPECT_GE(table.Require("sphere.S1.x"), table.num_machine());
  // Predicted residuals: another dataset's setup parameters are skipped on
  // purpose, malformed dotted names are not.
  EXPECT_NO_THROW(PredictResiduals(ds, {{"facet.F99", 0.001}, {"dbb.B7.length", 0.01}}, nullptr));
  ExpectInvalid([&] { PredictResiduals(ds, {{"EX0C.x", 0.001}}, nullptr); }, {"'EX0C.x'"});
  ExpectInvalid([&] { PredictResiduals(ds, {{"sphere.S1", 0.001}}, nullptr); }, {"'sphere.S1'"});
  // Error files and simulate specs.
  const Machine& m = ds.machine();
  ExpectInvalid([&] { ErrorModel::FromJson(m, R"({"EX0C.x": 0.01})"); }, {"'EX0C.x'"});
  EXPECT_NO_THROW(ErrorModel::FromJson(m, R"({"EX0C": 0.01, "facet.F3": 0.002, "sphere.S1.x": 0.1})"));
  ExpectInvalid([&] { m.RequireParameter("ECCB"); }, {"did you mean \"ECCb\"?"});
  json spec = SimSpec();
  spec["errors"]["EX0C.x"] = 0.01;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.errors.EX0C.x"});
  spec = SimSpec();
  spec["setup"] = {{"sphere.S1.q", 0.01}};
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.setup.sphere.S1.q"});
}

TEST(LoaderBoundary, ImplausibleMagnitudesAreRefusedNamingTheField) {
  struct Case {
    std::function<void(json&)> edit;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](json& d) { d["artefact"]["spheres"][0]["radius"] = 1e308; }, "artefact.spheres[0].radius"},
      {[](json& d) { d["artefact"]["spheres"][0]["center"][1] = -1e6; }, "artefact.spheres[0].center[1]"},
      {[](json& d) { d["artefact"]["facets"][0]["point"][0] = 1e308; }, "artefact.facets[0].point[0]"},
      {[](json& d) { d["artefact"]["scale_bars"][0]["length"] = 1e308; }, "artefact.scale_bars[0].length"},
      {[](json& d) { d["probe"]["tip_radius"] = 1e308; }, "probe.tip_radius"},
      {[](json& d) { d["observations"][2]["length"] = 1e308; }, "observations[2].length"},
      {[](json& d) { d["observations"][2]["reading"] = 1e308; }, "observations[2].reading"},
      {[](json& d) { d["observations"][2]["reading"] = 120.0; }, "observations[2].reading"},
      {[](json& d) { d["observations"][2]["tool_ball"][2] = 1e308; }, "observations[2].tool_ball[2]"},
      {[](json& d) { d["observations"][3]["measured"][0] = 1e308; }, "observations[3].measured[0]"},
      {[](json& d) { d["observations"][0]["axes"]["X"] = 1e308; }, "observations[0].axes.X"},
      {[](json& d) { d["observations"][0]["axes"]["B"] = -1e308; }, "observations[0].axes.B"},
      {[](json& d) { d["observations"][0]["axes"]["C"] = 2e5; }, "observations[0].axes.C"},
      {[](json& d) { d["machine"]["axes"]["B"]["point"][2] = 1e308; }, "machine.axes.B.point[2]"},
      {[](json& d) { d["machine"]["tool"]["tip"][2] = 1e308; }, "machine.tool.tip[2]"},
  };
  for (const Case& c : cases) {
    json d = SmallDataset();
    c.edit(d);
    ExpectInvalid([&] { Load(d); }, {c.field});
  }
  json spec = SimSpec();
  spec["errors"]["EX0C"] = 1e308;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"errors.EX0C"});
  spec = SimSpec();
  spec["sigma"] = 1e308;
  ExpectInvalid([&] { Simulate(spec.dump()); }, {"simulate.sigma"});
}

TEST(LoaderBoundary, ScaleBarsAreCheckedAtLoad) {
  json d = SmallDataset();
  d["artefact"]["scale_bars"][0]["spheres"] = {"S1", "S1"};
  ExpectInvalid([&] { Load(d); }, {"artefact.scale_bars[0].spheres", "joins sphere 'S1' to itself"});
  d["artefact"]["scale_bars"][0]["spheres"] = {"S1", 2};
  ExpectInvalid([&] { Load(d); }, {"artefact.scale_bars[0].spheres[1]", "string"});
  d["artefact"]["scale_bars"][0]["spheres"] = {"S1", "S9"};
  ExpectInvalid([&] { Load(d); }, {"artefact.scale_bars[0].spheres", "'S9'"});
}

bool ValidUtf8(const std::string& s) {
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    size_t n = c < 0x80 ? 1 : (c & 0xE0) == 0xC0 ? 2 : (c & 0xF0) == 0xE0 ? 3 : (c & 0xF8) == 0xF0 ? 4 : 0;
    if (n == 0 || i + n > s.size()) return false;
    for (size_t k = 1; k < n; ++k)
      if ((static_cast<unsigned char>(s[i + k]) & 0xC0) != 0x80) return false;
    i += n;
  }
  return true;
}

std::string MessageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "no std::invalid_argument";
  return "";
}

TEST(LoaderBoundary, DeepNestingGivesAShortNamedError) {
  // 100k unclosed '[' once produced a 300 kB message.
  const std::string deep = R"({"machine": )" + std::string(100000, '[');
  const std::string msg = MessageOf([&] { Dataset::FromJson(deep); });
  EXPECT_LT(msg.size(), 1000u);
  EXPECT_NE(msg.find("dataset.machine"), std::string::npos) << msg;
  EXPECT_NE(msg.find("nested deeper than"), std::string::npos) << msg;
  // A 5000-deep dict (closed): refused by name, no recursion.
  std::string dict = R"({"machine": )";
  for (int i = 0; i < 5000; ++i) dict += R"({"a": )";
  dict += "1" + std::string(5000, '}') + "}";
  const std::string msg2 = MessageOf([&] { Dataset::FromJson(dict); });
  EXPECT_LT(msg2.size(), 1000u);
  EXPECT_NE(msg2.find("nested deeper than"), std::string::npos) << msg2;
  // Brackets inside strings do not count.
  json d = SmallDataset();
  d["observations"][0]["id"] = std::string(200, '[');
  EXPECT_NO_THROW(Load(d));
}

TEST(LoaderBoundary, MessagesAreValidUtf8AndNeverCutACharacter) {
  json mj = Hu40t();
  mj["topology"] = "wC\xC3\xA9" "fXt";  // wCéfXt
  const std::string msg = MessageOf([&] { Machine::FromJson(mj.dump()); });
  EXPECT_TRUE(ValidUtf8(msg)) << msg;
  EXPECT_NE(msg.find("'\xC3\xA9'"), std::string::npos) << msg;  // the whole letter, quoted
  // Invalid bytes (not UTF-8) in the text: escaped, still valid UTF-8.
  const std::string raw = R"({"topology": "wC)" + std::string("\xFF\xC3") + R"(fXt", "axes": {}})";
  const std::string msg2 = MessageOf([&] { Machine::FromJson(raw); });
  EXPECT_TRUE(ValidUtf8(msg2)) << msg2;
  EXPECT_NE(msg2.find("\\xFF"), std::string::npos) << msg2;
  // An unknown key with a multi-byte name is quoted whole.
  json d = SmallDataset();
  d["observations"][0]["dir\xC3\xA9" "ction"] = 1;
  const std::string msg3 = MessageOf([&] { Load(d); });
  EXPECT_TRUE(ValidUtf8(msg3)) << msg3;
  EXPECT_NE(msg3.find("dir\xC3\xA9" "ction"), std::string::npos) << msg3;
}

TEST(LoaderBoundary, SyntaxErrorsStillNameTheField) {
  std::string text = SmallDataset().dump();
  const size_t at = text.find(R"("reading":0.001)");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, std::string(R"("reading":0.001)").size(), R"("reading":0.001.2)");
  ExpectInvalid([&] { Dataset::FromJson(text); }, {"dataset.observations[2].reading", "invalid JSON"});
  text = SmallDataset().dump();
  text.replace(text.find(R"("reading":0.001)"), std::string(R"("reading":0.001)").size(), R"("reading":1e999)");
  ExpectInvalid([&] { Dataset::FromJson(text); }, {"dataset.observations[2].reading", "double range"});
}

// ---- Streaming load (observations converted one by one) ---------------------

// The dataset text with its members in the given order.
std::string InOrder(const json& d, const std::vector<std::string>& keys) {
  std::string text = "{";
  for (size_t i = 0; i < keys.size(); ++i)
    text += (i ? "," : "") + json(keys[i]).dump() + ":" + d[keys[i]].dump();
  return text + "}";
}

TEST(LoaderStreaming, EveryMemberOrderLoadsTheSameDataset) {
  // The stream takes machine and artefact before the observations; any other
  // order goes through the document parser; both give the same dataset.
  const json d = SmallDataset();
  const std::string expected = Load(d).ToJson();
  for (const auto& order : std::vector<std::vector<std::string>>{
           {"machine", "probe", "artefact", "observations"},
           {"observations", "machine", "probe", "artefact"},
           {"machine", "observations", "artefact", "probe"},
           {"artefact", "observations", "probe", "machine"}})
    EXPECT_EQ(Dataset::FromJson(InOrder(d, order)).ToJson(), expected) << order[0] << "," << order[1];
  // Ball samples need no artefact: they stream with it given after them.
  json balls = d;
  balls["observations"] = json::array({d["observations"][2], d["observations"][3]});
  EXPECT_EQ(Dataset::FromJson(InOrder(balls, {"machine", "observations", "artefact", "probe"})).ToJson(),
            Load(balls).ToJson());
}

TEST(LoaderStreaming, EveryFieldFormConvertsAsTheDocumentParserReadsIt) {
  // The common observation converts straight from the parser's events, any
  // other form through the document reader: both must give the same dataset.
  json d = SmallDataset();
  json& o = d["observations"];
  o[0]["sigma"] = 0.002;
  o[0]["id"] = "touch 1";
  o[0]["direction"] = {{"X", 1.0}, {"Y", -1}, {"Z", 0}, {"B", -0.0}};  // integral floats
  o[1]["axes"].erase("S");                                             // S may be left out
  o[1]["axes"]["C1"] = 12.5;                                           // its alias
  o[1]["axes"]["X"] = -7;                                              // a negative integer
  o[2]["sigma"] = {0.0007};                                            // one per row
  o[2]["setup"] = "A 1";
  o[3]["sigma"] = {0.001, 0.002, 0.003};
  o[3].erase("setup");                                                 // the default mounting
  o.push_back({{"type", "ball3d"}, {"axes", Axes()}, {"measured", {1, 0, 0}}, {"tool_ball", {0, 0, 0}},
               {"table_ball", {0, 0, 100}}, {"sigma", 1}, {"direction", {{"C", 1}}}});
  o.push_back({{"type", "dbb"}, {"setup", "A1"}, {"axes", Axes()}, {"reading", -0.5}, {"length", 150},
               {"tool_ball", {0.5, 0, 0}}, {"table_ball", {0, 0, 100}}, {"id", "last"}});
  const std::string streamed = Dataset::FromJson(InOrder(d, {"machine", "artefact", "observations", "probe"})).ToJson();
  const std::string document = Dataset::FromJson(InOrder(d, {"observations", "machine", "artefact", "probe"})).ToJson();
  EXPECT_EQ(streamed, document);
  const Dataset ds = Dataset::FromJson(InOrder(d, {"machine", "artefact", "observations", "probe"}));
  const Machine& m = ds.machine();
  EXPECT_EQ(ds.observations[0].sigma, Eigen::VectorXd::Constant(1, 0.002));
  EXPECT_EQ(ds.observations[0].id, "touch 1");
  EXPECT_EQ(ds.observations[0].direction[m.AxisIndex('X')], 1);
  EXPECT_EQ(ds.observations[1].axes[m.AxisIndex('S')], 12.5);
  EXPECT_EQ(ds.observations[1].axes[m.AxisIndex('X')], -7.0);
  EXPECT_EQ(ds.observations[3].setup, "");
  EXPECT_EQ(ds.observations[3].sigma, Eigen::Vector3d(0.001, 0.002, 0.003));
  EXPECT_EQ(ds.observations[4].sigma, Eigen::Vector3d::Constant(1.0));
  EXPECT_EQ(ds.observations[5].data<BallMountData>().length, 150.0);
  EXPECT_EQ(ds.observations[5].data<BallMountData>().tool_ball, Eigen::Vector3d(0.5, 0, 0));
}

TEST(LoaderStreaming, MessagesAreThoseOfTheDocumentOrder) {
  const std::vector<std::string> order = {"machine", "artefact", "observations", "probe"};
  // A bad observation and, after the observations, an unknown member: the
  // member is named first, as the document parser checks the top level first.
  json d = SmallDataset();
  d["observations"][1]["axes"]["Q"] = 1.0;
  std::string text = InOrder(d, order);
  text.insert(text.size() - 1, R"(,"probes":{})");
  ExpectInvalid([&] { Dataset::FromJson(text); }, {"dataset: unknown key \"probes\"", "\"probe\""});
  // ... a bad probe after the observations, likewise.
  d = SmallDataset();
  d["observations"][1]["axes"]["Q"] = 1.0;
  d["probe"]["tip_radius"] = -1.0;
  ExpectInvalid([&] { Dataset::FromJson(InOrder(d, order)); }, {"dataset.probe.tip_radius"});
  // With a valid head, the first bad observation.
  d = SmallDataset();
  d["observations"][1]["axes"]["Q"] = 1.0;
  d["observations"][3]["measured"] = "x";
  ExpectInvalid([&] { Dataset::FromJson(InOrder(d, order)); }, {"dataset.observations[1].axes", "'Q'"});
  // A syntax error behind a bad observation is the first thing said.
  text = InOrder(d, order);
  text.insert(text.size() - 1, ",");
  ExpectInvalid([&] { Dataset::FromJson(text); }, {"invalid JSON"});
  // A repeated member: the last one counts, as in the document parser.
  d = SmallDataset();
  text = InOrder(d, order);
  json first = d["observations"];
  first[0]["target"] = "nowhere";
  text.insert(text.size() - 1, R"(,"observations":)" + json::array({d["observations"][1]}).dump());
  text.insert(1, R"("observations":)" + first.dump() + ",");
  EXPECT_EQ(Dataset::FromJson(text).observations.size(), 1u);
  // Fields one by one: the message of the document parser, whatever the order.
  for (const auto& [edit, needle] : std::vector<std::pair<std::function<void(json&)>, std::string>>{
           {[](json& o) { o[0]["axes"]["X"] = 2e5; }, "observations[0].axes.X"},
           {[](json& o) { o[0]["axes"].erase("Y"); }, "observations[0].axes: missing axis 'Y'"},
           {[](json& o) { o[0]["direction"]["X"] = 2; }, "observations[0].direction.X"},
           {[](json& o) { o[0]["sigma"] = 0.0; }, "observations[0].sigma"},
           {[](json& o) { o[2]["reading"] = 101.0; }, "observations[2].reading"},
           {[](json& o) { o[2]["length"] = 0; }, "observations[2].length: must be > 0 mm"},
           {[](json& o) { o[2]["setup"] = "A.1"; }, "observations[2].setup"},
           {[](json& o) { o[3]["measured"] = {1, 2}; }, "observations[3].measured"},
           {[](json& o) { o[3]["tool_ball"] = {1, 2, "3"}; }, "observations[3].tool_ball[2]"},
           {[](json& o) { o[3].erase("table_ball"); }, "observations[3].table_ball"},
           {[](json& o) { o[1]["target"] = 5; }, "observations[1].target: missing (a string)"},
           {[](json& o) { o[1]["type"] = "spere"; }, "did you mean \"sphere\""},
           {[](json& o) { o[0]["id"] = 3; }, "observations[0].id"},
           {[](json& o) { o[0]["axes"] = {{"X", {1}}}; }, "observations[0].axes.X: expected a number"}}) {
    d = SmallDataset();
    edit(d["observations"]);
    const std::string streamed = MessageOf([&] { Dataset::FromJson(InOrder(d, order)); });
    const std::string document =
        MessageOf([&] { Dataset::FromJson(InOrder(d, {"observations", "machine", "artefact", "probe"})); });
    EXPECT_EQ(streamed, document);
    EXPECT_NE(streamed.find(needle), std::string::npos) << streamed;
  }
  // An observation that is not an object, a target defined nowhere.
  d = SmallDataset();
  d["observations"][2] = 7;
  ExpectInvalid([&] { Dataset::FromJson(InOrder(d, order)); }, {"dataset.observations[2]: expected an object"});
  d = SmallDataset();
  d["observations"][1]["target"] = "S9";
  ExpectInvalid([&] { Dataset::FromJson(InOrder(d, {"machine", "observations", "artefact"})); },
                {"dataset.observations[1].target: unknown sphere 'S9'"});
}

// ---- The fast reader and the file read piece by piece -----------------------

TEST(LoaderFast, EveryNumberAndStringFormReadsAsTheDocumentParserReadsIt) {
  // The fast reader parses numbers and strings itself (std::from_chars, its
  // own escapes); it must read each as the document parser does, and give
  // up (to the SAX stream) on what it does not handle.
  const std::vector<std::string> numbers = {"0", "-0", "-0.0", "7", "-7", "1E2", "1e-7", "-2.5E+1", "0.1",
                                            "12345", "99.999999999999999999", "2.5e-300", "1.7976931348623157e2"};
  const std::vector<std::string> ids = {R"("plain")", R"("q\"uote\\back\/slash")", R"("tab\tnl\nret\r\b\f")",
                                        R"("\u00e9t\u00e9")", "\"\xc3\xa9t\xc3\xa9\"", R"("")"};
  const json d = SmallDataset();
  std::string obs;
  for (size_t i = 0; i < numbers.size() + ids.size(); ++i) {
    const std::string x = i < numbers.size() ? numbers[i] : "1";
    const std::string id = i < numbers.size() ? R"("n")" : ids[i - numbers.size()];
    obs += std::string(i ? ",\n" : "") + R"({"type": "ball3d", "setup": "R1", "axes": {"X": )" + x +
           R"(, "Y": 2, "Z": -5, "B": 30, "C": 0, "S": 0}, "measured": [)" + x + R"(, 0, 0], "tool_ball": [0, 0, )" +
           x + R"(], "table_ball": [0, 0, 100], "sigma": 0.001, "direction": {"X": 1, "C": -1.0}, "id": )" + id + "}";
  }
  const std::string head = "\"machine\": " + d["machine"].dump() + ", \"probe\": {\"tip_radius\": 3}";
  const std::string fast = "{" + head + ", \"observations\": [" + obs + "]}";
  const std::string document = "{\"observations\": [" + obs + "], " + head + "}";
  const Dataset a = Dataset::FromJson(fast), b = Dataset::FromJson(document);
  EXPECT_EQ(a.ToJson(), b.ToJson());
  ASSERT_EQ(a.observations.size(), numbers.size() + ids.size());
  const int ax = a.machine().AxisIndex('X');
  for (size_t i = 0; i < numbers.size(); ++i) {
    const double x = std::stod(numbers[i]);
    EXPECT_EQ(a.observations[i].axes[ax], x) << numbers[i];
    // -0 is an integer to a JSON parser (+0.0); -0.0 keeps its sign
    if (numbers[i].find_first_of(".eE") != std::string::npos)
      EXPECT_EQ(std::signbit(a.observations[i].axes[ax]), std::signbit(x)) << numbers[i];
  }
  EXPECT_EQ(a.observations[numbers.size() + 1].id, "q\"uote\\back/slash");
  EXPECT_EQ(a.observations[numbers.size() + 3].id, "\xc3\xa9t\xc3\xa9");
  // A byte order mark is skipped, as the document parser skips it.
  EXPECT_EQ(Dataset::FromJson("\xEF\xBB\xBF" + fast).ToJson(), a.ToJson());
  // Invalid numbers and literals are the document parser's to name.
  for (const std::string& bad : {"01", "1.", ".5", "-", "1e", "+1", "0x10", "NaN", "tru"}) {
    std::string text = fast;
    text.replace(text.find("\"Y\": 2"), 6, "\"Y\": " + bad);
    ExpectInvalid([&] { Dataset::FromJson(text); }, {"invalid JSON"});
  }
}

// `text` in a temporary file; the file's path.
std::string TempFile(const std::string& text) {
  char name[] = "/tmp/fivecal_loader_XXXXXX";
  const int fd = mkstemp(name);
  EXPECT_GE(fd, 0);
  EXPECT_EQ(write(fd, text.data(), text.size()), static_cast<ssize_t>(text.size()));
  close(fd);
  return name;
}

// Every piece of the file read piece by piece, joined, as ToJson; "" when
// the reader says the file does not stream.
std::string ReadInPieces(const std::string& path, size_t rows, size_t buffer, std::vector<size_t>* sizes = nullptr) {
  DatasetFileReader r(path, buffer);
  std::optional<Dataset> whole;
  while (std::optional<Dataset> piece = r.Next(rows)) {
    if (sizes) sizes->push_back(piece->observations.size());
    if (!whole) whole.emplace(piece->Subset({}));
    for (Observation& o : piece->observations) whole->observations.push_back(std::move(o));
  }
  if (!r.streamable() || !whole) return "";
  return whole->ToJson();
}

TEST(LoaderFast, AFileReadPieceByPieceIsTheWholeFile) {
  // Many observations of every flat kind and some of others (through the
  // reference reader), a buffer far smaller than the file: pieces of any
  // size join up to what Dataset::FromJson loads, observations crossing the
  // buffer's refills included.
  json d = SmallDataset();
  json& o = d["observations"];
  const json base = o;
  for (int i = 0; i < 300; ++i) {
    json x = base[i % base.size()];
    x["axes"]["X"] = 0.37 * i;
    if (i % 7 == 0) x["id"] = "id " + std::to_string(i);
    if (i % 11 == 0) x["sigma"] = 0.002;
    o.push_back(x);
  }
  const std::string text = InOrder(d, {"machine", "probe", "artefact", "observations"});
  const std::string path = TempFile(text);
  const std::string expected = Dataset::FromJson(text).ToJson();
  std::vector<size_t> sizes;
  EXPECT_EQ(ReadInPieces(path, 7, 4096, &sizes), expected);
  EXPECT_EQ(sizes.front(), 7u);
  EXPECT_EQ(std::accumulate(sizes.begin(), sizes.end(), size_t{0}), o.size());
  EXPECT_EQ(ReadInPieces(path, 1000, 4096), expected);
  EXPECT_EQ(ReadInPieces(path, 1, 1 << 20), expected);
  std::remove(path.c_str());

  // A bad observation is named by its index in the file, in any piece.
  json bad = d;
  bad["observations"][250]["axes"]["X"] = 2e5;
  const std::string bad_text = InOrder(bad, {"machine", "probe", "artefact", "observations"});
  const std::string bad_path = TempFile(bad_text);
  const std::string whole_message = MessageOf([&] { Dataset::FromJson(bad_text); });
  EXPECT_NE(whole_message.find("observations[250].axes.X"), std::string::npos) << whole_message;
  EXPECT_EQ(MessageOf([&] { ReadInPieces(bad_path, 7, 4096); }), whole_message);
  std::remove(bad_path.c_str());

  // What does not stream says so, or fails a piece's checks (a probe given
  // after the observations): the caller loads it whole. Members after the
  // observations, no observations, a string beyond ASCII, a syntax error.
  for (const std::string& t :
       {InOrder(d, {"machine", "artefact", "observations", "probe"}),
        InOrder(d, {"observations", "machine", "probe", "artefact"}),
        std::string(text).replace(text.find("\"id 0\""), 6, "\"id \xc3\xa9\""),
        text.substr(0, text.size() - 2),
        text + "x"}) {
    const std::string p = TempFile(t);
    std::string got;
    try {
      got = ReadInPieces(p, 7, 4096);
    } catch (const std::invalid_argument&) {
    }
    EXPECT_EQ(got, "");
    std::remove(p.c_str());
  }
  EXPECT_THROW(DatasetFileReader("/nonexistent/x.json"), std::invalid_argument);
}

}  // namespace
}  // namespace fivecal
