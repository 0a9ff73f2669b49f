// ObservationKind: everything the generic code (loader, parameter table,
// problem builder, analytic batch, simulator, identification report, the
// Python layer through the bindings) needs to know about one observation
// kind, split by concern into six interfaces: KindIdentity, KindFileFormat,
// KindSetup, KindResidual, KindSimulation, KindReporting. Each kind lives in
// its own file pair (observations/facet.h|.cc, sphere, dbb, ...) and is
// listed once in observations/registry.cc, or registers itself
// (RegisterObservationKind); docs/adding_an_observation_kind.md walks
// through adding one.
//
// A kind owns its data: every observation carries the kind's payload (its
// struct among payloads.h's alternatives, made by NewPayload()), which only
// the kind's methods read, through Observation::data<T>(). The generic code
// handles the common header (type, id, setup, axes, direction, sigma) and
// hands the whole observation to the kind.
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
#include <initializer_list>
#include <map>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "fivecal/observations/dataset.h"
#include "fivecal/solve/long_kernel.h"
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

// What the layers above the core (reports, plots, plausibility checks) show
// of a kind: they read it through the registry (_core.observation_kinds())
// and name no kind. Every field has a default that shows nothing.
struct KindReport {
  // The artefact list an observation's "target" names ("facets"), nullptr
  // when the kind touches no artefact.
  const char* target_list = nullptr;
  // The file key of Observation::setup ("setup", "instrument", "station"),
  // nullptr when the kind has none; the report's data section lists the
  // observations by that id under `setup_heading`, counted in `count_word`s.
  const char* setup_key = nullptr;
  const char* setup_heading = nullptr;
  const char* count_word = "observation";
  // Whether the poses of its observations are rotary indexations (a ball
  // bar sweeps the axes: its poses are none).
  bool indexed = true;
  // A per-component figure of its first three residual rows: the component
  // names, what the figure calls the kind, the frame of the components, the
  // caption, and the file key of what the instrument recorded itself as a
  // deviation (nullptr: the deviation from the nominal machine is computed).
  std::vector<std::string> components;
  const char* component_label = "";
  const char* component_frame = "";
  const char* component_caption = "";
  const char* recorded_deviation = nullptr;
  // The instrument's range: a value of file field `range_field` beyond
  // `range` (mm) is a reading in the wrong unit; `range_note` says what the
  // instrument measures, `range_what` names the values in messages.
  const char* range_field = nullptr;
  double range = 0;
  const char* range_note = "";
  const char* range_what = "";
  // Procedure figures the report draws for the kind's data ("polar": the
  // circular-test plots of report/polar.py), nullptr for none.
  const char* figures = nullptr;
};

// One column of a kind's instrument table (`fivecal import`, docs/import.md,
// python/fivecal/io/tables.py): the header name, the observation's file key
// it fills (`index`: its entry in a vector key, -1 the value itself), and
// how a cell is read. The table importer reads these and names no kind.
struct TableColumn {
  std::string name, field;
  int index = -1;
  // "length" (mm unless the header or --units says otherwise), "rotation"
  // (an angle of an orientation or of its noise, rad unless the header says
  // otherwise; a table whose `field` has rotation columns reads that
  // orientation in any form its columns give, python/fivecal/io/rotations.py),
  // "number" (no unit: a quaternion's or a matrix's entry), "text", "joint" (a
  // joint layout's value, in the unit of the joint it moves).
  std::string quantity = "length";
  bool measured = false;  // what the instrument measured: --units applies
  bool required = false;  // the header must name it
  std::string alias;      // a shorter header users write ("mx")
  // The sidecar key / option that stands in when the header lacks the
  // column, and the message when neither gives it.
  std::string sidecar, missing;
  // |value| (mm) beyond `range` is a reading in the wrong unit, refused with
  // `range_message` (a Python format string of value, limit, limit_m,
  // column).
  double range = 0;
  std::string range_message;

  TableColumn(std::string n, std::string f, int i = -1) : name(std::move(n)), field(std::move(f)), index(i) {}
  TableColumn& Text() { quantity = "text"; return *this; }
  TableColumn& Quantity(const char* q) { quantity = q; return *this; }
  TableColumn& Measured() { measured = true; return *this; }
  TableColumn& Required() { required = true; return *this; }
  TableColumn& Alias(const char* a) { alias = a; return *this; }
  TableColumn& Sidecar(const char* key, const char* msg = "") { sidecar = key; missing = msg; return *this; }
  TableColumn& Range(double limit, const char* msg) { range = limit; range_message = msg; return *this; }
};

// A rule of a kind's table (generic layout) that the importer applies to
// every row, naming the cell it fails on: the kind's own checks declared as
// data, so that python/fivecal/io/tables.py applies them without naming any
// kind's key. `message` is a Python format string; the fields it may use are
// given per rule ({value}: the offending value, {axes}: the machine's axes
// but S, {column}: the column a value belongs in, without unit).
//   "default"  a row without keys[0] takes the sidecar key / option `option`
//              when given, else `then` when the row has `if_key`, else `value`;
//   "one_of"   keys[0] is one of `values` (else "'x' is neither a nor b",
//              with a did-you-mean);
//   "no_char"  the text of keys[0] holds none of `chars` ({value});
//   "excludes" when the row's `if_key` is `value`, it has none of `keys`
//              (the message names the first cell given);
//   "requires" when the row's `if_key` is `value`, it has every one of `keys`
//              ({axes});
//   "size"     each of `keys` present has `size` entries;
//   "nonzero"  each vector of `keys` present is not of zero length ({value});
//   "limit"    each entry of `keys` present is within `limit` (mm), beyond
//              it a unit mistake ({value}, {column}).
struct TableRule {
  std::string rule;
  std::vector<std::string> keys, values;
  std::string value, option, if_key, then, chars, message;
  int size = 0;
  double limit = 0;

  TableRule(std::string r, std::vector<std::string> k) : rule(std::move(r)), keys(std::move(k)) {}
  TableRule& Value(const char* v) { value = v; return *this; }
  TableRule& Values(std::vector<std::string> v) { values = std::move(v); return *this; }
  TableRule& Option(const char* o) { option = o; return *this; }
  TableRule& If(const char* key, const char* then_value = "") { if_key = key; then = then_value; return *this; }
  TableRule& Chars(const char* c) { chars = c; return *this; }
  TableRule& Size(int n) { size = n; return *this; }
  TableRule& Limit(double mm) { limit = mm; return *this; }
  TableRule& Message(const char* m) { message = m; return *this; }
};

// A kind's instrument table: the import it belongs to and its columns.
// Kinds with the same `name` share one import (the probe touches: a probing
// log names facets, spheres and cylinders); a kind that declares none is
// read by the generic reader under its own name, its columns named after
// its file keys (json_keys), so a new kind is importable with no Python edit.
struct KindTable {
  std::string name;                      // empty: the kind's own name
  std::vector<std::string> aliases;      // other names of the import ("rtest")
  std::vector<std::string> row_aliases;  // other names a row's type cell may give the kind
  // The reader of its rows (tables.py): "touch" (a probe touch naming its
  // artefact target), "mount" (a ball on a mounting), "instrument" (a fixed
  // instrument following a target), "station" (a distance from a station),
  // "generic" (columns named after the file keys).
  std::string layout = "generic";
  std::vector<TableColumn> columns;
  std::string expected;                  // the columns after the axes, for messages
  // The sidecar keys and options the import takes beyond the common ones
  // (probe, artefact, setup, sigma, header).
  std::vector<std::string> options;
  // Other header names: of a key in the generic layout ("deviation" ->
  // "measured"; a name ending in "_" renames a prefix), of a column in the
  // others ("tx" -> "measured_x"). Generic layout: the vector keys that are
  // directions (no unit; key -> what a message calls it), and the rules each
  // row must meet, in the order the importer applies them.
  std::vector<std::pair<std::string, std::string>> header_aliases;
  std::vector<std::pair<std::string, std::string>> directions;
  std::vector<TableRule> rules;
};

// A file key of the flat form a kind declares (KindFileFormat::flat_keys):
// its name, what its value is, and whether the writers put it before the
// axes (an observation's target or set-up id) or after the direction (the
// rest). The loaders and writers know a kind's keys only from this table.
struct FlatKey {
  enum Shape : unsigned char { kNumber, kVector, kText };
  const char* name;
  Shape shape = kNumber;
  bool head = false;
};

// One observation as the streaming loader reads it without building its
// JSON document (observations/dataset.cc), and as the streaming writers
// (writer.h) put it out: the values of the kind's flat keys, slot k holding
// the kind's flat_keys()[k], each given at most once; every number finite
// and within the loader's bounds (vectors within kMaxLinear). The common
// header (type, axes, direction, sigma, id) is not in it: the loader and the
// writers handle it themselves.
struct FlatObservation {
  static constexpr int kMaxKeys = 8;
  unsigned seen = 0;  // bit k: slot k was given
  double values[kMaxKeys][3] = {};
  const std::string* texts[kMaxKeys] = {};
  bool has(int k) const { return (seen & (1u << k)) != 0; }
  // Whether every slot given is among `keys`.
  bool only(std::initializer_list<int> keys) const {
    unsigned allowed = 0;
    for (int k : keys) allowed |= 1u << k;
    return (seen & ~allowed) == 0;
  }
  double number(int k) const { return values[k][0]; }
  Eigen::Vector3d vector(int k) const { return {values[k][0], values[k][1], values[k][2]}; }
  const std::string& text(int k) const { return *texts[k]; }
  void set_number(int k, double x) {
    values[k][0] = x;
    seen |= 1u << k;
  }
  void set_vector(int k, const Eigen::Vector3d& x) {
    for (int c = 0; c < 3; ++c) values[k][c] = x[c];
    seen |= 1u << k;
  }
  // `s` must outlive the flat form (the observation's own string).
  void set_text(int k, const std::string* s) {
    texts[k] = s;
    seen |= 1u << k;
  }
};

// Who the kind is: its type code, name, rows, units and default noise.
class KindIdentity {
 public:
  virtual ~KindIdentity() = default;

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
  // The empty payload of an observation of this kind (payloads.h): the
  // loaders and the simulator set it before the kind reads into it. A kind
  // defined outside the core keeps its numbers in a KindOwnData.
  virtual ObservationPayload NewPayload() const { return KindOwnData{}; }
  // A probe touch: needs dataset.probe.tip_radius, and a plan entry may leave
  // the linear axes to the simulator.
  virtual bool probe_touch() const { return false; }
  // A plan entry may leave the linear axes to SimulateEntry (the probe
  // touches; a kind whose commands follow from a nominal point).
  virtual bool plan_finds_linear_axes() const { return probe_touch(); }
};

// Its fields in the dataset file (docs/formats.md): read, checked, written.
class KindFileFormat {
 public:
  virtual ~KindFileFormat() = default;

  // Every key an observation of this kind may have, in the order the
  // "unknown key" message lists them.
  virtual std::vector<const char*> json_keys() const = 0;
  // Reads the kind's own fields into its payload, which the loader has set
  // to NewPayload() (type, axes, direction, sigma and id are read by the
  // loader); `where` is "dataset.observations[i]".
  virtual void Read(const nlohmann::json& o, const std::string& where, const Dataset& ds,
                    Observation* ob) const = 0;
  // Checks the kind's own fields of an observation built in code; `where()`
  // gives "observations[i]" (built only for a message).
  virtual void Validate(const Dataset& ds, const Observation& o,
                        const std::function<std::string()>& where) const = 0;
  // Writes the kind's own fields: every key of its payload (the dataset
  // writes the common header only).
  virtual void Write(const Observation& o, nlohmann::json* out) const = 0;
  // The kind's flat form: the keys the streaming loader's fast path and the
  // streaming writers read and write without a JSON value, at most
  // FlatObservation::kMaxKeys (the writers put the head keys first in this
  // order, then the others by name, as Write's JSON object orders them);
  // empty (the default): the kind has none, and its observations go through
  // Read and Write. Only a speed-up for kinds that come in long traces.
  virtual const std::vector<FlatKey>& flat_keys() const {
    static const std::vector<FlatKey> none;
    return none;
  }
  // The streaming loader's fast path: the kind's own fields from the flat
  // form (slot k: flat_keys()[k]), when Read and Validate would accept them
  // outright; false sends the observation through Read (whose result and
  // messages are the reference).
  virtual bool ReadFlat(const FlatObservation&, const Artefact&, Observation*) const { return false; }
  // ReadFlat's inverse, the streaming writers' fast path (writer.h): fills
  // `f` (empty) with the kind's own fields of `o` (its set-up id or target
  // included) when they are exactly what the writer's "setup", Write and
  // WriteOnMachine would write; false sends the observation through Write
  // (the reference).
  virtual bool WriteFlat(const Observation&, FlatObservation*) const { return false; }
  // Writes the own fields that need the machine (the axis letters of a
  // second pose); called after Write.
  virtual void WriteOnMachine(const Machine&, const Observation&, nlohmann::json* /*out*/) const {}
  // Its instrument table (fivecal import); the default: the generic reader.
  virtual KindTable Table() const { return {}; }

  // Long traces as column blocks (dataset.h TraceBlock). A kind opts in by
  // giving its per-row values a count > 0 (the default 0: its samples stay
  // Observations) and the five methods below, all from its own file.
  virtual int block_values() const { return 0; }
  // The file column of per-row value v ("reading", "measured_x"), for
  // messages, and its bound: a finite |x| <= bound (mm) is accepted.
  virtual std::string block_value_name(int) const { return ""; }
  virtual double block_value_bound(int) const { return 0; }
  // What a block of `o` shares: its payload with the per-row values zero.
  virtual ObservationPayload BlockCommon(const Observation& o) const { return o.payload; }
  // Whether `o` may be a row of a block whose rows share `common`.
  virtual bool BlockShares(const ObservationPayload& /*common*/, const Observation& /*o*/) const { return false; }
  // o's per-row values (block_values() of them), and their inverse: o's
  // payload already holds the block's `common`, the values go in.
  virtual void BlockValues(const Observation& /*o*/, double* /*v*/) const {}
  virtual void SetBlockValues(const double* /*v*/, Observation* /*o*/) const {}
};

// The set-up parameters it brings (names, order, default set, priors).
class KindSetup {
 public:
  virtual ~KindSetup() = default;

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
};

// Its residual: the templated functor (automatic derivatives) and the
// analytic batch.
class KindResidual {
 public:
  virtual ~KindResidual() = default;

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
  // The scale bars (indices into the artefact's) whose rows
  // AddArtefactResiduals adds for `ds`: the simulator draws their lengths.
  virtual std::vector<int> ScaleBarRows(const Dataset&) const { return {}; }
  // The analytic batch: one prepared row per observation, then the artefact
  // rows; EvaluateAnalytic gets a run of consecutive rows of this kind with
  // the same `variant`. A kind whose analytic() is false leaves both to the
  // defaults, which throw std::logic_error: nothing may call them.
  virtual void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                               AnalyticRow* r) const = 0;
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
  virtual void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const = 0;
  // Long traces (solve/long_kernel.h): observations [begin, end) of `ds`,
  // every one of this kind, as a column block with a fused residual and
  // Jacobian kernel over the `estimated` table entries. Null (the default):
  // the kind has none, and its samples go through the analytic batch.
  virtual std::unique_ptr<LongRun> MakeLongRun(const Dataset& /*ds*/, const ParameterTable& /*t*/,
                                               const std::vector<int>& /*estimated*/, int /*begin*/,
                                               int /*end*/) const {
    return nullptr;
  }
};

// Its simulation: a plan entry's noise-free observation and where the
// simulator's noise enters.
class KindSimulation {
 public:
  virtual ~KindSimulation() = default;

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
  virtual const char* noise_class() const = 0;
  // The noise class residual row k draws on: noise_class(), or another for
  // rows in another unit (a pose's rotation rows: "pose_angle"). A class's
  // unit is that of its rows (NoiseClassUnit): the one place that says which
  // levels are in rad.
  virtual const char* noise_class_row(int) const { return noise_class(); }
  // The noise inputs of observation i of a plan (SimulationPlan), from a
  // simulated entry (`slot`) or from a recorded observation (`rec`, `slot`
  // null).
  virtual void AddInputs(SimulationPlan* plan, int i, const PlanSlot* slot,
                         const RecordedContext* rec) const = 0;
  // Moves input `component` of observation `o` (index i) by x from the plan's
  // noise-free value.
  virtual void ApplyInput(const SimulationPlan& plan, int i, int component, double x,
                          Observation* o) const = 0;
};

// What reports, plots, plausibility checks and the design show of it.
class KindReporting {
 public:
  virtual ~KindReporting() = default;

  // Whether an observation of this kind fixes the length scale by itself.
  virtual bool LengthReference() const { return false; }
  // Whether the artefact gives a length reference with these observations.
  virtual bool ArtefactLengthReference(const Dataset&) const { return false; }
  // What reports, plots and plausibility checks show of the kind.
  virtual KindReport Report() const { return {}; }
  // The index of observation `o`'s target in its artefact list
  // (Report().target_list), -1 when the kind has none or it is absent.
  virtual int ArtefactTarget(const Dataset&, const Observation&) const { return -1; }
  // The contact point on the artefact of a planned touch `e` of this kind
  // and the surface's outward unit normal there (workpiece frame): what a
  // reachability check of a plan needs. False for a kind that touches no
  // surface; std::invalid_argument naming `where` for a target not there.
  virtual bool PlannedContact(const Dataset&, const nlohmann::json& /*e*/, const std::string& /*where*/,
                              Eigen::Vector3d* /*point*/, Eigen::Vector3d* /*normal*/) const {
    return false;
  }
  // The tool point of observation `o` at the fit, and its residual rows `r`
  // as a vector in the workpiece frame.
  virtual void ReportVector(const ReportContext& c, const Observation& o, const double* r,
                            Eigen::Vector3d* point, Eigen::Vector3d* vector) const = 0;
};

// One observation kind: the concerns above, each an interface of its own
// (generic code may take the one it needs: the loader a KindFileFormat, the
// report a KindReporting), composed as Pinocchio composes a joint model from
// its parts. The defaults that cross concerns live here: the noise class is
// the name, a kind without an analytic batch throws if one is asked of it.
class ObservationKind : public KindIdentity,
                        public KindFileFormat,
                        public KindSetup,
                        public KindResidual,
                        public KindSimulation,
                        public KindReporting {
 public:
  // The kind's key among the simulator's noise levels: its name unless it
  // shares an instrument's noise with other kinds (KindSimulation).
  const char* noise_class() const override { return name(); }
  // Without an analytic batch (analytic() false) nothing may call these:
  // they throw std::logic_error naming the kind.
  void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                       AnalyticRow* r) const override;
  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override;

  // The kind's noise level among the simulator's levels.
  double NoiseLevel(const NoiseLevels& n) const;
  // The noise classes of the kind's rows, each once, in row order.
  std::vector<std::string> noise_classes() const;
  // The level of residual row k.
  double NoiseLevelRow(const NoiseLevels& n, int k) const;
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_KIND_H_
