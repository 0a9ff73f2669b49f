// The streaming writers (observations/writer.h): the JSON text loads back as
// the same dataset whatever the piece size, a sink that fails stops the
// write, and the columns of every block load back through ColumnLoader as
// the same observations (the flat fast path and the JSON path alike).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/observations/columns.h"
#include "fivecal/observations/dataset.h"
#include "fivecal/observations/writer.h"

namespace fivecal {
namespace {

const char* kMachine = R"("machine": {"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})";

// Samples of one kind: ball3d (flat fast path: ids, per-row noise, two
// mountings) or facet touches (through the kind's Write: targets, backlash).
Dataset Samples(const std::string& kind, int n) {
  std::string obs;
  for (int i = 0; i < n; ++i) {
    const std::string axes = R"("axes": {"X": )" + std::to_string(0.1 * i) + R"(, "Y": -1.5, "Z": )" +
                             std::to_string(-40 + 0.01 * i) + R"(, "B": 30, "C": )" + std::to_string(i % 360) + "}";
    std::string o;
    if (kind == "ball3d") {
      o = R"({"type": "ball3d", "setup": ")" + std::string(i % 2 ? "R1" : "R2") + R"(", )" + axes +
          R"(, "tool_ball": [0, 0, 100], "table_ball": [100, 0.25, 1e-7], "measured": [0.001, )" +
          std::to_string(-0.0001 * i) + ", 3e-05]";
      if (i % 3 == 0) o += R"(, "sigma": [0.001, 0.002, 0.003])";
      if (i % 3 == 1) o += R"(, "sigma": 0.0015)";
      if (i % 4 == 0) o += R"(, "id": "s\"q)" + std::to_string(i) + "\"";
    } else {
      o = R"({"type": "facet", "target": "F1", )" + axes + R"(, "direction": {"X": 1, "C": -1})";
    }
    obs += (i ? ", " : "") + o + "}";
  }
  return Dataset::FromJson(std::string("{") + kMachine +
                           R"(, "probe": {"tip_radius": 3.0}, "artefact": {"facets": [{"id": "F1",
                              "point": [0,0,10], "normal": [0,0,1]}]}, "observations": [)" +
                           obs + "]}");
}

std::string Written(const Dataset& ds, size_t chunk, int* pieces) {
  std::string out;
  *pieces = 0;
  WriteDatasetJson(ds, [&](const char* p, size_t n) { out.append(p, n), ++*pieces; }, chunk);
  return out;
}

TEST(DatasetWriter, JsonLoadsBackTheSameDatasetWhateverThePieceSize) {
  for (const char* kind : {"ball3d", "facet"}) {
    const Dataset ds = Samples(kind, 40);
    int whole = 0, small = 0;
    const std::string a = Written(ds, size_t{1} << 20, &whole), b = Written(ds, 200, &small);
    EXPECT_EQ(whole, 1);
    EXPECT_GT(small, 10);
    EXPECT_EQ(a, b);
    EXPECT_EQ(Dataset::FromJson(a).ToJson(), ds.ToJson()) << kind;
  }
}

TEST(DatasetWriter, ASinkThatFailsStopsTheWrite) {
  const Dataset ds = Samples("ball3d", 200);
  int calls = 0;
  EXPECT_THROW(WriteDatasetJson(
                   ds,
                   [&](const char*, size_t) {
                     if (++calls == 2) throw std::runtime_error("disk full");
                   },
                   100),
               std::runtime_error);
  EXPECT_EQ(calls, 2);
}

// Every block of columns, handed to the loader as Arrow buffers would be.
Dataset ThroughColumns(const Dataset& ds, int64_t block) {
  const ColumnWriter w(ds);
  ColumnLoader loader(Dataset::FromJson(ds.Subset({}).ToJson(), false), w.rows());
  for (int64_t b = 0; b < w.rows(); b += block) {
    const int64_t e = std::min(w.rows(), b + block);
    std::vector<ColumnWriter::Block> cols = w.Write(b, e);
    std::vector<std::vector<double>> numbers;
    std::vector<std::vector<int64_t>> offsets;
    numbers.reserve(cols.size());
    offsets.reserve(cols.size());
    ColumnBatch batch;
    batch.rows = e - b;
    for (size_t c = 0; c < cols.size(); ++c) {
      const ColumnWriter::Spec& s = w.columns()[c];
      const uint8_t* valid = cols[c].valid.empty() ? nullptr : cols[c].valid.data();
      if (s.name == "type") {
        batch.kind = cols[c].text.substr(0, static_cast<size_t>(cols[c].offsets[1]));
      } else if (s.type == ColumnWriter::Type::kString) {
        offsets.emplace_back(cols[c].offsets.begin(), cols[c].offsets.end());
        batch.strings.push_back({s.name, offsets.back().data(), cols[c].text.data(), valid});
      } else {
        if (s.type == ColumnWriter::Type::kInt8) numbers.emplace_back(cols[c].small.begin(), cols[c].small.end());
        else numbers.push_back(cols[c].numbers);
        batch.numbers.push_back({s.name, numbers.back().data(), valid});
      }
    }
    loader.Add(batch);
  }
  return loader.Finish();
}

TEST(DatasetWriter, ColumnsLoadBackAsTheSameObservations) {
  for (const char* kind : {"ball3d", "facet"}) {
    const Dataset ds = Samples(kind, 41);
    EXPECT_EQ(ThroughColumns(ds, 41).ToJson(), ds.ToJson()) << kind;
    EXPECT_EQ(ThroughColumns(ds, 7).ToJson(), ds.ToJson()) << kind;
  }
  const Dataset ds = Samples("ball3d", 5);
  const ColumnWriter w(ds);
  std::vector<std::string> names;
  for (const ColumnWriter::Spec& s : w.columns()) names.push_back(s.name);
  const std::vector<std::string> expected = {"type", "id", "X", "Y", "Z", "B", "C", "S", "setup", "measured_x",
                                             "measured_y", "measured_z", "table_ball_x", "table_ball_y",
                                             "table_ball_z", "tool_ball_x", "tool_ball_y", "tool_ball_z", "sigma",
                                             "sigma_x", "sigma_y", "sigma_z"};
  EXPECT_EQ(names, expected);
  EXPECT_THROW(w.Write(2, 1), std::invalid_argument);
}

// Consecutive pieces of `ds` (the head with observations [b, e)).
std::vector<Dataset> Pieces(const Dataset& ds, size_t rows) {
  std::vector<Dataset> out;
  for (size_t b = 0; b < ds.observations.size(); b += rows) {
    std::vector<int> idx;
    for (size_t i = b; i < std::min(ds.observations.size(), b + rows); ++i) idx.push_back(static_cast<int>(i));
    out.push_back(ds.Subset(idx));
  }
  return out;
}

TEST(DatasetWriter, PiecesWriteWhatTheWholeWrites) {
  // fivecal convert writes a file it reads piece by piece: the same text and
  // the same columns as the whole dataset's, whatever the piece size.
  for (const char* kind : {"ball3d", "facet"}) {
    const Dataset ds = Samples(kind, 41);
    int n = 0;
    const std::string whole = Written(ds, 1 << 20, &n);
    const ColumnWriter all(ds);
    for (size_t rows : {1, 7, 41}) {
      std::string text;
      DatasetJsonWriter w(ds, [&](const char* p, size_t k) { text.append(p, k); }, 64);
      ColumnWriter cw;
      bool first = true;
      size_t offset = 0;
      const std::vector<Dataset> pieces = Pieces(ds, rows);
      for (const Dataset& piece : pieces) {
        w.Add(piece);
        const bool changed = cw.Scan(piece, static_cast<int64_t>(offset));
        if (first) EXPECT_TRUE(changed);
        first = false;
        offset += piece.observations.size();
      }
      w.Finish();
      EXPECT_EQ(text, whole) << kind << " " << rows;
      ASSERT_EQ(cw.columns().size(), all.columns().size()) << kind << " " << rows;
      offset = 0;
      for (const Dataset& piece : pieces) {
        const int64_t k = static_cast<int64_t>(piece.observations.size());
        const auto a = cw.Write(piece, 0, k), b = all.Write(static_cast<int64_t>(offset), static_cast<int64_t>(offset) + k);
        for (size_t c = 0; c < a.size(); ++c) {
          EXPECT_EQ(cw.columns()[c].name, all.columns()[c].name);
          EXPECT_EQ(a[c].text, b[c].text);
          EXPECT_EQ(a[c].offsets, b[c].offsets);
          EXPECT_EQ(a[c].small, b[c].small);
          EXPECT_EQ(a[c].valid, b[c].valid);
          ASSERT_EQ(a[c].numbers.size(), b[c].numbers.size());
          for (size_t r = 0; r < a[c].numbers.size(); ++r)
            EXPECT_TRUE(a[c].numbers[r] == b[c].numbers[r] || (std::isnan(a[c].numbers[r]) && std::isnan(b[c].numbers[r])));
        }
        offset += piece.observations.size();
      }
    }
  }
  // A column the first piece lacks (ids from observation 4 on) changes the
  // columns when its piece is scanned: a streamed writer starts again.
  const Dataset ds = Samples("ball3d", 9);
  ColumnWriter cw;
  const std::vector<Dataset> pieces = Pieces(ds, 2);  // ids at 0, 4, 8
  EXPECT_TRUE(cw.Scan(pieces[0]));
  EXPECT_FALSE(cw.Scan(pieces[1], 2));
  EXPECT_FALSE(cw.Scan(pieces[2], 4));
  const Dataset late = Samples("ball3d", 9).Subset({1, 2, 3, 4});
  ColumnWriter cl;
  EXPECT_TRUE(cl.Scan(late.Subset({0, 1})));
  EXPECT_TRUE(cl.Scan(late.Subset({2, 3}), 2));  // the id of sample 4
  EXPECT_EQ(cl.columns()[1].name, "id");
}

}  // namespace
}  // namespace fivecal
