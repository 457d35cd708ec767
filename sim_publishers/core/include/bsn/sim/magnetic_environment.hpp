// The magnetic field a sensor sees: the earth field (magnitude, dip, optionally a heading that changes),
// dipole magnets, ferromagnetic floor regions, and magnets attached to the sensor. Earth frame ENU, uT.
#pragma once

#include <cstddef>
#include <vector>

#include "bsn/fusion/rotation.hpp"
#include "bsn/sim/signal.hpp"

namespace bsn::sim {

using fusion::Quat;
using fusion::Vec3;

/// Field of a magnetic dipole of moment m (A m^2) at displacement r (m) from it, in uT:
/// mu0/(4 pi) (3 r^ (m . r^) - m) / |r|^3, with mu0/(4 pi) = 1e-7 T m/A = 0.1 uT m/A. Zero at r = 0.
Vec3 dipole_field(const Vec3& moment_am2, const Vec3& r_m);

/// A change of the earth field's heading at constant magnitude and dip (Seel & Ruppin 2017, section 3.1):
/// the horizontal part turns by delta_rad about the vertical (positive = counter-clockwise seen from above)
/// over ramp_s (0 = a jump) from at_s on.
struct HeadingChange {
  double at_s = 0.0;
  double delta_rad = 0.0;
  double ramp_s = 0.0;
};

/// A dipole magnet at `position_m` with moment `moment_am2` (earth frame). With `active` windows it is
/// brought in: its position moves from position + approach_from_m to position as the window's envelope goes
/// 0 -> 1 (with approach_from_m = 0 its moment is scaled by the envelope instead). Empty = always there.
struct Dipole {
  Vec3 position_m = Vec3::Zero();
  Vec3 moment_am2 = Vec3::Zero();
  Vec3 approach_from_m = Vec3::Zero();
  std::vector<Window> active;
};

/// A ferromagnetic floor region: inside the box [min_m, max_m] the field gains `field_ut` (earth frame),
/// fading in over `edge_m` at the sides and top, so a sensor walking in sees a smooth change.
struct FloorRegion {
  Vec3 min_m = Vec3::Zero();
  Vec3 max_m = Vec3::Zero();
  Vec3 field_ut = Vec3::Zero();
  double edge_m = 0.2;
  std::vector<Window> active;  ///< empty = always there
};

/// A magnet attached to a segment's sensor (e.g. a strap clasp): a constant hard-iron field in the sensor
/// frame, the dipole field of `moment_am2` at `offset_m` from the sensor (both in the sensor frame).
struct AttachedMagnet {
  std::size_t segment = 0;  ///< index of the segment whose sensor carries it
  Vec3 offset_m = Vec3(0.0, 0.02, 0.0);
  Vec3 moment_am2 = Vec3::Zero();
  Vec3 field_sensor_ut() const { return dipole_field(moment_am2, -offset_m); }
};

class MagneticEnvironment {
 public:
  double magnitude_ut = 49.0;  ///< earth field magnitude, uT
  double dip_deg = 64.0;       ///< inclination below the horizon (positive: field points down), degrees
  std::vector<HeadingChange> heading_changes;
  std::vector<Dipole> dipoles;
  std::vector<FloorRegion> floor_regions;
  std::vector<AttachedMagnet> attached_magnets;

  /// Earth field (with heading changes) at time t, ENU, uT.
  Vec3 earth_field(double t_s) const;
  /// Everything that is not attached to a sensor, at a point, ENU, uT.
  Vec3 field_at(const Vec3& position_m, double t_s) const;
  /// What the magnetometer of segment `segment` reads without sensor errors: R^T field + attached magnets.
  Vec3 sensor_field(std::size_t segment, const Vec3& position_m, const Quat& q_sensor_to_earth, double t_s) const;
};

/// Magnitude (uT) and dip (rad, positive down) of a field in the earth frame: the indicators Fan et al. 2018
/// plot (their eq. 17).
struct MagnitudeDip {
  double magnitude_ut;
  double dip_rad;
};
MagnitudeDip magnitude_and_dip(const Vec3& field_enu);

}  // namespace bsn::sim
