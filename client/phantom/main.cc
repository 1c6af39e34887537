// hapco-phantom: a simulated haptic device. 1 kHz absolute-time servo tick: device position
// (the scene's trajectory, or a hand dragging the device along it) -> quantised pose ->
// DDS -> newest force (never waiting) -> safety filter -> "motors". Counts missed ticks,
// stale-force ticks and the round trip of each force (client time echoed by the server).
// The device model is hapco_phantom_lib (phantom.h); DDS via hapco::service.
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/cli.h"
#include "common/error.h"
#include "common/realtime.h"
#include "io/scene_file.h"
#include "phantom.h"
#include "service/dds.h"

namespace {

constexpr const char* kUsage = R"(usage: hapco-phantom SCENE.txtpb --client-id ID [options]

A simulated haptic device that drives a hapco-server session at 1 kHz.

  --client-id ID      session id, 1..64 of [A-Za-z0-9_.-] (required)
  --domain N          DDS domain id (default 0); configuration from CYCLONEDDS_URI
  --mode M            kinematic (default): tick k publishes exactly the trajectory's step k
                      (no quantisation, so forces compare with hapco-sim);
                      hand: a hand (spring-damper, 300 N/m, 6 N s/m) drags a 0.05 kg device
                      with 0.5 N s/m damping along the trajectory, pushed back by the rendered
                      force; positions quantised to 0.023 mm
  --trajectory T      scene (default: the scene's phases, one step per tick) or a CSV file
                      of x_m,y_m,z_m rows (one per tick; a header line is skipped)
  --duration S        run S seconds (holding the trajectory's last point after its end);
                      default: the trajectory's length
  --csv FILE          one row per tick (tick, pose sequence, position, force sequence, raw
                      force, rendered force, round trip; force sequence -1 = no new force),
                      plus a row per extra force received within the same tick
  --timeout-ms T      no new force for T ms -> the rendered force ramps to zero in 20 ms
                      (default 50); it resumes (rate limited) when forces return
  --rt-priority N     SCHED_FIFO priority 1..99 for the tick (needs CAP_SYS_NICE; default 0)
  --connect-timeout-s S  wait at most S s for the server (default 30)
  --help              this text

Safety (every tick): a NaN/Inf force is never rendered (the last good one is kept), the
magnitude is clamped to 7.9 N, the change per tick is limited to 0.25 N (250 N/s).
Exit code: 0 done, 1 bad input, 2 no server found, 3 DDS failure.
)";

struct Options {
  std::string scene_path, client_id, mode = "kinematic", trajectory = "scene", csv_path;
  int domain = 0, rt_priority = 0;
  double duration_s = 0, timeout_ms = 50, connect_timeout_s = 30;
};

Options Parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> const char* {
      if (i + 1 >= argc) throw hapco::InputError(arg + " needs a value (see --help)");
      return argv[++i];
    };
    if (arg == "--help" || arg == "-h") {
      std::fputs(kUsage, stdout);
      std::exit(0);
    } else if (arg == "--client-id") {
      o.client_id = value();
    } else if (arg == "--domain") {
      char* end = nullptr;
      const char* text = value();
      const long d = std::strtol(text, &end, 10);
      if (end == text || *end != '\0' || d < 0 || d > 230) throw hapco::InputError("--domain expects 0..230");
      o.domain = static_cast<int>(d);
    } else if (arg == "--mode") {
      o.mode = value();
      if (o.mode != "kinematic" && o.mode != "hand") throw hapco::InputError("--mode must be kinematic or hand");
    } else if (arg == "--trajectory") {
      o.trajectory = value();
    } else if (arg == "--duration") {
      o.duration_s = hapco::cli::ParsePositive("--duration", value());
    } else if (arg == "--csv") {
      o.csv_path = value();
    } else if (arg == "--timeout-ms") {
      o.timeout_ms = hapco::cli::ParsePositive("--timeout-ms", value());
    } else if (arg == "--rt-priority") {
      char* end = nullptr;
      const char* text = value();
      const long priority = std::strtol(text, &end, 10);
      if (end == text || *end != '\0' || priority < 0 || priority > 99) throw hapco::InputError("--rt-priority expects 0..99");
      o.rt_priority = static_cast<int>(priority);
    } else if (arg == "--connect-timeout-s") {
      o.connect_timeout_s = hapco::cli::ParsePositive("--connect-timeout-s", value());
    } else if (!arg.empty() && arg[0] == '-') {
      throw hapco::InputError("unknown option " + arg + " (see --help)");
    } else if (o.scene_path.empty()) {
      o.scene_path = arg;
    } else {
      throw hapco::InputError("only one scene file is accepted (see --help)");
    }
  }
  if (o.scene_path.empty()) throw hapco::InputError("missing SCENE argument (see --help)");
  if (o.client_id.empty()) throw hapco::InputError("--client-id is required (see --help)");
  hapco::service::ValidateClientId(o.client_id);
  return o;
}

// Trajectory points 0..N (point 0 = start), m.
std::vector<Eigen::Vector3d> LoadTrajectory(const Options& o, const hapco::sim::SceneSpec& scene) {
  std::vector<Eigen::Vector3d> points;
  if (o.trajectory == "scene") {
    for (int k = 0; k <= scene.total_steps(); ++k) points.push_back(scene.DeviceTranslationAtStep(k));
    return points;
  }
  std::ifstream in(o.trajectory);
  if (!in) throw hapco::InputError("cannot read trajectory " + o.trajectory);
  points.push_back(Eigen::Vector3d::Zero());
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    for (char& c : line) if (c == ',') c = ' ';
    std::istringstream fields(line);
    Eigen::Vector3d p;
    if (!(fields >> p.x() >> p.y() >> p.z()) || !p.allFinite()) {
      if (number == 1) continue;  // header
      throw hapco::InputError(o.trajectory + ":" + std::to_string(number) + ": expected x_m,y_m,z_m");
    }
    points.push_back(p);
  }
  if (points.size() < 2) throw hapco::InputError(o.trajectory + ": no trajectory rows");
  return points;
}

timespec ToTimespec(int64_t ns) {
  return timespec{static_cast<time_t>(ns / 1'000'000'000LL), static_cast<long>(ns % 1'000'000'000LL)};
}

// One CSV row: a force received in a tick (or none: sequence -1) and what was rendered.
struct Row {
  long long force_sequence = -1;
  Eigen::Vector3d raw_n = Eigen::Vector3d::Zero();
  double round_trip_us = -1;
  Eigen::Vector3d rendered_n = Eigen::Vector3d::Zero();
};

void FlushRow(std::FILE* csv, int tick, bool publishing, const Eigen::Vector3d& position, const Row& row) {
  std::fprintf(csv, "%d,%lld,%.12g,%.12g,%.12g,%lld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.1f\n", tick,
               publishing ? static_cast<long long>(tick) : -1LL, position.x(), position.y(), position.z(),
               row.force_sequence, row.raw_n.x(), row.raw_n.y(), row.raw_n.z(), row.rendered_n.x(),
               row.rendered_n.y(), row.rendered_n.z(), row.round_trip_us);
}

int Run(const Options& o) {
  using namespace hapco;
  const sim::SceneSpec scene = io::LoadSceneFile(o.scene_path);
  const std::vector<Eigen::Vector3d> trajectory = LoadTrajectory(o, scene);
  const int64_t period_ns = 1'000'000;  // 1 kHz
  const double tick_s = 1e-3;
  const int trajectory_ticks = static_cast<int>(trajectory.size()) - 1;
  const int ticks = o.duration_s > 0 ? static_cast<int>(std::lround(o.duration_s / tick_s)) : trajectory_ticks;

  std::FILE* csv = nullptr;
  if (!o.csv_path.empty()) {
    csv = std::fopen(o.csv_path.c_str(), "w");
    if (csv == nullptr) throw InputError("cannot write " + o.csv_path);
    std::fprintf(csv, "tick,sequence,x_m,y_m,z_m,force_sequence,raw_fx_n,raw_fy_n,raw_fz_n,"
                      "fx_n,fy_n,fz_n,round_trip_us\n");
  }

  hapco::UseRealtimePriority(o.rt_priority, "hapco-phantom");
  service::Participant participant(o.domain);
  service::Topic<hapco_idl_DevicePose> pose_topic(participant);
  service::Topic<hapco_idl_FeedbackForce> force_topic(participant);
  service::Topic<hapco_idl_SessionControl> session_topic(participant);
  service::Publisher publisher(participant);
  service::Subscriber subscriber(participant, service::ClientPartition(o.client_id));
  service::Writer<hapco_idl_DevicePose> pose_writer(publisher, pose_topic);
  service::Writer<hapco_idl_SessionControl> session_writer(publisher, session_topic);
  // Reader history 8 (the writer keeps 1; history is not request/offered): when two forces
  // arrive within one tick the newest is rendered and the older one is still logged and
  // timed instead of being overwritten unseen.
  service::Reader<hapco_idl_FeedbackForce> force_reader(subscriber, force_topic,
                                                        service::ForceQos().KeepLast(8));

  // Connect: the server's pose reader and session reader discovered, then SESSION_JOIN, and
  // wait until the server's force writer for this client matches our reader, so that the
  // first pose already gets its force back (bounded waits, no sleeps).
  const auto connect_ns = static_cast<dds_duration_t>(o.connect_timeout_s * 1e9);
  if (!pose_writer.WaitForReaders(1, connect_ns) || !session_writer.WaitForReaders(1, connect_ns)) {
    std::fprintf(stderr, "hapco-phantom: no hapco-server found in domain %d within %.0f s\n", o.domain, o.connect_timeout_s);
    return 2;
  }
  auto control = service::MakeSample<hapco_idl_SessionControl>();
  service::SetClientId(control->client_id, o.client_id);
  control->command = hapco_idl_SESSION_JOIN;
  std::snprintf(control->scene_name, sizeof(control->scene_name), "%s", scene.name.c_str());
  service::CheckReturn(session_writer.Write(*control), "SESSION_JOIN");
  if (!force_reader.WaitForWriters(1, connect_ns)) {
    std::fprintf(stderr, "hapco-phantom: the server did not open a session for '%s' within %.0f s\n",
                 o.client_id.c_str(), o.connect_timeout_s);
    return 2;
  }

  phantom::SafetyParameters safety_parameters;
  safety_parameters.timeout_s = o.timeout_ms * 1e-3;
  safety_parameters.tick_s = tick_s;
  phantom::SafetyFilter safety(safety_parameters);
  phantom::HandModel hand({}, trajectory[0]);

  hapco_idl_DevicePose pose{};
  service::SetClientId(pose.client_id, o.client_id);
  pose.orientation = {1.0, 0.0, 0.0, 0.0};
  hapco_idl_FeedbackForce force{};
  // Round trip: pose sampled -> its force taken at a tick (so it includes the wait for the
  // tick that renders it). server_us: server receive -> send (step + publish).
  std::vector<double> round_trips_us, server_us;
  round_trips_us.reserve(static_cast<std::size_t>(ticks) + 64);
  server_us.reserve(static_cast<std::size_t>(ticks) + 64);
  uint64_t missed_ticks = 0, forces_received = 0, write_errors = 0;
  double peak_rendered_n = 0;
  uint64_t last_force_sequence = 0;
  const int64_t start_ns = hapco::MonotonicNowNs();
  int64_t deadline_ns = start_ns + period_ns;
  Eigen::Vector3d rendered = Eigen::Vector3d::Zero();
  Row pending_row;
  // After the last pose, a few more ticks (without poses) collect the last forces.
  const int drain_ticks = static_cast<int>(std::lround(o.timeout_ms));
  int drained = 0;
  for (int tick = 1;; ++tick) {
    const bool publishing = tick <= ticks;
    if (!publishing) {
      if (last_force_sequence >= static_cast<uint64_t>(ticks) || drained >= drain_ticks) break;
      ++drained;
    }
    const timespec wake = ToTimespec(deadline_ns);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr) != 0) {
    }
    const int64_t now = hapco::MonotonicNowNs();
    if (now - deadline_ns > period_ns) {
      // Overrun: count the ticks that never ran and realign to the grid (no burst of poses).
      const int64_t late = (now - deadline_ns) / period_ns;
      missed_ticks += static_cast<uint64_t>(late);
      deadline_ns += late * period_ns;
    }
    deadline_ns += period_ns;
    const double now_s = static_cast<double>(now - start_ns) * 1e-9;

    Eigen::Vector3d position = trajectory.back();
    if (publishing) {
      const int k = std::min(tick, trajectory_ticks);
      if (o.mode == "kinematic") {
        position = trajectory[static_cast<std::size_t>(k)];
      } else {
        // The hand's target velocity: the trajectory's, zero once it holds its last point.
        const int previous = tick > trajectory_ticks ? k : std::max(0, k - 1);
        const Eigen::Vector3d velocity =
            (trajectory[static_cast<std::size_t>(k)] - trajectory[static_cast<std::size_t>(previous)]) / tick_s;
        position = phantom::Quantize(hand.Step(trajectory[static_cast<std::size_t>(k)], velocity, rendered, tick_s));
      }
      pose.sequence_number = static_cast<uint64_t>(tick);
      pose.client_time_ns = hapco::MonotonicNowNs();
      pose.position_m = {position.x(), position.y(), position.z()};
      if (pose_writer.Write(pose) != DDS_RETCODE_OK) ++write_errors;
    }
    // Every force that arrived since the last tick, never waiting; the newest is rendered.
    int taken = 0;
    bool fresh = false;
    Eigen::Vector3d raw = Eigen::Vector3d::Constant(std::nan(""));
    while (force_reader.Take(&force)) {
      if (forces_received > 0 && force.pose_sequence <= last_force_sequence) continue;  // reordered
      ++forces_received;
      fresh = true;
      last_force_sequence = force.pose_sequence;
      raw = Eigen::Vector3d(force.force_n.x, force.force_n.y, force.force_n.z);
      const double round_trip_us = static_cast<double>(hapco::MonotonicNowNs() - force.client_time_ns) * 1e-3;
      round_trips_us.push_back(round_trip_us);
      server_us.push_back(static_cast<double>(force.server_send_ns - force.server_receive_ns) * 1e-3);
      if (csv != nullptr && taken++ > 0) FlushRow(csv, tick, publishing, position, pending_row);
      pending_row = {static_cast<long long>(force.pose_sequence), raw, round_trip_us, rendered};
    }
    rendered = safety.Update(fresh, raw, now_s);
    peak_rendered_n = std::max(peak_rendered_n, rendered.norm());
    if (csv != nullptr) {
      if (!fresh) pending_row = {-1, raw, -1.0};
      pending_row.rendered_n = rendered;
      FlushRow(csv, tick, publishing, position, pending_row);
    }
  }
  control->command = hapco_idl_SESSION_LEAVE;
  session_writer.Write(*control);
  session_writer.WaitForAcks(DDS_MSECS(500));
  if (csv != nullptr) std::fclose(csv);

  std::vector<double> rt = round_trips_us;
  std::printf("hapco-phantom %s: %d ticks, %llu forces received; round trip (to the rendering tick) "
              "p50 %.0f us, p99 %.0f us, max %.0f us; server step+publish p50 %.0f us, p99 %.0f us, "
              "max %.0f us; missed ticks %llu, stale ticks %llu, NaN forces %llu, clamped %llu, "
              "peak rendered force %.3f N, pose write errors %llu\n",
              o.client_id.c_str(), ticks, static_cast<unsigned long long>(forces_received),
              phantom::Quantile(&rt, 0.5), phantom::Quantile(&rt, 0.99), phantom::Quantile(&rt, 1.0),
              phantom::Quantile(&server_us, 0.5), phantom::Quantile(&server_us, 0.99),
              phantom::Quantile(&server_us, 1.0),
              static_cast<unsigned long long>(missed_ticks), static_cast<unsigned long long>(safety.stale_ticks()),
              static_cast<unsigned long long>(safety.rejected_non_finite()),
              static_cast<unsigned long long>(safety.clamped()), peak_rendered_n,
              static_cast<unsigned long long>(write_errors));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-phantom", [&] { return Run(Parse(argc, argv)); });
}
