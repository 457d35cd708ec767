// The calibration service's store round trip for the alignment kind (saved per node, loaded back with what it was
// fitted from, the old file kept as .previous), and the nodes of a body an alignment request collects.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "alignment_nodes.hpp"
#include "calibration_store.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

class Store : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("bsn_calibration_store_test_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

config::AlignmentRecord record(const std::string& segment, double angle) {
  config::AlignmentRecord a;
  a.segment = segment;
  a.sensor_to_segment = calib::Quat(Eigen::AngleAxisd(angle, calib::Vec3(0.3, -1.0, 0.2).normalized()));
  a.source = "pose+hinge thigh_l-" + segment;
  a.hinge_residual = 0.02;
  a.axis_observability = 0.07;
  a.samples = 1500;
  return a;
}

TEST_F(Store, AnAlignmentRoundTripsPerNodeAndKeepsThePreviousFile) {
  CalibrationStore store(dir_.string());
  const std::string path = store.save_alignment("shank_l", record("shank_l", 1.0), "req-1");
  EXPECT_EQ(path, store.path_of("shank_l", calib::CalibrationKind::alignment));
  EXPECT_EQ(fs::path(path).filename(), "shank_l.alignment.calib.yaml");
  store.save_alignment("shank_l", record("shank_l", 2.0), "req-2");
  EXPECT_TRUE(fs::exists(path + ".previous")) << "the replaced alignment is kept";

  std::vector<std::string> problems;
  const std::vector<StoredCalibration> loaded = store.load_all(problems);
  EXPECT_TRUE(problems.empty()) << ::testing::PrintToString(problems);
  ASSERT_EQ(loaded.size(), 1u);
  const StoredCalibration& s = loaded[0];
  EXPECT_EQ(s.node, "shank_l");
  EXPECT_EQ(s.kind, calib::CalibrationKind::alignment);
  EXPECT_EQ(s.document.request_id, "req-2");
  ASSERT_TRUE(s.document.alignment);
  const config::AlignmentRecord want = record("shank_l", 2.0);
  EXPECT_EQ(s.document.alignment->segment, "shank_l");
  // 12 significant digits in the file: the rotation comes back within 1e-10 rad.
  EXPECT_LT(s.document.alignment->sensor_to_segment.angularDistance(want.sensor_to_segment), 1e-10);
  EXPECT_EQ(s.document.alignment->source, want.source);
  EXPECT_DOUBLE_EQ(s.document.alignment->hinge_residual, want.hinge_residual);
  EXPECT_DOUBLE_EQ(s.document.alignment->axis_observability, want.axis_observability);
  EXPECT_EQ(s.document.alignment->samples, want.samples);
}

TEST_F(Store, AnUnreadableAlignmentIsSkippedWithItsLine) {
  CalibrationStore store(dir_.string());
  store.save_alignment("thigh_l", record("thigh_l", 0.5), "ok");
  std::ofstream(dir_ / "shank_l.alignment.calib.yaml")
      << "node: shank_l\nalignment:\n  segment: shank_l\n  sensor_to_segment: [3, 0, 0, 0]\n";
  std::vector<std::string> problems;
  const auto loaded = store.load_all(problems);
  ASSERT_EQ(loaded.size(), 1u);
  EXPECT_EQ(loaded[0].node, "thigh_l");
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("shank_l.alignment.calib.yaml:4: sensor_to_segment must be a unit quaternion"),
            std::string::npos)
      << problems[0];
}

TEST(AlignmentNodes, ParentsFirstWithEachJointsFlexionDirection) {
  fusion::BodyModel body = fusion::default_lower_body();
  // Listed children first: the request still collects parents before children.
  std::reverse(body.segments.begin(), body.segments.end());
  std::string problem;
  const std::vector<calib::AlignmentNode> nodes = alignment_nodes(body, {}, problem);
  EXPECT_EQ(problem, "");
  ASSERT_EQ(nodes.size(), 7u);
  EXPECT_EQ(calib::validate(nodes), "") << "every parent before its child";
  for (const calib::AlignmentNode& n : nodes) {
    SCOPED_TRACE(n.node);
    // The knee flexes the shank backwards, hip and ankle flexion turn the child forwards (align_body's signs).
    const int sign = n.joint.starts_with("knee")                                  ? -1
                     : n.joint.starts_with("hip") || n.joint.starts_with("ankle") ? 1
                                                                                  : 0;
    EXPECT_EQ(n.flexion_sign, sign);
    if (n.segment == "pelvis") {
      EXPECT_EQ(n.parent, -1);
    } else {
      ASSERT_GE(n.parent, 0);
      EXPECT_EQ(nodes[static_cast<std::size_t>(n.parent)].segment, body.segments[*body.find_segment(n.segment)].parent);
    }
  }
  // A subset: a parent left out makes its child a root of the alignment.
  const auto leg = alignment_nodes(body, {"shank_l", "foot_l"}, problem);
  ASSERT_EQ(leg.size(), 2u);
  EXPECT_EQ(leg[0].node, "shank_l");
  EXPECT_EQ(leg[0].parent, -1);
  EXPECT_EQ(leg[1].parent, 0);
  // A node of no segment: no nodes, and the problem lists the body's.
  EXPECT_TRUE(alignment_nodes(body, {"foot_l", "nobody"}, problem).empty());
  EXPECT_NE(problem.find("'nobody' is on no segment of the body (its nodes: "), std::string::npos) << problem;
}

}  // namespace
}  // namespace bsn::services
