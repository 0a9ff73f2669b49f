// Verify after loading (controllers/verify.h): drawn checks of a change that
// took effect, was not applied, turned, doubled, read in the wrong unit or
// with one component's sign turned, each named; a check too noisy to tell
// says so; a change the check does not measure is refused, named.
#include <gtest/gtest.h>

#include <random>

#include "fivecal/controllers/verify.h"

namespace fivecal {
namespace controllers {
namespace {

Machine TableTable() {  // A/C trunnion: a check names C's X offset and A's Y offset as the spindle's
  return Machine::FromJson(R"({"name": "tt", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]},
    "A": {"type": "rotary", "direction": [1,0,0], "point": [0,0,-45]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,150]}})");
}

// The check's names for the pivots of C and A on this machine.
const std::vector<std::string> kNames = {"EX0S", "EY0C", "EY0S", "EZ0A"};

struct Draw {
  NamedEstimate previous, change, now;
};

// A previous check of the pivots theta (sigma s each), the change c (its
// covariance sc^2: how well it corrects, not how well it is loaded), and a
// check after loading that applied f_j * c_j.
Draw MakeDraw(const Eigen::VectorXd& theta, const Eigen::VectorXd& c, const Eigen::VectorXd& f, double s, double sc,
              std::mt19937& rng) {
  std::normal_distribution<double> z(0, 1);
  const Eigen::Index n = theta.size();
  Draw d;
  const Eigen::MatrixXd C = Eigen::MatrixXd::Identity(n, n) * s * s;
  d.previous = {kNames, theta, C};
  d.change = {kNames, c, Eigen::MatrixXd::Identity(n, n) * sc * sc};
  d.now = {kNames, theta - f.cwiseProduct(c), C};
  for (Eigen::Index i = 0; i < n; ++i) {
    d.previous.values[i] += s * z(rng);
    d.now.values[i] += s * z(rng);
  }
  return d;
}

ChangeVerification Verify(const Eigen::VectorXd& f, double s = 0.0007, unsigned seed = 1,
                       double scale = 1.0) {
  std::mt19937 rng(seed);
  Eigen::VectorXd theta(4), c(4);
  theta << 0.021, -0.013, 0.008, 0.017;
  c = theta * scale;
  const Draw d = MakeDraw(theta, c, f, s, 0.0003, rng);
  return VerifyChange(TableTable(), d.previous, d.change, d.now);
}

bool Names(const ChangeOutcome& o, ChangeCause cause) {
  for (const Hypothesis& h : o.causes)
    if (h.cause == cause) return true;
  return false;
}

TEST(VerifyChange, TookEffectIsSaidAndFlaggedNoMoreOftenThanTheThreeSigmaRate) {
  int flagged = 0, cannot = 0;
  const int n = 2000;
  for (int i = 0; i < n; ++i) {
    const ChangeVerification v = Verify(Eigen::VectorXd::Ones(4), 0.0007, 100 + i);
    if (v.outcome.verdict == ChangeVerdict::kCannotTell) ++cannot;
    else if (!v.took_effect()) ++flagged;
    for (const ParameterChange& r : v.parameters) EXPECT_NEAR(r.ratio, 1.0, 5 * r.ratio_std) << r.name;
  }
  // chi2 beyond its 3 sigma quantile: 0.27 %; each resolvable alternative beats it by 3 sigma: < 0.14 %
  EXPECT_LE(flagged, 0.01 * n) << flagged;
  EXPECT_EQ(cannot, 0);
  const ChangeVerification v = Verify(Eigen::VectorXd::Ones(4));
  EXPECT_TRUE(v.took_effect()) << v.outcome.message;
  EXPECT_NEAR(v.ratio, 1.0, 3 * v.ratio_std);
  EXPECT_LT(v.ratio_std, 0.05);
  ASSERT_EQ(v.parameters.size(), 4u);
  for (const ParameterChange& r : v.parameters) {
    EXPECT_TRUE(r.as_predicted) << r.name;
    EXPECT_EQ(r.outcome.verdict, ChangeVerdict::kTookEffect) << r.name << ": " << r.outcome.message;
  }
}

TEST(VerifyChange, EachCauseIsNamed) {
  struct Case {
    double f;
    ChangeCause cause;
    double scale;  // of the change: an inch value read as mm shows only on a large change
  };
  for (const Case& k : {Case{0.0, ChangeCause::kNotApplied, 1}, Case{-1.0, ChangeCause::kSignReversed, 1},
                        Case{2.0, ChangeCause::kAppliedTwice, 1}, Case{1000.0, ChangeCause::kMicronAsMm, 1},
                        Case{25.4, ChangeCause::kMmAsInch, 1}, Case{1 / 25.4, ChangeCause::kInchAsMm, 50}}) {
    for (unsigned seed = 1; seed <= 20; ++seed) {
      const ChangeVerification v = Verify(Eigen::VectorXd::Constant(4, k.f), 0.0007, seed, k.scale);
      EXPECT_EQ(v.outcome.verdict, ChangeVerdict::kCause) << k.f << ": " << v.outcome.message;
      ASSERT_FALSE(v.outcome.causes.empty());
      EXPECT_EQ(v.outcome.causes[0].cause, k.cause) << k.f << ": " << v.outcome.message;
      EXPECT_NEAR(v.ratio, k.f, 4 * v.ratio_std + 1e-3 * k.f);
      for (const ParameterChange& r : v.parameters) EXPECT_FALSE(r.as_predicted) << r.name;
    }
  }
  // not applied and "a mm value read as µm" are one for a change of micrometres: both named
  const ChangeVerification v = Verify(Eigen::VectorXd::Zero(4));
  EXPECT_TRUE(Names(v.outcome, ChangeCause::kMmAsMicron)) << v.outcome.message;
  EXPECT_NE(v.outcome.message.find("cannot tell these apart"), std::string::npos) << v.outcome.message;
  // the inch reading is resolved from "not applied" on a 1 mm change
  const ChangeVerification w = Verify(Eigen::VectorXd::Constant(4, 1 / 25.4), 0.0007, 3, 50);
  EXPECT_FALSE(Names(w.outcome, ChangeCause::kNotApplied)) << w.outcome.message;
}

TEST(VerifyChange, OneComponentsSignIsNamed) {
  for (int j = 0; j < 4; ++j) {
    Eigen::VectorXd f = Eigen::VectorXd::Ones(4);
    f[j] = -1;
    const ChangeVerification v = Verify(f, 0.0007, 7 + j);
    ASSERT_EQ(v.outcome.verdict, ChangeVerdict::kCause) << v.outcome.message;
    ASSERT_EQ(v.outcome.causes.size(), 1u) << v.outcome.message;
    EXPECT_EQ(v.outcome.causes[0].cause, ChangeCause::kComponentSign);
    EXPECT_EQ(v.outcome.causes[0].component, kNames[size_t(j)]);
    EXPECT_NE(v.outcome.message.find(kNames[size_t(j)]), std::string::npos);
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(v.parameters[size_t(i)].as_predicted, i != j);
      if (i == j) EXPECT_EQ(v.parameters[size_t(i)].outcome.causes[0].cause, ChangeCause::kSignReversed);
    }
  }
}

TEST(VerifyChange, TooNoisyACheckCannotTellAndNeverNamesACause) {
  // the change (10 - 20 µm) is about the check's sigma (15 µm): no verdict either way
  int named = 0, took = 0;
  for (unsigned seed = 0; seed < 200; ++seed) {
    const ChangeVerification v = Verify(Eigen::VectorXd::Ones(4), 0.015, seed);
    named += v.outcome.verdict == ChangeVerdict::kCause || v.outcome.verdict == ChangeVerdict::kDiffers;
    took += v.took_effect();
    EXPECT_NE(v.outcome.verdict, ChangeVerdict::kCause) << v.outcome.message;
  }
  EXPECT_EQ(took, 0);
  EXPECT_LE(named, 2);
  const ChangeVerification v = Verify(Eigen::VectorXd::Ones(4), 0.015, 1);
  EXPECT_EQ(v.outcome.verdict, ChangeVerdict::kCannotTell);
  EXPECT_NE(v.outcome.message.find("cannot tell"), std::string::npos);
}

TEST(VerifyChange, SomethingElseDiffersWithTheNumbers) {
  const ChangeVerification v = Verify(Eigen::VectorXd::Constant(4, 0.5));
  EXPECT_EQ(v.outcome.verdict, ChangeVerdict::kDiffers) << v.outcome.message;
  EXPECT_NEAR(v.ratio, 0.5, 4 * v.ratio_std);
  EXPECT_NE(v.outcome.message.find("not one of these"), std::string::npos);
  EXPECT_NE(v.outcome.message.find("observed / expected change 0.4"), std::string::npos) << v.outcome.message;
}

TEST(VerifyChange, AnExportsNamesMeetTheChecksSpindleNames) {
  // the export says C's X offset (EX0C) and A's Y offset (EY0A); the check
  // measures them as the spindle's, with the sign turned (workpiece side)
  std::mt19937 rng(5);
  Eigen::VectorXd theta(4), c(4);
  theta << 0.021, -0.013, 0.008, 0.017;
  c = theta;
  Draw d = MakeDraw(theta, c, Eigen::VectorXd::Ones(4), 0.0007, 0.0003, rng);
  d.change.names = {"EX0C", "EY0C", "EY0A", "EZ0A"};
  d.change.values[0] *= -1;
  d.change.values[2] *= -1;
  const ChangeVerification v = VerifyChange(TableTable(), d.previous, d.change, d.now);
  EXPECT_TRUE(v.took_effect()) << v.outcome.message;
  EXPECT_EQ(v.parameters[0].name, "EX0S");
  EXPECT_NEAR(v.parameters[0].expected, 0.021, 0.002);
  // the same names with the sign not turned: the two spindle-named components reversed
  d.change.values[0] *= -1;
  d.change.values[2] *= -1;
  EXPECT_FALSE(VerifyChange(TableTable(), d.previous, d.change, d.now).took_effect());
}

TEST(VerifyChange, BadInputIsRefusedNamed) {
  std::mt19937 rng(5);
  Eigen::VectorXd theta(4);
  theta << 0.021, -0.013, 0.008, 0.017;
  const Draw d = MakeDraw(theta, theta, Eigen::VectorXd::Ones(4), 0.0007, 0.0003, rng);
  const Machine m = TableTable();
  const auto expect_throw = [&](const NamedEstimate& p, const NamedEstimate& c, const NamedEstimate& n,
                                const std::string& what) {
    try {
      VerifyChange(m, p, c, n);
      ADD_FAILURE() << "no error; expected " << what;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  NamedEstimate c = d.change;
  c.names[1] = "EZ0C";  // along C: a sphere check cannot see it
  expect_throw(d.previous, c, d.now, "expect: EZ0C is not measured by this check (it measures: EX0S, EY0C");
  NamedEstimate p = d.previous;
  p.names[3] = "EB0A";
  expect_throw(p, d.change, d.now, "previous: has no EZ0A");
  c = d.change;
  c.values.setZero();
  c.covariance.setZero();
  expect_throw(d.previous, c, d.now, "nothing to verify");
  NamedEstimate p2 = d.previous;
  p2.covariance(0, 1) = p2.covariance(1, 0) = 10 * p2.covariance(0, 0);
  expect_throw(p2, d.change, d.now, "previous.covariance: not positive semi-definite");
  // the change's covariance is not read unless asked (verify.h): a NaN there is no error
  c = d.change;
  c.covariance(1, 1) = std::nan("");
  EXPECT_TRUE(VerifyChange(m, d.previous, c, d.now).took_effect());
  VerifyOptions with;
  with.change_covariance = true;
  try {
    VerifyChange(m, d.previous, c, d.now, with);
    ADD_FAILURE() << "a NaN covariance read without error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("expect.EY0C: covariance with EY0C is not finite"), std::string::npos)
        << e.what();
  }
  c = d.change;
  c.values.conservativeResize(3);
  expect_throw(d.previous, c, d.now, "expect: 4 names but 3 values");
  c = d.change;
  c.values[2] = std::nan("");
  expect_throw(d.previous, c, d.now, "expect.EY0S: value is not finite");
  c = d.change;
  c.names[1] = "EX0S";
  expect_throw(d.previous, c, d.now, "expect: EX0S named twice");
  NamedEstimate n = d.now, q = d.previous;
  n.covariance.setZero();
  q.covariance.setZero();
  expect_throw(q, d.change, n, "singular");
  // a zero change is left out, said so
  c = d.change;
  c.values[3] = 0;
  const ChangeVerification v = VerifyChange(m, d.previous, c, d.now);
  EXPECT_EQ(v.not_compared, std::vector<std::string>{"EZ0A"});
  EXPECT_EQ(v.parameters.size(), 3u);
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
