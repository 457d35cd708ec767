// Smooth scalar signals of time with exact first and second derivatives: the building block of every
// simulated joint angle, root rotation and root translation.
#pragma once

#include <vector>

namespace bsn::sim {

/// Value and its exact first and second time derivatives.
struct SignalValue {
  double value = 0.0;
  double rate = 0.0;          ///< d/dt
  double acceleration = 0.0;  ///< d2/dt2
};

/// A time window with smooth (C2, quintic) edges: 0 before start_s, rising to 1 over ramp_s, 1 until end_s,
/// falling to 0 over the following ramp_s.
struct Window {
  double start_s = 0.0;
  double end_s = 0.0;
  double ramp_s = 0.5;
};

/// A + rate*t + sum of harmonics (all multiplied by the envelope when one is given) + smooth steps.
struct Signal {
  struct Harmonic {
    double amplitude = 0.0;     ///< in the signal's unit
    double frequency_hz = 0.0;  ///< Hz
    double phase_rad = 0.0;     ///< rad
  };
  struct Step {
    double amplitude = 0.0;   ///< total change, in the signal's unit
    double start_s = 0.0;     ///< s
    double duration_s = 1.0;  ///< s, > 0: quintic minimum-jerk profile (zero rate and acceleration at both ends)
  };

  double constant = 0.0;
  double rate = 0.0;                ///< linear term per second
  std::vector<Harmonic> harmonics;  ///< multiplied by `envelope` if it is not empty
  std::vector<Window> envelope;     ///< union of windows (should not overlap); empty = always on
  std::vector<Step> steps;

  static Signal constant_value(double c) {
    Signal s;
    s.constant = c;
    return s;
  }

  SignalValue at(double t_s) const;
};

/// Quintic smoothstep 10u^3 - 15u^4 + 6u^5 of u = (t - start) / duration with its time derivatives.
SignalValue smooth_step(double t_s, double start_s, double duration_s);

/// Sum of the windows' smooth indicators (0..1 when they do not overlap) and its derivatives.
SignalValue envelope_at(const std::vector<Window>& windows, double t_s);

/// True when t_s lies in one of the windows, including their ramps.
bool inside_any(const std::vector<Window>& windows, double t_s);

}  // namespace bsn::sim
