// The samples of a session file's stream as bsn types, whichever way the stream holds them: serialised (the `cdr`
// and `cdr_end` columns beside the typed ones, as `bsn record` writes every stream) or as typed columns alone (a
// stream of a type listed by rebuilt_from_columns, whose text fields are the same in every sample and stored once
// as attributes of the stream's group, as `bsn process` writes its orientations and joint angles: half the bytes,
// and no serialisation per sample).
#pragma once

#include <fastdds/rtps/common/SerializedPayload.h>

#include <map>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "bsn_idl/bsnPubSubTypes.h"
#include "sample_fields.hpp"

namespace bsn::services {

/// Types whose samples a stream may hold as columns alone: every field a column, or a text stored once.
template <class T>
inline constexpr bool kColumnsOnly = std::is_same_v<T, bsn::Orientation> || std::is_same_v<T, bsn::JointAngles>;

/// A sample's text fields (not its key) in visit order, name and value: a columns-only stream's group attributes.
using TextFields = std::vector<std::pair<std::string, std::string>>;

template <class T>
TextFields text_fields(const T& sample) {
  struct Texts : FieldVisitor {
    TextFields out;
    void key(const char*, const std::string&) override {}
    void text(const char* name, const std::string& value) override { out.emplace_back(name, value); }
    void u64(const char*, const char*, std::uint64_t) override {}
    void u32(const char*, const char*, std::uint32_t) override {}
    void f64(const char*, const char*, const double*, int) override {}
  } texts;
  visit_fields(sample, texts);
  return std::move(texts.out);
}

/// The samples of a columns-only stream, rebuilt from its columns and its group's attributes. Throws io::IoError
/// naming the file and the dataset.
std::vector<bsn::Orientation> orientations_from_columns(const io::SessionReader& r, const io::SessionStream& s);
std::vector<bsn::JointAngles> joint_angles_from_columns(const io::SessionReader& r, const io::SessionStream& s);

/// Every sample of a stream, in the order written; `arrival` (when given) gets each sample's arrival_ns.
/// Throws io::IoError naming the file and the dataset.
template <class PubSub>
std::vector<typename PubSub::type> read_stream_samples(const io::SessionReader& r, const io::SessionStream& s,
                                                       std::vector<std::uint64_t>* arrival = nullptr) {
  using T = typename PubSub::type;
  std::vector<T> out;
  if (!r.has(s, "cdr")) {
    if constexpr (std::is_same_v<T, bsn::Orientation>) {
      out = orientations_from_columns(r, s);
    } else if constexpr (std::is_same_v<T, bsn::JointAngles>) {
      out = joint_angles_from_columns(r, s);
    } else {
      throw io::IoError(r.path() + ": '" + s.group + "' holds no serialised samples ('cdr')");
    }
  } else {
    const auto cdr = r.read_u8(s, "cdr");
    const auto ends = r.read_u64(s, "cdr_end");
    out.reserve(ends.size());
    PubSub type;
    std::uint64_t begin = 0;
    for (const std::uint64_t end : ends) {
      if (end < begin || end > cdr.size() || end - begin > (1u << 20)) {
        throw io::IoError(r.path() + ": dataset '" + s.group + "/cdr_end' points outside '" + s.group + "/cdr'");
      }
      eprosima::fastrtps::rtps::SerializedPayload_t payload(static_cast<std::uint32_t>(end - begin));
      std::copy(cdr.begin() + static_cast<long>(begin), cdr.begin() + static_cast<long>(end), payload.data);
      payload.length = static_cast<std::uint32_t>(end - begin);
      T sample;
      if (!type.deserialize(&payload, &sample)) {
        throw io::IoError(r.path() + ": a sample in '" + s.group + "/cdr' does not deserialise as " + s.type);
      }
      out.push_back(std::move(sample));
      begin = end;
    }
  }
  if (arrival) {
    *arrival = r.read_u64(s, "arrival_ns");
    if (arrival->size() != out.size())
      throw io::IoError(r.path() + ": '" + s.group + "/arrival_ns' and the samples of '" + s.group +
                        "' differ in length");
  }
  return out;
}

}  // namespace bsn::services
