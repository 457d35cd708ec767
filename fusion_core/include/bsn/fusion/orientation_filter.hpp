// The interface every orientation filter implements, the skeleton of update() they share, and the registry that
// makes one from a name and parameters (the body model's per-segment `filter:` block).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "bsn/fusion/imu_sample.hpp"

namespace bsn::fusion {

struct FilterTimingParams;

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

/// The timing state every filter keeps; OrientationFilter holds it and advances it.
struct FilterClock {
  bool initialised = false;   ///< the filter has an orientation
  std::uint64_t last_ns = 0;  ///< timestamp of the last used sample
  std::uint64_t init_ns = 0;  ///< timestamp of the last (re)initialisation
};

/// A saved filter state, opaque: OrientationFilter::save() makes one, restore() takes it back into a filter of the
/// same name and parameters.
class FilterSnapshot {
 public:
  virtual ~FilterSnapshot() = default;
  std::string_view filter() const { return filter_; }  ///< the registered name of the filter it was saved from

 private:
  friend class OrientationFilter;
  std::string_view filter_;
  FilterClock clock_;
};

class OrientationFilter {
 public:
  virtual ~OrientationFilter() = default;

  /// Feeds one sample, in this order:
  ///  - a non-finite sample (ImuSample::finite()) is rejected without touching the state;
  ///  - the first usable sample initialises the orientation from start_orientation() (kInitialised);
  ///  - a timestamp that does not advance is rejected without touching the state;
  ///  - the gap rule: after a gap longer than max_gap_s the orientation restarts from the sample as at the first
  ///    one (kInitialised, flags().reinitialised), and the gyro bias estimate is KEPT: the bias belongs to the
  ///    sensor, which a gap does not change, while the orientation may have moved unobserved;
  ///  - otherwise the state advances by dt = the time since the last used sample (kUpdated).
  UpdateResult update(const ImuSample& sample) {
    if (!sample.finite()) return UpdateResult::kRejected;
    if (clock_.initialised) {
      if (sample.timestamp_ns <= clock_.last_ns) return UpdateResult::kRejected;
      const std::uint64_t dt_ns = sample.timestamp_ns - clock_.last_ns;
      if (dt_ns <= max_gap_ns_) {
        const UpdateResult result = step(sample, static_cast<double>(dt_ns) * 1e-9);
        if (result == UpdateResult::kUpdated) clock_.last_ns = sample.timestamp_ns;
        return result;
      }
    }
    const UpdateResult result = start(sample);
    if (result == UpdateResult::kInitialised) clock_ = {true, sample.timestamp_ns, sample.timestamp_ns};
    return result;
  }

  /// Sensor-to-earth orientation after the last update (identity before the first).
  virtual Quat orientation() const = 0;

  virtual FilterFlags flags() const = 0;

  /// Gyro bias estimate, sensor frame, rad/s; zero for filters that estimate none.
  virtual Vec3 gyro_bias() const = 0;

  /// True once the filter has an orientation.
  bool initialised() const { return clock_.initialised; }

  /// Forgets the whole state, the gyro bias estimate too; the next usable sample initialises again.
  void reset() {
    clock_ = FilterClock{};
    clear();
  }

  /// Everything the filter keeps between samples (its clock and its State, the components in it included), copied;
  /// allocates once, never touched by update().
  std::unique_ptr<FilterSnapshot> save() const;
  /// Puts a saved state back: the filter then continues bit for bit as the one it was saved from, provided both were
  /// made with the same parameters (which a State does not carry). Throws std::invalid_argument for a snapshot of
  /// another filter.
  void restore(const FilterSnapshot& snapshot);

  /// Registered name, e.g. "complementary".
  std::string_view name() const { return name_; }

  const FilterClock& clock() const { return clock_; }

 protected:
  /// Checks the timing parameters (std::invalid_argument naming `filter`) and keeps them in ns. `filter` is the
  /// registered name (a string literal: snapshots keep it).
  OrientationFilter(std::string_view filter, const FilterTimingParams& timing);

  /// (Re)initialises from the sample: orientation and everything tied to it, never the gyro bias estimate (the gap
  /// rule). initialised() tells a restart after a gap (true) from the first start (false). Returns kInitialised, or
  /// kRejected with the state unchanged when the sample cannot give an orientation.
  virtual UpdateResult start(const ImuSample& sample) = 0;
  /// Advances the state by dt_s (0 < dt_s <= max_gap_s) with the sample; clock() still holds the previous sample's
  /// time. Returns kUpdated, or kRejected with the state unchanged.
  virtual UpdateResult step(const ImuSample& sample, double dt_s) = 0;
  /// Clears the filter's own state, the gyro bias estimate included (reset()).
  virtual void clear() = 0;

  /// The filter's State in a snapshot (save()), and back (restore(); the snapshot is of this filter's class).
  virtual std::unique_ptr<FilterSnapshot> save_state() const = 0;
  virtual void restore_state(const FilterSnapshot& snapshot) = 0;
  /// The snapshot of a State, and the State of a snapshot made by state_snapshot<State>.
  template <class State>
  struct StateSnapshot final : FilterSnapshot {
    explicit StateSnapshot(const State& s) : state(s) {}
    State state;
  };
  template <class State>
  static std::unique_ptr<FilterSnapshot> state_snapshot(const State& state) {
    return std::make_unique<StateSnapshot<State>>(state);
  }
  template <class State>
  static const State& snapshot_state(const FilterSnapshot& snapshot) {
    return static_cast<const StateSnapshot<State>&>(snapshot).state;
  }

  /// True within init_period_s of the last (re)initialisation.
  bool within_init_period(std::uint64_t t_ns) const { return t_ns - clock_.init_ns < init_period_ns_; }
  std::uint64_t max_gap_ns() const { return max_gap_ns_; }
  std::uint64_t init_period_ns() const { return init_period_ns_; }

 private:
  std::string_view name_;
  FilterClock clock_;
  std::uint64_t max_gap_ns_ = 0;
  std::uint64_t init_period_ns_ = 0;
};

/// The base of every filter: its Params (P, derived from FilterTimingParams) and its State (S: everything it keeps
/// between samples, the components in it included, with the orientation `q` and the `flags`), a fresh filter's State
/// for reset(), and what the interface asks of them. A filter derives from FilterBase<ItsParams, ItsState>, fills
/// state_ with its components in its constructor and ends it with keep_fresh_state().
template <class P, class S>
class FilterBase : public OrientationFilter {
 public:
  using Params = P;
  using State = S;

  Quat orientation() const final { return state_.q; }
  FilterFlags flags() const final { return state_.flags; }
  /// The State's gyro bias estimate: its `gyro_bias` or `bias`, else its rest low-pass's (`bias_lowpass`).
  Vec3 gyro_bias() const final {
    if constexpr (requires { state_.gyro_bias; }) {
      return state_.gyro_bias;
    } else if constexpr (requires { state_.bias; }) {
      return state_.bias;
    } else {
      return state_.bias_lowpass.bias();
    }
  }
  const Params& params() const { return params_; }
  const State& state() const { return state_; }
  /// Continues from a state() of a filter with the same parameters.
  void set_state(const State& state) { state_ = state; }

 protected:
  /// `params` as checked by the filter; the timing parameters are checked here.
  FilterBase(std::string_view filter, const Params& params) : OrientationFilter(filter, params), params_(params) {}
  /// The state reset() returns to: state_ as the constructor leaves it.
  void keep_fresh_state() { fresh_ = state_; }
  const State& fresh_state() const { return fresh_; }
  void clear() override { state_ = fresh_; }
  /// The end of a step that advanced the state: the rest detector and the start-up flag see the sample.
  UpdateResult updated(const ImuSample& s) {
    state_.flags.resting = state_.rest.update(s);
    state_.flags.initialising = within_init_period(s.timestamp_ns);
    return UpdateResult::kUpdated;
  }

  Params params_;
  State state_;

 private:
  std::unique_ptr<FilterSnapshot> save_state() const final { return state_snapshot(state_); }
  void restore_state(const FilterSnapshot& snapshot) final { state_ = snapshot_state<State>(snapshot); }

  State fresh_;
};

/// A filter's name and parameter overrides (name -> value, SI units as each filter documents).
struct FilterSpec {
  std::string name = "seel_ruppin";  ///< the default: the most accurate on the BROAD recordings
  std::vector<std::pair<std::string, double>> parameters;
};

/// One registered filter: its name, its capabilities (what the tests of every filter ask of it) and its maker.
struct FilterInfo {
  const char* name;
  /// Never uses the magnetometer after the start (which may take its heading from it).
  bool six_d_only = false;
  /// Rejects a disturbed magnetometer with the shared MagDisturbanceDetector, whose parameters (mag_norm_enter,
  /// mag_norm_leave, mag_reference_tau_s, mag_max_rejection_s, mag_accept_after_s ...) it takes under their names.
  bool rejects_magnetometer = false;
  std::unique_ptr<OrientationFilter> (*make)(const FilterSpec&) = nullptr;  ///< throws as make_filter() does
};

/// Every filter the body model can name, in the order filter_names() lists them.
std::span<const FilterInfo> filter_registry();

/// Names make_filter accepts.
std::vector<std::string> filter_names();

/// Makes a filter. Throws std::invalid_argument naming the problem for an unknown filter, an unknown
/// parameter or an out-of-range value.
std::unique_ptr<OrientationFilter> make_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
