#pragma once
// Helpers for the DDS integration tests: per-test domain + loopback config, a forked peer
// process (real UDP over loopback instead of Cyclone's in-process delivery), deterministic
// sample contents.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <functional>
#include <string>

#include "service/config.h"
#include "service/dds.h"
#include "../test_domain.h"

namespace hapco::service::testing {

// Generous: discovery on loopback takes milliseconds, but the machine is shared.
inline constexpr dds_duration_t kDiscoveryTimeoutNs = DDS_SECS(10);
inline constexpr dds_duration_t kDataTimeoutNs = DDS_SECS(10);

// Each test gets its own domain (from its full name, reserved: ../test_domain.h) and the loopback config. Must run
// before the first participant of the process exists (ctest runs one test per process).
inline dds_domainid_t SetUpTestDomain() {
  UseLoopbackConfig();
  const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
  return ReserveTestDomain(std::string(info->test_suite_name()) + "." + info->name());  // ../test_domain.h
}

// A child process running `body` (its return value is the exit code). Fork before the parent
// creates any DDS entity: the child must not inherit Cyclone's threads half-initialised.
// Pipes: parent->child `to_child`, child->parent `to_parent` (one uint64 per message).
class ChildProcess {
 public:
  explicit ChildProcess(const std::function<int(ChildProcess&)>& body) {
    int a[2];
    int b[2];
    if (pipe(a) != 0 || pipe(b) != 0) throw std::runtime_error("pipe failed");
    pid_ = fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      in_fd_ = a[0];
      out_fd_ = b[1];
      close(a[1]);
      close(b[0]);
      int code = 90;
      try {
        code = body(*this);
      } catch (const std::exception& e) {
        fprintf(stderr, "child: %s\n", e.what());
        code = 91;
      }
      fflush(stderr);
      _exit(code);
    }
    in_fd_ = b[0];
    out_fd_ = a[1];
    close(a[0]);
    close(b[1]);
  }
  ~ChildProcess() {
    if (pid_ > 0 && !joined_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(in_fd_);
    close(out_fd_);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  // Freeze / resume the child (a hung peer: it neither reads nor acknowledges).
  void Stop() { kill(pid_, SIGSTOP); }
  void Continue() { kill(pid_, SIGCONT); }

  void Send(uint64_t value) {
    if (write(out_fd_, &value, sizeof(value)) != static_cast<ssize_t>(sizeof(value))) {
      throw std::runtime_error("pipe write failed");
    }
  }
  // Waits for one value for at most timeout_ms; false on timeout or closed pipe.
  bool Receive(uint64_t* value, int timeout_ms) {
    pollfd p{in_fd_, POLLIN, 0};
    if (poll(&p, 1, timeout_ms) != 1) return false;
    return read(in_fd_, value, sizeof(*value)) == static_cast<ssize_t>(sizeof(*value));
  }
  // Exit code of the child, or -1 if it did not exit within timeout_ms (it is then killed).
  int Join(int timeout_ms) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    int status = 0;
    for (;;) {
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) break;
      if (std::chrono::steady_clock::now() > deadline) return -1;  // destructor kills it
      // Bounded polling on the child's exit: block on the pipe, which closes when it exits.
      pollfd p{in_fd_, POLLIN, 0};
      poll(&p, 1, 10);
    }
    joined_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  pid_t pid_ = -1;
  int in_fd_ = -1;
  int out_fd_ = -1;
  bool joined_ = false;
};

inline int64_t MonotonicNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Deterministic, distinct contents of contact sample i of frame `step` (exactly representable
// doubles so equality is exact after the round trip).
inline void FillContact(uint64_t step, uint32_t i, hapco_idl_ContactSample* c) {
  const double s = static_cast<double>(step);
  const double k = static_cast<double>(i);
  c->id = i;
  c->position_m = {k * 0.25, -k * 0.5, s + 0.125};
  c->normal = {0.0, 0.0, 1.0};
  c->force_n = {k * 1.5, k * -2.0, s * 0.75};
  c->gap_m = k * 0.0625;
  c->slip_m = s * 0.03125;
  c->state = static_cast<hapco_idl_ContactState>(i % 3);
}

inline bool SameContact(const hapco_idl_ContactSample& a, const hapco_idl_ContactSample& b) {
  return a.id == b.id && a.position_m.x == b.position_m.x && a.position_m.y == b.position_m.y &&
         a.position_m.z == b.position_m.z && a.normal.z == b.normal.z && a.force_n.x == b.force_n.x &&
         a.force_n.y == b.force_n.y && a.force_n.z == b.force_n.z && a.gap_m == b.gap_m &&
         a.slip_m == b.slip_m && a.state == b.state;
}

}  // namespace hapco::service::testing
