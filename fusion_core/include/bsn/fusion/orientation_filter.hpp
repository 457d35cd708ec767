// The interface every orientation filter implements, and the factory that makes one from a name and
// parameters (the body model's per-segment `filter:` block).
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion {

/// Why the filter did what it did at the last update.
struct FilterFlags {
  bool resting = false;        ///< the sensor has been still for the rest time
  bool mag_rejected = false;   ///< the magnetometer was present but not used (disturbed or degenerate)
  bool initialising = false;   ///< within the start-up period after (re)initialisation
  bool reinitialised = false;  ///< this update re-initialised the state (first sample, long gap)
};

enum class UpdateResult {
  kUpdated,      ///< the state advanced with this sample
  kInitialised,  ///< the state was (re)initialised from this sample
  kRejected,     ///< the sample was not used and the state is unchanged (non-finite, time not advancing,
                 ///< or no accelerometer to initialise from)
};

class OrientationFilter {
 public:
  virtual ~OrientationFilter() = default;

  /// Feeds one sample. Non-finite input or a timestamp that does not advance is rejected without touching
  /// the state.
  virtual UpdateResult update(const ImuSample& sample) = 0;

  /// Sensor-to-earth orientation after the last update (identity before the first).
  virtual Quat orientation() const = 0;

  virtual FilterFlags flags() const = 0;

  /// Gyro bias estimate, sensor frame, rad/s; zero for filters that estimate none.
  virtual Vec3 gyro_bias() const = 0;

  /// True once the filter has an orientation.
  virtual bool initialised() const = 0;

  /// Forgets the state; the next usable sample initialises again.
  virtual void reset() = 0;

  /// Registered factory name, e.g. "complementary".
  virtual std::string_view name() const = 0;
};

/// A filter's name and parameter overrides (name -> value, SI units as each filter documents).
struct FilterSpec {
  std::string name = "seel_ruppin";  ///< the default: the most accurate on the BROAD recordings
  std::vector<std::pair<std::string, double>> parameters;
};

/// Names make_filter accepts.
std::vector<std::string> filter_names();

/// Makes a filter. Throws std::invalid_argument naming the problem for an unknown filter, an unknown
/// parameter or an out-of-range value.
std::unique_ptr<OrientationFilter> make_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
