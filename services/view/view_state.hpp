// The state behind `bsn view`: the latest orientation, truth, joint angles and status it has seen, turned into the
// JSON messages the page reads. No DDS and no sockets here, so it is unit tested on its own.
//
// Messages (one JSON object each; the server sends them to a browser in arrays, one array per WebSocket frame):
//   {"k":"o","seg":S,"node":N,"ts":NS,"q":[w,x,y,z],"flags":F,"err":DEG|null}  orientation (err: to the truth of
//                                                                               the same sample in the same frame,
//                                                                               where known)
//   {"k":"t","seg":S,"ts":NS,"q":[w,x,y,z],"flags":F}                           truth, in the frame of the segment's
//                                                                               latest estimate (FLAG_SEGMENT_FRAME:
//                                                                               the ISB segment frame, else the sensor)
//   {"k":"j","joint":J,"parent":P,"child":C,"axes":A,"ts":NS,"deg":[a,b,c],"flags":F,
//    "anatomy":T,"side":S,"names":[n1,n2,n3],"anat":[a,b,c]}                   joint angles, degrees: the axis
//                                                                               sequence's, and the named anatomical
//                                                                               ones (names [] without an anatomy;
//                                                                               anatomy, side and names when they
//                                                                               change and once a second, and in the
//                                                                               snapshot)
//   {"k":"s","process":P,"nodes":[{"node":N,"seg":S,"rate":HZ,"stale":B,"calib":ID},...]}  status
// Orientations, truth and joint angles are passed on at most kMaxRateHz per segment (joint), on one fixed grid for
// all, so that a 100 Hz source gives the full rate and the messages of all segments come together.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "bsn_idl/bsn.h"

namespace bsn::services {

/// `text` as a JSON string literal (with the quotes). Bytes outside printable ASCII are escaped (\u00XX, read as
/// Latin-1), so the result is valid UTF-8 whatever the network sent: a browser closes a WebSocket on a text frame
/// that is not UTF-8.
std::string json_string(std::string_view text);

/// Angle of the rotation between two unit quaternions (w, x, y, z), degrees, in [0, 180].
double rotation_angle_deg(const std::array<double, 4>& a, const std::array<double, 4>& b);

class ViewState {
 public:
  static constexpr double kMaxRateHz = 30.0;
  /// Truth samples kept per segment to find the one of an estimate's timestamp (the estimate comes after it).
  static constexpr std::size_t kTruthHistory = 32;
  /// Names longer than this are cut (a hostile writer's key is not passed on whole).
  static constexpr std::size_t kMaxNameChars = 64;
  /// Segments, joints or status processes kept per kind; samples of further ones are dropped and counted.
  static constexpr std::size_t kMaxKeys = 256;

  /// Each returns the message to send now, or nothing (rate limit, or a rejected sample). `now_ns`: a monotonic
  /// clock.
  std::optional<std::string> on_orientation(const bsn::Orientation& o, std::uint64_t now_ns);
  /// A truth sample: bsn/truth/orientation (sensor frame) or bsn/truth/segment_orientation (FLAG_SEGMENT_FRAME).
  /// Passed on only in the frame of the segment's latest estimate.
  std::optional<std::string> on_truth(const bsn::Orientation& t, std::uint64_t now_ns);
  std::optional<std::string> on_joint(const bsn::JointAngles& j, std::uint64_t now_ns);
  std::optional<std::string> on_status(const bsn::Status& s);

  /// The latest message of every segment, truth, joint and status process: what a new browser gets first.
  std::vector<std::string> snapshot() const;

  /// Samples dropped because a value was not finite (never passed on as NaN).
  std::uint64_t rejected_non_finite() const { return rejected_non_finite_; }
  /// Samples dropped because kMaxKeys names of their kind were already known.
  std::uint64_t rejected_too_many_names() const { return rejected_too_many_names_; }

 private:
  struct Limited {
    std::uint64_t next_due_ns = 0;
    std::string latest;              ///< the last message sent (joints: with their names, for the snapshot)
    std::string names;               ///< joints: the "anatomy", "side" and "names" members last sent
    std::uint64_t names_due_ns = 0;  ///< joints: when they go again (a browser's queue may have dropped them)
  };
  /// True if a message of this slot may go now; moves it on to the next grid point.
  static bool due(Limited& slot, std::uint64_t now_ns);

  std::map<std::string, Limited> orientation_;
  std::map<std::string, Limited> truth_msg_;
  using TruthHistory = std::deque<std::pair<std::uint64_t, std::array<double, 4>>>;
  std::map<std::string, TruthHistory> truth_;          ///< sensor frames
  std::map<std::string, TruthHistory> segment_truth_;  ///< ISB segment frames
  std::map<std::string, bool> estimate_in_segment_frame_;
  std::map<std::string, Limited> joint_;
  std::map<std::string, std::string> status_;
  std::uint64_t rejected_non_finite_ = 0;
  std::uint64_t rejected_too_many_names_ = 0;
};

}  // namespace bsn::services
