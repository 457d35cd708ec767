#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <type_traits>

#include "bsn/dds/conversions.hpp"
#include "bsn/dds/sample_source.hpp"
#include "bsn/dds/shutdown.hpp"
#include "bsn/logging/log.hpp"
#include "format.hpp"
#include "sample_fields.hpp"
#include "tools.hpp"

namespace bsn::services {
namespace {

struct EchoOptions {
  std::string topic;
  long count = 0;          ///< stop after this many samples (0 = never)
  double rate_hz = 0.0;    ///< print at most this many samples per second (0 = all)
  double timeout_s = 0.0;  ///< exit 1 if not `count` samples within this time (0 = wait forever)
  int domain = 0;
  std::string subject;          ///< the subject (DDS partition) of estimates and status
  std::string format = "text";  ///< text (human units), csv (header line, then SI values) or json (one per line)
};

using Clock = std::chrono::steady_clock;

struct Printer {
  explicit Printer(const EchoOptions& o) : opt(o) {}
  const EchoOptions& opt;
  std::mutex mutex;
  std::atomic<long> printed{0};
  /// Per sample key (joint, segment, node, ...): --rate limits each key on its own, so every joint of a body shows
  /// at the rate asked for, not a share of it.
  std::map<std::string, Clock::time_point> last_print;

  /// Prints `line` of the sample with DDS key `key`; `header` (if any) goes before the first line printed.
  void print(const std::string& line, const std::string& key, const std::string& header = "") {
    std::lock_guard lock(mutex);
    if (opt.count > 0 && printed.load() >= opt.count) return;
    const auto now = Clock::now();
    if (opt.rate_hz > 0.0) {
      const auto [last, first] = last_print.try_emplace(key, now);
      if (!first && now - last->second < std::chrono::duration<double>(1.0 / opt.rate_hz)) return;
      last->second = now;
    }
    if (printed.load() == 0 && !header.empty()) {
      std::fputs(header.c_str(), stdout);
      std::fputc('\n', stdout);
    }
    std::fputs(line.c_str(), stdout);
    std::fputc('\n', stdout);
    std::fflush(stdout);
    if (++printed == opt.count) dds::request_shutdown();
  }
};

// What a reader of estimates must not take at face value: a key written by more than one writer at once (a second
// fusion service, a foreign writer), and numbers that are not finite. Both are flagged and counted, never hidden.
template <class T>
constexpr bool kIsEstimate = std::is_same_v<T, bsn::Orientation> || std::is_same_v<T, bsn::JointAngles>;

struct EstimateWatch {
  std::mutex mutex;
  dds::KeyWriters writers;
  std::uint64_t non_finite = 0;
  std::set<std::string> shared_keys;  ///< keys seen with more than one writer (listed at the end, bounded)
  static constexpr std::size_t kMaxSharedKeysListed = 16;
  std::size_t max_writers = 1;

  /// Writers of the sample's key within the last second; warns once per key when more than one.
  std::size_t note(const std::string& key, const eprosima::fastdds::dds::SampleInfo& info, bool finite) {
    std::lock_guard lock(mutex);
    non_finite += finite ? 0 : 1;
    const std::size_t n = writers.note(key, info.sample_identity.writer_guid(), dds::monotonic_ns());
    if (n > 1 && shared_keys.size() < kMaxSharedKeysListed && shared_keys.insert(key).second)
      logging::log_warn("key '", logging::printable(key), "' is written by ", n, " writers at once (another ",
                        "fusion service or a foreign writer on the domain); its lines say writers=", n);
    max_writers = std::max(max_writers, n);
    return n;
  }
};

// One line per sample; an orientation line says which of the orientation topics it comes from (the estimate, the
// sensor's truth or the segment's truth; its flags say the frame).
const char* orientation_label(std::string_view topic) {
  if (topic == dds::kTruthOrientationTopic.name) return "truth";
  if (topic == dds::kTruthSegmentOrientationTopic.name) return "segment-truth";
  return "orientation";
}
std::string format_line(const bsn::Orientation& s, std::string_view topic) {
  return format_sample(s, orientation_label(topic));
}
template <class T>
std::string format_line(const T& s, std::string_view) {
  return format_sample(s);
}
std::string non_finite_line(const bsn::Orientation& s, std::string_view topic) {
  return format_non_finite(s, orientation_label(topic));
}
std::string non_finite_line(const bsn::JointAngles& s, std::string_view) { return format_non_finite(s); }

// --format csv|json: SI values at full precision, for scripts. The CSV header comes with the first sample.
template <class T>
std::string machine_line(const T& s, const char* topic, const std::string& format) {
  if constexpr (HasFields<T>) {
    return format == "json" ? json_object(s, topic) : csv_row(s);
  } else {
    return format_line(s, topic);
  }
}
template <class T>
std::string csv_header_of(const T& s, const std::string& format) {
  if constexpr (HasFields<T>) {
    return format == "csv" ? csv_header(s) : "";
  } else {
    return "";
  }
}

std::vector<std::string> topic_names() {
  std::vector<std::string> names;
  dds::for_each_topic([&names](const auto& topic) { names.emplace_back(topic.name); });
  return names;
}

std::string topic_list() {
  std::string list;
  for (const std::string& n : topic_names()) list += (list.empty() ? "" : ", ") + n;
  return list;
}

int run_echo(const EchoOptions& opt) {
  if (const auto names = topic_names(); std::find(names.begin(), names.end(), opt.topic) == names.end()) {
    const std::string near = nearest_name(opt.topic, names);
    std::fprintf(stderr, "bsn echo: error: unknown topic '%s'%s (known: %s)\n", opt.topic.c_str(),
                 near.empty() ? "" : ("; did you mean '" + near + "'?").c_str(), topic_list().c_str());
    return 2;
  }
  bool machine_format_known = true;
  dds::for_each_topic([&](const auto& topic) {
    using T = typename std::remove_cvref_t<decltype(topic)>::Type;
    if (opt.topic == topic.name && !HasFields<T>) machine_format_known = opt.format == "text";
  });
  if (!machine_format_known) {
    std::fprintf(stderr, "bsn echo: error: no %s format for %s yet (use --format text)\n", opt.format.c_str(),
                 opt.topic.c_str());
    return 2;
  }
  Printer printer(opt);
  EstimateWatch watch;
  DdsCommandFrame frame(opt.domain, "bsn echo", opt.subject);
  std::shared_ptr<void> reader;  // of the one topic named, whatever its type
  dds::for_each_topic([&](const auto& topic) {
    if (opt.topic != topic.name) return;
    reader = frame.participant().make_reader(
        topic, [&printer, &opt, &watch, name = topic.name](const auto& s, const auto& info) {
          using T = std::remove_cvref_t<decltype(s)>;
          if constexpr (kIsEstimate<T>) {
            const bool finite = dds::finite_values(s);
            const std::size_t writers = watch.note(key_of(s), info, finite);
            if (opt.format == "text") {
              printer.print((finite ? format_line(s, name) : non_finite_line(s, name)) +
                                (writers > 1 ? " writers=" + std::to_string(writers) : ""),
                            key_of(s));
            } else if (finite) {  // a machine format has no place for a flag: such samples are counted instead
              printer.print(machine_line(s, name, opt.format), key_of(s), csv_header_of(s, opt.format));
            }
          } else if (opt.format == "text") {
            printer.print(format_line(s, name), key_of(s));
          } else {
            printer.print(machine_line(s, name, opt.format), key_of(s), csv_header_of(s, opt.format));
          }
        });
  });
  // At the end, whatever ended it: what was flagged, on stderr (stdout stays the samples).
  struct Summary {
    EstimateWatch& watch;
    const std::string& topic;
    ~Summary() {
      std::lock_guard lock(watch.mutex);
      if (watch.non_finite > 0)
        std::fprintf(stderr, "bsn echo: %llu sample(s) on %s held non-finite numbers: flagged, never printed as data\n",
                     static_cast<unsigned long long>(watch.non_finite), topic.c_str());
      if (!watch.shared_keys.empty())
        std::fprintf(stderr, "bsn echo: %zu key(s) on %s were written by more than one writer at once (up to %zu)\n",
                     watch.shared_keys.size(), topic.c_str(), watch.max_writers);
    }
  } summary{watch, opt.topic};
  const auto start = Clock::now();
  return frame.run_ticks(std::chrono::milliseconds(20), [&]() -> std::optional<int> {
    if (opt.timeout_s > 0.0 && Clock::now() - start > std::chrono::duration<double>(opt.timeout_s)) {
      std::fprintf(stderr, "bsn echo: timeout: %ld of %ld samples on %s within %.1f s\n", printer.printed.load(),
                   opt.count, opt.topic.c_str(), opt.timeout_s);
      return 1;
    }
    return std::nullopt;
  });
}

}  // namespace

Command echo_command() {
  return {"echo", "Print a bsn topic live, one line per sample, in degrees", [](CLI::App* cmd) {
            auto opt = std::make_shared<EchoOptions>();
            cmd->add_option("topic", opt->topic, "one of: " + topic_list())->required();
            cmd->add_option("--count", opt->count, "exit after N samples")->check(non_negative_number());
            cmd->add_option("--rate", opt->rate_hz,
                            "print at most HZ samples per second of each key (joint, segment, node)")
                ->check(non_negative_number(1e6));
            cmd->add_option("--timeout", opt->timeout_s, "exit 1 if --count samples have not arrived within S seconds")
                ->check(non_negative_number(1e9));
            cmd->add_option("--format", opt->format,
                            "text (human units), csv (SI, header first) or json (one per line)")
                ->check(CLI::IsMember({"text", "csv", "json"}))
                ->capture_default_str();
            add_domain_option(cmd, opt->domain);
            add_subject_option(cmd, opt->subject);
            return [opt] { return run_echo(*opt); };
          }};
}

}  // namespace bsn::services
