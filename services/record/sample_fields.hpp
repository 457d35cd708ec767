// The fields of each bsn sample type, named and with units, described once: the recorder's typed HDF5 columns,
// `bsn echo --format csv|json` and `bsn export --format csv` all come from here. A type without visit_fields is
// still recorded (serialised), just not as columns.
#pragma once

#include <cstdint>
#include <string>

#include "bsn_idl/bsn.h"

namespace bsn::services {

/// Receives the fields of one sample, in a fixed order per type.
class FieldVisitor {
 public:
  virtual ~FieldVisitor() = default;
  /// The DDS key of the sample (a session file's stream group), not a column.
  virtual void key(const char* name, const std::string& value) = 0;
  /// A string field (text outputs only; a session file has it in the serialised sample).
  virtual void text(const char* name, const std::string& value) = 0;
  virtual void u64(const char* name, const char* unit, std::uint64_t value) = 0;
  virtual void u32(const char* name, const char* unit, std::uint32_t value) = 0;
  /// `n` doubles (1 for a scalar; 3 for acc, written as acc_x, acc_y, acc_z in text outputs).
  virtual void f64(const char* name, const char* unit, const double* values, int n) = 0;
  /// `n` doubles that have names of their own in this sample (`labels[i]`: a joint's anatomical angle names, or the
  /// axis-sequence angles named by their axes in rotation order). Only files of one key use them (a CSV file per
  /// joint); everything else sees f64 with `name`.
  virtual void named_f64(const char* name, const char* unit, const double* values, int n,
                         const std::string* const* labels) {
    (void)labels;
    f64(name, unit, values, n);
  }
};

void visit_fields(const bsn::RawSample& s, FieldVisitor& v);
void visit_fields(const bsn::Orientation& s, FieldVisitor& v);
void visit_fields(const bsn::JointAngles& s, FieldVisitor& v);
void visit_fields(const bsn::Status& s, FieldVisitor& v);
void visit_fields(const bsn::CalibrationRequest& s, FieldVisitor& v);
void visit_fields(const bsn::CalibrationResult& s, FieldVisitor& v);

template <class T>
concept HasFields = requires(const T& s, FieldVisitor& v) {
  visit_fields(s, v);
};

/// Names of the text columns of `n` values of `name`: name for 1, name_w.. for quaternions (4), name_x.. for 3,
/// name_0.. otherwise.
std::string component_name(const char* name, int n, int i);

/// The DDS key of a sample ("" for a type without fields).
template <class T>
std::string key_of(const T& s) {
  if constexpr (HasFields<T>) {
    struct KeyProbe : FieldVisitor {
      std::string k;
      void key(const char*, const std::string& value) override { k = value; }
      void text(const char*, const std::string&) override {}
      void u64(const char*, const char*, std::uint64_t) override {}
      void u32(const char*, const char*, std::uint32_t) override {}
      void f64(const char*, const char*, const double*, int) override {}
    } probe;
    visit_fields(s, probe);
    return probe.k;
  } else {
    (void)s;
    return "";
  }
}

/// One line of CSV (values only) or its header (names, with the unit in brackets: "acc_x [m/s^2]"). `named`: the
/// columns that have names of their own in this sample get them ("flexion_extension [rad]", "angle_1_z [rad]"), for
/// a file that holds one key only.
template <class T>
std::string csv_header(const T& s, bool named = false);
/// A CSV row; `prefix` columns (e.g. arrival time) come first, already formatted.
template <class T>
std::string csv_row(const T& s, const std::string& prefix = "");
/// One JSON object on one line: {"topic": ..., "node_id": ..., "acc": [..], ...}.
template <class T>
std::string json_object(const T& s, const std::string& topic);

/// Formatting visitors behind the three functions above.
class CsvHeaderVisitor : public FieldVisitor {
 public:
  std::string out;
  bool named = false;
  void named_f64(const char* name, const char* unit, const double* values, int n,
                 const std::string* const* labels) override {
    if (!named) return f64(name, unit, values, n);
    for (int i = 0; i < n; ++i) add(labels[i]->c_str(), unit);
  }
  void key(const char* name, const std::string&) override { add(name, ""); }
  void text(const char* name, const std::string&) override { add(name, ""); }
  void u64(const char* name, const char* unit, std::uint64_t) override { add(name, unit); }
  void u32(const char* name, const char* unit, std::uint32_t) override { add(name, unit); }
  void f64(const char* name, const char* unit, const double*, int n) override {
    for (int i = 0; i < n; ++i) add(component_name(name, n, i).c_str(), unit);
  }

 private:
  void add(const char* name, const char* unit);
};

class CsvRowVisitor : public FieldVisitor {
 public:
  std::string out;
  void key(const char*, const std::string& value) override { add_text(value); }
  void text(const char*, const std::string& value) override { add_text(value); }
  void u64(const char*, const char*, std::uint64_t value) override;
  void u32(const char*, const char*, std::uint32_t value) override;
  void f64(const char*, const char*, const double* values, int n) override;

 private:
  void add_text(const std::string& value);
  void sep() {
    if (!out.empty()) out += ',';
  }
};

class JsonVisitor : public FieldVisitor {
 public:
  std::string out;
  void key(const char* name, const std::string& value) override { text(name, value); }
  void text(const char* name, const std::string& value) override;
  void u64(const char* name, const char*, std::uint64_t value) override;
  void u32(const char* name, const char*, std::uint32_t value) override;
  void f64(const char* name, const char*, const double* values, int n) override;

 private:
  void name(const char* n);
};

template <class T>
std::string csv_header(const T& s, bool named) {
  CsvHeaderVisitor v;
  v.named = named;
  visit_fields(s, v);
  return v.out;
}

template <class T>
std::string csv_row(const T& s, const std::string& prefix) {
  CsvRowVisitor v;
  v.out = prefix;
  visit_fields(s, v);
  return v.out;
}

template <class T>
std::string json_object(const T& s, const std::string& topic) {
  JsonVisitor v;
  v.text("topic", topic);
  visit_fields(s, v);
  return "{" + v.out + "}";
}

}  // namespace bsn::services
