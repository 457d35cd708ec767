// The heading of a child segment relative to its parent from the kinematic constraint of a hinge joint, after
// Laidig, Schauer & Seel 2017 ("Exploiting kinematic constraints to compensate magnetic disturbances when calculating
// joint angles of approximate hinge joints from orientation estimates of inertial sensors", ICORR 2017).
//
// Why: in a disturbed magnetic field each segment's filter takes its heading from the field it sees, and two sensors
// a few decimetres apart see different fields, so their headings err differently. That difference is a rotation of
// the child about the vertical, and it shows in the joint angles (at the knee: axial rotation, and ab/adduction when
// the knee is flexed). The inclinations are not affected: they come from gravity.
//
// Method. A hinge axis is fixed in both segments (j_p in the parent's frame, j_c in the child's). With correct
// orientations it is one direction in the earth frame: q_p j_p = q_c j_c. With headings that err by e_p and e_c,
// the child's axis is off by a rotation about the vertical z by delta = e_p - e_c: a = q_p j_p equals R_z(delta) b
// with b = q_c j_c. Over a window, delta minimises the sum of |a - R_z(delta) b|^2, which is the maximum of
//   sum (R_z(delta) b) . a = cos(delta) sum (a_h . b_h) + sin(delta) sum (b_h x a_h)_z + const,
// so delta = atan2(S_sin, S_cos) with S_cos = sum a_h . b_h and S_sin = sum (b_h x a_h)_z over the horizontal parts
// a_h, b_h of the two axes. Each sample's pair (a_h . b_h, (b_h x a_h)_z) = |a_h| |b_h| (cos d_k, sin d_k) carries
// its own observability weight |a_h| |b_h|: an axis near vertical tells nothing about the heading about it, and
// weighs nothing. The sums are exponentially weighted (window time constant `window_s`), which smooths the noise of
// the orientations and of the joint's departures from a perfect hinge while it follows a slowly changing offset; a
// sample whose observability |a_h| |b_h| is below `min_observability` is left out (the estimate is held), so a
// phase with the axis near vertical neither moves the estimate nor lets noise in. The corrected child is
// R_z(delta) q_c: its heading in the parent's magnetometer frame, so the joint angles no longer depend on the
// difference of the two fields. Until a first observable sample, delta = 0 (the magnetometers' relative heading).
//
// Assumptions: the joint is an (approximate) hinge, its axis known in both segment frames (the ISB flexion axis Z
// for the knee, from the sensor-to-segment alignment or a known mounting); both orientations have correct
// inclinations (the disturbance turns headings only, as in filters with a heading-only magnetometer correction); the
// heading offset changes slowly against the window (the filters' heading time constants are seconds); and the axis is
// away from vertical often enough (true in gait: the knee axis stays near horizontal). A real knee's ab/adduction and
// axial rotation of a few degrees move the axes apart: the estimate moves by up to their amplitude, less where they
// change sign within the window (the simulator's knee is an exact hinge, so its tests do not show this). Near the
// singularity Laidig et al. go further than this estimator, which only holds the last estimate there.
//
// Plain C++ + Eigen: Params (units, defaults, reasons), Coefficients derived from them, State; no allocation.
#pragma once

#include <cstdint>

#include "bsn/fusion/rotation.hpp"

namespace bsn::fusion {

class HingeHeadingEstimator {
 public:
  struct Params {
    /// Time constant of the exponential window over which the axis mismatch is minimised, s. Default 1 s: a
    /// gait cycle, so the knee's departures from a hinge and the orientation noise average out, while a heading
    /// offset that changes as fast as the filters' heading corrections (seel_ruppin: 4 s) is followed within a
    /// quarter of its change.
    double window_s = 1.0;
    /// A sample counts only when the product of the two axes' horizontal lengths |a_h| |b_h| reaches this
    /// (dimensionless, 0..1). Default 0.1: with both segments agreeing, the axis within about 18 deg of vertical
    /// (|a_h| = |b_h| < 0.32) is left out, where the heading about it is barely seen: an inclination error of e
    /// turns the horizontal part of the axis by up to e / |a_h|, three times e there.
    double min_observability = 0.1;
    /// A step between two samples longer than this restarts the window, s: after a gap the filters may have
    /// re-initialised and their headings jumped. Default 1 s (the filters' max_gap_s).
    double max_step_s = 1.0;
    /// The hinge axis in the parent's and in the child's frame (any length > 0, normalised). Default Z: the ISB
    /// segment frames' medio-lateral axis, the flexion axis of the knee, elbow and ankle.
    Vec3 parent_axis = Vec3::UnitZ();
    Vec3 child_axis = Vec3::UnitZ();

    /// Throws std::invalid_argument naming the field unless window_s and max_step_s are finite and > 0,
    /// min_observability is in [0, 1) and both axes are finite and non-zero.
    void check() const;
  };

  /// Derived from Params once.
  struct Coefficients {
    double inverse_window_s = 1.0;  ///< 1 / window_s, 1/s
    double min_observability = 0.1;
    std::uint64_t max_step_ns = 1'000'000'000;
    Vec3 parent_axis = Vec3::UnitZ();  ///< unit
    Vec3 child_axis = Vec3::UnitZ();   ///< unit
  };

  /// What the estimator has done so far; the joint's output shows it.
  struct State {
    /// Rotation of the child about the earth's vertical that makes the two axes coincide, rad, in (-pi, pi]
    /// (counter-clockwise seen from above); 0 until `estimated`.
    double offset_rad = 0.0;
    /// Windowed mean of |a_h| |b_h| over every sample, 0..1: 1 with the axis horizontal, 0 with it vertical (or
    /// never seen). Below min_observability the estimate is being held, not updated.
    double observability = 0.0;
    /// Windowed, observability-weighted mean of (cos d_k, sin d_k) over the counted samples: offset_rad is its
    /// angle. Its length over the observability is the agreement of the samples (1: one offset throughout).
    double sum_cos = 0.0, sum_sin = 0.0;
    bool observed = false;                   ///< the last sample was counted
    bool estimated = false;                  ///< a sample has been counted since the start or the last restart
    std::uint64_t counted = 0;               ///< samples counted since the start or the last restart
    std::uint64_t timestamp_ns = 0;          ///< of the last sample (valid with `started`)
    std::uint64_t counted_timestamp_ns = 0;  ///< of the last counted sample (valid with `estimated`)
    bool started = false;
  };

  /// Throws std::invalid_argument on bad Params (see Params::check).
  explicit HingeHeadingEstimator(const Params& params);
  HingeHeadingEstimator() : HingeHeadingEstimator(Params{}) {}

  /// One pair of orientations (frame-to-earth of the frames the axes are given in) at the child's sample time
  /// (sensor clock, ns). A time going backwards or a step over max_step_s restarts the window.
  const State& update(const Quat& q_parent, const Quat& q_child, std::uint64_t timestamp_ns);
  /// The child's orientation with its heading corrected: R_z(offset) * q_child.
  Quat correct(const Quat& q_child) const { return heading_rotation_ * q_child; }
  /// Forgets everything (a filter restarted, the frames changed): the offset is 0 until the next counted sample.
  void reset();

  const Params& params() const { return params_; }
  const Coefficients& coefficients() const { return coefficients_; }
  const State& state() const { return state_; }

 private:
  Params params_;
  Coefficients coefficients_;
  State state_;
  Quat heading_rotation_ = Quat::Identity();  ///< R_z(state_.offset_rad)
};

}  // namespace bsn::fusion
