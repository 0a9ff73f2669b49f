#include "fivecal/observations/dbb.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/observations/simulate.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/problem.h"
#include "json_util.h"

namespace fivecal {
namespace {

using namespace json_util;

class Kind final : public BallMountKind {
 public:
  ObservationType type() const override { return ObservationType::kDbb; }
  const char* name() const override { return "dbb"; }
  const char* label() const override { return "ball bar length change"; }
  KindReport Report() const override {
    KindReport r;
    r.setup_key = "setup";
    r.setup_heading = "double ball bar setups";
    r.count_word = "sample";
    r.indexed = false;  // a ball bar sweeps the axes
    r.range_field = "reading";
    r.range = 2.0;  // a QC20 ballbar measures about +-1 mm
    r.range_note = "a ballbar measures about ±1 mm";
    r.range_what = "readings";
    r.figures = "polar";
    return r;
  }
  // A ball bar trace: axes and the reading; the bar length and the balls
  // from the sidecar unless columns give them.
  KindTable Table() const override {
    KindTable t;
    t.layout = "mount";
    t.columns = MountColumns();
    t.columns.push_back(TableColumn("reading", "reading").Measured().Required().Range(
        Report().range,
        "reading {value:.6g} mm is beyond a ballbar's range (about ±1 mm, refused beyond ±{limit:g} mm); "
        "readings look like µm: name the column reading_um or give --units um"));
    t.columns.push_back(TableColumn("length", "length").Sidecar(
        "length", "no bar length: give --length MM, 'length' in the sidecar or a 'length' column"));
    t.expected = "reading_um [id]";
    t.options = {"length", "tool_ball", "table_ball"};
    return t;
  }
  // A ball bar's resolution-limited reading noise.
  double default_sigma() const override { return 0.0005; }

  std::vector<const char*> json_keys() const override {
    return {"type", "setup", "axes", "direction", "reading", "length", "tool_ball", "table_ball", "sigma", "id"};
  }
  void Read(const json& o, const std::string& w, const Dataset&, Observation* ob) const override {
    BallMountData& d = ob->data<BallMountData>();
    d.reading = ReadBounded(o, "reading", w, kMaxDbbReading);
    d.length = ReadBounded(o, "length", w, kMaxLinear);
    if (d.length <= 0) throw std::invalid_argument(w + ".length: must be > 0 mm");
    ReadMount(o, w, ob);
  }
  enum Slot { kReading = kFlatOwn, kLength };
  const std::vector<FlatKey>& flat_keys() const override {
    static const std::vector<FlatKey> keys = [] {
      std::vector<FlatKey> k = MountFlatKeys();
      k.push_back({"reading", FlatKey::kNumber});
      k.push_back({"length", FlatKey::kNumber});
      return k;
    }();
    return keys;
  }
  bool ReadFlat(const FlatObservation& f, const Artefact&, Observation* ob) const override {
    if (!f.has(kReading) || !f.has(kLength)) return false;
    const double reading = f.number(kReading), length = f.number(kLength);
    if (!(std::abs(reading) <= kMaxDbbReading) || !(length > 0 && length <= kMaxLinear)) return false;
    BallMountData& d = ob->data<BallMountData>();
    d.reading = reading;
    d.length = length;
    return ReadFlatMount(f, ob);
  }
  bool WriteFlat(const Observation& o, FlatObservation* f) const override {
    const BallMountData& d = o.data<BallMountData>();
    f->set_number(kReading, d.reading);
    f->set_number(kLength, d.length);
    WriteFlatMount(o, f);
    return true;
  }

  void DefaultSetup(const Dataset&, const ParameterTable& t, const Observation& o,
                    std::set<int>* out) const override {
    out->insert(t.group(type(), o.setup)[0]);
  }
  std::vector<PriorClass> prior_classes() const override {
    std::vector<PriorClass> c = {{"dbb_length", 1.0, "mm", "dbb[.<setup>].length: ball-bar length offset"}};
    for (const PriorClass& m : BallMountKind::prior_classes()) c.push_back(m);
    return c;
  }
  // Placement (docs/setup_uncertainty.md): the bar's length comes from its
  // calibrator to a micrometre or two; the table ball sits on a magnetic nest
  // placed and centred by hand (tens of um); the tool cup sits in the
  // spindle taper, on the spindle axis to a few um, at the tool length a
  // presetter or a touch-off gives (about 20 um).
  double DefaultPlacement(const std::string& n) const override {
    if (!PriorClassOfName(n)) return 0.0;
    if (std::string(PriorClassOfName(n)) == "dbb_length") return 0.002;
    if (n.find(".table.") != std::string::npos) return 0.030;
    return n.compare(n.size() - 2, 2, ".z") == 0 ? 0.020 : 0.005;
  }
  const char* PriorClassOfName(const std::string& n) const override {
    if (n.rfind("dbb.", 0) != 0) return nullptr;
    const std::string length = ".length";
    return n.size() >= length.size() && n.compare(n.size() - length.size(), length.size(), length) == 0
               ? "dbb_length"
               : "mount";
  }

  void EvaluateAnalytic(AnalyticEval& e, const AnalyticRow* rows, int count) const override {
    const Eigen::VectorXd& v = e.v;
    Eigen::Matrix3d G;
    for (const AnalyticRow* r = rows; r != rows + count; ++r) {
      Eigen::Vector3d tip, target = r->a;
      for (int c = 0; c < 3; ++c) {
        tip[c] = r->tool_ball[c] + v[r->idx[1 + c]];
        target[c] += v[r->idx[4 + c]];
      }
      Eigen::Vector3d P;
      e.ToolPoint(*r, tip, &P);
      const Eigen::Vector3d d = P - target;
      const double len = d.norm();
      e.residuals[e.row] = len - r->constant - v[r->idx[0]];
      const Eigen::Vector3d u = d / len;
      G.row(0) = u.transpose();
      e.Put(e.row, r->idx[0], -1.0);
      for (int k = 0; k < 3; ++k) e.Put(e.row, r->idx[4 + k], -u[k]);
      e.Chain(G, 1, r->idx + 1);
      e.row += 1;
    }
  }

  bool has_length() const override { return true; }
  void SetSample(const Eigen::MatrixXd& values, int r, double length, Observation* o) const override {
    BallMountData& d = o->data<BallMountData>();
    d.length = length;
    d.reading = values(r, 0);
    RequireFinite(d.reading, "ball samples: readings[" + std::to_string(r) + "]");
  }

  std::vector<const char*> plan_keys() const override {
    return {"type", "setup", "axes", "length", "tool_ball", "table_ball", "direction", "id"};
  }
  void AddInputs(SimulationPlan* plan, int i, const PlanSlot*, const RecordedContext*) const override {
    AddPlanInput(plan, i, 0, -1.0, NoiseLevel(plan->noise));
  }
  void ApplyInput(const SimulationPlan& plan, int i, int, double x, Observation* o) const override {
    o->data<BallMountData>().reading = plan.base.observations[i].data<BallMountData>().reading + x;
  }

 protected:
  void ValidateOwn(const Observation& o, const std::function<std::string()>& w) const override {
    const BallMountData& d = o.data<BallMountData>();
    if (!(std::abs(d.reading) <= kMaxDbbReading)) RequireBounded(d.reading, kMaxDbbReading, w() + ".reading");
    if (!(d.length > 0 && d.length <= kMaxLinear))
      throw std::invalid_argument(w() + ".length: must be > 0 and <= 1e5 mm");
  }
  void WriteOwn(const Observation& o, json* jo) const override {
    const BallMountData& d = o.data<BallMountData>();
    (*jo)["reading"] = d.reading;
    (*jo)["length"] = d.length;
  }
  void AddFunctor(ResidualBuilder& b, const Observation& o, const MountRefs& refs) const override {
    b.Add(new DbbResidual(b.context, o, refs), 1);
  }
  void SimulateReading(const json& e, const std::string& w, const PlanTruth& t, const std::string& prefix,
                       const Eigen::Vector3d& d, Observation* ob) const override {
    if (!e.contains("length")) throw std::invalid_argument(w + ".length: missing (nominal bar length, mm)");
    BallMountData& bar = ob->data<BallMountData>();
    bar.length = ReadBounded(e, "length", w, kMaxLinear);
    if (!(bar.length > 0)) throw std::invalid_argument(w + ".length: must be > 0 mm");
    bar.reading = d.norm() - bar.length - t.setup(prefix + ".length");
    // What the loader would refuse, refused here, naming the plan entry.
    if (!(std::abs(bar.reading) <= kMaxDbbReading))
      throw std::invalid_argument(w + ": the simulated reading " + std::to_string(bar.reading) +
                                  " mm is beyond a ball bar's range (|reading| <= 100 mm); is the "
                                  "bar length the ball distance at these axes?");
  }
  Eigen::Vector3d ReportRows(const double* r, const Eigen::Vector3d& d) const override {
    return r[0] * d.normalized();
  }
  // NC programs: a ball bar path (dbb_program).
  const char* nc_program() const override { return "dbb"; }
};

}  // namespace

const ObservationKind& DbbKind() {
  static const Kind kind;
  return kind;
}

}  // namespace fivecal
