// What the probe-touch kinds (facet, sphere, cylinder) share: a stylus tip of
// radius dataset.probe.tip_radius touching an artefact surface, and the
// probe's trigger model (pretravel and lobing, probe_trigger.h) with its
// setup parameters probe.*, which the first probe touch brings into the
// parameter table. Simulated touches approach along the nominal surface
// normal and trigger the true pretravel beyond the contact; the noise is the
// trigger position along that approach line.
#ifndef FIVECAL_OBSERVATIONS_PROBE_TOUCH_H_
#define FIVECAL_OBSERVATIONS_PROBE_TOUCH_H_

#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/probe_trigger.h"

namespace fivecal {

// A planned touch as an NC program writer needs it (ProbeTouchKind::
// PlannedTouchContact), workpiece frame, mm.
struct TouchContact {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();    // nominal contact point on the surface
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // outward unit normal there: the stylus comes in along -normal
  // The radius of the ball around the target the moves keep out of (its
  // ClearanceBalls entry), 0 when none is modelled.
  double clearance = 0;
};

// A target's solid as the program's moves see it: a ball.
struct ClearanceBall {
  std::string id;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius = 0;
};

// The first crossing of a probe line with a target (ProbeTouchKind::
// CrossProbeLine).
struct ProbeCrossing {
  bool inside = false;  // the line starts on or inside the target's offset surface
  double s = 0;         // the crossing p + s d (infinite: none ahead)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // outward unit surface normal at the crossing
};

class ProbeTouchKind : public ObservationKind {
 public:
  // Touch probe noise: a good kinematic touch-trigger probe's repeatability.
  double default_sigma() const override { return 0.001; }
  bool probe_touch() const override { return true; }
  // One probing log for every probe touch: each row names its target, whose
  // artefact list says the kind.
  KindTable Table() const final;

  // A touch names its target, one of the artefact's <name()>s; the file has
  // nothing else of the kind's own.
  std::vector<const char*> json_keys() const final { return {"type", "target", "axes", "direction", "sigma", "id"}; }
  void Read(const nlohmann::json& o, const std::string& where, const Dataset& ds, Observation* ob) const final;
  void Write(const Observation& o, nlohmann::json* out) const final;
  ObservationPayload NewPayload() const final { return TouchData{}; }
  // The flat form: the target alone (slot 0).
  const std::vector<FlatKey>& flat_keys() const final {
    static const std::vector<FlatKey> keys = {{"target", FlatKey::kText, true}};
    return keys;
  }
  bool ReadFlat(const FlatObservation& f, const Artefact& a, Observation* ob) const final {
    if (!f.has(0) || TargetIndex(a, f.text(0)) < 0) return false;
    ob->data<TouchData>().target = f.text(0);
    return true;
  }
  bool WriteFlat(const Observation& o, FlatObservation* f) const final {
    if (!o.setup.empty()) return false;  // not a touch's key: the reference writer says so
    const std::string& target = o.data<TouchData>().target;
    if (!target.empty()) f->set_text(0, &target);
    return true;
  }
  // A planned touch: its target and where on it ("point"; a sphere's
  // touches say "normal" instead).
  std::vector<const char*> plan_keys() const override { return {"type", "target", "axes", "point", "direction", "id"}; }
  // The stylus tip and the first DefaultTargetParameters() of the target's
  // setup group.
  void DefaultSetup(const Dataset& ds, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const final;
  void Validate(const Dataset& ds, const Observation& o,
                const std::function<std::string()>& where) const final;
  void SimulateEntry(const nlohmann::json& e, const std::string& where, const PlanTruth& t,
                     Observation* ob, PlanSlot* slot) const final;
  const char* noise_class() const final { return "probe"; }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot* slot, const RecordedContext* rec) const final;
  void ApplyInput(const SimulationPlan& plan, int i, int component, double x, Observation* o) const final;
  // probe.pretravel ... probe.lobe.s3, on the first probe touch.
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override;
  std::vector<PriorClass> prior_classes() const override { return {ProbeClass()}; }
  const char* PriorClassOfName(const std::string& n) const override;
  int ArtefactTarget(const Dataset& ds, const Observation& o) const final {
    return TargetIndex(ds.artefact, o.data<TouchData>().target);
  }

 protected:
  static PriorClass ProbeClass();
  // The index of the artefact's target `id` of this kind (-1: none).
  virtual int TargetIndex(const Artefact& a, const std::string& id) const = 0;
  // How many of the target's setup parameters, in group order, a touch
  // estimates by default.
  virtual int DefaultTargetParameters() const = 0;
  // TargetIndex, or std::invalid_argument naming `where`.target.
  int RequireTarget(const Dataset& ds, const std::string& id, const std::string& where) const;
  // The stylus tip centre of touch `o` at the fit (workpiece frame): where
  // the report draws the touch's residual.
  static Eigen::Vector3d FittedTipCentre(const ReportContext& c, const Observation& o);
  using Gap = std::function<double(const Eigen::Vector3d&)>;
  // A planned touch on target ob->data<TouchData>().target: the surface normal n at the touch,
  // the nominal tip-centre target c, and the signed distance of the true
  // surface from a tip centre P (zero at the touch).
  virtual void PlannedTouch(const nlohmann::json& e, const std::string& where, const PlanTruth& t,
                            const Observation& ob, Eigen::Vector3d* n, Eigen::Vector3d* c, Gap* gap) const = 0;
  // A recorded touch: the nominal surface normal at the nominal tool point
  // P0, and a function of the tip centre whose change along the approach is
  // the sensitivity of the touch.
  virtual void RecordedTouch(const RecordedContext& rec, const Observation& o, const Eigen::Vector3d& P0,
                             const std::string& where, Eigen::Vector3d* n, Gap* gap) const = 0;

  // ---- What an NC program needs (io/nc_programs.py; docs/adding_an_observation_kind.md) ----
 public:
  // The program family the kind's plan entries run in: "probing" (one
  // G38.2 cycle of every probe touch, in plan order); a kind with a cycle of
  // its own names it (the sphere: "sphere").
  virtual const char* nc_program() const { return "probing"; }
  // A planned touch `e` at its pose, from PlannedTouch (the simulator's
  // nominal geometry, so the program aims where the simulation touches).
  TouchContact PlannedTouchContact(const Dataset& ds, const nlohmann::json& e, const std::string& where) const;
  // The balls around the kind's targets in `ds` that the program's moves
  // keep out of (a sphere's); none by default: other solids are not modelled.
  virtual std::vector<ClearanceBall> ClearanceBalls(const Dataset&) const { return {}; }
  // Where the stylus centre on the line p + s d (workpiece frame) first
  // reaches the nominal surface of `target` (one stylus radius off it):
  // the exact crossing a simulated probe trips at. The default throws
  // std::invalid_argument: a kind without it gets no simulated trip log.
  virtual ProbeCrossing CrossProbeLine(const Dataset& ds, const std::string& target, const Eigen::Vector3d& p,
                                       const Eigen::Vector3d& d) const;
};

// The trigger term in the analytic batch: PrepareProbeTrigger fills the
// row's probe0 and M; ProbePretravel returns p(M u_work) at the current
// values, puts its derivatives in the probe parameters into the current row,
// and gives dp/du_work in `grad` (workpiece frame) when wanted.
void PrepareProbeTrigger(const Dataset& ds, const ParameterTable& t, const Observation& o, AnalyticRow* r);
double ProbePretravel(const AnalyticEval& e, const AnalyticRow& r, const Eigen::Vector3d& u_work,
                      Eigen::Vector3d* grad);

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_PROBE_TOUCH_H_
