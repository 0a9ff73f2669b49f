// Identifiability: the undetermined groups depend on the free and weak
// subspaces of the Jacobian, not on the basis an SVD picks inside them, so
// the fast decomposition AnalyzeDetermination uses groups as Jacobi does.
#include <gtest/gtest.h>

#include "test_files.h"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/identifiability.h"
#include "fivecal/solve/priors.h"
#include "fivecal/solve/problem.h"

namespace fivecal {
namespace {

using Groups = std::vector<std::vector<int>>;

Eigen::MatrixXd RandomOrthogonal(int m, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g;
  Eigen::MatrixXd A(m, m);
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) A(i, j) = g(rng);
  return Eigen::HouseholderQR<Eigen::MatrixXd>(A).householderQ();
}

// A Jacobian with three separate exactly free directions (columns 1 = 0,
// 3 = 2, 4 = 0 vector: e0 - e1, e2 - e3, e4), one weak direction (column 6
// seen at 1e-3) and well determined columns 5, 7.
Eigen::MatrixXd ThreeFreeDirections() {
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  Eigen::MatrixXd J(40, 8);
  for (int i = 0; i < J.rows(); ++i)
    for (int j = 0; j < J.cols(); ++j) J(i, j) = 10 * g(rng);
  J.col(1) = J.col(0);
  J.col(3) = J.col(2);
  J.col(4).setZero();
  J.col(6) *= 1e-4;
  return J;
}

std::vector<bool> Bad(const Determination& d, int p) {
  std::vector<bool> bad(p, false);
  for (int j : d.undetermined) bad[j] = true;
  return bad;
}

TEST(Identifiability, GroupsDoNotDependOnTheBasisOfADegenerateFreeSpace) {
  const Eigen::MatrixXd J = ThreeFreeDirections();
  const int p = static_cast<int>(J.cols());
  const Determination d = AnalyzeDetermination(J, Eigen::VectorXd::Ones(p), kDeterminedRatio);
  EXPECT_EQ(d.groups, (Groups{{0, 1}, {2, 3}, {4}, {6}}));

  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeFullV);
  const Eigen::VectorXd s = svd.singularValues();
  const double zero = 1e-12 * std::max(s[0], 1.0), weak = 1.0 / kDeterminedRatio;
  const std::vector<bool> bad = Bad(d, p);
  // Any rotation of the three-dimensional free space is as good a basis of
  // it; read off the vectors' supports, a mixed basis joins all five columns.
  for (unsigned seed : {1u, 2u, 3u}) {
    Eigen::MatrixXd V = svd.matrixV();
    V.rightCols(3) = V.rightCols(3) * RandomOrthogonal(3, seed);
    EXPECT_EQ(UndeterminedGroups(s, V, bad, zero, weak), d.groups) << "seed " << seed;
  }
}

TEST(Identifiability, GroupsFollowAPermutationOfTheColumns) {
  const Eigen::MatrixXd J = ThreeFreeDirections();
  const int p = static_cast<int>(J.cols());
  const std::vector<int> perm = {7, 4, 2, 6, 0, 5, 3, 1};  // new column k is old column perm[k]
  Eigen::MatrixXd Jp(J.rows(), p);
  for (int k = 0; k < p; ++k) Jp.col(k) = J.col(perm[k]);
  const Determination d = AnalyzeDetermination(Jp, Eigen::VectorXd::Ones(p), kDeterminedRatio);
  Groups old;
  for (const auto& g : d.groups) {
    std::vector<int> o;
    for (int k : g) o.push_back(perm[k]);
    std::sort(o.begin(), o.end());
    old.push_back(o);
  }
  std::sort(old.begin(), old.end());
  EXPECT_EQ(old, (Groups{{0, 1}, {2, 3}, {4}, {6}}));
}

// A well determined set (every singular value well above 1 / threshold) is
// judged without singular vectors; the ratios and singular values are the
// SVD's.
TEST(Identifiability, DeterminedSetWithoutSingularVectorsAgreesWithTheSvd) {
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  Eigen::MatrixXd J(50, 6);
  for (int i = 0; i < J.rows(); ++i)
    for (int j = 0; j < J.cols(); ++j) J(i, j) = g(rng);
  J.col(5) = J.col(4) + 0.3 * J.col(5);  // correlated, still determined
  J *= 5;
  const Eigen::VectorXd prior = (Eigen::VectorXd(6) << 1, 2, 3, 0.5, 4, 4).finished();
  const Determination d = AnalyzeDetermination(J, prior, kDeterminedRatio);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J * prior.asDiagonal(), Eigen::ComputeFullV);
  const Eigen::VectorXd s = svd.singularValues();
  ASSERT_GT(s[5], 2.0 / kDeterminedRatio);
  const Eigen::MatrixXd& V = svd.matrixV();
  EXPECT_EQ(d.rank, 6);
  EXPECT_TRUE(d.undetermined.empty());
  EXPECT_TRUE(d.groups.empty());
  for (int j = 0; j < 6; ++j) {
    double r2 = 0;
    for (int k = 0; k < 6; ++k) r2 += V(j, k) * V(j, k) / (s[k] * s[k]);
    EXPECT_NEAR(d.ratio[j], std::sqrt(r2), 1e-12 * std::sqrt(r2)) << j;
    EXPECT_NEAR(d.singular_values[j], s[j], 1e-10 * s[0]) << j;
  }
}

// AnalyzeDetermination (QR, then divide and conquer) against a one-sided
// Jacobi SVD of the whole prior-scaled Jacobian, on TANGO data for parameter
// sets from well determined to heavily confounded.
TEST(Identifiability, FastDeterminationGroupsAsJacobiOnTangoData) {
  const Dataset ds = Simulate(ReadFile(std::string(FIVECAL_SOURCE_DIR) + "/tests/data/tango_thin_spec.json"));
  const ParameterTable table(ds);
  const std::vector<int> setup = table.DefaultSetup(ds);
  const int nm = table.num_machine();
  std::vector<std::vector<int>> sets;
  for (int step : {1, 2, 3, 5}) {
    std::vector<int> est = setup;
    for (int i = 0; i < nm; i += step)
      if (std::find(setup.begin(), setup.end(), i) == setup.end()) est.push_back(i);
    sets.push_back(est);
  }
  int groups_seen = 0;
  for (const std::vector<int>& est : sets) {
    std::vector<std::string> names;
    for (int i : est) names.push_back(table.names()[i]);
    const std::vector<double> pr = PriorScales(ds.machine(), names, {}, {});
    const Eigen::VectorXd prior = Eigen::Map<const Eigen::VectorXd>(pr.data(), pr.size());
    Problem problem(ds, table, Eigen::VectorXd::Zero(table.size()), est);
    Eigen::VectorXd r;
    Eigen::MatrixXd J;
    problem.Evaluate(&r, &J);
    const Eigen::MatrixXd Jw = problem.row_sigma().cwiseInverse().asDiagonal() * J;
    const int p = static_cast<int>(est.size());
    const Determination d = AnalyzeDetermination(Jw, prior, kDeterminedRatio);

    Eigen::JacobiSVD<Eigen::MatrixXd> svd(Jw * prior.asDiagonal(), Eigen::ComputeFullV);
    const Eigen::VectorXd s = svd.singularValues();
    const Eigen::MatrixXd& V = svd.matrixV();
    const double zero = 1e-12 * std::max(s[0], 1.0), weak = 1.0 / kDeterminedRatio;
    Eigen::VectorXd ratio2 = Eigen::VectorXd::Zero(p), free2 = Eigen::VectorXd::Zero(p);
    for (int k = 0; k < p; ++k) {
      const double sk = k < s.size() ? s[k] : 0.0;
      for (int j = 0; j < p; ++j) {
        if (sk > zero) ratio2[j] += std::abs(V(j, k)) >= 1e-9 ? V(j, k) * V(j, k) / (sk * sk) : 0.0;
        else free2[j] += V(j, k) * V(j, k);
      }
    }
    std::vector<int> undetermined;
    std::vector<bool> bad(p, false);
    for (int j = 0; j < p; ++j)
      if (free2[j] >= 1e-18 || !(std::sqrt(ratio2[j]) < kDeterminedRatio)) undetermined.push_back(j), bad[j] = true;
    EXPECT_EQ(d.undetermined, undetermined) << p << " parameters";
    EXPECT_EQ(d.groups, UndeterminedGroups(s, V, bad, zero, weak)) << p << " parameters";
    groups_seen += static_cast<int>(d.groups.size());
  }
  EXPECT_GT(groups_seen, 2);  // the comparison saw undetermined groups
}

}  // namespace
}  // namespace fivecal
