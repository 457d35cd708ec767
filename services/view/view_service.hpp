// `bsn view`: a live 3D view of the body in the browser. DDS readers of orientation, truth, joint angles and status
// feed a ViewState; its messages go to every browser over a WebSocket (ViewServer), at most 30 Hz per segment.
#pragma once

#include <string>

#include "command.hpp"

namespace bsn::services {

struct ViewOptions {
  int port = 8080;
  std::string bind = "127.0.0.1";  ///< loopback by default: --bind 0.0.0.0 shows the view to the lab network
  int domain = 0;
  std::string subject;  ///< the subject (DDS partition) of the estimates and status shown
  std::string token;    ///< when set, every request needs it (--token, or $BSN_VIEW_TOKEN)
};

/// `bsn view`.
Command view_command();

}  // namespace bsn::services
