#include "fivecal/observations/probe_touch.h"

#include <cmath>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/observations/simulate.h"
#include "json_util.h"

namespace fivecal {

using namespace json_util;

void ProbeTouchKind::Validate(const Dataset& ds, const Observation& o,
                              const std::function<std::string()>& where) const {
  if (ds.tip_radius <= 0)
    throw std::invalid_argument("dataset.probe.tip_radius: missing or zero but the dataset has probe touches");
  ValidateTarget(ds, o, where);
}


void ProbeTouchKind::SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                                   PlanSlot* slot) const {
  const Dataset& ds = *t.dataset;
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  if (ds.tip_radius <= 0)
    throw std::invalid_argument("simulate.probe.tip_radius: missing or zero, but " + w + " is a probe touch");
  if (!e.contains("target") || !e["target"].is_string()) throw std::invalid_argument(w + ".target: missing");
  ob->target = e["target"].get<std::string>();
  Eigen::Vector3d n, c;
  Gap gap;
  PlannedTouch(e, w, t, *ob, &n, &c, &gap);
  // Nominal linear commands for the tip-centre target and the approach line.
  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());
  Eigen::MatrixXd target(2, 3);
  target.row(0) = c.transpose();
  target.row(1) = (c - n).transpose();
  const Eigen::MatrixXd cmds = InverseKinematics(m, nominal, target, nullptr, ob->axes);
  const Eigen::VectorXd c0 = cmds.row(0).transpose();
  const Eigen::VectorXd d = (cmds.row(1) - cmds.row(0)).transpose();  // per mm of approach
  std::vector<int> dir(ob->direction.data(), ob->direction.data() + na);
  for (int k = 0; k < na; ++k)
    if (!m.axis(k).rotary()) dir[k] = d[k] > 1e-12 ? 1 : (d[k] < -1e-12 ? -1 : 0);
  auto g = [&](double s) { return gap(ToolAtCommand(m, t.theta, c0 + s * d, dir, t.tip)); };
  double s = 0;
  for (int it = 0; it < 60; ++it) {
    const double h = 1e-4;
    const double gs = g(s), gp = (g(s + h) - g(s - h)) / (2 * h);
    if (!(std::abs(gp) > 1e-6)) throw std::invalid_argument(w + ": the approach does not reach the surface");
    const double ds_ = -gs / gp;
    s += ds_;
    if (std::abs(ds_) < 1e-13) break;
  }
  if (std::abs(s) > 50.0)
    throw std::invalid_argument(w + ": the erroneous machine touches " + std::to_string(s) +
                                " mm away from the nominal point; errors far too large?");
  const double h = 1e-4;
  slot->start = c0;
  slot->approach = d;
  slot->s0 = s;
  slot->sensitivity = (g(s + h) - g(s - h)) / (2 * h);
  ob->axes = c0 + s * d;
  for (int k = 0; k < na; ++k) ob->direction[k] = dir[k];
}

void ProbeTouchKind::AddInputs(SimulationPlan* plan, int i, const PlanSlot* slot,
                               const RecordedContext* rec) const {
  if (slot) {
    plan->start[i] = slot->start;
    plan->approach[i] = slot->approach;
    plan->s0[i] = slot->s0;
    AddPlanInput(plan, i, 0, slot->sensitivity, NoiseLevel(plan->noise));
    return;
  }
  // Nominal approach: along minus the nominal surface normal at the nominal
  // tool point, as a line in linear-axis command space.
  const Dataset& ds = *rec->dataset;
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  const Observation& o = ds.observations[i];
  const std::string w = "observations[" + std::to_string(i) + "]";
  std::vector<int> dir(o.direction.data(), o.direction.data() + na);
  const Eigen::VectorXd nominal = Eigen::VectorXd::Zero(m.num_parameters());
  const Eigen::Vector3d P0 = ToolAtCommand(m, nominal, o.axes, dir, m.tip());
  Eigen::Vector3d n;
  Gap gap;
  RecordedTouch(*rec, o, P0, w, &n, &gap);
  Eigen::MatrixXd target(2, 3);
  target.row(0) = P0.transpose();
  target.row(1) = (P0 - n).transpose();
  const Eigen::MatrixXd cmds = InverseKinematics(m, nominal, target, nullptr, o.axes);
  Eigen::VectorXd d = (cmds.row(1) - cmds.row(0)).transpose();
  for (int k = 0; k < na; ++k)
    if (m.axis(k).rotary()) d[k] = 0.0;
  plan->start[i] = o.axes;
  plan->approach[i] = d;
  plan->s0[i] = 0.0;
  const double h = 1e-4;
  const double sens = (gap(ToolAtCommand(m, rec->theta, o.axes + h * d, dir, rec->tip)) -
                       gap(ToolAtCommand(m, rec->theta, o.axes - h * d, dir, rec->tip))) / (2 * h);
  if (!(std::abs(sens) > 1e-6))
    throw std::invalid_argument(w + ": the nominal approach does not move the tip off the surface");
  AddPlanInput(plan, i, 0, sens, NoiseLevel(plan->noise));
}

void ProbeTouchKind::ApplyInput(const SimulationPlan& plan, int i, int, double x, Observation* o) const {
  const double s = plan.s0[i] + x;
  o->axes = plan.start[i] + s * plan.approach[i];
}

}  // namespace fivecal
