#include "fusion_command.hpp"

#include <cstdio>
#include <string>

#include "bsn/config/body_config.hpp"
#include "bsn/config/calibration_file.hpp"
#include "bsn/logging/log.hpp"
#include "fusion_service.hpp"

namespace bsn::services {
namespace {

struct FusionCommandOptions {
  std::string body_path;  ///< "" = the default 7-segment lower body
  bool print_body = false;
  int domain = 0;
  FusionService::Options service;
};

int run_fusion(const FusionCommandOptions& opt) {
  fusion::BodyModel body;
  FusionService::Options service_options = opt.service;
  try {
    body = opt.body_path.empty() ? fusion::default_lower_body() : config::load_body_model(opt.body_path);
    service_options.calibrations = config::load_body_calibrations(opt.body_path);
  } catch (const config::ConfigError& e) {
    std::fprintf(stderr, "bsn fusion: error: %s\n", e.what());
    return 2;
  }
  if (opt.print_body) {
    std::fputs(config::body_model_to_yaml(body).c_str(), stdout);
    return 0;
  }
  DdsCommandFrame frame(opt.domain, "bsn fusion");
  FusionService service(frame.participant(), body, service_options);
  logging::log_info("fusing ", body.segments.size(), " segments of '", body.name.empty() ? opt.body_path : body.name,
                    "' in domain ", opt.domain);
  const int exit_code = frame.run_ticks(std::chrono::milliseconds(20), [&service] {
    service.tick();
    return std::optional<int>();
  });
  logging::log_info("stopped");
  return exit_code;
}

}  // namespace

Command fusion_command() {
  return {"fusion", "Fusion service: one filter per body segment", [](CLI::App* cmd) {
            auto opt = std::make_shared<FusionCommandOptions>();
            cmd->add_option("--body", opt->body_path, "YAML body model (default: 7-segment lower body)");
            cmd->add_flag("--print-body", opt->print_body, "print the body model in effect as YAML and exit");
            cmd->add_option("--stale-timeout", opt->service.stale_timeout_s,
                            "seconds without samples before a node is stale")
                ->capture_default_str();
            cmd->add_option("--status-period", opt->service.status_period_s, "seconds between bsn/status samples")
                ->capture_default_str();
            cmd->add_flag("--best-effort", opt->service.best_effort,
                          "publish orientations and joint angles BEST_EFFORT instead of RELIABLE");
            cmd->add_option("--max-time-jump", opt->service.gate.max_forward_jump_s,
                            "a sensor timestamp more than S seconds ahead is rejected as a jump")
                ->capture_default_str();
            add_domain_option(cmd, opt->domain);
            return [opt] { return run_fusion(*opt); };
          }};
}

}  // namespace bsn::services
