// The long-data kernel: R-test and ball-bar traces (10^4 to 10^7 samples, a
// handful of unknowns) fitted on the normal equations without a prepared
// row per sample.
//
// A kind that records long traces gives its samples as a LongRun
// (ObservationKind::MakeLongRun): a column block (structure of arrays: the
// axis columns in internal units, the readings, the set-up index of every
// sample and a small table of set-ups) and a fused evaluation that writes,
// for a chunk of samples, the residual rows and only the Jacobian columns of
// the estimated parameters (4 of 50 for a location fit), row-major so that
// a chunk's rows stay in the cache until AccumulateNormal has folded them
// into J^T J and J^T r.
//
// AccumulateNormal is compiled for AVX-512, AVX2+FMA and generic x86-64 and
// chosen at load time (target_clones), so the core still runs on any x86-64
// and other architectures build the plain loop. Its sum order depends on the
// rows alone: the partial sums of NormalEquationProblem's fixed blocks are
// the same whatever the thread count (to the clone's rounding).
#ifndef FIVECAL_LONG_KERNEL_H_
#define FIVECAL_LONG_KERNEL_H_

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "fivecal/model/kinematic_model.h"

namespace fivecal {

class Dataset;
class ParameterTable;

// Width of a chunk's Jacobian rows: p estimated parameters padded to a
// multiple of 8 (one AVX-512 register of doubles, two AVX2 ones), the
// padding columns zero; up to 4 parameters (a location fit of a trace) a
// width of 4, one AVX2 register, rather than 8 whose upper half would
// multiply zeros. Each entry of N is the same sum of the same products in
// the same order at either width.
inline int PaddedWidth(int p) { return p <= 4 ? 4 : (p + 7) / 8 * 8; }

class LongRun {
 public:
  virtual ~LongRun() = default;
  // Residual rows per sample.
  virtual int rows_per_sample() const = 0;
  // Samples [begin, end) of the run (0-based within it) at `values` (every
  // table entry), `model` built there (RestrictJacobian to the estimated set
  // when J is wanted): residual rows (mm) from r[0]; with J, the rows'
  // derivatives in the estimated parameters, row k at J + k ld, the columns
  // past p left as they are (the caller keeps them zero).
  virtual void Evaluate(const KinematicModel& model, const Eigen::VectorXd& values, int begin, int end,
                        double* r, double* J, int ld) const = 0;
};

// N += J^T J, g += J^T r over m rows of J (row-major, stride ld: 4 or a
// multiple of 8; the columns from p on zero). N is p x ld row-major: row a holds
// sum J_a J_b for every b < ld (the padding columns stay zero).
void AccumulateNormal(const double* J, const double* r, int m, int p, int ld, double* N, double* g);

// Which SIMD clone AccumulateNormal runs on this CPU ("avx512f",
// "x86-64-v3" or "default"): what the bench records.
const char* NormalKernelIsa();

}  // namespace fivecal

#endif  // FIVECAL_LONG_KERNEL_H_
