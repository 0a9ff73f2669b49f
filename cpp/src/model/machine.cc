#include "fivecal/model/machine.h"
#include "fivecal/model/machine_kinds.h"

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

constexpr const char* kAxisLetters = "XYZABCS";

bool IsAxisLetter(char c) { return std::string(kAxisLetters).find(c) != std::string::npos; }

AxisType NaturalType(char c) {
  return (c == 'X' || c == 'Y' || c == 'Z') ? AxisType::kLinear : AxisType::kRotary;
}

// The whole (UTF-8) character starting at tokens[i], for messages: a
// multi-byte letter such as 'é' must not be cut.
std::string Character(const std::vector<char>& tokens, size_t i) {
  const unsigned char c = static_cast<unsigned char>(tokens[i]);
  const size_t n = c < 0x80 ? 1 : (c & 0xE0) == 0xC0 ? 2 : (c & 0xF0) == 0xE0 ? 3 : (c & 0xF8) == 0xF0 ? 4 : 1;
  return std::string(tokens.begin() + i, tokens.begin() + std::min(tokens.size(), i + n));
}

// Splits the topology into the workpiece-side letters (read w->f) and the
// tool-side letters (read f->t).
void ParseTopology(const std::string& topo, std::string* workpiece, std::string* tool) {
  const std::string where = "machine.topology " + Quote(topo);
  if (topo.empty()) throw std::invalid_argument(where + ": empty topology");
  std::vector<char> tokens;
  for (size_t i = 0; i < topo.size(); ++i) {
    if (topo[i] == '(') {
      size_t close = topo.find(')', i);
      if (close == std::string::npos)
        throw std::invalid_argument(where + ": unmatched '('");
      std::string inner = topo.substr(i + 1, close - i - 1);
      if (inner != "C1")
        throw std::invalid_argument(where + ": unknown token " + Quote("(" + inner + ")") +
                                    "; only '(C1)' (the spindle) is recognised");
      tokens.push_back('S');
      i = close;
    } else {
      tokens.push_back(topo[i]);
    }
  }
  if (tokens.front() != 'w')
    throw std::invalid_argument(where + ": must start with 'w' (workpiece)");
  if (tokens.back() != 't')
    throw std::invalid_argument(where + ": must end with 't' (tool)");
  int foundation = -1;
  std::set<char> seen;
  for (size_t i = 1; i + 1 < tokens.size(); ++i) {
    char c = tokens[i];
    if (c == 'f' || c == 'b') {
      if (foundation >= 0)
        throw std::invalid_argument(where + ": more than one foundation ('f' or 'b')");
      foundation = static_cast<int>(i);
      continue;
    }
    if (!IsAxisLetter(c))
      throw std::invalid_argument(where + ": unknown axis letter " + Quote(Character(tokens, i)) +
                                  " (expected X Y Z A B C S, 'f'/'b' foundation)");
    if (!seen.insert(c).second)
      throw std::invalid_argument(where + ": duplicate axis '" + std::string(1, c) + "'");
  }
  if (foundation < 0)
    throw std::invalid_argument(where + ": no foundation ('f' or 'b') between 'w' and 't'");
  workpiece->assign(tokens.begin() + 1, tokens.begin() + foundation);
  tool->assign(tokens.begin() + foundation + 1, tokens.end() - 1);
}

}  // namespace

void RequireFinite(double x, const std::string& what) {
  if (!std::isfinite(x)) throw std::invalid_argument(what + ": value is not finite (NaN or inf)");
}

Eigen::Vector3d UnitDirection(const Eigen::Vector3d& v, const std::string& what) {
  for (int i = 0; i < 3; ++i) RequireFinite(v[i], what + "[" + std::to_string(i) + "]");
  const double scale = v.cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) throw std::invalid_argument(what + ": zero vector (a direction needs a non-zero component)");
  const Eigen::Vector3d s = v / scale;  // largest component +-1: its norm is in [1, sqrt(3)]
  return s / s.norm();
}

void RequireBounded(double x, double bound, const std::string& what, const char* unit) {
  RequireFinite(x, what);
  if (!(std::abs(x) <= bound)) {
    char buf[128];
    std::snprintf(buf, sizeof buf, ": %.6g %s is implausible (the bound is |x| <= %g %s)", x, unit, bound,
                  unit);
    // A position or length past the machine-size bound is almost always a file
    // written in µm; say so here, since this check refuses before the Python
    // units heuristics (which say the same for 10-100 m) get to look.
    const bool linear_mm = bound == kMaxLinear && std::string(unit) == "mm";
    throw std::invalid_argument(what + buf +
                                (linear_mm ? "; values this large look like \xc2\xb5m: divide by 1000 "
                                             "(fivecal expects mm)"
                                           : ""));
  }
}

Machine::Machine(std::string name, std::string topology, std::vector<Axis> axes,
                 Eigen::Vector3d tip, const Eigen::Vector3d* tool_axis)
    : name_(std::move(name)), topology_(std::move(topology)), tip_(tip) {
  std::string wp, tl;
  ParseTopology(topology_, &wp, &tl);
  std::map<char, Axis> by_name;
  for (const Axis& a : axes) {
    if (!IsAxisLetter(a.name))
      throw std::invalid_argument("machine.axes: unknown axis letter '" + std::string(1, a.name) +
                                  "' (expected X Y Z A B C S)");
    if (!by_name.emplace(a.name, a).second)
      throw std::invalid_argument("machine.axes: duplicate axis '" + std::string(1, a.name) + "'");
  }
  const std::string order = wp + tl;
  for (char c : order) {
    auto it = by_name.find(c);
    if (it == by_name.end())
      throw std::invalid_argument("machine.axes: axis '" + std::string(1, c) +
                                  "' appears in topology '" + topology_ +
                                  "' but has no definition");
    Axis a = it->second;
    const std::string where = "machine.axes." + std::string(1, c);
    if (a.type != NaturalType(c))
      throw std::invalid_argument(where + ".type: axis letter '" + std::string(1, c) + "' is " +
                                  (NaturalType(c) == AxisType::kLinear ? "linear" : "rotary") +
                                  " by ISO 230-1 naming");
    for (int i = 0; i < 3; ++i)
      RequireBounded(a.point[i], kMaxLinear, where + ".point[" + std::to_string(i) + "]");
    // Every path (file, dict, direct construction) comes through here: a
    // plain norm() of [0,0,1.35e154] or [-1e308,-1e308,0] is inf and would
    // turn the axis into a zero (motionless) one.
    a.direction = UnitDirection(a.direction, where + ".direction");
    axes_.push_back(a);
    by_name.erase(it);
  }
  if (!by_name.empty())
    throw std::invalid_argument("machine.axes: axis '" + std::string(1, by_name.begin()->first) +
                                "' is defined but not in topology '" + topology_ + "'");
  if (axes_.empty())
    throw std::invalid_argument("machine.topology " + Quote(topology_) +
                                ": no axes between 'w' and 't'; a machine needs at least one");
  // Two parallel linear axes move the tool along one line only: the model
  // would be singular and a fit would "converge" to anything.
  for (size_t i = 0; i < axes_.size(); ++i)
    for (size_t k = i + 1; k < axes_.size(); ++k)
      if (!axes_[i].rotary() && !axes_[k].rotary() &&
          axes_[i].direction.cross(axes_[k].direction).norm() < 1e-6)
        throw std::invalid_argument("machine.axes." + std::string(1, axes_[k].name) +
                                    ".direction: parallel to linear axis " + std::string(1, axes_[i].name) +
                                    "; linear axes must be independent");
  for (int i = 0; i < 3; ++i)
    RequireBounded(tip_[i], kMaxLinear, "machine.tool.tip[" + std::to_string(i) + "]");
  int s = AxisIndex('S');
  if (tool_axis) {
    tool_axis_ = UnitDirection(*tool_axis, "machine.tool.axis");
  } else {
    tool_axis_ = s >= 0 ? axes_[s].direction : Eigen::Vector3d::UnitZ();
  }
  BuildChains();
  BuildParameters();
}

void Machine::BuildChains() {
  std::string wp, tl;
  ParseTopology(topology_, &wp, &tl);
  // Workpiece letters are read w->f, so the chain from the foundation is reversed.
  for (int i = static_cast<int>(wp.size()) - 1; i >= 0; --i) workpiece_chain_.push_back(i);
  for (size_t i = 0; i < tl.size(); ++i) tool_chain_.push_back(static_cast<int>(wp.size() + i));
}

bool Machine::on_tool_side(int axis) const {
  return axis >= static_cast<int>(workpiece_chain_.size());
}

void Machine::BuildParameters() {
  params_.clear();
  axis_offset_.clear();
  for (int k = 0; k < num_axes(); ++k) {
    const char a = axes_[k].name;
    axis_offset_.push_back(static_cast<int>(params_.size()));
    for (int c = 0; c < 6; ++c) {
      ParameterInfo p;
      p.name = std::string("E") + kComponentLetters[c] + "0" + a;
      p.kind = ParameterKind::kLocation;
      p.axis = k;
      p.component = c;
      params_.push_back(p);
    }
    for (int c = 0; c < 6; ++c) {
      for (int d = 1; d <= 3; ++d) {
        ParameterInfo p;
        p.name = std::string("E") + kComponentLetters[c] + a + std::to_string(d);
        p.kind = ParameterKind::kMotion;
        p.axis = k;
        p.component = c;
        p.degree = d;
        params_.push_back(p);
      }
    }
    if (a != 'S') {
      ParameterInfo p;
      p.name = std::string("E") + a + a + "b";
      p.kind = ParameterKind::kBacklash;
      p.axis = k;
      p.component = std::string("XYZABC").find(a);
      params_.push_back(p);
    }
  }
  tip_offset_ = static_cast<int>(params_.size());
  for (int c = 0; c < 3; ++c) {
    ParameterInfo p;
    p.name = std::string("tip.") + "xyz"[c];
    p.kind = ParameterKind::kTip;
    p.component = c;
    params_.push_back(p);
  }
  index_.clear();
  for (int i = 0; i < num_parameters(); ++i) index_[params_[i].name] = i;
}

int Machine::backlash_index(int axis) const {
  if (axes_.at(axis).name == 'S') return -1;
  return axis_offset_[axis] + 24;
}

int Machine::AxisIndex(char name) const {
  for (int i = 0; i < num_axes(); ++i)
    if (axes_[i].name == name) return i;
  return -1;
}

std::string Machine::axis_names() const {
  std::string s;
  for (const Axis& a : axes_) s += a.name;
  return s;
}

std::vector<std::string> Machine::parameter_names() const {
  std::vector<std::string> out;
  out.reserve(params_.size());
  for (const auto& p : params_) out.push_back(p.name);
  return out;
}

int Machine::ParameterIndex(const std::string& name) const {
  auto it = index_.find(name);
  return it == index_.end() ? -1 : it->second;
}

int Machine::RequireParameter(const std::string& name) const {
  int i = ParameterIndex(name);
  if (i >= 0) return i;
  std::string msg = "unknown parameter " + Quote(name) + " for machine " + Quote(name_) + " (axes " +
                    axis_names() + ")" + DidYouMean(name, parameter_names());
  if (name.size() >= 3 && name[0] == 'E') {
    char axis = name.size() >= 4 && name[2] == '0' ? name[3] : name[2];
    if (AxisIndex(axis) < 0 && IsAxisLetter(axis))
      msg += ": this machine has no axis '" + std::string(1, axis) + "'";
  }
  throw std::invalid_argument(msg);
}

namespace {
Machine ParseMachine(const json& j);
}

Machine Machine::FromJson(const std::string& text) {
  return Guard("machine", [&] { return ParseMachine(Parse(text, "machine")); });
}

namespace {
Machine ParseMachine(const json& j) {
  if (!j.is_object()) throw std::invalid_argument("machine: expected a JSON object");
  CheckKeys(j, {"name", "topology", "axes", "tool", "priors", "kind", "$schema"}, "machine");
  if (j.contains("name") && !j["name"].is_string())
    throw std::invalid_argument("machine.name: expected a string");
  std::string name = j.value("name", std::string("unnamed"));
  if (!j.contains("topology") || !j["topology"].is_string())
    throw std::invalid_argument("machine.topology: missing (a string such as \"wCBXfZYSt\")");
  std::string topology = j["topology"].get<std::string>();
  if (!j.contains("axes") || !j["axes"].is_object())
    throw std::invalid_argument("machine.axes: missing (an object keyed by axis letter)");
  std::vector<Axis> axes;
  bool seen_spindle = false;
  for (auto& [key, val] : j["axes"].items()) {
    std::string letter = key == "C1" ? "S" : key;
    const std::string where = "machine.axes." + key;
    if (letter.size() != 1 || !IsAxisLetter(letter[0]))
      throw std::invalid_argument(where + ": unknown axis letter " + Quote(key) +
                                  " (expected X Y Z A B C S)");
    if (!val.is_object()) throw std::invalid_argument(where + ": expected an object");
    if (letter == "S" && seen_spindle)
      throw std::invalid_argument("machine.axes: duplicate axis 'S': both \"S\" and its alias \"C1\" are given; keep one");
    if (letter == "S") seen_spindle = true;
    CheckKeys(val, {"type", "direction", "point"}, where);
    Axis a;
    a.name = letter[0];
    a.type = NaturalType(a.name);
    if (val.contains("type")) {
      std::string t = val["type"].is_string() ? val["type"].get<std::string>() : "";
      if (t == "linear") a.type = AxisType::kLinear;
      else if (t == "rotary") a.type = AxisType::kRotary;
      else throw std::invalid_argument(where + ".type: expected \"linear\" or \"rotary\"");
    }
    if (!val.contains("direction"))
      throw std::invalid_argument(where + ".direction: missing");
    // Any finite scale: the direction is normalised (stably) by the model.
    a.direction = ReadVector3(val["direction"], where + ".direction", HUGE_VAL);
    if (val.contains("point")) a.point = ReadVector3(val["point"], where + ".point");
    if (a.type == AxisType::kLinear && a.point.norm() != 0.0)
      throw std::invalid_argument(where + ".point: a linear axis has no pivot point; omit it");
    axes.push_back(a);
  }
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();
  Eigen::Vector3d tool_axis;
  bool has_tool_axis = false;
  if (j.contains("tool")) {
    const json& t = j["tool"];
    if (!t.is_object()) throw std::invalid_argument("machine.tool: expected an object");
    CheckKeys(t, {"tip", "axis"}, "machine.tool");
    if (t.contains("tip")) tip = ReadVector3(t["tip"], "machine.tool.tip");
    if (t.contains("axis")) {
      tool_axis = ReadVector3(t["axis"], "machine.tool.axis", HUGE_VAL);
      has_tool_axis = true;
    }
  }
  Machine m(name, topology, axes, tip, has_tool_axis ? &tool_axis : nullptr);
  if (j.contains("priors")) {
    const json& p = j["priors"];
    if (!p.is_object())
      throw std::invalid_argument("machine.priors: expected an object parameter name -> prior sigma");
    for (auto& [key, val] : p.items()) {
      const std::string where = "machine.priors." + key;
      if (key.rfind("class:", 0) == 0) {
        if (key.size() == 6) throw std::invalid_argument(where + ": empty class name after 'class:'");
      } else {
        try {
          m.RequireParameter(key);
        } catch (const std::invalid_argument& e) {
          throw std::invalid_argument(where + ": " + e.what());
        }
      }
      if (!val.is_number()) throw std::invalid_argument(where + ": expected a number");
      const double v = val.get<double>();
      if (!(std::isfinite(v) && v > 0))
        throw std::invalid_argument(where + ": must be a finite number > 0 (one sigma, mm or rad)");
      m.priors[key] = v;
    }
  }
  // The kind's class priors (machine_kinds.h) under the file's own, which win
  // key by key; a written machine carries them as explicit class priors.
  if (j.contains("kind")) {
    if (!j["kind"].is_string())
      throw std::invalid_argument("machine.kind: expected a string (machining_centre, positioner, robot, cmm)");
    for (const auto& [key, v] : MachineKindPriors(CanonicalMachineKind(j["kind"].get<std::string>(), "machine.kind")))
      m.priors.emplace(key, v);
  }
  return m;
}
}  // namespace

Machine Machine::Load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::invalid_argument("machine: cannot open " + Quote(path, 400));
  std::stringstream ss;
  ss << in.rdbuf();
  try {
    return FromJson(ss.str());
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(SafeMessage(path + ": " + e.what()));
  }
}

std::string Machine::ToJson() const {
  json j;
  j["name"] = name_;
  j["topology"] = topology_;
  json axes = json::object();
  for (const Axis& a : axes_) {
    json ja;
    ja["type"] = a.rotary() ? "rotary" : "linear";
    ja["direction"] = Array3(a.direction);
    if (a.rotary()) ja["point"] = Array3(a.point);
    axes[std::string(1, a.name)] = ja;
  }
  j["axes"] = axes;
  j["tool"] = {{"tip", Array3(tip_)}, {"axis", Array3(tool_axis_)}};
  if (!priors.empty()) j["priors"] = priors;
  return j.dump(1);
}

ErrorModel::ErrorModel(const Machine& machine)
    : machine_(machine), values_(Eigen::VectorXd::Zero(machine.num_parameters())) {}

ErrorModel ErrorModel::FromJson(const Machine& machine, const std::string& text) {
  json j = Parse(text, "errors");
  // Accept both {"EX0C": 0.1} and the result format {"parameters": {"EX0C": {"value": ..}}}.
  if (j.is_object() && j.contains("parameters")) j = j["parameters"];
  if (!j.is_object()) throw std::invalid_argument("errors: expected a JSON object name -> value");
  ErrorModel e(machine);
  for (auto& [name, val] : j.items()) {
    // A result file also carries setup parameters (facet.F3, sphere.S1.x,
    // ...): those are skipped, any other unknown name (EX0C.x) is refused.
    if (machine.ParameterIndex(name) < 0 && IsSetupParameterName(name)) continue;
    double v;
    if (val.is_number()) v = val.get<double>();
    else if (val.is_object() && val.contains("value") && val["value"].is_number())
      v = val["value"].get<double>();
    else throw std::invalid_argument("errors." + name + ": expected a number");
    e.Set(name, v);
  }
  return e;
}

void ErrorModel::Set(const std::string& name, double value) {
  RequireBounded(value, kMaxErrorValue, "errors." + name, "(mm or rad)");
  values_[machine_.RequireParameter(name)] = value;
}

double ErrorModel::Get(const std::string& name) const {
  return values_[machine_.RequireParameter(name)];
}

}  // namespace fivecal
