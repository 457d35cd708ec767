// The page of `bsn view` (services/view/web/*), built into the program so that it needs no installed files of its
// own. CMake generates the definition from the files.
#pragma once

#include <string>
#include <vector>

namespace bsn::services {

struct WebAsset {
  std::string path;  ///< URL path, e.g. "/index.html"
  std::string content_type;
  std::string body;
};

const std::vector<WebAsset>& view_web_assets();

}  // namespace bsn::services
