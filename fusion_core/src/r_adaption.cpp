#include "bsn/fusion/r_adaption.hpp"

#include <algorithm>
#include <cmath>

namespace bsn::fusion {

MagneticRAdaption::Reference MagneticRAdaption::Reference::of(const Vec3& m, const Vec3& up) {
  Reference ref;
  ref.norm = m.norm();
  ref.sin_dip = ref.norm > 0.0 ? std::clamp(-m.dot(up) / ref.norm, -1.0, 1.0) : 0.0;
  return ref;
}

double MagneticRAdaption::update(std::uint64_t t_ns, const Vec3& m, const Vec3& up, const Reference& ref,
                                 double rate_rad_s, double dt_s) {
  if (ref.norm != last_ref_.norm || ref.sin_dip != last_ref_.sin_dip) {
    last_ref_ = ref;
    if (ref.norm > 0.0) detector_.set_reference_sine(ref.norm, ref.sin_dip);
  }
  detector_.update(t_ns, m, up, rate_rad_s, std::isfinite(dt_s) ? dt_s : 0.0);
  if (!detector_.usable()) return kInfiniteVariance;
  const double gain = detector_.gain_factor();
  return 1.0 / (gain * gain);
}

}  // namespace bsn::fusion
