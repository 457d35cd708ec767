// Calibration files: the YAML that `bsn calibrate` writes and `bsn fusion` loads per node (body-model key
// `calibration: FILE`). Format (every channel optional; u = transform * (raw - bias)):
//
//   node: thigh_l                    # optional: the node it belongs to; a body segment on another node refuses it
//   request_id: lab-2026-12-01-1     # optional, informational: the live request that produced it
//   magnetometer:
//     bias: [bx, by, bz]             # raw unit
//     transform: [[h11, h12, h13], [h21, h22, h23], [h31, h32, h33]]
//     field_magnitude: 1.0           # informational: |u| after calibration
//     field_vector: [ux, uy, uz]     # informational: the field at the reference pose
//   accelerometer: {bias: [...], transform: [[...], [...], [...]]}
//   gyroscope: {bias: [...], transform: [[...], [...], [...]]}
//   quality: {...}                   # informational, not read back
//   alignment:                       # sensor-to-segment rotation (`bsn calibration`'s alignment kind)
//     segment: thigh_l               # the segment it was fitted for
//     sensor_to_segment: [w, x, y, z]  # v_segment = q v_sensor q*, into the segment's ISB frame
//     source: pose+hinge thigh_l-shank_l  # informational: what fixed the axes (pose+heading: the N-pose alone)
//     hinge_residual: 0.03           # informational: the hinge fit's RMS residual over its RMS rate
//     axis_observability: 0.05       # informational: how well the data pinned the axis in this sensor
//     samples: 2400                  # informational
#pragma once

#include <optional>
#include <string>
#include <unordered_map>

#include "bsn/calib/field_calibration.hpp"
#include "bsn/calib/segment_alignment.hpp"
#include "bsn/calib/sensor_calibration.hpp"
#include "bsn/config/body_config.hpp"

namespace bsn::config {

/// Parses calibration YAML; `source` names it in messages. Throws ConfigError("SOURCE:LINE: problem") on a
/// syntax error, unknown key, wrong size, non-finite number or singular transform.
calib::SensorCalibration parse_calibration(const std::string& yaml_text, const std::string& source);

/// Reads a calibration file. Throws ConfigError.
calib::SensorCalibration load_calibration_file(const std::string& path);

/// A sensor-to-segment alignment as a calibration file holds it, with what it was fitted from.
struct AlignmentRecord {
  std::string segment;
  calib::Quat sensor_to_segment = calib::Quat::Identity();
  std::string source;
  double hinge_residual = 0.0;
  double axis_observability = 0.0;
  std::size_t samples = 0;
};

/// A calibration file with what it says about itself.
struct CalibrationDocument {
  calib::SensorCalibration calibration;
  std::string node;                           ///< its `node:`, "" if it names none
  int node_line = 0;                          ///< line of `node:` (1-based), 0 without
  std::string request_id;                     ///< its `request_id:`, "" if none
  double magnetometer_field_magnitude = 0.0;  ///< its magnetometer's field_magnitude, 0 if none
  calib::Vec3 magnetometer_field_vector = calib::Vec3::Zero();
  double accelerometer_field_magnitude = 0.0;
  std::optional<AlignmentRecord> alignment;  ///< its `alignment:`, if any
};

/// parse_calibration and load_calibration_file, with the file's own node, request id and field figures.
CalibrationDocument parse_calibration_document(const std::string& yaml_text, const std::string& source);
CalibrationDocument load_calibration_document(const std::string& path);

/// A calibration file's text. `magnetometer` (with its quality report) and `accelerometer` are written when
/// ok(); `gyroscope` when given.
std::string calibration_to_yaml(const std::string& node, const calib::FieldCalibration* magnetometer,
                                const calib::FieldCalibration* accelerometer,
                                const calib::ChannelCalibration* gyroscope, const std::string& request_id = "");

/// The text of a calibration file holding one alignment.
std::string alignment_to_yaml(const std::string& node, const AlignmentRecord& alignment,
                              const std::string& request_id = "");

/// The calibrations named by the segments of a body model file (`calibration: FILE`, relative to the body
/// file), by node id. Empty for "" (the default body). Throws ConfigError, also for a file whose `node:` is not
/// the segment's node ("FILE:LINE: ...").
std::unordered_map<std::string, calib::SensorCalibration> load_body_calibrations(const std::string& body_path);

/// Sets the sensor_to_segment of every segment of `body` (loaded from `body_path`) whose calibration file holds an
/// alignment. Throws ConfigError for an alignment fitted for another segment, or a segment that also gives
/// sensor_axes or sensor_to_segment (two mountings for one sensor).
void apply_body_alignments(const std::string& body_path, fusion::BodyModel& body);

/// `path` relative to the directory of `relative_to` (a file), unless it is absolute.
std::string resolve_relative(const std::string& path, const std::string& relative_to);

}  // namespace bsn::config
