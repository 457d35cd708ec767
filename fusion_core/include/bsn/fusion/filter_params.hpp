// Binding a filter's named parameters (the body model's `filter:` block) to its Params struct.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>

#include "bsn/fusion/orientation_filter.hpp"

namespace bsn::fusion {

/// One settable parameter: its name in YAML and the Params field it sets. Every parameter is a double on the
/// wire; a filter that needs a count or a switch converts and checks it in its constructor.
template <class Params>
struct ParamField {
  const char* name;
  double Params::*field;
};

/// A filter's parameter table: its own entries followed by the shared groups' (rest_param_fields() etc.), in
/// the order given. The order is the one the "unknown parameter" message lists the names in.
template <class Params, std::size_t... N>
constexpr std::array<ParamField<Params>, (N + ...)> join_param_fields(
    const std::array<ParamField<Params>, N>&... parts) {
  std::array<ParamField<Params>, (N + ...)> all{};
  auto out = all.begin();
  ((out = std::copy(parts.begin(), parts.end(), out)), ...);
  return all;
}

/// Applies spec.parameters to `params` (the defaults). Throws std::invalid_argument naming the filter, the
/// unknown parameter and the known ones.
template <class Params, std::size_t N>
Params bind_parameters(std::string_view filter, const FilterSpec& spec, const std::array<ParamField<Params>, N>& fields,
                       Params params = Params{}) {
  for (const auto& [key, value] : spec.parameters) {
    bool known = false;
    for (const auto& f : fields) {
      if (key == f.name) {
        params.*(f.field) = value;
        known = true;
      }
    }
    if (!known) {
      std::string names;
      for (const auto& f : fields) names += std::string(names.empty() ? "" : ", ") + f.name;
      throw std::invalid_argument("filter '" + std::string(filter) + "' has no parameter '" + key +
                                  "' (known: " + names + ")");
    }
  }
  return params;
}

/// Throws std::invalid_argument unless value is finite and > 0.
inline void require_positive(std::string_view filter, double value, const char* name) {
  if (!(value > 0.0) || value == std::numeric_limits<double>::infinity()) {
    throw std::invalid_argument(std::string(filter) + ": parameter " + name + " must be a finite value > 0, got " +
                                std::to_string(value));
  }
}

/// Throws std::invalid_argument unless value is 0 or 1 (an on/off parameter).
inline void require_switch(std::string_view filter, double value, const char* name) {
  if (value != 0.0 && value != 1.0) {
    throw std::invalid_argument(std::string(filter) + ": parameter " + name + " must be 0 or 1, got " +
                                std::to_string(value));
  }
}

/// Throws std::invalid_argument unless value is finite and >= 0.
inline void require_non_negative(std::string_view filter, double value, const char* name) {
  if (!(value >= 0.0) || value == std::numeric_limits<double>::infinity()) {
    throw std::invalid_argument(std::string(filter) + ": parameter " + name + " must be a finite value >= 0, got " +
                                std::to_string(value));
  }
}

/// Throws std::invalid_argument, naming `owner`, unless every field of `params` that `fields` lists is finite and > 0.
template <class P, std::size_t N>
void require_positive_fields(std::string_view owner, const P& params, const std::array<ParamField<P>, N>& fields) {
  for (const auto& f : fields) require_positive(owner, params.*(f.field), f.name);
}

/// Re-initialisation and start-up timing, the same in every filter; each filter's Params derives from it, so the
/// field names are the parameter names (timing_param_fields() lists them).
struct FilterTimingParams {
  /// A timestamp gap longer than this re-initialises the orientation from the sample (start_orientation()), s.
  /// Shorter gaps are bridged with the gyro. Default 1 s.
  double max_gap_s = 1.0;
  /// After (re)initialisation the filter reports `initialising` for this long (the IECF's gain ramp and the
  /// Seel-Ruppin start-up corrections last as long), s. Default 3 s.
  double init_period_s = 3.0;

  /// Throws std::invalid_argument, naming `owner`, unless both are finite and > 0.
  void check(std::string_view owner) const;
};

/// The timing parameters' entries of a filter's parameter table (P derives from FilterTimingParams).
template <class P>
constexpr std::array<ParamField<P>, 2> timing_param_fields() {
  return {{{"max_gap_s", &P::max_gap_s}, {"init_period_s", &P::init_period_s}}};
}

inline void FilterTimingParams::check(std::string_view owner) const {
  require_positive_fields(owner, *this, timing_param_fields<FilterTimingParams>());
}

}  // namespace bsn::fusion
