#include "fivecal/controllers/linuxcnc_5axis.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace fivecal {
namespace controllers {

namespace {

constexpr double kDeg = M_PI / 180.0;
const char* const kWhat = "model 5axiskins: ";

int Position(const std::vector<int>& chain, int axis) {
  for (size_t k = 0; k < chain.size(); ++k)
    if (chain[k] == axis) return int(k);
  return -1;
}

}  // namespace

FiveAxisMapping MatchFiveAxis(const Machine& m) {
  std::vector<int> rot;
  for (int i = 0; i < m.num_axes(); ++i)
    if (m.axis(i).rotary() && m.axis(i).name != 'S') rot.push_back(i);
  const int ib = m.AxisIndex('B'), ic = m.AxisIndex('C');
  bool fits = rot.size() == 2 && ib >= 0 && ic >= 0 && m.axis(ib).rotary() && m.axis(ic).rotary();
  for (int i : rot) fits = fits && m.on_tool_side(i);
  if (!fits)
    throw std::invalid_argument(std::string(kWhat) + "machine '" + m.name() + "' (" + m.topology() +
                                ") needs a spindle head with C and, on it, B (topology like w X Y f Z C B S t)");
  if (Position(m.tool_chain(), ic) > Position(m.tool_chain(), ib))
    throw std::invalid_argument(std::string(kWhat) +
                                "C must carry B (C nearer the foundation in the tool chain)");
  const Eigen::Vector3d& uc = m.axis(ic).direction;
  const Eigen::Vector3d& ub = m.axis(ib).direction;
  if (std::abs(std::abs(uc.z()) - 1) > 1e-9 || std::abs(std::abs(ub.y()) - 1) > 1e-9)
    throw std::invalid_argument(std::string(kWhat) + "C must be along +-z and B along +-y");
  const Eigen::Vector3d& pc = m.axis(ic).point;
  const Eigen::Vector3d& pb = m.axis(ib).point;
  const Eigen::Vector3d& tip = m.tip();
  if (std::abs(pb.x() - pc.x()) > 1e-9 || std::abs(pb.y() - pc.y()) > 1e-9 ||
      std::abs(tip.x() - pc.x()) > 1e-9 || std::abs(tip.y() - pc.y()) > 1e-9)
    throw std::invalid_argument(std::string(kWhat) +
                                "B must cross the C axis and the tool tip lie on it (5axiskins has a "
                                "single pivot and pivot-length only)");
  FiveAxisMapping map;
  const char* letters = "XYZ";
  for (int k = 0; k < 3; ++k) {
    const int i = m.AxisIndex(letters[k]);
    if (i < 0)
      throw std::invalid_argument(std::string(kWhat) + "machine '" + m.name() + "' has no axis " +
                                  std::string(1, letters[k]));
    const double s = m.axis(i).direction[k];
    if (m.axis(i).rotary() || std::abs(std::abs(s) - 1) > 1e-9)
      throw std::invalid_argument(std::string(kWhat) + "axis " + std::string(1, letters[k]) +
                                  " is not along " + std::string(1, "xyz"[k]));
    map.axis[k] = i;
    map.sign[k] = m.on_tool_side(i) ? s : -s;
  }
  map.axis[3] = ib;
  map.axis[4] = ic;
  map.sign[3] = ub.y() > 0 ? -1.0 : 1.0;
  map.sign[4] = uc.z() > 0 ? 1.0 : -1.0;
  map.pivot_length = pb.z() - tip.z();
  map.origin = tip;
  return map;
}

// Transcribed from 5axiskins.c (s2r(pivot_length, C, 180 - B) plus the pivot
// above the tip) term by term, as linuxcnc_trt.cc does trtfuncs.c.
Eigen::MatrixXd FiveAxisForward(double L, const Eigen::MatrixXd& j) {
  if (j.cols() != 5)
    throw std::invalid_argument("joints: expected N x 5 (X Y Z B C), got " + std::to_string(j.cols()) +
                                " columns");
  Eigen::MatrixXd w(j.rows(), 3);
  for (Eigen::Index i = 0; i < j.rows(); ++i) {
    const double b = j(i, 3) * kDeg, c = j(i, 4) * kDeg;
    const double p = 180.0 * kDeg - b;
    w(i, 0) = j(i, 0) + L * std::sin(p) * std::cos(c);
    w(i, 1) = j(i, 1) + L * std::sin(p) * std::sin(c);
    w(i, 2) = j(i, 2) + L * std::cos(p) + L;
  }
  return w;
}

Eigen::MatrixXd FiveAxisInverse(double L, const Eigen::MatrixXd& world) {
  if (world.cols() != 5)
    throw std::invalid_argument("world: expected N x 5 (X Y Z B C), got " + std::to_string(world.cols()) +
                                " columns");
  Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(world.rows(), 5);
  zero.rightCols<2>() = world.rightCols<2>();
  Eigen::MatrixXd j = world;
  j.leftCols<3>() = world.leftCols<3>() - FiveAxisForward(L, zero);
  return j;
}

Eigen::MatrixXd FiveAxisJoints(const Machine& m, const FiveAxisMapping& map, const Eigen::MatrixXd& q) {
  if (q.cols() != m.num_axes())
    throw std::invalid_argument("poses: " + std::to_string(q.cols()) + " columns, machine has " +
                                std::to_string(m.num_axes()) + " axes");
  Eigen::MatrixXd j(q.rows(), 5);
  for (int k = 0; k < 5; ++k) j.col(k) = map.sign[k] * q.col(map.axis[k]);
  return j;
}

}  // namespace controllers
}  // namespace fivecal
