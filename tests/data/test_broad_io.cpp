#include <gtest/gtest.h>

#include <algorithm>

#include "broad_data.hpp"
#include "bsn/io/recording.hpp"

namespace bsn {
namespace {

TEST(BroadData, EveryTrialReadsWithConsistentChannels) {
  BSN_REQUIRE_BROAD();
  const auto files = testing::broad_files();
  EXPECT_EQ(files.size(), 8u);
  for (const auto& f : files) {
    const io::Recording rec = io::read_broad_hdf5(f.string());
    EXPECT_NEAR(rec.sampling_rate_hz, 285.714, 0.1) << f;
    EXPECT_GT(rec.size(), 10000u) << f;
    EXPECT_EQ(static_cast<std::size_t>(rec.opt_quat.rows()), rec.size()) << f;
    EXPECT_EQ(rec.movement.size(), rec.size()) << f;
    // Physics: outside the movement phase the sensor rests, so the specific force is g; the field magnitude is
    // that of a lab (tens of uT).
    std::vector<double> rest_acc;
    for (std::size_t i = 0; i < rec.size(); ++i) {
      if (!rec.movement[i]) rest_acc.push_back(rec.acc.row(static_cast<Eigen::Index>(i)).norm());
    }
    ASSERT_FALSE(rest_acc.empty()) << f;
    std::nth_element(rest_acc.begin(), rest_acc.begin() + static_cast<std::ptrdiff_t>(rest_acc.size() / 2),
                     rest_acc.end());
    EXPECT_NEAR(rest_acc[rest_acc.size() / 2], 9.81, 0.2) << f;
    const double mag = rec.mag.rowwise().norm().mean();
    EXPECT_GT(mag, 10.0) << f;
    EXPECT_LT(mag, 200.0) << f;
    // Reference quaternions are unit where present.
    for (Eigen::Index i = 0; i < rec.opt_quat.rows(); i += 97) {
      if (!rec.opt_quat.row(i).array().isNaN().any()) {
        EXPECT_NEAR(rec.opt_quat.row(i).norm(), 1.0, 1e-6) << f;
      }
    }
    EXPECT_GT(std::count(rec.movement.begin(), rec.movement.end(), 1), 0) << f;
  }
}

}  // namespace
}  // namespace bsn
