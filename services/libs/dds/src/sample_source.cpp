#include "bsn/dds/sample_source.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace bsn::dds {
namespace {

template <std::size_t N>
bool all_finite(const std::array<double, N>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

fusion::SourceId source_id(const eprosima::fastrtps::rtps::GUID_t& writer) {
  fusion::SourceId id;
  std::copy(std::begin(writer.guidPrefix.value), std::end(writer.guidPrefix.value), id.bytes.begin());
  std::copy(std::begin(writer.entityId.value), std::end(writer.entityId.value), id.bytes.begin() + 12);
  return id;
}

std::string writer_name(const fusion::SourceId& writer) {
  std::string out;
  char part[4];
  for (std::size_t i = 0; i < 12; ++i) {
    std::snprintf(part, sizeof part, "%02x", writer.bytes[i]);
    out += (i ? "." : "") + std::string(part);
  }
  out += '|';
  for (std::size_t i = 12; i < 16; ++i) {
    std::snprintf(part, sizeof part, "%x", writer.bytes[i]);
    out += (i > 12 ? "." : "") + std::string(part);
  }
  return out;
}

std::string writer_name(const eprosima::fastrtps::rtps::GUID_t& writer) { return writer_name(source_id(writer)); }

std::size_t KeyWriters::note(const std::string& key, const eprosima::fastrtps::rtps::GUID_t& writer,
                             std::uint64_t now_ns) {
  auto it = keys_.find(key);
  if (it == keys_.end()) {
    if (keys_.size() >= kMaxKeys) return 1;
    it = keys_.emplace(key, std::vector<Heard>{}).first;
  }
  std::vector<Heard>& heard = it->second;
  std::erase_if(heard, [&](const Heard& h) { return h.writer != writer && now_ns - h.at_ns > window_ns_; });
  const auto self = std::find_if(heard.begin(), heard.end(), [&](const Heard& h) { return h.writer == writer; });
  if (self != heard.end()) {
    self->at_ns = now_ns;
  } else if (heard.size() < kMaxWritersPerKey) {
    heard.push_back({writer, now_ns});
  }
  return heard.size();
}

bool finite_values(const bsn::Orientation& o) {
  return all_finite(o.quat()) && std::isfinite(o.yaw()) && std::isfinite(o.pitch()) && std::isfinite(o.roll()) &&
         all_finite(o.gyro_bias());
}

bool finite_values(const bsn::JointAngles& j) {
  return all_finite(j.quat()) && all_finite(j.angles()) && all_finite(j.anatomical()) &&
         std::isfinite(j.heading_offset()) && std::isfinite(j.heading_observability());
}

}  // namespace bsn::dds
