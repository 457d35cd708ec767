#include "record_service.hpp"

#include <fastdds/rtps/common/SerializedPayload.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <map>
#include <mutex>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/dds/topics.hpp"
#include "bsn/fusion/body_model.hpp"
#include "bsn/io/recording.hpp"
#include "bsn/io/session_file.hpp"
#include "bsn/logging/log.hpp"
#include "sample_fields.hpp"
#include "session_columns.hpp"

#ifndef BSN_VERSION
#define BSN_VERSION "unknown"
#endif

namespace bsn::services {
namespace {

using Clock = std::chrono::steady_clock;

std::uint64_t unix_ns() {
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
}

template <class T>
struct TopicPubSub;
template <class P>
struct TopicPubSub<dds::Topic<P>> {
  using type = P;
};

struct StreamState {
  std::size_t id = 0;
  std::uint64_t cdr_bytes = 0;
};

struct TopicState {
  std::string name;
  std::uint64_t samples = 0;
  std::map<std::string, StreamState> streams;  // by key
};

class Recorder {
 public:
  explicit Recorder(io::SessionWriter& writer) : writer_(writer) {}

  // Under the lock: the readers made before this one already deliver samples on DDS threads, and a growing
  // vector moves the topics they write to.
  std::size_t add_topic(const std::string& name) {
    std::lock_guard lock(mutex_);
    topics_.push_back({name, 0, {}});
    return topics_.size() - 1;
  }

  // Called on a DDS thread for every sample of topic `topic`.
  template <class PubSub>
  void on_sample(std::size_t topic, const typename PubSub::type& sample) {
    const std::uint64_t arrival = unix_ns();
    using T = typename PubSub::type;
    std::lock_guard lock(mutex_);
    static PubSub pubsub;  // one per type (its constructor allocates); used under the lock
    const std::uint32_t size = pubsub.getSerializedSizeProvider(const_cast<T*>(&sample))();
    if (payload_.max_size < size) payload_.reserve(size);
    if (!pubsub.serialize(const_cast<T*>(&sample), &payload_)) {
      ++serialise_failures_;
      return;
    }
    TopicState& t = topics_[topic];
    const std::string key = key_of(sample);
    auto it = t.streams.find(key);
    if (it == t.streams.end()) {
      ColumnSpecVisitor spec;
      if constexpr (HasFields<T>) visit_fields(sample, spec);
      const std::size_t id = writer_.add_stream(t.name, key.empty() ? "_" : key, pubsub.getName(), spec.specs);
      it = t.streams.emplace(key, StreamState{id, 0}).first;
    }
    StreamState& s = it->second;
    writer_.append(s.id, kArrivalColumn, &arrival, 1);
    writer_.append(s.id, kCdrColumn, payload_.data, payload_.length);
    s.cdr_bytes += payload_.length;
    writer_.append(s.id, kCdrEndColumn, &s.cdr_bytes, 1);
    if constexpr (HasFields<T>) {
      AppendVisitor append(writer_, s.id);
      visit_fields(sample, append);
    }
    ++t.samples;
  }

  // Hands what arrived to the writer (under the lock), then writes it to disk (outside).
  void flush() {
    std::uint64_t staged = 0;
    {
      std::lock_guard lock(mutex_);
      writer_.stage();
      for (const TopicState& t : topics_) staged += t.samples;
    }
    writer_.write_staged();
    flushed_samples_ = staged;
  }
  /// Samples in the file as of the last successful flush.
  std::uint64_t flushed_samples() const { return flushed_samples_; }

  std::string progress_line(double elapsed_s) {
    std::lock_guard lock(mutex_);
    std::string line;
    char buf[160];
    std::snprintf(buf, sizeof buf, "%7.1f s ", elapsed_s);
    line += buf;
    for (const TopicState& t : topics_) {
      std::snprintf(buf, sizeof buf, " %s %llu", t.name.c_str() + (t.name.rfind("bsn/", 0) == 0 ? 4 : 0),
                    static_cast<unsigned long long>(t.samples));
      line += buf;
    }
    std::snprintf(buf, sizeof buf, "  %.1f MB", static_cast<double>(writer_.file_bytes()) / 1e6);
    return line + buf;
  }

  /// Streams (keys) of topic `topic` that delivered a sample so far.
  std::size_t stream_count(std::size_t topic) {
    std::lock_guard lock(mutex_);
    return topics_[topic].streams.size();
  }

  std::uint64_t total_samples() {
    std::lock_guard lock(mutex_);
    std::uint64_t n = 0;
    for (const TopicState& t : topics_) n += t.samples;
    return n;
  }
  std::uint64_t serialise_failures() const { return serialise_failures_; }

 private:
  io::SessionWriter& writer_;
  std::mutex mutex_;
  std::vector<TopicState> topics_;
  eprosima::fastrtps::rtps::SerializedPayload_t payload_{256};
  std::uint64_t serialise_failures_ = 0;
  std::uint64_t flushed_samples_ = 0;
};

std::string iso_time(std::uint64_t unix_time_ns) {
  const std::time_t secs = static_cast<std::time_t>(unix_time_ns / 1000000000u);
  std::tm tm{};
  gmtime_r(&secs, &tm);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03uZ", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec, static_cast<unsigned>((unix_time_ns / 1000000u) % 1000u));
  return buf;
}

std::string host_name() {
  char buf[256] = {};
  if (gethostname(buf, sizeof buf - 1) != 0) return "unknown";
  return buf;
}

// The metadata: what produced the recording and with which body model, filters and calibrations.
std::map<std::string, std::string> metadata(const RecordOptions& opt, const fusion::BodyModel& body,
                                            const std::vector<std::string>& topics, std::uint64_t start_ns) {
  std::string filters;
  for (const auto& s : body.segments) {
    filters += s.name + ": " + s.filter.name;
    for (const auto& [k, v] : s.filter.parameters) filters += " " + k + "=" + std::to_string(v);
    filters += "\n";
  }
  // Per node and channel: u = transform * (raw - bias), as bsn fusion applies them.
  std::string calibrations;
  auto channel = [&calibrations](const char* name, const std::optional<calib::ChannelCalibration>& c) {
    if (!c) return;
    char buf[400];
    const auto& b = c->bias;
    const auto& h = c->transform;
    std::snprintf(
        buf, sizeof buf,
        "  %s: {bias: [%.9g, %.9g, %.9g], transform: [[%.9g, %.9g, %.9g], [%.9g, %.9g, %.9g], [%.9g, %.9g, %.9g]]}\n",
        name, b.x(), b.y(), b.z(), h(0, 0), h(0, 1), h(0, 2), h(1, 0), h(1, 1), h(1, 2), h(2, 0), h(2, 1), h(2, 2));
    calibrations += buf;
  };
  for (const auto& [node, c] : config::load_body_calibrations(opt.body_path)) {
    calibrations += node + ":\n";
    channel("accelerometer", c.accelerometer);
    channel("gyroscope", c.gyroscope);
    channel("magnetometer", c.magnetometer);
  }
  std::string topic_list;
  for (const auto& t : topics) topic_list += (topic_list.empty() ? "" : ",") + t;
  return {{"bsn_version", BSN_VERSION},
          {"host", host_name()},
          {"start_time_utc", iso_time(start_ns)},
          {"start_unix_ns", std::to_string(start_ns)},
          {"body_model_file", opt.body_path.empty() ? "(default lower body)" : opt.body_path},
          {"body_model", config::body_model_to_yaml(body)},
          {"filter_parameters", filters},
          {"calibrations", calibrations},
          {"topics", topic_list},
          // The subject (DDS partition) its estimates and status were read from; "" is the default partition.
          {"subject", opt.subject}};
}

/// Whether every topic named is one bsn knows; says the first that is not, with the nearest name.
bool known_topics(const std::vector<std::string>& named, const std::vector<std::string>& known) {
  for (const std::string& t : named) {
    if (std::find(known.begin(), known.end(), t) == known.end()) {
      const std::string near = nearest_name(t, known);
      std::fprintf(stderr, "bsn record: error: unknown topic '%s'%s\n", t.c_str(),
                   near.empty() ? "" : ("; did you mean '" + near + "'?").c_str());
      return false;
    }
  }
  return true;
}

/// One reader per recorded topic into `recorder` (kept in `readers`); `per_segment` gets the recorder's indices of
/// the topics with one stream per segment (raw, orientation).
void subscribe(dds::Participant& participant, Recorder& recorder, const std::vector<std::string>& topics,
               std::vector<std::shared_ptr<void>>& readers, std::vector<std::size_t>& per_segment) {
  dds::for_each_topic([&](const auto& topic) {
    using PubSub = typename TopicPubSub<std::remove_cvref_t<decltype(topic)>>::type;
    if (std::find(topics.begin(), topics.end(), topic.name) == topics.end()) return;
    const std::size_t index = recorder.add_topic(topic.name);
    if (topic.name == dds::kRawTopic.name || topic.name == dds::kOrientationTopic.name) per_segment.push_back(index);
    auto reader = participant.make_reader(
        topic, [&recorder, index](const auto& s, const auto&) { recorder.on_sample<PubSub>(index, s); });
    participant.expect_peer(*reader, "writer of a recorded topic");
    readers.push_back(std::move(reader));
  });
}

}  // namespace

std::vector<std::string> all_topic_names() {
  std::vector<std::string> names;
  dds::for_each_topic([&names](const auto& topic) { names.emplace_back(topic.name); });
  return names;
}

int run_record(const RecordOptions& opt) {
  logging::set_log_identity("record");
  const std::vector<std::string> known = all_topic_names();
  if (!known_topics(opt.topics, known)) return 2;
  const std::vector<std::string> topics = opt.topics.empty() ? known : opt.topics;
  // A full disk or a file size limit must give an error from write(), not kill the process.
  std::signal(SIGXFSZ, SIG_IGN);
  const std::uint64_t start_ns = unix_ns();
  std::unique_ptr<io::SessionWriter> writer;
  fusion::BodyModel body;
  try {
    body = opt.body_path.empty() ? fusion::default_lower_body() : config::load_body_model(opt.body_path);
    writer = std::make_unique<io::SessionWriter>(opt.out, opt.overwrite, metadata(opt, body, topics, start_ns));
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn record: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn record: error: %s\n", e.what());
    return std::string(e.what()).find("--overwrite") != std::string::npos ? 2 : 1;
  }
  Recorder recorder(*writer);
  int exit_code = 0;
  {
    DdsCommandFrame frame(opt.domain, "bsn record", opt.subject);
    std::vector<std::shared_ptr<void>> readers;
    std::vector<std::size_t> per_segment;  ///< the recorded topics with one stream per segment (raw, orientation)
    subscribe(frame.participant(), recorder, topics, readers, per_segment);
    logging::log_info("recording ", topics.size(), " topics to ", opt.out, " in domain ", opt.domain);
    const bool terminal = isatty(STDERR_FILENO) != 0;
    const auto start = Clock::now();
    auto last_flush = start;
    auto last_progress = start;
    // --duration counts from the first sample recorded, so a trial holds what was asked for however long discovery
    // took; with no sample at all it ends at the same time after the start. With --body it counts from when every
    // segment's stream of bsn/raw and bsn/orientation flows (each node and the fusion are discovered one by one, up
    // to seconds apart), or from kStreamsWait_s after the first sample, with a warning naming what was missing.
    // Samples before that are kept (a recording loses nothing), so early streams are longer than the duration.
    constexpr double kStreamsWait_s = 10.0;
    std::optional<Clock::time_point> first_sample, trial_start;
    auto every_stream_flows = [&] {
      if (opt.body_path.empty()) return true;
      for (const std::size_t t : per_segment)
        if (recorder.stream_count(t) < body.segments.size()) return false;
      return true;
    };
    exit_code = frame.run_ticks(std::chrono::milliseconds(50), [&]() -> std::optional<int> {
      const auto now = Clock::now();
      const double elapsed = std::chrono::duration<double>(now - start).count();
      if (!first_sample && recorder.total_samples() > 0) first_sample = now;
      if (first_sample && !trial_start) {
        const bool waited_enough = std::chrono::duration<double>(now - *first_sample).count() >= kStreamsWait_s;
        if (every_stream_flows() || waited_enough) {
          trial_start = now;
          if (!every_stream_flows())
            logging::log_warn("not every segment of the body sent bsn/raw and bsn/orientation within ", kStreamsWait_s,
                              " s of the first sample; the duration counts from now");
        }
      }
      const double recorded = trial_start    ? std::chrono::duration<double>(now - *trial_start).count()
                              : first_sample ? 0.0
                                             : elapsed;
      if (now - last_flush >= std::chrono::duration<double>(opt.flush_period_s)) {
        last_flush = now;
        try {
          recorder.flush();
        } catch (const io::IoError& e) {
          if (terminal) std::fputc('\n', stderr);
          logging::log_error(e.what(), "; ", recorder.flushed_samples(), " samples are safely in the file");
          return 1;
        }
      }
      if (terminal && now - last_progress >= std::chrono::milliseconds(500)) {
        last_progress = now;
        std::fprintf(stderr, "\r%s", recorder.progress_line(elapsed).c_str());
        std::fflush(stderr);
      }
      if (opt.duration_s > 0.0 && recorded >= opt.duration_s) return 0;
      return std::nullopt;
    });
    if (terminal) std::fputc('\n', stderr);
    readers.clear();  // no callback after this, so the writer can close
  }
  if (exit_code == 0) {
    try {
      writer->close();
    } catch (const io::IoError& e) {
      logging::log_error(e.what());
      exit_code = 1;
    }
  }
  logging::log_info("recorded ", recorder.total_samples(), " samples to ", opt.out);
  return exit_code;
}

Command record_command() {
  return {
      "record", "Record bsn topics to an HDF5 session file", [](CLI::App* cmd) {
        auto opt = std::make_shared<RecordOptions>();
        cmd->add_option("--out", opt->out, "session file to write (.h5)")->required();
        cmd->add_option("--topic", opt->topics, "record only this topic (repeatable; default: every topic)");
        cmd->add_option(
               "--duration", opt->duration_s,
               "stop S seconds after the first sample (with --body: after every segment's first) (default: at Ctrl-C)")
            ->check(CLI::NonNegativeNumber);
        cmd->add_flag("--overwrite", opt->overwrite, "replace an existing file");
        cmd->add_option("--body", opt->body_path, "body model stored in the metadata (default: the lower body)");
        cmd->add_option("--flush-period", opt->flush_period_s, "seconds between writes to disk (0.05..1)")
            ->check(CLI::Range(0.05, 1.0))
            ->capture_default_str();
        add_domain_option(cmd, opt->domain);
        add_subject_option(cmd, opt->subject);
        return [opt] { return run_record(*opt); };
      }};
}

}  // namespace bsn::services
