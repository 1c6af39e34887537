#pragma once
// Small helpers shared by the thin executables (design.md, example 14): flag values parsed
// with messages that say what to fix, and one boundary that turns errors into exit codes.
#include <functional>
#include <string>
#include <string_view>

namespace hapco::cli {

// A finite number, else InputError "FLAG expects a number, got 'TEXT'".
double ParseDouble(std::string_view flag, const char* text);
// A finite number > 0, else InputError "FLAG expects a number > 0, got 'TEXT'".
double ParsePositive(std::string_view flag, const char* text);
// An integer in [minimum, maximum], else InputError naming the flag and the range.
long ParseInteger(std::string_view flag, const char* text, long minimum, long maximum);

// Runs `body` and returns its exit code; an InputError prints "TOOL: message" on stderr and
// returns 1, any other exception "TOOL: unexpected error: ..." and returns 3.
int RunMain(const char* tool, const std::function<int()>& body);
// The same, and `--version` anywhere among the arguments prints VersionLine(tool) and returns
// 0 without running `body`.
int RunMain(const char* tool, int argc, char** argv, const std::function<int()>& body);

// "TOOL HapCo 0.1.0 (git DESCRIBE)": the project version and the tree's `git describe` at
// configure time.
std::string VersionLine(std::string_view tool);
// True when an argument is `--version`.
bool AsksForVersion(int argc, char** argv);

}  // namespace hapco::cli
