// Writing a dataset out without building it whole a second time: the JSON
// file streamed piece by piece, and the columns of a columnar (Parquet) file
// block by block (docs/formats.md, "Dataset" and "Columnar datasets"). The
// writing half of columns.h: the column names are the ones ColumnLoader
// reads, so a block written here loads back as the same observations.
//
// Both walk the observations once per output and keep at most one piece or
// block in memory: 10^6 samples take seconds and a few tens of MB beyond the
// dataset itself, where a JSON document of the whole (Dataset::ToJson,
// parsed into Python dicts) took minutes and gigabytes.
#ifndef FIVECAL_OBSERVATIONS_WRITER_H_
#define FIVECAL_OBSERVATIONS_WRITER_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

// Receives the output piece by piece. An exception it throws stops the write
// and propagates (the caller's file is then left as it was: the Python
// layer writes to a temporary file and renames it only on success).
using ByteSink = std::function<void(const char* data, size_t size)>;

// The dataset as a JSON file, handed to `sink` in pieces of about
// `chunk_bytes`: the head (machine, probe, artefact, instruments, set-up
// uncertainty) indented, then one observation per line, "type" first. It
// loads back (Dataset::FromJson) as the same dataset: ToJson of both is the
// same text.
void WriteDatasetJson(const Dataset& ds, const ByteSink& sink, size_t chunk_bytes = size_t{1} << 20);

// The head of a dataset file (everything but the observations) as JSON text:
// what a columnar file carries as its metadata, one entry per key.
std::map<std::string, std::string> DatasetHead(const Dataset& ds);

// The columns of a columnar dataset, named as ColumnLoader reads them.
class ColumnWriter {
 public:
  enum class Type { kString, kFloat64, kInt8 };
  struct Spec {
    std::string name;
    Type type = Type::kFloat64;
  };
  // One column over a block of rows: `numbers` (kFloat64), `small` (kInt8)
  // or `offsets` (rows + 1) and `text` (kString); `valid` per row (0: null,
  // the observation has no such key), empty when every row holds a value.
  struct Block {
    std::vector<double> numbers;
    std::vector<int8_t> small;
    std::vector<int32_t> offsets;
    std::string text;
    std::vector<uint8_t> valid;
  };

  // Walks every observation once to find the columns: "type", "id" (when an
  // observation has one), the axes by letter (linear, rotary, spindle),
  // dir_<axis> where some observation has a backlash direction, each kind's
  // own keys (3-vectors as <key>_x|y|z, a second pose <name>_<axis>) in the
  // order they first appear, the noise last ("sigma", and "sigma_<r>" or
  // "sigma_x|y|z" for one value per residual row). std::invalid_argument
  // names the observation and key of a value no column can hold. The dataset
  // must outlive the writer.
  explicit ColumnWriter(const Dataset& ds);

  const std::vector<Spec>& columns() const { return columns_; }
  int64_t rows() const { return static_cast<int64_t>(ds_.size()); }
  // Rows [begin, end) of every column, in columns() order.
  std::vector<Block> Write(int64_t begin, int64_t end) const;

 private:
  // Where a kind's own key goes: one column, three (a vector) or one per
  // machine axis (<name>_axes).
  struct KeyColumns {
    enum Shape { kNumber, kText, kVector, kAxes } shape = kNumber;
    int first = -1;            // column of a number or text, of component x of a vector
    std::vector<int> by_axis;  // kAxes: column of each machine axis, -1 when no row gives it
  };
  const Dataset& ds_;
  std::vector<Spec> columns_;
  std::map<std::string, KeyColumns, std::less<>> keys_;  // found by name as the kinds write them
  int id_ = -1, sigma_ = -1, sigma_rows_ = -1;  // sigma_rows_: column of row 1 of per-row noise
  bool numbered_sigma_ = false;
  std::vector<int> axis_col_, dir_col_;  // by machine axis index; dir -1 when no column
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_WRITER_H_
