// Identify, stage 1 of 6: request -> problem -> fit -> determination ->
// covariance -> verdict (identify.cc runs them in that order).
//
// The request stage turns the options into what is estimated: the parameter
// table, the start values, the priors and placements of every parameter, and
// the estimated set (presets expanded, "location" selected on the data near
// its solution, "auto" every candidate).
#ifndef FIVECAL_SOLVE_IDENTIFY_REQUEST_H_
#define FIVECAL_SOLVE_IDENTIFY_REQUEST_H_

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/identify.h"
#include "fivecal/solve/problem.h"

namespace fivecal {

struct IdentifyRequest {
  explicit IdentifyRequest(const Dataset& ds) : table(ds) {}
  ParameterTable table;
  // Per table entry: the user's start values (`initial`), the plausible size
  // (prior sigma), the placement uncertainty of set-up quantities (0: none)
  // and the prior of a MAP fit (the plausible size narrowed by the placement:
  // 1/s^2 = 1/prior^2 + 1/placement^2).
  Eigen::VectorXd initial, prior_all, placement_all, map_prior_all;
  std::vector<int> forced;      // explicit names, presets, default setup
  std::vector<int> candidates;  // "location" / "auto" candidates, in priority order
  bool location = false, automatic = false;
  bool map = false;             // prior rows in the fit ("auto" or prior=true)

  // The estimated set (table indices) and where its fit starts (every table
  // entry: `initial`, with the "location" selection's solution on `est`).
  std::vector<int> est;
  std::vector<std::string> estimated;  // names of `est`
  // "location": the candidates its selection left out, each with why.
  std::vector<std::pair<std::string, std::string>> left_out;
  // d(estimate)/d(left-out candidate) at the selection's solution (Result::left_out_moves).
  std::vector<LeftOutMoves> left_out_moves;
  Eigen::VectorXd start;
  // Per estimated parameter: the prior that scales the determination (a MAP
  // fit's prior rows, a set-up quantity's narrowed by its placement; in least
  // squares the plausible size), the placement that enters least squares as a
  // row of its own (0 in a MAP fit, whose prior holds it), and those rows
  // (`ls_rows`, per table entry; empty: none).
  Eigen::VectorXd prior, place, ls_rows;
  bool placed = false;  // ls_rows not empty
};

// Everything but the estimated set: options validated, table, priors,
// placements, the forced set and the candidates.
IdentifyRequest PrepareRequest(const Dataset& ds, const IdentifyOptions& options);

// The whole request: PrepareRequest, then the estimated set resolved (for
// "location" by fits and selections until the set is stable). Throws when
// nothing is left to estimate.
IdentifyRequest ResolveRequest(const Dataset& ds, const IdentifyOptions& options);

// Gather(all, idx)[k] = all[idx[k]].
Eigen::VectorXd Gather(const Eigen::VectorXd& all, const std::vector<int>& idx);

}  // namespace fivecal

#endif  // FIVECAL_SOLVE_IDENTIFY_REQUEST_H_
