// IdentifyOptions from the keyword arguments every identifying binding takes
// (identify, monte_carlo, gum), so a new option is wired in one place.
#ifndef FIVECAL_BINDINGS_IDENTIFY_OPTIONS_H_
#define FIVECAL_BINDINGS_IDENTIFY_OPTIONS_H_

#include <map>
#include <string>
#include <vector>

#include "fivecal/solve/identify.h"

namespace fivecal {

inline IdentifyOptions MakeOptions(const std::vector<std::string>& estimate, const std::vector<std::string>& fix,
                                   const std::map<std::string, double>& initial, const std::string& robust,
                                   double robust_scale, int max_iterations, bool include_default_setup,
                                   double selection_tolerance, bool allow_unidentifiable = false,
                                   int num_threads = 0,
                                   const std::map<std::string, double>& priors = {},
                                   bool prior = false) {
  IdentifyOptions o;
  o.estimate = estimate;
  o.fix = fix;
  o.initial = initial;
  o.robust = robust;
  o.robust_scale = robust_scale;
  o.max_iterations = max_iterations;
  o.include_default_setup = include_default_setup;
  o.selection_tolerance = selection_tolerance;
  o.allow_unidentifiable = allow_unidentifiable;
  o.num_threads = num_threads;
  o.priors = priors;
  o.prior = prior;
  return o;
}

}  // namespace fivecal

#endif  // FIVECAL_BINDINGS_IDENTIFY_OPTIONS_H_
