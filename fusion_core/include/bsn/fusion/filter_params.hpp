// Binding a filter's named parameters (the body model's `filter:` block) to its Params struct.
#pragma once

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

/// Applies spec.parameters to `params` (the defaults). Throws std::invalid_argument naming the filter, the
/// unknown parameter and the known ones.
template <class Params, std::size_t N>
Params bind_parameters(std::string_view filter, const FilterSpec& spec, const ParamField<Params> (&fields)[N],
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

/// Throws std::invalid_argument unless value is finite and >= 0.
inline void require_non_negative(std::string_view filter, double value, const char* name) {
  if (!(value >= 0.0) || value == std::numeric_limits<double>::infinity()) {
    throw std::invalid_argument(std::string(filter) + ": parameter " + name + " must be a finite value >= 0, got " +
                                std::to_string(value));
  }
}

}  // namespace bsn::fusion
