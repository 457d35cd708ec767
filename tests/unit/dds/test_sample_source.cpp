// Writer identities without a running DDS: GUIDs as source ids and text, per-key writer counts, finite estimates.
#include <gtest/gtest.h>

#include <limits>

#include "bsn/dds/sample_source.hpp"

namespace bsn::dds {
namespace {

using eprosima::fastrtps::rtps::GUID_t;

GUID_t guid(std::uint8_t process, std::uint8_t entity) {
  GUID_t g;
  g.guidPrefix.value[0] = 0x01;
  g.guidPrefix.value[1] = 0x0f;
  g.guidPrefix.value[4] = process;
  g.entityId.value[2] = 0x01;
  g.entityId.value[3] = entity;
  return g;
}

TEST(SampleSource, GuidIsASourceIdAndPrintsAsFastDdsDoes) {
  const GUID_t g = guid(0xab, 0x03);
  const fusion::SourceId id = source_id(g);
  EXPECT_TRUE(id.known());
  EXPECT_EQ(id.bytes[4], 0xab);
  EXPECT_EQ(id.bytes[15], 0x03);
  EXPECT_EQ(writer_name(g), "01.0f.00.00.ab.00.00.00.00.00.00.00|0.0.1.3");
  EXPECT_NE(source_id(guid(0xab, 0x04)), id) << "two writers of one participant are two sources";
  EXPECT_FALSE(source_id(GUID_t::unknown()).known());
}

TEST(SampleSource, KeyWritersCountsWritersWithinTheWindow) {
  constexpr std::uint64_t kWindow = 1'000'000'000;
  KeyWriters writers(kWindow);
  EXPECT_EQ(writers.note("pelvis", guid(1, 3), 0), 1u);
  EXPECT_EQ(writers.note("pelvis", guid(1, 3), 10), 1u) << "the same writer again";
  EXPECT_EQ(writers.note("thigh_l", guid(2, 3), 20), 1u) << "another key";
  EXPECT_EQ(writers.note("pelvis", guid(2, 3), 30), 2u) << "a second writer of one key";
  EXPECT_EQ(writers.note("pelvis", guid(2, 3), 10 + kWindow), 2u) << "the first still within the window";
  // The first writer stopped (a restarted service): it drops out once silent for longer than the window.
  EXPECT_EQ(writers.note("pelvis", guid(2, 3), 11 + kWindow), 1u);
}

TEST(SampleSource, KeyWritersIsBounded) {
  KeyWriters writers;
  for (std::uint8_t w = 0; w < 20; ++w) writers.note("k", guid(w, 3), 0);
  EXPECT_EQ(writers.note("k", guid(99, 3), 0), KeyWriters::kMaxWritersPerKey);
}

TEST(SampleSource, NonFiniteEstimatesAreNoticed) {
  bsn::Orientation o;
  o.quat({1.0, 0.0, 0.0, 0.0});
  EXPECT_TRUE(finite_values(o));
  for (int field = 0; field < 3; ++field) {
    bsn::Orientation bad = o;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    if (field == 0) bad.quat({nan, 0.0, 0.0, 0.0});
    if (field == 1) bad.pitch(std::numeric_limits<double>::infinity());
    if (field == 2) bad.gyro_bias({0.0, nan, 0.0});
    EXPECT_FALSE(finite_values(bad)) << field;
  }
  bsn::JointAngles j;
  j.quat({1.0, 0.0, 0.0, 0.0});
  EXPECT_TRUE(finite_values(j));
  for (int field = 0; field < 4; ++field) {
    bsn::JointAngles bad = j;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    if (field == 0) bad.angles({0.0, 0.0, -std::numeric_limits<double>::infinity()});
    if (field == 1) bad.anatomical({0.0, nan, 0.0});
    if (field == 2) bad.heading_offset(nan);
    if (field == 3) bad.heading_observability(std::numeric_limits<double>::infinity());
    EXPECT_FALSE(finite_values(bad)) << field;
  }
}

}  // namespace
}  // namespace bsn::dds
