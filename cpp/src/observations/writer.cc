#include "fivecal/observations/writer.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {
namespace {

using json_util::json;

// The kind's own keys of one observation, as Dataset::ToJson writes them:
// the generic writer's "setup" first (a kind may rename it: the machined
// features call it "part"), then the kind's
// Write and WriteOnMachine. Type, axes, direction, noise and id are not in
// it: both writers below put those out themselves, without a JSON value
// per number. `jo` is reused row after row (its map nodes stay, which
// halves the allocations per row): a key an earlier row had and this one
// lacks is left null, and null means absent.
void OwnKeys(const Machine& m, const Observation& o, json* jo) {
  if (!jo->is_object()) *jo = json::object();
  for (auto& v : *jo) v = nullptr;
  if (!o.setup.empty()) (*jo)["setup"] = o.setup;
  const ObservationKind& kind = KindOf(o);
  kind.Write(o, jo);
  kind.WriteOnMachine(m, o, jo);
}

// One observation's own keys: the kind's flat form when it gives one (no
// JSON value built: the long traces' kinds), else its Write (OwnKeys).
// Visit(v, head) calls v.text(key, string), v.number(key, double),
// v.vector(key, const double[3]) or v.other(key, json) for the keys that go
// before the axes (head: a target, a set-up id) or for the others in name
// order (not head), as Dataset::ToJson's JSON object orders them.
class OwnRow {
 public:
  void Fill(const Machine& m, const Observation& o) {
    const ObservationKind& kind = KindOf(o);
    flat_ = FlatObservation();
    flat_row_ = kind.WriteFlat(o, &flat_);
    if (flat_row_) {
      keys_ = &kind.flat_keys();
      order_ = &OrderOf(kind);
    } else {
      OwnKeys(m, o, &jo_);
    }
    type_ = ObservationTypeName(o.type);
  }

  template <class V>
  void Visit(V& v, bool head) const {
    if (flat_row_) {
      for (const int k : head ? order_->head : order_->rest) {
        if (!flat_.has(k)) continue;
        const FlatKey& key = (*keys_)[k];
        switch (key.shape) {
          case FlatKey::kText: v.text(key.name, flat_.text(k)); break;
          case FlatKey::kNumber: v.number(key.name, flat_.number(k)); break;
          case FlatKey::kVector: v.vector(key.name, flat_.values[k]); break;
        }
      }
      return;
    }
    auto one = [&](const std::string& k, const json& x) {
      if (x.is_string()) {
        v.text(k.c_str(), x.get_ref<const std::string&>());
      } else if (x.is_number_float()) {
        v.number(k.c_str(), x.get<double>());
      } else if (x.is_array() && x.size() == 3 &&
                 std::all_of(x.begin(), x.end(), [](const json& c) { return c.is_number_float(); })) {
        const double c[3] = {x[0].get<double>(), x[1].get<double>(), x[2].get<double>()};
        v.vector(k.c_str(), c);
      } else {
        v.other(k.c_str(), x);
      }
    };
    if (head) {
      for (const char* k : {"target", "setup"}) {
        const auto it = jo_.find(k);
        if (it != jo_.end() && !it->is_null()) one(k, *it);
      }
      return;
    }
    for (const auto& [k, x] : jo_.items()) {
      if (k == "target" || k == "setup" || x.is_null()) continue;
      if (k == "type" || k == "axes" || k == "direction" || k == "sigma" || k == "id")
        throw std::logic_error(std::string("dataset writer: kind ") + type_ +
                               " writes the generic key " + k);
      one(k, x);
    }
  }

 private:
  // A kind's flat slots in the order the writers put them.
  struct Order {
    std::vector<int> head, rest;
  };
  const Order& OrderOf(const ObservationKind& kind) {
    auto it = orders_.find(&kind);
    if (it != orders_.end()) return it->second;
    Order& o = orders_[&kind];
    const std::vector<FlatKey>& keys = kind.flat_keys();
    for (int k = 0; k < static_cast<int>(keys.size()); ++k) (keys[k].head ? o.head : o.rest).push_back(k);
    std::sort(o.rest.begin(), o.rest.end(),
              [&](int a, int b) { return std::strcmp(keys[a].name, keys[b].name) < 0; });
    return o;
  }

  FlatObservation flat_;
  bool flat_row_ = false;
  const std::vector<FlatKey>* keys_ = nullptr;
  const Order* order_ = nullptr;
  std::map<const ObservationKind*, Order> orders_;
  json jo_;
  const char* type_ = "";  // the observation's kind, for a message
};

// Linear axes, then rotary, then the spindle (the order people write them
// in), other letters last: axis indices in the order both writers put them.
std::vector<int> AxisOrder(const Machine& m) {
  std::vector<int> order(static_cast<size_t>(m.num_axes()));
  for (int k = 0; k < m.num_axes(); ++k) order[k] = k;
  auto rank = [&](int k) {
    const size_t p = std::string("XYZABCS").find(m.axis(k).name);
    return std::make_pair(p == std::string::npos ? 7 : static_cast<int>(p), m.axis(k).name);
  };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return rank(a) < rank(b); });
  return order;
}

// Whether the noise of `o` is one number (every row the same), as ToJson
// writes it.
bool OneSigma(const Observation& o) { return (o.sigma.array() == o.sigma[0]).all(); }

// ---------------------------------------------------------------- JSON text

// The shortest text that reads back as the same double (std::to_chars), with
// ".0" on an integral value as nlohmann writes it, so that a reader keeps it
// a float.
void AppendNumber(double x, std::string* out) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, x);
  out->append(buf, r.ptr);
  if (std::find_if(buf, r.ptr, [](char c) { return c == '.' || c == 'e' || c == 'n' || c == 'i'; }) == r.ptr)
    out->append(".0");
}

void AppendString(const std::string& s, std::string* out) {
  static const char* hex = "0123456789abcdef";
  out->push_back('"');
  for (const char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out->push_back('\\');
      out->push_back(c);
    } else if (u < 0x20) {
      out->append("\\u00");
      out->push_back(hex[u >> 4]);
      out->push_back(hex[u & 15]);
    } else {
      out->push_back(c);
    }
  }
  out->push_back('"');
}

void AppendValue(const json& v, std::string* out) {
  switch (v.type()) {
    case json::value_t::number_float:
      AppendNumber(v.get<double>(), out);
      return;
    case json::value_t::string:
      AppendString(v.get_ref<const std::string&>(), out);
      return;
    case json::value_t::array: {
      out->push_back('[');
      bool first = true;
      for (const json& x : v) {
        if (!first) out->append(", ");
        first = false;
        AppendValue(x, out);
      }
      out->push_back(']');
      return;
    }
    case json::value_t::object: {
      out->push_back('{');
      bool first = true;
      for (const auto& [k, x] : v.items()) {
        if (!first) out->append(", ");
        first = false;
        AppendString(k, out);
        out->append(": ");
        AppendValue(x, out);
      }
      out->push_back('}');
      return;
    }
    default:
      out->append(v.dump());  // integers, true/false, null
  }
}

// ToJson of no observations is the head as ToJson writes it (the same keys,
// numbers and defaults): one writer of the head, not two.
json Head(const Dataset& ds) {
  json head = json::parse(ds.Subset({}).ToJson());
  head.erase("observations");
  return head;
}

}  // namespace

std::map<std::string, std::string> DatasetHead(const Dataset& ds) {
  const json head = Head(ds);
  std::map<std::string, std::string> out;
  for (const auto& [k, v] : head.items()) out[k] = v.dump();
  return out;
}

namespace {

// Puts the own keys out as `, "key": value`.
struct Emit {
  std::string* buf;
  void key(const char* k) {
    buf->append(", ");
    AppendString(k, buf);
    buf->append(": ");
  }
  void text(const char* k, const std::string& v) {
    key(k);
    AppendString(v, buf);
  }
  void number(const char* k, double x) {
    key(k);
    AppendNumber(x, buf);
  }
  void vector(const char* k, const double* c) {
    key(k);
    buf->push_back('[');
    AppendNumber(c[0], buf);
    buf->append(", ");
    AppendNumber(c[1], buf);
    buf->append(", ");
    AppendNumber(c[2], buf);
    buf->push_back(']');
  }
  void other(const char* k, const json& v) {
    key(k);
    AppendValue(v, buf);
  }
};

}  // namespace

struct DatasetJsonWriter::State {
  OwnRow own;
  std::vector<std::string> letters;
  std::vector<int> order;
};

DatasetJsonWriter::DatasetJsonWriter(const Dataset& head, ByteSink sink, size_t chunk_bytes)
    : sink_(std::move(sink)), chunk_bytes_(chunk_bytes), machine_(head.machine()), state_(new State) {
  const int na = machine_.num_axes();
  state_->order = AxisOrder(machine_);
  for (int k = 0; k < na; ++k) state_->letters.push_back(std::string(1, machine_.axis(k).name));
  // "{\n ...\n}" (never empty: the machine is there), reopened for the observations.
  buf_ = Head(head).dump(1);
  buf_.resize(buf_.size() - 2);
  buf_ += ",\n \"observations\": [";
  buf_.reserve(chunk_bytes + 4096);
}

DatasetJsonWriter::~DatasetJsonWriter() = default;

void DatasetJsonWriter::Add(const Dataset& piece) {
  if (piece.machine().num_axes() != machine_.num_axes())
    throw std::invalid_argument("dataset writer: a piece of " + std::to_string(piece.machine().num_axes()) +
                                " axes for a head of " + std::to_string(machine_.num_axes()));
  // Block rows (dataset.h TraceBlock) through one scratch observation.
  piece.ForEachRow([&](size_t, const Observation& o) { Add(o); });
}

void DatasetJsonWriter::Add(const Observation& o) {
  const int na = machine_.num_axes();
  const std::vector<int>& order = state_->order;
  const std::vector<std::string>& letters = state_->letters;
  std::string& buf = buf_;
  Emit emit{&buf};
  buf.append(written_ ? ",\n  {\"type\": " : "\n  {\"type\": ");
  ++written_;
  AppendString(ObservationTypeName(o.type), &buf);
  OwnRow& own = state_->own;
  own.Fill(machine_, o);
  own.Visit(emit, true);
  buf.append(", \"axes\": {");
  for (int j = 0; j < na; ++j) {
    const int k = order[j];
    buf.append(j ? ", \"" : "\"").append(letters[k]).append("\": ");
    AppendNumber(o.axes[k], &buf);
  }
  buf.push_back('}');
  if ((o.direction.array() != 0).any()) {
    buf.append(", \"direction\": {");
    bool firstd = true;
    for (const int k : order) {
      if (o.direction[k] == 0) continue;
      buf.append(firstd ? "\"" : ", \"").append(letters[k]).append(o.direction[k] > 0 ? "\": 1" : "\": -1");
      firstd = false;
    }
    buf.push_back('}');
  }
  own.Visit(emit, false);
  if (o.sigma.size() > 0) {
    buf.append(", \"sigma\": ");
    if (OneSigma(o)) {
      AppendNumber(o.sigma[0], &buf);
    } else {
      buf.push_back('[');
      for (int r = 0; r < o.sigma.size(); ++r) {
        if (r) buf.append(", ");
        AppendNumber(o.sigma[r], &buf);
      }
      buf.push_back(']');
    }
  }
  if (!o.id.empty()) {
    buf.append(", \"id\": ");
    AppendString(o.id, &buf);
  }
  buf.push_back('}');
  if (buf.size() >= chunk_bytes_) {
    sink_(buf.data(), buf.size());
    buf.clear();
  }
}

void DatasetJsonWriter::Finish() {
  buf_.append(written_ ? "\n ]\n}\n" : "]\n}\n");
  sink_(buf_.data(), buf_.size());
  buf_.clear();
}

void WriteDatasetJson(const Dataset& ds, const ByteSink& sink, size_t chunk_bytes) {
  DatasetJsonWriter w(ds, sink, chunk_bytes);
  w.Add(ds);
  w.Finish();
}

// ---------------------------------------------------------------- columns

ColumnWriter::ColumnWriter(const Dataset& ds) : ds_(&ds) {
  Scan(ds);
}

bool ColumnWriter::Scan(const Dataset& ds, int64_t offset) {
  if (!machine_) machine_ = std::make_shared<const Machine>(ds.machine());
  const Machine& m = *machine_;
  const int na = m.num_axes();
  if (ds.machine().num_axes() != na)
    throw std::invalid_argument("columns: a piece of " + std::to_string(ds.machine().num_axes()) +
                                " axes after pieces of " + std::to_string(na));
  auto where = [&](size_t i, const std::string& key) {
    return "observations[" + std::to_string(static_cast<int64_t>(i) + offset) + "] (" +
           ObservationTypeName(ds.TypeOf(i)) + "), " + key;
  };

  // What the rows hold: decides the generic columns, which come first.
  any_dir_.resize(static_cast<size_t>(na), false);
  ds.ForEachRow([&](size_t, const Observation& o) {
    any_id_ |= !o.id.empty();
    for (int k = 0; k < na; ++k) any_dir_[k] = any_dir_[k] || o.direction[k] != 0;
    if (o.sigma.size() == 0) return;
    if (OneSigma(o)) {
      one_sigma_ = true;
    } else {
      row_sigmas_ = std::max(row_sigmas_, static_cast<int>(o.sigma.size()));
      // Three values read as a vector (sigma_x|y|z, as the CSV tables write
      // them) unless some observation has another number of rows.
      numbered_sigma_ |= o.sigma.size() != 3;
    }
  });
  if (row_sigmas_ > 9)
    throw std::invalid_argument("sigma: " + std::to_string(row_sigmas_) +
                                " values per observation have no column form (sigma_1 to sigma_9)");

  // The kinds' own keys, in the order they first appear (column indices
  // within own_, placed after the generic columns by Layout).
  struct Find {
    ColumnWriter* w;
    const Machine& m;
    std::function<std::string(const std::string&)> where;
    int add(const std::string& name, Type t) {
      w->own_.push_back({name, t});
      return static_cast<int>(w->own_.size()) - 1;
    }
    KeyColumns* Register(const std::string& key, KeyColumns::Shape shape) {
      static const char* what[] = {"a number", "text", "a 3-vector", "axis commands"};
      auto it = w->keys_.find(key);
      if (it != w->keys_.end()) {
        if (it->second.shape != shape)
          throw std::invalid_argument(where(key) + ": " + what[shape] + " where an earlier observation has " +
                                      what[it->second.shape] + " (one column holds one kind of value)");
        return &it->second;
      }
      KeyColumns& k = w->keys_[key];
      k.shape = shape;
      if (shape == KeyColumns::kNumber) k.first = add(key, Type::kFloat64);
      if (shape == KeyColumns::kText) k.first = add(key, Type::kString);
      if (shape == KeyColumns::kVector) {
        k.first = add(key + "_x", Type::kFloat64);
        add(key + "_y", Type::kFloat64);
        add(key + "_z", Type::kFloat64);
      }
      if (shape == KeyColumns::kAxes) k.by_axis.assign(static_cast<size_t>(m.num_axes()), -1);
      return &k;
    }
    void text(const char* k, const std::string&) { Register(k, KeyColumns::kText); }
    void number(const char* k, double) { Register(k, KeyColumns::kNumber); }
    void vector(const char* k, const double*) { Register(k, KeyColumns::kVector); }
    void other(const char* key, const json& v) {
      const std::string k = key;
      if (v.is_number()) {
        Register(k, KeyColumns::kNumber);
      } else if (v.is_array()) {
        throw std::invalid_argument(where(k) + ": a list of " + std::to_string(v.size()) +
                                    " values has no column form (3-vectors of numbers only)");
      } else if (v.is_object()) {
        if (k.size() <= 5 || k.compare(k.size() - 5, 5, "_axes") != 0)
          throw std::invalid_argument(where(k) + ": only a set of axis commands (<name>_axes) has a column form");
        KeyColumns* kc = Register(k, KeyColumns::kAxes);
        const std::string base = k.substr(0, k.size() - 5);
        for (const auto& [a, x] : v.items()) {
          const int ax = a.size() == 1 ? m.AxisIndex(a[0]) : -1;
          if (ax < 0) throw std::invalid_argument(where(k) + "." + a + ": not an axis letter of the machine");
          if (!x.is_number()) throw std::invalid_argument(where(k) + "." + a + ": expected a number");
          if (kc->by_axis[ax] < 0) kc->by_axis[ax] = add(base + "_" + a, Type::kFloat64);
        }
      } else if (!v.is_null()) {
        throw std::invalid_argument(where(k) + ": true/false has no column form");
      }
    }
  };
  size_t row = 0;
  Find find{this, m, [&](const std::string& key) { return where(row, key); }};
  OwnRow own;
  Observation row_scratch;
  for (; row < ds.size(); ++row) {
    own.Fill(m, ds.Row(row, &row_scratch));
    own.Visit(find, true);
    own.Visit(find, false);
  }
  return Layout();
}

bool ColumnWriter::Layout() {
  const Machine& m = *machine_;
  const int na = m.num_axes();
  std::vector<Spec> columns;
  auto add = [&](const std::string& name, Type t) {
    columns.push_back({name, t});
    return static_cast<int>(columns.size()) - 1;
  };
  add("type", Type::kString);
  id_ = any_id_ ? add("id", Type::kString) : -1;
  const std::vector<int> order = AxisOrder(m);
  axis_col_.assign(static_cast<size_t>(na), -1);
  dir_col_.assign(static_cast<size_t>(na), -1);
  for (int k : order) axis_col_[k] = add(std::string(1, m.axis(k).name), Type::kFloat64);
  for (int k : order)
    if (any_dir_[k]) dir_col_[k] = add("dir_" + std::string(1, m.axis(k).name), Type::kInt8);
  own_base_ = static_cast<int>(columns.size());
  for (const Spec& s : own_) columns.push_back(s);

  // The noise last.
  sigma_ = one_sigma_ ? add("sigma", Type::kFloat64) : -1;
  sigma_rows_ = -1;
  for (int r = 0; r < row_sigmas_; ++r) {
    const int c = add(numbered_sigma_ ? "sigma_" + std::to_string(r + 1) : std::string("sigma_") + "xyz"[r],
                      Type::kFloat64);
    if (r == 0) sigma_rows_ = c;
  }
  // Two keys whose columns share a name (a vector "a" and a number "a_x")
  // would load as something else.
  std::vector<std::string> names;
  for (const Spec& s : columns) names.push_back(s.name);
  std::sort(names.begin(), names.end());
  const auto dup = std::adjacent_find(names.begin(), names.end());
  if (dup != names.end())
    throw std::invalid_argument("column " + *dup + ": two keys of the observations would both fill it");
  const bool changed = columns.size() != columns_.size() ||
                       !std::equal(columns.begin(), columns.end(), columns_.begin(), [](const Spec& a, const Spec& b) {
                         return a.name == b.name && a.type == b.type;
                       });
  columns_ = std::move(columns);
  return changed;
}

std::vector<ColumnWriter::Block> ColumnWriter::Write(int64_t begin, int64_t end) const {
  if (!ds_) throw std::logic_error("columns: the writer was made without a dataset (Write(piece, ...))");
  return Write(*ds_, begin, end);
}

std::vector<ColumnWriter::Block> ColumnWriter::Write(const Dataset& ds, int64_t begin, int64_t end) const {
  const int64_t rows = static_cast<int64_t>(ds.size());
  if (!machine_ || ds.machine().num_axes() != machine_->num_axes())
    throw std::invalid_argument("columns: a dataset the writer has not scanned");
  if (begin < 0 || end < begin || end > rows)
    throw std::invalid_argument("columns: rows " + std::to_string(begin) + " to " + std::to_string(end) +
                                " outside 0 to " + std::to_string(rows));
  const Machine& m = *machine_;
  const int na = m.num_axes();
  const size_t n = static_cast<size_t>(end - begin);
  std::vector<Block> out(columns_.size());
  for (size_t c = 0; c < columns_.size(); ++c) {
    Block& b = out[c];
    switch (columns_[c].type) {
      case Type::kFloat64:
        b.numbers.assign(n, std::numeric_limits<double>::quiet_NaN());
        break;
      case Type::kInt8:
        b.small.assign(n, 0);  // no direction given: no backlash term, as the loader reads it
        break;
      case Type::kString:
        b.offsets.assign(n + 1, 0);
        break;
    }
    b.valid.assign(n, 0);
  }
  // Text columns are filled row after row: each holds its running length.
  auto put_text = [&](int c, size_t r, const std::string& s) {
    Block& b = out[c];
    b.text.append(s);
    if (b.text.size() > static_cast<size_t>(std::numeric_limits<int32_t>::max()))
      throw std::invalid_argument("column " + columns_[c].name + ": more than 2 GB of text in one block of rows");
    b.offsets[r + 1] = static_cast<int32_t>(b.text.size());
    b.valid[r] = 1;
  };
  auto put = [&](int c, size_t r, double x) {
    out[c].numbers[r] = x;
    out[c].valid[r] = 1;
  };
  // Puts the own keys into their columns (found by the constructor).
  struct Fill {
    const ColumnWriter* w;
    const Machine& m;
    std::function<void(int, size_t, const std::string&)> put_text;
    std::function<void(int, size_t, double)> put;
    size_t r = 0;
    const KeyColumns& Of(const char* k) const {
      const auto it = w->keys_.find(k);
      // The kind wrote a key the constructor's walk did not see.
      if (it == w->keys_.end())
        throw std::logic_error(std::string("dataset writer: key ") + k + " changed since the columns were found");
      return it->second;
    }
    void text(const char* k, const std::string& v) { put_text(w->own_base_ + Of(k).first, r, v); }
    void number(const char* k, double x) { put(w->own_base_ + Of(k).first, r, x); }
    void vector(const char* k, const double* c) {
      const int first = w->own_base_ + Of(k).first;
      for (int i = 0; i < 3; ++i) put(first + i, r, c[i]);
    }
    void other(const char* k, const json& v) {
      const KeyColumns& kc = Of(k);
      if (kc.shape == KeyColumns::kNumber) put(w->own_base_ + kc.first, r, v.get<double>());
      if (kc.shape == KeyColumns::kAxes)
        for (const auto& [a, x] : v.items()) put(w->own_base_ + kc.by_axis[m.AxisIndex(a[0])], r, x.get<double>());
    }
  } fill{this, m, put_text, put};
  OwnRow own;
  Observation scratch;
  for (size_t r = 0; r < n; ++r) {
    const Observation& o = ds.Row(static_cast<size_t>(begin) + r, &scratch);
    for (size_t c = 0; c < columns_.size(); ++c)
      if (columns_[c].type == Type::kString) out[c].offsets[r + 1] = out[c].offsets[r];
    put_text(0, r, ObservationTypeName(o.type));
    if (id_ >= 0 && !o.id.empty()) put_text(id_, r, o.id);
    for (int k = 0; k < na; ++k) {
      put(axis_col_[k], r, o.axes[k]);
      if (dir_col_[k] >= 0) {
        out[dir_col_[k]].small[r] = static_cast<int8_t>(o.direction[k]);
        out[dir_col_[k]].valid[r] = 1;
      }
    }
    fill.r = r;
    own.Fill(m, o);
    own.Visit(fill, true);
    own.Visit(fill, false);
    if (o.sigma.size() > 0) {
      if (OneSigma(o)) put(sigma_, r, o.sigma[0]);
      else
        for (int k = 0; k < o.sigma.size(); ++k) put(sigma_rows_ + k, r, o.sigma[k]);
    }
  }
  for (Block& b : out)
    if (std::all_of(b.valid.begin(), b.valid.end(), [](uint8_t v) { return v != 0; })) b.valid.clear();
  return out;
}

}  // namespace fivecal
