#include "fivecal/observations/columns.h"

#include <algorithm>
#include <cmath>
#include <limits>
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

ColumnLoader::ColumnLoader(Dataset head, int64_t rows, int64_t first_row)
    : ds_(std::move(head)), first_(first_row), total_(rows) {
  if (rows < 0) throw std::invalid_argument("columns: negative row count");
  ds_.observations.clear();
  ds_.blocks.clear();
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
  // One row read as an Observation through the kind (the reference: its
  // checks and messages are a JSON file's).
  auto read_row = [&](int64_t i, int64_t row, Observation& ob) {
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
    };

  // A kind kept in columns: its rows go into blocks, read column by column;
  // the first row of each block (and any row a column check refuses) goes
  // through read_row, for the kind's own checks and messages.
  const int nv = kind->block_values();
  bool columnar = nv > 0;
  std::vector<const Column*> value_col(static_cast<size_t>(std::max(nv, 0)), nullptr);
  for (int v = 0; v < nv; ++v)
    for (const Column& c : cols)
      if (c.number && c.name == kind->block_value_name(v)) value_col[static_cast<size_t>(v)] = &c;
  for (const Column* c : value_col)
    // A missing or partly null value column: the rows' own messages.
    if (!c || (c->number->valid && std::find(c->number->valid, c->number->valid + b.rows, 0) != c->number->valid + b.rows))
      columnar = false;
  // The columns a block's rows share: every one but the axes, directions,
  // noise, values and id.
  std::vector<const Column*> shared_num, shared_txt;
  std::vector<std::string> shared_names;
  std::vector<const Column*> axis_col, dir_col, sigma_col;
  const Column* id_col = nullptr;
  for (const Column& c : cols) {
    if (c.role == Role::kAxis) axis_col.push_back(&c);
    else if (c.role == Role::kDirection) dir_col.push_back(&c);
    else if (c.role == Role::kSigma) sigma_col.push_back(&c);
    else if (c.role == Role::kScalar && c.key == "id") id_col = &c;
    else if (std::find(value_col.begin(), value_col.end(), &c) != value_col.end()) continue;
    else (c.number ? shared_num : shared_txt).push_back(&c);
  }
  for (const Column* c : shared_num) shared_names.push_back(c->name);
  for (const Column* c : shared_txt) shared_names.push_back("text:" + c->name);
  auto text_of = [](const Column& c, int64_t i) {
    return std::string(c.text->data + c.text->offsets[i], static_cast<size_t>(c.text->offsets[i + 1] - c.text->offsets[i]));
  };
  auto same_shared = [&](const Segment& g, int64_t i) {
    for (size_t k = 0; k < shared_num.size(); ++k) {
      const bool null = shared_num[k]->Null(i);
      if (null != (g.shared_null[k] != 0)) return false;
      if (!null && !(shared_num[k]->number->values[i] == g.shared_numbers[k])) return false;
    }
    for (size_t k = 0; k < shared_txt.size(); ++k) {
      const size_t f = shared_num.size() + k;
      const bool null = shared_txt[k]->Null(i);
      if (null != (g.shared_null[f] != 0)) return false;
      if (null) continue;
      const StringColumn& t = *shared_txt[k]->text;
      const std::string& x = g.shared_texts[k];
      const size_t len = static_cast<size_t>(t.offsets[i + 1] - t.offsets[i]);
      if (len != x.size() || x.compare(0, len, t.data + t.offsets[i], len) != 0) return false;
    }
    return true;
  };
  const int rows_per = kind->rows();
  std::vector<double> vals(static_cast<size_t>(std::max(nv, 1))), sig(static_cast<size_t>(rows_per));
  std::vector<double> q(static_cast<size_t>(na));
  std::vector<int> dirs(static_cast<size_t>(na));
  // A block a previous batch opened takes this batch's rows only when the
  // batch has the same shared columns.
  bool joinable = !segments_.empty() && segments_.back().block.type == kind->type() &&
                  segments_.back().shared_names == shared_names;
  std::string id;

  for (int64_t i = 0; i < b.rows; ++i) {
    const int64_t at = b.positions ? b.positions[i] : next_ + i;
    const int64_t row = first_ + at;  // what messages call it
    if (at < 0 || at >= total)
      throw std::invalid_argument(RowName(*kind, row) + ": row outside the " + std::to_string(total) + " announced");
    if (placed_[static_cast<size_t>(at)])
      throw std::invalid_argument(RowName(*kind, row) + ": row given twice");
    placed_[static_cast<size_t>(at)] = 1;
    if (!columnar) {
      object_at_.push_back(at);
      objects_.emplace_back();
      read_row(i, row, objects_.back());
      continue;
    }
    Segment* g = segments_.empty() ? nullptr : &segments_.back();
    const bool joins = joinable && g && g->start + static_cast<int64_t>(g->block.size()) == at && same_shared(*g, i);
    if (!joins) {
      Observation ob;
      read_row(i, row, ob);
      segments_.emplace_back();
      g = &segments_.back();
      g->start = at;
      g->block.type = kind->type();
      g->block.setup = ob.setup;
      g->block.common = kind->BlockCommon(ob);
      g->block.axes.resize(static_cast<size_t>(na));
      g->block.values.resize(static_cast<size_t>(nv));
      // The first block of a file of one kind: every row, at most (a trace
      // of one mounting grows without a copy; untouched capacity costs no
      // memory). Later blocks grow as vectors do.
      if (!b.positions && at == 0) {
        const size_t rest = static_cast<size_t>(total);
        for (auto& c : g->block.axes) c.reserve(rest);
        for (auto& c : g->block.values) c.reserve(rest);
      }
      for (const Column* c : shared_num) {
        g->shared_null.push_back(c->Null(i) ? 1 : 0);
        g->shared_numbers.push_back(c->Null(i) ? 0.0 : c->number->values[i]);
      }
      for (const Column* c : shared_txt) {
        g->shared_null.push_back(c->Null(i) ? 1 : 0);
        g->shared_texts.push_back(c->Null(i) ? std::string() : text_of(*c, i));
      }
      g->shared_names = shared_names;
      joinable = true;
      kind->BlockValues(ob, vals.data());
      PushBlockRow(&g->block, na, ob.axes.data(), ob.direction.data(), vals.data(), rows_per,
                   ob.sigma.size() ? ob.sigma.data() : nullptr, &ob.id);
      continue;
    }
    // Column checks; a row one refuses is read through the kind, whose
    // message names the row and the column as a per-object row's does.
    bool bad = false;
    std::fill(q.begin(), q.end(), 0.0);
    std::fill(dirs.begin(), dirs.end(), 0);
    for (const Column* c : axis_col) {
      if (c->Null(i)) {
        bad = bad || m.axis(c->index).name != 'S';
        continue;
      }
      const double x = c->number->values[i];
      const bool rot = m.axis(c->index).rotary();
      if (!(std::abs(x) <= (rot ? kMaxRotaryDeg : kMaxLinear))) bad = true;
      q[static_cast<size_t>(c->index)] = x;
    }
    for (const Column* c : dir_col) {
      if (c->Null(i)) continue;
      const double x = c->number->values[i];
      if (!(x == -1.0 || x == 0.0 || x == 1.0)) bad = true;
      else dirs[static_cast<size_t>(c->index)] = static_cast<int>(x);
    }
    for (int v = 0; v < nv; ++v) {
      const double x = value_col[static_cast<size_t>(v)]->number->values[i];
      if (!(std::abs(x) <= kind->block_value_bound(v))) bad = true;
      vals[static_cast<size_t>(v)] = x;
    }
    int given = 0;
    for (const Column* c : sigma_col) {
      if (c->Null(i)) continue;
      if (c->index < 0) std::fill(sig.begin(), sig.end(), c->number->values[i]);
      else sig[static_cast<size_t>(c->index)] = c->number->values[i];
      given += c->index < 0 ? rows_per : 1;
    }
    if (given != 0 && given != rows_per) bad = true;
    if (bad) {
      Observation ob;
      read_row(i, row, ob);
      Fail(*kind, row, "?", "refused by a column check the kind accepts (a bug)");
    }
    if (id_col && !id_col->Null(i)) id = text_of(*id_col, i);
    else id.clear();
    PushBlockRow(&g->block, na, q.data(), dirs.data(), vals.data(), rows_per, given ? sig.data() : nullptr, &id);
  }
  if (!b.positions) next_ += b.rows;
}

Dataset ColumnLoader::Finish(bool whole) {
  for (size_t r = 0; r < placed_.size(); ++r)
    if (!placed_[r]) throw std::invalid_argument("row " + std::to_string(first_ + static_cast<int64_t>(r)) + ": no observation");
  // The dataset's order is the per-object observations, then the blocks
  // (dataset.h TraceBlock): block rows before the last per-object row
  // become Observations.
  int64_t split = 0;
  for (int64_t at : object_at_) split = std::max(split, at + 1);
  // Rows that change mounting every few rows make blocks of a few rows,
  // each of a dozen vectors: fewer than 64 rows a block on average, they
  // are Observations.
  int64_t block_rows = 0, blocks = 0;
  for (const Segment& g : segments_) {
    const int64_t end = g.start + static_cast<int64_t>(g.block.size());
    if (end <= split) continue;  // Observations anyway
    block_rows += end - std::max(g.start, split);
    ++blocks;
  }
  if (blocks * 64 > block_rows) split = total_;
  std::sort(segments_.begin(), segments_.end(), [](const Segment& a, const Segment& b) { return a.start < b.start; });
  std::vector<Segment> kept;
  for (Segment& g : segments_) {
    const int64_t n = static_cast<int64_t>(g.block.size());
    const int64_t k = std::min(n, std::max<int64_t>(0, split - g.start));
    for (int64_t r = 0; r < k; ++r) {
      object_at_.push_back(g.start + r);
      objects_.emplace_back();
      ds_.FillRow(g.block, static_cast<size_t>(r), &objects_.back());
    }
    if (k == n) continue;
    if (k > 0) {
      // A noise column of one value is every row's: it stays.
      auto drop = [k](auto& cols) {
        for (auto& c : cols)
          if (c.size() > 1) c.erase(c.begin(), c.begin() + k);
      };
      drop(g.block.axes);
      drop(g.block.direction);
      drop(g.block.values);
      drop(g.block.sigma);
      if (!g.block.ids.empty()) g.block.ids.erase(g.block.ids.begin(), g.block.ids.begin() + k);
      g.start += k;
    }
    kept.push_back(std::move(g));
  }
  segments_.clear();
  std::vector<size_t> order(objects_.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return object_at_[a] < object_at_[b]; });
  ds_.observations.reserve(objects_.size());
  for (size_t i : order) ds_.observations.push_back(std::move(objects_[i]));
  objects_.clear();
  object_at_.clear();
  for (Segment& g : kept) ds_.blocks.push_back(std::move(g.block));
  ds_.Validate();
  // An instrument noise no observation uses is a typo, as in a JSON file.
  Observation first;
  for (const auto& kv : ds_.instrument_sigma) {
    if (!whole) break;
    bool named = false;
    for (const Observation& o : ds_.observations)
      if (const std::string* id = InstrumentId(o))
        if (*id == kv.first) {
          named = true;
          break;
        }
    for (const TraceBlock& b : ds_.blocks)
      if (!named && b.size()) {
        ds_.FillRow(b, 0, &first);
        if (const std::string* id = InstrumentId(first)) named = *id == kv.first;
      }
    if (!named)
      throw std::invalid_argument("dataset.instruments." + kv.first + ": no observation names this instrument");
  }
  placed_.clear();
  return std::move(ds_);
}

void PushBlockRow(TraceBlock* b, int na, const double* axes, const int* direction, const double* values, int rows,
                  const double* sigma, const std::string* id) {
  const size_t n = b->size();
  for (int k = 0; k < na; ++k) b->axes[static_cast<size_t>(k)].push_back(axes[k]);
  bool dir = false;
  for (int k = 0; direction && k < na; ++k) dir = dir || direction[k] != 0;
  if (dir && b->direction.empty()) b->direction.assign(static_cast<size_t>(na), std::vector<int8_t>(n, 0));
  if (!b->direction.empty())
    for (int k = 0; k < na; ++k) b->direction[static_cast<size_t>(k)].push_back(static_cast<int8_t>(direction ? direction[k] : 0));
  for (size_t c = 0; c < b->values.size(); ++c) b->values[c].push_back(values[c]);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (sigma && b->sigma.empty())
    // Until a row differs, one value per column stands for every row
    // (NaN: the rows before declared none).
    b->sigma.assign(static_cast<size_t>(rows), std::vector<double>(1, n == 0 ? 0.0 : nan));
  if (!b->sigma.empty()) {
    bool constant = b->sigma[0].size() == 1;
    for (int k = 0; k < rows && constant; ++k) {
      const double x = sigma ? sigma[k] : nan;
      const double was = b->sigma[static_cast<size_t>(k)][0];
      constant = n == 0 || x == was;
    }
    if (constant && n == 0)
      for (int k = 0; k < rows; ++k) b->sigma[static_cast<size_t>(k)][0] = sigma[k];
    if (!constant) {
      for (int k = 0; k < rows; ++k) {
        std::vector<double>& c = b->sigma[static_cast<size_t>(k)];
        if (c.size() == 1 && n != 1) c.assign(n, c[0]);
        c.push_back(sigma ? sigma[k] : nan);
      }
    }
  }
  // Ids only once a row has one (the rows before: none).
  if (!b->ids.empty() || (id && !id->empty())) {
    b->ids.resize(n);
    b->ids.push_back(id ? *id : std::string());
  }
}

}  // namespace fivecal
