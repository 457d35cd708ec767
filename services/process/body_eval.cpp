// `bsn eval --body`: the body pipeline's estimates against the recordings' reference orientation per segment.
#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <string_view>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/conversions.hpp"
#include "bsn/fusion/orientation_error.hpp"
#include "bsn/io/json.hpp"
#include "bsn/io/recording.hpp"
#include "fusion_pipeline.hpp"
#include "process_command.hpp"
#include "process_input.hpp"

namespace bsn::services {
namespace {

using namespace process_detail;

/// The reference of one segment: sensor-to-earth by timestamp.
using TruthTrack = std::map<std::uint64_t, fusion::Quat>;

struct JointSeries {
  std::string name;
  std::size_t parent = 0, child = 0;
  fusion::JointConvention convention;
  bool aligned = false;
  std::vector<double> t_s;
  std::vector<fusion::Quat> est, truth;  ///< relative orientations in the published frames
};

/// The mean rotation of unit quaternions (the dominant eigenvector of sum q q^T, Markley et al. 2007).
fusion::Quat mean_rotation(const std::vector<fusion::Quat>& qs) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  for (const fusion::Quat& q : qs) {
    const Eigen::Vector4d v(q.w(), q.x(), q.y(), q.z());
    m += v * v.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> eig(m);
  const Eigen::Vector4d v = eig.eigenvectors().col(3);
  return fusion::Quat(v[0], v[1], v[2], v[3]).normalized();
}

double wrap(double a) { return std::remainder(a, 2.0 * std::numbers::pi); }

/// --align-window: all, none or A:B seconds from the first sample.
struct AlignWindow {
  bool align = true;
  double from = 0.0, to = std::numeric_limits<double>::infinity();
};

AlignWindow parse_align_window(const std::string& text) {
  AlignWindow w;
  w.align = text != "none";
  if (!w.align || text == "all") return w;
  const auto colon = text.find(':');
  char* end = nullptr;
  bool ok = colon != std::string::npos;
  if (ok) {
    w.from = std::strtod(text.c_str(), &end);
    ok = end == text.c_str() + colon;
    w.to = std::strtod(text.c_str() + colon + 1, &end);
    ok = ok && *end == '\0' && std::isfinite(w.from) && std::isfinite(w.to) && w.to > w.from && w.from >= 0.0;
  }
  if (!ok) throw UsageError("--align-window must be all, none or A:B in seconds with B > A >= 0, not '" + text + "'");
  return w;
}

/// Per segment the estimate and the truth in the published frame, and their time; per joint its series.
struct EvalSeries {
  std::vector<std::vector<fusion::Quat>> seg_est, seg_truth;
  std::vector<std::vector<double>> seg_t;
  std::vector<JointSeries> joints;
};

/// The input through the body pipeline, each estimate paired with the truth at its sample time.
EvalSeries collect_series(const BodyEvalOptions& opt, const ProcessOptions& p, const fusion::BodyModel& body,
                          const ProcessInput& in) {
  std::vector<TruthTrack> truth(body.segments.size());
  for (const bsn::Orientation& o : in.truth) {
    const auto seg = body.find_segment(o.segment());
    if (seg) truth[*seg][o.timestamp_ns()] = dds::to_quat(o.quat());
  }
  for (const RecordedTruth& t : in.recorded_truth) {
    const auto seg = body.find_segment(t.segment);
    if (!seg) continue;
    for (std::size_t i = 0; i < t.size(); ++i) truth[*seg][t.timestamp_ns[i]] = truth_quat(t, i);
  }
  const std::vector<Event> events =
      merge_events(in, p.order.empty() ? (in.session ? "arrival" : "time") : p.order, false);
  FusionPipeline pipeline(
      body, opt.body_path.empty() ? fusion::BodyFusion::Calibrations{} : config::load_body_calibrations(opt.body_path),
      {}, 0);
  EvalSeries out;
  const std::size_t n = body.segments.size();
  out.seg_est.resize(n);
  out.seg_truth.resize(n);
  out.seg_t.resize(n);
  out.joints.resize(n);
  auto& seg_est = out.seg_est;
  auto& seg_truth = out.seg_truth;
  auto& seg_t = out.seg_t;
  auto& joints = out.joints;
  std::vector<std::string_view> node(in.tracks.size());
  for (std::size_t k = 0; k < in.tracks.size(); ++k) node[k] = body.segments[in.tracks[k].segment].node;
  std::optional<std::uint64_t> t0;
  auto frame_of = [&](std::size_t segment, const fusion::Quat& q_sensor, bool aligned) {
    return aligned ? fusion::segment_orientation(q_sensor, pipeline.fusion().segment(segment).sensor_to_segment)
                   : q_sensor;
  };
  for (const Event& ev : events) {
    const NodeTrack& t = in.tracks[ev.track];
    const std::size_t i = ev.index;
    if (!t0) t0 = t.timestamp_ns[i];
    const fusion::SampleResult& r = pipeline.process({node[ev.track], t.seq[i], imu_sample(t, i)}, t.timestamp_ns[i]);
    if (r.outcome != fusion::SampleOutcome::kEstimated) continue;
    const auto truth_now = truth[r.segment].find(t.timestamp_ns[i]);
    if (truth_now == truth[r.segment].end()) continue;
    const double ts = 1e-9 * static_cast<double>(t.timestamp_ns[i] - *t0);
    seg_t[r.segment].push_back(ts);
    seg_est[r.segment].push_back(r.orientation);
    seg_truth[r.segment].push_back(frame_of(r.segment, truth_now->second, r.aligned));
    if (!r.joint) continue;
    const auto parent_truth = truth[r.joint->parent].find(t.timestamp_ns[i]);
    if (parent_truth == truth[r.joint->parent].end()) continue;
    JointSeries& j = joints[r.segment];
    j.name = fusion::joint_name(body.segments[r.segment]);
    j.parent = r.joint->parent;
    j.child = r.segment;
    j.convention = r.joint->convention;
    j.aligned = r.joint->aligned;
    j.t_s.push_back(ts);
    j.est.push_back(r.joint->relative);
    j.truth.push_back(
        fusion::canonical(fusion::relative_orientation(frame_of(r.joint->parent, parent_truth->second, j.aligned),
                                                       frame_of(r.segment, truth_now->second, j.aligned))));
  }
  return out;
}

/// The per-segment constant alignment: q_truth = q_est * B over the window (B in the published frame).
std::vector<fusion::Quat> fit_alignment(const EvalSeries& series, const AlignWindow& window) {
  std::vector<fusion::Quat> alignment(series.seg_t.size(), fusion::Quat::Identity());
  if (!window.align) return alignment;
  for (std::size_t s = 0; s < series.seg_t.size(); ++s) {
    std::vector<fusion::Quat> d;
    for (std::size_t k = 0; k < series.seg_t[s].size(); ++k)
      if (series.seg_t[s][k] >= window.from && series.seg_t[s][k] <= window.to)
        d.push_back(series.seg_est[s][k].conjugate() * series.seg_truth[s][k]);
    if (!d.empty()) alignment[s] = mean_rotation(d);
  }
  return alignment;
}

/// Per segment the BROAD error angles, unaligned and aligned: appended to `json` and `table`.
void score_segments(const EvalSeries& series, const std::vector<fusion::Quat>& alignment, const fusion::BodyModel& body,
                    std::string& json, std::string& table) {
  const auto& seg_t = series.seg_t;
  const auto& seg_est = series.seg_est;
  const auto& seg_truth = series.seg_truth;
  bool first = true;
  for (std::size_t s = 0; s < body.segments.size(); ++s) {
    if (seg_t[s].empty()) continue;
    fusion::RmsErrorAccumulator raw_acc, aligned_acc;
    for (std::size_t k = 0; k < seg_t[s].size(); ++k) {
      raw_acc.add(fusion::error_angles(seg_est[s][k], seg_truth[s][k]));
      aligned_acc.add(fusion::error_angles(seg_est[s][k] * alignment[s], seg_truth[s][k]));
    }
    auto angles = [](const fusion::ErrorAngles& e) {
      return "{\"total_deg\": " + io::json_number(e.total * 180 / std::numbers::pi, 9) +
             ", \"heading_deg\": " + io::json_number(e.heading * 180 / std::numbers::pi, 9) +
             ", \"inclination_deg\": " + io::json_number(e.inclination * 180 / std::numbers::pi, 9) + "}";
    };
    json += std::string(first ? "" : ", ") + io::json_string(body.segments[s].name) +
            ": {\"samples\": " + std::to_string(seg_t[s].size()) + ", \"unaligned\": " + angles(raw_acc.rms()) +
            ", \"aligned\": " + angles(aligned_acc.rms()) + "}";
    first = false;
    char line[200];
    const auto e = aligned_acc.rms();
    std::snprintf(line, sizeof line, "%-16s %7.2f %8.2f %12.2f\n", body.segments[s].name.c_str(),
                  e.total * 180 / std::numbers::pi, e.heading * 180 / std::numbers::pi,
                  e.inclination * 180 / std::numbers::pi);
    table += line;
  }
}

/// Per joint the RMS of the relative orientation's error and of the named anatomical angles: into json and table.
void score_joints(const EvalSeries& series, const std::vector<fusion::Quat>& alignment, std::string& json,
                  std::string& table) {
  const auto& joints = series.joints;
  json += "}, \"joints\": {";
  table += "joint              relative  anatomical 1/2/3   (deg RMS, unaligned | aligned)\n";
  bool first = true;
  for (const JointSeries& j : joints) {
    if (j.t_s.empty()) continue;
    const bool anatomical = j.convention.type != fusion::JointType::kNone && j.aligned;
    auto figures = [&](bool aligned) {
      double rel_sq = 0.0;
      Eigen::Vector3d anat_sq = Eigen::Vector3d::Zero();
      for (std::size_t k = 0; k < j.t_s.size(); ++k) {
        const fusion::Quat est =
            aligned ? fusion::Quat(alignment[j.parent].conjugate() * j.est[k] * alignment[j.child]) : j.est[k];
        const double e = fusion::angle_between(est, j.truth[k]);
        rel_sq += e * e;
        if (anatomical) {
          const fusion::Vec3 a =
              fusion::anatomical_angles(est, j.convention) - fusion::anatomical_angles(j.truth[k], j.convention);
          for (int c = 0; c < 3; ++c) anat_sq[c] += wrap(a[c]) * wrap(a[c]);
        }
      }
      const double n = static_cast<double>(j.t_s.size());
      std::array<double, 4> out{std::sqrt(rel_sq / n) * 180 / std::numbers::pi, 0, 0, 0};
      for (int c = 0; c < 3; ++c) out[c + 1] = std::sqrt(anat_sq[c] / n) * 180 / std::numbers::pi;
      return out;
    };
    const auto names = fusion::anatomical_angle_names(j.convention.type);
    auto to_json = [&](const std::array<double, 4>& f) {
      std::string s = "{\"relative_deg\": " + io::json_number(f[0], 9);
      if (anatomical) {
        s += ", \"anatomical_deg\": {";
        for (int c = 0; c < 3; ++c)
          s +=
              std::string(c ? ", " : "") + io::json_string(std::string(names[c])) + ": " + io::json_number(f[c + 1], 9);
        s += "}";
      }
      return s + "}";
    };
    const auto plain = figures(false), aligned = figures(true);
    json += std::string(first ? "" : ", ") + io::json_string(j.name) +
            ": {\"samples\": " + std::to_string(j.t_s.size()) + ", \"unaligned\": " + to_json(plain) +
            ", \"aligned\": " + to_json(aligned) + "}";
    first = false;
    char line[240];
    if (anatomical) {
      std::snprintf(line, sizeof line, "%-16s %8.2f  %5.2f %5.2f %5.2f | %8.2f  %5.2f %5.2f %5.2f\n", j.name.c_str(),
                    plain[0], plain[1], plain[2], plain[3], aligned[0], aligned[1], aligned[2], aligned[3]);
    } else {  // no anatomy, or a segment of the joint not aligned: the relative orientation only
      std::snprintf(line, sizeof line, "%-16s %8.2f      -     -     - | %8.2f      -     -     -\n", j.name.c_str(),
                    plain[0], aligned[0]);
    }
    table += line;
  }
  json += "}}";
}

/// Each joint's relative-orientation error (aligned) over time, one polyline per joint, as SVG.
void write_plot(const std::string& path, const EvalSeries& series, const std::vector<fusion::Quat>& alignment) {
  const auto& joints = series.joints;
  constexpr double kW = 800, kH = 300;
  double t_max = 1e-9, e_max = 1e-9;
  std::vector<std::vector<std::pair<double, double>>> lines;
  for (const JointSeries& j : joints) {
    if (j.t_s.empty()) continue;
    auto& l = lines.emplace_back();
    for (std::size_t k = 0; k < j.t_s.size(); k += std::max<std::size_t>(1, j.t_s.size() / 2000)) {
      const double e = fusion::angle_between(
                           fusion::Quat(alignment[j.parent].conjugate() * j.est[k] * alignment[j.child]), j.truth[k]) *
                       180 / std::numbers::pi;
      l.emplace_back(j.t_s[k], e);
      t_max = std::max(t_max, j.t_s[k]);
      e_max = std::max(e_max, e);
    }
  }
  std::ofstream svg(path);
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << kW << "\" height=\"" << kH + 40 << "\">\n"
      << "<text x=\"10\" y=\"20\" font-size=\"14\">joint error (deg, aligned) over time (s); max " << e_max << " deg, "
      << t_max << " s</text>\n";
  const char* colours[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"};
  std::size_t c = 0;
  for (const JointSeries& j : joints) {
    if (j.t_s.empty()) continue;
    svg << "<polyline fill=\"none\" stroke=\"" << colours[c % 7] << "\" points=\"";
    for (const auto& [t, e] : lines[c]) svg << t / t_max * kW << "," << 30 + kH - e / e_max * kH << " ";
    svg << "\"><title>" << j.name << "</title></polyline>\n";
    ++c;
  }
  svg << "</svg>\n";
  if (!svg) throw io::IoError(path + ": cannot write");
}

int body_eval(const BodyEvalOptions& opt) {
  const AlignWindow window = parse_align_window(opt.align_window);
  ProcessOptions p;
  p.input = opt.input;
  p.body_path = opt.body_path;
  p.filters = opt.filters;
  p.import = opt.import;
  std::vector<std::string> notes;
  fusion::BodyModel body;
  ProcessInput in = load_input(p, body, notes);
  if (in.truth.empty() && in.recorded_truth.empty())
    throw UsageError(opt.input + ": no reference orientation (opt_quat, or bsn/truth/orientation) to score against");
  const EvalSeries series = collect_series(opt, p, body, in);
  const std::vector<fusion::Quat> alignment = fit_alignment(series, window);
  std::string json = "{\"input\": " + io::json_string(opt.input) +
                     ", \"align_window\": " + io::json_string(opt.align_window) + ", \"segments\": {";
  std::string table = "segment            total  heading  inclination  (deg RMS, aligned)\n";
  score_segments(series, alignment, body, json, table);
  score_joints(series, alignment, json, table);
  if (!opt.plot_path.empty()) write_plot(opt.plot_path, series, alignment);
  for (const std::string& n : notes) std::fprintf(stderr, "bsn eval: note: %s\n", n.c_str());
  std::fputs(opt.json ? (json + "\n").c_str() : table.c_str(), stdout);
  return 0;
}

}  // namespace

int run_body_eval(const BodyEvalOptions& opt) {
  try {
    return body_eval(opt);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const io::FormatError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 1;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "bsn eval: error: %s\n", e.what());
    return 2;
  }
}

}  // namespace bsn::services
