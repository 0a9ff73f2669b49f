// Identify, stage 6 of 6 (identify_request.h lists them): the Result, with
// what the data determined, the plausibility of the values, the adequacy of
// the residuals against the declared noise and what the verdict rests on.
#ifndef FIVECAL_SOLVE_IDENTIFY_VERDICT_H_
#define FIVECAL_SOLVE_IDENTIFY_VERDICT_H_

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/identify_covariance.h"
#include "fivecal/solve/identify_determination.h"
#include "fivecal/solve/identify_fit.h"
#include "fivecal/solve/identify_request.h"

namespace fivecal {

Result JudgeResult(const Dataset& ds, const IdentifyOptions& opt, const IdentifyRequest& rq, const IdentifyFit& fit,
                   const IdentifyDetermination& det, const IdentifyCovariance& cov);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_VERDICT_H_
