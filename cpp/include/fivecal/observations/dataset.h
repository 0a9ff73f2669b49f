// Dataset: a machine, the artefact it measured and the recorded observations
// (docs/formats.md, "Dataset"). Validation happens here, once, with
// messages naming the observation index and field; the residuals never check.
#ifndef FIVECAL_DATASET_H_
#define FIVECAL_DATASET_H_

#include <Eigen/Core>
#include <map>
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
  // A dataset with only the observations at `indices` (same machine and artefact).
  Dataset Subset(const std::vector<int>& indices) const;

 private:
  Machine machine_;
};

}  // namespace fivecal

#endif  // FIVECAL_DATASET_H_
