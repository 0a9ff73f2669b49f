// What the ball-sample kinds (dbb, ball3d) share: a tool ball at tool_ball
// (F at the zero pose) and a table ball or nest at table_ball (workpiece
// frame), one mounting per setup id with the parameters
// <kind>[.<setup>].tool.x|y|z and .table.x|y|z (and dbb's .length).
#ifndef FIVECAL_OBSERVATIONS_BALL_MOUNT_H_
#define FIVECAL_OBSERVATIONS_BALL_MOUNT_H_

#include <memory>

#include "fivecal/observations/kind.h"
#include "fivecal/observations/residuals.h"

namespace fivecal {

// A mounting's setup parameters as a residual sees them: length offset
// (dbb only), tool-ball and table-ball offsets.
struct MountRefs {
  SetupRef length;
  SetupRef tool[3];
  SetupRef table[3];
};

// The tool ball's centre P_ball minus the table ball's (workpiece frame), for
// a tool whose tip is tool_ball + <kind>.tool (F at the zero pose) and a
// table ball at table_ball + <kind>.table.
template <typename T>
Vec3<T> BallDistance(const ParameterAccess& access, const PoseData& pose, T const* const* p,
                     const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball, const MountRefs& refs) {
  std::vector<T> theta;
  access.Theta(p, &theta);
  const Machine& m = access.machine();
  Vec3<T> tip = tool_ball.template cast<T>(), table = table_ball.template cast<T>();
  for (int i = 0; i < 3; ++i) {
    tip[i] += access.Setup(p, refs.tool[i]);
    table[i] += access.Setup(p, refs.table[i]);
  }
  Vec3<T> P;
  ToolInWorkpiece<T>(m, theta.data(), pose.q.data(), pose.dir.data(), tip, &P);
  return P - table;
}

class BallMountKind : public ObservationKind {
 public:
  // The columns of every ball mounting's table: id, sigma, setup and the
  // tool and table balls (a column each, else the sidecar's).
  static std::vector<TableColumn> MountColumns();
  void Validate(const Dataset& ds, const Observation& o,
                const std::function<std::string()>& where) const final;
  void Write(const Observation& o, nlohmann::json* out) const override;

  void AddObservationParameters(const Observation& o, ParameterTable* t) const final;
  bool IsParameterName(const std::string& rest) const final;
  std::vector<PriorClass> prior_classes() const override;
  std::vector<int> MountPositions(const ParameterTable& t, const Observation& o) const final;
  void AddResidual(ResidualBuilder& b, const Observation& o) const final;
  void PrepareAnalytic(const Dataset& ds, const ParameterTable& t, const Observation& o,
                       AnalyticRow* r) const final;
  void PrepareAnalyticAfter(const Dataset& ds, const ParameterTable& t, const Observation& po,
                            const AnalyticRow& prev, const Observation& o, AnalyticRow* r) const final;
  void SimulateEntry(const nlohmann::json& e, const std::string& where, const PlanTruth& t,
                     Observation* ob, PlanSlot* slot) const final;
  bool LengthReference() const final { return true; }
  ObservationPayload NewPayload() const final { return BallMountData{}; }
  // The column block of a trace and its fused kernel (solve/long_kernel.h):
  // a mounting with a length has one row, the ball distance less the bar
  // (|P - table| - (length + reading + <kind>.length)); one without has
  // three, the ball displacement (P - table - measured).
  std::unique_ptr<LongRun> MakeLongRun(const Dataset& ds, const ParameterTable& t,
                                       const std::vector<int>& estimated, int begin, int end) const final;
  void ReportVector(const ReportContext& c, const Observation& o, const double* r, Eigen::Vector3d* point,
                    Eigen::Vector3d* vector) const final;

  // Column blocks: a block is one mounting (set-up, balls, bar length); the
  // per-row values are the reading (dbb) or the measured x y z (ball3d).
  int block_values() const final { return has_length() ? 1 : 3; }
  std::string block_value_name(int v) const final;
  double block_value_bound(int v) const final;
  ObservationPayload BlockCommon(const Observation& o) const final;
  bool BlockShares(const ObservationPayload& common, const Observation& o) const final;
  void BlockValues(const Observation& o, double* v) const final;
  void SetBlockValues(const double* v, Observation* o) const final;

  // Whether the mounting has a length parameter (<kind>[.<setup>].length)
  // and samples a bar length.
  virtual bool has_length() const = 0;
  // Sample r of Dataset::AppendBallSamples: its row of `values` (rows()
  // wide) and the bar length.
  virtual void SetSample(const Eigen::MatrixXd& values, int r, double length, Observation* o) const = 0;

 protected:
  // Reads setup, tool_ball and table_ball (a kind's Read calls it).
  static void ReadMount(const nlohmann::json& o, const std::string& where, Observation* ob);
  // The flat form's slots every mounting has (flat_keys() starts with
  // MountFlatKeys()); a kind's own keys follow from kFlatOwn.
  enum MountSlot { kFlatSetup, kFlatToolBall, kFlatTableBall, kFlatOwn };
  static std::vector<FlatKey> MountFlatKeys() {
    return {{"setup", FlatKey::kText, true}, {"tool_ball", FlatKey::kVector}, {"table_ball", FlatKey::kVector}};
  }
  // The mounting from the flat form (a kind's ReadFlat calls it): false
  // unless both balls are given and the setup id is one ReadMount accepts.
  static bool ReadFlatMount(const FlatObservation& f, Observation* ob) {
    if (!f.has(kFlatToolBall) || !f.has(kFlatTableBall)) return false;
    if (f.has(kFlatSetup)) {
      if (f.text(kFlatSetup).find('.') != std::string::npos) return false;
      ob->setup = f.text(kFlatSetup);
    }
    BallMountData& d = ob->data<BallMountData>();
    d.tool_ball = f.vector(kFlatToolBall);
    d.table_ball = f.vector(kFlatTableBall);
    return true;
  }
  // The set-up id (when there is one) and both balls in the flat form (a
  // kind's WriteFlat calls it).
  static void WriteFlatMount(const Observation& o, FlatObservation* f) {
    const BallMountData& d = o.data<BallMountData>();
    if (!o.setup.empty()) f->set_text(kFlatSetup, &o.setup);
    f->set_vector(kFlatToolBall, d.tool_ball);
    f->set_vector(kFlatTableBall, d.table_ball);
  }
  // The kind's own fields (checked after the setup id, before the ball
  // positions; written with them).
  virtual void ValidateOwn(const Observation& o, const std::function<std::string()>& where) const = 0;
  virtual void WriteOwn(const Observation& o, nlohmann::json* out) const = 0;
  // Adds the kind's functor for observation `o` with its mounting `refs`.
  virtual void AddFunctor(ResidualBuilder& b, const Observation& o, const MountRefs& refs) const = 0;
  // The noise-free reading of a planned sample: P - table is the true ball
  // distance vector, `prefix` the mounting's parameter prefix.
  virtual void SimulateReading(const nlohmann::json& e, const std::string& where, const PlanTruth& t,
                               const std::string& prefix, const Eigen::Vector3d& distance,
                               Observation* ob) const = 0;
  // The report vector of rows r given the ball distance vector d.
  virtual Eigen::Vector3d ReportRows(const double* r, const Eigen::Vector3d& d) const = 0;
  // The tool ball at the solution from the sample's residual rows r where
  // they hold it whole (ball3d: r = P - table - measured), so the report
  // does not run the chain of every sample a third time; false (a length
  // reading holds one component): the report evaluates the chain.
  virtual bool PointFromRows(const double* r, const BallMountData& d, const Eigen::Vector3d& table_ball,
                             Eigen::Vector3d* point) const {
    (void)r, (void)d, (void)table_ball, (void)point;
    return false;
  }

 private:
  // The fields of a prepared row that come from the sample itself.
  static void PrepareSample(const Observation& o, AnalyticRow* r);

  // ---- What an NC program needs (io/nc_programs.py, io/dbb_program.py) ----
 public:
  // The program family the kind's plan entries run in (an R-test path, a
  // ball bar path); nullptr: no program writes them.
  virtual const char* nc_program() const { return nullptr; }
};

}  // namespace fivecal

#endif  // FIVECAL_OBSERVATIONS_BALL_MOUNT_H_
