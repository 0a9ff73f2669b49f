// Reading a JSON dataset file piece by piece (fivecal convert, a trace too
// long to hold whole): the head once, then consecutive pieces of
// observations, each a Dataset with the file's machine, artefact and
// instruments, so that memory holds one piece and a buffer of the file.
#ifndef FIVECAL_OBSERVATIONS_DATASET_READER_H_
#define FIVECAL_OBSERVATIONS_DATASET_READER_H_

#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "fivecal/observations/dataset.h"

namespace fivecal {

class DatasetFileReader {
 public:
  // Opens `path` and reads the head (every member before "observations").
  // std::invalid_argument naming the file when it cannot be opened.
  explicit DatasetFileReader(const std::string& path, size_t buffer_bytes = size_t{1} << 22);
  ~DatasetFileReader();
  DatasetFileReader(const DatasetFileReader&) = delete;
  DatasetFileReader& operator=(const DatasetFileReader&) = delete;

  // False when the file is not of the common layout this reader streams
  // (head first, observations last, plain ASCII strings, valid JSON, no
  // instrument id used by two kinds across pieces, every declared
  // instrument used): load it whole (Dataset::FromJson), which accepts or
  // names what is wrong with the reference messages. Can turn false at any
  // Next(): what was read so far is then to be thrown away.
  bool streamable() const { return streamable_; }
  // The next at most `rows` observations as a dataset with the file's head,
  // checked as Dataset::FromJson checks them; messages name an observation
  // by its index in the file (dataset.observations[i]). None at the end of
  // the observations, or when the file turns out not streamable.
  std::optional<Dataset> Next(size_t rows);
  // The members of the file before its observations, as JSON text (an
  // object): what the file says, for a schema check.
  std::string head_json() const;
  // Observations handed out so far.
  size_t observations_read() const { return read_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  bool streamable_ = false;
  bool done_ = false;
  std::optional<Dataset> piece_;
  size_t read_ = 0;
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_DATASET_READER_H_
