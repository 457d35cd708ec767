#include "bsn/calib/field_calibration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <complex>
#include <optional>
#include <string>

namespace bsn::calib {
namespace {

constexpr std::size_t kMinEllipsoidSamples = 9;  // 9 free quadric coefficients
constexpr std::size_t kMinPoses = 5;             // eq. 29: 3 equations per pose pair, 12 unknowns
// Centred readings whose smallest variance is below this fraction of the largest lie in one plane (within ~3 %
// of the extent): an ellipsoid cannot be determined.
constexpr double kMinFlatness = 1e-3;
constexpr double kWeakCoverage = 0.3;

std::string column_name(Eigen::Index j) { return "column " + std::to_string(j); }

// First non-finite column, or -1.
Eigen::Index first_non_finite(const Eigen::Ref<const Points3>& p) {
  for (Eigen::Index j = 0; j < p.cols(); ++j)
    if (!p.col(j).allFinite()) return j;
  return -1;
}

bool matrix_finite(const Mat3& m) { return m.allFinite(); }

using Mat10 = Eigen::Matrix<double, 10, 10>;
using Vec10 = Eigen::Matrix<double, 10, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat4 = Eigen::Matrix4d;

// Quadric a x^2 + b y^2 + c z^2 + 2f yz + 2g xz + 2h xy + 2p x + 2q y + 2r z + d = 0 with the coefficients
// split into the quadratic part v1 = (a, b, c, f, g, h) and the linear part v2 = (p, q, r, d); design row
// (x^2, y^2, z^2, 2yz, 2xz, 2xy, 2x, 2y, 2z, 1) and scatter S = [S11 S12; S21 S22].
Mat10 design_scatter(const Points3& p) {
  Mat10 scatter = Mat10::Zero();
  for (Eigen::Index k = 0; k < p.cols(); ++k) {
    const double x = p(0, k), y = p(1, k), z = p(2, k);
    Vec10 row;
    row << x * x, y * y, z * z, 2 * y * z, 2 * x * z, 2 * x * y, 2 * x, 2 * y, 2 * z, 1.0;
    scatter.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  return scatter.selfadjointView<Eigen::Lower>();
}

// Li & Griffiths 2004: minimise v^T S v subject to 4J - I^2 = 1 (I = a + b + c, J = ab + bc + ac - f^2 - g^2 -
// h^2). 4J - I^2 > 0 forces the quadratic part to be definite, so only ellipsoids qualify; every ellipsoid whose
// shortest axis is at least half its longest does, far beyond any magnetometer's or accelerometer's distortion.
// For fixed v1 the best v2 is -S22^-1 S21 v1, leaving (S11 - S12 S22^-1 S21) v1 = lambda C v1 with
// v1^T C v1 = 4J - I^2; exactly one eigenvector has v1^T C v1 > 0, and it is the solution.
// Returns the quadric's coefficients v = (v1, v2), or nullopt with fit.message saying why there is none.
std::optional<Vec10> li_griffiths_quadric(const Mat10& scatter, double lambda_max, EllipsoidFit& fit) {
  const Mat6 s11 = scatter.topLeftCorner<6, 6>();
  const Eigen::Matrix<double, 6, 4> s12 = scatter.topRightCorner<6, 4>();
  const Mat4 s22 = scatter.bottomRightCorner<4, 4>();
  const Eigen::LDLT<Mat4> s22_solver(s22);
  if (s22_solver.info() != Eigen::Success || !(s22_solver.vectorD().minCoeff() > 1e-14 * lambda_max)) {
    fit.message = "the readings do not determine an ellipsoid (linear part singular)";
    fit.condition_number = 0.0;
    return std::nullopt;
  }
  const Eigen::Matrix<double, 4, 6> linear_from_quadratic = -s22_solver.solve(s12.transpose());
  const Mat6 reduced = s11 + s12 * linear_from_quadratic;
  Mat6 constraint = Mat6::Zero();
  constraint.topLeftCorner<3, 3>() << -1, 1, 1, 1, -1, 1, 1, 1, -1;
  constraint.bottomRightCorner<3, 3>() = -4.0 * Eigen::Matrix3d::Identity();
  // C^-1 in closed form: the top-left block [-1 1 1; 1 -1 1; 1 1 -1] has inverse [0 1 1; 1 0 1; 1 1 0] / 2.
  Mat6 constraint_inverse = Mat6::Zero();
  constraint_inverse.topLeftCorner<3, 3>() << 0, 0.5, 0.5, 0.5, 0, 0.5, 0.5, 0.5, 0;
  constraint_inverse.bottomRightCorner<3, 3>() = -0.25 * Eigen::Matrix3d::Identity();
  const Eigen::EigenSolver<Mat6> generalised(constraint_inverse * reduced);
  if (generalised.info() != Eigen::Success) {
    fit.message = "eigen decomposition of the ellipsoid problem did not converge";
    return std::nullopt;
  }
  // Choose by the sign of the constraint rather than of lambda: with noise-free data lambda is ~0 and its sign is
  // rounding noise, while v1^T C v1 > 0 stays clear.
  Vec6 v1 = Vec6::Zero();
  double best_constraint = 0.0;
  const double largest_eigenvalue = generalised.eigenvalues().cwiseAbs().maxCoeff();
  for (Eigen::Index i = 0; i < 6; ++i) {
    // The eigenvalues are real in theory; a clearly complex pair is rounding on a degenerate problem, not a fit.
    if (std::abs(generalised.eigenvalues()(i).imag()) > 1e-9 * largest_eigenvalue) continue;
    const Vec6 real_part = generalised.eigenvectors().col(i).real();
    const double norm_sq = real_part.squaredNorm();
    if (!(norm_sq > 0.0)) continue;
    const double value = real_part.dot(constraint * real_part) / norm_sq;
    if (value > best_constraint) {
      best_constraint = value;
      v1 = real_part;
    }
  }
  if (!(best_constraint > 0.0)) {
    fit.message = "the fitted quadric is not an ellipsoid: the readings do not cover enough directions";
    return std::nullopt;
  }
  Vec10 v;
  v << v1, linear_from_quadratic * v1;
  return v;
}

}  // namespace

EllipsoidFit fit_ellipsoid(const Eigen::Ref<const Points3>& raw) {
  EllipsoidFit fit;
  fit.sample_count = static_cast<std::size_t>(raw.cols());
  if (fit.sample_count < kMinEllipsoidSamples) {
    fit.message = "too few samples for an ellipsoid: " + std::to_string(fit.sample_count) + ", need at least " +
                  std::to_string(kMinEllipsoidSamples);
    return fit;
  }
  if (const Eigen::Index bad = first_non_finite(raw); bad >= 0) {
    fit.message = "non-finite reading (NaN or Inf) in " + column_name(bad);
    return fit;
  }
  // Condition the problem: centre on the mean and scale to unit rms radius, so that the quadric's coefficients
  // are of similar size whatever the raw unit and offset (raw offsets of 32000 LSB with a 600 LSB radius would
  // otherwise leave nothing of the shape in double precision).
  const Vec3 centre = raw.rowwise().mean();
  const Points3 centred = raw.colwise() - centre;
  const double scale = std::sqrt(centred.squaredNorm() / static_cast<double>(raw.cols()));
  if (!(scale > 1e-12 * (1.0 + centre.norm()))) {
    fit.message = "constant data: the readings do not change";
    return fit;
  }
  const Points3 p = centred / scale;
  const Eigen::SelfAdjointEigenSolver<Mat3> spread(p * p.transpose() / static_cast<double>(p.cols()));
  fit.flatness = spread.eigenvalues()(0) / spread.eigenvalues()(2);
  if (fit.flatness < kMinFlatness) {
    fit.message = "the readings lie in one plane (smallest/largest variance " + std::to_string(fit.flatness) +
                  "): turn the sensor about more than one axis";
    return fit;
  }

  const Mat10 scatter = design_scatter(p);
  // The condition of the (unconstrained) algebraic problem, for the quality report: a near-null second direction
  // of the design scatter means the readings admit more than one quadric.
  const Eigen::SelfAdjointEigenSolver<Mat10> eig(scatter, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success) {
    fit.message = "eigen decomposition of the ellipsoid problem did not converge";
    return fit;
  }
  const double lambda_max = eig.eigenvalues()(9);
  const double lambda_2 = eig.eigenvalues()(1);
  fit.condition_number = lambda_2 > 0.0 ? std::sqrt(lambda_max / lambda_2) : INFINITY;
  if (!(lambda_2 > 1e-14 * lambda_max)) {
    fit.message = "the readings do not determine an ellipsoid (condition number too large)";
    fit.condition_number = 0.0;
    return fit;
  }

  const std::optional<Vec10> quadric = li_griffiths_quadric(scatter, lambda_max, fit);
  if (!quadric) return fit;
  const Vec10& v = *quadric;

  Mat3 a;
  a << v(0), v(5), v(4), v(5), v(1), v(3), v(4), v(3), v(2);
  const Vec3 w(v(6), v(7), v(8));
  const Eigen::FullPivLU<Mat3> lu(a);
  if (!lu.isInvertible()) {
    fit.message = "the fitted quadric has no centre (not an ellipsoid)";
    return fit;
  }
  const Vec3 c = -lu.solve(w);
  const double k = c.dot(a * c) - v(9);  // (p - c)^T A (p - c) = k
  const Mat3 sigma_n = a / k;
  const Eigen::SelfAdjointEigenSolver<Mat3> shape(sigma_n);
  if (!std::isfinite(k) || k == 0.0 || !(shape.eigenvalues()(0) > 0.0)) {
    fit.message = "the fitted quadric is not an ellipsoid: the readings do not cover enough directions";
    return fit;
  }
  // Back to raw units: p = (g - centre) / scale.
  fit.bias = centre + scale * c;
  fit.sigma = sigma_n / (scale * scale);
  if (!fit.bias.allFinite() || !matrix_finite(fit.sigma)) {
    fit.message = "numerical failure in the ellipsoid fit";
    fit.bias.setZero();
    fit.sigma.setIdentity();
    return fit;
  }
  fit.status = FitStatus::ok;
  return fit;
}

Mat3 symmetric_transform(const Mat3& sigma, double field_magnitude) {
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(sigma);
  const Vec3 root = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  return field_magnitude * eig.eigenvectors() * root.asDiagonal() * eig.eigenvectors().transpose();
}

namespace {

// Residuals of |u| - M, sphere coverage and octants of the corrected readings.
void fill_quality(FieldCalibration& out, const Eigen::Ref<const Points3>& ellipsoid_samples,
                  const Eigen::Ref<const Points3>& poses, const EllipsoidFit& ellipsoid) {
  FitQuality& q = out.quality;
  const double m = out.field_magnitude;
  double sum_sq = 0.0, worst = 0.0;
  for (Eigen::Index k = 0; k < ellipsoid_samples.cols(); ++k) {
    const double r = apply(out.calibration, ellipsoid_samples.col(k)).norm() - m;
    sum_sq += r * r;
    worst = std::max(worst, std::abs(r));
  }
  q.sample_count = static_cast<std::size_t>(ellipsoid_samples.cols());
  q.residual_rms = q.sample_count > 0 ? std::sqrt(sum_sq / static_cast<double>(q.sample_count)) : 0.0;
  q.residual_max = worst;
  q.ellipsoid_condition = ellipsoid.condition_number;

  Mat3 directions = Mat3::Zero();
  bool octant[8] = {};
  for (Eigen::Index j = 0; j < poses.cols(); ++j) {
    const Vec3 u = apply(out.calibration, poses.col(j));
    if (!(u.norm() > 0.0)) continue;
    const Vec3 n = u.normalized();
    directions += n * n.transpose();
    octant[(n.x() >= 0 ? 1 : 0) + (n.y() >= 0 ? 2 : 0) + (n.z() >= 0 ? 4 : 0)] = true;
  }
  q.pose_count = static_cast<std::size_t>(poses.cols());
  if (poses.cols() > 0) {
    const Eigen::SelfAdjointEigenSolver<Mat3> eig(directions / static_cast<double>(poses.cols()));
    q.sphere_coverage = std::max(0.0, 3.0 * eig.eigenvalues()(0));
  }
  q.octants_covered = 0;
  for (bool o : octant) q.octants_covered += o ? 1 : 0;

  if (q.sphere_coverage < kWeakCoverage)
    q.warnings.push_back("poses cover the sphere poorly (coverage " + std::to_string(q.sphere_coverage) +
                         " of 1): add poses pointing the sensor in other directions");
  if (ellipsoid.flatness < 0.05)
    q.warnings.push_back("the readings are nearly flat (variance ratio " + std::to_string(ellipsoid.flatness) +
                         "): bias and scale along the thin axis are weak");
  if (m > 0.0 && q.residual_rms > 0.05 * m)
    q.warnings.push_back("large residual of |u| - M (" + std::to_string(q.residual_rms / m * 100.0) +
                         " % rms): magnetic disturbance or movement during the recording?");
}

FieldCalibration failure(std::string message, double field_magnitude) {
  FieldCalibration out;
  out.status = FitStatus::failed;
  out.message = std::move(message);
  out.field_magnitude = field_magnitude;
  return out;
}

}  // namespace

FieldCalibration fit_transform(const Eigen::Ref<const Points3>& poses, const std::vector<Mat3>& rotations,
                               const EllipsoidFit& ellipsoid, double field_magnitude) {
  if (!(field_magnitude > 0.0) || !std::isfinite(field_magnitude))
    return failure("field magnitude must be positive and finite", field_magnitude);
  if (!ellipsoid.ok()) return failure("ellipsoid fit failed: " + ellipsoid.message, field_magnitude);
  const std::size_t count = static_cast<std::size_t>(poses.cols());
  if (rotations.size() != count)
    return failure("got " + std::to_string(count) + " poses but " + std::to_string(rotations.size()) + " rotations",
                   field_magnitude);
  if (count < kMinPoses)
    return failure("too few poses: " + std::to_string(count) + ", need at least " + std::to_string(kMinPoses),
                   field_magnitude);
  if (const Eigen::Index bad = first_non_finite(poses); bad >= 0)
    return failure("non-finite pose mean (NaN or Inf) in pose " + std::to_string(bad), field_magnitude);
  for (std::size_t j = 0; j < count; ++j) {
    if (!matrix_finite(rotations[j]) || (rotations[j].transpose() * rotations[j] - Mat3::Identity()).norm() > 1e-6 ||
        rotations[j].determinant() < 0.0)
      return failure("rotation " + std::to_string(j) + " is not a rotation matrix", field_magnitude);
  }

  // Eq. 25 for a pair of poses (i, j): (R_j^0 - R_i^0) u_0 = H (g_j - g_i), with u_j = R_j^0 u_0 and
  // R_j^0 = rotations[j]^T rotations[0]. We use every pair, not only pairs with one reference pose: the sum of
  // squared pair residuals equals J times the sum of squared residuals taken from the mean pose, so the rows
  // are (R_j^0 - mean R^0) u_0 - H (g_j - mean g) = 0 (3 J rows instead of 3 J (J - 1) / 2). This spreads the
  // noise of any one pose over all equations instead of repeating it in each.
  const Mat3 r0 = rotations[0];
  Mat3 mean_rotation = Mat3::Zero();
  for (std::size_t j = 0; j < count; ++j) mean_rotation += rotations[j].transpose() * r0;
  mean_rotation /= static_cast<double>(count);
  const Vec3 mean_reading = poses.rowwise().mean();
  const Points3 diffs = poses.colwise() - mean_reading;
  // Scale the reading differences to unit rms so that the columns of A for u_0 (R - mean R, of order 1) and for
  // H are of similar size whatever the raw unit (the homogeneous least-squares solution depends on column
  // scaling); the unknowns u_0 and H' = H * s are then both of the order of M.
  const double s = std::sqrt(diffs.squaredNorm() / static_cast<double>(count));
  if (!(s > 0.0)) return failure("constant data: the pose readings are all equal", field_magnitude);

  const Eigen::Index rows = static_cast<Eigen::Index>(3 * count);
  Eigen::Matrix<double, Eigen::Dynamic, 12> a(rows, 12);
  a.setZero();
  for (std::size_t j = 0; j < count; ++j) {
    const Vec3 d = diffs.col(static_cast<Eigen::Index>(j)) / s;
    const Eigen::Index r = static_cast<Eigen::Index>(3 * j);
    a.block<3, 3>(r, 0) = rotations[j].transpose() * r0 - mean_rotation;
    for (int axis = 0; axis < 3; ++axis) a.block<1, 3>(r + axis, 3 + 3 * axis) = -d.transpose();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  const auto& sv = svd.singularValues();
  if (!(sv(10) > 1e-10 * sv(0)))
    return failure("the relative rotations do not determine H (rotations about one axis only, or poses repeated)",
                   field_magnitude);
  Eigen::Matrix<double, 12, 1> x = svd.matrixV().col(11);
  Vec3 u0 = x.head<3>();
  if (!(u0.norm() > 0.0)) return failure("the field vector came out zero", field_magnitude);
  Mat3 h_scaled;
  h_scaled << x.segment<3>(3).transpose(), x.segment<3>(6).transpose(), x.segment<3>(9).transpose();
  double kappa = field_magnitude / u0.norm();  // eq. 33 with |u_0| = M
  if (h_scaled.determinant() < 0.0) kappa = -kappa;

  FieldCalibration out;
  out.field_magnitude = field_magnitude;
  out.calibration.bias = ellipsoid.bias;
  out.calibration.transform = kappa * h_scaled / s;
  out.field_vector = kappa * u0;
  if (!out.calibration.transform.allFinite() || !out.field_vector.allFinite())
    return failure("numerical failure in the transformation fit", field_magnitude);
  out.quality.transform_condition = sv(0) / sv(10);

  double pose_sq = 0.0;
  for (std::size_t j = 0; j < count; ++j) {
    const Vec3 predicted = rotations[j].transpose() * r0 * out.field_vector;
    pose_sq += (apply(out.calibration, poses.col(static_cast<Eigen::Index>(j))) - predicted).squaredNorm();
  }
  out.quality.pose_residual_rms = std::sqrt(pose_sq / static_cast<double>(count));
  const Mat3 m2_sigma = field_magnitude * field_magnitude * ellipsoid.sigma;
  out.quality.ellipsoid_consistency =
      (out.calibration.transform.transpose() * out.calibration.transform - m2_sigma).norm() / m2_sigma.norm();
  out.status = FitStatus::ok;
  return out;
}

FieldCalibration calibrate_field(const Eigen::Ref<const Points3>& poses, const std::vector<Mat3>& rotations,
                                 double field_magnitude, const Eigen::Ref<const Points3>& ellipsoid_samples) {
  const bool own_samples = ellipsoid_samples.cols() > 0;
  const EllipsoidFit ellipsoid = fit_ellipsoid(own_samples ? ellipsoid_samples : poses);
  FieldCalibration out = fit_transform(poses, rotations, ellipsoid, field_magnitude);
  if (!out.ok()) return out;
  fill_quality(out, own_samples ? ellipsoid_samples : poses, poses, ellipsoid);
  if (out.quality.ellipsoid_consistency > 0.05)
    out.quality.warnings.push_back("H^T H differs from M^2 Sigma by " +
                                   std::to_string(out.quality.ellipsoid_consistency * 100.0) +
                                   " %: the relative rotations disagree with the readings (gyro error?)");
  return out;
}

FieldCalibration calibrate_field_without_rotations(const Eigen::Ref<const Points3>& samples, double field_magnitude) {
  if (!(field_magnitude > 0.0) || !std::isfinite(field_magnitude))
    return failure("field magnitude must be positive and finite", field_magnitude);
  const EllipsoidFit ellipsoid = fit_ellipsoid(samples);
  if (!ellipsoid.ok()) return failure("ellipsoid fit failed: " + ellipsoid.message, field_magnitude);
  FieldCalibration out;
  out.field_magnitude = field_magnitude;
  out.calibration.bias = ellipsoid.bias;
  out.calibration.transform = symmetric_transform(ellipsoid.sigma, field_magnitude);
  out.status = FitStatus::ok;
  fill_quality(out, samples, samples, ellipsoid);  // coverage over the raw readings; there are no poses
  out.quality.pose_count = 0;
  out.quality.warnings.push_back("no relative rotations: H is symmetric, its alignment to the gyro axes unknown");
  return out;
}

}  // namespace bsn::calib
