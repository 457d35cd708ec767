// Units an input file states (or the user gives), turned into bsn's: m/s^2, rad/s, uT, ns.
#pragma once

#include <map>
#include <string>

namespace bsn::io {

/// Quantity ("acc", "gyr", "mag", "time") -> unit name, overriding what an importer assumes for its format.
using UnitOptions = std::map<std::string, std::string>;

/// The factor that turns a value of `quantity` in `unit` into bsn's unit: acc m/s^2 (also g, mg), gyr rad/s (also
/// deg/s, dps), mag uT (also nT, mT, G, mG, au = Xsens' arbitrary unit, 40 uT; au:K = K uT), time ns (also s, ms,
/// us). Throws std::invalid_argument naming the units it knows.
double unit_factor(const std::string& quantity, const std::string& unit);

/// Parses "QUANTITY=UNIT" (the --unit option) into `units`; throws std::invalid_argument when either is unknown.
void add_unit_option(UnitOptions& units, const std::string& quantity_is_unit);

}  // namespace bsn::io
