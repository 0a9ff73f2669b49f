#include "fivecal/procedures/machining_test.h"

#include <ceres/ceres.h>
#include <ceres/dynamic_autodiff_cost_function.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include "fivecal/solve/identifiability.h"
#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

const char* kSetup[6] = {"workpiece.x", "workpiece.y", "workpiece.z",
                         "workpiece.a", "workpiece.b", "workpiece.c"};

// One cut of a test: internal commands and the sensitive direction brought
// into the workpiece frame, n = R0^T r, with its sign in the difference.
struct Cut {
  std::vector<double> q;
  std::vector<int> dir;
  Eigen::Vector3d n;
  double sign = 1.0;
};

struct PreparedTest {
  Eigen::Vector3d point;
  std::vector<Cut> cuts;
  double measured = 0;
};

// Full parameter vector: machine theta, then the six workpiece set-up values.
int SetupIndex(const Machine& m, const std::string& name) {
  for (int i = 0; i < 6; ++i)
    if (name == kSetup[i]) return m.num_parameters() + i;
  return -1;
}

int RequireIndex(const Machine& m, const std::string& name) {
  const int s = SetupIndex(m, name);
  if (s >= 0) return s;
  const int i = m.ParameterIndex(name);
  if (i < 0)
    throw std::invalid_argument("machining: unknown parameter '" + name +
                                "' (a machine parameter or workpiece.x|y|z|a|b|c)");
  return i;
}

Eigen::VectorXd FullValues(const Machine& m, const std::map<std::string, double>& values) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(m.num_parameters() + 6);
  for (const auto& [name, x] : values) {
    RequireFinite(x, "machining.values." + name);
    v[RequireIndex(m, name)] = x;
  }
  return v;
}

Eigen::VectorXd CheckedPose(const Machine& m, const Eigen::VectorXd& pose, const std::string& where) {
  if (pose.size() != m.num_axes())
    throw std::invalid_argument(where + ": expected " + std::to_string(m.num_axes()) + " axis values (" +
                                m.axis_names() + "), got " + std::to_string(pose.size()));
  for (int k = 0; k < pose.size(); ++k)
    if (m.axis(k).rotary()) RequireFinite(pose[k], where + "." + std::string(1, m.axis(k).name));
  return pose;
}

// Commands cutting W_N at the rotary pose: nominal inverse kinematics.
Eigen::VectorXd CutCommands(const Machine& m, const Eigen::Vector3d& W, const Eigen::VectorXd& pose) {
  Eigen::VectorXd start = pose;
  for (int k = 0; k < m.num_axes(); ++k)
    if (!m.axis(k).rotary()) start[k] = 0;
  const Eigen::VectorXd theta0 = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::MatrixXd target = W.transpose();
  return InverseKinematics(m, theta0, target, nullptr, start).row(0).transpose();
}

std::vector<PreparedTest> Prepare(const Machine& m, const std::vector<MachiningTest>& tests) {
  if (tests.empty()) throw std::invalid_argument("machining: no tests");
  const Eigen::VectorXd theta0 = Eigen::VectorXd::Zero(m.num_parameters());
  std::vector<PreparedTest> out;
  for (size_t i = 0; i < tests.size(); ++i) {
    const MachiningTest& t = tests[i];
    const std::string w = "machining.tests[" + std::to_string(i) + "]" + (t.id.empty() ? "" : " (" + t.id + ")");
    for (int c = 0; c < 3; ++c) RequireFinite(t.point[c], w + ".point");
    const Eigen::Vector3d r = UnitDirection(t.direction, w + ".direction");
    RequireFinite(t.measured, w + ".measured");
    PreparedTest p;
    p.point = t.point;
    p.measured = t.measured;
    for (int which = 0; which < 2; ++which) {
      if (which == 1 && t.reference.size() == 0) break;
      const Eigen::VectorXd pose = CheckedPose(m, which == 0 ? t.pose : t.reference,
                                               w + (which == 0 ? ".pose" : ".reference"));
      const Eigen::VectorXd cmd = CutCommands(m, t.point, pose);
      Cut c;
      c.q.resize(m.num_axes());
      AxisValuesToInternal(m, cmd.data(), c.q.data());
      c.dir.assign(m.num_axes(), 0);
      Eigen::Vector3d p_last;
      const Frame<double> Fw = ChainFrame<double>(m, m.workpiece_chain(), theta0.data(), c.q.data(), nullptr, &p_last);
      c.n = Fw.R.transpose() * r;
      c.sign = which == 0 ? 1.0 : -1.0;
      p.cuts.push_back(c);
    }
    out.push_back(p);
  }
  return out;
}

// e = sum over cuts of sign * n . (W - P),  W = d + Rz(c) Ry(b) Rx(a) W_N.
template <typename T>
T MachiningError(const Machine& m, const PreparedTest& t, const T* all) {
  const int np = m.num_parameters();
  const T* s = all + np;
  const Vec3<T> W = Vec3<T>(s[0], s[1], s[2]) + RotZYX(s[3], s[4], s[5]) * t.point.template cast<T>();
  const Vec3<T> tip = TipWithOffsets<T>(m, all);
  T e(0.0);
  for (const Cut& c : t.cuts) {
    Vec3<T> P;
    ToolInWorkpiece<T>(m, all, c.q.data(), c.dir.data(), tip, &P);
    e += c.sign * c.n.template cast<T>().dot(W - P);
  }
  return e;
}

// Residual of one machining test over the estimated parameters (one block):
//
//   r = e(pose) - e(reference) - measured
//   e(q) = n(q) . (W - P(q)),  n = R0(q)^T r_F,  W = d + R(a,b,c) W_N,
//   P(q) = inv(T_fw(q)) T_ft(q) 0 (workpiece frame; kinematics.h).
//
// Fixed parameters are constants held by the functor.
class MachiningTestResidual {
 public:
  MachiningTestResidual(const Machine& m, PreparedTest test, Eigen::VectorXd fixed, std::vector<int> estimated)
      : machine_(m), test_(std::move(test)), fixed_(std::move(fixed)), estimated_(std::move(estimated)) {}

  template <typename T>
  bool operator()(T const* const* p, T* residual) const {
    std::vector<T> all(fixed_.size());
    for (int i = 0; i < fixed_.size(); ++i) all[i] = T(fixed_[i]);
    for (size_t k = 0; k < estimated_.size(); ++k) all[estimated_[k]] = p[0][k];
    residual[0] = MachiningError<T>(machine_, test_, all.data()) - T(test_.measured);
    return true;
  }

  static ceres::CostFunction* Create(const Machine& m, const PreparedTest& test, const Eigen::VectorXd& fixed,
                                     const std::vector<int>& estimated) {
    auto* f = new ceres::DynamicAutoDiffCostFunction<MachiningTestResidual, 4>(
        new MachiningTestResidual(m, test, fixed, estimated));
    f->AddParameterBlock(static_cast<int>(estimated.size()));
    f->SetNumResiduals(1);
    return f;
  }

 private:
  const Machine& machine_;
  const PreparedTest test_;
  const Eigen::VectorXd fixed_;
  const std::vector<int> estimated_;
};

Eigen::MatrixXd DenseJacobian(ceres::Problem& problem, Eigen::VectorXd* residuals) {
  double cost = 0;
  std::vector<double> r;
  ceres::CRSMatrix crs;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, &r, nullptr, &crs);
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int i = 0; i < crs.num_rows; ++i)
    for (int k = crs.rows[i]; k < crs.rows[i + 1]; ++k) J(i, crs.cols[k]) = crs.values[k];
  if (residuals) *residuals = Eigen::Map<Eigen::VectorXd>(r.data(), r.size());
  return J;
}

}  // namespace

std::vector<std::string> WorkpieceSetupNames() { return std::vector<std::string>(kSetup, kSetup + 6); }

std::vector<MachiningTest> ZhangZhangTests(const Machine& m, double L, double H) {
  RequireFinite(L, "zhang_zhang_tests.L");
  RequireFinite(H, "zhang_zhang_tests.H");
  const int a = m.AxisIndex('A'), c = m.AxisIndex('C');
  if (a < 0 || c < 0 || !m.axis(a).rotary() || !m.axis(c).rotary())
    throw std::invalid_argument("zhang_zhang_tests: machine '" + m.name() + "' needs rotary axes A and C (axes " +
                                m.axis_names() + ")");
  const Eigen::Vector3d ua = m.axis(a).direction, uc = m.axis(c).direction;
  if (std::abs(std::abs(ua.x()) - 1.0) > 1e-9)
    throw std::invalid_argument("zhang_zhang_tests: the A axis must lie along +-X at the zero pose");
  if (std::abs(std::abs(uc.z()) - 1.0) > 1e-9)
    throw std::invalid_argument("zhang_zhang_tests: the C axis must lie along +-Z at the zero pose");
  const double sa = ua.x() > 0 ? 1.0 : -1.0, sc = uc.z() > 0 ? 1.0 : -1.0;
  auto pose = [&](double alpha, double gamma) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_axes());
    q[a] = sa * alpha + 0.0;  // Rot(-u, -q) = Rot(u, q); + 0.0: no -0
    q[c] = sc * gamma + 0.0;
    return q;
  };
  const Eigen::Vector3d W(0.0, L, H);
  std::vector<MachiningTest> t(3);
  t[0] = {"T1", W, Eigen::Vector3d(0, -1, 0), pose(90, 180), pose(90, 0), 0.0};
  t[1] = {"T2", W, Eigen::Vector3d(0, 0, 1), pose(90, 180), pose(0, 0), 0.0};
  t[2] = {"T3", W, Eigen::Vector3d(0, -1, 0), pose(90, 180), pose(0, 0), 0.0};
  return t;
}

Eigen::Vector3d ZhangZhangFirstOrder(double L, double H, const Eigen::Vector3d& Ad, const Eigen::Vector3d& Ax,
                                     const Eigen::Vector3d& Cd, const Eigen::Vector3d& Cx) {
  return Eigen::Vector3d(-2 * Ax[0] * (Cd[1] + L) + 2 * Ax[1] * Cd[0],
                         Ad[1] - Ad[2] - Cd[1] + (H - L) * Cx[0] - (H + L) * Ax[0],
                         Ad[1] + Ad[2] + Cd[1] + Cx[0] * (L - H) - Ax[0] * (H + L));
}

Eigen::MatrixXd MachiningPoses(const Machine& m, const std::vector<MachiningTest>& tests) {
  Eigen::MatrixXd out(2 * tests.size(), m.num_axes());
  for (size_t i = 0; i < tests.size(); ++i) {
    const std::string w = "machining.tests[" + std::to_string(i) + "]";
    out.row(2 * i) = CutCommands(m, tests[i].point, CheckedPose(m, tests[i].pose, w + ".pose")).transpose();
    if (tests[i].reference.size())
      out.row(2 * i + 1) =
          CutCommands(m, tests[i].point, CheckedPose(m, tests[i].reference, w + ".reference")).transpose();
    else
      out.row(2 * i + 1).setConstant(std::numeric_limits<double>::quiet_NaN());
  }
  return out;
}

Eigen::VectorXd PredictMachining(const Machine& m, const std::vector<MachiningTest>& tests,
                                 const std::map<std::string, double>& values) {
  const std::vector<PreparedTest> prepared = Prepare(m, tests);
  const Eigen::VectorXd all = FullValues(m, values);
  Eigen::VectorXd e(prepared.size());
  for (size_t i = 0; i < prepared.size(); ++i) e[i] = MachiningError<double>(m, prepared[i], all.data());
  return e;
}

Eigen::MatrixXd MachiningJacobian(const Machine& m, const std::vector<MachiningTest>& tests,
                                  const std::vector<std::string>& names,
                                  const std::map<std::string, double>& values) {
  const std::vector<PreparedTest> prepared = Prepare(m, tests);
  const Eigen::VectorXd all = FullValues(m, values);
  if (names.empty()) throw std::invalid_argument("machining_jacobian: no parameter names");
  std::vector<int> est;
  for (const std::string& n : names) {
    const int i = RequireIndex(m, n);
    if (std::find(est.begin(), est.end(), i) != est.end())
      throw std::invalid_argument("machining_jacobian: '" + n + "' named twice");
    est.push_back(i);
  }
  std::vector<double> x(est.size());
  for (size_t i = 0; i < est.size(); ++i) x[i] = all[est[i]];
  ceres::Problem problem;
  for (const PreparedTest& t : prepared)
    problem.AddResidualBlock(MachiningTestResidual::Create(m, t, all, est), nullptr, x.data());
  return DenseJacobian(problem, nullptr);
}

std::string MachiningResult::ToJson() const {
  json j;
  json p = json::object();
  for (size_t i = 0; i < estimated.size(); ++i)
    p[estimated[i]] = {{"value", values[i]}, {"std", std::isfinite(std[i]) ? json(std[i]) : json(nullptr)}};
  j["parameters"] = p;
  j["predicted"] = std::vector<double>(predicted.data(), predicted.data() + predicted.size());
  j["residuals"] = std::vector<double>(residuals.data(), residuals.data() + residuals.size());
  j["sigma"] = std::isfinite(sigma) ? json(sigma) : json(nullptr);
  j["condition_number"] = std::isfinite(condition_number) ? json(condition_number) : json(nullptr);
  j["rank"] = rank;
  j["converged"] = converged;
  j["iterations"] = iterations;
  return j.dump();
}

MachiningResult IdentifyMachining(const Machine& m, const std::vector<MachiningTest>& tests,
                                  const MachiningOptions& opt) {
  const std::vector<PreparedTest> prepared = Prepare(m, tests);
  if (opt.estimate.empty()) throw std::invalid_argument("machining: nothing to estimate");
  if (!(opt.sigma >= 0) || !std::isfinite(opt.sigma)) throw std::invalid_argument("machining: sigma must be >= 0 mm");
  const Eigen::VectorXd all = FullValues(m, opt.values);
  std::vector<int> est;
  for (const std::string& n : opt.estimate) {
    const int i = RequireIndex(m, n);
    if (std::find(est.begin(), est.end(), i) != est.end())
      throw std::invalid_argument("machining: '" + n + "' requested twice");
    est.push_back(i);
  }
  const int k = static_cast<int>(est.size());
  const int nt = static_cast<int>(prepared.size());
  if (nt < k)
    throw std::invalid_argument("machining: " + std::to_string(k) + " parameters but only " + std::to_string(nt) +
                                " machining tests");
  std::vector<double> x(k);
  for (int i = 0; i < k; ++i) x[i] = all[est[i]];

  ceres::Problem problem;
  for (const PreparedTest& t : prepared)
    problem.AddResidualBlock(MachiningTestResidual::Create(m, t, all, est), nullptr, x.data());

  MachiningResult res;
  res.estimated = opt.estimate;
  {
    const Identifiability id = AnalyzeJacobian(DenseJacobian(problem, nullptr), opt.rank_tolerance);
    if (id.rank < k) {
      std::string msg = "machining: the tests cannot identify the requested parameters (rank " +
                        std::to_string(id.rank) + " of " + std::to_string(k) + "); confounded: ";
      for (size_t g = 0; g < id.confounded.size(); ++g) {
        msg += g ? "; {" : "{";
        for (size_t c = 0; c < id.confounded[g].size(); ++c)
          msg += (c ? ", " : "") + opt.estimate[id.confounded[g][c]];
        msg += "}";
      }
      throw std::invalid_argument(msg);
    }
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = 1e-16;
  so.gradient_tolerance = 1e-20;
  so.parameter_tolerance = 1e-14;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  res.converged = summary.termination_type == ceres::CONVERGENCE;
  res.iterations = static_cast<int>(summary.iterations.size()) - 1;

  Eigen::VectorXd r;
  const Eigen::MatrixXd J = DenseJacobian(problem, &r);
  const Identifiability id = AnalyzeJacobian(J, opt.rank_tolerance);
  res.condition_number = id.condition_number;
  res.rank = id.rank;
  res.values = Eigen::Map<Eigen::VectorXd>(x.data(), k);
  res.residuals = r;
  Eigen::VectorXd measured(nt);
  for (int i = 0; i < nt; ++i) measured[i] = prepared[i].measured;
  res.predicted = r + measured;
  if (opt.sigma > 0) res.sigma = opt.sigma;
  else if (nt > k) res.sigma = std::sqrt(r.squaredNorm() / (nt - k));
  else res.sigma = std::numeric_limits<double>::quiet_NaN();
  res.covariance = res.sigma * res.sigma * id.inverse_normal;
  res.std = res.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  return res;
}

}  // namespace fivecal
