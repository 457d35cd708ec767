#include "export_service.hpp"

#include <cstdio>
#include <filesystem>

#include "export_formats.hpp"

namespace bsn::services {

namespace fs = std::filesystem;

int run_export(const ExportOptions& opt) {
  if (opt.format == "sto" && opt.to_s < opt.from_s) {
    std::fprintf(stderr, "bsn export: error: --to %g is before --from %g\n", opt.to_s, opt.from_s);
    return 2;
  }
  try {
    const io::SessionReader r(opt.session);
    std::error_code ec;
    fs::create_directories(opt.out_dir, ec);
    if (!fs::is_directory(opt.out_dir)) {
      std::fprintf(stderr, "bsn export: error: cannot create folder %s\n", opt.out_dir.c_str());
      return 1;
    }
    int files = 0;
    if (opt.format == "csv") files = export_csv(r, opt.out_dir);
    if (opt.format == "sto") files = export_sto(r, opt.out_dir, opt);
    if (opt.format == "broad") files = export_broad(r, opt.out_dir);
    if (files == 0) {
      std::fprintf(stderr, "bsn export: error: %s holds nothing to export as %s\n", opt.session.c_str(),
                   opt.format.c_str());
      return 1;
    }
    std::fprintf(stderr, "bsn export: %d files in %s\n", files, opt.out_dir.c_str());
    return 0;
  } catch (const io::FormatError& e) {  // missing, empty, truncated or not a session: the input is wrong
    std::fprintf(stderr, "bsn export: error: %s\n", e.what());
    return 2;
  } catch (const io::IoError& e) {
    std::fprintf(stderr, "bsn export: error: %s\n", e.what());
    return 1;
  }
}

Command export_command() {
  return {"export", "Export a session file: OpenSim .sto, CSV per topic, or BROAD HDF5 per node", [](CLI::App* cmd) {
            auto opt = std::make_shared<ExportOptions>();
            cmd->add_option("session", opt->session, "session file from bsn record")->required();
            cmd->add_option("--format", opt->format, "sto, csv or broad")
                ->required()
                ->check(CLI::IsMember({"sto", "csv", "broad"}));
            cmd->add_option("--out", opt->out_dir, "output folder")->required();
            cmd->add_option("--frame", opt->frame, "sto: opensim (ground Y up) or enu (as recorded, Z up)")
                ->check(CLI::IsMember({"opensim", "enu"}))
                ->capture_default_str();
            cmd->add_option("--frames", opt->frames,
                            "sto: segment (every sample in its segment frame, the alignment applied to all) or "
                            "sensor (every sample in its sensor frame, the alignment in alignment.csv)")
                ->check(CLI::IsMember({"segment", "sensor"}))
                ->capture_default_str();
            cmd->add_option("--from", opt->from_s, "sto: first row, s from the session's first complete row")
                ->check(non_negative_number(1e9));
            cmd->add_option("--to", opt->to_s, "sto: last row, s from the session's first complete row")
                ->check(non_negative_number(1e9));
            cmd->add_option("--calibration-at", opt->calibration_at_s,
                            "sto: the row of calibration.sto (the IMU placer's input; default: --from), s")
                ->check(non_negative_number(1e9));
            cmd->add_option("--opensim-name", opt->opensim_names,
                            "sto: SEGMENT=BODY, the OpenSim body of a segment (column BODY_imu); default: "
                            "Rajagopal's names (pelvis, femur_l, tibia_l, calcn_l, torso, humerus_l, ...)")
                ->check([](const std::string& v) {
                  const auto eq = v.find('=');
                  return eq == std::string::npos || eq == 0 || eq + 1 == v.size() ? std::string("must be SEGMENT=BODY")
                                                                                  : std::string();
                });
            return [opt] { return run_export(*opt); };
          }};
}

}  // namespace bsn::services
