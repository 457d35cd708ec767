// Session files (`bsn record`, `bsn replay`, `bsn export`): one HDF5 file, one group per topic and key
// (/bsn/raw/thigh_l, ...), each holding appendable columns (1-D, or N x width), and string attributes at the
// root for the metadata. This layer knows nothing of DDS or of the bsn types: the services say which columns a
// stream has. Layout of a stream group: attributes topic, key, type; datasets as registered, each with a unit
// attribute where one was given.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bsn/io/recording.hpp"

namespace bsn::io {

enum class ColumnType : std::uint8_t { kU8, kU32, kU64, kF64 };

/// Bytes of one element of `type`.
std::size_t column_type_size(ColumnType type);

struct ColumnSpec {
  std::string name;  ///< dataset name in the stream's group
  ColumnType type;
  int width = 1;     ///< values per row: 1 gives an N dataset, more an N x width one
  std::string unit;  ///< "" = none
};

/// How a writer's datasets are chunked. Live: small chunks (a recorder flushes every second and keeps one chunk per
/// dataset in memory). Bulk: a file written in a few large blocks (`bsn process`): each dataset's chunk is sized to
/// its first block (at most kBulkChunkBytes), so a dataset is a handful of chunks instead of hundreds; readers see
/// the same file either way.
enum class ChunkLayout : std::uint8_t { kLive, kBulk };

/// The bytes appended to one column and not yet written: a growing buffer whose append is a copy (no
/// initialisation of new bytes, no lookup), for writers that append every sample.
class ColumnBuffer {
 public:
  void append(const void* data, std::size_t bytes) {
    if (bytes == 0) return;
    if (size_ + bytes > capacity_) grow(size_ + bytes);
    std::memcpy(data_.get() + size_, data, bytes);
    size_ += bytes;
  }
  /// append() of a size known when compiling: inlined to a few stores where append() would call memcpy.
  template <std::size_t kBytes>
  void append_fixed(const void* data) {
    if (size_ + kBytes > capacity_) [[unlikely]]
      grow(size_ + kBytes);
    std::memcpy(data_.get() + size_, data, kBytes);
    size_ += kBytes;
  }
  template <class T>
  void append_value(const T& value) {
    append_fixed<sizeof value>(&value);
  }
  /// Empties the buffer and gives its memory back.
  void release() {
    data_.reset();
    size_ = capacity_ = 0;
  }
  /// Room for `bytes` in all without another allocation.
  void reserve(std::size_t bytes) {
    if (bytes > capacity_) grow(bytes);
  }
  const unsigned char* data() const { return data_.get(); }
  std::size_t size() const { return size_; }
  void clear() { size_ = 0; }
  void swap(ColumnBuffer& other) noexcept {
    data_.swap(other.data_);
    std::swap(size_, other.size_);
    std::swap(capacity_, other.capacity_);
  }

 private:
  void grow(std::size_t at_least);
  std::unique_ptr<unsigned char[]> data_;
  std::size_t size_ = 0, capacity_ = 0;
};

/// The value of the root attribute "format" that marks a bsn session file.
inline constexpr const char* kSessionFormat = "bsn-session";

/// Writes a session file. Appends only touch memory; write_staged() does every HDF5 call and flushes the file,
/// so a crash (kill -9) between two writes leaves the file as it was after the last one. Thread use: the caller
/// serialises add_stream, append and stage (e.g. under one mutex taken by its DDS callbacks); write_staged may run
/// on another thread meanwhile (it only touches what stage() handed over).
class SessionWriter {
 public:
  /// Creates `path` (an existing file is refused unless `overwrite`) with the root attributes `attributes` (plus
  /// format = kSessionFormat). Throws IoError naming the file.
  SessionWriter(const std::string& path, bool overwrite, const std::map<std::string, std::string>& attributes,
                ChunkLayout layout = ChunkLayout::kLive);
  ~SessionWriter();
  SessionWriter(const SessionWriter&) = delete;
  SessionWriter& operator=(const SessionWriter&) = delete;

  /// Registers the group /<topic>/<key> (the key escaped for HDF5: '/', '%' and a leading '.' as %XX) with its
  /// columns and string attributes of its own (besides topic, key and type); returns the stream's id. Its group is
  /// created at the next write_staged().
  std::size_t add_stream(const std::string& topic, const std::string& key, const std::string& type_name,
                         std::vector<ColumnSpec> columns, std::map<std::string, std::string> attributes = {});
  /// Appends `rows` rows of column `column` (rows x width elements of its type, contiguous).
  void append(std::size_t stream, std::size_t column, const void* data, std::size_t rows);
  /// The buffer that append() fills for a column: appending whole rows to it is appending to the column. Valid as
  /// long as the writer; the same serialisation rules as append().
  ColumnBuffer& column_buffer(std::size_t stream, std::size_t column);
  /// Room in every column of a stream for `rows` rows appended before the next stage(), so that appending them
  /// copies no buffer.
  void reserve(std::size_t stream, std::size_t rows);
  /// Gives back the memory of a stream's buffers (a stream that gets no more samples, after write_staged()); what
  /// was appended and not yet written is dropped.
  void release(std::size_t stream);
  /// Hands what was appended so far to the next write_staged(). Cheap (swaps buffers).
  void stage();
  /// Writes what stage() handed over, then flushes the file to disk. Before writing it checks the free space
  /// (file system and RLIMIT_FSIZE); when it does not suffice, or a write fails, it throws IoError saying so:
  /// the file then holds everything up to the last successful write_staged().
  void write_staged();
  /// stage() + write_staged() + close the file. Throws IoError on failure.
  void close();

  /// Size of the file on disk, bytes.
  std::uint64_t file_bytes() const;
  const std::string& path() const { return path_; }

 private:
  struct Column;
  struct Stream;
  void create_stream(Stream& s);
  std::string path_;
  void set_metadata_cache_size();  ///< to the datasets created so far
  unsigned long long chunk_rows(const Column& c, unsigned long long first_rows) const;
  ChunkLayout layout_;
  long long file_id_ = -1;
  std::size_t metadata_cache_bytes_ = 0;
  std::vector<std::unique_ptr<Stream>> streams_;
  std::vector<Stream*> staged_streams_;
};

/// One stream (topic and key) of a session file.
struct SessionStream {
  std::string topic;
  std::string key;
  std::string type;
  std::string group;                              ///< HDF5 path of its group
  std::map<std::string, std::string> attributes;  ///< the group's string attributes other than topic, key and type
};

/// Reads a session file. Every error names the file and the dataset.
class SessionReader {
 public:
  /// Throws IoError if `path` is not an HDF5 file or not a bsn session.
  explicit SessionReader(const std::string& path);
  ~SessionReader();
  SessionReader(const SessionReader&) = delete;
  SessionReader& operator=(const SessionReader&) = delete;

  const std::vector<SessionStream>& streams() const { return streams_; }
  /// Streams of one topic, in key order.
  std::vector<SessionStream> streams_of(const std::string& topic) const;
  /// Root attributes (the metadata).
  const std::map<std::string, std::string>& attributes() const { return attributes_; }
  bool has(const SessionStream& s, const std::string& dataset) const;
  /// Rows of a dataset (the first dimension).
  std::size_t rows(const SessionStream& s, const std::string& dataset) const;

  std::vector<std::uint8_t> read_u8(const SessionStream& s, const std::string& dataset) const;
  std::vector<std::uint32_t> read_u32(const SessionStream& s, const std::string& dataset) const;
  std::vector<std::uint64_t> read_u64(const SessionStream& s, const std::string& dataset) const;
  /// rows x width values, row-major; throws if the dataset's width is not `width`.
  std::vector<double> read_f64(const SessionStream& s, const std::string& dataset, int width) const;

  const std::string& path() const { return path_; }

 private:
  template <class T>
  std::vector<T> read(const SessionStream& s, const std::string& dataset, long long mem_type, int width) const;
  std::string path_;
  void set_metadata_cache_size();  ///< to the datasets created so far
  long long file_id_ = -1;
  std::size_t metadata_cache_bytes_ = 0;
  std::vector<SessionStream> streams_;
  std::map<std::string, std::string> attributes_;
};

/// True if `path` is an HDF5 file whose root attribute format is kSessionFormat.
bool is_session_file(const std::string& path);

}  // namespace bsn::io
