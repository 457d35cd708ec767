#pragma once

#include "command.hpp"

namespace bsn::services {

/// `bsn demo`: its options and what runs it.
Command demo_command();

}  // namespace bsn::services
