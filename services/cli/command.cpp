#include "command.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

#include "bsn/config/subjects.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/logging/log.hpp"

namespace bsn::services {
namespace {

std::vector<std::string> option_names(const CLI::App& app) {
  std::vector<std::string> names;
  for (const CLI::Option* o : app.get_options()) {
    for (const std::string& n : o->get_lnames()) names.push_back("--" + n);
    for (const std::string& n : o->get_snames()) names.push_back("-" + n);
  }
  return names;
}

// CLI11's message, and for the first argument nobody took that looks like a typo, the name it was meant to be.
// CLI11 reports an unknown command as "A subcommand is required", so that case gets its own message.
void print_usage_error(CLI::App& app, const CLI::ParseError& error, std::span<const Command> commands) {
  const std::vector<CLI::App*> chosen = app.get_subcommands();
  std::string message = error.what();
  for (const std::string& arg : app.remaining(true)) {
    const bool is_option = arg.starts_with('-');
    if (!is_option && !chosen.empty()) continue;
    // A value such as the 5 of "--domain 5" is no command name (they start with a letter).
    if (!is_option && (arg.empty() || !std::isalpha(static_cast<unsigned char>(arg[0])))) continue;
    std::vector<std::string> candidates;
    if (is_option) {
      candidates = option_names(chosen.empty() ? app : *chosen.front());
    } else {
      for (const Command& c : commands) candidates.push_back(c.name);
    }
    const std::string word = arg.substr(0, arg.find('='));
    const std::string near = nearest_name(word, candidates);
    if (!is_option) message = "unknown command '" + word + "'";
    if (!near.empty()) message += "; did you mean '" + near + "'?";
    if (!near.empty() || !is_option) break;
  }
  if (chosen.empty() && message == error.what()) {
    // No command at all, or only options: say which commands there are.
    std::string names;
    for (const Command& c : commands) names += (names.empty() ? "" : ", ") + c.name;
    message += " (one of: " + names + ")";
  }
  std::fprintf(stderr, "bsn: %s\nRun with --help for more information.\n", message.c_str());
}

}  // namespace

int run_cli(int argc, char** argv, std::span<const Command> commands,
            const std::function<std::string(const std::string&)>& footer) {
  CLI::App app{"bsn: inertial motion tracking on a body sensor network over DDS"};
  app.set_version_flag("--version", "bsn 0.1.0");
  app.require_subcommand(1);
  std::vector<std::pair<CLI::App*, std::function<int()>>> runs;
  for (const Command& c : commands) {
    CLI::App* sub = app.add_subcommand(c.name, c.description);
    if (!c.examples.empty()) {
      sub->footer("Examples:\n" + c.examples + "\n");
    } else if (footer) {
      sub->footer(footer(c.name));
    }
    runs.emplace_back(sub, c.add_options(sub));
  }
  try {
    app.parse(argc, argv);
    for (std::size_t i = 0; i < runs.size(); ++i) {
      if (!*runs[i].first) continue;
      logging::set_log_identity(commands[i].name);
      return runs[i].second();
    }
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == static_cast<int>(CLI::ExitCodes::Success)) return app.exit(e);  // --help, --version
    print_usage_error(app, e, commands);
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bsn: error: %s\n", e.what());
    return 1;
  }
  return 0;
}

CLI::Validator number_in(double min, double max, bool min_exclusive) {
  const std::string range = (min_exclusive ? "> " : ">= ") + CLI::detail::to_string(min) +
                            (std::isinf(max) ? std::string() : " and <= " + CLI::detail::to_string(max));
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        const bool number = !text.empty() && end == text.c_str() + text.size();
        if (number && std::isfinite(v) && (min_exclusive ? v > min : v >= min) && v <= max) return {};
        return "must be a finite number " + range + " (got " + text + ")";
      },
      "NUMBER " + range);
}

CLI::Validator positive_number(double max) { return number_in(0.0, max, true); }
CLI::Validator non_negative_number(double max) { return number_in(0.0, max, false); }

void add_domain_option(CLI::App* command, int& domain) {
  std::string bad_environment;
  try {
    domain = dds::default_domain();
  } catch (const std::invalid_argument& e) {
    domain = 0;
    bad_environment = e.what();
  }
  CLI::Option* option = command->add_option("--domain", domain, "DDS domain id, 0..232 (default: $BSN_DOMAIN or 0)")
                            ->check(CLI::Validator(
                                [](std::string& text) -> std::string {
                                  char* end = nullptr;
                                  errno = 0;
                                  const long v = std::strtol(text.c_str(), &end, 10);
                                  if (!text.empty() && *end == '\0' && errno == 0 && v >= 0 && v <= 232) return {};
                                  return "'" + text + "' is not a DDS domain id in 0..232";
                                },
                                "INT in 0..232"));
  // A bad BSN_DOMAIN is a usage error (exit 2) unless --domain overrides it: never a silent fallback to domain 0,
  // where this process could disturb another system.
  if (!bad_environment.empty()) {
    command->parse_complete_callback([option, bad_environment] {
      if (option->count() == 0) throw CLI::ValidationError(bad_environment);
    });
  }
  // Both go into the environment, where the participant reads them, so children (bsn demo's) inherit them.
  command
      ->add_option_function<std::string>(
          "--profile", [](const std::string& file) { ::setenv("FASTRTPS_DEFAULT_PROFILES_FILE", file.c_str(), 1); },
          "Fast DDS XML profiles file, e.g. share/bsn/profiles/discovery-client.xml (default: "
          "$FASTRTPS_DEFAULT_PROFILES_FILE; none: UDP with multicast discovery)")
      ->check(CLI::ExistingFile);
  command
      ->add_option_function<std::string>(
          "--security", [](const std::string& dir) { ::setenv("BSN_SECURITY_DIR", dir.c_str(), 1); },
          "DDS-Security identity folder made by deploy/security/make-pki.sh (ca.pem, cert.pem, key.pem, "
          "governance.p7s, permissions.p7s) (default: $BSN_SECURITY_DIR; none: the network is open)")
      ->check(CLI::ExistingDirectory);
}

DdsCommandFrame::Handlers::Handlers() { dds::install_shutdown_handlers(); }

DdsCommandFrame::DdsCommandFrame(int domain, const std::string& participant_name, const std::string& subject)
    : participant_({domain, participant_name, subject}) {}

void add_subject_option(CLI::App* command, std::string& subject) {
  command
      ->add_option("--subject", subject,
                   "the subject (DDS partition) whose estimates and status to read (default: the single-body "
                   "fusion's, in the default partition)")
      ->check(CLI::Validator(
          [](std::string& value) {
            const std::string problem = config::subject_name_problem(value);
            return problem.empty() ? std::string() : "subject '" + value + "' " + problem;
          },
          "NAME"));
}

int DdsCommandFrame::run_ticks(std::chrono::milliseconds period, const std::function<std::optional<int>()>& tick) {
  while (dds::sleep_unless_shutdown(period)) {
    participant_.watch_peers();
    if (const std::optional<int> code = tick()) return *code;
  }
  return 0;
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  // d[i][j]: distance between the first i characters of a and the first j of b.
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

std::string nearest_name(std::string_view word, const std::vector<std::string>& candidates) {
  // Close enough: about one edit per three letters (leading dashes of options do not count), and not all of them.
  const std::size_t letters = word.size() - std::min(word.find_first_not_of('-'), word.size());
  const std::size_t limit = std::min(std::max<std::size_t>(1, (letters + 1) / 3), letters == 0 ? 0 : letters - 1);
  std::string best;
  std::size_t best_distance = limit + 1;
  for (const std::string& c : candidates) {
    if (const std::size_t d = edit_distance(word, c); d < best_distance) {
      best = c;
      best_distance = d;
    }
  }
  return best;
}

}  // namespace bsn::services
