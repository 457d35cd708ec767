#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bsn/calib/pose_segmentation.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/fusion/rotation.hpp"
#include "bsn/io/json.hpp"
#include "bsn/io/recording.hpp"
#include "calibrate_modes.hpp"
#include "tools.hpp"

namespace bsn::services {
namespace {

using calib::FieldCalibration;
using calib::Points3;

using io::json_string;
// Calibration parameters keep 10 significant digits: they are applied to raw readings.
std::string number(double v) { return io::json_number(v, 10); }

std::string json_vector(const calib::Vec3& v) {
  return "[" + number(v.x()) + ", " + number(v.y()) + ", " + number(v.z()) + "]";
}

std::string json_quality(const calib::FitQuality& q) {
  std::string warnings;
  for (const auto& w : q.warnings) warnings += (warnings.empty() ? "" : ", ") + json_string(w);
  return "{\"pose_count\": " + std::to_string(q.pose_count) + ", \"sample_count\": " + std::to_string(q.sample_count) +
         ", \"residual_rms\": " + number(q.residual_rms) + ", \"residual_max\": " + number(q.residual_max) +
         ", \"pose_residual_rms\": " + number(q.pose_residual_rms) +
         ", \"sphere_coverage\": " + number(q.sphere_coverage) +
         ", \"octants_covered\": " + std::to_string(q.octants_covered) +
         ", \"ellipsoid_condition\": " + number(q.ellipsoid_condition) +
         ", \"transform_condition\": " + number(q.transform_condition) +
         ", \"ellipsoid_consistency\": " + number(q.ellipsoid_consistency) + ", \"warnings\": [" + warnings + "]}";
}

std::string json_calibration(const FieldCalibration& c) {
  const calib::Mat3& h = c.calibration.transform;
  std::string rows;
  for (int r = 0; r < 3; ++r) rows += (r ? ", " : "") + json_vector(h.row(r).transpose());
  return "{\"bias\": " + json_vector(c.calibration.bias) + ", \"transform\": [" + rows +
         "], \"field_magnitude\": " + number(c.field_magnitude) + ", \"field_vector\": " + json_vector(c.field_vector) +
         ", \"quality\": " + json_quality(c.quality) + "}";
}

void print_report(const char* channel, const FieldCalibration& c) {
  const calib::Mat3& h = c.calibration.transform;
  const calib::FitQuality& q = c.quality;
  std::printf("%s: u = H (raw - B), |u| = %g\n", channel, c.field_magnitude);
  std::printf("  B  = [%.6g, %.6g, %.6g]\n", c.calibration.bias.x(), c.calibration.bias.y(), c.calibration.bias.z());
  for (int r = 0; r < 3; ++r)
    std::printf("  %s [%.6g, %.6g, %.6g]\n", r == 0 ? "H =" : "   ", h(r, 0), h(r, 1), h(r, 2));
  std::printf("  field vector at pose 0: [%.6g, %.6g, %.6g]\n", c.field_vector.x(), c.field_vector.y(),
              c.field_vector.z());
  std::printf("  quality: %zu poses, %zu samples; | |u| - M | rms %.3g (%.2f %%), max %.3g; pose residual rms %.3g\n",
              q.pose_count, q.sample_count, q.residual_rms, 100.0 * q.residual_rms / c.field_magnitude, q.residual_max,
              q.pose_residual_rms);
  std::printf(
      "           sphere coverage %.2f of 1, %d of 8 octants; condition: ellipsoid %.3g, H %.3g; "
      "H^T H vs M^2 Sigma %.2f %%\n",
      q.sphere_coverage, q.octants_covered, q.ellipsoid_condition, q.transform_condition,
      100.0 * q.ellipsoid_consistency);
  for (const auto& w : q.warnings) std::printf("  warning: %s\n", w.c_str());
}

Points3 columns(const io::RowsX3& rows) { return rows.transpose(); }

std::string default_output(const std::string& input) {
  std::filesystem::path p(input);
  p.replace_extension(".calib.yaml");
  return p.string();
}

int run_fit(const CalibrateOptions& opt) {
  io::Recording rec;
  try {
    rec = io::read_recording(opt.input);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn calibrate: %s\n", e.what());
    return 2;
  }
  if (!(opt.field_magnitude > 0.0) || !std::isfinite(opt.field_magnitude)) {
    std::fprintf(stderr, "bsn calibrate: --field-magnitude must be positive\n");
    return 2;
  }
  calib::PoseSegmentationParams params;
  params.rest_rate_rad_s = opt.rest_rate_rad_s;
  params.min_pose_s = opt.min_pose_s;
  const Points3 rates = columns(rec.gyr);
  calib::PoseSegmentation poses;
  const FieldCalibration mag = calib::calibrate_field_from_recording(rates, columns(rec.mag), rec.sampling_rate_hz,
                                                                     opt.field_magnitude, params, &poses);
  if (!mag.ok()) {
    std::fprintf(stderr, "bsn calibrate: %s: magnetometer: %s\n", opt.input.c_str(), mag.message.c_str());
    return 1;
  }
  FieldCalibration acc;
  if (opt.accelerometer) {
    acc =
        calib::calibrate_field_from_recording(rates, columns(rec.acc), rec.sampling_rate_hz, fusion::kGravity, params);
    if (!acc.ok()) {
      std::fprintf(stderr, "bsn calibrate: %s: accelerometer: %s\n", opt.input.c_str(), acc.message.c_str());
      return 1;
    }
  }
  calib::ChannelCalibration gyro;
  gyro.bias = poses.gyro_bias;

  const std::string out_path = opt.output.empty() ? default_output(opt.input) : opt.output;
  {
    std::ofstream out(out_path);
    out << "# bsn calibration of " << std::filesystem::path(opt.input).filename().string()
        << " (bsn calibrate): u = transform * (raw - bias)\n"
        << config::calibration_to_yaml(opt.node, &mag, opt.accelerometer ? &acc : nullptr,
                                       opt.gyro_bias ? &gyro : nullptr);
    if (!out) {
      std::fprintf(stderr, "bsn calibrate: cannot write %s\n", out_path.c_str());
      return 2;
    }
  }
  if (opt.json) {
    std::printf("%s\n", json_calibration(mag).c_str());
  } else {
    print_report("magnetometer", mag);
    if (opt.accelerometer) print_report("accelerometer", acc);
    std::printf("gyro bias from %zu rest samples: [%.6g, %.6g, %.6g] rad/s\n", poses.rest_samples, poses.gyro_bias.x(),
                poses.gyro_bias.y(), poses.gyro_bias.z());
    std::printf("wrote %s\n", out_path.c_str());
  }
  return 0;
}

/// Runs the command; returns the process exit code (0 ok, 1 the data do not calibrate, 2 unreadable input).
int run_calibrate(const CalibrateOptions& options) {
  if (options.live) {
    if (!options.input.empty() || !options.allan.empty()) {
      std::fprintf(stderr, "bsn calibrate: --live takes no --input or --allan\n");
      return 2;
    }
    LiveCalibrationOptions live = options.live_options;
    live.node = options.node;
    if (options.field_magnitude_given) live.field_magnitude = options.field_magnitude;
    return run_live_calibration(live);
  }
  if (!options.alignment.empty()) {
    if (!options.input.empty() || !options.allan.empty()) {
      std::fprintf(stderr, "bsn calibrate: --alignment takes no --input or --allan\n");
      return 2;
    }
    return run_offline_alignment(options);
  }
  if (options.input.empty() == options.allan.empty()) {
    std::fprintf(stderr, "bsn calibrate: give exactly one of --input FILE, --allan FILE or --alignment DIR\n");
    return 2;
  }
  return options.allan.empty() ? run_fit(options) : run_allan(options);
}

}  // namespace

Command calibrate_command() {
  return {"calibrate", "Calibrate a hand-turned recording (magnetometer, accelerometer) or identify noise (--allan)",
          [](CLI::App* cmd) {
            auto opt = std::make_shared<CalibrateOptions>();
            cmd->add_option("--input", opt->input, "recording (CSV, BROAD HDF5) of still poses turned by hand");
            cmd->add_option("--allan", opt->allan, "static recording: print Allan noise figures instead");
            cmd->add_option("--alignment", opt->alignment,
                            "a recorded alignment (N-pose, flexions): a session file (bsn record) or a folder with "
                            "DIR/<node>.hdf5 per node of the body: write <node>.alignment.calib.yaml beside it (or "
                            "into --output DIR) instead");
            auto* field = cmd->add_option("--field-magnitude", opt->field_magnitude,
                                          "|calibrated magnetometer|, M (with --live: uT, default 50)")
                              ->capture_default_str()
                              ->check(positive_number(1e6));
            cmd->add_flag("--json", opt->json, "print the magnetometer calibration as one JSON object");
            cmd->add_option("--output", opt->output,
                            "calibration file to write (default: INPUT.calib.yaml); with --alignment: the folder");
            cmd->add_option("--node", opt->node,
                            "node id to record in the calibration file; with --live: the node (or ID,ID,...) to "
                            "calibrate");
            cmd->add_flag("--accelerometer", opt->accelerometer, "also calibrate the accelerometer (|g|)");
            cmd->add_flag("--gyro-bias", opt->gyro_bias, "also write the gyro bias measured at rest");
            cmd->add_option("--rest-threshold", opt->rest_rate_rad_s, "rest when |gyro - bias| < this, rad/s")
                ->capture_default_str()
                ->check(positive_number(100.0));
            cmd->add_option("--min-pose", opt->min_pose_s, "shortest rest counted as a pose, s")
                ->capture_default_str()
                ->check(positive_number(3600.0));
            cmd->add_option("--plot", opt->plot, "with --allan: write the Allan curves as SVG");
            LiveCalibrationOptions& live = opt->live_options;
            cmd->add_flag("--live", opt->live, "calibrate live through `bsn calibration` (see --node, --kind)");
            cmd->add_option("--kind", live.kind,
                            "with --live: magnetometer, gyro-bias, accelerometer or alignment (sensor-to-segment "
                            "rotations of a body's nodes: N-pose, then flexions)")
                ->capture_default_str();
            cmd->add_option("--body", live.body_path,
                            "with --alignment, or --live --kind alignment: the body model whose nodes are aligned "
                            "(default: the 7-segment lower body; with --live, --node picks some of its nodes)");
            cmd->add_option(
                   "--pose", live.pose_s,
                   "with --alignment or --live --kind alignment: the N-pose at the start lasts at least S seconds "
                   "(default 3)")
                ->check(non_negative_number(60.0));
            cmd->add_flag("--all-nodes", live.all_nodes, "with --live: every node publishing on bsn/raw");
            cmd->add_option("--duration", live.duration_s, "with --live: collect for S seconds (0: --samples only)")
                ->capture_default_str();
            cmd->add_option("--samples", live.sample_count, "with --live: or until N samples per node");
            cmd->add_flag("--until-good", live.until_good,
                          "with --live: stop as soon as the quality report is good enough");
            cmd->add_option("--request-id", live.request_id, "with --live: the request id (default: host-pid-time)");
            cmd->add_option("--service-timeout", live.service_timeout_s,
                            "with --live: seconds to wait for a calibration service")
                ->capture_default_str();
            add_domain_option(cmd, live.domain);
            return [opt, field] {
              opt->field_magnitude_given = field->count() > 0;
              return run_calibrate(*opt);
            };
          }};
}

}  // namespace bsn::services
