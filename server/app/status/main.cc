// hapco-status: waits for a ServerStatus on "hapco/status" (transient-local, so a running
// server's last status arrives at once), prints it and exits 0; exits 1 if none arrives in
// time. The container HEALTHCHECK runs it (docker/Dockerfile, docs/container.md).
// --max-age-s also rejects a stale status (a server whose loop hangs keeps its DDS
// participant, and with it the last status, alive): the check then waits for a newer one.
#include <dds/dds.h>

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <string>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "service/dds.h"
#include "service/pose_intake.h"
#include "service/qos.h"
#include "service/server_choice.h"

namespace {

constexpr const char* kDescription =
    R"(Waits for a hapco-server's ServerStatus (topic "hapco/status", transient-local: a running server's last status arrives at once), prints it and exits 0. The container HEALTHCHECK runs it (docs/container.md).)";

constexpr const char* kFooter = "Exit code: 0 status received, 1 none in time (or bad flags), 3 DDS failure.";

struct Options {
  int domain = 0;
  double timeout_s = 5, max_age_s = 0;
  std::string server_id, security_dir;
  bool quiet = false;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco-status", "[options]", kDescription, kFooter);
  command.AddDomain(&o->domain);
  command.AddSecurity(&o->security_dir, "DIR/monitor");
  command.AddConnectTimeout(&o->timeout_s, "give up after S seconds: exit 1 (default 5)");
  command.AddNumber("--max-age-s", &o->max_age_s, "S",
                    "accept only a status published less than S seconds ago (default: any); the server publishes "
                    "one every --status-period-s (default 1 s)",
                    "Checks", 0, HUGE_VAL, true);
  command.AddText("--server-id", &o->server_id, "ID", "accept only the server with this id (default: any)",
                  "Checks");
  command.AddQuiet(&o->quiet, "print nothing on success");
  command.Deprecate("--timeout-s", "--connect-timeout-s");
  const bool parsed = command.Parse(argc, argv);
  // The rule hapco-server applies to its own id: an id it could never have is a typo.
  if (parsed && !o->server_id.empty() && !hapco::service::IsValidClientId(o->server_id)) {
    throw hapco::InputError("--server-id expects 1-64 of [A-Za-z0-9_.-], got '" + o->server_id + "'");
  }
  return parsed;
}

dds_duration_t Seconds(double s) { return static_cast<dds_duration_t>(s * 1e9); }

int Run(const Options& o) {
  namespace svc = hapco::service;
  svc::Participant participant(o.domain, svc::SecurityIdentity{o.security_dir, "monitor"});  // disabled without --security
  svc::Topic<hapco_idl_ServerStatus> topic(participant);
  svc::Subscriber subscriber(participant);
  // Transient-local: every server's newest status arrives as soon as it is matched.
  svc::Reader<hapco_idl_ServerStatus> reader(subscriber, topic, svc::StatusQos());
  auto status = svc::MakeSample<hapco_idl_ServerStatus>();

  // Several servers may share the domain (docs/several-servers.md): after the first status, the
  // others' for kOthersWindowS more (each announces itself at once when matched), one line each.
  constexpr double kOthersWindowS = 0.3;
  std::map<std::string, std::string> lines;  // server id -> its line
  std::set<std::string> others;  // servers heard that --server-id left out
  dds_time_t deadline = dds_time() + Seconds(o.timeout_s);
  for (dds_time_t now = dds_time(); now < deadline; now = dds_time()) {
    reader.WaitForData(deadline - now);
    dds_sample_info_t info;
    while (reader.Take(status.get(), &info)) {
      if (!info.valid_data) continue;
      const std::string id = svc::ServerIdOf(status->server_id);
      if (!o.server_id.empty() && o.server_id != id) {
        others.insert(id);
        continue;
      }
      // source_timestamp is the server's wall clock: the age check assumes synchronised
      // clocks (same host in a HEALTHCHECK).
      const double age_s = static_cast<double>(dds_time() - info.source_timestamp) * 1e-9;
      if (o.max_age_s > 0 && age_s > o.max_age_s) continue;
      const auto& c = status->counters;
      char line[1024];
      std::snprintf(
          line, sizeof(line),
          "hapco-status: server %s, domain %d, serving for %.1f s (scene ready), %" PRIu32 " of %" PRIu32 " sessions, scenes %s, pose "
          "received to answered p50 %.0f us p99 %.0f us max %.0f us, queueing included (mean per pose: physics %.0f, model %.0f, force write %.0f, contact "
          "frame %.0f us), status age %.3f s; bad input: nan %" PRIu64 ", workspace %" PRIu64
          ", jumps %" PRIu64 ", out-of-order %" PRIu64 ", duplicates %" PRIu64 ", unknown clients %" PRIu64
          ", floods %" PRIu64,
          id.c_str(), o.domain, static_cast<double>(status->uptime_ns) * 1e-9,
          static_cast<uint32_t>(status->sessions), static_cast<uint32_t>(status->max_sessions),
          status->scene_names[0] != '\0' ? status->scene_names : "?", status->step_time_p50_us,
          status->step_time_p99_us, status->step_time_max_us, status->physics_mean_us, status->model_mean_us,
          status->force_write_mean_us, status->frame_mean_us, age_s, c.bad_pose_nan, c.out_of_workspace,
          c.position_jumps, c.out_of_order, c.duplicates, c.unknown_clients, c.floods);
      if (lines.empty()) deadline = std::min(deadline, dds_time() + Seconds(o.server_id.empty() ? kOthersWindowS : 0));
      lines[id] = line;
    }
  }
  if (!lines.empty()) {
    if (!o.quiet) {
      for (const auto& [id, line] : lines) std::printf("%s\n", line.c_str());
    }
    return 0;
  }
  if (!others.empty()) {
    std::string heard;
    for (const std::string& id : others) heard += (heard.empty() ? "" : ", ") + id;
    std::fprintf(stderr, "hapco-status: no%s status of server '%s' in domain %d within %.1f s; servers heard: %s\n",
                 o.max_age_s > 0 ? " fresh" : "", o.server_id.c_str(), o.domain, o.timeout_s, heard.c_str());
    return 1;
  }
  std::fprintf(stderr, "hapco-status: no%s server status in domain %d within %.1f s (check "
               "the server, --domain and CYCLONEDDS_URI peers)\n",
               o.max_age_s > 0 ? " fresh" : "", o.domain, o.timeout_s);
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-status", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
