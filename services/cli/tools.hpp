// bsn's own tools, each in its own source next to its run function: `bsn echo` (print a topic live), `bsn demo`
// (simulated body + fusion in the terminal), `bsn eval` (score filters on recordings), `bsn calibrate` (offline
// calibration and Allan noise figures). Services (fusion, sim, ...) declare their command in their own header.
#pragma once

#include "command.hpp"

namespace bsn::services {

Command echo_command();
Command demo_command();
Command eval_command();
Command calibrate_command();

}  // namespace bsn::services
