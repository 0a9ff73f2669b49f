// Identify, stage 5 of 6 (identify_request.h lists them): the residual
// statistics, the covariance, the rank and the condition number, from the
// fit's shared factor.
#ifndef FIVECAL_SOLVE_IDENTIFY_COVARIANCE_H_
#define FIVECAL_SOLVE_IDENTIFY_COVARIANCE_H_

#include <Eigen/Core>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_determination.h"
#include "fivecal/solve/identify_fit.h"
#include "fivecal/solve/identify_request.h"

namespace fivecal {

struct IdentifyCovariance {
  Eigen::MatrixXd covariance, correlation;  // estimated x estimated
  Eigen::VectorXd std;
  int rank = 0;
  double condition_number = 0;
  // A MAP fit's posterior in prior units under the documented priors,
  // (Js^T Js + I)^-1 with Js = Jw diag(prior) (empty in least squares).
  Eigen::MatrixXd scaled_posterior;
  double chi2 = 0;      // data rows against the declared noise, outliers left out
  int chi2_rows = 0;
  int dof = 0;
  double chi2_p = 1;
  double rms = 0, max_abs = 0, sigma = 0;
  std::vector<int> outliers;
  std::vector<UnitResiduals> residual_units;
};

IdentifyCovariance CovarianceAtSolution(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq,
                                        const IdentifyFit& fit, const IdentifyDetermination& det);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_COVARIANCE_H_
