#pragma once

#include "command.hpp"

namespace bsn::services {

/// `bsn echo`: its options and what runs it.
Command echo_command();

}  // namespace bsn::services
