// Calibration of a triaxial sensor of a constant vector field (magnetometer: the earth's field; accelerometer at
// rest: gravity) in the model of Zhang & Yang 2015: u = H (g - B), |u| = M.
//  1. Ellipsoid fit (eqs. 12-18): the raw readings g lie on the ellipsoid (g - B)^T Sigma (g - B) = 1 with
//     Sigma = H^T H / M^2. It gives the combined bias B and Sigma, but H only up to a rotation (eq. 22).
//  2. Transformation (eqs. 23-33): with the relative rotations between static poses known (a jig, or the
//     gyroscope), u_j = R_j^i u_i and u_j - u_i = H (g_j - g_i) form a homogeneous linear system in
//     X = [u_i, H rows]; its SVD null vector, scaled to |u_i| = M, gives H and the field vector u_i.
// Every function returns a result with a status and a message; none throws, none returns NaN.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "bsn/calib/sensor_calibration.hpp"

namespace bsn::calib {

using Points3 = Eigen::Matrix3Xd;  ///< one reading per column

enum class FitStatus {
  ok,      ///< parameters determined; `warnings` may still list weak spots
  failed,  ///< the data cannot determine the parameters; `message` says why; numbers are left at identity/zero
};

/// Result of the ellipsoid fit (step 1).
struct EllipsoidFit {
  FitStatus status = FitStatus::failed;
  std::string message;            ///< why it failed, empty when ok
  Mat3 sigma = Mat3::Identity();  ///< Sigma of eq. 17 (1/unit^2), positive definite when ok
  Vec3 bias = Vec3::Zero();       ///< combined bias B (eq. 18), in the raw unit
  double condition_number = 0.0;  ///< sqrt(lambda_max / lambda_2) of the normalised design scatter: big = weak
  double flatness = 0.0;          ///< smallest / largest variance of the centred readings: 0 = in one plane
  std::size_t sample_count = 0;
  bool ok() const { return status == FitStatus::ok; }
};

/// Fits an ellipsoid to raw readings (at least 9, finite, not constant, not in one plane). The data are centred
/// and scaled first; the quadric's algebraic least squares is constrained to ellipsoids (Li & Griffiths 2004:
/// 4J - I^2 = 1), solved as a 6x6 generalised eigenproblem, so partial coverage or noise cannot turn the result
/// into a hyperboloid; a quadric that still is not a real ellipsoid is reported as a failure.
EllipsoidFit fit_ellipsoid(const Eigen::Ref<const Points3>& raw);

/// The symmetric factor K = M Lambda sqrt(D) Lambda^T of eq. 20 (K^T K = M^2 Sigma): H up to a rotation.
Mat3 symmetric_transform(const Mat3& sigma, double field_magnitude);

/// Quality of a complete calibration.
struct FitQuality {
  std::size_t pose_count = 0;          ///< static poses used for H
  std::size_t sample_count = 0;        ///< readings used for the ellipsoid
  double residual_rms = 0.0;           ///< rms of |u| - M over the ellipsoid's readings, in the unit of M
  double residual_max = 0.0;           ///< largest | |u| - M |, unit of M
  double pose_residual_rms = 0.0;      ///< rms of |H (g_j - B) - R_j^i u_i| over the poses, unit of M
  double sphere_coverage = 0.0;        ///< 3 x smallest eigenvalue of mean(n n^T) of the corrected pose directions n:
                                       ///< 1 = evenly spread over the sphere, 0 = all in one plane
  int octants_covered = 0;             ///< of the 8 octants, how many hold a corrected pose direction
  double ellipsoid_condition = 0.0;    ///< EllipsoidFit::condition_number
  double transform_condition = 0.0;    ///< sigma_1 / sigma_11 of the scaled system A X = 0 (eq. 30): big = weak
  double ellipsoid_consistency = 0.0;  ///< |H^T H - M^2 Sigma| / |M^2 Sigma| (Frobenius): steps 1 and 2 agree at 0
  std::vector<std::string> warnings;   ///< weak but usable data, in words
};

/// A complete calibration of one channel: u = H (g - B) with |u| = M.
struct FieldCalibration {
  FitStatus status = FitStatus::failed;
  std::string message;               ///< why it failed, empty when ok
  ChannelCalibration calibration;    ///< B and H
  double field_magnitude = 1.0;      ///< M, in the calibrated unit
  Vec3 field_vector = Vec3::Zero();  ///< u_i: the field in the sensor frame at the reference pose (pose 0)
  FitQuality quality;
  bool ok() const { return status == FitStatus::ok; }
};

/// Step 2 with a given bias: H and u_0 from pose means `poses` (column j = mean raw reading at pose j, pose 0 the
/// reference) and `rotations[j]` = orientation of pose j's sensor frame in pose 0's sensor frame (R_0^T R_j for
/// sensor-to-earth R; rotations[0] = I; this is what integrating the gyro from pose 0 to pose j gives). Then
/// u_j = rotations[j]^T u_0, i.e. the paper's R_j^i = rotations[j]^T. kappa's sign (eq. 33, arbitrary in the
/// paper) is chosen so that det H > 0: the calibrated axes form a right-handed frame.
FieldCalibration fit_transform(const Eigen::Ref<const Points3>& poses, const std::vector<Mat3>& rotations,
                               const EllipsoidFit& ellipsoid, double field_magnitude);

/// Steps 1 and 2. The ellipsoid is fitted to `ellipsoid_samples` (e.g. every raw reading of a hand-turned
/// recording), or to the pose means when it has no columns. At least 5 poses are needed (eq. 29: 12 unknowns).
FieldCalibration calibrate_field(const Eigen::Ref<const Points3>& poses, const std::vector<Mat3>& rotations,
                                 double field_magnitude,
                                 const Eigen::Ref<const Points3>& ellipsoid_samples = Points3(3, 0));

/// Without relative rotations: B from the ellipsoid and the symmetric H = K of eq. 20 (scale and the symmetric
/// part of misalignment/soft iron; the rotation between this sensor's and the gyro's axes stays unknown).
FieldCalibration calibrate_field_without_rotations(const Eigen::Ref<const Points3>& samples, double field_magnitude);

}  // namespace bsn::calib
