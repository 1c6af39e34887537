#pragma once
// The machine's 1, 5 and 15 minute load averages as /proc/loadavg gives them ("0.52 1.15 1.80";
// empty where it cannot be read). Benchmarks print them at start and end: on 2 cores a busy
// neighbour makes every figure several times worse (platform-notes.md).
#include <fstream>
#include <string>

namespace hapco {

inline std::string LoadAverageText() {
  std::ifstream file("/proc/loadavg");
  std::string one, five, fifteen;
  if (!(file >> one >> five >> fifteen)) return "";
  return one + " " + five + " " + fifteen;
}

}  // namespace hapco
