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

// The paper's machine class: C on A on the foundation, A along +-X, C along +-Z.
struct TableAxes {
  int a = -1, c = -1;
  Eigen::Vector3d na, nc;  // nominal directions made positive (+X, +Z)
};

TableAxes RequireTiltingTable(const Machine& m, const char* what) {
  const std::vector<int>& w = m.workpiece_chain();
  auto fail = [&](const std::string& why) {
    throw std::invalid_argument(std::string(what) + ": machine '" + m.name() + "' (" + m.topology() +
                                "): " + why +
                                "; the Jiang & Cripps test needs a C table (about Z) on an A "
                                "axis (about X), topology wCAf...");
  };
  if (w.size() != 2) fail("the workpiece side must hold exactly the A and C axes");
  const Axis& a = m.axis(w[0]);
  const Axis& c = m.axis(w[1]);
  if (a.name != 'A' || c.name != 'C') fail("the workpiece chain is not A then C");
  if (std::abs(std::abs(a.direction.x()) - 1.0) > 1e-9) fail("A is not along X");
  if (std::abs(std::abs(c.direction.z()) - 1.0) > 1e-9) fail("C is not along Z");
  TableAxes t;
  t.a = w[0];
  t.c = w[1];
  t.na = Eigen::Vector3d::UnitX();
  t.nc = Eigen::Vector3d::UnitZ();
  return t;
}

// Plane basis normal to a positive basis vector n: A (n = X): Y, Z; C (n = Z): X, Y.
void PlaneBasis(const Eigen::Vector3d& n, Eigen::Vector3d* e1, Eigen::Vector3d* e2) {
  if (n.x() > 0.5) *e1 = Eigen::Vector3d::UnitY();
  else *e1 = Eigen::Vector3d::UnitX();
  *e2 = n.cross(*e1);
}

Eigen::Vector3d InPlane(const Eigen::Vector3d& v, const Eigen::Vector3d& n) { return v - n * n.dot(v); }

std::string SetupList(const Dataset& ds) {
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
FourStepStep AnalyzeStep(const Dataset& ds, const TableAxes& t, const std::string& setup, char axis,
                         const Eigen::Vector3d* o_prime, const Eigen::Vector2d& pivot_offset,
                         const FourStepOptions& opt) {
  const Machine& m = ds.machine();
  const std::string w = "four-step: setup '" + setup + "'";
  FourStepStep st;
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
  const int moving = axis == 'A' ? t.a : t.c;
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
    if (axis == 'C' && std::abs(o.axes[t.a]) > 1e-9)
      throw std::invalid_argument(wo + ": A = " + std::to_string(o.axes[t.a]) +
                                  " deg; the C steps are run at A = 0");
    if ((o.tool_ball - o0.tool_ball).norm() > 1e-12 || (o.table_ball - o0.table_ball).norm() > 1e-12 ||
        o.length != o0.length)
      throw std::invalid_argument(wo + ": tool_ball, table_ball and length must be the same for "
                                  "every sample of one ball-bar mounting");
  }
  const Eigen::Vector3d n = axis == 'A' ? t.na : t.nc;
  PlaneBasis(n, &st.e1, &st.e2);
  st.normal = n;
  st.spindle_ball = NominalToolBallInF(m, o0.axes, o0.tool_ball);
  const Eigen::Vector3d p_axis = m.axis(moving).point;  // C at A = 0: its zero-pose line

  Eigen::Vector3d O = st.spindle_ball;
  if (!st.extended) {
    const double off = InPlane(st.spindle_ball - p_axis, n).norm();
    if (off > kPlacementTolerance) {
      std::ostringstream s;
      s << w << ": the spindle ball is " << off << " mm from the nominal " << axis
        << " axis; the method needs it on the axis (Jiang & Cripps, Section 3.1)";
      throw std::invalid_argument(s.str());
    }
  } else {
    O = *o_prime;
    const Eigen::Vector3d d = st.spindle_ball - O;
    const double lateral = InPlane(d, n).norm();
    st.arm = d.norm();  // |S'O'| of eqs. 11, 18-19
    if (lateral > kPlacementTolerance || st.arm < 1.0) {
      std::ostringstream s;
      s << w << ": the spindle ball must be moved along the " << axis << " axis from the step "
        << "without the extension (moved " << n.dot(d) << " mm along, " << lateral << " mm across)";
      throw std::invalid_argument(s.str());
    }
  }

  const int N = static_cast<int>(st.observations.size());
  Eigen::VectorXd theta(N);
  Eigen::Vector3d b0 = Eigen::Vector3d::Zero();
  for (int i = 0; i < N; ++i) {
    const Observation& o = ds.observations[st.observations[i]];
    const Eigen::Vector3d b = NominalTableBallInF(m, o.axes, o.table_ball);
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
    const double L = o0.length + offset + ds.observations[st.observations[i]].reading;
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
Eigen::VectorXd Assemble(const Machine& m, const TableAxes& t, const std::vector<FourStepStep>& st,
                         const Eigen::Vector2d c[4], const FourStepOptions& opt, FourStepResult* out) {
  const Eigen::Vector3d pA = m.axis(t.a).point, pC = m.axis(t.c).point;
  Eigen::Vector2d oeA, oeC;
  Eigen::Vector3d PA, vA, PC, vC;
  double tA, tC;
  AxisLine(st[0], st[1], c[0], c[1], &oeA, &PA, &vA, &tA);
  AxisLine(st[2], st[3], c[2], c[3], &oeC, &PC, &vC, &tC);

  // A: the model's line passes through p_A + e_A along R_A u_A, with EX0A = 0.
  Eigen::Vector3d pointA;
  if (opt.refer_positions) pointA = PA + vA * (-(PA - pA).dot(t.na) / vA.dot(t.na));
  else pointA = PA - t.na * t.na.dot(PA - pA);
  Eigen::Vector3d eA = pointA - pA;
  eA.x() = 0.0;
  // R_A = Rz(EC0A) Ry(EB0A): R_A e_x = (cos c cos b, sin c cos b, -sin b) = vA.
  const double EB0A = -std::asin(vA.z()), EC0A = std::atan2(vA.y(), vA.x());
  const Eigen::Matrix3d RA = RotZYX(0.0, EB0A, EC0A);

  // C: its line in the A frame (at A = 0) passes through (p_C - p_A) + e_C
  // along R_C u_C; in F that is p_A + e_A + R_A(...).
  Eigen::Vector3d y = Eigen::Vector3d::Zero(), d = Eigen::Vector3d::UnitZ();
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
  if (d.z() < 0) d = -d;
  Eigen::Vector3d eC = y - (pC - pA);
  if (opt.refer_positions) eC += d * (-eC.z() / d.z());  // EZ0C = 0 along the measured line
  eC.z() = 0.0;
  // R_C = Ry(EB0C) Rx(EA0C): R_C e_z = (cos a sin b, -sin a, cos a cos b) = d.
  const double EA0C = -std::asin(d.y()), EB0C = std::atan2(d.x(), d.z());

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
  Eigen::VectorXd v(8);
  v << eA.y(), eA.z(), EB0A, EC0A, eC.x(), eC.y(), EA0C, EB0C;
  return v;
}

}  // namespace

const std::vector<std::string>& FourStepParameterNames() {
  static const std::vector<std::string> names = {"EY0A", "EZ0A", "EB0A", "EC0A",
                                                 "EX0C", "EY0C", "EA0C", "EB0C"};
  return names;
}

double FourStepResult::Get(const std::string& name) const {
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return values[i];
  throw std::invalid_argument("four-step result: no parameter '" + name + "'");
}

FourStepResult AnalyzeFourStep(const Dataset& ds, const FourStepOptions& opt) {
  const TableAxes t = RequireTiltingTable(ds.machine(), "four-step");
  for (const auto& kv : opt.length_offsets) RequireFinite(kv.second, "length_offsets." + kv.first);
  for (int i = 0; i < 2; ++i) {
    RequireFinite(opt.a_pivot_offset[i], "a_pivot_offset");
    RequireFinite(opt.c_pivot_offset[i], "c_pivot_offset");
  }
  FourStepResult r;
  r.steps.push_back(AnalyzeStep(ds, t, opt.a_setup, 'A', nullptr, opt.a_pivot_offset, opt));
  r.steps.push_back(
      AnalyzeStep(ds, t, opt.a_extended_setup, 'A', &r.steps[0].spindle_ball, opt.a_pivot_offset, opt));
  r.steps.push_back(AnalyzeStep(ds, t, opt.c_setup, 'C', nullptr, opt.c_pivot_offset, opt));
  r.steps.push_back(
      AnalyzeStep(ds, t, opt.c_extended_setup, 'C', &r.steps[2].spindle_ball, opt.c_pivot_offset, opt));

  Eigen::Vector2d c[4];
  for (int i = 0; i < 4; ++i) c[i] = r.steps[i].centre;
  r.names = FourStepParameterNames();
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

std::string FourStepPlanJson(const Machine& m, const FourStepPlanOptions& o) {
  const TableAxes t = RequireTiltingTable(m, "four-step plan");
  const char* w = "four-step plan";
  for (double x : {o.length, o.extended_length, o.a_start, o.a_end, o.c_start, o.c_end, o.step})
    RequireFinite(x, w);
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
  const Eigen::Vector3d pA = m.axis(t.a).point, pC = m.axis(t.c).point;
  const Eigen::Vector3d tool = o.tool_ball.allFinite() ? o.tool_ball : m.tip();
  const Eigen::Vector3d a_pivot =
      o.a_pivot.allFinite() ? o.a_pivot : Eigen::Vector3d(pA + Eigen::Vector3d(100.0, o.length, 0.0));
  const Eigen::Vector3d c_pivot =
      o.c_pivot.allFinite() ? o.c_pivot : Eigen::Vector3d(pC + Eigen::Vector3d(o.length, 0.0, 0.0));
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
  check(a_pivot, pA, t.na, "a_pivot");
  check(c_pivot, pC, t.nc, "c_pivot");
  const Eigen::Vector3d SA = pA + t.na * t.na.dot(a_pivot - pA);
  const Eigen::Vector3d SC = pC + t.nc * t.nc.dot(c_pivot - pC);

  json plan = json::array();
  auto add_step = [&](const std::string& setup, int moving, double from, double to,
                      const Eigen::Vector3d& S, const Eigen::Vector3d& pivot, double length) {
    const double sgn = to >= from ? 1.0 : -1.0;
    const int n = static_cast<int>(std::floor(std::abs(to - from) / o.step + 1e-9)) + 1;
    for (int i = 0; i < n; ++i) {
      Eigen::VectorXd pose = Eigen::VectorXd::Zero(m.num_axes());
      pose[moving] = from + sgn * o.step * i;
      const Eigen::VectorXd cmd = ToolBallCommands(m, tool, S, pose);
      json axes = json::object();
      for (int k = 0; k < m.num_axes(); ++k) axes[std::string(1, m.axis(k).name)] = cmd[k];
      plan.push_back({{"type", "dbb"},
                      {"setup", setup},
                      {"axes", axes},
                      {"direction", {{std::string(1, m.axis(moving).name), static_cast<int>(sgn)}}},
                      {"length", length},
                      {"tool_ball", json_util::Array3(tool)},
                      {"table_ball", json_util::Array3(pivot)}});
    }
  };
  add_step(o.a_setup, t.a, o.a_start, o.a_end, SA, a_pivot, o.length);
  add_step(o.a_extended_setup, t.a, o.a_start, o.a_end, SA + o.a_extension_sign * arm * t.na, a_pivot,
           o.extended_length);
  add_step(o.c_setup, t.c, o.c_start, o.c_end, SC, c_pivot, o.length);
  add_step(o.c_extended_setup, t.c, o.c_start, o.c_end, SC + o.c_extension_sign * arm * t.nc, c_pivot,
           o.extended_length);
  return plan.dump();
}

}  // namespace fivecal
