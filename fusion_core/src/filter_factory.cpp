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

// The registry: one line per filter (name, 6D-only, maker). Each filter's header declares its make_* function.
constexpr FilterInfo kFilters[] = {
    {"complementary", false, &make_complementary_filter},
    {"dlkf", false, &make_dlkf_filter},
    {"ekf", false, &make_ekf_filter},
    {"mekf", false, &make_mekf_filter},
    {"mekf_adaptive", false, &make_mekf_adaptive_filter},
    {"seel_ruppin", false, &make_seel_ruppin_filter},
    {"seel_ruppin6", true, &make_seel_ruppin6_filter},
    {"madgwick", false, &make_madgwick_filter},
    {"madgwick6", true, &make_madgwick6_filter},
    {"iecf", false, &make_iecf_filter},
    {"iecf6", true, &make_iecf6_filter},
};

}  // namespace

OrientationFilter::OrientationFilter(std::string_view filter, const FilterTimingParams& timing) {
  timing.check(filter);
  max_gap_ns_ = seconds_to_ns(timing.max_gap_s);
  init_period_ns_ = seconds_to_ns(timing.init_period_s);
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
