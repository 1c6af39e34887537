#include "cli/command_line.h"

#include <fnmatch.h>
#include <unistd.h>


#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>

#include "cli/run_main.h"
#include "common/error.h"

namespace hapco::cli {
namespace {

constexpr int kHelpWidth = 96;        // columns of the help text
constexpr int kHelpOptionColumn = 24;  // where option descriptions start

// Thrown by --bash-completion while parsing (before required options are checked).
class CompletionRequested : public CLI::Success {
 public:
  CompletionRequested() : CLI::Success("bash completion requested", 0) {}
};

std::string Quoted(const std::string& text) { return "'" + text + "'"; }

// A finite decimal number, else nullopt-like: returns false.
bool ToFiniteDouble(const std::string& text, double* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const double parsed = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size() || !std::isfinite(parsed)) return false;
  *value = parsed;
  return true;
}

bool ToInteger(const std::string& text, long* value) {
  if (text.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const long parsed = std::strtol(text.c_str(), &end, 10);
  if (end != text.c_str() + text.size() || errno == ERANGE) return false;
  *value = parsed;
  return true;
}

std::string FormatNumber(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

std::string Join(const std::vector<std::string>& items, const std::string& separator) {
  std::string joined;
  for (const std::string& item : items) joined += (joined.empty() ? "" : separator) + item;
  return joined;
}

// "--output" or "-o, --output" or "SCENE" for an option.
std::string DisplayNames(const CLI::Option& option) {
  if (option.get_positional()) return option.get_name(true);
  std::vector<std::string> names;
  for (const std::string& name : option.get_snames()) names.push_back("-" + name);
  for (const std::string& name : option.get_lnames()) names.push_back("--" + name);
  return Join(names, ", ");
}

}  // namespace

std::string WrapText(const std::string& text, int width, int indent, int first_column) {
  std::string out;
  int column = first_column;
  std::istringstream lines(text);
  std::string line;
  bool first_line = true;
  while (std::getline(lines, line)) {
    if (!first_line) {
      out += "\n" + std::string(indent, ' ');
      column = indent;
    }
    first_line = false;
    // Keep a line's own leading spaces (indented examples in descriptions).
    const size_t lead = line.find_first_not_of(' ');
    if (lead == std::string::npos) continue;
    out += line.substr(0, lead);
    column += static_cast<int>(lead);
    std::istringstream words(line.substr(lead));
    std::string word;
    bool line_start = true;
    while (words >> word) {
      if (!line_start && column + 1 + static_cast<int>(word.size()) > width) {
        out += "\n" + std::string(indent, ' ');
        column = indent;
        line_start = true;
      }
      if (!line_start) {
        out += ' ';
        ++column;
      }
      out += word;
      column += static_cast<int>(word.size());
      line_start = false;
    }
  }
  return out;
}

CommandLine::CommandLine(std::string tool, std::string synopsis, std::string description, std::string footer)
    : tool_(std::move(tool)), synopsis_(std::move(synopsis)), description_(std::move(description)),
      footer_(std::move(footer)) {
  app_.name(tool_);
  // A flag given twice: the last one wins (as the hand-written parsers did), not an error.
  app_.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
  app_.set_help_flag("-h,--help", "this text")->group(kGroupGeneral);
  const std::string version = VersionLine(tool_);
  app_.add_flag_callback("--version", [version] { throw CLI::CallForVersion(version, 0); },
                         "the HapCo version and git revision, then exit")
      ->group(kGroupGeneral)
      ->trigger_on_parse();
  app_.add_flag_callback("--bash-completion", [] { throw CompletionRequested(); },
                         "print a bash completion function for this tool (scripts/bash-completion)")
      ->group(kGroupGeneral)
      ->trigger_on_parse();
}

CLI::Option* CommandLine::AddNumber(const std::string& name, double* value, const std::string& metavar,
                                    const std::string& help, const std::string& group, double minimum,
                                    double maximum, bool open_minimum) {
  const std::string flag = name;
  CLI::Validator check(
      [flag, minimum, maximum, open_minimum](std::string& text) -> std::string {
        double parsed = 0;
        if (!ToFiniteDouble(text, &parsed)) throw InputError(flag + " expects a number, got " + Quoted(text));
        const bool below = open_minimum ? !(parsed > minimum) : parsed < minimum;
        if (below || parsed > maximum) {
          std::string range;
          if (maximum == HUGE_VAL) {
            range = (open_minimum ? "> " : ">= ") + FormatNumber(minimum);
          } else {
            range = (open_minimum ? "in (" : "in [") + FormatNumber(minimum) + ", " + FormatNumber(maximum) + "]";
          }
          throw InputError(flag + " expects a number " + range + ", got " + Quoted(text));
        }
        return "";
      },
      "");
  metavars_[name] = metavar;
  return app_.add_option(name, *value, help)->check(check)->group(group);
}

CLI::Option* CommandLine::AddInteger(const std::string& name, int* value, const std::string& metavar,
                                     const std::string& help, const std::string& group, long minimum,
                                     long maximum) {
  const std::string flag = name;
  CLI::Validator check(
      [flag, minimum, maximum](std::string& text) -> std::string {
        long parsed = 0;
        if (!ToInteger(text, &parsed) || parsed < minimum || parsed > maximum) {
          throw InputError(flag + " expects an integer in [" + std::to_string(minimum) + ", " +
                           std::to_string(maximum) + "], got " + Quoted(text));
        }
        return "";
      },
      "");
  metavars_[name] = metavar;
  return app_.add_option(name, *value, help)->check(check)->group(group);
}

CLI::Option* CommandLine::AddText(const std::string& name, std::string* value, const std::string& metavar,
                                  const std::string& help, const std::string& group) {
  metavars_[name] = metavar;
  // An empty value was taken as the option left out by some tools (--csv "": no CSV, exit 0)
  // and refused by others: one rule for all. A LIST may be empty (no items: scripts pass
  // --loss-cases "" when they have none).
  if (metavar == "LIST") return app_.add_option(name, *value, help)->group(group);
  const std::string flag = name;
  CLI::Validator not_empty(
      [flag](std::string& text) -> std::string {
        if (text.empty()) throw InputError(flag + " needs a value (leave the option out for its default)");
        return "";
      },
      "");
  return app_.add_option(name, *value, help)->check(not_empty)->group(group);
}

CLI::Option* CommandLine::AddChoice(const std::string& name, std::string* value, std::vector<std::string> choices,
                                    const std::string& help, const std::string& group) {
  const std::string flag = name;
  CLI::Validator check(
      [flag, choices](std::string& text) -> std::string {
        if (std::find(choices.begin(), choices.end(), text) == choices.end()) {
          throw InputError(flag + " expects " + Join(choices, " | ") + ", got " + Quoted(text));
        }
        return "";
      },
      "");
  metavars_[name] = Join(choices, "|");
  choices_[name] = std::move(choices);
  return app_.add_option(name, *value, help)->check(check)->group(group);
}

CLI::Option* CommandLine::AddFlag(const std::string& name, bool* value, const std::string& help,
                                  const std::string& group) {
  return app_.add_flag(name, *value, help)->group(group);
}

CLI::Option* CommandLine::AddScene(std::string* path, const std::string& help) {
  metavars_["SCENE"] = "";
  return app_.add_option("SCENE", *path, help)->required()->group("Arguments");
}

CLI::Option* CommandLine::AddDomain(int* domain) {
  return AddInteger("--domain", domain, "N",
                    "DDS domain id (default 0); the configuration comes from CYCLONEDDS_URI "
                    "(loopback: docker/cyclonedds-loopback.xml)",
                    kGroupDds, 0, 230);
}

CLI::Option* CommandLine::AddRtPriority(int* priority, const std::string& what) {
  return AddInteger("--rt-priority", priority, "N",
                    "run " + what + " (and DDS's threads) with SCHED_FIFO priority N (1..99; needs "
                    "CAP_SYS_NICE; default 0 = normal policy)",
                    kGroupGeneral, 0, 99);
}

CLI::Option* CommandLine::AddQuiet(bool* quiet, const std::string& what) {
  return AddFlag("--quiet", quiet, what, kGroupGeneral);
}

// `option` is filled in once the option exists: a required output has no "leave it out".
CLI::Validator OutputFileCheck(const std::string& flag, std::shared_ptr<const CLI::Option*> option) {
  // Checked when the command line is read, not when the run ends: a directory or a folder that
  // does not exist was found only after the whole run (hapco-sim --output DIR: the run, then
  // "cannot move ...partial", the recording left under another name).
  return CLI::Validator(
      [flag, option](std::string& text) -> std::string {
        if (text.empty()) {
          const bool required = *option != nullptr && (*option)->get_required();
          throw InputError(flag + " needs a file name" + (required ? "" : " (leave the option out for no file)"));
        }
        // "-o=x.rec" gives -o the value "=x.rec" (a short option's value follows a space).
        if (text[0] == '=') {
          throw InputError(flag + ": the file name " + Quoted(text) + " starts with '=': write -o " + text.substr(1) +
                           " or " + flag + "=" + text.substr(1));
        }
        std::error_code error;
        const std::filesystem::path path(text);
        if (std::filesystem::is_directory(path, error)) throw InputError(flag + ": " + text + " is a directory");
        if (std::filesystem::exists(path, error) && access(path.c_str(), W_OK) == 0) return "";  // (also /dev/null)
        const std::filesystem::path parent = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
        if (!std::filesystem::is_directory(parent, error)) {
          throw InputError(flag + ": the folder " + parent.string() + " of " + text + " does not exist");
        }
        if (access(parent.c_str(), W_OK) != 0) {
          throw InputError(flag + ": the folder " + parent.string() + " of " + text + " is not writable");
        }
        return "";
      },
      "");
}

CLI::Validator OutputDirectoryCheck(const std::string& flag) {
  // A folder to write into, created if missing: it, or the nearest folder above it that
  // exists, must be a writable directory (checked before any work, as for files).
  return CLI::Validator(
      [flag](std::string& text) -> std::string {
        if (text.empty()) throw InputError(flag + " needs a folder name (leave the option out for none)");
        std::error_code error;
        std::filesystem::path path = std::filesystem::absolute(text, error);
        if (error) throw InputError(flag + ": " + text + ": " + error.message());
        while (!std::filesystem::exists(path, error) && path.has_parent_path() && path != path.parent_path()) {
          path = path.parent_path();
        }
        if (!std::filesystem::is_directory(path, error)) {
          throw InputError(flag + ": " + path.string() + " is not a folder (the output folder " + text +
                           " cannot be made there)");
        }
        if (access(path.c_str(), W_OK) != 0) throw InputError(flag + ": " + path.string() + " is not writable");
        return "";
      },
      "");
}

CLI::Option* CommandLine::AddOutputDirectory(const std::string& name, std::string* path, const std::string& metavar,
                                             const std::string& help, const std::string& group) {
  metavars_[name] = metavar;
  // Without its trailing slashes: the tools append "/file" ("charts//steps.csv" was printed).
  const CLI::Validator trailing_slashes(
      [](std::string& text) -> std::string {
        while (text.size() > 1 && text.back() == '/') text.pop_back();
        return "";
      },
      "");
  return app_.add_option(name, *path, help)
      ->check(OutputDirectoryCheck(name))
      ->transform(trailing_slashes)
      ->group(group);
}

CLI::Option* CommandLine::AddOutputFile(const std::string& name, std::string* path, const std::string& metavar,
                                        const std::string& help, const std::string& group) {
  metavars_[name] = metavar;
  return AddOutputFileOption(name, name, path, help, group);
}

CLI::Option* CommandLine::AddOutputFileOption(const std::string& names, const std::string& flag, std::string* path,
                                              const std::string& help, const std::string& group) {
  auto option_ref = std::make_shared<const CLI::Option*>(nullptr);
  CLI::Option* option = app_.add_option(names, *path, help)->check(OutputFileCheck(flag, option_ref))->group(group);
  *option_ref = option;
  output_files_.insert(option);
  return option;
}

void CommandLine::WritesInto(const CLI::Option* folder_option, std::vector<std::string> patterns) {
  folder_writes_[folder_option] = std::move(patterns);
}

void CommandLine::CheckOutputsAreNotInputs() const {
  // An output that is also an input, or another output, destroys what it overwrites before it
  // is read or written: hapco-recorder s.txtpb --output s.txtpb wrote a recording over the
  // scene the server ran, hapco-sim --trajectory t.csv --csv t.csv over its trajectory (a
  // helper session).
  struct Given {
    const CLI::Option* option;
    std::filesystem::path path;
  };
  std::vector<Given> given;
  for (const CLI::Option* option : app_.get_options()) {
    if (option->count() == 0 || option->results().empty() || option->results().back().empty()) continue;
    given.push_back({option, std::filesystem::path(option->results().back())});
  }
  const auto same_file = [](const std::filesystem::path& a, const std::filesystem::path& b) {
    std::error_code error;
    if (std::filesystem::exists(a, error) && std::filesystem::exists(b, error)) {
      return std::filesystem::equivalent(a, b, error) && !error;
    }
    return std::filesystem::weakly_canonical(a, error) == std::filesystem::weakly_canonical(b, error) && !error;
  };
  const auto display = [](const CLI::Option* option) {
    return option->get_positional() ? option->get_name(true) : option->get_name();
  };
  // Inputs among the files an output folder gets.
  for (const Given& folder : given) {
    const auto writes = folder_writes_.find(folder.option);
    if (writes == folder_writes_.end()) continue;
    for (const Given& other : given) {
      std::error_code error;
      if (output_files_.count(other.option) > 0 || folder_writes_.count(other.option) > 0 ||
          !std::filesystem::is_regular_file(other.path, error)) {
        continue;
      }
      const std::filesystem::path parent = other.path.has_parent_path() ? other.path.parent_path() : ".";
      if (!std::filesystem::equivalent(parent, folder.path, error) || error) continue;
      const std::string name = other.path.filename().string();
      for (const std::string& pattern : writes->second) {
        if (fnmatch(pattern.c_str(), name.c_str(), 0) == 0) {
          throw InputError(display(other.option) + " " + other.path.string() + " is a file " + display(folder.option) +
                           " " + folder.path.string() + " writes (" + pattern +
                           "): writing it would destroy the input; give another folder");
        }
      }
    }
  }
  for (const Given& output : given) {
    if (output_files_.count(output.option) == 0) continue;
    std::error_code error;
    if (!std::filesystem::is_regular_file(output.path, error) && std::filesystem::exists(output.path, error)) {
      continue;  // /dev/null and the like may be given twice
    }
    for (const Given& other : given) {
      if (other.option == output.option) continue;
      const bool other_is_output = output_files_.count(other.option) > 0;
      // An input counts when it names an existing file; two outputs clash even before they exist.
      if (!other_is_output && !std::filesystem::is_regular_file(other.path, error)) continue;
      if (!same_file(output.path, other.path)) continue;
      if (other_is_output && other.option < output.option) continue;  // say it once per pair
      throw InputError(display(output.option) + " " + output.path.string() + " is also " +
                       (other_is_output ? "the file of " : "the input ") + display(other.option) +
                       ": writing it would destroy " + (other_is_output ? "the other output" : "the input") +
                       "; give another file");
    }
  }
}

CLI::Option* CommandLine::AddOutput(std::string* path, const std::string& help) {
  metavars_["--output"] = "FILE";
  return AddOutputFileOption("-o,--output", "--output", path, help, kGroupOutput);
}

CLI::Option* CommandLine::AddCsv(std::string* path, const std::string& help) {
  return AddOutputFile("--csv", path, "FILE", help, kGroupOutput);
}

CLI::Option* CommandLine::AddSolver(std::string* name, const std::string& default_help) {
  return AddChoice("--solver", name, {"local-uzawa", "global-uzawa-gs", "global-uzawa-jacobi", "reference"},
                   "frictional contact solver (default: " + default_help +
                       "); global-uzawa-jacobi is the De Saxce fixed point for stability studies: with "
                       "the paper's rho it does not converge on the shipped meshes "
                       "(docs/contact-benchmark.md)",
                   "Solver");
}

CLI::Option* CommandLine::AddMaxIterations(int* iterations, const std::string& default_help) {
  // The range of a scene file's solver.max_iterations.
  return AddInteger("--max-iter", iterations, "N",
                    "cap on the solver's outer iterations (sweeps), 1..1000000 as in a scene file (default: " +
                        default_help + ")",
                    "Solver", 1, 1000000);
}

CLI::Option* CommandLine::AddAndersonDepth(int* depth, const std::string& default_help, int maximum) {
  return AddInteger("--anderson-depth", depth, "N",
                    "Anderson acceleration of the solver's sweeps from the last N, 0 = off (the plain sweeps), at "
                    "most " + std::to_string(maximum) + "; docs/stability.md (default: " + default_help + ")",
                    "Solver", 0, maximum);
}

CLI::Option* CommandLine::AddConnectTimeout(double* seconds, const std::string& help) {
  // At most kMaxDurationS, as --duration-s: seconds become int64 nanoseconds (1e12 s overflowed
  // and gave up at once, "within 1000000000000.0 s").
  return AddNumber("--connect-timeout-s", seconds, "S", help, kGroupDds, 0, kMaxDurationS, true);
}

CLI::Option* CommandLine::AddForceTimeout(double* milliseconds) {
  // At least one 1 kHz tick: 0.05 was taken and logged "no force for 0 ms" (a helper session).
  return AddNumber("--force-timeout-ms", milliseconds, "T",
                   "no new force for T ms -> the rendered force ramps to zero over max(20 ms, |F| / 250 N/s), "
                   "31.6 ms from the 7.9 N clamp (default 50, at least 1: one tick); it resumes (rate limited) "
                   "when forces return",
                   "Device", 1, 1e6);
}

CLI::Option* CommandLine::AddMaxAnswerAge(double* milliseconds) {
  return AddNumber("--max-answer-age-ms", milliseconds, "T",
                   "an answer to a pose sampled more than T ms ago is not rendered, only counted: after a "
                   "network outage the answers to poses long past arrive (default 500, above the 200 ms "
                   "round trips the rendering modes are measured at)",
                   "Device", 1, 60000);
}

void CommandLine::AddRendering(std::string* mode, double* max_model_stiffness_n_per_m) {
  AddChoice("--render", mode, {"auto", "direct", "direct+passivity", "local-model", "local-model+passivity"},
            "direct: the newest force, held until the next; local-model: the model sent with the newest "
            "force at the device's current position every tick (in contact the contact's plane, with "
            "friction on the device; apart the obstacle surface ahead); +passivity: a time-domain passivity "
            "controller on what is rendered, a damper of at most 25 N s/m within the 0.25 N/tick rate limit (the "
            "energy it dissipates is reported; direct+passivity suits round trips of a few ms only: from 50 ms it oscillates, "
            "docs/network-haptics.md). auto (default): direct "
            "with --mode kinematic (forces compare with hapco-sim), local-model+passivity with --mode hand "
            "(passive and without oscillation up to a 200 ms round trip and 10 % loss with jitter up to "
            "+-5 ms; jitter with loss dips its energy to about -1e-3 J, and reordering beyond +-40 ms starves "
            "it of forces: docs/network-haptics.md, \"Limits\")",
            "Device");
  AddNumber("--max-model-stiffness-n-per-m", max_model_stiffness_n_per_m, "K",
            "local-model: a contact stiffer than K N/m is rendered as the same wall made softer, at the "
            "same place; friction's lateral spring is capped to K too (default 3000, what the device "
            "renders stably)",
            "Device", 0, HUGE_VAL, true);
}

CLI::Option* CommandLine::AddDuration(double* seconds, const std::string& help) {
  // At most 10^6 s (11.6 days): a tick count of 1 kHz runs fits an int32 (2.2e6 s overflowed
  // it: "the number of ticks must be positive"; 1e10 s made the recorder stop at once). At
  // least one 1 kHz tick (0.0001 s passed here and failed later with that same message).
  return AddNumber("--duration-s", seconds, "S", help, "Run", 1e-3, kMaxDurationS);
}

CLI::Option* CommandLine::AddSecurity(std::string* dir, const std::string& who) {
  metavars_["--security"] = "DIR";
  const CLI::Validator not_empty(
      [](std::string& text) -> std::string {
        if (text.empty()) throw InputError("--security needs the deployment's folder (leave it out for no security)");
        return "";
      },
      "");
  return app_.add_option("--security", *dir,
                         "secured DDS (authentication, access control, encryption) with the deployment made by "
                         "scripts/dds-security init DIR; this tool runs as " + who + " (docs/security.md)")
      ->check(not_empty)  // ("" ran unsecured without a word: an unset $DIR turned security off)
      ->group(kGroupDds);
}

CLI::Option* CommandLine::AddWorkspace(double* metres, const std::string& help) {
  return AddNumber("--workspace-m", metres, "X", help, "Pose checks", 0, HUGE_VAL, true);
}

CLI::Option* CommandLine::AddMaxJump(double* metres, const std::string& help) {
  // At most 1 m per pose: "--max-jump-m 2", meant as 2 mm, passed silently (a helper session).
  return AddNumber("--max-jump-m", metres, "X", help + " (in metres, at most 1)", "Pose checks", 0, 1.0, true);
}

void CommandLine::AddMultirate(int* physics_every, double* max_model_distance_m) {
  AddInteger("--physics-every", physics_every, "K",
             "multirate: a contact step on at least every K-th pose; a pose between, within --model-distance-m "
             "of the last step's pose, is answered by that step's contacts solved again at the pose (in "
             "contact), or zero while no gap can have closed (apart), and stepped otherwise; the device "
             "turning gets a step at the turning pose. Fewer steps for a force error measured in "
             "docs/load-and-network.md, \"Multirate\" (default 1: a step on every pose)",
             "Multirate", 1, 1000);
  // At most 2 mm (the server's default jump limit): the frozen contacts do not follow the
  // geometry, and at 0.1 m with K = 1000 the answers were 89-136 % of the peak off.
  AddNumber("--model-distance-m", max_model_distance_m, "X",
            "with --physics-every K > 1: a pose farther than X m from the last step's pose gets a step "
            "(default 5e-4, at most 2e-3: the answers do not follow the geometry beyond the last step)",
            "Multirate", 0, 2e-3);
  multirate_physics_every_ = physics_every;
}

std::vector<std::string> NearMisses(const std::string& given, const std::vector<NearMissCandidate>& known) {
  const auto lower = [](std::string text) {
    for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return text;
  };
  const auto edit_distance = [](const std::string& a, const std::string& b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
      size_t diagonal = row[0];
      row[0] = i;
      for (size_t j = 1; j <= b.size(); ++j) {
        const size_t substitution = diagonal + (a[i - 1] == b[j - 1] ? 0 : 1);
        diagonal = row[j];
        row[j] = std::min({row[j] + 1, row[j - 1] + 1, substitution});
      }
    }
    return row[b.size()];
  };
  // "--duration" for "--duration-s": a name is also matched without its unit.
  const auto without_unit = [](const std::string& name) {
    for (const char* unit : {"-pct", "-ms", "-s", "-m"}) {
      const std::string suffix(unit);
      if (name.size() > suffix.size() + 3 && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
        return name.substr(0, name.size() - suffix.size());
      }
    }
    return name;
  };
  // "--no-x" for "--x" (or back) means the opposite: never a hint (--no-overwrite -> --overwrite).
  const auto opposite = [](const std::string& a, const std::string& b) {
    return a == "--no-" + b.substr(std::min<size_t>(2, b.size())) || b == "--no-" + a.substr(std::min<size_t>(2, a.size()));
  };
  const std::string typed = lower(given);
  if (typed.rfind("--", 0) != 0 || typed.size() < 3) return {};
  std::vector<std::string> beginning, closest;
  const size_t allowed = std::max<size_t>(1, typed.size() / 4);  // edits
  size_t best = allowed + 1;
  // "--" alone or "--x" begins too many options to say anything useful.
  const bool long_enough = typed.size() >= 5;
  for (const NearMissCandidate& candidate : known) {
    const std::string spelling = lower(candidate.spelling);
    if (candidate.spelling == given || spelling.rfind("--", 0) != 0 || opposite(typed, spelling)) continue;
    if (long_enough && spelling.rfind(typed, 0) == 0) beginning.push_back(candidate.suggestion);
    const size_t distance = std::min(edit_distance(typed, spelling), edit_distance(typed, without_unit(spelling)));
    if (distance > allowed) continue;
    if (distance < best) {
      best = distance;
      closest = {candidate.suggestion};
    } else if (distance == best) {
      closest.push_back(candidate.suggestion);
    }
  }
  std::vector<std::string>& misses = beginning.empty() ? closest : beginning;
  std::sort(misses.begin(), misses.end());
  misses.erase(std::unique(misses.begin(), misses.end()), misses.end());
  if (misses.size() > 3) misses.clear();  // too many to be a hint
  return misses;
}

std::string CommandLine::UnknownOptionMessage(const std::string& argument) const {
  const std::string given = argument.substr(0, argument.find('='));
  std::vector<NearMissCandidate> known;
  for (const CLI::Option* option : app_.get_options()) {
    for (const std::string& name : option->get_lnames()) known.push_back({"--" + name, "--" + name});
  }
  // An old spelling's typo is a miss of its current name (--recrod: --output).
  for (const auto& [old_name, current] : deprecated_) {
    if (!current.empty()) known.push_back({old_name, current});
  }
  const std::vector<std::string> misses = NearMisses(given, known);
  if (misses.empty()) return "unknown option " + given + " (see --help)";
  std::string hint;
  for (size_t k = 0; k < misses.size(); ++k) {
    hint += (k == 0 ? "" : (k + 1 == misses.size() ? " or " : ", ")) + misses[k];
  }
  return "unknown option " + given + " (did you mean " + hint + "? see --help)";
}

void CommandLine::Deprecate(const std::string& old_name, const std::string& current_name) {
  deprecated_[old_name] = current_name;
}

bool CommandLine::Parse(int argc, char** argv) {
  std::vector<std::string> arguments;
  for (int k = 1; k < argc; ++k) arguments.emplace_back(argv[k]);
  return Parse(std::move(arguments));
}

bool CommandLine::Parse(std::vector<std::string> arguments) {
  // Old spellings first (never after "--", which ends the options).
  std::vector<std::string> rewritten;
  bool options_ended = false;
  for (const std::string& argument : arguments) {
    if (argument == "--" && !options_ended) {
      // Ends the options (POSIX). CLI11, as set up here, left it over as an unknown option; what
      // follows is still read by the parser, so an argument after it that starts with '-' is
      // taken as an option (none of HapCo's positionals needs that).
      options_ended = true;
      continue;
    }
    if (!options_ended) {
      const std::string name = argument.substr(0, argument.find('='));
      const auto old = deprecated_.find(name);
      if (old != deprecated_.end()) {
        const std::string& current = old->second;
        if (current.empty()) {
          std::fprintf(stderr, "%s: note: %s is deprecated: give the file as an argument (see --help)\n",
                       tool_.c_str(), name.c_str());
          if (name.size() < argument.size()) rewritten.push_back(argument.substr(name.size() + 1));
        } else {
          std::fprintf(stderr, "%s: note: %s is deprecated, use %s (same meaning)\n", tool_.c_str(), name.c_str(),
                       current.c_str());
          rewritten.push_back(current + argument.substr(name.size()));
        }
        continue;
      }
    }
    rewritten.push_back(argument);
  }
  std::reverse(rewritten.begin(), rewritten.end());  // CLI11 takes the arguments reversed
  try {
    app_.parse(rewritten);
  } catch (const CLI::CallForHelp&) {
    std::fputs(Help().c_str(), stdout);
    return false;
  } catch (const CLI::CallForVersion& version) {
    std::printf("%s\n", version.what());
    return false;
  } catch (const CompletionRequested&) {
    std::fputs(BashCompletion().c_str(), stdout);
    return false;
  } catch (const CLI::ExtrasError&) {
    const std::vector<std::string> extra = app_.remaining();
    const std::string first = extra.empty() ? std::string("?") : extra.front();
    if (!first.empty() && first[0] == '-') throw InputError(UnknownOptionMessage(first));
    throw InputError("unexpected argument " + Quoted(first) + " (see --help)");
  } catch (const CLI::RequiredError& error) {
    // CLI11 checks requirements before extras: an unknown option is the better message
    // ("hapco-sim --bogus" is a typo, not a missing scene).
    for (const std::string& extra : app_.remaining()) {
      if (!extra.empty() && extra[0] == '-') throw InputError(UnknownOptionMessage(extra));
    }
    const std::string what = error.what();
    for (const CLI::Option* option : app_.get_options()) {
      if (option->get_positional() && option->get_required() && option->count() == 0) {
        throw InputError("missing " + option->get_name(true) + " argument (see --help)");
      }
    }
    throw InputError(what + " (see --help)");
  } catch (const CLI::ArgumentMismatch& error) {
    // "--steps: 1 required INT missing" and the like: a flag at the end without its value.
    std::string what = error.what();
    const size_t colon = what.find(':');
    if (colon != std::string::npos && what.rfind("--", 0) == 0) what = what.substr(0, colon) + " needs a value";
    throw InputError(what + " (see --help)");
  } catch (const CLI::ParseError& error) {
    throw InputError(std::string(error.what()) + " (see --help)");
  }
  CheckOutputsAreNotInputs();
  if (multirate_physics_every_ != nullptr && *multirate_physics_every_ == 1 && app_.count("--model-distance-m") > 0) {
    std::fprintf(stderr, "%s: note: --model-distance-m has no effect without --physics-every K > 1 (every pose is stepped)\n",
                 tool_.c_str());
  }
  return true;
}

std::string CommandLine::Help() const {
  std::string out = "usage: " + tool_ + " " + synopsis_ + "\n";
  if (!description_.empty()) out += "\n" + WrapText(description_, kHelpWidth, 0, 0) + "\n";
  // Groups in order of first appearance, General last; hidden options (no group) skipped.
  std::vector<std::string> groups;
  for (const CLI::Option* option : app_.get_options()) {
    const std::string& group = option->get_group();
    if (group.empty() || group == kGroupGeneral) continue;
    if (std::find(groups.begin(), groups.end(), group) == groups.end()) groups.push_back(group);
  }
  // Positional arguments first.
  std::stable_partition(groups.begin(), groups.end(), [](const std::string& g) { return g == "Arguments"; });
  groups.push_back(kGroupGeneral);
  for (const std::string& group : groups) {
    out += "\n" + group + ":\n";
    // The tool's own options first; in General, --help, --version and --bash-completion last.
    std::vector<const CLI::Option*> listed;
    for (const CLI::Option* option : app_.get_options()) {
      if (option->get_group() == group) listed.push_back(option);
    }
    std::stable_partition(listed.begin(), listed.end(), [](const CLI::Option* option) {
      const std::string name = option->get_name();
      return name != "--help" && name != "--version" && name != "--bash-completion";
    });
    for (const CLI::Option* option : listed) {
      std::string left = "  " + DisplayNames(*option);
      const auto metavar = metavars_.find(option->get_name());
      if (!option->get_positional() && metavar != metavars_.end() && !metavar->second.empty()) {
        left += " " + metavar->second;
      }
      if (static_cast<int>(left.size()) + 2 > kHelpOptionColumn) {
        left += "  ";
      } else {
        left.resize(kHelpOptionColumn, ' ');
      }
      out += left + WrapText(option->get_description(), kHelpWidth, kHelpOptionColumn,
                             static_cast<int>(left.size())) + "\n";
    }
  }
  if (!footer_.empty()) out += "\n" + WrapText(footer_, kHelpWidth, 0, 0) + "\n";
  return out;
}

std::string CommandLine::BashCompletion() const {
  std::string function = "_" + tool_;
  std::replace(function.begin(), function.end(), '-', '_');
  std::vector<std::string> flags, files, dirs, values;
  std::string choice_cases;
  for (const CLI::Option* option : app_.get_options()) {
    if (option->get_positional()) continue;
    std::vector<std::string> names;
    for (const std::string& name : option->get_lnames()) names.push_back("--" + name);
    for (const std::string& name : option->get_snames()) names.push_back("-" + name);
    if (!option->get_group().empty()) {
      for (const std::string& name : option->get_lnames()) flags.push_back("--" + name);
    }
    if (option->get_expected_max() == 0) continue;  // a flag: no value
    const std::string key = option->get_name();
    const auto choices = choices_.find(key);
    const auto metavar = metavars_.find(key);
    if (choices != choices_.end()) {
      choice_cases += "    " + Join(names, "|") + ") COMPREPLY=($(compgen -W \"" + Join(choices->second, " ") +
                      "\" -- \"$cur\")); return ;;\n";
    } else if (metavar != metavars_.end() && metavar->second == "DIR") {
      dirs.insert(dirs.end(), names.begin(), names.end());
    } else if (metavar != metavars_.end() && metavar->second.find("FILE") != std::string::npos) {
      files.insert(files.end(), names.begin(), names.end());
    } else {
      values.insert(values.end(), names.begin(), names.end());
    }
  }
  std::string out = "# bash completion for " + tool_ + " (generated by " + tool_ + " --bash-completion)\n";
  out += function + "() {\n";
  out += "  local cur=\"${COMP_WORDS[COMP_CWORD]}\" prev=\"${COMP_WORDS[COMP_CWORD-1]}\"\n";
  out += "  case \"$prev\" in\n" + choice_cases;
  if (!files.empty()) out += "    " + Join(files, "|") + ") COMPREPLY=($(compgen -f -- \"$cur\")); return ;;\n";
  if (!dirs.empty()) out += "    " + Join(dirs, "|") + ") COMPREPLY=($(compgen -d -- \"$cur\")); return ;;\n";
  if (!values.empty()) out += "    " + Join(values, "|") + ") COMPREPLY=(); return ;;\n";
  out += "  esac\n";
  out += "  if [[ \"$cur\" == -* ]]; then\n";
  out += "    COMPREPLY=($(compgen -W \"" + Join(flags, " ") + "\" -- \"$cur\"))\n";
  out += "  else\n    COMPREPLY=($(compgen -f -- \"$cur\"))\n  fi\n}\n";
  out += "complete -o filenames -F " + function + " " + tool_ + "\n";
  return out;
}

}  // namespace hapco::cli
