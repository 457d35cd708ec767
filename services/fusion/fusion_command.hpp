#pragma once

#include "command.hpp"

namespace bsn::services {

/// `bsn fusion`: its options and what runs it.
Command fusion_command();

}  // namespace bsn::services
