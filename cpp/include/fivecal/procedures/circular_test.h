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
//    signs come from the recorded order of the samples. As ballbar software
//    does, it is split by the end of the travel where the axis reverses:
//    backlash.1+ is b1 on the half of the circle around the + end of axis 1
//    (cos phi > 0, the reversal at phi = 0), backlash.1- around its - end
//    (cos phi < 0, the reversal at 180 deg); column cos phi sgn(dx1/dt) on
//    that half, 0 on the other. The axis error jumps where the halves meet
//    (axis 1 at 90/270 deg), at right angles to the bar, so the radial trace
//    stays continuous there. Their mean is reported as backlash.k (derived,
//    with the covariance of both). Lateral play is not split: with the
//    backlash split, the four quadrant levels of s|cos phi| leave one
//    combination for lateral play (L1+ - L1- = B1- - B1+ as columns).
// The diagnoses ballbar users know beyond these (docs/dbb.md, "Planar
// circular tests"), each a linear term of the same fit; e_k is the position
// error of axis k, x1 = R cos phi, x2 = R sin phi about the pivot, and the
// radial deviation is d = e1 cos phi + e2 sin phi to first order:
//  * reversal spike of axis k (height p_k, outward > 0): after axis k
//    reverses at phi_r (axis 1: 0/180 deg, axis 2: 90/270 deg) it sticks
//    and catches up with a decay over the path angle w (spike_width):
//    e1 = p1 sgn(cos phi_r) exp(-dphi / w), dphi = angle travelled since
//    phi_r; column cos phi sgn(cos phi_r) exp(-dphi/w) (sin for axis 2).
//    Split as backlash: reversal_spike.1+ the spikes after the reversal at
//    the + end (phi_r = 0), .1- at the - end (180 deg).
//  * lateral play of axis k (L_k): the carriage of the other axis shifts
//    along axis k (perpendicular to its own travel) when that other axis
//    reverses: e1 = L1 sgn(dx2/dt) -> d = s L1 |cos phi|,
//    e2 = L2 sgn(dx1/dt) -> d = -s L2 |sin phi|. (A shift along the
//    reversing axis itself would be backlash.) Needs both directions: with
//    one, s|cos| is radial play.
//  * cyclic error of axis k with pitch p (cyclic_pitch, mm):
//    e1 = a1 cos(2 pi x1 / p) + b1 sin(2 pi x1 / p); amplitude sqrt(a^2+b^2).
//  * straightness of axis k (quadratic bow, peak to valley S_k over the
//    test diameter, the ends of the travel towards + of the other axis):
//    e2 = S1 (x1 / R)^2 -> d = S1 sin phi cos^2 phi; e1 = S2 (x2/R)^2 ->
//    d = S2 cos phi sin^2 phi (the constant part is a centre offset).
//  * radial play along axis k (rho_k): play taken up in the direction of the
//    outward (centrifugal) load: e1 = rho1 sgn(x1) -> d = rho1 |cos phi|,
//    e2 = rho2 sgn(x2) -> d = rho2 |sin phi|; the same in both directions.
// Extended diagnoses below options.significance standard uncertainties are
// dropped one by one (backward elimination), so a term the machine does not
// show does not cost the others precision.
// Ranking: each diagnosis' contribution to circularity is the circular
// deviation (range about its own least-squares circle, as G) of the fitted
// term's radial deviation alone, the largest over the runs; centre and radius
// are set-up and are not ranked. As a percentage it is that contribution over
// the circularity (the largest G of the runs) times 100, the figure ballbar
// software ranks by; the percentages need not add up to 100 (ranges of
// separate terms do not add).
// Parameters the data cannot carry (servo mismatch and lateral play from one
// direction only; a backlash, lateral play or spike whose axis never reverses
// inside the data; any term the samples cannot separate from the others) are
// left out of the fit and flagged.
// Standard uncertainties: s^2 (A^T A)^-1 with s^2 = RSS / (n - p).
#ifndef FIVECAL_CIRCULAR_TEST_H_
#define FIVECAL_CIRCULAR_TEST_H_

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

namespace fivecal {

struct CircularRun {
  Eigen::VectorXd angles;    // phi (deg), in the recorded order
  Eigen::VectorXd readings;  // bar length - R (mm)
  int direction = 0;         // +1 CCW, -1 CW, 0 = from the angles
};

// Which diagnoses to fit beyond the ISO/base set (centre, radius, scale
// mismatch, squareness, servo mismatch, backlash).
struct CircularDiagnosisOptions {
  bool reversal_spikes = true;
  double spike_width = 3.0;  // deg of path angle: the decay of a reversal spike
  bool lateral_play = true;
  bool straightness = true;
  bool radial_play = true;
  // Cyclic error pitch per axis (mm); 0 = not fitted.
  double cyclic_pitch1 = 0.0, cyclic_pitch2 = 0.0;
  // Search the pitch of axis k instead of taking cyclic_pitchk (ignored then):
  //  * the readings of each run less their least-squares harmonics 0..8 (the
  //    basis of TraceHarmonics: the shape terms), pooled;
  //  * a periodogram of that remainder against proj_k (cos, sin)(2 pi x_k f),
  //    x_k = R (cos phi | sin phi), proj_k = cos phi | sin phi, the power of
  //    the two-column least-squares fit, over f from 2 / R (pitch R/2) to
  //    1 / (4 h) (h the largest sample spacing along the axis in any run),
  //    evenly at df = 1 / (16 R), which keeps the phase error over the
  //    diameter under a quarter turn; the first strongest f wins;
  //  * the full diagnosis (significance 0, the other axis' cyclic error out)
  //    at 9 frequencies evenly over f +- df: the least residual rms gives the
  //    pitch.
  // The best of many pitches passes a fixed threshold by chance far more
  // often than one pitch given in advance, so with significance > 0 a found
  // pitch is kept only when the cyclic error's z = hypot(a / s_a, b / s_b)
  // (fit with every diagnosis in) reaches the Rayleigh tail
  // sqrt(-2 ln(erfc(significance / sqrt 2) / n)), n the frequencies tried
  // (Bonferroni); otherwise it is dropped (pitch 0) and listed in
  // not_significant as "cyclic_error.k (pitch P mm searched among n: z
  // sigma, need needed)". Throws std::invalid_argument when the samples are
  // too sparse for any pitch below R / 2.
  bool search_cyclic_pitch1 = false, search_cyclic_pitch2 = false;
  // An extended diagnosis whose value is below this many standard
  // uncertainties is dropped (least significant first, refitting after
  // each) and listed in not_significant; 0 keeps every one.
  double significance = 3.0;
};

// Feed-in and feed-out (overshoot) arcs removed from a recorded run.
struct TrimmedRun {
  CircularRun run;           // the data arc
  int removed_start = 0;     // samples of the feed-in arc
  int removed_end = 0;       // samples of the feed-out arc
  double arc_start = 0.0;    // deg swept by the removed feed-in / feed-out
  double arc_end = 0.0;
  double data_first = 0.0, data_last = 0.0;  // unwrapped angles kept (deg)
};

// Detects the overshoot arcs by the sweep beyond data_arc (deg, 360 for a full
// circle): the angles are unwrapped (steps under 180 deg), samples going
// against the run's direction at either end are removed, and what the sweep
// exceeds data_arc by is removed from both ends, feed_in deg at the start
// (NaN = half the excess each side, the symmetric arcs ballbar programs
// use). A run sweeping no more than data_arc + tolerance is returned as is.
TrimmedRun TrimOvershoot(const CircularRun& run, double data_arc = 360.0,
                         double feed_in = std::numeric_limits<double>::quiet_NaN(),
                         double tolerance = 1e-6);

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
                                   // servo_mismatch, backlash.k+, backlash.k-, reversal_spike.k+|-, lateral_play.k,
                                   // straightness.k, radial_play.k, cyclic_error.k.cos|sin
                                   // (k = 1, 2; those fitted)
  Eigen::VectorXd values, std;     // mm, mm/mm, rad
  std::vector<std::string> not_fitted;  // with the reason in the text
  std::vector<std::string> not_significant;  // extended diagnoses dropped below options.significance
  // Each dropped diagnosis (a name, or the group cyclic_error.k) with its
  // |value| (a cyclic error's amplitude) and standard uncertainty in the fit
  // it was dropped from: a tolerance can still be graded by |value| + 3 std.
  std::vector<std::string> dropped_names;
  Eigen::VectorXd dropped_values, dropped_std;
  double rms = 0.0;                // residual after the fit (mm)
  // Diagnoses (a name, or the group "cyclic_error.k" of its .cos/.sin
  // parameters) in decreasing contribution to circularity (mm).
  std::vector<std::string> ranking;
  Eigen::VectorXd contribution;
  Eigen::VectorXd contribution_percent;  // contribution / circularity x 100
  double circularity = 0.0;              // the largest G of the runs (mm)
  // Values derived from the fitted ones with their covariance: backlash.k,
  // the mean of backlash.k+ and backlash.k- (when both are fitted).
  std::vector<std::string> derived_names;
  Eigen::VectorXd derived_values, derived_std;
  double Get(const std::string& name) const;
  bool Has(const std::string& name) const;
};

struct CircularTestResult {
  double nominal_radius = 0.0;
  std::vector<CircularRunResult> runs;
  double hysteresis = 0.0;  // H (mm); 0 with one run
  bool has_hysteresis = false;
  CircularDiagnosis diagnosis;
  // The pitches (mm) the cyclic errors were fitted with, given or found (0 =
  // none, also for a found pitch the significance gate dropped), and the
  // number of frequencies the search of axis k tried (0 = not searched).
  double cyclic_pitch1 = 0.0, cyclic_pitch2 = 0.0;
  int cyclic_pitches_tried1 = 0, cyclic_pitches_tried2 = 0;
};

// runs: one or two (CW and CCW); throws std::invalid_argument naming the run
// and field on bad input.
CircularTestResult AnalyzeCircularTest(const std::vector<CircularRun>& runs, double nominal_radius,
                                       double feed = 0.0 /* mm/min, 0 = unknown */,
                                       const CircularDiagnosisOptions& options = CircularDiagnosisOptions());

// The contribution to circularity (mm) of one diagnosis of the given value
// (mm, mm/mm, rad; servo_mismatch in mm) on a full circle of radius R: the
// circular deviation of its term alone, as the ranking computes it, the
// larger of a CCW and a CW run. For the diagnoses read from another program
// (a .b5r file) and for tolerances. Throws std::invalid_argument naming an
// unknown diagnosis.
double DiagnosisContribution(const std::string& name, double value, double nominal_radius,
                             const CircularDiagnosisOptions& options = CircularDiagnosisOptions());

// Thermal compensation of a ball bar reading: the bar at t_bar (deg C) has
// grown by L alpha_bar (t_bar - t_ref), so the distance between the balls is
// D = L (1 + alpha_bar (t_bar - t_ref)) + reading; the machine at t_machine
// carries a scale expanded by alpha_machine (t_machine - t_ref), so the
// distance at the reference temperature is D / (1 + alpha_machine
// (t_machine - t_ref)). Returned: that distance minus L, per reading (mm).
// alpha in 1/K (steel 11.5e-6); |alpha| above 1e-4 /K is refused (a value in
// ppm/K given as 1/K), temperatures outside -20 .. 60 deg C too; the error
// names the field.
struct BarThermal {
  double alpha_bar = 0.0, t_bar = 20.0;
  double alpha_machine = 0.0, t_machine = 20.0;
  double t_ref = 20.0;
};
Eigen::VectorXd CompensateBarTemperature(const Eigen::VectorXd& readings, double nominal_length,
                                         const BarThermal& thermal);

// Fourier coefficients of a trace by least squares on
// [1, cos phi, sin phi, ..., cos K phi, sin K phi] (works for uneven sampling;
// on arcs shorter than a turn the harmonics are not orthogonal and are fitted
// jointly). Returns (K+1) x 2: row k = (a_k, b_k), row 0 = (mean, 0).
Eigen::MatrixXd TraceHarmonics(const Eigen::VectorXd& angles_deg, const Eigen::VectorXd& values,
                               int max_order);

}  // namespace fivecal

#endif  // FIVECAL_CIRCULAR_TEST_H_
