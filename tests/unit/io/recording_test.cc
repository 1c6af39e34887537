// Recording files: exact round trip, and nothing complete is lost to a torn tail, a damaged
// record or a writer killed with SIGKILL.
#include "io/recording.h"

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "common/error.h"

namespace hapco::io {
namespace {

using google::protobuf::util::MessageDifferencer;

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hapco_" + std::to_string(getpid()) + "_" + name)).string();
}

recording::Header MakeHeader() {
  recording::Header header;
  header.set_format_version(1);
  header.set_writer("recording_test");
  header.set_scene_name("benchmark1");
  header.set_scene_text("format_version: 1\n");
  return header;
}

recording::Step MakeStep(int step) {
  recording::Step out;
  out.set_step(static_cast<std::uint64_t>(step));
  out.set_client_id("phantom-1");
  out.mutable_contact_force_n()->set_z(0.1 * step);
  out.set_solver_status("converged");
  out.set_iterations(static_cast<std::uint32_t>(step % 7));
  for (int c = 0; c < step % 5; ++c) {
    auto* contact = out.add_contacts();
    contact->set_id(static_cast<std::uint32_t>(c));
    contact->mutable_force_n()->set_z(1.0 + c);
    contact->set_state(recording::STICKING);
  }
  return out;
}

std::string ReadBytes(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
}

void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

TEST(Crc32Test, MatchesTheStandardCheckValue) {
  // The CRC-32/ISO-HDLC check value of the ASCII string "123456789".
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
  EXPECT_EQ(Crc32("", 0), 0u);
}

TEST(RecordingTest, RoundTripIsExact) {
  const std::string path = TempPath("roundtrip.hapcorec");
  {
    RecordingWriter writer(path, MakeHeader());
    for (int step = 1; step <= 50; ++step) writer.AppendStep(MakeStep(step));
    EXPECT_EQ(writer.records_written(), 51);
  }
  RecordingReadReport report;
  const auto records = ReadRecording(path, &report);
  ASSERT_EQ(records.size(), 51u);
  EXPECT_FALSE(report.torn_tail);
  EXPECT_EQ(report.damaged_records, 0);
  EXPECT_TRUE(MessageDifferencer::Equals(records[0].header(), MakeHeader()));
  for (int step = 1; step <= 50; ++step) {
    EXPECT_TRUE(MessageDifferencer::Equals(records[static_cast<std::size_t>(step)].step(), MakeStep(step)));
  }
  std::filesystem::remove(path);
}

// A writer stopped at any byte leaves every complete record readable.
TEST(RecordingTest, TornTailAtEveryByteKeepsEveryCompleteRecord) {
  const std::string path = TempPath("torn.hapcorec");
  std::vector<std::size_t> record_ends;
  {
    RecordingWriter writer(path, MakeHeader());
    record_ends.push_back(std::filesystem::file_size(path));
    for (int step = 1; step <= 6; ++step) {
      writer.AppendStep(MakeStep(step));
      record_ends.push_back(std::filesystem::file_size(path));
    }
  }
  const std::string full = ReadBytes(path);
  const std::string cut_path = TempPath("torn_cut.hapcorec");
  for (std::size_t size = record_ends.front(); size <= full.size(); ++size) {
    WriteBytes(cut_path, full.substr(0, size));
    RecordingReadReport report;
    const auto records = ReadRecording(cut_path, &report);
    const auto complete = static_cast<std::size_t>(
        std::upper_bound(record_ends.begin(), record_ends.end(), size) - record_ends.begin());
    ASSERT_EQ(records.size(), complete) << "cut at byte " << size;
    const bool on_boundary = std::find(record_ends.begin(), record_ends.end(), size) != record_ends.end();
    EXPECT_EQ(report.torn_tail, !on_boundary) << "cut at byte " << size;
    EXPECT_EQ(report.damaged_records, 0);
    if (!on_boundary) {
      EXPECT_NE(report.Summary().find("torn tail"), std::string::npos);
    }
  }
  std::filesystem::remove(path);
  std::filesystem::remove(cut_path);
}

// A flipped byte inside one record loses that record only; the reader resyncs after it.
TEST(RecordingTest, DamagedRecordIsSkippedAndTheRestIsKept) {
  const std::string path = TempPath("damaged.hapcorec");
  std::size_t record_10_start = 0;
  {
    RecordingWriter writer(path, MakeHeader());
    for (int step = 1; step <= 20; ++step) {
      if (step == 10) record_10_start = std::filesystem::file_size(path);
      writer.AppendStep(MakeStep(step));
    }
  }
  std::string bytes = ReadBytes(path);
  bytes[record_10_start + 14] = static_cast<char>(bytes[record_10_start + 14] ^ 0x5A);
  WriteBytes(path, bytes);
  RecordingReadReport report;
  const auto records = ReadRecording(path, &report);
  ASSERT_EQ(records.size(), 20u);  // header + 19 steps
  EXPECT_EQ(report.damaged_records, 1);
  std::vector<std::uint64_t> steps;
  for (const auto& record : records) {
    if (record.has_step()) steps.push_back(record.step().step());
  }
  EXPECT_EQ(std::count(steps.begin(), steps.end(), 10u), 0);
  EXPECT_EQ(steps.back(), 20u);
  std::filesystem::remove(path);
}

// VisitRecording (hapco-report: one record at a time, the file mapped) hands over exactly the
// records ParseRecording returns from the same bytes, damage and a torn tail included, and
// reads a pipe as well as a file.
TEST(RecordingTest, VisitingAFileGivesTheRecordsOfParsingItsBytes) {
  const std::string path = TempPath("visited.hapcorec");
  std::size_t record_7_start = 0;
  {
    RecordingWriter writer(path, MakeHeader());
    for (int step = 1; step <= 12; ++step) {
      if (step == 7) record_7_start = std::filesystem::file_size(path);
      writer.AppendStep(MakeStep(step));
    }
  }
  std::string bytes = ReadBytes(path);
  bytes[record_7_start + 13] = static_cast<char>(bytes[record_7_start + 13] ^ 0x33);  // damage step 7
  bytes.resize(bytes.size() - 5);                                                        // tear step 12
  WriteBytes(path, bytes);
  RecordingReadReport parsed_report, visited_report;
  const auto parsed = ParseRecording(bytes, path, &parsed_report);
  std::vector<recording::Record> visited;
  VisitRecording(path, &visited_report, [&](const recording::Record& r) { visited.push_back(r); });
  ASSERT_EQ(visited.size(), parsed.size());
  ASSERT_EQ(parsed.size(), 11u);  // header + steps 1..11 without 7
  for (std::size_t i = 0; i < parsed.size(); ++i) EXPECT_TRUE(MessageDifferencer::Equals(visited[i], parsed[i])) << i;
  EXPECT_EQ(visited_report.Summary(), parsed_report.Summary());
  EXPECT_EQ(visited_report.damaged_records, 1);
  EXPECT_TRUE(visited_report.torn_tail);
  // Through a pipe (not a regular file: read into memory).
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(fds[0]);
    std::size_t at = 0;
    while (at < bytes.size()) {
      const ssize_t n = write(fds[1], bytes.data() + at, bytes.size() - at);
      if (n <= 0) _exit(1);
      at += static_cast<std::size_t>(n);
    }
    _exit(0);
  }
  close(fds[1]);
  std::vector<recording::Record> piped;
  RecordingReadReport piped_report;
  VisitRecording("/proc/self/fd/" + std::to_string(fds[0]), &piped_report,
                 [&](const recording::Record& r) { piped.push_back(r); });
  close(fds[0]);
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_EQ(piped.size(), parsed.size());
  EXPECT_EQ(piped_report.Summary(), parsed_report.Summary());
  EXPECT_THROW(VisitRecording(std::filesystem::temp_directory_path().string(), nullptr,
                              [](const recording::Record&) {}),
               InputError);
  std::filesystem::remove(path);
}

TEST(RecordingTest, NotARecordingIsAClearError) {
  const std::string path = TempPath("not.hapcorec");
  WriteBytes(path, "step,force\n1,2\n");
  try {
    ReadRecording(path, nullptr);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("not a HapCo recording"), std::string::npos);
  }
  std::filesystem::remove(path);
  EXPECT_THROW(ReadRecording(TempPath("missing.hapcorec"), nullptr), InputError);
}

std::string ErrorOfWriter(const std::string& path, ExistingFile existing) {
  try {
    RecordingWriter writer(path, MakeHeader(), existing);
  } catch (const InputError& error) {
    return error.what();
  }
  return "";
}

// Two recorders on one --output interleaved their records and both reported success; a
// restarted recorder truncated its predecessor's steps (a helper session). A second writer on
// a file is refused while the first lives, and a live recorder never truncates data.
TEST(RecordingTest, ASecondWriterAndExistingDataAreRefused) {
  const std::string path = TempPath("locked.hapcorec");
  std::filesystem::remove(path);
  {
    RecordingWriter first(path, MakeHeader(), ExistingFile::kRefuse);  // a new file is fine
    first.AppendStep(MakeStep(1));
    const std::string second = ErrorOfWriter(path, ExistingFile::kReplace);
    EXPECT_NE(second.find("another process is writing " + path), std::string::npos) << second;
    first.AppendStep(MakeStep(2));
  }
  const std::string recorded = ReadBytes(path);
  const std::string refused = ErrorOfWriter(path, ExistingFile::kRefuse);
  EXPECT_NE(refused.find(path + " already holds " + std::to_string(recorded.size()) + " bytes"), std::string::npos)
      << refused;
  EXPECT_NE(refused.find("--overwrite"), std::string::npos) << refused;
  EXPECT_EQ(ReadBytes(path), recorded) << "a refused file is left as it was";
  // Replacing (hapco-sim, hapco-recorder --overwrite) truncates: the header alone is left.
  EXPECT_EQ(ErrorOfWriter(path, ExistingFile::kReplace), "");
  EXPECT_EQ(ReadRecording(path, nullptr).size(), 1u);
  // An empty file (made by mktemp, say) is no recording to keep.
  WriteBytes(path, "");
  EXPECT_EQ(ErrorOfWriter(path, ExistingFile::kRefuse), "");
  std::filesystem::remove(path);
}

// A writer process killed with SIGKILL while writing: every record it completed reads back,
// in order, with no gap.
TEST(RecordingTest, WriterKilledWithSigkillLeavesAReadableFile) {
  const std::string path = TempPath("killed.hapcorec");
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    RecordingWriter writer(path, MakeHeader());
    for (int step = 1;; ++step) writer.AppendStep(MakeStep(step));
  }
  // Wait (bounded) until the child has written a good amount, then kill it mid-stream.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::error_code error;
  while (std::chrono::steady_clock::now() < deadline) {
    const auto size = std::filesystem::file_size(path, error);  // error until the file exists
    if (!error && size >= 200000) break;
  }
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));
  RecordingReadReport report;
  const auto records = ReadRecording(path, &report);
  ASSERT_GT(records.size(), 100u);
  EXPECT_EQ(report.damaged_records, 0);
  ASSERT_TRUE(records[0].has_header());
  for (std::size_t i = 1; i < records.size(); ++i) {
    ASSERT_TRUE(records[i].has_step());
    EXPECT_EQ(records[i].step().step(), i);
    EXPECT_TRUE(MessageDifferencer::Equals(records[i].step(), MakeStep(static_cast<int>(i))));
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hapco::io
