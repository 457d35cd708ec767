// The HDF5 helpers of bsn_io (private to it): an owning identifier and quiet errors. BROAD files and session
// files both use them.
#pragma once

#include <hdf5.h>

namespace bsn::io::hdf5 {

// Owns one HDF5 identifier and closes it with the matching function.
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() { reset(); }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  Handle(Handle&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = -1; }
  Handle& operator=(Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      close_ = o.close_;
      o.id_ = -1;
    }
    return *this;
  }
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }
  /// Closes now; returns false if HDF5 reported an error while closing (e.g. the disk is full).
  bool reset() {
    bool closed = true;
    if (id_ >= 0 && close_ != nullptr) closed = close_(id_) >= 0;
    id_ = -1;
    return closed;
  }

 private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

// HDF5 prints its own error stack to stderr by default; we report errors ourselves.
struct QuietErrors {
  QuietErrors() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }
};

inline void quiet_errors() { static const QuietErrors quiet; }

// Datasets without modification times: the same content always gives the same bytes, so outputs can be
// compared with cmp and reruns are reproducible.
inline hid_t untimed_dataset_properties() {
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  if (dcpl >= 0) H5Pset_obj_track_times(dcpl, false);
  return dcpl;
}

}  // namespace bsn::io::hdf5
