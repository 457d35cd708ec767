// `bsn process`'s output streams: the samples of one topic, one stream per key, in a session file. The types that
// session_samples.hpp can rebuild from columns (orientations, joint angles) are written as columns alone, their
// text fields (the same in every sample of a stream) once as the stream's attributes; the others are serialised
// too, as `bsn record` writes them.
#pragma once

#include <fastdds/rtps/common/SerializedPayload.h>

#include <cstdint>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "bsn/io/session_file.hpp"
#include "sample_fields.hpp"
#include "session_columns.hpp"
#include "session_samples.hpp"

namespace bsn::services::process_detail {

template <class PubSub>
class TopicOutput {
 public:
  using T = typename PubSub::type;
  /// serialised: each sample also as CDR (a topic whose texts may differ between the samples of one key).
  TopicOutput(io::SessionWriter& writer, const char* topic, bool serialised = !kColumnsOnly<T>)
      : writer_(writer), topic_(topic), serialised_(serialised) {}
  /// Room for `rows` more samples of the stream `index` will have, so that appending them copies no buffer
  /// (effective once the stream exists, i.e. from its first sample on; before, it is noted for then).
  void reserve(std::size_t index, std::size_t rows) {
    if (index >= reserve_rows_.size()) reserve_rows_.resize(index + 1);
    reserve_rows_[index] = rows;
  }
  /// The writer's stream of `index`, if it has one yet.
  std::optional<std::size_t> stream_id(std::size_t index) const {
    if (index >= streams_.size() || !streams_[index]) return std::nullopt;
    return streams_[index]->id;
  }
  /// Streams are looked up by a small index the caller keeps (a segment), so a sample costs no string work. In a
  /// columns-only topic every sample of one index must have the texts of its first (FusionPipeline's outputs have
  /// their segment's or joint's, from the body), which the stream's attributes hold.
  void write(std::size_t index, const T& sample, std::uint64_t arrival_ns) {
    if (index >= streams_.size()) streams_.resize(index + 1);
    auto& s = streams_[index];
    if (!s) {
      s = add_stream(sample);
      if (index < reserve_rows_.size() && reserve_rows_[index] > 0) writer_.reserve(s->id, reserve_rows_[index]);
    }
    s->buffers[kArrivalColumn]->append_value(arrival_ns);
    if (serialised_) {
      if (!type_.serialize(const_cast<T*>(&sample), &payload_))
        throw io::IoError(std::string(topic_) + ": a sample does not serialise");
      s->buffers[kCdrColumn]->append(payload_.data, payload_.length);
      s->cdr_bytes += payload_.length;
      s->buffers[kCdrEndColumn]->append_value(s->cdr_bytes);
    }
    if constexpr (kColumnsOnly<T>) {
      if (s->direct) return s->direct->append(sample);
    }
    BufferAppendVisitor append(s->buffers.data(), serialised_ ? kFirstFieldColumn : kFirstFieldColumnWithoutCdr);
    visit_fields(sample, append);
  }

 private:
  struct NoDirectColumns {
    void append(const T&) const {}
  };
  using Direct = std::conditional_t<kColumnsOnly<T>, DirectColumns<T>, NoDirectColumns>;
  struct Stream {
    std::size_t id = 0;
    std::uint64_t cdr_bytes = 0;
    std::vector<io::ColumnBuffer*> buffers;  ///< its columns' buffers, in column order
    std::optional<Direct> direct;            ///< a columns-only stream's field columns
  };
  Stream add_stream(const T& sample) {
    ColumnSpecVisitor spec(serialised_);
    visit_fields(sample, spec);
    const std::string key = key_of(sample);
    Stream s;
    std::map<std::string, std::string> attributes;
    if (!serialised_) {
      const TextFields texts = text_fields(sample);
      attributes.insert(texts.begin(), texts.end());
    }
    s.id = writer_.add_stream(topic_, key.empty() ? "_" : key, type_.getName(), spec.specs, attributes);
    for (std::size_t c = 0; c < spec.specs.size(); ++c) s.buffers.push_back(&writer_.column_buffer(s.id, c));
    if constexpr (kColumnsOnly<T>) {
      if (!serialised_) {
        ColumnBinder bind(spec.specs, s.buffers.data(), kFirstFieldColumnWithoutCdr);
        s.direct.emplace(bind);
      }
    }
    return s;
  }
  io::SessionWriter& writer_;
  const char* topic_;
  bool serialised_;
  PubSub type_;
  eprosima::fastrtps::rtps::SerializedPayload_t payload_{64 * 1024};  // larger than any bsn sample
  std::vector<std::optional<Stream>> streams_;
  std::vector<std::size_t> reserve_rows_;
};

}  // namespace bsn::services::process_detail
