// The columnar loader (observations/columns.h): observations of a kind built
// from column buffers read as the same JSON observations do, and every
// refusal names the kind, the row and the column.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/observations/columns.h"
#include "fivecal/observations/dataset.h"

namespace fivecal {
namespace {

const char* kHead = R"({"machine": {"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}},
 "artefact": {"facets": [{"id": "F1", "point": [0,0,10], "normal": [0,0,1]}]},
 "probe": {"tip_radius": 3.0}, "observations": []})";

// Three ball3d samples of mounting R1, as Arrow would hold them.
struct Ball3dColumns {
  std::vector<std::vector<double>> values = {
      {1, 2, 3}, {4, 5, 6}, {-1, -2, -3}, {0, 30, 60}, {0, 45, 90}, {0, 0, 0},  // X Y Z B C S
      {0.001, 0.002, 0.003}, {0, 0, 0}, {-0.001, 0, 0.001},                      // measured
      {0, 0, 0}, {0, 0, 0}, {100, 100, 100}, {50, 50, 50}, {0, 0, 0}, {0, 0, 0}};
  std::vector<std::string> names = {"X", "Y", "Z", "B", "C", "S", "measured_x", "measured_y", "measured_z",
                                    "tool_ball_x", "tool_ball_y", "tool_ball_z", "table_ball_x", "table_ball_y",
                                    "table_ball_z"};
  std::vector<int64_t> offsets = {0, 2, 4, 6};
  std::string setup = "R1R1R1";
  ColumnBatch Batch() const {
    ColumnBatch b;
    b.kind = "ball3d";
    b.rows = 3;
    for (size_t c = 0; c < names.size(); ++c) b.numbers.push_back({names[c], values[c].data(), nullptr});
    b.strings.push_back({"setup", offsets.data(), setup.data(), nullptr});
    return b;
  }
};

void ExpectInvalid(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

Dataset Load(const ColumnBatch& b) {
  ColumnLoader l(Dataset::FromJson(kHead, false), b.rows);
  l.Add(b);
  return l.Finish();
}

TEST(Columns, Ball3dRowsReadAsTheirJsonObservations) {
  const Ball3dColumns c;
  const Dataset ds = Load(c.Batch());
  ASSERT_EQ(ds.observations.size(), 3u);
  const Observation& o = ds.observations[1];
  EXPECT_EQ(o.type, ObservationType::kBall3d);
  EXPECT_EQ(o.setup, "R1");
  EXPECT_EQ(o.data<BallMountData>().measured, Eigen::Vector3d(0.002, 0, 0));
  EXPECT_EQ(o.data<BallMountData>().tool_ball, Eigen::Vector3d(0, 0, 100));
  // The same observation from JSON: identical dataset text.
  const Dataset js = Dataset::FromJson(ds.ToJson());
  EXPECT_EQ(js.ToJson(), ds.ToJson());
}

TEST(Columns, NanNamesKindRowAndColumn) {
  Ball3dColumns c;
  c.values[7][2] = std::numeric_limits<double>::quiet_NaN();
  ExpectInvalid([&] { Load(c.Batch()); }, "ball3d row 2, column measured_y: NaN");
}

TEST(Columns, UnknownAndMissingColumnsAreNamed) {
  Ball3dColumns c;
  c.names[6] = "mesured_x";
  ExpectInvalid([&] { Load(c.Batch()); }, "unknown column 'mesured_x' (did you mean \"measured_x\"?)");
  Ball3dColumns d;
  d.names.erase(d.names.begin() + 1);
  d.values.erase(d.values.begin() + 1);
  ExpectInvalid([&] { Load(d.Batch()); }, "missing column Y");
}

TEST(Columns, KindChecksKeepTheirMeaning) {
  // A setup with a dot is refused by the ball kinds' own check.
  Ball3dColumns c;
  c.setup = "R.1R1R1";
  c.offsets = {0, 3, 5, 7};
  ExpectInvalid([&] { Load(c.Batch()); }, "must not contain '.'");
}

TEST(Columns, PositionsPlaceRowsAndEveryRowMustBeFilled) {
  const Ball3dColumns c;
  ColumnBatch b = c.Batch();
  const std::vector<int64_t> pos = {3, 1, 0};
  b.positions = pos.data();
  ColumnLoader l(Dataset::FromJson(kHead, false), 4);
  l.Add(b);
  ExpectInvalid([&] { l.Finish(); }, "row 2: no observation");
}

}  // namespace
}  // namespace fivecal
