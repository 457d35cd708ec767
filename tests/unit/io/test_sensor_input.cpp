// The parsers of real sensors' input: every documented format is read exactly, and every kind of bad input gives
// its own rejection reason (never a reading made of garbage).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>

#include "bsn/io/sensor_input.hpp"

namespace bsn::io {
namespace {

TEST(SensorLine, TenAndSevenColumns) {
  const ParseResult r = parse_sensor_line("1234567,0.1,-0.2,9.81,0.01,0.02,-0.03,20.5,-3,40\r");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(*r.reading.device_time, 1234567.0);
  EXPECT_EQ(r.reading.acc[2], 9.81);
  EXPECT_EQ(r.reading.gyr[2], -0.03);
  EXPECT_TRUE(r.reading.has_mag);
  EXPECT_EQ(r.reading.mag[1], -3.0);
  const ParseResult six = parse_sensor_line("10, 0, 0, 9.8, 0, 0, 0");
  ASSERT_TRUE(six.ok());
  EXPECT_FALSE(six.reading.has_mag);
  const ParseResult empty_mag = parse_sensor_line("10,0,0,9.8,0,0,0,,,");
  ASSERT_TRUE(empty_mag.ok());
  EXPECT_FALSE(empty_mag.reading.has_mag);
}

TEST(SensorLine, EachKindOfBadLineHasItsReason) {
  EXPECT_EQ(parse_sensor_line("").rejection, InputRejection::kIgnored);
  EXPECT_EQ(parse_sensor_line("# bsn sketch v1").rejection, InputRejection::kIgnored);
  EXPECT_EQ(parse_sensor_line("10,0,0,9.8,abc,0,0").rejection, InputRejection::kNotANumber);
  EXPECT_EQ(parse_sensor_line("10,0,0,9.8,0.1x,0,0").rejection, InputRejection::kNotANumber);
  EXPECT_EQ(parse_sensor_line("10,0,0,9.8,0,0").rejection, InputRejection::kColumnCount);
  EXPECT_EQ(parse_sensor_line("10,0,0,9.8,0,0,0,1,2").rejection, InputRejection::kColumnCount);
  EXPECT_EQ(parse_sensor_line("1,2,3,4,5,6,7,8,9,10,11,12").rejection, InputRejection::kColumnCount);
  EXPECT_EQ(parse_sensor_line("10,0,0,nan,0,0,0").rejection, InputRejection::kNonFinite);
  EXPECT_EQ(parse_sensor_line("10,0,0,1e999,0,0,0").rejection, InputRejection::kNotANumber);  // out of range
  EXPECT_EQ(parse_sensor_line(std::string(300, '1')).rejection, InputRejection::kLineTooLong);
  EXPECT_EQ(parse_sensor_line("\x01\xff\x7f,0,0,9.8,0,0,0").rejection, InputRejection::kNotANumber);
}

TEST(LineAssembler, PartialLinesJoinAndOverlongLinesAreReportedOnce) {
  LineAssembler a;
  std::vector<std::string> lines;
  int overflows = 0;
  auto feed = [&](const std::string& s) {
    a.feed(
        std::span(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()),
        [&](std::string_view l) { lines.emplace_back(l); }, [&] { ++overflows; });
  };
  feed("1,2,3");
  EXPECT_TRUE(lines.empty());
  feed(",4\n5,6");
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "1,2,3,4");
  feed(std::string(1000, 'g'));
  feed("still garbage\n7,8\n");
  EXPECT_EQ(overflows, 1);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], "7,8");
}

std::vector<std::uint8_t> osc_string(const std::string& s) {
  std::vector<std::uint8_t> out(s.begin(), s.end());
  out.push_back(0);
  while (out.size() % 4) out.push_back(0);
  return out;
}

void put_be32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 3; i >= 0; --i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

std::vector<std::uint8_t> osc_message(const std::string& address, const std::string& tags, int floats) {
  std::vector<std::uint8_t> m = osc_string(address);
  const auto t = osc_string(tags);
  m.insert(m.end(), t.begin(), t.end());
  for (int i = 0; i < floats; ++i) {
    const float f = static_cast<float>(i + 1);
    std::uint32_t bits;
    std::memcpy(&bits, &f, 4);
    put_be32(m, bits);
  }
  return m;
}

TEST(OscSensors, MessageInNgimuUnitsBecomesSi) {
  const ParseResult r = parse_osc_sensors(osc_message("/sensors", ",ffffffffff", 10));
  ASSERT_TRUE(r.ok()) << input_rejection_name(r.rejection);
  EXPECT_FALSE(r.reading.device_time.has_value());
  EXPECT_DOUBLE_EQ(r.reading.gyr[0], 1.0 * std::numbers::pi / 180.0);  // deg/s -> rad/s
  EXPECT_DOUBLE_EQ(r.reading.acc[0], 4.0 * 9.80665);                   // g -> m/s^2
  EXPECT_DOUBLE_EQ(r.reading.mag[2], 9.0);                             // uT
}

TEST(OscSensors, BundleTimeTagGivesTheDeviceTime) {
  std::vector<std::uint8_t> b = osc_string("#bundle");
  put_be32(b, 3900000000u);  // seconds since 1900
  put_be32(b, 0x80000000u);  // + 0.5 s
  const auto other = osc_message("/battery", ",f", 1);
  put_be32(b, static_cast<std::uint32_t>(other.size()));
  b.insert(b.end(), other.begin(), other.end());
  const auto m = osc_message("/sensors", ",ffffffffff", 10);
  put_be32(b, static_cast<std::uint32_t>(m.size()));
  b.insert(b.end(), m.begin(), m.end());
  const ParseResult r = parse_osc_sensors(b);
  ASSERT_TRUE(r.ok()) << input_rejection_name(r.rejection);
  EXPECT_DOUBLE_EQ(*r.reading.device_time, 3900000000.5);
}

TEST(OscSensors, BadDatagramsHaveTheirReasons) {
  EXPECT_EQ(parse_osc_sensors(osc_message("/sensors", ",fff", 3)).rejection, InputRejection::kWrongTypeTags);
  EXPECT_EQ(parse_osc_sensors(osc_message("/sensors", ",ffffffffffi", 11)).rejection, InputRejection::kWrongTypeTags);
  EXPECT_EQ(parse_osc_sensors(osc_message("/quaternion", ",ffff", 4)).rejection, InputRejection::kWrongAddress);
  auto cut = osc_message("/sensors", ",ffffffffff", 10);
  cut.resize(cut.size() - 8);
  EXPECT_EQ(parse_osc_sensors(cut).rejection, InputRejection::kTruncated);
  cut.resize(cut.size() - 1);  // not a multiple of 4
  EXPECT_EQ(parse_osc_sensors(cut).rejection, InputRejection::kTruncated);
  EXPECT_EQ(parse_osc_sensors(std::vector<std::uint8_t>(2000, 0)).rejection, InputRejection::kOversized);
  EXPECT_EQ(parse_osc_sensors(std::vector<std::uint8_t>{'/', 's', 'e', 'n'}).rejection, InputRejection::kTruncated);
  std::vector<std::uint8_t> bundle = osc_string("#bundle");
  put_be32(bundle, 0);
  put_be32(bundle, 1);
  put_be32(bundle, 400);  // element larger than the datagram
  EXPECT_EQ(parse_osc_sensors(bundle).rejection, InputRejection::kTruncated);
}

TEST(IioType, ParsesTheKernelFormatAndNamesWhatIsWrong) {
  const auto t = parse_iio_channel_type("be:u12/16>>4\n");
  ASSERT_TRUE(t);
  EXPECT_TRUE(t->big_endian);
  EXPECT_FALSE(t->is_signed);
  EXPECT_EQ(t->bits, 12);
  EXPECT_EQ(t->storage_bits, 16);
  EXPECT_EQ(t->shift, 4);
  std::string error;
  EXPECT_FALSE(parse_iio_channel_type("me:s16/16>>0", &error));
  EXPECT_NE(error.find("endianness"), std::string::npos) << error;
  EXPECT_FALSE(parse_iio_channel_type("le:s16/24>>0", &error));
  EXPECT_NE(error.find("storage"), std::string::npos) << error;
  EXPECT_FALSE(parse_iio_channel_type("le:s20/16>>0", &error));
  EXPECT_FALSE(parse_iio_channel_type("le:s16/16", &error));
}

TEST(IioScan, LayoutAlignsLikeTheKernelAndValuesScale) {
  IioScanLayout layout;
  auto channel = [](int index, const char* type, int target, double scale) {
    IioScanLayout::Channel c;
    c.index = index;
    c.type = *parse_iio_channel_type(type);
    c.target = target;
    c.scale = scale;
    return c;
  };
  layout.channels = {channel(0, "le:s16/16>>0", 0, 0.01), channel(1, "le:s16/16>>0", 1, 0.01),
                     channel(2, "be:s12/16>>4", 2, 0.01), channel(3, "le:s64/64>>0", 9, 1e-9)};
  finish_iio_layout(layout);
  EXPECT_EQ(layout.channels[2].offset, 4u);
  EXPECT_EQ(layout.channels[3].offset, 8u);  // the timestamp is aligned to 8 bytes
  EXPECT_EQ(layout.scan_bytes, 16u);
  std::vector<std::uint8_t> scan(16, 0);
  const std::int16_t x = -981;
  std::memcpy(scan.data(), &x, 2);
  // z: 12-bit signed -5 stored big-endian, shifted left by 4.
  const std::uint16_t z = static_cast<std::uint16_t>((static_cast<std::uint16_t>(-5) & 0xFFF) << 4);
  scan[4] = static_cast<std::uint8_t>(z >> 8);
  scan[5] = static_cast<std::uint8_t>(z & 0xFF);
  const std::int64_t ts = 2500000000;
  std::memcpy(scan.data() + 8, &ts, 8);
  const ParseResult r = parse_iio_scan(scan, layout);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r.reading.has_acc);
  EXPECT_FALSE(r.reading.has_gyr);
  EXPECT_DOUBLE_EQ(r.reading.acc[0], -9.81);
  EXPECT_DOUBLE_EQ(r.reading.acc[2], -0.05);
  EXPECT_DOUBLE_EQ(*r.reading.device_time, 2.5);
  EXPECT_EQ(parse_iio_scan(std::span(scan.data(), 15), layout).rejection, InputRejection::kShortRead);
}

TEST(AxisMap, RemapsSignsAndScales) {
  DeviceReading d;
  d.has_acc = d.has_gyr = true;
  d.acc = {1.0, 2.0, 3.0};
  d.gyr = {4.0, 5.0, 6.0};
  AxisMap m;
  m.acc.source = {1, 0, 2};
  m.acc.sign = {1.0, -1.0, 1.0};
  m.acc.scale = 2.0;
  const auto s = apply_axis_map(d, m);
  EXPECT_EQ(s.acc, fusion::Vec3(4.0, -2.0, 6.0));
  EXPECT_EQ(s.gyr, fusion::Vec3(4.0, 5.0, 6.0));
  EXPECT_FALSE(s.has_mag);
}

}  // namespace
}  // namespace bsn::io
