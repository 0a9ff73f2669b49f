// Test design: how well a measurement plan identifies a parameter set, and a
// search that picks K rotary indexations (and their targets) from a pool of
// candidates to minimise the condition number (thesis ch. 8, Table 8-4).
//
// A plan is judged on the Jacobian of its residuals at a linearisation point
// (nominal by default), over the parameters `Identify` would estimate on it:
// the requested machine errors plus the default setup set the plan implies
// (tip.x|y|z, every touched facet, every touched sphere centre, ...).
//
//   condition number   sigma_max / sigma_min of the column-scaled Jacobian,
//                      exactly what Identify reports (identifiability.h);
//   D-optimality       d_criterion = (1/p_m) log det(S_m), S_m the information
//                      about the p_m machine parameters once the setup
//                      parameters are eliminated (Schur complement of J^T J,
//                      "Ds-optimality"), with every machine parameter in
//                      characteristic units (CharacteristicScale: the error a
//                      1 mm parameter change makes at a length L, 400 mm by
//                      default, as thesis Table 6-1 sizes its errors);
//                      d_std = sigma exp(-d_criterion / 2) is the geometric
//                      mean of the predicted standard uncertainties in those
//                      units (mm); larger d_criterion / smaller d_std is better;
//   predicted_std      sigma sqrt(diag (J^T J)^+), parameter units.
//
// The search works on per-observation information matrices M_o = J_o^T J_o
// (p x p, p the parameters of the whole pool), so one evaluation costs O(p^3)
// whatever the number of touches: a p x p eigen-decomposition for the
// condition number and for rank-deficient selections; for the D-criterion of
// a full-rank one, an elimination of the setup columns and a Cholesky
// factorisation of the machine block, its full rank certified against the
// step's reference selection (same value to rounding, about ten times
// cheaper). The chosen plan is then assessed exactly from its Jacobian rows
// (AssessPlan). Candidates are grouped into indexations (a group: the
// touches made at one rotary pose); the search picks K groups: forward
// greedy (rank first, then the criterion), then exchange passes
// (Fedorov-style swaps of one chosen and one unchosen group, best improving
// swap first) until no swap improves. Optionally, touches are then removed
// one at a time (the one whose removal hurts least) down to a touch budget:
// the "targets" of the chosen indexations.
//
// Accessibility: CandidatePlan lists, for each candidate indexation, the
// targets a probe can touch there: facets whose outward normal does not face
// away from the spindle (n . a >= min_dot, a the nominal tool axis in the
// workpiece frame, pointing from the stylus ball to the spindle) and sphere
// touches likewise, with every axis command of the nominal touch within its
// limits. Collision checks with fixtures are the caller's (e.g.
// fivecal.tango.facet_accessible) and can prune the plan afterwards.
//
// Units: mm, degrees for rotary commands, rad for angular errors.
#ifndef FIVECAL_DESIGN_H_
#define FIVECAL_DESIGN_H_

#include <Eigen/Core>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"

namespace fivecal {

struct DesignOptions {
  // As IdentifyOptions::estimate / fix: names and presets (S1..S4, location, auto).
  std::vector<std::string> estimate;
  std::vector<std::string> fix;
  // Linearisation point (and fixed values), name -> value; unnamed = 0 (nominal).
  std::map<std::string, double> values;
  bool include_default_setup = true;
  double sigma = 0.0006;                  // mm, measurement noise for predicted_std / d_std
  double characteristic_length = 400.0;   // mm, for the D-optimality units
  double rank_tolerance = 1e-9;           // as AnalyzeJacobian
};

struct PlanQuality {
  std::vector<std::string> parameters;  // estimated: machine errors, then setup
  int n_observations = 0;
  int n_rows = 0;
  int n_parameters = 0;
  int n_machine = 0;                    // machine parameters (the rest is setup)
  double condition_number = 0.0;        // column-scaled; inf if rank deficient
  int rank = 0;
  double log_det_per_parameter = 0.0;   // of the column-scaled J^T J (<= 0)
  double d_criterion = 0.0;             // Ds-optimality, characteristic units; -inf if singular
  double d_std = 0.0;                   // mm; inf if singular
  Eigen::VectorXd predicted_std;        // per parameter, parameter units
  std::vector<std::vector<std::string>> confounded;
  std::string ToJson() const;
};

// The size (mm) of the error a unit change of the parameter makes at the
// characteristic length L: 1 for mm parameters (location offsets, tip,
// setup, linear backlash, linear components of rotary-axis error motions per
// rad^d), L for angular ones (location angles, rotary backlash, angular
// components of rotary-axis error motions), L^d for degree-d linear
// components of linear-axis error motions and L^(d+1) for their angular ones.
// 1e-3 / scale is the thesis Table 6-1 value (1 um, 2.5 urad, 2.5 um/m at 400 mm).
double CharacteristicScale(const Machine& m, const std::string& name, double length);

// Quality of the plan made by `subset` (observation indices; null = all) of ds.
PlanQuality AssessPlan(const Dataset& ds, const DesignOptions& options,
                       const std::vector<int>* subset = nullptr);

struct SearchOptions {
  int k = 0;                       // indexations (groups) to pick, 1..number of groups
  std::vector<int> required;       // groups always kept (counted in k)
  std::string criterion = "condition";  // "condition" (minimise) or "d" (maximise d_criterion)
  std::string method = "exchange";      // "greedy" or "exchange"
  int max_passes = 50;             // exchange passes
  int max_touches = 0;             // > 0: then drop single touches down to this budget
  // Called after every evaluation batch: (phase, done, total, best criterion);
  // return false to stop (the best plan so far is returned, `stopped` set).
  std::function<bool(const std::string&, int, int, double)> progress;
};

struct DesignResult {
  std::vector<int> groups;        // chosen groups, ascending
  std::vector<int> observations;  // chosen observations, ascending
  PlanQuality quality;            // the chosen plan (exact, from its Jacobian)
  PlanQuality reference;          // the whole pool
  std::vector<double> history;    // criterion after each accepted step
  int evaluations = 0;
  bool stopped = false;
  std::string ToJson() const;
};

// `group[i]` is the indexation (0..G-1) of observation i of the candidate pool
// `candidates` (a dataset of the touches the plan could make, e.g. simulated
// noise-free on the nominal machine). Throws std::invalid_argument for bad
// groups, k or options.
DesignResult DesignPlan(const Dataset& candidates, const std::vector<int>& group,
                        const DesignOptions& options, const SearchOptions& search);

struct Accessibility {
  std::map<char, std::pair<double, double>> limits;  // axis -> [min, max], mm / degrees
  double min_dot = -0.02;  // facet or sphere touch normal . tool axis >= min_dot
  std::vector<std::string> targets;  // facet / sphere ids to use (empty: every facet and sphere)
};

// Plan entries (the JSON array `simulate` takes) touching every accessible
// target at each indexation. `indexations` is N x num_axes (machine axis
// order, degrees; only the rotary columns are used), `directions` optional
// N x num_axes last-move directions recorded with the touches. Facets are
// touched at their nominal point, spheres along each of `sphere_normals`
// (unit vectors from the centre, workpiece frame). `group` (if given)
// receives the indexation row of each entry.
std::string CandidatePlan(const Dataset& setup, const Eigen::MatrixXd& indexations,
                          const Eigen::MatrixXi* directions,
                          const std::vector<Eigen::Vector3d>& sphere_normals,
                          const Accessibility& access, std::vector<int>* group = nullptr);

namespace internal {

// Test hook for the search's D-criterion scoring: random selections of the
// pool's groups (built by adding and removing groups, as the exchange does),
// each changed by adding an unchosen group or removing one chosen touch, scored
// as DesignPlan scores candidates and by the eigen-decomposition.
struct ScoreCheck {
  double fast = 0, exact = 0;          // d_criterion; -inf when rank deficient
  int fast_deficiency = 0, exact_deficiency = 0;
  bool fast_path = false;              // the eigen-decomposition was avoided
  bool removal = false;
};
std::vector<ScoreCheck> CheckDesignScores(const Dataset& candidates, const std::vector<int>& group,
                                          const DesignOptions& options, int states, unsigned seed);

}  // namespace internal

}  // namespace fivecal

#endif  // FIVECAL_DESIGN_H_
