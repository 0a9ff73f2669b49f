#include "fivecal/controllers/linuxcnc_trt.h"

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "fivecal/model/kinematics.h"

namespace fivecal {
namespace controllers {

namespace {

constexpr double kDeg = M_PI / 180.0;

std::string Vec(const Eigen::Vector3d& v) {
  char b[96];
  std::snprintf(b, sizeof b, "[%g, %g, %g]", v.x(), v.y(), v.z());
  return b;
}

// +1 / -1 when u is (within 1e-9) +e / -e, 0 otherwise.
double BasisSign(const Eigen::Vector3d& u, int i) {
  if (std::abs(std::abs(u[i]) - 1.0) > 1e-9) return 0.0;
  return u[i] > 0 ? 1.0 : -1.0;
}

}  // namespace

TrtKins ParseTrtKins(const std::string& name) {
  std::string n = name;
  const std::string suffix = "-kins";
  if (n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0)
    n.resize(n.size() - suffix.size());
  if (n == "xyzac-trt") return TrtKins::kXyzac;
  if (n == "xyzbc-trt") return TrtKins::kXyzbc;
  throw std::invalid_argument("kins: '" + name + "' (expected xyzac-trt or xyzbc-trt)");
}

std::string TrtKinsName(TrtKins kins) {
  return kins == TrtKins::kXyzac ? "xyzac-trt" : "xyzbc-trt";
}

std::vector<std::string> TrtPinNames(TrtKins kins) {
  if (kins == TrtKins::kXyzac)
    return {"x-rot-point", "y-rot-point", "z-rot-point", "y-offset", "z-offset", "tool-offset"};
  return {"x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "z-offset", "tool-offset"};
}

double& TrtPin(TrtPins& p, const std::string& name) {
  if (name == "x-rot-point") return p.x_rot_point;
  if (name == "y-rot-point") return p.y_rot_point;
  if (name == "z-rot-point") return p.z_rot_point;
  if (name == "x-offset") return p.x_offset;
  if (name == "y-offset") return p.y_offset;
  if (name == "z-offset") return p.z_offset;
  if (name == "tool-offset") return p.tool_offset;
  throw std::invalid_argument("pins: unknown pin '" + name +
                              "' (x|y|z-rot-point, x|y|z-offset, tool-offset)");
}

double TrtPin(const TrtPins& p, const std::string& name) {
  return TrtPin(const_cast<TrtPins&>(p), name);
}

// Transcribed from trtfuncs.c (LinuxCNC 2.9.0~pre1, git f1270d6ed7), term by
// term, so a difference to LinuxCNC shows up as a failing round trip rather
// than hiding in an algebraic rewrite.
Eigen::Vector3d TrtForward(TrtKins kins, const TrtPins& p, const Eigen::Matrix<double, 5, 1>& j) {
  const double xr = p.x_rot_point, yr = p.y_rot_point, zr = p.z_rot_point;
  const double dz = p.z_offset + p.tool_offset;
  const double t = j[3] * kDeg, c = j[4] * kDeg;
  const double X = j[0], Y = j[1], Z = j[2];
  Eigen::Vector3d w;
  if (kins == TrtKins::kXyzac) {
    const double dy = p.y_offset, a = t;
    w.x() = +std::cos(c) * (X - xr) + std::sin(c) * std::cos(a) * (Y - dy - yr) +
            std::sin(c) * std::sin(a) * (Z - dz - zr) + std::sin(c) * dy + xr;
    w.y() = -std::sin(c) * (X - xr) + std::cos(c) * std::cos(a) * (Y - dy - yr) +
            std::cos(c) * std::sin(a) * (Z - dz - zr) + std::cos(c) * dy + yr;
    w.z() = -std::sin(a) * (Y - dy - yr) + std::cos(a) * (Z - dz - zr) + dz + zr;
  } else {
    const double dx = p.x_offset, b = t;
    w.x() = std::cos(c) * std::cos(b) * (X - dx - xr) + std::sin(c) * (Y - yr) -
            std::cos(c) * std::sin(b) * (Z - dz - zr) + std::cos(c) * dx + xr;
    w.y() = -std::sin(c) * std::cos(b) * (X - dx - xr) + std::cos(c) * (Y - yr) +
            std::sin(c) * std::sin(b) * (Z - dz - zr) - std::sin(c) * dx + yr;
    w.z() = std::sin(b) * (X - dx - xr) + std::cos(b) * (Z - dz - zr) + dz + zr;
  }
  return w;
}

Eigen::Vector3d TrtInverse(TrtKins kins, const TrtPins& p, const Eigen::Vector3d& w, double t_deg,
                           double c_deg) {
  const double xr = p.x_rot_point, yr = p.y_rot_point, zr = p.z_rot_point;
  const double dz = p.z_offset + p.tool_offset;
  const double t = t_deg * kDeg, c = c_deg * kDeg;
  const double x = w.x() - xr, y = w.y() - yr, z = w.z() - zr;
  Eigen::Vector3d J;
  if (kins == TrtKins::kXyzac) {
    const double dy = p.y_offset, a = t;
    J.x() = std::cos(c) * x - std::sin(c) * y + xr;
    J.y() = std::sin(c) * std::cos(a) * x + std::cos(c) * std::cos(a) * y - std::sin(a) * z -
            std::cos(a) * dy + std::sin(a) * dz + dy + yr;
    J.z() = std::sin(c) * std::sin(a) * x + std::cos(c) * std::sin(a) * y + std::cos(a) * z -
            std::sin(a) * dy - std::cos(a) * dz + dz + zr;
  } else {
    const double dx = p.x_offset, b = t;
    const double dpx = -std::cos(b) * dx - std::sin(b) * dz + dx;
    const double dpz = std::sin(b) * dx - std::cos(b) * dz + dz;
    J.x() = std::cos(c) * std::cos(b) * x - std::sin(c) * std::cos(b) * y + std::sin(b) * z + dpx + xr;
    J.y() = std::sin(c) * x + std::cos(c) * y + yr;
    J.z() = -std::cos(c) * std::sin(b) * x + std::sin(c) * std::sin(b) * y + std::cos(b) * z + dpz + zr;
  }
  return J;
}

TrtMapping MatchTrt(const Machine& m, TrtKins kins) {
  const std::string kn = TrtKinsName(kins);
  const char tilt = kins == TrtKins::kXyzac ? 'A' : 'B';
  const int tilt_dir = kins == TrtKins::kXyzac ? 0 : 1;
  const std::string letters = std::string("XYZ") + tilt + "C";
  TrtMapping map;
  map.kins = kins;
  for (int i = 0; i < m.num_axes(); ++i) {
    const char n = m.axis(i).name;
    if (n != 'S' && letters.find(n) == std::string::npos)
      throw std::invalid_argument("machine '" + m.name() + "' (" + m.topology() + "): axis " +
                                  std::string(1, n) + " has no joint in LinuxCNC's " + kn +
                                  " kinematics (joints " + letters + ")");
  }
  // Workpiece chain from the foundation: linear axes first, then T, then C.
  const std::vector<int>& wc = m.workpiece_chain();
  int it = -1, ic = -1;
  for (size_t k = 0; k < wc.size(); ++k) {
    const char n = m.axis(wc[k]).name;
    if (n == tilt) it = int(k);
    if (n == 'C') ic = int(k);
  }
  if (it < 0 || ic < 0 || ic != it + 1 || ic != int(wc.size()) - 1)
    throw std::invalid_argument(
        "machine '" + m.name() + "' (" + m.topology() + "): " + kn + " needs a table carrying " +
        std::string(1, tilt) + " and, on it, C next to the workpiece (topology like w C" +
        std::string(1, tilt) + " ... f X Y Z S t)");
  for (int k = 0; k < 5; ++k) {
    const int i = m.AxisIndex(letters[k]);
    if (i < 0)
      throw std::invalid_argument("machine '" + m.name() + "': no axis " +
                                  std::string(1, letters[k]) + " for " + kn);
    const Axis& ax = m.axis(i);
    const int basis = k < 3 ? k : (k == 3 ? tilt_dir : 2);
    const double s = BasisSign(ax.direction, basis);
    if ((k < 3) == ax.rotary() || s == 0.0)
      throw std::invalid_argument(
          "machine '" + m.name() + "': axis " + std::string(1, letters[k]) + " direction " +
          Vec(ax.direction) + " is not along " + std::string(1, "xyz"[basis]) + " as " + kn +
          " requires (a misalignment belongs in the location errors, e.g. EB0C)");
    map.axis[k] = i;
    // A workpiece-side linear axis moves the table: the tool moves by -q u
    // relative to it.
    map.sign[k] = (k < 3 && !m.on_tool_side(i)) ? -s : s;
  }
  map.origin = m.tip();
  return map;
}

Eigen::MatrixXd TrtJoints(const Machine& m, const TrtMapping& map, const Eigen::MatrixXd& q) {
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("poses: " + std::to_string(q.cols()) + " columns, machine has " +
                                std::to_string(m.num_axes()) + " axes");
  Eigen::MatrixXd j(q.rows(), 5);
  for (int k = 0; k < 5; ++k) j.col(k) = map.sign[k] * q.col(map.axis[k]);
  return j;
}

Eigen::MatrixXd TrtCommands(const Machine& m, const TrtMapping& map, const Eigen::MatrixXd& j) {
  if (j.cols() != 5)
    throw std::invalid_argument("joints: " + std::to_string(j.cols()) + " columns, expected 5");
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(j.rows(), m.num_axes());
  for (int k = 0; k < 5; ++k) q.col(map.axis[k]) = map.sign[k] * j.col(k);
  return q;
}

namespace {

// Residual (N x 3) true point - (LinuxCNC world + origin) for given pins.
Eigen::MatrixXd Residual(TrtKins kins, const TrtPins& p, const Eigen::MatrixXd& joints,
                         const Eigen::MatrixXd& truth, const Eigen::Vector3d& origin) {
  Eigen::MatrixXd r(joints.rows(), 3);
  for (int i = 0; i < joints.rows(); ++i) {
    const Eigen::Matrix<double, 5, 1> j = joints.row(i).transpose();
    r.row(i) = truth.row(i) - (TrtForward(kins, p, j) + origin).transpose();
  }
  return r;
}

void Stats(const Eigen::MatrixXd& r, double* rms, double* max) {
  const Eigen::VectorXd n = r.rowwise().norm();
  *rms = n.size() ? std::sqrt(n.squaredNorm() / double(n.size())) : 0.0;
  *max = n.size() ? n.maxCoeff() : 0.0;
}

}  // namespace

TrtFit FitTrtPins(const Machine& m, TrtKins kins, const Eigen::VectorXd& theta,
                  const Eigen::MatrixXd& poses, const TrtPins& held) {
  const TrtMapping map = MatchTrt(m, kins);
  if (poses.rows() < 4)
    throw std::invalid_argument("poses: " + std::to_string(poses.rows()) +
                                " rows; the pins need at least 4 poses over the rotary ranges");
  const Eigen::MatrixXd joints = TrtJoints(m, map, poses);
  const Eigen::MatrixXd truth = ToolPoints(m, theta, poses);  // validates theta and poses

  TrtFit fit;
  fit.solved = {"x-rot-point", "y-rot-point", "z-rot-point",
                kins == TrtKins::kXyzac ? "y-offset" : "x-offset"};
  // The forward kinematics is affine in the pins: the columns of the
  // least-squares matrix are its exact differences for unit pin steps. The
  // last three unknowns are a constant shift of the workpiece frame: the
  // rotary axes' location errors carry the table (and the part on it) along,
  // which no pin represents and probing the part into the work offset does.
  const Eigen::MatrixXd r0 = Residual(kins, held, joints, truth, map.origin);
  const int n = int(joints.rows());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(3 * n, 7);
  for (int c = 0; c < 4; ++c) {
    TrtPins p = held;
    TrtPin(p, fit.solved[c]) += 1.0;
    const Eigen::MatrixXd rc = Residual(kins, p, joints, truth, map.origin);
    Eigen::MatrixXd d = r0 - rc;  // d(LinuxCNC point)/d(pin)
    for (int i = 0; i < n; ++i) A.block(3 * i, c, 3, 1) = d.row(i).transpose();
  }
  for (int i = 0; i < n; ++i) A.block(3 * i, 4, 3, 3).setIdentity();
  Eigen::VectorXd b(3 * n);
  for (int i = 0; i < n; ++i) b.segment(3 * i, 3) = r0.row(i).transpose();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  qr.setThreshold(1e-9);
  if (qr.rank() < 7)
    throw std::invalid_argument(
        "poses: the rotary angles do not determine the " + TrtKinsName(kins) +
        " pins (use at least two tilt angles and two C angles, not all 0)");
  const Eigen::VectorXd x = qr.solve(b);
  fit.pins = held;
  for (int c = 0; c < 4; ++c) TrtPin(fit.pins, fit.solved[c]) += x[c];
  fit.workpiece_shift = x.tail<3>();
  fit.residual = Residual(kins, fit.pins, joints, truth, map.origin);
  fit.residual.rowwise() -= fit.workpiece_shift.transpose();
  // The input pins with only the workpiece shift fitted (the mean residual).
  fit.workpiece_shift_held = r0.colwise().mean().transpose();
  fit.residual_held = r0;
  fit.residual_held.rowwise() -= fit.workpiece_shift_held.transpose();
  Stats(fit.residual, &fit.rms, &fit.max);
  Stats(fit.residual_held, &fit.rms_held, &fit.max_held);
  return fit;
}

}  // namespace controllers
}  // namespace fivecal
