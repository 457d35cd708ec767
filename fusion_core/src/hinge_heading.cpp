#include "bsn/fusion/hinge_heading.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {
namespace {

constexpr const char* kOwner = "kinematic heading";

// The weight of a new sample in an exponential window after dt_ns: 1 - exp(-dt / window).
double window_weight(std::uint64_t dt_ns, double inverse_window_s) {
  return -std::expm1(-1e-9 * static_cast<double>(dt_ns) * inverse_window_s);
}

void require_axis(const Vec3& axis, const char* name) {
  if (!axis.allFinite() || !(axis.norm() > 1e-9)) {
    throw std::invalid_argument(std::string(kOwner) + ": " + name + " must be a finite, non-zero vector");
  }
}

}  // namespace

void HingeHeadingEstimator::Params::check() const {
  require_positive(kOwner, window_s, "window_s");
  require_positive(kOwner, max_step_s, "max_step_s");
  if (!(min_observability >= 0.0 && min_observability < 1.0)) {
    throw std::invalid_argument(std::string(kOwner) + ": parameter min_observability must be in [0, 1), got " +
                                std::to_string(min_observability));
  }
  require_axis(parent_axis, "parent_axis");
  require_axis(child_axis, "child_axis");
}

HingeHeadingEstimator::HingeHeadingEstimator(const Params& params) : params_(params) {
  params.check();
  coefficients_.inverse_window_s = 1.0 / params.window_s;
  coefficients_.min_observability = params.min_observability;
  coefficients_.max_step_ns = seconds_to_ns(params.max_step_s);
  coefficients_.parent_axis = params.parent_axis.normalized();
  coefficients_.child_axis = params.child_axis.normalized();
}

void HingeHeadingEstimator::reset() {
  state_ = State{};
  heading_rotation_ = Quat::Identity();
}

const HingeHeadingEstimator::State& HingeHeadingEstimator::update(const Quat& q_parent, const Quat& q_child,
                                                                  std::uint64_t timestamp_ns) {
  State& s = state_;
  const bool restart =
      !s.started || timestamp_ns < s.timestamp_ns || timestamp_ns - s.timestamp_ns > coefficients_.max_step_ns;
  if (restart && s.started) reset();
  // The weight of this sample in the exponential window; the first sample is the window.
  const double alpha = s.started ? window_weight(timestamp_ns - s.timestamp_ns, coefficients_.inverse_window_s) : 1.0;
  s.started = true;

  const Vec3 a = rotate(q_parent, coefficients_.parent_axis);  // the axis as the parent sees it, earth frame
  const Vec3 b = rotate(q_child, coefficients_.child_axis);    // ... and as the child sees it
  // |a_h| |b_h| from the squared lengths: one square root.
  // Non-finite orientations (never from a filter) count as unobservable, so nothing non-finite enters the state.
  const double product = std::sqrt((a.x() * a.x() + a.y() * a.y()) * (b.x() * b.x() + b.y() * b.y()));
  const double horizontal = std::isfinite(product) ? product : 0.0;
  s.observability += alpha * (horizontal - s.observability);
  s.observed = horizontal >= coefficients_.min_observability && horizontal > 0.0;
  if (s.observed) {
    // The window of the counted samples runs on the time since the last counted one, so after a phase with the
    // axis near vertical the new samples take over as fast as the window allows (the offset may have moved).
    const double counted_alpha =
        s.estimated ? window_weight(timestamp_ns - s.counted_timestamp_ns, coefficients_.inverse_window_s) : 1.0;
    const double dot = a.x() * b.x() + a.y() * b.y();    // |a_h| |b_h| cos d
    const double cross = b.x() * a.y() - b.y() * a.x();  // |a_h| |b_h| sin d: turns b_h onto a_h
    s.sum_cos += counted_alpha * (dot - s.sum_cos);
    s.sum_sin += counted_alpha * (cross - s.sum_sin);
    s.offset_rad = std::atan2(s.sum_sin, s.sum_cos);
    s.estimated = true;
    ++s.counted;
    s.counted_timestamp_ns = timestamp_ns;
    const double half = 0.5 * s.offset_rad;
    heading_rotation_ = Quat(std::cos(half), 0.0, 0.0, std::sin(half));
  }
  s.timestamp_ns = timestamp_ns;
  return s;
}

}  // namespace bsn::fusion
