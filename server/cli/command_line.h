#pragma once
// One command-line convention for every HapCo executable (issue 18), on CLI11.
//
// A tool builds a CommandLine, adds its options (the shared ones through the Add* functions
// below, so that the same concept has the same name, unit, range and help everywhere), then
// calls Parse. Conventions (docs/cli.md):
//   - a physical quantity carries its unit in the flag name: --duration-s, --max-jump-m,
//     --force-timeout-ms, --paper-tol-m; dimensionless values do not (--tol, --mu);
//   - the scene file is always the first positional argument, the tool's main output file is
//     always --output FILE, a per-step table --csv FILE, charts --plots DIR;
//   - a bad value names the flag and the accepted range ("--steps expects an integer in
//     [1, 100000000], got 'x'"), an unknown option says "unknown option --x";
//   - old spellings users have in scripts keep working through Deprecate(): the argument is
//     rewritten before parsing and a one-line note goes to stderr.
// --help (grouped by purpose), --version and --bash-completion come with every CommandLine.
#include <CLI/CLI.hpp>

#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace hapco::cli {

// Help groups shared by the tools, in the order they usually appear.
inline constexpr const char* kGroupDds = "DDS";
inline constexpr const char* kGroupOutput = "Output";
inline constexpr const char* kGroupGeneral = "General";

class CommandLine {
 public:
  // tool: the executable's name; synopsis: what follows it on the usage line;
  // description: the paragraphs shown after the usage line; footer: after the options
  // (exit codes, signals).
  CommandLine(std::string tool, std::string synopsis, std::string description, std::string footer);
  // Options hold pointers into the caller's variables: build it in place, never copy it.
  CommandLine(const CommandLine&) = delete;
  CommandLine& operator=(const CommandLine&) = delete;

  CLI::App& app() { return app_; }
  const std::string& tool() const { return tool_; }

  // --- typed options with HapCo's messages (the value is checked before it is converted) ---
  // A finite number in [minimum, maximum]; open_minimum excludes the minimum itself.
  CLI::Option* AddNumber(const std::string& name, double* value, const std::string& metavar,
                         const std::string& help, const std::string& group, double minimum,
                         double maximum, bool open_minimum = false);
  CLI::Option* AddInteger(const std::string& name, int* value, const std::string& metavar,
                          const std::string& help, const std::string& group, long minimum, long maximum);
  // Any text but "" (an empty value is refused: leave the option out instead), except for
  // metavar "LIST", which may be empty.
  CLI::Option* AddText(const std::string& name, std::string* value, const std::string& metavar,
                       const std::string& help, const std::string& group);
  // A file to write: not empty, not a directory, in an existing writable folder (checked when
  // the command line is read, before any work).
  CLI::Option* AddOutputFile(const std::string& name, std::string* path, const std::string& metavar,
                             const std::string& help, const std::string& group);
  // A folder to write into, created if missing: it, or the nearest existing folder above it,
  // must be a writable directory (checked when the command line is read).
  CLI::Option* AddOutputDirectory(const std::string& name, std::string* path, const std::string& metavar,
                                  const std::string& help, const std::string& group);
  // One of `choices` (the help's metavar lists them when it is empty).
  CLI::Option* AddChoice(const std::string& name, std::string* value, std::vector<std::string> choices,
                         const std::string& help, const std::string& group);
  CLI::Option* AddFlag(const std::string& name, bool* value, const std::string& help, const std::string& group);

  // --- shared definitions ---
  // SCENE.txtpb, the first positional argument (required).
  CLI::Option* AddScene(std::string* path, const std::string& help = "scene file (proto/scene.proto)");
  // --domain N, 0..230, group DDS.
  CLI::Option* AddDomain(int* domain);
  // --rt-priority N, 0..99 (0 = normal policy); `what` names what runs SCHED_FIFO.
  CLI::Option* AddRtPriority(int* priority, const std::string& what);
  // --quiet; `what` says what is silenced.
  CLI::Option* AddQuiet(bool* quiet, const std::string& what);
  // --output FILE / -o FILE: the tool's main output file.
  CLI::Option* AddOutput(std::string* path, const std::string& help);
  // --csv FILE: one row per step or tick.
  CLI::Option* AddCsv(std::string* path, const std::string& help);
  // --solver NAME: the contact solvers of server/contact (same names as a scene file).
  CLI::Option* AddSolver(std::string* name, const std::string& default_help);
  // --max-iter N: outer iterations (sweeps) of the contact solver, 1..1e6 (as a scene file).
  CLI::Option* AddMaxIterations(int* iterations, const std::string& default_help);
  // --anderson-depth N: Anderson acceleration of the solver's sweeps from the last N, 0 = off
  // (contact::SolverParameters::anderson_depth; `maximum` is its kMaxAndersonDepth).
  CLI::Option* AddAndersonDepth(int* depth, const std::string& default_help, int maximum);
  // --connect-timeout-s S: how long to wait for a server (status, clients).
  CLI::Option* AddConnectTimeout(double* seconds, const std::string& help);
  // --force-timeout-ms T: no new force for T ms -> the rendered force ramps to zero.
  CLI::Option* AddForceTimeout(double* milliseconds);
  // --max-answer-age-ms T: answers to poses older than T ms are not rendered (phantom.h).
  CLI::Option* AddMaxAnswerAge(double* milliseconds);
  // --render auto|direct|direct+passivity|local-model|local-model+passivity and
  // --max-model-stiffness-n-per-m K: how a client renders the forces it receives
  // (client/phantom/force_renderer.h, docs/network-haptics.md), group Device.
  void AddRendering(std::string* mode, double* max_model_stiffness_n_per_m);
  // --duration-s S: how long the tool runs.
  static constexpr double kMaxDurationS = 1e6;
  CLI::Option* AddDuration(double* seconds, const std::string& help);
  // --security DIR: run secured with the deployment of scripts/dds-security init DIR; `who`
  // says which identity the tool takes (DIR/server, DIR/<client id>, ...).
  CLI::Option* AddSecurity(std::string* dir, const std::string& who);
  // --workspace-m X and --max-jump-m X: the pose checks of hapco-server (sim/pose_limits.h).
  CLI::Option* AddWorkspace(double* metres, const std::string& help);
  CLI::Option* AddMaxJump(double* metres, const std::string& help);
  // --physics-every K and --model-distance-m X: multirate answering (sim/multirate.h), group
  // "Multirate"; the same meaning in hapco-server and hapco-sim. Parse notes a distance given
  // without K > 1 (it has no effect then).
  void AddMultirate(int* physics_every, double* max_model_distance_m);

  // `old_name` (e.g. "--record") keeps working as `current_name` ("--output"), with a note on
  // stderr. An empty current_name drops the flag, so its value becomes a positional argument
  // (recorder --scene FILE -> FILE).
  void Deprecate(const std::string& old_name, const std::string& current_name);

  // Declares the files an output folder option writes into its folder (glob patterns, e.g.
  // "ticks-*.csv"): an input that is one of them is refused before any work (a loadtest
  // replaying DIR/ticks-lt-1.csv with --csv-dir DIR overwrote its own trajectory).
  void WritesInto(const CLI::Option* folder_option, std::vector<std::string> patterns);

  // Parses the arguments. Returns false when the run is over with exit code 0 (--help,
  // --version, --bash-completion printed on stdout). A bad command line throws InputError
  // with a message that names the option (RunMain prints it and exits 1).
  [[nodiscard]] bool Parse(int argc, char** argv);
  // The same on already split arguments (tests).
  [[nodiscard]] bool Parse(std::vector<std::string> arguments);

  // The help text: usage line, description, options by group, footer.
  std::string Help() const;
  // A bash completion function for this tool, from the same definitions.
  std::string BashCompletion() const;

 private:
  // An output file option: checked when read, and against the other files given.
  CLI::Option* AddOutputFileOption(const std::string& names, const std::string& flag, std::string* path,
                                   const std::string& help, const std::string& group);
  // Throws InputError when an output file is also an input file or another output, or when an
  // input is a file an output folder's option writes (WritesInto).
  void CheckOutputsAreNotInputs() const;
  // "unknown option --x (see --help)", with the options it is a near miss of, if any.
  std::string UnknownOptionMessage(const std::string& argument) const;

  std::string tool_, synopsis_, description_, footer_;
  CLI::App app_;
  std::map<std::string, std::string> deprecated_;          // old spelling -> current ("" = drop)
  const int* multirate_physics_every_ = nullptr;            // AddMultirate's K, for Parse's note
  std::map<std::string, std::vector<std::string>> choices_;  // option name -> accepted values
  std::map<std::string, std::string> metavars_;              // option name -> FILE, DIR, N, ...
  std::set<const CLI::Option*> output_files_;                // options that name a file to write
  std::map<const CLI::Option*, std::vector<std::string>> folder_writes_;  // WritesInto
};

// An option spelling a typo may be near, and what to suggest for it (an old spelling's current name).
struct NearMissCandidate {
  std::string spelling, suggestion;
};

// What `given` (an unknown long option) is a near miss of, ignoring case: the suggestions of
// the spellings it begins, else of the closest by edit distance (a spelling also counts without
// its unit suffix: --durtion for --duration-s) if within a quarter of its length (at least 1
// edit). Never a --no-x for --x or back (the opposite meaning). Empty when none is near; at most 3.
std::vector<std::string> NearMisses(const std::string& given, const std::vector<NearMissCandidate>& known);

// Word-wraps `text` to `width` columns, continuation lines indented by `indent` spaces;
// explicit newlines in `text` are kept.
std::string WrapText(const std::string& text, int width, int indent, int first_column);

}  // namespace hapco::cli
