#include "fivecal/observations/ball_mount.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "fivecal/model/kinematic_model.h"
#include "fivecal/observations/simulate.h"
#include "fivecal/model/kinematics.h"
#include "fivecal/solve/analytic_residuals.h"
#include "fivecal/solve/long_kernel.h"
#include "fivecal/solve/problem.h"
#include "fivecal/observations/registry.h"
#include "json_util.h"

namespace fivecal {

using namespace json_util;

namespace {
const char* kXYZ[3] = {"x", "y", "z"};

// A trace as columns: per sample its axis readings (internal units), its
// readings and the index of its mounting; per mounting the balls and the
// table entries of its parameters. No per-sample row is prepared at a pass.
//
// Rows per sample R: 3, the displacement d = P - (table + dt) - measured
// (gradient in P: the identity); 1, the distance |P - (table + dt)| -
// (constant + length) (gradient u, the unit ball-to-ball vector). With the
// tool ball at tool_ball + dtool acting as the tip, dP/d(dtool) is the
// kinematic model's tip columns; the table offset enters as -gradient.
template <int R>
class MountRun final : public LongRun {
 public:
  struct Mount {
    Eigen::Vector3d tool_ball, table_ball;
    int idx[7];
  };
  // Where column j of a mounting's rows comes from.
  enum Source : int { kZero, kMachine, kTool, kTable, kLength };

  MountRun(const Dataset& ds, const ParameterTable& t, const ObservationKind& kind, const std::vector<int>& est,
           int begin, int end)
      : na_(ds.machine().num_axes()), n_(end - begin), p_(static_cast<int>(est.size())),
        np_(ds.machine().num_parameters()), tip0_(ds.machine().tip_index()) {
    const Machine& m = ds.machine();
    if (static_cast<size_t>(begin) >= ds.observations.size() && n_ > 0) {
      // Rows of a column block: its columns are borrowed, not copied (the
      // block outlives the run: both belong to the fit's dataset).
      size_t at = ds.observations.size();
      const TraceBlock* b = nullptr;
      for (const TraceBlock& x : ds.blocks) {
        if (at == static_cast<size_t>(begin)) b = &x;
        at += x.size();
      }
      if (!b || b->size() != static_cast<size_t>(n_))
        throw std::logic_error("ball run: rows " + std::to_string(begin) + " to " + std::to_string(end) +
                               " are not one column block");
      block_ = b;
      for (int k = 0; k < na_; ++k) scale_[k] = m.axis(k).rotary() ? (M_PI / 180.0) : 1.0;
      Observation first;
      ds.FillRow(*b, 0, &first);
      AddMount(t, kind, est, first);
      return;
    }
    q_.resize(static_cast<size_t>(n_) * na_);
    reading_.resize(static_cast<size_t>(n_) * R);
    mount_.resize(n_);
    bool any_dir = false;
    for (int i = 0; i < n_; ++i) {
      const Observation& o = ds.observations[begin + i];
      const BallMountData& b = o.data<BallMountData>();
      AxisValuesToInternal(m, o.axes.data(), q_.data() + static_cast<size_t>(i) * na_);
      if (!any_dir && (o.direction.array() != 0).any()) {
        any_dir = true;
        dir_.assign(static_cast<size_t>(n_) * na_, 0);
      }
      if (any_dir) std::copy(o.direction.data(), o.direction.data() + na_, dir_.data() + static_cast<size_t>(i) * na_);
      if constexpr (R == 3)
        for (int c = 0; c < 3; ++c) reading_[static_cast<size_t>(i) * R + c] = b.measured[c];
      else
        reading_[i] = b.length + b.reading;
      // A trace is one mounting: the previous sample's first.
      int k = mounts_.empty() ? -1 : mount_[i > 0 ? i - 1 : 0];
      auto same = [&](int j) {
        return setups_[j] == o.setup && mounts_[j].tool_ball == b.tool_ball && mounts_[j].table_ball == b.table_ball;
      };
      if (k < 0 || !same(k)) {
        k = -1;
        for (int j = 0; j < static_cast<int>(mounts_.size()) && k < 0; ++j)
          if (same(j)) k = j;
        if (k < 0) k = AddMount(t, kind, est, o);
      }
      mount_[i] = k;
    }
  }

  // A new mounting (o's) and where its rows' Jacobian columns come from.
  int AddMount(const ParameterTable& t, const ObservationKind& kind, const std::vector<int>& est,
               const Observation& o) {
    const BallMountData& b = o.data<BallMountData>();
    Mount mt;
    mt.tool_ball = b.tool_ball;
    mt.table_ball = b.table_ball;
    const std::vector<int>& g = t.group(kind.type(), o.setup);
    for (int c = 0; c < 7; ++c) mt.idx[c] = g[c];
    const int k = static_cast<int>(mounts_.size());
    mounts_.push_back(mt);
    setups_.push_back(o.setup);
    for (int j = 0; j < p_; ++j) {
      const int e = est[j];
      int src = kZero, arg = 0;
      if (e < np_) {
        // The probe tip's offsets do not carry the ball.
        if (!(e >= tip0_ && e < tip0_ + 3)) src = kMachine, arg = e;
      } else {
        for (int c = 0; c < 3; ++c) {
          if (e == mt.idx[1 + c]) src = kTool, arg = c;
          if (e == mt.idx[4 + c]) src = kTable, arg = c;
        }
        if (e == mt.idx[0] && mt.idx[0] >= 0) src = kLength;
      }
      source_.push_back(src);
      arg_.push_back(arg);
    }
    block_length_ = b.length;
    return k;
  }

  int rows_per_sample() const override { return R; }

  void Evaluate(const KinematicModel& model, const Eigen::VectorXd& v, int begin, int end, double* r, double* J,
                int ld) const override {
    constexpr int W = KinematicModel::kLanes;
    const int nm = static_cast<int>(mounts_.size());
    // Per mounting at these values: the tool ball (the tip) and the table ball.
    Eigen::Vector3d tip[8], target[8];
    std::vector<Eigen::Vector3d> tips, targets;
    Eigen::Vector3d* tp = tip;
    Eigen::Vector3d* tg = target;
    if (nm > 8) {
      tips.resize(nm);
      targets.resize(nm);
      tp = tips.data();
      tg = targets.data();
    }
    double length[8];
    std::vector<double> lengths(nm > 8 ? nm : 0);
    double* ln = nm > 8 ? lengths.data() : length;
    for (int k = 0; k < nm; ++k) {
      const Mount& mt = mounts_[k];
      for (int c = 0; c < 3; ++c) {
        tp[k][c] = mt.tool_ball[c] + v[mt.idx[1 + c]];
        tg[k][c] = mt.table_ball[c] + v[mt.idx[4 + c]];
      }
      ln[k] = mt.idx[0] >= 0 ? v[mt.idx[0]] : 0.0;
    }
    // The machine columns asked of the kinematic model (the same for every
    // mounting: a machine parameter is kMachine in each) and each one's slot.
    std::vector<int> columns;
    std::vector<int> slot(p_, -1);
    if (J && nm > 0)
      for (int j = 0; j < p_; ++j)
        if (source_[j] == kMachine) {
          slot[j] = static_cast<int>(columns.size());
          columns.push_back(arg_[j]);
        }
    const int nc = static_cast<int>(columns.size());
    // One batch of W samples (the last one padded with its last sample):
    // inputs and outputs of KinematicModel::ToolPointLanes.
    alignas(64) double qb[64 * W], db[64 * W], tb[3 * W], Pb[3 * W], dtb[9 * W];
    std::vector<double> jb(static_cast<size_t>(3 * W) * std::max(nc, 1));
    if (na_ > 64) throw std::logic_error("ball mount: more than 64 axes");
    // A block (one mounting) is read from its columns in file units; other
    // runs from the copies the constructor made in internal units.
    const bool has_dir = block_ ? !block_->direction.empty() : !dir_.empty();
    auto mount_of = [&](int s) { return block_ ? 0 : mount_[s]; };
    for (int s0 = begin; s0 < end; s0 += W) {
      const int count = std::min(W, end - s0);
      for (int l = 0; l < W; ++l) {
        const int s = s0 + std::min(l, count - 1);
        if (block_) {
          for (int a = 0; a < na_; ++a) qb[a * W + l] = block_->axes[a][s] * scale_[a];
          if (has_dir)
            for (int a = 0; a < na_; ++a) db[a * W + l] = block_->direction[a][s];
        } else {
          const double* q = q_.data() + static_cast<size_t>(s) * na_;
          for (int a = 0; a < na_; ++a) qb[a * W + l] = q[a];
          if (has_dir) {
            const int* d = dir_.data() + static_cast<size_t>(s) * na_;
            for (int a = 0; a < na_; ++a) db[a * W + l] = d[a];
          }
        }
        const Eigen::Vector3d& t = tp[mount_of(s)];
        for (int c = 0; c < 3; ++c) tb[c * W + l] = t[c];
      }
      model.ToolPointLanes(qb, has_dir ? db : nullptr, tb, Pb, columns.data(), nc, J ? jb.data() : nullptr,
                           J ? dtb : nullptr);
      for (int l = 0; l < count; ++l) {
        const int s = s0 + l;
        const int k = mount_of(s);
        double rb[3];
        const double* rd;
        if (block_) {
          if constexpr (R == 3)
            for (int c = 0; c < 3; ++c) rb[c] = block_->values[c][s];
          else
            rb[0] = block_length_ + block_->values[0][s];
          rd = rb;
        } else {
          rd = reading_.data() + static_cast<size_t>(s) * R;
        }
        const Eigen::Vector3d P(Pb[l], Pb[W + l], Pb[2 * W + l]);
        double* out = r + static_cast<size_t>(s - begin) * R;
        Eigen::Matrix<double, R, 3> G;
        if constexpr (R == 3) {
          for (int c = 0; c < 3; ++c) out[c] = P[c] - tg[k][c] - rd[c];
          G.setIdentity();
        } else {
          const Eigen::Vector3d dd = P - tg[k];
          const double len = dd.norm();
          out[0] = len - rd[0] - ln[k];
          G = (dd / len).transpose();
        }
        if (!J) continue;
        const int* src = source_.data() + static_cast<size_t>(k) * p_;
        const int* arg = arg_.data() + static_cast<size_t>(k) * p_;
        for (int row = 0; row < R; ++row) {
          double* jr = J + (static_cast<size_t>(s - begin) * R + row) * ld;
          const double g0 = G(row, 0), g1 = G(row, 1), g2 = G(row, 2);
          for (int j = 0; j < p_; ++j) {
            double x = 0.0;
            switch (src[j]) {
              case kMachine: {
                const double* c = jb.data() + static_cast<size_t>(3 * slot[j]) * W + l;
                x = g0 * c[0] + g1 * c[W] + g2 * c[2 * W];
                break;
              }
              case kTool: {
                // dP/dtip column arg[j]: rows r at dtb[(3 r + arg) W + l].
                const double* c = dtb + arg[j] * W + l;
                x = g0 * c[0] + g1 * c[3 * W] + g2 * c[6 * W];
                break;
              }
              case kTable:
                x = -G(row, arg[j]);
                break;
              case kLength:
                x = -1.0;
                break;
              default:
                break;
            }
            jr[j] = x;
          }
        }
      }
    }
  }

 private:
  int na_, n_, p_, np_, tip0_;
  // Borrowed rows of a column block (one mounting), or null: the copies below.
  const TraceBlock* block_ = nullptr;
  double scale_[16] = {};
  double block_length_ = 0.0;
  std::vector<double> q_;
  std::vector<int> dir_;  // empty: no sample records a move direction
  std::vector<double> reading_;
  std::vector<int32_t> mount_;
  std::vector<Mount> mounts_;
  std::vector<std::string> setups_;
  std::vector<int> source_, arg_;  // mounts x p
};
}  // namespace

std::vector<TableColumn> BallMountKind::MountColumns() {
  std::vector<TableColumn> c = {TableColumn("id", "id").Text(), TableColumn("sigma", "sigma").Measured(),
                                TableColumn("setup", "setup").Text()};
  for (const char* ball : {"tool_ball", "table_ball"})
    for (int i = 0; i < 3; ++i) c.push_back(TableColumn(std::string(ball) + "_" + kXYZ[i], ball, i).Sidecar(ball));
  return c;
}

std::unique_ptr<LongRun> BallMountKind::MakeLongRun(const Dataset& ds, const ParameterTable& t,
                                                    const std::vector<int>& est, int begin, int end) const {
  if (rows() == 3) return std::make_unique<MountRun<3>>(ds, t, *this, est, begin, end);
  if (rows() == 1) return std::make_unique<MountRun<1>>(ds, t, *this, est, begin, end);
  return nullptr;
}

void BallMountKind::ReadMount(const json& o, const std::string& w, Observation* ob) {
  ob->setup = ReadSetup(o, w);
  // By reference: o.value(key, json()) copies the array, per sample of a trace.
  static const json absent;
  auto member = [&](const char* key) -> const json& {
    auto it = o.find(key);
    return it == o.end() ? absent : *it;
  };
  BallMountData& d = ob->data<BallMountData>();
  d.tool_ball = ReadVector3(member("tool_ball"), w + ".tool_ball");
  d.table_ball = ReadVector3(member("table_ball"), w + ".table_ball");
}

void BallMountKind::Validate(const Dataset&, const Observation& o,
                             const std::function<std::string()>& w) const {
  if (o.setup.find('.') != std::string::npos)
    throw std::invalid_argument(w() + ".setup: " + Quote(o.setup) + " must not contain '.'");
  ValidateOwn(o, w);
  const BallMountData& d = o.data<BallMountData>();
  for (int c = 0; c < 3; ++c) {
    if (!(std::abs(d.tool_ball[c]) <= kMaxLinear))
      RequireBounded(d.tool_ball[c], kMaxLinear, w() + ".tool_ball[" + std::to_string(c) + "]");
    if (!(std::abs(d.table_ball[c]) <= kMaxLinear))
      RequireBounded(d.table_ball[c], kMaxLinear, w() + ".table_ball[" + std::to_string(c) + "]");
  }
}

void BallMountKind::Write(const Observation& o, json* jo) const {
  const BallMountData& d = o.data<BallMountData>();
  (*jo)["tool_ball"] = Array3(d.tool_ball);
  (*jo)["table_ball"] = Array3(d.table_ball);
  WriteOwn(o, jo);
}

void BallMountKind::AddObservationParameters(const Observation& o, ParameterTable* t) const {
  if (t->has_group(type(), o.setup)) return;
  const std::string base = name();
  const std::string prefix = o.setup.empty() ? base : base + "." + o.setup;
  // [length, tool x y z, table x y z]; length is -1 when the kind has none.
  std::vector<int> idx;
  idx.push_back(has_length() ? t->Add(prefix + ".length") : -1);
  for (const char* c : kXYZ) idx.push_back(t->Add(prefix + ".tool." + c));
  for (const char* c : kXYZ) idx.push_back(t->Add(prefix + ".table." + c));
  t->AddGroup(type(), o.setup, idx);
}

bool BallMountKind::IsParameterName(const std::string& rest) const {
  auto ends_with = [&](const std::string& suffix) {
    return rest.size() > suffix.size() && rest.compare(rest.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  for (const std::string f : {"length", "tool.x", "tool.y", "tool.z", "table.x", "table.y", "table.z"}) {
    if (!has_length() && f == "length") continue;
    // <kind>.<field> (the default mounting) or <kind>.<setup>.<field> with
    // a setup id free of dots.
    if (rest == f) return true;
    if (ends_with("." + f)) return rest.substr(0, rest.size() - f.size() - 1).find('.') == std::string::npos;
  }
  return false;
}

std::vector<PriorClass> BallMountKind::prior_classes() const {
  return {{"mount", 2.0, "mm",
           "dbb/ball3d tool and table ball positions (dbb.tool.x, ball3d.R1.table.z ...): "
           "a nest is placed to about a millimetre"}};
}

std::vector<int> BallMountKind::MountPositions(const ParameterTable& t, const Observation& o) const {
  const auto& mt = t.group(type(), o.setup);
  return std::vector<int>(mt.begin() + 1, mt.begin() + 7);
}

void BallMountKind::AddResidual(ResidualBuilder& b, const Observation& o) const {
  const auto& mt = b.table.group(type(), o.setup);
  MountRefs refs;
  if (mt[0] >= 0) refs.length = b.Ref(mt[0]);
  for (int c = 0; c < 3; ++c) refs.tool[c] = b.Ref(mt[1 + c]);
  for (int c = 0; c < 3; ++c) refs.table[c] = b.Ref(mt[4 + c]);
  AddFunctor(b, o, refs);
}

// a: table ball, tool_ball, measured (ball3d), constant: length + reading
// (dbb), idx: the mounting's [length, tool x y z, table x y z].
void BallMountKind::PrepareAnalytic(const Dataset&, const ParameterTable& t, const Observation& o,
                                    AnalyticRow* r) const {
  const auto& mt = t.group(type(), o.setup);
  for (int c = 0; c < 7; ++c) r->idx[c] = mt[c];
  PrepareSample(o, r);
}

// A trace's samples share one mounting: its indices from the row before
// rather than a lookup of the setup id per sample.
void BallMountKind::PrepareAnalyticAfter(const Dataset& ds, const ParameterTable& t, const Observation& po,
                                         const AnalyticRow& prev, const Observation& o, AnalyticRow* r) const {
  if (o.setup != po.setup) return PrepareAnalytic(ds, t, o, r);
  std::copy(prev.idx, prev.idx + 7, r->idx);
  PrepareSample(o, r);
}

void BallMountKind::PrepareSample(const Observation& o, AnalyticRow* r) {
  const BallMountData& d = o.data<BallMountData>();
  r->a = d.table_ball;
  r->tool_ball = d.tool_ball;
  r->measured = d.measured;
  r->constant = d.length + d.reading;
}

void BallMountKind::SimulateEntry(const json& e, const std::string& w, const PlanTruth& t, Observation* ob,
                                  PlanSlot*) const {
  const Machine& m = t.dataset->machine();
  ob->setup = ReadSetup(e, w);
  BallMountData& d = ob->data<BallMountData>();
  d.tool_ball = ReadVector3(e.value("tool_ball", json()), w + ".tool_ball");
  d.table_ball = ReadVector3(e.value("table_ball", json()), w + ".table_ball");
  const std::string prefix = std::string(name()) + (ob->setup.empty() ? "" : "." + ob->setup);
  const Eigen::Vector3d tool_true =
      d.tool_ball + Eigen::Vector3d(t.setup(prefix + ".tool.x"), t.setup(prefix + ".tool.y"),
                                      t.setup(prefix + ".tool.z"));
  const Eigen::Vector3d table_true =
      d.table_ball + Eigen::Vector3d(t.setup(prefix + ".table.x"), t.setup(prefix + ".table.y"),
                                       t.setup(prefix + ".table.z"));
  std::vector<int> dir(ob->direction.data(), ob->direction.data() + m.num_axes());
  const Eigen::Vector3d P = ToolAtCommand(m, t.theta, ob->axes, dir, tool_true);
  SimulateReading(e, w, t, prefix, P - table_true, ob);
}

void BallMountKind::ReportVector(const ReportContext& c, const Observation& o, const double* r,
                                 Eigen::Vector3d* point, Eigen::Vector3d* vector) const {
  const Dataset& ds = *c.dataset;
  const Eigen::VectorXd& values = *c.values;
  const auto& mt = c.table->group(type(), o.setup);
  const BallMountData& d = o.data<BallMountData>();
  Eigen::Vector3d table_ball = d.table_ball;
  for (int k = 0; k < 3; ++k) table_ball[k] += values[mt[4 + k]];
  if (!PointFromRows(r, d, table_ball, point)) {
    Eigen::Vector3d t = c.model->tip();
    for (int k = 0; k < 3; ++k) t[k] = d.tool_ball[k] + values[mt[1 + k]];
    const PoseData pose(ds.machine(), o);
    *point = c.model->ToolPoint(pose.q.data(), pose.dir.data(), t);
  }
  *vector = ReportRows(r, *point - table_ball);
}

std::string BallMountKind::block_value_name(int v) const {
  return has_length() ? std::string("reading") : std::string("measured_") + kXYZ[v];
}

double BallMountKind::block_value_bound(int) const { return has_length() ? kMaxDbbReading : kMaxLinear; }

ObservationPayload BallMountKind::BlockCommon(const Observation& o) const {
  BallMountData d = o.data<BallMountData>();
  d.measured.setZero();
  d.reading = 0.0;
  return d;
}

bool BallMountKind::BlockShares(const ObservationPayload& common, const Observation& o) const {
  const BallMountData* c = std::get_if<BallMountData>(&common);
  const BallMountData* d = std::get_if<BallMountData>(&o.payload);
  return c && d && c->tool_ball == d->tool_ball && c->table_ball == d->table_ball && c->length == d->length;
}

void BallMountKind::BlockValues(const Observation& o, double* v) const {
  const BallMountData& d = o.data<BallMountData>();
  if (has_length()) v[0] = d.reading;
  else
    for (int c = 0; c < 3; ++c) v[c] = d.measured[c];
}

void BallMountKind::SetBlockValues(const double* v, Observation* o) const {
  BallMountData& d = o->data<BallMountData>();
  if (has_length()) d.reading = v[0];
  else
    for (int c = 0; c < 3; ++c) d.measured[c] = v[c];
}

// Here rather than in dataset.cc: array samples are the ball kinds' own.
// They go into a column block of their own (dataset.h TraceBlock): no
// Observation per sample.
void Dataset::AppendBallSamples(ObservationType type, const std::string& setup,
                                const Eigen::MatrixXd& axes, const Eigen::MatrixXi* dirs,
                                const Eigen::Vector3d& tool_ball, const Eigen::Vector3d& table_ball,
                                double length, const Eigen::MatrixXd& values, double sigma) {
  const int n = static_cast<int>(axes.rows()), na = machine_.num_axes();
  const auto* kind = dynamic_cast<const BallMountKind*>(&KindOf(type));
  if (!kind) throw std::invalid_argument("ball samples: type must be dbb or ball3d");
  const int width = kind->rows();
  if (axes.cols() != na)
    throw std::invalid_argument("ball samples: axes must have " + std::to_string(na) + " columns (" +
                                machine_.axis_names() + ")");
  if (values.rows() != n || values.cols() != width)
    throw std::invalid_argument(std::string("ball samples: ") +
                                (width == 1 ? "readings" : "measured") + " must be " +
                                std::to_string(n) + " x " + std::to_string(width));
  if (dirs && (dirs->rows() != n || dirs->cols() != na))
    throw std::invalid_argument("ball samples: directions must match axes");
  if (setup.find('.') != std::string::npos)
    throw std::invalid_argument("ball samples: setup '" + setup + "' must not contain '.'");
  for (int i = 0; i < 3; ++i) {
    RequireFinite(tool_ball[i], "ball samples: tool_ball");
    RequireFinite(table_ball[i], "ball samples: table_ball");
  }
  if (kind->has_length() && !(length > 0))
    throw std::invalid_argument("ball samples: length must be > 0 mm");
  if (sigma != 0.0 && !(sigma >= kMinSigma && sigma <= kMaxSigma))
    throw std::invalid_argument("ball samples: sigma must be a finite number > 0 mm (0 = the default)");
  for (int k = 0; k < na; ++k)
    for (int r = 0; r < n; ++r) {
      RequireFinite(axes(r, k), "ball samples: axes." + std::string(1, machine_.axis(k).name) + "[" +
                                    std::to_string(r) + "]");
      if (dirs && std::abs((*dirs)(r, k)) > 1)
        throw std::invalid_argument("ball samples: directions must be -1, 0 or +1");
    }
  for (int c = 0; c < width; ++c)
    for (int r = 0; r < n; ++r)
      RequireFinite(values(r, c), std::string("ball samples: ") + (width == 1 ? "readings[" : "measured[") +
                                      std::to_string(r) + "]");
  if (n == 0) return;
  TraceBlock b;
  b.type = type;
  b.setup = setup;
  BallMountData common;
  common.tool_ball = tool_ball;
  common.table_ball = table_ball;
  if (kind->has_length()) common.length = length;
  b.common = common;
  b.axes.resize(na);
  for (int k = 0; k < na; ++k) b.axes[k].assign(axes.col(k).data(), axes.col(k).data() + n);
  if (dirs && (dirs->array() != 0).any()) {
    b.direction.resize(na);
    for (int k = 0; k < na; ++k) {
      b.direction[k].resize(n);
      for (int r = 0; r < n; ++r) b.direction[k][r] = static_cast<int8_t>((*dirs)(r, k));
    }
  }
  b.values.resize(width);
  for (int c = 0; c < width; ++c) b.values[c].assign(values.col(c).data(), values.col(c).data() + n);
  if (sigma > 0) b.sigma.assign(width, std::vector<double>(1, sigma));
  blocks.push_back(std::move(b));
}

}  // namespace fivecal
