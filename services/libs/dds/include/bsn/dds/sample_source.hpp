// Who wrote a sample: DDS writer GUIDs as the fusion core's opaque source ids and as text, per-key writer counts for
// readers of estimates (a key written by two writers at once is a conflict), and the finiteness of an estimate.
#pragma once

#include <fastdds/rtps/common/Guid.h>

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "bsn/fusion/body_fusion.hpp"
#include "bsn_idl/bsn.h"

namespace bsn::dds {

/// The writer GUID (12-byte prefix, 4-byte entity id) as the core's source id.
fusion::SourceId source_id(const eprosima::fastrtps::rtps::GUID_t& writer);

/// A writer GUID as Fast DDS prints it ("01.0f.3a.9c.52.11.00.00.01.00.00.00|0.0.1.3"), so logs match its tools.
std::string writer_name(const fusion::SourceId& writer);
std::string writer_name(const eprosima::fastrtps::rtps::GUID_t& writer);

/// Per key, the writers heard within the last `window_ns` on the arrival clock. One writer per key is how bsn
/// publishes; two at once are a second fusion service or a foreign writer. A writer that stopped (a restarted
/// service) drops out after the window, so a restart is not flagged for ever. Not thread-safe.
class KeyWriters {
 public:
  static constexpr std::size_t kMaxKeys = 4096;        ///< keys tracked; later ones are not (bounded memory)
  static constexpr std::size_t kMaxWritersPerKey = 8;  ///< more writers than this count as this many

  explicit KeyWriters(std::uint64_t window_ns = 1'000'000'000) : window_ns_(window_ns) {}

  /// Notes a sample of `key` from `writer` at `now_ns`; returns the writers of `key` heard within the window,
  /// this one included (1 for an untracked key).
  std::size_t note(const std::string& key, const eprosima::fastrtps::rtps::GUID_t& writer, std::uint64_t now_ns);

 private:
  struct Heard {
    eprosima::fastrtps::rtps::GUID_t writer;
    std::uint64_t at_ns = 0;
  };
  std::uint64_t window_ns_;
  std::unordered_map<std::string, std::vector<Heard>> keys_;
};

/// True when every number an estimate carries (quaternion, angles, gyro bias; a joint's anatomical angles and
/// kinematic heading too) is finite.
bool finite_values(const bsn::Orientation& o);
bool finite_values(const bsn::JointAngles& j);

}  // namespace bsn::dds
