// Body model rules and the YAML loader's messages: file, line and problem.
#include <gtest/gtest.h>

#include "bsn/config/body_config.hpp"
#include "bsn/fusion/body_model.hpp"

namespace bsn {
namespace {

using config::ConfigError;
using config::parse_body_model;

// Parses and returns the error message, or "" if it parsed.
std::string error_of(const std::string& yaml) {
  try {
    parse_body_model(yaml, "body.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(BodyModel, DefaultLowerBodyIsValid) {
  const fusion::BodyModel body = fusion::default_lower_body();
  EXPECT_EQ(body.segments.size(), 7u);
  EXPECT_FALSE(fusion::check_body_model(body).has_value());
  EXPECT_EQ(fusion::joint_name(body.segments[*body.find_segment("shank_l")]), "knee_l");
}

TEST(BodyModel, ParsesAFullFile) {
  const auto body = parse_body_model(R"(name: leg
defaults:
  filter: {name: complementary, tau_acc_s: 3}
  joint_axes: zxy
segments:
  - name: thigh
    node: n1
  - name: shank
    node: n2
    parent: thigh
    joint: knee
    filter: {tau_mag_s: 8}
  - name: foot
    node: n3
    parent: shank
    joint_axes: xyz
)",
                                     "body.yaml");
  ASSERT_EQ(body.segments.size(), 3u);
  EXPECT_EQ(body.name, "leg");
  EXPECT_EQ(body.segments[1].joint, "knee");
  EXPECT_EQ(body.segments[1].joint_axes.name(), "zxy");
  EXPECT_EQ(body.segments[2].joint_axes.name(), "xyz");
  EXPECT_EQ(fusion::joint_name(body.segments[2]), "shank-foot");
  // Segment filter blocks override the defaults key by key.
  const auto& params = body.segments[1].filter.parameters;
  ASSERT_EQ(params.size(), 2u);
  EXPECT_EQ(params[0], (std::pair<std::string, double>{"tau_acc_s", 3.0}));
  EXPECT_EQ(params[1], (std::pair<std::string, double>{"tau_mag_s", 8.0}));
}

TEST(BodyModel, RoundTripsThroughYaml) {
  const auto body = fusion::default_lower_body();
  const auto again = parse_body_model(config::body_model_to_yaml(body), "generated");
  ASSERT_EQ(again.segments.size(), body.segments.size());
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    EXPECT_EQ(again.segments[i].name, body.segments[i].name);
    EXPECT_EQ(again.segments[i].parent, body.segments[i].parent);
    EXPECT_EQ(fusion::joint_name(again.segments[i]), fusion::joint_name(body.segments[i]));
  }
}

TEST(BodyModel, AnatomyAndMountingFromTheFile) {
  const auto body = parse_body_model(R"(segments:
  - name: thigh
  - name: shank
    parent: thigh
    joint: j2
    anatomy: knee
    side: left
    sensor_axes: [up, anterior, left]
  - name: foot
    parent: shank
    joint: ankle_r
    sensor_to_segment: [1, 0, 0, 0]
)",
                                     "body.yaml");
  ASSERT_EQ(body.segments.size(), 3u);
  EXPECT_EQ(fusion::joint_convention(body.segments[1]),
            (fusion::JointConvention{fusion::JointType::kKnee, fusion::BodySide::kLeft}));
  // Inferred from the joint's name when the file does not say.
  EXPECT_EQ(fusion::joint_convention(body.segments[2]),
            (fusion::JointConvention{fusion::JointType::kAnkle, fusion::BodySide::kRight}));
  EXPECT_FALSE(body.segments[0].sensor_to_segment);
  ASSERT_TRUE(body.segments[1].sensor_to_segment);
  // Sensor x points up: it is the segment's Y (superior); sensor z points left: the segment's -Z.
  const fusion::Quat& m = *body.segments[1].sensor_to_segment;
  EXPECT_LT((m * fusion::Vec3::UnitX() - fusion::Vec3::UnitY()).norm(), 1e-12);
  EXPECT_LT((m * fusion::Vec3::UnitZ() + fusion::Vec3::UnitZ()).norm(), 1e-12);
  ASSERT_TRUE(body.segments[2].sensor_to_segment);
  EXPECT_LT(fusion::angle_between(*body.segments[2].sensor_to_segment, fusion::Quat::Identity()), 1e-12);
  // Printed and read again, the model keeps its anatomy and mountings.
  const auto again = parse_body_model(config::body_model_to_yaml(body), "generated");
  EXPECT_EQ(fusion::joint_convention(again.segments[1]), fusion::joint_convention(body.segments[1]));
  ASSERT_TRUE(again.segments[1].sensor_to_segment);
  EXPECT_LT(fusion::angle_between(*again.segments[1].sensor_to_segment, m), 1e-9);
}

TEST(BodyModel, BadAnatomyAndMountingNameTheirLine) {
  const std::string head = "segments:\n  - name: a\n  - name: b\n    parent: a\n";
  std::string e = error_of(head + "    anatomy: neck\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("anatomy 'neck'"), std::string::npos) << e;
  e = error_of(head + "    side: up\n");
  EXPECT_NE(e.find("side 'up'"), std::string::npos) << e;
  e = error_of(head + "    sensor_axes: [anterior, right, up]\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("right-handed"), std::string::npos) << e;
  e = error_of(head + "    sensor_axes: [anterior, sideways, up]\n");
  EXPECT_NE(e.find("'sideways'"), std::string::npos) << e;
  e = error_of(head + "    sensor_to_segment: [2, 0, 0, 0]\n");
  EXPECT_NE(e.find("unit quaternion"), std::string::npos) << e;
}

TEST(BodyModel, KinematicHeadingFromTheFile) {
  const auto body = parse_body_model(R"(segments:
  - name: thigh
  - name: shank
    parent: thigh
    heading: kinematic
  - name: foot
    parent: shank
    heading: {mode: kinematic, window_s: 2.5, min_observability: 0.2}
  - name: toe
    parent: foot
    heading: magnetometer
)",
                                     "body.yaml");
  ASSERT_EQ(body.segments.size(), 4u);
  EXPECT_FALSE(body.segments[0].kinematic_heading);
  ASSERT_TRUE(body.segments[1].kinematic_heading);
  EXPECT_EQ(body.segments[1].kinematic_heading->window_s, fusion::HingeHeadingEstimator::Params{}.window_s);
  ASSERT_TRUE(body.segments[2].kinematic_heading);
  EXPECT_EQ(body.segments[2].kinematic_heading->window_s, 2.5);
  EXPECT_EQ(body.segments[2].kinematic_heading->min_observability, 0.2);
  EXPECT_FALSE(body.segments[3].kinematic_heading);
  // Printed and read again, the modes and their parameters stay.
  const auto again = parse_body_model(config::body_model_to_yaml(body), "generated");
  ASSERT_TRUE(again.segments[1].kinematic_heading);
  ASSERT_TRUE(again.segments[2].kinematic_heading);
  EXPECT_EQ(again.segments[2].kinematic_heading->window_s, 2.5);
  EXPECT_EQ(again.segments[2].kinematic_heading->min_observability, 0.2);
  EXPECT_FALSE(again.segments[3].kinematic_heading);
}

TEST(BodyModel, BadKinematicHeadingNamesItsLine) {
  const std::string head = "segments:\n  - name: a\n  - name: b\n    parent: a\n";
  std::string e = error_of(head + "    heading: compass\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("'compass'"), std::string::npos) << e;
  e = error_of(head + "    heading: {mode: kinematic, window_s: 0}\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("window_s"), std::string::npos) << e;
  e = error_of(head + "    heading: {mode: kinematic, window: 2}\n");
  EXPECT_NE(e.find("unknown key 'window'"), std::string::npos) << e;
  e = error_of(head + "    heading: {window_s: 2}\n");
  EXPECT_NE(e.find("needs a mode"), std::string::npos) << e;
  e = error_of("segments:\n  - name: a\n    heading: kinematic\n");
  EXPECT_NE(e.find("body.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("has no parent"), std::string::npos) << e;
}

TEST(BodyModel, HingeAxisFromTheFile) {
  const auto body = parse_body_model(R"(segments:
  - name: base
  - name: link_1
    parent: base
    hinge_axis: z
    heading: kinematic
  - name: link_2
    parent: link_1
    hinge_axis: anterior
    heading: {mode: kinematic, window_s: 2}
  - name: link_3
    parent: link_2
    hinge_axis: [0, 3, 4]
  - name: link_4
    parent: link_3
    hinge_axis: {parent: -y, child: [1, 0, 0]}
)",
                                     "body.yaml");
  ASSERT_EQ(body.segments.size(), 5u);
  EXPECT_FALSE(body.segments[0].hinge_axis);
  auto near = [](const fusion::Vec3& a, const fusion::Vec3& b) { return (a - b).norm() < 1e-12; };
  ASSERT_TRUE(body.segments[1].hinge_axis);
  EXPECT_TRUE(near(body.segments[1].hinge_axis->parent, fusion::Vec3::UnitZ()));
  ASSERT_TRUE(body.segments[2].hinge_axis);
  EXPECT_TRUE(near(body.segments[2].hinge_axis->parent, fusion::Vec3::UnitX()));
  EXPECT_TRUE(near(body.segments[2].hinge_axis->child, fusion::Vec3::UnitX()));
  ASSERT_TRUE(body.segments[3].hinge_axis);
  EXPECT_TRUE(near(body.segments[3].hinge_axis->parent, fusion::Vec3(0, 0.6, 0.8)));  // normalised
  ASSERT_TRUE(body.segments[4].hinge_axis);
  EXPECT_TRUE(near(body.segments[4].hinge_axis->parent, -fusion::Vec3::UnitY()));
  EXPECT_TRUE(near(body.segments[4].hinge_axis->child, fusion::Vec3::UnitX()));
  // The kinematic heading takes its axes from the hinge axis; without one, Z.
  const auto p = fusion::kinematic_heading_params(body.segments[2]);
  ASSERT_TRUE(p);
  EXPECT_TRUE(near(p->parent_axis, fusion::Vec3::UnitX()));
  EXPECT_EQ(p->window_s, 2.0);
  EXPECT_FALSE(fusion::kinematic_heading_params(body.segments[3]));
  // Printed and read back, the same axes.
  const auto again = parse_body_model(config::body_model_to_yaml(body), "again.yaml");
  for (std::size_t i = 0; i < body.segments.size(); ++i) {
    ASSERT_EQ(again.segments[i].hinge_axis.has_value(), body.segments[i].hinge_axis.has_value()) << i;
    if (!body.segments[i].hinge_axis) continue;
    EXPECT_TRUE(near(again.segments[i].hinge_axis->parent, body.segments[i].hinge_axis->parent)) << i;
    EXPECT_TRUE(near(again.segments[i].hinge_axis->child, body.segments[i].hinge_axis->child)) << i;
  }
  EXPECT_TRUE(again.segments[2].kinematic_heading);
}

TEST(BodyModel, BadHingeAxisNamesItsLine) {
  const std::string head = "segments:\n  - name: a\n  - name: b\n    parent: a\n";
  std::string e = error_of(head + "    hinge_axis: w\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("hinge_axis 'w' is not x, y, z"), std::string::npos) << e;
  e = error_of(head + "    hinge_axis: [0, 0, 0]\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("zero vector"), std::string::npos) << e;
  e = error_of(head + "    hinge_axis: [1, 0]\n");
  EXPECT_NE(e.find("a vector [x, y, z]"), std::string::npos) << e;
  e = error_of(head + "    hinge_axis: [1, nan, 0]\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  e = error_of(head + "    hinge_axis: {parent: x}\n");
  EXPECT_NE(e.find("needs both parent and child"), std::string::npos) << e;
  e = error_of(head + "    hinge_axis: {parent: x, child: x, other: y}\n");
  EXPECT_NE(e.find("unknown key 'other'"), std::string::npos) << e;
  e = error_of("segments:\n  - name: a\n    hinge_axis: x\n");
  EXPECT_NE(e.find("body.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("has no parent"), std::string::npos) << e;
}

TEST(BodyModel, UnknownKeyNamesFileLineAndKey) {
  const std::string e = error_of("segments:\n  - name: a\n    colour: red\n");
  EXPECT_NE(e.find("body.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown key 'colour'"), std::string::npos) << e;
}

TEST(BodyModel, DuplicateSegmentNamesTheSecondEntry) {
  const std::string e = error_of("segments:\n  - name: a\n    node: n1\n  - name: a\n    node: n2\n");
  EXPECT_NE(e.find("body.yaml:4:"), std::string::npos) << e;
  EXPECT_NE(e.find("duplicate segment 'a'"), std::string::npos) << e;
}

TEST(BodyModel, DuplicateNode) {
  const std::string e = error_of("segments:\n  - name: a\n    node: n1\n  - name: b\n    node: n1\n");
  EXPECT_NE(e.find("body.yaml:4:"), std::string::npos) << e;
  EXPECT_NE(e.find("node 'n1'"), std::string::npos) << e;
}

TEST(BodyModel, ParentCycle) {
  const std::string e = error_of("segments:\n  - name: a\n    parent: b\n  - name: b\n    parent: a\n");
  EXPECT_NE(e.find("body.yaml:2:"), std::string::npos) << e;
  EXPECT_NE(e.find("parent cycle: a -> b -> a"), std::string::npos) << e;
}

TEST(BodyModel, SelfParentIsACycle) {
  const std::string e = error_of("segments:\n  - name: a\n    parent: a\n");
  EXPECT_NE(e.find("parent cycle"), std::string::npos) << e;
}

TEST(BodyModel, UnknownParent) {
  const std::string e = error_of("segments:\n  - name: a\n  - name: b\n    parent: torso\n");
  EXPECT_NE(e.find("body.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("unknown parent 'torso'"), std::string::npos) << e;
}

TEST(BodyModel, YamlSyntaxError) {
  const std::string e = error_of("segments:\n  - name: a\n  - name: [b\n");
  EXPECT_NE(e.find("body.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("YAML syntax error"), std::string::npos) << e;
}

TEST(BodyModel, BadFilterParameterNamesItsLine) {
  const std::string e = error_of("segments:\n  - name: a\n    filter: {name: complementary, tau_acc_s: -1}\n");
  EXPECT_NE(e.find("body.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("tau_acc_s"), std::string::npos) << e;
  const std::string e2 = error_of("segments:\n  - name: a\n    filter: {name: complementary, tau: x}\n");
  EXPECT_NE(e2.find("must be a number"), std::string::npos) << e2;
  const std::string e3 = error_of("segments:\n  - name: a\n    filter: {name: magic}\n");
  EXPECT_NE(e3.find("unknown filter 'magic'"), std::string::npos) << e3;
}

TEST(BodyModel, BadJointAxes) {
  const std::string e = error_of("segments:\n  - name: a\n  - name: b\n    parent: a\n    joint_axes: zzx\n");
  EXPECT_NE(e.find("body.yaml:5:"), std::string::npos) << e;
  EXPECT_NE(e.find("zzx"), std::string::npos) << e;
}

TEST(BodyModel, StructuralProblems) {
  EXPECT_NE(error_of("").find("empty"), std::string::npos);
  EXPECT_NE(error_of("name: x\n").find("no 'segments'"), std::string::npos);
  EXPECT_NE(error_of("segments: []\n").find("no segments"), std::string::npos);
  EXPECT_NE(error_of("segments: 3\n").find("list"), std::string::npos);
  EXPECT_NE(error_of("segments:\n  - node: n\n").find("without 'name'"), std::string::npos);
  EXPECT_NE(error_of("segments:\n  - name: " + std::string(64, 'a') + "\n").find("63 characters"), std::string::npos);
}

TEST(BodyModel, MissingFileIsAConfigError) {
  try {
    config::load_body_model("/nonexistent/body.yaml");
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/body.yaml"), std::string::npos);
  }
}

}  // namespace
}  // namespace bsn
