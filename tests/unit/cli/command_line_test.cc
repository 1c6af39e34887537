#include "cli/command_line.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "common/error.h"

namespace hapco::cli {
namespace {

// A small tool with one option of each kind, as the executables define them.
struct ToyOptions {
  std::string scene, output, solver = "reference", security;
  double tol = 1e-6, duration_s = 1;
  int steps = 0, domain = 0;
  bool quiet = false;
};

// A CommandLine keeps pointers to the options, so it is built in place.
#define TOY_COMMAND(command) CommandLine command("hapco-toy", "SCENE [options]", "A toy tool.", "Exit code: 0.")

void DefineToy(CommandLine& command, ToyOptions* options) {
  command.AddScene(&options->scene);
  command.AddDomain(&options->domain);
  command.AddOutput(&options->output, "where to write");
  command.AddSolver(&options->solver, "reference");
  command.AddNumber("--tol", &options->tol, "X", "tolerance", "Solver", 0, HUGE_VAL, true);
  command.AddInteger("--steps", &options->steps, "N", "steps", "Run", 1, 100);
  command.AddDuration(&options->duration_s, "how long");
  command.AddQuiet(&options->quiet, "no progress");
  command.AddSecurity(&options->security, "a toy");
  command.Deprecate("--record", "--output");
  command.Deprecate("--scene", "");
}

std::string ErrorOf(const std::vector<std::string>& arguments) {
  ToyOptions options;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  try {
    (void)command.Parse(arguments);
  } catch (const InputError& error) {
    return error.what();
  }
  return "";
}

TEST(CommandLineTest, AcceptsGoodValues) {
  ToyOptions options;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  ASSERT_TRUE(command.Parse({"scene.txtpb", "--tol", "1e-3", "--steps=7", "-o", "out.rec", "--solver",
                             "local-uzawa", "--duration-s", "2.5", "--quiet", "--steps", "9"}));
  EXPECT_EQ(options.scene, "scene.txtpb");
  EXPECT_DOUBLE_EQ(options.tol, 1e-3);
  EXPECT_EQ(options.steps, 9);  // the last one wins
  EXPECT_EQ(options.output, "out.rec");
  EXPECT_EQ(options.solver, "local-uzawa");
  EXPECT_DOUBLE_EQ(options.duration_s, 2.5);
  EXPECT_TRUE(options.quiet);
}

// An output folder is kept without trailing slashes (the tools append "/file": a helper saw
// "charts//steps.csv").
TEST(CommandLineTest, AnOutputFolderLosesItsTrailingSlashes) {
  std::string dir;
  CommandLine command("hapco-toy", "[options]", "A toy tool.", "Exit code: 0.");
  command.AddOutputDirectory("--plots", &dir, "DIR", "charts here", "Output");
  const std::string tmp = ::testing::TempDir();
  ASSERT_TRUE(command.Parse(std::vector<std::string>{"--plots", tmp + "/charts//"}));
  EXPECT_EQ(dir, tmp + "/charts");
}

TEST(CommandLineTest, BadInputNamesTheOptionAndTheRange) {
  EXPECT_EQ(ErrorOf({"s", "--steps", "banana"}), "--steps expects an integer in [1, 100], got 'banana'");
  EXPECT_EQ(ErrorOf({"s", "--steps", "101"}), "--steps expects an integer in [1, 100], got '101'");
  EXPECT_EQ(ErrorOf({"s", "--steps", "3.5"}), "--steps expects an integer in [1, 100], got '3.5'");
  EXPECT_EQ(ErrorOf({"s", "--tol", "nan"}), "--tol expects a number, got 'nan'");
  EXPECT_EQ(ErrorOf({"s", "--tol", "0"}), "--tol expects a number > 0, got '0'");
  EXPECT_EQ(ErrorOf({"s", "--duration-s", "-5"}), "--duration-s expects a number in [0.001, 1e+06], got '-5'");
  // Beyond 10^6 s a 1 kHz tick count overflowed (2.2e6 s: "the number of ticks must be positive"),
  // and below one tick there was no tick (0.0001 s: the same message, later).
  EXPECT_EQ(ErrorOf({"s", "--duration-s", "2.2e6"}), "--duration-s expects a number in [0.001, 1e+06], got '2.2e6'");
  EXPECT_EQ(ErrorOf({"s", "--duration-s", "0.0001"}), "--duration-s expects a number in [0.001, 1e+06], got '0.0001'");
  // An empty --security ran unsecured without a word (an unset $DIR; a helper session).
  EXPECT_EQ(ErrorOf({"s", "--security", ""}), "--security needs the deployment's folder (leave it out for no security)");
  // "--" ends the options (it was "unknown option --").
  EXPECT_EQ(ErrorOf({"--steps", "3", "--", "s"}), "");
  EXPECT_EQ(ErrorOf({"s", "--domain", "231"}), "--domain expects an integer in [0, 230], got '231'");
  EXPECT_EQ(ErrorOf({"s", "--solver", "newton"}),
            "--solver expects local-uzawa | global-uzawa-gs | global-uzawa-jacobi | reference, got 'newton'");
  EXPECT_EQ(ErrorOf({"s", "--bogus"}), "unknown option --bogus (see --help)");
  EXPECT_EQ(ErrorOf({"s", "extra"}), "unexpected argument 'extra' (see --help)");
  // A near miss names what was probably meant (a helper typed the scripts' --duration).
  EXPECT_EQ(ErrorOf({"s", "--duration", "3"}), "unknown option --duration (did you mean --duration-s? see --help)");
  EXPECT_EQ(ErrorOf({"s", "--dur=3"}), "unknown option --dur (did you mean --duration-s? see --help)");
  EXPECT_EQ(ErrorOf({"s", "--ouput", "x"}), "unknown option --ouput (did you mean --output? see --help)");
  EXPECT_EQ(ErrorOf({"--stepz", "3", "s"}), "unknown option --stepz (did you mean --steps? see --help)");
  EXPECT_EQ(ErrorOf({"--steps", "3"}), "missing SCENE argument (see --help)");
  EXPECT_EQ(ErrorOf({"s", "--steps"}), "--steps needs a value (see --help)");
}

// Output paths are checked when the command line is read: hapco-sim --output DIR ran the whole
// simulation, then failed to rename its partial file and left it behind; "" meant "no file"
// in some tools and was refused in others.
// hapco-recorder s.txtpb --output s.txtpb wrote its recording over the scene the server ran;
// hapco-sim --trajectory t.csv --csv t.csv over the trajectory it was reading (a helper session).
TEST(CommandLineTest, AnOutputThatIsAlsoAnInputOrAnotherOutputIsRefused) {
  const std::string dir = ::testing::TempDir();
  const std::string scene = dir + "/hapco_cli_scene.txtpb";
  std::FILE* file = std::fopen(scene.c_str(), "w");
  ASSERT_NE(file, nullptr);
  std::fclose(file);
  EXPECT_EQ(ErrorOf({scene, "-o", scene}),
            "--output " + scene + " is also the input SCENE: writing it would destroy the input; give another file");
  // The same file by another path.
  EXPECT_EQ(ErrorOf({scene, "-o", dir + "/./hapco_cli_scene.txtpb"}),
            "--output " + dir + "/./hapco_cli_scene.txtpb is also the input SCENE: writing it would destroy the "
            "input; give another file");
  // Two outputs on one file clash before either exists.
  ToyOptions options;
  std::string csv;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  command.AddCsv(&csv, "a table");
  const std::string out = dir + "/hapco_cli_not_yet.rec";
  try {
    (void)command.Parse({scene, "-o", out, "--csv", out});
    ADD_FAILURE() << "two outputs on one file were accepted";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("is also the file of"), std::string::npos) << error.what();
  }
  EXPECT_EQ(ErrorOf({scene, "-o", dir + "/hapco_cli_other.rec"}), "");
  EXPECT_EQ(ErrorOf({scene, "-o", "/dev/null"}), "") << "a device is no input to destroy";
  std::remove(scene.c_str());
}

// An input among the files an output folder gets is refused (hapco-loadtest --trajectory
// DIR/ticks-lt-1.csv --csv-dir DIR overwrote its trajectory; hapco-report DIR/steps.csv --plots DIR).
TEST(CommandLineTest, AnInputAmongTheFilesAnOutputFolderWritesIsRefused) {
  const std::string dir = ::testing::TempDir() + "/hapco_cli_folder";
  std::filesystem::create_directories(dir);
  const std::string input = dir + "/steps.csv";
  std::FILE* file = std::fopen(input.c_str(), "w");
  ASSERT_NE(file, nullptr);
  std::fclose(file);
  const auto error_of = [&](const std::vector<std::string>& arguments) -> std::string {
    std::string scene, plots;
    CommandLine command("hapco-toy", "SCENE [options]", "A toy tool.", "Exit code: 0.");
    command.AddScene(&scene);
    command.WritesInto(command.AddOutputDirectory("--plots", &plots, "DIR", "charts", "Output"), {"steps.csv", "*.png"});
    try {
      (void)command.Parse(arguments);
    } catch (const InputError& error) {
      return error.what();
    }
    return "";
  };
  EXPECT_EQ(error_of({input, "--plots", dir}), "SCENE " + input + " is a file --plots " + dir +
                                                   " writes (steps.csv): writing it would destroy the input; give "
                                                   "another folder");
  EXPECT_EQ(error_of({input, "--plots", dir + "/charts"}), "") << "another folder";
  // A short option's value after '=' is refused with the spelling meant ("-o=x.rec" wrote "=x.rec").
  EXPECT_EQ(ErrorOf({"s", "-o=x.rec"}), "--output: the file name '=x.rec' starts with '=': write -o x.rec or --output=x.rec");
  std::filesystem::remove_all(dir);
}

// A required output has no "leave the option out" (hapco-recorder --output "" said so).
TEST(CommandLineTest, ARequiredOutputNeedsAFileName) {
  std::string output;
  CommandLine command("hapco-toy", "[options]", "A toy tool.", "Exit code: 0.");
  command.AddOutput(&output, "the recording")->required();
  try {
    (void)command.Parse(std::vector<std::string>{"--output", ""});
    ADD_FAILURE() << "an empty required output was accepted";
  } catch (const InputError& error) {
    EXPECT_EQ(std::string(error.what()), "--output needs a file name");
  }
}

TEST(CommandLineTest, NearMissesAreBeginningsOrWithinAQuarterOfTheLength) {
  std::vector<NearMissCandidate> known;
  for (const char* name : {"--max-iter", "--max-jump-m", "--mu", "--output", "--quiet", "-o", "--duration-s",
                           "--version", "--overwrite", "--no-local-model", "--vtk"}) {
    known.push_back({name, name});
  }
  known.push_back({"--record", "--output"});  // an old spelling
  const auto misses = [&](const std::string& given) { return NearMisses(given, known); };
  using Names = std::vector<std::string>;
  EXPECT_EQ(misses("--max"), (Names{"--max-iter", "--max-jump-m"}));
  EXPECT_EQ(misses("--max-jump"), (Names{"--max-jump-m"}));
  EXPECT_EQ(misses("--outptu"), (Names{"--output"}));  // 2 edits in 9
  EXPECT_EQ(misses("--qiet"), (Names{"--quiet"}));
  EXPECT_EQ(misses("--QUIET"), (Names{"--quiet"})) << "case is ignored";
  // Without its unit, --duration-s is one edit from --durtion (--version is three: no hint).
  EXPECT_EQ(misses("--durtion"), (Names{"--duration-s"}));
  EXPECT_EQ(misses("--recrod"), (Names{"--output"})) << "an old spelling's typo gets the current name";
  EXPECT_TRUE(misses("--no-overwrite").empty()) << "the opposite is no hint";
  EXPECT_TRUE(misses("--local-model").empty()) << "the opposite is no hint";
  // A candidate exactly at the limit was suggested without being near (a helper saw
  // "--to: did you mean --mu or --vtk?").
  EXPECT_EQ(misses("--to"), Names{});  // 2 edits from --mu and --vtk
  EXPECT_EQ(misses("--m"), (Names{"--mu"}));  // 1 edit
  EXPECT_TRUE(misses("--bogus").empty());
  EXPECT_TRUE(misses("--output").empty()) << "a known option is no miss";
  EXPECT_TRUE(misses("-O").empty()) << "short options are not guessed";
  EXPECT_TRUE(NearMisses("--", {{"--a1", "--a1"}, {"--a2", "--a2"}, {"--a3", "--a3"}, {"--a4", "--a4"}}).empty());
}

TEST(CommandLineTest, OutputPathsAndEmptyValuesAreCheckedBeforeAnyWork) {
  const std::string dir = ::testing::TempDir();
  EXPECT_EQ(ErrorOf({"s", "-o", dir}), "--output: " + dir + " is a directory");
  EXPECT_EQ(ErrorOf({"s", "-o", dir + "/no-such-folder/out.rec"}),
            "--output: the folder " + dir + "/no-such-folder of " + dir + "/no-such-folder/out.rec does not exist");
  EXPECT_EQ(ErrorOf({"s", "-o", ""}), "--output needs a file name (leave the option out for no file)");
  EXPECT_EQ(ErrorOf({"s", "-o", dir + "/out.rec"}), "");
  EXPECT_EQ(ErrorOf({"s", "-o", "/dev/null"}), "") << "an existing writable file is fine wherever it is";
  // Text and folders.
  ToyOptions options;
  std::string name, folder;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  command.AddText("--name", &name, "ID", "a name", "Run");
  command.AddOutputDirectory("--plots", &folder, "DIR", "charts", "Output");
  const auto error_of = [&](const std::vector<std::string>& arguments) -> std::string {
    try {
      (void)command.Parse(arguments);
    } catch (const InputError& error) {
      return error.what();
    }
    return "";
  };
  EXPECT_EQ(error_of({"s", "--name", ""}), "--name needs a value (leave the option out for its default)");
  EXPECT_EQ(error_of({"s", "--plots", dir + "/new/deeper"}), "") << "made when needed";
  EXPECT_EQ(error_of({"s", "--plots", "/dev/null/charts"}),
            "--plots: /dev/null is not a folder (the output folder /dev/null/charts cannot be made there)");
}

TEST(CommandLineTest, OldSpellingsKeepWorkingWithANote) {
  ToyOptions options;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  testing::internal::CaptureStderr();
  ASSERT_TRUE(command.Parse({"--record=old.rec", "--scene", "scene.txtpb"}));
  const std::string notes = testing::internal::GetCapturedStderr();
  EXPECT_EQ(options.output, "old.rec");
  EXPECT_EQ(options.scene, "scene.txtpb");
  EXPECT_NE(notes.find("hapco-toy: note: --record is deprecated, use --output"), std::string::npos) << notes;
  EXPECT_NE(notes.find("--scene is deprecated: give the file as an argument"), std::string::npos) << notes;
}

TEST(CommandLineTest, MultirateDistanceIsBoundedAndNotedWhenItHasNoEffect) {
  const auto parse = [](const std::vector<std::string>& arguments, int* every, double* distance, std::string* notes) {
    TOY_COMMAND(command);
    command.AddMultirate(every, distance);
    testing::internal::CaptureStderr();
    try {
      (void)command.Parse(arguments);
    } catch (const InputError& error) {
      *notes = testing::internal::GetCapturedStderr();
      return std::string(error.what());
    }
    *notes = testing::internal::GetCapturedStderr();
    return std::string();
  };
  int every = 1;
  double distance = 5e-4;
  std::string notes;
  EXPECT_EQ(parse({"--model-distance-m", "1e-3"}, &every, &distance, &notes), "");
  EXPECT_DOUBLE_EQ(distance, 1e-3);
  EXPECT_NE(notes.find("hapco-toy: note: --model-distance-m has no effect without --physics-every K > 1"),
            std::string::npos)
      << notes;
  EXPECT_EQ(parse({"--physics-every", "8", "--model-distance-m", "2e-3"}, &every, &distance, &notes), "");
  EXPECT_EQ(every, 8);
  EXPECT_EQ(notes, "") << "a distance with K > 1 is what it is for";
  EXPECT_EQ(parse({"--physics-every", "8", "--model-distance-m", "0.01"}, &every, &distance, &notes),
            "--model-distance-m expects a number in [0, 0.002], got '0.01'");
}

TEST(CommandLineTest, HelpIsGroupedAndVersionIsListed) {
  ToyOptions options;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  const std::string help = command.Help();
  EXPECT_EQ(help.rfind("usage: hapco-toy SCENE [options]\n", 0), 0u) << help;
  const size_t arguments = help.find("\nArguments:\n  SCENE");
  const size_t dds = help.find("\nDDS:\n  --domain N");
  const size_t solver = help.find("\nSolver:\n");
  const size_t general = help.find("\nGeneral:\n");
  ASSERT_NE(arguments, std::string::npos) << help;
  ASSERT_NE(dds, std::string::npos) << help;
  ASSERT_NE(solver, std::string::npos) << help;
  ASSERT_NE(general, std::string::npos) << help;
  EXPECT_LT(arguments, dds);
  EXPECT_LT(solver, general);
  EXPECT_NE(help.find("  -o, --output FILE"), std::string::npos) << help;
  EXPECT_NE(help.find("  --version             the HapCo version"), std::string::npos) << help;
  EXPECT_EQ(help.find("--record"), std::string::npos) << "deprecated spellings are not advertised";
  // Wrapped to the help width.
  std::size_t start = 0;
  while (start < help.size()) {
    const std::size_t end = help.find('\n', start);
    EXPECT_LE(std::min(end, help.size()) - start, 96u) << help.substr(start, end - start);
    start = end == std::string::npos ? help.size() : end + 1;
  }
}

TEST(CommandLineTest, HelpAndVersionEndTheRunWithoutCheckingRequiredArguments) {
  for (const char* flag : {"--help", "--version", "--bash-completion"}) {
    ToyOptions options;
    TOY_COMMAND(command);
  DefineToy(command, &options);
    testing::internal::CaptureStdout();
    EXPECT_FALSE(command.Parse({flag})) << flag;
    EXPECT_FALSE(testing::internal::GetCapturedStdout().empty()) << flag;
  }
}

TEST(CommandLineTest, BashCompletionCompletesFlagsChoicesAndFiles) {
  ToyOptions options;
  TOY_COMMAND(command);
  DefineToy(command, &options);
  const std::string script = command.BashCompletion();
  EXPECT_NE(script.find("complete -o filenames -F _hapco_toy hapco-toy"), std::string::npos) << script;
  EXPECT_NE(script.find("--solver) COMPREPLY=($(compgen -W \"local-uzawa global-uzawa-gs"), std::string::npos)
      << script;
  EXPECT_NE(script.find("--output|-o) COMPREPLY=($(compgen -f"), std::string::npos) << script;
  EXPECT_NE(script.find("--duration-s"), std::string::npos) << script;
  EXPECT_EQ(script.find("--record"), std::string::npos) << script;
  // A flag takes no value: after it, file names complete again.
  EXPECT_EQ(script.find("--quiet)"), std::string::npos) << script;
  EXPECT_EQ(script.find("--quiet|"), std::string::npos) << script;
  EXPECT_EQ(script.find("|--quiet"), std::string::npos) << script;
}

TEST(CommandLineTest, AnUnknownOptionIsReportedBeforeAMissingArgument) {
  EXPECT_EQ(ErrorOf({"--bogus"}), "unknown option --bogus (see --help)");
}

TEST(WrapTextTest, WrapsAtTheWidthAndKeepsExplicitLines) {
  EXPECT_EQ(WrapText("aaa bbb ccc", 7, 2, 0), "aaa bbb\n  ccc");
  EXPECT_EQ(WrapText("one\ntwo", 80, 4, 0), "one\n    two");
}

}  // namespace
}  // namespace hapco::cli
