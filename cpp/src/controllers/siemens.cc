#include "fivecal/controllers/siemens.h"

#include <Eigen/Geometry>
#include <cmath>
#include <stdexcept>

namespace fivecal {
namespace controllers {

namespace {

// Where the commissioning manual describes the record (12/2017, §21.7.3
// p. 568, offset vectors; §21.7 p. 572, TOOLCARRIER <=> TRAORI), and where
// it says what each vector means per type (03/2013 §22.6 p. 502).
const char kOffsetSource[] =
    "SINUMERIK Operate commissioning manual 12/2017 (6FC5397-1DP40-6BA1) §21.7.3 p. 568; "
    "meaning per kinematics type: 03/2013 (6FC5397-1DP40-3BA1) §22.6 p. 502";
const char kAxisSource[] =
    "SINUMERIK Operate commissioning manual 12/2017 (6FC5397-1DP40-6BA1) §21.7.3 p. 568 and the CYCLE800 "
    "checklist §21.7.2 (sign for an axis that moves the workpiece); rotation sense: function manual W1 "
    "08/2005 (6FC5397-0BP10-0BA0) §2.5 p. 2-92";
const char kTypeSource[] =
    "SINUMERIK 840D programming guide advanced 04.00 §15.2 p. 15-512 ($TC_CARR23: T, P, M); "
    "commissioning manual 12/2017 (6FC5397-1DP40-6BA1) §21.7 p. 572";

// $TC_CARR numbers of each vector's x, y, z.
int FirstNumber(const std::string& vector) {
  if (vector == "I1") return 1;
  if (vector == "I2") return 4;
  if (vector == "V1") return 7;
  if (vector == "V2") return 10;
  if (vector == "I3") return 15;
  return 18;  // I4
}

struct Record {
  char type = 'P';
  Eigen::Vector3d I1 = Eigen::Vector3d::Zero(), I2 = Eigen::Vector3d::Zero(), I3 = Eigen::Vector3d::Zero(),
                  I4 = Eigen::Vector3d::Zero(), V1 = Eigen::Vector3d::Zero(), V2 = Eigen::Vector3d::Zero();
  Eigen::Vector3d& operator[](const std::string& v) {
    return v == "I1" ? I1 : v == "I2" ? I2 : v == "I3" ? I3 : v == "I4" ? I4 : v == "V1" ? V1 : V2;
  }
};

// The machine's axes as the record sees them: the two rotary axes (1 carries
// 2; in mixed kinematics 1 is the head's) and the linear axes X, Y, Z.
struct Layout {
  char type = 'P';
  int rot[2] = {-1, -1};
  int lin[3] = {-1, -1, -1};
};

std::string Who(const Machine& m) { return "machine '" + m.name() + "' (" + m.topology() + ")"; }

Layout Analyze(const Machine& m) {
  Layout l;
  std::vector<int> wp, tool;
  for (int side = 0; side < 2; ++side) {
    bool rotary_seen = false;
    for (int k : side == 0 ? m.workpiece_chain() : m.tool_chain()) {
      const Axis& a = m.axis(k);
      if (a.name == 'S') continue;
      if (a.rotary()) {
        rotary_seen = true;
        (side == 0 ? wp : tool).push_back(k);
      } else if (rotary_seen) {
        // The record's rotary axes sit between the linear axes and the part
        // (table) or the tool (head): the vectors are fixed in the machine axes.
        throw std::invalid_argument("siemens: " + Who(m) + ": linear axis " + std::string(1, a.name) +
                                    " is carried by a rotary axis; a swivel data record describes rotary "
                                    "axes that carry the tool or the part directly");
      }
    }
  }
  if (wp.size() + tool.size() != 2)
    throw std::invalid_argument("siemens: " + Who(m) + " has " + std::to_string(wp.size() + tool.size()) +
                                " rotary axes; the export writes swivel data records of two rotary axes");
  if (wp.size() == 2) {
    l.type = 'P';
    l.rot[0] = wp[0];
    l.rot[1] = wp[1];
  } else if (tool.size() == 2) {
    l.type = 'T';
    l.rot[0] = tool[0];
    l.rot[1] = tool[1];
  } else {
    // Mixed: "rotary axis 1 is always the axis for the tool orientation" (12/2017 §21.7.2).
    l.type = 'M';
    l.rot[0] = tool[0];
    l.rot[1] = wp[0];
  }
  // The record's components are along the machine axes X, Y, Z, which follow
  // the right-hand rule as the tool's motion relative to the part (checklist
  // §21.7.2: an axis that moves the workpiece moves the other way).
  for (int c = 0; c < 3; ++c) {
    const char name = "XYZ"[c];
    const int k = m.AxisIndex(name);
    if (k < 0 || m.axis(k).rotary())
      throw std::invalid_argument("siemens: " + Who(m) + " has no linear axis " + std::string(1, name));
    const Eigen::Vector3d e = (m.on_tool_side(k) ? 1.0 : -1.0) * m.axis(k).direction;
    if ((e - Eigen::Vector3d::Unit(c)).norm() > 1e-9)
      throw std::invalid_argument(
          "siemens: " + Who(m) + ": a positive " + std::string(1, name) + " moves the tool relative to the part along (" +
          std::to_string(e.x()) + ", " + std::to_string(e.y()) + ", " + std::to_string(e.z()) +
          "), not +" + std::string(1, char(name - 'X' + 'x')) +
          "; the swivel data record's vectors are in machine axes that follow the right-hand rule "
          "(DIN 66217 / ISO 841, commissioning manual 12/2017 §21.7.2)");
    l.lin[c] = k;
  }
  for (const Axis& a : m.axes())
    if (!a.rotary() && a.name != 'X' && a.name != 'Y' && a.name != 'Z')
      throw std::invalid_argument("siemens: " + Who(m) + ": linear axis " + std::string(1, a.name) +
                                  " is not one of the record's machine axes X, Y, Z");
  return l;
}

int RecordNumber(const VendorOptions& o, bool required) {
  for (const auto& [key, value] : o)
    if (key != "record")
      throw std::invalid_argument("option '" + key + "': siemens takes only 'record' (the swivel data record number n)");
  const auto it = o.find("record");
  if (it == o.end()) {
    if (!required) return 0;
    throw std::invalid_argument(
        "option record: state the number n of the swivel data record to write ($TC_CARR..[n]) with --set "
        "record=N; a controller holds one record per swivel head, table or combination, and writing into "
        "another one would change that kinematics");
  }
  size_t used = 0;
  long n = 0;
  try {
    n = std::stol(it->second, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != it->second.size() || n < 1 || n > 999999)
    throw std::invalid_argument("option record: '" + it->second +
                                "' is not a swivel data record number (an integer 1, 2, ...)");
  return int(n);
}

size_t Count(char type) { return 3 * SiemensVendor::Vectors(type).size() + 1; }

Record Unpack(const Machine& m, const Eigen::VectorXd& values) {
  Record r;
  r.type = SiemensVendor::KinematicsType(m);
  if (size_t(values.size()) != Count(r.type))
    throw std::invalid_argument("siemens: " + std::to_string(values.size()) + " values, a type " +
                                std::string(1, r.type) + " record has " + std::to_string(Count(r.type)));
  Eigen::Index i = 0;
  for (const std::string& v : SiemensVendor::Vectors(r.type)) {
    for (int c = 0; c < 3; ++c) RequireFinite(values[i + c], "$TC_CARR" + std::to_string(FirstNumber(v) + c));
    r[v] = values.segment<3>(i);
    i += 3;
  }
  if (values[i] != double(r.type)) {
    // the letter when the value is one's character code, else the number
    const double c = values[i];
    const std::string given = (c == 'T' || c == 'P' || c == 'M') ? std::string(1, char(int(c))) : std::to_string(c);
    throw std::invalid_argument("$TC_CARR23: the record's kinematics type '" + given + "' is not the machine's '" +
                                std::string(1, r.type) + "'");
  }
  for (const char* v : {"V1", "V2"})
    if (!(r[v].norm() > 0))
      throw std::invalid_argument(std::string(v) + " ($TC_CARR" + std::to_string(FirstNumber(v)) + ".." +
                                  std::to_string(FirstNumber(v) + 2) + "): a zero vector gives the rotary axis no direction");
  return r;
}

Eigen::VectorXd Pack(const Record& rec) {
  Record r = rec;
  const std::vector<std::string> vs = SiemensVendor::Vectors(r.type);
  Eigen::VectorXd out(Count(r.type));
  Eigen::Index i = 0;
  for (const std::string& v : vs) {
    out.segment<3>(i) = r[v];
    i += 3;
  }
  out[i] = double(r.type);
  return out;
}

// Right-handed rotation about v by deg degrees: W1 p. 2-92 counts the angle
// positive clockwise looking along the vector. The vector's length does not
// enter (the W1 example's head axis is (-1, 0, 1)).
Eigen::Matrix3d Rot(const Eigen::Vector3d& v, double deg) {
  return Eigen::AngleAxisd(deg * M_PI / 180.0, v.normalized()).toRotationMatrix();
}

const TableAxis* Row(const KinematicsTable& t, const Axis& a, bool tool, const char* what) {
  for (const TableAxis& r : t.axes)
    if (r.axis == a.name && r.tool_chain == tool) {
      if (!r.rotary) break;
      return &r;
    }
  throw std::invalid_argument(std::string("siemens: the kinematics table has no rotary row ") + a.name +
                              " on the " + (tool ? "tool" : "workpiece") + " side (" + what + ")");
}

}  // namespace

std::vector<std::string> SiemensVendor::Vectors(char type) {
  if (type == 'T') return {"I1", "I2", "I3", "V1", "V2"};
  if (type == 'P') return {"I2", "I3", "I4", "V1", "V2"};
  return {"I1", "I2", "I3", "I4", "V1", "V2"};
}

char SiemensVendor::KinematicsType(const Machine& m) { return Analyze(m).type; }

std::map<std::string, std::string> SiemensVendor::OptionHelp() const {
  return {{"record",
           "required: the number n of the swivel data record written ($TC_CARR1[n] ...), 1, 2, ...; the "
           "controller holds one record per swivel head, swivel table or combination"}};
}

VendorModel SiemensVendor::Model(const Machine& m, const VendorOptions& o) const {
  RecordNumber(o, false);
  VendorModel vm;
  const char type = Analyze(m).type;
  vm.model = type == 'P' ? ControllerModel::kTableTable : type == 'T' ? ControllerModel::kHeadHead
                                                                       : ControllerModel::kTableHead;
  vm.directions = true;  // V1, V2 are written
  // The record has no tool length: that is tool data, measured per tool. A
  // tool length column would move the head's pivots with the probe's length.
  vm.tool_length = false;
  return vm;
}

std::vector<VendorValue> SiemensVendor::Values(const Machine& m, const VendorOptions& o) const {
  const int n = RecordNumber(o, true);
  const char type = Analyze(m).type;
  const std::string idx = "[" + std::to_string(n) + "]";
  std::vector<VendorValue> out;
  for (const std::string& v : Vectors(type))
    for (int c = 0; c < 3; ++c) {
      VendorValue val;
      val.name = "$TC_CARR" + std::to_string(FirstNumber(v) + c) + idx;
      const bool axis = v[0] == 'V';
      val.unit = axis ? "" : "mm";  // a direction component: changes like an angle in rad
      val.source = std::string(axis ? "rotary axis vector " : "offset vector ") + v + " " + "xyz"[c] + ": " +
                   (axis ? kAxisSource : kOffsetSource);
      out.push_back(val);
    }
  VendorValue t;
  t.name = "$TC_CARR23" + idx;
  t.unit = "letter";
  t.source = std::string("kinematics type (the letter's character code: 84 T, 80 P, 77 M): ") + kTypeSource;
  t.fixed = true;
  out.push_back(t);
  return out;
}

Eigen::VectorXd SiemensVendor::Map(const Machine& m, const KinematicsTable& t, const VendorOptions& o) const {
  RecordNumber(o, false);
  const Layout l = Analyze(m);
  const bool tool1 = l.type != 'P', tool2 = l.type == 'T';
  const TableAxis& r1 = *Row(t, m.axis(l.rot[0]), tool1, "rotary axis 1");
  const TableAxis& r2 = *Row(t, m.axis(l.rot[1]), tool2, "rotary axis 2");
  Record r;
  r.type = l.type;
  r.V1 = r1.direction.normalized();
  r.V2 = r2.direction.normalized();
  const Eigen::Vector3d p1 = r1.point, p2 = r2.point;
  // The tool's shift at the zero pose (tool adapter = tip + L, L = -tip of the
  // machine file): a head's pivot errors carry the spindle with them.
  const Eigen::Vector3d A = t.tool_tip - m.tip();
  if (l.type == 'P') {
    if (A.norm() > 1e-9)
      throw std::invalid_argument("siemens: the tool tip moved by " + std::to_string(1e3 * A.norm()) +
                                  " um at the zero pose; a swivel table's record carries no tool offset "
                                  "(that is the tool's data)");
    r.I2 = p1;
    r.I3 = p2 - p1;
    r.I4 = -(r.I2 + r.I3);  // "closure of the I4 = -(I2 + I3) vector chain"
  } else if (l.type == 'T') {
    r.I1 = -p1;
    r.I2 = p1 - p2;
    r.I3 = p2 - A;
  } else {
    r.I1 = -p1;
    r.I2 = p1 - A;
    r.I3 = p2;
    r.I4 = -p2;  // "closure of the I4 = -I3 vector chain"
  }
  return Pack(r);
}

KinematicsTable SiemensVendor::Table(const Machine& m, const Eigen::VectorXd& values, const VendorOptions& o) const {
  RecordNumber(o, false);
  const Layout l = Analyze(m);
  const Record r = Unpack(m, values);
  KinematicsTable t = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
  const auto set = [&](int axis, const Eigen::Vector3d& v, const Eigen::Vector3d& p) {
    for (TableAxis& row : t.axes)
      if (row.axis == m.axis(axis).name) {
        row.direction = v.normalized();
        row.point = p;
      }
  };
  // The table side as ToolPoints evaluates it (y = R^T (tip - offset)) is
  // the rigid motion about the lines through -(I3 + I4) and -I4 (P) or -I4
  // (M): I2 + I3 + I4 = 0 makes them I2 and I2 + I3 (I3).
  if (l.type == 'P') {
    set(l.rot[0], r.V1, -(r.I3 + r.I4));
    set(l.rot[1], r.V2, -r.I4);
  } else if (l.type == 'T') {
    set(l.rot[0], r.V1, -r.I1);
    set(l.rot[1], r.V2, -r.I1 - r.I2);
    t.tool_tip = m.tip() - (r.I1 + r.I2 + r.I3);
  } else {
    set(l.rot[0], r.V1, -r.I1);
    set(l.rot[1], r.V2, -r.I4);
    t.tool_tip = m.tip() - (r.I1 + r.I2);
  }
  return t;
}

// The swivel data record's transformation, from the manual's vector chain
// (see siemens.h): apart from fivecal's kinematics and from TableToolPoints.
Eigen::MatrixXd SiemensVendor::ToolPoints(const Machine& m, const Eigen::VectorXd& values, const Eigen::MatrixXd& q,
                                          const VendorOptions& o) const {
  RecordNumber(o, false);
  const Layout l = Analyze(m);
  const Record r = Unpack(m, values);
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("axes: " + std::to_string(q.cols()) + " columns, machine has " +
                                std::to_string(m.num_axes()) + " axes");
  const Eigen::Vector3d L = -m.tip();  // tool length vector, tip -> tool adapter (tool data)
  Eigen::MatrixXd out(q.rows(), 3);
  for (Eigen::Index i = 0; i < q.rows(); ++i) {
    for (int k = 0; k < m.num_axes(); ++k)
      RequireFinite(q(i, k), "axes[" + std::to_string(i) + "]." + std::string(1, m.axis(k).name));
    const Eigen::Vector3d P(q(i, l.lin[0]), q(i, l.lin[1]), q(i, l.lin[2]));
    const Eigen::Matrix3d R1 = Rot(r.V1, q(i, l.rot[0])), R2 = Rot(r.V2, q(i, l.rot[1]));
    Eigen::Vector3d tip, y;
    if (l.type == 'T') {
      // The resulting tool length compensation I1 + R1 (I2 + R2 (I3 + L)) (W1 fig. 2-42).
      tip = P - (r.I1 + R1 * (r.I2 + R2 * (r.I3 + L)));
      y = tip;
    } else if (l.type == 'P') {
      tip = P - L;
      // The table offset (W1 §2.5.4, example §4.1) and the table's rotation.
      const Eigen::Vector3d offset = r.I2 + R1 * (r.I3 + R2 * r.I4) - (r.I2 + r.I3 + r.I4);
      y = (R1 * R2).transpose() * (tip - offset);
    } else {
      tip = P - (r.I1 + R1 * (r.I2 + L));
      const Eigen::Vector3d offset = r.I3 + R2 * r.I4 - (r.I3 + r.I4);
      y = R2.transpose() * (tip - offset);
    }
    out.row(i) = y.transpose();
  }
  return out;
}

}  // namespace controllers
}  // namespace fivecal
