// Private JSON helpers shared by the parsers (machine, dataset, simulation):
// every failure names the field it is about.
#ifndef FIVECAL_SRC_JSON_UTIL_H_
#define FIVECAL_SRC_JSON_UTIL_H_

#include <Eigen/Core>
#include <cstdint>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal::json_util {

using nlohmann::json;

// Deepest nesting a document may have: every format here is at most about 6
// levels deep, and a pre-scan refusing deeper text keeps a hostile file
// (100k unclosed '[') from costing memory, recursion or a huge message.
inline constexpr int kMaxDepth = 64;

// Parses JSON; a syntax error or a number out of double range names the
// field being read (what.observations[3].axes.B). The fast parse has no
// callback; only after a failure is the text parsed again with a callback
// tracking the path, to name the field.
json Parse(const std::string& text, const std::string& what);

// A message safe to hand to any caller: invalid UTF-8 bytes escaped as \xNN
// (Python decodes exception messages as UTF-8) and at most `max_bytes` long,
// cut on a character boundary.
std::string SafeMessage(const std::string& s, size_t max_bytes = 2000);

// `s` quoted for a message: truncated to `max_bytes` on a character boundary,
// invalid UTF-8 escaped.
std::string Quote(const std::string& s, size_t max_bytes = 80);

// Runs a parser body, turning nlohmann's type errors (a number where a string
// belongs, ...) into std::invalid_argument prefixed with `what`, and making
// every message safe (SafeMessage).
template <typename F>
auto Guard(const std::string& what, F&& body) -> decltype(body()) {
  try {
    return body();
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(SafeMessage(what + ": wrong JSON type: " + e.what()));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(SafeMessage(e.what()));
  }
}

// " (did you mean "X"?)" for the candidate closest to `name` by edit
// distance when it is close enough to be a typo, else "".
std::string DidYouMean(const std::string& name, const std::vector<std::string>& candidates);

// Refuses a key of `obj` not in `allowed`: `where: unknown key "k" (did you
// mean "x"?)`, listing the allowed keys when none is close.
void CheckKeys(const json& obj, std::initializer_list<const char*> allowed, const std::string& where);
void CheckKeys(const json& obj, const std::vector<const char*>& allowed, const std::string& where);

// An integer field that files may write as 1 or 1.0: exact integral values
// only, compared as JSON values (no truncation of 2^32+1 or 0.5).
bool IntegralValue(const json& v, int64_t* out);
// A backlash direction: -1, 0 or +1 (integral floats accepted).
int ReadDirection(const json& v, const std::string& where);
// A seed: an integer 0 <= seed < 2^64 (integral floats accepted).
uint64_t ReadSeed(const json& v, const std::string& where);

// A 3-vector of finite numbers, each |x| <= bound.
Eigen::Vector3d ReadVector3(const json& j, const std::string& where, double bound = kMaxLinear);

inline double ReadNumber(const json& obj, const char* key, const std::string& where) {
  if (!obj.contains(key)) throw std::invalid_argument(where + "." + key + ": missing");
  const json& v = obj[key];
  if (!v.is_number()) throw std::invalid_argument(where + "." + key + ": expected a number");
  const double x = v.get<double>();
  RequireFinite(x, where + "." + key);
  return x;
}

// A number |x| <= bound (unit named in the message).
double ReadBounded(const json& obj, const char* key, const std::string& where, double bound,
                   const char* unit = "mm");

inline std::string ReadString(const json& obj, const char* key, const std::string& where) {
  if (!obj.contains(key) || !obj[key].is_string())
    throw std::invalid_argument(where + "." + key + ": missing (a string)");
  return obj[key].get<std::string>();
}

// A DBB / ball3d mounting id: a string without '.' (it becomes part of the
// setup parameter names dbb.<setup>.length, ...).
std::string ReadSetup(const json& obj, const std::string& where);

inline json Array3(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// Axis index for a JSON key ("C1" is the spindle S); throws naming `where`.
int AxisOfKey(const Machine& m, const std::string& key, const std::string& where);

// Reads an "axes" object (axis letter -> command, mm / degrees) into
// `values` (machine axis order) and marks `given`; refuses unknown axes,
// both S and its alias C1, non-numbers and implausible magnitudes.
void ReadAxes(const Machine& m, const json& axes, const std::string& where, Eigen::VectorXd* values,
              std::vector<bool>* given);
// Reads a "direction" object (axis letter -> -1/0/+1) into `dir`.
void ReadDirections(const Machine& m, const json& dirs, const std::string& where, Eigen::VectorXi* dir);

}  // namespace fivecal::json_util

#endif  // FIVECAL_SRC_JSON_UTIL_H_
