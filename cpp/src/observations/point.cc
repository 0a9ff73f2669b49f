#include "fivecal/observations/point.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
// Parameters, per instrument (Observation::setup): its pose
// instrument.<id>.x|y|z|a|b|c, and the offsets of the target it follows on
// each side (the payload's target), instrument.<id>.tool_x|y|z and
// .work_x|y|z: one tracker may follow a target on the tool and one on the
// table. The pose kind shares both groups (fixed_frame, point.h).
const char* kFields[6] = {"x", "y", "z", "a", "b", "c"};
const char* kXYZ[3] = {"x", "y", "z"};

std::string Prefix(const Observation& o) { return "instrument." + o.setup; }
std::string TargetPrefix(const Observation& o) { return Prefix(o) + "." + o.data<PointData>().target + "_"; }

}  // namespace

KindTable fixed_frame::InstrumentTable(bool sigma) {
  KindTable t;
  t.layout = "instrument";
  t.columns = {TableColumn("id", "id").Text()};
  if (sigma) t.columns.push_back(TableColumn("sigma", "sigma").Measured());
  const char* xyz[3] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i)
    t.columns.push_back(TableColumn(std::string("measured_") + xyz[i], "measured", i)
                            .Measured()
                            .Required()
                            .Alias((std::string("m") + xyz[i]).c_str())
                            .Range(kMaxLinear,
                                   "{value:.6g} mm is beyond any instrument's range ({limit_m:g} m); coordinates "
                                   "look like µm: name the column {column}_um or give --units um"));
  // a camera's or motion-capture log's translation (TUM, EuRoC, ROS): never an axis
  t.header_aliases = {{"tx", "measured_x"}, {"ty", "measured_y"}, {"tz", "measured_z"}};
  // a circle-point-analysis layout: one joint moved per row, the others at home
  t.columns.push_back(TableColumn("joint", "joint").Text());
  t.columns.push_back(TableColumn("position", "position").Quantity("joint"));
  t.columns.push_back(TableColumn("home", "home").Quantity("joint"));
  t.columns.push_back(TableColumn("joint_type", "joint_type").Text());
  // instruments: the noise per instrument, copied into the dataset
  t.options = {"instrument", "target", "target_point", "instrument_origin", "instrument_angles", "align",
               "joints", "instruments"};
  return t;
}

namespace {

class Kind final : public ObservationKind {
 public:
  ObservationType type() const override { return ObservationType::kPoint; }
  const char* name() const override { return "point"; }
  const char* label() const override { return "fixed-frame 3D point (tracker, camera, CMM)"; }
  KindReport Report() const override {
    KindReport r;
    r.setup_key = "instrument";
    r.setup_heading = "fixed instruments";
    r.components = {"x", "y", "z"};
    r.component_label = "tracker / camera point";
    r.component_frame = "instrument frame";
    r.component_caption =
        "Tracker / camera points: deviation from the nominal machine (seen through the fitted "
        "instrument pose) and residual after the fit per component (instrument frame) against the "
        "rotary angle, one line per instrument / indexation group.";
    return r;
  }
  // A tracker's, camera's or CMM's table: axes (or a joint layout) and the
  // measured coordinates; the instrument's pose from the sidecar or a rigid
  // alignment.
  KindTable Table() const override {
    KindTable t = fixed_frame::InstrumentTable(true);
    t.aliases = {"tracker"};
    t.expected = "measured_x measured_y measured_z [id] [sigma]";
    return t;
  }
  int rows() const override { return 3; }
  // A laser tracker over a machine-tool volume: a few micrometres.
  double default_sigma() const override { return 0.005; }
  const char* instrument_key() const override { return "instrument"; }
  bool analytic() const override { return false; }
  // The instrument reports coordinates in its calibrated length unit, so its
  // data fix the machine's scale (EXX1 ...) like a scale bar does.
  bool LengthReference() const override { return true; }

  std::vector<const char*> json_keys() const override {
    return {"type", "instrument", "axes", "direction", "measured", "target", "target_point",
            "instrument_origin", "instrument_angles", "sigma", "id"};
  }
  ObservationPayload NewPayload() const override { return PointData{}; }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    PointData& d = ob->data<PointData>();
    fixed_frame::ReadInstrument(o, w, ob, &d);
    fixed_frame::ReadTarget(o, w, &d);
    d.measured = ReadVector3(o.value("measured", json()), w + ".measured");
  }
  void Validate(const Dataset&, const Observation& o, const std::function<std::string()>& w) const override {
    const PointData& d = o.data<PointData>();
    fixed_frame::ValidateInstrument(o, d, w);
    for (int c = 0; c < 3; ++c)
      if (!(std::abs(d.measured[c]) <= kMaxLinear))
        RequireBounded(d.measured[c], kMaxLinear, w() + ".measured[" + std::to_string(c) + "]");
    fixed_frame::ValidateTarget(d, w);
  }
  void Write(const Observation& o, json* jo) const override {
    const PointData& d = o.data<PointData>();
    fixed_frame::WriteInstrument(o, d, jo);
    fixed_frame::WriteTarget(d, jo);
    (*jo)["measured"] = Array3(d.measured);
  }

  // ---- setup: the instrument's pose and the target's offsets, always
  // estimated (a tracker's pose in the machine frame is never known well
  // enough to be fixed) ----
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override {
    fixed_frame::AddInstrumentPose(o.setup, t);
    fixed_frame::AddTargetOffsets(o.setup, o.data<PointData>().target, t);
  }
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    for (int i : fixed_frame::InstrumentPose(t, o.setup)) out->insert(i);
    for (int i : fixed_frame::TargetOffsets(t, o.setup, o.data<PointData>().target)) out->insert(i);
  }
  bool IsParameterName(const std::string&) const override { return false; }  // instrument.* and target.*
  std::vector<PriorClass> prior_classes() const override {
    return {{"instrument_position", 2.0, "mm",
             "instrument.<id>.x|y|z: correction of a tracker's or camera's nominal origin in the machine frame"},
            {"instrument_angle", 0.01, "rad",
             "instrument.<id>.a|b|c: correction of its nominal orientation (0.6 deg)"},
            {"target", 1.0, "mm",
             "instrument.<id>.tool_x|y|z, .work_x|y|z: where the target it follows really sits"}};
  }
  const char* PriorClassOfName(const std::string& n) const override { return fixed_frame::PriorClassOfName(n); }
  double DefaultPlacement(const std::string& n) const override { return fixed_frame::DefaultPlacement(n); }
  std::vector<int> MountPositions(const ParameterTable& t, const Observation& o) const override {
    return fixed_frame::InstrumentPose(t, o.setup);
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const auto& g = fixed_frame::InstrumentPose(b.table, o.setup);
    const auto& tg = fixed_frame::TargetOffsets(b.table, o.setup, o.data<PointData>().target);
    InstrumentRefs refs;
    for (int c = 0; c < 3; ++c) {
      refs.position[c] = b.Ref(g[c]);
      refs.angle[c] = b.Ref(g[3 + c]);
      refs.target[c] = b.Ref(tg[c]);
    }
    b.Add(new PointResidual(b.context, o, o.data<PointData>(), refs), 3);
  }

  // ---- simulation ----
  std::vector<const char*> plan_keys() const override {
    return {"type", "instrument", "axes", "direction", "target", "target_point", "instrument_origin",
            "instrument_angles", "id"};
  }
  void SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                     PlanSlot*) const override {
    PointData& d = ob->data<PointData>();
    fixed_frame::ReadInstrument(e, w, ob, &d);
    fixed_frame::ReadTarget(e, w, &d);
    const std::string pre = Prefix(*ob) + ".", tpre = TargetPrefix(*ob);
    PointData truth = d;
    for (int c = 0; c < 3; ++c) {
      truth.instrument_origin[c] += t.setup(pre + kFields[c]);
      truth.instrument_angles[c] += t.setup(pre + kFields[3 + c]);
      truth.target_point[c] += t.setup(tpre + kXYZ[c]);
    }
    const Machine& m = t.dataset->machine();
    const PoseData pose(m, *ob);
    const double ang[3] = {truth.instrument_angles[0], truth.instrument_angles[1], truth.instrument_angles[2]};
    d.measured = PointInInstrument<double>(m, t.theta.data(), pose.q.data(), pose.dir.data(), d.on_tool,
                                           truth.target_point, truth.instrument_origin, ang);
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    for (int c = 0; c < 3; ++c) AddPlanInput(plan, i, c, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int c, double x, Observation* o) const override {
    o->data<PointData>().measured[c] = plan.base.observations[i].data<PointData>().measured[c] + x;
  }

  // ---- report: the residual turned into F, at the target's place ----
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    fixed_frame::ReportPoint(c, o, o.data<PointData>(), r, point, vector);
  }
};

}  // namespace

const ObservationKind& PointKind() {
  static const Kind kind;
  return kind;
}

namespace fixed_frame {

void ReadTarget(const json& o, const std::string& w, FixedTargetData* d) {
  if (!o.contains("target") || !o["target"].is_string())
    throw std::invalid_argument(w + ".target: missing (\"tool\" or \"work\": the side that carries the target)");
  d->target = o["target"].get<std::string>();
  if (d->target != "tool" && d->target != "work")
    throw std::invalid_argument(w + ".target: " + Quote(d->target) + " is neither \"tool\" nor \"work\"");
  d->on_tool = d->target == "tool";
  d->target_point = ReadVector3(o.value("target_point", json()), w + ".target_point");
}

void ValidateTarget(const FixedTargetData& d, const std::function<std::string()>& w) {
  if (d.target != "tool" && d.target != "work")
    throw std::invalid_argument(w() + ".target: " + Quote(d.target) + " is neither \"tool\" nor \"work\"");
  for (int c = 0; c < 3; ++c)
    if (!(std::abs(d.target_point[c]) <= kMaxLinear))
      RequireBounded(d.target_point[c], kMaxLinear, w() + ".target_point[" + std::to_string(c) + "]");
}

void WriteTarget(const FixedTargetData& d, json* jo) {
  if (!d.target.empty()) (*jo)["target"] = d.target;
  (*jo)["target_point"] = Array3(d.target_point);
}

void ReadInstrument(const json& o, const std::string& w, Observation* ob, PointData* d) {
  if (!o.contains("instrument") || !o["instrument"].is_string())
    throw std::invalid_argument(w + ".instrument: missing (the instrument's name, a string such as \"T1\")");
  ob->setup = o["instrument"].get<std::string>();
  if (ob->setup.empty() || ob->setup.find('.') != std::string::npos)
    throw std::invalid_argument(w + ".instrument: " + Quote(ob->setup) + " must be a non-empty name without '.'");
  if (o.contains("instrument_origin"))
    d->instrument_origin = ReadVector3(o["instrument_origin"], w + ".instrument_origin");
  if (o.contains("instrument_angles"))
    d->instrument_angles = ReadVector3(o["instrument_angles"], w + ".instrument_angles", 360.0) * kDegToRad;
}

void ValidateInstrument(const Observation& o, const PointData& d, const std::function<std::string()>& w) {
  if (o.setup.empty() || o.setup.find('.') != std::string::npos)
    throw std::invalid_argument(w() + ".instrument: the instrument id must be a non-empty name without '.'");
  auto bounded = [&](const Eigen::Vector3d& v, double bound, const char* field) {
    for (int c = 0; c < 3; ++c)
      if (!(std::abs(v[c]) <= bound)) RequireBounded(v[c], bound, w() + "." + field + "[" + std::to_string(c) + "]");
  };
  bounded(d.instrument_origin, kMaxLinear, "instrument_origin");
  bounded(d.instrument_angles, 2 * 3.14159265358979323846, "instrument_angles");
}

void WriteInstrument(const Observation& o, const PointData& d, json* jo) {
  // The generic writer put the instrument id under "setup"; the file calls
  // it "instrument".
  jo->erase("setup");
  (*jo)["instrument"] = o.setup;
  if (!d.instrument_origin.isZero()) (*jo)["instrument_origin"] = Array3(d.instrument_origin);
  if (!d.instrument_angles.isZero()) (*jo)["instrument_angles"] = Array3(d.instrument_angles / kDegToRad);
}

// Both groups live under kPoint whichever kind adds them, so that a point and
// a pose observation of one instrument share its pose and target offsets.
const std::vector<int>& AddInstrumentPose(const std::string& id, ParameterTable* t) {
  if (!t->has_group(ObservationType::kPoint, id)) {
    if (t->Index("instrument." + id + ".x") >= 0) IdClash(id);
    std::vector<int> idx;
    for (const char* f : kFields) idx.push_back(t->Add("instrument." + id + "." + f));
    t->AddGroup(ObservationType::kPoint, id, idx);
  }
  return t->group(ObservationType::kPoint, id);
}

const std::vector<int>& InstrumentPose(const ParameterTable& t, const std::string& id) {
  return t.group(ObservationType::kPoint, id);
}

// The group key: an id has no '.', so "<id>.<side>" is never an id.
const std::vector<int>& AddTargetOffsets(const std::string& id, const std::string& side, ParameterTable* t) {
  const std::string key = id + "." + side;
  if (!t->has_group(ObservationType::kPoint, key)) {
    std::vector<int> idx;
    for (const char* f : kXYZ) idx.push_back(t->Add("instrument." + id + "." + side + "_" + f));
    t->AddGroup(ObservationType::kPoint, key, idx);
  }
  return t->group(ObservationType::kPoint, key);
}

const std::vector<int>& TargetOffsets(const ParameterTable& t, const std::string& id, const std::string& side) {
  return t.group(ObservationType::kPoint, id + "." + side);
}

void ReportPoint(const ReportContext& c, const Observation& o, const PointData& d, const double* r,
                 Eigen::Vector3d* point, Eigen::Vector3d* vector) {
  const Eigen::VectorXd& v = *c.values;
  const auto& g = InstrumentPose(*c.table, o.setup);
  Eigen::Vector3d origin = d.instrument_origin, angles = d.instrument_angles;
  for (int k = 0; k < 3; ++k) {
    origin[k] += v[g[k]];
    angles[k] += v[g[3 + k]];
  }
  const Eigen::Matrix3d R = RotZYX(angles[0], angles[1], angles[2]);
  *vector = R * Eigen::Vector3d(r[0], r[1], r[2]);
  *point = R * (d.measured + Eigen::Vector3d(r[0], r[1], r[2])) + origin;
}

const char* PriorClassOfName(const std::string& n) {
  if (n.rfind("instrument.", 0) != 0) return nullptr;
  const std::string f = n.substr(n.rfind('.') + 1);
  if (f.rfind("tool_", 0) == 0 || f.rfind("work_", 0) == 0) {
    const std::string c = f.substr(5);
    return (c == "a" || c == "b" || c == "c") ? "target_angle" : "target";
  }
  if (f == "length") return "dead_length";
  return (f == "a" || f == "b" || f == "c") ? "instrument_angle" : "instrument_position";
}

// A tracker, camera or tracer station on its tripod is set where the plan
// says by tape and eye: a couple of millimetres and about 10 mrad (0.6 deg),
// the plausible size of its class. Its pose is what the data find; this row
// only keeps a machine error confounded with it from being fitted as if the
// pose were known. Targets and a station's dead length are readings' zeros
// and the target's own offsets, not placements: no row.
double DefaultPlacement(const std::string& n) {
  const char* c = PriorClassOfName(n);
  if (!c) return 0.0;
  const std::string cls = c;
  if (cls == "instrument_position") return 2.0;
  if (cls == "instrument_angle") return 0.01;
  return 0.0;
}

void IdClash(const std::string& id) {
  throw std::invalid_argument("dataset: " + Quote(id) +
                              " names both a distance station and a point/pose instrument; their parameters "
                              "instrument." + id + ".* would mean different things: give them different names");
}

}  // namespace fixed_frame

}  // namespace fivecal
