#include "fivecal/observations/writer.h"

#include <algorithm>
#include <charconv>
#include <cmath>
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
// the generic writer's "target" and "setup" first (a kind may rename them:
// the machined features call them "feature" and "part"), then the kind's
// Write and WriteOnMachine. Type, axes, direction, noise and id are not in
// it: both writers below put those out themselves, without a JSON value
// per number. `jo` is reused row after row (its map nodes stay, which
// halves the allocations per row): a key an earlier row had and this one
// lacks is left null, and null means absent.
void OwnKeys(const Machine& m, const Observation& o, json* jo) {
  if (!jo->is_object()) *jo = json::object();
  for (auto& v : *jo) v = nullptr;
  if (!o.target.empty()) (*jo)["target"] = o.target;
  if (!o.setup.empty()) (*jo)["setup"] = o.setup;
  const ObservationKind& kind = KindOf(o);
  kind.Write(o, jo);
  kind.WriteOnMachine(m, o, jo);
}

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

bool Generic(const std::string& key) {
  return key == "type" || key == "axes" || key == "direction" || key == "sigma" || key == "id";
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

void WriteDatasetJson(const Dataset& ds, const ByteSink& sink, size_t chunk_bytes) {
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  const std::vector<int> order = AxisOrder(m);
  std::vector<std::string> letters;
  for (int k = 0; k < na; ++k) letters.push_back(std::string(1, m.axis(k).name));

  // "{\n ...\n}" (never empty: the machine is there), reopened for the observations.
  std::string buf = Head(ds).dump(1);
  buf.resize(buf.size() - 2);
  buf += ",\n \"observations\": [";
  buf.reserve(chunk_bytes + 4096);

  bool first = true;
  json own;
  for (const Observation& o : ds.observations) {
    buf.append(first ? "\n  {\"type\": " : ",\n  {\"type\": ");
    first = false;
    AppendString(ObservationTypeName(o.type), &buf);
    OwnKeys(m, o, &own);
    for (const char* k : {"target", "setup"}) {
      const auto it = own.find(k);
      if (it == own.end() || it->is_null()) continue;
      buf.append(", \"").append(k).append("\": ");
      AppendValue(*it, &buf);
    }
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
    for (const auto& [k, v] : own.items()) {
      if (k == "target" || k == "setup" || v.is_null()) continue;
      if (Generic(k))
        throw std::logic_error(std::string("dataset writer: kind ") + ObservationTypeName(o.type) +
                               " writes the generic key " + k);
      buf.append(", ");
      AppendString(k, &buf);
      buf.append(": ");
      AppendValue(v, &buf);
    }
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
    if (buf.size() >= chunk_bytes) {
      sink(buf.data(), buf.size());
      buf.clear();
    }
  }
  buf.append(ds.observations.empty() ? "]\n}\n" : "\n ]\n}\n");
  sink(buf.data(), buf.size());
}

// ---------------------------------------------------------------- columns

ColumnWriter::ColumnWriter(const Dataset& ds) : ds_(ds) {
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  auto add = [&](const std::string& name, Type t) {
    columns_.push_back({name, t});
    return static_cast<int>(columns_.size()) - 1;
  };
  auto where = [&](size_t i, const std::string& key) {
    return "observations[" + std::to_string(i) + "] (" + ObservationTypeName(ds.observations[i].type) + "), " + key;
  };

  // What the rows hold: decides the generic columns, which come first.
  bool any_id = false, one_sigma = false;
  std::vector<bool> any_dir(static_cast<size_t>(na), false);
  int row_sigmas = 0;
  for (const Observation& o : ds.observations) {
    any_id |= !o.id.empty();
    for (int k = 0; k < na; ++k) any_dir[k] = any_dir[k] || o.direction[k] != 0;
    if (o.sigma.size() == 0) continue;
    if (OneSigma(o)) {
      one_sigma = true;
    } else {
      row_sigmas = std::max(row_sigmas, static_cast<int>(o.sigma.size()));
      // Three values read as a vector (sigma_x|y|z, as the CSV tables write
      // them) unless some observation has another number of rows.
      numbered_sigma_ |= o.sigma.size() != 3;
    }
  }
  if (row_sigmas > 9)
    throw std::invalid_argument("sigma: " + std::to_string(row_sigmas) +
                                " values per observation have no column form (sigma_1 to sigma_9)");
  add("type", Type::kString);
  if (any_id) id_ = add("id", Type::kString);
  const std::vector<int> order = AxisOrder(m);
  axis_col_.assign(static_cast<size_t>(na), -1);
  dir_col_.assign(static_cast<size_t>(na), -1);
  for (int k : order) axis_col_[k] = add(std::string(1, m.axis(k).name), Type::kFloat64);
  for (int k : order)
    if (any_dir[k]) dir_col_[k] = add("dir_" + std::string(1, m.axis(k).name), Type::kInt8);

  // The kinds' own keys, in the order they first appear.
  json own;
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    OwnKeys(m, ds.observations[i], &own);
    for (const auto& [key, v] : own.items()) {
      if (Generic(key))
        throw std::logic_error("dataset writer: kind " + std::string(ObservationTypeName(ds.observations[i].type)) +
                               " writes the generic key " + key);
      KeyColumns kc;
      if (v.is_string()) {
        kc.shape = KeyColumns::kText;
      } else if (v.is_number()) {
        kc.shape = KeyColumns::kNumber;
      } else if (v.is_array()) {
        if (v.size() != 3 || !std::all_of(v.begin(), v.end(), [](const json& x) { return x.is_number(); }))
          throw std::invalid_argument(where(i, key) + ": a list of " + std::to_string(v.size()) +
                                      " values has no column form (3-vectors of numbers only)");
        kc.shape = KeyColumns::kVector;
      } else if (v.is_object()) {
        if (key.size() <= 5 || key.compare(key.size() - 5, 5, "_axes") != 0)
          throw std::invalid_argument(where(i, key) + ": only a set of axis commands (<name>_axes) has a column form");
        kc.shape = KeyColumns::kAxes;
      } else if (v.is_null()) {
        continue;
      } else {
        throw std::invalid_argument(where(i, key) + ": true/false has no column form");
      }
      auto it = keys_.find(key);
      if (it == keys_.end()) {
        it = keys_.emplace(key, kc).first;
        KeyColumns& k = it->second;
        if (kc.shape == KeyColumns::kNumber) k.first = add(key, Type::kFloat64);
        if (kc.shape == KeyColumns::kText) k.first = add(key, Type::kString);
        if (kc.shape == KeyColumns::kVector) {
          k.first = add(key + "_x", Type::kFloat64);
          add(key + "_y", Type::kFloat64);
          add(key + "_z", Type::kFloat64);
        }
        if (kc.shape == KeyColumns::kAxes) k.by_axis.assign(static_cast<size_t>(na), -1);
      } else if (it->second.shape != kc.shape) {
        static const char* what[] = {"a number", "text", "a 3-vector", "axis commands"};
        throw std::invalid_argument(where(i, key) + ": " + what[kc.shape] + " where an earlier observation has " +
                                    what[it->second.shape] + " (one column holds one kind of value)");
      }
      if (kc.shape == KeyColumns::kAxes) {
        const std::string base = key.substr(0, key.size() - 5);
        for (const auto& [a, x] : v.items()) {
          const int k = a.size() == 1 ? m.AxisIndex(a[0]) : -1;
          if (k < 0) throw std::invalid_argument(where(i, key) + "." + a + ": not an axis letter of the machine");
          if (!x.is_number()) throw std::invalid_argument(where(i, key) + "." + a + ": expected a number");
          if (it->second.by_axis[k] < 0) it->second.by_axis[k] = add(base + "_" + a, Type::kFloat64);
        }
      }
    }
  }

  // The noise last.
  if (one_sigma) sigma_ = add("sigma", Type::kFloat64);
  if (row_sigmas) {
    for (int r = 0; r < row_sigmas; ++r) {
      const int c = add(numbered_sigma_ ? "sigma_" + std::to_string(r + 1) : std::string("sigma_") + "xyz"[r],
                        Type::kFloat64);
      if (r == 0) sigma_rows_ = c;
    }
  }
  // Two keys whose columns share a name (a vector "a" and a number "a_x")
  // would load as something else.
  std::vector<std::string> names;
  for (const Spec& s : columns_) names.push_back(s.name);
  std::sort(names.begin(), names.end());
  const auto dup = std::adjacent_find(names.begin(), names.end());
  if (dup != names.end())
    throw std::invalid_argument("column " + *dup + ": two keys of the observations would both fill it");
}

std::vector<ColumnWriter::Block> ColumnWriter::Write(int64_t begin, int64_t end) const {
  if (begin < 0 || end < begin || end > rows())
    throw std::invalid_argument("columns: rows " + std::to_string(begin) + " to " + std::to_string(end) +
                                " outside 0 to " + std::to_string(rows()));
  const Machine& m = ds_.machine();
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
  json own;
  for (size_t r = 0; r < n; ++r) {
    const Observation& o = ds_.observations[static_cast<size_t>(begin) + r];
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
    OwnKeys(m, o, &own);
    for (const auto& [key, v] : own.items()) {
      if (v.is_null()) continue;
      const auto it = keys_.find(key);
      if (it == keys_.end()) {
        // The kind wrote a key the walk in the constructor did not see.
        throw std::logic_error("dataset writer: observation " + std::to_string(begin + r) + " key " + key +
                               " changed since the columns were found");
      }
      const KeyColumns& kc = it->second;
      switch (kc.shape) {
        case KeyColumns::kNumber:
          put(kc.first, r, v.get<double>());
          break;
        case KeyColumns::kText:
          put_text(kc.first, r, v.get_ref<const std::string&>());
          break;
        case KeyColumns::kVector:
          for (int c = 0; c < 3; ++c) put(kc.first + c, r, v[static_cast<size_t>(c)].get<double>());
          break;
        case KeyColumns::kAxes:
          for (const auto& [a, x] : v.items()) put(kc.by_axis[m.AxisIndex(a[0])], r, x.get<double>());
          break;
      }
    }
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
