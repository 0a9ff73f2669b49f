// Every registered observation kind (observations/registry.cc), the same
// checks: its templated residual against the analytic batch and against
// central finite differences, its simulation giving zero residuals at the
// truth, and its file fields surviving load -> save -> load. A new kind gets
// these by adding a sample plan entry below (the test fails without one).
#include <gtest/gtest.h>

#include <ceres/gradient_checker.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <sstream>

#include "fivecal/observations/pose.h"
#include "fivecal/observations/registry.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

using nlohmann::json;

const char* kBase = R"({
 "machine": {"name": "hu40t", "topology": "wCBXfZYSt", "axes": {
   "X": {"type": "linear", "direction": [-1,0,0]},
   "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
   "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
   "Z": {"type": "linear", "direction": [0,0,1]}, "Y": {"type": "linear", "direction": [0,1,0]},
   "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}}, "tool": {"tip": [0,0,100]}},
 "probe": {"tip_radius": 3.0},
 "artefact": {"facets": [{"id": "T", "point": [10,20,0], "normal": [0,0,1]},
                         {"id": "E", "point": [150,0,-20], "normal": [1,0,0]}],
              "spheres": [{"id": "S1", "center": [-100,0,30], "radius": 12.7},
                          {"id": "S2", "center": [100,0,30], "radius": 12.7}],
              "scale_bars": [{"spheres": ["S1","S2"], "length": 200}]},
 "errors": {"EX0C": -0.1, "EA0C": 2e-5, "EB0C": 1e-5, "EA0B": -1e-5, "EC0B": 2e-5, "EB0Z": 7e-5,
            "EXX1": 1e-5, "EYY1": -2e-5, "EXX2": 1e-8, "EAC1": 3e-6, "EZB2": 2e-4,
            "EXXb": 0.003, "ECCb": -4e-5, "EBBb": 3e-5, "tip.x": 0.01, "tip.z": -0.02, "EX0S": -0.13}
})";

// Per kind: plan entries and the true values of the setup parameters they
// bring; `artefact`: entries the kind adds to the base artefact.
struct Sample {
  const char* plan;
  const char* setup;
  const char* artefact = nullptr;
};
const std::map<std::string, Sample> kSamples = {
    {"facet",
     {R"([{"type": "facet", "target": "T", "axes": {"B": 0, "C": 0, "S": 0}, "direction": {"B": 1, "C": -1}},
          {"type": "facet", "target": "T", "axes": {"B": 0, "C": 90, "S": 90}, "id": "t2"},
          {"type": "facet", "target": "E", "axes": {"B": 30, "C": 0}, "direction": {"B": -1, "C": 1}}])",
      R"({"facet.T": 0.01, "facet.E": -0.004, "probe.pretravel": 0.002, "probe.axial": -0.001,
          "probe.lobe.c3": 0.004, "probe.lobe.s2": 0.001})"}},
    {"sphere",
     {R"([{"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [0,0,1]},
          {"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [1,0,1]},
          {"type": "sphere", "target": "S2", "axes": {"B": 0, "C": 30}, "normal": [-1,1,1]}])",
      R"({"sphere.S1.x": 0.002, "sphere.S2.z": -0.003, "sphere.S1.r": 0.001, "probe.lobe.c3": 0.004,
          "probe.lobe.s3": -0.003, "probe.axial": 0.002, "probe.lobe.c2": -0.001})"}},
    {"cylinder",
     {R"([{"type": "cylinder", "target": "K", "axes": {"B": 0, "C": 0}, "point": [180, 0, -40]},
          {"type": "cylinder", "target": "K", "axes": {"B": 20, "C": 90}, "point": [10, -170, -45], "id": "k2"},
          {"type": "cylinder", "target": "H", "axes": {"B": -10, "C": 30}, "point": [40, -20, 0],
           "direction": {"B": 1}}])",
      R"({"cylinder.K.r": 0.02, "cylinder.K.x": 0.01, "cylinder.H.y": -0.003, "cylinder.H.rx": 1e-4,
          "cylinder.H.ry": -2e-4, "probe.lobe.c3": 0.004, "probe.pretravel": 0.001})",
      R"({"cylinders": [{"id": "K", "point": [0,0,-30], "axis": [0,0,1], "radius": 180},
                        {"id": "H", "point": [40,-30,0], "axis": [0.6,0,0.8], "radius": 10, "inside": true}]})"}},
    {"dbb",
     {R"([{"type": "dbb", "axes": {"X": 10, "Y": 20, "Z": -50, "B": 20, "C": 40}, "length": 100,
           "tool_ball": [0,0,100], "table_ball": [50,0,0], "direction": {"C": 1, "X": -1}},
          {"type": "dbb", "setup": "A2", "axes": {"X": -40, "Y": 5, "Z": -30, "B": -10, "C": 120}, "length": 150,
           "tool_ball": [0,0,90], "table_ball": [0,80,10]}])",
      R"({"dbb.length": 0.003, "dbb.tool.x": 0.001, "dbb.table.y": -0.002, "dbb.A2.table.z": 0.002})"}},
    {"ball3d",
     {R"([{"type": "ball3d", "setup": "R1", "axes": {"X": -30, "Y": 5, "Z": 10, "B": -40, "C": 200},
           "tool_ball": [0,0,100], "table_ball": [0,60,20], "direction": {"Y": 1}},
          {"type": "ball3d", "setup": "R1", "axes": {"X": 20, "Y": -15, "Z": 0, "B": 25, "C": -60},
           "tool_ball": [0,0,100], "table_ball": [0,60,20]}])",
      R"({"ball3d.R1.tool.z": 0.004, "ball3d.R1.table.x": 0.001})"}},
    {"point",
     {R"([{"type": "point", "instrument": "T1", "axes": {"X": -30, "Y": 5, "Z": 10, "B": -40, "C": 200},
           "target": "tool", "target_point": [0,0,100], "instrument_origin": [1500, -200, 300],
           "instrument_angles": [1, -2, 30], "direction": {"Y": 1}},
          {"type": "point", "instrument": "T1", "axes": {"X": 20, "Y": -15, "Z": 0, "B": 25, "C": -60},
           "target": "tool", "target_point": [0,0,100], "instrument_origin": [1500, -200, 300],
           "instrument_angles": [1, -2, 30]},
          {"type": "point", "instrument": "C2", "axes": {"X": 0, "Y": 0, "Z": 0, "B": 30, "C": 45},
           "target": "work", "target_point": [80, 20, 40]}])",
      R"({"instrument.T1.x": 0.05, "instrument.T1.c": 1e-3, "instrument.T1.tool_z": 0.02,
          "instrument.C2.a": -2e-4, "instrument.C2.work_x": 0.01})"}},
    {"pose",
     {R"([{"type": "pose", "instrument": "T1", "axes": {"X": -30, "Y": 5, "Z": 10, "B": -40, "C": 200},
           "target": "tool", "target_point": [0,0,100], "target_rotation": [0.1, -0.2, 0.3],
           "instrument_origin": [1500, -200, 300], "instrument_angles": [1, -2, 30], "direction": {"Y": 1}},
          {"type": "pose", "instrument": "T1", "axes": {"X": 20, "Y": -15, "Z": 0, "B": 25, "C": -60},
           "target": "tool", "target_point": [0,0,100], "target_rotation": [0.1, -0.2, 0.3],
           "instrument_origin": [1500, -200, 300], "instrument_angles": [1, -2, 30]},
          {"type": "pose", "instrument": "C2", "axes": {"X": 0, "Y": 0, "Z": 0, "B": 30, "C": 45},
           "target": "work", "target_point": [80, 20, 40], "id": "w1"}])",
      R"({"instrument.T1.x": 0.05, "instrument.T1.c": 1e-3, "instrument.T1.tool_z": 0.02,
          "instrument.T1.tool_a": 2e-3, "instrument.T1.tool_c": -1e-3,
          "instrument.C2.a": -2e-4, "instrument.C2.work_x": 0.01, "instrument.C2.work_b": 5e-4})"}},
    {"distance",
     {R"([{"type": "distance", "station": "L1", "axes": {"X": -30, "Y": 5, "Z": 10, "B": -40, "C": 200},
           "target": "tool", "target_point": [0,0,100], "station_position": [800, -300, 200],
           "dead_length": 150, "direction": {"Y": 1}},
          {"type": "distance", "station": "L2", "axes": {"X": 20, "Y": -15, "Z": 0, "B": 25, "C": -60},
           "target": "tool", "target_point": [0,0,100], "station_position": [-600, 500, 400]},
          {"type": "distance", "station": "L1", "instrument": "LT2", "axes": {"X": 0, "Y": 0, "Z": 0, "B": 30, "C": 45},
           "target": "work", "target_point": [80, 20, 40], "station_position": [800, -300, 200], "id": "w1"}])",
      R"({"instrument.L1.x": 0.05, "instrument.L1.length": 0.02, "instrument.L2.z": -0.03,
          "instrument.tracer.tool_z": 0.02, "instrument.LT2.work_x": 0.01})"}},
    {"machined",
     {R"([{"type": "machined", "part": "P1", "feature": "face", "axes": {"B": 30, "C": 45}, "point": [40, 60, 20],
           "normal": [0, 1, 0], "direction": {"C": 1}},
          {"type": "machined", "part": "P1", "feature": "step", "axes": {"B": 90, "C": 180}, "point": [0, 80, 30],
           "normal": [0, 0, 1], "reference_axes": {"B": 90, "C": 0}},
          {"type": "machined", "part": "P2", "feature": "step", "axes": {"B": -30, "C": 90}, "point": [50, 0, 10],
           "normal": [1, 0, 0.2], "reference_axes": {"X": 20, "Y": -10, "Z": -60, "B": 0, "C": 0},
           "reference_point": [50, 10, 25], "reference_normal": [0, 0, 1], "id": "s3"}])",
      R"({"machined.P1.x": 0.01, "machined.P1.c": 2e-4, "machined.P2.a": -1e-4, "machined.P2.z": 0.005})"}},
};

std::string SpecOf(const ObservationKind& k) {
  json spec = json::parse(kBase);
  const Sample& s = kSamples.at(k.name());
  spec["plan"] = json::parse(s.plan);
  spec["setup"] = json::parse(s.setup);
  if (s.artefact) spec["artefact"].update(json::parse(s.artefact));
  return spec.dump();
}

std::vector<int> All(int n) {
  std::vector<int> v(n);
  for (int i = 0; i < n; ++i) v[i] = i;
  return v;
}

class EveryKind : public ::testing::TestWithParam<const ObservationKind*> {};

TEST(ObservationRegistry, KindsAreRegisteredOnceWithASample) {
  std::set<std::string> names;
  std::set<int> types;
  for (const ObservationKind* k : ObservationKinds()) {
    EXPECT_TRUE(names.insert(k->name()).second) << k->name();
    EXPECT_TRUE(types.insert(static_cast<int>(k->type())).second) << k->name();
    EXPECT_EQ(&KindOf(k->type()), k);
    EXPECT_EQ(FindKind(k->name()), k);
    EXPECT_STREQ(ObservationTypeName(k->type()), k->name());
    EXPECT_GE(k->rows(), 1);
    EXPECT_GT(k->default_sigma(), 0.0);
    EXPECT_TRUE(kSamples.count(k->name())) << "add a sample plan entry of kind " << k->name();
    EXPECT_NE(std::string(k->label()), "");
  }
  EXPECT_EQ(FindKind("facett"), nullptr);
}

TEST_P(EveryKind, SimulatedDataHaveZeroResidualsAtTheTruth) {
  const ObservationKind& k = *GetParam();
  const SimulationPlan plan = BuildSimulationPlan(SpecOf(k));
  const Dataset& ds = plan.base;
  for (const Observation& o : ds.observations) ASSERT_EQ(o.type, k.type());
  const ParameterTable table(ds);
  Eigen::VectorXd truth = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : plan.values) truth[table.Require(name)] = value;
  for (bool analytic : {true, false}) {
    Problem p(ds, table, truth, All(table.size()), "", 0.0, analytic);
    ASSERT_EQ(p.num_rows(), static_cast<int>(ds.observations.size()) * k.rows() +
                                (k.type() == ObservationType::kSphere ? 1 : 0));
    Eigen::VectorXd r;
    p.Evaluate(&r, nullptr);
    EXPECT_LT(r.cwiseAbs().maxCoeff(), 1e-9) << k.name() << (analytic ? " analytic" : " autodiff");
  }
}

TEST_P(EveryKind, ResidualMatchesAnalyticJacobianAndFiniteDifferences) {
  const ObservationKind& k = *GetParam();
  const SimulationPlan plan = BuildSimulationPlan(SpecOf(k));
  const Dataset& ds = plan.base;
  const ParameterTable table(ds);
  // Away from the truth and from zero, every parameter at a plausible size.
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  const Machine& m = ds.machine();
  Eigen::VectorXd values(table.size()), size(table.size());
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
  const std::vector<int> all = All(table.size());
  Problem fast(ds, table, values, all, "", 0.0, true);
  Problem jet(ds, table, values, all, "", 0.0, false);
  ASSERT_EQ(fast.row_source(), jet.row_source());
  Eigen::VectorXd rf, rj;
  Eigen::MatrixXd Jf, Jj;
  fast.Evaluate(&rf, &Jf);
  jet.Evaluate(&rj, &Jj);
  EXPECT_LT((rf - rj).cwiseAbs().maxCoeff(), 1e-12) << k.name();
  int setup_columns = 0;
  for (int c = 0; c < Jf.cols(); ++c) {
    const double scale = Jj.col(c).cwiseAbs().maxCoeff();
    for (int r = 0; r < Jf.rows(); ++r)
      ASSERT_NEAR(Jf(r, c), Jj(r, c), 1e-9 * (1.0 + std::abs(Jj(r, c)))) << k.name() << " " << table.names()[c];
    if (c >= table.num_machine() && scale > 0) ++setup_columns;
    // Central differences of the templated residual, with a step moving the
    // rows by at most about 1e-4 mm and a tenth of the parameter's plausible
    // size, so that the curvature (a degree-3 error motion turns by
    // theta * q^3, q up to hundreds of mm) does not show. The rounding of
    // rows of ~1e2 mm (1e-14 relative) over 2h bounds the agreement.
    const double h = scale > 0 ? std::min(1e-4 / scale, 0.1 * size[c]) : 0.1 * size[c];
    Eigen::VectorXd vp = values, vm = values;
    vp[c] += h;
    vm[c] -= h;
    Problem pp(ds, table, vp, all, "", 0.0, false), pm(ds, table, vm, all, "", 0.0, false);
    Eigen::VectorXd rp, rm;
    pp.Evaluate(&rp, nullptr);
    pm.Evaluate(&rm, nullptr);
    const Eigen::VectorXd fd = (rp - rm) / (2 * h);
    for (int r = 0; r < Jf.rows(); ++r)
      EXPECT_NEAR(fd[r], Jj(r, c), 1e-5 * scale + 1e-7 + 1e-13 / h) << k.name() << " row " << r << " " << table.names()[c];
  }
  // The kind's own setup parameters enter its residual.
  EXPECT_GT(setup_columns, 0) << k.name();
}

// The payload rule (payloads.h): an observation holds its kind's struct
// whichever way it was made (simulated, loaded by the streaming loader or
// the document parser), and asking it for another struct, or handing a kind
// an observation with another, is a std::invalid_argument naming the type,
// never a std::bad_variant_access.
TEST_P(EveryKind, PayloadIsItsKindsStructAfterLoad) {
  const ObservationKind& k = *GetParam();
  const ObservationPayload expected = k.NewPayload();
  const Dataset simulated = Simulate(SpecOf(k));
  const std::string text = simulated.ToJson();
  // The streaming loader, and the document parser (which observations
  // before the machine send the file to).
  json head = json::parse(text);
  const std::string observations = head["observations"].dump();
  head.erase("observations");
  const Dataset streamed = Dataset::FromJson(text);
  const Dataset parsed = Dataset::FromJson("{\"observations\": " + observations + ", " + head.dump().substr(1));
  for (const Dataset* ds : {&simulated, &streamed, &parsed}) {
    ASSERT_FALSE(ds->observations.empty());
    for (const Observation& o : ds->observations)
      EXPECT_EQ(o.payload.index(), expected.index())
          << k.name() << " holds " << PayloadName(o.payload) << ", its kind makes " << PayloadName(expected);
  }
  // A struct the kind does not hold.
  const bool own = std::holds_alternative<KindOwnData>(expected);
  const std::string quoted = "'" + std::string(k.name()) + "'";
  Observation o = streamed.observations[0];
  try {
    if (own) (void)o.data<TouchData>();
    else (void)o.data<KindOwnData>();
    ADD_FAILURE() << k.name() << ": data<> of a struct it does not hold returned";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("of type " + quoted), std::string::npos) << msg;
    EXPECT_NE(msg.find(PayloadName(expected)), std::string::npos) << msg;
    EXPECT_NE(msg.find(own ? "not TouchData" : "not KindOwnData"), std::string::npos) << msg;
  }
  // An observation built in code with another kind's payload: refused by
  // the checks, naming the type, before any residual reads it.
  Dataset bad = streamed;
  if (own) bad.observations[0].payload = TouchData{};
  else bad.observations[0].payload = KindOwnData{};
  try {
    bad.Validate();
    ADD_FAILURE() << k.name() << ": an observation holding the wrong payload was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("of type " + quoted), std::string::npos) << e.what();
  }
}

TEST_P(EveryKind, FileFieldsRoundTrip) {
  const ObservationKind& k = *GetParam();
  Dataset ds = Simulate(SpecOf(k));
  // A declared noise per row, different per row when there are several.
  ds.observations[0].sigma = Eigen::VectorXd::LinSpaced(k.rows(), 0.002, 0.002 * k.rows());
  const std::string saved = ds.ToJson();
  const json j = json::parse(saved);
  const std::vector<const char*> keys = k.json_keys();
  for (const json& o : j["observations"]) {
    EXPECT_EQ(o["type"], k.name());
    for (auto it = o.begin(); it != o.end(); ++it)
      EXPECT_TRUE(std::any_of(keys.begin(), keys.end(), [&](const char* key) { return it.key() == key; }))
          << k.name() << " writes key " << it.key() << " it does not read";
  }
  const Dataset back = Dataset::FromJson(saved);
  ASSERT_EQ(back.observations.size(), ds.observations.size());
  EXPECT_EQ(back.ToJson(), saved);
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation &a = ds.observations[i], &b = back.observations[i];
    EXPECT_EQ(a.type, b.type);
    EXPECT_EQ(a.setup, b.setup);
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.axes, b.axes);
    EXPECT_EQ(a.direction, b.direction);
    EXPECT_EQ(a.sigma, b.sigma);
    // Every payload field, bit for bit (the structs' operator==).
    EXPECT_EQ(a.payload.index(), b.payload.index()) << PayloadName(a.payload) << " came back as " << PayloadName(b.payload);
    EXPECT_TRUE(a.payload == b.payload) << k.name() << " observation " << i << ": payload changed";
  }
  // An unknown key is refused, naming the observation and the kind's keys.
  json bad = j;
  bad["observations"][0]["bogus_field"] = 1;
  try {
    Dataset::FromJson(bad.dump());
    ADD_FAILURE() << k.name() << ": unknown key accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("dataset.observations[0]: unknown key \"bogus_field\""), std::string::npos)
        << e.what();
  }
}

TEST_P(EveryKind, SetupParameterNamesHaveAShapeAndAPriorClass) {
  const ObservationKind& k = *GetParam();
  const Dataset ds = Simulate(SpecOf(k));
  const ParameterTable table(ds);
  ASSERT_GT(table.size(), table.num_machine()) << k.name() << " brings no setup parameter";
  // A dataset of the same machine without these parameters.
  const Dataset elsewhere(ds.machine());
  const ParameterTable other_table(elsewhere);
  std::set<std::string> classes;
  for (const PriorClass& c : PriorClasses()) classes.insert(c.name);
  for (int i = table.num_machine(); i < table.size(); ++i) {
    const std::string& name = table.names()[i];
    EXPECT_TRUE(classes.count(PriorClassOf(ds.machine(), name))) << name;
    if (other_table.Index(name) >= 0) continue;
    try {
      other_table.Require(name);
      ADD_FAILURE() << name;
    } catch (const std::invalid_argument& e) {
      // Named as a setup parameter of another dataset, not as a malformed name.
      EXPECT_NE(std::string(e.what()).find("not a setup parameter of this dataset"), std::string::npos)
          << name << ": " << e.what();
    }
  }
}

// ---- pose and distance: their own checks ---------------------------------

// The kBase machine with the given observations (no plan: recorded data).
json FixedFrameDataset(const json& observations) {
  json d = json::parse(kBase);
  d.erase("errors");
  d["observations"] = observations;
  return d;
}

json PoseAtZero(const Eigen::Vector3d& measured_rotation) {
  // Every rotary axis at 0, nominal instrument and target orientations 0:
  // with every parameter 0 the predicted orientation is exactly the identity.
  json o = {{"type", "pose"}, {"instrument", "T1"}, {"target", "tool"}, {"target_point", {0, 0, 100}},
            {"axes", {{"X", 10}, {"Y", -20}, {"Z", 5}, {"B", 0}, {"C", 0}}},
            {"measured", {10, -20, 105}},
            {"measured_rotation", {measured_rotation[0], measured_rotation[1], measured_rotation[2]}}};
  return o;
}

// GradientChecker on every residual block of `ds` at `values`, all setup
// parameters and the location errors estimated (their natural scale is 1: mm
// and rad), entry by entry: |J - numeric| <= 1e-6 |J| + 1e-9 x the row's largest.
void CheckGradients(const Dataset& ds, const Eigen::VectorXd& values, const std::string& what) {
  const ParameterTable table(ds);
  const Machine& m = ds.machine();
  std::vector<int> est;
  for (int i = 0; i < table.size(); ++i)
    if (i >= table.num_machine() || m.parameters()[i].kind == ParameterKind::kLocation) est.push_back(i);
  Problem problem(ds, table, values, est, "", 0.0, false);
  std::vector<ceres::ResidualBlockId> blocks;
  problem.ceres_problem().GetResidualBlocks(&blocks);
  ASSERT_EQ(blocks.size(), ds.observations.size()) << what;
  ceres::NumericDiffOptions nd;
  nd.ridders_relative_initial_step_size = 1e-3;
  for (size_t b = 0; b < blocks.size(); ++b) {
    const ceres::CostFunction* cost = problem.ceres_problem().GetCostFunctionForResidualBlock(blocks[b]);
    std::vector<double*> params;
    problem.ceres_problem().GetParameterBlocksForResidualBlock(blocks[b], &params);
    const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;  // all Euclidean
    ceres::GradientChecker checker(cost, no_manifolds, nd);
    ceres::GradientChecker::ProbeResults res;
    std::vector<const double*> cp(params.begin(), params.end());
    checker.Probe(cp.data(), 1e-6, &res);
    ASSERT_EQ(res.local_jacobians.size(), params.size()) << what << res.error_log;
    ASSERT_TRUE(res.residuals.allFinite()) << what;
    const int nr = cost->num_residuals();
    Eigen::VectorXd row_max = Eigen::VectorXd::Zero(nr);
    for (const auto& J : res.local_jacobians) row_max = row_max.cwiseMax(J.col(0).cwiseAbs());
    for (int i = 0; i < nr; ++i) EXPECT_GT(row_max[i], 0.0) << what << " row " << i << " sees no parameter";
    for (size_t k = 0; k < params.size(); ++k) {
      const int index = static_cast<int>(params[k] - problem.values().data());
      for (int i = 0; i < nr; ++i) {
        const double a = res.local_jacobians[k](i, 0), n = res.local_numeric_jacobians[k](i, 0);
        ASSERT_TRUE(std::isfinite(a)) << what << " row " << i << " " << table.names()[index];
        EXPECT_LE(std::abs(a - n), 1e-6 * std::max(std::abs(a), std::abs(n)) + 1e-9 * row_max[i])
            << what << " row " << i << " " << table.names()[index] << ": jet " << a << " numeric " << n;
      }
    }
  }
}

TEST(PoseKind, RotationRowsHaveRightDerivativesAtAndNearZeroRotation) {
  for (const Eigen::Vector3d& rot : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1e-9, -2e-9, 5e-10),
                                     Eigen::Vector3d(1e-4, 3e-5, -2e-4), Eigen::Vector3d(0.4, -1.2, 2.0)}) {
    const Dataset ds = Dataset::FromJson(FixedFrameDataset(json::array({PoseAtZero(rot)})).dump());
    const ParameterTable table(ds);
    Eigen::VectorXd values = Eigen::VectorXd::Zero(table.size());
    std::ostringstream what;
    what << "measured rotation " << rot.transpose();
    if (rot.isZero()) {
      // The residual's rotation rows are exactly zero here: the small-angle
      // branch of the logarithm is the one differentiated.
      Problem p(ds, table, values, All(table.size()), "", 0.0, false);
      Eigen::VectorXd r;
      p.Evaluate(&r, nullptr);
      ASSERT_EQ(r.size(), 6);
      EXPECT_EQ(r.tail(3), Eigen::Vector3d::Zero());
    }
    CheckGradients(ds, values, what.str());
  }
}

TEST(PoseKind, JacobianIsContinuousThroughZeroRotation) {
  // The Jet Jacobian at exactly zero misfit (the Taylor branch) equals the
  // one a nanoradian away (the general branch).
  Eigen::MatrixXd J[2];
  const Eigen::Vector3d rots[2] = {Eigen::Vector3d::Zero(), Eigen::Vector3d(1e-9, 1e-9, -1e-9)};
  for (int k = 0; k < 2; ++k) {
    const Dataset ds = Dataset::FromJson(FixedFrameDataset(json::array({PoseAtZero(rots[k])})).dump());
    const ParameterTable table(ds);
    Problem p(ds, table, Eigen::VectorXd::Zero(table.size()), All(table.size()), "", 0.0, false);
    Eigen::VectorXd r;
    p.Evaluate(&r, &J[k]);
  }
  EXPECT_LT((J[0] - J[1]).cwiseAbs().maxCoeff(), 1e-6 * J[0].cwiseAbs().maxCoeff());
}

TEST(DistanceKind, ResidualHasRightDerivatives) {
  json obs = json::array();
  const double stations[3][3] = {{800, -300, 200}, {-600, 500, 400}, {100, 900, -300}};
  for (int s = 0; s < 3; ++s)
    obs.push_back({{"type", "distance"}, {"station", "L" + std::to_string(s)}, {"target", s == 2 ? "work" : "tool"},
                   {"target_point", {10, 20, 100}}, {"reading", 12.5}, {"dead_length", 300},
                   {"station_position", {stations[s][0], stations[s][1], stations[s][2]}},
                   {"axes", {{"X", 30}, {"Y", -20}, {"Z", 5}, {"B", 25}, {"C", 140}}}});
  const Dataset ds = Dataset::FromJson(FixedFrameDataset(obs).dump());
  const ParameterTable table(ds);
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1e-3);
  Eigen::VectorXd values(table.size());
  for (int i = 0; i < table.size(); ++i) values[i] = i < table.num_machine() ? 0.0 : n(rng);
  for (int i = 0; i < table.num_machine(); ++i)
    if (ds.machine().parameters()[i].kind == ParameterKind::kLocation) values[i] = 0.01 * n(rng);
  CheckGradients(ds, values, "distance");
}

TEST(FixedFrameKinds, BadFieldsAreNamed) {
  auto refused = [](json o, const std::vector<std::string>& words) {
    try {
      Dataset::FromJson(FixedFrameDataset(json::array({o})).dump());
      ADD_FAILURE() << o.dump() << " accepted";
    } catch (const std::invalid_argument& e) {
      for (const std::string& w : words)
        EXPECT_NE(std::string(e.what()).find(w), std::string::npos) << e.what() << " lacks " << w;
    }
  };
  const json pose = PoseAtZero(Eigen::Vector3d(0.1, 0.2, 0.3));
  json o = pose;
  o.erase("measured_rotation");
  refused(o, {"observations[0].measured_rotation"});
  o = pose;
  o["measured_rotation"] = {0, 0, 7};
  refused(o, {"observations[0].measured_rotation"});
  o = pose;
  o["target_rotation"] = {0, 0};
  refused(o, {"observations[0].target_rotation"});
  o = pose;
  o["sigma"] = 0.01;  // rows in mm and rad: one number cannot be both
  refused(o, {"observations[0].sigma", "mm, mm, mm, rad, rad, rad", "6 values"});
  o = pose;
  o["sigma"] = {0.01, 0.01, 0.01, 1e-4, 1e-4, 0};
  refused(o, {"observations[0].sigma[5]", "rad"});
  const json dist = {{"type", "distance"}, {"station", "L1"}, {"target", "tool"}, {"target_point", {0, 0, 100}},
                     {"reading", 1.0}, {"station_position", {500, 0, 0}},
                     {"axes", {{"X", 0}, {"Y", 0}, {"Z", 0}, {"B", 0}, {"C", 0}}}};
  for (const char* key : {"station", "reading", "station_position", "target", "target_point"}) {
    o = dist;
    o.erase(key);
    refused(o, {std::string("observations[0].") + key});
  }
  o = dist;
  o["dead_length"] = "300";
  refused(o, {"observations[0].dead_length"});
  o = dist;
  o["station"] = "L.1";
  refused(o, {"observations[0].station"});
  o = dist;
  o["setup"] = "L1";  // a distance names its station, not a mounting
  refused(o, {"observations[0]: unknown key \"setup\""});
  // One id for a station and a tracker: instrument.T1.x would be both.
  o = dist;
  o["station"] = "T1";
  try {
    Dataset::FromJson(FixedFrameDataset(json::array({pose, o})).dump());
    ADD_FAILURE() << "station named like a tracker accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("observations[1].station: 'T1' is also the instrument of observations[0]"),
              std::string::npos) << e.what();
  }
}

TEST(FixedFrameKinds, InstrumentSigmaIsTheDefaultOfItsObservations) {
  json d = FixedFrameDataset(json::array({PoseAtZero(Eigen::Vector3d(0.1, 0.2, 0.3)), PoseAtZero(Eigen::Vector3d::Zero())}));
  d["observations"][1]["sigma"] = {1, 2, 3, 4e-3, 5e-3, 6e-3};
  Dataset ds = Dataset::FromJson(d.dump());
  // No declaration: the kind's per-row default, mm then rad.
  EXPECT_EQ(ObservationSigma(ds, ds.observations[0], 0), PoseKind().default_sigma_row(0));
  EXPECT_EQ(ObservationSigma(ds, ds.observations[0], 4), PoseKind().default_sigma_row(4));
  EXPECT_LT(PoseKind().default_sigma_row(4), PoseKind().default_sigma_row(0));
  d["instruments"] = {{"T1", {{"sigma", {0.1, 0.2, 0.3, 1e-4, 2e-4, 3e-4}}}}};
  ds = Dataset::FromJson(d.dump());
  EXPECT_EQ(ObservationSigma(ds, ds.observations[0], 2), 0.3);
  EXPECT_EQ(ObservationSigma(ds, ds.observations[0], 5), 3e-4);
  EXPECT_EQ(ObservationSigma(ds, ds.observations[1], 5), 6e-3);  // its own wins
  EXPECT_EQ(Dataset::FromJson(ds.ToJson()).instrument_sigma, ds.instrument_sigma);
  EXPECT_EQ(ds.Subset({1}).instrument_sigma, ds.instrument_sigma);
  d["instruments"] = {{"T1", {{"sigma", 0.01}}}};  // one number for mm and rad rows
  try {
    Dataset::FromJson(d.dump());
    ADD_FAILURE() << "one number for a pose instrument accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("dataset.instruments.T1.sigma: 1 value for a pose instrument"),
              std::string::npos) << e.what();
  }
}

TEST(FixedFrameKinds, SimulatedPoseNoiseIsWhatItDeclares) {
  // A rotation input is a rotation of the reading about a target axis: at
  // the truth its residual row moves by exactly minus the input, whatever the
  // measured orientation.
  json spec = json::parse(kBase);
  spec["plan"] = json::parse(kSamples.at("pose").plan);
  spec["setup"] = json::parse(kSamples.at("pose").setup);
  spec["sigma"] = {{"pose", 0.01}, {"pose_angle", 1e-4}};
  const SimulationPlan plan = BuildSimulationPlan(spec.dump());
  ASSERT_EQ(plan.num_inputs(), 18);
  EXPECT_EQ(plan.base.observations[0].sigma, (Eigen::VectorXd(6) << 0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-4).finished());
  Eigen::VectorXd dev = Eigen::VectorXd::Zero(18);
  dev[4] = 3e-4;   // observation 0, rotation row 1
  dev[15] = -2e-4; // observation 2, rotation row 0
  const Dataset noisy = ApplyInputDeviations(plan, dev);
  const ParameterTable table(noisy);
  Eigen::VectorXd truth = Eigen::VectorXd::Zero(table.size());
  for (const auto& [name, value] : plan.values) truth[table.Require(name)] = value;
  Problem p(noisy, table, truth, All(table.size()), "", 0.0, false);
  Eigen::VectorXd r;
  p.Evaluate(&r, nullptr);
  EXPECT_LT((r - dev).cwiseAbs().maxCoeff(), 1e-10) << r.transpose();
  // A number sets the mm levels only.
  spec["sigma"] = 0.002;
  const SimulationPlan mm = BuildSimulationPlan(spec.dump());
  EXPECT_EQ(mm.base.observations[0].sigma[0], 0.002);
  EXPECT_EQ(mm.base.observations[0].sigma[3], PoseKind().default_sigma_row(3));
}

TEST(FixedFrameKinds, PoseNoiseDrawnAgainIntoOneDatasetIsAFreshDraw) {
  // A pose composes its rotation inputs onto the current reading: a dataset
  // realised again in place (Monte Carlo trials) must start from the
  // noise-free reading, not from the previous trial's.
  json spec = json::parse(kBase);
  spec["plan"] = json::parse(kSamples.at("pose").plan);
  spec["setup"] = json::parse(kSamples.at("pose").setup);
  spec["sigma"] = {{"pose", 0.01}, {"pose_angle", 1e-3}};
  const SimulationPlan plan = BuildSimulationPlan(spec.dump());
  Dataset reused = plan.base;
  for (uint64_t seed : {7u, 8u, 9u}) {
    AddNoiseInto(plan, seed, &reused);
    const Dataset fresh = AddNoise(plan, seed);
    for (size_t i = 0; i < fresh.observations.size(); ++i) {
      const PoseTargetData &a = reused.observations[i].data<PoseTargetData>(),
                           &b = fresh.observations[i].data<PoseTargetData>();
      EXPECT_EQ(a.measured_rotation, b.measured_rotation) << seed << " " << i;
      EXPECT_EQ(a.measured, b.measured) << seed << " " << i;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Registry, EveryKind, ::testing::ValuesIn(ObservationKinds()),
                         [](const ::testing::TestParamInfo<const ObservationKind*>& info) {
                           return std::string(info.param->name());
                         });

}  // namespace
}  // namespace fivecal
