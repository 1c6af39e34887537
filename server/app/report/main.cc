// hapco-report: turns a HapCo recording into a summary, CSV and charts. Thin: reading is
// hapco::io::VisitRecording (one record at a time), charts are scripts/plot_recording.py (matplotlib).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <map>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/output_file.h"
#include "common/statistics.h"
#include "io/recording.h"
#include "io/recording_sessions.h"

namespace {

constexpr const char* kDescription =
    R"(Reads a HapCo recording (hapco-sim --output, hapco-recorder), prints what it holds and how it ends (a torn tail from a writer that was killed is skipped and reported), and optionally writes one CSV row per step and PNG charts: force over time, contacts by state over time, round-trip histogram (online recordings).)";

constexpr const char* kFooter =
    "Exit code: 0 on success, 1 on a missing/unreadable file or a file that is not a recording.";

struct Options {
  std::string path, csv_path, plots_dir;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("hapco-report", "RECORDING [options]", kDescription, kFooter);
  command.app()
      .add_option("RECORDING", options->path, "a HapCo recording (proto/recording.proto)")
      ->group("Arguments");  // checked after parsing: an unknown option is reported first
  command.AddCsv(&options->csv_path,
                 "steps as CSV, one row per step of every client (client_id column; units in the header; "
                 "contacts_missing = 1: the step's frame was lost, written from its force alone)");
  CLI::Option* plots = command.AddOutputDirectory("--plots", &options->plots_dir, "DIR",
                  "write force.png, contact_states.png, round_trip.png to DIR (needs /usr/bin/python3 with "
                  "matplotlib; implies a CSV at DIR/steps.csv unless --csv is given)",
                  hapco::cli::kGroupOutput);
  command.WritesInto(plots, {"steps.csv", "*.png"});
  if (!command.Parse(argc, argv)) return false;
  if (options->path.empty()) throw hapco::InputError("missing RECORDING argument (see --help)");
  return true;
}

std::string Quote(const std::string& text) { return "'" + text + "'"; }

// What the summary and the CSV need of a step; its contacts are not kept (hapco-report held
// every record of a recording at once: ~4.5x the file, a helper session). Strings interned.
struct StepRow {
  uint64_t step = 0, pose_sequence = 0;
  int64_t time_ns = 0;
  int client = 0, server = 0, solver_status = 0;
  double dx = 0, dy = 0, dz = 0, fx = 0, fy = 0, fz = 0, device_fx = 0, device_fy = 0, device_fz = 0;
  uint32_t separating = 0, sticking = 0, sliding = 0, iterations = 0;
  double solve_s = 0, step_s = 0, round_trip_s = 0, server_time_s = 0;
  bool contacts_missing = false;
  int contacts = 0;
};

class Interned {
 public:
  int Of(const std::string& text) {
    auto [it, inserted] = index_.try_emplace(text, static_cast<int>(texts_.size()));
    if (inserted) texts_.push_back(text);
    return it->second;
  }
  const std::string& operator[](int i) const { return texts_[static_cast<std::size_t>(i)]; }

 private:
  std::map<std::string, int> index_;
  std::vector<std::string> texts_;
};

int Run(const Options& options) {
  const std::string& path = options.path;
  std::string csv_path = options.csv_path;
  const std::string& plots_dir = options.plots_dir;
  hapco::io::RecordingReadReport report;
  std::vector<StepRow> steps;
  std::deque<hapco::recording::ServerStatus> status_records;  // few (one a second per server)
  std::vector<const hapco::recording::ServerStatus*> statuses;
  std::vector<std::string> header_lines;
  bool have_header = false, offline = false;
  Interned texts;
  // Per client, in order of appearance: its sessions (io/recording_sessions.h), steps, steps
  // without contacts.
  struct ClientSummary {
    long steps = 0, without_contacts = 0;
    hapco::io::ClientSessions sessions;
  };
  std::vector<std::string> client_order;
  std::map<std::string, ClientSummary> clients;
  hapco::io::VisitRecording(path, &report, [&](const hapco::recording::Record& record) {
    if (record.has_header()) {
      const auto& header = record.header();
      have_header = true;
      // Online recordings (hapco-recorder) carry the server's time per step but not the solve
      // and step timings of an offline run: the CSV leaves those cells empty, not 0.
      if (header.writer() == "hapco-sim") offline = true;
      char line[512];
      std::snprintf(line, sizeof line, "header     written by %s (HapCo %s), scene %s, solver %s\n",
                    header.writer().c_str(), header.hapco_version().c_str(),
                    header.scene_name().empty() ? "(none)" : header.scene_name().c_str(),
                    header.solver().empty() ? "(none)" : header.solver().c_str());
      header_lines.emplace_back(line);
    } else if (record.has_step()) {
      const auto& step = record.step();
      auto [it, inserted] = clients.try_emplace(step.client_id());
      if (inserted) client_order.push_back(step.client_id());
      it->second.sessions.Add(step);
      StepRow row;
      row.step = step.step();
      row.pose_sequence = step.pose_sequence();
      row.time_ns = step.time_ns();
      row.client = texts.Of(step.client_id());
      row.server = texts.Of(step.server_id());
      row.solver_status = texts.Of(step.solver_status());
      row.dx = step.device_translation_m().x();
      row.dy = step.device_translation_m().y();
      row.dz = step.device_translation_m().z();
      row.fx = step.contact_force_n().x();
      row.fy = step.contact_force_n().y();
      row.fz = step.contact_force_n().z();
      row.device_fx = step.device_force_n().x();
      row.device_fy = step.device_force_n().y();
      row.device_fz = step.device_force_n().z();
      row.separating = step.separating();
      row.sticking = step.sticking();
      row.sliding = step.sliding();
      row.iterations = step.iterations();
      row.solve_s = step.solve_s();
      row.step_s = step.step_s();
      row.round_trip_s = step.round_trip_s();
      row.server_time_s = step.server_time_s();
      row.contacts_missing = step.contacts_missing();
      row.contacts = step.contacts_size();
      steps.push_back(row);
    } else if (record.has_status()) {
      status_records.push_back(record.status());
      statuses.push_back(&status_records.back());
    }
  });
  std::printf("recording  %s: %s\n", path.c_str(), report.Summary().c_str());
  if (report.records == 0) {
    // Not even the header survived (a file cut right after it was created): nothing to report.
    throw hapco::InputError(path + " holds no complete record (" + report.Summary() +
                            "): the file was cut before its first record ended");
  }
  for (const std::string& line : header_lines) std::fputs(line.c_str(), stdout);
  if (!have_header) std::printf("header     missing\n");
  double peak_force_n = 0, peak_device_n = 0;
  long not_converged = 0, contacts[3] = {0, 0, 0};
  std::vector<double> step_times, server_times, round_trips;
  for (const StepRow& step : steps) {
    ClientSummary& c = clients[texts[step.client]];
    ++c.steps;
    if (step.contacts_missing) ++c.without_contacts;
    if (step.server_time_s > 0) server_times.push_back(step.server_time_s);
    peak_force_n = std::max(peak_force_n, std::sqrt(step.fx * step.fx + step.fy * step.fy + step.fz * step.fz));
    peak_device_n = std::max(peak_device_n, std::sqrt(step.device_fx * step.device_fx + step.device_fy * step.device_fy +
                                                      step.device_fz * step.device_fz));
    if (texts[step.solver_status] != "converged") ++not_converged;
    contacts[0] += step.separating;
    contacts[1] += step.sticking;
    contacts[2] += step.sliding;
    step_times.push_back(step.step_s);
    if (step.round_trip_s > 0) round_trips.push_back(step.round_trip_s);
  }
  std::printf("steps      %zu; peak contact force %.3f N, peak device force %.3f N; %ld not converged\n",
              steps.size(), peak_force_n, peak_device_n, not_converged);
  std::printf("contacts   separating %ld, sticking %ld, sliding %ld (contact-steps)\n", contacts[0], contacts[1],
              contacts[2]);
  // Nearest rank, as the phantom and the server report theirs.
  const auto percentile = &hapco::QuantileOf;
  for (const auto& id : client_order) {
    const ClientSummary& c = clients[id];
    std::string sessions;
    unsigned long long gaps = 0;  // steps the servers made that are not in the file
    // Of them, steps before a session's first recorded one. A session counts its steps from 1,
    // so these are missing too: in the client's first session, the recording may have begun
    // after them; in a later one it was running, so they were lost (a helper session saw a
    // moved client's step 1 reported as "before the recording began", 12 s into it).
    unsigned long long before = 0, lost_at_start = 0;
    for (const hapco::io::RecordedSession& s : c.sessions.sessions()) {
      (sessions.empty() ? before : lost_at_start) += s.before_first();
      sessions += (sessions.empty() ? "" : ", ") + std::to_string(s.first_step) + ".." + std::to_string(s.last_step);
      if (!s.server_id.empty()) sessions += " on " + s.server_id;
      gaps += s.missing;
    }
    const std::size_t count = c.sessions.sessions().size();
    std::string before_text;
    if (before > 0) before_text = std::to_string(before) + " of them before the recording began or lost at its start";
    if (lost_at_start > 0) {
      before_text += (before_text.empty() ? "" : ", ") + std::to_string(lost_at_start) +
                     " lost at the start of a later session";
    }
    if (!before_text.empty()) before_text = " (" + before_text + ")";
    std::printf("client     %s: %ld steps in %zu session%s (%s), %llu not in the file%s, %ld without contacts "
                "(frame lost)\n",
                id.c_str(), c.steps, count, count == 1 ? "" : "s", sessions.c_str(), gaps + before + lost_at_start,
                before_text.c_str(),
                c.without_contacts);
    // Where the steps inside the sessions went: the longest run (a stopped recorder, a loaded host).
    const hapco::io::RecordedSession* widest = nullptr;
    for (const hapco::io::RecordedSession& s : c.sessions.sessions()) {
      if (s.largest_gap > 0 && (widest == nullptr || s.largest_gap > widest->largest_gap)) widest = &s;
    }
    if (widest != nullptr) {
      std::printf("gaps       %s: %llu steps missing inside its sessions, the longest run %llu steps (%llu..%llu%s%s)\n",
                  id.c_str(), gaps, static_cast<unsigned long long>(widest->largest_gap),
                  static_cast<unsigned long long>(widest->largest_gap_first),
                  static_cast<unsigned long long>(widest->largest_gap_first + widest->largest_gap - 1),
                  widest->server_id.empty() ? "" : " on ", widest->server_id.c_str());
    }
  }
  // Offline recordings time every step; online ones carry the server's pose-in -> force-out.
  if (!step_times.empty() && percentile(step_times, 1.0) > 0) {
    std::printf("step time  p50 %.1f us, p99 %.1f us, max %.1f us\n", 1e6 * percentile(step_times, 0.5),
                1e6 * percentile(step_times, 0.99), 1e6 * percentile(step_times, 1.0));
  }
  if (!server_times.empty()) {
    std::printf("server     pose received -> force sent p50 %.1f us, p99 %.1f us, max %.1f us\n",
                1e6 * percentile(server_times, 0.5), 1e6 * percentile(server_times, 0.99),
                1e6 * percentile(server_times, 1.0));
  }
  // Status records per server, in the order each first appears: a recording can hold several
  // servers (clients moved after a failover, a restarted server), and each one's counters are
  // its own (before, the last record's server was credited with every record).
  std::vector<std::string> status_servers;
  std::map<std::string, std::vector<const hapco::recording::ServerStatus*>> statuses_of;
  for (const auto* status : statuses) {
    auto& list = statuses_of[status->server_id()];
    if (list.empty()) status_servers.push_back(status->server_id());
    list.push_back(status);
  }
  if (status_servers.size() > 1) {
    std::string names;
    for (const std::string& id : status_servers) {
      names += (names.empty() ? "" : ", ") + id + " (" + std::to_string(statuses_of[id].size()) + ")";
    }
    std::printf("status     %zu records from %zu servers: %s\n", statuses.size(), status_servers.size(), names.c_str());
  }
  for (const std::string& id : status_servers) {
    const auto& mine = statuses_of[id];
    const auto& s = *mine.back();
    std::printf("status     %zu records from %s; last: uptime %.1f s, %u sessions, step p50 %.1f us, p99 %.1f us, "
                "max %.1f us\n",
                mine.size(), s.server_id().c_str(), s.uptime_s(), s.sessions(), 1e6 * s.step_time_p50_s(),
                1e6 * s.step_time_p99_s(), 1e6 * s.step_time_max_s());
    double worst_p99_s = 0, worst_max_s = 0, peak_cpu = 0;
    for (const auto* status : mine) {
      worst_p99_s = std::max(worst_p99_s, status->step_time_p99_s());
      worst_max_s = std::max(worst_max_s, status->step_time_max_s());
      peak_cpu = std::max(peak_cpu, status->cpu_use());
    }
    // With several servers each line names its server.
    const std::string who = status_servers.size() > 1 ? s.server_id() + ": " : std::string();
    std::printf("status     %sworst status period: step p99 %.1f us, max %.1f us; server CPU peak %.0f %% of a core\n",
                who.c_str(), 1e6 * worst_p99_s, 1e6 * worst_max_s, 100.0 * peak_cpu);
    std::printf("server     %s%llu steps, superseded poses %llu, contact frames dropped %llu, non-finite forces %llu "
                "(last status)\n",
                who.c_str(), static_cast<unsigned long long>(s.steps()), static_cast<unsigned long long>(s.superseded()),
                static_cast<unsigned long long>(s.contact_frames_dropped()),
                static_cast<unsigned long long>(s.non_finite_forces()));
    if (s.answers_between_steps() > 0 || s.turn_steps() > 0) {
      // Multirate: forces sent between the steps above, which a recording does not hold.
      std::printf("server     %s%llu poses answered between steps (--physics-every; not in this recording), %llu extra "
                  "steps at turning poses (last status)\n",
                  who.c_str(), static_cast<unsigned long long>(s.answers_between_steps()),
                  static_cast<unsigned long long>(s.turn_steps()));
    }
    std::printf("bad input  %snan %llu, workspace %llu, jumps %llu, out-of-order %llu, duplicates %llu, "
                "unknown clients %llu, floods %llu (server counters, last status)\n",
                who.c_str(), static_cast<unsigned long long>(s.bad_pose_nan()),
                static_cast<unsigned long long>(s.out_of_workspace()),
                static_cast<unsigned long long>(s.position_jumps()), static_cast<unsigned long long>(s.out_of_order()),
                static_cast<unsigned long long>(s.duplicates()), static_cast<unsigned long long>(s.unknown_clients()),
                static_cast<unsigned long long>(s.floods()));
  }
  if (!round_trips.empty()) {
    std::printf("round trip p50 %.1f us, p99 %.1f us, max %.1f us\n", 1e6 * percentile(round_trips, 0.5),
                1e6 * percentile(round_trips, 0.99), 1e6 * percentile(round_trips, 1.0));
  }
  if (!plots_dir.empty() && csv_path.empty()) csv_path = plots_dir + "/steps.csv";
  if (!plots_dir.empty()) {
    if (std::system(("mkdir -p " + Quote(plots_dir)).c_str()) != 0) {
      throw hapco::InputError("cannot create " + plots_dir);
    }
  }
  if (!csv_path.empty()) {
    std::FILE* csv = std::fopen(csv_path.c_str(), "w");
    if (csv == nullptr) throw hapco::InputError("cannot write " + csv_path);
    std::fprintf(csv, "step,client_id,time_ns,dx_m,dy_m,dz_m,fx_n,fy_n,fz_n,device_fx_n,device_fy_n,device_fz_n,"
                      "separating,sticking,sliding,iterations,solver_status,solve_s,step_s,round_trip_s,"
                      "pose_sequence,server_time_s,contacts_missing,contacts,server_id\n");
    auto seconds_or_empty = [offline](double seconds) {
      char text[32] = "";
      if (offline) std::snprintf(text, sizeof text, "%.6g", seconds);
      return std::string(text);
    };
    for (const StepRow& s : steps) {
      std::fprintf(csv, "%llu,%s,%lld,%.9g,%.9g,%.9g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%u,%u,%u,%u,%s,%s,%s,%.6g,"
                   "%llu,%.6g,%d,%d,%s\n",
                   static_cast<unsigned long long>(s.step), texts[s.client].c_str(), static_cast<long long>(s.time_ns),
                   s.dx, s.dy, s.dz, s.fx, s.fy, s.fz, s.device_fx, s.device_fy, s.device_fz, s.separating, s.sticking,
                   s.sliding, s.iterations, texts[s.solver_status].c_str(), seconds_or_empty(s.solve_s).c_str(),
                   seconds_or_empty(s.step_s).c_str(), s.round_trip_s, static_cast<unsigned long long>(s.pose_sequence),
                   s.server_time_s, s.contacts_missing ? 1 : 0, s.contacts, texts[s.server].c_str());
    }
    hapco::CloseOutputFile(csv, csv_path);
    std::printf("csv        %s\n", csv_path.c_str());
  }
  if (!plots_dir.empty() && steps.empty()) {
    // (The chart script failed on it, and the message blamed matplotlib: a helper session.)
    throw hapco::InputError("--plots: the recording holds no steps to chart");
  }
  if (!plots_dir.empty()) {
    const char* env = std::getenv("HAPCO_SCRIPTS_DIR");
    const std::string scripts = env != nullptr ? env : HAPCO_DEFAULT_SCRIPTS_DIR;
    const std::string command = "/usr/bin/python3 " + Quote(scripts + "/plot_recording.py") + " " + Quote(csv_path) +
                                " " + Quote(plots_dir);
    std::fflush(stdout);  // keep our lines before the script's
    const int status = std::system(command.c_str());
    if (status != 0) {
      // (Piped into `head`, the script died of a closed stdout, and this blamed matplotlib.)
      throw hapco::InputError("chart script failed (exit status " + std::to_string(status) + "): " + command +
                              " (its messages are above; without any, is python3-matplotlib installed? was the "
                              "output piped into a command that closed it early?)");
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-report", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
