// `bsn`: one program, one subcommand per process role (like git).
#include <CLI/CLI.hpp>
#include <cstdio>

#include "bsn/dds/log.hpp"
#include "bsn/dds/participant.hpp"
#include "calibrate_command.hpp"
#include "demo_command.hpp"
#include "echo_command.hpp"
#include "eval_command.hpp"
#include "fusion_command.hpp"
#include "sim_node.hpp"

namespace {

void add_domain_option(CLI::App* cmd, int& domain) {
  domain = bsn::dds::default_domain();
  cmd->add_option("--domain", domain, "DDS domain id, 0..232 (default: $BSN_DOMAIN or 0)")->check(CLI::Range(0, 232));
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bsn: inertial motion tracking on a body sensor network over DDS"};
  app.set_version_flag("--version", "bsn 0.1.0");
  app.require_subcommand(1);

  bsn::sim::SimNodeOptions sim;
  auto* sim_cmd = app.add_subcommand("sim", "Simulated sensor node: publishes bsn/raw and bsn/truth/orientation");
  sim_cmd->add_option("--node", sim.node, "node id on bsn/raw (required unless --scenario with --out)");
  sim_cmd->add_option("--segment", sim.segment, "segment name on bsn/truth/orientation (default: node id)");
  sim_cmd->add_option("--rate", sim.rate_hz, "sample rate in Hz")->capture_default_str();
  sim_cmd->add_option("--seed", sim.seed, "motion and noise seed (default: from the node id)");
  sim_cmd->add_option("--duration", sim.duration_s, "stop after S seconds (default: run until Ctrl-C)");
  sim_cmd->add_flag("--ideal", sim.ideal, "no sensor noise (with --scenario: every sensor error off)");
  sim_cmd
      ->add_option("--scenario", sim.scenario, "scenario YAML file: publish its segment --segment (default: node id)")
      ->check(CLI::ExistingFile);
  sim_cmd->add_option("--speed", sim.speed, "with --scenario: publish N times faster than real time")
      ->capture_default_str();
  sim_cmd->add_option("--out", sim.out_dir, "with --scenario: write DIR/<segment>.hdf5 (BROAD layout) and exit");
  add_domain_option(sim_cmd, sim.domain);

  bsn::services::FusionCommandOptions fusion;
  auto* fusion_cmd = app.add_subcommand("fusion", "Fusion service: one filter per body segment");
  fusion_cmd->add_option("--body", fusion.body_path, "YAML body model (default: 7-segment lower body)");
  fusion_cmd->add_flag("--print-body", fusion.print_body, "print the body model in effect as YAML and exit");
  fusion_cmd
      ->add_option("--stale-timeout", fusion.service.stale_timeout_s, "seconds without samples before a node is stale")
      ->capture_default_str();
  fusion_cmd->add_option("--status-period", fusion.service.status_period_s, "seconds between bsn/status samples")
      ->capture_default_str();
  fusion_cmd->add_flag("--best-effort", fusion.service.best_effort,
                       "publish orientations and joint angles BEST_EFFORT instead of RELIABLE");
  fusion_cmd
      ->add_option("--max-time-jump", fusion.service.gate.max_forward_jump_s,
                   "a sensor timestamp more than S seconds ahead is rejected as a jump")
      ->capture_default_str();
  add_domain_option(fusion_cmd, fusion.domain);

  bsn::services::EchoOptions echo;
  auto* echo_cmd = app.add_subcommand("echo", "Print a bsn topic live, one line per sample, in degrees");
  echo_cmd->add_option("topic", echo.topic, "one of: " + bsn::services::echo_topic_list())->required();
  echo_cmd->add_option("--count", echo.count, "exit after N samples")->check(CLI::NonNegativeNumber);
  echo_cmd->add_option("--rate", echo.rate_hz, "print at most HZ samples per second")->check(CLI::NonNegativeNumber);
  echo_cmd->add_option("--timeout", echo.timeout_s, "exit 1 if --count samples have not arrived within S seconds")
      ->check(CLI::NonNegativeNumber);
  add_domain_option(echo_cmd, echo.domain);

  bsn::services::DemoOptions demo;
  auto* demo_cmd = app.add_subcommand("demo", "Simulated lower body + fusion, live joint angles in the terminal");
  demo_cmd->add_option("--duration", demo.duration_s, "stop after S seconds (default: run until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  demo_cmd->add_option("--body", demo.body_path, "YAML body model (default: 7-segment lower body)");
  demo_cmd->add_option("--rate", demo.rate_hz, "sample rate of the simulated nodes, Hz")->capture_default_str();
  add_domain_option(demo_cmd, demo.domain);

  bsn::services::EvalOptions eval;
  auto* eval_cmd = app.add_subcommand("eval", "Score filters against the reference of recordings (BROAD HDF5, CSV)");
  eval_cmd->add_option("inputs", eval.inputs, "recordings (.hdf5 in BROAD layout, .csv) or folders of them")
      ->required();
  eval_cmd->add_option("--filter", eval.filters, "NAME or NAME:key=value,...; repeatable; 'all' = every filter")
      ->take_all();
  eval_cmd->add_flag("--json", eval.json, "print one JSON object instead of the table");
  eval_cmd->add_option("--plot", eval.plot_path, "write an SVG image of the total error over time per filter");

  bsn::services::CalibrateOptions calibrate;
  auto* calibrate_cmd = app.add_subcommand(
      "calibrate", "Calibrate a hand-turned recording (magnetometer, accelerometer) or identify noise (--allan)");
  calibrate_cmd->add_option("--input", calibrate.input, "recording (CSV, BROAD HDF5) of still poses turned by hand");
  calibrate_cmd->add_option("--allan", calibrate.allan, "static recording: print Allan noise figures instead");
  calibrate_cmd->add_option("--field-magnitude", calibrate.field_magnitude, "|calibrated magnetometer|, M")
      ->capture_default_str();
  calibrate_cmd->add_flag("--json", calibrate.json, "print the magnetometer calibration as one JSON object");
  calibrate_cmd->add_option("--output", calibrate.output, "calibration file to write (default: INPUT.calib.yaml)");
  calibrate_cmd->add_option("--node", calibrate.node, "node id to record in the calibration file");
  calibrate_cmd->add_flag("--accelerometer", calibrate.accelerometer, "also calibrate the accelerometer (|g|)");
  calibrate_cmd->add_flag("--gyro-bias", calibrate.gyro_bias, "also write the gyro bias measured at rest");
  calibrate_cmd->add_option("--rest-threshold", calibrate.rest_rate_rad_s, "rest when |gyro - bias| < this, rad/s")
      ->capture_default_str();
  calibrate_cmd->add_option("--min-pose", calibrate.min_pose_s, "shortest rest counted as a pose, s")
      ->capture_default_str();
  calibrate_cmd->add_option("--plot", calibrate.plot, "with --allan: write the Allan curves as SVG");

  CLI11_PARSE(app, argc, argv);
  if (*sim_cmd) {
    if (sim.scenario.empty() && sim.node.empty()) return app.exit(CLI::RequiredError("--node"));
    sim.rate_given = sim_cmd->count("--rate") > 0;
  }

  try {
    if (*sim_cmd) {
      bsn::dds::set_log_identity("sim " + (sim.node.empty() ? std::string("scenario") : sim.node));
      return bsn::sim::run_sim_node(sim);
    }
    if (*fusion_cmd) {
      bsn::dds::set_log_identity("fusion");
      return bsn::services::run_fusion(fusion);
    }
    if (*echo_cmd) {
      bsn::dds::set_log_identity("echo");
      return bsn::services::run_echo(echo);
    }
    if (*eval_cmd) return bsn::services::run_eval(eval);
    if (*demo_cmd) {
      bsn::dds::set_log_identity("demo");
      return bsn::services::run_demo(demo);
    }
    if (*calibrate_cmd) return bsn::services::run_calibrate(calibrate);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
