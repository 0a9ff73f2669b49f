// AnalyticResiduals: every residual row of a dataset as ONE Ceres cost
// function with analytic derivatives from KinematicModel. Same residual
// definitions as the functors of residuals.h (facet, sphere, scale bar, dbb,
// ball3d) and the same row order (observations in order, then the scale bars
// whose balls were probed); the functors stay the reference the tests compare
// against. One block lets the kinematic constants be prepared once per
// evaluation instead of once per touch, and avoids Jets entirely.
//
// Chain rule per row, with P the tool point and J = dP/dtheta:
//   facet   r = n.(P - a) - r_tip - f        dr/dtheta = n^T J,  dr/df = -1
//   sphere  r = |P - c - dc| - (R + r_tip + dR)
//                                             dr/dtheta = u^T J,  dr/ddc = -u^T, dr/ddR = -1
//   bar     r = |c1 + d1 - c2 - d2| - L       dr/dd1 = u^T, dr/dd2 = -u^T
//   dbb     r = |P_ball - t - dt| - (L + dL + reading), the tool ball's tip
//           being tool_ball + dbb.tool:       dr/dtool = u^T dP/dtip, dr/ddt = -u^T, dr/ddL = -1
//   ball3d  r = P_ball - t - dt - measured    dr/dtool = dP/dtip, dr/ddt = -I
// (u the unit vector of the distance.) For ball samples the probe tip
// offsets tip.x|y|z do not enter.
#ifndef FIVECAL_ANALYTIC_RESIDUALS_H_
#define FIVECAL_ANALYTIC_RESIDUALS_H_

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

class AnalyticResiduals : public ceres::CostFunction {
 public:
  // values: every parameter of the table (constants for the fixed ones);
  // estimated: the table indices that are the parameter blocks, in order.
  AnalyticResiduals(const Dataset& ds, const ParameterTable& table, const Eigen::VectorXd& values,
                    const std::vector<int>& estimated);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  // Per row: the observation index, or -(1 + scale bar index).
  const std::vector<int>& row_source() const { return row_source_; }

 private:
  struct Row {
    ObservationType type = ObservationType::kFacet;
    bool bar = false;
    std::vector<double> q;   // internal units
    std::vector<int> dir;
    Eigen::Vector3d a = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();  // facet point/normal; sphere centre; ball positions
    Eigen::Vector3d tool_ball = Eigen::Vector3d::Zero(), measured = Eigen::Vector3d::Zero();
    double constant = 0;     // facet: r_tip; sphere: R + r_tip; dbb: L + reading; bar: L
    int idx[8] = {-1, -1, -1, -1, -1, -1, -1, -1};  // setup parameter indices
  };

  const Dataset& ds_;
  Eigen::VectorXd values_;
  std::vector<int> estimated_;
  std::vector<int> block_of_;  // per table index: block or -1
  std::vector<Row> rows_;      // one per observation or bar (ball3d gives 3 residual rows)
  std::vector<int> row_source_;
};

}  // namespace fivecal

#endif  // FIVECAL_ANALYTIC_RESIDUALS_H_
