// Three simulated sensor nodes and the fusion service as separate processes; the test subscribes like any DDS
// client (bsn echo does the same) and checks rates, accuracy against the simulator's truth, joint angles against
// the truth's relative orientation, and the stale-node report.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <map>
#include <mutex>
#include <numbers>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/participant.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/rotation.hpp"
#include "process_fixture.hpp"

namespace bsn::integration {
namespace {

using namespace std::chrono_literals;
using SampleInfo = eprosima::fastdds::dds::SampleInfo;

constexpr double kRateHz = 100.0;  // default rate of `bsn sim`
constexpr double kMinRateShare = 0.95;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// s1 (root) <- s2 <- s3, one node per segment.
constexpr const char* kChainBody = R"(name: integration_chain
segments:
  - name: s1
    node: n1
    filter: {name: complementary}
  - name: s2
    node: n2
    parent: s1
    joint: j12
    joint_axes: zyx
  - name: s3
    node: n3
    parent: s2
    joint: j23
    joint_axes: zxy
)";

const std::vector<std::string> kSegments{"s1", "s2", "s3"};

struct Estimate {
  Clock::time_point arrival;
  std::uint64_t timestamp_ns;
  std::array<double, 4> quat;
};

struct JointSample {
  std::uint64_t timestamp_ns;  // the child's sample
  std::array<double, 4> quat;
  std::array<double, 3> angles;
};

struct JointSeen {
  std::string parent, child, axes;
  std::vector<Clock::time_point> arrivals;
  std::vector<JointSample> samples;
  bool all_finite = true;
};

struct StatusSeen {
  Clock::time_point arrival;
  bsn::Status status;
};

/// Everything the DDS callbacks record; they run on DDS threads, the test reads under the mutex.
struct Observed {
  std::mutex mutex;
  std::map<std::string, std::vector<Estimate>> estimates;                                 // by segment
  std::map<std::string, std::unordered_map<std::uint64_t, std::array<double, 4>>> truth;  // segment -> t -> q
  std::map<std::string, JointSeen> joints;
  std::vector<StatusSeen> statuses;

  std::size_t estimate_count(const std::string& segment) {
    std::lock_guard lock(mutex);
    auto it = estimates.find(segment);
    return it == estimates.end() ? 0 : it->second.size();
  }
};

/// The test's own DDS subscriber.
class Subscriber {
 public:
  Subscriber(int domain, Observed& obs) : participant_({domain, "bsn integration test"}) {
    orientation_ =
        participant_.make_reader(dds::kOrientationTopic, [&obs](const bsn::Orientation& o, const SampleInfo&) {
          const auto now = Clock::now();
          std::lock_guard lock(obs.mutex);
          obs.estimates[o.segment()].push_back({now, o.timestamp_ns(), o.quat()});
        });
    truth_ =
        participant_.make_reader(dds::kTruthOrientationTopic, [&obs](const bsn::Orientation& o, const SampleInfo&) {
          std::lock_guard lock(obs.mutex);
          obs.truth[o.segment()][o.timestamp_ns()] = o.quat();
        });
    joints_ = participant_.make_reader(dds::kJointAnglesTopic, [&obs](const bsn::JointAngles& j, const SampleInfo&) {
      const auto now = Clock::now();
      std::lock_guard lock(obs.mutex);
      JointSeen& seen = obs.joints[j.joint()];
      seen.parent = j.parent();
      seen.child = j.child();
      seen.axes = j.axes();
      seen.arrivals.push_back(now);
      seen.samples.push_back({j.timestamp_ns(), j.quat(), j.angles()});
      for (double a : j.angles()) seen.all_finite = seen.all_finite && std::isfinite(a);
    });
    status_ = participant_.make_reader(dds::kStatusTopic, [&obs](const bsn::Status& s, const SampleInfo&) {
      const auto now = Clock::now();
      std::lock_guard lock(obs.mutex);
      obs.statuses.push_back({now, s});
    });
  }

 private:
  dds::Participant participant_;
  std::unique_ptr<dds::Reader<bsn::Orientation>> orientation_, truth_;
  std::unique_ptr<dds::Reader<bsn::JointAngles>> joints_;
  std::unique_ptr<dds::Reader<bsn::Status>> status_;
};

std::size_t count_between(const std::vector<Estimate>& v, Clock::time_point from, Clock::time_point to) {
  std::size_t n = 0;
  for (const auto& e : v) n += (e.arrival >= from && e.arrival < to) ? 1 : 0;
  return n;
}

std::size_t count_between(const std::vector<Clock::time_point>& v, Clock::time_point from, Clock::time_point to) {
  std::size_t n = 0;
  for (const auto& t : v) n += (t >= from && t < to) ? 1 : 0;
  return n;
}

struct JointAccuracy {
  std::size_t in_window = 0, matched = 0;
  double max_error_deg = 0.0;         // published quaternion against the truth's relative orientation
  double max_angles_error_deg = 0.0;  // published angles, composed again, against the same
};

/// The fusion service publishes a joint with each child estimate, from that estimate and the parent's latest one.
/// Every joint sample with sensor time in [from, to) is matched to the two estimates it came from (the parent's is
/// the one whose relative orientation to the child's gives the published quaternion) and compared with
/// q_truth_parent* (x) q_truth_child at those two estimates' sample times.
// The parent's truth at sensor time t: its samples are at its own instants (every sim keeps its own phase on the one
// monotonic clock), so t falls between two of them; slerp between the two (10 ms apart at 100 Hz).
std::optional<fusion::Quat> truth_at(const std::map<std::uint64_t, std::array<double, 4>>& truth, std::uint64_t t) {
  const auto after = truth.lower_bound(t);
  if (after == truth.end()) return std::nullopt;
  if (after->first == t) return dds::to_quat(after->second);
  if (after == truth.begin()) return std::nullopt;
  const auto before = std::prev(after);
  if (after->first - before->first > 50'000'000) return std::nullopt;  // a gap, not neighbours
  const double a = static_cast<double>(t - before->first) / static_cast<double>(after->first - before->first);
  return dds::to_quat(before->second).slerp(a, dds::to_quat(after->second));
}

// Each joint sample is at the child's sample time, with the parent turned to that time (BodyFusion), so it is
// compared with the truth of both segments at the child's time.
JointAccuracy joint_accuracy(const JointSeen& joint, const std::vector<Estimate>& child,
                             const std::unordered_map<std::uint64_t, std::array<double, 4>>& truth_parent,
                             const std::unordered_map<std::uint64_t, std::array<double, 4>>& truth_child,
                             std::uint64_t from, std::uint64_t to, const fusion::AxisSequence& axes) {
  std::unordered_map<std::uint64_t, fusion::Quat> child_at;
  for (const auto& e : child) child_at.emplace(e.timestamp_ns, dds::to_quat(e.quat));
  const std::map<std::uint64_t, std::array<double, 4>> parent_truth(truth_parent.begin(), truth_parent.end());
  JointAccuracy acc;
  for (const JointSample& j : joint.samples) {
    if (j.timestamp_ns < from || j.timestamp_ns >= to) continue;
    ++acc.in_window;
    const auto c = child_at.find(j.timestamp_ns);  // a joint sample belongs to one of the child's estimates
    const auto truth_c = truth_child.find(j.timestamp_ns);
    const auto truth_p = truth_at(parent_truth, j.timestamp_ns);
    if (c == child_at.end() || truth_c == truth_child.end() || !truth_p) continue;
    ++acc.matched;
    const fusion::Quat q = dds::to_quat(j.quat);
    const fusion::Quat truth = fusion::relative_orientation(*truth_p, dds::to_quat(truth_c->second));
    const double err = fusion::angle_between(q, truth) * kRadToDeg;
    const double angles_err =
        fusion::angle_between(fusion::compose(fusion::Vec3(j.angles[0], j.angles[1], j.angles[2]), axes), truth) *
        kRadToDeg;
    if (!(err <= acc.max_error_deg)) acc.max_error_deg = err;  // also catches NaN
    if (!(angles_err <= acc.max_angles_error_deg)) acc.max_angles_error_deg = angles_err;
  }
  return acc;
}

class LiveSystem : public ProcessTest {
 protected:
  /// Writes the body file and starts `bsn fusion` and one `bsn sim` per segment of the chain.
  void start_chain(int domain) {
    const std::string body = (dir() / "chain.yaml").string();
    write_file(body, kChainBody);
    const std::string d = std::to_string(domain);
    spawn("fusion", {"fusion", "--domain", d, "--body", body});
    for (int i = 1; i <= 3; ++i) {
      const std::string n = std::to_string(i);
      spawn("sim-n" + n, {"sim", "--domain", d, "--node", "n" + n, "--segment", "s" + n});
    }
  }

  /// Stops the sims, then fusion, and expects each to exit 0 after SIGTERM (clean DDS shutdown).
  void stop_chain(const std::vector<std::string>& skip = {}) {
    for (const std::string name : {"sim-n3", "sim-n2", "sim-n1", "fusion"}) {
      if (std::find(skip.begin(), skip.end(), name) != skip.end()) continue;
      const auto st = stop(name);
      EXPECT_TRUE(exited_cleanly(st)) << name << " " << describe_status(st) << " after SIGTERM";
    }
  }
};

// Orientation rate >= 95 % of 100 Hz per segment; estimate within 2 deg of the simulator's truth for 10 s after a
// 5 s settling time; both joints at the child's rate and within 4 deg of the truth's relative orientation.
TEST_F(LiveSystem, LiveAccuracy) {
  const int kDomain = test_domain(0);
  constexpr auto kRateWindow = 10s;
  constexpr auto kSettle = std::chrono::nanoseconds(5s);
  constexpr auto kAccuracyWindow = std::chrono::nanoseconds(10s);
  constexpr double kMaxErrorDeg = 2.0;
  // The rotation angle between two orientations is a metric that rotations leave unchanged, so the error of
  // q_parent* (x) q_child is at most the parent's error plus the child's.
  constexpr double kMaxJointErrorDeg = 2.0 * kMaxErrorDeg;
  constexpr double kMinMatchedShare = 0.90;

  Observed obs;
  Subscriber sub(kDomain, obs);
  start_chain(kDomain);

  ASSERT_TRUE(wait_until(
      [&] {
        for (const auto& s : kSegments)
          if (obs.estimate_count(s) == 0) return false;
        return true;
      },
      20s))
      << "not every segment produced an orientation within 20 s";

  // Wait until every segment has 10 s of arrivals and its accuracy window (sensor time first + 15 s) has passed.
  Clock::time_point last_first{};
  {
    std::lock_guard lock(obs.mutex);
    for (const auto& s : kSegments) last_first = std::max(last_first, obs.estimates[s].front().arrival);
  }
  const auto until = last_first + kSettle + kAccuracyWindow + 700ms;
  std::this_thread::sleep_until(until);

  {
    std::lock_guard lock(obs.mutex);
    for (const auto& s : kSegments) {
      SCOPED_TRACE("segment " + s);
      const auto& est = obs.estimates[s];
      const Clock::time_point first = est.front().arrival;

      // Rate over a 10 s window of arrivals.
      const std::size_t n = count_between(est, first, first + kRateWindow);
      const double rate = static_cast<double>(n) / std::chrono::duration<double>(kRateWindow).count();
      EXPECT_GE(rate, kMinRateShare * kRateHz) << n << " orientations in 10 s";

      // Accuracy: estimates with sensor time in [t0 + 5 s, t0 + 15 s), matched to truth by timestamp.
      const std::uint64_t t0 = est.front().timestamp_ns;
      const std::uint64_t from = t0 + static_cast<std::uint64_t>(kSettle.count());
      const std::uint64_t to = from + static_cast<std::uint64_t>(kAccuracyWindow.count());
      const auto& truth = obs.truth[s];
      std::size_t in_window = 0, matched = 0;
      double max_err = 0.0, sum_sq = 0.0;
      std::uint64_t worst_t = 0;
      for (const auto& e : est) {
        if (e.timestamp_ns < from || e.timestamp_ns >= to) continue;
        ++in_window;
        auto it = truth.find(e.timestamp_ns);
        if (it == truth.end()) continue;
        ++matched;
        const double err = fusion::angle_between(dds::to_quat(e.quat), dds::to_quat(it->second)) * kRadToDeg;
        sum_sq += err * err;
        if (!(err <= max_err)) {  // also catches NaN
          max_err = err;
          worst_t = e.timestamp_ns;
        }
      }
      // 10 s of samples at >= 95 % of 100 Hz.
      EXPECT_GE(static_cast<double>(in_window), kMinRateShare * kRateHz * 10.0) << "estimates in the accuracy window";
      ASSERT_GT(in_window, 0u);
      EXPECT_GE(static_cast<double>(matched), kMinMatchedShare * static_cast<double>(in_window))
          << matched << " of " << in_window << " estimates found their truth sample";
      EXPECT_LT(max_err, kMaxErrorDeg) << "worst at sensor time t0 + " << static_cast<double>(worst_t - t0) * 1e-9
                                       << " s";
      std::printf("[ measure  ] %s: %.1f Hz, %zu/%zu matched, max error %.3f deg, rms %.3f deg\n", s.c_str(), rate,
                  matched, in_window, max_err, matched > 0 ? std::sqrt(sum_sq / static_cast<double>(matched)) : 0.0);
    }

    // Joint angles for both joints, from the right segments, at the child's rate.
    const std::map<std::string, std::array<std::string, 3>> expected_joints{{"j12", {"s1", "s2", "zyx"}},
                                                                            {"j23", {"s2", "s3", "zxy"}}};
    for (const auto& [joint, pcx] : expected_joints) {
      SCOPED_TRACE("joint " + joint);
      auto it = obs.joints.find(joint);
      ASSERT_NE(it, obs.joints.end()) << "no sample on " << dds::kJointAnglesTopic.name;
      const JointSeen& j = it->second;
      EXPECT_EQ(j.parent, pcx[0]);
      EXPECT_EQ(j.child, pcx[1]);
      EXPECT_EQ(j.axes, pcx[2]);
      EXPECT_TRUE(j.all_finite);
      const Clock::time_point first = j.arrivals.front();
      const std::size_t n = count_between(j.arrivals, first, first + kRateWindow);
      EXPECT_GE(static_cast<double>(n), kMinRateShare * kRateHz * 10.0) << "joint samples in 10 s";

      // Values, over the sensor-time window in which both segments' estimates are checked.
      const auto axes = fusion::parse_axis_sequence(j.axes);
      ASSERT_TRUE(axes.has_value());
      const std::uint64_t from =
          std::max(obs.estimates[j.parent].front().timestamp_ns, obs.estimates[j.child].front().timestamp_ns) +
          static_cast<std::uint64_t>(kSettle.count());
      const JointAccuracy a = joint_accuracy(j, obs.estimates[j.child], obs.truth[j.parent], obs.truth[j.child], from,
                                             from + static_cast<std::uint64_t>(kAccuracyWindow.count()), *axes);
      EXPECT_GE(static_cast<double>(a.in_window), kMinRateShare * kRateHz * 10.0) << "joints in the accuracy window";
      EXPECT_GE(static_cast<double>(a.matched), kMinMatchedShare * static_cast<double>(a.in_window))
          << a.matched << " of " << a.in_window << " joint samples found their child estimate and both truths";
      EXPECT_LT(a.max_error_deg, kMaxJointErrorDeg) << "joint quaternion";
      EXPECT_LT(a.max_angles_error_deg, kMaxJointErrorDeg) << "joint angles";
      std::printf("[ measure  ] %s: %zu/%zu matched, max error %.3f deg (quaternion), %.3f deg (angles)\n",
                  joint.c_str(), a.matched, a.in_window, a.max_error_deg, a.max_angles_error_deg);
    }
    EXPECT_EQ(obs.joints.size(), expected_joints.size()) << "unexpected joints on " << dds::kJointAnglesTopic.name;
  }

  stop_chain();
}

// A node whose process dies: the other segments keep their rate, and bsn/status reports the node stale within
// 1 s (stale timeout 0.3 s, status published at once on the change).
TEST_F(LiveSystem, StaleNode) {
  const int kDomain = test_domain(1);
  constexpr auto kAfterKill = 3s;
  constexpr auto kMaxStaleDelay = 1s;

  Observed obs;
  Subscriber sub(kDomain, obs);
  start_chain(kDomain);

  // Data flows for every segment and a status says no node is stale.
  ASSERT_TRUE(wait_until(
      [&] {
        for (const auto& s : kSegments)
          if (obs.estimate_count(s) < 100) return false;
        std::lock_guard lock(obs.mutex);
        if (obs.statuses.empty()) return false;
        const auto& nodes = obs.statuses.back().status.nodes();
        return nodes.size() == 3 && std::none_of(nodes.begin(), nodes.end(), [](const auto& n) { return n.stale(); });
      },
      20s))
      << "the chain did not reach a steady state (1 s of data on every segment, a status without stale nodes)";

  child("sim-n2").signal(SIGKILL);
  const auto killed = Clock::now();
  std::this_thread::sleep_until(killed + kAfterKill + 200ms);
  const auto st = child("sim-n2").wait_for(2s);
  EXPECT_TRUE(st && WIFSIGNALED(*st) && WTERMSIG(*st) == SIGKILL) << describe_status(st);

  {
    std::lock_guard lock(obs.mutex);
    for (const std::string s : {"s1", "s3"}) {
      const std::size_t n = count_between(obs.estimates[s], killed, killed + kAfterKill);
      const double rate = static_cast<double>(n) / std::chrono::duration<double>(kAfterKill).count();
      EXPECT_GE(rate, kMinRateShare * kRateHz)
          << "segment " << s << ": " << n << " orientations in the 3 s after the kill";
    }
    // The dead node's segment stops (allow samples already in flight at the kill).
    EXPECT_EQ(count_between(obs.estimates["s2"], killed + 200ms, Clock::now()), 0u)
        << "orientations of s2 after its node was killed";

    const StatusSeen* stale = nullptr;
    for (const auto& seen : obs.statuses) {
      if (seen.arrival < killed) continue;
      for (const auto& n : seen.status.nodes()) {
        if (n.node_id() == "n2" && n.stale()) stale = &seen;
      }
      if (stale) break;
    }
    ASSERT_NE(stale, nullptr) << "no status with n2 stale after the kill (" << obs.statuses.size() << " statuses)";
    const double delay = std::chrono::duration<double>(stale->arrival - killed).count();
    EXPECT_LE(delay, std::chrono::duration<double>(kMaxStaleDelay).count()) << "kill to stale report, s";
    for (const auto& n : stale->status.nodes()) {
      if (n.node_id() != "n2") {
        EXPECT_FALSE(n.stale()) << n.node_id() << " reported stale with n2";
      }
    }
    std::printf("[ measure  ] kill to stale report: %.3f s\n", delay);
  }

  stop_chain({"sim-n2"});
}

}  // namespace
}  // namespace bsn::integration
