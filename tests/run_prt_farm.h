// Runs the prt-farm executable under mpirun for the MPI integration tests (farm_mpi_test.cpp,
// compression_phase_mpi_test.cpp, …), and writes the edited test scenes they farm. The including
// target defines PRT_MPIEXEC, PRT_MPIEXEC_NUMPROC_FLAG, PRT_MPIEXEC_PREFLAGS,
// PRT_MPIEXEC_POSTFLAGS, PRT_FARM_EXE and PRT_MPI_TEST_ENV_LIST (tests/CMakeLists.txt).
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace prt::testing {

struct RunResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// The environment every MPI test needs in a root container (PRT_MPI_TEST_ENV of the top
// CMakeLists.txt), set here as well in case the test runs outside CTest; never overrides a
// variable the caller set.
inline void ApplyMpiTestEnvironment() {
  std::stringstream env(PRT_MPI_TEST_ENV_LIST);
  std::string item;
  while (std::getline(env, item, ';')) {
    const std::size_t eq = item.find('=');
    if (eq != std::string::npos) {
      ::setenv(item.substr(0, eq).c_str(), item.substr(eq + 1).c_str(), 0);
    }
  }
}

// `mpirun -np ranks prt-farm args`, waiting for it; the exit code is 128 + signal when killed.
inline RunResult RunPrtFarm(int ranks, const std::string& args) {
  ApplyMpiTestEnvironment();
  const std::string command = std::string(PRT_MPIEXEC) + " " + PRT_MPIEXEC_NUMPROC_FLAG + " " +
                              std::to_string(ranks) + " " + PRT_MPIEXEC_PREFLAGS + " " +
                              PRT_FARM_EXE + " " + PRT_MPIEXEC_POSTFLAGS + " " + args + " 2>&1";
  RunResult r;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

// Replaces the first `from` in `text` with `to` (`from` must be there: a test edits a known file).
inline void ReplaceOnce(std::string& text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  if (at == std::string::npos) throw std::invalid_argument("ReplaceOnce: no '" + from + "'");
  text.replace(at, from.size(), to);
}

// An edited copy of a tests/data scene that may live anywhere: `text` with its mesh path
// "box.off" made absolute, written to `file`; returns `file`.
inline std::string WriteTestScene(std::string text, const std::string& file) {
  ReplaceOnce(text, "path = \"box.off\"",
              "path = \"" + std::string(PRT_TESTS_DATA_DIR) + "/box.off\"");
  std::ofstream(file) << text;
  return file;
}

}  // namespace prt::testing
