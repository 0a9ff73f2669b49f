#include "fivecal/observations/probe_touch.h"

#include <cmath>
#include <stdexcept>

#include "fivecal/model/inverse.h"
#include "fivecal/model/kinematic_model.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {

using namespace json_util;

// ---- instrument table (fivecal import probing) ------------------------------------

KindTable ProbeTouchKind::Table() const {
  KindTable t;
  t.name = "probing";
  t.aliases = {"touch", "probe"};
  t.layout = "touch";
  t.columns = {TableColumn("id", "id").Text(), TableColumn("sigma", "sigma").Measured(),
               TableColumn("target", "target").Text().Required(), TableColumn("type", "type").Text(),
               TableColumn("approach", "approach").Text()};
  t.expected = "target [approach] [id]";
  return t;
}

// ---- trigger model (probe_trigger.h) ------------------------------------------

const char* const kProbeParameterNames[kProbeTerms] = {"probe.pretravel", "probe.axial",   "probe.lobe.c2",
                                                       "probe.lobe.s2",   "probe.lobe.c3", "probe.lobe.s3"};

bool IsProbeParameterName(const std::string& name) {
  for (const char* n : kProbeParameterNames)
    if (name == n) return true;
  return false;
}

void ProbeBasisGradient(const Eigen::Vector3d& u, double* b, Eigen::Matrix<double, kProbeTerms, 3>* g) {
  ProbeBasis<double>(u, b);
  const double x = u[0], y = u[1], z = u[2];
  *g << 0, 0, 0,                                   //
      0, 0, 2 * z,                                 //
      2 * x, -2 * y, 0,                            //
      2 * y, 2 * x, 0,                             //
      3 * x * x - 3 * y * y, -6 * x * y, 0,        //
      6 * x * y, 3 * x * x - 3 * y * y, 0;
}

namespace {

// Rows: the probe frame's x, y, z in F at the zero pose.
Eigen::Matrix3d ProbeAxes(const Machine& m) {
  const Eigen::Vector3d z = m.tool_axis().normalized();
  Eigen::Vector3d x = Eigen::Vector3d::UnitX() - z * z.x();
  if (x.norm() < 0.1) x = Eigen::Vector3d::UnitY() - z * z.y();
  x.normalize();
  Eigen::Matrix3d B;
  B.row(0) = x.transpose();
  B.row(1) = z.cross(x).transpose();
  B.row(2) = z.transpose();
  return B;
}

}  // namespace

namespace {
// The rotation of ChainFrame at zero errors: with every error zero an axis
// frame rotates by its own motion only (the location and error-motion
// rotations are exact identities), so this is the product of the rotary
// axes' rotations, bit for bit, without the sines and cosines of the zero
// angles (this runs for every touch of every Monte Carlo trial).
Eigen::Matrix3d NominalChainRotation(const Machine& m, const std::vector<int>& chain, const Eigen::VectorXd& axes) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  for (int k : chain) {
    const Axis& ax = m.axis(k);
    if (ax.rotary()) R = R * AxisAngle<double>(ax.direction, axes[k] * (M_PI / 180.0));
  }
  return R;
}
}  // namespace

Eigen::Matrix3d ProbeFrameRotation(const Machine& m, const Observation& o) {
  const Eigen::Matrix3d Rt = NominalChainRotation(m, m.tool_chain(), o.axes);
  const Eigen::Matrix3d Rw = NominalChainRotation(m, m.workpiece_chain(), o.axes);
  // A direction v of the probe (F at the zero pose) is Fw.R^T Ft.R v in the
  // workpiece frame (ToolInWorkpiece).
  const Eigen::Matrix3d probe_to_work = Rw.transpose() * Rt;
  return ProbeAxes(m) * probe_to_work.transpose();
}

int ProbeParameterIndex(const ParameterTable& t) { return t.Index(kProbeParameterNames[0]); }

ProbeTrigger MakeProbeTrigger(ResidualBuilder& b, const Observation& o) {
  ProbeTrigger tr;
  const int i0 = ProbeParameterIndex(b.table);
  if (i0 < 0) return tr;
  tr.rotation = ProbeFrameRotation(b.dataset.machine(), o);
  for (int k = 0; k < kProbeTerms; ++k) tr.ref[k] = b.Ref(i0 + k);
  return tr;
}

void PrepareProbeTrigger(const Dataset& ds, const ParameterTable& t, const Observation& o, AnalyticRow* r) {
  r->probe0 = ProbeParameterIndex(t);
  if (r->probe0 >= 0) r->probe_rotation = ProbeFrameRotation(ds.machine(), o);
}

double ProbePretravel(const AnalyticEval& e, const AnalyticRow& r, const Eigen::Vector3d& u_work,
                      Eigen::Vector3d* grad) {
  if (grad) grad->setZero();
  if (r.probe0 < 0) return 0.0;
  const Eigen::Vector3d u = r.probe_rotation * u_work;
  double b[kProbeTerms];
  Eigen::Matrix<double, kProbeTerms, 3> G;
  ProbeBasisGradient(u, b, &G);
  double p = 0.0;
  Eigen::RowVector3d gu = Eigen::RowVector3d::Zero();
  for (int k = 0; k < kProbeTerms; ++k) {
    const double c = e.v[r.probe0 + k];
    p += b[k] * c;
    gu += c * G.row(k);
    e.Put(e.row, r.probe0 + k, b[k]);
  }
  if (grad) *grad = (gu * r.probe_rotation).transpose();
  return p;
}

// ---- ProbeTouchKind -------------------------------------------------------------

void ProbeTouchKind::AddObservationParameters(const Observation&, ParameterTable* t) const {
  if (ProbeParameterIndex(*t) >= 0) return;
  for (const char* n : kProbeParameterNames) t->Add(n);
}

PriorClass ProbeTouchKind::ProbeClass() {
  return {"probe", 0.01, "mm",
          "probe.pretravel|axial|lobe.*: a touch probe's pretravel and its variation with the approach "
          "direction (lobing): up to about 10 um"};
}

const char* ProbeTouchKind::PriorClassOfName(const std::string& n) const {
  return IsProbeParameterName(n) ? "probe" : nullptr;
}

int ProbeTouchKind::RequireTarget(const Dataset& ds, const std::string& id, const std::string& where) const {
  const int i = TargetIndex(ds.artefact, id);
  if (i < 0)
    throw std::invalid_argument(where + ".target: unknown " + name() + " " + Quote(id) + " (not among the artefact's " +
                                name() + "s)");
  return i;
}

Eigen::Vector3d ProbeTouchKind::FittedTipCentre(const ReportContext& c, const Observation& o) {
  const PoseData pose(c.dataset->machine(), o);
  return c.model->ToolPoint(pose.q.data(), pose.dir.data(), c.model->tip());
}

void ProbeTouchKind::Read(const json& o, const std::string& w, const Dataset& ds, Observation* ob) const {
  ob->data<TouchData>().target = ReadString(o, "target", w);
  RequireTarget(ds, ob->data<TouchData>().target, w);
}

void ProbeTouchKind::Write(const Observation& o, json* jo) const {
  const std::string& target = o.data<TouchData>().target;
  if (!target.empty()) (*jo)["target"] = target;
}

void ProbeTouchKind::DefaultSetup(const Dataset& ds, const ParameterTable& t, const Observation& o,
                                  std::set<int>* out) const {
  const int tip = ds.machine().tip_index();
  for (int c = 0; c < 3; ++c) out->insert(tip + c);
  const auto& g = t.group(type(), o.data<TouchData>().target);
  for (int k = 0; k < DefaultTargetParameters(); ++k) out->insert(g[k]);
}

void ProbeTouchKind::Validate(const Dataset& ds, const Observation& o,
                              const std::function<std::string()>& where) const {
  if (ds.tip_radius <= 0)
    throw std::invalid_argument("dataset.probe.tip_radius: missing or zero but the dataset has probe touches");
  RequireTarget(ds, o.data<TouchData>().target, where());
}


void ProbeTouchKind::SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                                   PlanSlot* slot) const {
  const Dataset& ds = *t.dataset;
  const Machine& m = ds.machine();
  const int na = m.num_axes();
  if (ds.tip_radius <= 0)
    throw std::invalid_argument("simulate.probe.tip_radius: missing or zero, but " + w + " is a probe touch");
  if (!e.contains("target") || !e["target"].is_string()) throw std::invalid_argument(w + ".target: missing");
  ob->data<TouchData>().target = e["target"].get<std::string>();
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
  // The true trigger: the tip centre is recorded p(u) beyond the contact, u
  // the inward normal of the true surface (minus the gap's gradient), which
  // the residual sees as gap + p(u) (probe_trigger.h).
  double coef[kProbeTerms];
  bool trigger = false;
  for (int k = 0; k < kProbeTerms; ++k) trigger |= (coef[k] = t.setup(kProbeParameterNames[k])) != 0.0;
  Eigen::Matrix3d M = Eigen::Matrix3d::Identity();
  if (trigger) {
    Observation at = *ob;
    at.axes = c0;
    M = ProbeFrameRotation(m, at);
  }
  auto pretravel = [&](const Eigen::Vector3d& P) {
    if (!trigger) return 0.0;
    const double h = 1e-4;
    Eigen::Vector3d grad;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d e = Eigen::Vector3d::Unit(c) * h;
      grad[c] = (gap(P + e) - gap(P - e)) / (2 * h);
    }
    double b[kProbeTerms];
    ProbeBasis<double>(Eigen::Vector3d(M * (-grad.normalized())), b);
    double p = 0;
    for (int k = 0; k < kProbeTerms; ++k) p += b[k] * coef[k];
    return p;
  };
  auto g = [&](double s) {
    const Eigen::Vector3d P = ToolAtCommand(m, t.theta, c0 + s * d, dir, t.tip);
    return gap(P) + pretravel(P);
  };
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

// ---- What an NC program needs (io/nc_programs.py) -------------------------------

namespace {
// The observation fields a planned touch's geometry reads (one place to
// repoint when the observation's fields move).
void SetTouchTarget(Observation* ob, ObservationType type, const std::string& target) {
  ob->type = type;
  ob->payload = TouchData{};
  ob->data<TouchData>().target = target;
}
}  // namespace

TouchContact ProbeTouchKind::PlannedTouchContact(const Dataset& ds, const json& e, const std::string& w) const {
  if (!e.is_object()) throw std::invalid_argument(w + ": expected a plan entry (an object)");
  if (!e.contains("target") || !e["target"].is_string()) throw std::invalid_argument(w + ".target: missing");
  const std::string target = e["target"].get<std::string>();
  RequireTarget(ds, target, w);
  // The nominal set-up: every set-up parameter zero, the nominal machine.
  PlanTruth truth;
  truth.dataset = &ds;
  truth.theta = Eigen::VectorXd::Zero(ds.machine().num_parameters());
  truth.tip = ds.machine().tip();
  truth.setup = [](const std::string&) { return 0.0; };
  Observation ob;
  SetTouchTarget(&ob, type(), target);
  Eigen::Vector3d n, c;
  Gap gap;
  PlannedTouch(e, w, truth, ob, &n, &c, &gap);
  TouchContact out;
  out.normal = n;
  out.point = c - ds.tip_radius * n;  // PlannedTouch gives the stylus centre
  for (const ClearanceBall& b : ClearanceBalls(ds))
    if (b.id == target) out.clearance = b.radius;
  return out;
}

ProbeCrossing ProbeTouchKind::CrossProbeLine(const Dataset&, const std::string&, const Eigen::Vector3d&,
                                             const Eigen::Vector3d&) const {
  throw std::invalid_argument(std::string("a probe line's crossing with a ") + name() +
                              " target is not modelled (no simulated trip for this kind)");
}

}  // namespace fivecal
