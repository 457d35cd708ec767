// The examples and choices at the end of each subcommand's --help, for the commands that do not carry their own
// (Command::examples; the CLI usage test fails for a command with neither). The examples are commands that
// run as written from a checkout after `cmake --workflow --preset build` (paths are the repository's own).
#include <map>
#include <string>

#include "bsn/fusion/orientation_filter.hpp"
#include "command.hpp"

namespace bsn::services {
namespace {

std::string filter_list() {
  std::string names;
  for (const std::string& n : fusion::filter_names()) names += (names.empty() ? "" : ", ") + n;
  return names;
}

const std::map<std::string, std::string>& examples() {
  static const std::map<std::string, std::string> table = {
      {"sim",
       "  bsn sim --node thigh_l                                   smooth random motion, live on bsn/raw, 100 Hz\n"
       "  bsn sim --scenario sim_publishers/scenarios/fan_b.yaml --node imu --speed 10\n"
       "  bsn sim --scenario sim_publishers/scenarios/fan_e.yaml --out trial/    trial/imu.hdf5 (BROAD layout)\n"
       "Scenarios: sim_publishers/scenarios/*.yaml (installed: /usr/share/bsn/scenarios)."},
      {"fusion",
       "  bsn fusion                                 the default body: pelvis; thigh, shank, foot left and right (_l, "
       "_r)\n"
       "  bsn fusion --print-body > body.yaml        the default body as a file to edit\n"
       "  bsn fusion --body body.yaml --domain 12"},
      {"echo",
       "  bsn echo bsn/joint_angles --rate 5         each joint at most 5 times a second\n"
       "  bsn echo bsn/status --count 1 --timeout 10\n"
       "  bsn echo bsn/raw --format csv --count 100 > raw.csv"},
      {"demo",
       "  bsn demo                                   a simulated walking lower body and its fusion until Ctrl-C\n"
       "  bsn demo --duration 20 --view              with the live 3D view in the browser (its URL is printed)\n"
       "  bsn demo --random --rate 200               every node on its own random motion\n"
       "  bsn demo --calibrate                       live magnetometer calibration, heading error before and after"},
      {"eval",
       "  bsn sim --scenario sim_publishers/scenarios/fan_e.yaml --out trial/ && bsn eval trial/imu.hdf5\n"
       "  bsn eval trial/ --filter seel_ruppin --filter \"madgwick:beta=0.05\" --plot errors.svg\n"
       "  bsn eval --standard-tests --json           Fan et al.'s tests A-E, Table 5\n"
       "Filters: all, " +
           filter_list() +
           "\n"
           "CSV columns (header line, any order): t_s or t_ns; acc_x,acc_y,acc_z (m/s^2); gyr_x,gyr_y,gyr_z (rad/s);\n"
           "  optional mag_x,mag_y,mag_z (uT), quat_w,quat_x,quat_y,quat_z (reference, sensor-to-earth ENU), "
           "movement."},
      {"calibrate",
       "  bsn sim --scenario sim_publishers/scenarios/mag_calibration_session.yaml --out turns/\n"
       "  bsn calibrate --input turns/imu.hdf5 --field-magnitude 50 --node thigh_l   writes turns/imu.calib.yaml\n"
       "  bsn calibrate --allan still/imu.hdf5 --plot allan.svg   (still/: the allan_static_30min.yaml scenario)\n"
       "  bsn calibrate --live --node thigh_l --until-good        through a running `bsn calibration`\n"
       "  bsn calibrate --live --kind alignment --until-good       every node of the body: N-pose, then flexions\n"
       "  bsn calibrate --alignment lab/     (lab/: the gait_alignment.yaml scenario) writes "
       "lab/<node>.alignment.calib.yaml\n"
       "Kinds with --live: magnetometer, gyro-bias, accelerometer, alignment."},
      {"calibration",
       "  bsn calibration                            serve requests for every node, store in ~/.local/state/bsn\n"
       "  bsn calibration --store /var/lib/bsn/calibration --domain 12"},
      {"record",
       "  bsn record --out walk.h5                   every topic until Ctrl-C\n"
       "  bsn record --out raw.h5 --topic bsn/raw --duration 60"},
      {"replay",
       "  bsn replay walk.h5 --speed 2               a session, twice real time\n"
       "  bsn replay trial/imu.hdf5 --loop --node-map imu=pelvis\n"
       "Inputs: sessions from bsn record (.h5), BROAD-layout .hdf5, bsn eval .csv, or folders of them."},
      {"export",
       "  bsn export walk.h5 --format sto --out walk/      OpenSense orientations (segment frames), .mot angles\n"
       "  bsn export walk.h5 --format sto --out walk/ --frames sensor --from 5 --to 35\n"
       "  bsn export walk.h5 --format csv --out walk/      one CSV per topic with units\n"
       "  bsn export walk.h5 --format broad --out walk/    per node, for bsn eval"},
      {"process",
       "  bsn process walk.h5 --out walk-offline.h5               the session again, its body and calibrations\n"
       "  bsn process walk.h5 --body legs.yaml --filter ekf --out walk-ekf.h5\n"
       "  bsn process lab/ --body legs.yaml --out lab.h5           a folder of <node>.hdf5 or <node>.csv"},
      {"node",
       "  bsn node --source serial:/dev/ttyUSB0?baud=115200 --node thigh_l\n"
       "  bsn node --source udp:9000 --node hand_r --map hand_r.map.yaml\n"
       "  bsn node --source iio:iio:device0 --node pelvis\n"
       "Sources: serial:PATH[?baud=N] (line protocol), udp:PORT (lines or NGIMU OSC), iio:DEVICE (Linux IIO)."},
      {"view",
       "  bsn view                                   http://127.0.0.1:8080/ on this machine only\n"
       "  bsn view --bind 0.0.0.0 --port 8081        open to the lab network\n"
       "  bsn demo --view                            the demo with its view"},
      {"ros2-bridge",
       "  bsn ros2-bridge                            rt/bsn/<segment>/imu, rt/tf, rt/bsn/joint_states for ROS 2 tools\n"
       "  bsn ros2-bridge --domain 0                 ROS 2's default domain (ROS_DOMAIN_ID=0)"},
      {"session",
       "  bsn session deploy/sessions/lower_body_sim.yaml   the simulated lower body: align, record trials/walk.h5, "
       "export\n"
       "Session files: deploy/sessions/*.yaml; bodies: deploy/bodies/*.yaml."},
      {"tune",
       "  bsn sim --scenario sim_publishers/scenarios/nez_slow.yaml --out slow/\n"
       "  bsn tune --filter mekf slow/imu.hdf5 --max-evaluations 60\n"
       "  bsn tune --filter seel_ruppin recordings/ --param tau_acc_s=0.1:10:log --holdout 2\n"
       "Filters: " +
           filter_list()},
  };
  return table;
}

}  // namespace

std::string command_examples(const std::string& name) {
  const auto it = examples().find(name);
  return it == examples().end() ? std::string() : "Examples:\n" + it->second + "\n";
}

}  // namespace bsn::services
