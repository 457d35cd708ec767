#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"

namespace bsn::config {
namespace {

namespace fs = std::filesystem;

class TempDir : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("bsn_calib_file_test_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  fs::path dir_;
};

constexpr const char* kCalibration = R"(node: thigh_l
magnetometer:
  bias: [1, -2, 3]
  transform: [[2, 0, 0], [0, 1, 0.5], [0, 0, 1]]
  field_magnitude: 50
  field_vector: [0, 20, -45]
gyroscope: {bias: [0.01, 0, -0.02]}
quality: {pose_count: 12}
)";

TEST_F(TempDir, WrittenFileLoadsBackExactly) {
  calib::FieldCalibration mag;
  mag.status = calib::FitStatus::ok;
  mag.calibration.bias = calib::Vec3(12.5, -30.25, 7.125);
  mag.calibration.transform << 0.83, 0.035, 0.17, 0.22, 0.72, 0.007, 0.11, 0.23, 0.9;
  mag.field_magnitude = 50.0;
  calib::ChannelCalibration gyro;
  gyro.bias = calib::Vec3(0.01, -0.02, 0.005);
  const std::string path = write("c.yaml", calibration_to_yaml("n1", &mag, nullptr, &gyro));
  const calib::SensorCalibration c = load_calibration_file(path);
  ASSERT_TRUE(c.magnetometer && c.gyroscope);
  EXPECT_FALSE(c.accelerometer);
  EXPECT_TRUE(c.magnetometer->bias.isApprox(mag.calibration.bias, 1e-9));
  EXPECT_TRUE(c.magnetometer->transform.isApprox(mag.calibration.transform, 1e-9));
  EXPECT_TRUE(c.gyroscope->bias.isApprox(gyro.bias, 1e-9));
  EXPECT_EQ(c.gyroscope->transform, calib::Mat3::Identity());
}

TEST_F(TempDir, ParsesTheDocumentedFormat) {
  const calib::SensorCalibration c = parse_calibration(kCalibration, "x.yaml");
  ASSERT_TRUE(c.magnetometer);
  EXPECT_EQ(calib::apply(*c.magnetometer, calib::Vec3(3, 0, 5)), calib::Vec3(4, 3, 2));
}

TEST_F(TempDir, BadFilesNameTheLineAndTheProblem) {
  auto message = [](const std::string& text) {
    try {
      (void)parse_calibration(text, "bad.yaml");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message("magnetometer:\n  bias: [1, 2]\n"), "bad.yaml:2: magnetometer bias must be a list of 3 numbers");
  EXPECT_EQ(message("magnetometer:\n  bias: [1, 2, .nan]\n"), "bad.yaml:2: magnetometer bias must be finite");
  EXPECT_EQ(message("magnetometer:\n  transform: [[1, 0, 0], [0, 1, 0], [0, 0, 0]]\n"),
            "bad.yaml:2: magnetometer transform is singular");
  EXPECT_NE(message("magnetometr:\n  bias: [1, 2, 3]\n").find("bad.yaml:1: unknown key 'magnetometr'"),
            std::string::npos);
  EXPECT_EQ(message("node: a\n"),
            "bad.yaml:1: the calibration file holds no magnetometer, accelerometer, gyroscope or alignment");
  EXPECT_NE(message("magnetometer: [\n").find("YAML syntax error"), std::string::npos);
  EXPECT_THROW((void)load_calibration_file((dir_ / "missing.yaml").string()), ConfigError);
}

TEST_F(TempDir, BodyKeyLoadsTheFileRelativeToTheBodyFileForItsNode) {
  fs::create_directories(dir_ / "cal");
  std::string text = kCalibration;
  text.replace(text.find("node: thigh_l"), 13, "node: sensor7");
  write("cal/thigh.yaml", text);
  const std::string body = write("body.yaml", R"(segments:
  - name: pelvis
  - name: thigh_l
    node: sensor7
    parent: pelvis
    calibration: cal/thigh.yaml
)");
  const fusion::BodyModel model = load_body_model(body);
  EXPECT_EQ(model.segments.size(), 2u);
  const auto calibrations = load_body_calibrations(body);
  ASSERT_EQ(calibrations.size(), 1u);
  ASSERT_EQ(calibrations.count("sensor7"), 1u);
  EXPECT_TRUE(calibrations.at("sensor7").magnetometer->bias.isApprox(calib::Vec3(1, -2, 3)));
  EXPECT_TRUE(load_body_calibrations("").empty());
}

TEST_F(TempDir, BodyKeyRefusesAFileMadeForAnotherNode) {
  write("imu.yaml", "node: imu\nrequest_id: r1\nmagnetometer:\n  bias: [1, 2, 3]\n");
  const std::string body = write("body.yaml", R"(segments:
  - name: pelvis
  - name: thigh_l
    calibration: imu.yaml
)");
  try {
    (void)load_body_calibrations(body);
    FAIL() << "a calibration for node imu was accepted on node thigh_l";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("imu.yaml:1: this calibration is for node 'imu'"), std::string::npos) << m;
    EXPECT_NE(m.find("body.yaml:4"), std::string::npos) << m;
    EXPECT_NE(m.find("on node 'thigh_l'"), std::string::npos) << m;
  }
  const CalibrationDocument doc = load_calibration_document((dir_ / "imu.yaml").string());
  EXPECT_EQ(doc.node, "imu");
  EXPECT_EQ(doc.request_id, "r1");
}

TEST_F(TempDir, BodyKeyWithABadFileStopsAtTheSegmentsLine) {
  write("broken.yaml", "magnetometer:\n  bias: [1, 2]\n");
  const std::string body = write("body.yaml", R"(segments:
  - name: pelvis
    calibration: missing.yaml
)");
  try {
    (void)load_body_model(body);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(body + ":3: calibration: "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos) << e.what();
  }
  const std::string body2 = write("body2.yaml", "segments:\n  - name: pelvis\n    calibration: broken.yaml\n");
  try {
    (void)load_body_model(body2);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("broken.yaml:2: magnetometer bias must be a list of 3 numbers"),
              std::string::npos)
        << e.what();
  }
}

TEST_F(TempDir, AlignmentFileLoadsBackExactlyWithWhatItWasFittedFrom) {
  AlignmentRecord a;
  a.segment = "shank_l";
  a.sensor_to_segment = calib::Quat(Eigen::AngleAxisd(2.0, calib::Vec3(1, -2, 0.5).normalized()));
  a.source = "pose+hinge thigh_l-shank_l";
  a.hinge_residual = 0.031;
  a.axis_observability = 0.052;
  a.samples = 2400;
  const std::string path = write("shank_l.alignment.calib.yaml", alignment_to_yaml("shank_l", a, "lab-7"));
  const CalibrationDocument doc = load_calibration_document(path);
  EXPECT_EQ(doc.node, "shank_l");
  EXPECT_EQ(doc.request_id, "lab-7");
  EXPECT_TRUE(doc.calibration.empty()) << "an alignment file holds no channel calibration";
  ASSERT_TRUE(doc.alignment);
  EXPECT_EQ(doc.alignment->segment, "shank_l");
  // Written with 12 significant digits: the rotation comes back within 1e-10 rad.
  EXPECT_LT(doc.alignment->sensor_to_segment.angularDistance(a.sensor_to_segment), 1e-10);
  EXPECT_EQ(doc.alignment->source, a.source);
  EXPECT_DOUBLE_EQ(doc.alignment->hinge_residual, 0.031);
  EXPECT_DOUBLE_EQ(doc.alignment->axis_observability, 0.052);
  EXPECT_EQ(doc.alignment->samples, 2400u);
}

TEST_F(TempDir, BadAlignmentsNameTheLineAndTheProblem) {
  auto error_of = [&](const std::string& text) {
    try {
      load_calibration_document(write("a.calib.yaml", text));
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of("alignment:\n  segment: s\n  sensor_to_segment: [2, 0, 0, 0]\n")
                .find(":3: sensor_to_segment "
                      "must be a unit"),
            std::string::npos);
  EXPECT_NE(error_of("alignment:\n  sensor_to_segment: [1, 0, 0, 0]\n").find("needs segment"), std::string::npos);
  EXPECT_NE(error_of("alignment:\n  segment: s\n  sensor_to_segment: [1, 0, 0]\n").find("[w, x, y, z]"),
            std::string::npos);
}

TEST_F(TempDir, BodyKeyAppliesAnAlignmentToItsSegmentOnly) {
  AlignmentRecord a;
  a.segment = "shank_l";
  a.sensor_to_segment = calib::Quat(Eigen::AngleAxisd(1.0, calib::Vec3::UnitX()));
  write("shank.calib.yaml", alignment_to_yaml("shank_l", a));
  const std::string body_path = write("body.yaml",
                                      "segments:\n  - name: thigh_l\n  - name: shank_l\n    parent: thigh_l\n"
                                      "    calibration: shank.calib.yaml\n");
  fusion::BodyModel body = load_body_model(body_path);
  apply_body_alignments(body_path, body);
  EXPECT_FALSE(body.segments[0].sensor_to_segment);
  ASSERT_TRUE(body.segments[1].sensor_to_segment);
  EXPECT_LT(body.segments[1].sensor_to_segment->angularDistance(a.sensor_to_segment), 1e-10);
  // Fitted for another segment: refused, naming both.
  a.segment = "thigh_l";
  write("shank.calib.yaml", alignment_to_yaml("shank_l", a));
  try {
    apply_body_alignments(body_path, body);
    ADD_FAILURE() << "an alignment of another segment was applied";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("fitted for segment 'thigh_l'"), std::string::npos) << e.what();
  }
  // Two mountings for one sensor: refused at the body file's line.
  a.segment = "shank_l";
  write("shank.calib.yaml", alignment_to_yaml("shank_l", a));
  const std::string twice = write("twice.yaml",
                                  "segments:\n  - name: shank_l\n    sensor_to_segment: [1, 0, 0, 0]\n"
                                  "    calibration: shank.calib.yaml\n");
  body = load_body_model(twice);
  try {
    apply_body_alignments(twice, body);
    ADD_FAILURE() << "two mountings were accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("twice.yaml:4: segment 'shank_l' gives its mounting twice"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace bsn::config
