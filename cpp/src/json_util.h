// Private JSON helpers shared by the parsers (machine, dataset, simulation):
// every failure names the field it is about.
#ifndef FIVECAL_SRC_JSON_UTIL_H_
#define FIVECAL_SRC_JSON_UTIL_H_

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/machine.h"

namespace fivecal::json_util {

using nlohmann::json;

// Parses JSON; a syntax error or a number out of double range names the
// field being read (what.observations[3].axes.B), tracked with the parser's
// callback since the lexer fails before the value reaches the parsers.
inline json Parse(const std::string& text, const std::string& what) {
  struct Level {
    bool array;
    int done = 0;  // completed elements of an array
    std::string key;
  };
  std::vector<Level> stack;
  auto completed = [&] {
    if (!stack.empty() && stack.back().array) ++stack.back().done;
  };
  json::parser_callback_t track = [&](int, json::parse_event_t event, json& parsed) {
    switch (event) {
      case json::parse_event_t::object_start: stack.push_back({false}); break;
      case json::parse_event_t::array_start: stack.push_back({true}); break;
      case json::parse_event_t::key: stack.back().key = parsed.get<std::string>(); break;
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        stack.pop_back();
        completed();
        break;
      case json::parse_event_t::value: completed(); break;
    }
    return true;
  };
  auto where = [&] {
    std::string path = what;
    for (const Level& l : stack)
      path += l.array ? "[" + std::to_string(l.done) + "]" : (l.key.empty() ? "" : "." + l.key);
    return path;
  };
  try {
    return json::parse(text, track);
  } catch (const json::parse_error& e) {
    throw std::invalid_argument(where() + ": invalid JSON: " + e.what());
  } catch (const json::out_of_range& e) {
    throw std::invalid_argument(where() + ": " + e.what() + " (a number outside the double range)");
  }
}

// Runs a parser body, turning nlohmann's type errors (a number where a string
// belongs, ...) into std::invalid_argument prefixed with `what`.
template <typename F>
auto Guard(const std::string& what, F&& body) -> decltype(body()) {
  try {
    return body();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(what + ": wrong JSON type: " + e.what());
  }
}

inline Eigen::Vector3d ReadVector3(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3)
    throw std::invalid_argument(where + ": expected an array of 3 numbers");
  Eigen::Vector3d v;
  for (int i = 0; i < 3; ++i) {
    if (!j[i].is_number())
      throw std::invalid_argument(where + "[" + std::to_string(i) + "]: not a number");
    v[i] = j[i].get<double>();
    RequireFinite(v[i], where + "[" + std::to_string(i) + "]");
  }
  return v;
}

inline double ReadNumber(const json& obj, const char* key, const std::string& where) {
  if (!obj.contains(key)) throw std::invalid_argument(where + "." + key + ": missing");
  const json& v = obj[key];
  if (!v.is_number()) throw std::invalid_argument(where + "." + key + ": expected a number");
  const double x = v.get<double>();
  RequireFinite(x, where + "." + key);
  return x;
}

inline std::string ReadString(const json& obj, const char* key, const std::string& where) {
  if (!obj.contains(key) || !obj[key].is_string())
    throw std::invalid_argument(where + "." + key + ": missing (a string)");
  return obj[key].get<std::string>();
}

inline json Array3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// Axis index for a JSON key ("C1" is the spindle S); throws naming `where`.
inline int AxisOfKey(const Machine& m, const std::string& key, const std::string& where) {
  const char c = key == "C1" ? 'S' : (key.size() == 1 ? key[0] : '?');
  const int k = m.AxisIndex(c);
  if (k < 0)
    throw std::invalid_argument(where + ": machine '" + m.name() + "' has no axis '" + key +
                                "' (axes " + m.axis_names() + ")");
  return k;
}

}  // namespace fivecal::json_util

#endif  // FIVECAL_SRC_JSON_UTIL_H_
