#include "bsn/calib/segment_alignment.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <limits>

namespace bsn::calib {
namespace {

// Two unit vectors spanning the plane perpendicular to unit j.
void tangent_basis(const Vec3& j, Vec3& u, Vec3& w) {
  Eigen::Index least = 0;
  j.cwiseAbs().minCoeff(&least);
  u = j.cross(Vec3::Unit(least)).normalized();
  w = j.cross(u);
}

// d|g x j| / dj = ((g x j) x g) / |g x j|; zero where g x j vanishes (the residual's kink).
Vec3 norm_cross_gradient(const Vec3& g, const Vec3& j, double& value) {
  const Vec3 v = g.cross(j);
  value = v.norm();
  return value > 1e-12 ? Vec3(v.cross(g) / value) : Vec3(Vec3::Zero());
}

double cost(const std::vector<Vec3>& g1, const std::vector<Vec3>& g2, const Vec3& j1, const Vec3& j2) {
  double c = 0.0;
  for (std::size_t k = 0; k < g1.size(); ++k) {
    const double e = g1[k].cross(j1).norm() - g2[k].cross(j2).norm();
    c += e * e;
  }
  return c;
}

// The Gauss-Newton normal equations at (j1, j2) in the tangent bases of tangent_basis(): J^T J, and J^T e of the
// residuals e = |g1 x j1| - |g2 x j2| when `jte` is given.
Eigen::Matrix4d normal_matrix(const std::vector<Vec3>& g1, const std::vector<Vec3>& g2, const Vec3& j1, const Vec3& j2,
                              Eigen::Vector4d* jte = nullptr) {
  Vec3 u1, w1, u2, w2;
  tangent_basis(j1, u1, w1);
  tangent_basis(j2, u2, w2);
  Eigen::Matrix4d jtj = Eigen::Matrix4d::Zero();
  if (jte) jte->setZero();
  for (std::size_t k = 0; k < g1.size(); ++k) {
    double n1 = 0.0, n2 = 0.0;
    const Vec3 d1 = norm_cross_gradient(g1[k], j1, n1);
    const Vec3 d2 = norm_cross_gradient(g2[k], j2, n2);
    const Eigen::Vector4d row(d1.dot(u1), d1.dot(w1), -d2.dot(u2), -d2.dot(w2));
    jtj += row * row.transpose();
    if (jte) *jte += row * (n1 - n2);
  }
  return jtj;
}

// Levenberg-Marquardt-damped Gauss-Newton on (j1, j2) in their tangent planes. Returns the final cost.
double refine(const std::vector<Vec3>& g1, const std::vector<Vec3>& g2, Vec3& j1, Vec3& j2, int max_iterations) {
  double c = cost(g1, g2, j1, j2), lambda = 1e-3;
  for (int it = 0; it < max_iterations; ++it) {
    Vec3 u1, w1, u2, w2;
    tangent_basis(j1, u1, w1);
    tangent_basis(j2, u2, w2);
    Eigen::Vector4d jte;
    const Eigen::Matrix4d jtj = normal_matrix(g1, g2, j1, j2, &jte);
    bool improved = false;
    for (int tries = 0; tries < 10 && !improved; ++tries) {
      Eigen::Matrix4d a = jtj;
      a.diagonal() *= 1.0 + lambda;
      const Eigen::Vector4d step = a.ldlt().solve(-jte);
      const Vec3 n1 = (j1 + step[0] * u1 + step[1] * w1).normalized();
      const Vec3 n2 = (j2 + step[2] * u2 + step[3] * w2).normalized();
      const double nc = cost(g1, g2, n1, n2);
      if (nc <= c) {
        improved = true;
        const bool done = c - nc <= 1e-12 * c || step.norm() < 1e-10;
        j1 = n1;
        j2 = n2;
        c = nc;
        lambda = std::max(1e-9, lambda * 0.3);
        if (done) return c;
      } else {
        lambda *= 10.0;
      }
    }
    if (!improved) break;
  }
  return c;
}

}  // namespace

std::optional<HingeAxisFit> fit_hinge_axis(std::span<const Vec3> gyr_parent, std::span<const Vec3> gyr_child,
                                           const HingeAxisParams& params) {
  if (gyr_parent.size() != gyr_child.size()) return std::nullopt;
  std::vector<std::size_t> moving;
  for (std::size_t k = 0; k < gyr_parent.size(); ++k) {
    const Vec3 &a = gyr_parent[k], &b = gyr_child[k];
    if (!a.allFinite() || !b.allFinite()) continue;
    if (std::max(a.norm(), b.norm()) >= params.min_rate_rad_s) moving.push_back(k);
  }
  if (moving.size() < std::max<std::size_t>(params.min_samples, 4)) return std::nullopt;
  const std::size_t n = std::min(moving.size(), std::max<std::size_t>(params.max_samples, 4));
  std::vector<Vec3> g1(n), g2(n);
  double rate2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = moving[i * moving.size() / n];  // evenly over the moving samples
    g1[i] = gyr_parent[k];
    g2[i] = gyr_child[k];
    rate2 += 0.5 * (g1[i].squaredNorm() + g2[i].squaredNorm());
  }
  // Nine starts near the sensor axes (off them a little: an exact axis can be a stationary point by symmetry).
  HingeAxisFit best;
  double best_cost = std::numeric_limits<double>::infinity();
  const Vec3 nudge(0.05, 0.03, 0.02);
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      Vec3 j1 = (Vec3::Unit(a) + nudge).normalized(), j2 = (Vec3::Unit(b) + nudge).normalized();
      const double c = refine(g1, g2, j1, j2, params.max_iterations);
      if (c < best_cost) {
        best_cost = c;
        best.parent_axis = j1;
        best.child_axis = j2;
      }
    }
  }
  best.samples = n;
  best.rms_residual_rad_s = std::sqrt(best_cost / static_cast<double>(n));
  best.rms_rate_rad_s = std::sqrt(rate2 / static_cast<double>(n));
  const Eigen::Matrix4d jtj = normal_matrix(g1, g2, best.parent_axis, best.child_axis);
  const double scale = std::max(1e-300, rate2);  // n * rms_rate^2
  best.parent_observability =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(jtj.topLeftCorner<2, 2>()).eigenvalues()(0) / scale;
  best.child_observability =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(jtj.bottomRightCorner<2, 2>()).eigenvalues()(0) / scale;
  return best;
}

std::optional<Quat> alignment_from_up_and_right(const Vec3& up_in_sensor, const Vec3& right_in_sensor) {
  if (!(up_in_sensor.norm() > 1e-9) || !(right_in_sensor.norm() > 1e-9) || !up_in_sensor.allFinite() ||
      !right_in_sensor.allFinite())
    return std::nullopt;
  const Vec3 y = up_in_sensor.normalized();
  const Vec3 r = right_in_sensor.normalized();
  const Vec3 z_raw = r - r.dot(y) * y;
  if (z_raw.norm() < std::sin(10.0 * 3.14159265358979323846 / 180.0)) return std::nullopt;
  const Vec3 z = z_raw.normalized();
  const Vec3 x = y.cross(z);
  Mat3 m;  // rows: the segment's axes in sensor coordinates, so m * v_sensor = v_segment
  m.row(0) = x.transpose();
  m.row(1) = y.transpose();
  m.row(2) = z.transpose();
  Quat q(m);
  q.normalize();
  if (q.w() < 0.0) q.coeffs() *= -1.0;
  return q;
}

std::optional<Mat3> earth_axes_in_sensor(const Vec3& acc, const Vec3& mag) {
  if (!acc.allFinite() || !mag.allFinite() || !(acc.norm() > 1e-9)) return std::nullopt;
  const Vec3 up = acc.normalized();
  const Vec3 east_raw = mag.cross(up);
  if (!(east_raw.norm() > 1e-6 * std::max(1.0, mag.norm()))) return std::nullopt;
  const Vec3 east = east_raw.normalized();
  Mat3 e;
  e.row(0) = east.transpose();
  e.row(1) = up.cross(east).transpose();
  e.row(2) = up.transpose();
  return e;
}

BodyAlignment align_body(std::span<const AlignmentSegment> segments, const AlignmentParams& params) {
  const std::size_t n = segments.size();
  BodyAlignment out;
  out.segments.resize(n);
  std::vector<std::optional<Mat3>> earth(n);
  for (std::size_t i = 0; i < n; ++i) earth[i] = earth_axes_in_sensor(segments[i].acc_pose, segments[i].mag_pose);

  // Every joint's hinge fit; the child's axis turned to point like the parent's on earth in the N-pose.
  struct Joint {
    std::size_t parent = 0, child = 0;
    HingeAxisFit fit;
    double relative = 0.0;
  };
  std::vector<Joint> hinges;
  for (std::size_t i = 0; i < n; ++i) {
    const int p = segments[i].parent;
    if (p < 0 || static_cast<std::size_t>(p) >= i) continue;
    const auto pi = static_cast<std::size_t>(p);
    const auto fit = fit_hinge_axis(segments[pi].gyr, segments[i].gyr, params.hinge);
    if (!fit || !(fit->rms_rate_rad_s > 0.0)) continue;
    Joint j{pi, i, *fit, fit->rms_residual_rad_s / fit->rms_rate_rad_s};
    if (j.relative > params.max_relative_residual || !earth[pi] || !earth[i]) continue;
    if ((*earth[pi] * j.fit.parent_axis).dot(*earth[i] * j.fit.child_axis) < 0.0) j.fit.child_axis *= -1.0;
    hinges.push_back(j);
  }

  // The body's right direction on earth: each hinge with a known flexion direction votes with its axis, turned so
  // that its largest excursion from the start (the N-pose) has the flexion's sign, weighted by that excursion.
  Vec3 right = Vec3::Zero();
  for (const Joint& j : hinges) {
    const int sign = segments[j.child].flexion_sign;
    if (sign == 0 || std::min(j.fit.parent_observability, j.fit.child_observability) < params.min_observability)
      continue;
    const auto& gp = segments[j.parent].gyr;
    const auto& gc = segments[j.child].gyr;
    double angle = 0.0, extreme = 0.0;  // in rad x samples: only its sign and relative size matter
    for (std::size_t k = 0; k < gp.size() && k < gc.size(); ++k) {
      if (!gp[k].allFinite() || !gc[k].allFinite()) continue;
      angle += gc[k].dot(j.fit.child_axis) - gp[k].dot(j.fit.parent_axis);
      if (std::abs(angle) > std::abs(extreme)) extreme = angle;
    }
    const Vec3 axis_earth = *earth[j.parent] * j.fit.parent_axis;
    right += ((extreme > 0.0) == (sign > 0) ? 1.0 : -1.0) * std::abs(extreme) * axis_earth;
  }
  right.z() = 0.0;
  if (!(right.norm() > 1e-9)) {
    out.problem =
        "no joint with a known flexion direction moved like a hinge: flex the knees (and hips, ankles) a few times "
        "after the N-pose";
    for (auto& s : out.segments) s.problem = out.problem;
    return out;
  }
  right.normalize();

  for (std::size_t i = 0; i < n; ++i) {
    SegmentAlignmentResult& r = out.segments[i];
    if (!earth[i]) {
      r.problem = "no N-pose: the mean specific force and magnetic field are missing or parallel";
      continue;
    }
    // The best hinge this segment takes part in gives its right axis in sensor coordinates.
    const Joint* best = nullptr;
    for (const Joint& j : hinges) {
      const double observability = j.child == i ? j.fit.child_observability : j.fit.parent_observability;
      if ((j.parent == i || j.child == i) && observability >= params.min_observability &&
          (!best || j.relative < best->relative))
        best = &j;
    }
    Vec3 lateral;
    if (best) {
      lateral = best->child == i ? best->fit.child_axis : best->fit.parent_axis;
      if ((*earth[i] * lateral).dot(right) < 0.0) lateral = -lateral;
      r.source = "hinge " + segments[best->parent].name + "-" + segments[best->child].name;
      r.relative_residual = best->relative;
      r.axis_observability = best->child == i ? best->fit.child_observability : best->fit.parent_observability;
    } else {
      lateral = earth[i]->transpose() * right;  // earth to sensor coordinates
      r.source = "pose heading";
    }
    r.sensor_to_segment = alignment_from_up_and_right(segments[i].acc_pose, lateral);
    if (!r.sensor_to_segment) r.problem = "the joint axis is within 10 deg of the vertical in the N-pose";
  }
  return out;
}

}  // namespace bsn::calib
