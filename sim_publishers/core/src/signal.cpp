#include "bsn/sim/signal.hpp"

#include <cmath>
#include <numbers>

namespace bsn::sim {

SignalValue smooth_step(double t, double start, double duration) {
  if (t <= start) return {0.0, 0.0, 0.0};
  if (t >= start + duration || duration <= 0.0) return {1.0, 0.0, 0.0};
  const double u = (t - start) / duration;
  const double u2 = u * u;
  return {u2 * u * (10.0 - 15.0 * u + 6.0 * u2), 30.0 * u2 * (1.0 - u) * (1.0 - u) / duration,
          60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / (duration * duration)};
}

SignalValue envelope_at(const std::vector<Window>& windows, double t) {
  SignalValue e;
  for (const Window& w : windows) {
    const SignalValue up = smooth_step(t, w.start_s, w.ramp_s);
    const SignalValue down = smooth_step(t, w.end_s, w.ramp_s);
    e.value += up.value - down.value;
    e.rate += up.rate - down.rate;
    e.acceleration += up.acceleration - down.acceleration;
  }
  return e;
}

bool inside_any(const std::vector<Window>& windows, double t) {
  for (const Window& w : windows) {
    if (t >= w.start_s && t <= w.end_s + w.ramp_s) return true;
  }
  return false;
}

SignalValue Signal::at(double t) const {
  SignalValue h;  // harmonic part
  for (const Harmonic& k : harmonics) {
    const double w = 2.0 * std::numbers::pi * k.frequency_hz;
    const double s = std::sin(w * t + k.phase_rad), c = std::cos(w * t + k.phase_rad);
    h.value += k.amplitude * s;
    h.rate += k.amplitude * w * c;
    h.acceleration -= k.amplitude * w * w * s;
  }
  if (!envelope.empty()) {
    const SignalValue e = envelope_at(envelope, t);
    h = {e.value * h.value, e.rate * h.value + e.value * h.rate,
         e.acceleration * h.value + 2.0 * e.rate * h.rate + e.value * h.acceleration};
  }
  SignalValue out{constant + rate * t + h.value, rate + h.rate, h.acceleration};
  for (const Step& st : steps) {
    const SignalValue s = smooth_step(t, st.start_s, st.duration_s);
    out.value += st.amplitude * s.value;
    out.rate += st.amplitude * s.rate;
    out.acceleration += st.amplitude * s.acceleration;
  }
  return out;
}

}  // namespace bsn::sim
