#include "bsn/fusion/rest_detector.hpp"

#include <cmath>

#include "bsn/fusion/filter_params.hpp"

namespace bsn::fusion {

RestDetector::RestDetector(const Params& params) : params_(params) {
  params.check("rest detector");
  min_duration_ns_ = seconds_to_ns(params.rest_min_s);
  gyr_threshold_sq_ = params.rest_gyr_rad_s * params.rest_gyr_rad_s;
  const double acc_low = kGravity - params.rest_acc_m_s2;
  acc_low_sq_ = acc_low < 0.0 ? -1.0 : acc_low * acc_low;  // below zero: every |acc| is above the lower bound
  const double acc_high = kGravity + params.rest_acc_m_s2;
  acc_high_sq_ = acc_high * acc_high;
}

}  // namespace bsn::fusion
