#include "fivecal/observations/pose.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

constexpr double kTwoPi = 2 * 3.14159265358979323846;
const char* kXYZ[3] = {"x", "y", "z"};
const char* kABC[3] = {"a", "b", "c"};

// The target frame's orientation corrections instrument.<id>.<side>_a|b|c,
// one group per id and side (a point observation of the same target has no
// use for them).
std::string AngleKey(const Observation& o) { return o.setup + "." + o.data<PoseTargetData>().target; }
std::string AnglePrefix(const Observation& o) { return "instrument." + o.setup + "." + o.data<PoseTargetData>().target + "_"; }

class Kind final : public ObservationKind {
 public:
  ObservationType type() const override { return ObservationType::kPose; }
  const char* name() const override { return "pose"; }
  const char* label() const override { return "fixed-frame 6D pose (camera fiducial, 6D tracker)"; }
  KindReport Report() const override {
    KindReport r;
    r.setup_key = "instrument";
    r.setup_heading = "fixed instruments";
    r.components = {"x", "y", "z"};
    r.component_label = "6D pose, position part";
    r.component_frame = "instrument frame";
    r.component_caption =
        "6D poses, position part: deviation from the nominal machine (fitted instrument pose) and "
        "residual after the fit per component (instrument frame) against the rotary angle.";
    return r;
  }
  // The point's table and the measured orientation (measured_rotation), in
  // any form a camera, motion capture or tracker writes it: a rotation
  // vector (rad unless the header or the sidecar's rotation.unit says
  // otherwise), a quaternion (qw qx qy qz, or q0..q3 / q1..q4 with
  // rotation.order), a matrix (r11 ... r33, row by row) or Euler angles
  // (euler_1..3 or roll pitch yaw, with rotation.sequence). The importer
  // reads the columns of the "rotation" quantity's key through
  // python/fivecal/io/rotations.py, which tells the form from the columns
  // given; none is required alone. Its rows differ in unit, so one sigma
  // column cannot weigh them: its noise is six sigma_x ... sigma_rz columns,
  // six values in the sidecar, the dataset's instruments entry or the kind's
  // default.
  KindTable Table() const override {
    KindTable t = fixed_frame::InstrumentTable(false);
    t.aliases = {"6d"};
    const char* xyz[3] = {"x", "y", "z"};
    for (int i = 0; i < 3; ++i)
      t.columns.push_back(TableColumn(std::string("measured_r") + xyz[i], "measured_rotation", i)
                              .Quantity("rotation")
                              .Alias((std::string("mr") + xyz[i]).c_str()));
    for (const char* q : {"qw", "qx", "qy", "qz", "q0", "q1", "q2", "q3", "q4"})
      t.columns.push_back(TableColumn(q, "measured_rotation").Quantity("number"));
    for (int i = 1; i <= 3; ++i)
      for (int j = 1; j <= 3; ++j)
        t.columns.push_back(
            TableColumn("r" + std::to_string(i) + std::to_string(j), "measured_rotation").Quantity("number"));
    for (const char* e : {"euler_1", "euler_2", "euler_3", "roll", "pitch", "yaw"})
      t.columns.push_back(TableColumn(e, "measured_rotation").Quantity("rotation"));
    // per-row noise, one per residual row: mm (--units applies), then rad
    for (int i = 0; i < 3; ++i)
      t.columns.push_back(TableColumn(std::string("sigma_") + xyz[i], "sigma", i).Measured());
    for (int i = 0; i < 3; ++i)
      t.columns.push_back(TableColumn(std::string("sigma_r") + xyz[i], "sigma", 3 + i).Quantity("rotation"));
    t.expected = "measured_x measured_y measured_z measured_rx measured_ry measured_rz [id]";
    t.options.push_back("target_rotation");
    t.options.push_back("rotation");
    return t;
  }
  int rows() const override { return 6; }
  const char* unit_row(int k) const override { return k < 3 ? "mm" : "rad"; }
  // A 6D tracker probe or a camera seeing a fiducial over a machine-tool
  // volume: ten micrometres in position, 0.1 mrad (20 arc seconds) in
  // orientation -- between a tracker probe's ~0.01 deg and a camera's.
  double default_sigma() const override { return 0.01; }
  double default_sigma_row(int k) const override { return k < 3 ? 0.01 : 1e-4; }
  const char* instrument_key() const override { return "instrument"; }
  bool analytic() const override { return false; }
  // A camera or 6D tracker reports positions in its calibrated length unit:
  // like a point tracker, its data fix the machine's scale (EXX1 ...).
  bool LengthReference() const override { return true; }
  ObservationPayload NewPayload() const override { return PoseTargetData{}; }

  std::vector<const char*> json_keys() const override {
    return {"type", "instrument", "axes", "direction", "measured", "measured_rotation", "target", "target_point",
            "target_rotation", "instrument_origin", "instrument_angles", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    ReadOwn(o, w, ob);
    PoseTargetData& d = ob->data<PoseTargetData>();
    d.measured = ReadVector3(o.value("measured", json()), w + ".measured");
    d.measured_rotation = ReadVector3(o.value("measured_rotation", json()), w + ".measured_rotation", kTwoPi);
  }
  void Validate(const Dataset&, const Observation& o, const std::function<std::string()>& w) const override {
    const PoseTargetData& d = o.data<PoseTargetData>();
    fixed_frame::ValidateInstrument(o, d, w);
    auto bounded = [&](const Eigen::Vector3d& v, double bound, const char* field) {
      for (int c = 0; c < 3; ++c)
        if (!(std::abs(v[c]) <= bound)) RequireBounded(v[c], bound, w() + "." + field + "[" + std::to_string(c) + "]");
    };
    bounded(d.measured, kMaxLinear, "measured");
    bounded(d.measured_rotation, kTwoPi, "measured_rotation");
    bounded(d.target_rotation, kTwoPi, "target_rotation");
    fixed_frame::ValidateTarget(d, w);
  }
  void Write(const Observation& o, json* jo) const override {
    const PoseTargetData& d = o.data<PoseTargetData>();
    fixed_frame::WriteInstrument(o, d, jo);
    fixed_frame::WriteTarget(d, jo);
    (*jo)["measured"] = Array3(d.measured);
    (*jo)["measured_rotation"] = Array3(d.measured_rotation);
    if (!d.target_rotation.isZero()) (*jo)["target_rotation"] = Array3(d.target_rotation);
  }

  // ---- setup: the instrument's pose, the target's offsets (shared with the
  // point kind) and the target frame's orientation, all estimated by default:
  // a fiducial's orientation on a spindle or a table is never known exactly ----
  void AddObservationParameters(const Observation& o, ParameterTable* t) const override {
    fixed_frame::AddInstrumentPose(o.setup, t);
    fixed_frame::AddTargetOffsets(o.setup, o.data<PoseTargetData>().target, t);
    if (!t->has_group(type(), AngleKey(o))) {
      std::vector<int> idx;
      for (const char* f : kABC) idx.push_back(t->Add(AnglePrefix(o) + f));
      t->AddGroup(type(), AngleKey(o), idx);
    }
  }
  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    for (int i : fixed_frame::InstrumentPose(t, o.setup)) out->insert(i);
    for (int i : fixed_frame::TargetOffsets(t, o.setup, o.data<PoseTargetData>().target)) out->insert(i);
    for (int i : t.group(type(), AngleKey(o))) out->insert(i);
  }
  bool IsParameterName(const std::string&) const override { return false; }  // instrument.*
  std::vector<PriorClass> prior_classes() const override {
    return {{"target_angle", 0.05, "rad",
             "instrument.<id>.tool_a|b|c, .work_a|b|c: correction of a pose target's nominal orientation (3 deg)"}};
  }
  const char* PriorClassOfName(const std::string& n) const override { return fixed_frame::PriorClassOfName(n); }
  double DefaultPlacement(const std::string& n) const override { return fixed_frame::DefaultPlacement(n); }
  std::vector<int> MountPositions(const ParameterTable& t, const Observation& o) const override {
    return fixed_frame::InstrumentPose(t, o.setup);
  }

  void AddResidual(ResidualBuilder& b, const Observation& o) const override {
    const auto& g = fixed_frame::InstrumentPose(b.table, o.setup);
    const auto& tg = fixed_frame::TargetOffsets(b.table, o.setup, o.data<PoseTargetData>().target);
    const auto& ag = b.table.group(type(), AngleKey(o));
    PoseRefs refs;
    for (int c = 0; c < 3; ++c) {
      refs.point.position[c] = b.Ref(g[c]);
      refs.point.angle[c] = b.Ref(g[3 + c]);
      refs.point.target[c] = b.Ref(tg[c]);
      refs.target_angle[c] = b.Ref(ag[c]);
    }
    b.Add(new PoseResidual(b.context, o, refs), 6);
  }

  // ---- simulation ----
  std::vector<const char*> plan_keys() const override {
    return {"type", "instrument", "axes", "direction", "target", "target_point", "target_rotation",
            "instrument_origin", "instrument_angles", "id"};
  }
  void SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                     PlanSlot*) const override {
    ReadOwn(e, w, ob);
    PoseTargetData& d = ob->data<PoseTargetData>();
    const std::string pre = "instrument." + ob->setup + ".", tpre = AnglePrefix(*ob);
    PoseTargetData truth = d;
    double tang[3];
    for (int c = 0; c < 3; ++c) {
      truth.instrument_origin[c] += t.setup(pre + kXYZ[c]);
      truth.instrument_angles[c] += t.setup(pre + kABC[c]);
      truth.target_point[c] += t.setup(tpre + kXYZ[c]);
      tang[c] = t.setup(tpre + kABC[c]);
    }
    const Machine& m = t.dataset->machine();
    const PoseData pose(m, *ob);
    const double ang[3] = {truth.instrument_angles[0], truth.instrument_angles[1], truth.instrument_angles[2]};
    const Eigen::Matrix3d target_R =
        RotationOfVector<double>(truth.target_rotation) * RotZYX(tang[0], tang[1], tang[2]);
    Eigen::Matrix3d R;
    PoseInInstrument<double>(m, t.theta.data(), pose.q.data(), pose.dir.data(), d.on_tool, truth.target_point,
                             target_R, truth.instrument_origin, ang, &d.measured, &R);
    d.measured_rotation = VectorOfRotation<double>(R);
  }
  const char* noise_class_row(int k) const override { return k < 3 ? "pose" : "pose_angle"; }
  // Rotation noise is a small rotation of the reading in the target frame,
  // R_m exp(x e_k), so that it enters the residual row k as -x exactly (a
  // noise added to the rotation vector's components would reach the rows
  // through the non-orthogonal Jacobian of exp at large rotations).
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    for (int c = 0; c < 6; ++c) AddPlanInput(plan, i, c, -1.0, NoiseLevelRow(plan->noise, c));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int c, double x, Observation* o) const override {
    PoseTargetData& d = o->data<PoseTargetData>();
    if (c < 3) {
      d.measured[c] = plan.base.observations[i].data<PoseTargetData>().measured[c] + x;
      return;
    }
    // Composed onto the reading's current orientation: each rotation input
    // is applied once, in input order, starting from the noise-free one.
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    e[c - 3] = x;
    d.measured_rotation =
        VectorOfRotation<double>(RotationOfVector<double>(d.measured_rotation) * RotationOfVector<double>(e));
  }

  // ---- report: the position rows, as the point kind's ----
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const override {
    fixed_frame::ReportPoint(c, o, o.data<PoseTargetData>(), r, point, vector);
  }

 private:
  static void ReadOwn(const json& o, const std::string& w, Observation* ob) {
    PoseTargetData& d = ob->data<PoseTargetData>();
    fixed_frame::ReadInstrument(o, w, ob, &d);
    fixed_frame::ReadTarget(o, w, &d);
    if (o.contains("target_rotation"))
      d.target_rotation = ReadVector3(o["target_rotation"], w + ".target_rotation", kTwoPi);
  }
};

}  // namespace

const ObservationKind& PoseKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
