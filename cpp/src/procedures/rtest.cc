#include "fivecal/procedures/rtest.h"

#include <cmath>
#include <stdexcept>

#include "fivecal/procedures/sphere_check.h"

namespace fivecal {

std::vector<std::string> RTestLocationErrors(const Machine& m) {
  std::vector<std::string> out;
  for (char a : CheckedRotaryAxes(m))
    for (const std::string& n : PivotParameters(m, a, false)) out.push_back(n);
  return out;
}

RTestResult EvaluateRTest(const Dataset& ds, const RTestOptions& options) {
  for (size_t i = 0; i < options.estimate.size(); ++i)
    if (options.estimate[i].empty())
      throw std::invalid_argument("estimate[" + std::to_string(i) + "]: an empty parameter name");
  RTestResult out;
  for (size_t i = 0; i < ds.observations.size(); ++i) {
    const Observation& o = ds.observations[i];
    if (o.type != ObservationType::kBall3d) continue;
    const std::string name = o.setup.empty() ? "(no setup)" : o.setup;
    RTestGroup* g = nullptr;
    for (RTestGroup& t : out.tests)
      if (t.name == name) g = &t;
    if (!g) {
      out.tests.emplace_back();
      g = &out.tests.back();
      g->name = name;
    }
    g->observations.push_back(static_cast<int>(i));
  }
  if (out.tests.empty()) throw std::invalid_argument("R-test: the dataset has no ball3d observations");
  for (RTestGroup& g : out.tests) {
    g.deviations.resize(g.observations.size(), 3);
    for (size_t k = 0; k < g.observations.size(); ++k)
      g.deviations.row(k) = ds.observations[g.observations[k]].measured.transpose();
    g.ranges = (g.deviations.colwise().maxCoeff() - g.deviations.colwise().minCoeff()).transpose();
  }
  if (options.identify) {
    out.estimated = options.estimate.empty() ? RTestLocationErrors(ds.machine()) : options.estimate;
    IdentifyOptions io;
    io.estimate = out.estimated;
    out.fit = Identify(ds, io);
    out.identified = true;
  }
  return out;
}

}  // namespace fivecal
