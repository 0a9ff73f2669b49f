#include "fivecal/observations/columns.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

// What a column fills. The roles come from the column name alone (columns.h);
// which names a kind accepts comes from its json_keys().
enum class Role { kAxis, kDirection, kSigma, kVector, kAxesObject, kScalar };

struct Column {
  std::string name;
  Role role = Role::kScalar;
  std::string key;  // the observation key (vector, axes object, scalar)
  int index = 0;    // axis index, vector component or sigma row
  const NumberColumn* number = nullptr;
  const StringColumn* text = nullptr;
  bool Null(int64_t r) const {
    const uint8_t* v = number ? number->valid : text->valid;
    return v && !v[r];
  }
};

std::string RowName(const ObservationKind& k, int64_t row) {
  return std::string(k.name()) + " row " + std::to_string(row);
}

[[noreturn]] void Fail(const ObservationKind& k, int64_t row, const std::string& column, const std::string& what) {
  throw std::invalid_argument(RowName(k, row) + ", column " + column + ": " + what);
}

bool IsUpper(const std::string& s) { return s.size() == 1 && s[0] >= 'A' && s[0] <= 'Z'; }

// The columns of `b` with their roles; refuses a column the kind does not
// have, naming it (and a near miss), and a vector missing some of its
// components.
std::vector<Column> Roles(const ObservationKind& kind, const Machine& m, const ColumnBatch& b) {
  const std::vector<const char*> keys = kind.json_keys();
  auto has_key = [&](const std::string& k) {
    return k != "type" && k != "axes" && k != "direction" && k != "sigma" &&
           std::any_of(keys.begin(), keys.end(), [&](const char* x) { return k == x; });
  };
  std::vector<Column> out;
  std::set<std::string> seen;
  auto add = [&](const std::string& name, const NumberColumn* n, const StringColumn* s) {
    if (!seen.insert(name).second)
      throw std::invalid_argument(std::string(kind.name()) + ": column " + name + " given twice");
    Column c;
    c.name = name;
    c.number = n;
    c.text = s;
    // <head>_<tail>: the last underscore splits a vector component, an axis
    // letter or a noise row from its key (tool_ball_x, dir_C, sigma_2).
    const size_t us = name.rfind('_');
    const std::string head = us == std::string::npos ? name : name.substr(0, us);
    const std::string tail = us == std::string::npos ? "" : name.substr(us + 1);
    const bool axis_tail = IsUpper(tail) && m.AxisIndex(tail[0]) >= 0;
    if (IsUpper(name) && m.AxisIndex(name[0]) >= 0) {
      c.role = Role::kAxis;
      c.index = m.AxisIndex(name[0]);
    } else if (head == "dir" && axis_tail) {
      c.role = Role::kDirection;
      c.index = m.AxisIndex(tail[0]);
    } else if (name == "sigma" ||
               (head == "sigma" && tail.size() == 1 && tail[0] >= '1' && tail[0] < '1' + kind.rows())) {
      c.role = Role::kSigma;
      c.index = name == "sigma" ? -1 : tail[0] - '1';
    } else if (head == "sigma" && kind.rows() == 3 && (tail == "x" || tail == "y" || tail == "z")) {
      // Three rows named as a vector is, as the CSV tables write them.
      c.role = Role::kSigma;
      c.index = tail[0] - 'x';
    } else if (us != std::string::npos && has_key(head) && (tail == "x" || tail == "y" || tail == "z")) {
      c.role = Role::kVector;
      c.key = head;
      c.index = tail[0] - 'x';
    } else if (us != std::string::npos && axis_tail && has_key(head + "_axes")) {
      // Another set of axis commands: reference_C is reference_axes.C.
      c.role = Role::kAxesObject;
      c.key = head + "_axes";
      c.index = m.AxisIndex(tail[0]);
    } else if (has_key(name)) {
      c.role = Role::kScalar;
      c.key = name;
    } else {
      // Every name this kind accepts, for the message.
      std::vector<std::string> names;
      for (int a = 0; a < m.num_axes(); ++a) names.emplace_back(1, m.axis(a).name);
      for (int a = 0; a < m.num_axes(); ++a) names.push_back("dir_" + std::string(1, m.axis(a).name));
      for (const char* k : keys)
        if (has_key(k)) names.push_back(k);
      names.push_back("sigma");
      std::string list;
      for (const std::string& x : names) list += (list.empty() ? "" : ", ") + x;
      // A near miss may be a vector component (mesured_x: measured_x).
      std::vector<std::string> near = names;
      for (const char* k : keys)
        if (has_key(k))
          for (const char* comp : {"_x", "_y", "_z"}) near.push_back(k + std::string(comp));
      throw std::invalid_argument(std::string(kind.name()) + ": unknown column " + Quote(name) +
                                  DidYouMean(name, near) + " (machine axes " + m.axis_names() +
                                  "; columns of a " + kind.name() + " observation: " + list +
                                  ", a vector as <key>_x|y|z)");
    }
    if (c.role != Role::kScalar && !n)
      throw std::invalid_argument(std::string(kind.name()) + ": column " + name + ": expected numbers, got text");
    if (c.role == Role::kScalar && c.key == "id" && !s)
      throw std::invalid_argument(std::string(kind.name()) + ": column id: expected text, got numbers");
    out.push_back(c);
  };
  for (const NumberColumn& n : b.numbers) add(n.name, &n, nullptr);
  for (const StringColumn& s : b.strings) add(s.name, nullptr, &s);
  // Whole-table checks: a missing axis, a vector with some components only,
  // one noise column form only.
  for (int a = 0; a < m.num_axes(); ++a)
    if (m.axis(a).name != 'S' && !seen.count(std::string(1, m.axis(a).name)))
      throw std::invalid_argument(std::string(kind.name()) + ": missing column " + std::string(1, m.axis(a).name) +
                                  " (the " + (m.axis(a).rotary() ? "degrees" : "mm") + " of axis " +
                                  std::string(1, m.axis(a).name) + "; machine axes " + m.axis_names() + ")");
  for (const Column& c : out)
    if (c.role == Role::kVector)
      for (const char* comp : {"x", "y", "z"})
        if (!seen.count(c.key + "_" + comp))
          throw std::invalid_argument(std::string(kind.name()) + ": missing column " + c.key + "_" + comp + " (" +
                                      c.name + " is given: a vector takes " + c.key + "_x, _y and _z)");
  return out;
}

}  // namespace

ColumnLoader::ColumnLoader(Dataset head, int64_t rows, int64_t first_row) : ds_(std::move(head)), first_(first_row) {
  if (rows < 0) throw std::invalid_argument("columns: negative row count");
  ds_.observations.clear();
  ds_.observations.resize(static_cast<size_t>(rows));
  placed_.assign(static_cast<size_t>(rows), 0);
}

void ColumnLoader::Add(const ColumnBatch& b) {
  const ObservationKind* kind = FindKind(b.kind);
  if (!kind)
    throw std::invalid_argument("type: unknown observation type " + Quote(b.kind) + " (" + KindList() + ")" +
                                DidYouMean(b.kind, KindNames()));
  const Machine& m = ds_.machine();
  const int na = m.num_axes();
  const std::vector<Column> cols = Roles(*kind, m, b);
  const int64_t total = static_cast<int64_t>(placed_.size());
  if (!b.positions && next_ + b.rows > total)
    throw std::invalid_argument("columns: more rows than the " + std::to_string(total) + " announced");

  // The kind's own keys as one JSON object, built once and overwritten in
  // place row after row: its Read() then sees what a JSON file would give
  // it, without a document per row. A row with a null among them gets an
  // object of its own (nulls are absent keys: optional fields).
  json own = json::object();
  std::vector<std::pair<const Column*, json*>> slots;
  for (const Column& c : cols) {
    if (c.role == Role::kScalar && c.key == "id") continue;
    if (c.role == Role::kScalar) own[c.key] = c.number ? json(0.0) : json(std::string());
    if (c.role == Role::kVector) own[c.key] = json::array({0.0, 0.0, 0.0});
    if (c.role == Role::kAxesObject) own[c.key][std::string(1, m.axis(c.index).name)] = 0.0;
  }
  for (const Column& c : cols) {
    if (c.role == Role::kScalar && c.key != "id") slots.emplace_back(&c, &own[c.key]);
    if (c.role == Role::kVector) slots.emplace_back(&c, &own[c.key][static_cast<size_t>(c.index)]);
    if (c.role == Role::kAxesObject) slots.emplace_back(&c, &own[c.key][std::string(1, m.axis(c.index).name)]);
  }
  bool sigma_one = false;
  int sigma_cols = 0;
  for (const Column& c : cols)
    if (c.role == Role::kSigma) {
      if (c.index < 0) sigma_one = true;
      else ++sigma_cols;
    }
  if (sigma_one)
    for (int r = 1; r < kind->rows(); ++r)
      if (std::string(kind->unit_row(r)) != kind->unit_row(0))
        throw std::invalid_argument(std::string(kind->name()) + ": column sigma: a " + kind->name() +
                                    " observation's rows differ in unit: give sigma_1 to sigma_" +
                                    std::to_string(kind->rows()));

  std::string w = RowName(*kind, 0);
  const size_t w_prefix = w.size() - 1;
  for (int64_t i = 0; i < b.rows; ++i) {
    const int64_t at = b.positions ? b.positions[i] : next_ + i;
    const int64_t row = first_ + at;  // what messages call it
    if (at < 0 || at >= total)
      throw std::invalid_argument(RowName(*kind, row) + ": row outside the " + std::to_string(total) + " announced");
    if (placed_[static_cast<size_t>(at)])
      throw std::invalid_argument(RowName(*kind, row) + ": row given twice");
    placed_[static_cast<size_t>(at)] = 1;
    Observation& ob = ds_.observations[static_cast<size_t>(at)];
    ob.type = kind->type();
    ob.payload = kind->NewPayload();
    ob.axes = Eigen::VectorXd::Zero(na);
    ob.direction = Eigen::VectorXi::Zero(na);
    bool any_null = false;
    for (const Column& c : cols) {
      if (c.Null(i)) {
        if (c.role == Role::kAxis && m.axis(c.index).name != 'S')
          Fail(*kind, row, c.name, "null (every axis but S needs a reading)");
        if (c.role != Role::kAxis && c.role != Role::kDirection && c.role != Role::kSigma && c.key != "id")
          any_null = true;
        continue;
      }
      if (c.number) {
        const double x = c.number->values[i];
        if (std::isnan(x)) Fail(*kind, row, c.name, "NaN (an empty cell? a missing value must be null)");
        if (!std::isfinite(x)) Fail(*kind, row, c.name, "not a finite number");
        switch (c.role) {
          case Role::kAxis: {
            const bool rot = m.axis(c.index).rotary();
            if (!(std::abs(x) <= (rot ? kMaxRotaryDeg : kMaxLinear)))
              RequireBounded(x, rot ? kMaxRotaryDeg : kMaxLinear, RowName(*kind, row) + ", column " + c.name,
                             rot ? "degrees" : "mm");
            ob.axes[c.index] = x;
            break;
          }
          case Role::kDirection:
            if (!(x == -1.0 || x == 0.0 || x == 1.0)) Fail(*kind, row, c.name, "must be -1, 0 or +1");
            ob.direction[c.index] = static_cast<int>(x);
            break;
          default:
            break;
        }
      }
    }
    // Noise: one column for every residual row, or one per row (all of them).
    if (sigma_one || sigma_cols) {
      Eigen::VectorXd s(kind->rows());
      int given = 0;
      for (const Column& c : cols) {
        if (c.role != Role::kSigma || c.Null(i)) continue;
        if (c.index < 0) s.setConstant(c.number->values[i]);
        else s[c.index] = c.number->values[i];
        given += c.index < 0 ? kind->rows() : 1;
      }
      if (given == kind->rows()) ob.sigma = s;
      else if (given != 0)
        Fail(*kind, row, "sigma", "give sigma, or every one of sigma_1 to sigma_" +
                                      std::to_string(kind->rows()) + ", or none (null: the default noise)");
    }
    for (const Column& c : cols)
      if (c.role == Role::kScalar && c.key == "id" && !c.Null(i))
        ob.id.assign(c.text->data + c.text->offsets[i], static_cast<size_t>(c.text->offsets[i + 1] - c.text->offsets[i]));

    for (auto& [c, slot] : slots) {
      if (c->Null(i)) continue;
      if (c->number) *slot = c->number->values[i];
      else
        slot->get_ref<std::string&>().assign(c->text->data + c->text->offsets[i],
                                             static_cast<size_t>(c->text->offsets[i + 1] - c->text->offsets[i]));
    }
    // The row's name, in a buffer reused row after row.
    w.resize(w_prefix);
    w += std::to_string(row);
    auto read = [&](const json& o) {
      try {
        kind->Read(o, w, ds_, &ob);
      } catch (const std::invalid_argument& e) {
        // "ball3d row 17.length: ..." reads as the column it is about.
        std::string msg = e.what();
        if (msg.rfind(w + ".", 0) == 0) msg = w + ", column " + msg.substr(w.size() + 1);
        // A key no column gives: say which column is missing.
        const size_t start = w.size() + 9, end = msg.find_first_of(":[.", start);
        if (msg.rfind(w + ", column ", 0) == 0 && end != std::string::npos) {
          const std::string key = msg.substr(start, end - start);
          if (!o.contains(key) && !std::any_of(cols.begin(), cols.end(), [&](const Column& c) { return c.key == key; }))
            throw std::invalid_argument(std::string(kind->name()) + ": missing column " + key +
                                        " (or " + key + "_x|y|z for a vector): " + msg);
        }
        throw std::invalid_argument(msg);
      } catch (const nlohmann::json::exception& e) {
        throw std::invalid_argument(w + ": wrong column type: " + e.what());
      }
    };
    if (!any_null) {
      read(own);
    } else {
      json o = own;
      for (const Column& c : cols) {
        if (!c.Null(i) || c.role == Role::kAxis || c.role == Role::kDirection || c.role == Role::kSigma ||
            c.key == "id")
          continue;
        if (c.role == Role::kScalar) o.erase(c.key);
        // A vector with a null component is absent only when all three are
        // null; a partial one is an error.
        if (c.role == Role::kVector && o.contains(c.key)) {
          for (const Column& d : cols)
            if (d.role == Role::kVector && d.key == c.key && !d.Null(i))
              Fail(*kind, row, c.name, "null while " + d.name + " is given");
          o.erase(c.key);
        }
        if (c.role == Role::kAxesObject && o.contains(c.key)) {
          o[c.key].erase(std::string(1, m.axis(c.index).name));
          if (o[c.key].empty()) o.erase(c.key);
        }
      }
      read(o);
    }
  }
  if (!b.positions) next_ += b.rows;
}

Dataset ColumnLoader::Finish(bool whole) {
  for (size_t r = 0; r < placed_.size(); ++r)
    if (!placed_[r]) throw std::invalid_argument("row " + std::to_string(first_ + static_cast<int64_t>(r)) + ": no observation");
  ds_.Validate();
  // An instrument noise no observation uses is a typo, as in a JSON file.
  for (const auto& kv : ds_.instrument_sigma) {
    if (!whole) break;
    bool named = false;
    for (const Observation& o : ds_.observations)
      if (const std::string* id = InstrumentId(o))
        if (*id == kv.first) {
          named = true;
          break;
        }
    if (!named)
      throw std::invalid_argument("dataset.instruments." + kv.first + ": no observation names this instrument");
  }
  placed_.clear();
  return std::move(ds_);
}

}  // namespace fivecal
