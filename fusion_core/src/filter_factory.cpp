#include <string>

#include "bsn/fusion/complementary_filter.hpp"
#include "bsn/fusion/dlkf_filter.hpp"
#include "bsn/fusion/ekf_filter.hpp"
#include "bsn/fusion/iecf_filter.hpp"
#include "bsn/fusion/madgwick_filter.hpp"
#include "bsn/fusion/mekf_filter.hpp"
#include "bsn/fusion/orientation_filter.hpp"
#include "bsn/fusion/seel_ruppin_filter.hpp"

namespace bsn::fusion {
namespace {

struct FilterMaker {
  const char* name;
  std::unique_ptr<OrientationFilter> (*make)(const FilterSpec&);
};

// Every filter the body model can name. Each filter's header declares its make_* function.
constexpr FilterMaker kFilters[] = {
    {"complementary", &make_complementary_filter},
    {"dlkf", &make_dlkf_filter},
    {"ekf", &make_ekf_filter},
    {"mekf", &make_mekf_filter},
    {"mekf_adaptive", &make_mekf_adaptive_filter},
    {"seel_ruppin", &make_seel_ruppin_filter},
    {"madgwick", &make_madgwick_filter},
    {"madgwick6", &make_madgwick6_filter},
    {"iecf", &make_iecf_filter},
    {"iecf6", &make_iecf6_filter},
};

}  // namespace

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
