#include "fivecal/controllers/fanuc.h"

#include <Eigen/Dense>
#include <cctype>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace controllers {

namespace {

// A-79348E: "FANUC Series 30i-MODEL A, Tool center point control for 5-axis
// machining, Additional manual" (Jan. 16, 2004), sheet numbers n/88.
const char* const kManual = "FANUC A-79348E";

std::string Src(const std::string& what, const std::string& where) {
  return what + "; " + kManual + ", " + where;
}

enum Type { kToolRotation = 2, kTableRotation = 12, kMixed = 21 };

// What the options and the machine's topology fix, validated once.
struct Setup {
  Type type = kTableRotation;
  int first = -1, second = -1;  // machine axis indices: master (for 21 the tool's), slave
  Eigen::Vector3d k = Eigen::Vector3d::UnitZ();  // tool axis, from the tip into the spindle
  double tool_length = 0;       // tip of the measuring tool -> controlled point / point D
  double holder_offset = 0;     // No. 19666 as the controller has it (types 2, 21)
  int number_first = 0, number_second = 0;  // controlled-axis numbers in the path
};

const std::set<std::string>& Keys() {
  static const std::set<std::string> keys = {"increment", "tool-length", "holder-offset", "axis-order", "path"};
  return keys;
}

std::string AxisName(const Machine& m, int i) { return std::string(1, m.axis(i).name); }

std::string Vec(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s.precision(9);
  s << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return s.str();
}

// The basic axis (0 X, 1 Y, 2 Z) a direction lies along, or -1.
int BasicAxis(const Eigen::Vector3d& d, double tol, double* deviation = nullptr) {
  const Eigen::Vector3d u = d.normalized();
  Eigen::Index i = 0;
  u.cwiseAbs().maxCoeff(&i);
  const double dev = std::acos(std::min(1.0, std::abs(u[i])));
  if (deviation) *deviation = dev;
  return dev <= tol ? int(i) : -1;
}

double Number(const VendorOptions& o, const std::string& key, const std::string& what) {
  const auto it = o.find(key);
  if (it == o.end())
    throw std::invalid_argument("fanuc: option " + key + " is required (--set " + key + "=<mm>): " + what);
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(it->second, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != it->second.size() || !std::isfinite(v))
    throw std::invalid_argument("fanuc: option " + key + "=" + it->second + ": expected a number in mm");
  return v;
}

Setup Parse(const Machine& m, const VendorOptions& o) {
  for (const auto& [key, value] : o)
    if (!Keys().count(key)) {
      std::string known;
      for (const std::string& k : Keys()) known += (known.empty() ? "" : ", ") + k;
      throw std::invalid_argument("fanuc: unknown option '" + key + "' (the options are " + known + ")");
    }
  Setup s;
  std::vector<int> table, tool;
  for (int k : m.workpiece_chain())
    if (m.axis(k).rotary()) table.push_back(k);
  for (int k : m.tool_chain())
    if (m.axis(k).rotary() && m.axis(k).name != 'S') tool.push_back(k);
  const std::string machine = "machine '" + m.name() + "' (" + m.topology() + ")";
  if (table.size() + tool.size() != 2)
    throw std::invalid_argument("fanuc: " + machine + " has " + std::to_string(table.size() + tool.size()) +
                                " rotary axes; tool centre point control (No. 19680 = 2, 12, 21) takes two");
  if (table.size() == 2) {
    s.type = kTableRotation;
    s.first = table[0];  // the workpiece chain runs from the foundation outward: the carrier first
    s.second = table[1];
  } else if (tool.size() == 2) {
    s.type = kToolRotation;
    s.first = tool[0];
    s.second = tool[1];
  } else {
    s.type = kMixed;
    s.first = tool[0];
    s.second = table[0];
  }
  // Fanuc's chains put the rotary axes between the linear axes and the tool
  // or the table: a linear axis carried by a rotary axis is not in them.
  for (const std::vector<int>* chain : {&m.workpiece_chain(), &m.tool_chain()}) {
    bool rotary_seen = false;
    for (int k : *chain) {
      if (m.axis(k).name == 'S') continue;
      if (m.axis(k).rotary()) rotary_seen = true;
      else if (rotary_seen)
        throw std::invalid_argument("fanuc: " + machine + ": linear axis " + AxisName(m, k) +
                                    " is carried by a rotary axis; Fanuc's tool centre point model has the "
                                    "rotary axes between the linear axes and the tool or table");
    }
  }
  for (int k = 0; k < m.num_axes(); ++k) {
    if (m.axis(k).name == 'S') continue;
    double dev = 0;
    if (BasicAxis(m.axis(k).direction, 1e-12, &dev) < 0)
      throw std::invalid_argument(
          "fanuc: " + machine + ": axis " + AxisName(m, k) + " direction " + Vec(m.axis(k).direction) +
          " is not along X, Y or Z; an inclined rotary axis (the 'inclination angle' Nos. 19683/19688) is not "
          "covered: its definition is not in the public pages this export rests on");
  }
  if (BasicAxis(m.tool_axis(), 1e-12) < 0)
    throw std::invalid_argument("fanuc: " + machine + ": tool axis " + Vec(m.tool_axis()) +
                                " is not along X, Y or Z");
  s.k = m.tool_axis().normalized();

  const auto inc = o.find("increment");
  if (inc == o.end())
    throw std::invalid_argument(
        "fanuc: option increment is required (--set increment=IS-B or IS-C): the machine's increment system "
        "sets the least input increment of the offsets (IS-B 0.001 mm, IS-C 0.0001 mm)");
  if (inc->second != "IS-B" && inc->second != "IS-C")
    throw std::invalid_argument("fanuc: option increment=" + inc->second + ": expected IS-B or IS-C (mm machines)");
  s.tool_length = Number(o, "tool-length",
                         "the length the controller added to the tip of the tool or probe the measurement "
                         "used to reach its controlled point (that tool's length offset, plus the tool holder "
                         "offset No. 19666 where the controller adds it)");
  if (s.type != kTableRotation)
    s.holder_offset = Number(o, "holder-offset", "the controller's current tool holder offset, No. 19666");
  const auto order = o.find("axis-order");
  if (order == o.end())
    throw std::invalid_argument(
        "fanuc: option axis-order is required (--set axis-order=XYZAC): the controlled axes of the path in "
        "their order, which give the controlled-axis numbers Nos. 19681 and 19686");
  std::string ax = order->second;
  for (char& c : ax) c = char(std::toupper(static_cast<unsigned char>(c)));
  for (std::size_t i = 0; i < ax.size(); ++i)
    if (ax.find(ax[i]) != i)
      throw std::invalid_argument("fanuc: option axis-order=" + ax + ": axis " + std::string(1, ax[i]) +
                                  " appears twice");
  for (int k : {s.first, s.second}) {
    const std::size_t at = ax.find(m.axis(k).name);
    if (at == std::string::npos)
      throw std::invalid_argument("fanuc: option axis-order=" + ax + " lacks rotary axis " + AxisName(m, k));
    (k == s.first ? s.number_first : s.number_second) = int(at) + 1;
  }
  if (o.count("path")) {
    const std::string& p = o.at("path");
    if (p.empty() || p.size() > 2 || p.find_first_not_of("0123456789") != std::string::npos || std::stoi(p) < 1)
      throw std::invalid_argument("fanuc: option path=" + p + ": expected a path number 1, 2, ...");
  }
  return s;
}

// Right-handed rotation by angle (rad) about the basic axis `axis`.
Eigen::Matrix3d BasicRotation(int axis, double angle) {
  const double c = std::cos(angle), sn = std::sin(angle);
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  const int a = (axis + 1) % 3, b = (axis + 2) % 3;
  R(a, a) = c;
  R(a, b) = -sn;
  R(b, a) = sn;
  R(b, b) = c;
  return R;
}

constexpr int kCommon = 7;  // 19680, 19681, 19682, 19684, 19686, 19687, 19689

Eigen::Index Size(Type t) { return kCommon + (t == kTableRotation ? 6 : 7); }

int FindRow(const Machine& m, const KinematicsTable& t, int axis) {
  for (std::size_t i = 0; i < t.axes.size(); ++i)
    if (t.axes[i].axis == m.axis(axis).name) return int(i);
  throw std::invalid_argument("fanuc: the kinematics table has no row for axis " + AxisName(m, axis));
}

// The axis direction and rotation direction codes of a table row
// (Nos. 19682/19687: the basic axis, 1 X, 2 Y, 3 Z; Nos. 19684/19689: 0 a
// positive command turns the carriage right-handed about that axis, 1
// left-handed).
void Codes(const Machine& m, int axis, const Eigen::Vector3d& d, double* code, double* turn) {
  double dev = 0;
  const int b = BasicAxis(d, 1e-9, &dev);
  if (b < 0)
    throw std::invalid_argument("fanuc: axis " + AxisName(m, axis) + " direction " + Vec(d) + " is " +
                                std::to_string(dev) +
                                " rad off the basic axes; Nos. 19682/19687 take X, Y or Z only, so a direction "
                                "change cannot be written");
  *code = b + 1;
  *turn = d[b] > 0 ? 0 : 1;
}

struct Decoded {
  int axis1 = 2, axis2 = 2;  // basic axes
  double sign1 = 1, sign2 = 1;
  Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();  // the two offset vectors
  double holder = 0;
};

// Checks `values` against the machine and the options (a file whose codes
// say another machine than the machine file is refused, naming the value).
Decoded Decode(const Machine& m, const Setup& s, const Eigen::VectorXd& v) {
  if (v.size() != Size(s.type))
    throw std::invalid_argument("fanuc: " + std::to_string(v.size()) + " values, the " +
                                std::to_string(int(s.type)) + " type has " + std::to_string(Size(s.type)));
  for (Eigen::Index i = 0; i < v.size(); ++i) RequireFinite(v[i], "fanuc values[" + std::to_string(i) + "]");
  double c1 = 0, t1 = 0, c2 = 0, t2 = 0;
  Codes(m, s.first, m.axis(s.first).direction, &c1, &t1);
  Codes(m, s.second, m.axis(s.second).direction, &c2, &t2);
  const double expect[kCommon] = {double(s.type), double(s.number_first), c1, t1, double(s.number_second), c2, t2};
  const char* names[kCommon] = {"19680", "19681", "19682", "19684", "19686", "19687", "19689"};
  for (int i = 0; i < kCommon; ++i)
    if (v[i] != expect[i]) {
      std::ostringstream msg;
      msg << "fanuc: No. " << names[i] << " = " << v[i] << " in the values, but machine '" << m.name()
          << "' with the options gives " << expect[i]
          << " (the machine file and the controller disagree on the mechanism, an axis or its turning sense)";
      throw std::invalid_argument(msg.str());
    }
  Decoded d;
  d.axis1 = int(c1) - 1;
  d.axis2 = int(c2) - 1;
  d.sign1 = t1 == 0 ? 1 : -1;
  d.sign2 = t2 == 0 ? 1 : -1;
  if (s.type == kTableRotation) {
    d.a = v.segment<3>(kCommon);
    d.b = v.segment<3>(kCommon + 3);
  } else {
    d.holder = v[kCommon];
    // tool-length includes the holder offset the control adds: a file with
    // another No. 19666 than the options state would place point D elsewhere
    if (d.holder != s.holder_offset) {
      std::ostringstream msg;
      msg << "fanuc: No. 19666 = " << d.holder << " in the values, but --set holder-offset=" << s.holder_offset
          << " (state the control's tool holder offset, and a tool-length that includes it)";
      throw std::invalid_argument(msg.str());
    }
    d.a = v.segment<3>(kCommon + 1);
    d.b = v.segment<3>(kCommon + 4);
  }
  return d;
}

}  // namespace

std::map<std::string, std::string> FanucVendor::OptionHelp() const {
  return {
      {"increment",
       "IS-B or IS-C (required): the increment system of the machine (mm); the offsets are written to "
       "0.001 mm (IS-B) or 0.0001 mm (IS-C), the least input increment the manual gives"},
      {"tool-length",
       "mm (required): what the controller added to the tip of the tool or probe the measurement used to reach "
       "its controlled point (that tool's length offset, plus the tool holder offset No. 19666 where the "
       "controller adds it); it places the machine origin (table rotation type) and point D"},
      {"holder-offset", "mm (tool rotation and mixed types, required there): the current No. 19666, written unchanged"},
      {"axis-order",
       "the controlled axes of the path in their order, e.g. XYZAC (required): gives the controlled-axis "
       "numbers Nos. 19681 and 19686"},
      {"path", "the path the parameters belong to (default 1); only written in the file"},
  };
}

VendorModel FanucVendor::Model(const Machine& m, const VendorOptions& o) const {
  const Setup s = Parse(m, o);
  VendorModel vm;
  vm.model = s.type == kTableRotation ? ControllerModel::kTableTable
             : s.type == kToolRotation ? ControllerModel::kHeadHead
                                       : ControllerModel::kTableHead;
  // The axis directions are codes for basic axes (Nos. 19682/19687): a
  // direction change has no place; the pivots and the tool length do.
  vm.directions = false;
  vm.tool_length = true;
  return vm;
}

std::vector<VendorValue> FanucVendor::Values(const Machine& m, const VendorOptions& o) const {
  const Setup s = Parse(m, o);
  const std::string first = s.type == kMixed ? "first rotation axis (the tool's)" : "first rotation axis (master)";
  const std::string second =
      s.type == kMixed ? "second rotation axis (the table's)" : "second rotation axis (slave)";
  std::vector<VendorValue> v = {
      {"19680", "", Src("mechanical unit type: 2 tool rotation, 12 table rotation, 21 mixed", "sheet 72/88"), true},
      {"19681", "",
       Src("controlled-axis number of the " + first, "sheet 78/88 (No. 19696 IA1 names it); axis " +
                                                         AxisName(m, s.first)),
       true},
      {"19682", "",
       Src("axis direction of the " + first + ": 1 X, 2 Y, 3 Z",
           "named on sheets 75 and 78/88; its own sheet and the coding are not in the public copy read: check "
           "the coding against your parameter manual"),
       true},
      {"19684", "",
       Src("rotation direction of the " + first +
               ": 0 right-hand thread about the axis of No. 19682 for a positive command, 1 left-hand",
           "sheet 75/88"),
       true},
      {"19686", "",
       Src("controlled-axis number of the " + second, "sheet 75/88; axis " + AxisName(m, s.second)), true},
      {"19687", "",
       Src("axis direction of the " + second + ": 1 X, 2 Y, 3 Z",
           "Nos. 19687-19690 are the second axis's as 19682-19685 the first's (sheet 78/88); the coding as "
           "No. 19682"),
       true},
      {"19689", "",
       Src("rotation direction of the " + second + ": as No. 19684",
           "Nos. 19687-19690 are the second axis's as 19682-19685 the first's (sheet 78/88)"),
       true},
  };
  const char* xyz[3] = {"X", "Y", "Z"};
  const auto rtp = [&](const std::string& where) {
    for (int i = 0; i < 3; ++i)
      v.push_back({"rotary table position " + std::string(xyz[i]), "mm",
                   Src("rotary table position (" + std::string(xyz[i]) +
                           "): the vector from the machine coordinate origin to a point on the " + where +
                           " in the machine coordinate system, all rotation axes at 0 degrees; its parameter "
                           "number is not in the public pages read (look it up in your parameter manual)",
                       "sheet 59/88, Fig. 1.1 (n), and the figure on sheet 82/88"),
                   false});
  };
  if (s.type == kTableRotation) {
    rtp("first rotation axis of the table (point A)");
    for (int i = 0; i < 3; ++i)
      v.push_back({std::to_string(19703 + i), "mm",
                   Src("intersection offset vector between the first and second rotation axes of the table (" +
                           std::string(xyz[i]) + "): from point A on the first axis to point B on the second",
                       "sheet 82/88"),
                   false});
    return v;
  }
  v.push_back({"19666", "mm",
               Src("tool holder offset: added with the tool length offset to the tool tip to give point D; "
                   "written unchanged",
                   "named on sheet 83/88"),
               true});
  for (int i = 0; i < 3; ++i)
    v.push_back({std::to_string(19709 + i), "mm",
                 Src("intersection offset vector between the tool axis and the tool rotation axis (" +
                         std::string(xyz[i]) + "): from point D on the tool axis to point E on the " +
                         (s.type == kMixed ? "tool rotation axis" : "second rotation axis of the tool"),
                     "sheet 83/88"),
                 false});
  if (s.type == kToolRotation) {
    for (int i = 0; i < 3; ++i)
      v.push_back({std::to_string(19712 + i), "mm",
                   Src("intersection offset vector between the second and first rotation axes of the tool (" +
                           std::string(xyz[i]) + "): from point E on the second axis to point F on the first",
                       "sheet 84/88"),
                   false});
  } else {
    rtp("rotation axis of the table");
  }
  return v;
}

// Points on the controller's chain, in fivecal's frame:
//   table rotation type: the machine origin c0 = tip + L k (the controlled
//     point of the measuring tool at zero commands), A on the first axis,
//     B on the second: rotary table position = A - c0, 19703-05 = B - A;
//   tool rotation type: D = tip + L k (sheet 83: "point D is determined by
//     adding the tool length offset and tool holder offset to the tool
//     tip"), E on the second axis, F on the first: 19709-11 = E - D,
//     19712-14 = F - E;
//   mixed: D as above, E on the tool's axis: 19709-11 = E - D; the rotary
//     table position from E (the controlled point) to a point on the table's axis.
Eigen::VectorXd FanucVendor::Map(const Machine& m, const KinematicsTable& table, const VendorOptions& o) const {
  const Setup s = Parse(m, o);
  const TableAxis& r1 = table.axes.at(FindRow(m, table, s.first));
  const TableAxis& r2 = table.axes.at(FindRow(m, table, s.second));
  Eigen::VectorXd v(Size(s.type));
  v[0] = s.type;
  v[1] = s.number_first;
  Codes(m, s.first, r1.direction, &v[2], &v[3]);
  v[4] = s.number_second;
  Codes(m, s.second, r2.direction, &v[5], &v[6]);
  const Eigen::Vector3d D = table.tool_tip + s.tool_length * s.k;
  if (s.type == kTableRotation) {
    v.segment<3>(kCommon) = r1.point - D;  // D is the controlled point here: the machine origin
    v.segment<3>(kCommon + 3) = r2.point - r1.point;
  } else if (s.type == kToolRotation) {
    v[kCommon] = s.holder_offset;
    v.segment<3>(kCommon + 1) = r2.point - D;
    v.segment<3>(kCommon + 4) = r1.point - r2.point;
  } else {
    v[kCommon] = s.holder_offset;
    v.segment<3>(kCommon + 1) = r1.point - D;
    v.segment<3>(kCommon + 4) = r2.point - r1.point;
  }
  return v;
}

// The values fix the chain up to where the machine origin sits in fivecal's
// frame (the work offset takes that); it is anchored as the nominal machine
// has it: the table type's controlled point at the nominal tip + L k, the
// head's point F (mixed: E) at the nominal point of the first axis.
KinematicsTable FanucVendor::Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const {
  const Setup s = Parse(m, o);
  const Decoded d = Decode(m, s, values);
  KinematicsTable t = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
  Eigen::Vector3d p1, p2, tip;
  if (s.type == kTableRotation) {
    tip = m.tip();
    p1 = tip + s.tool_length * s.k + d.a;
    p2 = p1 + d.b;
  } else if (s.type == kToolRotation) {
    p1 = m.axis(s.first).point;
    p2 = p1 - d.b;
    tip = p2 - d.a - s.tool_length * s.k;
  } else {
    p1 = m.axis(s.first).point;
    tip = p1 - d.a - s.tool_length * s.k;
    p2 = p1 + d.b;
  }
  TableAxis& r1 = t.axes.at(FindRow(m, t, s.first));
  TableAxis& r2 = t.axes.at(FindRow(m, t, s.second));
  r1.direction = d.sign1 * Eigen::Vector3d::Unit(d.axis1);
  r2.direction = d.sign2 * Eigen::Vector3d::Unit(d.axis2);
  // The table's convention: the point of the line nearest the nominal pivot.
  const auto nearest = [&](const TableAxis& r, const Eigen::Vector3d& on, int axis) -> Eigen::Vector3d {
    return on + (m.axis(axis).point - on).dot(r.direction) * r.direction;
  };
  r1.point = nearest(r1, p1, s.first);
  r2.point = nearest(r2, p2, s.second);
  t.tool_tip = tip;
  t.tool_axis = s.k;
  t.part_origin.setZero();
  t.part_rotation.setIdentity();
  return t;
}

// Fanuc's transformation as the manual describes the mechanism (A-79348E
// sheets 59, 72, 75, 82-84), in the machine coordinate system:
//
//   machine coordinates P: the controlled point relative to the table, the
//     linear axes' displacement (tool side +q u, table side -q u);
//   R_i = rotation of axis i's carriage by the command about the basic axis
//     of No. 19682/19687, right-handed for No. 19684/19689 = 0, left-handed
//     for 1 ("clockwise as viewed from the negative to positive direction
//     ... (right-hand thread rotation)", sheet 75);
//   tool rotation type (2): tool tip = P + R1 (-(F-E) + R2 (-(E-D) - L k)),
//     P the position of F: the first axis carries the second, which carries the tool;
//   table rotation type (12): tool tip T = P - L k; in the table's frame
//     x = R2^T (R1^T (T - A) + A - B) + B, A the rotary table position,
//     B = A + No. 19703-05: the first axis carries the second, which carries the part;
//   mixed (21): T = P + R1 (-(E-D) - L k), P the position of E; in the
//     table's frame x = R2^T (T - A) + A, A the rotary table position.
//
// The result is moved into fivecal's frame by the anchor Table uses.
Eigen::MatrixXd FanucVendor::ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                                        const VendorOptions& o) const {
  const Setup s = Parse(m, o);
  const Decoded d = Decode(m, s, values);
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("fanuc: axes: " + std::to_string(q.cols()) + " columns, machine has " +
                                std::to_string(m.num_axes()) + " axes");
  const double deg = M_PI / 180.0;
  const Eigen::Vector3d Lk = s.tool_length * s.k;
  Eigen::Vector3d anchor;
  if (s.type == kTableRotation) anchor = m.tip() + Lk;
  else anchor = m.axis(s.first).point;
  Eigen::MatrixXd out(q.rows(), 3);
  for (Eigen::Index i = 0; i < q.rows(); ++i) {
    Eigen::Vector3d P = Eigen::Vector3d::Zero();
    for (int k = 0; k < m.num_axes(); ++k) {
      RequireFinite(q(i, k), "axes[" + std::to_string(i) + "]." + AxisName(m, k));
      if (m.axis(k).rotary()) continue;
      P += (m.on_tool_side(k) ? 1.0 : -1.0) * q(i, k) * m.axis(k).direction;
    }
    const Eigen::Matrix3d R1 = BasicRotation(d.axis1, d.sign1 * q(i, s.first) * deg);
    const Eigen::Matrix3d R2 = BasicRotation(d.axis2, d.sign2 * q(i, s.second) * deg);
    Eigen::Vector3d x;
    if (s.type == kToolRotation) {
      x = P + R1 * (-d.b + R2 * (-d.a - Lk));
    } else if (s.type == kTableRotation) {
      const Eigen::Vector3d T = P - Lk, A = d.a, B = d.a + d.b;
      x = R2.transpose() * (R1.transpose() * (T - A) + A - B) + B;
    } else {
      const Eigen::Vector3d T = P + R1 * (-d.a - Lk), A = d.b;
      x = R2.transpose() * (T - A) + A;
    }
    out.row(i) = (x + anchor).transpose();
  }
  return out;
}

}  // namespace controllers
}  // namespace fivecal
