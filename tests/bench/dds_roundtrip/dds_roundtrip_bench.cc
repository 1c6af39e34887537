// Pose -> force round trip over Cyclone DDS on loopback, two processes (fork), with the
// HapCo QoS (best effort, KEEP_LAST 1, latency_budget 0) and per-client force partition.
// The "server" echoes each pose from a data-available listener (platform-notes.md: ~30 us
// faster than a waitset); the client waits on a waitset. Prints p50/p99/max of the round
// trip for an unpaced run and a 1 kHz paced run. Compare: `ddsperf ping` / `ddsperf pong`
// (it prints half the round trip). Usage: dds_roundtrip_bench [UNPACED_N [PACED_N]]
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "service/config.h"
#include "service/dds.h"

namespace hs = hapco::service;

namespace {

constexpr const char* kClient = "bench-client";

int64_t NowNs() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

int RunServer(dds_domainid_t domain, int stop_fd) {
  hs::Participant p(domain);
  hs::Topic<hapco_idl_DevicePose> pose_topic(p);
  hs::Topic<hapco_idl_FeedbackForce> force_topic(p);
  hs::Subscriber sub(p);
  hs::Publisher pub(p, hs::ClientPartition(kClient));
  hs::Reader<hapco_idl_DevicePose> poses(sub, pose_topic);
  hs::Writer<hapco_idl_FeedbackForce> forces(pub, force_topic);
  poses.SetOnDataAvailable([&] {
    hapco_idl_DevicePose pose{};
    while (poses.Take(&pose)) {
      hapco_idl_FeedbackForce f{};
      std::memcpy(f.client_id, pose.client_id, sizeof(f.client_id));
      f.pose_sequence = pose.sequence_number;
      f.client_time_ns = pose.client_time_ns;
      f.server_receive_ns = NowNs();
      f.force_n = {1.0, 2.0, 3.0};
      f.server_send_ns = NowNs();
      forces.Write(f);
    }
  });
  char c;
  const ssize_t r = read(stop_fd, &c, 1);  // block until the client closes the pipe
  (void)r;
  return 0;
}

struct Stats {
  double p50_us, p99_us, max_us;
  int lost;
};

Stats Run(hs::Writer<hapco_idl_DevicePose>& poses, hs::Reader<hapco_idl_FeedbackForce>& forces,
          int n, bool paced, uint64_t* sequence) {
  std::vector<double> rtt_us;
  rtt_us.reserve(static_cast<size_t>(n));
  int lost = 0;
  timespec next;
  clock_gettime(CLOCK_MONOTONIC, &next);
  for (int i = 0; i < n; ++i) {
    if (paced) {  // 1 kHz servo tick at absolute times (pacing, not synchronisation)
      next.tv_nsec += 1'000'000;
      if (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
    hapco_idl_DevicePose pose{};
    hs::SetClientId(pose.client_id, kClient);
    pose.sequence_number = ++*sequence;
    pose.client_time_ns = NowNs();
    poses.Write(pose);
    bool got = false;
    // Wait at most 5 ms for this pose's force; older forces are discarded.
    const int64_t deadline = pose.client_time_ns + 5'000'000;
    while (!got && NowNs() < deadline) {
      if (!forces.WaitForData(deadline - NowNs())) break;
      hapco_idl_FeedbackForce f{};
      while (forces.Take(&f)) {
        if (f.pose_sequence == pose.sequence_number) {
          rtt_us.push_back(static_cast<double>(NowNs() - f.client_time_ns) * 1e-3);
          got = true;
        }
      }
    }
    if (!got) ++lost;
  }
  std::sort(rtt_us.begin(), rtt_us.end());
  if (rtt_us.empty()) return {0, 0, 0, lost};
  auto at = [&](double q) { return rtt_us[static_cast<size_t>(q * static_cast<double>(rtt_us.size() - 1))]; };
  return {at(0.5), at(0.99), rtt_us.back(), lost};
}

struct Options {
  int unpaced_n = 3000;
  int paced_n = 2000;
};

constexpr const char* kDescription =
    R"(Pose -> force round trip over Cyclone DDS on loopback between two processes (fork), with HapCo's QoS (best effort, KEEP_LAST 1, latency_budget 0) and per-client force partition: the "server" echoes each pose from a data-available listener, the client waits on a waitset. Prints p50/p99/max of the round trip and the lost poses (no force within 5 ms) for an unpaced run and a 1 kHz paced run; compare with ddsperf ping/pong (it prints half the round trip). Uses its own DDS domain on the loopback configuration. Prints numbers, never asserts.)";

constexpr const char* kFooter = "Exit code: 0 when the benchmark ran, 1 on bad input or when discovery failed.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("dds_roundtrip_bench", "[UNPACED_N [PACED_N]]", kDescription, kFooter);
  command.AddInteger("UNPACED_N", &o->unpaced_n, "", "round trips of the unpaced run, back to back (default 3000)",
                     "Arguments", 1, 10000000);
  command.AddInteger("PACED_N", &o->paced_n, "", "round trips of the 1 kHz paced run (default 2000)", "Arguments",
                     1, 10000000);
  return command.Parse(argc, argv);
}

int RunBenchmark(const Options& options) {
  const int unpaced_n = options.unpaced_n;
  const int paced_n = options.paced_n;
  hs::UseLoopbackConfig();
  const dds_domainid_t domain = hs::DomainIdForName("dds_roundtrip_bench");
  int fds[2];
  if (pipe(fds) != 0) return 1;
  const pid_t child = fork();  // before any DDS entity exists in this process
  if (child == 0) {
    close(fds[1]);
    _exit(RunServer(domain, fds[0]));
  }
  close(fds[0]);
  int rc = 0;
  try {
    hs::Participant p(domain);
    hs::Topic<hapco_idl_DevicePose> pose_topic(p);
    hs::Topic<hapco_idl_FeedbackForce> force_topic(p);
    hs::Publisher pub(p);
    hs::Subscriber sub(p, hs::ClientPartition(kClient));
    hs::Writer<hapco_idl_DevicePose> poses(pub, pose_topic);
    hs::Reader<hapco_idl_FeedbackForce> forces(sub, force_topic);
    if (!poses.WaitForReaders(1, DDS_SECS(10)) || !forces.WaitForWriters(1, DDS_SECS(10))) {
      std::fprintf(stderr, "dds_roundtrip_bench: discovery failed\n");
      rc = 1;
    } else {
      uint64_t sequence = 0;
      Run(poses, forces, 200, false, &sequence);  // warm-up
      std::printf("pose->force round trip, 2 processes, loopback, listener echo, waitset client\n");
      std::printf("%-16s %8s %10s %10s %10s %6s\n", "mode", "n", "p50_us", "p99_us", "max_us", "lost");
      const Stats u = Run(poses, forces, unpaced_n, false, &sequence);
      std::printf("%-16s %8d %10.1f %10.1f %10.1f %6d\n", "unpaced", unpaced_n, u.p50_us, u.p99_us,
                  u.max_us, u.lost);
      const Stats k = Run(poses, forces, paced_n, true, &sequence);
      std::printf("%-16s %8d %10.1f %10.1f %10.1f %6d\n", "paced_1kHz", paced_n, k.p50_us, k.p99_us,
                  k.max_us, k.lost);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "dds_roundtrip_bench: %s\n", e.what());
    rc = 1;
  }
  close(fds[1]);  // stops the server
  int status = 0;
  waitpid(child, &status, 0);
  return rc;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("dds_roundtrip_bench", [&] {
    Options options;
    return Parse(argc, argv, &options) ? RunBenchmark(options) : 0;
  });
}
