// Double ball bar algorithms: circle fits (Jiang & Cripps eqs. 5-8), the
// four-step test against simulated C600U-like readings, the Wang et al.
// path on the VMC0656-like table, planar circular tests (ISO 230-4 values
// and the least-squares diagnosis) and trace harmonics.
//
// Truth tests simulate known errors with the virtual machine (simulate.h)
// and check the recovery; the tolerances are the measured approximation
// errors of docs/dbb.md or 3 sigma with noise.
#include <gtest/gtest.h>

#include "test_files.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <functional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "fivecal/procedures/circle_fit.h"
#include "fivecal/procedures/circular_test.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/procedures/dbb_four_step.h"
#include "fivecal/procedures/dbb_setup.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/machine.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/procedures/wang_path.h"

namespace fivecal {
namespace {

using nlohmann::json;
constexpr double kPi = 3.14159265358979323846;
constexpr double kUm = 1e-3, kUrad = 1e-6;

json MachineJson(const char* name) {
  return json::parse(ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/" + name));
}

// Jiang & Cripps Tables 2-3 sizes: positions as printed (mm), orientations
// read as arc-seconds (examples/machines/README.md).
std::map<std::string, double> PaperPiges() {
  const double arcsec = kPi / (180.0 * 3600.0);
  return {{"EY0A", 0.0342},          {"EZ0A", -0.0353},         {"EB0A", 6.62 * arcsec},
          {"EC0A", 1.89 * arcsec},   {"EX0C", 0.0013},          {"EY0C", -0.0525},
          {"EA0C", -22.32 * arcsec}, {"EB0C", -3.75 * arcsec}};
}

Dataset SimulateFourStep(const std::map<std::string, double>& errors, double sigma, int seed,
                         const std::map<std::string, double>& setup = {}) {
  const json mj = MachineJson("c600u.json");
  const Machine m = Machine::FromJson(mj.dump());
  json spec = {{"machine", mj}, {"errors", errors}, {"setup", setup},
               {"plan", json::parse(FourStepPlanJson(m))}, {"sigma", {{"dbb", sigma}}}, {"seed", seed}};
  return Simulate(spec.dump());
}

// ---- circle fits -----------------------------------------------------------

TEST(CircleFit, AlgebraicAndGeometricRecoverAnExactCircle) {
  for (double sweep : {2 * kPi, kPi / 2}) {  // full circle and the A test's quarter arc
    Eigen::MatrixXd p(91, 2);
    for (int i = 0; i < 91; ++i) {
      const double t = -0.3 + sweep * i / 90.0;
      p.row(i) << 0.0342 + 99.99 * std::cos(t), -0.0353 + 99.99 * std::sin(t);
    }
    for (const CircleFit& f : {FitCircleAlgebraic(p), FitCircleGeometric(p)}) {
      EXPECT_NEAR(f.centre.x(), 0.0342, 1e-10);
      EXPECT_NEAR(f.centre.y(), -0.0353, 1e-10);
      EXPECT_NEAR(f.radius, 99.99, 1e-10);
      EXPECT_LT(f.rms, 1e-10);
    }
  }
}

TEST(CircleFit, CovarianceMatchesTheScatterOfRepeatedFits) {
  // The first-order covariance must predict the spread of centres over
  // noisy repetitions of a quarter arc (the A steps), within 20 %.
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.0005);
  std::vector<double> cx;
  double predicted = 0;
  for (int rep = 0; rep < 300; ++rep) {
    Eigen::MatrixXd p(91, 2);
    for (int i = 0; i < 91; ++i) {
      const double t = kPi / 2 * i / 90.0, r = 100 + noise(rng);
      p.row(i) << r * std::cos(t), r * std::sin(t);
    }
    const CircleFit f = FitCircleAlgebraic(p);
    cx.push_back(f.centre.x());
    predicted += std::sqrt(f.covariance(0, 0)) / 300;
  }
  double mean = 0, var = 0;
  for (double x : cx) mean += x / cx.size();
  for (double x : cx) var += (x - mean) * (x - mean) / (cx.size() - 1);
  EXPECT_NEAR(std::sqrt(var) / predicted, 1.0, 0.2);
}

TEST(CircleFit, RejectsTooFewOrCollinearPoints) {
  Eigen::MatrixXd two(2, 2);
  two << 0, 0, 1, 1;
  EXPECT_THROW(FitCircleAlgebraic(two), std::invalid_argument);
  Eigen::MatrixXd line(5, 2);
  for (int i = 0; i < 5; ++i) line.row(i) << i, 2.0 * i;
  try {
    FitCircleAlgebraic(line, "A1 fit");
    ADD_FAILURE() << "collinear points accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("A1 fit"), std::string::npos);
  }
}

// ---- Jiang & Cripps four-step test -----------------------------------------

TEST(FourStep, RecoversThePaperSizedPigesWithoutNoise) {
  const auto truth = PaperPiges();
  const FourStepResult r = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1));
  ASSERT_EQ(r.names.size(), 8u);
  for (const auto& [n, v] : truth) {
    // Approximation error at these sizes (docs/dbb.md): < 0.05 um, < 0.05 urad.
    const double tol = n[1] == 'A' || n[1] == 'B' || n[1] == 'C' ? 0.05 * kUrad : 0.05 * kUm;
    EXPECT_NEAR(r.Get(n), v, tol) << n;
  }
  EXPECT_LT(r.a_delta, 1e-9);  // eq. 20: negligible, as the paper says
  EXPECT_LT(r.c_delta, 1e-9);
  for (const FourStepStep& s : r.steps) EXPECT_LT(s.rms, 1e-4) << s.setup;
}

TEST(FourStep, FourStepAndEngineBothRecoverTheTruthWithNoise) {
  const auto truth = PaperPiges();
  for (int seed : {1, 2}) {
    const Dataset ds = SimulateFourStep(truth, 0.0003, seed);
    const FourStepResult r = AnalyzeFourStep(ds);
    IdentifyOptions opt;
    opt.estimate = FourStepParameterNames();
    const Result e = Identify(ds, opt);
    ASSERT_TRUE(e.converged);
    for (size_t i = 0; i < r.names.size(); ++i) {
      const std::string& n = r.names[i];
      EXPECT_LT(std::abs(r.values[i] - truth.at(n)), 3 * r.std[i]) << "four-step " << n;
      const auto it = std::find(e.estimated.begin(), e.estimated.end(), n);
      ASSERT_NE(it, e.estimated.end());
      const int k = static_cast<int>(it - e.estimated.begin());
      const int j = static_cast<int>(std::find(e.names.begin(), e.names.end(), n) - e.names.begin());
      EXPECT_LT(std::abs(e.values[j] - truth.at(n)), 3 * e.std[k]) << "engine " << n;
      // Both see the same readings: their uncertainties agree within a factor 1.5.
      EXPECT_NEAR(r.std[i] / e.std[k], 1.0, 0.5) << n;
    }
  }
}

// Where the four-step approximations break (docs/dbb.md, "Four-step
// approximations"): the error grows with the square of the tilt.
TEST(FourStep, OrientationApproximationErrorGrowsQuadratically) {
  const auto paper = PaperPiges();
  double err_at[3];
  const double scale[3] = {10, 30, 100};  // 1.1, 3.2, 10.8 mrad largest tilt
  for (int k = 0; k < 3; ++k) {
    auto truth = paper;
    for (auto& [n, v] : truth)
      if (n[1] == 'A' || n[1] == 'B' || n[1] == 'C') v *= scale[k];
    const FourStepResult r = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1));
    err_at[k] = 0;
    for (const auto& [n, v] : truth)
      if (n[1] == 'A' || n[1] == 'B' || n[1] == 'C') err_at[k] = std::max(err_at[k], std::abs(r.Get(n) - v));
  }
  EXPECT_LT(err_at[0], 1.0 * kUrad);   // ~1 mrad: below 1 urad
  EXPECT_LT(err_at[1], 5.0 * kUrad);   // ~3 mrad: the paper's 1" (4.8 urad) repeatability
  EXPECT_GT(err_at[2], 10.0 * kUrad);  // ~10 mrad: the method has broken down
  EXPECT_GT(err_at[2] / err_at[0], 30.0);
}

TEST(FourStep, LargePositionErrorsOvaliseTheCircleFit) {
  auto truth = PaperPiges();
  for (auto& [n, v] : truth)
    if (n[1] == 'X' || n[1] == 'Y' || n[1] == 'Z') v *= 10;  // 0.34 - 0.53 mm
  const FourStepResult r = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1));
  // e^2/R: (0.525 mm)^2 / 100 mm ~ 2.8 um (Zargarbashi & Mayer, the paper's ref. [28]).
  EXPECT_GT(std::abs(r.Get("EY0A") - truth["EY0A"]), 1.0 * kUm);
  EXPECT_LT(std::abs(r.Get("EY0A") - truth["EY0A"]), 4.0 * kUm);
}

TEST(FourStep, SpindleBallPlacementErrorBecomesAnOrientationError) {
  // 1 um of lateral error of the spindle ball in the extension step tilts the
  // measured axis by 1 um / |S'O'| = 1/111.8 mm = 8.94 urad.
  const auto truth = PaperPiges();
  const FourStepResult r0 = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1));
  const FourStepResult r1 = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1, {{"dbb.A2.tool.y", 0.001}}));
  const FourStepResult r2 = AnalyzeFourStep(SimulateFourStep(truth, 0.0, 1, {{"dbb.C2.tool.x", 0.001}}));
  EXPECT_NEAR(r1.Get("EC0A") - r0.Get("EC0A"), 0.001 / std::sqrt(150.0 * 150 - 100 * 100), 0.05 * kUrad);
  EXPECT_NEAR(r2.Get("EB0C") - r0.Get("EB0C"), -0.001 / std::sqrt(150.0 * 150 - 100 * 100), 0.05 * kUrad);
}

TEST(FourStep, StartAngleCorrectionRemovesAPivotOffset) {
  const auto truth = PaperPiges();
  // The C pivot 1 mm off along Y (tangential at the start): uncorrected, the
  // fitted centres turn by d_e = 10 mrad; eq. 1 with P0P0' = (0, 1) mm undoes it.
  const Dataset ds = SimulateFourStep(truth, 0.0, 1, {{"dbb.C1.table.y", 1.0}, {"dbb.C2.table.y", 1.0}});
  FourStepOptions corrected;
  corrected.c_pivot_offset = Eigen::Vector2d(0.0, 1.0);
  const FourStepResult raw = AnalyzeFourStep(ds), fixed = AnalyzeFourStep(ds, corrected);
  EXPECT_NEAR(fixed.steps[2].start_angle_error, std::atan(1.0 / 100.0), 1e-12);
  EXPECT_GT(std::abs(raw.Get("EB0C") - truth.at("EB0C")), 0.5 * kUrad);
  EXPECT_NEAR(fixed.Get("EB0C"), truth.at("EB0C"), 0.05 * kUrad);
  EXPECT_NEAR(fixed.Get("EX0C"), truth.at("EX0C"), 0.01 * kUm);
}

TEST(FourStep, PositionOnlyRemovalLeavesTheATiltInC) {
  // The paper's text removes A's position from C; A's tilt EB0A then stays in EB0C.
  const auto truth = PaperPiges();
  const Dataset ds = SimulateFourStep(truth, 0.0, 1);
  FourStepOptions pos;
  pos.a_removal = ARemoval::kPositionOnly;
  FourStepOptions none;
  none.a_removal = ARemoval::kNone;
  EXPECT_NEAR(AnalyzeFourStep(ds, pos).Get("EB0C") - truth.at("EB0C"), truth.at("EB0A"), 0.1 * kUrad);
  EXPECT_NEAR(AnalyzeFourStep(ds, none).Get("EY0C") - truth.at("EY0C"), truth.at("EY0A"), 0.1 * kUm);
  // Not referring the A position from the pivot plane (100 mm along A) to the
  // axis point leaves the tilt x 100 mm in it.
  FourStepOptions local;
  local.refer_positions = false;
  EXPECT_NEAR(AnalyzeFourStep(ds, local).Get("EZ0A") - truth.at("EZ0A"), -100.0 * truth.at("EB0A"),
              0.1 * kUm);
}

TEST(FourStep, RejectsSetupsTheEquationsDoNotDescribe) {
  const Dataset ds = SimulateFourStep(PaperPiges(), 0.0, 1);
  FourStepOptions o;
  o.c_setup = "C9";
  try {
    AnalyzeFourStep(ds, o);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'C9'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("A1, A2, C1, C2"), std::string::npos) << e.what();
  }
  FourStepPlanOptions p;
  p.a_pivot = Eigen::Vector3d(100, 90, 0);  // 90 mm from the A axis with a 100 mm bar
  const Machine m = Machine::FromJson(MachineJson("c600u.json").dump());
  EXPECT_THROW(FourStepPlanJson(m, p), std::invalid_argument);
  // The KX8-like A axis is at 45 deg: no plane basis of the method.
  const Machine kx8 = Machine::FromJson(MachineJson("kx8.json").dump());
  try {
    FourStepPlanJson(kx8);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("not along X, Y or Z"), std::string::npos) << e.what();
  }
  // Parallel rotary axes.
  json par = MachineJson("c600u.json");
  par["axes"]["A"]["direction"] = {0, 0, 1};
  try {
    FourStepPlanJson(Machine::FromJson(par.dump()));
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("parallel"), std::string::npos) << e.what();
  }
}

// Other pairs: the paper's sizes given by role (carrier = the paper's A,
// carried = its C); noise-free error within the per-configuration
// approximation of docs/dbb.md, and with noise within 3 sigma, as the engine.
TEST(FourStep, OtherPairsRecoverTheTruth) {
  json ac = MachineJson("c600u.json");  // A tilting table carried by a C table
  ac["topology"] = "wACfXYZSt";
  ac["axes"]["C"]["direction"] = {0, 0, 1};
  ac["axes"]["A"]["direction"] = {1, 0, 0};
  ac["axes"]["A"]["point"] = {0, 0, 80};
  for (const json& mj : {MachineJson("hu40t.json"), ac}) {
    const Machine m = Machine::FromJson(mj.dump());
    const std::vector<std::string> names = FourStepParameterNames(m);
    const std::vector<double> role = {0.0342, -0.0353, 45e-6, -30e-6, 0.0013, -0.0525, -108e-6, 25e-6};
    std::map<std::string, double> truth;
    for (int i = 0; i < 8; ++i) truth[names[i]] = role[i];
    for (double sigma : {0.0, 0.0003}) {
      json spec = {{"machine", mj}, {"errors", truth}, {"plan", json::parse(FourStepPlanJson(m))},
                   {"sigma", {{"dbb", sigma}}}, {"seed", 5}};
      const Dataset ds = Simulate(spec.dump());
      const FourStepResult r = AnalyzeFourStep(ds);
      ASSERT_EQ(r.names, names);
      IdentifyOptions opt;
      opt.estimate = names;
      const Result e = Identify(ds, opt);
      ASSERT_TRUE(e.converged);
      for (int i = 0; i < 8; ++i) {
        const std::string& n = names[i];
        const bool ang = n[1] == 'A' || n[1] == 'B' || n[1] == 'C';
        if (sigma == 0.0) {
          EXPECT_NEAR(r.values[i], truth[n], ang ? 0.3 * kUrad : 0.05 * kUm) << m.name() << " " << n;
        } else {
          EXPECT_LT(std::abs(r.values[i] - truth[n]), 3 * r.std[i]) << m.name() << " " << n;
          const int j = static_cast<int>(std::find(e.names.begin(), e.names.end(), n) - e.names.begin());
          EXPECT_LT(std::abs(r.values[i] - e.values[j]), r.std[i]) << m.name() << " engine " << n;
        }
      }
    }
  }
}

// ---- Wang et al. path --------------------------------------------------------

TEST(WangPath, KeepsTheTableBallOnTheCircle) {
  const Machine m = Machine::FromJson(MachineJson("vmc0656.json").dump());
  for (const auto& [ball, rho, h] :
       std::vector<std::tuple<Eigen::Vector3d, double, double>>{
           {Eigen::Vector3d(0, 150, 130), 80, 60}, {Eigen::Vector3d(0, 150, 130), 100, 0},
           {Eigen::Vector3d(20, 120, 160), 60, 40}}) {
    WangPathOptions o;
    o.table_ball = ball;
    o.radius = rho;
    o.height = h;
    o.step = 0.5;
    const WangPath p = ComputeWangPath(m, o);
    EXPECT_LT(p.max_circle_error, 1e-9);
    EXPECT_NEAR(p.bar_length, std::hypot(rho, h), 1e-12);
    // The whole path moves in small steps: no branch jump.
    for (int i = 1; i < p.tilt.size(); ++i) {
      EXPECT_LT(std::abs(p.tilt[i] - p.tilt[i - 1]), 2.0);
      EXPECT_LT(std::abs(p.rotary[i] - p.rotary[i - 1]), 2.0);
    }
  }
}

TEST(WangPath, AxesReverseWhereThePaperSays) {
  // A reverses at phi = 90, 270 deg, C at 180, 360 deg (Section 3).
  const Machine m = Machine::FromJson(MachineJson("vmc0656.json").dump());
  const WangPath p = ComputeWangPath(m);
  std::vector<double> a_rev, c_rev;
  for (int i = 1; i + 1 < p.tracking.size(); ++i) {
    if ((p.tilt[i] - p.tilt[i - 1]) * (p.tilt[i + 1] - p.tilt[i]) < 0) a_rev.push_back(p.tracking[i]);
    if ((p.rotary[i] - p.rotary[i - 1]) * (p.rotary[i + 1] - p.rotary[i]) < 0) c_rev.push_back(p.tracking[i]);
  }
  EXPECT_EQ(a_rev, (std::vector<double>{90, 270, 450}));
  EXPECT_EQ(c_rev, (std::vector<double>{180, 360}));
  // The chosen branch is the smaller move from the start pose (0, 0).
  EXPECT_LT(std::hypot(p.tilt[0], p.rotary[0]), std::hypot(p.other_tilt[0], p.other_rotary[0]));
}

TEST(WangPath, RejectsGeometryWithoutASphere) {
  json mj = MachineJson("vmc0656.json");
  mj["axes"]["C"]["point"] = {0, 5, 100};  // C no longer meets A
  try {
    ComputeWangPath(Machine::FromJson(mj.dump()));
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("miss each other"), std::string::npos) << e.what();
  }
  WangPathOptions o;
  o.radius = 500;
  try {
    ComputeWangPath(Machine::FromJson(MachineJson("vmc0656.json").dump()), o);
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("radius"), std::string::npos) << e.what();
  }
}

// ---- planar circular tests -----------------------------------------------------

// A CW or CCW run with the errors of circular_test.h put in exactly (not
// through the linear model): scale, squareness, backlash as axis offsets,
// servo lag as a delayed angle, centre offset of the pivot.
CircularRun SyntheticRun(int dir, double R, double k1, double k2, double psi, double b1, double b2,
                         double lag1, double lag2, double feed_mm_s, Eigen::Vector2d centre,
                         double sigma, int seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  CircularRun r;
  r.direction = dir;
  const int n = 720;
  r.angles.resize(n);
  r.readings.resize(n);
  const double w = feed_mm_s / R;  // rad/s
  for (int i = 0; i < n; ++i) {
    const double phi = dir * 0.5 * i * kPi / 180.0;
    const double p1 = phi - dir * w * lag1, p2 = phi - dir * w * lag2;  // lagging axes
    const double x1c = R * std::cos(p1), x2c = R * std::sin(p2);
    const double v1 = -dir * std::sin(phi), v2 = dir * std::cos(phi);
    const double s1 = v1 > 1e-12 ? 1 : (v1 < -1e-12 ? -1 : 0), s2 = v2 > 1e-12 ? 1 : (v2 < -1e-12 ? -1 : 0);
    const double x2 = (1 + k2) * x2c + b2 * s2;
    const double x1 = (1 + k1) * x1c - psi * x2 + b1 * s1;
    r.angles[i] = phi * 180.0 / kPi;
    r.readings[i] = std::hypot(x1 - centre.x(), x2 - centre.y()) - R + noise(rng);
  }
  return r;
}

TEST(CircularTest, DiagnosisRecoversInjectedErrors) {
  const double R = 100, feed = 2000.0 / 60;  // 2000 mm/min
  const Eigen::Vector2d c(0.004, -0.003);
  std::vector<CircularRun> runs = {
      SyntheticRun(-1, R, 25e-6, -5e-6, 40e-6, 0.002, -0.003, 0.0012, 0.0010, feed, c, 0.0003, 1),
      SyntheticRun(+1, R, 25e-6, -5e-6, 40e-6, 0.002, -0.003, 0.0012, 0.0010, feed, c, 0.0003, 2)};
  const CircularTestResult res = AnalyzeCircularTest(runs, R, 2000);
  const CircularDiagnosis& d = res.diagnosis;
  const std::map<std::string, double> truth = {{"scale_mismatch", 30e-6}, {"squareness", 40e-6},
                                               {"backlash.1+", 0.002},     {"backlash.2+", -0.003},
                                               {"backlash.1-", 0.002},     {"backlash.2-", -0.003},
                                               {"servo_mismatch", feed * 0.0002}, {"centre.1", -0.004},
                                               {"centre.2", 0.003}};
  for (const auto& [n, v] : truth) {
    const int i = static_cast<int>(std::find(d.names.begin(), d.names.end(), n) - d.names.begin());
    ASSERT_LT(i, static_cast<int>(d.names.size())) << n;
    // 3 sigma plus the first-order model error (~1 % of the effect).
    EXPECT_LT(std::abs(d.values[i] - v), 3 * d.std[i] + 0.01 * std::abs(v)) << n << " " << d.values[i];
  }
  EXPECT_LT(d.rms, 0.00035);
  EXPECT_TRUE(res.has_hysteresis);
}

TEST(CircularTest, IsoValuesOfAnOffsetCircle) {
  // A pivot off by 5 um: the path is a circle (G ~ 0), F = +-5 um, the LSC
  // centre is the offset (readings see the machine circle from the pivot).
  std::vector<CircularRun> runs = {
      SyntheticRun(+1, 100, 0, 0, 0, 0, 0, 0, 0, 10, Eigen::Vector2d(0.005, 0), 0.0, 1)};
  const CircularTestResult res = AnalyzeCircularTest(runs, 100);
  EXPECT_LT(res.runs[0].circular_deviation, 1e-6);
  EXPECT_NEAR(res.runs[0].radial_deviation_max, 0.005, 1e-6);
  EXPECT_NEAR(res.runs[0].radial_deviation_min, -0.005, 1e-6);
  EXPECT_NEAR(res.runs[0].centre.x(), -0.005, 1e-6);
  EXPECT_FALSE(res.diagnosis.Has("servo_mismatch"));  // one direction only
  // one direction: servo mismatch and both lateral plays are left out
  ASSERT_EQ(res.diagnosis.not_fitted.size(), 3u);
  EXPECT_FALSE(res.diagnosis.Has("lateral_play.1"));
  EXPECT_FALSE(res.has_hysteresis);
}

TEST(CircularTest, RejectsBadRuns) {
  CircularRun r;
  r.angles = Eigen::VectorXd::LinSpaced(10, 0, 90);
  r.readings = Eigen::VectorXd::Zero(9);
  EXPECT_THROW(AnalyzeCircularTest({r}, 100), std::invalid_argument);
  r.readings = Eigen::VectorXd::Zero(10);
  EXPECT_THROW(AnalyzeCircularTest({r}, -1), std::invalid_argument);
  EXPECT_THROW(AnalyzeCircularTest({r, r}, 100), std::invalid_argument);  // both CCW
}

// A run whose axes carry the position errors e(phi, s, x) given, computed
// exactly (the reading is the distance to the pivot), 0.5 deg sampling.
CircularRun ErrorRun(int dir, double R, const std::function<Eigen::Vector2d(double, int)>& err,
                     double sigma, int seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  CircularRun r;
  r.direction = dir;
  const int n = 720;
  r.angles.resize(n);
  r.readings.resize(n);
  for (int i = 0; i < n; ++i) {
    const double deg = dir * 0.5 * i, phi = deg * kPi / 180;
    const Eigen::Vector2d p = R * Eigen::Vector2d(std::cos(phi), std::sin(phi)) + err(deg, dir);
    r.angles[i] = deg;
    r.readings[i] = p.norm() - R + noise(rng);
  }
  return r;
}

int SgnD(double x) { return x > 1e-12 ? 1 : (x < -1e-12 ? -1 : 0); }

TEST(CircularTest, ExtendedDiagnosesAreRecoveredAndRankedFirst) {
  const double R = 100, sigma = 0.0003;
  // A little of the base errors everywhere, so each injected term must be
  // told from them.
  auto base = [&](double deg, int s) {
    const double phi = deg * kPi / 180, x1 = R * std::cos(phi), x2 = R * std::sin(phi);
    const double v1 = -s * SgnD(std::sin(phi)), v2 = s * SgnD(std::cos(phi));
    return Eigen::Vector2d(5e-6 * x1 - 4e-6 * x2 + 0.0005 * v1, 0.0004 * v2);
  };
  struct Case {
    std::string name;  // diagnosis (group) expected first
    std::vector<std::pair<std::string, double>> truth;
    std::function<Eigen::Vector2d(double, int)> err;
  };
  const double p = 0.006, w = 3.0, pitch = 10.0;
  std::vector<Case> cases = {
      {"reversal_spike.1", {{"reversal_spike.1+", p}, {"reversal_spike.1-", p}}, [&](double deg, int s) {
         // stick after the reversal of axis 1 at 0 / 180 deg, decaying over w deg
         double t = s * deg;
         const double dphi = t - 180.0 * std::floor(t / 180.0);
         const double rev = (deg - s * dphi) * kPi / 180;
         return Eigen::Vector2d(p * SgnD(std::cos(rev)) * std::exp(-dphi / w), 0.0);
       }},
      {"lateral_play.1", {{"lateral_play.1", 0.004}}, [&](double deg, int s) {
         // axis-2 carriage shifts along axis 1 with the sign of its motion
         return Eigen::Vector2d(0.004 * s * SgnD(std::cos(deg * kPi / 180)), 0.0);
       }},
      {"cyclic_error.2", {{"cyclic_error.2.cos", 0.003}, {"cyclic_error.2.sin", -0.002}},
       [&](double deg, int) {
         const double x2 = R * std::sin(deg * kPi / 180), a = 2 * kPi * x2 / pitch;
         return Eigen::Vector2d(0.0, 0.003 * std::cos(a) - 0.002 * std::sin(a));
       }},
      {"straightness.1", {{"straightness.1", 0.008}}, [&](double deg, int) {
         const double x1 = R * std::cos(deg * kPi / 180);
         return Eigen::Vector2d(0.0, 0.008 * (x1 / R) * (x1 / R));
       }},
      {"radial_play.2", {{"radial_play.2", 0.005}}, [&](double deg, int) {
         return Eigen::Vector2d(0.0, 0.005 * SgnD(std::sin(deg * kPi / 180)));
       }},
  };
  CircularDiagnosisOptions o;
  o.cyclic_pitch1 = pitch;
  o.cyclic_pitch2 = pitch;
  int seed = 10;
  for (const Case& c : cases) {
    auto err = [&](double deg, int s) { return Eigen::Vector2d(base(deg, s) + c.err(deg, s)); };
    std::vector<CircularRun> runs = {ErrorRun(-1, R, err, sigma, ++seed), ErrorRun(+1, R, err, sigma, ++seed)};
    const CircularDiagnosis d = AnalyzeCircularTest(runs, R, 1000, o).diagnosis;
    for (const auto& [n, v] : c.truth) {
      ASSERT_TRUE(d.Has(n)) << n;
      const int i = static_cast<int>(std::find(d.names.begin(), d.names.end(), n) - d.names.begin());
      EXPECT_LT(std::abs(d.values[i] - v), 3 * d.std[i] + 0.01 * std::abs(v)) << c.name << " " << n << " "
                                                                              << d.values[i];
    }
    ASSERT_FALSE(d.ranking.empty());
    // a split diagnosis (spikes at the + and - end) ranks by either end
    EXPECT_EQ(d.ranking[0].substr(0, c.name.size()), c.name);
    EXPECT_LT(d.rms, 1.2 * sigma) << c.name;
  }
}

TEST(CircularTest, TermsTheDataDoNotShowAreDropped) {
  // Only scale, squareness and backlash: every extended term is below 3
  // sigma and dropped, and the classic values keep the classic precision.
  std::vector<CircularRun> runs = {
      SyntheticRun(-1, 100, 25e-6, -5e-6, 40e-6, 0.002, -0.003, 0, 0, 10, Eigen::Vector2d::Zero(), 0.0003, 3),
      SyntheticRun(+1, 100, 25e-6, -5e-6, 40e-6, 0.002, -0.003, 0, 0, 10, Eigen::Vector2d::Zero(), 0.0003, 4)};
  CircularDiagnosisOptions o;
  o.cyclic_pitch1 = o.cyclic_pitch2 = 10.0;
  const CircularDiagnosis d = AnalyzeCircularTest(runs, 100, 0, o).diagnosis;
  EXPECT_EQ(d.names.size(), 10u);  // backlash at both ends of both axes
  EXPECT_EQ(d.not_significant.size(), 12u);
  // each left out with its |value| and std, all below the threshold
  ASSERT_EQ(d.dropped_names.size(), 12u);
  for (Eigen::Index j = 0; j < d.dropped_values.size(); ++j)
    EXPECT_LT(d.dropped_values[j], 3.0 * d.dropped_std[j]) << d.dropped_names[j];
  CircularDiagnosisOptions none;
  none.reversal_spikes = none.lateral_play = none.straightness = none.radial_play = false;
  const CircularDiagnosis classic = AnalyzeCircularTest(runs, 100, 0, none).diagnosis;
  const int i = static_cast<int>(std::find(d.names.begin(), d.names.end(), "scale_mismatch") - d.names.begin());
  EXPECT_NEAR(d.std[i], classic.std[i], 1e-15);
  // everything kept: radial play shares cos 2phi with scale mismatch
  o.significance = 0;
  const CircularDiagnosis all = AnalyzeCircularTest(runs, 100, 0, o).diagnosis;
  EXPECT_EQ(all.names.size(), 24u);
  EXPECT_GT(all.std[i], 3 * classic.std[i]);
  // a quarter arc, one direction: what it cannot carry is named, nothing throws
  CircularRun arc;
  arc.angles = Eigen::VectorXd::LinSpaced(181, 10, 100);
  arc.readings = Eigen::VectorXd::Zero(181);
  const CircularDiagnosis q = AnalyzeCircularTest({arc}, 100, 0, o).diagnosis;
  EXPECT_FALSE(q.Has("backlash.1+"));
  EXPECT_FALSE(q.Has("backlash.1-"));
  EXPECT_FALSE(q.Has("reversal_spike.1+"));
  EXPECT_FALSE(q.Has("lateral_play.1"));
}

TEST(CircularTest, OvershootArcsAreRemoved) {
  // 180 deg of feed-in and of feed-out around the 360 deg data arc, with the
  // angles printed modulo 360 as a recorder may.
  auto err = [](double deg, int) {
    const double phi = deg * kPi / 180;
    return Eigen::Vector2d(0.003 * std::cos(phi) * std::cos(phi), 0.001);
  };
  // 0.5 deg steps from -180 to 540 deg: 1441 samples.
  CircularRun full;
  full.direction = +1;
  const int m = 1441;
  full.angles.resize(m);
  full.readings.resize(m);
  CircularRun data;
  data.direction = +1;
  data.angles.resize(721);
  data.readings.resize(721);
  for (int i = 0, j = 0; i < m; ++i) {
    const double deg = -180.0 + 0.5 * i, phi = deg * kPi / 180;
    const Eigen::Vector2d p = 100 * Eigen::Vector2d(std::cos(phi), std::sin(phi)) + err(deg, 1);
    full.angles[i] = deg - 360.0 * std::floor(deg / 360.0);
    full.readings[i] = p.norm() - 100;
    if (deg >= 0 && deg <= 360) {
      data.angles[j] = deg;
      data.readings[j++] = p.norm() - 100;
    }
  }
  const TrimmedRun t = TrimOvershoot(full);
  EXPECT_EQ(t.removed_start, 360);
  EXPECT_EQ(t.removed_end, 360);
  EXPECT_NEAR(t.arc_start, 180.0, 1e-9);
  EXPECT_NEAR(t.arc_end, 180.0, 1e-9);
  ASSERT_EQ(t.run.angles.size(), 721);
  const CircularTestResult a = AnalyzeCircularTest({t.run}, 100), b = AnalyzeCircularTest({data}, 100);
  EXPECT_NEAR(a.runs[0].circular_deviation, b.runs[0].circular_deviation, 1e-12);
  for (size_t i = 0; i < b.diagnosis.names.size(); ++i)
    EXPECT_NEAR(a.diagnosis.Get(b.diagnosis.names[i]), b.diagnosis.values[i], 1e-12) << b.diagnosis.names[i];
  // A run without overshoot is kept whole.
  EXPECT_EQ(TrimOvershoot(data).removed_start + TrimOvershoot(data).removed_end, 0);
}

TEST(CircularTest, SearchFindsTheCyclicPitchAndTheGateRefusesChance) {
  const double R = 100, sigma = 0.0003;
  auto base = [&](double deg, int s) {
    const double phi = deg * kPi / 180, x1 = R * std::cos(phi), x2 = R * std::sin(phi);
    return Eigen::Vector2d(6e-6 * x1 - 5e-6 * x2 - 0.0006 * s * SgnD(std::sin(phi)),
                           -3e-6 * x2 + 0.0005 * s * SgnD(std::cos(phi)));
  };
  auto cyc = [&](double deg, int s) {
    const double x2 = R * std::sin(deg * kPi / 180);
    return Eigen::Vector2d(base(deg, s) + Eigen::Vector2d(0, 0.003 * std::cos(2 * kPi * x2 / 8.0 + 0.7)));
  };
  CircularDiagnosisOptions o;
  o.search_cyclic_pitch2 = true;
  const CircularTestResult found =
      AnalyzeCircularTest({ErrorRun(-1, R, cyc, sigma, 31), ErrorRun(1, R, cyc, sigma, 32)}, R, 0, o);
  EXPECT_NEAR(found.cyclic_pitch2, 8.0, 8.0 * 2e-3);
  EXPECT_EQ(found.cyclic_pitch1, 0.0);
  EXPECT_GT(found.cyclic_pitches_tried2, 100);
  EXPECT_EQ(found.cyclic_pitches_tried1, 0);
  const CircularDiagnosis& d = found.diagnosis;
  ASSERT_TRUE(d.Has("cyclic_error.2.cos"));
  EXPECT_NEAR(std::hypot(d.Get("cyclic_error.2.cos"), d.Get("cyclic_error.2.sin")), 0.003, 1e-4);
  EXPECT_EQ(d.ranking[0], "cyclic_error.2");
  // nothing periodic: the best of the pitches tried does not clear the
  // Bonferroni threshold, and the report says so
  o.search_cyclic_pitch1 = true;
  const CircularTestResult quiet =
      AnalyzeCircularTest({ErrorRun(-1, R, base, sigma, 33), ErrorRun(1, R, base, sigma, 34)}, R, 0, o);
  EXPECT_EQ(quiet.cyclic_pitch1, 0.0);
  EXPECT_EQ(quiet.cyclic_pitch2, 0.0);
  EXPECT_FALSE(quiet.diagnosis.Has("cyclic_error.1.cos"));
  int gated = 0;
  for (const std::string& s : quiet.diagnosis.not_significant)
    gated += s.rfind("cyclic_error.", 0) == 0 && s.find("searched among") != std::string::npos;
  EXPECT_EQ(gated, 2);
  // too sparse along the axis for any pitch below R/2
  CircularRun sparse;
  sparse.angles = Eigen::VectorXd::LinSpaced(45, 0, 352);
  sparse.readings = Eigen::VectorXd::Zero(45);
  try {
    AnalyzeCircularTest({sparse}, R, 0, o);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cyclic_pitch auto"), std::string::npos) << e.what();
  }
}

TEST(WangFourPoint, SaysWhatTheFourPointsCannotSee) {
  // Columns 1..3 symmetric (rows 0 = 3, 1 = 2), column 0 antisymmetric: the
  // structure of the Wang path's diagonal readings (docs/dbb.md).
  Eigen::MatrixXd S(4, 4);
  S << 1.0, 0.3, -0.2, 0.5,
      -0.5, 0.1, 0.4, -0.3,
       0.5, 0.1, 0.4, -0.3,
      -1.0, 0.3, -0.2, 0.5;
  const Eigen::VectorXd scale = Eigen::Vector4d(0.01, 0.01, 0.01, 5e-5);
  const Eigen::VectorXd r = Eigen::Vector4d(0.001, 0.002, 0.002, 0.001);
  const WangFourPoint a = AnalyzeWangFourPoint(S, scale, &r);
  EXPECT_EQ(a.rank, 3);
  EXPECT_FALSE(a.solved);
  ASSERT_EQ(a.null_space.cols(), 1);
  const Eigen::VectorXd v = a.null_space.col(0);
  EXPECT_NEAR((S * scale.asDiagonal() * v).norm(), 0.0, 1e-12);
  EXPECT_GT(v.cwiseAbs().maxCoeff(), 0.0);
  Eigen::Index at;
  v.cwiseAbs().maxCoeff(&at);
  EXPECT_GT(v[at], 0.0);  // signed: largest component positive
  EXPECT_EQ(a.estimable, std::vector<int>({0}));
  EXPECT_NEAR(a.singular_values[0], 1.0, 1e-15);
  EXPECT_LT(a.singular_values[3], 1e-12);
  // a regular system is solved exactly
  Eigen::MatrixXd T = S;
  T(0, 1) = 0.35;
  const Eigen::Vector4d e(0.002, -0.001, 0.003, 2e-5);
  const Eigen::VectorXd rt = T * e;
  const WangFourPoint b = AnalyzeWangFourPoint(T, scale, &rt);
  EXPECT_EQ(b.rank, 4);
  ASSERT_TRUE(b.solved);
  EXPECT_LT((b.values - e).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(b.estimable.size(), 4u);
  const WangFourPoint c = AnalyzeWangFourPoint(T, scale);
  EXPECT_FALSE(c.solved);
  // bad input names the field
  auto message = [](const Eigen::MatrixXd& s, const Eigen::VectorXd& sc, const Eigen::VectorXd* rr) {
    try {
      AnalyzeWangFourPoint(s, sc, rr);
    } catch (const std::invalid_argument& ex) {
      return std::string(ex.what());
    }
    return std::string("no throw");
  };
  Eigen::MatrixXd nan = S;
  nan(2, 1) = std::nan("");
  EXPECT_NE(message(nan, scale, nullptr).find("sensitivity[2][1]"), std::string::npos);
  EXPECT_NE(message(S, Eigen::Vector3d(1, 1, 1), nullptr).find("scale"), std::string::npos);
  EXPECT_NE(message(S, Eigen::Vector4d(1, 0, 1, 1), nullptr).find("scale[1]"), std::string::npos);
  const Eigen::VectorXd r3 = Eigen::Vector3d(1, 2, 3);
  EXPECT_NE(message(S, scale, &r3).find("readings"), std::string::npos);
}

TEST(BarLengthCommands, MoveTheToolBallAlongTheBar) {
  // c600u: linear axes on the tool side; hu40t: X on the workpiece side.
  for (const char* name : {"c600u.json", "hu40t.json"}) {
    const Machine m = Machine::FromJson(MachineJson(name).dump());
    const Eigen::Vector3d tool(0, 0, 100), table(30, -20, 40);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-60, 60);
    Eigen::MatrixXd poses(6, m.num_axes());
    for (int i = 0; i < poses.rows(); ++i)
      for (int k = 0; k < m.num_axes(); ++k) poses(i, k) = m.axis(k).name == 'S' ? 0.0 : u(rng);
    const Eigen::MatrixXd out = BarLengthCommands(m, tool, table, 118.5, poses);
    for (int i = 0; i < poses.rows(); ++i) {
      const Eigen::Vector3d before = NominalToolBallInWorkpiece(m, poses.row(i).transpose(), tool);
      const Eigen::Vector3d after = NominalToolBallInWorkpiece(m, out.row(i).transpose(), tool);
      EXPECT_NEAR((after - table).norm(), 118.5, 1e-10) << name;
      // along the bar: the ball stays on the line from the table ball
      EXPECT_NEAR((after - table).normalized().cross((before - table).normalized()).norm(), 0.0, 1e-12) << name;
      for (int k = 0; k < m.num_axes(); ++k)
        if (m.axis(k).rotary()) EXPECT_EQ(out(i, k), poses(i, k)) << name;
    }
    EXPECT_THROW(BarLengthCommands(m, tool, table, 0.0, poses), std::invalid_argument);
    EXPECT_THROW(BarLengthCommands(m, tool, table, 100.0, poses.leftCols(2)), std::invalid_argument);
    Eigen::MatrixXd bad = poses;
    bad(1, 0) = std::nan("");
    try {
      BarLengthCommands(m, tool, table, 100.0, bad);
      ADD_FAILURE() << "no throw";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("poses[1]"), std::string::npos) << e.what();
    }
  }
}

TEST(TraceHarmonics, RecoversCoefficients) {
  Eigen::VectorXd a(300), v(300);
  for (int i = 0; i < 300; ++i) {
    a[i] = 90 + 1.2 * i;
    const double p = a[i] * kPi / 180;
    v[i] = 0.5 + 2 * std::cos(p) - 3 * std::sin(p) + 0.25 * std::cos(2 * p) + 0.1 * std::sin(3 * p);
  }
  const Eigen::MatrixXd h = TraceHarmonics(a, v, 4);
  EXPECT_NEAR(h(0, 0), 0.5, 1e-12);
  EXPECT_NEAR(h(1, 0), 2, 1e-12);
  EXPECT_NEAR(h(1, 1), -3, 1e-12);
  EXPECT_NEAR(h(2, 0), 0.25, 1e-12);
  EXPECT_NEAR(h(3, 1), 0.1, 1e-12);
  EXPECT_NEAR(h(4, 0), 0.0, 1e-12);
}


TEST(CircularTest, BacklashAtEachEndAndItsContribution) {
  // X loses 5 um at its + end and 1 um at its - end: the two ends are told
  // apart, their mean is the derived backlash.1, and the ranking and its
  // percentages follow the contributions (a step of 2 b).
  const double R = 100, sigma = 0.0003;
  auto err = [&](double deg, int s) {
    const double phi = deg * kPi / 180, v1 = -s * SgnD(std::sin(phi));
    return Eigen::Vector2d((std::cos(phi) > 0 ? 0.005 : 0.001) * v1, 0.0);
  };
  std::vector<CircularRun> runs = {ErrorRun(-1, R, err, sigma, 71), ErrorRun(+1, R, err, sigma, 72)};
  const CircularTestResult res = AnalyzeCircularTest(runs, R);
  const CircularDiagnosis& d = res.diagnosis;
  EXPECT_NEAR(d.Get("backlash.1+"), 0.005, 1e-4);
  EXPECT_NEAR(d.Get("backlash.1-"), 0.001, 1e-4);
  ASSERT_EQ(d.derived_names.size(), 2u);
  EXPECT_EQ(d.derived_names[0], "backlash.1");
  EXPECT_NEAR(d.derived_values[0], 0.5 * (d.Get("backlash.1+") + d.Get("backlash.1-")), 1e-15);
  EXPECT_EQ(d.ranking[0], "backlash.1+");
  EXPECT_NEAR(d.contribution[0], DiagnosisContribution("backlash.1+", d.Get("backlash.1+"), R), 2e-4);
  const double G = std::max(res.runs[0].circular_deviation, res.runs[1].circular_deviation);
  EXPECT_DOUBLE_EQ(d.circularity, G);
  EXPECT_NEAR(d.contribution_percent[0], 100 * d.contribution[0] / G, 1e-9);
  EXPECT_NEAR(DiagnosisContribution("squareness", 40e-6, R), R * 40e-6, 1e-12);
  EXPECT_NEAR(DiagnosisContribution("backlash.2-", 0.002, R), 0.004, 2e-6);
  EXPECT_THROW(DiagnosisContribution("wobble", 1.0, R), std::invalid_argument);
}

TEST(CircularTest, BarTemperatureCompensation) {
  BarThermal th;
  th.alpha_bar = 1e-6;
  th.t_bar = 23;
  th.alpha_machine = 11.5e-6;
  th.t_machine = 23;
  const Eigen::VectorXd r = CompensateBarTemperature(Eigen::Vector2d(0.0, 0.001), 100, th);
  EXPECT_NEAR(r[0], 100 * (1 + 3e-6) / (1 + 34.5e-6) - 100, 1e-12);
  EXPECT_NEAR(r[1] - r[0], 0.001 / (1 + 34.5e-6), 1e-12);
  th.alpha_machine = 11.5;  // ppm/K given as 1/K
  EXPECT_THROW(CompensateBarTemperature(r, 100, th), std::invalid_argument);
  th.alpha_machine = 11.5e-6;
  th.t_bar = 296;  // kelvin
  EXPECT_THROW(CompensateBarTemperature(r, 100, th), std::invalid_argument);
}
}  // namespace
}  // namespace fivecal
