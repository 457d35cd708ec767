// `bsn process` and `bsn eval --body`'s input: a session file or recordings read once into flat per-node arrays,
// the body they go through, and the merged order in which the samples reach the pipeline.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "bsn/fusion/body_model.hpp"
#include "bsn_idl/bsn.h"
#include "process_command.hpp"
#include "session_streams.hpp"

namespace bsn::services::process_detail {

/// A usage error: a bad option, body or input (exit 2).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One node's samples, column by column, and where they came from.
struct NodeTrack : RawColumns {
  std::string node;
  std::size_t segment = 0;
};

struct TimedCalibration {
  std::uint64_t arrival_ns = 0;
  bsn::CalibrationResult result;
};

/// One segment's reference orientations from a recording, as read: bsn/truth/orientation's samples are made of them
/// when written (time = arrival, the quaternion normalised, gyro bias and flags 0), so reading builds no sample.
struct RecordedTruth {
  std::string segment, node;
  std::vector<std::uint64_t> timestamp_ns;
  std::vector<double> quat;  ///< w, x, y, z per sample, as recorded (finite)
  std::size_t size() const { return timestamp_ns.size(); }
};

struct ProcessInput {
  std::vector<NodeTrack> tracks;
  std::vector<TimedCalibration> calibrations;  ///< from a session's bsn/calibration/result, in arrival order
  std::vector<bsn::Orientation> truth;         ///< a session's bsn/truth/orientation, to carry over as it was
  std::vector<std::uint64_t> truth_arrival_ns;
  std::vector<RecordedTruth> recorded_truth;  ///< recordings' reference orientations, per segment in body order
  std::string recorded_body;                  ///< a session's body_model attribute
  bool session = false;
};

/// Reads the input and the body (nodes mapped to segments, --filter applied); checks the input and the options.
ProcessInput load_input(const ProcessOptions& opt, fusion::BodyModel& body, std::vector<std::string>& notes);

/// One event of the merged input: a sample of a track, or (as-recorded) a calibration result.
struct Event {
  std::uint64_t key = 0;    ///< arrival or sensor time
  std::uint64_t tie = 0;    ///< sensor time (arrival order), 0 (time order)
  std::uint32_t rank = 0;   ///< segment index: a parent usually comes before its children in a body file
  std::uint32_t track = 0;  ///< track index, or kCalibration
  std::uint64_t index = 0;  ///< sample index in the track, or calibration index
  static constexpr std::uint32_t kCalibration = 0xffffffffu;
};

/// The merged order of every sample (and, with `calibrations`, every calibration result) of the input.
std::vector<Event> merge_events(const ProcessInput& in, const std::string& order, bool calibrations);

/// Sample `i` of a track as the raw sample a node publishes (its node id is left as it is).
void fill_raw(const NodeTrack& t, std::size_t i, bsn::RawSample& raw);
/// Sample `i` of a track as the fusion takes it (dds::to_imu_sample, as of fill_raw's sample).
fusion::ImuSample imu_sample(const NodeTrack& t, std::size_t i);

/// A recording's reference orientation as its bsn/truth/orientation sample has it: normalised, then canonical
/// (dds::fill_orientation).
fusion::Quat truth_quat(const RecordedTruth& t, std::size_t i);

}  // namespace bsn::services::process_detail
