#include "fivecal/procedures/dbb_four_step.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "fivecal/procedures/circle_fit.h"
#include "fivecal/procedures/dbb_setup.h"
#include "fivecal/model/kinematics.h"
#include "json_util.h"

namespace fivecal {
namespace {

using json_util::json;

constexpr double kPi = 3.14159265358979323846;
// Set-up checks: a spindle ball further than this from where the method needs
// it (on the axis, or straight along it for the extension) is a set-up the
// paper's equations do not describe.
constexpr double kPlacementTolerance = 1.0;  // mm

constexpr char kLinearLetters[] = "XYZ";
constexpr char kRotaryLetters[] = "ABC";

// Index 0..2 of the basis vector n is (up to sign), or -1.
int BasisIndex(const Eigen::Vector3d& d) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(std::abs(d[k]) - 1.0) < 1e-9) return k;
  return -1;
}

// Plane basis normal to the positive basis vector n, cyclic: X: Y, Z;
// Y: Z, X; Z: X, Y (the paper's A: Y, Z and C: X, Y).
void PlaneBasis(const Eigen::Vector3d& n, Eigen::Vector3d* e1, Eigen::Vector3d* e2) {
  const int k = BasisIndex(n);
  *e1 = Eigen::Vector3d::Unit((k + 1) % 3);
  *e2 = n.cross(*e1);
}

// The rotation E = Rz(c) Ry(b) Rx(a) of an axis along basis vector k, with
// its own-axis component zero, that turns e_k into the unit vector d; the
// three angles (a, b, c), the k-th zero.
Eigen::Vector3d OrientationFromDirection(int k, const Eigen::Vector3d& d) {
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
  switch (k) {
    case 0:  // Rz(c) Ry(b) e_x = (cos c cos b, sin c cos b, -sin b)
      r[1] = -std::asin(d.z());
      r[2] = std::atan2(d.y(), d.x());
      break;
    case 1:  // Rz(c) Rx(a) e_y = (-sin c cos a, cos c cos a, sin a)
      r[0] = std::asin(d.z());
      r[2] = std::atan2(-d.x(), d.y());
      break;
    default:  // Ry(b) Rx(a) e_z = (cos a sin b, -sin a, cos a cos b)
      r[0] = -std::asin(d.y());
      r[1] = std::atan2(d.x(), d.z());
      break;
  }
  return r;
}

Eigen::Vector3d InPlane(const Eigen::Vector3d& v, const Eigen::Vector3d& n) { return v - n * n.dot(v); }

// Frame of the link that carries the carrier axis, nominal, at `cmd` (F
// coordinates of a point given in that frame's zero-pose coordinates).
Frame<double> BaseFrame(const Machine& m, const FourStepPair& t, const Eigen::VectorXd& cmd,
                        Eigen::Vector3d* p_parent) {
  std::vector<double> q(m.num_axes());
  AxisValuesToInternal(m, cmd.data(), q.data());
  const Eigen::VectorXd theta = Eigen::VectorXd::Zero(m.num_parameters());
  return ChainFrame<double>(m, t.base_chain, theta.data(), q.data(), nullptr, p_parent);
}

Eigen::Vector3d ToBase(const Machine& m, const FourStepPair& t, const Eigen::VectorXd& cmd,
                       const Eigen::Vector3d& x_in_f) {
  Eigen::Vector3d p;
  const Frame<double> B = BaseFrame(m, t, cmd, &p);
  return B.inverse() * x_in_f + p;
}

// Nominal positions of the two balls in the frame carrying the pair: the
// fixed one (the spindle ball on a table pair, the table ball on a head pair)
// and the moving one (the pivot on the pair's side).
Eigen::Vector3d FixedBall(const Machine& m, const FourStepPair& t, const Eigen::VectorXd& cmd,
                          const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball) {
  return ToBase(m, t, cmd,
                t.tool_side ? NominalTableBallInF(m, cmd, table_ball) : NominalToolBallInF(m, cmd, tool_ball));
}

Eigen::Vector3d MovingBall(const Machine& m, const FourStepPair& t, const Eigen::VectorXd& cmd,
                           const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball) {
  return ToBase(m, t, cmd,
                t.tool_side ? NominalToolBallInF(m, cmd, tool_ball) : NominalTableBallInF(m, cmd, table_ball));
}

// Commands equal to `pose` except the linear axes, set so the fixed ball sits
// at `target` in the frame carrying the pair. The map is affine in the linear
// commands once the rotary axes are fixed, so one least-norm solve is exact.
Eigen::VectorXd PlaceFixedBall(const Machine& m, const FourStepPair& t, const Eigen::Vector3d& tool_ball,
                               const Eigen::Vector3d& table_ball, const Eigen::Vector3d& target,
                               const Eigen::VectorXd& pose) {
  std::vector<int> linear;
  for (int k = 0; k < m.num_axes(); ++k)
    if (!m.axis(k).rotary()) linear.push_back(k);
  Eigen::VectorXd base = pose;
  for (int k : linear) base[k] = 0.0;
  const Eigen::Vector3d s0 = FixedBall(m, t, base, tool_ball, table_ball);
  Eigen::MatrixXd J(3, linear.size());
  for (size_t j = 0; j < linear.size(); ++j) {
    Eigen::VectorXd c = base;
    c[linear[j]] = 1.0;
    J.col(j) = FixedBall(m, t, c, tool_ball, table_ball) - s0;
  }
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(J);
  cod.setThreshold(1e-9);
  if (linear.size() < 3 || cod.rank() < 3)
    throw std::invalid_argument("machine '" + m.name() + "' (" + m.topology() +
                                "): the ball bar's fixed ball cannot be placed freely relative to the "
                                "rotary axes (the linear axes span fewer than three directions)");
  const Eigen::VectorXd x = cod.solve(Eigen::Vector3d(target - s0));
  Eigen::VectorXd out = base;
  for (size_t j = 0; j < linear.size(); ++j) out[linear[j]] = x[j];
  return out;
}

std::string SetupList(const Dataset& given_ds) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  std::vector<std::string> s;
  for (const Observation& o : ds.observations)
    if (o.type == ObservationType::kDbb && std::find(s.begin(), s.end(), o.setup) == s.end())
      s.push_back(o.setup.empty() ? "(default)" : o.setup);
  std::string out;
  for (const std::string& x : s) out += (out.empty() ? "" : ", ") + x;
  return out.empty() ? "none" : out;
}

// One step: readings -> points in the plane of the axis -> circle fit.
// o_prime: the ideal rotation centre O' (the spindle ball of the step without
// the extension); null for that step itself.
FourStepStep AnalyzeStep(const Dataset& given_ds, const FourStepPair& t, const std::string& setup, bool carrier,
                         const Eigen::Vector3d* o_prime, const Eigen::Vector2d& pivot_offset,
                         const FourStepOptions& opt) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const Machine& m = ds.machine();
  const std::string w = "four-step: setup '" + setup + "'";
  FourStepStep st;
  const int moving = carrier ? t.carrier : t.carried;
  const char axis = m.axis(moving).name;
  st.setup = setup;
  st.axis = axis;
  st.extended = o_prime != nullptr;
  for (int i = 0; i < static_cast<int>(ds.observations.size()); ++i) {
    const Observation& o = ds.observations[i];
    if (o.type == ObservationType::kDbb && o.setup == setup) st.observations.push_back(i);
  }
  if (st.observations.empty())
    throw std::invalid_argument(w + ": no DBB observations (DBB setups in the dataset: " +
                                SetupList(ds) + ")");
  if (st.observations.size() < 5)
    throw std::invalid_argument(w + ": " + std::to_string(st.observations.size()) +
                                " samples; the circle fit needs at least 5");
  const Observation& o0 = ds.observations[st.observations[0]];
  for (int idx : st.observations) {
    const Observation& o = ds.observations[idx];
    const std::string wo = w + ", observation " + std::to_string(idx);
    for (int k = 0; k < m.num_axes(); ++k) {
      if (k == moving) continue;
      if (std::abs(o.axes[k] - o0.axes[k]) > 1e-9)
        throw std::invalid_argument(wo + ": axis " + std::string(1, m.axis(k).name) +
                                    " moves; only " + std::string(1, axis) + " may move in this step");
    }
    if (!carrier && std::abs(o.axes[t.carrier]) > 1e-9)
      throw std::invalid_argument(wo + ": " + std::string(1, m.axis(t.carrier).name) + " = " +
                                  std::to_string(o.axes[t.carrier]) + " deg; the " + std::string(1, axis) +
                                  " steps are run with the axis carrying " + std::string(1, axis) + " at 0");
    const BallMountData &b = o.data<BallMountData>(), &b0 = o0.data<BallMountData>();
    if ((b.tool_ball - b0.tool_ball).norm() > 1e-12 || (b.table_ball - b0.table_ball).norm() > 1e-12 ||
        b.length != b0.length)
      throw std::invalid_argument(wo + ": tool_ball, table_ball and length must be the same for "
                                  "every sample of one ball-bar mounting");
  }
  const Eigen::Vector3d n = carrier ? t.n_carrier : t.n_carried;
  PlaneBasis(n, &st.e1, &st.e2);
  st.normal = n;
  const BallMountData& mount = o0.data<BallMountData>();
  st.spindle_ball = FixedBall(m, t, o0.axes, mount.tool_ball, mount.table_ball);
  // The carried axis at carrier = 0: its zero-pose line, in the frame carrying the pair.
  const Eigen::Vector3d p_axis = m.axis(moving).point;

  Eigen::Vector3d O = st.spindle_ball;
  if (!st.extended) {
    const double off = InPlane(st.spindle_ball - p_axis, n).norm();
    if (off > kPlacementTolerance) {
      std::ostringstream s;
      s << w << ": the " << (t.tool_side ? "table" : "spindle") << " ball is " << off
        << " mm from the nominal " << axis << " axis; the method needs it on the axis (Jiang & "
        << "Cripps, Section 3.1)";
      throw std::invalid_argument(s.str());
    }
  } else {
    O = *o_prime;
    const Eigen::Vector3d d = st.spindle_ball - O;
    const double lateral = InPlane(d, n).norm();
    st.arm = d.norm();  // |S'O'| of eqs. 11, 18-19
    if (lateral > kPlacementTolerance || st.arm < 1.0) {
      std::ostringstream s;
      s << w << ": the " << (t.tool_side ? "table" : "spindle") << " ball must be moved along the "
        << axis << " axis from the step "
        << "without the extension (moved " << n.dot(d) << " mm along, " << lateral << " mm across)";
      throw std::invalid_argument(s.str());
    }
  }

  const int N = static_cast<int>(st.observations.size());
  Eigen::VectorXd theta(N);
  Eigen::Vector3d b0 = Eigen::Vector3d::Zero();
  for (int i = 0; i < N; ++i) {
    const Observation& o = ds.observations[st.observations[i]];
    const BallMountData& ball = o.data<BallMountData>();
    const Eigen::Vector3d b = MovingBall(m, t, o.axes, ball.tool_ball, ball.table_ball);
    if (i == 0) b0 = b;
    const Eigen::Vector3d rel = b - O;
    double a = std::atan2(rel.dot(st.e2), rel.dot(st.e1));
    if (i > 0) a += 2 * kPi * std::round((theta[i - 1] - a) / (2 * kPi));  // continuous sweep
    theta[i] = a;
  }
  if (opt.uniform_angles)  // eq. 2: theta_i = (i/N) theta from the first sample
    for (int i = 1; i < N; ++i) theta[i] = theta[0] + (theta[N - 1] - theta[0]) * i / (N - 1.0);

  st.nominal_radius = InPlane(b0 - O, n).norm();
  // eq. 1: i along the start position, j 90 deg ahead in the plane.
  const Eigen::Vector2d iv(std::cos(theta[0]), std::sin(theta[0])), jv(-iv.y(), iv.x());
  st.start_angle_error = std::atan2(pivot_offset.dot(jv), pivot_offset.dot(iv) + st.nominal_radius);
  st.angles = theta.array() + st.start_angle_error;

  auto it = opt.length_offsets.find(setup);
  const double offset = it == opt.length_offsets.end() ? 0.0 : it->second;
  st.points.resize(N, 2);
  for (int i = 0; i < N; ++i) {
    const double L = mount.length + offset + ds.observations[st.observations[i]].data<BallMountData>().reading;
    double r = L;  // eqs. 3-4: R_n + d_i
    if (st.extended) {
      if (!(L > st.arm))
        throw std::invalid_argument(w + ": bar length " + std::to_string(L) +
                                    " mm is shorter than |S'O'| = " + std::to_string(st.arm) + " mm");
      r = std::sqrt(L * L - st.arm * st.arm);  // eq. 11: EP_i^2 = S'P_i^2 - S'E^2, S'E ~ |S'O'|
    }
    st.points(i, 0) = r * std::cos(st.angles[i]);
    st.points(i, 1) = r * std::sin(st.angles[i]);
  }
  const CircleFit fit = FitCircleAlgebraic(st.points, "four-step circle fit");
  st.centre = fit.centre;
  st.radius = fit.radius;
  st.residuals = fit.residuals;
  st.rms = fit.rms;
  st.centre_covariance = fit.covariance.topLeftCorner<2, 2>();
  return st;
}

// Measured axis line from the two centres of one axis: the point where the
// axis pierces the plane of the pivot (S + centre) and its direction (made
// positive along n).
void AxisLine(const FourStepStep& s1, const FourStepStep& s2, const Eigen::Vector2d& c1,
              const Eigen::Vector2d& c2, Eigen::Vector2d* oe, Eigen::Vector3d* point,
              Eigen::Vector3d* dir, double* tilt1) {
  const Eigen::Vector3d& n = s1.normal;
  *oe = c1 - c2;  // O'E = O'P - EP
  const double h = n.dot(s2.spindle_ball - s1.spindle_ball);  // signed S'O' along n
  // The line through S' along the real axis meets the base plane at E:
  // O'E = -h tilt  (eqs. 18-19 with the sign of the extension).
  const Eigen::Vector2d tilt = -*oe / h;
  *tilt1 = tilt.x();
  *dir = (n + tilt.x() * s1.e1 + tilt.y() * s1.e2).normalized();
  *point = s1.spindle_ball + c1.x() * s1.e1 + c1.y() * s1.e2;
}

// From the four centres to the eight PIGEs (fivecal names and signs).
Eigen::VectorXd Assemble(const Machine& m, const FourStepPair& t, const std::vector<FourStepStep>& st,
                         const Eigen::Vector2d c[4], const FourStepOptions& opt, FourStepResult* out) {
  const Eigen::Vector3d pA = m.axis(t.carrier).point, pC = m.axis(t.carried).point;
  const Eigen::Vector3d& nA = t.n_carrier;
  const Eigen::Vector3d& nC = t.n_carried;
  Eigen::Vector2d oeA, oeC;
  Eigen::Vector3d PA, vA, PC, vC;
  double tA, tC;
  AxisLine(st[0], st[1], c[0], c[1], &oeA, &PA, &vA, &tA);
  AxisLine(st[2], st[3], c[2], c[3], &oeC, &PC, &vC, &tC);

  // Carrier: the model's line passes through p_A + e_A along R_A u_A, with
  // no position error along the axis.
  Eigen::Vector3d pointA;
  if (opt.refer_positions) pointA = PA + vA * (-(PA - pA).dot(nA) / vA.dot(nA));
  else pointA = PA - nA * nA.dot(PA - pA);
  Eigen::Vector3d eA = InPlane(pointA - pA, nA);
  const Eigen::Vector3d rA = OrientationFromDirection(BasisIndex(nA), vA);
  const Eigen::Matrix3d RA = RotZYX(rA[0], rA[1], rA[2]);

  // Carried: its line in the carrier frame (at carrier = 0) passes through
  // (p_C - p_A) + e_C along R_C u_C; in the frame carrying the pair that is
  // p_A + e_A + R_A(...).
  Eigen::Vector3d y = Eigen::Vector3d::Zero(), d = nC;
  switch (opt.a_removal) {
    case ARemoval::kFull:
      y = RA.transpose() * (PC - pA - eA);
      d = RA.transpose() * vC;
      break;
    case ARemoval::kPositionOnly:
      y = PC - pA - eA;
      d = vC;
      break;
    case ARemoval::kNone:
      y = PC - pA;
      d = vC;
      break;
  }
  if (d.dot(nC) < 0) d = -d;
  Eigen::Vector3d eC = y - (pC - pA);
  if (opt.refer_positions) eC += d * (-eC.dot(nC) / d.dot(nC));  // no position error along the line
  eC = InPlane(eC, nC);
  const Eigen::Vector3d rC = OrientationFromDirection(BasisIndex(nC), d);

  if (out) {
    out->a_oe = oeA;
    out->c_oe = oeC;
    out->a_direction = vA;
    out->c_direction = vC;
    out->a_point = PA;
    out->c_point = PC;
    // eq. 20: Delta = PO' (1/cos E - 1), with the tilt towards the first plane axis.
    out->a_delta = c[0].norm() * (1.0 / std::cos(std::atan(tA)) - 1.0);
    out->c_delta = c[2].norm() * (1.0 / std::cos(std::atan(tC)) - 1.0);
  }
  const int a1 = BasisIndex(st[0].e1), a2 = BasisIndex(st[0].e2);
  const int c1 = BasisIndex(st[2].e1), c2 = BasisIndex(st[2].e2);
  Eigen::VectorXd v(8);
  v << eA[a1], eA[a2], rA[a1], rA[a2], eC[c1], eC[c2], rC[c1], rC[c2];
  return v;
}

}  // namespace

FourStepPair RequireFourStepPair(const Machine& m, const std::string& what) {
  auto fail = [&](const std::string& why) {
    throw std::invalid_argument(what + ": machine '" + m.name() + "' (" + m.topology() + "): " + why);
  };
  std::vector<int> rot;
  for (int k = 0; k < m.num_axes(); ++k)
    if (m.axis(k).rotary() && m.axis(k).name != 'S') rot.push_back(k);
  if (rot.size() != 2)
    fail("has " + std::to_string(rot.size()) +
         " rotary axes besides the spindle; the Jiang & Cripps test is for a pair of rotary axes");
  FourStepPair t;
  const bool w0 = !m.on_tool_side(rot[0]), w1 = !m.on_tool_side(rot[1]);
  if (w0 != w1)
    fail(std::string("one rotary axis on the table (") + m.axis(w0 ? rot[0] : rot[1]).name +
         ") and one on the spindle head (" + m.axis(w0 ? rot[1] : rot[0]).name +
         "): each axis' fixed ball rides on the other axis, so the two axis lines are measured only "
         "relative to each other (a common shift is the linear axes' zero) and the paper's removal of "
         "a carrier does not apply; fit both with the general engine (fivecal identify)");
  t.tool_side = !w0;
  const std::vector<int>& chain = t.tool_side ? m.tool_chain() : m.workpiece_chain();
  std::vector<int> pos;
  for (size_t i = 0; i < chain.size(); ++i)
    if (chain[i] == rot[0] || chain[i] == rot[1]) pos.push_back(static_cast<int>(i));
  t.carrier = chain[pos[0]];
  t.carried = chain[pos[1]];
  for (int k : {t.carrier, t.carried}) {
    const Axis& ax = m.axis(k);
    if (BasisIndex(ax.direction) < 0) {
      std::ostringstream s;
      s << "the " << ax.name << " axis (direction " << ax.direction.transpose()
        << ") is not along X, Y or Z; the four-step plane bases and the PIGE names (E<dir>0"
        << ax.name << ") need an axis along a machine axis (a nutating axis: use the general engine)";
      fail(s.str());
    }
  }
  const int kA = BasisIndex(m.axis(t.carrier).direction), kC = BasisIndex(m.axis(t.carried).direction);
  if (kA == kC)
    fail(std::string("the ") + m.axis(t.carrier).name + " and " + m.axis(t.carried).name +
         " axes are parallel; the two axes then do not orient the tool in two directions, and the "
         "carried axis' orientation errors cannot be told from the carrier's in a test at carrier = 0");
  t.n_carrier = Eigen::Vector3d::Unit(kA);
  t.n_carried = Eigen::Vector3d::Unit(kC);
  for (size_t i = pos[0] + 1; i < chain.size(); ++i) {
    const Axis& ax = m.axis(chain[i]);
    if (!ax.rotary())
      fail(std::string("the linear axis ") + ax.name + " is carried by the rotary axis " +
           m.axis(t.carrier).name + "; it would move the axis lines of the test with its command");
  }
  for (int i = 0; i < pos[0]; ++i) {
    if (m.axis(chain[i]).rotary())
      fail(std::string("the rotary axis ") + m.axis(chain[i]).name + " carries the pair");
    t.base_chain.push_back(chain[i]);
  }
  return t;
}

std::vector<std::string> FourStepPair::DefaultSetups(const Machine& m) const {
  const std::string a(1, m.axis(carrier).name), c(1, m.axis(carried).name);
  return {a + "1", a + "2", c + "1", c + "2"};
}

const std::vector<std::string>& FourStepParameterNames() {
  static const std::vector<std::string> names = {"EY0A", "EZ0A", "EB0A", "EC0A",
                                                 "EX0C", "EY0C", "EA0C", "EB0C"};
  return names;
}

std::vector<std::string> FourStepParameterNames(const Machine& m) {
  const FourStepPair t = RequireFourStepPair(m, "four-step");
  std::vector<std::string> names;
  for (int k : {t.carrier, t.carried}) {
    const Eigen::Vector3d n = k == t.carrier ? t.n_carrier : t.n_carried;
    Eigen::Vector3d e1, e2;
    PlaneBasis(n, &e1, &e2);
    const int i1 = BasisIndex(e1), i2 = BasisIndex(e2);
    const std::string ax(1, m.axis(k).name);
    names.push_back(std::string("E") + kLinearLetters[i1] + "0" + ax);
    names.push_back(std::string("E") + kLinearLetters[i2] + "0" + ax);
    names.push_back(std::string("E") + kRotaryLetters[i1] + "0" + ax);
    names.push_back(std::string("E") + kRotaryLetters[i2] + "0" + ax);
  }
  return names;
}

double FourStepResult::Get(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return values[i];
  throw std::invalid_argument("four-step result: no parameter '" + name + "'");
}

FourStepResult AnalyzeFourStep(const Dataset& given_ds, const FourStepOptions& opt_in) {
  // Works on Observation objects: column blocks expanded (dataset.h).
  const ExpandedView expanded_ds(given_ds);
  const Dataset& ds = *expanded_ds;
  const FourStepPair t = RequireFourStepPair(ds.machine(), "four-step");
  FourStepOptions opt = opt_in;
  const std::vector<std::string> def = t.DefaultSetups(ds.machine());
  if (opt.a_setup.empty()) opt.a_setup = def[0];
  if (opt.a_extended_setup.empty()) opt.a_extended_setup = def[1];
  if (opt.c_setup.empty()) opt.c_setup = def[2];
  if (opt.c_extended_setup.empty()) opt.c_extended_setup = def[3];
  for (const auto& kv : opt.length_offsets) RequireFinite(kv.second, "length_offsets." + kv.first);
  for (int i = 0; i < 2; ++i) {
    RequireFinite(opt.a_pivot_offset[i], "a_pivot_offset");
    RequireFinite(opt.c_pivot_offset[i], "c_pivot_offset");
  }
  FourStepResult r;
  r.carrier = std::string(1, ds.machine().axis(t.carrier).name);
  r.carried = std::string(1, ds.machine().axis(t.carried).name);
  r.tool_side = t.tool_side;
  r.steps.push_back(AnalyzeStep(ds, t, opt.a_setup, true, nullptr, opt.a_pivot_offset, opt));
  r.steps.push_back(
      AnalyzeStep(ds, t, opt.a_extended_setup, true, &r.steps[0].spindle_ball, opt.a_pivot_offset, opt));
  r.steps.push_back(AnalyzeStep(ds, t, opt.c_setup, false, nullptr, opt.c_pivot_offset, opt));
  r.steps.push_back(
      AnalyzeStep(ds, t, opt.c_extended_setup, false, &r.steps[2].spindle_ball, opt.c_pivot_offset, opt));

  Eigen::Vector2d c[4];
  for (int i = 0; i < 4; ++i) c[i] = r.steps[i].centre;
  r.names = FourStepParameterNames(ds.machine());
  r.values = Assemble(ds.machine(), t, r.steps, c, opt, &r);

  // First-order propagation of the four centre covariances (the steps are
  // independent measurements) through the assembly, by central differences.
  Eigen::MatrixXd J(8, 8), Cin = Eigen::MatrixXd::Zero(8, 8);
  const double h = 1e-6;  // mm
  for (int j = 0; j < 8; ++j) {
    Eigen::Vector2d cp[4], cm[4];
    for (int i = 0; i < 4; ++i) cp[i] = cm[i] = c[i];
    cp[j / 2][j % 2] += h;
    cm[j / 2][j % 2] -= h;
    J.col(j) = (Assemble(ds.machine(), t, r.steps, cp, opt, nullptr) -
                Assemble(ds.machine(), t, r.steps, cm, opt, nullptr)) / (2 * h);
  }
  for (int i = 0; i < 4; ++i) Cin.block<2, 2>(2 * i, 2 * i) = r.steps[i].centre_covariance;
  r.covariance = J * Cin * J.transpose();
  r.std = r.covariance.diagonal().cwiseMax(0.0).cwiseSqrt();
  return r;
}

std::string FourStepPlanJson(const Machine& m, const FourStepPlanOptions& o_in) {
  const FourStepPair t = RequireFourStepPair(m, "four-step plan");
  FourStepPlanOptions o = o_in;
  const char* w = "four-step plan";
  // A rotary table (or a head's C axis) about the tool axis turns a full
  // circle; a tilting axis sweeps the paper's -20..70 deg.
  auto default_range = [&](int k, double* from, double* to) {
    const bool table = std::abs(std::abs(m.axis(k).direction.dot(m.tool_axis())) - 1.0) < 1e-9;
    if (std::isnan(*from)) *from = table ? 0.0 : -20.0;
    if (std::isnan(*to)) *to = table ? 359.0 : 70.0;
  };
  default_range(t.carrier, &o.a_start, &o.a_end);
  default_range(t.carried, &o.c_start, &o.c_end);
  // The extended spindle ball goes up (towards the tool) along an axis
  // parallel to the tool axis, and along -n for a tilting axis ("X driven
  // negative"), so it stays above a rotary table.
  auto default_sign = [&](int k, double* sign) {
    if (!std::isnan(*sign)) return;
    const Eigen::Vector3d& n = k == t.carrier ? t.n_carrier : t.n_carried;
    const double along = n.dot(m.tool_axis());
    *sign = std::abs(std::abs(along) - 1.0) < 1e-9 ? (along > 0 ? 1.0 : -1.0) : -1.0;
    // On a head pair the fixed ball is the table ball: it goes further from
    // the head, past the tool-ball pivot.
    const double to_tip = n.dot(m.tip() - m.axis(k).point);
    if (t.tool_side && std::abs(to_tip) > 1e-9) *sign = to_tip > 0 ? 1.0 : -1.0;
  };
  default_sign(t.carrier, &o.a_extension_sign);
  default_sign(t.carried, &o.c_extension_sign);
  const std::vector<std::string> def = t.DefaultSetups(m);
  if (o.a_setup.empty()) o.a_setup = def[0];
  if (o.a_extended_setup.empty()) o.a_extended_setup = def[1];
  if (o.c_setup.empty()) o.c_setup = def[2];
  if (o.c_extended_setup.empty()) o.c_extended_setup = def[3];
  for (double x : {o.length, o.extended_length, o.a_start, o.a_end, o.c_start, o.c_end, o.step})
    RequireFinite(x, w);
  // Positions and lengths within the machine-size bound: the geometry below
  // takes norms and cross products, which overflow for 1e308 mm and would
  // turn a typo into a misleading message about the machine.
  RequireBounded(o.length, kMaxLinear, "four-step plan.length");
  RequireBounded(o.extended_length, kMaxLinear, "four-step plan.extended_length");
  auto bounded = [](const Eigen::Vector3d& v, const char* name) {
    if (!v.allFinite()) return;  // NaN: not given, the plan's own choice
    for (int i = 0; i < 3; ++i)
      RequireBounded(v[i], kMaxLinear, std::string("four-step plan.") + name + "[" + std::to_string(i) + "]");
  };
  bounded(o.tool_ball, "tool_ball");
  bounded(o.a_pivot, "a_pivot");
  bounded(o.c_pivot, "c_pivot");
  if (!(o.length > 0)) throw std::invalid_argument("four-step plan.length: must be > 0 mm");
  if (!(o.extended_length > o.length))
    throw std::invalid_argument("four-step plan.extended_length: must exceed length");
  if (!(o.step > 0)) throw std::invalid_argument("four-step plan.step: must be > 0 deg");
  // A real ball bar records a few thousand samples per revolution; a tiny
  // step (1e-7 deg) would otherwise try to allocate billions of poses.
  constexpr double kMaxSamplesPerStep = 1e6;
  for (double span : {o.a_end - o.a_start, o.c_end - o.c_start}) {
    const double count = std::floor(std::abs(span) / o.step + 1e-9) + 1;
    if (!(count <= kMaxSamplesPerStep)) {
      std::ostringstream s;
      s << "four-step plan.step: " << o.step << " deg gives " << count << " samples over " << std::abs(span)
        << " deg; at most 1000000 per step (use a larger step)";
      throw std::invalid_argument(s.str());
    }
  }
  if (std::abs(o.a_extension_sign) != 1.0 || std::abs(o.c_extension_sign) != 1.0)
    throw std::invalid_argument("four-step plan: extension signs must be +1 or -1");
  const double arm = std::sqrt(o.extended_length * o.extended_length - o.length * o.length);
  const Eigen::Vector3d pA = m.axis(t.carrier).point, pC = m.axis(t.carried).point;
  Eigen::Vector3d e1A, e2A, e1C, e2C;
  PlaneBasis(t.n_carrier, &e1A, &e2A);
  PlaneBasis(t.n_carried, &e1C, &e2C);
  // Default pivots: on a table pair the paper's (100 mm along the carrier,
  // one bar length along the first plane axis). On a head pair the pivot is
  // the tool ball, so it is put on the side of the tool tip: along the axis
  // towards the tip and across it towards the tip where the tip is off the axis.
  auto default_pivot = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n, const Eigen::Vector3d& e1,
                           const Eigen::Vector3d& e2, double along) {
    Eigen::Vector3d across = e1;
    if (t.tool_side) {
      const Eigen::Vector3d to_tip = m.tip() - p;
      if (along != 0.0 && std::abs(n.dot(to_tip)) > 1e-9) along = std::copysign(along, n.dot(to_tip));
      double best = 1e-9;
      for (const Eigen::Vector3d& c : {e1, e2, Eigen::Vector3d(-e1), Eigen::Vector3d(-e2)})
        if (c.dot(to_tip) > best) {
          best = c.dot(to_tip);
          across = c;
        }
    }
    return Eigen::Vector3d(p + along * n + o.length * across);
  };
  const Eigen::Vector3d a_pivot =
      o.a_pivot.allFinite() ? o.a_pivot : default_pivot(pA, t.n_carrier, e1A, e2A, 100.0);
  const Eigen::Vector3d c_pivot = o.c_pivot.allFinite() ? o.c_pivot : default_pivot(pC, t.n_carried, e1C, e2C, 0.0);
  auto check = [&](const Eigen::Vector3d& piv, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                   const char* name) {
    const double r = InPlane(piv - p, n).norm();
    if (std::abs(r - o.length) > 1e-6) {
      std::ostringstream s;
      s << "four-step plan." << name << ": the pivot is " << r << " mm from the axis; put it one bar "
        << "length (" << o.length << " mm) away";
      throw std::invalid_argument(s.str());
    }
  };
  check(a_pivot, pA, t.n_carrier, "a_pivot");
  check(c_pivot, pC, t.n_carried, "c_pivot");
  const Eigen::Vector3d SA = pA + t.n_carrier * t.n_carrier.dot(a_pivot - pA);
  const Eigen::Vector3d SC = pC + t.n_carried * t.n_carried.dot(c_pivot - pC);

  json plan = json::array();
  // `pivot`: the moving ball; `S`: where the fixed ball must be, in the
  // frame carrying the pair; `S0`: the fixed ball of the step without the
  // extension (the table ball's place on a head pair).
  auto add_step = [&](const std::string& setup, int moving, double from, double to, const Eigen::Vector3d& S,
                      const Eigen::Vector3d& S0, const Eigen::Vector3d& pivot, double length) {
    Eigen::Vector3d tool, table;
    if (t.tool_side) {
      tool = pivot;
      table = o.tool_ball.allFinite() ? o.tool_ball : S0;
    } else {
      tool = o.tool_ball.allFinite() ? o.tool_ball : m.tip();
      table = pivot;
    }
    const double sgn = to >= from ? 1.0 : -1.0;
    const int n = static_cast<int>(std::floor(std::abs(to - from) / o.step + 1e-9)) + 1;
    for (int i = 0; i < n; ++i) {
      Eigen::VectorXd pose = Eigen::VectorXd::Zero(m.num_axes());
      pose[moving] = from + sgn * o.step * i;
      const Eigen::VectorXd cmd = PlaceFixedBall(m, t, tool, table, S, pose);
      json axes = json::object();
      for (int k = 0; k < m.num_axes(); ++k) axes[std::string(1, m.axis(k).name)] = cmd[k];
      plan.push_back({{"type", "dbb"},
                      {"setup", setup},
                      {"axes", axes},
                      {"direction", {{std::string(1, m.axis(moving).name), static_cast<int>(sgn)}}},
                      {"length", length},
                      {"tool_ball", json_util::Array3(tool)},
                      {"table_ball", json_util::Array3(table)}});
    }
  };
  add_step(o.a_setup, t.carrier, o.a_start, o.a_end, SA, SA, a_pivot, o.length);
  add_step(o.a_extended_setup, t.carrier, o.a_start, o.a_end, SA + o.a_extension_sign * arm * t.n_carrier, SA,
           a_pivot, o.extended_length);
  add_step(o.c_setup, t.carried, o.c_start, o.c_end, SC, SC, c_pivot, o.length);
  add_step(o.c_extended_setup, t.carried, o.c_start, o.c_end, SC + o.c_extension_sign * arm * t.n_carried, SC,
           c_pivot, o.extended_length);
  return plan.dump();
}

}  // namespace fivecal
