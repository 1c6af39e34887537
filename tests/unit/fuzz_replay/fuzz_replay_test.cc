// Every seed and every minimised finding of each fuzz harness, run through the same target
// function the libFuzzer executable calls. A finding that comes back aborts (fuzz check) or
// throws something other than InputError, and the test fails.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_targets.h"

namespace {

namespace fs = std::filesystem;
using Target = int (*)(const std::uint8_t*, std::size_t);

// Files of tests/fuzz/corpus/<harness> and tests/data/fuzz/<harness>, sorted.
std::vector<fs::path> Inputs(const std::string& harness) {
  std::vector<fs::path> files;
  for (const fs::path& dir : {fs::path(HAPCO_SOURCE_DIR) / "tests/fuzz/corpus" / harness,
                             fs::path(HAPCO_SOURCE_DIR) / "tests/data/fuzz" / harness}) {
    if (!fs::is_directory(dir)) continue;
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (entry.is_regular_file()) files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

int Replay(const std::string& harness, Target target) {
  int replayed = 0;
  for (const fs::path& file : Inputs(harness)) {
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    SCOPED_TRACE(file.string());
    EXPECT_EQ(target(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()), 0);
    ++replayed;
  }
  return replayed;
}

TEST(FuzzReplay, SceneText) { EXPECT_GE(Replay("scene_text", hapco::fuzz::SceneText), 5); }
TEST(FuzzReplay, TrajectoryCsv) { EXPECT_GE(Replay("trajectory_csv", hapco::fuzz::TrajectoryCsv), 4); }
TEST(FuzzReplay, Recording) { EXPECT_GE(Replay("recording", hapco::fuzz::Recording), 4); }
TEST(FuzzReplay, FclibLocal) { EXPECT_GE(Replay("fclib_local", hapco::fuzz::FclibLocal), 10); }
TEST(FuzzReplay, PoseSession) { EXPECT_GE(Replay("pose_session", hapco::fuzz::PoseSession), 2); }

}  // namespace
