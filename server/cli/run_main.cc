#include "cli/run_main.h"

#include <cstdio>
#include <exception>
#include <string>

#include "common/error.h"
#include "common/version.h"

namespace hapco::cli {

int RunMain(const char* tool, const std::function<int()>& body) {
  try {
    return body();
  } catch (const InputError& error) {
    std::fprintf(stderr, "%s: %s\n", tool, error.what());
    return 1;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "%s: unexpected error: %s\n", tool, error.what());
    return 3;
  }
}

std::string VersionLine(std::string_view tool) {
  return std::string(tool) + " HapCo " + HAPCO_VERSION_STRING + " (git " + HAPCO_GIT_DESCRIBE + ")";
}

}  // namespace hapco::cli
