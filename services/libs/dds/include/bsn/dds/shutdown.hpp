// SIGINT/SIGTERM handling: every long-running bsn process stops its loop on either signal and then closes its
// DDS entities, so no Fast DDS resources are left behind.
#pragma once

#include <chrono>

namespace bsn::dds {

/// Installs the handlers (idempotent).
void install_shutdown_handlers();

/// True once SIGINT or SIGTERM arrived (or request_shutdown was called).
bool shutdown_requested();

/// Asks the process's loops to stop, as a signal would.
void request_shutdown();

/// Sleeps for `d` or until shutdown is requested; returns false if shutdown was requested.
bool sleep_unless_shutdown(std::chrono::nanoseconds d);

}  // namespace bsn::dds
