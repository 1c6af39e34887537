#pragma once
// The fuzz targets: one function per reader of outside input. Each takes arbitrary bytes,
// returns 0, and aborts (HAPCO_FUZZ_CHECK) when the reader breaks a promise: an exception
// other than InputError escapes, or an accepted input violates what the reader guarantees.
// Built twice: into the libFuzzer executables (clang, ASan + UBSan, preset `fuzz`) and into
// the release replay test (tests/unit/fuzz_replay), which runs the seed corpora and every
// minimised finding under tests/data/fuzz/ with g++.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace hapco::fuzz {

int SceneText(const std::uint8_t* data, std::size_t size);      // io::ParseSceneText + bodies
int TrajectoryCsv(const std::uint8_t* data, std::size_t size);  // io::ParseTrajectoryCsv
int Recording(const std::uint8_t* data, std::size_t size);      // io::ParseRecording
int FclibLocal(const std::uint8_t* data, std::size_t size);     // fclib::ReadFclib* (files)
int PoseSession(const std::uint8_t* data, std::size_t size);    // service/pose_intake.h

}  // namespace hapco::fuzz

#define HAPCO_FUZZ_CHECK(condition, what)                                                   \
  do {                                                                                      \
    if (!(condition)) {                                                                     \
      std::fprintf(stderr, "%s:%d: fuzz check failed: %s (%s)\n", __FILE__, __LINE__, what, \
                   #condition);                                                             \
      std::abort();                                                                         \
    }                                                                                       \
  } while (false)
