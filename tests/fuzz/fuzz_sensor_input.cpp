// The parsers of real sensors' input (`bsn node`) on arbitrary bytes. The first byte picks the path, the rest is
// the input: 0 the serial line protocol (bytes through the LineAssembler, each line parsed), 1 one UDP datagram as
// a line or as OSC (what `bsn node --source udp:` does with it), 2 an IIO layout from type strings plus one scan.
// Invariants: a rejection is one of the named reasons; a reading has finite values in the channels it claims; a
// line handed on is never longer than kMaxLineLength; an axis-mapped reading stays finite.
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "bsn/io/sensor_input.hpp"
#include "fuzz_check.hpp"

namespace {

using bsn::io::InputRejection;
using bsn::io::ParseResult;

bool finite3(const std::array<double, 3>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

void check(const ParseResult& r) {
  BSN_FUZZ_CHECK(r.rejection < InputRejection::kCount, "a rejection outside the named reasons");
  BSN_FUZZ_CHECK(std::string_view(bsn::io::input_rejection_name(r.rejection)).size() > 0, "a nameless rejection");
  if (!r.ok()) return;
  const bsn::io::DeviceReading& d = r.reading;
  BSN_FUZZ_CHECK(!d.has_acc || finite3(d.acc), "a non-finite accelerometer reading");
  BSN_FUZZ_CHECK(!d.has_gyr || finite3(d.gyr), "a non-finite gyroscope reading");
  BSN_FUZZ_CHECK(!d.has_mag || finite3(d.mag), "a non-finite magnetometer reading");
  BSN_FUZZ_CHECK(!d.device_time || std::isfinite(*d.device_time), "a non-finite device time");
  // Axis maps (a remap, a sign flip, a unit scale) keep a finite reading finite.
  bsn::io::AxisMap map;
  map.acc.source = {2, 0, 1};
  map.acc.sign = {-1.0, 1.0, -1.0};
  map.gyr.scale = 3.14159265358979 / 180.0;
  const bsn::fusion::ImuSample s = bsn::io::apply_axis_map(d, map);
  BSN_FUZZ_CHECK(s.acc.allFinite() && s.gyr.allFinite() && s.mag.allFinite(), "a non-finite mapped sample");
}

void fuzz_serial(std::span<const std::uint8_t> bytes) {
  bsn::io::LineAssembler lines;
  // Fed in two pieces, as a serial port delivers them: a line split across reads must come out whole.
  const std::size_t half = bytes.size() / 2;
  for (const auto piece : {bytes.first(half), bytes.subspan(half)}) {
    lines.feed(
        piece,
        [](std::string_view line) {
          BSN_FUZZ_CHECK(line.size() <= bsn::io::kMaxLineLength, "a line longer than the limit was handed on");
          check(bsn::io::parse_sensor_line(line));
        },
        [] {});
  }
  BSN_FUZZ_CHECK(lines.pending() <= bsn::io::kMaxLineLength, "the assembler holds more than one line");
}

void fuzz_udp(std::span<const std::uint8_t> datagram) {
  check(bsn::io::parse_osc_sensors(datagram));
  check(bsn::io::parse_sensor_line(std::string_view(reinterpret_cast<const char*>(datagram.data()), datagram.size())));
}

// Input: up to 10 type strings separated by ';' (one per channel, in scan order, targets acc, gyr, mag, time), a
// '|' and then the scan bytes.
void fuzz_iio(std::span<const std::uint8_t> bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const std::size_t bar = text.find('|');
  if (bar == std::string_view::npos) return;
  bsn::io::IioScanLayout layout;
  std::string_view types = text.substr(0, bar);
  int target = 0;
  while (!types.empty() && target < 10) {
    const std::size_t semi = types.find(';');
    const std::string_view one = types.substr(0, semi);
    std::string error;
    if (const auto type = bsn::io::parse_iio_channel_type(one, &error)) {
      BSN_FUZZ_CHECK(
          type->storage_bits == 8 || type->storage_bits == 16 || type->storage_bits == 32 || type->storage_bits == 64,
          "a storage size the kernel never uses was accepted");
      BSN_FUZZ_CHECK(type->bits >= 1 && type->bits <= type->storage_bits, "significant bits beyond the storage");
      BSN_FUZZ_CHECK(type->shift >= 0 && type->shift < type->storage_bits, "a shift beyond the storage");
      BSN_FUZZ_CHECK(type->repeat >= 1, "a repeat below one");
      bsn::io::IioScanLayout::Channel c;
      c.index = target;
      c.type = *type;
      c.scale = target == 9 ? 1e-9 : 0.001;
      c.target = target;
      layout.channels.push_back(c);
    } else {
      BSN_FUZZ_CHECK(!error.empty(), "a type string refused without saying why");
    }
    ++target;
    if (semi == std::string_view::npos) break;
    types.remove_prefix(semi + 1);
  }
  bsn::io::finish_iio_layout(layout);
  for (const auto& c : layout.channels) {
    BSN_FUZZ_CHECK(c.offset + static_cast<std::size_t>(c.type.storage_bits / 8) * c.type.repeat <= layout.scan_bytes,
                   "a channel outside its scan");
  }
  check(bsn::io::parse_iio_scan(bytes.subspan(bar + 1), layout));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::span<const std::uint8_t> rest(data + 1, size - 1);
  switch (data[0] % 3) {
    case 0:
      fuzz_serial(rest);
      break;
    case 1:
      fuzz_udp(rest);
      break;
    default:
      fuzz_iio(rest);
      break;
  }
  return 0;
}
