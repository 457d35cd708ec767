// `bsn`: one program, one subcommand per process role (like git). Each command registers its options next to
// its run function; this list is the only place that names them all.
#include "calibration_service.hpp"
#include "command.hpp"
#include "export_service.hpp"
#include "fusion_service.hpp"
#include "node_service.hpp"
#include "process_command.hpp"
#include "record_service.hpp"
#include "replay_service.hpp"
#include "ros2_bridge.hpp"
#include "session_service.hpp"
#include "sim_node.hpp"
#include "tools.hpp"
#include "view_service.hpp"

int main(int argc, char** argv) {
  using namespace bsn::services;
  const Command commands[] = {bsn::sim::sim_command(), fusion_command(),    echo_command(),        demo_command(),
                              eval_command(),          calibrate_command(), calibration_command(), record_command(),
                              replay_command(),        export_command(),    process_command(),     node_command(),
                              tune_command(),          view_command(),      ros2_bridge_command(), session_command()};
  return run_cli(argc, argv, commands, command_examples);
}
