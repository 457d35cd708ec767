#include "bsn/io/session_file.hpp"

#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <cstring>
#include <filesystem>

#include "hdf5_handle.hpp"

namespace bsn::io {

using hdf5::Handle;

namespace {

// Live: rows per chunk: at 100 Hz about 5 s per chunk, small enough that a 64-segment body's thousand-odd open
// datasets stay a few MB of chunk cache, large enough that indexing costs little.
constexpr hsize_t kChunkRows = 512;
// A byte column (serialised samples) holds about 100 bytes per sample: its chunks hold about as many samples.
hsize_t live_chunk_rows(ColumnType t) { return t == ColumnType::kU8 ? kChunkRows * 64 : kChunkRows; }
// Bulk: a chunk holds the dataset's first block, between kBulkMinChunkRows rows (a stream of a few rows, e.g. one
// bsn/status, stays a few KB) and kBulkChunkBytes (a chunk is read whole: 4 MiB keeps a reader's memory small).
// Each chunk costs HDF5 a B-tree insertion and a write of its own; with live chunks a 10-minute 7-segment body is
// about 30,000 of them.
constexpr hsize_t kBulkMinChunkRows = 1024;
constexpr hsize_t kBulkChunkBytes = 4u << 20;

// Half the most chunks a chunk-index B-tree node holds (HDF5's "istore_k"; its default is 32).
constexpr unsigned kChunkIndexK = 8;
// What the metadata cache holds per dataset: the nodes an append walks (root, one inner, the leaf being filled)
// and the object header, in the cache's own accounting (the size in the file; in memory they take several times
// that). Beyond it, least recently used first, the cache lets go of full nodes no append needs again.
constexpr std::size_t kMetadataCacheBytesPerDataset = 3 * 1024;
constexpr std::size_t kMinMetadataCacheBytes = 1 << 20;

// Space kept free beyond the data of one write, for the metadata HDF5 writes with it.
constexpr std::uint64_t kMetadataMargin = 1u << 20;

hid_t file_type(ColumnType t) {
  switch (t) {
    case ColumnType::kU8:
      return H5T_STD_U8LE;
    case ColumnType::kU32:
      return H5T_STD_U32LE;
    case ColumnType::kU64:
      return H5T_STD_U64LE;
    case ColumnType::kF64:
      return H5T_IEEE_F64LE;
  }
  return H5T_STD_U8LE;
}

hid_t memory_type(ColumnType t) {
  switch (t) {
    case ColumnType::kU8:
      return H5T_NATIVE_UINT8;
    case ColumnType::kU32:
      return H5T_NATIVE_UINT32;
    case ColumnType::kU64:
      return H5T_NATIVE_UINT64;
    case ColumnType::kF64:
      return H5T_NATIVE_DOUBLE;
  }
  return H5T_NATIVE_UINT8;
}

std::string escape_key(const std::string& key) {
  std::string out;
  for (std::size_t i = 0; i < key.size(); ++i) {
    const char c = key[i];
    if (c == '/' || c == '%' || (i == 0 && c == '.') || static_cast<unsigned char>(c) < 0x20) {
      static const char* hex = "0123456789ABCDEF";
      out += '%';
      out += hex[(static_cast<unsigned char>(c) >> 4) & 0xF];
      out += hex[static_cast<unsigned char>(c) & 0xF];
    } else {
      out += c;
    }
  }
  return out.empty() ? "%" : out;
}

bool write_string_attribute(hid_t object, const std::string& name, const std::string& value) {
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), std::max<std::size_t>(value.size(), 1));
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(object, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  return attr.ok() && H5Awrite(attr.get(), type.get(), padded.data()) >= 0;
}

bool read_string_attribute(hid_t object, const char* name, std::string& out) {
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) return false;
  Handle type(H5Aget_type(attr.get()), H5Tclose);
  if (H5Tget_class(type.get()) != H5T_STRING || H5Tis_variable_str(type.get()) > 0) return false;
  const std::size_t n = H5Tget_size(type.get());
  std::string buf(n, '\0');
  Handle mem(H5Tcopy(type.get()), H5Tclose);
  if (H5Aread(attr.get(), mem.get(), buf.data()) < 0) return false;
  buf.resize(std::strlen(buf.c_str()));
  out = buf;
  return true;
}

std::uint64_t size_of_file(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 ? static_cast<std::uint64_t>(st.st_size) : 0;
}

// Bytes the file may still grow by: the file system's free space and the process's file size limit.
std::uint64_t headroom(const std::string& path) {
  std::uint64_t room = UINT64_MAX;
  const std::string dir = std::filesystem::path(path).parent_path().string();
  struct statvfs vfs {};
  if (::statvfs(dir.empty() ? "." : dir.c_str(), &vfs) == 0) {
    room = static_cast<std::uint64_t>(vfs.f_bavail) * static_cast<std::uint64_t>(vfs.f_frsize);
  }
  struct rlimit lim {};
  if (::getrlimit(RLIMIT_FSIZE, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY) {
    const std::uint64_t size = size_of_file(path);
    room = std::min<std::uint64_t>(room, lim.rlim_cur > size ? lim.rlim_cur - size : 0);
  }
  return room;
}

}  // namespace

std::size_t column_type_size(ColumnType type) {
  switch (type) {
    case ColumnType::kU8:
      return 1;
    case ColumnType::kU32:
      return 4;
    case ColumnType::kU64:
    case ColumnType::kF64:
      return 8;
  }
  return 1;
}

struct SessionWriter::Column {
  ColumnSpec spec;
  ColumnBuffer pending;  // appended, not yet staged
  ColumnBuffer staged;   // handed to the next write
  Handle dataset;
  hsize_t chunk = 0;  // rows per chunk, set when the dataset is created
  hsize_t rows_written = 0;
  std::size_t row_bytes() const { return column_type_size(spec.type) * static_cast<std::size_t>(spec.width); }
};

struct SessionWriter::Stream {
  std::string topic, key, type;
  std::map<std::string, std::string> attributes;
  std::vector<Column> columns;
  Handle group;
};

SessionWriter::SessionWriter(const std::string& path, bool overwrite,
                             const std::map<std::string, std::string>& attributes, ChunkLayout layout)
    : path_(path), layout_(layout) {
  hdf5::quiet_errors();
  if (!overwrite && std::filesystem::exists(path)) {
    throw IoError(path + ": file exists; give --overwrite to replace it");
  }
  // The library's earliest file format on purpose: HDF5 1.10's own (superblock 3) marks a file as open for writing
  // until it is closed, and a recording cut by a crash then no longer opens without `h5clear`.
  // Small chunk-index nodes: HDF5 holds each B-tree node in memory with room for all its keys (~270 bytes each, of
  // which the file stores ~30), so the default of 64 chunks per node made every dataset's node 17 KB, filled page
  // by page as chunks were added (RSS +0.12 MB/s for a 64-segment body) and split into two after 64 chunks (+45 MB
  // at once, 5 minutes in). Eight keys per node (16 chunks) keep the nodes an append uses small, and the metadata
  // cache, sized to the datasets (set_metadata_cache_size), lets the full ones go.
  const Handle fcpl(H5Pcreate(H5P_FILE_CREATE), H5Pclose);
  if (!fcpl.ok() || H5Pset_istore_k(fcpl.get(), kChunkIndexK) < 0) throw IoError(path + ": cannot set up HDF5");
  file_id_ = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT);
  if (file_id_ < 0) throw IoError(path + ": cannot create HDF5 file");
  set_metadata_cache_size();
  std::map<std::string, std::string> attrs = attributes;
  attrs["format"] = kSessionFormat;
  for (const auto& [name, value] : attrs) {
    if (!write_string_attribute(file_id_, name, value)) {
      throw IoError(path + ": cannot write attribute '" + name + "'");
    }
  }
  if (H5Fflush(file_id_, H5F_SCOPE_GLOBAL) < 0) throw IoError(path + ": cannot write the file");
}

SessionWriter::~SessionWriter() {
  for (auto& s : streams_) {
    for (auto& c : s->columns) c.dataset.reset();
    s->group.reset();
  }
  if (file_id_ >= 0) H5Fclose(file_id_);
}

std::size_t SessionWriter::add_stream(const std::string& topic, const std::string& key, const std::string& type_name,
                                      std::vector<ColumnSpec> columns, std::map<std::string, std::string> attributes) {
  auto s = std::make_unique<Stream>();
  s->topic = topic;
  s->key = key;
  s->type = type_name;
  s->attributes = std::move(attributes);
  for (auto& spec : columns) {
    Column c;
    c.spec = std::move(spec);
    s->columns.push_back(std::move(c));
  }
  streams_.push_back(std::move(s));
  return streams_.size() - 1;
}

void SessionWriter::append(std::size_t stream, std::size_t column, const void* data, std::size_t rows) {
  Column& c = streams_.at(stream)->columns.at(column);
  const auto* bytes = static_cast<const unsigned char*>(data);
  c.pending.append(bytes, rows * c.row_bytes());
}

ColumnBuffer& SessionWriter::column_buffer(std::size_t stream, std::size_t column) {
  return streams_.at(stream)->columns.at(column).pending;
}

void SessionWriter::reserve(std::size_t stream, std::size_t rows) {
  for (Column& c : streams_.at(stream)->columns) c.pending.reserve(rows * c.row_bytes());
}

void SessionWriter::release(std::size_t stream) {
  for (Column& c : streams_.at(stream)->columns) {
    c.pending.release();
    c.staged.release();
  }
}

void ColumnBuffer::grow(std::size_t at_least) {
  const std::size_t capacity = std::max<std::size_t>({at_least, 2 * capacity_, 4096});
  std::unique_ptr<unsigned char[]> data(new unsigned char[capacity]);
  if (size_ > 0) std::memcpy(data.get(), data_.get(), size_);
  data_ = std::move(data);
  capacity_ = capacity;
}

void SessionWriter::stage() {
  staged_streams_.clear();
  for (auto& s : streams_) {
    for (auto& c : s->columns) {
      // `staged` is empty here (write_staged clears it), so the swap hands over the data and keeps the capacity.
      c.staged.swap(c.pending);
      // Bulk: the next block as large as this one gets the same room at once instead of growing into it.
      if (layout_ == ChunkLayout::kBulk) c.pending.reserve(c.staged.size());
    }
    staged_streams_.push_back(s.get());
  }
}

void SessionWriter::create_stream(Stream& s) {
  const std::string group_path = "/" + s.topic + "/" + escape_key(s.key);
  Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  H5Pset_create_intermediate_group(lcpl.get(), 1);
  Handle gcpl(H5Pcreate(H5P_GROUP_CREATE), H5Pclose);
  H5Pset_obj_track_times(gcpl.get(), false);
  s.group = Handle(H5Gcreate2(file_id_, group_path.c_str(), lcpl.get(), gcpl.get(), H5P_DEFAULT), H5Gclose);
  if (!s.group.ok()) throw IoError(path_ + ": cannot create group '" + group_path + "'");
  if (!write_string_attribute(s.group.get(), "topic", s.topic) ||
      !write_string_attribute(s.group.get(), "key", s.key) || !write_string_attribute(s.group.get(), "type", s.type)) {
    throw IoError(path_ + ": cannot write the attributes of '" + group_path + "'");
  }
  for (const auto& [name, value] : s.attributes) {
    if (!write_string_attribute(s.group.get(), name, value))
      throw IoError(path_ + ": cannot write the attribute '" + name + "' of '" + group_path + "'");
  }
  for (Column& c : s.columns) {
    const int rank = c.spec.width > 1 ? 2 : 1;
    const hsize_t dims[2] = {0, static_cast<hsize_t>(c.spec.width)};
    const hsize_t maxdims[2] = {H5S_UNLIMITED, static_cast<hsize_t>(c.spec.width)};
    c.chunk = chunk_rows(c, c.staged.size() / c.row_bytes());
    const hsize_t chunk[2] = {c.chunk, static_cast<hsize_t>(c.spec.width)};
    Handle space(H5Screate_simple(rank, dims, maxdims), H5Sclose);
    Handle dcpl(hdf5::untimed_dataset_properties(), H5Pclose);
    H5Pset_chunk(dcpl.get(), rank, chunk);
    // A chunk cache for the chunk being filled and no more: the default (1 MiB per dataset) keeps every chunk
    // written, and a 64-segment body's thousands of datasets then grow the recorder by megabytes a second.
    std::size_t cache_bytes = 2 * chunk[0] * chunk[1] * column_type_size(c.spec.type);
    if (layout_ == ChunkLayout::kBulk) {
      // Bulk: no chunk cache and no fill value, so HDF5 writes each block from the caller's buffer straight into
      // the file (H5D__chunk_cacheable: a chunk larger than the cache, with nothing to fill, bypasses it) instead
      // of filling a cached chunk with the fill value, copying the block into it and writing that. Every row up to
      // the dataset's extent is written, so no reader sees an unfilled byte.
      H5Pset_fill_time(dcpl.get(), H5D_FILL_TIME_NEVER);
      cache_bytes = 0;
    }
    Handle dapl(H5Pcreate(H5P_DATASET_ACCESS), H5Pclose);
    H5Pset_chunk_cache(dapl.get(), 11, cache_bytes, 1.0);
    c.dataset = Handle(H5Dcreate2(s.group.get(), c.spec.name.c_str(), file_type(c.spec.type), space.get(), H5P_DEFAULT,
                                  dcpl.get(), dapl.get()),
                       H5Dclose);
    if (!c.dataset.ok()) throw IoError(path_ + ": cannot create dataset '" + group_path + "/" + c.spec.name + "'");
    if (!c.spec.unit.empty() && !write_string_attribute(c.dataset.get(), "unit", c.spec.unit)) {
      throw IoError(path_ + ": cannot write the unit of '" + group_path + "/" + c.spec.name + "'");
    }
  }
}

unsigned long long SessionWriter::chunk_rows(const Column& c, unsigned long long first_rows) const {
  if (layout_ == ChunkLayout::kLive) return live_chunk_rows(c.spec.type);
  const hsize_t most = std::max<hsize_t>(1, kBulkChunkBytes / c.row_bytes());
  return std::min(most, std::max<hsize_t>(first_rows, kBulkMinChunkRows));
}

void SessionWriter::set_metadata_cache_size() {
  std::size_t datasets = 0;
  for (const auto& st : streams_) datasets += st->columns.size();
  const std::size_t bytes = std::max(kMinMetadataCacheBytes, datasets * kMetadataCacheBytesPerDataset);
  if (bytes == metadata_cache_bytes_) return;
  H5AC_cache_config_t config;
  config.version = H5AC__CURR_CACHE_CONFIG_VERSION;
  if (H5Fget_mdc_config(file_id_, &config) < 0) throw IoError(path_ + ": cannot read the metadata cache settings");
  // A fixed size: HDF5's adaptive modes let the cache grow to 32 MB in its accounting, several times that in memory.
  config.set_initial_size = true;
  config.initial_size = config.min_size = config.max_size = bytes;
  config.incr_mode = H5C_incr__off;
  config.flash_incr_mode = H5C_flash_incr__off;
  config.decr_mode = H5C_decr__off;
  if (H5Fset_mdc_config(file_id_, &config) < 0) throw IoError(path_ + ": cannot size the metadata cache");
  metadata_cache_bytes_ = bytes;
}

void SessionWriter::write_staged() {
  if (file_id_ < 0) throw IoError(path_ + ": the file is closed");
  // What this write adds to the file: HDF5 allocates whole chunks, so count the chunks the new rows start.
  std::uint64_t bytes = 0;
  for (const Stream* s : staged_streams_) {
    for (const Column& c : s->columns) {
      const hsize_t rows = c.staged.size() / c.row_bytes();
      if (rows == 0) continue;
      const hsize_t chunk = c.chunk ? c.chunk : chunk_rows(c, rows);
      const hsize_t before = (c.rows_written + chunk - 1) / chunk, after = (c.rows_written + rows + chunk - 1) / chunk;
      bytes += (after - before) * chunk * c.row_bytes();
    }
  }
  const std::uint64_t room = headroom(path_);
  if (room < bytes + kMetadataMargin) {
    throw IoError(path_ + ": disk full (" + std::to_string(room) + " bytes left for the file, " +
                  std::to_string(bytes) + " to write): the file holds everything up to the last flush");
  }
  bool created = false;
  for (Stream* s : staged_streams_) {
    if (!s->group.ok()) {
      create_stream(*s);
      created = true;
    }
  }
  if (created) set_metadata_cache_size();
  for (Stream* s : staged_streams_) {
    for (Column& c : s->columns) {
      const hsize_t rows = c.staged.size() / c.row_bytes();
      if (rows == 0) continue;
      const int rank = c.spec.width > 1 ? 2 : 1;
      const hsize_t width = static_cast<hsize_t>(c.spec.width);
      const hsize_t new_dims[2] = {c.rows_written + rows, width};
      const hsize_t start[2] = {c.rows_written, 0};
      const hsize_t count[2] = {rows, width};
      bool ok = H5Dset_extent(c.dataset.get(), new_dims) >= 0;
      Handle file_space(H5Dget_space(c.dataset.get()), H5Sclose);
      Handle mem_space(H5Screate_simple(rank, count, nullptr), H5Sclose);
      ok = ok && file_space.ok() &&
           H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) >= 0 &&
           H5Dwrite(c.dataset.get(), memory_type(c.spec.type), mem_space.get(), file_space.get(), H5P_DEFAULT,
                    c.staged.data()) >= 0;
      if (!ok) {
        throw IoError(path_ + ": cannot write dataset '/" + s->topic + "/" + escape_key(s->key) + "/" + c.spec.name +
                      "' (disk full or file size limit?): the file holds everything up to the last flush");
      }
      c.rows_written += rows;
      c.staged.clear();
    }
  }
  staged_streams_.clear();
  if (H5Fflush(file_id_, H5F_SCOPE_GLOBAL) < 0) {
    throw IoError(path_ + ": cannot flush the file (disk full or file size limit?)");
  }
}

void SessionWriter::close() {
  if (file_id_ < 0) return;
  stage();
  write_staged();
  for (auto& s : streams_) {
    for (auto& c : s->columns) c.dataset.reset();
    s->group.reset();
  }
  const hid_t id = file_id_;
  file_id_ = -1;
  if (H5Fclose(id) < 0) throw IoError(path_ + ": cannot close the file");
}

std::uint64_t SessionWriter::file_bytes() const { return size_of_file(path_); }

// ---------------------------------------------------------------------------------------------------------------

namespace {

struct VisitState {
  hid_t file;
  std::vector<SessionStream>* streams;
};

herr_t collect_attribute(hid_t object, const char* name, const H5A_info_t*, void* data) {
  auto* out = static_cast<std::map<std::string, std::string>*>(data);
  std::string value;
  if (read_string_attribute(object, name, value)) (*out)[name] = value;
  return 0;
}

herr_t visit_link(hid_t, const char* name, const H5L_info_t* info, void* data) {
  auto* state = static_cast<VisitState*>(data);
  if (info->type != H5L_TYPE_HARD) return 0;
  Handle object(H5Oopen(state->file, name, H5P_DEFAULT), H5Oclose);
  if (!object.ok()) return 0;
  H5O_info_t oinfo;
  if (H5Oget_info2(object.get(), &oinfo, H5O_INFO_BASIC) < 0 || oinfo.type != H5O_TYPE_GROUP) return 0;
  SessionStream s;
  if (!read_string_attribute(object.get(), "topic", s.topic)) return 0;
  read_string_attribute(object.get(), "key", s.key);
  read_string_attribute(object.get(), "type", s.type);
  hsize_t index = 0;
  H5Aiterate2(object.get(), H5_INDEX_NAME, H5_ITER_INC, &index, collect_attribute, &s.attributes);
  for (const char* own : {"topic", "key", "type"}) s.attributes.erase(own);
  s.group = std::string("/") + name;
  state->streams->push_back(std::move(s));
  return 0;
}

}  // namespace

SessionReader::SessionReader(const std::string& path) : path_(path) {
  hdf5::quiet_errors();
  if (!std::filesystem::exists(path)) throw FormatError(path + ": no such file");
  if (H5Fis_hdf5(path.c_str()) <= 0) throw FormatError(path + ": not an HDF5 file (or truncated)");
  file_id_ = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file_id_ < 0) throw FormatError(path + ": cannot open as HDF5 (truncated or damaged?)");
  hsize_t index = 0;
  H5Aiterate2(file_id_, H5_INDEX_NAME, H5_ITER_INC, &index, collect_attribute, &attributes_);
  if (attributes_.count("format") == 0 || attributes_.at("format") != kSessionFormat) {
    throw FormatError(path + ": not a bsn session file (root attribute 'format' is not '" + kSessionFormat + "')");
  }
  VisitState state{file_id_, &streams_};
  if (H5Lvisit(file_id_, H5_INDEX_NAME, H5_ITER_INC, visit_link, &state) < 0) {
    throw FormatError(path + ": cannot list the groups (truncated or damaged?)");
  }
  std::sort(streams_.begin(), streams_.end(),
            [](const SessionStream& a, const SessionStream& b) { return a.group < b.group; });
}

SessionReader::~SessionReader() {
  if (file_id_ >= 0) H5Fclose(file_id_);
}

std::vector<SessionStream> SessionReader::streams_of(const std::string& topic) const {
  std::vector<SessionStream> out;
  for (const auto& s : streams_)
    if (s.topic == topic) out.push_back(s);
  return out;
}

bool SessionReader::has(const SessionStream& s, const std::string& dataset) const {
  const std::string p = s.group + "/" + dataset;
  return H5Lexists(file_id_, p.c_str(), H5P_DEFAULT) > 0;
}

std::size_t SessionReader::rows(const SessionStream& s, const std::string& dataset) const {
  const std::string p = s.group + "/" + dataset;
  Handle ds(H5Dopen2(file_id_, p.c_str(), H5P_DEFAULT), H5Dclose);
  if (!ds.ok()) throw FormatError(path_ + ": missing dataset '" + p + "'");
  Handle space(H5Dget_space(ds.get()), H5Sclose);
  hsize_t dims[2] = {0, 0};
  if (H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 1) throw FormatError(path_ + ": bad dataset '" + p + "'");
  return static_cast<std::size_t>(dims[0]);
}

template <class T>
std::vector<T> SessionReader::read(const SessionStream& s, const std::string& dataset, long long mem_type,
                                   int width) const {
  const std::string p = s.group + "/" + dataset;
  if (H5Lexists(file_id_, p.c_str(), H5P_DEFAULT) <= 0) throw FormatError(path_ + ": missing dataset '" + p + "'");
  Handle ds(H5Dopen2(file_id_, p.c_str(), H5P_DEFAULT), H5Dclose);
  if (!ds.ok()) throw FormatError(path_ + ": cannot open dataset '" + p + "'");
  Handle space(H5Dget_space(ds.get()), H5Sclose);
  hsize_t dims[2] = {0, 1};
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2 || H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0) {
    throw FormatError(path_ + ": dataset '" + p + "' is not a column");
  }
  const hsize_t cols = rank == 2 ? dims[1] : 1;
  if (cols != static_cast<hsize_t>(width)) {
    throw FormatError(path_ + ": dataset '" + p + "' has " + std::to_string(cols) + " columns, expected " +
                      std::to_string(width));
  }
  std::vector<T> out(static_cast<std::size_t>(dims[0] * cols));
  if (!out.empty() && H5Dread(ds.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0) {
    throw FormatError(path_ + ": cannot read dataset '" + p + "' (truncated file?)");
  }
  return out;
}

std::vector<std::uint8_t> SessionReader::read_u8(const SessionStream& s, const std::string& d) const {
  return read<std::uint8_t>(s, d, H5T_NATIVE_UINT8, 1);
}
std::vector<std::uint32_t> SessionReader::read_u32(const SessionStream& s, const std::string& d) const {
  return read<std::uint32_t>(s, d, H5T_NATIVE_UINT32, 1);
}
std::vector<std::uint64_t> SessionReader::read_u64(const SessionStream& s, const std::string& d) const {
  return read<std::uint64_t>(s, d, H5T_NATIVE_UINT64, 1);
}
std::vector<double> SessionReader::read_f64(const SessionStream& s, const std::string& d, int width) const {
  return read<double>(s, d, H5T_NATIVE_DOUBLE, width);
}

bool is_session_file(const std::string& path) {
  hdf5::quiet_errors();
  if (!std::filesystem::is_regular_file(path) || H5Fis_hdf5(path.c_str()) <= 0) return false;
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  std::string format;
  return file.ok() && read_string_attribute(file.get(), "format", format) && format == kSessionFormat;
}

}  // namespace bsn::io
