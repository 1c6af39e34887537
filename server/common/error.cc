#include "common/error.h"

#include <cstdio>
#include <cstdlib>

namespace hapco {
namespace {
int assertion_exit_code = -1;
}  // namespace

void SetAssertionExitCode(int exit_code) { assertion_exit_code = exit_code; }

void AssertionFailed(const char* condition, const char* file, int line, const char* message) {
  std::fprintf(stderr, "hapco: internal error at %s:%d: %s (%s)\n", file, line, message,
               condition);
  if (assertion_exit_code >= 0) {
    std::fflush(stderr);
    std::_Exit(assertion_exit_code);
  }
  std::abort();
}

}  // namespace hapco
