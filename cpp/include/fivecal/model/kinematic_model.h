// KinematicModel: a Machine with one set of error values, prepared for fast
// double-precision forward kinematics and the analytic Jacobian of the tool
// point with respect to every machine parameter (Pinocchio's "Data": work
// buffers and precomputed constants, separate from the immutable model).
//
// The Jacobian uses the product-of-factors form of the chain. Every error
// parameter enters one factor G of  T = A . G(theta) . B,  a translation or a
// rotation about a local unit axis e, so with (R_a, t_a) the accumulated frame
// just after that factor and P the point in F:
//
//   translation:  dP/dtheta = R_a e
//   rotation:     dP/dtheta = (R_a e) x (P - t_a)
//
// Error-motion coefficients scale that by q^d. On the workpiece side the
// point is X = inv(T_fw) P, so a factor there contributes
// dX = -R_fw^T (the same twist evaluated at P). The Euler factors
// Rz(c) Ry(b) Rx(a) share one origin, and their axes in the frame before them
// are z, Rz(c) y and Rz(c) Ry(b) x.
#ifndef FIVECAL_KINEMATIC_MODEL_H_
#define FIVECAL_KINEMATIC_MODEL_H_

#include <Eigen/Core>
#include <vector>

#include "fivecal/model/machine.h"

namespace fivecal {

class KinematicModel {
 public:
  // theta: every machine parameter (Machine::parameter_names() order).
  KinematicModel(const Machine& m, const double* theta);

  const Machine& machine() const { return *machine_; }
  // Tip (F at the zero pose) including the tip.x|y|z offsets of theta.
  const Eigen::Vector3d& tip() const { return tip_; }

  // Tool point in the workpiece frame; q in mm / rad (machine axis order),
  // dir may be null. `tip` is the tool point in F at the zero pose.
  Eigen::Vector3d ToolPoint(const double* q, const int* dir, const Eigen::Vector3d& tip) const;
  void ToolPose(const double* q, const int* dir, const Eigen::Vector3d& tip, Eigen::Vector3d* point,
                Eigen::Vector3d* axis) const;

  // Tool point and J = dP/dtheta (3 x num_parameters, column-major). The
  // tip.x|y|z columns are dP/dtip, which also serve a ball-bar tool ball
  // whose tip is not the probe's. Every column is written unless
  // RestrictJacobian was called.
  void ToolPointJacobian(const double* q, const int* dir, const Eigen::Vector3d& tip,
                         Eigen::Vector3d* point, double* J) const;

  // A fit needs only the columns of its estimated parameters: afterwards
  // ToolPointJacobian writes the wanted columns and the tip columns; the
  // others are left as they are.
  void RestrictJacobian(const std::vector<int>& wanted_parameters);

  // The long-data kernel's form of ToolPoint / ToolPointJacobian: kLanes
  // samples at once as structure of arrays (entry l of a block of kLanes is
  // sample l), so that the chain runs as SIMD over samples. The same chain
  // and the same columns (a gtest compares them to 1e-12 at random poses and
  // errors); what it saves: the frames stay one shared matrix until the first
  // commanded rotation (a column of linear axes is a sum of vectors), each
  // rotary command's sine and cosine once per sample, and only the columns
  // asked for are formed.
  //   q:    q[k kLanes + l], axis k (machine order) of sample l, mm / rad;
  //   dir:  likewise, -1 / 0 / +1 (null: no backlash direction);
  //   tip:  tip[c kLanes + l], the tool point at the zero pose (F);
  //   P:    P[c kLanes + l], the tool point in the workpiece frame.
  // With J: for the machine parameter columns[j] (one RestrictJacobian
  // wants, or a tip.x|y|z), dP_c/dtheta at J[(3 j + c) kLanes + l]; with
  // dtip too: dP_r/dtip_c at dtip[(3 r + c) kLanes + l].
  static constexpr int kLanes = 8;
  void ToolPointLanes(const double* q, const double* dir, const double* tip, double* P, const int* columns,
                      int num_columns, double* J, double* dtip) const;

 private:
  struct AxisConstants {
    Eigen::Matrix3d RE;     // Rz(EC0) Ry(EB0) Rx(EA0)
    double loc_sin[3], loc_cos[3];  // of EA0 EB0 EC0
    bool loc_rot[3];                // EA0 EB0 EC0 nonzero
    Eigen::Vector3d tE;     // p_k - p_parent + (EX0, EY0, EZ0)
    Eigen::Vector3d eAxes[3];  // local axes of EA0 EB0 EC0 (x_c, y_c, z)
    Eigen::Vector3d direction;
    int unit_axis = -1;     // direction = unit_sign * e_unit_axis, or -1 (general)
    double unit_sign = 1.0;
    bool rotary = false;
    const double* poly;     // theta + motion_index(k, 0, 1): 18 coefficients
    bool motion_t = false, motion_r = false;
    bool motion[6];         // component c has a nonzero coefficient
    double backlash = 0.0;
    int offset = 0;         // location_index(k, 0)
    int backlash_index = -1;
    int motion_index[6][4];  // motion_index(k, c, d), d = 1..3
    bool want_location = true, want_motion = true;  // Jacobian groups to write
    // Within them, the columns to write: location component c (bit c), the
    // backlash (bit 6); error motion component c, degree d (bit 3 c + d - 1).
    unsigned location_mask = 0x7f, motion_mask = 0x3ffff;
  };
  // Frames recorded along one chain for the Jacobian (rotations relative to
  // the chain's base frame).
  struct Factor {
    Eigen::Matrix3d R_before;   // before E_k (rotation only; translation irrelevant)
    Eigen::Vector3d oE;         // origin of the E_k rotations
    Eigen::Vector3d backlash_w; // direction of the commanded motion (after E_k)
    Eigen::Matrix3d R_afterM;   // after M_k
    Eigen::Vector3d oEps;       // origin of the eps_k rotations
    Eigen::Vector3d epsW[3];    // axes of the eps rotations EA EB EC (base frame)
    double qpow[4];             // 1, q, q^2, q^3
  };

  static constexpr int kMaxChain = 8;
  struct LaneFrame;   // ToolPointLanes' running frame and recorded factors
  struct LaneFactor;
  template <bool kRecord>
  void ChainLanes(const std::vector<int>& chain, const double* q, const double* dir, LaneFrame* frame,
                  LaneFactor* factors) const;
  template <bool kRecord>
  void Chain(const std::vector<int>& chain, const double* q, const int* dir, Eigen::Matrix3d* R,
             Eigen::Vector3d* t, Eigen::Vector3d* p_last, Factor* factors) const;
  void Columns(const std::vector<int>& chain, const Factor* f, const int* dir,
               const Eigen::Vector3d& P, const Eigen::Matrix3d& out, double sign, double* J) const;

  const Machine* machine_;
  std::vector<AxisConstants> axes_;
  Eigen::Vector3d tip_;
};

}  // namespace fivecal

#endif  // FIVECAL_KINEMATIC_MODEL_H_
