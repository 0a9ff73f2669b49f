// Priors: the class table, the override precedence, the refusal of unknown
// classes, the MAP prior rows against finite differences, the
// prior-scaled noise-tied identifiability and the option validation at the
// Identify boundary.
#include <gtest/gtest.h>

#include "test_files.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

const Dataset& Tango() {
  static const Dataset ds =
      Simulate(ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/tests/data/tango_thin_spec.json"));
  return ds;
}

double Default(const std::string& cls) {
  for (const PriorClass& c : PriorClasses())
    if (c.name == cls) return c.sigma;
  ADD_FAILURE() << "no class " << cls;
  return 0;
}

TEST(PriorTable, EveryParameterKindHasItsClass) {
  const Machine& m = Tango().machine();
  const std::map<std::string, std::string> expected = {
      {"EX0C", "location_offset"}, {"EY0S", "location_offset"}, {"EA0B", "location_angle"},
      {"EC0Y", "location_angle"},  {"EXX1", "scale_gain"},      {"EZZ1", "scale_gain"},
      {"EYX1", "linear_motion_1"}, {"EXX2", "linear_motion_2"}, {"EZY3", "linear_motion_3"},
      {"EAX1", "linear_tilt_1"},   {"ECZ2", "linear_tilt_2"},   {"EXB1", "rotary_motion_1"},
      {"EZB2", "rotary_motion_2"}, {"ECC1", "rotary_tilt_1"},   {"EBB3", "rotary_tilt_3"},
      {"EXXb", "backlash_linear"}, {"ECCb", "backlash_rotary"}, {"tip.z", "tip"},
      {"facet.F1", "facet"},       {"sphere.S1.x", "sphere_center"},
      {"sphere.S1.r", "sphere_radius"}, {"dbb.length", "dbb_length"},
      {"dbb.A1.length", "dbb_length"},  {"dbb.A1.tool.x", "mount"},
      {"ball3d.R1.table.z", "mount"}};
  for (const auto& [name, cls] : expected) EXPECT_EQ(PriorClassOf(m, name), cls) << name;
  EXPECT_THROW(PriorClassOf(m, "EQQ1"), std::invalid_argument);
}

TEST(PriorTable, ErrorMotionPriorsAreSizedByTheReferenceTravel) {
  // Degree d: the class's effect over the reference travel, divided by travel^d.
  for (int d = 1; d <= 3; ++d) {
    EXPECT_NEAR(Default("linear_motion_" + std::to_string(d)) * std::pow(250.0, d), 0.010, 1e-15);
    EXPECT_NEAR(Default("linear_tilt_" + std::to_string(d)) * std::pow(250.0, d), 50e-6, 1e-18);
    EXPECT_NEAR(Default("rotary_motion_" + std::to_string(d)), 0.010, 1e-15);
    EXPECT_NEAR(Default("rotary_tilt_" + std::to_string(d)), 50e-6, 1e-18);
  }
  EXPECT_EQ(Default("location_offset"), 0.1);
  EXPECT_EQ(Default("location_angle"), 1e-4);
  EXPECT_EQ(Default("scale_gain"), 1e-4);
  EXPECT_EQ(Default("backlash_linear"), 0.005);
  EXPECT_EQ(Default("backlash_rotary"), 2e-5);
  // Setup parameters are poorly known: mm-sized.
  for (const char* c : {"tip", "facet", "sphere_center", "dbb_length", "mount"})
    EXPECT_GE(Default(c), 1.0) << c;
}

TEST(PriorTable, OverridesApplyInOrderMachineClassNameThenCallClassName) {
  const Machine& m = Tango().machine();
  const std::vector<std::string> names = {"EX0C", "EY0S", "EA0B", "EXX1"};
  auto scales = [&](const std::map<std::string, double>& mp, const std::map<std::string, double>& cp) {
    return PriorScales(m, names, mp, cp);
  };
  EXPECT_EQ(scales({}, {})[0], 0.1);
  EXPECT_EQ(scales({{"class:location_offset", 0.3}}, {})[1], 0.3);
  EXPECT_EQ(scales({{"class:location_offset", 0.3}, {"EX0C", 0.2}}, {})[0], 0.2);
  // The call's class beats the machine file's name, the call's name beats all.
  EXPECT_EQ(scales({{"EX0C", 0.2}}, {{"class:location_offset", 0.4}})[0], 0.4);
  EXPECT_EQ(scales({{"EX0C", 0.2}}, {{"class:location_offset", 0.4}, {"EX0C", 0.5}})[0], 0.5);
  EXPECT_EQ(scales({}, {{"EX0C", 0.5}})[1], 0.1);  // only the named one
  EXPECT_EQ(scales({}, {{"class:scale_gain", 2e-4}})[3], 2e-4);
  EXPECT_EQ(scales({}, {{"class:scale_gain", 2e-4}})[2], 1e-4);
}

TEST(PriorTable, UnknownClassIsRefusedWithDidYouMean) {
  const std::vector<std::string> known = {"EX0C", "EXX1"};
  try {
    ValidatePriors({{"class:location_ofset", 0.1}}, "priors", known);
    ADD_FAILURE() << "accepted an unknown class";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("did you mean 'class:location_offset'"), std::string::npos)
        << e.what();
  }
  try {
    ValidatePriors({{"EX0D", 0.1}}, "priors", known);
    ADD_FAILURE() << "accepted an unknown parameter";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("did you mean 'EX0C'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ValidatePriors({{"EX0C", -1.0}}, "priors", known), std::invalid_argument);
  EXPECT_THROW(ValidatePriors({{"EX0C", 0.0}}, "priors", known), std::invalid_argument);
  EXPECT_THROW(ValidatePriors({{"EX0C", NAN}}, "priors", known), std::invalid_argument);
  EXPECT_NO_THROW(ValidatePriors({{"EX0C", 0.2}, {"class:scale_gain", 1e-5}}, "priors", known));
  // Through Identify.
  IdentifyOptions o;
  o.estimate = {"EX0C"};
  o.priors = {{"class:scale_gian", 1e-4}};
  EXPECT_THROW(Identify(Tango(), o), std::invalid_argument);
}

// The prior rows (theta - mean) / sigma and their derivative, and the whole
// weighted MAP problem's Jacobian against central differences.
TEST(MapRows, JacobianMatchesFiniteDifferences) {
  const Dataset& ds = Tango();
  const ParameterTable table(ds);
  Eigen::VectorXd values = Eigen::VectorXd::Zero(table.size());
  std::vector<int> est;
  for (const char* n : {"EX0C", "EA0C", "EXX1", "EYY1", "ECCb", "tip.z", "facet.F3"}) est.push_back(table.Require(n));
  values[table.Require("EX0C")] = 0.02;
  values[table.Require("EXX1")] = 3e-5;
  const std::vector<double> p = PriorScales(ds.machine(), table.names(), {}, {});
  const Eigen::VectorXd prior = Eigen::Map<const Eigen::VectorXd>(p.data(), p.size());
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(table.size());
  mean[table.Require("EX0C")] = 0.01;
  Problem problem(ds, table, values, est);
  problem.AddPriors(prior, mean);
  ceres::Problem& cp = problem.ceres_problem();
  auto eval = [&](std::vector<double>* r, ceres::CRSMatrix* J) {
    ceres::Problem::EvaluateOptions eo;
    for (int i : est) eo.parameter_blocks.push_back(const_cast<double*>(&problem.values()[i]));
    ASSERT_TRUE(cp.Evaluate(eo, nullptr, r, nullptr, J));
  };
  std::vector<double> r0;
  ceres::CRSMatrix J;
  eval(&r0, &J);
  const int n = problem.num_rows();
  ASSERT_EQ(static_cast<int>(r0.size()), n + static_cast<int>(est.size()));
  // Prior rows come last, one per estimated parameter.
  for (size_t k = 0; k < est.size(); ++k) {
    const int i = est[k];
    EXPECT_NEAR(r0[n + k], (values[i] - mean[i]) / prior[i], 1e-12) << table.names()[i];
  }
  // Data rows are weighted by 1 / declared sigma.
  Eigen::VectorXd rmm;
  problem.Evaluate(&rmm, nullptr);
  for (int i = 0; i < n; ++i) EXPECT_NEAR(r0[i], rmm[i] / problem.row_sigma()[i], 1e-9) << i;
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(r0.size(), est.size());
  for (int row = 0; row < J.num_rows; ++row)
    for (int e = J.rows[row]; e < J.rows[row + 1]; ++e) dense(row, J.cols[e]) = J.values[e];
  double* base = const_cast<double*>(problem.values().data());
  for (size_t k = 0; k < est.size(); ++k) {
    const int i = est[k];
    const double h = 1e-3 * prior[i];  // the model is nearly linear; smaller h drowns in rounding of the weighted rows
    const double keep = base[i];
    std::vector<double> rp, rm;
    base[i] = keep + h;
    eval(&rp, nullptr);
    base[i] = keep - h;
    eval(&rm, nullptr);
    base[i] = keep;
    // Rows where the parameter has no first-order effect still see rounding
    // of the other terms (weighted rows reach 1e5 per rad): judge each entry
    // against its column's scale too, which a wrong derivative would exceed.
    const double column = dense.col(k).cwiseAbs().maxCoeff();
    for (size_t row = 0; row < r0.size(); ++row) {
      const double fd = (rp[row] - rm[row]) / (2 * h);
      EXPECT_NEAR(dense(row, k), fd, 1e-4 * std::max(1.0, std::abs(fd)) + 1e-8 * column)
          << table.names()[i] << " row " << row << " column max " << column;
    }
  }
}

// Placement priors (priors.h PlacementSigma): the kinds' defaults, the
// dataset's overrides (a name beats its class), and the refusal of names that
// are not this dataset's set-up parameters.
TEST(Placement, DefaultsOverridesAndRefusals) {
  const Dataset& ds = Tango();
  const Machine& m = ds.machine();
  const ParameterTable table(ds);
  std::string sphere;
  for (const std::string& n : table.names())
    if (n.rfind("sphere.", 0) == 0 && n.size() > 2 && n.compare(n.size() - 2, 2, ".x") == 0) sphere = n;
  ASSERT_FALSE(sphere.empty());
  const std::string radius = sphere.substr(0, sphere.size() - 2) + ".r";
  EXPECT_EQ(PlacementSigma(m, "EX0C", {}), 0.0);  // machine errors: PriorScales
  EXPECT_EQ(PlacementSigma(m, "tip.z", {}), 0.0);
  EXPECT_EQ(PlacementSigma(m, sphere, {}), 0.0);  // found by the probing, unless declared
  EXPECT_DOUBLE_EQ(PlacementSigma(m, radius, {}), 0.001);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, "dbb.W1.table.z", {}), 0.030);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, "dbb.W1.tool.z", {}), 0.020);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, "dbb.W1.length", {}), 0.002);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, "ball3d.K1.table.x", {}), 0.050);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, "instrument.T1.a", {}), 0.01);
  EXPECT_EQ(PlacementSigma(m, "instrument.T1.tool_x", {}), 0.0);  // a target offset: no placement
  const std::map<std::string, double> o = {{"class:sphere_center", 0.02}, {sphere, 0.005}};
  EXPECT_DOUBLE_EQ(PlacementSigma(m, sphere, o), 0.005);
  EXPECT_DOUBLE_EQ(PlacementSigma(m, sphere.substr(0, sphere.size() - 1) + "y", o), 0.02);
  ValidateSetupUncertainty(m, o, "dataset.setup_uncertainty", table.names());
  auto message = [&](const std::map<std::string, double>& u) {
    try {
      ValidateSetupUncertainty(m, u, "dataset.setup_uncertainty", table.names());
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message({{"sphere.NOPE.x", 0.01}}).find("dataset.setup_uncertainty['sphere.NOPE.x']: unknown set-up"),
            std::string::npos);
  EXPECT_NE(message({{"EX0C", 0.01}}).find("machine error"), std::string::npos);
  EXPECT_NE(message({{"class:mounts", 0.01}}).find("unknown set-up class 'mounts'"), std::string::npos);
  EXPECT_NE(message({{"class:location_offset", 0.01}}).find("unknown set-up class"), std::string::npos);
  EXPECT_NE(message({{sphere, 0.0}}).find("finite and > 0"), std::string::npos);
  EXPECT_NE(message({{sphere, -1.0}}).find("finite and > 0"), std::string::npos);
}

// The placement rows of a least-squares fit: Problem::AddPriors with +inf
// (no row) for the parameters without a placement, one row (theta - 0) / u
// per placed one, checked against finite differences like the MAP rows.
TEST(Placement, RowsAndJacobianMatchFiniteDifferences) {
  const Dataset& ds = Tango();
  const ParameterTable table(ds);
  std::vector<int> est;
  for (const char* n : {"EX0C", "EA0C", "tip.z", "facet.F3"}) est.push_back(table.Require(n));
  for (int i = 0; i < table.size(); ++i)
    if (table.names()[i].rfind("sphere.", 0) == 0 && est.size() < 9) est.push_back(i);
  // Sphere centres placed by the dataset, radii by their default (certificate).
  const std::vector<double> u =
      PlacementScales(ds.machine(), table.names(), {{"class:sphere_center", 0.05}});
  const Eigen::VectorXd placement = Eigen::Map<const Eigen::VectorXd>(u.data(), u.size());
  const Eigen::VectorXd rows = PlacementRows(placement, est);
  ASSERT_EQ(rows.size(), table.size());
  std::vector<int> placed;
  for (int i : est) {
    if (placement[i] > 0) {
      placed.push_back(i);
      EXPECT_EQ(rows[i], placement[i]);
    } else {
      EXPECT_TRUE(std::isinf(rows[i])) << table.names()[i];
    }
  }
  ASSERT_GE(placed.size(), 3u);
  EXPECT_EQ(PlacementRows(placement, {table.Require("EX0C")}).size(), 0);  // none placed: no rows at all
  Eigen::VectorXd values = Eigen::VectorXd::Zero(table.size());
  values[table.Require("EX0C")] = 0.02;
  for (int i : placed) values[i] = 0.03;
  Problem problem(ds, table, values, est);
  problem.AddPriors(rows, Eigen::VectorXd::Zero(table.size()));
  ceres::Problem& cp = problem.ceres_problem();
  auto eval = [&](std::vector<double>* r, ceres::CRSMatrix* J) {
    ceres::Problem::EvaluateOptions eo;
    for (int i : est) eo.parameter_blocks.push_back(const_cast<double*>(&problem.values()[i]));
    ASSERT_TRUE(cp.Evaluate(eo, nullptr, r, nullptr, J));
  };
  std::vector<double> r0;
  ceres::CRSMatrix J;
  eval(&r0, &J);
  const int n = problem.num_rows();
  ASSERT_EQ(r0.size(), n + placed.size());
  for (size_t k = 0; k < placed.size(); ++k) EXPECT_NEAR(r0[n + k], 0.03 / placement[placed[k]], 1e-12);
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(r0.size(), est.size());
  for (int row = 0; row < J.num_rows; ++row)
    for (int e = J.rows[row]; e < J.rows[row + 1]; ++e) dense(row, J.cols[e]) = J.values[e];
  double* base = const_cast<double*>(problem.values().data());
  for (size_t k = 0; k < est.size(); ++k) {
    const int i = est[k];
    const double h = 1e-6;
    const double keep = base[i];
    std::vector<double> rp, rm;
    base[i] = keep + h;
    eval(&rp, nullptr);
    base[i] = keep - h;
    eval(&rm, nullptr);
    base[i] = keep;
    const double column = dense.col(k).cwiseAbs().maxCoeff();
    for (size_t row = n; row < r0.size(); ++row) {  // the placement rows: exact
      const double fd = (rp[row] - rm[row]) / (2 * h);
      EXPECT_NEAR(dense(row, k), fd, 1e-6 * std::max(1.0, std::abs(fd))) << table.names()[i] << " row " << row;
    }
    for (int row = 0; row < n; ++row) {
      const double fd = (rp[row] - rm[row]) / (2 * h);
      EXPECT_NEAR(dense(row, k), fd, 1e-4 * std::max(1.0, std::abs(fd)) + 1e-6 * column)
          << table.names()[i] << " row " << row;
    }
  }
  // The analyses see the same rows: WithPlacementRows appends e_j / u_j.
  Eigen::VectorXd ue(est.size());
  for (size_t k = 0; k < est.size(); ++k) ue[k] = placement[est[k]];
  const Eigen::MatrixXd A = WithPlacementRows(Eigen::MatrixXd::Zero(2, est.size()), ue);
  ASSERT_EQ(A.rows(), 2 + static_cast<int>(placed.size()));
  for (size_t k = 0, row = 2; k < est.size(); ++k)
    if (ue[k] > 0) EXPECT_DOUBLE_EQ(A(row++, k), 1.0 / ue[k]);
}

TEST(Determination, RatioIsDataSigmaOverPriorAndNoiseTied) {
  // Two parameters, y = a x + b x (the same column): no direction of a - b is
  // seen; a third parameter c is seen with data sigma 0.1 prior.
  Eigen::MatrixXd Jw(4, 3);
  Jw << 1, 1, 0, 2, 2, 0, 0, 0, 5, 0, 0, 5;
  const Eigen::VectorXd prior = Eigen::Vector3d(1, 1, 1);
  const Determination d = AnalyzeDetermination(Jw, prior, kDeterminedRatio);
  EXPECT_NEAR(d.ratio[2], 1.0 / std::sqrt(50.0), 1e-12);
  EXPECT_FALSE(std::isfinite(d.ratio[0]));
  ASSERT_EQ(d.groups.size(), 1u);
  EXPECT_EQ(d.groups[0], (std::vector<int>{0, 1}));
  // A column seen only weakly relative to its prior (data sigma 0.8 prior) is
  // not determined, though the matrix is of full rank: the tolerance is tied
  // to the noise and the prior, not to machine epsilon.
  Eigen::MatrixXd W(2, 2);
  W << 1.25, 0, 0, 10;
  const Determination w = AnalyzeDetermination(W, Eigen::Vector2d(1, 1), kDeterminedRatio);
  EXPECT_NEAR(w.ratio[0], 0.8, 1e-12);
  EXPECT_EQ(w.undetermined, std::vector<int>{0});
  EXPECT_EQ(w.rank, 1);
  // Doubling the prior of the weak one makes it determined (ratio 0.4).
  const Determination w2 = AnalyzeDetermination(W, Eigen::Vector2d(2, 1), kDeterminedRatio);
  EXPECT_TRUE(w2.undetermined.empty());
}

TEST(IdentifyOptionsValidation, NamedErrors) {
  auto expect = [](IdentifyOptions o, const std::string& field) {
    o.estimate = {"EX0C"};
    try {
      Identify(Tango(), o);
      ADD_FAILURE() << "accepted bad " << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
    }
  };
  IdentifyOptions o;
  o.max_iterations = 0;
  expect(o, "max_iterations");
  o = {};
  o.max_iterations = 10000000;
  expect(o, "max_iterations");
  o = {};
  o.selection_tolerance = 0;
  expect(o, "selection_tolerance");
  o = {};
  o.selection_tolerance = 1;
  expect(o, "selection_tolerance");
  o = {};
  o.robust = "hubber";
  expect(o, "robust");
  o = {};
  o.num_threads = -1;
  expect(o, "num_threads");
  o = {};
  o.initial = {{"EX0C", NAN}};
  expect(o, "EX0C");
  o = {};
  o.initial = {{"EX0C", INFINITY}};
  expect(o, "EX0C");
  o = {};
  o.robust_scale = -1;
  expect(o, "robust_scale");
}

TEST(IdentifyPriors, AutoIsAMapFitThatListsWhatTheDataDidNotDetermine) {
  IdentifyOptions o;
  o.estimate = {"auto"};
  const Result r = Identify(Tango(), o);
  EXPECT_TRUE(r.map_fit);
  ASSERT_EQ(r.prior_std.size(), r.estimated.size());
  ASSERT_EQ(r.informed.size(), r.estimated.size());
  EXPECT_FALSE(r.undetermined.empty());
  for (size_t j = 0; j < r.estimated.size(); ++j) {
    EXPECT_TRUE(std::isfinite(r.std[j]));
    // A posterior sigma never exceeds the prior's (up to the chi2 inflation).
    EXPECT_LE(r.informed[j], 1.0 * std::sqrt(std::max(1.0, r.chi2 / r.dof)) + 1e-9) << r.estimated[j];
  }
  // The C pivot position is informed (the spindle offsets are not: with every
  // error motion free they are confounded with the spindle's).
  for (const char* n : {"EX0C"}) {
    const auto it = std::find(r.estimated.begin(), r.estimated.end(), n);
    ASSERT_NE(it, r.estimated.end());
    EXPECT_LT(r.informed[it - r.estimated.begin()], kInformedThreshold) << n;
  }
  EXPECT_EQ(r.verdict(), "ok");
  const std::string j = r.ToJson();
  EXPECT_NE(j.find("\"verdict\""), std::string::npos);
  EXPECT_NE(j.find("\"prior_std\""), std::string::npos);
  EXPECT_EQ(j.find(": inf"), std::string::npos);
  EXPECT_EQ(j.find("Infinity"), std::string::npos);
  EXPECT_EQ(j.find("NaN"), std::string::npos);
}

TEST(IdentifyPriors, AutoThatDeterminesNoMachineErrorIsNotUsableAndSaysWhatWouldTellIt) {
  // Eight touches at the first indexation: the set-up is seen, no machine error is.
  std::vector<int> first;
  for (int i = 0; i < 8; ++i) first.push_back(i);
  const Dataset few = Tango().Subset(first);
  IdentifyOptions o;
  o.estimate = {"auto"};
  const Result r = Identify(few, o);
  EXPECT_TRUE(r.converged);
  EXPECT_TRUE(r.seeks_machine_errors);
  EXPECT_EQ(r.identified_machine_errors, 0);
  EXPECT_EQ(r.verdict(), "undetermined");
  // One entry per family, each with its cause and the measurement that would tell it.
  ASSERT_FALSE(r.not_determined.empty());
  size_t named = 0;
  for (const NotDetermined& f : r.not_determined) {
    EXPECT_FALSE(f.names.empty()) << f.family;
    EXPECT_LE(f.names.size(), static_cast<size_t>(f.estimated)) << f.family;
    EXPECT_NE(f.why.find(": "), std::string::npos) << f.family << ": " << f.why;
    named += f.names.size();
  }
  EXPECT_GE(named, r.estimated.size() - 1);
  const auto offsets = std::find_if(r.not_determined.begin(), r.not_determined.end(),
                                    [](const NotDetermined& f) { return f.family == "location offsets"; });
  ASSERT_NE(offsets, r.not_determined.end());
  EXPECT_NE(offsets->why.find("indexations: measure at 3 or more indexations of each"), std::string::npos)
      << offsets->why;
  const std::string j = r.ToJson();
  EXPECT_NE(j.find("\"not_determined\""), std::string::npos);
  EXPECT_NE(j.find("\"identified_machine_errors\": 0"), std::string::npos);
  // The whole plan determines machine errors: usable.
  const Result all = Identify(Tango(), o);
  EXPECT_GT(all.identified_machine_errors, 0);
  EXPECT_EQ(all.verdict(), "ok");
}

TEST(IdentifyPriors, ChiSquareAgainstTheDeclaredNoise) {
  // The simulated noise (0.6 um) against the declared one (the simulator's
  // 0.6 um, or the 1 um default when a file declares none): adequate,
  // chi2/dof between 0.36 and 1.
  IdentifyOptions o;
  o.estimate = {"S3"};
  const Result r = Identify(Tango(), o);
  EXPECT_TRUE(r.adequate) << r.adequacy;
  EXPECT_GT(r.dof, 0);
  EXPECT_GT(r.chi2 / r.dof, 0.2);
  EXPECT_LT(r.chi2 / r.dof, 1.3);
  EXPECT_GT(r.chi2_p, 1e-3);
  // Leaving the scale gains and backlash out: residuals of several um, inadequate.
  o.estimate = {"EX0C", "EY0S"};
  const Result bad = Identify(Tango(), o);
  EXPECT_FALSE(bad.adequate);
  EXPECT_LT(bad.chi2_p, 1e-3);
  EXPECT_FALSE(bad.adequacy.empty());
  EXPECT_EQ(bad.verdict(), "inadequate");
}

}  // namespace
}  // namespace fivecal
