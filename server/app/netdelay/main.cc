// hapco-netdelay: holds every packet of one NFQUEUE for delay ± jitter, drops a random share,
// then accepts it - the fallback of scripts/netlab where the kernel has no sch_netem
// (platform-notes.md, "Network impairment"; docs/network-lab.md).
//
// One thread, one poll loop (netlink socket, timerfd, signalfd): the netlink socket is
// non-blocking and drained in bounded batches; held packets sit in a min-heap keyed by their
// release time; the timerfd is armed at the earliest release time as an absolute
// CLOCK_MONOTONIC deadline, so every packet's release is computed from its own arrival and
// nothing accumulates (no drift at any rate). Verdicts are sent from the same thread, so no
// locking is needed and nothing ever blocks on the socket.
#include <arpa/inet.h>
#include <fcntl.h>
#include <libnetfilter_queue/libnetfilter_queue.h>
#include <linux/netfilter.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <queue>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/realtime.h"

namespace {

constexpr const char* kDescription =
    R"(Binds NFQUEUE queue N of the current network namespace, holds every queued packet for delay + jitter (sampled per packet, seeded), drops --loss-pct of them at random, and accepts the rest when their time is up. Route packets to it with e.g.
  iptables -A OUTPUT -o IFACE -j NFQUEUE --queue-num N
(scripts/netlab does this in its namespaces; docs/network-lab.md).)";

constexpr const char* kFooter =
    R"(Prints "hapco-netdelay: ready" on stderr once the queue is bound. SIGINT/SIGTERM: accepts every held packet at once, prints a summary (packets, dropped, added delay measured from receipt to verdict: mean/max, release lateness, kernel-side drops) and exits 0.
Exit code: 0 after a clean shutdown, 1 on bad flags, 3 if the queue cannot be bound (not root / CAP_NET_ADMIN, or another process holds queue N).)";

struct Options {
  int queue_num = 0;
  double delay_ms = 0.0, jitter_ms = 0.0, loss_pct = 0.0, stats_period_s = 0.0;
  bool normal = false, fifo = false, quiet = false;
  std::uint64_t seed = 1;
  unsigned max_held = 100000;
  int rt_priority = 0;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco-netdelay", "[options]", kDescription, kFooter);
  command.AddInteger("--queue-num", &o->queue_num, "N", "NFQUEUE number, 0..65535 (default 0)", "Queue", 0, 65535);
  int max_held = static_cast<int>(o->max_held);
  command.AddInteger("--max-held", &max_held, "N",
                     "kernel queue length, 1..10000000 (default 100000); beyond it the kernel drops", "Queue", 1,
                     10000000);
  command.AddNumber("--delay-ms", &o->delay_ms, "D", "mean added delay per packet, ms, 0..10000 (default 0)",
                    "Impairment", 0, 10000);
  command.AddNumber("--jitter-ms", &o->jitter_ms, "J",
                    "jitter, ms, 0..10000 (default 0): uniform in [D-J, D+J], or normal with standard deviation J "
                    "(--jitter-dist normal); a negative sampled delay counts as 0",
                    "Impairment", 0, 10000);
  std::string jitter_dist = "uniform";
  command.AddChoice("--jitter-dist", &jitter_dist, {"uniform", "normal"},
                    "uniform (default, like netem without a distribution table) or normal", "Impairment");
  command.AddFlag("--fifo", &o->fifo,
                  "keep packet order: a packet never leaves before an earlier one (its release time is max(own "
                  "sample, previous release)). Default: packets are released at their own sampled time, so "
                  "jitter reorders them, as netem does",
                  "Impairment");
  command.AddNumber("--loss-pct", &o->loss_pct, "P", "drop P % of the packets at random, 0..100 (default 0)",
                    "Impairment", 0, 100);
  // 64-bit: beyond AddInteger's int, same message.
  constexpr long kMaxSeed = 0x7fffffffffffffffL;
  std::string seed_text = "1";
  command.AddText("--seed", &seed_text, "S", "random seed, 0..2^63-1 (default 1)", "Impairment")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            char* end = nullptr;
            errno = 0;
            const long long seed = std::strtoll(text.c_str(), &end, 10);
            if (text.empty() || *end != '\0' || errno == ERANGE || seed < 0) {
              throw hapco::InputError("--seed expects an integer in [0, " + std::to_string(kMaxSeed) + "], got '" +
                                      text + "'");
            }
            return "";
          },
          ""));
  command.AddNumber("--stats-period-s", &o->stats_period_s, "S",
                    "print a stats line every S seconds (default 0 = only the summary at exit)",
                    hapco::cli::kGroupOutput, 0, HUGE_VAL);
  // The shared definition (name, range, group); its help mentions DDS, which netdelay has none of.
  command.AddRtPriority(&o->rt_priority, "the release loop")
      ->description("run the release loop with SCHED_FIFO priority N, for tighter release times (1..99; needs "
                    "CAP_SYS_NICE; default 0 = normal policy)");
  command.AddQuiet(&o->quiet, "no start line (\"ready\" and the summary are still printed)");
  command.Deprecate("--stats-period", "--stats-period-s");
  if (!command.Parse(argc, argv)) return false;

  o->max_held = static_cast<unsigned>(max_held);
  o->normal = jitter_dist == "normal";
  o->seed = std::stoull(seed_text);
  return true;
}

struct Held {
  std::int64_t release_ns;
  std::uint64_t order;  // tie-break: equal release times leave in arrival order
  std::int64_t arrival_ns;
  std::uint32_t id;
  bool operator>(const Held& other) const {
    return release_ns != other.release_ns ? release_ns > other.release_ns : order > other.order;
  }
};

// Running statistics of one quantity, ns.
struct Stat {
  std::uint64_t count = 0;
  double sum_ns = 0.0;
  std::int64_t max_ns = 0;
  void Add(std::int64_t ns) {
    ++count;
    sum_ns += static_cast<double>(ns);
    max_ns = std::max(max_ns, ns);
  }
  double MeanMs() const { return count ? sum_ns / static_cast<double>(count) * 1e-6 : 0.0; }
  double MaxMs() const { return static_cast<double>(max_ns) * 1e-6; }
};

struct State {
  Options options;
  nfq_q_handle* queue = nullptr;
  std::mt19937_64 rng;
  std::uniform_real_distribution<double> uniform{0.0, 1.0};
  std::normal_distribution<double> normal{0.0, 1.0};
  std::priority_queue<Held, std::vector<Held>, std::greater<>> held;
  std::int64_t recv_time_ns = 0;      // time the current netlink batch was received
  std::int64_t last_release_ns = 0;   // for --fifo
  std::uint64_t next_order = 0, last_released_order = 0;
  std::uint64_t packets = 0, dropped = 0, accepted = 0, flushed = 0, reordered = 0, verdict_errors = 0;
  std::uint64_t netlink_overruns = 0;
  std::size_t peak_held = 0;
  Stat added, lateness;                // receipt -> verdict; release time -> verdict
  Stat interval_added;                 // for --stats-period-s
  std::uint64_t interval_packets = 0;
};

std::int64_t SampleDelayNs(State& s) {
  const Options& o = s.options;
  double delay_ms = o.delay_ms;
  if (o.jitter_ms > 0.0) {
    delay_ms += o.normal ? o.jitter_ms * s.normal(s.rng) : o.jitter_ms * (2.0 * s.uniform(s.rng) - 1.0);
  }
  return static_cast<std::int64_t>(std::llround(std::max(delay_ms, 0.0) * 1e6));
}

int OnPacket(nfq_q_handle* queue, nfgenmsg* /*message*/, nfq_data* data, void* user) {
  auto& s = *static_cast<State*>(user);
  const nfqnl_msg_packet_hdr* header = nfq_get_msg_packet_hdr(data);
  if (header == nullptr) return 0;
  const std::uint32_t id = ntohl(header->packet_id);
  ++s.packets;
  ++s.interval_packets;
  // The loss draw comes first and always, so a seed gives the same drop pattern at any delay.
  const double draw = s.uniform(s.rng);
  if (s.options.loss_pct > 0.0 && draw * 100.0 < s.options.loss_pct) {
    if (nfq_set_verdict(queue, id, NF_DROP, 0, nullptr) < 0) ++s.verdict_errors;
    ++s.dropped;
    return 0;
  }
  std::int64_t release = s.recv_time_ns + SampleDelayNs(s);
  if (s.options.fifo) release = std::max(release, s.last_release_ns);
  s.last_release_ns = std::max(s.last_release_ns, release);
  s.held.push(Held{release, ++s.next_order, s.recv_time_ns, id});
  s.peak_held = std::max(s.peak_held, s.held.size());
  return 0;
}

void Accept(State& s, const Held& h, std::int64_t now_ns, bool flush) {
  if (nfq_set_verdict(s.queue, h.id, NF_ACCEPT, 0, nullptr) < 0) ++s.verdict_errors;
  ++s.accepted;
  if (h.order < s.last_released_order) ++s.reordered;
  s.last_released_order = std::max(s.last_released_order, h.order);
  if (flush) {
    ++s.flushed;
    return;
  }
  s.added.Add(now_ns - h.arrival_ns);
  s.interval_added.Add(now_ns - h.arrival_ns);
  s.lateness.Add(std::max<std::int64_t>(now_ns - h.release_ns, 0));
}

void ArmTimer(int timer_fd, const State& s) {
  itimerspec spec{};
  if (!s.held.empty()) {
    const std::int64_t t = std::max<std::int64_t>(s.held.top().release_ns, 1);  // 0 would disarm
    spec.it_value.tv_sec = t / 1'000'000'000;
    spec.it_value.tv_nsec = t % 1'000'000'000;
  }
  timerfd_settime(timer_fd, TFD_TIMER_ABSTIME, &spec, nullptr);
}

// queue_dropped (queue full) and user_dropped (netlink buffer full) of queue N, from
// /proc/net/netfilter/nfnetlink_queue; -1 if not readable.
std::pair<long, long> KernelDrops(int queue_num) {
  std::ifstream in("/proc/net/netfilter/nfnetlink_queue");
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    long queue = -1, portid = 0, total = 0, mode = 0, range = 0, queue_dropped = 0, user_dropped = 0;
    if (fields >> queue >> portid >> total >> mode >> range >> queue_dropped >> user_dropped && queue == queue_num) {
      return {queue_dropped, user_dropped};
    }
  }
  return {-1, -1};
}

int Run(const Options& o) {
  // Releases are timerfd deadlines: the default 50 us timer slack would add to every one.
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  hapco::UseRealtimePriority(o.rt_priority, "hapco-netdelay");

  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  sigprocmask(SIG_BLOCK, &signals, nullptr);
  const int signal_fd = signalfd(-1, &signals, SFD_NONBLOCK | SFD_CLOEXEC);
  const int timer_fd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
  HAPCO_ASSERT(signal_fd >= 0 && timer_fd >= 0, "signalfd/timerfd failed");

  State s;
  s.options = o;
  s.rng.seed(o.seed);

  nfq_handle* handle = nfq_open();
  if (handle == nullptr) {
    std::fprintf(stderr, "hapco-netdelay: nfq_open failed: %s (needs root / CAP_NET_ADMIN)\n", std::strerror(errno));
    return 3;
  }
  s.queue = nfq_create_queue(handle, static_cast<std::uint16_t>(o.queue_num), &OnPacket, &s);
  if (s.queue == nullptr) {
    std::fprintf(stderr, "hapco-netdelay: cannot bind NFQUEUE %d: %s (not root, or another process holds it)\n",
                 o.queue_num, std::strerror(errno));
    nfq_close(handle);
    return 3;
  }
  // Only metadata (the packet id): the payload is not needed to delay a packet.
  if (nfq_set_mode(s.queue, NFQNL_COPY_META, 0) < 0) nfq_set_mode(s.queue, NFQNL_COPY_PACKET, 0);
  nfq_set_queue_maxlen(s.queue, o.max_held);
  // GSO super-packets are queued whole (one verdict) instead of being segmented first.
  nfq_set_queue_flags(s.queue, NFQA_CFG_F_GSO, NFQA_CFG_F_GSO);
  nfnl_rcvbufsiz(nfq_nfnlh(handle), 8u << 20);
  const int netlink_fd = nfq_fd(handle);
  fcntl(netlink_fd, F_SETFL, fcntl(netlink_fd, F_GETFL) | O_NONBLOCK);

  if (!o.quiet) {
    std::fprintf(stderr, "hapco-netdelay: queue %d, delay %.3f ms, jitter %.3f ms (%s, %s), loss %.3f %%, seed %llu\n",
                 o.queue_num, o.delay_ms, o.jitter_ms, o.normal ? "normal" : "uniform",
                 o.fifo ? "fifo" : "may reorder", o.loss_pct, static_cast<unsigned long long>(o.seed));
  }
  std::fprintf(stderr, "hapco-netdelay: ready\n");
  std::fflush(stderr);

  const std::int64_t start_ns = hapco::MonotonicNowNs();
  const std::int64_t stats_period_ns = static_cast<std::int64_t>(o.stats_period_s * 1e9);
  std::int64_t next_stats_ns = start_ns + stats_period_ns;
  alignas(8) static char buffer[1 << 16];
  bool running = true;
  while (running) {
    pollfd fds[3] = {{netlink_fd, POLLIN, 0}, {timer_fd, POLLIN, 0}, {signal_fd, POLLIN, 0}};
    int timeout_ms = -1;
    if (stats_period_ns > 0) {
      timeout_ms = static_cast<int>(std::max<std::int64_t>((next_stats_ns - hapco::MonotonicNowNs()) / 1'000'000 + 1, 0));
    }
    if (poll(fds, 3, timeout_ms) < 0 && errno != EINTR) {
      std::fprintf(stderr, "hapco-netdelay: poll: %s\n", std::strerror(errno));
      break;
    }
    if (fds[2].revents & POLLIN) running = false;
    if (fds[1].revents & POLLIN) {
      std::uint64_t expirations = 0;
      [[maybe_unused]] const ssize_t r = read(timer_fd, &expirations, sizeof expirations);
    }
    if (fds[0].revents & POLLIN) {
      // Bounded batch so releases are not starved by a flood of arrivals.
      for (int batch = 0; batch < 256; ++batch) {
        const ssize_t n = recv(netlink_fd, buffer, sizeof buffer, MSG_DONTWAIT);
        if (n < 0) {
          if (errno == ENOBUFS) {  // the kernel could not deliver (and dropped) some packets
            ++s.netlink_overruns;
            continue;
          }
          break;  // EAGAIN: drained
        }
        s.recv_time_ns = hapco::MonotonicNowNs();
        nfq_handle_packet(handle, buffer, static_cast<int>(n));
      }
    }
    const std::int64_t now = hapco::MonotonicNowNs();
    while (!s.held.empty() && s.held.top().release_ns <= now) {
      Accept(s, s.held.top(), now, false);
      s.held.pop();
    }
    ArmTimer(timer_fd, s);
    if (stats_period_ns > 0 && now >= next_stats_ns) {
      std::fprintf(stderr, "hapco-netdelay: t %.1f s: %llu pkt/s, added delay mean %.3f ms max %.3f ms, held %zu\n",
                   static_cast<double>(now - start_ns) * 1e-9,
                   static_cast<unsigned long long>(static_cast<double>(s.interval_packets) / o.stats_period_s),
                   s.interval_added.MeanMs(), s.interval_added.MaxMs(), s.held.size());
      s.interval_added = Stat{};
      s.interval_packets = 0;
      next_stats_ns += stats_period_ns * ((now - next_stats_ns) / stats_period_ns + 1);
    }
  }
  // Shutdown: release everything still held (not counted in the delay statistics).
  const std::int64_t end_ns = hapco::MonotonicNowNs();
  while (!s.held.empty()) {
    Accept(s, s.held.top(), end_ns, true);
    s.held.pop();
  }
  const auto [queue_dropped, user_dropped] = KernelDrops(o.queue_num);
  nfq_destroy_queue(s.queue);
  nfq_close(handle);

  const double seconds = static_cast<double>(end_ns - start_ns) * 1e-9;
  std::fprintf(stderr,
               "hapco-netdelay: summary: queue %d, %.1f s, %llu packets (%.0f pkt/s), %llu dropped (%.3f %%), "
               "%llu accepted (%llu flushed at exit), added delay mean %.3f ms max %.3f ms (target %.3f ms +- %.3f), "
               "release lateness mean %.3f ms max %.3f ms, reordered %llu, peak held %zu, kernel queue drops %ld, "
               "netlink drops %ld, overruns %llu, verdict errors %llu\n",
               o.queue_num, seconds, static_cast<unsigned long long>(s.packets),
               seconds > 0 ? static_cast<double>(s.packets) / seconds : 0.0, static_cast<unsigned long long>(s.dropped),
               s.packets ? 100.0 * static_cast<double>(s.dropped) / static_cast<double>(s.packets) : 0.0,
               static_cast<unsigned long long>(s.accepted), static_cast<unsigned long long>(s.flushed), s.added.MeanMs(),
               s.added.MaxMs(), o.delay_ms, o.jitter_ms, s.lateness.MeanMs(), s.lateness.MaxMs(),
               static_cast<unsigned long long>(s.reordered), s.peak_held, queue_dropped, user_dropped,
               static_cast<unsigned long long>(s.netlink_overruns), static_cast<unsigned long long>(s.verdict_errors));
  close(timer_fd);
  close(signal_fd);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-netdelay", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
