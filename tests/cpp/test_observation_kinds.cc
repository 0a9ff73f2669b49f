// Every registered observation kind (observations/registry.cc), the same
// checks: its templated residual against the analytic batch and against
// central finite differences, its simulation giving zero residuals at the
// truth, and its file fields surviving load -> save -> load. A new kind gets
// these by adding a sample plan entry below (the test fails without one).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

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

// Per kind: plan entries and the true values of the setup parameters they bring.
struct Sample {
  const char* plan;
  const char* setup;
};
const std::map<std::string, Sample> kSamples = {
    {"facet",
     {R"([{"type": "facet", "target": "T", "axes": {"B": 0, "C": 0, "S": 0}, "direction": {"B": 1, "C": -1}},
          {"type": "facet", "target": "T", "axes": {"B": 0, "C": 90, "S": 90}, "id": "t2"},
          {"type": "facet", "target": "E", "axes": {"B": 30, "C": 0}, "direction": {"B": -1, "C": 1}}])",
      R"({"facet.T": 0.01, "facet.E": -0.004})"}},
    {"sphere",
     {R"([{"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [0,0,1]},
          {"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [1,0,1]},
          {"type": "sphere", "target": "S2", "axes": {"B": 0, "C": 30}, "normal": [-1,1,1]}])",
      R"({"sphere.S1.x": 0.002, "sphere.S2.z": -0.003, "sphere.S1.r": 0.001})"}},
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
    EXPECT_EQ(a.target, b.target);
    EXPECT_EQ(a.setup, b.setup);
    EXPECT_EQ(a.id, b.id);
    EXPECT_EQ(a.axes, b.axes);
    EXPECT_EQ(a.direction, b.direction);
    EXPECT_EQ(a.reading, b.reading);
    EXPECT_EQ(a.length, b.length);
    EXPECT_EQ(a.tool_ball, b.tool_ball);
    EXPECT_EQ(a.table_ball, b.table_ball);
    EXPECT_EQ(a.measured, b.measured);
    EXPECT_EQ(a.sigma, b.sigma);
    ASSERT_EQ(a.own.size(), b.own.size());
    for (const auto& [key, v] : a.own) {
      ASSERT_TRUE(b.own.count(key)) << key;
      EXPECT_EQ(v.size(), b.own.at(key).size()) << key;
      if (v.size() == b.own.at(key).size()) EXPECT_EQ(v, b.own.at(key)) << key;
    }
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

INSTANTIATE_TEST_SUITE_P(Registry, EveryKind, ::testing::ValuesIn(ObservationKinds()),
                         [](const ::testing::TestParamInfo<const ObservationKind*>& info) {
                           return std::string(info.param->name());
                         });

}  // namespace
}  // namespace fivecal
