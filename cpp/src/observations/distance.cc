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
  ObservationPayload NewPayload() const override { return DistanceData{}; }

  std::vector<const char*> json_keys() const override {
    return {"type", "station", "axes", "direction", "reading", "target", "target_point", "station_position",
            "dead_length", "instrument", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    ReadOwn(o, w, ob);
    if (!o.contains("reading")) throw std::invalid_argument(w + ".reading: missing (the distance reading, mm)");
    ob->data<DistanceData>().reading = ReadBounded(o, "reading", w, kMaxLinear);
  }
  void Validate(const Dataset&, const Observation& o, const std::function<std::string()>& w) const override {
    const DistanceData& d = o.data<DistanceData>();
    if (o.setup.empty() || o.setup.find('.') != std::string::npos)
      throw std::invalid_argument(w() + ".station: the station id must be a non-empty name without '.'");
    if (d.tracer.empty() || d.tracer.find('.') != std::string::npos)
      throw std::invalid_argument(w() + ".instrument: the tracer's name must be a non-empty name without '.'");
    if (!(std::abs(d.reading) <= kMaxLinear)) RequireBounded(d.reading, kMaxLinear, w() + ".reading");
    if (!(std::abs(d.dead_length) <= kMaxLinear)) RequireBounded(d.dead_length, kMaxLinear, w() + ".dead_length");
    for (int c = 0; c < 3; ++c)
      if (!(std::abs(d.station[c]) <= kMaxLinear))
        RequireBounded(d.station[c], kMaxLinear, w() + ".station_position[" + std::to_string(c) + "]");
    fixed_frame::ValidateTarget(d, w);
  }
  void Write(const Observation& o, json* jo) const override {
    const DistanceData& d = o.data<DistanceData>();
    // The generic writer put the station id under "setup".
    jo->erase("setup");
    (*jo)["station"] = o.setup;
    (*jo)["reading"] = d.reading;
    fixed_frame::WriteTarget(d, jo);
    (*jo)["station_position"] = Array3(d.station);
    if (d.dead_length != 0.0) (*jo)["dead_length"] = d.dead_length;
    if (d.tracer != kDefaultTracer) (*jo)["instrument"] = d.tracer;
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
    fixed_frame::AddTargetOffsets(o.data<DistanceData>().tracer, o.data<DistanceData>().target, t);
  }
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    for (int i : t.group(type(), o.setup)) out->insert(i);
    for (int i : fixed_frame::TargetOffsets(t, o.data<DistanceData>().tracer, o.data<DistanceData>().target)) out->insert(i);
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
    const auto& tg = fixed_frame::TargetOffsets(b.table, o.data<DistanceData>().tracer, o.data<DistanceData>().target);
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
    DistanceData& d = ob->data<DistanceData>();
    const std::string pre = Prefix(*ob), tpre = "instrument." + d.tracer + "." + d.target + "_";
    Eigen::Vector3d station = d.station, target = d.target_point;
    for (int c = 0; c < 3; ++c) {
      station[c] += t.setup(pre + kXYZ[c]);
      target[c] += t.setup(tpre + kXYZ[c]);
    }
    const Machine& m = t.dataset->machine();
    const PoseData pose(m, *ob);
    const Eigen::Vector3d P = TargetInF<double>(m, t.theta.data(), pose.q.data(), pose.dir.data(), d.on_tool,
                                                target);
    d.reading = (P - station).norm() - d.dead_length - t.setup(pre + "length");
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    AddPlanInput(plan, i, 0, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int, double x, Observation* o) const override {
    o->data<DistanceData>().reading = plan.base.observations[i].data<DistanceData>().reading + x;
  }

  // ---- report: the residual along the line of sight, at the target ----
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    const DistanceData& d = o.data<DistanceData>();
    const Machine& m = c.dataset->machine();
    const Eigen::VectorXd& v = *c.values;
    const auto& g = c.table->group(type(), o.setup);
    const auto& tg = fixed_frame::TargetOffsets(*c.table, d.tracer, d.target);
    Eigen::Vector3d station = d.station, target = d.target_point;
    for (int k = 0; k < 3; ++k) {
      station[k] += v[g[k]];
      target[k] += v[tg[k]];
    }
    const Eigen::VectorXd theta = v.head(m.num_parameters());
    const PoseData pose(m, o);
    *point = TargetInF<double>(m, theta.data(), pose.q.data(), pose.dir.data(), d.on_tool, target);
    const Eigen::Vector3d sight = *point - station;
    *vector = sight.norm() > 0 ? Eigen::Vector3d(r[0] * sight / sight.norm()) : Eigen::Vector3d::Zero();
  }

 private:
  static void ReadOwn(const json& o, const std::string& w, Observation* ob) {
    if (!o.contains("station") || !o["station"].is_string())
      throw std::invalid_argument(w + ".station: missing (the station's name, a string such as \"L1\")");
    DistanceData* d = &ob->data<DistanceData>();
    ob->setup = o["station"].get<std::string>();
    if (ob->setup.empty() || ob->setup.find('.') != std::string::npos)
      throw std::invalid_argument(w + ".station: " + Quote(ob->setup) + " must be a non-empty name without '.'");
    d->tracer = kDefaultTracer;
    if (o.contains("instrument")) {
      if (!o["instrument"].is_string())
        throw std::invalid_argument(w + ".instrument: expected a string (the tracer whose target the station follows)");
      d->tracer = o["instrument"].get<std::string>();
      if (d->tracer.empty() || d->tracer.find('.') != std::string::npos)
        throw std::invalid_argument(w + ".instrument: " + Quote(d->tracer) +
                                    " must be a non-empty name without '.'");
    }
    fixed_frame::ReadTarget(o, w, d);
    if (!o.contains("station_position"))
      throw std::invalid_argument(w + ".station_position: missing (the station's nominal position in the machine "
                                  "frame, [x, y, z] mm)");
    d->station = ReadVector3(o["station_position"], w + ".station_position");
    if (o.contains("dead_length")) d->dead_length = ReadBounded(o, "dead_length", w, kMaxLinear);
  }
};

}  // namespace

const ObservationKind& DistanceKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
