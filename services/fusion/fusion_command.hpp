#pragma once

#include <string>

#include "fusion_service.hpp"

namespace bsn::services {

struct FusionCommandOptions {
  std::string body_path;  ///< "" = the default 7-segment lower body
  bool print_body = false;
  int domain = 0;
  FusionService::Options service;
};

int run_fusion(const FusionCommandOptions& options);

}  // namespace bsn::services
