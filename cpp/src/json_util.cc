#include "json_util.h"

#include "fivecal/observations/registry.h"
#include "fivecal/observations/probe_trigger.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>

namespace fivecal::json_util {
namespace {

// Length of the valid UTF-8 sequence starting at s[i], or 0 if invalid.
size_t Utf8Length(const std::string& s, size_t i) {
  const auto b = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = b(i);
  if (c < 0x80) return 1;
  size_t n;
  unsigned int cp;
  if ((c & 0xE0) == 0xC0) n = 2, cp = c & 0x1F;
  else if ((c & 0xF0) == 0xE0) n = 3, cp = c & 0x0F;
  else if ((c & 0xF8) == 0xF0) n = 4, cp = c & 0x07;
  else return 0;
  if (i + n > s.size()) return 0;
  for (size_t k = 1; k < n; ++k) {
    if ((b(i + k) & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (b(i + k) & 0x3F);
  }
  // Overlong forms, surrogates and values past U+10FFFF are invalid too.
  if ((n == 2 && cp < 0x80) || (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000) ||
      (cp >= 0xD800 && cp <= 0xDFFF) || cp > 0x10FFFF)
    return 0;
  return n;
}

// s made valid UTF-8 (invalid bytes as \xNN), cut on a character boundary
// once it would exceed max_bytes; *cut says whether it was.
std::string Sanitize(const std::string& s, size_t max_bytes, bool* cut) {
  std::string out;
  out.reserve(std::min(s.size(), max_bytes) + 8);
  *cut = false;
  for (size_t i = 0; i < s.size();) {
    const size_t n = Utf8Length(s, i);
    char esc[8];
    const size_t add = n ? n : 4;
    if (out.size() + add > max_bytes) {
      *cut = true;
      break;
    }
    if (n) {
      out.append(s, i, n);
      i += n;
    } else {
      std::snprintf(esc, sizeof esc, "\\x%02X", static_cast<unsigned char>(s[i]));
      out += esc;
      ++i;
    }
  }
  return out;
}

// The path of the value a parse fails in, tracked by a SAX handler that
// builds nothing (the DOM parser's callback mode is much slower, so the fast
// parse has none and this runs only after it failed, to name the field).
class PathSax : public nlohmann::json_sax<json> {
 public:
  std::string error;
  std::string Path(const std::string& what) const {
    std::string path = what;
    for (const Level& l : stack_)
      path += l.array ? "[" + std::to_string(l.done) + "]" : (l.key.empty() ? "" : "." + l.key);
    return path;
  }
  bool null() override { return Completed(); }
  bool boolean(bool) override { return Completed(); }
  bool number_integer(number_integer_t) override { return Completed(); }
  bool number_unsigned(number_unsigned_t) override { return Completed(); }
  bool number_float(number_float_t, const string_t&) override { return Completed(); }
  bool string(string_t&) override { return Completed(); }
  bool binary(binary_t&) override { return Completed(); }
  bool start_object(std::size_t) override {
    stack_.push_back(Level{false, 0, {}});
    return true;
  }
  bool key(string_t& k) override {
    stack_.back().key = k;
    return true;
  }
  bool end_object() override { return End(); }
  bool start_array(std::size_t) override {
    stack_.push_back(Level{true, 0, {}});
    return true;
  }
  bool end_array() override { return End(); }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception& ex) override {
    error = ex.what();
    if (dynamic_cast<const json::out_of_range*>(&ex)) error += " (a number outside the double range)";
    else error = "invalid JSON: " + error;
    return false;
  }

 private:
  struct Level {
    bool array = false;
    long done = 0;  // completed elements of an array
    std::string key;
  };
  bool Completed() {
    if (!stack_.empty() && stack_.back().array) ++stack_.back().done;
    return true;
  }
  bool End() {
    stack_.pop_back();
    return Completed();
  }
  std::vector<Level> stack_;
};

std::string PathOfFailure(const std::string& text, const std::string& what, std::string* error) {
  PathSax sax;
  json::sax_parse(text, &sax);
  if (!sax.error.empty()) *error = sax.error;
  return sax.Path(what);
}

// Where the text first nests deeper than kMaxDepth: -1 if it never does.
// Strings are skipped (brackets inside them do not count).
long DepthExceededAt(const std::string& text) {
  int depth = 0;
  bool in_string = false;
  const char* p = text.data();
  const size_t n = text.size();
  for (size_t i = 0; i < n; ++i) {
    const char c = p[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
      continue;
    }
    switch (c) {
      case '"': in_string = true; break;
      case '[':
      case '{':
        if (++depth > kMaxDepth) return static_cast<long>(i);
        break;
      case ']':
      case '}': --depth; break;
      default: break;
    }
  }
  return -1;
}

std::string Lower(const std::string& s) {
  std::string o = s;
  for (char& c : o) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return o;
}

size_t EditDistance(const std::string& a, const std::string& b) {
  std::vector<size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

}  // namespace

std::string SafeMessage(const std::string& s, size_t max_bytes) {
  bool cut = false;
  std::string out = Sanitize(s, max_bytes, &cut);
  if (cut) out += " ... (message cut)";
  return out;
}

std::string Quote(const std::string& s, size_t max_bytes) {
  bool cut = false;
  std::string out = Sanitize(s, max_bytes, &cut);
  return "'" + out + (cut ? "...'" : "'");
}

json Parse(const std::string& text, const std::string& what) {
  const long deep = DepthExceededAt(text);
  if (deep >= 0) {
    // Name where it happens from the text before that point; the path is
    // cut to stay short however deep the document goes.
    std::string ignored;
    const std::string path = PathOfFailure(text.substr(0, static_cast<size_t>(deep)), what, &ignored);
    throw std::invalid_argument(SafeMessage(path, 300) + ": nested deeper than " +
                                std::to_string(kMaxDepth) + " levels (at byte " + std::to_string(deep) +
                                "); no file of this kind nests so deep");
  }
  try {
    return json::parse(text);
  } catch (const json::exception&) {
    std::string error = "invalid JSON";
    const std::string path = PathOfFailure(text, what, &error);
    throw std::invalid_argument(SafeMessage(SafeMessage(path, 300) + ": " + error));
  }
}

std::string DidYouMean(const std::string& name, const std::vector<std::string>& candidates) {
  const std::string low = Lower(name);
  size_t best = std::numeric_limits<size_t>::max();
  const std::string* pick = nullptr;
  for (const std::string& c : candidates) {
    const size_t d = Lower(c) == low ? 0 : EditDistance(low, Lower(c)) + (c.size() == name.size() ? 0 : 0);
    if (d < best) best = d, pick = &c;
  }
  if (!pick) return "";
  const size_t len = std::max(name.size(), pick->size());
  const size_t allowed = len <= 3 ? 1 : len <= 8 ? 2 : 3;
  if (best > allowed) return "";
  return " (did you mean \"" + *pick + "\"?)";
}

void CheckKeys(const json& obj, std::initializer_list<const char*> allowed, const std::string& where) {
  CheckKeys(obj, std::vector<const char*>(allowed), where);
}

void CheckKeys(const json& obj, const std::vector<const char*>& allowed, const std::string& where) {
  for (auto it = obj.begin(); it != obj.end(); ++it) {
    const std::string& key = it.key();
    bool ok = false;
    for (const char* a : allowed)
      if (key == a) {
        ok = true;
        break;
      }
    if (ok) continue;
    const std::vector<std::string> names(allowed.begin(), allowed.end());
    std::string hint = DidYouMean(key, names);
    if (hint.empty()) {
      hint = " (expected";
      for (const std::string& n : names) hint += " \"" + n + "\"";
      hint += ")";
    }
    throw std::invalid_argument(where + ": unknown key \"" + Quote(key).substr(1, Quote(key).size() - 2) +
                                "\"" + hint);
  }
}

bool IntegralValue(const json& v, int64_t* out) {
  if (v.is_number_unsigned()) {
    const uint64_t u = v.get<uint64_t>();
    if (u > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) return false;
    *out = static_cast<int64_t>(u);
    return true;
  }
  if (v.is_number_integer()) {
    *out = v.get<int64_t>();
    return true;
  }
  if (v.is_number_float()) {
    const double d = v.get<double>();
    // 2^63 is exactly representable; anything at or above it does not fit.
    if (!std::isfinite(d) || d != std::floor(d) || std::abs(d) >= 9223372036854775808.0) return false;
    *out = static_cast<int64_t>(d);
    return true;
  }
  return false;
}

int ReadDirection(const json& v, const std::string& where) {
  int64_t x = 0;
  if (!IntegralValue(v, &x) || x < -1 || x > 1)
    throw std::invalid_argument(where + ": must be -1, 0 or +1 (got " + Quote(v.dump(), 40) + ")");
  return static_cast<int>(x);
}

uint64_t ReadSeed(const json& v, const std::string& where) {
  const std::string bad = where + ": must be an integer 0 <= seed < 2^64 (got " + Quote(v.dump(), 40) + ")";
  if (v.is_number_unsigned()) return v.get<uint64_t>();
  if (v.is_number_integer()) {
    if (v.get<int64_t>() < 0) throw std::invalid_argument(bad);
    return static_cast<uint64_t>(v.get<int64_t>());
  }
  if (v.is_number_float()) {
    const double d = v.get<double>();
    if (std::isfinite(d) && d == std::floor(d) && d >= 0 && d < 18446744073709551616.0)
      return static_cast<uint64_t>(d);
  }
  throw std::invalid_argument(bad);
}

Eigen::Vector3d ReadVector3(const json& j, const std::string& where, double bound) {
  if (!j.is_array() || j.size() != 3)
    throw std::invalid_argument(where + ": expected an array of 3 numbers");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    if (!j[i].is_number())
      throw std::invalid_argument(where + "[" + std::to_string(i) + "]: not a number");
    v[i] = j[i].get<double>();
    // The message is built only for a value that fails: this runs for every
    // vector of every observation of a 10^6-sample trace.
    if (std::isfinite(bound) ? !(std::abs(v[i]) <= bound) : !std::isfinite(v[i])) {
      if (std::isfinite(bound)) RequireBounded(v[i], bound, where + "[" + std::to_string(i) + "]");
      else RequireFinite(v[i], where + "[" + std::to_string(i) + "]");
    }
  }
  return v;
}

double ReadBounded(const json& obj, const char* key, const std::string& where, double bound,
                   const char* unit) {
  const double x = ReadNumber(obj, key, where);
  RequireBounded(x, bound, where + "." + key, unit);
  return x;
}

std::string ReadSetup(const json& obj, const std::string& where) {
  if (!obj.contains("setup")) return "";
  if (!obj["setup"].is_string())
    throw std::invalid_argument(where + ".setup: expected a string (a mounting id such as \"A1\")");
  const std::string s = obj["setup"].get<std::string>();
  if (s.find('.') != std::string::npos)
    throw std::invalid_argument(where + ".setup: " + Quote(s) + " must not contain '.'");
  return s;
}

int AxisOfKey(const Machine& m, const std::string& key, const std::string& where) {
  const char c = key == "C1" ? 'S' : (key.size() == 1 ? key[0] : '?');
  const int k = m.AxisIndex(c);
  if (k < 0)
    throw std::invalid_argument(where + ": machine " + Quote(m.name()) + " has no axis " + Quote(key) +
                                " (axes " + m.axis_names() + ")");
  return k;
}

namespace {
// The key of a per-axis object as the axis index; refuses both 'S' and 'C1'.
int AxisSlot(const Machine& m, const std::string& key, const std::string& where,
             std::vector<bool>* seen) {
  const char c = key == "C1" ? 'S' : (key.size() == 1 ? key[0] : '?');
  const int k = m.AxisIndex(c);
  if (k < 0) AxisOfKey(m, key, where + "." + key);  // throws the message
  if ((*seen)[k])
    throw std::invalid_argument(where + ": both \"S\" and its alias \"C1\" are given; keep one");
  (*seen)[k] = true;
  return k;
}
}  // namespace

void ReadAxes(const Machine& m, const json& axes, const std::string& where, Eigen::VectorXd* values,
              std::vector<bool>* given) {
  if (!axes.is_object())
    throw std::invalid_argument(where + ": expected an object axis letter -> command (mm / degrees)");
  given->assign(m.num_axes(), false);
  for (auto it = axes.begin(); it != axes.end(); ++it) {
    const int k = AxisSlot(m, it.key(), where, given);
    const json& v = it.value();
    if (!v.is_number()) throw std::invalid_argument(where + "." + it.key() + ": expected a number");
    const double x = v.get<double>();
    const bool rot = m.axis(k).rotary();
    if (!(std::abs(x) <= (rot ? kMaxRotaryDeg : kMaxLinear)))
      RequireBounded(x, rot ? kMaxRotaryDeg : kMaxLinear, where + "." + it.key(), rot ? "degrees" : "mm");
    (*values)[k] = x;
  }
}

void ReadDirections(const Machine& m, const json& dirs, const std::string& where, Eigen::VectorXi* dir) {
  if (!dirs.is_object())
    throw std::invalid_argument(where + ": expected an object axis letter -> -1, 0 or +1");
  std::vector<bool> seen(m.num_axes(), false);
  for (auto it = dirs.begin(); it != dirs.end(); ++it) {
    const int k = AxisSlot(m, it.key(), where, &seen);
    const json& v = it.value();
    int64_t x;
    if (IntegralValue(v, &x) && x >= -1 && x <= 1) (*dir)[k] = static_cast<int>(x);
    else (*dir)[k] = ReadDirection(v, where + "." + it.key());
  }
}

}  // namespace fivecal::json_util
