// One live calibration of one sensor node: it takes the node's raw samples as they arrive, says how far the
// collection is and what the person holding the sensor should do now, and when the collection ends fits with the
// same functions as the offline `bsn calibrate` (so both give the same numbers for the same samples).
// The calibration service runs one session per node of a request. Times are arguments (no clock), nothing is
// printed; the buffer grows with the samples (reserved in steps), as an offline fit does.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/calib/pose_segmentation.hpp"

namespace bsn::calib {

enum class CalibrationKind {
  magnetometer,   ///< B and H from still poses turned by hand (|u| = field_magnitude)
  gyro_bias,      ///< mean gyro rate at rest
  accelerometer,  ///< B and H from still poses (|u| = g)
  alignment,      ///< sensor-to-segment rotation of a body's nodes together: AlignmentSession, not this one
};

/// "magnetometer", "gyro-bias", "accelerometer", "alignment": the one spelling of each kind, in the client's --kind,
/// the store's file names, the logs and the messages. (A calibration file's channels are named by their sensor, so a
/// gyro-bias result is its `gyroscope:` channel.)
const char* kind_name(CalibrationKind kind);
/// The kind of a name (kind_name's), nullopt if unknown.
std::optional<CalibrationKind> parse_kind(std::string_view name);

/// What decides when a collection ends and when its data are good enough.
struct SessionParams {
  CalibrationKind kind = CalibrationKind::magnetometer;
  /// Collect for this long from the start, s (0: no time limit; then sample_count must be set). Default 0.
  double duration_s = 0.0;
  /// Or until this many samples (0: no count limit). The first limit reached ends the collection.
  std::size_t sample_count = 0;
  /// Also end as soon as the data are good enough (see the fields below). Default off: the whole time is used.
  bool until_good = false;
  /// |u| the magnetometer is scaled to (uT: the filters compare magnitudes relative to it). Default 50 uT.
  double field_magnitude = 50.0;
  /// |u| the accelerometer is scaled to, m/s^2 (standard gravity).
  double gravity = 9.80665;
  PoseSegmentationParams segmentation;
  /// Good enough (magnetometer, accelerometer): at least this many poses, ...  Default 12: twice the 5-pose
  /// minimum of eq. 29, and where the Table I Monte Carlo error of H levels off.
  std::size_t good_poses = 12;
  /// ... this many of the 8 octants holding a pose's field direction ...  Default 6.
  int good_octants = 6;
  /// ... a sphere coverage of at least this, and no warning in the quality report. Default 0.5 (the report warns
  /// below 0.3).
  double good_coverage = 0.5;
  /// Good enough (gyro bias): this much rest, s. Default 3 s (the bias low-pass of the filters needs 2 s).
  double good_rest_s = 3.0;
  /// A node silent this long ends the session with a failure, s. Default 2 s.
  double silence_timeout_s = 2.0;
  /// Lost samples (a jump in seq) up to this many in a row are interpolated linearly, so the gyro integration
  /// between poses stays right; a longer gap fails the session. Default 10 (0.1 s at 100 Hz).
  std::size_t max_interpolated_gap = 10;
  /// Collections are refused beyond these: 1 h, and 1 h of 1 kHz samples.
  double max_duration_s = 3600.0;
  std::size_t max_samples = 3'600'000;
};

/// "" when the parameters describe a collection that can end, else why not ("duration_s must be ...").
std::string validate(const SessionParams& params);

/// One raw sample as the node sent it (uncalibrated), with a flag per channel present.
/// Seconds from one arrival or sensor time to a later one, ns in; 0 when `to_ns` is not later.
inline double seconds_between(std::uint64_t from_ns, std::uint64_t to_ns) {
  return to_ns > from_ns ? static_cast<double>(to_ns - from_ns) * 1e-9 : 0.0;
}

struct SessionSample {
  std::uint64_t seq = 0;
  std::uint64_t timestamp_ns = 0;  ///< sensor clock
  Vec3 acc = Vec3::Zero(), gyr = Vec3::Zero(), mag = Vec3::Zero();
  bool has_acc = true, has_gyr = true, has_mag = true;
};

struct SessionProgress {
  bool started = false;          ///< at least one sample arrived
  bool collection_over = false;  ///< a limit was reached (or the node fell silent)
  std::size_t samples = 0;
  std::size_t poses = 0;         ///< still poses so far
  int octants = 0;               ///< of 8, after a provisional fit (0 before 5 poses)
  double sphere_coverage = 0.0;  ///< after a provisional fit (0 before 5 poses)
  bool good_enough = false;
  double elapsed_s = 0.0;
  double seconds_left = -1.0;  ///< until duration_s, -1 without a time limit
  double fraction = 0.0;       ///< 0..1, the most advanced of time, samples and (with until_good) quality
  std::string instruction;     ///< what the person should do now
};

struct SessionResult {
  CalibrationKind kind = CalibrationKind::magnetometer;
  bool success = false;
  std::string message;      ///< why it failed; "" on success
  FieldCalibration field;   ///< magnetometer or accelerometer: B, H, M, u_0, quality report
  ChannelCalibration gyro;  ///< gyro bias (all kinds: the mean rate over the rests), identity transform
  std::size_t samples = 0;
  std::size_t interpolated = 0;  ///< lost samples filled in
  std::size_t rest_samples = 0;
};

class CalibrationSession {
 public:
  /// start_ns: the start on the arrival clock (monotonic, ns), from which duration_s and the silence run.
  /// Throws std::invalid_argument when validate(params) is not empty.
  CalibrationSession(const SessionParams& params, std::uint64_t start_ns);

  /// Adds a sample that arrived at now_ns; ignored once the collection is over.
  void add(const SessionSample& sample, std::uint64_t now_ns);

  /// True once duration_s has passed, sample_count samples arrived, the data were found good enough (with
  /// until_good, at the last progress()), the node fell silent, or the buffer is full.
  bool collection_over(std::uint64_t now_ns) const;

  /// Where the collection stands at now_ns. Segments the poses collected so far and, from 5 poses on, fits
  /// provisionally (about 1 ms per 10 000 samples).
  SessionProgress progress(std::uint64_t now_ns);

  /// Fits what was collected (call once the collection is over, or to end it early).
  SessionResult finish() const;

  const SessionParams& params() const { return params_; }
  std::size_t samples() const { return static_cast<std::size_t>(count_); }

 private:
  void push(const SessionSample& s);
  double sample_rate_hz() const;
  std::string failure_before_fit() const;

  SessionParams params_;
  std::uint64_t start_ns_;
  std::optional<std::uint64_t> last_arrival_ns_;
  std::optional<std::uint64_t> last_seq_;
  // One column per sample (gaps filled in); a channel a sample does not carry is NaN.
  Points3 gyr_{3, 0}, acc_{3, 0}, mag_{3, 0};
  std::vector<std::uint64_t> timestamps_;
  Eigen::Index count_ = 0;
  std::size_t interpolated_ = 0;
  std::size_t non_finite_ = 0;
  std::optional<std::uint64_t> first_non_finite_seq_;
  std::optional<std::uint64_t> gap_too_long_at_seq_;
  std::size_t gap_length_ = 0;
  bool good_enough_ = false;
  bool full_ = false;
};

}  // namespace bsn::calib
