// Planar circular tests with a double ball bar (ISO 230-4, and the
// diagnosis ballbar software reports), plus the Fourier harmonics of a trace.
//
// A run: the machine interpolates a circle of nominal radius R around the
// pivot in a plane with axes (1, 2) (XY: X, Y; YZ: Y, Z; ZX: Z, X). The
// polar angle phi is measured from axis 1 towards axis 2; the readings d(phi)
// are bar length minus R (mm); direction +1 = counter-clockwise (phi
// increasing), -1 = clockwise.
//
// ISO 230-4 evaluation, per run (P_i = (R + d_i)(cos phi_i, sin phi_i)):
//  * least-squares circle (centre c, radius R_ls): the geometric fit of
//    circle_fit.h, "LSC";
//  * circular deviation G = max_i r_i - min_i r_i, r_i = |P_i - c| (the
//    minimum radial separation of two circles concentric with the LSC that
//    enclose the path);
//  * radial deviation F: max and min of d_i (the path against the nominal
//    circle with its centre on the nominal centre, the pivot);
//  * mean radius R_ls, centre offset c.
// Both runs: circular hysteresis H = max over phi of |d_ccw(phi) - d_cw(phi)|
// (ISO 230-4: the largest radial difference between the two paths), both
// paths taken about the pivot and compared at the CW run's angles by linear
// interpolation of the CCW run (periodic when it covers a full turn).
//
// Diagnosis: one linear least-squares fit of every reading of every run to
//
//   d = dR + x0 cos phi + y0 sin phi                       radius, centre offset
//     + (R m / 2) cos 2phi                                  scale mismatch m = k1 - k2
//     - (R psi / 2) sin 2phi                                squareness psi
//     + s (v dtau / 2) sin 2phi  = s (l / 2) sin 2phi        servo mismatch l = v dtau
//     + b1 cos phi sgn(dx1/dt) + b2 sin phi sgn(dx2/dt)     backlash b1, b2
//
// derived to first order from the axis errors they stand for:
//  * scale errors k1, k2: x1 = (1 + k1) x1_cmd ...: d = R(k1 cos^2 + k2 sin^2)
//    = R(k1 + k2)/2 + R(k1 - k2)/2 cos 2phi; the mean scale cannot be told
//    from the bar length, so it goes into dR and only m is reported;
//  * squareness psi (rad): the angle between the +1 and +2 motions is
//    90 deg + psi, i.e. x1 = x1_cmd - psi x2_cmd: d = -psi R cos phi sin phi;
//    psi > 0 stretches the trace along the 135/315 deg diagonal;
//  * servo mismatch: axis 1 lags its command by tau1, axis 2 by tau2; at
//    feed v (mm/s) the path angle advances at s v / R, so
//    x1 = R cos(phi - s v tau1 / R) ...: d = s v (tau1 - tau2)/2 sin 2phi;
//    the same sin 2phi as squareness but with the sign of the direction s,
//    which is why CW and CCW runs are both needed; l = v (tau1 - tau2) (mm),
//    dtau = l / v when the feed is given;
//  * backlash: x1 = x1_cmd + b1 sgn(dx1/dt) (fivecal's E11b: the axis sits
//    b1 ahead of its command in the direction it moves; the step seen at the
//    reversal is 2 b1; b < 0 is the usual lagging lost motion). The motion
//    signs come from the recorded order of the samples.
// Parameters the data cannot carry (servo mismatch from one direction only;
// a backlash whose axis never reverses) are left out of the fit and flagged.
// Standard uncertainties: s^2 (A^T A)^-1 with s^2 = RSS / (n - p).
#ifndef FIVECAL_CIRCULAR_TEST_H_
#define FIVECAL_CIRCULAR_TEST_H_

#include <Eigen/Core>
#include <string>
#include <vector>

namespace fivecal {

struct CircularRun {
  Eigen::VectorXd angles;    // phi (deg), in the recorded order
  Eigen::VectorXd readings;  // bar length - R (mm)
  int direction = 0;         // +1 CCW, -1 CW, 0 = from the angles
};

struct CircularRunResult {
  int direction = 0;
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // LSC centre offset (mm)
  double mean_radius = 0.0;                          // LSC radius (mm)
  double circular_deviation = 0.0;                   // G (mm)
  double radial_deviation_max = 0.0, radial_deviation_min = 0.0;  // F (mm)
  Eigen::VectorXd radial;  // |P_i - c| - R_ls (mm), per sample
};

struct CircularDiagnosis {
  std::vector<std::string> names;  // radius, centre.1, centre.2, scale_mismatch, squareness,
                                   // servo_mismatch, backlash.1, backlash.2 (those fitted)
  Eigen::VectorXd values, std;     // mm, mm/mm, rad
  std::vector<std::string> not_fitted;  // with the reason in the text
  double rms = 0.0;                // residual after the fit (mm)
  double Get(const std::string& name) const;
  bool Has(const std::string& name) const;
};

struct CircularTestResult {
  double nominal_radius = 0.0;
  std::vector<CircularRunResult> runs;
  double hysteresis = 0.0;  // H (mm); 0 with one run
  bool has_hysteresis = false;
  CircularDiagnosis diagnosis;
};

// runs: one or two (CW and CCW); throws std::invalid_argument naming the run
// and field on bad input.
CircularTestResult AnalyzeCircularTest(const std::vector<CircularRun>& runs, double nominal_radius,
                                       double feed = 0.0 /* mm/min, 0 = unknown */);

// Fourier coefficients of a trace by least squares on
// [1, cos phi, sin phi, ..., cos K phi, sin K phi] (works for uneven sampling;
// on arcs shorter than a turn the harmonics are not orthogonal and are fitted
// jointly). Returns (K+1) x 2: row k = (a_k, b_k), row 0 = (mean, 0).
Eigen::MatrixXd TraceHarmonics(const Eigen::VectorXd& angles_deg, const Eigen::VectorXd& values,
                               int max_order);

}  // namespace fivecal

#endif  // FIVECAL_CIRCULAR_TEST_H_
