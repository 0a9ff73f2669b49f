// Hostile values at the C++ boundary, for the sanitizer build
// (scripts/sanitize.sh): seeds and trial counts at the limits of their types,
// numbers at the edge of the double range in JSON (1e308, -1e308, 2^64),
// overflowing axis directions. Each must end in a result or a
// std::invalid_argument naming the field, never in undefined behaviour
// (float->integer casts out of range, signed overflow), an over-sized
// allocation or another exception type. The plain build checks the outcome;
// the sanitizer build also aborts on any UB on the way.
#include <gtest/gtest.h>

#include "test_files.h"

#include <climits>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <string>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/model/machine.h"
#include "fivecal/uncertainty/monte_carlo.h"
#include "fivecal/observations/simulate.h"

namespace fivecal {
namespace {

using nlohmann::json;

std::string TangoSpec() { return ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/tests/data/tango_thin_spec.json"); }

IdentifyOptions SmallFit() {
  IdentifyOptions o;
  o.estimate = {"EX0C", "EA0C", "EB0C", "EX0S", "EY0S", "EB0Z"};
  return o;
}

// Either a value or std::invalid_argument whose message contains `field`;
// any other exception fails the test (gtest reports it).
void ExpectValueOrNamedError(const std::function<void()>& body, const std::string& field) {
  try {
    body();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

// JSON texts of a number that nlohmann stores as a double, a uint64 or an
// int64 at the edge of its type.
const char* const kHugeNumbers[] = {"1e308", "-1e308", "18446744073709551616", "18446744073709551615",
                                    "-9223372036854775808", "4.9e-324", "1e-308"};

// ---- Seeds -----------------------------------------------------------------------

std::string SpecWithSeed(const std::string& seed_text) {
  json spec = json::parse(TangoSpec());
  spec.erase("seed");
  std::string text = spec.dump();
  // Spliced as text: a 2^64 literal or a float must reach the parser as written.
  text.insert(text.size() - 1, ",\"seed\":" + seed_text);
  return text;
}

TEST(HostileSeed, IntegersOverTheWholeUint64RangeAreAccepted) {
  for (const char* s : {"0", "1", "18446744073709551615"}) {
    const SimulationPlan plan = BuildSimulationPlan(SpecWithSeed(s));
    EXPECT_EQ(plan.seed, std::stoull(s)) << s;
  }
}

TEST(HostileSeed, NegativeFloatAndOutOfRangeSeedsAreRefusedByName) {
  // Before: nlohmann's float->uint64 cast of 1e20 or -1.5 was undefined
  // behaviour (the fit ran with seed 0 on x86), and -1 wrapped to 2^64-1.
  for (const char* s : {"-1", "-9223372036854775808", "1.5", "1e20", "-1e308", "1e308",
                        "18446744073709551616", "\"7\"", "null", "true"}) {
    try {
      BuildSimulationPlan(SpecWithSeed(s));
      ADD_FAILURE() << "seed " << s << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("seed"), std::string::npos) << s << ": " << e.what();
    }
  }
}

TEST(HostileSeed, IntegralFloatSeedIsTheInteger) {
  // numpy writes 7.0; JSON Schema counts it as an integer.
  EXPECT_EQ(BuildSimulationPlan(SpecWithSeed("7.0")).seed, 7u);
}

TEST(HostileSeed, AddNoiseAtTheSeedLimits) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  for (uint64_t s : {uint64_t{0}, std::numeric_limits<uint64_t>::max()}) {
    const Dataset ds = AddNoise(plan, s);
    for (const Observation& o : ds.observations) EXPECT_TRUE(o.axes.allFinite()) << s;
  }
  EXPECT_NE(TrialSeed(std::numeric_limits<uint64_t>::max(), std::numeric_limits<uint64_t>::max()),
            TrialSeed(0, 0));
}

// ---- Monte Carlo options at their limits -------------------------------------------

MonteCarloOptions FewTrials() {
  MonteCarloOptions o;
  o.trials = 6;
  o.blocks = 2;
  o.threads = 1;
  o.keep_samples = false;
  return o;
}

void ExpectMonteCarloRefuses(const MonteCarloOptions& o, const std::string& field) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  try {
    MonteCarlo(plan, SmallFit(), o);
    ADD_FAILURE() << field << " accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

TEST(HostileMonteCarlo, TrialCountsBeyondMemoryAreRefusedBeforeAllocating) {
  // Before: INT_MAX trials allocated a trials x p matrix (bad_alloc, or an
  // allocation-size abort under ASan) before any check.
  MonteCarloOptions o = FewTrials();
  for (int t : {INT_MIN, -1, 0, 1, INT_MAX}) {
    o.trials = t;
    ExpectMonteCarloRefuses(o, "trials");
  }
}

TEST(HostileMonteCarlo, ThreadCountsAtTheLimitsAreRefusedByName) {
  // Before: INT_MAX threads with as many trials tried to start that many
  // threads (std::system_error).
  MonteCarloOptions o = FewTrials();
  for (int t : {INT_MIN, -1, INT_MAX}) {
    o.threads = t;
    ExpectMonteCarloRefuses(o, "threads");
  }
}

TEST(HostileMonteCarlo, SignificantDigitsAndBlocksAtTheLimits) {
  // Before: INT_MAX significant digits overflowed the exponent of the
  // numerical tolerance (signed overflow, UB).
  MonteCarloOptions o = FewTrials();
  for (int d : {INT_MIN, 0, INT_MAX}) {
    o.significant_digits = d;
    ExpectMonteCarloRefuses(o, "significant_digits");
  }
  o = FewTrials();
  for (int b : {INT_MIN, 1}) {
    o.blocks = b;
    ExpectMonteCarloRefuses(o, "blocks");
  }
  // More blocks than trials: too few per block for a stability estimate.
  o.blocks = INT_MAX;
  const MonteCarloResult r = MonteCarlo(BuildSimulationPlan(TangoSpec()), SmallFit(), o);
  for (int j = 0; j < r.stability.size(); ++j) EXPECT_TRUE(std::isnan(r.stability[j]));
}

TEST(HostileMonteCarlo, ExtremeSeedAndProbabilityRun) {
  const SimulationPlan plan = BuildSimulationPlan(TangoSpec());
  MonteCarloOptions o = FewTrials();
  o.seed = std::numeric_limits<uint64_t>::max();
  o.threads = 2;
  o.probability = std::numeric_limits<double>::denorm_min();
  o.significant_digits = 17;
  const MonteCarloResult r = MonteCarlo(plan, SmallFit(), o);
  EXPECT_EQ(r.used + r.not_converged + r.failed, 6);
  // Before: p one ulp below 1 ran every trial, then failed in the normal
  // quantile of (1 + p) / 2 = 1.
  for (double p : {0.0, 1.0, -1.0, std::nextafter(1.0, 0.0), std::numeric_limits<double>::quiet_NaN()}) {
    o.probability = p;
    ExpectMonteCarloRefuses(o, "probability");
  }
}

TEST(HostileMonteCarlo, NumericalToleranceAtTheDoubleLimits) {
  for (double u : {std::numeric_limits<double>::denorm_min(), std::numeric_limits<double>::min(),
                   std::numeric_limits<double>::max(), 1.0, 0.0, -1.0,
                   std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()})
    for (int d : {1, 2, 17}) {
      const double t = NumericalTolerance(u, d);
      EXPECT_TRUE(std::isfinite(t) && t >= 0) << u << " " << d;
    }
  for (int d : {INT_MIN, -1, 0, 18, INT_MAX}) EXPECT_THROW(NumericalTolerance(1.0, d), std::invalid_argument) << d;
}

// ---- Huge numbers in JSON -----------------------------------------------------------

// The thin TANGO dataset with one field of the JSON replaced by `number`.
std::string DatasetWith(const std::function<void(json&, const json&)>& set, const char* number) {
  json ds = json::parse(Simulate(TangoSpec()).ToJson());
  set(ds, json::parse(number));
  return ds.dump();
}

void LoadAndFit(const std::string& text) {
  const Dataset ds = Dataset::FromJson(text);
  const Result r = Identify(ds, SmallFit());
  (void)r.ToJson();
}

TEST(HostileJson, HugeAxisValuesReadingsAndTipRadius) {
  for (const char* n : kHugeNumbers) {
    SCOPED_TRACE(n);
    ExpectValueOrNamedError(
        [&] { LoadAndFit(DatasetWith([](json& d, const json& v) { d["observations"][0]["axes"]["X"] = v; }, n)); },
        "observations[0]");
    ExpectValueOrNamedError(
        [&] { LoadAndFit(DatasetWith([](json& d, const json& v) { d["observations"][3]["axes"]["C"] = v; }, n)); },
        "observations[3]");
    ExpectValueOrNamedError(
        [&] { LoadAndFit(DatasetWith([](json& d, const json& v) { d["probe"]["tip_radius"] = v; }, n)); },
        "tip_radius");
  }
}

TEST(HostileJson, HugeArtefactGeometry) {
  const json ds = json::parse(Simulate(TangoSpec()).ToJson());
  ASSERT_TRUE(ds.contains("artefact"));
  for (const char* n : kHugeNumbers) {
    for (const char* part : {"facets", "spheres", "scale_bars"}) {
      if (!ds["artefact"].contains(part) || ds["artefact"][part].empty()) continue;
      for (auto& [key, value] : ds["artefact"][part][0].items()) {
        if (value.is_string()) continue;
        json d = ds;
        if (value.is_array()) d["artefact"][part][0][key][2] = json::parse(n);
        else d["artefact"][part][0][key] = json::parse(n);
        SCOPED_TRACE(std::string(part) + "[0]." + key + " = " + n);
        ExpectValueOrNamedError([&] { LoadAndFit(d.dump()); }, "artefact");
      }
    }
  }
}

TEST(HostileJson, MachineAxisDirectionsAtTheDoubleLimits) {
  // [0, 0, 1.35e154] squares to infinity: a plain norm() made it (0, 0, 0).
  const json spec = json::parse(TangoSpec());
  for (const char* n : {"1.35e154", "1e308", "-1e308", "4.9e-324", "18446744073709551616"}) {
    json m = spec["machine"];
    m["axes"]["Z"]["direction"] = json::array({0, 0, json::parse(n)});
    ExpectValueOrNamedError(
        [&] {
          const Machine machine = Machine::FromJson(m.dump());
          const int z = [&] {
            for (int k = 0; k < machine.num_axes(); ++k)
              if (machine.axis(k).name == 'Z') return k;
            return -1;
          }();
          ASSERT_GE(z, 0);
          EXPECT_NEAR(machine.axis(z).direction.norm(), 1.0, 1e-12) << n;
        },
        "Z");
  }
}

TEST(HostileJson, SpecNoiseAndErrorsAtTheDoubleLimits) {
  for (const char* n : kHugeNumbers) {
    SCOPED_TRACE(n);
    json spec = json::parse(TangoSpec());
    spec["sigma"] = json::parse(n);
    ExpectValueOrNamedError([&] { (void)BuildSimulationPlan(spec.dump()); }, "sigma");
    spec = json::parse(TangoSpec());
    spec["errors"]["EX0C"] = json::parse(n);
    ExpectValueOrNamedError([&] { (void)BuildSimulationPlan(spec.dump()); }, "EX0C");
  }
}

}  // namespace
}  // namespace fivecal
