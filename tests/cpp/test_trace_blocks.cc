// Long traces as column blocks (dataset.h TraceBlock): the same samples as
// blocks and as one Observation each give the same fit bit for bit, the
// expansion and the packing are each other's inverse in order, ids and
// noise, Subset slices blocks, and Validate / the column loader name the
// row of a bad sample.
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>
#include <stdexcept>

#include "fivecal/model/kinematics.h"
#include "fivecal/observations/columns.h"
#include "fivecal/observations/registry.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

const std::map<std::string, double> kTruth = {{"EB0A", 3e-5}, {"EA0C", 4e-5}, {"EB0C", -2e-5}, {"EY0C", -0.012}};

// R-test (ball3d) or ball-bar (dbb) samples of the c600u at random (A, C),
// simulated at kTruth with 0.5 um noise, as one column block.
Dataset Trace(ObservationType type, int n, unsigned seed = 1) {
  Dataset ds(Machine::Load(std::string(FIVECAL_SOURCE_DIR) + "/examples/machines/c600u.json"));
  const Machine& m = ds.machine();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 5e-4);
  Eigen::MatrixXd axes = Eigen::MatrixXd::Zero(n, m.num_axes());
  Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i) {
    // A ball bar of 100 mm stays within its +-100 mm reading range at small tilts.
    axes(i, m.AxisIndex('A')) = type == ObservationType::kDbb ? -10 + 20 * u(rng) : -90 + 180 * u(rng);
    axes(i, m.AxisIndex('C')) = 360 * u(rng);
    for (char a : {'X', 'Y', 'Z'}) axes(i, m.AxisIndex(a)) = -20 + 40 * u(rng);
    dirs(i, m.AxisIndex('C')) = i % 3 ? 1 : -1;
  }
  const bool bar = type == ObservationType::kDbb;
  const Eigen::Vector3d tool(0, 0, 150), table(50, 0, 80);
  ds.AppendBallSamples(type, bar ? "A1" : "R1", axes, &dirs, tool, table, bar ? 100.0 : 0.0,
                       Eigen::MatrixXd::Zero(n, bar ? 1 : 3));
  // The readings the true machine gives (its residuals at zero readings).
  std::vector<int> src;
  const Eigen::VectorXd r = PredictResiduals(ds, kTruth, &src);
  TraceBlock& b = ds.blocks.back();
  for (int i = 0; i < n; ++i)
    for (size_t c = 0; c < b.values.size(); ++c)
      b.values[c][i] = r[b.values.size() * i + c] + noise(rng);
  return ds;
}

void ExpectSameResult(const Result& a, const Result& b) {
  EXPECT_EQ(a.fit_path, b.fit_path);
  EXPECT_EQ(a.verdict(), b.verdict());
  ASSERT_EQ(a.values.size(), b.values.size());
  for (Eigen::Index i = 0; i < a.values.size(); ++i) EXPECT_EQ(a.values[i], b.values[i]) << i;
  for (Eigen::Index i = 0; i < a.std.size(); ++i) EXPECT_EQ(a.std[i], b.std[i]) << i;
  EXPECT_EQ(a.chi2, b.chi2);
  EXPECT_EQ(a.residuals, b.residuals);
  EXPECT_EQ(a.residual_vectors, b.residual_vectors);
  EXPECT_EQ(a.points, b.points);
}

TEST(TraceBlocks, ArraySamplesAreOneBlockAndExpandInOrder) {
  Dataset ds = Trace(ObservationType::kBall3d, 50);
  ASSERT_EQ(ds.blocks.size(), 1u);
  EXPECT_TRUE(ds.observations.empty());
  EXPECT_EQ(ds.size(), 50u);
  const Dataset objects = ds.Expanded();
  ASSERT_EQ(objects.observations.size(), 50u);
  EXPECT_TRUE(objects.blocks.empty());
  EXPECT_EQ(objects.ToJson(), ds.ToJson());
  // Packing is the inverse: the same rows, one block again.
  Dataset packed = objects;
  EXPECT_EQ(packed.PackTraces(), 50u);
  EXPECT_EQ(packed.blocks.size(), 1u);
  EXPECT_EQ(packed.ToJson(), ds.ToJson());
  EXPECT_EQ(objects.Expanded().PackTraces(100), 0u);  // fewer than min_rows: left alone
}

TEST(TraceBlocks, BlocksAndObjectsFitAlike) {
  for (ObservationType type : {ObservationType::kBall3d, ObservationType::kDbb}) {
    const Dataset ds = Trace(type, 4000);
    const Dataset objects = ds.Expanded();
    for (const char* path : {"normal_equations", "dense"}) {
      IdentifyOptions opt;
      opt.estimate = {"EA0C", "EB0C"};
      if (type == ObservationType::kBall3d) opt.estimate = {"EB0A", "EA0C", "EB0C", "EY0C"};
      opt.fit_path = path;
      opt.num_threads = 2;
      SCOPED_TRACE(std::string(ObservationTypeName(type)) + " " + path);
      const Result a = Identify(ds, opt), b = Identify(objects, opt);
      EXPECT_EQ(a.fit_path, path);
      ExpectSameResult(a, b);
    }
  }
}

// The report point of an R-test sample comes from its residual
// (P = table + measured + r, BallMountKind::PointFromRows), not from the
// chain a third time: it must be the chain's tool ball at the solution.
TEST(TraceBlocks, Ball3dReportPointsAreTheChainsToolBall) {
  const Dataset ds = Trace(ObservationType::kBall3d, 2000);
  const Machine& m = ds.machine();
  const TraceBlock& b = ds.blocks.back();
  const int n = static_cast<int>(b.size());
  Eigen::MatrixXd axes(n, m.num_axes());
  Eigen::MatrixXi dirs(n, m.num_axes());
  for (int k = 0; k < m.num_axes(); ++k)
    for (int i = 0; i < n; ++i) {
      axes(i, k) = b.axes[k][i];
      dirs(i, k) = b.direction.empty() ? 0 : b.direction[k][i];
    }
  for (const char* path : {"normal_equations", "dense"}) {
    IdentifyOptions opt;
    opt.estimate = {"EB0A", "EA0C", "EB0C", "EY0C", "ball3d.R1.tool.x", "ball3d.R1.tool.z"};
    opt.fit_path = path;
    const Result res = Identify(ds, opt);
    SCOPED_TRACE(path);
    ASSERT_EQ(res.points.rows(), n);
    const Eigen::VectorXd theta = res.values.head(m.num_parameters());
    auto value = [&](const std::string& name) {
      const auto it = std::find(res.names.begin(), res.names.end(), name);
      return it == res.names.end() ? 0.0 : res.values[it - res.names.begin()];
    };
    const Eigen::Vector3d tip(value("ball3d.R1.tool.x"), value("ball3d.R1.tool.y"),
                              150.0 + value("ball3d.R1.tool.z"));
    EXPECT_NE(tip.x(), 0.0);  // a fitted tool ball offset, not the nominal one
    Eigen::MatrixXd expected;
    ToolPoses(m, theta, axes, &dirs, &expected, nullptr, &tip);
    EXPECT_LT((res.points - expected).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(res.residual_vectors.rows(), n);
    for (int i = 0; i < n; i += 97)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(res.residual_vectors(i, c), res.residuals[3 * i + c]);
  }
}

TEST(TraceBlocks, SubsetSlicesBlocksAndKeepsOrder) {
  const Dataset ds = Trace(ObservationType::kDbb, 30);
  const Dataset objects = ds.Expanded();
  const std::vector<int> idx = {4, 5, 6, 20, 2};
  const Dataset a = ds.Subset(idx), b = objects.Subset(idx);
  EXPECT_EQ(a.ToJson(), b.ToJson());
  EXPECT_EQ(a.size(), idx.size());
  EXPECT_EQ(a.block_rows(), idx.size());
  EXPECT_THROW(ds.Subset({30}), std::invalid_argument);
}

TEST(TraceBlocks, ValidateNamesTheRowOfABadSample) {
  Dataset ds = Trace(ObservationType::kBall3d, 40);
  ds.blocks[0].values[1][17] = 2e5;  // beyond any length
  try {
    ds.Validate();
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("observations[17].measured[1]"), std::string::npos) << e.what();
  }
  ds = Trace(ObservationType::kBall3d, 40);
  ds.blocks[0].direction[ds.machine().AxisIndex('C')][9] = 2;
  try {
    ds.Validate();
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("observations[9].direction.C"), std::string::npos) << e.what();
  }
}

TEST(TraceBlocks, ConsumersOfObservationsRefuseUnexpandedBlocks) {
  // A consumer that needs an Observation per sample must expand first;
  // handed blocks, it says so instead of leaving their rows out.
  const Dataset ds = Trace(ObservationType::kBall3d, 20);
  const ParameterTable t(ds);
  EXPECT_GE(t.Index("ball3d.R1.table.x"), 0);
  EXPECT_THROW(Problem(ds, t, Eigen::VectorXd::Zero(t.size()), {}), std::logic_error);
}

TEST(TraceBlocks, TheColumnLoaderWritesBlocksAndNamesRowAndColumn) {
  const Dataset ds = Trace(ObservationType::kBall3d, 64);
  const Machine& m = ds.machine();
  const int n = 64;
  std::vector<std::vector<double>> cols;
  std::vector<std::string> names;
  for (int k = 0; k < m.num_axes(); ++k) {
    names.push_back(std::string(1, m.axis(k).name));
    cols.push_back(ds.blocks[0].axes[k]);
  }
  for (int c = 0; c < 3; ++c) {
    names.push_back(std::string("measured_") + "xyz"[c]);
    cols.push_back(ds.blocks[0].values[c]);
  }
  for (const char* ball : {"tool_ball", "table_ball"})
    for (int c = 0; c < 3; ++c) {
      names.push_back(std::string(ball) + "_" + "xyz"[c]);
      const auto& d = std::get<BallMountData>(ds.blocks[0].common);
      cols.push_back(std::vector<double>(n, (std::string(ball) == "tool_ball" ? d.tool_ball : d.table_ball)[c]));
    }
  auto load = [&](int bad_col, int bad_row, double x) {
    std::vector<std::vector<double>> c = cols;
    if (bad_col >= 0) c[bad_col][bad_row] = x;
    Dataset head(m);
    ColumnLoader l(head, n);
    ColumnBatch b;
    b.kind = "ball3d";
    b.rows = n;
    for (size_t k = 0; k < c.size(); ++k) b.numbers.push_back({names[k], c[k].data(), nullptr});
    StringColumn setup;
    setup.name = "setup";
    std::vector<int64_t> off(n + 1);
    std::string text;
    for (int r = 0; r <= n; ++r) off[r] = 2 * r;
    for (int r = 0; r < n; ++r) text += "R1";
    setup.offsets = off.data();
    setup.data = text.data();
    b.strings.push_back(setup);
    l.Add(b);
    return l.Finish();
  };
  const Dataset back = load(-1, 0, 0);
  EXPECT_TRUE(back.observations.empty());
  ASSERT_EQ(back.blocks.size(), 1u);
  Observation a, b;
  for (size_t i = 0; i < 64; i += 7) {
    const Observation& x = ds.Row(i, &a);
    const Observation& y = back.Row(i, &b);
    EXPECT_EQ(x.axes, y.axes);
    EXPECT_EQ(x.data<BallMountData>(), y.data<BallMountData>());
  }
  const int my = m.num_axes() + 1;
  try {
    load(my, 17, std::numeric_limits<double>::quiet_NaN());
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ball3d row 17, column measured_y: NaN"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace fivecal
