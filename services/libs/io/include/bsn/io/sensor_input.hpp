// What real sensors send, parsed: pure functions from bytes to one reading or one specific rejection reason (no
// I/O, no DDS, no state beyond what is passed in), so `bsn node` and fuzz targets share them. One entry point each:
//   parse_sensor_line   one line of the bsn line protocol (serial and UDP)
//   parse_osc_sensors   one UDP datagram of OSC: an x-io NGIMU "/sensors" message, or a bundle holding one
//   parse_iio_scan      one scan of the Linux IIO buffered interface, given the layout read from sysfs
// plus the helpers they rest on: LineAssembler (bytes of a stream into lines) and parse_iio_channel_type (the
// "le:s16/16>>0" strings of scan_elements/*_type), and apply_axis_map (device axes and units into bsn's).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::io {

/// Why input was not turned into a sample. Every value but kNone is counted by `bsn node`.
enum class InputRejection : std::uint8_t {
  kNone,           ///< a reading
  kIgnored,        ///< an empty line or a '#' comment (not an error, not counted as one)
  kLineTooLong,    ///< a line longer than kMaxLineLength (garbage or a lost newline)
  kNotANumber,     ///< a field that is not a number (text, garbage bytes)
  kColumnCount,    ///< not 7 or 10 fields
  kNonFinite,      ///< NaN or infinity in a field
  kTruncated,      ///< a datagram or message shorter than its content says
  kOversized,      ///< a datagram longer than any valid one
  kNotOsc,         ///< not an OSC message or bundle
  kWrongAddress,   ///< an OSC message other than /sensors
  kWrongTypeTags,  ///< /sensors without the ten float arguments
  kShortRead,      ///< an IIO scan shorter than the layout's scan size
  kCount
};

/// Name used in logs and on bsn/status, e.g. "column_count".
const char* input_rejection_name(InputRejection r);

/// One reading in the device's axes, in SI units (m/s^2, rad/s, uT) as far as the format defines them (the line
/// protocol is SI by definition; NGIMU and IIO readings are converted), before apply_axis_map.
struct DeviceReading {
  std::optional<double> device_time;  ///< in the device's time unit (line protocol) or s (OSC, IIO); none = use arrival
  std::array<double, 3> acc{}, gyr{}, mag{};
  bool has_acc = false, has_gyr = false, has_mag = false;
};

struct ParseResult {
  InputRejection rejection = InputRejection::kNone;
  DeviceReading reading;  ///< valid when rejection == kNone
  bool ok() const { return rejection == InputRejection::kNone; }
};

inline constexpr std::size_t kMaxLineLength = 256;

/// The line protocol: "T,AX,AY,AZ,GX,GY,GZ" or "T,AX,AY,AZ,GX,GY,GZ,MX,MY,MZ" (decimal numbers, optional spaces,
/// an optional trailing '\r'); T is the device clock (unit in the axis map, default microseconds); empty
/// magnetometer fields (",,") mean no magnetometer in this sample. Lines starting with '#' are ignored.
ParseResult parse_sensor_line(std::string_view line);

/// Splits a byte stream (a serial port) into lines. Bytes after an overlong line are dropped up to the next
/// newline, and that line is reported as too long once.
class LineAssembler {
 public:
  /// Feeds bytes; calls `on_line(line)` for each complete line and `on_overflow()` for each overlong one.
  template <class OnLine, class OnOverflow>
  void feed(std::span<const std::uint8_t> bytes, OnLine&& on_line, OnOverflow&& on_overflow) {
    for (const std::uint8_t b : bytes) {
      if (b == '\n') {
        if (overflow_) {
          overflow_ = false;
        } else {
          on_line(std::string_view(buffer_));
        }
        buffer_.clear();
        continue;
      }
      if (overflow_) continue;
      if (buffer_.size() >= kMaxLineLength) {
        overflow_ = true;
        buffer_.clear();
        on_overflow();
        continue;
      }
      buffer_.push_back(static_cast<char>(b));
    }
  }
  /// Forgets a partial line (the device went away mid-line).
  void reset() {
    buffer_.clear();
    overflow_ = false;
  }
  std::size_t pending() const { return buffer_.size(); }

 private:
  std::string buffer_;
  bool overflow_ = false;
};

/// Largest UDP datagram accepted (a bundle of a few messages); anything longer is kOversized.
inline constexpr std::size_t kMaxDatagram = 1472;

/// An NGIMU "/sensors" message: ten float32 arguments (",ffffffffff"): gyroscope x, y, z in deg/s, accelerometer
/// x, y, z in g, magnetometer x, y, z in uT, barometer in hPa (ignored), converted to SI. As a bare message it has no
/// time (the arrival time is used); in a bundle ("#bundle", NTP time tag, size-prefixed elements) the time tag gives
/// device_time in seconds (a tag of 1, "immediately", gives none). Other messages are kWrongAddress.
ParseResult parse_osc_sensors(std::span<const std::uint8_t> datagram);

/// One channel's storage in an IIO scan, from its scan_elements/in_<name>_type: "[be|le]:[s|u]BITS/STORAGE[Xn]>>SHIFT".
struct IioChannelType {
  bool big_endian = false;
  bool is_signed = true;
  int bits = 16;          ///< significant bits
  int storage_bits = 16;  ///< 8, 16, 32 or 64
  int shift = 0;
  int repeat = 1;
};

/// Parses a type string; nullopt with `error` set (naming the problem) if it is not one.
std::optional<IioChannelType> parse_iio_channel_type(std::string_view text, std::string* error = nullptr);

/// The layout of an enabled IIO scan: which channel sits where and how it scales to SI.
struct IioScanLayout {
  struct Channel {
    int index = 0;  ///< scan_elements/in_<name>_index: order in the scan
    IioChannelType type;
    std::size_t offset = 0;     ///< byte offset in the scan (aligned to its storage size, as the kernel does)
    double scale = 1.0;         ///< to SI: m/s^2, rad/s, uT, or s for the timestamp
    double value_offset = 0.0;  ///< in_<name>_offset, added before scaling
    int target = -1;            ///< 0..2 acc x..z, 3..5 gyr, 6..8 mag, 9 timestamp, -1 unused
  };
  std::vector<Channel> channels;  ///< enabled channels, in scan order
  std::size_t scan_bytes = 0;     ///< bytes of one scan, padded to its largest element
};

/// Computes every channel's offset and scan_bytes from their order and storage (the kernel's alignment rule).
void finish_iio_layout(IioScanLayout& layout);

/// One scan: kShortRead if `scan` is shorter than layout.scan_bytes.
ParseResult parse_iio_scan(std::span<const std::uint8_t> scan, const IioScanLayout& layout);

/// How one channel's device axes map onto bsn's sensor axes: out[i] = sign[i] * in[source[i]] * scale.
struct ChannelMap {
  std::array<int, 3> source{0, 1, 2};
  std::array<double, 3> sign{1.0, 1.0, 1.0};
  double scale = 1.0;   ///< device unit to SI (m/s^2, rad/s, uT)
  bool enabled = true;  ///< false: the channel is dropped (e.g. an uncalibrated magnetometer)
};

struct AxisMap {
  double time_scale_s = 1e-6;  ///< seconds per device time unit (line protocol; default microseconds)
  ChannelMap acc, gyr, mag;
};

/// The reading in bsn's axes and units; the caller sets timestamp_ns.
fusion::ImuSample apply_axis_map(const DeviceReading& reading, const AxisMap& map);

}  // namespace bsn::io
