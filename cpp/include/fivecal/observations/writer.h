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
#include <memory>
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

// WriteDatasetJson piece by piece: the head of `head` (its observations are
// not written), then the observations Add is given, one piece or one
// observation at a time (pieces of one file, each with the head's machine),
// then Finish. The text is the same as WriteDatasetJson of the whole.
class DatasetJsonWriter {
 public:
  DatasetJsonWriter(const Dataset& head, ByteSink sink, size_t chunk_bytes = size_t{1} << 20);
  ~DatasetJsonWriter();
  DatasetJsonWriter(const DatasetJsonWriter&) = delete;
  DatasetJsonWriter& operator=(const DatasetJsonWriter&) = delete;
  void Add(const Dataset& piece);
  void Add(const Observation& o);
  void Finish();

 private:
  struct State;
  ByteSink sink_;
  size_t chunk_bytes_;
  Machine machine_;
  std::unique_ptr<State> state_;
  std::string buf_;
  size_t written_ = 0;
};

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
  // A writer of pieces (a file read piece by piece): Scan each piece, then
  // Write it; the columns are those of the pieces scanned so far together,
  // the same as the whole dataset's once every piece is scanned.
  ColumnWriter() = default;
  // Adds what the observations of `piece` hold (`offset`: the index of its
  // first observation in the whole, for messages); true when the columns
  // changed (the first piece's scan always changes them).
  bool Scan(const Dataset& piece, int64_t offset = 0);

  const std::vector<Spec>& columns() const { return columns_; }
  int64_t rows() const { return ds_ ? static_cast<int64_t>(ds_->size()) : 0; }
  // Rows [begin, end) of every column, in columns() order: of the dataset
  // the writer was made with, or of a piece it has scanned (or one whose
  // rows hold nothing beyond the columns).
  std::vector<Block> Write(int64_t begin, int64_t end) const;
  std::vector<Block> Write(const Dataset& piece, int64_t begin, int64_t end) const;

 private:
  // Where a kind's own key goes: one column, three (a vector) or one per
  // machine axis (<name>_axes); indices into own_.
  struct KeyColumns {
    enum Shape { kNumber, kText, kVector, kAxes } shape = kNumber;
    int first = -1;            // column of a number or text, of component x of a vector
    std::vector<int> by_axis;  // kAxes: column of each machine axis, -1 when no row gives it
  };
  // columns_ from what the scans found; whether they changed.
  bool Layout();

  const Dataset* ds_ = nullptr;
  std::shared_ptr<const Machine> machine_;
  // What the scans found.
  bool any_id_ = false, one_sigma_ = false, numbered_sigma_ = false;
  std::vector<bool> any_dir_;
  int row_sigmas_ = 0;
  std::vector<Spec> own_;  // the kinds' own columns, in the order they first appear
  std::map<std::string, KeyColumns, std::less<>> keys_;  // found by name as the kinds write them
  // The layout.
  std::vector<Spec> columns_;
  int own_base_ = 0;  // column of own_[0]
  int id_ = -1, sigma_ = -1, sigma_rows_ = -1;  // sigma_rows_: column of row 1 of per-row noise
  std::vector<int> axis_col_, dir_col_;  // by machine axis index; dir -1 when no column
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_WRITER_H_
