// Dataset: a machine, the artefact it measured and the recorded observations
// (docs/formats.md, "Dataset"). Validation happens here, once, with
// messages naming the observation index and field; the residuals never check.
#ifndef FIVECAL_DATASET_H_
#define FIVECAL_DATASET_H_

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <variant>
#include <vector>

#include "fivecal/model/machine.h"
#include "fivecal/observations/payloads.h"

namespace fivecal {

struct Facet {
  std::string id;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // a point of the nominal plane, mm
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(); // unit outward normal
};

struct Sphere {
  std::string id;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius = 0.0;
};

// A cylinder section (observation type "cylinder"): the axis line through
// `point` along unit `axis`, workpiece frame. inside: a bore, touched from
// inside; otherwise a boss or a table periphery, touched from outside.
struct Cylinder {
  std::string id;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double radius = 0.0;
  bool inside = false;
};

struct ScaleBar {
  std::string sphere1, sphere2;
  double length = 0.0;  // calibrated centre distance, mm
};

struct Artefact {
  std::vector<Facet> facets;
  std::vector<Sphere> spheres;
  std::vector<ScaleBar> scale_bars;
  std::vector<Cylinder> cylinders;
  int FacetIndex(const std::string& id) const;   // -1 if absent
  int SphereIndex(const std::string& id) const;  // -1 if absent
  int CylinderIndex(const std::string& id) const;  // -1 if absent
};

// The observation kinds. Each has its file pair observations/<kind>.h|.cc
// and one line in observations/registry.cc (ObservationKind, kind.h), which
// say everything else about it.
enum class ObservationType { kFacet, kSphere, kDbb, kBall3d, kPoint, kPose, kDistance, kCylinder, kMachined };

// The kind's name in files ("facet", "sphere", "dbb", "ball3d").
const char* ObservationTypeName(ObservationType t);

// Residual rows one observation of a kind contributes (1, or 3 for ball3d).
int ResidualRows(ObservationType t);

// Default instrument noise (one sigma, mm) of a kind, used when a file
// declares none: typical noise levels of the instrument class, not of one
// particular instrument (each kind's file says which).
double DefaultSigma(ObservationType t);

// One observation: a common header that every kind has and generic code
// reads (type, id, axes, direction, sigma, setup), and the payload its kind
// owns (payloads.h), read only by that kind's code through data<T>().
struct Observation {
  ObservationType type = ObservationType::kFacet;
  std::string id;      // optional user label, kept through load and save
  // The mounting (dbb, ball3d), instrument (point, pose), station (distance)
  // or part (machined) id; "" = the kind's default set-up.
  std::string setup;
  Eigen::VectorXd axes;       // machine axis order, mm / degrees
  Eigen::VectorXi direction;  // last move direction per axis: -1, 0, +1
  // Declared noise (one sigma, mm): empty = DefaultSigma(type); otherwise one
  // value per residual row (ResidualRows(type)), finite and > 0. A file's
  // single number is expanded to every row.
  Eigen::VectorXd sigma;
  // The kind's own data: set to its kind's empty payload
  // (ObservationKind::NewPayload) before the kind reads into it.
  ObservationPayload payload;

  // The payload as the kind's struct T; std::invalid_argument naming the
  // observation's type (and id) when it holds another.
  template <class T>
  const T& data() const {
    if (const T* p = std::get_if<T>(&payload)) return *p;
    WrongPayload(T::kName);
  }
  template <class T>
  T& data() {
    if (T* p = std::get_if<T>(&payload)) return *p;
    WrongPayload(T::kName);
  }

 private:
  [[noreturn]] void WrongPayload(const char* wanted) const;
};

// The name a payload gives the thing its observation is about, whatever
// the kind (a touch's artefact id, a fixed-frame target's side, a machined
// feature), "" for a payload without one: what tells two observations of
// one type and set-up apart when code that is not about a kind compares
// them (a refit's reference, the design's cache).
const std::string& PayloadTarget(const Observation& o);

// The instrument id of an observation whose kind has one (point and pose:
// "instrument", distance: "station"), else nullptr.
const std::string* InstrumentId(const Observation& o);

// A long trace held as columns (issue 30): the samples of one columnar kind
// (ObservationKind::block_values() > 0: dbb, ball3d) and one set-up, with
// no Observation per sample. 10^7 R-test samples take 72 B each here
// (six axes, three readings) instead of an Observation's 312 B + heap.
//
// Row order: a dataset's observation index i runs over `observations`
// first (0 .. observations.size() - 1), then over the blocks' rows, block
// after block (Dataset::size(), Row()). A loader only puts rows into blocks
// when this order is the file's (the trailing rows of a trace file, which
// is every row of an R-test or ball-bar trace); rows of a columnar kind
// before a per-object row stay Observations. Messages therefore name block
// rows by the same index as a per-object row ("observations[i]", or the
// file row), and save -> load keeps the order, the ids and the values.
//
// Axes are kept in file units (mm, degrees), not the kernel's internal
// ones: a save writes them back bit for bit, messages quote what the file
// said, and the conversion (a multiply per rotary axis) costs nothing
// beside the kinematic chain the kernel evaluates per sample.
struct TraceBlock {
  ObservationType type = ObservationType::kBall3d;
  std::string setup;
  // What every row shares (a mounting's balls, a bar length): the kind's
  // payload with its per-row values zero (ObservationKind::BlockCommon).
  ObservationPayload common;
  // Machine axis order, one column of size() values each.
  std::vector<std::vector<double>> axes;
  // Empty: no row records a move direction; else one column per axis.
  std::vector<std::vector<int8_t>> direction;
  // The kind's per-row values (block_values() columns: dbb the reading,
  // ball3d the measured x y z).
  std::vector<std::vector<double>> values;
  // Declared noise: empty = the default for every row; otherwise one column
  // per residual row, each of one value (every row's) or of size() values,
  // NaN in a row that declares none (sigma_at()).
  std::vector<std::vector<double>> sigma;
  // Empty: no row has an id; else one per row ("" = none).
  std::vector<std::string> ids;

  size_t size() const { return axes.empty() ? 0 : axes[0].size(); }
  double sigma_at(int k, size_t r) const {
    const std::vector<double>& c = sigma[static_cast<size_t>(k)];
    return c.size() == 1 ? c[0] : c[r];
  }
};

class Dataset {
 public:
  explicit Dataset(Machine machine) : machine_(std::move(machine)) {}
  // require_observations=false accepts an empty observation list (a dataset
  // being built, e.g. by the simulator).
  static Dataset FromJson(const std::string& text, bool require_observations = true);
  std::string ToJson() const;

  const Machine& machine() const { return machine_; }
  double tip_radius = 0.0;
  Artefact artefact;
  std::vector<Observation> observations;
  // Long traces as column blocks; their rows follow `observations` (see
  // TraceBlock for the order). Code that reads samples one at a time uses
  // size() / Row() / ForEachRow(); code that needs Observation objects
  // calls Expanded() (or ExpandBlocks()) at its entry.
  std::vector<TraceBlock> blocks;
  // Declared noise per instrument id ("instruments" in the file): what an
  // observation of that instrument without its own sigma declares; one value
  // per residual row of its kind, or one for all when its rows share a unit.
  std::map<std::string, Eigen::VectorXd> instrument_sigma;
  // Placement uncertainty of set-up quantities ("setup_uncertainty" in the
  // file): set-up parameter name or "class:<class>" -> one sigma in the
  // parameter's unit (mm, rad), overriding the kinds' defaults (priors.h
  // PlacementSigma; docs/setup_uncertainty.md).
  std::map<std::string, double> setup_uncertainty;

  // Throws std::invalid_argument naming the observation index and field.
  void Validate() const;
  // Appends N ball-bar (type kDbb: `values` N x 1 readings, `length` the bar)
  // or ball3d (`values` N x 3 measured displacements) samples of one mounting
  // from arrays: large traces (10^6 samples) without going through JSON.
  // axes: N x num_axes (mm / degrees); dirs: optional N x num_axes.
  // sigma: the declared noise of every sample's rows (mm); 0 = the default.
  void AppendBallSamples(ObservationType type, const std::string& setup, const Eigen::MatrixXd& axes,
                         const Eigen::MatrixXi* dirs, const Eigen::Vector3d& tool_ball,
                         const Eigen::Vector3d& table_ball, double length,
                         const Eigen::MatrixXd& values, double sigma = 0.0);
  // A dataset with only the observations at `indices` (same machine and
  // artefact); block rows stay in blocks (consecutive rows of one block one
  // block), and follow the per-object observations as everywhere.
  Dataset Subset(const std::vector<int>& indices) const;

  // Every observation, per-object and block rows.
  size_t size() const { return observations.size() + block_rows(); }
  size_t block_rows() const {
    size_t n = 0;
    for (const TraceBlock& b : blocks) n += b.size();
    return n;
  }
  // Observation i (0 <= i < size()): a per-object one itself, a block row
  // filled into *scratch (reused row after row: no allocation once its
  // vectors have their sizes).
  const Observation& Row(size_t i, Observation* scratch) const;
  // The type of observation i, without filling a row.
  ObservationType TypeOf(size_t i) const {
    if (i < observations.size()) return observations[i].type;
    size_t r = i - observations.size();
    for (const TraceBlock& b : blocks) {
      if (r < b.size()) return b.type;
      r -= b.size();
    }
    return ObservationType::kFacet;  // out of range: as an empty Observation
  }
  // Row r of block b as an observation, into *o.
  void FillRow(const TraceBlock& b, size_t r, Observation* o) const;
  // Only the declared sigma of row r into *o (the rest of a block's rows'
  // set-up is the block's): ForEachRowNoise's step.
  static void FillRowSigma(const TraceBlock& b, size_t r, Observation* o);
  // f(i, observation) for every observation in order (block rows through
  // one scratch observation: f must not keep a reference to it).
  template <class F>
  void ForEachRow(F&& f) const {
    EachRow(f, false);
  }
  // The same for a walk that reads only a row's kind, set-up and declared
  // noise (the row sigmas of a fit): a block row is its block's first row
  // with its own sigma, not a whole row filled per sample (10^7 of them).
  template <class F>
  void ForEachRowNoise(F&& f) const {
    EachRow(f, true);
  }

 private:
  template <class F>
  void EachRow(F& f, bool noise_only) const {
    size_t i = 0;
    for (const Observation& o : observations) f(i++, o);
    Observation scratch;
    for (const TraceBlock& b : blocks) {
      if (noise_only && b.size()) FillRow(b, 0, &scratch);
      for (size_t r = 0, n = b.size(); r < n; ++r) {
        if (noise_only) FillRowSigma(b, r, &scratch);
        else FillRow(b, r, &scratch);
        f(i++, static_cast<const Observation&>(scratch));
      }
    }
  }

 public:
  // THE expansion: a copy whose blocks are Observations (same order), for
  // the code that works on Observation objects (procedures, design, refit,
  // simulation, the dense fit paths). A dataset without blocks is copied
  // as it is.
  Dataset Expanded() const;
  void ExpandBlocks();
  // The reverse: the trailing observations of columnar kinds (after the
  // last per-object one of another kind or shape) into blocks, in order.
  // What a loader that builds Observations calls so that long data fit and
  // save as columns. Returns the rows moved (none when fewer than
  // min_rows would move).
  size_t PackTraces(size_t min_rows = 0);
  // Appends observation o as the next row of the dataset's last block, or
  // of a new block (o of a columnar kind, every per-object observation
  // before it): the building step of PackTraces, Subset and loaders.
  void AppendBlockRow(const Observation& o);

 private:
  Machine machine_;
};

// `ds` itself, or its expansion (Dataset::Expanded) when it holds column
// blocks: what a consumer of Observation objects takes at its entry
// (`const ExpandedView view(given); const Dataset& ds = *view;`), so that
// no such consumer leaves block rows out.
class ExpandedView {
 public:
  explicit ExpandedView(const Dataset& ds) : p_(&ds) {
    if (!ds.blocks.empty()) {
      own_ = std::make_unique<Dataset>(ds.Expanded());
      p_ = own_.get();
    }
  }
  const Dataset& operator*() const { return *p_; }
  const Dataset* operator->() const { return p_; }

 private:
  std::unique_ptr<Dataset> own_;
  const Dataset* p_;
};

}  // namespace fivecal

#endif  // FIVECAL_DATASET_H_
