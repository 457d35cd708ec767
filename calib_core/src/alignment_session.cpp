#include "bsn/calib/alignment_session.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <stdexcept>

namespace bsn::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The N-pose means leave out this much at each end of the rest: the settling after and before a movement, s.
constexpr double kPoseEdgeTrim_s = 0.25;

std::string one_decimal(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

}  // namespace

std::string validate(const AlignmentSessionParams& p) {
  if (!std::isfinite(p.duration_s) || !(p.duration_s > 0.0))
    return "duration_s must be a positive number for an alignment (got " + one_decimal(p.duration_s) + ")";
  if (p.duration_s > p.max_duration_s)
    return "duration_s " + one_decimal(p.duration_s) + " is absurd for an alignment: at most " +
           one_decimal(p.max_duration_s) + " s";
  if (!std::isfinite(p.pose_s) || !(p.pose_s >= 0.5) || p.pose_s > 60.0)
    return "pose_s must be 0.5..60 s (got " + one_decimal(p.pose_s) + ")";
  if (p.pose_s >= p.duration_s)
    return "pose_s " + one_decimal(p.pose_s) + " leaves no time for the flexions within duration_s " +
           one_decimal(p.duration_s);
  if (!(p.still_rate_rad_s > 0.0) || !(p.start_timeout_s > 0.0) || !(p.silence_timeout_s > 0.0) ||
      !(p.max_pairing_gap_s > 0.0) || !(p.min_moving_s >= 0.0))
    return "still_rate_rad_s, start_timeout_s, silence_timeout_s and max_pairing_gap_s must be positive";
  return "";
}

std::string validate(const std::vector<AlignmentNode>& nodes) {
  if (nodes.empty()) return "the alignment names no node";
  std::set<std::string> seen;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const AlignmentNode& n = nodes[i];
    if (n.node.empty()) return "node " + std::to_string(i) + " of the alignment has an empty id";
    if (!seen.insert(n.node).second) return "node '" + n.node + "' is named twice";
    if (n.parent >= static_cast<int>(i) || n.parent < -1)
      return "node '" + n.node + "': its parent must come before it in the list";
  }
  return "";
}

AlignmentSession::AlignmentSession(std::vector<AlignmentNode> nodes, const AlignmentSessionParams& params,
                                   std::uint64_t start_ns)
    : nodes_(std::move(nodes)), params_(params), start_ns_(start_ns), buffers_(nodes_.size()) {
  if (std::string why = validate(params_); !why.empty()) throw std::invalid_argument(why);
  if (std::string why = validate(nodes_); !why.empty()) throw std::invalid_argument(why);
}

void AlignmentSession::add(std::size_t index, const SessionSample& s, std::uint64_t now_ns) {
  if (index >= buffers_.size() || collection_over(now_ns)) return;
  Buffer& b = buffers_[index];
  b.last_arrival_ns = now_ns;
  // Duplicates, reordered samples and a clock running backwards leave the buffer in sensor order.
  if (b.last_seq && s.seq <= *b.last_seq) return;
  b.last_seq = s.seq;
  if (!b.timestamps.empty() && s.timestamp_ns <= b.timestamps.back()) return;
  const bool finite =
      s.has_gyr && s.has_acc && s.gyr.allFinite() && s.acc.allFinite() && (!s.has_mag || s.mag.allFinite());
  if (!finite) {
    ++b.non_finite;  // never paired: the instant is missing from the alignment, not spoiling it
    return;
  }
  if (b.timestamps.size() >= params_.max_samples) {
    full_ = true;
    return;
  }
  if (b.timestamps.size() == b.timestamps.capacity()) {
    // Grow in steps (a minute at 100 Hz, then doubling): no reallocation per sample.
    const std::size_t capacity = std::max<std::size_t>(6000, 2 * b.timestamps.capacity());
    b.timestamps.reserve(capacity);
    b.acc.reserve(capacity);
    b.gyr.reserve(capacity);
    b.mag.reserve(capacity);
  }
  b.timestamps.push_back(s.timestamp_ns);
  b.acc.push_back(s.acc);
  b.gyr.push_back(s.gyr);
  b.mag.push_back(s.has_mag ? s.mag : Vec3::Constant(kNaN));
}

std::string AlignmentSession::silence_failure(std::uint64_t now_ns) const {
  std::string never, silent;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const Buffer& b = buffers_[i];
    if (!b.last_arrival_ns) {
      if (seconds_between(start_ns_, now_ns) >= params_.start_timeout_s)
        never += (never.empty() ? "'" : ", '") + nodes_[i].node + "'";
    } else if (seconds_between(*b.last_arrival_ns, now_ns) >= params_.silence_timeout_s) {
      silent += (silent.empty() ? "'" : ", '") + nodes_[i].node + "'";
    }
  }
  if (!never.empty())
    return "node " + never + " sent no sample within " + one_decimal(params_.start_timeout_s) +
           " s (check the node id and that it publishes in this domain); the alignment needs every node of the body";
  if (!silent.empty())
    return "node " + silent + " stopped sending for " + one_decimal(params_.silence_timeout_s) +
           " s; the alignment needs every node of the body throughout";
  return "";
}

bool AlignmentSession::collection_over(std::uint64_t now_ns) const {
  if (full_ || good_enough_) return true;
  if (seconds_between(start_ns_, now_ns) >= params_.duration_s) return true;
  return !silence_failure(now_ns).empty();
}

AlignmentSession::Paired AlignmentSession::pair() const {
  Paired p;
  const Buffer& ref = buffers_[0];
  for (const Buffer& b : buffers_)
    if (b.timestamps.empty()) return p;
  const auto gap_ns = static_cast<std::uint64_t>(params_.max_pairing_gap_s * 1e9);
  std::vector<std::size_t> cursor(buffers_.size(), 0);
  std::vector<std::size_t> row(buffers_.size());
  p.rows.reserve(ref.timestamps.size());
  for (std::size_t k = 0; k < ref.timestamps.size(); ++k) {
    const std::uint64_t t = ref.timestamps[k];
    bool complete = true;
    row[0] = k;
    for (std::size_t i = 1; i < buffers_.size() && complete; ++i) {
      const std::vector<std::uint64_t>& ts = buffers_[i].timestamps;
      std::size_t& c = cursor[i];
      while (c + 1 < ts.size() && ts[c + 1] <= t) ++c;
      // The nearer of the samples at or before t and after it.
      std::size_t best = c;
      if (c + 1 < ts.size()) {
        const std::uint64_t before = t > ts[c] ? t - ts[c] : ts[c] - t;
        const std::uint64_t after = ts[c + 1] > t ? ts[c + 1] - t : t - ts[c + 1];
        if (after < before) best = c + 1;
      }
      const std::uint64_t d = ts[best] > t ? ts[best] - t : t - ts[best];
      complete = d <= gap_ns;
      row[i] = best;
    }
    if (complete) p.rows.push_back(row);
  }
  if (p.rows.size() >= 2) {
    const double span = seconds_between(ref.timestamps[p.rows.front()[0]], ref.timestamps[p.rows.back()[0]]);
    // The rate of the paired instants where they are dense: the reference's own rate.
    const double ref_span = seconds_between(ref.timestamps.front(), ref.timestamps.back());
    p.rate_hz = ref_span > 0.0 ? static_cast<double>(ref.timestamps.size() - 1) / ref_span : 0.0;
    if (!(span > 0.0)) p.rate_hz = 0.0;
  }
  return p;
}

bool AlignmentSession::still(const Paired& p, std::size_t row) const {
  for (std::size_t i = 0; i < buffers_.size(); ++i)
    if (!(buffers_[i].gyr[p.rows[row][i]].norm() < params_.still_rate_rad_s)) return false;
  return true;
}

std::pair<std::size_t, std::size_t> AlignmentSession::find_pose(const Paired& p, std::size_t& longest,
                                                                std::size_t& trailing) const {
  longest = trailing = 0;
  if (p.rate_hz <= 0.0) return {0, 0};
  const auto needed = static_cast<std::size_t>(std::ceil(params_.pose_s * p.rate_hz));
  std::size_t run_start = 0, run = 0;
  for (std::size_t k = 0; k < p.rows.size(); ++k) {
    if (!still(p, k)) {
      run = 0;
      continue;
    }
    if (run == 0) run_start = k;
    ++run;
    longest = std::max(longest, run);
    // The pose lasts as long as the rest does: its end is the first movement after pose_s of stillness.
    if (run >= needed && (k + 1 == p.rows.size() || !still(p, k + 1))) return {run_start, k + 1};
  }
  trailing = run;
  return {0, 0};
}

std::size_t AlignmentSession::next_rest(const Paired& p, std::size_t from, std::size_t rows) const {
  std::size_t run = 0;
  for (std::size_t k = from; k < p.rows.size(); ++k) {
    run = still(p, k) ? run + 1 : 0;
    if (run >= rows) return k + 1 - run;
  }
  return p.rows.size();
}

AlignmentProgress AlignmentSession::progress(std::uint64_t now_ns) {
  AlignmentProgress out;
  out.elapsed_s = seconds_between(start_ns_, now_ns);
  out.seconds_left = std::max(0.0, params_.duration_s - out.elapsed_s);
  out.fraction = std::min(1.0, out.elapsed_s / params_.duration_s);
  out.samples.resize(nodes_.size());
  out.moving_s.assign(nodes_.size(), 0.0);
  out.node_instructions.assign(nodes_.size(), "");
  std::string missing;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    out.samples[i] = buffers_[i].timestamps.size();
    if (out.samples[i] == 0) missing += (missing.empty() ? "" : ", ") + nodes_[i].node;
  }
  if (!missing.empty()) {
    out.collection_over = collection_over(now_ns);
    out.instruction = "waiting for the samples of " + missing + " on bsn/raw";
    for (std::size_t i = 0; i < nodes_.size(); ++i)
      out.node_instructions[i] = out.samples[i] == 0 ? "waiting for its samples" : "sending";
    return out;
  }
  const Paired p = pair();
  std::size_t longest = 0, trailing = 0;
  const auto [pose_begin, pose_end] = find_pose(p, longest, trailing);
  const std::string pose_words = "stand still in the N-pose (upright, arms at the sides, feet parallel, looking ahead)";
  if (pose_end == 0) {
    out.phase = AlignmentPhase::pose;
    out.still_s = p.rate_hz > 0.0 ? static_cast<double>(trailing) / p.rate_hz : 0.0;
    out.instruction = pose_words + ": " + one_decimal(std::min(out.still_s, params_.pose_s)) + " of " +
                      one_decimal(params_.pose_s) + " s";
    if (p.rows.empty() && out.elapsed_s > 1.0)
      out.instruction += " (the nodes' sensor times never agree within " +
                         one_decimal(1000.0 * params_.max_pairing_gap_s) + " ms: one clock is needed)";
    for (auto& n : out.node_instructions) n = "N-pose";
    out.collection_over = collection_over(now_ns);
    return out;
  }
  // After the pose: how long each joint with a flexion direction has moved.
  out.phase = AlignmentPhase::moves;
  const double min_rate = params_.fit.hinge.min_rate_rad_s;
  bool all_moved = true;
  std::string behind;
  double behind_s = 0.0;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const AlignmentNode& n = nodes_[i];
    if (n.parent < 0 || n.flexion_sign == 0) continue;
    const auto parent = static_cast<std::size_t>(n.parent);
    std::size_t moving = 0;
    for (std::size_t k = pose_end; k < p.rows.size(); ++k)
      if (std::max(buffers_[parent].gyr[p.rows[k][parent]].norm(), buffers_[i].gyr[p.rows[k][i]].norm()) >= min_rate)
        ++moving;
    out.moving_s[i] = static_cast<double>(moving) / p.rate_hz;
    out.node_instructions[i] = (n.joint.empty() ? n.segment : n.joint) + " moved " + one_decimal(out.moving_s[i]) +
                               " of " + one_decimal(params_.min_moving_s) + " s";
    if (out.moving_s[i] < params_.min_moving_s) {
      all_moved = false;
      // The first joint of the body's order still short of movement: the procedure's order (left leg first).
      if (behind.empty()) {
        behind_s = out.moving_s[i];
        behind = n.joint.empty() ? n.segment : n.joint;
      }
    }
  }
  if (all_moved) {
    out.phase = AlignmentPhase::good_enough;
    out.instruction = "N-pose and flexions recorded: stand still, then walk";
    out.instruction += params_.until_good ? " (good enough: finishing)" : " (good enough already)";
    if (params_.until_good) {
      good_enough_ = true;
      out.fraction = 1.0;
    }
  } else {
    out.instruction =
        "N-pose recorded. Flex each leg three times, left then right: lift the knee, bend it, pull the toes up (" +
        behind + " moved " + one_decimal(behind_s) + " of " + one_decimal(params_.min_moving_s) + " s)";
  }
  out.collection_over = collection_over(now_ns);
  return out;
}

AlignmentSessionResult AlignmentSession::finish(std::uint64_t now_ns) const {
  AlignmentSessionResult r;
  r.nodes.resize(nodes_.size());
  for (std::size_t i = 0; i < nodes_.size(); ++i) r.nodes[i].samples = buffers_[i].timestamps.size();
  auto fail_all = [&r](const std::string& why) {
    r.problem = why;
    for (NodeAlignment& n : r.nodes) n.message = why;
    return r;
  };
  if (std::string why = silence_failure(now_ns); !why.empty()) return fail_all(why);
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (buffers_[i].timestamps.empty())
      return fail_all("node '" + nodes_[i].node + "' sent no usable sample (" + std::to_string(buffers_[i].non_finite) +
                      " held NaN or Inf or lacked a channel)");
  const Paired p = pair();
  r.paired_samples = p.rows.size();
  std::size_t fewest = buffers_[0].timestamps.size();
  for (const Buffer& b : buffers_) fewest = std::min(fewest, b.timestamps.size());
  // Nodes of one clock pair nearly every sample; half or fewer paired is another clock (or a clock far off).
  if (p.rows.size() < 2 || p.rate_hz <= 0.0 || 2 * p.rows.size() < fewest) {
    // The node whose first sample lies furthest from the first node's names the problem.
    std::size_t worst = 0;
    double offset = 0.0;
    for (std::size_t i = 1; i < buffers_.size(); ++i) {
      const double d = static_cast<double>(
                           static_cast<std::int64_t>(buffers_[i].timestamps.front() - buffers_[0].timestamps.front())) *
                       1e-9;
      if (std::abs(d) >= std::abs(offset)) {
        offset = d;
        worst = i;
      }
    }
    return fail_all("the nodes' samples rarely share an instant (" + std::to_string(p.rows.size()) + " of " +
                    std::to_string(fewest) + "): their sensor clocks differ (node '" + nodes_[worst].node +
                    "' starts " + one_decimal(offset) + " s from node '" + nodes_[0].node +
                    "'); the alignment needs the nodes of a body on one clock");
  }
  std::size_t longest = 0, trailing = 0;
  const auto [pose_begin, pose_end] = find_pose(p, longest, trailing);
  if (pose_end == 0)
    return fail_all("no N-pose: the nodes were never still at once for " + one_decimal(params_.pose_s) +
                    " s (the longest was " + one_decimal(static_cast<double>(longest) / p.rate_hz) +
                    " s); stand still at the start");
  const std::uint64_t t0 = buffers_[0].timestamps[p.rows.front()[0]];
  r.pose_start_s = seconds_between(t0, buffers_[0].timestamps[p.rows[pose_begin][0]]);
  r.pose_end_s = seconds_between(t0, buffers_[0].timestamps[p.rows[pose_end - 1][0]]);

  // The flexions: from the pose's end to the next rest of every node (the procedure stands still again before it
  // walks; walking moves the hips as ball joints, not hinges), or to the end. Between two flexions the body rests
  // less than that.
  const auto rest_rows = static_cast<std::size_t>(std::ceil(std::max(1.0, 0.5 * params_.pose_s) * p.rate_hz));
  const std::size_t moves_end = next_rest(p, pose_end, rest_rows);
  r.moves_end_s = seconds_between(t0, buffers_[0].timestamps[p.rows[moves_end - 1][0]]);
  // The pose means without its edges, and the rates of the flexions.
  const auto trim =
      std::min<std::size_t>(static_cast<std::size_t>(kPoseEdgeTrim_s * p.rate_hz), (pose_end - pose_begin) / 4);
  std::vector<AlignmentSegment> in(nodes_.size());
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    AlignmentSegment& s = in[i];
    s.name = nodes_[i].segment;
    s.parent = nodes_[i].parent;
    s.flexion_sign = nodes_[i].flexion_sign;
    const Buffer& b = buffers_[i];
    std::size_t count = 0, mags = 0;
    for (std::size_t k = pose_begin + trim; k < pose_end - trim; ++k, ++count) {
      s.acc_pose += b.acc[p.rows[k][i]];
      // A slower magnetometer leaves samples without one (NaN): the mean is over those that have it. None at all
      // leaves it zero, and align_body says "no N-pose" for the segment.
      if (const Vec3& m = b.mag[p.rows[k][i]]; m.allFinite()) {
        s.mag_pose += m;
        ++mags;
      }
    }
    s.acc_pose /= static_cast<double>(std::max<std::size_t>(count, 1));
    s.mag_pose /= static_cast<double>(std::max<std::size_t>(mags, 1));
    s.gyr.reserve(moves_end - pose_end);
    for (std::size_t k = pose_end; k < moves_end; ++k) s.gyr.push_back(b.gyr[p.rows[k][i]]);
  }
  const BodyAlignment aligned = align_body(in, params_.fit);
  r.problem = aligned.problem;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const SegmentAlignmentResult& a = aligned.segments[i];
    NodeAlignment& n = r.nodes[i];
    if (!a.sensor_to_segment) {
      n.message = a.problem.empty() ? "not aligned" : a.problem;
      continue;
    }
    n.success = true;
    n.sensor_to_segment = *a.sensor_to_segment;
    n.source = a.source.rfind("hinge ", 0) == 0 ? "pose+" + a.source : "pose+heading";
    n.relative_residual = a.relative_residual;
    n.axis_observability = a.axis_observability;
  }
  return r;
}

}  // namespace bsn::calib
