// The frame of `bsn`: each subcommand registers itself as a Command next to its run function, main() lists them,
// and run_cli parses and dispatches. Long-running DDS commands run inside a DdsCommandFrame.
#pragma once

#include <CLI/CLI.hpp>
#include <chrono>
#include <functional>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "bsn/dds/participant.hpp"

namespace bsn::services {

/// One `bsn` subcommand. `add_options` declares its options on the CLI11 subcommand (bound to storage that the
/// returned function owns) and returns what runs it once the command line is parsed: the process exit code.
struct Command {
  std::string name;
  std::string description;
  std::function<std::function<int()>(CLI::App*)> add_options;
  /// Example command lines for the end of its --help, one per line (a new command writes them here; the older ones
  /// are in command_examples.cpp's table). Empty: the table's entry.
  std::string examples = {};
};

/// The examples and choices of command `name` for its --help (empty if the table has none).
std::string command_examples(const std::string& name);

/// Parses the command line and runs the chosen command. A usage error prints CLI11's message (for a mistyped
/// command or option with "did you mean ...?") and returns 2; an exception from the command prints it and
/// returns 1.
/// `footer(name)`, when given, ends each command's --help (its examples and choices: command_examples).
int run_cli(int argc, char** argv, std::span<const Command> commands,
            const std::function<std::string(const std::string&)>& footer = {});

/// Parse-time check of a numeric option: a finite number in [min, max], or in (min, max] with `min_exclusive`.
/// A value outside is a usage error (exit 2) whose message names the option, e.g.
/// "--stale-timeout: must be a finite number > 0 (got -1)". Every numeric option of every command has one.
CLI::Validator number_in(double min, double max, bool min_exclusive = false);
/// A finite number > 0 (durations, periods, rates, limits), at most `max`.
CLI::Validator positive_number(double max = std::numeric_limits<double>::infinity());
/// A finite number >= 0 (durations where 0 means "no limit", counts), at most `max`.
CLI::Validator non_negative_number(double max = std::numeric_limits<double>::infinity());

/// Adds --domain (default: $BSN_DOMAIN or 0) to a DDS command.
void add_domain_option(CLI::App* command, int& domain);

/// Adds --subject NAME to a command that reads estimates: the subject (DDS partition) it reads.
void add_subject_option(CLI::App* command, std::string& subject);

/// What every long-running DDS command (fusion, echo, sim) runs in: SIGINT/SIGTERM handlers and the process's
/// one participant from construction, the periodic tick loop in run_ticks(). Endpoints made from participant()
/// are declared after the frame, so they close before the participant does.
class DdsCommandFrame {
 public:
  /// `subject`: the subject whose estimates and status the participant reads and writes (Participant::Options).
  DdsCommandFrame(int domain, const std::string& participant_name, const std::string& subject = "");
  dds::Participant& participant() { return participant_; }

  /// Calls `tick` every `period` (and the participant's watch_peers before it) until SIGINT, SIGTERM or
  /// dds::request_shutdown (-> 0) or until `tick` returns an exit code (-> that code).
  int run_ticks(std::chrono::milliseconds period, const std::function<std::optional<int>()>& tick);

 private:
  struct Handlers {
    Handlers();
  } handlers_;  // first, so that a signal while the participant starts is not lost
  dds::Participant participant_;
};

/// Optimal string alignment distance: insertions, deletions, substitutions and swaps of neighbours count one.
std::size_t edit_distance(std::string_view a, std::string_view b);

/// The candidate nearest to `word` by edit_distance if it is close enough to be a typo of it, else "".
std::string nearest_name(std::string_view word, const std::vector<std::string>& candidates);

}  // namespace bsn::services
