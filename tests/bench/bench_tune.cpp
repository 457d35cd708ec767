// `bsn tune`'s speed and the seed's reproduction:
//  - time to identify the MEKF's four sigmas on a 10-minute 128 Hz recording (the simulator's nez_intermediate
//    scenario) with the default budget on two worker threads; target < 60 s (Nez's exhaustive step 1: 9 days);
//  - with --all: the three Nez scenarios each identified on their own, printed beside Nez Table 3, with the error of
//    the identified set and of the Table 3 preset of the same intensity on the scenario.
// Usage: bsn_bench_tune [--all] [--threads N]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <string>

#include "bsn/eval/tune_runner.hpp"
#include "bsn/fusion/mekf_filter.hpp"
#include "bsn/sim/scenario_file.hpp"

namespace {

using namespace bsn;
constexpr double kDeg = 180.0 / std::numbers::pi;

}  // namespace

int main(int argc, char** argv) {
  bool all = false;
  unsigned threads = 2;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--all") == 0) {
      all = true;
    } else if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = static_cast<unsigned>(std::stoul(argv[++i]));
    } else {
      std::fprintf(stderr, "usage: bsn_bench_tune [--all] [--threads N]\n");
      return 2;
    }
  }
  const char* scenarios[] = {"nez_slow", "nez_intermediate", "nez_fast"};
  const int preset_of[] = {1, 2, 3};  // Table 3 column of each scenario
  std::printf("%-17s %9s %9s %9s %9s | %10s %10s | %6s %8s\n", "scenario", "sigma_g", "sigma_bg", "sigma_a", "sigma_m",
              "tuned deg", "Table3 deg", "evals", "time s");
  for (int s = all ? 0 : 1; s < (all ? 3 : 2); ++s) {
    const sim::ScenarioSpec spec = sim::load_scenario(std::string(BSN_SCENARIO_DIR) + "/" + scenarios[s] + ".yaml");
    const eval::TuneRecording rec{scenarios[s], eval::simulate_recording(spec), {}};
    eval::TuneSetup setup = eval::nez_mekf_setup(rec, preset_of[s]);
    setup.threads = threads;
    const auto t0 = std::chrono::steady_clock::now();
    const eval::TuneResult r = eval::tune(setup);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%-17s %9.3g %9.3g %9.3g %9.3g | %10.2f %10.2f | %6zu %8.1f\n", scenarios[s], r.values[0], r.values[1],
                r.values[2], r.values[3], r.fit_rmse[0] * kDeg, r.base_fit_rmse[0] * kDeg, r.optimiser.evaluations,
                seconds);
    const fusion::MekfNoise& t = fusion::kNezTable3[static_cast<std::size_t>(preset_of[s])];
    std::printf("%-17s %9.3g %9.3g %9.3g %9.3g   (%zu samples, %.0f s at %.0f Hz)\n", "  Nez Table 3", t.sigma_g,
                t.sigma_bg, t.sigma_a, t.sigma_m, rec.rec.size(), static_cast<double>(rec.rec.size()) / spec.rate_hz,
                spec.rate_hz);
  }
  return 0;
}
