// The analytic batch residuals (one Ceres block, KinematicModel derivatives)
// against the per-observation functors with automatic derivatives: same rows,
// same residuals, same Jacobian, for every observation type.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "fivecal/solve/identify.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

const char* kSpec = R"({
 "machine": {"name": "hu40t", "topology": "wCBXfZYSt", "axes": {
   "X": {"type": "linear", "direction": [-1,0,0]},
   "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
   "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
   "Z": {"type": "linear", "direction": [0,0,1]}, "Y": {"type": "linear", "direction": [0,1,0]},
   "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}}, "tool": {"tip": [0,0,100]}},
 "probe": {"tip_radius": 3.0},
 "artefact": {"facets": [{"id": "T", "point": [10,20,0], "normal": [0,0,1]},
                         {"id": "E", "point": [150,0,-20], "normal": [1,0,0]},
                         {"id": "N", "point": [0,150,-20], "normal": [0,1,0]}],
              "spheres": [{"id": "S1", "center": [-100,0,30], "radius": 12.7},
                          {"id": "S2", "center": [100,0,30], "radius": 12.7}],
              "scale_bars": [{"spheres": ["S1","S2"], "length": 200}]},
 "errors": {"EX0C": -0.1, "EA0C": 2e-5, "EB0C": 1e-5, "EA0B": -1e-5, "EC0B": 2e-5, "EB0Z": 7e-5,
            "EXX1": 1e-5, "EYY1": -2e-5, "EXX2": 1e-8, "EAC1": 3e-6, "EZB2": 2e-4, "ECX3": 1e-12,
            "EXXb": 0.003, "ECCb": -4e-5, "EBBb": 3e-5, "tip.x": 0.01, "tip.z": -0.02, "EX0S": -0.13},
 "setup": {"facet.T": 0.01, "sphere.S1.x": 0.002, "dbb.length": 0.003, "dbb.tool.x": 0.001,
           "dbb.table.y": -0.002, "ball3d.R1.tool.z": 0.004, "ball3d.R1.table.x": 0.001},
 "plan": [
  {"type": "facet", "target": "T", "axes": {"B": 0, "C": 0, "S": 0}, "direction": {"B": 1, "C": -1}},
  {"type": "facet", "target": "T", "axes": {"B": 0, "C": 90, "S": 90}},
  {"type": "facet", "target": "E", "axes": {"B": 30, "C": 0}, "direction": {"B": -1, "C": 1}},
  {"type": "facet", "target": "N", "axes": {"B": 0, "C": -45}, "direction": {"C": 1}},
  {"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [0,0,1]},
  {"type": "sphere", "target": "S1", "axes": {"B": 0, "C": 0}, "normal": [1,0,1]},
  {"type": "sphere", "target": "S2", "axes": {"B": 0, "C": 0}, "normal": [-1,1,1]},
  {"type": "dbb", "axes": {"X": 10, "Y": 20, "Z": -50, "B": 20, "C": 40}, "length": 100,
   "tool_ball": [0,0,100], "table_ball": [50,0,0], "direction": {"C": 1, "X": -1}},
  {"type": "ball3d", "setup": "R1", "axes": {"X": -30, "Y": 5, "Z": 10, "B": -40, "C": 200},
   "tool_ball": [0,0,100], "table_ball": [0,60,20], "direction": {"Y": 1}}],
 "sigma": 0.0005, "seed": 4})";

TEST(AnalyticResiduals, MatchAutodiffFunctorsForEveryObservationType) {
  const Dataset ds = Simulate(kSpec);
  const ParameterTable table(ds);
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0.0, 1.0);
  // A point away from zero for every parameter (realistic magnitudes).
  Eigen::VectorXd values(table.size());
  const Machine& m = ds.machine();
  for (int i = 0; i < table.size(); ++i) {
    double s = 1e-3;
    if (i < m.num_parameters()) {
      const ParameterInfo& p = m.parameters()[i];
      const double range = p.axis >= 0 && m.axis(p.axis).rotary() ? 3.0 : 300.0;
      s = (p.angular() ? 1e-5 : 1e-3) / (p.kind == ParameterKind::kMotion ? std::pow(range, p.degree) : 1.0);
    }
    values[i] = s * n(rng);
  }
  std::vector<int> all(table.size());
  for (int i = 0; i < table.size(); ++i) all[i] = i;
  Problem fast(ds, table, values, all, "", 0.0, true);
  Problem ref(ds, table, values, all, "", 0.0, false);
  ASSERT_EQ(fast.num_rows(), ref.num_rows());
  EXPECT_EQ(fast.row_source(), ref.row_source());
  Eigen::VectorXd rf, rr;
  Eigen::MatrixXd Jf, Jr;
  fast.Evaluate(&rf, &Jf);
  ref.Evaluate(&rr, &Jr);
  EXPECT_LT((rf - rr).cwiseAbs().maxCoeff(), 1e-12);
  int compared = 0;
  for (int c = 0; c < Jf.cols(); ++c)
    for (int r = 0; r < Jf.rows(); ++r) {
      EXPECT_NEAR(Jf(r, c), Jr(r, c), 1e-9 * (1.0 + std::abs(Jr(r, c))))
          << table.names()[all[c]] << " row " << r;
      compared += Jr(r, c) != 0.0;
    }
  EXPECT_GT(compared, 500);  // the comparison covers real derivatives
}

TEST(AnalyticResiduals, IdentifyGivesTheSameFitAsTheFunctors) {
  const Dataset ds = Simulate(kSpec);
  IdentifyOptions o;
  o.estimate = {"EX0C", "EB0C", "EXXb", "facet.T"};
  o.include_default_setup = false;  // 12 rows: keep the fit small
  const Result a = Identify(ds, o);   // analytic (no robust loss)
  o.robust = "huber";
  o.robust_scale = 1.0;                // 1 mm: quadratic everywhere, same optimum
  const Result b = Identify(ds, o);   // functors
  ASSERT_EQ(a.estimated, b.estimated);
  // Both converge to the same optimum: far inside its statistical uncertainty.
  for (size_t i = 0; i < a.estimated.size(); ++i) {
    const int k = static_cast<int>(std::find(a.names.begin(), a.names.end(), a.estimated[i]) - a.names.begin());
    EXPECT_LT(std::abs(a.values[k] - b.values[k]), 1e-3 * a.std[i]) << a.estimated[i];
  }
}

}  // namespace
}  // namespace fivecal
