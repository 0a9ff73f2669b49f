// Helpers shared by the controller gtests (absorber, LinuxCNC trt, vendor
// export path, Beckhoff): random poses over a working volume and an error
// vector from names.
#ifndef FIVECAL_TESTS_CONTROLLER_FIXTURES_H_
#define FIVECAL_TESTS_CONTROLLER_FIXTURES_H_

#include <Eigen/Core>
#include <map>
#include <random>
#include <string>

#include "fivecal/model/machine.h"

namespace fivecal {
namespace test_fixtures {

// Poses over a working volume: linear +-100 mm, A/B -90..60, C a full turn.
inline Eigen::MatrixXd Poses(const Machine& m, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> lin(-100, 100), tilt(-90, 60), rot(-180, 180);
  Eigen::MatrixXd q = Eigen::MatrixXd::Zero(n, m.num_axes());
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < m.num_axes(); ++k) {
      const char a = m.axis(k).name;
      q(i, k) = a == 'S' ? 0.0 : a == 'C' ? rot(rng) : (a == 'A' || a == 'B') ? tilt(rng) : lin(rng);
    }
  return q;
}

// The machine's parameter vector with the named errors set, the rest 0.
inline Eigen::VectorXd Theta(const Machine& m, const std::map<std::string, double>& errors) {
  Eigen::VectorXd th = Eigen::VectorXd::Zero(m.num_parameters());
  for (const auto& [n, v] : errors) th[m.RequireParameter(n)] = v;
  return th;
}

}  // namespace test_fixtures
}  // namespace fivecal

#endif  // FIVECAL_TESTS_CONTROLLER_FIXTURES_H_
