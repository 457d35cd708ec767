// Sensor error models and presets; determinism of the whole scenario runner.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "bsn/sim/scenario.hpp"
#include "bsn/sim/sensor_model.hpp"

namespace bsn::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

TEST(SimSensorModel, IdealPresetIsExact) {
  const SensorErrors ideal = *sensor_preset("ideal");
  EXPECT_TRUE(ideal.gyr.ideal() && ideal.acc.ideal() && ideal.mag.ideal());
  SensorSimulator sim(ideal, 100.0, 1);
  const Vec3 w(0.1, -2.0, 3.0), f(1.0, 2.0, 9.0), m(20.0, -5.0, -40.0);
  for (int k = 0; k < 10; ++k) {
    const auto s = sim.measure(w, f, m, k * 0.01, 7, true);
    EXPECT_EQ(s.gyr, w);
    EXPECT_EQ(s.acc, f);
    EXPECT_EQ(s.mag, m);
  }
}

TEST(SimSensorModel, EveryPresetExistsAndUnknownIsRejected) {
  for (const std::string& name : sensor_preset_names()) EXPECT_TRUE(sensor_preset(name).has_value()) << name;
  EXPECT_FALSE(sensor_preset("perfect").has_value());
}

TEST(SimSensorModel, OpalPresetIsNezTable2) {
  const SensorErrors e = *sensor_preset("opal");
  EXPECT_EQ(e.gyr.white_density, 1e-3);                   // sigma_g, rad/s
  EXPECT_EQ(e.gyr.bias_instability, 3e-3);                // sigma_bg, rad/s
  EXPECT_EQ(e.acc.white_density, 4e-3);                   // sigma_a, m/s^2
  EXPECT_EQ(e.mag.white_density, 0.2);                    // sigma_m, uT
  EXPECT_DOUBLE_EQ(e.acc.range, 6.0 * fusion::kGravity);  // APDM: +-6 g
  EXPECT_EQ(e.mag_bandwidth_hz, 0.0);  // the same 50 Hz on every channel: no relative magnetometer lag
}

TEST(SimSensorModel, MagnetometerFollowsZhangYangEquation8) {
  // Without noise, the reading g satisfies u = R T S A_si (g - b - b_hi) exactly (Table I parameters).
  SensorErrors e = *sensor_preset("zhang_yang_table1");
  e.mag.white_density = 0.0;
  const Mat3 h = e.mag.physical_from_reading();
  SensorSimulator sim(e, 100.0, 1);
  for (const Vec3& u : {Vec3(20, 0, -44), Vec3(-30, 25, 10), Vec3(0, 0, 49)}) {
    const Vec3 g = sim.measure(Vec3::Zero(), Vec3::Zero(), u, 0.0, 0, true).mag;
    EXPECT_LT((h * (g - e.mag.bias - e.mag.hard_iron) - u).norm(), 1e-9);
  }
}

TEST(SimSensorModel, WhiteNoiseHasTheConfiguredDensity) {
  SensorErrors e;
  e.gyr.white_density = 0.01;
  const double rate = 200.0;
  SensorSimulator sim(e, rate, 9);
  const int n = 20000;
  double sum_sq = 0.0;
  for (int k = 0; k < n; ++k)
    sum_sq += sim.measure(Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), 0, 0, true).gyr.squaredNorm();
  // Per-sample SD = density * sqrt(rate); relative standard error of the estimate 1/sqrt(6n) ~ 0.3 %.
  EXPECT_NEAR(std::sqrt(sum_sq / (3.0 * n)), 0.01 * std::sqrt(rate), 0.02 * 0.01 * std::sqrt(rate));
}

TEST(SimSensorModel, SaturationQuantisationAndBiasSteps) {
  SensorErrors e;
  e.gyr.range = 2.0;
  e.gyr.lsb = 0.01;
  e.gyr.bias_steps.push_back({5.0, Vec3(0, 0, 2.0 * kDeg)});
  SensorSimulator sim(e, 100.0, 1);
  const Vec3 before = sim.measure(Vec3(3.0, -0.123456, 0.5), Vec3::Zero(), Vec3::Zero(), 4.99, 0, true).gyr;
  EXPECT_EQ(before.x(), 2.0);             // saturated
  EXPECT_NEAR(before.y(), -0.12, 1e-15);  // quantised to the LSB
  EXPECT_NEAR(before.z(), 0.5, 1e-15);
  const Vec3 after = sim.measure(Vec3(0, 0, 0.5), Vec3::Zero(), Vec3::Zero(), 5.0, 0, true).gyr;
  EXPECT_NEAR(after.z(), std::round((0.5 + 2.0 * kDeg) / 0.01) * 0.01, 1e-15);
}

TEST(SimSensorModel, RejectsBadParameters) {
  SensorErrors e;
  e.gyr.white_density = -1.0;
  EXPECT_THROW(SensorSimulator(e, 100.0, 1), std::invalid_argument);
  e = {};
  e.mag.scale = Vec3(1.0, 0.0, 1.0);
  EXPECT_THROW(SensorSimulator(e, 100.0, 1), std::invalid_argument);
  e = {};
  e.acc.bias.x() = std::nan("");
  EXPECT_THROW(SensorSimulator(e, 100.0, 1), std::invalid_argument);
  EXPECT_THROW(SensorSimulator({}, 0.0, 1), std::invalid_argument);
  e = {};
  e.drop_probability = 1.5;
  EXPECT_THROW(SensorSimulator(e, 100.0, 1), std::invalid_argument);
}

ScenarioSpec consumer_gait(std::uint64_t seed) {
  ScenarioSpec spec;
  spec.body = BodyKind::kLowerBody;
  spec.gait = Gait{};
  spec.duration_s = 20.0;
  spec.seed = seed;
  spec.sensors = *sensor_preset("consumer_mems");
  spec.sensors.drop_probability = 0.01;
  spec.sensors.jitter_s = 1e-3;
  return spec;
}

TEST(SimSensorModel, SlowMagnetometerDropsAndJitterAppearAtTheirRates) {
  ScenarioRunner runner(consumer_gait(4), {"foot_l"}, false);
  std::vector<ScenarioSample> out;
  int n = 0, mags = 0, drops = 0;
  double sum_sq_jitter = 0.0;
  std::uint64_t last_ns = 0;
  while (runner.next(out)) {
    const ScenarioSample& s = out[0];
    if (n > 0) {
      EXPECT_GT(s.sample.timestamp_ns, last_ns);
    }
    last_ns = s.sample.timestamp_ns;
    const double jitter = static_cast<double>(s.sample.timestamp_ns) * 1e-9 - n * 0.01;
    if (n > 0) sum_sq_jitter += jitter * jitter;
    mags += s.sample.has_mag;
    drops += s.dropped;
    ++n;
  }
  ASSERT_EQ(n, 2000);
  EXPECT_EQ(mags, 1000);  // 50 Hz magnetometer under a 100 Hz IMU
  // Binomial(2000, 0.01): mean 20, SD 4.5.
  EXPECT_GE(drops, 5);
  EXPECT_LE(drops, 40);
  EXPECT_NEAR(std::sqrt(sum_sq_jitter / (n - 1)), 1e-3, 0.1e-3);
}

// A magnetometer that lags the gyro by d samples reads the field of d samples earlier (the first ones repeat the first
// field); its own first-order low-pass answers a field step with 1 - exp(-2 pi f_c t), exactly at the sample times.
TEST(SimSensorModel, MagnetometerDelayAndBandwidth) {
  SensorErrors delayed;
  delayed.mag_delay_samples = 2;
  SensorSimulator d(delayed, 100.0, 1);
  for (int k = 0; k < 10; ++k) {
    const fusion::ImuSample s = d.measure(Vec3::Zero(), Vec3::Zero(), Vec3(k, 0, 0), k * 0.01, k, true);
    EXPECT_EQ(s.mag.x(), std::max(0, k - 2)) << k;
  }
  SensorErrors lowpassed;
  lowpassed.mag_bandwidth_hz = 5.0;
  SensorSimulator l(lowpassed, 100.0, 1);
  l.measure(Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), 0.0, 0, true);  // starts at the first field, 0
  for (int k = 1; k <= 50; ++k) {
    const fusion::ImuSample s = l.measure(Vec3::Zero(), Vec3::Zero(), Vec3(1, 0, 0), k * 0.01, k, true);
    EXPECT_NEAR(s.mag.x(), 1.0 - std::exp(-2.0 * std::numbers::pi * 5.0 * 0.01 * k), 1e-12) << k;
  }
  SensorErrors bad;
  bad.mag_delay_samples = -1;
  EXPECT_THROW(SensorSimulator(bad, 100.0, 1), std::invalid_argument);
  bad.mag_delay_samples = 0;
  bad.mag_bandwidth_hz = -1.0;
  EXPECT_THROW(SensorSimulator(bad, 100.0, 1), std::invalid_argument);
}

TEST(SimSensorModel, SameSeedIsBitIdenticalAnotherSeedDiffers) {
  ScenarioRunner a(consumer_gait(42), {}, false), b(consumer_gait(42), {}, false), c(consumer_gait(43), {}, false);
  std::vector<ScenarioSample> sa, sb, sc;
  int differ = 0, n = 0;
  while (a.next(sa)) {
    ASSERT_TRUE(b.next(sb));
    ASSERT_TRUE(c.next(sc));
    for (std::size_t i = 0; i < sa.size(); ++i) {
      EXPECT_EQ(sa[i].sample.gyr, sb[i].sample.gyr);
      EXPECT_EQ(sa[i].sample.acc, sb[i].sample.acc);
      EXPECT_EQ(sa[i].sample.mag, sb[i].sample.mag);
      EXPECT_EQ(sa[i].sample.timestamp_ns, sb[i].sample.timestamp_ns);
      EXPECT_EQ(sa[i].dropped, sb[i].dropped);
      EXPECT_EQ(sa[i].truth.coeffs(), sb[i].truth.coeffs());
      differ += sa[i].sample.gyr != sc[i].sample.gyr;
      ++n;
    }
  }
  EXPECT_GT(differ, n * 9 / 10);  // quantisation can hide a noise difference only rarely
  // The sensors of different segments get different noise from the same seed.
  ScenarioRunner d(consumer_gait(42), {"thigh_l", "thigh_r"}, false);
  ASSERT_TRUE(d.next(sa));
  EXPECT_NE(sa[0].sample.acc - sa[0].truth.conjugate() * Vec3(0, 0, fusion::kGravity),
            sa[1].sample.acc - sa[1].truth.conjugate() * Vec3(0, 0, fusion::kGravity));
}

TEST(SimSensorModel, SelectingSegmentsDoesNotChangeTheirNoise) {
  ScenarioRunner all(consumer_gait(8), {}, false), one(consumer_gait(8), {"shank_r"}, false);
  std::vector<ScenarioSample> a, o;
  const std::size_t shank_r = *all.body().find("shank_r");
  for (int k = 0; k < 50; ++k) {
    ASSERT_TRUE(all.next(a) && one.next(o));
    EXPECT_EQ(a[shank_r].sample.gyr, o[0].sample.gyr);
  }
  EXPECT_THROW(ScenarioRunner(consumer_gait(8), {"tail"}, false), std::invalid_argument);
}

}  // namespace
}  // namespace bsn::sim
