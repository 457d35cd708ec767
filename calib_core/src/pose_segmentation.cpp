#include "bsn/calib/pose_segmentation.hpp"

#include <Eigen/Geometry>
#include <cmath>

namespace bsn::calib {
namespace {

// Rest flag per sample: the moving mean (centred window) of |rate - bias| below the threshold.
std::vector<bool> rest_flags(const Eigen::Ref<const Points3>& rates, const Vec3& bias, double threshold,
                             Eigen::Index half_window) {
  const Eigen::Index n = rates.cols();
  Eigen::VectorXd magnitude(n);
  for (Eigen::Index k = 0; k < n; ++k) magnitude(k) = (rates.col(k) - bias).norm();
  // Prefix sums give each window's mean in O(1).
  Eigen::VectorXd prefix(n + 1);
  prefix(0) = 0.0;
  for (Eigen::Index k = 0; k < n; ++k) prefix(k + 1) = prefix(k) + magnitude(k);
  std::vector<bool> rest(static_cast<std::size_t>(n));
  for (Eigen::Index k = 0; k < n; ++k) {
    const Eigen::Index lo = std::max<Eigen::Index>(0, k - half_window);
    const Eigen::Index hi = std::min<Eigen::Index>(n, k + half_window + 1);
    rest[static_cast<std::size_t>(k)] = (prefix(hi) - prefix(lo)) / static_cast<double>(hi - lo) < threshold;
  }
  return rest;
}

// Why the inputs cannot be segmented, or "" when they can.
std::string input_problem(const Eigen::Ref<const Points3>& rates, const Eigen::Ref<const Points3>& readings,
                          double sample_rate_hz, const PoseSegmentationParams& params) {
  if (!(sample_rate_hz > 0.0) || !std::isfinite(sample_rate_hz)) {
    return "sample rate must be positive and finite";
  }
  if (rates.cols() != readings.cols()) {
    return "gyro and readings differ in length (" + std::to_string(rates.cols()) + " vs " +
           std::to_string(readings.cols()) + ")";
  }
  if (!(params.rest_rate_rad_s > 0.0) || !(params.min_pose_s > 0.0) || !(params.smoothing_s >= 0.0) ||
      !(params.edge_trim_s >= 0.0)) {
    return "segmentation parameters must be positive";
  }
  for (Eigen::Index k = 0; k < rates.cols(); ++k) {
    if (!rates.col(k).allFinite()) {
      return "non-finite gyro sample (NaN or Inf) at sample " + std::to_string(k);
    }
  }
  return "";
}

// The gyro integrated (bias removed) from the first sample, sampled at each run's middle sample.
std::vector<Eigen::Quaterniond> orientations_at_middles(const Eigen::Ref<const Points3>& rates, const Vec3& bias,
                                                        double sample_rate_hz, const std::vector<std::size_t>& begins,
                                                        const std::vector<std::size_t>& ends) {
  const auto n = static_cast<std::size_t>(rates.cols());
  const double dt = 1.0 / sample_rate_hz;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  std::vector<Eigen::Quaterniond> at_middle;
  std::size_t next = 0;
  for (std::size_t k = 0; k < n && next < begins.size(); ++k) {
    if (k == (begins[next] + ends[next]) / 2) {
      at_middle.push_back(q);
      ++next;
    }
    const Vec3 w = (rates.col(static_cast<Eigen::Index>(k)) - bias) * dt;
    const double angle = w.norm();
    if (angle > 0.0) q = (q * Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle))).normalized();
  }
  return at_middle;
}

}  // namespace

PoseSegmentation segment_poses(const Eigen::Ref<const Points3>& rates, const Eigen::Ref<const Points3>& readings,
                               double sample_rate_hz, const PoseSegmentationParams& params) {
  PoseSegmentation out;
  if (std::string problem = input_problem(rates, readings, sample_rate_hz, params); !problem.empty()) {
    out.message = std::move(problem);
    return out;
  }
  const Eigen::Index n = rates.cols();
  const auto half_window = static_cast<Eigen::Index>(params.smoothing_s * sample_rate_hz / 2.0);
  const auto min_len = static_cast<std::size_t>(params.min_pose_s * sample_rate_hz);
  const auto trim = static_cast<std::size_t>(params.edge_trim_s * sample_rate_hz);

  // Two passes: rest with the raw gyro (bias unknown), the bias from those samples, then rest again with the
  // bias removed, so that a bias near the threshold neither hides nor fakes rests.
  std::vector<bool> rest = rest_flags(rates, Vec3::Zero(), 2.0 * params.rest_rate_rad_s, half_window);
  Vec3 bias = Vec3::Zero();
  std::size_t still = 0;
  for (Eigen::Index k = 0; k < n; ++k)
    if (rest[static_cast<std::size_t>(k)]) {
      bias += rates.col(k);
      ++still;
    }
  if (still == 0) {
    out.message = "no rest found: the sensor never stayed still (gyro above " +
                  std::to_string(2.0 * params.rest_rate_rad_s) + " rad/s)";
    return out;
  }
  bias /= static_cast<double>(still);
  rest = rest_flags(rates, bias, params.rest_rate_rad_s, half_window);

  // Runs of rest, trimmed, at least min_len long.
  std::vector<std::size_t> begins, ends;
  out.gyro_bias.setZero();
  out.rest_samples = 0;
  for (std::size_t k = 0; k < static_cast<std::size_t>(n);) {
    if (!rest[k]) {
      ++k;
      continue;
    }
    std::size_t e = k;
    while (e < static_cast<std::size_t>(n) && rest[e]) ++e;
    if (e - k >= min_len + 2 * trim) {
      begins.push_back(k + trim);
      ends.push_back(e - trim);
      for (std::size_t i = k + trim; i < e - trim; ++i) out.gyro_bias += rates.col(static_cast<Eigen::Index>(i));
      out.rest_samples += e - k - 2 * trim;
    }
    k = e;
  }
  if (begins.empty()) {
    out.message = "no pose of at least " + std::to_string(params.min_pose_s) + " s found";
    return out;
  }
  out.gyro_bias /= static_cast<double>(out.rest_samples);

  // Integrate the bias-corrected gyro and keep the orientation at each pose's middle sample.
  const std::vector<Eigen::Quaterniond> at_middle =
      orientations_at_middles(rates, out.gyro_bias, sample_rate_hz, begins, ends);

  // Pose means of the finite readings; a pose without any is dropped.
  Points3 means(3, static_cast<Eigen::Index>(begins.size()));
  Eigen::Index kept = 0;
  const Eigen::Quaterniond first_inverse = at_middle.front().conjugate();
  bool have_reference = false;
  Eigen::Quaterniond reference_inverse = first_inverse;
  for (std::size_t p = 0; p < begins.size(); ++p) {
    Vec3 sum = Vec3::Zero();
    std::size_t count = 0;
    for (std::size_t i = begins[p]; i < ends[p]; ++i) {
      const auto c = readings.col(static_cast<Eigen::Index>(i));
      if (c.allFinite()) {
        sum += c;
        ++count;
      }
    }
    if (count == 0) continue;
    if (!have_reference) {
      reference_inverse = at_middle[p].conjugate();
      have_reference = true;
    }
    means.col(kept++) = sum / static_cast<double>(count);
    out.begin.push_back(begins[p]);
    out.end.push_back(ends[p]);
    out.rotations.push_back((reference_inverse * at_middle[p]).toRotationMatrix());
  }
  out.means = means.leftCols(kept);
  if (kept == 0) {
    out.message = "no pose holds a finite reading of the channel";
    return out;
  }
  out.status = FitStatus::ok;
  return out;
}

FieldCalibration calibrate_field_from_recording(const Eigen::Ref<const Points3>& rates,
                                                const Eigen::Ref<const Points3>& readings, double sample_rate_hz,
                                                double field_magnitude, const PoseSegmentationParams& params,
                                                PoseSegmentation* segmentation) {
  PoseSegmentation poses = segment_poses(rates, readings, sample_rate_hz, params);
  FieldCalibration out;
  if (!poses.ok()) {
    out.message = "pose segmentation failed: " + poses.message;
    out.field_magnitude = field_magnitude;
  } else {
    Points3 finite(3, readings.cols());
    Eigen::Index kept = 0;
    for (Eigen::Index k = 0; k < readings.cols(); ++k)
      if (readings.col(k).allFinite()) finite.col(kept++) = readings.col(k);
    out = calibrate_field(poses.means, poses.rotations, field_magnitude, finite.leftCols(kept));
  }
  if (segmentation != nullptr) *segmentation = std::move(poses);
  return out;
}

}  // namespace bsn::calib
