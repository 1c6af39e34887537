#include "cli/run_main.h"

#include <cstdio>
#include <exception>
#include <filesystem>
#include <new>
#include <string>

#include "common/error.h"
#include "common/progress.h"
#include "common/version.h"

namespace hapco::cli {

int RunMain(const char* tool, const std::function<int()>& body) {
  // The libraries' progress on long work (a large scene's precomputation) as "TOOL: line".
  SetProgressSink([tool](const std::string& line) { std::fprintf(stderr, "%s: %s\n", tool, line.c_str()); });
  try {
    return body();
  } catch (const InputError& error) {
    std::fprintf(stderr, "%s: %s\n", tool, error.what());
    return 1;
  } catch (const std::filesystem::filesystem_error& error) {
    // A path the user gave (an output folder under /proc, a file where a folder should be):
    // bad input, not the DDS failure that exit code 3 stands for.
    std::fprintf(stderr, "%s: %s\n", tool, error.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: out of memory: the problem asked for is larger than this machine can hold (make it smaller)\n",
                 tool);
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
