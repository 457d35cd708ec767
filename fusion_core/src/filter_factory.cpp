#include <stdexcept>
#include <string>

#include "bsn/fusion/complementary_filter.hpp"
#include "bsn/fusion/dlkf_filter.hpp"
#include "bsn/fusion/ekf_filter.hpp"
#include "bsn/fusion/filter_params.hpp"
#include "bsn/fusion/iecf_filter.hpp"
#include "bsn/fusion/madgwick_filter.hpp"
#include "bsn/fusion/mekf_filter.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/seel_ruppin_filter.hpp"

namespace bsn::fusion {
namespace {

// The registry: one line per filter (name, capabilities, maker). Each filter's header declares its make_* function.
constexpr FilterInfo kFilters[] = {
    {.name = "complementary", .rejects_magnetometer = true, .make = &make_complementary_filter},
    {.name = "dlkf", .rejects_magnetometer = true, .make = &make_dlkf_filter},
    {.name = "ekf", .rejects_magnetometer = true, .make = &make_ekf_filter},
    {.name = "mekf", .rejects_magnetometer = true, .make = &make_mekf_filter},
    {.name = "mekf_adaptive", .rejects_magnetometer = true, .make = &make_mekf_adaptive_filter},
    {.name = "seel_ruppin", .rejects_magnetometer = true, .make = &make_seel_ruppin_filter},
    {.name = "seel_ruppin6", .six_d_only = true, .make = &make_seel_ruppin6_filter},
    {.name = "madgwick", .make = &make_madgwick_filter},
    {.name = "madgwick6", .six_d_only = true, .make = &make_madgwick6_filter},
    {.name = "iecf", .rejects_magnetometer = true, .make = &make_iecf_filter},
    {.name = "iecf6", .six_d_only = true, .make = &make_iecf6_filter},
};

}  // namespace

OrientationFilter::OrientationFilter(std::string_view filter, const FilterTimingParams& timing) : name_(filter) {
  timing.check(filter);
  max_gap_ns_ = seconds_to_ns(timing.max_gap_s);
  init_period_ns_ = seconds_to_ns(timing.init_period_s);
}

std::unique_ptr<FilterSnapshot> OrientationFilter::save() const {
  std::unique_ptr<FilterSnapshot> snapshot = save_state();
  snapshot->filter_ = name();
  snapshot->clock_ = clock_;
  return snapshot;
}

void OrientationFilter::restore(const FilterSnapshot& snapshot) {
  // Names are unique in the registry and every name belongs to one class, so the name tells the State's type.
  if (snapshot.filter_ != name()) {
    throw std::invalid_argument("cannot restore a state of filter '" + std::string(snapshot.filter_) +
                                "' into filter '" + std::string(name()) + "'");
  }
  restore_state(snapshot);
  clock_ = snapshot.clock_;
}

std::span<const FilterInfo> filter_registry() { return kFilters; }

std::vector<std::string> filter_names() {
  std::vector<std::string> names;
  for (const auto& f : kFilters) names.emplace_back(f.name);
  return names;
}

std::unique_ptr<OrientationFilter> make_filter(const FilterSpec& spec) {
  for (const auto& f : kFilters) {
    if (spec.name == f.name) return f.make(spec);
  }
  std::string names;
  for (const auto& n : filter_names()) names += (names.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown filter '" + spec.name + "' (known: " + names + ")");
}

}  // namespace bsn::fusion
