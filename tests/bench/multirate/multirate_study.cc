// multirate_study: what answering some poses with the last step's local model costs in force
// accuracy and saves in time (sim/multirate.h, docs/load-and-network.md "Multirate").
//
// For each --physics-every K, a fresh session answers every pose of the path through a
// MultirateAnswerer; K = 1 (a step on every pose, the server's default) is the reference, run in
// the same process on the same poses. Printed per K: the share of poses that got a physics step,
// the force error against the reference (RMS and max of |F_K - F_1| over the path, relative to
// the reference's peak |F|), the largest pose-to-pose change of the answered force against the
// reference's own (what the device feels as a jump), and the CPU time per pose against K = 1.
// Prints numbers, never asserts on time; the accuracy has its test in
// tests/unit/sim/multirate_test.cc.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "common/load_average.h"
#include "common/statistics.h"
#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "io/scene_file.h"
#include "io/trajectory_file.h"
#include "sim/device_path.h"
#include "sim/local_model.h"
#include "sim/multirate.h"
#include "sim/step_pipeline.h"
#include "sim/two_body_model.h"

namespace {

using namespace hapco;  // NOLINT: a short study driver

struct Options {
  std::string scene = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark1.txtpb";
  std::string path = "top-face";  // or "scene", or a trajectory CSV via --trajectory
  std::string trajectory;
  double spacing_m = 1e-4;        // top-face path: device travel per pose (1 kHz: m per ms)
  std::string physics_every = "1,2,4,8";
  double max_model_distance_m = sim::MultirateParameters{}.max_model_distance_m;
  int repeats = 3;
  std::string csv;
  std::string between = "frozen";  // or "return-mapping"
  std::string summary;             // appends one row per K (scripts/multirate-tradeoff)
};

// CPU time of this thread, s: the runs compare work, not the VM's scheduling.
double ThreadCpuSeconds() {
  timespec now{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

std::vector<int> ParseList(const std::string& text) {
  std::vector<int> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    char* end = nullptr;
    const long value = std::strtol(item.c_str(), &end, 10);
    if (item.empty() || *end != '\0' || value < 1 || value > 1000) {
      throw InputError("--physics-every: a comma-separated list of integers in [1, 1000], got '" + text + "'");
    }
    values.push_back(static_cast<int>(value));
  }
  if (std::find(values.begin(), values.end(), 1) == values.end()) values.insert(values.begin(), 1);
  return values;
}

std::vector<Eigen::Vector3d> DevicePath(const sim::SceneSpec& scene, const Options& options) {
  if (!options.trajectory.empty()) return io::LoadTrajectoryCsv(options.trajectory, "");
  if (options.path == "scene") return scene.DeviceTrajectory();
  // The top-face sweep of sim_pipeline_bench: a 3 mm press, then the tool from x = 5 mm to 95 mm
  // and back, at `spacing_m` per pose.
  const Eigen::Vector3d home = scene.tool.box.min_corner_m;
  const double x_low = 0.005 - home.x(), x_high = 0.095 - scene.tool.box.size_m.x() - home.x();
  return sim::PolylinePath({{0, 0, 0}, {0, 0, -0.003}, {x_low, 0, -0.003}, {x_high, 0, -0.003},
                            {0, 0, -0.003}, {0, 0, 0}},
                           options.spacing_m);
}

struct Run {
  std::vector<Eigen::Vector3d> force_n;           // per pose (poses 1..n), N
  std::vector<sim::AnswerSource> source;
  double seconds = 0;                              // thread CPU over the whole path
  // Wall time of the Answer calls by what they did, s: a step (a turn step and the answer after
  // it count as a step), a model answer; and how many of each.
  double step_seconds = 0, model_seconds = 0;
  int step_calls = 0, model_calls = 0;
  int not_converged = 0;                           // physics steps not converged
};

Run AnswerPath(const sim::TwoBodyModel& model, const std::vector<Eigen::Vector3d>& path, int physics_every,
               double max_model_distance_m, sim::BetweenSteps between) {
  sim::TwoBodySession session(model);
  sim::LocalModelBuilder builder;
  builder.Prepare(model);
  sim::MultirateParameters parameters;
  parameters.physics_every = physics_every;
  parameters.max_model_distance_m = max_model_distance_m;
  parameters.between_steps = between;
  sim::MultirateAnswerer answerer(session, builder, parameters);
  Run run;
  run.force_n.reserve(path.size());
  const double start_s = ThreadCpuSeconds();
  for (std::size_t k = 1; k < path.size(); ++k) {
    const long turn_steps_before = answerer.turn_steps();
    const auto call_start = std::chrono::steady_clock::now();
    const sim::MultirateAnswer answer = answerer.Answer(path[k]);
    const double call_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - call_start).count();
    if (answer.source == sim::AnswerSource::kStep || answerer.turn_steps() != turn_steps_before) {
      run.step_seconds += call_s;
      ++run.step_calls;
    } else if (answer.source == sim::AnswerSource::kModel) {
      run.model_seconds += call_s;
      ++run.model_calls;
    }
    run.force_n.push_back(answer.device_force_n);
    run.source.push_back(answer.source);
    if (answer.source == sim::AnswerSource::kStep &&
        session.last_output().status != contact::SolverStatus::kConverged) {
      ++run.not_converged;
    }
  }
  run.seconds = ThreadCpuSeconds() - start_s;
  return run;
}

double MaxJump(const std::vector<Eigen::Vector3d>& force_n) {
  double jump = 0;
  for (std::size_t k = 1; k < force_n.size(); ++k) jump = std::max(jump, (force_n[k] - force_n[k - 1]).norm());
  return jump;
}

constexpr const char* kDescription =
    R"(Multirate answering (sim/multirate.h): the physics on every K-th pose at most, the last step's local contact model on the poses between. For each K of --physics-every, the same path is answered and compared with K = 1 (a step on every pose) in the same run: share of poses stepped, force error (RMS and max of |F_K - F_1| relative to the peak |F_1|), the largest pose-to-pose force change against K = 1's own, and CPU time per pose against K = 1 (median of --repeats). Prints numbers only; the load average is printed at start and end.)";

bool Parse(int argc, char** argv, Options* options) {
  cli::CommandLine command("multirate_study", "[SCENE.txtpb] [options]", kDescription,
                           "Exit code: 0 when the study ran, 1 on bad input.");
  command.app()
      .add_option("SCENE", options->scene,
                  "scene file (proto/scene.proto); default: proto/scenes/benchmark1.txtpb of the source tree")
      ->group("Arguments");
  command.AddChoice("--path", &options->path, {"top-face", "scene"},
                    "top-face: a 3 mm press and a sweep over the whole top face and back (default); scene: the "
                    "scene's trajectory",
                    "Run");
  command.AddText("--trajectory", &options->trajectory, "CSV",
                  "the device path from a trajectory CSV instead (io/trajectory_file.h)", "Run");
  command.AddNumber("--spacing-m", &options->spacing_m, "M",
                    "top-face path: device travel per pose, m (1e-4 = 0.1 m/s at 1 kHz; default)", "Run", 0, 0.01,
                    true);
  command.AddText("--physics-every", &options->physics_every, "K,K,...",
                  "the K to compare (1 is always run: the reference; default 1,2,4,8)", "Run");
  command.AddNumber("--max-model-distance-m", &options->max_model_distance_m, "M",
                    "a step once the device is this far from the last step's pose, m (default 5e-4)", "Run", 0,
                    0.1);
  command.AddChoice("--between", &options->between, {"frozen", "return-mapping"},
                    "how a pose in contact is answered between steps: frozen (the step's contacts solved again at "
                    "this pose; default) or return-mapping (a linear model with friction cut back to the cone)",
                    "Run");
  command.AddInteger("--repeats", &options->repeats, "N", "timed runs per K, interleaved (default 3)", "Run", 1,
                     1000);
  command.AddCsv(&options->csv, "one row per pose and K: k, pose, source, force, reference force");
  command.AddOutputFile("--summary", &options->summary, "FILE",
                  "append one row per K to FILE (header written when the file is new): path, spacing, distance, K, "
                  "shares, errors, time ratio",
                  hapco::cli::kGroupOutput);
  return command.Parse(argc, argv);
}

double Median(const std::vector<double>& v) { return QuantileOf(v, 0.5); }

int RunStudy(const Options& options) {
  const std::vector<int> every = ParseList(options.physics_every);
  std::printf("load average at start: %s\n", hapco::LoadAverageText().c_str());
  const sim::SceneSpec scene = io::LoadSceneFile(options.scene);
  const sim::TwoBodyModel model(scene);
  const std::vector<Eigen::Vector3d> path = DevicePath(scene, options);
  std::printf("scene %s, path %s: %zu poses, between steps: %s, max model distance %.3g m\n", scene.name.c_str(),
              options.trajectory.empty() ? options.path.c_str() : options.trajectory.c_str(), path.size() - 1,
              options.between.c_str(), options.max_model_distance_m);
  std::vector<Run> runs(every.size());
  std::vector<std::vector<double>> seconds(every.size());
  for (int repeat = 0; repeat < options.repeats; ++repeat) {
    for (std::size_t i = 0; i < every.size(); ++i) {
      Run run = AnswerPath(model, path, every[i], options.max_model_distance_m,
                           options.between == "frozen" ? sim::BetweenSteps::kFrozenContacts
                                                       : sim::BetweenSteps::kReturnMapping);
      seconds[i].push_back(run.seconds);
      if (repeat == 0) runs[i] = std::move(run);
    }
  }
  const Run& reference = runs[static_cast<std::size_t>(std::find(every.begin(), every.end(), 1) - every.begin())];
  const std::size_t reference_index = static_cast<std::size_t>(&reference - runs.data());
  double peak_n = 0;
  for (const auto& f : reference.force_n) peak_n = std::max(peak_n, f.norm());
  const double reference_jump_n = MaxJump(reference.force_n);
  const double reference_s = Median(seconds[reference_index]);
  std::printf("reference (a step on every pose): peak |F| %.4g N, largest pose-to-pose change %.4g N, %.2f us per pose\n",
              peak_n, reference_jump_n, 1e6 * reference_s / static_cast<double>(reference.force_n.size()));
  std::printf("%4s %8s %8s %8s %12s %12s %12s %10s %10s %8s %9s %9s\n", "K", "steps%", "model%", "apart%",
              "rms err %pk", "max err %pk", "max jump N", "us/pose", "time/K=1", "unconv", "us/step", "us/model");
  std::FILE* csv = options.csv.empty() ? nullptr : std::fopen(options.csv.c_str(), "w");
  if (!options.csv.empty() && csv == nullptr) throw InputError("cannot write " + options.csv);
  if (csv != nullptr) std::fprintf(csv, "physics_every,pose,source,fx_n,fy_n,fz_n,ref_fx_n,ref_fy_n,ref_fz_n\n");
  std::FILE* summary = nullptr;
  if (!options.summary.empty()) {
    const bool is_new = !std::ifstream(options.summary).good();
    summary = std::fopen(options.summary.c_str(), "a");
    if (summary == nullptr) throw InputError("cannot write " + options.summary);
    if (is_new) {
      std::fprintf(summary, "scene,path,spacing_m,between,max_model_distance_m,physics_every,steps_pct,model_pct,apart_pct,"
                            "rms_error_pct_of_peak,max_error_pct_of_peak,max_jump_n,reference_max_jump_n,us_per_pose,"
                            "time_ratio,peak_n,load1\n");
    }
  }
  for (std::size_t i = 0; i < every.size(); ++i) {
    const Run& run = runs[i];
    const double n = static_cast<double>(run.force_n.size());
    int counts[3] = {0, 0, 0};
    double sum_sq = 0, max_error = 0;
    for (std::size_t k = 0; k < run.force_n.size(); ++k) {
      ++counts[static_cast<int>(run.source[k])];
      const double error = (run.force_n[k] - reference.force_n[k]).norm();
      sum_sq += error * error;
      max_error = std::max(max_error, error);
      if (csv != nullptr) {
        std::fprintf(csv, "%d,%zu,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", every[i], k + 1,
                     sim::AnswerSourceName(run.source[k]), run.force_n[k].x(), run.force_n[k].y(),
                     run.force_n[k].z(), reference.force_n[k].x(), reference.force_n[k].y(),
                     reference.force_n[k].z());
      }
    }
    const double per_pose_s = Median(seconds[i]) / n;
    // Wall time per call of the first run (us; a turn step and its answer count as one step call).
    const auto per_call_us = [](double s, int calls) { return calls > 0 ? 1e6 * s / calls : 0.0; };
    std::printf("%4d %8.1f %8.1f %8.1f %12.3f %12.3f %12.4g %10.2f %10.3f %8d %9.1f %9.1f\n", every[i],
                100.0 * counts[0] / n, 100.0 * counts[1] / n, 100.0 * counts[2] / n,
                100.0 * std::sqrt(sum_sq / n) / peak_n, 100.0 * max_error / peak_n, MaxJump(run.force_n),
                1e6 * per_pose_s, Median(seconds[i]) / reference_s, run.not_converged,
                per_call_us(run.step_seconds, run.step_calls), per_call_us(run.model_seconds, run.model_calls));
    if (summary != nullptr) {
      std::fprintf(summary, "%s,%s,%.6g,%s,%.6g,%d,%.3f,%.3f,%.3f,%.5f,%.5f,%.6g,%.6g,%.3f,%.5f,%.6g,%s\n",
                   scene.name.c_str(), options.trajectory.empty() ? options.path.c_str() : "file",
                   options.path == "top-face" && options.trajectory.empty() ? options.spacing_m : 0.0,
                   options.between.c_str(), options.max_model_distance_m, every[i], 100.0 * counts[0] / n,
                   100.0 * counts[1] / n, 100.0 * counts[2] / n, 100.0 * std::sqrt(sum_sq / n) / peak_n,
                   100.0 * max_error / peak_n, MaxJump(run.force_n), reference_jump_n, 1e6 * per_pose_s,
                   Median(seconds[i]) / reference_s, peak_n, hapco::LoadAverageText().substr(0, hapco::LoadAverageText().find(' ')).c_str());
    }
  }
  if (summary != nullptr) std::fclose(summary);
  if (csv != nullptr) std::fclose(csv);
  std::printf("load average at end: %s\n", hapco::LoadAverageText().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("multirate_study", [&] {
    Options options;
    return Parse(argc, argv, &options) ? RunStudy(options) : 0;
  });
}
