#include "bsn/calib/calibration_session.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace bsn::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// A node that never sent gets this long for discovery when only sample_count limits the collection, s.
constexpr double kNeverStartedTimeout_s = 5.0;
constexpr std::size_t kMinFitPoses = 5;  // eq. 29

// The half of the sphere (in the sensor frame) that holds the fewest corrected pose directions, as words, and
// the way to turn the sensor to fill it. "" when every half holds at least two.
std::string missing_half(const Points3& directions, CalibrationKind kind) {
  static constexpr const char* kNames[6] = {"+x half", "-x half", "+y half", "-y half", "upper half", "lower half"};
  static constexpr const char* kAxes[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
  int counts[6] = {};
  for (Eigen::Index j = 0; j < directions.cols(); ++j) {
    const Vec3 n = directions.col(j);
    for (int a = 0; a < 3; ++a) {
      if (n(a) > 0.3) ++counts[2 * a];
      if (n(a) < -0.3) ++counts[2 * a + 1];
    }
  }
  int worst = 0;
  for (int h = 1; h < 6; ++h)
    if (counts[h] < counts[worst]) worst = h;
  if (counts[worst] >= 2) return "";
  // The magnetometer reads the field along an axis when that axis points along the field (north and down in
  // most of the world); the accelerometer reads +g on the axis that points up.
  const std::string how = kind == CalibrationKind::accelerometer ? std::string(" up") : " north and down";
  return std::string("cover the ") + kNames[worst] + " of the sphere (point the sensor's " + kAxes[worst] + " axis" +
         how + ")";
}

}  // namespace

const char* kind_name(CalibrationKind kind) {
  switch (kind) {
    case CalibrationKind::magnetometer:
      return "magnetometer";
    case CalibrationKind::gyro_bias:
      return "gyro-bias";
    case CalibrationKind::accelerometer:
      return "accelerometer";
    case CalibrationKind::alignment:
      return "alignment";
  }
  return "unknown";
}

std::optional<CalibrationKind> parse_kind(std::string_view name) {
  if (name == "magnetometer") return CalibrationKind::magnetometer;
  if (name == "gyro-bias") return CalibrationKind::gyro_bias;
  if (name == "accelerometer") return CalibrationKind::accelerometer;
  if (name == "alignment") return CalibrationKind::alignment;
  return std::nullopt;
}

std::string validate(const SessionParams& p) {
  if (p.kind == CalibrationKind::alignment) return "the alignment is collected by an AlignmentSession, for a body";
  if (!std::isfinite(p.duration_s) || p.duration_s < 0.0)
    return "duration_s must be a finite number >= 0 (got " + std::to_string(p.duration_s) + ")";
  if (p.duration_s > p.max_duration_s)
    return "duration_s " + std::to_string(p.duration_s) + " is absurd: at most " + std::to_string(p.max_duration_s) +
           " s";
  if (p.sample_count > p.max_samples)
    return "sample_count " + std::to_string(p.sample_count) + " is absurd: at most " + std::to_string(p.max_samples);
  if (p.duration_s == 0.0 && p.sample_count == 0) return "neither duration_s nor sample_count is set";
  if (p.duration_s > 0.0 && p.duration_s < 0.1) return "duration_s below 0.1 s cannot collect anything";
  if (!std::isfinite(p.field_magnitude) || !(p.field_magnitude > 0.0) || p.field_magnitude > 1e5)
    return "field_magnitude must be in (0, 1e5] (got " + std::to_string(p.field_magnitude) + ")";
  if (!(p.silence_timeout_s > 0.0)) return "silence_timeout_s must be positive";
  return "";
}

CalibrationSession::CalibrationSession(const SessionParams& params, std::uint64_t start_ns)
    : params_(params), start_ns_(start_ns) {
  if (const std::string why = validate(params_); !why.empty()) throw std::invalid_argument(why);
}

void CalibrationSession::push(const SessionSample& s) {
  if (count_ == gyr_.cols()) {
    // Grow in steps (one minute at 100 Hz, then doubling): no reallocation per sample.
    const Eigen::Index capacity = std::max<Eigen::Index>(6000, 2 * gyr_.cols());
    gyr_.conservativeResize(3, capacity);
    acc_.conservativeResize(3, capacity);
    mag_.conservativeResize(3, capacity);
    timestamps_.reserve(static_cast<std::size_t>(capacity));
  }
  const Vec3 nan = Vec3::Constant(kNaN);
  gyr_.col(count_) = s.has_gyr ? s.gyr : nan;
  acc_.col(count_) = s.has_acc ? s.acc : nan;
  mag_.col(count_) = s.has_mag ? s.mag : nan;
  timestamps_.push_back(s.timestamp_ns);
  ++count_;
}

void CalibrationSession::add(const SessionSample& s, std::uint64_t now_ns) {
  if (collection_over(now_ns)) return;
  last_arrival_ns_ = now_ns;
  const bool finite =
      (!s.has_gyr || s.gyr.allFinite()) && (!s.has_acc || s.acc.allFinite()) && (!s.has_mag || s.mag.allFinite());
  if (!finite) {
    ++non_finite_;
    if (!first_non_finite_seq_) first_non_finite_seq_ = s.seq;
  }
  if (last_seq_ && s.seq <= *last_seq_) return;  // duplicate or reordered: the buffer keeps sensor order
  if (last_seq_ && s.seq > *last_seq_ + 1 && count_ > 0) {
    const std::uint64_t missing = s.seq - *last_seq_ - 1;
    if (missing > params_.max_interpolated_gap) {
      if (!gap_too_long_at_seq_) {
        gap_too_long_at_seq_ = *last_seq_ + 1;
        gap_length_ = static_cast<std::size_t>(missing);
      }
    } else {
      // Linear interpolation between the last sample and this one, channel by channel and in time.
      const Eigen::Index last = count_ - 1;
      const Vec3 g0 = gyr_.col(last), a0 = acc_.col(last), m0 = mag_.col(last);
      const std::uint64_t t0 = timestamps_.back();
      for (std::uint64_t k = 1; k <= missing; ++k) {
        const double f = static_cast<double>(k) / static_cast<double>(missing + 1);
        SessionSample fill;
        fill.seq = *last_seq_ + k;
        fill.timestamp_ns = t0 + static_cast<std::uint64_t>(f * static_cast<double>(s.timestamp_ns - t0));
        fill.gyr = g0 + f * ((s.has_gyr ? s.gyr : g0) - g0);
        fill.acc = a0 + f * ((s.has_acc ? s.acc : a0) - a0);
        fill.mag = m0 + f * ((s.has_mag ? s.mag : m0) - m0);
        push(fill);
        ++interpolated_;
      }
    }
  }
  last_seq_ = s.seq;
  if (static_cast<std::size_t>(count_) >= params_.max_samples) {
    full_ = true;
    return;
  }
  push(s);
}

bool CalibrationSession::collection_over(std::uint64_t now_ns) const {
  if (full_ || good_enough_) return true;
  if (params_.sample_count > 0 && static_cast<std::size_t>(count_) >= params_.sample_count) return true;
  const double elapsed = seconds_between(start_ns_, now_ns);
  if (params_.duration_s > 0.0 && elapsed >= params_.duration_s) return true;
  if (last_arrival_ns_) return seconds_between(*last_arrival_ns_, now_ns) >= params_.silence_timeout_s;
  return params_.duration_s == 0.0 && elapsed >= kNeverStartedTimeout_s;
}

double CalibrationSession::sample_rate_hz() const {
  if (count_ < 2 || timestamps_.back() <= timestamps_.front()) return 0.0;
  return static_cast<double>(count_ - 1) / (static_cast<double>(timestamps_.back() - timestamps_.front()) * 1e-9);
}

SessionProgress CalibrationSession::progress(std::uint64_t now_ns) {
  SessionProgress p;
  p.started = count_ > 0;
  p.samples = static_cast<std::size_t>(count_);
  p.elapsed_s = seconds_between(start_ns_, now_ns);
  if (params_.duration_s > 0.0) {
    p.seconds_left = std::max(0.0, params_.duration_s - p.elapsed_s);
    p.fraction = std::min(1.0, p.elapsed_s / params_.duration_s);
  }
  if (params_.sample_count > 0)
    p.fraction =
        std::max(p.fraction, std::min(1.0, static_cast<double>(count_) / static_cast<double>(params_.sample_count)));
  if (count_ == 0) {
    p.collection_over = collection_over(now_ns);
    p.instruction = "waiting for the node's samples on bsn/raw";
    return p;
  }
  const double rate = sample_rate_hz();
  const Points3 gyr = gyr_.leftCols(count_);
  const bool gyro_finite = gyr.allFinite();
  const Points3& channel_all = params_.kind == CalibrationKind::accelerometer ? acc_ : mag_;
  const Points3 channel = params_.kind == CalibrationKind::gyro_bias ? gyr : Points3(channel_all.leftCols(count_));
  PoseSegmentation poses;
  if (rate > 0.0 && gyro_finite) poses = segment_poses(gyr, channel, rate, params_.segmentation);
  p.poses = poses.ok() ? static_cast<std::size_t>(poses.means.cols()) : 0;

  // How long the sensor has been still at the end of the buffer (rest threshold on |gyro - bias|).
  const Vec3 bias = poses.ok() ? poses.gyro_bias : Vec3::Zero();
  const double threshold = (poses.ok() ? 1.0 : 2.0) * params_.segmentation.rest_rate_rad_s;
  Eigen::Index still = 0;
  while (still < count_ && gyr.col(count_ - 1 - still).allFinite() &&
         (gyr.col(count_ - 1 - still) - bias).norm() < threshold)
    ++still;
  const double still_s = rate > 0.0 ? static_cast<double>(still) / rate : 0.0;
  const double pose_s = params_.segmentation.min_pose_s + 2.0 * params_.segmentation.edge_trim_s;

  std::string advice;
  if (params_.kind == CalibrationKind::gyro_bias) {
    const double rest_s = rate > 0.0 ? static_cast<double>(poses.rest_samples) / rate : 0.0;
    p.good_enough = rest_s >= params_.good_rest_s;
    if (params_.until_good) p.fraction = std::max(p.fraction, std::min(1.0, rest_s / params_.good_rest_s));
    p.instruction = still_s > 0.0 ? "hold still" : "hold still: the sensor moves";
  } else {
    if (p.poses >= kMinFitPoses) {
      const double m = params_.kind == CalibrationKind::accelerometer ? params_.gravity : params_.field_magnitude;
      // The ellipsoid over the readings (every n-th, at most ~4000: a provisional fit need not be exact).
      const Eigen::Index step = std::max<Eigen::Index>(1, count_ / 4000);
      Points3 readings(3, count_ / step + 1);
      Eigen::Index kept = 0;
      for (Eigen::Index k = 0; k < count_; k += step)
        if (channel.col(k).allFinite()) readings.col(kept++) = channel.col(k);
      const FieldCalibration fit = calibrate_field(poses.means, poses.rotations, m, readings.leftCols(kept));
      if (fit.ok()) {
        p.octants = fit.quality.octants_covered;
        p.sphere_coverage = fit.quality.sphere_coverage;
        Points3 directions(3, poses.means.cols());
        for (Eigen::Index j = 0; j < poses.means.cols(); ++j)
          directions.col(j) = apply(fit.calibration, poses.means.col(j)).normalized();
        advice = missing_half(directions, params_.kind);
        p.good_enough = p.poses >= params_.good_poses && p.octants >= params_.good_octants &&
                        p.sphere_coverage >= params_.good_coverage && fit.quality.warnings.empty();
      }
    }
    if (params_.until_good) {
      p.fraction = std::max(
          p.fraction,
          std::min(p.good_enough ? 1.0 : 0.99,
                   static_cast<double>(p.poses) / static_cast<double>(std::max<std::size_t>(1, params_.good_poses))));
    }
    if (still_s >= pose_s) {
      p.instruction = "pose " + std::to_string(p.poses) + " recorded: turn to a new orientation";
      if (!advice.empty()) p.instruction += "; " + advice;
    } else if (still_s > 0.0) {
      p.instruction = "hold still";
    } else {
      p.instruction = "turn to a new orientation, then hold still for " +
                      std::to_string(static_cast<int>(std::ceil(pose_s))) + " s";
    }
    if (p.good_enough) p.instruction += params_.until_good ? " (good enough: finishing)" : " (good enough already)";
  }
  if (p.good_enough && params_.until_good) good_enough_ = true;
  p.collection_over = collection_over(now_ns);
  return p;
}

std::string CalibrationSession::failure_before_fit() const {
  if (count_ == 0) return "no sample arrived";
  if (non_finite_ > 0)
    return std::to_string(non_finite_) + " samples hold NaN or Inf (the first at seq " +
           std::to_string(*first_non_finite_seq_) + ")";
  if (gap_too_long_at_seq_)
    return std::to_string(gap_length_) + " samples lost in a row from seq " + std::to_string(*gap_too_long_at_seq_) +
           ": the gyro integration between the poses would be wrong";
  if (sample_rate_hz() <= 0.0) return "too few samples (" + std::to_string(count_) + ") or timestamps not increasing";
  if (!gyr_.leftCols(count_).allFinite()) return "some samples carry no gyroscope reading";
  return "";
}

SessionResult CalibrationSession::finish() const {
  SessionResult r;
  r.kind = params_.kind;
  r.samples = static_cast<std::size_t>(count_);
  r.interpolated = interpolated_;
  r.field.field_magnitude = params_.kind == CalibrationKind::accelerometer ? params_.gravity : params_.field_magnitude;
  if (std::string why = failure_before_fit(); !why.empty()) {
    r.message = std::move(why);
    return r;
  }
  const double rate = sample_rate_hz();
  const Points3 gyr = gyr_.leftCols(count_);
  if (params_.kind == CalibrationKind::gyro_bias) {
    const PoseSegmentation rests = segment_poses(gyr, gyr, rate, params_.segmentation);
    if (!rests.ok()) {
      r.message = rests.message;
      return r;
    }
    r.gyro.bias = rests.gyro_bias;
    r.rest_samples = rests.rest_samples;
    r.field.status = FitStatus::ok;
    r.success = true;
    return r;
  }
  const Points3 readings =
      params_.kind == CalibrationKind::accelerometer ? acc_.leftCols(count_) : mag_.leftCols(count_);
  PoseSegmentation poses;
  r.field = calibrate_field_from_recording(gyr, readings, rate, r.field.field_magnitude, params_.segmentation, &poses);
  r.gyro.bias = poses.gyro_bias;
  r.rest_samples = poses.rest_samples;
  r.success = r.field.ok();
  if (!r.success) r.message = r.field.message;
  return r;
}

}  // namespace bsn::calib
