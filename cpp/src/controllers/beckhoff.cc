#include "fivecal/controllers/beckhoff.h"

#include <algorithm>
#include <cmath>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {

namespace {

const char* const kInfosys = "Beckhoff Information System (infosys.beckhoff.com), ";
const char* const kSrcChain =
    "TF5240 Universal Kinematics, 'Programming or description of the kinematic chain' (page 278674827) "
    "and 'Sequence of axes in the kinematic chain' (278706443)";
const char* const kSrcTables =
    "TF5280 Volumetric compensation, 'List of parameters supported' (296423819), 'ISG CSV format' "
    "(296429067), 'Etalon Exchange Format' (296430091); P-VOLC-00014 interpolation GRID";

constexpr double kUnit01um = 1e4;  // 0.1 um per mm: zero_position and point (P-CHAN-00286, -00293)
constexpr double kDeg = M_PI / 180.0;

enum class VolComp { kOff, kError, kCorrection };

struct Grid {
  double start = 0, step = 1;
  int n = 0;
  double at(int i) const { return start + step * i; }
};

struct Opts {
  std::string prefix;           // "kinematik[91]." or "trafo[j]."
  bool trafo = false;
  std::string axes;             // the channel's axis order: letter i has index i
  double tool_length = 0;       // mm: the tool table's length of the tool fivecal's tip describes
  VolComp volcomp = VolComp::kOff;
  double lin_scale = 1, ang_scale = 1;  // file units per mm, per rad
  std::string lin_unit = "mm", ang_unit = "rad";
  std::map<char, Grid> grids;   // machine axis letter -> grid (mm / degrees)
};

std::string Known(const std::map<std::string, std::string>& help) {
  std::string s;
  for (const auto& [k, v] : help) s += (s.empty() ? "" : ", ") + k;
  return s;
}

std::vector<int> NonSpindle(const Machine& m) {
  std::vector<int> out;
  for (int i = 0; i < m.num_axes(); ++i)
    if (m.axis(i).name != 'S') out.push_back(i);
  return out;
}

double Number(const std::string& key, const std::string& text) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(v))
    throw std::invalid_argument("option " + key + "=" + text + ": expected a number");
  return v;
}

Opts Parse(const Machine& m, const VendorOptions& o, const std::map<std::string, std::string>& help) {
  for (const auto& [k, v] : o) {
    const bool grid = k.size() == 6 && k.rfind("grid.", 0) == 0;
    if (!grid && help.count(k) == 0)
      throw std::invalid_argument("option '" + k + "': not a beckhoff option (known: " + Known(help) +
                                  ", grid.<axis>)");
    if (grid && (m.AxisIndex(k[5]) < 0 || k[5] == 'S'))
      throw std::invalid_argument("option '" + k + "': machine '" + m.name() + "' has no NC axis " +
                                  std::string(1, k[5]) + " (axes " + m.axis_names() + ")");
  }
  const auto need = [&](const std::string& k) -> std::string {
    const auto it = o.find(k);
    if (it == o.end())
      throw std::invalid_argument("beckhoff export needs --set " + k + "=...: " + help.at(k) +
                                  " (the public manual does not decide it for this machine)");
    return it->second;
  };
  Opts op;
  const std::string syntax = need("syntax");
  std::smatch mt;
  if (syntax == "kinematik") {
    op.prefix = "kinematik[91].";
  } else if (std::regex_match(syntax, mt, std::regex(R"(trafo\[(\d{1,3})\])"))) {
    op.prefix = syntax + ".";
    op.trafo = true;
  } else {
    throw std::invalid_argument("option syntax=" + syntax + ": expected 'kinematik' (CNC builds V2.11.20xx/28xx) "
                                "or 'trafo[j]' (builds from V3.00, j the transformation's index)");
  }
  op.axes = need("axes");
  std::string expect, got = op.axes;
  for (int k : NonSpindle(m)) expect += m.axis(k).name;
  std::string se = expect, sg = got;
  std::sort(se.begin(), se.end());
  std::sort(sg.begin(), sg.end());
  if (se != sg)
    throw std::invalid_argument("option axes=" + op.axes + ": must list each NC axis of machine '" + m.name() +
                                "' (" + expect + ") once, in the order of the channel's axis indices");
  op.tool_length = Number("tool_length", need("tool_length"));
  if (std::abs(op.tool_length) > kMaxLinear)
    throw std::invalid_argument("option tool_length=" + o.at("tool_length") + ": not a length in mm");

  const auto vc = o.find("volcomp");
  const std::string volcomp = vc == o.end() ? "off" : vc->second;
  if (volcomp == "off") op.volcomp = VolComp::kOff;
  else if (volcomp == "error") op.volcomp = VolComp::kError;
  else if (volcomp == "correction") op.volcomp = VolComp::kCorrection;
  else
    throw std::invalid_argument("option volcomp=" + volcomp + ": expected off, error or correction");
  if (op.volcomp == VolComp::kOff) {
    for (const char* k : {"volcomp_units", "volcomp_frame"})
      if (o.count(k)) throw std::invalid_argument(std::string("option ") + k + ": only with volcomp=error|correction");
    for (const auto& [k, v] : o)
      if (k.rfind("grid.", 0) == 0) throw std::invalid_argument("option " + k + ": only with volcomp=error|correction");
    return op;
  }
  const std::string units = need("volcomp_units");
  if (units == "mm,rad") {
    op.lin_scale = 1, op.ang_scale = 1, op.lin_unit = "mm", op.ang_unit = "rad";
  } else if (units == "um,urad") {
    op.lin_scale = 1e3, op.ang_scale = 1e6, op.lin_unit = "um", op.ang_unit = "urad";
  } else {
    throw std::invalid_argument("option volcomp_units=" + units + ": expected mm,rad or um,urad");
  }
  const std::string frame = need("volcomp_frame");
  if (frame != "carriage")
    throw std::invalid_argument("option volcomp_frame=" + frame + ": fivecal writes only 'carriage' tables (" +
                                help.at("volcomp_frame") + ")");
  for (int k : NonSpindle(m)) {
    const char a = m.axis(k).name;
    const std::string key = std::string("grid.") + a;
    const auto it = o.find(key);
    if (it == o.end())
      throw std::invalid_argument("beckhoff export with volcomp needs --set " + key +
                                  "=START:STOP:STEP (the table grid of axis " + std::string(1, a) +
                                  (m.axis(k).rotary() ? ", degrees)" : ", mm)"));
    std::stringstream ss(it->second);
    std::string part;
    std::vector<double> v;
    while (std::getline(ss, part, ':')) v.push_back(Number(key, part));
    if (v.size() != 3 || !(v[2] > 0) || !(v[1] > v[0]))
      throw std::invalid_argument("option " + key + "=" + it->second + ": expected START:STOP:STEP with STOP > START, STEP > 0");
    const double cells = (v[1] - v[0]) / v[2];
    if (std::abs(cells - std::round(cells)) > 1e-6 * std::max(1.0, cells) || std::round(cells) > 2000)
      throw std::invalid_argument("option " + key + "=" + it->second +
                                  ": (STOP - START) / STEP must be a whole number of at most 2000 steps");
    Grid g;
    g.start = v[0];
    g.step = v[2];
    g.n = int(std::round(cells)) + 1;
    op.grids[a] = g;
  }
  return op;
}

// Where each value sits in the vector Values() lists.
struct Layout {
  std::vector<VendorValue> values;
  std::vector<double> fixed_values;      // value of each fixed entry (NaN: not fixed)
  int zero_orientation = -1, zero_position = -1;
  std::vector<int> chain;                // machine axis indices, workpiece to tool (ID 91's chain)
  std::vector<int> channel_of;           // machine axis index -> channel index (-1: spindle)
  std::vector<int> orientation, point;   // per machine axis: first of 3 (point: -1 for linear axes)
  std::vector<int> grid_first, table_first;  // per machine axis: first grid position, first table value
  std::vector<int> grid_n;
  // false: the table entries carry no name, unit or source (Map and
  // MapMotions, which the export runs once per parameter, read positions only)
  bool texts = true;
};

void Add(Layout& L, const std::string& name, const std::string& unit, const std::string& source,
         double fixed = NAN) {
  VendorValue& v = L.values.emplace_back();
  v.name = name;
  v.unit = unit;
  v.source = source;
  v.fixed = !std::isnan(fixed);
  L.fixed_values.push_back(fixed);
}

// A table entry: its texts only when the layout carries them.
void AddTable(Layout& L, const std::string& name, const std::string& unit, const std::string& source,
              double fixed = NAN) {
  if (L.texts) return Add(L, name, unit, source, fixed);
  L.values.emplace_back().fixed = !std::isnan(fixed);
  L.fixed_values.push_back(fixed);
}

Layout MakeLayout(const Machine& m, const Opts& op, bool texts = true) {
  Layout L;
  L.texts = texts;
  const std::string src = std::string(kInfosys) + kSrcChain;
  const std::string& P = op.prefix;
  L.channel_of.assign(m.num_axes(), -1);
  for (size_t i = 0; i < op.axes.size(); ++i) L.channel_of[m.AxisIndex(op.axes[i])] = int(i);
  const std::vector<int>& wp = m.workpiece_chain();
  for (auto it = wp.rbegin(); it != wp.rend(); ++it)
    if (m.axis(*it).name != 'S') L.chain.push_back(*it);
  for (int k : m.tool_chain())
    if (m.axis(k).name != 'S') L.chain.push_back(k);
  const int n = int(L.chain.size());

  if (op.trafo) Add(L, P + "id", "", src + "; P-CHAN-00262", 91);
  Add(L, P + "number_of_axes", "", src + "; P-CHAN-00289", n);
  for (int c = 0; c < n; ++c)
    Add(L, P + "chain[" + std::to_string(c) + "]", "", src + "; P-CHAN-00290", L.channel_of[L.chain[c]]);
  L.zero_orientation = int(L.values.size());
  for (int j = 0; j < 3; ++j)
    Add(L, P + "zero_orientation[" + std::to_string(j) + "]", "", src + "; P-CHAN-00285, 'Description of flange and tool' (556386059)");
  L.zero_position = int(L.values.size());
  for (int j = 0; j < 3; ++j)
    Add(L, P + "zero_position[" + std::to_string(j) + "]", "0.0001mm", src + "; P-CHAN-00286, 'Description of flange and tool' (556386059)");
  L.orientation.assign(m.num_axes(), -1);
  L.point.assign(m.num_axes(), -1);
  for (size_t i = 0; i < op.axes.size(); ++i) {
    const int k = m.AxisIndex(op.axes[i]);
    const std::string A = P + "axis[" + std::to_string(i) + "].";
    Add(L, A + "type", "", src + "; P-CHAN-00291 (1 translator, 2 rotator)", m.axis(k).rotary() ? 2 : 1);
    L.orientation[k] = int(L.values.size());
    for (int j = 0; j < 3; ++j)
      Add(L, A + "orientation[" + std::to_string(j) + "]", "",
          src + "; P-CHAN-00292; workpiece-side axes multiplied by -1 (278732555)");
    if (m.axis(k).rotary()) {
      L.point[k] = int(L.values.size());
      for (int j = 0; j < 3; ++j) Add(L, A + "point[" + std::to_string(j) + "]", "0.0001mm", src + "; P-CHAN-00293");
    }
  }
  L.grid_first.assign(m.num_axes(), -1);
  L.table_first.assign(m.num_axes(), -1);
  L.grid_n.assign(m.num_axes(), 0);
  if (op.volcomp == VolComp::kOff) return L;
  // A fine grid lists thousands of values, and the export builds the layout
  // once per parameter: the texts are made once per table, not per value.
  size_t total = L.values.size();
  for (char a : op.axes) total += 7 * size_t(op.grids.at(a).n);
  L.values.reserve(total);
  L.fixed_values.reserve(total);
  const std::string tsrc = std::string(kInfosys) + kSrcTables;
  const std::string arg_src = tsrc + " (the table's argument)";
  const std::string value_src =
      tsrc + (op.volcomp == VolComp::kError ? "; the error motion (ISO 230-1 sign), negate not set"
                                            : "; the correction (minus the error motion)");
  for (char a : op.axes) {
    const int k = m.AxisIndex(a);
    const Grid& g = op.grids.at(a);
    const std::string arg(1, a);
    L.grid_n[k] = g.n;
    L.grid_first[k] = int(L.values.size());
    for (int i = 0; i < g.n; ++i)
      AddTable(L, L.texts ? arg + "[" + std::to_string(i) + "]" : "", m.axis(k).rotary() ? "deg" : "mm", arg_src,
               g.at(i));
    L.table_first[k] = int(L.values.size());
    for (int c = 0; c < 6; ++c)
      for (int i = 0; i < g.n; ++i) {
        AddTable(L, L.texts ? std::string("E") + kComponentLetters[c] + arg + "[" + std::to_string(i) + "]" : "",
                 c < 3 ? op.lin_unit : op.ang_unit, value_src);
        L.values.back().motion = true;
      }
  }
  return L;
}

Eigen::Matrix3d Rodrigues(const Eigen::Vector3d& u, double q) {
  Eigen::Matrix3d K;
  K << 0, -u.z(), u.y(), u.z(), 0, -u.x(), -u.y(), u.x(), 0;
  return Eigen::Matrix3d::Identity() + std::sin(q) * K + (1 - std::cos(q)) * K * K;
}

Eigen::Vector3d Unit(const Eigen::Vector3d& v, const std::string& what) {
  return UnitDirection(v, what);
}

Eigen::Vector3d Vec(const Eigen::VectorXd& values, int first) { return values.segment<3>(first); }

void CheckValues(const Machine& m, const Layout& L, const Eigen::VectorXd& values) {
  if (values.size() != Eigen::Index(L.values.size()))
    throw std::invalid_argument("values: " + std::to_string(values.size()) + " given, beckhoff lists " +
                                std::to_string(L.values.size()) + " for machine '" + m.name() + "' with these options");
  for (size_t i = 0; i < L.values.size(); ++i) {
    RequireFinite(values[Eigen::Index(i)], L.values[i].name);
    if (L.values[i].fixed && std::abs(values[Eigen::Index(i)] - L.fixed_values[i]) > 1e-9 * std::max(1.0, std::abs(L.fixed_values[i])))
      throw std::invalid_argument(L.values[i].name + " = " + std::to_string(values[Eigen::Index(i)]) + ": machine '" +
                                  m.name() + "' (" + m.topology() + ") with these options has " +
                                  std::to_string(L.fixed_values[i]) + " there (another machine or another axis order?)");
  }
}

}  // namespace

std::map<std::string, std::string> BeckhoffVendor::OptionHelp() const {
  return {
      {"syntax", "the channel parameter list syntax: 'kinematik' (kinematik[91].*, CNC builds V2.11.20xx/28xx) "
                 "or 'trafo[j]' (trafo[j].* with trafo[j].id 91, builds from V3.00)"},
      {"axes", "the NC axes in the order of the channel's axis indices, e.g. XYZCA: axis[i] is the i-th letter"},
      {"tool_length", "mm: the tool length the controller's tool table holds for the tool (probe) whose tip fivecal "
                      "identified; zero_position is that tip plus this length along zero_orientation"},
      {"volcomp", "off (default: no TF5280 tables, error motions are left), error (tables hold the error motion, "
                  "ISO 230-1 sign, with 'negate' not configured) or correction (tables hold its negative); with "
                  "tables, also grid.<axis>=START:STOP:STEP for every NC axis (mm, degrees): the table's grid"},
      {"volcomp_units", "with volcomp: units of the table values, mm,rad or um,urad (TF5280's pages do not state them)"},
      {"volcomp_frame", "with volcomp: 'carriage' states that the controller's TF5280 model applies each axis's "
                        "error motion to that axis's own carriage (for a table axis: the table), in the carriage's "
                        "frame after its motion, angular errors about the axis point (rotary) or the origin (linear), "
                        "as fivecal's model does; TF5280's composition rule is not public"},
  };
}

VendorModel BeckhoffVendor::Model(const Machine& m, const VendorOptions& o) const {
  Parse(m, o, OptionHelp());
  int linear = 0, wp = 0, tool = 0;
  std::string letters;
  for (int k : NonSpindle(m)) {
    const Axis& a = m.axis(k);
    letters += a.name;
    if (!a.rotary()) ++linear;
    else if (m.on_tool_side(k)) ++tool;
    else ++wp;
  }
  if (linear != 3 || wp + tool != 2)
    throw std::invalid_argument("beckhoff: machine '" + m.name() + "' (" + m.topology() + ", NC axes " + letters +
                                ") is not supported: the export covers five-axis machines with the linear axes "
                                "X, Y, Z and two rotary axes (TF5280 needs exactly X, Y, Z; fivecal's absorption "
                                "models need two rotary axes)");
  VendorModel vm;
  vm.model = wp == 2 ? ControllerModel::kTableTable : tool == 2 ? ControllerModel::kHeadHead : ControllerModel::kTableHead;
  vm.directions = true;  // ID 91 stores every axis's orientation
  vm.tool_length = true;
  return vm;
}

std::vector<VendorValue> BeckhoffVendor::Values(const Machine& m, const VendorOptions& o) const {
  Model(m, o);
  return MakeLayout(m, Parse(m, o, OptionHelp())).values;
}

Eigen::VectorXd BeckhoffVendor::Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const {
  Model(m, o);
  const Opts op = Parse(m, o, OptionHelp());
  const Layout L = MakeLayout(m, op, false);
  Eigen::VectorXd v = Eigen::VectorXd::Zero(Eigen::Index(L.values.size()));
  for (size_t i = 0; i < L.values.size(); ++i)
    if (L.values[i].fixed) v[Eigen::Index(i)] = L.fixed_values[i];
  // ID 91 describes everything in one coordinate system at the zero
  // position: the machine frame of the table (vendor.h: the controller's
  // workpiece frame; the part frame's offset is the work offset's).
  const Eigen::Vector3d n = table.tool_axis;
  const Eigen::Vector3d tip = table.tool_tip;
  v.segment<3>(L.zero_orientation) = n;
  v.segment<3>(L.zero_position) = (tip + op.tool_length * n) * kUnit01um;
  for (const TableAxis& r : table.axes) {
    const int k = m.AxisIndex(r.axis);
    if (k < 0 || L.orientation[k] < 0)
      throw std::invalid_argument(std::string("table: axis ") + r.axis + " is not an NC axis of machine '" + m.name() + "'");
    if (r.tool_chain != m.on_tool_side(k))
      throw std::invalid_argument(std::string("table: axis ") + r.axis + " is on the other side of machine '" + m.name() + "'");
    // The chain walks from the workpiece: a table axis's vector is the
    // opposite of its carriage's motion (278732555: "multiplied by -1").
    const double sign = r.tool_chain ? 1.0 : -1.0;
    v.segment<3>(L.orientation[k]) = sign * r.direction;
    if (L.point[k] >= 0) v.segment<3>(L.point[k]) = r.point * kUnit01um;
  }
  return v;
}

Eigen::VectorXd BeckhoffVendor::MapMotions(const Machine& m, const Eigen::VectorXd& theta, const VendorOptions& o) const {
  Model(m, o);
  const Opts op = Parse(m, o, OptionHelp());
  const Layout L = MakeLayout(m, op, false);
  if (theta.size() != m.num_parameters())
    throw std::invalid_argument("theta: " + std::to_string(theta.size()) + " values, machine has " +
                                std::to_string(m.num_parameters()) + " parameters");
  Eigen::VectorXd v = Eigen::VectorXd::Zero(Eigen::Index(L.values.size()));
  if (op.volcomp == VolComp::kOff) return v;
  const double sign = op.volcomp == VolComp::kError ? 1.0 : -1.0;
  for (char a : op.axes) {
    const int k = m.AxisIndex(a);
    const Grid& g = op.grids.at(a);
    // TF5280 ('carriage' frame): angular errors of a linear axis act about
    // the origin, fivecal's about the axis point p_k; a rotary axis's about
    // its pivot in both. Moving the rotation to the origin adds (I - R) p_k.
    const Eigen::Vector3d p = m.axis(k).rotary() ? Eigen::Vector3d::Zero() : m.axis(k).point;
    for (int i = 0; i < g.n; ++i) {
      const double q = m.axis(k).rotary() ? g.at(i) * kDeg : g.at(i);
      double e[6];
      ErrorMotions(m, k, theta.data(), q, e);
      const Eigen::Vector3d t = Eigen::Vector3d(e[0], e[1], e[2]) + (p - RotZYX(e[3], e[4], e[5]) * p);
      for (int c = 0; c < 6; ++c) {
        const double val = c < 3 ? t[c] * op.lin_scale : e[c] * op.ang_scale;
        v[L.table_first[k] + c * g.n + i] = sign * val;
      }
    }
  }
  return v;
}

KinematicsTable BeckhoffVendor::Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const {
  Model(m, o);
  const Opts op = Parse(m, o, OptionHelp());
  const Layout L = MakeLayout(m, op);
  CheckValues(m, L, values);
  KinematicsTable t;
  t.tool_axis = Unit(Vec(values, L.zero_orientation), L.values[L.zero_orientation].name);
  t.tool_tip = Vec(values, L.zero_position) / kUnit01um - op.tool_length * t.tool_axis;
  for (const std::vector<int>* chain : {&m.workpiece_chain(), &m.tool_chain()})
    for (int k : *chain) {
      if (m.axis(k).name == 'S') continue;
      TableAxis r;
      r.axis = m.axis(k).name;
      r.tool_chain = m.on_tool_side(k);
      r.rotary = m.axis(k).rotary();
      r.direction = (r.tool_chain ? 1.0 : -1.0) * Unit(Vec(values, L.orientation[k]), L.values[L.orientation[k]].name);
      if (L.point[k] >= 0) r.point = Vec(values, L.point[k]) / kUnit01um;
      t.axes.push_back(r);
    }
  return t;
}

Eigen::MatrixXd BeckhoffVendor::ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                                     const VendorOptions& o) const {
  Model(m, o);
  const Opts op = Parse(m, o, OptionHelp());
  const Layout L = MakeLayout(m, op);
  CheckValues(m, L, values);
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("axes: " + std::to_string(q.cols()) + " columns, machine '" + m.name() + "' has " +
                                std::to_string(m.num_axes()) + " axes");

  // ID 91 as the values state it (P-CHAN-00289..00293), read from the values
  // alone: chain[c] is a channel index, axis[i] its type, orientation, point.
  const int first_chain = op.trafo ? 2 : 1;
  const int n = int(std::lround(values[first_chain - 1]));
  struct Link {
    int channel, machine_axis;
    bool rotary;
    Eigen::Vector3d u, p;
  };
  std::vector<Link> chain;
  for (int c = 0; c < n; ++c) {
    Link l;
    l.channel = int(std::lround(values[first_chain + c]));
    l.machine_axis = m.AxisIndex(op.axes.at(size_t(l.channel)));
    const int ori = L.orientation[l.machine_axis];
    l.rotary = std::lround(values[ori - 1]) == 2;  // axis[i].type precedes its orientation
    l.u = Unit(Vec(values, ori), L.values[size_t(ori)].name);
    l.p = l.rotary ? Eigen::Vector3d(Vec(values, L.point[l.machine_axis]) / kUnit01um) : Eigen::Vector3d::Zero();
    chain.push_back(l);
  }
  const Eigen::Vector3d n0 = Unit(Vec(values, L.zero_orientation), L.values[L.zero_orientation].name);
  // 556386059: TCP = zero_position - tool length * zero_orientation.
  const Eigen::Vector3d tcp0 = Vec(values, L.zero_position) / kUnit01um - op.tool_length * n0;

  // TF5280 tables (volcomp on): linear interpolation on each axis's grid
  // (P-VOLC-00014 GRID). The error motion of axis k is the rigid motion
  // G_k: x -> R x + t, R = Rz(EC) Ry(EB) Rx(EA), about the axis point
  // (rotary) or the origin (linear), acting on the axis's carriage after its
  // motion ('carriage' frame); which axes carry the workpiece is TF5280's
  // workpiece_axes, here the machine's topology.
  const double vsign = op.volcomp == VolComp::kCorrection ? -1.0 : 1.0;
  const auto error_motion = [&](const Link& l, double qk, Eigen::Index row, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
    const int k = l.machine_axis, nk = L.grid_n[k];
    const double g0 = values[L.grid_first[k]], g1 = values[L.grid_first[k] + nk - 1];
    const double tol = 1e-9 * std::max(1.0, std::abs(g1 - g0));
    if (qk < g0 - tol || qk > g1 + tol)
      throw std::invalid_argument("axes[" + std::to_string(row) + "]." + std::string(1, m.axis(k).name) + " = " +
                                  std::to_string(qk) + ": outside the volumetric table's grid [" + std::to_string(g0) +
                                  ", " + std::to_string(g1) + "]");
    const double step = (g1 - g0) / (nk - 1);
    const int i = std::min(nk - 2, std::max(0, int(std::floor((qk - g0) / step))));
    const double w = (qk - (g0 + step * i)) / step;
    double e[6];
    for (int c = 0; c < 6; ++c) {
      const Eigen::Index a = L.table_first[k] + c * nk + i;
      e[c] = vsign * ((1 - w) * values[a] + w * values[a + 1]) / (c < 3 ? op.lin_scale : op.ang_scale);
    }
    *R = RotZYX(e[3], e[4], e[5]);
    *t = Eigen::Vector3d(e[0], e[1], e[2]) + l.p - *R * l.p;
  };

  Eigen::MatrixXd out(q.rows(), 3);
  for (Eigen::Index row = 0; row < q.rows(); ++row) {
    // The product of the chain's motions from the workpiece (chain[0]) to the
    // tool applied to the tool centre point: the innermost link first.
    Eigen::Vector3d x = tcp0;
    for (int c = n - 1; c >= 0; --c) {
      const Link& l = chain[size_t(c)];
      const int k = l.machine_axis;
      const double v = q(row, k);
      RequireFinite(v, "axes[" + std::to_string(row) + "]." + std::string(1, m.axis(k).name));
      const auto screw = [&](const Eigen::Vector3d& y) -> Eigen::Vector3d {
        if (!l.rotary) return y + v * l.u;
        return l.p + Rodrigues(l.u, v * kDeg) * (y - l.p);
      };
      if (op.volcomp == VolComp::kOff) {
        x = screw(x);
        continue;
      }
      Eigen::Matrix3d R;
      Eigen::Vector3d t;
      error_motion(l, v, row, &R, &t);
      // Tool side: the carriage moves (screw), its error motion rides on it.
      // Workpiece side: the chain runs against the carriage, so its error
      // motion is undone after the (reversed) screw.
      if (m.on_tool_side(k)) x = screw(R * x + t);
      else x = R.transpose() * (screw(x) - t);
    }
    out.row(row) = x.transpose();
  }
  return out;
}

Eigen::VectorXd WithoutErrorMotions(const Machine& m, const Eigen::VectorXd& theta) {
  Eigen::VectorXd out = theta;
  for (int i = 0; i < m.num_parameters(); ++i)
    if (m.parameters()[size_t(i)].kind == ParameterKind::kMotion) out[i] = 0;
  return out;
}

}  // namespace controllers
}  // namespace fivecal
