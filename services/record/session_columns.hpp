// The columns of a session file's stream, as `bsn record` writes them and `bsn process` writes them again: the
// arrival time, the serialised sample and its end offset, then the type's own fields (sample_fields.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
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

}  // namespace bsn::services
