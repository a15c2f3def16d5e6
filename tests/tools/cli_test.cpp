// Every program's command line behaves the same (tarmac::cli, config/.../cli.hpp): --help prints
// the usage on stdout and exits 0, --version prints "<program> <version>", an unknown option is
// named on stderr with exit 64 (EX_USAGE), `--opt=value` is read as `--opt value`, and a value that
// is not a number for a numeric option exits 64 naming the option. The programs run as processes;
// every case stops before DDS or real data are touched.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

struct Outcome {
  int exit_code = -1;  ///< -1: ended by a signal, -2: killed after the timeout
  std::string out, err;
};

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Runs `args` (args[0] the program), stdout and stderr kept apart, in `dir`.
Outcome run(const std::vector<std::string>& args, const fs::path& dir) {
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const pid_t pid = fork();
  if (pid == 0) {
    freopen(out.c_str(), "w", stdout);
    freopen(err.c_str(), "w", stderr);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  Outcome r;
  int status = 0;
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (waitpid(pid, &status, WNOHANG) != pid) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      r.exit_code = -2;
      break;
    }
    std::this_thread::sleep_for(10ms);
  }
  if (r.exit_code != -2 && WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
  r.out = read_text(out);
  r.err = read_text(err);
  return r;
}

/// One program and the arguments of its cases. "{empty}" stands for an empty directory, "{tmp}"
/// for a scratch directory (both made per test).
struct Program {
  std::string name = {}, path = {};
  std::vector<std::string> required = {};  ///< valid values for its required options
  bool runs_without_arguments = true;      ///< false: no arguments is a usage error
  /// Options in the `--opt=value` form, and the exit code of the run they give: past the command
  /// line, so a data, config or DDS error, or 0.
  std::vector<std::string> equals_form = {};
  int equals_exit = 0;
  std::string numeric_option = {};  ///< takes a number; empty when the program has none
};

void PrintTo(const Program& program, std::ostream* out) {
  *out << program.name;
}

const std::vector<Program>& programs() {
  static const std::vector<Program> all = {
      // Either --config or --check-config.
      {.name = "tarmacd",
       .path = TARMAC_TARMACD,
       .runs_without_arguments = false,
       .equals_form = {"--check-config=" TARMAC_SOURCE_DIR "/config/tarmac.yaml"}},
      // An empty directory is no dataset: exit 65 (EX_DATAERR).
      {.name = "tarmac-map",
       .path = TARMAC_MAP,
       .required = {"--dataset", "{empty}"},
       .runs_without_arguments = false,
       .equals_form = {"--dataset={empty}", "--threads=2", "--out={tmp}/map"},
       .equals_exit = 65,
       .numeric_option = "--threads"},
      {.name = "tarmac-bench",
       .path = TARMAC_BENCH,
       .required = {"--dataset", "{empty}"},
       .runs_without_arguments = false,
       .equals_form = {"--dataset={empty}", "--threads=2", "--window=40,40,8"},
       .equals_exit = 65,
       .numeric_option = "--threads"},
      // Security material missing: refused before any DDS entity exists, exit 69.
      {.name = "tarmac-dds-bench",
       .path = TARMAC_DDS_BENCH,
       .equals_form = {"--security={empty}", "--points=16"},
       .equals_exit = 69,
       .numeric_option = "--points"},
      {.name = "tarmac-sim",
       .path = TARMAC_SIM,
       .required = {"--out", "{tmp}/sim"},
       .runs_without_arguments = false,
       .equals_form = {"--out={tmp}/sim", "--scans=1", "--beams=2", "--azimuth-steps=16",
                       "--tilt-deg=-3"},
       .numeric_option = "--scans"},
      {.name = "tarmac-replay",
       .path = TARMAC_REPLAY,
       .required = {"--dataset", "{empty}"},
       .runs_without_arguments = false,
       .equals_form = {"--dataset={empty}", "--rate-scale=2"},
       .equals_exit = 65,
       .numeric_option = "--rate-scale"},
      // --score on a directory without ground truth: exit 65 before DDS.
      {.name = "tarmac-audit",
       .path = TARMAC_AUDIT,
       .equals_form = {"--score={empty}", "--timeout-s=5"},
       .equals_exit = 65,
       .numeric_option = "--timeout-s"},
      // An invalid config: exit 78 (EX_CONFIG) before DDS.
      {.name = "tarmac-echo",
       .path = TARMAC_ECHO,
       .required = {"rt/tarmac/costmap"},
       .runs_without_arguments = false,
       .equals_form = {"rt/tarmac/costmap",
                       "--config=" TARMAC_SOURCE_DIR "/tests/config/bad_unknown_key.yaml"},
       .equals_exit = 78,
       .numeric_option = "--count"},
      // An invalid config: exit 78 before DDS.
      {.name = "tarmac-fleet",
       .path = TARMAC_FLEET,
       .required = {"--out", "{tmp}/site"},
       .runs_without_arguments = false,
       .equals_form = {"--out={tmp}/site",
                       "--config=" TARMAC_SOURCE_DIR "/tests/config/bad_unknown_key.yaml"},
       .equals_exit = 78,
       .numeric_option = "--seconds"},
  };
  return all;
}

class Cli : public ::testing::TestWithParam<Program> {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("tarmac-cli-" + std::to_string(getpid()) + "-" + GetParam().name);
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "empty");
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// The program with `args`, placeholders replaced.
  Outcome run_with(std::vector<std::string> args) {
    for (auto& a : args) {
      for (const auto& [key, value] :
           {std::pair<std::string, std::string>{"{empty}", (dir_ / "empty").string()},
            {"{tmp}", dir_.string()}}) {
        if (const auto at = a.find(key); at != std::string::npos) a.replace(at, key.size(), value);
      }
    }
    args.insert(args.begin(), GetParam().path);
    return run(args, dir_);
  }

  fs::path dir_;
};

TEST_P(Cli, Help_UsageOnStdoutExit0) {
  const Outcome r = run_with({"--help"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("Usage: " + GetParam().name), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--version"), std::string::npos) << r.out;
  EXPECT_EQ(r.err, "");
}

TEST_P(Cli, Version_NameAndVersionOnStdoutExit0) {
  const Outcome r = run_with({"--version"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, GetParam().name + " " TARMAC_VERSION "\n");
}

TEST_P(Cli, UnknownOption_NamedOnStderrExit64) {
  std::vector<std::string> args = GetParam().required;
  args.push_back("--no-such-option");
  const Outcome r = run_with(args);
  EXPECT_EQ(r.exit_code, 64);
  EXPECT_NE(r.err.find("--no-such-option"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--help"), std::string::npos) << r.err;  // the hint
  EXPECT_EQ(r.out, "");
}

TEST_P(Cli, EqualsForm_Accepted) {
  const Outcome r = run_with(GetParam().equals_form);
  EXPECT_EQ(r.exit_code, GetParam().equals_exit) << r.out << r.err;
  EXPECT_EQ(r.err.find("Run with --help"), std::string::npos) << r.err;
}

/// The programs that take a number.
class CliNumeric : public Cli {};

TEST_P(CliNumeric, NotANumber_NamedOnStderrExit64) {
  std::vector<std::string> args = GetParam().required;
  args.insert(args.end(), {GetParam().numeric_option, "abc"});
  const Outcome r = run_with(args);
  EXPECT_EQ(r.exit_code, 64);
  EXPECT_NE(r.err.find(GetParam().numeric_option + ": 'abc' is not"), std::string::npos) << r.err;
}

/// The programs that cannot run without arguments.
class CliRequired : public Cli {};

TEST_P(CliRequired, NoArguments_Exit64) {
  const Outcome r = run_with({});
  EXPECT_EQ(r.exit_code, 64);
  EXPECT_NE(r.err.find("--help"), std::string::npos) << r.err;
}

std::string test_name(const ::testing::TestParamInfo<Program>& info) {
  std::string name = info.param.name;
  for (char& c : name) c = c == '-' ? '_' : c;
  return name;
}

std::vector<Program> programs_where(bool (*keep)(const Program&)) {
  std::vector<Program> kept;
  for (const Program& p : programs()) {
    if (keep(p)) kept.push_back(p);
  }
  return kept;
}

INSTANTIATE_TEST_SUITE_P(Programs, Cli, ::testing::ValuesIn(programs()), test_name);
INSTANTIATE_TEST_SUITE_P(Programs, CliNumeric,
                         ::testing::ValuesIn(programs_where([](const Program& p) {
                           return !p.numeric_option.empty();
                         })),
                         test_name);
INSTANTIATE_TEST_SUITE_P(Programs, CliRequired,
                         ::testing::ValuesIn(programs_where([](const Program& p) {
                           return !p.runs_without_arguments;
                         })),
                         test_name);

}  // namespace
