#pragma once
// Error handling conventions (design.md, example 2):
// - bad input from a user (a file, a flag, a pose) throws hapco::InputError with a message
//   that says what to fix;
// - an internal invariant that can only fail through a bug uses HAPCO_ASSERT;
// - a solver that does not converge returns a status, it never throws.
#include <stdexcept>
#include <string>

namespace hapco {

class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

[[noreturn]] void AssertionFailed(const char* condition, const char* file, int line,
                                  const char* message);

// A failed assertion prints its message and calls abort(), unless a process sets an exit code
// here: fclib's reader worker (a forked child) ends with it instead, so that its parent tells a
// HapCo bug from a library's crash on a corrupt file (SIGSEGV, SIGABRT). -1 = abort().
void SetAssertionExitCode(int exit_code);

}  // namespace hapco

// Checked in every build type: the cost is a predictable branch, the benefit is a clear
// message instead of a wrong force.
#define HAPCO_ASSERT(condition, message)                                          \
  do {                                                                            \
    if (!(condition)) ::hapco::AssertionFailed(#condition, __FILE__, __LINE__, message); \
  } while (false)
