// The columns of a session file's stream, as `bsn record` writes them and `bsn process` writes them again: the
// arrival time, the serialised sample and its end offset, then the type's own fields (sample_fields.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsn/io/session_file.hpp"
#include "sample_fields.hpp"

namespace bsn::services {

/// Columns every stream has, before the type's own fields; a columns-only stream (session_samples.hpp) has the
/// arrival time only, its fields start at kFirstFieldColumnWithoutCdr.
enum : std::size_t { kArrivalColumn, kCdrColumn, kCdrEndColumn, kFirstFieldColumn };
inline constexpr std::size_t kFirstFieldColumnWithoutCdr = 1;

/// Collects a stream's column specs from one sample of its type.
class ColumnSpecVisitor : public FieldVisitor {
 public:
  /// serialised: with the cdr and cdr_end columns.
  explicit ColumnSpecVisitor(bool serialised = true) {
    if (!serialised) specs.erase(specs.begin() + kFirstFieldColumnWithoutCdr, specs.end());
  }
  std::vector<io::ColumnSpec> specs{{"arrival_ns", io::ColumnType::kU64, 1, "ns since 1970 (UTC), recorder clock"},
                                    {"cdr", io::ColumnType::kU8, 1, "XCDR1 serialised samples, concatenated"},
                                    {"cdr_end", io::ColumnType::kU64, 1, "end offset of each sample in cdr"}};
  void key(const char*, const std::string&) override {}
  void text(const char*, const std::string&) override {}
  void u64(const char* name, const char* unit, std::uint64_t) override {
    specs.push_back({name, io::ColumnType::kU64, 1, unit});
  }
  void u32(const char* name, const char* unit, std::uint32_t) override {
    specs.push_back({name, io::ColumnType::kU32, 1, unit});
  }
  void f64(const char* name, const char* unit, const double*, int n) override {
    specs.push_back({name, io::ColumnType::kF64, n, unit});
  }
};

/// Appends one sample's fields to its stream's columns, from `first_column` on.
class AppendVisitor : public FieldVisitor {
 public:
  AppendVisitor(io::SessionWriter& w, std::size_t stream, std::size_t first_column = kFirstFieldColumn)
      : writer_(w), stream_(stream), column_(first_column) {}
  void key(const char*, const std::string&) override {}
  void text(const char*, const std::string&) override {}
  void u64(const char*, const char*, std::uint64_t value) override { writer_.append(stream_, column_++, &value, 1); }
  void u32(const char*, const char*, std::uint32_t value) override { writer_.append(stream_, column_++, &value, 1); }
  void f64(const char*, const char*, const double* values, int) override {
    writer_.append(stream_, column_++, values, 1);
  }

 private:
  io::SessionWriter& writer_;
  std::size_t stream_;
  std::size_t column_;
};

/// AppendVisitor for a writer that appends every sample: straight into the columns' buffers (`buffers[k]`: the
/// stream's column k, from SessionWriter::column_buffer), from `first_column` on.
class BufferAppendVisitor : public FieldVisitor {
 public:
  BufferAppendVisitor(io::ColumnBuffer* const* buffers, std::size_t first_column)
      : buffers_(buffers), column_(first_column) {}
  void key(const char*, const std::string&) override {}
  void text(const char*, const std::string&) override {}
  void u64(const char*, const char*, std::uint64_t value) override { buffers_[column_++]->append_value(value); }
  void u32(const char*, const char*, std::uint32_t value) override { buffers_[column_++]->append_value(value); }
  void f64(const char*, const char*, const double* values, int n) override {
    buffers_[column_++]->append(values, sizeof(double) * static_cast<std::size_t>(n));
  }

 private:
  io::ColumnBuffer* const* buffers_;
  std::size_t column_;
};

/// Binds a stream's field columns by name to their buffers, for writers that append straight into the buffers
/// (DirectColumns). Every field column must be bound, each to a name and a row size the caller expects, so a field
/// that visit_fields adds, renames or retypes is an error when the stream is created, never a column left short.
class ColumnBinder {
 public:
  /// specs: the stream's columns (ColumnSpecVisitor); buffers[k]: column k's; fields from `first_column` on.
  ColumnBinder(const std::vector<io::ColumnSpec>& specs, io::ColumnBuffer* const* buffers, std::size_t first_column)
      : specs_(specs), buffers_(buffers), first_(first_column) {}
  io::ColumnBuffer* operator()(const char* name, std::size_t row_bytes) {
    for (std::size_t c = first_; c < specs_.size(); ++c) {
      if (specs_[c].name != name) continue;
      if (io::column_type_size(specs_[c].type) * static_cast<std::size_t>(specs_[c].width) != row_bytes)
        throw std::logic_error("column '" + specs_[c].name + "' has another row size than its direct writer's");
      ++bound_;
      return buffers_[c];
    }
    throw std::logic_error(std::string("no column '") + name + "' for its direct writer");
  }
  void check_all_bound() const {
    if (first_ + bound_ != specs_.size())
      throw std::logic_error("a stream has columns that its direct writer does not fill (sample_fields.cpp changed?)");
  }

 private:
  const std::vector<io::ColumnSpec>& specs_;
  io::ColumnBuffer* const* buffers_;
  std::size_t first_, bound_ = 0;
};

/// The field columns of the types `bsn process` writes a sample of per input sample, appended by plain stores into
/// their buffers: the same bytes as BufferAppendVisitor over visit_fields, without a virtual call per field.
template <class T>
struct DirectColumns;

template <>
struct DirectColumns<bsn::Orientation> {
  explicit DirectColumns(ColumnBinder& bind)
      : timestamp(bind("timestamp_ns", 8)),
        quat(bind("quat", 32)),
        yaw(bind("yaw", 8)),
        pitch(bind("pitch", 8)),
        roll(bind("roll", 8)),
        gyro_bias(bind("gyro_bias", 24)),
        flags(bind("flags", 4)) {
    bind.check_all_bound();
  }
  void append(const bsn::Orientation& s) const {
    timestamp->append_value(static_cast<std::uint64_t>(s.timestamp_ns()));
    quat->append_fixed<32>(s.quat().data());
    yaw->append_value(s.yaw());
    pitch->append_value(s.pitch());
    roll->append_value(s.roll());
    gyro_bias->append_fixed<24>(s.gyro_bias().data());
    flags->append_value(static_cast<std::uint32_t>(s.flags()));
  }
  io::ColumnBuffer *timestamp, *quat, *yaw, *pitch, *roll, *gyro_bias, *flags;
};

template <>
struct DirectColumns<bsn::JointAngles> {
  explicit DirectColumns(ColumnBinder& bind)
      : timestamp(bind("timestamp_ns", 8)),
        quat(bind("quat", 32)),
        angles(bind("angles", 24)),
        flags(bind("flags", 4)),
        anatomical{bind("anatomical_0", 8), bind("anatomical_1", 8), bind("anatomical_2", 8)},
        heading_offset(bind("heading_offset", 8)),
        heading_observability(bind("heading_observability", 8)) {
    bind.check_all_bound();
  }
  void append(const bsn::JointAngles& s) const {
    timestamp->append_value(static_cast<std::uint64_t>(s.timestamp_ns()));
    quat->append_fixed<32>(s.quat().data());
    angles->append_fixed<24>(s.angles().data());
    flags->append_value(static_cast<std::uint32_t>(s.flags()));
    for (std::size_t i = 0; i < 3; ++i) anatomical[i]->append_value(s.anatomical()[i]);
    heading_offset->append_value(s.heading_offset());
    heading_observability->append_value(s.heading_observability());
  }
  io::ColumnBuffer *timestamp, *quat, *angles, *flags, *anatomical[3], *heading_offset, *heading_observability;
};

}  // namespace bsn::services
