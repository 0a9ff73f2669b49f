// KinematicModel (the fast double path with the analytic Jacobian) against the
// templated forward kinematics: same point, and the same derivatives as the
// ceres::Jet evaluation of ToolInWorkpiece for every machine parameter.
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <random>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/observations/probe_trigger.h"

namespace fivecal {
namespace {

const char* kMachines[] = {
    R"({"name": "hu40t", "topology": "wCBXfZYSt", "axes": {
      "X": {"type": "linear", "direction": [-1,0,0]},
      "B": {"type": "rotary", "direction": [0,-1,0], "point": [0,0,-120]},
      "C": {"type": "rotary", "direction": [0,0,-1], "point": [0,0,0]},
      "Z": {"type": "linear", "direction": [0,0,1]}, "Y": {"type": "linear", "direction": [0,1,0]},
      "S": {"type": "rotary", "direction": [0,0,1], "point": [5,-3,0]}}, "tool": {"tip": [1,2,100]}})",
    R"({"name": "kx8", "topology": "wCAYbXZSt", "axes": {
      "Y": {"type": "linear", "direction": [0,-1,0]},
      "A": {"type": "rotary", "direction": [-0.7071067811865476,0,0.7071067811865476], "point": [0,10,-40]},
      "C": {"type": "rotary", "direction": [0,0,-1], "point": [3,0,0]},
      "X": {"type": "linear", "direction": [1,0,0]}, "Z": {"type": "linear", "direction": [0,0,1]},
      "S": {"type": "rotary", "direction": [0,0,1]}}, "tool": {"tip": [0,0,150]}})",
    R"({"name": "headhead", "topology": "wXYfZCASt", "axes": {
      "X": {"type": "linear", "direction": [-1,0,0]}, "Y": {"type": "linear", "direction": [0,-1,0]},
      "Z": {"type": "linear", "direction": [0,0,1]},
      "C": {"type": "rotary", "direction": [0,0,1], "point": [0,0,300]},
      "A": {"type": "rotary", "direction": [1,0,0], "point": [0,0,200]},
      "S": {"type": "rotary", "direction": [0,0,1], "point": [0,0,200]}}, "tool": {"tip": [0,0,50]}})"};

// Realistic error values: location 1e-2 mm / 1e-4 rad, error motions a few µm
// over the travel, backlash a few µm / µrad.
Eigen::VectorXd RandomTheta(const Machine& m, std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::VectorXd t(m.num_parameters());
  for (int i = 0; i < m.num_parameters(); ++i) {
    const ParameterInfo& p = m.parameters()[i];
    const bool rot_axis = p.axis >= 0 && m.axis(p.axis).rotary();
    const double range = rot_axis ? M_PI : 300.0;
    switch (p.kind) {
      case ParameterKind::kLocation: t[i] = n(rng) * (p.angular() ? 1e-4 : 1e-2); break;
      case ParameterKind::kMotion: t[i] = n(rng) * (p.angular() ? 2e-5 : 5e-3) / std::pow(range, p.degree); break;
      case ParameterKind::kBacklash: t[i] = n(rng) * (rot_axis ? 2e-5 : 3e-3); break;
      case ParameterKind::kTip: t[i] = n(rng) * 0.05; break;
    }
  }
  return t;
}

class KinematicModelTest : public ::testing::TestWithParam<int> {};

TEST_P(KinematicModelTest, PointAndJacobianMatchJetKinematics) {
  const Machine m = Machine::FromJson(kMachines[GetParam()]);
  std::mt19937 rng(7 + GetParam());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int np = m.num_parameters(), na = m.num_axes();
  using Jet = ceres::Jet<double, 4>;
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::VectorXd theta = RandomTheta(m, rng);
    std::vector<double> q(na);
    std::vector<int> dir(na);
    for (int k = 0; k < na; ++k) {
      q[k] = m.axis(k).rotary() ? u(rng) * M_PI : u(rng) * 300.0;
      dir[k] = trial % 3 == 0 ? 0 : (u(rng) > 0 ? 1 : -1);
    }
    const KinematicModel model(m, theta.data());
    Eigen::Vector3d P;
    Eigen::MatrixXd J(3, np);
    model.ToolPointJacobian(q.data(), dir.data(), model.tip(), &P, J.data());

    Eigen::Vector3d Pref;
    ToolInWorkpiece<double>(m, theta.data(), q.data(), dir.data(), TipWithOffsets(m, theta.data()), &Pref);
    EXPECT_LT((P - Pref).norm(), 1e-10);
    EXPECT_LT((model.ToolPoint(q.data(), dir.data(), model.tip()) - Pref).norm(), 1e-10);

    // Jet derivatives, four parameters at a time.
    for (int b = 0; b < np; b += 4) {
      std::vector<Jet> th(np);
      for (int i = 0; i < np; ++i) th[i] = Jet(theta[i]);
      for (int j = 0; j < 4 && b + j < np; ++j) th[b + j].v[j] = 1.0;
      Vec3<Jet> Pj;
      ToolInWorkpiece<Jet>(m, th.data(), q.data(), dir.data(), TipWithOffsets<Jet>(m, th.data()), &Pj);
      for (int j = 0; j < 4 && b + j < np; ++j)
        for (int r = 0; r < 3; ++r) {
          const double ref = Pj[r].v[j], got = J(r, b + j);
          EXPECT_NEAR(got, ref, 1e-9 * (1.0 + std::abs(ref)))
              << m.parameters()[b + j].name << " row " << r << " trial " << trial;
        }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Machines, KinematicModelTest, ::testing::Values(0, 1, 2));

// ToolPointLanes (the long-data kernel's batched chain) against the general
// ToolPointJacobian, sample by sample: random errors, poses (rotary commands
// over several turns), backlash directions and tips per lane, and a random
// set of wanted columns of every kind (location, error motion, backlash,
// tip) restricted as a fit restricts them. A wanted column the batched
// chain skipped, a frame recorded in the wrong place or a lane mixed up
// with its neighbour shows here.
TEST_P(KinematicModelTest, LanesMatchTheGeneralChain) {
  const Machine m = Machine::FromJson(kMachines[GetParam()]);
  std::mt19937 rng(11 + GetParam());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int np = m.num_parameters(), na = m.num_axes();
  constexpr int W = KinematicModel::kLanes;
  for (int trial = 0; trial < 30; ++trial) {
    Eigen::VectorXd theta = RandomTheta(m, rng);
    // Some trials with the errors of whole axes zero: the shared-frame path.
    if (trial % 3 == 1)
      for (int i = 0; i < np; ++i)
        if (m.parameters()[i].axis >= 0 && !m.axis(m.parameters()[i].axis).rotary()) theta[i] = 0.0;
    std::vector<int> wanted;
    for (int i = 0; i < np; ++i)
      if (u(rng) > (trial % 2 ? 0.6 : 0.9)) wanted.push_back(i);
    KinematicModel model(m, theta.data());
    model.RestrictJacobian(wanted);
    const bool with_dir = trial % 4 != 0;
    std::vector<double> q(static_cast<size_t>(na) * W), dir(static_cast<size_t>(na) * W), tip(3 * W);
    std::vector<std::vector<double>> qs(W, std::vector<double>(na));
    std::vector<std::vector<int>> ds(W, std::vector<int>(na));
    for (int l = 0; l < W; ++l) {
      for (int k = 0; k < na; ++k) {
        qs[l][k] = m.axis(k).rotary() ? u(rng) * (trial % 5 == 0 ? 40.0 : 1.0) * M_PI : u(rng) * 300.0;
        ds[l][k] = with_dir ? static_cast<int>(std::lround(1.4 * u(rng))) : 0;
        q[k * W + l] = qs[l][k];
        dir[k * W + l] = ds[l][k];
      }
      for (int c = 0; c < 3; ++c) tip[c * W + l] = model.tip()[c] + 50.0 * u(rng);
    }
    std::vector<double> P(3 * W), P0(3 * W), J(3 * W * wanted.size() + 1), dtip(9 * W);
    model.ToolPointLanes(q.data(), with_dir ? dir.data() : nullptr, tip.data(), P.data(), wanted.data(),
                         static_cast<int>(wanted.size()), J.data(), dtip.data());
    model.ToolPointLanes(q.data(), with_dir ? dir.data() : nullptr, tip.data(), P0.data(), nullptr, 0, nullptr,
                         nullptr);
    // A sample's numbers do not depend on its lane (the held and the
    // per-chunk batches group samples differently): the batch rotated by 3.
    std::vector<double> qr(q.size()), dr(dir.size()), tr(tip.size()), Pr(3 * W), Jr(J.size()), dtr(9 * W);
    auto at = [&](int l) { return (l + 3) % W; };
    for (int l = 0; l < W; ++l) {
      for (int k = 0; k < na; ++k) {
        qr[k * W + l] = q[k * W + at(l)];
        dr[k * W + l] = dir[k * W + at(l)];
      }
      for (int c = 0; c < 3; ++c) tr[c * W + l] = tip[c * W + at(l)];
    }
    model.ToolPointLanes(qr.data(), with_dir ? dr.data() : nullptr, tr.data(), Pr.data(), wanted.data(),
                         static_cast<int>(wanted.size()), Jr.data(), dtr.data());
    for (int l = 0; l < W; ++l) {
      for (int c = 0; c < 3; ++c) ASSERT_EQ(Pr[c * W + l], P[c * W + at(l)]) << "trial " << trial;
      for (size_t j = 0; j < 3 * wanted.size(); ++j) ASSERT_EQ(Jr[j * W + l], J[j * W + at(l)]) << "trial " << trial;
      for (int c = 0; c < 9; ++c) ASSERT_EQ(dtr[c * W + l], dtip[c * W + at(l)]) << "trial " << trial;
    }
    for (int l = 0; l < W; ++l) {
      const Eigen::Vector3d t(tip[l], tip[W + l], tip[2 * W + l]);
      Eigen::Vector3d Pref;
      Eigen::MatrixXd Jref(3, np);
      model.ToolPointJacobian(qs[l].data(), with_dir ? ds[l].data() : nullptr, t, &Pref, Jref.data());
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(P[c * W + l], Pref[c], 1e-12 * (1 + Pref.norm())) << "trial " << trial << " lane " << l;
        EXPECT_EQ(P0[c * W + l], P[c * W + l]) << "the point without J, trial " << trial;
      }
      for (size_t j = 0; j < wanted.size(); ++j) {
        const double scale = 1 + Jref.col(wanted[j]).norm() + Pref.norm() * (m.parameters()[wanted[j]].angular() ? 1 : 0);
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(J[(3 * j + c) * W + l], Jref(c, wanted[j]), 1e-12 * scale)
              << m.parameters()[wanted[j]].name << " row " << c << " trial " << trial << " lane " << l;
      }
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(dtip[(3 * r + c) * W + l], Jref(r, m.tip_index() + c), 1e-12) << "dtip trial " << trial;
    }
  }
}

TEST_P(KinematicModelTest, ProbeFrameRotationIsTheNominalChainFramesRotation) {
  // The probe-lobing rotation takes the product of the rotary axes' own
  // rotations for the nominal chain frames: bit for bit the same.
  const Machine m = Machine::FromJson(kMachines[GetParam()]);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.num_parameters());
  for (int trial = 0; trial < 50; ++trial) {
    Observation o;
    o.axes.resize(m.num_axes());
    for (int k = 0; k < m.num_axes(); ++k) o.axes[k] = m.axis(k).rotary() ? 360 * u(rng) : 300 * u(rng);
    std::vector<double> q(m.num_axes());
    AxisValuesToInternal(m, o.axes.data(), q.data());
    Eigen::Vector3d pt, pw;
    const Frame<double> Ft = ChainFrame<double>(m, m.tool_chain(), zero.data(), q.data(), nullptr, &pt);
    const Frame<double> Fw = ChainFrame<double>(m, m.workpiece_chain(), zero.data(), q.data(), nullptr, &pw);
    // At the zero pose the rotation is the probe's axes (times exact identities).
    Observation zero_pose;
    zero_pose.axes = Eigen::VectorXd::Zero(m.num_axes());
    const Eigen::Matrix3d expected = ProbeFrameRotation(m, zero_pose) * (Fw.R.transpose() * Ft.R).transpose();
    EXPECT_EQ(ProbeFrameRotation(m, o), expected) << trial;
  }
}

TEST(KinematicModel, ToolAxisMatchesTemplatedKinematics) {
  const Machine m = Machine::FromJson(kMachines[0]);
  std::mt19937 rng(3);
  const Eigen::VectorXd theta = RandomTheta(m, rng);
  const KinematicModel model(m, theta.data());
  std::vector<double> q = {0.3, -0.7, 120.0, -40.0, 33.0, 1.1};
  Eigen::Vector3d P, a, Pref, aref;
  model.ToolPose(q.data(), nullptr, model.tip(), &P, &a);
  ToolInWorkpiece<double>(m, theta.data(), q.data(), nullptr, TipWithOffsets(m, theta.data()), &Pref, &aref);
  EXPECT_LT((P - Pref).norm(), 1e-10);
  EXPECT_LT((a - aref).norm(), 1e-14);
}

TEST(KinematicModel, RestrictedJacobianWritesTheWantedColumnsUnchanged) {
  const Machine m = Machine::FromJson(kMachines[0]);
  std::mt19937 rng(5);
  const Eigen::VectorXd theta = RandomTheta(m, rng);
  KinematicModel full(m, theta.data()), part(m, theta.data());
  // One location error of B, one error motion of X: those two columns and the tip's.
  const int b = m.AxisIndex('B'), x = m.AxisIndex('X');
  part.RestrictJacobian({m.location_index(b, 4), m.motion_index(x, 1, 2)});
  std::vector<double> q = {0.3, -0.7, 120.0, -40.0, 33.0, 1.1};
  std::vector<int> dir = {1, -1, 1, 1, -1, 0};
  const int np = m.num_parameters();
  Eigen::MatrixXd Jf(3, np), Jp = Eigen::MatrixXd::Constant(3, np, 7.0);
  Eigen::Vector3d Pf, Pp;
  full.ToolPointJacobian(q.data(), dir.data(), full.tip(), &Pf, Jf.data());
  part.ToolPointJacobian(q.data(), dir.data(), part.tip(), &Pp, Jp.data());
  EXPECT_EQ(Pf, Pp);
  for (int i = 0; i < np; ++i) {
    const ParameterInfo& p = m.parameters()[i];
    const bool wanted = p.axis < 0 || i == m.location_index(b, 4) || i == m.motion_index(x, 1, 2);
    if (wanted) EXPECT_EQ(Jp.col(i), Jf.col(i)) << p.name;
    else EXPECT_EQ(Jp.col(i), Eigen::Vector3d::Constant(7.0)) << p.name << " was written";
  }
}

// Large location angles and error motions (outside the small-angle series)
// still give the templated kinematics' point.
TEST(KinematicModel, LargeAnglesMatchTemplatedKinematics) {
  const Machine m = Machine::FromJson(kMachines[1]);
  std::mt19937 rng(9);
  Eigen::VectorXd theta = RandomTheta(m, rng);
  for (int k = 0; k < m.num_axes(); ++k)
    for (int c = 3; c < 6; ++c) {
      theta[m.location_index(k, c)] = 0.05 * (c + k) - 0.2;
      theta[m.motion_index(k, c, 1)] = 0.002 * (c - 4);
    }
  const KinematicModel model(m, theta.data());
  // Multi-turn and negative commands exercise the argument reduction.
  for (const double turn : {0.0, 40.0, -1234.5}) {
    std::vector<double> q = {150.0, 0.9 + turn, -2.5 - turn, -80.0, 60.0, 0.05 + turn};
    Eigen::Vector3d P, Pref;
    model.ToolPose(q.data(), nullptr, model.tip(), &P, nullptr);
    ToolInWorkpiece<double>(m, theta.data(), q.data(), nullptr, TipWithOffsets(m, theta.data()), &Pref);
    // A wrong quadrant would be off by millimetres; 1e3 rad commands (and
    // error motions cubic in them) carry ~1e-13 relative rounding.
    EXPECT_LT((P - Pref).norm(), 1e-10 * (1.0 + std::abs(turn))) << "turn " << turn;
  }
}

}  // namespace
}  // namespace fivecal
