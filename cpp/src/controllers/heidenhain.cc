#include "fivecal/controllers/heidenhain.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

namespace fivecal {
namespace controllers {

namespace {

constexpr double kDeg = M_PI / 180.0;
const char* const kTableManual =
    "HEIDENHAIN Technical Manual iTNC 530 HSCI, July 2013, format of the description table "
    "(KEY, AXIS, COORD), p. 722 (example p. 670)";

int LetterIndex(char a) {  // X/A -> 0, Y/B -> 1, Z/C -> 2
  switch (a) {
    case 'X': case 'A': return 0;
    case 'Y': case 'B': return 1;
    case 'Z': case 'C': return 2;
    default: return -1;
  }
}
char RotaryLetter(int i) { return "ABC"[i]; }
char LinearLetter(int i) { return "XYZ"[i]; }

Eigen::Matrix3d Rot(int i, double rad) {
  return Eigen::AngleAxisd(rad, Eigen::Vector3d::Unit(i)).toRotationMatrix();
}

// The conventions the user states; see OptionHelp.
struct Options {
  double tool_length = 0;
  int table_sense = 0;  // +1 iso, -1 carriage, 0 not stated (the machine has no table-side axis)
};

Options ParseOptions(const Machine& m, const VendorOptions& o) {
  for (const auto& [k, v] : o)
    if (k != "table-axis-sign" && k != "tool-length")
      throw std::invalid_argument("heidenhain: unknown option \"" + k +
                                  "\" (known: table-axis-sign, tool-length)");
  Options out;
  const auto tl = o.find("tool-length");
  if (tl == o.end())
    throw std::invalid_argument(
        "heidenhain: the kinematics table starts at the tool reference point, which the machine file "
        "does not place: state the tool length L (the tool table's L of the tool whose tip the machine "
        "file gives, e.g. the probe) with --set tool-length=<mm>");
  try {
    size_t used = 0;
    out.tool_length = std::stod(tl->second, &used);
    if (used != tl->second.size()) throw std::invalid_argument("trailing text");
  } catch (const std::exception&) {
    throw std::invalid_argument("heidenhain: option tool-length: expected a length in mm, got \"" +
                                tl->second + "\"");
  }
  if (!std::isfinite(out.tool_length) || out.tool_length < 0)
    throw std::invalid_argument("heidenhain: option tool-length: expected a length >= 0 mm, got \"" +
                                tl->second + "\"");
  const auto ts = o.find("table-axis-sign");
  if (ts != o.end()) {
    if (ts->second == "iso") out.table_sense = 1;
    else if (ts->second == "carriage") out.table_sense = -1;
    else
      throw std::invalid_argument("heidenhain: option table-axis-sign: expected iso or carriage, got \"" +
                                  ts->second + "\"");
  }
  if (!m.workpiece_chain().empty() && out.table_sense == 0)
    throw std::invalid_argument(
        "heidenhain: the manual does not say in which sense a positive value of an axis after MachBase "
        "(a table axis) moves the chain: state it with --set table-axis-sign=iso (ISO 841: a positive "
        "value moves the tool relative to the part, the table itself the other way) or "
        "--set table-axis-sign=carriage (a positive value moves the table carriage positively)");
  return out;
}

// The machine's axes without the spindle, per chain.
std::vector<int> ChainAxes(const Machine& m, bool tool) {
  std::vector<int> out;
  for (int k : tool ? m.tool_chain() : m.workpiece_chain())
    if (m.axis(k).name != 'S') out.push_back(k);
  return out;
}

int ToolAxisIndex(const Machine& m) {
  const Eigen::Vector3d& a = m.tool_axis();
  for (int i = 0; i < 3; ++i)
    if ((a - Eigen::Vector3d::Unit(i)).norm() < 1e-9) return i;
  throw std::invalid_argument("heidenhain: the tool axis (" + std::to_string(a.x()) + ", " +
                              std::to_string(a.y()) + ", " + std::to_string(a.z()) +
                              ") is not +X, +Y or +Z (ToolAxis takes X, Y or Z)");
}

// The sense s of an axis in the chain: the axis direction in fivecal's
// convention (its carriage's motion) is s times the row's own axis.
int Sense(bool tool_side, const Options& opt) { return tool_side ? 1 : -opt.table_sense; }

// Two angles (a about j, then b about k) with Rot_j(a) Rot_k(b) e_i = v,
// (j, k) = (i+1, i+2) cyclic; a is taken nearest to `near` (deg).
void TurnOnto(int i, const Eigen::Vector3d& v_in, double near_deg, double* a_deg, double* b_deg) {
  const int j = (i + 1) % 3, k = (i + 2) % 3;
  const Eigen::Vector3d v = v_in.normalized();
  const double b = std::asin(std::max(-1.0, std::min(1.0, v[j])));
  double a = std::atan2(-v[k], v[i]) / kDeg;
  while (a - near_deg > 180) a -= 360;
  while (a - near_deg < -180) a += 360;
  *a_deg = a;
  *b_deg = b / kDeg;
}

}  // namespace

std::map<std::string, std::string> HeidenhainVendor::OptionHelp() const {
  return {
      {"tool-length",
       "<mm>: the tool table's length L of the tool whose tip the machine file gives (the probe); the "
       "kinematics table starts at the tool reference point, L behind the tip along the tool axis. Required."},
      {"table-axis-sign",
       "iso | carriage: the sense of a MachAxis row after MachBase (a table axis), which the manual does not "
       "state. iso: a positive value moves the tool relative to the part (ISO 841; the table itself turns "
       "the other way); carriage: a positive value moves the table carriage positively. Required when the "
       "machine has table-side axes."},
  };
}

std::vector<HeidenhainRow> HeidenhainVendor::Rows(const Machine& m, const VendorOptions& o) const {
  const Options opt = ParseOptions(m, o);
  Model(m, o);
  const int ti = ToolAxisIndex(m);
  std::vector<HeidenhainRow> rows;
  const auto add = [&](const std::string& key, char axis, bool coord, bool fixed, bool tool_side,
                       const std::string& role) {
    rows.push_back(HeidenhainRow{key, axis, coord, fixed, tool_side, role});
  };
  add("ToolAxis", LinearLetter(ti), false, true, true, "the tool axis");
  add("Trans", RotaryLetter((ti + 2) % 3), true, false, true, "spindle tilt");
  add("Trans", RotaryLetter((ti + 1) % 3), true, false, true, "spindle tilt");
  const auto side = [&](const std::vector<int>& axes, bool tool_side) {
    for (int k : axes) {
      const Axis& ax = m.axis(k);
      const std::string n(1, ax.name);
      const int i = LetterIndex(ax.name);
      const char j = RotaryLetter((i + 1) % 3), kk = RotaryLetter((i + 2) % 3);
      if (ax.rotary()) {
        for (char c : {'X', 'Y', 'Z'}) add("Trans", c, true, false, tool_side, "position of the " + n + " pivot");
        add("Trans", j, true, false, tool_side, "direction of " + n);
        add("Trans", kk, true, false, tool_side, "direction of " + n);
        add("MachAxis", ax.name, false, true, tool_side, "axis " + n);
        add("Trans", kk, true, false, tool_side, "direction of " + n + " undone");
        add("Trans", j, true, false, tool_side, "direction of " + n + " undone");
      } else {
        const Eigen::Vector3d v = Sense(tool_side, opt) * ax.direction;
        const bool reversed = (v + Eigen::Vector3d::Unit(i)).norm() < 1e-9;
        if (!reversed && (v - Eigen::Vector3d::Unit(i)).norm() > 1e-9)
          throw std::invalid_argument("heidenhain: linear axis " + n + " is not along the machine's " + n +
                                      " direction; the table written here does not tilt linear axes");
        if (reversed) add("Trans", j, true, true, tool_side, "axis " + n + " reversed");
        add("MachAxis", ax.name, false, true, tool_side, "axis " + n);
        if (reversed) add("Trans", j, true, true, tool_side, "axis " + n + " reversal undone");
      }
    }
  };
  std::vector<int> tool = ChainAxes(m, true);
  side(std::vector<int>(tool.rbegin(), tool.rend()), true);
  for (char c : {'X', 'Y', 'Z'}) add("Trans", c, true, false, true, "to the machine datum");
  add("MachBase", 0, false, true, false, "the machine base");
  side(ChainAxes(m, false), false);
  for (char c : {'X', 'Y', 'Z'}) add("Trans", c, true, false, false, "back to the machine datum");
  return rows;
}

VendorModel HeidenhainVendor::Model(const Machine& m, const VendorOptions& o) const {
  ParseOptions(m, o);
  int tool_rot = 0, part_rot = 0;
  for (int k : ChainAxes(m, true)) tool_rot += m.axis(k).rotary();
  for (int k : ChainAxes(m, false)) part_rot += m.axis(k).rotary();
  if (tool_rot + part_rot != 2)
    throw std::invalid_argument("heidenhain: the export covers machines with two rotary axes (head-head, "
                                "table-table, table-head); " + m.name() + " (" + m.topology() + ") has " +
                                std::to_string(tool_rot + part_rot));
  for (int k = 0; k < m.num_axes(); ++k)
    if (m.axis(k).name != 'S' && LetterIndex(m.axis(k).name) < 0)
      throw std::invalid_argument(std::string("heidenhain: axis ") + m.axis(k).name +
                                  " has no MachAxis letter (X Y Z A B C)");
  ToolAxisIndex(m);
  VendorModel vm;
  vm.model = part_rot == 2 ? ControllerModel::kTableTable
             : tool_rot == 2 ? ControllerModel::kHeadHead
                             : ControllerModel::kTableHead;
  vm.directions = true;
  vm.tool_length = true;
  return vm;
}

std::vector<VendorValue> HeidenhainVendor::Values(const Machine& m, const VendorOptions& o) const {
  std::vector<VendorValue> out;
  const std::vector<HeidenhainRow> rows = Rows(m, o);
  for (size_t r = 0; r < rows.size(); ++r) {
    const HeidenhainRow& row = rows[r];
    VendorValue v;
    v.name = "row " + std::to_string(r) + " " + row.key + (row.axis ? std::string(" ") + row.axis : "");
    const bool angular = row.axis == 'A' || row.axis == 'B' || row.axis == 'C';
    v.unit = !row.coord ? "" : angular ? "deg" : "mm";
    v.fixed = row.fixed;
    v.source = std::string(kTableManual) + "; " + row.role;
    if (row.role.rfind("position of the", 0) == 0 || row.role.rfind("direction of", 0) == 0)
      v.source += "; Cycle 451 MEASURE KINEMATICS (KinematicsOpt) optimises the rotary axes' rows and saves "
                  "them in the kinematics description (TNC 640 cycle programming 34059x-01, 19.4)";
    out.push_back(v);
  }
  return out;
}

Eigen::VectorXd HeidenhainVendor::Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const {
  const Options opt = ParseOptions(m, o);
  const std::vector<HeidenhainRow> rows = Rows(m, o);
  const std::vector<int> tool = ChainAxes(m, true), part = ChainAxes(m, false);
  if (table.axes.size() != tool.size() + part.size())
    throw std::invalid_argument("heidenhain: the kinematics table has " + std::to_string(table.axes.size()) +
                                " axes, the machine " + std::to_string(tool.size() + part.size()));
  // The nominal table's angles: a turn is taken nearest to them, so that a
  // 180 degree row does not jump by 360 with the sign of a small error.
  const KinematicsTable nom = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
  std::map<char, const TableAxis*> by_name;
  std::map<char, const TableAxis*> nom_by_name;
  for (size_t r = 0; r < table.axes.size(); ++r) {
    const TableAxis& ta = table.axes[r];
    const std::vector<int>& chain = r < part.size() ? part : tool;
    const int k = chain[r < part.size() ? r : r - part.size()];
    if (ta.axis != m.axis(k).name || ta.tool_chain != (r >= part.size()))
      throw std::invalid_argument(std::string("heidenhain: kinematics table row ") + std::to_string(r) +
                                  " is axis " + ta.axis + ", the machine has " + m.axis(k).name + " there");
    for (int c = 0; c < 3; ++c) {
      RequireFinite(ta.direction[c], std::string("table.") + ta.axis + ".direction");
      RequireFinite(ta.point[c], std::string("table.") + ta.axis + ".point");
    }
    by_name[ta.axis] = &ta;
    nom_by_name[ta.axis] = &nom.axes[r];
  }
  Eigen::VectorXd v = Eigen::VectorXd::Zero(Eigen::Index(rows.size()));
  size_t r = 0;
  const auto put = [&](double x) { v[Eigen::Index(r++)] = x; };
  const int ti = ToolAxisIndex(m);
  // The spindle: Rot_j(a) Rot_k(b) e_i = tool axis; the rows undo it
  // (Trans k -b, Trans j -a) so that the next frame is machine-parallel.
  {
    double a, b, na, nb;
    TurnOnto(ti, nom.tool_axis, 0, &na, &nb);
    TurnOnto(ti, table.tool_axis, na, &a, &b);
    put(0);  // ToolAxis
    put(-b);
    put(-a);
  }
  Eigen::Vector3d origin = table.tool_tip + opt.tool_length * table.tool_axis.normalized();
  const auto side = [&](const std::vector<int>& axes, bool tool_side) {
    for (int k : axes) {
      const Axis& ax = m.axis(k);
      const TableAxis& ta = *by_name.at(ax.name);
      const int i = LetterIndex(ax.name);
      const double s = Sense(tool_side, opt);
      if (ax.rotary()) {
        const Eigen::Vector3d d = ta.point - origin;
        put(d.x());
        put(d.y());
        put(d.z());
        origin = ta.point;
        double a, b, na, nb;
        TurnOnto(i, s * nom_by_name.at(ax.name)->direction, 0, &na, &nb);
        TurnOnto(i, s * ta.direction, na, &a, &b);
        put(a);
        put(b);
        put(0);  // MachAxis
        put(-b);
        put(-a);
      } else {
        const Eigen::Vector3d dv = s * ta.direction.normalized();
        const bool reversed = (dv + Eigen::Vector3d::Unit(i)).norm() < 1e-6;
        if (!reversed && (dv - Eigen::Vector3d::Unit(i)).norm() > 1e-6)
          throw std::invalid_argument(std::string("heidenhain: linear axis ") + ax.name +
                                      " is tilted in the kinematics table; the rows written here do not tilt "
                                      "linear axes");
        if (reversed) put(180);
        put(0);
        if (reversed) put(-180);
      }
    }
  };
  side(std::vector<int>(tool.rbegin(), tool.rend()), true);
  put(-origin.x());
  put(-origin.y());
  put(-origin.z());
  origin.setZero();
  put(0);  // MachBase
  side(part, false);
  // The workpiece frame the controller knows: the machine frame at the zero
  // pose, carried by the table axes (the part frame is the preset).
  put(-origin.x());
  put(-origin.y());
  put(-origin.z());
  if (r != rows.size()) throw std::logic_error("heidenhain: row count");
  return v;
}

namespace {

// The kinematics description as the manual defines it: the rows applied in
// order from the tool reference point, each a transformation of the current
// coordinate system (Trans X|Y|Z: translation by COORD along the current
// axis; Trans A|B|C: rotation by COORD degrees, right hand, about the current
// x|y|z; MachAxis: the axis's motion; ToolAxis, MachBase: no transformation).
// `motion(row)` gives the axis value for a MachAxis row. Returns the pose of
// the frame after each row (in the tool reference frame) and fills `base`
// with the pose at MachBase.
struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Pose operator*(const Pose& o) const { return Pose{R * o.R, R * o.t + t}; }
  Pose inverse() const { return Pose{R.transpose(), -(R.transpose() * t)}; }
};

template <class Motion>
std::vector<Pose> WalkRows(const std::vector<HeidenhainRow>& rows, const Eigen::VectorXd& values, Motion motion,
                           int table_sense, Pose* base) {
  std::vector<Pose> after;
  Pose T;
  bool past_base = false;
  for (size_t r = 0; r < rows.size(); ++r) {
    const HeidenhainRow& row = rows[r];
    const double x = values[Eigen::Index(r)];
    Pose M;
    const int i = LetterIndex(row.axis);
    const bool angular = row.axis == 'A' || row.axis == 'B' || row.axis == 'C';
    if (row.key == "Trans") {
      if (angular) M.R = Rot(i, x * kDeg);
      else M.t = x * Eigen::Vector3d::Unit(i);
    } else if (row.key == "MachAxis") {
      // A positive value moves what comes before the row (towards the tool)
      // relative to what follows: the frame that follows moves by -value.
      // After MachBase with table-axis-sign=carriage, the other way round.
      const double sigma = past_base ? table_sense : 1;
      const double qv = motion(r, row.axis);
      if (angular) M.R = Rot(i, -sigma * qv * kDeg);
      else M.t = -sigma * qv * Eigen::Vector3d::Unit(i);
    } else if (row.key == "MachBase") {
      past_base = true;
      *base = T;
    }
    T = T * M;
    after.push_back(T);
  }
  return after;
}

}  // namespace

KinematicsTable HeidenhainVendor::Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const {
  const Options opt = ParseOptions(m, o);
  const std::vector<HeidenhainRow> rows = Rows(m, o);
  if (values.size() != Eigen::Index(rows.size()))
    throw std::invalid_argument("heidenhain: " + std::to_string(values.size()) + " values, the table has " +
                                std::to_string(rows.size()) + " rows");
  for (Eigen::Index r = 0; r < values.size(); ++r) RequireFinite(values[r], "heidenhain row " + std::to_string(r));
  Pose base;
  const std::vector<Pose> after =
      WalkRows(rows, values, [](size_t, char) { return 0.0; }, opt.table_sense == 0 ? 1 : opt.table_sense, &base);
  // World (machine frame at the zero pose) = the frame at MachBase.
  const Pose world = base.inverse();
  const int ti = ToolAxisIndex(m);
  KinematicsTable t;
  std::map<char, TableAxis> found;
  const std::vector<int> tool = ChainAxes(m, true), part = ChainAxes(m, false);
  // A MachAxis row acts in the frame its preceding rows set up.
  for (size_t r = 0; r < rows.size(); ++r) {
    if (rows[r].key != "MachAxis") continue;
    const Pose W = world * (r == 0 ? Pose() : after[r - 1]);
    const int k = m.AxisIndex(rows[r].axis);
    const Axis& ax = m.axis(k);
    TableAxis ta;
    ta.axis = ax.name;
    ta.tool_chain = rows[r].tool_side;
    ta.rotary = ax.rotary();
    const double s = Sense(rows[r].tool_side, opt);
    ta.direction = s * W.R.col(LetterIndex(ax.name));
    if (ax.rotary()) ta.point = W.t + (ax.point - W.t).dot(ta.direction) * ta.direction;
    found[ax.name] = ta;
  }
  for (int k : part) t.axes.push_back(found.at(m.axis(k).name));
  for (int k : tool) t.axes.push_back(found.at(m.axis(k).name));
  const Pose tool_frame = world;  // the tool reference frame, seen from the machine frame
  t.tool_axis = tool_frame.R.col(ti);
  t.tool_tip = tool_frame.t - opt.tool_length * t.tool_axis;
  // The rows end in the controller's workpiece frame (the machine frame at
  // the zero pose); where the part sits on the table is the preset, not a row.
  t.part_origin.setZero();
  t.part_rotation.setIdentity();
  return t;
}

Eigen::MatrixXd HeidenhainVendor::ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                                       const VendorOptions& o) const {
  const Options opt = ParseOptions(m, o);
  const std::vector<HeidenhainRow> rows = Rows(m, o);
  if (values.size() != Eigen::Index(rows.size()))
    throw std::invalid_argument("heidenhain: " + std::to_string(values.size()) + " values, the table has " +
                                std::to_string(rows.size()) + " rows");
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("heidenhain: axes: " + std::to_string(q.cols()) + " columns, the machine has " +
                                std::to_string(m.num_axes()) + " axes");
  for (Eigen::Index r = 0; r < values.size(); ++r) RequireFinite(values[r], "heidenhain row " + std::to_string(r));
  const char ta = LinearLetter(ToolAxisIndex(m));
  Eigen::MatrixXd out(q.rows(), 3);
  std::map<char, double> qa;
  for (Eigen::Index n = 0; n < q.rows(); ++n) {
    for (Eigen::Index k = 0; k < q.cols(); ++k) {
      RequireFinite(q(n, k), "axes[" + std::to_string(n) + "]." + std::string(1, m.axis(int(k)).name));
      qa[m.axis(int(k)).name] = q(n, k);
    }
    out.row(n) = HeidenhainToolPoint(rows, values, qa, opt.tool_length, ta,
                                     opt.table_sense == 0 ? 1 : opt.table_sense).transpose();
  }
  return out;
}

Eigen::Vector3d HeidenhainToolPoint(const std::vector<HeidenhainRow>& rows, const Eigen::VectorXd& coord,
                                    const std::map<char, double>& q, double tool_length, char tool_axis,
                                    int table_sense) {
  if (coord.size() != Eigen::Index(rows.size()))
    throw std::invalid_argument("heidenhain: " + std::to_string(coord.size()) + " values for " +
                                std::to_string(rows.size()) + " rows");
  const int ti = LetterIndex(tool_axis);
  if (ti < 0 || tool_axis > 'Z' || tool_axis < 'X')
    throw std::invalid_argument(std::string("heidenhain: ToolAxis ") + tool_axis + ": expected X, Y or Z");
  Pose base;
  const std::vector<Pose> after = WalkRows(
      rows, coord,
      [&](size_t r, char a) {
        const auto it = q.find(a);
        if (it == q.end())
          throw std::invalid_argument("heidenhain: row " + std::to_string(r) + " MachAxis " + std::string(1, a) +
                                      ": no value for axis " + std::string(1, a));
        return it->second;
      },
      table_sense, &base);
  // The tool tip in the tool reference frame: L along -ToolAxis; the tool
  // point in the last frame (the workpiece frame): T^-1 tip.
  const Eigen::Vector3d tip = -tool_length * Eigen::Vector3d::Unit(ti);
  const Pose inv = after.back().inverse();
  return inv.R * tip + inv.t;
}

}  // namespace controllers
}  // namespace fivecal
