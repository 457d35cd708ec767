#include <cmath>
#include <vector>

#include "bsn/io/recording.hpp"
#include "hdf5_handle.hpp"

namespace bsn::io {
namespace {

using hdf5::Handle;

bool has_dataset(hid_t file, const char* name) { return H5Lexists(file, name, H5P_DEFAULT) > 0; }

// Reads an N x cols float64 dataset into a row-major matrix.
template <class Matrix>
Matrix read_matrix(hid_t file, const std::string& path, const char* name, int cols) {
  Handle ds(H5Dopen2(file, name, H5P_DEFAULT), H5Dclose);
  if (!ds.ok()) throw IoError(path + ": cannot open dataset '" + name + "'");
  Handle space(H5Dget_space(ds.get()), H5Sclose);
  hsize_t dims[2] = {0, 0};
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank != 2 || H5Sget_simple_extent_dims(space.get(), dims, nullptr) < 0 || dims[1] != static_cast<hsize_t>(cols)) {
    throw IoError(path + ": dataset '" + name + "' must be N x " + std::to_string(cols));
  }
  Matrix m(static_cast<Eigen::Index>(dims[0]), cols);
  if (dims[0] > 0 && H5Dread(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, m.data()) < 0) {
    throw IoError(path + ": cannot read dataset '" + name + "'");
  }
  return m;
}

// Reads a one-dimensional dataset, converted by HDF5 to `mem_type` (the C++ type T).
template <class T>
std::vector<T> read_vector(hid_t file, const std::string& path, const char* name, hid_t mem_type) {
  Handle ds(H5Dopen2(file, name, H5P_DEFAULT), H5Dclose);
  if (!ds.ok()) throw IoError(path + ": cannot open dataset '" + name + "'");
  Handle space(H5Dget_space(ds.get()), H5Sclose);
  hsize_t n = 0;
  if (H5Sget_simple_extent_ndims(space.get()) != 1 || H5Sget_simple_extent_dims(space.get(), &n, nullptr) < 0) {
    throw IoError(path + ": dataset '" + name + "' must be one-dimensional");
  }
  std::vector<T> v(n);
  if (n > 0 && H5Dread(ds.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) < 0) {
    throw IoError(path + ": cannot read dataset '" + name + "'");
  }
  return v;
}

std::vector<std::uint8_t> read_flags(hid_t file, const std::string& path, const char* name) {
  // BROAD stores booleans as an int8 enum; reading as native int8 converts enum and integer types alike.
  const auto raw = read_vector<std::int8_t>(file, path, name, H5T_NATIVE_INT8);
  return {raw.begin(), raw.end()};
}

using hdf5::untimed_dataset_properties;

template <class Matrix>
void write_matrix(hid_t file, const std::string& path, const char* name, const Matrix& m) {
  const hsize_t dims[2] = {static_cast<hsize_t>(m.rows()), static_cast<hsize_t>(m.cols())};
  Handle space(H5Screate_simple(2, dims, nullptr), H5Sclose);
  const Handle dcpl(untimed_dataset_properties(), H5Pclose);
  Handle ds(H5Dcreate2(file, name, H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT), H5Dclose);
  if (!ds.ok() || H5Dwrite(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, m.data()) < 0) {
    throw IoError(path + ": cannot write dataset '" + name + "'");
  }
}

}  // namespace

Recording read_broad_hdf5(const std::string& path) {
  hdf5::quiet_errors();
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) throw IoError(path + ": cannot open as HDF5");
  Recording rec;
  for (const char* required : {"imu_gyr", "imu_acc", "imu_mag"}) {
    if (!has_dataset(file.get(), required)) throw IoError(path + ": missing dataset '" + required + "'");
  }
  rec.gyr = read_matrix<RowsX3>(file.get(), path, "imu_gyr", 3);
  rec.acc = read_matrix<RowsX3>(file.get(), path, "imu_acc", 3);
  rec.mag = read_matrix<RowsX3>(file.get(), path, "imu_mag", 3);
  if (has_dataset(file.get(), "opt_quat")) rec.opt_quat = read_matrix<RowsX4>(file.get(), path, "opt_quat", 4);
  if (has_dataset(file.get(), "opt_pos")) rec.opt_pos = read_matrix<RowsX3>(file.get(), path, "opt_pos", 3);
  if (has_dataset(file.get(), "movement")) rec.movement = read_flags(file.get(), path, "movement");
  if (has_dataset(file.get(), "timestamp_ns"))
    rec.timestamp_ns = read_vector<std::uint64_t>(file.get(), path, "timestamp_ns", H5T_NATIVE_UINT64);
  if (H5Aexists(file.get(), "sampling_rate") <= 0) throw IoError(path + ": missing attribute 'sampling_rate'");
  Handle attr(H5Aopen(file.get(), "sampling_rate", H5P_DEFAULT), H5Aclose);
  if (!attr.ok() || H5Aread(attr.get(), H5T_NATIVE_DOUBLE, &rec.sampling_rate_hz) < 0) {
    throw IoError(path + ": cannot read attribute 'sampling_rate'");
  }
  rec.validate(path);
  // As for CSV: a recording of fewer than two samples has no time step to score or replay (an empty or cut file).
  if (rec.gyr.rows() < 2) throw IoError(path + ": fewer than two samples");
  return rec;
}

void write_broad_hdf5(const std::string& path, const Recording& rec) {
  hdf5::quiet_errors();
  rec.validate(path);
  Handle file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) throw IoError(path + ": cannot create HDF5 file");
  write_matrix(file.get(), path, "imu_gyr", rec.gyr);
  write_matrix(file.get(), path, "imu_acc", rec.acc);
  write_matrix(file.get(), path, "imu_mag", rec.mag);
  if (rec.opt_quat.rows() > 0) write_matrix(file.get(), path, "opt_quat", rec.opt_quat);
  if (rec.opt_pos.rows() > 0) write_matrix(file.get(), path, "opt_pos", rec.opt_pos);
  if (!rec.movement.empty()) {
    // The same int8 FALSE/TRUE enum as BROAD, so tools that read BROAD read ours.
    Handle type(H5Tenum_create(H5T_STD_I8LE), H5Tclose);
    const std::int8_t f = 0, t = 1;
    H5Tenum_insert(type.get(), "FALSE", &f);
    H5Tenum_insert(type.get(), "TRUE", &t);
    const hsize_t n = rec.movement.size();
    Handle space(H5Screate_simple(1, &n, nullptr), H5Sclose);
    const Handle dcpl(untimed_dataset_properties(), H5Pclose);
    Handle ds(H5Dcreate2(file.get(), "movement", type.get(), space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
              H5Dclose);
    std::vector<std::int8_t> v(rec.movement.begin(), rec.movement.end());
    // HDF5 converts no integer to an enum, so the memory type is the enum itself (int8 = the values in v).
    if (!ds.ok() || H5Dwrite(ds.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) < 0) {
      throw IoError(path + ": cannot write dataset 'movement'");
    }
  }
  if (!rec.timestamp_ns.empty()) {
    // bsn's addition to the layout: each sample's own time, so a session with gaps or a changing rate exports
    // as it was recorded (tools that read BROAD ignore the extra dataset and use sampling_rate).
    const hsize_t n = rec.timestamp_ns.size();
    Handle space(H5Screate_simple(1, &n, nullptr), H5Sclose);
    const Handle dcpl(untimed_dataset_properties(), H5Pclose);
    Handle ds(H5Dcreate2(file.get(), "timestamp_ns", H5T_STD_U64LE, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
              H5Dclose);
    if (!ds.ok() || H5Dwrite(ds.get(), H5T_NATIVE_UINT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, rec.timestamp_ns.data()) < 0) {
      throw IoError(path + ": cannot write dataset 'timestamp_ns'");
    }
  }
  Handle scalar(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(file.get(), "sampling_rate", H5T_IEEE_F64LE, scalar.get(), H5P_DEFAULT, H5P_DEFAULT),
              H5Aclose);
  if (!attr.ok() || H5Awrite(attr.get(), H5T_NATIVE_DOUBLE, &rec.sampling_rate_hz) < 0) {
    throw IoError(path + ": cannot write attribute 'sampling_rate'");
  }
}

}  // namespace bsn::io
