#pragma once
// Process-level integration test support: executables started for real (posix_spawn, output
// to files), bounded waits on their exit (pidfd + poll, no sleeps), CSV reading, a per-test
// output folder, and a per-test DDS domain with the loopback config that children inherit
// through CYCLONEDDS_URI (so concurrent test runs never see each other).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/inotify.h>
#include <signal.h>
#include <spawn.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Dense>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "service/config.h"
#include "service/dds.h"
#include "test_domain.h"

extern char** environ;

namespace hapco::service {

// A child process running an executable, stdout and stderr to files. Killed if still
// running at destruction.
class Process {
 public:
  Process(const std::vector<std::string>& args, const std::string& out_path, const std::string& err_path) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("posix_spawn " + args[0] + ": " + std::strerror(rc));
    pidfd_ = static_cast<int>(syscall(SYS_pidfd_open, pid_, 0));
    if (pidfd_ < 0) throw std::runtime_error("pidfd_open failed");
  }
  ~Process() {
    if (!joined_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(pidfd_);
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  void Signal(int signal) { kill(pid_, signal); }
  // Exit code (128 + signal if killed), or -1 if it is still running after timeout_ms.
  int Wait(int timeout_ms) {
    pollfd p{pidfd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) != 1) return -1;
    int status = 0;
    if (waitpid(pid_, &status, 0) != pid_) return -1;
    joined_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  pid_t pid_ = -1;
  int pidfd_ = -1;
  bool joined_ = false;
};

inline std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// CSV with a header: rows as column name -> text.
inline std::vector<std::map<std::string, std::string>> ReadCsv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> rows;
  auto split = [](const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string field;
    while (std::getline(ss, field, ',')) out.push_back(field);
    return out;
  };
  if (!std::getline(in, line)) return rows;
  header = split(line);
  while (std::getline(in, line)) {
    const auto fields = split(line);
    std::map<std::string, std::string> row;
    for (std::size_t i = 0; i < header.size() && i < fields.size(); ++i) row[header[i]] = fields[i];
    rows.push_back(row);
  }
  return rows;
}

inline Eigen::Vector3d Vec(const std::map<std::string, std::string>& row, const char* x, const char* y, const char* z) {
  return {std::stod(row.at(x)), std::stod(row.at(y)), std::stod(row.at(z))};
}

inline std::string TestDir() {
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string dir = std::string(HAPCO_BINARY_DIR) + "/test-output/" + info->test_suite_name() + "." + info->name();
  // Emptied first: a recorder refuses an --output that already holds data, and a test must not
  // read an earlier run's files as its own.
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline dds_domainid_t SetUpTestDomain() {
  UseLoopbackConfig();  // children inherit CYCLONEDDS_URI
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return ReserveTestDomain(std::string(info->test_suite_name()) + "." + info->name());  // test_domain.h
}

// Waits (inotify, bounded) until `done()` holds; `done` is checked after every change of
// the file at `path` (which must exist). False on timeout.
template <typename Predicate>
inline bool WaitForFile(const std::string& path, int timeout_ms, Predicate done) {
  const int fd = inotify_init1(IN_CLOEXEC);
  if (fd < 0) return false;
  inotify_add_watch(fd, path.c_str(), IN_MODIFY | IN_CLOSE_WRITE);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  bool ok = done();
  while (!ok) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(left.count())) == 1) {
      char events[4096];
      if (read(fd, events, sizeof(events)) < 0) break;
    }
    ok = done();
  }
  close(fd);
  return ok;
}

inline bool WaitForText(const std::string& path, const std::string& text, int timeout_ms) {
  return WaitForFile(path, timeout_ms, [&] { return ReadFile(path).find(text) != std::string::npos; });
}

}  // namespace hapco::service
