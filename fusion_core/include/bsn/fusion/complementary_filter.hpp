// A plain complementary filter: strapdown gyro integration, a tilt correction towards the accelerometer
// and a heading-only correction towards the horizontal magnetic field, each a first-order low-pass with
// an interpretable time constant. No bias estimation. It is the reference the seed filters must beat.
#pragma once

#include <string_view>

#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/rest_detector.hpp"

namespace bsn::fusion {

class ComplementaryFilter final : public OrientationFilter {
 public:
  /// Own fields below; rest detection and the gap and start-up timing come from the base structs (documented there).
  struct Params : RestDetector::Params, FilterTimingParams {
    /// Time constant of the tilt correction towards the accelerometer, s. Larger trusts the gyro longer
    /// (less sensitive to accelerations), smaller removes gyro drift faster. Default 2 s.
    double tau_acc_s = 2.0;
    /// Time constant of the heading correction towards the magnetometer, s. Default 4 s.
    double tau_mag_s = 4.0;
    /// The accelerometer is skipped when | |acc| - g | exceeds this, m/s^2 (strong external
    /// acceleration). Default 3 m/s^2.
    double acc_rejection_m_s2 = 3.0;
    /// The magnetometer is rejected when its norm differs from the norm at initialisation by more than this
    /// fraction (a magnetic disturbance). Default 0.2 (20 %).
    double mag_norm_tolerance = 0.2;
  };

  /// Quantities derived once from Params.
  struct Coefficients {
    double inv_tau_acc = 0.0;  ///< 1/tau_acc, 1/s; gain per sample is 1 - exp(-dt/tau)
    double inv_tau_mag = 0.0;  ///< 1/tau_mag, 1/s
  };

  struct State {
    Quat q = Quat::Identity();  ///< sensor-to-earth
    double mag_ref_norm = 0.0;  ///< |mag| at initialisation, uT; 0 = not known yet
    double gain_dt_s = -1.0;    ///< step for which gain_acc and gain_mag hold (dt rarely changes), s
    double gain_acc = 0.0;      ///< 1 - exp(-dt / tau_acc)
    double gain_mag = 0.0;      ///< 1 - exp(-dt / tau_mag)
    FilterFlags flags;
  };

  /// Throws std::invalid_argument on a non-positive or non-finite parameter.
  explicit ComplementaryFilter(const Params& params);
  ComplementaryFilter() : ComplementaryFilter(Params{}) {}

  Quat orientation() const override { return state_.q; }
  FilterFlags flags() const override { return state_.flags; }
  Vec3 gyro_bias() const override { return Vec3::Zero(); }
  std::string_view name() const override { return "complementary"; }

  const Params& params() const { return params_; }
  const State& state() const { return state_; }

 private:
  UpdateResult start(const ImuSample& s) override;
  UpdateResult step(const ImuSample& s, double dt) override;
  void clear() override {
    state_ = State{};
    rest_.reset();
  }

  Params params_;
  Coefficients coeff_;
  State state_;
  RestDetector rest_;
};

/// Factory entry: "complementary" with the Params fields as parameter names.
std::unique_ptr<OrientationFilter> make_complementary_filter(const FilterSpec& spec);

}  // namespace bsn::fusion
