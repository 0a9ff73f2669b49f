// Observations from column arrays: the reading half of a columnar dataset
// (Parquet, docs/formats.md "Columnar datasets (Parquet)"). The caller hands
// over the columns of a run of rows of one kind as raw buffers (Arrow's own
// buffers: float64 values, large-string offsets and bytes, a validity mask);
// nothing is converted row by row outside C++.
//
// A column's name says which observation key it fills, for every kind alike
// (the names of fivecal's observation tables, docs/formats.md):
//   X, Y, B, ...        the axis readings ("axes")
//   dir_X, ...          the backlash directions
//   <key>_x|y|z         a 3-vector key (tool_ball_x)
//   <name>_X, ...       the axis letters of key <name>_axes (reference_C)
//   sigma, sigma_<r>    one noise for every row, or one per residual row (1..)
//   <key>               a number or string key (reading, setup, target, id)
// Which keys a kind has, and what they mean, is the kind's own business: its
// json_keys() decide which columns exist, its Read() reads each row's keys,
// and Dataset::Validate() checks the whole as for a JSON file.
#ifndef FIVECAL_OBSERVATIONS_COLUMNS_H_
#define FIVECAL_OBSERVATIONS_COLUMNS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

struct NumberColumn {
  std::string name;
  const double* values = nullptr;
  const uint8_t* valid = nullptr;  // nullptr: every row holds a value; 0: null (the key is absent)
};

struct StringColumn {
  std::string name;
  const int64_t* offsets = nullptr;  // rows + 1 entries into `data`
  const char* data = nullptr;
  const uint8_t* valid = nullptr;
};

// The rows of one kind: `rows` entries of every column.
struct ColumnBatch {
  std::string kind;  // the observations' "type"
  int64_t rows = 0;
  std::vector<NumberColumn> numbers;
  std::vector<StringColumn> strings;
  // The dataset index of each row (the row of the file); nullptr: the rows
  // follow the previous batch.
  const int64_t* positions = nullptr;
};

// Appends one row to a column block (dataset.h TraceBlock): `axes` and
// `direction` (null: all 0) na values, `values` the kind's per-row values,
// `sigma` its rows' declared noise (null: the default), `id` (null or "":
// none). A noise every row shares stays one value per column.
void PushBlockRow(TraceBlock* b, int na, const double* axes, const int* direction, const double* values,
                  int rows, const double* sigma, const std::string* id);

// Builds a dataset of `rows` observations from batches. Messages name the
// kind, the row and the column: "ball3d row 17, column measured_y: NaN".
//
// Rows of a kind kept in columns (ObservationKind::block_values() > 0:
// dbb, ball3d) go straight into column blocks, one per run of consecutive
// file rows of one mounting, with no Observation per row; Finish() turns
// the block rows that precede a per-object row into Observations, so that
// the dataset's order (per-object observations, then blocks) is the file's.
class ColumnLoader {
 public:
  // `head`: machine, probe, artefact and instruments, no observations.
  // `first_row`: the file row of observation 0 (a piece of a longer file),
  // added to the rows messages name; positions stay 0 .. rows - 1.
  ColumnLoader(Dataset head, int64_t rows, int64_t first_row = 0);
  void Add(const ColumnBatch& batch);
  // Every row placed; the dataset validated as a loaded file is. `whole`:
  // the file's every row, so an instrument noise no observation names is a
  // typo (a piece of a file may not name every instrument).
  Dataset Finish(bool whole = true);

 private:
  Dataset ds_;
  std::vector<uint8_t> placed_;
  int64_t next_ = 0;
  int64_t first_ = 0;
  int64_t total_ = 0;
  // Rows read as Observations, with their dataset positions.
  std::vector<int64_t> object_at_;
  std::vector<Observation> objects_;
  // Column blocks: the position of each one's first row; the values of the
  // columns its rows share (numbers, then texts; a null as NaN / absent),
  // which a following row must repeat to join it.
  struct Segment {
    int64_t start = 0;
    TraceBlock block;
    std::vector<double> shared_numbers;
    std::vector<std::string> shared_texts;
    std::vector<uint8_t> shared_null;
    std::vector<std::string> shared_names;  // of the batch that opened it
  };
  std::vector<Segment> segments_;
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_COLUMNS_H_
