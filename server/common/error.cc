#include "common/error.h"

#include <cstdio>
#include <cstdlib>

namespace hapco {

void AssertionFailed(const char* condition, const char* file, int line, const char* message) {
  std::fprintf(stderr, "hapco: internal error at %s:%d: %s (%s)\n", file, line, message,
               condition);
  std::abort();
}

}  // namespace hapco
