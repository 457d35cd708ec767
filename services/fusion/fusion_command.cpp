#include "fusion_command.hpp"

#include <cstdio>
#include <thread>

#include "bsn/dds/body_config.hpp"
#include "bsn/dds/calibration_file.hpp"
#include "bsn/dds/log.hpp"
#include "bsn/dds/shutdown.hpp"

namespace bsn::services {

int run_fusion(const FusionCommandOptions& opt) {
  fusion::BodyModel body;
  FusionService::Options service_options = opt.service;
  try {
    body = opt.body_path.empty() ? fusion::default_lower_body() : dds::load_body_model(opt.body_path);
    service_options.calibrations = dds::load_body_calibrations(opt.body_path);
  } catch (const dds::ConfigError& e) {
    std::fprintf(stderr, "bsn fusion: error: %s\n", e.what());
    return 2;
  }
  if (opt.print_body) {
    std::fputs(dds::body_model_to_yaml(body).c_str(), stdout);
    return 0;
  }
  dds::install_shutdown_handlers();
  try {
    dds::Participant participant({opt.domain, "bsn fusion"});
    FusionService service(participant, body, service_options);
    dds::log_info("fusing ", body.segments.size(), " segments of '", body.name.empty() ? opt.body_path : body.name,
                  "' in domain ", opt.domain);
    while (dds::sleep_unless_shutdown(std::chrono::milliseconds(20))) service.tick();
  } catch (const std::exception& e) {
    dds::log_error(e.what());
    return 1;
  }
  dds::log_info("stopped");
  return 0;
}

}  // namespace bsn::services
