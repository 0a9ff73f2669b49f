#include "fivecal/procedures/rtest.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/procedures/sphere_check.h"

namespace fivecal {

std::vector<std::string> RTestLocationErrors(const Machine& m) {
  std::vector<std::string> out;
  for (char a : CheckedRotaryAxes(m))
    for (const std::string& n : PivotParameters(m, a, false)) out.push_back(n);
  return out;
}

RTestRoles RTestAxisRoles(const Machine& m) {
  const std::vector<char> rot = CheckedRotaryAxes(m);
  if (rot.size() != 2) {
    std::string names;
    for (char a : rot) names += std::string(names.empty() ? "" : ", ") + a;
    throw std::invalid_argument("R-test K tests: machine '" + m.name() + "' has " + std::to_string(rot.size()) +
                                " rotary axes (" + (names.empty() ? "none" : names) +
                                "); the tests are defined for two");
  }
  const double z0 = std::abs(m.axis(m.AxisIndex(rot[0])).direction.z());
  const double z1 = std::abs(m.axis(m.AxisIndex(rot[1])).direction.z());
  RTestRoles r;
  r.turn = z1 > z0 ? rot[1] : rot[0];
  r.tilt = r.turn == rot[0] ? rot[1] : rot[0];
  return r;
}

namespace {

// start, start + step, ... up to stop + 1e-9 (numpy's arange(start, stop + 1e-9, step))
std::vector<double> Range(double start, double stop, double step) {
  const double end = stop + 1e-9;
  const long n = std::max(0L, static_cast<long>(std::ceil((end - start) / step)));
  const double delta = (start + step) - start;
  std::vector<double> out(n);
  for (long i = 0; i < n; ++i) out[i] = start + i * delta;
  return out;
}

}  // namespace

Eigen::MatrixXd RTestSequence(const Machine& m, const std::string& test, double step, double tilt,
                              double tilt_min, double tilt_max) {
  const double min_step = 360.0 / 100000;
  if (!(std::isfinite(step) && step >= min_step))
    throw std::invalid_argument("step: " + std::to_string(step) + " deg; expected a number >= 0.0036 deg (at most "
                                "100000 samples a turn)");
  if (!std::isfinite(tilt)) throw std::invalid_argument("tilt: not a finite angle");
  if (!(std::isfinite(tilt_min) && std::isfinite(tilt_max) && tilt_min <= tilt_max))
    throw std::invalid_argument("tilt_range: (" + std::to_string(tilt_min) + ", " + std::to_string(tilt_max) +
                                ") is not a range of degrees");
  if (test != "K1" && test != "K2" && test != "K3" && test != "K4")
    throw std::invalid_argument("test: '" + test + "' is not an R-test K test (tests: K1, K2, K3, K4)");
  RTestAxisRoles(m);  // two rotary axes, or a clear refusal
  const std::vector<double> v = test == "K2" ? Range(tilt_min, tilt_max, step) : Range(0.0, 360.0, step);
  Eigen::MatrixXd out(v.size(), 2);
  for (size_t i = 0; i < v.size(); ++i) {
    if (test == "K1") out.row(i) << v[i], 0.0;
    if (test == "K2") out.row(i) << 0.0, v[i];
    if (test == "K3") out.row(i) << v[i], tilt;
    if (test == "K4") out.row(i) << v[i], tilt * std::sin(v[i] * (M_PI / 180.0));
  }
  return out;
}

RTestResult EvaluateRTest(const Dataset& given_ds, const RTestOptions& options) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  for (size_t i = 0; i < options.estimate.size(); ++i)
    if (options.estimate[i].empty())
      throw std::invalid_argument("estimate[" + std::to_string(i) + "]: an empty parameter name");
  RTestResult out;
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation& o = ds.observations[i];
    if (o.type != ObservationType::kBall3d) continue;
    const std::string name = o.setup.empty() ? "(no setup)" : o.setup;
    RTestGroup* g = nullptr;
    for (RTestGroup& t : out.tests)
      if (t.name == name) g = &t;
    if (!g) {
      out.tests.emplace_back();
      g = &out.tests.back();
      g->name = name;
    }
    g->observations.push_back(static_cast<int>(i));
  }
  if (out.tests.empty()) throw std::invalid_argument("R-test: the dataset has no ball3d observations");
  for (RTestGroup& g : out.tests) {
    g.deviations.resize(g.observations.size(), 3);
    for (size_t k = 0; k < g.observations.size(); ++k)
      g.deviations.row(k) = ds.observations[g.observations[k]].data<BallMountData>().measured.transpose();
    g.ranges = (g.deviations.colwise().maxCoeff() - g.deviations.colwise().minCoeff()).transpose();
  }
  if (options.identify) {
    out.estimated = options.estimate.empty() ? RTestLocationErrors(ds.machine()) : options.estimate;
    IdentifyOptions io;
    io.estimate = out.estimated;
    out.fit = Identify(ds, io);
    out.identified = true;
  }
  return out;
}

Eigen::MatrixXd RTestPathCommands(const Machine& m, const Eigen::MatrixXd& rotary, const Eigen::VectorXd& start,
                                  const Eigen::Vector3d& table_ball, const Eigen::Vector3d& tool_ball, bool chain) {
  const int na = m.num_axes();
  if (rotary.cols() != na)
    throw std::invalid_argument("rotary: " + std::to_string(rotary.cols()) + " columns, the machine has " +
                                std::to_string(na) + " axes");
  if (start.size() != na)
    throw std::invalid_argument("start: " + std::to_string(start.size()) + " values, the machine has " +
                                std::to_string(na) + " axes");
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(table_ball[k])) throw std::invalid_argument("table_ball: not finite");
    if (!std::isfinite(tool_ball[k])) throw std::invalid_argument("tool_ball: not finite");
  }
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::MatrixXd out(rotary.rows(), na);
  Eigen::VectorXd from = start;
  for (Eigen::Index i = 0; i < rotary.rows(); ++i) {
    RowMatrixXd q = from.transpose();
    for (int k = 0; k < na; ++k)
      if (m.axis(k).rotary() && m.axis(k).name != 'S') q(0, k) = rotary(i, k);
    double tip[3], ball[3];
    ToolPosesRowMajor(m, theta, q, nullptr, tip, nullptr);
    ToolPosesRowMajor(m, theta, q, nullptr, ball, nullptr, &tool_ball);
    Eigen::MatrixXd target(1, 3);
    for (int c = 0; c < 3; ++c) target(0, c) = table_ball[c] + (tip[c] - ball[c]);
    const Eigen::VectorXd q0 = q.row(0).transpose();
    out.row(i) = InverseKinematics(m, theta, target, nullptr, q0).row(0);
    for (int k = 0; k < na; ++k)
      if (m.axis(k).rotary() && m.axis(k).name != 'S') out(i, k) = rotary(i, k);
    if (chain) from = out.row(i).transpose();
  }
  return out;
}

}  // namespace fivecal
