// ObservationKind: everything the generic code (loader, parameter table,
// problem builder, analytic batch, simulator, identification report) needs
// to know about one observation kind, behind one interface. Each kind lives
// in its own file pair (observations/facet.h|.cc, sphere, dbb, ball3d) and is
// listed once in observations/registry.cc; docs/adding_an_observation_kind.md
// walks through adding one.
//
// The per-observation methods are virtual: they run while a file is read or a
// problem is built, never inside the solver's inner loop. The analytic batch
// calls a kind once per run of consecutive rows of that kind
// (EvaluateAnalytic), so the hot loop over rows is not a virtual call per row.
//
// This header uses nlohmann::json (forward declared): include it only where
// the JSON library is available (the core and its tests).
#ifndef FIVECAL_OBSERVATIONS_KIND_H_
#define FIVECAL_OBSERVATIONS_KIND_H_

#include <Eigen/Core>
#include <functional>
#include <map>
#include <nlohmann/json_fwd.hpp>
#include <set>
#include <string>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/priors.h"

namespace fivecal {

class ParameterTable;
class ResidualBuilder;
class KinematicModel;
struct AnalyticRow;
class AnalyticEval;
struct SimulationPlan;
struct NoiseLevels;

// What a plan entry's simulation knows of the true machine and setup.
struct PlanTruth {
  const Dataset* dataset = nullptr;       // machine, probe, artefact (no observations yet)
  Eigen::VectorXd theta;                  // true machine parameters
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();  // true probe tip (tip offsets applied)
  // True value of a setup parameter (0 when the spec does not name it).
  std::function<double(const std::string&)> setup;
};

// The noise direction of a simulated observation (probe touches: the trigger
// position along the nominal approach line).
struct PlanSlot {
  Eigen::VectorXd start, approach;
  double s0 = 0, sensitivity = -1;
};

// What PlanFromDataset hands a kind for one recorded observation.
struct RecordedContext {
  const Dataset* dataset = nullptr;
  const ParameterTable* table = nullptr;
  Eigen::VectorXd values;  // every table parameter
  Eigen::VectorXd theta;   // machine part of `values`
  Eigen::Vector3d tip = Eigen::Vector3d::Zero();  // tip with the offsets of `values`
};

// What the identification report hands a kind for one observation.
struct ReportContext {
  const Dataset* dataset = nullptr;
  const ParameterTable* table = nullptr;
  const Eigen::VectorXd* values = nullptr;  // every table parameter (the fit)
  const KinematicModel* model = nullptr;    // the machine at the fit
};

class ObservationKind {
 public:
  virtual ~ObservationKind() = default;

  // ---- identity ----
  virtual ObservationType type() const = 0;
  // The file's "type" and the prefix of the kind's setup parameters.
  virtual const char* name() const = 0;
  // What one observation is, for reports ("probe touch on a facet").
  virtual const char* label() const = 0;
  // Unit of the residual rows.
  virtual const char* unit() const { return "mm"; }
  // Residual rows per observation.
  virtual int rows() const { return 1; }
  // Instrument noise (one sigma, mm) when a file declares none.
  virtual double default_sigma() const = 0;
  // Unit and default noise of residual row k, for a kind whose rows differ
  // (pose: 3 rows mm, 3 rows rad); a number given for all rows is refused
  // when their units differ.
  virtual const char* unit_row(int) const { return unit(); }
  virtual double default_sigma_row(int) const { return default_sigma(); }
  // The file key naming the instrument of an observation (Observation::
  // setup), or nullptr: the id the dataset's "instruments" may declare a
  // noise for. Kinds with different keys ("instrument", "station") give an
  // id parameters of different meaning, so one id may not serve both.
  virtual const char* instrument_key() const { return nullptr; }
  // A probe touch: needs dataset.probe.tip_radius, and a plan entry may leave
  // the linear axes to the simulator.
  virtual bool probe_touch() const { return false; }
  // A plan entry may leave the linear axes to SimulateEntry (the probe
  // touches; a kind whose commands follow from a nominal point).
  virtual bool plan_finds_linear_axes() const { return probe_touch(); }

  // ---- dataset file (docs/formats.md) ----
  // Every key an observation of this kind may have, in the order the
  // "unknown key" message lists them.
  virtual std::vector<const char*> json_keys() const = 0;
  // Reads the kind's own fields (type, axes, direction, sigma and id are read
  // by the loader); `where` is "dataset.observations[i]".
  virtual void Read(const nlohmann::json& o, const std::string& where, const Dataset& ds,
                    Observation* ob) const = 0;
  // Checks the kind's own fields of an observation built in code; `where()`
  // gives "observations[i]" (built only for a message).
  virtual void Validate(const Dataset& ds, const Observation& o,
                        const std::function<std::string()>& where) const = 0;
  // Writes the kind's own fields.
  virtual void Write(const Observation& o, nlohmann::json* out) const = 0;
  // Writes the own fields that need the machine (the axis letters of a
  // second pose); called after Write.
  virtual void WriteOnMachine(const Machine&, const Observation&, nlohmann::json* /*out*/) const {}

  // ---- setup parameters ----
  // Parameters that belong to the artefact (one per facet, ...), added in
  // registry order before any observation's.
  virtual void AddArtefactParameters(const Dataset&, ParameterTable*) const {}
  // Parameters an observation brings (a mounting's, on its first sample).
  virtual void AddObservationParameters(const Observation&, ParameterTable*) const {}
  // Setup parameters estimated by default because of observation `o`.
  virtual void DefaultSetup(const Dataset& ds, const ParameterTable& t, const Observation& o,
                            std::set<int>* out) const = 0;
  // The prior classes of the kind's setup parameters (priors.h), and the
  // class of one of its parameter names (nullptr: not a name of this kind).
  // Whether "<name()>.<rest>" has the shape of one of the kind's setup
  // parameter names, whatever dataset it belongs to (a dotted name of no
  // kind's shape, EX0C.x, is a mistake worth saying so).
  virtual bool IsParameterName(const std::string& rest) const = 0;
  virtual std::vector<PriorClass> prior_classes() const { return {}; }
  virtual const char* PriorClassOfName(const std::string& name) const = 0;
  // The placement uncertainty (one sigma, in the parameter's unit) a
  // person's set-up gives the kind's parameter `name` when the dataset
  // declares none (priors.h PlacementSigma); 0: not a placed quantity (the
  // data find it, as a reading zero or an artefact's unknown position).
  virtual double DefaultPlacement(const std::string& /*name*/) const { return 0.0; }
  // Instrument mounting position parameters of `o` (empty when the kind has
  // none): a fit that estimates none of them cannot be adequate.
  virtual std::vector<int> MountPositions(const ParameterTable&, const Observation&) const { return {}; }

  // ---- residual ----
  // Whether the kind has the analytic batch (PrepareAnalytic,
  // EvaluateAnalytic). A kind without it is fitted through its templated
  // functor (automatic derivatives) whenever a dataset holds one of its
  // observations: correct, only slower.
  virtual bool analytic() const { return true; }
  // Adds the templated (automatic-derivative) residual of observation `o`.
  virtual void AddResidual(ResidualBuilder& b, const Observation& o) const = 0;
  // Residual rows that belong to the artefact rather than to one observation
  // (sphere: the scale bars), appended after every observation's rows.
  virtual void AddArtefactResiduals(ResidualBuilder&) const {}
  // The analytic batch: one prepared row per observation, then the artefact
  // rows; EvaluateAnalytic gets a run of consecutive rows of this kind with
  // the same `variant`. A kind whose analytic() is false leaves both to the
  // defaults, which throw std::logic_error: nothing may call them.
  virtual void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                               AnalyticRow* r) const;
  // PrepareAnalytic for `o` when the batch has just prepared `prev` for the
  // observation `po` before it (of this kind, same table): the streaming fit
  // prepares every row at every pass, and a kind whose rows look up their
  // setup parameters by setup id may take them from `prev` when the id is
  // the same. The row must come out as PrepareAnalytic makes it.
  virtual void PrepareAnalyticAfter(const Dataset& ds, const ParameterTable& t, const Observation& /*po*/,
                                    const AnalyticRow& /*prev*/, const Observation& o, AnalyticRow* r) const {
    PrepareAnalytic(ds, t, o, r);
  }
  virtual void AddArtefactAnalyticRows(const Dataset&, const ParameterTable&,
                                       std::vector<AnalyticRow>*, std::vector<int>* /*source*/) const {}
  virtual void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const;

  // ---- simulation ----
  // Every key of a plan entry of this kind (Simulate spec), in message order.
  virtual std::vector<const char*> plan_keys() const = 0;
  // The noise-free observation the true machine records for a plan entry;
  // axes and directions are read already. Fills the noise direction of a
  // probe touch in `slot`.
  virtual void SimulateEntry(const nlohmann::json& e, const std::string& where, const PlanTruth& t,
                             Observation* ob, PlanSlot* slot) const = 0;
  // The kind's key among the simulator's noise levels (a spec's "sigma"
  // object, NoiseLevels): its name unless it shares an instrument's noise
  // with other kinds (every probe touch: "probe").
  virtual const char* noise_class() const { return name(); }
  // The kind's noise level among the simulator's levels.
  double NoiseLevel(const NoiseLevels& n) const;
  // The noise class residual row k draws on: noise_class(), or another for
  // rows in another unit (a pose's rotation rows: "pose_angle"). A class's
  // unit is that of its rows (NoiseClassUnit): the one place that says which
  // levels are in rad.
  virtual const char* noise_class_row(int) const { return noise_class(); }
  // The noise classes of the kind's rows, each once, in row order.
  std::vector<std::string> noise_classes() const;
  // The level of residual row k.
  double NoiseLevelRow(const NoiseLevels& n, int k) const;
  // The noise inputs of observation i of a plan (SimulationPlan), from a
  // simulated entry (`slot`) or from a recorded observation (`rec`, `slot`
  // null).
  virtual void AddInputs(SimulationPlan* plan, int i, const PlanSlot* slot,
                         const RecordedContext* rec) const = 0;
  // Moves input `component` of observation `o` (index i) by x from the plan's
  // noise-free value.
  virtual void ApplyInput(const SimulationPlan& plan, int i, int component, double x,
                          Observation* o) const = 0;

  // ---- report ----
  // Whether an observation of this kind fixes the length scale by itself.
  virtual bool LengthReference() const { return false; }
  // Whether the artefact gives a length reference with these observations.
  virtual bool ArtefactLengthReference(const Dataset&) const { return false; }
  // The tool point of observation `o` at the fit, and its residual rows `r`
  // as a vector in the workpiece frame.
  virtual void ReportVector(const ReportContext& c, const Observation& o, const double* r,
                            Eigen::Vector3d* point, Eigen::Vector3d* vector) const = 0;
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_KIND_H_
