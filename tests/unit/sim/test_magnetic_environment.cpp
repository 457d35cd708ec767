// The magnetic environment: earth field, dipoles (1/r^3), floor regions, heading changes, attached magnets,
// and the magnetometer's ideal reading R^T field.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "bsn/sim/magnetic_environment.hpp"
#include "bsn/sim/scenario.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(SimMagnetic, DefaultEarthFieldIs49MicroteslaWith64DegreesDip) {
  const MagneticEnvironment env;
  const Vec3 b = env.earth_field(0.0);
  const MagnitudeDip md = magnitude_and_dip(b);
  EXPECT_NEAR(md.magnitude_ut, 49.0, 1e-12);
  EXPECT_NEAR(md.dip_rad, 64.0 * kDeg, 1e-12);
  EXPECT_NEAR(b.x(), 0.0, 1e-12);  // horizontal part points north (+y)
  EXPECT_GT(b.y(), 0.0);
  EXPECT_LT(b.z(), 0.0);  // northern hemisphere: down
}

TEST(SimMagnetic, DipoleFieldFallsWithTheCubeOfTheDistance) {
  const Vec3 m(0.0, 0.0, 0.5);  // A m^2
  // On the axis: mu0/(4 pi) 2m / r^3 = 0.1 uT m/A * 2 * 0.5 / r^3.
  EXPECT_NEAR(dipole_field(m, Vec3(0, 0, 0.1)).z(), 0.1 * 2.0 * 0.5 / 1e-3, 1e-9);
  for (const Vec3& dir : {Vec3(1, 0, 0), Vec3(0.3, -0.4, 0.8).normalized(), Vec3(0, 0, 1)}) {
    const Vec3 near = dipole_field(m, 0.1 * dir), far = dipole_field(m, 0.2 * dir);
    EXPECT_LT((near - 8.0 * far).norm(), 1e-9 * near.norm());
  }
  EXPECT_EQ(dipole_field(m, Vec3::Zero()), Vec3::Zero());
}

TEST(SimMagnetic, ApproachingDipoleAppearsOnlyInsideItsWindows) {
  MagneticEnvironment env;
  env.dipoles.push_back({Vec3(0.08, 0, 1), Vec3(0.05, 0, 0), Vec3(1.0, 0, 0), {{2.0, 4.0, 0.5}}});
  const Vec3 p(0, 0, 1);
  EXPECT_LT((env.field_at(p, 1.0) - env.earth_field(1.0)).norm(), 0.05);  // 1 m away: < 0.1 uT
  EXPECT_GT((env.field_at(p, 3.0) - env.earth_field(3.0)).norm(), 15.0);  // 8 cm, 0.05 A m^2 on axis: 19.5 uT
  EXPECT_NEAR((env.field_at(p, 3.0) - env.earth_field(3.0)).x(), 0.1 * 2 * 0.05 / std::pow(0.08, 3), 1e-9);
  EXPECT_LT((env.field_at(p, 5.0) - env.earth_field(5.0)).norm(), 0.05);
}

TEST(SimMagnetic, FloorRegionAddsItsFieldInsideAndFadesAtTheEdge) {
  MagneticEnvironment env;
  env.floor_regions.push_back({Vec3(1, -1, -1), Vec3(3, 1, 0.5), Vec3(5, -10, 20), 0.2, {}});
  EXPECT_LT((env.field_at(Vec3(2, 0, 0), 0) - env.earth_field(0) - Vec3(5, -10, 20)).norm(), 1e-12);
  EXPECT_LT((env.field_at(Vec3(0.5, 0, 0), 0) - env.earth_field(0)).norm(), 1e-12);
  EXPECT_LT((env.field_at(Vec3(2, 0, 0.8), 0) - env.earth_field(0)).norm(), 1e-12);
  const double half = (env.field_at(Vec3(1.1, 0, 0), 0) - env.earth_field(0)).norm() / Vec3(5, -10, 20).norm();
  EXPECT_NEAR(half, 0.5, 1e-12);  // the smooth step is at half height in the middle of the edge
}

TEST(SimMagnetic, HeadingChangeKeepsMagnitudeAndDip) {
  MagneticEnvironment env;
  env.heading_changes.push_back({10.0, 50.0 * kDeg, 0.0});
  env.heading_changes.push_back({20.0, 129.0 * kDeg, 2.0});
  const Vec3 before = env.earth_field(5.0), after = env.earth_field(15.0), later = env.earth_field(30.0);
  for (const Vec3& b : {after, later, env.earth_field(21.0)}) {
    EXPECT_NEAR(b.norm(), 49.0, 1e-12);
    EXPECT_NEAR(b.z(), before.z(), 1e-12);
  }
  auto heading = [](const Vec3& b) { return std::atan2(-b.x(), b.y()); };
  EXPECT_NEAR(heading(after) - heading(before), 50.0 * kDeg, 1e-12);
  EXPECT_NEAR(heading(later) - heading(before), 179.0 * kDeg, 1e-12);
}

TEST(SimMagnetic, AttachedMagnetIsAHardIronOffsetThatTurnsWithTheSensor) {
  MagneticEnvironment env;
  env.attached_magnets.push_back({0, Vec3(0, 0.03, 0), Vec3(0, 0.01, 0)});
  const Vec3 offset = env.attached_magnets[0].field_sensor_ut();
  EXPECT_NEAR(offset.y(), 0.1 * 2 * 0.01 / std::pow(0.03, 3), 1e-9);
  for (const Quat& q : {Quat::Identity(), fusion::from_yaw_pitch_roll({1.0, 0.4, -2.0})}) {
    const Vec3 reading = env.sensor_field(0, Vec3(0, 0, 1), q, 0.0);
    EXPECT_LT((reading - q.conjugate() * env.earth_field(0.0) - offset).norm(), 1e-12);
    EXPECT_LT((env.sensor_field(1, Vec3(0, 0, 1), q, 0.0) - q.conjugate() * env.earth_field(0.0)).norm(), 1e-12);
  }
}

TEST(SimMagnetic, IdealMagnetometerEqualsRotatedFieldAtTheSensor) {
  ScenarioSpec spec;
  spec.body = BodyKind::kLowerBody;
  spec.gait = Gait{};
  spec.duration_s = 5.0;
  spec.sensors = *sensor_preset("consumer_mems");
  spec.magnetic.dipoles.push_back({Vec3(2.0, 0.3, 0.1), Vec3(0, 0, 2.0), Vec3::Zero(), {}});
  spec.magnetic.floor_regions.push_back({Vec3(1, -2, -1), Vec3(4, 2, 0.3), Vec3(10, 5, -20), 0.3, {}});
  ScenarioRunner runner(spec, {}, /*ideal=*/true);
  std::vector<ScenarioSample> out;
  std::vector<SegmentState> states;
  int disturbed = 0;
  for (std::uint64_t k = 0; runner.next(out); ++k) {
    const double t = static_cast<double>(k) / spec.rate_hz;
    runner.body().evaluate(t, states);
    for (std::size_t i = 0; i < out.size(); ++i) {
      const Vec3 field = runner.magnetic().field_at(states[i].position, t);
      EXPECT_LT((out[i].sample.mag - out[i].truth.conjugate() * field).norm(), 1e-9);
      EXPECT_LT((out[i].sample.acc - states[i].specific_force_sensor()).norm(), 1e-12);
      EXPECT_LT((out[i].sample.gyr - states[i].gyr_sensor).norm(), 1e-12);
      EXPECT_TRUE(out[i].sample.has_mag);
      EXPECT_FALSE(out[i].dropped);
      if ((field - runner.magnetic().earth_field(t)).norm() > 1.0) ++disturbed;
    }
  }
  EXPECT_GT(disturbed, 100);  // the walk crosses the disturbed region
}

}  // namespace
}  // namespace bsn::sim
