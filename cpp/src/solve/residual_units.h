// Residual rows of different units side by side. A pose observation has
// three position rows (mm) and three rotation rows (rad); a rotation row's
// residual is some 100 times smaller in number than a position row's at the
// same multiple of its noise. One mm threshold or one rms over both would
// never flag a rotation outlier and would report a figure in no unit, so
// the robust loss scale, the rows it flags and the residual summary go
// through here.
#ifndef FIVECAL_SOLVE_RESIDUAL_UNITS_H_
#define FIVECAL_SOLVE_RESIDUAL_UNITS_H_

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"

namespace fivecal {

// Each row's residual expressed at its observation's position noise:
// r_i * s_obs / s_i, with s_i the row's declared sigma and s_obs the largest
// sigma among the observation's rows of its first unit (mm). A rotation row
// 5 sigma off then counts as a position row 5 sigma off; rows of one unit and
// one sigma (every kind but the pose) keep their residual unchanged.
// `source` is Problem::row_source() (observation index, or < 0 for a scale
// bar row: mm).
Eigen::VectorXd PositionScaledResiduals(const Dataset& ds, const Eigen::VectorXd& r, const Eigen::VectorXd& sigma,
                                        const std::vector<int>& source);

// The robust loss scale (mm) when none is given: 3 x the MAD-based sigma of
// the position-scaled residuals.
double DefaultRobustScale(const Eigen::VectorXd& scaled);

// Rows whose position-scaled residual exceeds `scale` (mm).
std::vector<int> RobustOutliers(const Eigen::VectorXd& scaled, double scale);

// The rms, largest |residual| and a posteriori sigma of the rows of each
// unit, the first row unit ("mm") first. `hat` is the covariance of the fit
// in declared-noise units ((Jw^T Jw + P)^-1), so row i took the fraction
// Jw_i hat Jw_i^T of a parameter: a unit's degrees of freedom are its rows
// less those fractions. The first unit gets `dof` less the other units'
// share, so a dataset of one unit keeps sigma = sqrt(sum r^2 / dof).
// The hat products are formed for the rows of the other units only.
std::vector<UnitResiduals> ResidualsByUnit(const Dataset& ds, const Eigen::VectorXd& r,
                                           const std::vector<int>& source, const Eigen::MatrixXd& Jw,
                                           const Eigen::MatrixXd& hat, int dof);

// The same with each unit's share of the parameters given (unit -> sum over
// its rows of Jw_i hat Jw_i^T, i.e. trace(hat Jw_u^T Jw_u)): the
// normal-equation fit has no rows of Jw, only each unit's Jw_u^T Jw_u. The
// rows' units are the fit's own (NormalEquationProblem::row_unit and
// other_units): no walk over the dataset's rows and kinds again.
std::vector<UnitResiduals> ResidualsByUnit(const Eigen::VectorXd& r, const std::vector<unsigned char>& row_unit,
                                           const std::vector<std::string>& other_units,
                                           const std::map<std::string, double>& share, int dof);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_RESIDUAL_UNITS_H_
