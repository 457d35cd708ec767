#pragma once

#include "command.hpp"

namespace bsn::services {

/// `bsn eval`: its options and what runs it.
Command eval_command();

}  // namespace bsn::services
