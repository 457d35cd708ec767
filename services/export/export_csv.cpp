#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fstream>
#include <type_traits>

#include "bsn/dds/topics.hpp"
#include "export_formats.hpp"
#include "sample_fields.hpp"
#include "session_streams.hpp"

namespace bsn::services {
namespace {

namespace fs = std::filesystem;

template <class T>
struct TopicPubSubOf;
template <class P>
struct TopicPubSubOf<dds::Topic<P>> {
  using type = P;
};

std::string file_stem_of(const std::string& topic) {
  std::string stem = topic.rfind("bsn/", 0) == 0 ? topic.substr(4) : topic;
  std::replace(stem.begin(), stem.end(), '/', '_');
  return stem;
}

// A key as a file name part: letters, digits, '-' and '_' kept, anything else '_'.
std::string file_part(const std::string& key) {
  std::string out;
  for (const char c : key.substr(0, 64))
    out += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' ? c : '_';
  return out.empty() ? "_" : out;
}

}  // namespace

// One CSV file per topic; joint angles one file per joint, so that their columns carry the joint's own angle names
// (flexion_extension, ...; the axis-sequence angles as angle_1_z, ...).
int export_csv(const io::SessionReader& r, const fs::path& out) {
  int files = 0;
  dds::for_each_topic([&](const auto& topic) {
    using PubSub = typename TopicPubSubOf<std::remove_cvref_t<decltype(topic)>>::type;
    using T = typename PubSub::type;
    const auto streams = r.streams_of(topic.name);
    if (streams.empty()) return;
    if constexpr (HasFields<T>) {
      constexpr bool per_key = std::is_same_v<T, bsn::JointAngles>;
      const std::size_t file_count = per_key ? streams.size() : 1;
      for (std::size_t k = 0; k < file_count; ++k) {
        const std::string stem = file_stem_of(topic.name) + (per_key ? "_" + file_part(streams[k].key) : std::string());
        const fs::path path = out / (stem + ".csv");
        std::ofstream f(path);
        bool header = false;
        for (std::size_t si = per_key ? k : 0; si < (per_key ? k + 1 : streams.size()); ++si) {
          const auto& s = streams[si];
          const auto arrival = r.read_u64(s, "arrival_ns");
          const auto samples = read_stream_samples<PubSub>(r, s);
          for (std::size_t i = 0; i < samples.size(); ++i) {
            if (!header) {
              f << "arrival_ns [ns since 1970]," << csv_header(samples[i], per_key) << "\n";
              header = true;
            }
            f << csv_row(samples[i], std::to_string(i < arrival.size() ? arrival[i] : 0)) << "\n";
          }
        }
        if (!f) throw io::IoError(path.string() + ": cannot write");
        ++files;
      }
    } else {
      std::fprintf(stderr, "bsn export: %s has no CSV layout yet; skipped\n", topic.name);
    }
  });
  return files;
}

}  // namespace bsn::services
