#include "common/cli.h"

#include "common/version.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "common/error.h"

namespace hapco::cli {

double ParseDouble(std::string_view flag, const char* text) {
  char* end = nullptr;
  const double value = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(value)) {
    throw InputError(std::string(flag) + " expects a number, got '" + text + "'");
  }
  return value;
}

double ParsePositive(std::string_view flag, const char* text) {
  const double value = ParseDouble(flag, text);
  if (!(value > 0)) throw InputError(std::string(flag) + " expects a number > 0, got '" + text + "'");
  return value;
}

long ParseInteger(std::string_view flag, const char* text, long minimum, long maximum) {
  char* end = nullptr;
  const long value = std::strtol(text, &end, 10);
  if (end == text || *end != '\0' || value < minimum || value > maximum) {
    throw InputError(std::string(flag) + " expects an integer in [" + std::to_string(minimum) + ", " +
                     std::to_string(maximum) + "], got '" + text + "'");
  }
  return value;
}

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

int RunMain(const char* tool, int argc, char** argv, const std::function<int()>& body) {
  if (AsksForVersion(argc, argv)) {
    std::printf("%s\n", VersionLine(tool).c_str());
    return 0;
  }
  return RunMain(tool, body);
}

std::string VersionLine(std::string_view tool) {
  return std::string(tool) + " HapCo " + HAPCO_VERSION_STRING + " (git " + HAPCO_GIT_DESCRIBE + ")";
}

bool AsksForVersion(int argc, char** argv) {
  for (int k = 1; k < argc; ++k) {
    if (std::string_view(argv[k]) == "--version") return true;
  }
  return false;
}

}  // namespace hapco::cli
