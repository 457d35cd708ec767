// Which error source gives Nez Table 3's sigma_m shape (1.5, 4, 45 uT from slow to fast)? The experiment of the
// README (Tuning): the three Nez scenarios (Opal-like sensor, 128 Hz, 10 min) with one documented error source
// added, the MEKF's four sigmas identified on each as bsn_bench_tune does, and the criterion along sigma_m with the
// other three as identified (how sharply the scenario decides sigma_m).
// Sources:
//   --hard-iron x,y,z / --soft-iron xx,yy,zz,xy,xz,yz  magnetometer calibration residual (uT; soft iron as I + the
//       symmetric deviation), in the sensor frame;
//   --lab SEED  the lab's field inhomogeneity: a floor of randomly oriented dipoles (a 9 x 9 grid 1 m apart, jittered,
//       drawn from SEED) 0.35 m below the floor, the sensor at 1 m above it, scaled so that the field's heading over a
//       4 m x 4 m area at the sensor's height has an RMS of 3 deg (de Vries et al. 2009: 3 deg SD at 100 cm and more,
//       29 deg at 5 cm above the floor; floors 1-3 give 41-45 deg at 5 cm);
//   --align-reference  the reference's heading set from the sensor's own magnetometer over the movement (Nez App.
//       A.2), instead of the true north;
//   --reference-late S, --reference-drift-ppm P  the reference shows the truth S + P 1e-6 t seconds late (Nez App.
//       A.1: 30 ppm, 18 ms after 10 min, before their correction).
//   --filter NAME=VALUE  a further fixed MEKF parameter (e.g. mag_rejection=0: without the disturbance detector).
//   --write DIR  instead of identifying: write the three recordings as DIR/<scenario>.hdf5 (BROAD's layout), for
//       `bsn eval DIR --filter all` (every filter on the same recordings).
// Usage: bsn_bench_nez_sources [sources] [--filter NAME=VALUE]... [--evaluations N] [--threads N] [--write DIR]
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/eval/tuning.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace {

using namespace bsn;
using fusion::Vec3;
constexpr double kDeg = 180.0 / std::numbers::pi;

std::vector<double> numbers(const std::string& text, std::size_t count) {
  std::vector<double> v;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) v.push_back(std::stod(item));
  if (v.size() != count) throw std::invalid_argument("expected " + std::to_string(count) + " numbers: " + text);
  return v;
}

// Heading of the horizontal field, east of north, rad (ENU).
double heading_of(const Vec3& b) { return std::atan2(b.x(), b.y()); }

// RMS heading of the field over a 4 m x 4 m area at height z_m, deg.
double heading_rms_deg(const sim::MagneticEnvironment& env, double z_m) {
  double sum_sq = 0.0;
  int n = 0;
  for (int ix = -20; ix <= 20; ++ix) {
    for (int iy = -20; iy <= 20; ++iy) {
      const double h = heading_of(env.field_at(Vec3(0.1 * ix, 0.1 * iy, z_m), 0.0));
      sum_sq += h * h;
      ++n;
    }
  }
  return std::sqrt(sum_sq / n) * kDeg;
}

// The floor is z = 0 (the Nez scenarios hold the sensor at 1 m); its sources lie 0.35 m below it, so that 3 deg at
// 1 m comes with tens of degrees at 5 cm, the order of de Vries' 29 deg (deeper sources would lower it).
void add_lab_floor(sim::MagneticEnvironment& env, std::uint64_t seed, double sensor_height_m) {
  constexpr double kSourceDepthM = 0.35;
  constexpr double kHeadingRmsDeg = 3.0;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  sim::MagneticEnvironment floor = env;
  floor.dipoles.clear();
  for (int ix = -4; ix <= 4; ++ix) {
    for (int iy = -4; iy <= 4; ++iy) {
      sim::Dipole d;
      const double jx = normal(rng), jy = normal(rng);  // sequenced draws: the same layout on any compiler
      const double mx = normal(rng), my = normal(rng), mz = normal(rng);
      d.position_m = Vec3(ix + 0.3 * jx, iy + 0.3 * jy, -kSourceDepthM);
      d.moment_am2 = Vec3(mx, my, mz);
      floor.dipoles.push_back(d);
    }
  }
  // The heading's RMS is nearly proportional to the moments at a few degrees: two scalings reach 3 deg closely.
  for (int pass = 0; pass < 2; ++pass) {
    const double scale = kHeadingRmsDeg / heading_rms_deg(floor, sensor_height_m);
    for (sim::Dipole& d : floor.dipoles) d.moment_am2 *= scale;
  }
  std::printf("lab floor %llu: heading RMS %.2f deg at the sensor's height, %.1f deg at 5 cm above the floor\n",
              static_cast<unsigned long long>(seed), heading_rms_deg(floor, sensor_height_m),
              heading_rms_deg(floor, 0.05));
  env.dipoles.insert(env.dipoles.end(), floor.dipoles.begin(), floor.dipoles.end());
}

fusion::Quat reference_row(const io::Recording& rec, Eigen::Index i) {
  return fusion::Quat(rec.opt_quat(i, 0), rec.opt_quat(i, 1), rec.opt_quat(i, 2), rec.opt_quat(i, 3));
}

void set_reference_row(io::Recording& rec, Eigen::Index i, const fusion::Quat& q) {
  rec.opt_quat.row(i) << q.w(), q.x(), q.y(), q.z();
}

// ref(t) = truth(t - late_s - drift_ppm 1e-6 t), slerp between samples.
void delay_reference(io::Recording& rec, double late_s, double drift_ppm) {
  const io::Recording truth = rec;
  const Eigen::Index n = rec.opt_quat.rows();
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / rec.sampling_rate_hz;
    const double at = (t - late_s - drift_ppm * 1e-6 * t) * rec.sampling_rate_hz;
    const Eigen::Index k = std::clamp<Eigen::Index>(static_cast<Eigen::Index>(std::floor(at)), 0, n - 2);
    const double f = std::clamp(at - static_cast<double>(k), 0.0, 1.0);
    set_reference_row(rec, i, reference_row(truth, k).slerp(f, reference_row(truth, k + 1)));
  }
}

// Nez App. A.2: the reference frame's north is where the sensor's magnetometer points on average over the movement.
void align_reference_heading(io::Recording& rec) {
  double c = 0.0, s = 0.0;
  for (Eigen::Index i = 0; i < rec.opt_quat.rows(); ++i) {
    if (!rec.movement[static_cast<std::size_t>(i)] || !rec.mag.row(i).allFinite()) continue;
    const double h = heading_of(reference_row(rec, i) * Vec3(rec.mag.row(i).transpose()));
    c += std::cos(h);
    s += std::sin(h);
  }
  const double turn = std::atan2(s, c);
  std::printf("reference heading turned by %.2f deg\n", turn * kDeg);
  const fusion::Quat rz(Eigen::AngleAxisd(turn, Vec3::UnitZ()));
  for (Eigen::Index i = 0; i < rec.opt_quat.rows(); ++i) set_reference_row(rec, i, rz * reference_row(rec, i));
}

}  // namespace

int main(int argc, char** argv) try {
  std::vector<double> hard, soft;
  long long lab_seed = -1;
  bool align = false;
  double late_s = 0.0, drift_ppm = 0.0;
  std::vector<std::pair<std::string, double>> fixed;
  std::size_t evaluations = 300;
  unsigned threads = 2;
  std::string write_dir;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--hard-iron" && has_value) {
      hard = numbers(argv[++i], 3);
    } else if (a == "--soft-iron" && has_value) {
      soft = numbers(argv[++i], 6);
    } else if (a == "--lab" && has_value) {
      lab_seed = std::stoll(argv[++i]);
    } else if (a == "--align-reference") {
      align = true;
    } else if (a == "--reference-late" && has_value) {
      late_s = std::stod(argv[++i]);
    } else if (a == "--reference-drift-ppm" && has_value) {
      drift_ppm = std::stod(argv[++i]);
    } else if (a == "--filter" && has_value && std::string(argv[i + 1]).find('=') != std::string::npos) {
      const std::string kv = argv[++i];
      const auto eq = kv.find('=');
      fixed.emplace_back(kv.substr(0, eq), std::stod(kv.substr(eq + 1)));
    } else if (a == "--evaluations" && has_value) {
      evaluations = std::stoul(argv[++i]);
    } else if (a == "--threads" && has_value) {
      threads = static_cast<unsigned>(std::stoul(argv[++i]));
    } else if (a == "--write" && has_value) {
      write_dir = argv[++i];
    } else {
      std::fprintf(stderr,
                   "usage: bsn_bench_nez_sources [--hard-iron x,y,z] [--soft-iron xx,yy,zz,xy,xz,yz] [--lab SEED] "
                   "[--align-reference] [--reference-late S] [--reference-drift-ppm P] [--filter NAME=VALUE]... "
                   "[--evaluations N] [--threads N] [--write DIR]\n");
      return 2;
    }
  }
  const char* scenarios[] = {"nez_slow", "nez_intermediate", "nez_fast"};
  const double sigma_m_profile[] = {0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0};
  for (int s = 0; s < 3; ++s) {
    sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/" + scenarios[s] + ".yaml");
    if (!hard.empty()) spec.sensors.mag.hard_iron = Vec3(hard[0], hard[1], hard[2]);
    if (!soft.empty()) {
      spec.sensors.mag.soft_iron << 1 + soft[0], soft[3], soft[4], soft[3], 1 + soft[1], soft[5], soft[4], soft[5],
          1 + soft[2];
    }
    if (lab_seed >= 0) {
      add_lab_floor(spec.magnetic, static_cast<std::uint64_t>(lab_seed), spec.free_motion.pose.position_m.z());
    }
    eval::TuneRecording rec{scenarios[s], eval::simulate_recording(spec), {}};
    if (late_s != 0.0 || drift_ppm != 0.0) delay_reference(rec.rec, late_s, drift_ppm);
    if (align) align_reference_heading(rec.rec);
    if (!write_dir.empty()) {
      std::filesystem::create_directories(write_dir);
      const std::string path = write_dir + "/" + scenarios[s] + ".hdf5";
      io::write_broad_hdf5(path, rec.rec);
      std::printf("wrote %s\n", path.c_str());
      continue;
    }
    eval::TuneSetup setup = eval::nez_mekf_setup(rec, s + 1);
    setup.base.parameters.insert(setup.base.parameters.end(), fixed.begin(), fixed.end());
    setup.threads = threads;
    setup.options.max_evaluations = evaluations;
    const eval::TuneResult r = eval::tune(setup);
    std::printf("%-17s sigma_g %.3g sigma_bg %.3g sigma_a %.3g sigma_m %.3g: %.2f deg (Table 3 preset %.2f deg)\n",
                scenarios[s], r.values[0], r.values[1], r.values[2], r.values[3], r.fit_rmse[0] * kDeg,
                r.base_fit_rmse[0] * kDeg);
    std::printf("  along sigma_m (uT: deg):");
    for (const double sigma_m : sigma_m_profile) {
      fusion::FilterSpec f = r.spec;
      for (auto& [name, value] : f.parameters) {
        if (name == "sigma_m") value = sigma_m;
      }
      std::printf(" %g: %.2f", sigma_m, eval::total_rmse(rec.rec, f) * kDeg);
      std::fflush(stdout);
    }
    std::printf("\n");
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bsn_bench_nez_sources: %s\n", e.what());
  return 2;
}
