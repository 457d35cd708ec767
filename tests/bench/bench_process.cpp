// `bsn process` speed: a 7-segment lower body, 10 minutes at 100 Hz (the simulator's walking, written as per-node
// BROAD files), through the real program five times on core 0; prints each run's wall time and CPU time (user +
// system, of the process alone: on a loaded machine the wall time also counts the time other processes held the
// core), their medians and the ratios to real time. Target: >= 2000x real time on one core.
// Usage: bsn_bench_process [--minutes 10] [--runs 5]
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

int run(const std::string& command) {
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// CPU seconds (user + system) of the finished children so far.
double children_cpu_s() {
  rusage u{};
  getrusage(RUSAGE_CHILDREN, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  double minutes = 10.0;
  int runs = 5;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--minutes") minutes = std::atof(argv[i + 1]);
    if (a == "--runs") runs = std::atoi(argv[i + 1]);
  }
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("bsn_bench_process_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const double seconds = 60.0 * minutes;
  {
    std::ofstream s(dir / "walk.yaml");
    s << "name: walk\ndescription: \"bench\"\nduration_s: " << seconds
      << "\nrate_hz: 100\nseed: 1\nsensors: consumer_mems\nbody:\n  kind: lower_body\n  gait: {speed_m_s: 1.2}\n";
  }
  const std::string bsn = BSN_EXECUTABLE;
  if (run(bsn + " sim --scenario " + (dir / "walk.yaml").string() + " --out " + (dir / "lab").string() +
          " > /dev/null 2>&1") != 0 ||
      run(bsn + " fusion --print-body > " + (dir / "body.yaml").string()) != 0) {
    std::fprintf(stderr, "bench_process: could not simulate the input\n");
    return 1;
  }
  std::vector<double> wall, cpu;
  for (int i = 0; i < runs; ++i) {
    const double cpu0 = children_cpu_s();
    const auto t0 = std::chrono::steady_clock::now();
    const int code =
        run("taskset -c 0 " + bsn + " process " + (dir / "lab").string() + " --body " + (dir / "body.yaml").string() +
            " --out " + (dir / "out.h5").string() + " --overwrite --quiet 2>" + (dir / "log.txt").string());
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (code != 0) {
      std::fprintf(stderr, "bench_process: bsn process failed (exit %d)\n", code);
      return 1;
    }
    wall.push_back(s);
    cpu.push_back(children_cpu_s() - cpu0);
    std::printf("run %d: %.3f s wall, %.3f s CPU\n", i + 1, s, cpu.back());
  }
  std::ifstream log(dir / "log.txt");
  std::string line;
  while (std::getline(log, line)) std::printf("%s\n", line.c_str());
  const double wall_s = median(wall), cpu_s = median(cpu);
  std::printf(
      "bsn process, 7 segments, %.0f s at 100 Hz, median of %d runs: %.3f s wall = %.0fx real time, %.3f s CPU = "
      "%.0fx real time (target 2000x); output %.1f MB\n",
      seconds, runs, wall_s, seconds / wall_s, cpu_s, seconds / cpu_s,
      static_cast<double>(fs::file_size(dir / "out.h5")) / 1e6);
  fs::remove_all(dir);
  return 0;
}
