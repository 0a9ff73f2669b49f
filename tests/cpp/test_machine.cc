// Machine model tests: topology parsing, axis validation, parameter
// enumeration and the error messages users see for bad input
// (DESIGN.md: "throw std::invalid_argument naming the bad field, row or
// parameter").
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "fivecal/model/kinematics.h"
#include "fivecal/model/machine.h"

namespace fivecal {
namespace {

// The HU40T-like horizontal machine of DESIGN.md.
const char* kHu40tJson = R"({"name": "HU40T-like", "topology": "wCBXfZYSt",
 "axes": {"X": {"type": "linear", "direction": [-1,0,0]},
          "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
          "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
          "Z": {"type": "linear", "direction": [0,0,1]},
          "Y": {"type": "linear", "direction": [0,1,0]},
          "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,0]}},
 "tool": {"tip": [0,0,100]}})";

// Runs `f`, expects std::invalid_argument whose what() contains every string
// in `needles`. Any other exception type (or none) is a failure: DESIGN.md
// promises std::invalid_argument (-> ValueError in Python) for bad input.
void ExpectInvalid(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
    ADD_FAILURE() << "expected std::invalid_argument, nothing was thrown";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const std::string& n : needles)
      EXPECT_NE(what.find(n), std::string::npos)
          << "message '" << what << "' does not mention '" << n << "'";
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected std::invalid_argument, got another exception type: " << e.what();
  } catch (...) {
    ADD_FAILURE() << "expected std::invalid_argument, got a non-std exception";
  }
}

// A small valid machine with a linear X, for the validation tests below.
Axis LinearX() {
  Axis a;
  a.name = 'X';
  a.type = AxisType::kLinear;
  a.direction = Eigen::Vector3d::UnitX();
  return a;
}

// ---- Topology, chains, axis order ------------------------------------------

TEST(Machine, Hu40tChainsReadFromTheFoundationOutward) {
  const Machine m = Machine::FromJson(kHu40tJson);
  EXPECT_EQ(m.name(), "HU40T-like");
  // Axes are stored in topology order, workpiece to tool.
  EXPECT_EQ(m.axis_names(), "CBXZYS");
  // Workpiece chain from the foundation outward: X, then B, then C.
  const std::vector<int> wp = {m.AxisIndex('X'), m.AxisIndex('B'), m.AxisIndex('C')};
  const std::vector<int> tl = {m.AxisIndex('Z'), m.AxisIndex('Y'), m.AxisIndex('S')};
  EXPECT_EQ(m.workpiece_chain(), wp);
  EXPECT_EQ(m.tool_chain(), tl);
  EXPECT_FALSE(m.on_tool_side(m.AxisIndex('C')));
  EXPECT_FALSE(m.on_tool_side(m.AxisIndex('X')));
  EXPECT_TRUE(m.on_tool_side(m.AxisIndex('Z')));
  EXPECT_TRUE(m.on_tool_side(m.AxisIndex('S')));
  EXPECT_EQ(m.AxisIndex('A'), -1);
  // Directions as given (already unit), B pivot as given.
  EXPECT_EQ(m.axis(m.AxisIndex('X')).direction, Eigen::Vector3d(-1, 0, 0));
  EXPECT_EQ(m.axis(m.AxisIndex('B')).point, Eigen::Vector3d(0, 0, -120));
  EXPECT_TRUE(m.axis(m.AxisIndex('B')).rotary());
  EXPECT_FALSE(m.axis(m.AxisIndex('Y')).rotary());
  EXPECT_EQ(m.tip(), Eigen::Vector3d(0, 0, 100));
  // Without an explicit tool axis the spindle direction is the tool axis.
  EXPECT_EQ(m.tool_axis(), Eigen::Vector3d(0, 0, 1));
}

TEST(Machine, DirectionsAreNormalised) {
  const Machine m = Machine::FromJson(R"({"topology": "wCfXt",
    "axes": {"X": {"direction": [2,0,0]}, "C": {"direction": [0,0,5], "point": [1,2,3]}}})");
  EXPECT_NEAR((m.axis(m.AxisIndex('X')).direction - Eigen::Vector3d::UnitX()).norm(), 0, 1e-15);
  EXPECT_NEAR((m.axis(m.AxisIndex('C')).direction - Eigen::Vector3d::UnitZ()).norm(), 0, 1e-15);
  // The type defaults from the ISO letter.
  EXPECT_TRUE(m.axis(m.AxisIndex('C')).rotary());
  EXPECT_FALSE(m.axis(m.AxisIndex('X')).rotary());
  // No spindle: the tool axis defaults to +Z.
  EXPECT_EQ(m.tool_axis(), Eigen::Vector3d::UnitZ());
}

TEST(Machine, FoundationMayBeWrittenB) {
  const Machine m = Machine::FromJson(R"({"topology": "wCAYbXZSt",
    "axes": {"C": {"direction": [0,0,1]}, "A": {"direction": [1,0,-1]},
             "Y": {"direction": [0,1,0]}, "X": {"direction": [1,0,0]},
             "Z": {"direction": [0,0,1]}, "S": {"direction": [0,0,1]}}})");
  EXPECT_EQ(m.axis_names(), "CAYXZS");
  const std::vector<int> wp = {2, 1, 0};  // Y, A, C from the foundation
  EXPECT_EQ(m.workpiece_chain(), wp);
}

TEST(Machine, SpindleMayBeWrittenC1) {
  // "(C1)" in the topology is the spindle, named S internally; its axis entry
  // may be keyed "C1" or "S".
  for (const char* key : {"C1", "S"}) {
    const std::string json = std::string(R"({"topology": "wCBXfZY(C1)t",
      "axes": {"X": {"direction": [-1,0,0]}, "B": {"direction": [0,-1,0], "point": [0,0,-120]},
               "C": {"direction": [0,0,-1]}, "Z": {"direction": [0,0,1]},
               "Y": {"direction": [0,1,0]}, ")") +
                             key + R"(": {"type": "rotary", "direction": [0,0,1]}},
      "tool": {"tip": [0,0,100]}})";
    const Machine m = Machine::FromJson(json);
    SCOPED_TRACE(key);
    EXPECT_EQ(m.axis_names(), "CBXZYS");
    EXPECT_GE(m.AxisIndex('S'), 0);
    EXPECT_TRUE(m.axis(m.AxisIndex('S')).rotary());
    EXPECT_EQ(m.num_parameters(), 152);
    EXPECT_EQ(m.backlash_index(m.AxisIndex('S')), -1);
    EXPECT_GE(m.ParameterIndex("ECS1"), 0);
    EXPECT_EQ(m.ParameterIndex("ESSb"), -1);
    EXPECT_EQ(m.tool_chain().back(), m.AxisIndex('S'));
  }
}

TEST(Machine, JsonRoundTrip) {
  const Machine m = Machine::FromJson(kHu40tJson);
  const Machine r = Machine::FromJson(m.ToJson());
  EXPECT_EQ(r.name(), m.name());
  EXPECT_EQ(r.topology(), m.topology());
  ASSERT_EQ(r.num_axes(), m.num_axes());
  for (int k = 0; k < m.num_axes(); ++k) {
    EXPECT_EQ(r.axis(k).name, m.axis(k).name);
    EXPECT_EQ(r.axis(k).type, m.axis(k).type);
    EXPECT_EQ(r.axis(k).direction, m.axis(k).direction);
    EXPECT_EQ(r.axis(k).point, m.axis(k).point);
  }
  EXPECT_EQ(r.tip(), m.tip());
  EXPECT_EQ(r.tool_axis(), m.tool_axis());
  EXPECT_EQ(r.parameter_names(), m.parameter_names());
}

// ---- Parameter enumeration -----------------------------------------------

TEST(Parameters, Hu40tNamesAndCount) {
  const Machine m = Machine::FromJson(kHu40tJson);
  // 6 axes x (6 location + 6 components x 3 degrees) + 5 backlash (no
  // spindle backlash) + 3 tip offsets.
  EXPECT_EQ(m.num_parameters(), 6 * 24 + 5 + 3);
  EXPECT_EQ(m.num_parameters(), 152);
  const std::vector<std::string> names = m.parameter_names();
  ASSERT_EQ(static_cast<int>(names.size()), 152);
  auto has = [&](const std::string& n) {
    return std::find(names.begin(), names.end(), n) != names.end();
  };
  for (const char* n : {"EX0C", "EY0C", "EA0C", "EC0B", "EZ0X", "EB0Z", "EC0Y", "EXX1", "EYX2",
                        "EZX3", "ECC3", "EAB1", "EXS1", "EXXb", "EYYb", "EZZb", "EBBb", "ECCb",
                        "tip.x", "tip.y", "tip.z"})
    EXPECT_TRUE(has(n)) << n;
  for (const char* n : {"ESSb", "EX0A", "EXA1", "EAAb", "EXX0", "EXX4", "EX0S0", "tip.w"})
    EXPECT_FALSE(has(n)) << n;
  // Names are unique.
  std::vector<std::string> sorted = names;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end());
}

TEST(Parameters, IndexRoundTripsAndMatchesLayout) {
  const Machine m = Machine::FromJson(kHu40tJson);
  const std::vector<std::string> names = m.parameter_names();
  for (int i = 0; i < m.num_parameters(); ++i) {
    EXPECT_EQ(m.ParameterIndex(names[i]), i) << names[i];
    EXPECT_EQ(m.RequireParameter(names[i]), i) << names[i];
    EXPECT_EQ(m.parameters()[i].name, names[i]);
  }
  EXPECT_EQ(m.ParameterIndex("EX0Q"), -1);
  EXPECT_EQ(m.ParameterIndex(""), -1);
  // The offsets the kinematics use must point at the parameter of that name.
  const std::string comp = "XYZABC";
  for (int k = 0; k < m.num_axes(); ++k) {
    const char a = m.axis(k).name;
    for (int c = 0; c < 6; ++c) {
      const std::string loc = std::string("E") + comp[c] + "0" + a;
      EXPECT_EQ(m.location_index(k, c), m.ParameterIndex(loc)) << loc;
      const ParameterInfo& pl = m.parameters()[m.location_index(k, c)];
      EXPECT_EQ(pl.kind, ParameterKind::kLocation);
      EXPECT_EQ(pl.axis, k);
      EXPECT_EQ(pl.component, c);
      EXPECT_EQ(pl.angular(), c >= 3) << loc;
      for (int d = 1; d <= 3; ++d) {
        const std::string mot = std::string("E") + comp[c] + a + std::to_string(d);
        EXPECT_EQ(m.motion_index(k, c, d), m.ParameterIndex(mot)) << mot;
        const ParameterInfo& pm = m.parameters()[m.motion_index(k, c, d)];
        EXPECT_EQ(pm.kind, ParameterKind::kMotion);
        EXPECT_EQ(pm.axis, k);
        EXPECT_EQ(pm.component, c);
        EXPECT_EQ(pm.degree, d);
      }
    }
    const std::string bl = std::string("E") + a + a + "b";
    if (a == 'S') {
      EXPECT_EQ(m.backlash_index(k), -1);
    } else {
      EXPECT_EQ(m.backlash_index(k), m.ParameterIndex(bl)) << bl;
      EXPECT_EQ(m.parameters()[m.backlash_index(k)].kind, ParameterKind::kBacklash);
      EXPECT_EQ(m.parameters()[m.backlash_index(k)].axis, k);
    }
  }
  for (int c = 0; c < 3; ++c) {
    const std::string tn = std::string("tip.") + "xyz"[c];
    EXPECT_EQ(m.tip_index() + c, m.ParameterIndex(tn)) << tn;
    EXPECT_EQ(m.parameters()[m.tip_index() + c].kind, ParameterKind::kTip);
    EXPECT_FALSE(m.parameters()[m.tip_index() + c].angular());
  }
}

TEST(Parameters, ErrorModelSetGetByName) {
  const Machine m = Machine::FromJson(kHu40tJson);
  ErrorModel e(m);
  EXPECT_EQ(e.values().size(), 152);
  EXPECT_EQ(e.values().cwiseAbs().maxCoeff(), 0.0);
  e.Set("EX0C", 0.011);
  e.Set("ECCb", -2e-5);
  e.Set("tip.z", 0.5);
  EXPECT_EQ(e.Get("EX0C"), 0.011);
  EXPECT_EQ(e.values()[m.ParameterIndex("ECCb")], -2e-5);
  EXPECT_EQ(e.values()[m.tip_index() + 2], 0.5);
  EXPECT_EQ(e.values().cwiseAbs().sum(), 0.011 + 2e-5 + 0.5);

  const ErrorModel f = ErrorModel::FromJson(m, R"({"EX0C": 0.25, "EB0Z": 1e-5})");
  EXPECT_EQ(f.Get("EX0C"), 0.25);
  EXPECT_EQ(f.Get("EB0Z"), 1e-5);
  // The result format is accepted too; setup parameters are skipped.
  const ErrorModel g = ErrorModel::FromJson(
      m, R"({"parameters": {"EYY1": {"value": 3e-6, "std": 1e-7}, "facet.F3": {"value": 0.1}}})");
  EXPECT_EQ(g.Get("EYY1"), 3e-6);
}

// ---- Bad input --------------------------------------------------------------

TEST(MachineValidation, UnknownAxisLetterInTopology) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wQfXt",
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"topology", "unknown axis letter", "'Q'"});
}

TEST(MachineValidation, DuplicateAxisInTopology) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wXfXt",
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"topology", "duplicate axis", "'X'"});
}

TEST(MachineValidation, DuplicateAxisDefinition) {
  // JSON keys are unique, so construct directly.
  ExpectInvalid([] { Machine("m", "wfXt", {LinearX(), LinearX()}, Eigen::Vector3d::Zero()); },
                {"duplicate axis", "'X'"});
}

TEST(MachineValidation, MissingAxisDefinition) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wCfXYt",
      "axes": {"X": {"direction": [1,0,0]}, "C": {"direction": [0,0,1]}}})"); },
                {"'Y'", "no definition"});
}

TEST(MachineValidation, AxisDefinedButNotInTopology) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"direction": [1,0,0]}, "B": {"direction": [0,1,0]}}})"); },
                {"'B'", "not in topology"});
}

TEST(MachineValidation, ZeroDirection) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"direction": [0,0,0]}}})"); },
                {"machine.axes.X.direction", "zero"});
}

TEST(MachineValidation, NaNDirectionConstructedDirectly) {
  Axis x = LinearX();
  x.direction = Eigen::Vector3d(std::numeric_limits<double>::quiet_NaN(), 0, 0);
  ExpectInvalid([&] { Machine("m", "wfXt", {x}, Eigen::Vector3d::Zero()); },
                {"machine.axes.X.direction", "not finite"});
  Axis c;
  c.name = 'C';
  c.type = AxisType::kRotary;
  c.direction = Eigen::Vector3d::UnitZ();
  c.point = Eigen::Vector3d(0, std::numeric_limits<double>::infinity(), 0);
  ExpectInvalid([&] { Machine("m", "wCfXt", {c, LinearX()}, Eigen::Vector3d::Zero()); },
                {"machine.axes.C.point", "not finite"});
}

TEST(MachineValidation, OverflowingDirectionInJson) {
  // 1e999 overflows a double. The parser's own exception
  // (nlohmann::json::out_of_range) must not leak: the user is promised
  // std::invalid_argument naming the document and the bad value.
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"direction": [1e999,0,0]}}})"); },
                {"machine.axes.X.direction[0]", "1e999", "double range"});
  // Nested arrays of objects: the element index and the key inside it.
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt", "list": [{"a": 1}, [2, 3], {"b": [4, -1e999]}],
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"machine.list[2].b[1]", "1e999"});
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt", "axes": {"X": {"direction": [1,0,]}}})"); },
                {"machine.axes.X.direction[2]", "invalid JSON"});
}

TEST(MachineValidation, WrongJsonTypeForName) {
  // A JSON value of the wrong type must also surface as std::invalid_argument
  // (not nlohmann::json::type_error).
  ExpectInvalid([] { Machine::FromJson(R"({"name": 5, "topology": "wfXt",
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"machine.name"});
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"direction": [1,0,"a"]}}})"); },
                {"machine.axes.X.direction[2]"});
}

TEST(MachineValidation, LinearAxisWithTypeRotary) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"type": "rotary", "direction": [1,0,0]}}})"); },
                {"machine.axes.X.type", "linear"});
}

TEST(MachineValidation, UnknownAxisType) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt",
      "axes": {"X": {"type": "prismatic", "direction": [1,0,0]}}})"); },
                {"machine.axes.X.type"});
}

TEST(MachineValidation, TopologyWithoutFoundation) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wCXt",
      "axes": {"X": {"direction": [1,0,0]}, "C": {"direction": [0,0,1]}}})"); },
                {"topology", "foundation"});
}

TEST(MachineValidation, TopologyMustRunFromWorkpieceToTool) {
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "tfXw",
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"topology", "'w'"});
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "",
      "axes": {"X": {"direction": [1,0,0]}}})"); },
                {"topology", "empty"});
}

TEST(MachineValidation, MissingTopologyOrAxes) {
  ExpectInvalid([] { Machine::FromJson(R"({"axes": {}})"); }, {"machine.topology"});
  ExpectInvalid([] { Machine::FromJson(R"({"topology": "wfXt"})"); }, {"machine.axes"});
  ExpectInvalid([] { Machine::FromJson("{not json"); }, {"invalid JSON"});
}

TEST(MachineValidation, UnknownParameterName) {
  const Machine m = Machine::FromJson(kHu40tJson);
  ErrorModel e(m);
  ExpectInvalid([&] { e.Set("EX0Q", 1.0); }, {"unknown parameter", "'EX0Q'"});
  // The hint says the machine has no A axis.
  ExpectInvalid([&] { e.Set("EX0A", 1.0); }, {"'EX0A'", "no axis 'A'"});
  ExpectInvalid([&] { e.Get("tip.w"); }, {"'tip.w'"});
  ExpectInvalid([&] { ErrorModel::FromJson(m, R"({"EXQ1": 1.0})"); }, {"'EXQ1'"});
  ExpectInvalid([&] { e.Set("EX0C", std::nan("")); }, {"errors.EX0C", "not finite"});
}

// Validation of pose input to the kinematics (ValidatePoses via ToolPoints).
class PoseValidation : public ::testing::Test {
 protected:
  Machine m = Machine::FromJson(kHu40tJson);
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(152);
  Eigen::MatrixXd axes = Eigen::MatrixXd::Zero(4, 6);
};

TEST_F(PoseValidation, NaNInAxesNamesAxisAndRow) {
  axes(3, m.AxisIndex('B')) = std::numeric_limits<double>::quiet_NaN();
  ExpectInvalid([&] { ToolPoints(m, theta, axes); }, {"axes.B[3]", "not finite"});
}

TEST_F(PoseValidation, WrongNumberOfAxesColumns) {
  const Eigen::MatrixXd five = Eigen::MatrixXd::Zero(2, 5);
  ExpectInvalid([&] { ToolPoints(m, theta, five); }, {"axes", "6 columns", "CBXZYS", "got 5"});
}

TEST_F(PoseValidation, DirectionMatrixEntryOutOfRange) {
  Eigen::MatrixXi dirs = Eigen::MatrixXi::Zero(4, 6);
  dirs(1, m.AxisIndex('Y')) = 2;
  ExpectInvalid([&] { ToolPoints(m, theta, axes, &dirs); },
                {"directions.Y[1]", "-1, 0 or +1", "got 2"});
  const Eigen::MatrixXi wrong_shape = Eigen::MatrixXi::Zero(3, 6);
  ExpectInvalid([&] { ToolPoints(m, theta, axes, &wrong_shape); }, {"directions", "shape"});
}

TEST_F(PoseValidation, ThetaOfWrongSize) {
  const Eigen::VectorXd short_theta = Eigen::VectorXd::Zero(151);
  ExpectInvalid([&] { ToolPoints(m, short_theta, axes); }, {"errors", "152", "151"});
}

TEST_F(PoseValidation, NonFiniteThetaNamesParameter) {
  theta[m.ParameterIndex("ECC2")] = std::numeric_limits<double>::infinity();
  ExpectInvalid([&] { ToolPoints(m, theta, axes); }, {"errors.ECC2", "not finite"});
}

}  // namespace
}  // namespace fivecal
