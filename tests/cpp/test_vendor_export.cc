// The one export path every controller vendor goes through (vendor.h),
// exercised with a test-only vendor whose values are the neutral table's
// own numbers: the absorption's sensitivity against finite differences, the
// change's covariance against its definition, the round trip, the way back
// (VendorToTheta) and the refusals at the boundary.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "controller_fixtures.h"
#include "fivecal/controllers/beckhoff.h"
#include "fivecal/controllers/fanuc.h"
#include "fivecal/controllers/heidenhain.h"
#include "fivecal/controllers/siemens.h"
#include "fivecal/controllers/vendor.h"
#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {
namespace {

using test_fixtures::Poses;
using test_fixtures::Theta;

Machine TableTable() {
  return Machine::FromJson(R"({"name": "tt", "topology": "wCAfXYZSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,1], "point": [12,-7,0]},
    "A": {"type": "rotary", "direction": [1,0,0], "point": [0,20,-45]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,150]}})");
}

// Values: per rotary row of the table its point and direction, then the
// tool tip; a code first (fixed). Its kinematics is the table's screws.
class TableVendor : public ControllerVendor {
 public:
  std::string Name() const override { return "test-table"; }
  std::string Title() const override { return "test vendor: the neutral table's numbers"; }
  std::map<std::string, std::string> OptionHelp() const override { return {{"scale", "1 or 1000"}}; }
  VendorModel Model(const Machine&, const VendorOptions& o) const override {
    for (const auto& [k, v] : o)
      if (k != "scale") throw std::invalid_argument("option '" + k + "': unknown (expected scale)");
    return {ControllerModel::kTableTable, true, true};
  }
  std::vector<VendorValue> Values(const Machine& m, const VendorOptions& o) const override {
    Model(m, o);
    std::vector<VendorValue> v = {{"type", "", "test", true}};
    for (const TableAxis& a : MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters())).axes) {
      if (!a.rotary) continue;
      for (const char* w : {"px", "py", "pz"}) v.push_back({std::string(1, a.axis) + w, "mm", "test"});
      for (const char* w : {"vx", "vy", "vz"}) v.push_back({std::string(1, a.axis) + w, "", "test"});
    }
    for (const char* w : {"tx", "ty", "tz"}) v.push_back({w, "mm", "test"});
    return v;
  }
  Eigen::VectorXd Map(const Machine&, const KinematicsTable& t, const VendorOptions& o) const override {
    const double s = o.count("scale") ? std::stod(o.at("scale")) : 1.0;
    std::vector<double> v = {7.0};
    for (const TableAxis& a : t.axes) {
      if (!a.rotary) continue;
      for (int c = 0; c < 3; ++c) v.push_back(s * a.point[c]);
      for (int c = 0; c < 3; ++c) v.push_back(a.direction[c]);
    }
    for (int c = 0; c < 3; ++c) v.push_back(s * t.tool_tip[c]);
    return Eigen::Map<Eigen::VectorXd>(v.data(), Eigen::Index(v.size()));
  }
  KinematicsTable Table(const Machine& m, const Eigen::VectorXd& v, const VendorOptions& o) const override {
    const double s = o.count("scale") ? std::stod(o.at("scale")) : 1.0;
    KinematicsTable t = MakeKinematicsTable(m, Eigen::VectorXd::Zero(m.num_parameters()));
    Eigen::Index i = 1;
    for (TableAxis& a : t.axes) {
      if (!a.rotary) continue;
      a.point = v.segment<3>(i) / s;
      a.direction = v.segment<3>(i + 3).normalized();
      i += 6;
    }
    t.tool_tip = v.segment<3>(i) / s;
    return t;
  }
  Eigen::MatrixXd ToolPoints(const Machine& m, const Eigen::VectorXd& v, const Eigen::MatrixXd& q,
                             const VendorOptions& o) const override {
    const KinematicsTable t = Table(m, v, o);
    Eigen::MatrixXd qt(q.rows(), Eigen::Index(t.axes.size()));
    for (size_t j = 0; j < t.axes.size(); ++j) qt.col(Eigen::Index(j)) = q.col(m.AxisIndex(t.axes[j].axis));
    return TableToolPoints(t, qt);
  }
};

TEST(VendorExport, RoundTripChangeAndWayBack) {
  const Machine m = TableTable();
  const TableVendor v;
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}, {"EY0C", -0.01}, {"EY0A", 0.015}, {"EZ0A", -0.012},
                                       {"EB0A", 3e-5}, {"EC0A", -2e-5}, {"EC0Y", 4e-6}});
  const Eigen::MatrixXd q = Poses(m, 60, 5);
  const VendorExport ex = ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {});
  EXPECT_LT(ex.round_trip_max, 1e-9);
  EXPECT_EQ(ex.change[0], 0.0);  // the code never changes
  // the new values are the absorbed model's table
  const Eigen::VectorXd absorbed = v.Map(m, MakeKinematicsTable(m, ex.absorption.theta), {});
  EXPECT_LT((ex.new_values - absorbed).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_TRUE(std::isnan(ex.sigma[1]));  // no covariance given: not a number, never 0
  // the way back: what a controller running the new values does, in fivecal's terms
  const Absorption back = VendorToTheta(m, v, ex.new_values, q, {});
  EXPECT_LT((back.theta - ex.absorption.theta).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(back.max, 1e-9);
  // old values from the controller: new = old + change
  Eigen::VectorXd old = ex.old_values;
  old[1] += 0.5;
  const VendorExport ex2 = ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {}, old);
  EXPECT_NEAR(ex2.new_values[1] - ex.new_values[1], 0.5, 1e-12);
  EXPECT_NEAR(ex2.old_minus_nominal[1], 0.5, 1e-12);
}

TEST(VendorExport, SensitivityIsTheDerivativeOfTheAbsorption) {
  const Machine m = TableTable();
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}, {"EY0A", 0.015}, {"EC0Y", 4e-6}, {"EB0A", 2e-5}});
  const Eigen::MatrixXd q = Poses(m, 40, 5);
  AbsorbOptions o;
  o.directions = true;
  const Absorption ab = Absorb(m, ControllerModel::kTableTable, th, q, o);
  ASSERT_EQ(ab.sensitivity.rows(), Eigen::Index(ab.parameters.size()));
  ASSERT_EQ(ab.sensitivity.cols(), m.num_parameters());
  for (const char* name : {"EX0C", "EY0A", "EC0Y", "EB0A", "EZ0C", "tip.z"}) {
    const int i = m.RequireParameter(name);
    const double h = (name[1] == 'A' || name[1] == 'B' || name[1] == 'C') ? 1e-7 : 1e-5;
    Eigen::VectorXd up = th, down = th;
    up[i] += h;
    down[i] -= h;
    const Eigen::VectorXd fd = (Absorb(m, ControllerModel::kTableTable, up, q, o).values -
                                Absorb(m, ControllerModel::kTableTable, down, q, o).values) /
                               (2 * h);
    const double scale = std::max(1.0, fd.cwiseAbs().maxCoeff());
    // Gauss-Newton's linearisation: exact for errors the model represents,
    // to the residual's second-order term otherwise (EC0Y is not represented)
    EXPECT_LT((fd - ab.sensitivity.col(i)).cwiseAbs().maxCoeff(), 1e-3 * scale) << name;
  }
}

TEST(VendorExport, CovarianceOfTheChangeIsItsLinearPropagation) {
  const Machine m = TableTable();
  const TableVendor v;
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}, {"EY0A", 0.015}});
  const Eigen::MatrixXd q = Poses(m, 40, 5);
  const int nt = m.num_parameters();
  // a covariance on a few parameters, correlated
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(nt, nt);
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0, 1);
  for (const char* name : {"EX0C", "EY0C", "EY0A", "EZ0A", "EB0A", "EC0Y"}) {
    const int i = m.RequireParameter(name);
    const double s = (name[1] == 'B' || name[1] == 'C') ? 5e-6 : 3e-3;
    for (const char* other : {"EX0C", "EY0C", "EY0A", "EZ0A", "EB0A", "EC0Y"})
      L(i, m.RequireParameter(other)) = (other == std::string(name) ? 1.0 : 0.3 * g(rng)) * s;
  }
  const Eigen::MatrixXd cov = L * L.transpose();
  const VendorExport ex = ExportToVendor(m, v, th, cov, q, {});
  // by definition: the change as a function of theta, differentiated numerically
  const auto change = [&](const Eigen::VectorXd& t) { return ExportToVendor(m, v, t, Eigen::MatrixXd(), q, {}).change; };
  Eigen::MatrixXd D(ex.change.size(), nt);
  for (int i = 0; i < nt; ++i) {
    Eigen::VectorXd up = th, down = th;
    const double h = 1e-6;
    up[i] += h;
    down[i] -= h;
    D.col(i) = (change(up) - change(down)) / (2 * h);
  }
  const Eigen::MatrixXd want = D * cov * D.transpose();
  EXPECT_LT((ex.covariance - want).cwiseAbs().maxCoeff(), 1e-6 * want.cwiseAbs().maxCoeff());
  EXPECT_EQ(ex.sigma[0], 0.0);  // the code is not uncertain
  EXPECT_GT(ex.sigma.maxCoeff(), 0.0);
  // the absorbed fivecal parameters' covariance is the same propagation
  const Eigen::MatrixXd ac = AbsorbedCovariance(ex, cov);
  EXPECT_EQ(ac.rows(), nt);
  EXPECT_GE(ac.diagonal().minCoeff(), -1e-18);
}

// One registration style: the registry lists each vendor class's one
// instance, by the name and title the class states.
TEST(VendorExport, TheRegistryListsEachVendorsOneInstance) {
  const std::vector<const ControllerVendor*> want = {&FanucVendor::Instance(), &SiemensVendor::Instance(),
                                                     &HeidenhainVendor::Instance(), &BeckhoffVendor::Instance()};
  EXPECT_EQ(ControllerVendors(), want);
  for (const ControllerVendor* v : want) EXPECT_EQ(&FindVendor(v->Name()), v);
  EXPECT_EQ(FindVendor("heidenhain").Name(), HeidenhainVendor::kName);
  EXPECT_EQ(FindVendor("beckhoff").Title(), std::string(BeckhoffVendor::kTitle));
}

// The tool offset reaches a vendor that holds the tool length along the
// spindle only (an offset across it is the stylus's), with its covariance
// projected the same way; a vendor without a tool length takes none of it.
TEST(VendorExport, ToolOffsetGoesInAlongTheSpindleOnly) {
  const Machine m = Machine::FromJson(R"({"name": "th", "topology": "wCfXYZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0,0,-1], "point": [-30,20,0]},
    "X": {"type": "linear", "direction": [1,0,0]}, "Y": {"type": "linear", "direction": [0,1,0]},
    "Z": {"type": "linear", "direction": [0,0,1]},
    "B": {"type": "rotary", "direction": [0,1,0], "point": [0,0,250]},
    "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,20]}})");
  const ControllerVendor& h = FindVendor("heidenhain");
  const VendorOptions o = {{"table-axis-sign", "iso"}, {"tool-length", "100"}};
  const Eigen::MatrixXd q = Poses(m, 80, 21);
  const int nt = m.num_parameters(), tip = m.tip_index();
  const Eigen::VectorXd along = Theta(m, {{"EX0C", 0.01}, {"tip.z", 0.04}});
  const Eigen::VectorXd all = Theta(m, {{"EX0C", 0.01}, {"tip.x", 0.03}, {"tip.y", -0.02}, {"tip.z", 0.04}});
  const Eigen::VectorXd none = Theta(m, {{"EX0C", 0.01}});
  const VendorExport a = ExportToVendor(m, h, along, Eigen::MatrixXd(), q, o);
  const VendorExport b = ExportToVendor(m, h, all, Eigen::MatrixXd(), q, o);
  const VendorExport c = ExportToVendor(m, h, none, Eigen::MatrixXd(), q, o);
  EXPECT_LT((a.change - b.change).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_GT((a.change - c.change).cwiseAbs().maxCoeff(), 0.039);  // the 40 um tool length is in the values
  EXPECT_LT(a.absorption.max, 1e-9);
  // covariance: tip.x alone gives no sigma; tip.z alone gives its own
  Eigen::MatrixXd cx = Eigen::MatrixXd::Zero(nt, nt), cz = cx;
  cx(tip, tip) = 1e-4;
  cz(tip + 2, tip + 2) = 1e-4;
  EXPECT_LT(ExportToVendor(m, h, along, cx, q, o).sigma.maxCoeff(), 1e-12);
  EXPECT_NEAR(ExportToVendor(m, h, along, cz, q, o).sigma.maxCoeff(), 1e-2, 1e-6);
  // Siemens keeps no tool length (tool data): the tool offset changes nothing
  const ControllerVendor& s = FindVendor("siemens");
  const VendorOptions so = {{"record", "1"}};
  EXPECT_LT((ExportToVendor(m, s, all, Eigen::MatrixXd(), q, so).change -
             ExportToVendor(m, s, none, Eigen::MatrixXd(), q, so).change).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(VendorExport, RefusesWhatItCannotUse) {
  const Machine m = TableTable();
  const TableVendor v;
  const Eigen::VectorXd th = Theta(m, {{"EX0C", 0.02}});
  const Eigen::MatrixXd q = Poses(m, 20, 5);
  const auto message = [](const std::function<void()>& f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  EXPECT_NE(message([&] { ExportToVendor(m, v, th, Eigen::MatrixXd::Identity(3, 3), q, {}); }).find("covariance"),
            std::string::npos);
  EXPECT_NE(message([&] { ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {{"sign", "+"}}); }).find("sign"),
            std::string::npos);
  EXPECT_NE(message([&] { ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {}, Eigen::VectorXd::Zero(2)); })
                .find("old values"),
            std::string::npos);
  Eigen::VectorXd old = ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {}).old_values;
  old[0] = 3;  // another topology's code: not this machine
  EXPECT_NE(message([&] { ExportToVendor(m, v, th, Eigen::MatrixXd(), q, {}, old); }).find("type"),
            std::string::npos);
  EXPECT_NE(message([&] { FindVendor("no-such-controller"); }).find("no-such-controller"), std::string::npos);
}

}  // namespace
}  // namespace controllers
}  // namespace fivecal
