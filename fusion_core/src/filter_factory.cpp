#include <cmath>
#include <stdexcept>
#include <string>

#include "bsn/fusion/complementary_filter.hpp"
#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::fusion {
namespace {

struct NamedParam {
  const char* name;
  double ComplementaryFilter::Params::*field;
};

constexpr NamedParam kComplementaryParams[] = {
    {"tau_acc_s", &ComplementaryFilter::Params::tau_acc_s},
    {"tau_mag_s", &ComplementaryFilter::Params::tau_mag_s},
    {"max_gap_s", &ComplementaryFilter::Params::max_gap_s},
    {"acc_rejection_m_s2", &ComplementaryFilter::Params::acc_rejection_m_s2},
    {"mag_norm_tolerance", &ComplementaryFilter::Params::mag_norm_tolerance},
    {"rest_gyr_rad_s", &ComplementaryFilter::Params::rest_gyr_rad_s},
    {"rest_acc_m_s2", &ComplementaryFilter::Params::rest_acc_m_s2},
    {"rest_min_s", &ComplementaryFilter::Params::rest_min_s},
    {"init_period_s", &ComplementaryFilter::Params::init_period_s},
};

std::unique_ptr<OrientationFilter> make_complementary(const FilterSpec& spec) {
  ComplementaryFilter::Params params;
  for (const auto& [key, value] : spec.parameters) {
    bool known = false;
    for (const auto& p : kComplementaryParams) {
      if (key == p.name) {
        params.*(p.field) = value;
        known = true;
      }
    }
    if (!known) {
      std::string names;
      for (const auto& p : kComplementaryParams) names += std::string(names.empty() ? "" : ", ") + p.name;
      throw std::invalid_argument("filter 'complementary' has no parameter '" + key + "' (known: " + names + ")");
    }
  }
  return std::make_unique<ComplementaryFilter>(params);
}

}  // namespace

std::vector<std::string> filter_names() { return {"complementary"}; }

std::unique_ptr<OrientationFilter> make_filter(const FilterSpec& spec) {
  if (spec.name == "complementary") return make_complementary(spec);
  std::string names;
  for (const auto& n : filter_names()) names += (names.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown filter '" + spec.name + "' (known: " + names + ")");
}

}  // namespace bsn::fusion
