#pragma once
// The boundary of every thin executable (design.md, example 14): errors become exit codes.
#include <functional>
#include <string>
#include <string_view>

namespace hapco::cli {

// Runs `body` and returns its exit code; an InputError, a filesystem error (a path the user
// gave) or running out of memory prints "TOOL: message" on stderr and returns 1, any other
// exception "TOOL: unexpected error: ..." and returns 3. The libraries' progress lines
// (common/progress.h) go to stderr as "TOOL: line".
int RunMain(const char* tool, const std::function<int()>& body);

// "TOOL HapCo 0.1.0 (git DESCRIBE)": the project version and the tree's `git describe` at
// configure time.
std::string VersionLine(std::string_view tool);

}  // namespace hapco::cli
