#include "fivecal/observations/distance.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

const char* kXYZ[3] = {"x", "y", "z"};
// Without "instrument", every station follows the target of one tracer of
// this name: the stations of a laser tracer moved around the machine see the
// same reflector, whose offset is then estimated once.
const char* kDefaultTracer = "tracer";

std::string Prefix(const Observation& o) { return "instrument." + o.setup + "."; }

class Kind final : public ObservationKind {
 public:
  ObservationType type() const override { return ObservationType::kDistance; }
  const char* name() const override { return "distance"; }
  const char* label() const override { return "distance from a station (tracking interferometer, laser tracer)"; }
  KindReport Report() const override {
    KindReport r;
    r.setup_key = "station";
    r.setup_heading = "distance stations";
    r.count_word = "reading";
    return r;
  }
  // A tracer's table: axes, the reading and the station it came from (a
  // column, else the only or the --station one); each station's nominal
  // place and dead length from the sidecar.
  KindTable Table() const override {
    KindTable t;
    t.aliases = {"tracer", "multilateration"};
    t.layout = "station";
    t.columns = {TableColumn("id", "id").Text(), TableColumn("sigma", "sigma").Measured(),
                 TableColumn("reading", "reading").Measured().Required().Range(
                     kMaxLinear,
                     "{value:.6g} mm is beyond any interferometer's range; readings look like µm: name the "
                     "column reading_um or give --units um"),
                 TableColumn("station", "station").Text()};
    t.expected = "reading [station] [id] [sigma]";
    t.options = {"stations", "station", "instrument", "target", "target_point", "instruments"};
    return t;
  }
  // A laser tracer or tracking interferometer: about a micrometre over a
  // machine-tool volume.
  double default_sigma() const override { return 0.001; }
  const char* instrument_key() const override { return "station"; }
  bool analytic() const override { return false; }

  std::vector<const char*> json_keys() const override {
    return {"type", "station", "axes", "direction", "reading", "target", "target_point", "station_position",
            "dead_length", "instrument", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    ReadOwn(o, w, ob);
    if (!o.contains("reading")) throw std::invalid_argument(w + ".reading: missing (the distance reading, mm)");
    ob->reading = ReadBounded(o, "reading", w, kMaxLinear);
  }
  void Validate(const Dataset&, const Observation& o, const std::function<std::string()>& w) const override {
    if (o.setup.empty() || o.setup.find('.') != std::string::npos)
      throw std::invalid_argument(w() + ".station: the station id must be a non-empty name without '.'");
    if (o.instrument.empty() || o.instrument.find('.') != std::string::npos)
      throw std::invalid_argument(w() + ".instrument: the tracer's name must be a non-empty name without '.'");
    if (!(std::abs(o.reading) <= kMaxLinear)) RequireBounded(o.reading, kMaxLinear, w() + ".reading");
    if (!(std::abs(o.length) <= kMaxLinear)) RequireBounded(o.length, kMaxLinear, w() + ".dead_length");
    for (int c = 0; c < 3; ++c)
      if (!(std::abs(o.instrument_origin[c]) <= kMaxLinear))
        RequireBounded(o.instrument_origin[c], kMaxLinear, w() + ".station_position[" + std::to_string(c) + "]");
    fixed_frame::ValidateTarget(o, w);
  }
  void Write(const Observation& o, json* jo) const override {
    // The generic writer put the station id under "setup".
    jo->erase("setup");
    (*jo)["station"] = o.setup;
    (*jo)["reading"] = o.reading;
    (*jo)["target_point"] = Array3(o.target_point);
    (*jo)["station_position"] = Array3(o.instrument_origin);
    if (o.length != 0.0) (*jo)["dead_length"] = o.length;
    if (o.instrument != kDefaultTracer) (*jo)["instrument"] = o.instrument;
  }

  // ---- setup: the station's position and dead length, and the tracer's
  // target offsets, all estimated by default (a station is set up anew each
  // time and its dead length is what homing leaves) ----
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override {
    if (!t->has_group(type(), o.setup)) {
      if (t->Index(Prefix(o) + "x") >= 0) fixed_frame::IdClash(o.setup);
      std::vector<int> idx;
      for (const char* f : kXYZ) idx.push_back(t->Add(Prefix(o) + f));
      idx.push_back(t->Add(Prefix(o) + "length"));
      t->AddGroup(type(), o.setup, idx);
    }
    fixed_frame::AddTargetOffsets(o.instrument, o.target, t);
  }
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    for (int i : t.group(type(), o.setup)) out->insert(i);
    for (int i : fixed_frame::TargetOffsets(t, o.instrument, o.target)) out->insert(i);
  }
  bool IsParameterName(const std::string&) const override { return false; }  // instrument.*
  std::vector<PriorClass> prior_classes() const override {
    return {{"dead_length", 10.0, "mm",
             "instrument.<station>.length: a distance station's dead length beyond the file's dead_length"}};
  }
  const char* PriorClassOfName(const std::string& n) const override { return fixed_frame::PriorClassOfName(n); }
  double DefaultPlacement(const std::string& n) const override { return fixed_frame::DefaultPlacement(n); }
  std::vector<int> MountPositions(const ParameterTable& t, const Observation& o) const override {
    return t.group(type(), o.setup);
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const auto& g = b.table.group(type(), o.setup);
    const auto& tg = fixed_frame::TargetOffsets(b.table, o.instrument, o.target);
    StationRefs refs;
    for (int c = 0; c < 3; ++c) {
      refs.position[c] = b.Ref(g[c]);
      refs.target[c] = b.Ref(tg[c]);
    }
    refs.length = b.Ref(g[3]);
    b.Add(new DistanceResidual(b.context, o, refs), 1);
  }

  // ---- simulation ----
  std::vector<const char*> plan_keys() const override {
    return {"type", "station", "axes", "direction", "target", "target_point", "station_position", "dead_length",
            "instrument", "id"};
  }
  void SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                     PlanSlot*) const override {
    ReadOwn(e, w, ob);
    const std::string pre = Prefix(*ob), tpre = "instrument." + ob->instrument + "." + ob->target + "_";
    Eigen::Vector3d station = ob->instrument_origin, target = ob->target_point;
    for (int c = 0; c < 3; ++c) {
      station[c] += t.setup(pre + kXYZ[c]);
      target[c] += t.setup(tpre + kXYZ[c]);
    }
    const Machine& m = t.dataset->machine();
    const PoseData pose(m, *ob);
    const Eigen::Vector3d P = TargetInF<double>(m, t.theta.data(), pose.q.data(), pose.dir.data(), ob->on_tool,
                                                target);
    ob->reading = (P - station).norm() - ob->length - t.setup(pre + "length");
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    AddPlanInput(plan, i, 0, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int, double x, Observation* o) const override {
    o->reading = plan.reading0[i] + x;
  }

  // ---- report: the residual along the line of sight, at the target ----
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const Machine& m = c.dataset->machine();
    const Eigen::VectorXd& v = *c.values;
    const auto& g = c.table->group(type(), o.setup);
    const auto& tg = fixed_frame::TargetOffsets(*c.table, o.instrument, o.target);
    Eigen::Vector3d station = o.instrument_origin, target = o.target_point;
    for (int k = 0; k < 3; ++k) {
      station[k] += v[g[k]];
      target[k] += v[tg[k]];
    }
    const Eigen::VectorXd theta = v.head(m.num_parameters());
    const PoseData pose(m, o);
    *point = TargetInF<double>(m, theta.data(), pose.q.data(), pose.dir.data(), o.on_tool, target);
    const Eigen::Vector3d d = *point - station;
    *vector = d.norm() > 0 ? Eigen::Vector3d(r[0] * d / d.norm()) : Eigen::Vector3d::Zero();
  }

 private:
  static void ReadOwn(const json& o, const std::string& w, Observation* ob) {
    if (!o.contains("station") || !o["station"].is_string())
      throw std::invalid_argument(w + ".station: missing (the station's name, a string such as \"L1\")");
    ob->setup = o["station"].get<std::string>();
    if (ob->setup.empty() || ob->setup.find('.') != std::string::npos)
      throw std::invalid_argument(w + ".station: " + Quote(ob->setup) + " must be a non-empty name without '.'");
    ob->instrument = kDefaultTracer;
    if (o.contains("instrument")) {
      if (!o["instrument"].is_string())
        throw std::invalid_argument(w + ".instrument: expected a string (the tracer whose target the station follows)");
      ob->instrument = o["instrument"].get<std::string>();
      if (ob->instrument.empty() || ob->instrument.find('.') != std::string::npos)
        throw std::invalid_argument(w + ".instrument: " + Quote(ob->instrument) +
                                    " must be a non-empty name without '.'");
    }
    fixed_frame::ReadTarget(o, w, ob);
    if (!o.contains("station_position"))
      throw std::invalid_argument(w + ".station_position: missing (the station's nominal position in the machine "
                                  "frame, [x, y, z] mm)");
    ob->instrument_origin = ReadVector3(o["station_position"], w + ".station_position");
    if (o.contains("dead_length")) ob->length = ReadBounded(o, "dead_length", w, kMaxLinear);
  }
};

}  // namespace

const ObservationKind& DistanceKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
