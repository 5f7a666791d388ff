#include "farm/mpi_support.h"

#include <sched.h>

#include <algorithm>
#include <filesystem>
#include <thread>

#include "farm/farm_options.h"
#include "vocabulary/errors.h"

namespace prt {

void CheckMpi(int rc, const std::string& what) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING] = {};
  int len = 0;
  MPI_Error_string(rc, text, &len);
  throw RankFailure(what + ": " + std::string(text, static_cast<std::size_t>(len)));
}

int ExitCodeOf(std::exception_ptr e, std::string& message, const std::string& context) {
  try {
    std::rethrow_exception(e);
  } catch (const UsageError& x) {
    message = x.what();
    return kExitUsage;
  } catch (const InputError& x) {
    message = x.what();
    return kExitBadInput;
  } catch (const FileIoError& x) {
    message = x.what();
    return kExitIoError;
  } catch (const std::filesystem::filesystem_error& x) {
    message = x.what();
    return kExitIoError;
  } catch (const RankFailure& x) {
    message = x.what();
    return kExitRankFailed;
  } catch (const std::exception& x) {
    message = context + ": " + x.what();
    return kExitRankFailed;
  } catch (...) {
    message = context + ": unknown exception";
    return kExitRankFailed;
  }
}

int AllowedCpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return 0;
  return CPU_COUNT(&set);
}

int AutoThreads(MPI_Comm comm) {
  MPI_Comm node;
  int local_ranks = 1;
  if (MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node) == MPI_SUCCESS) {
    MPI_Comm_size(node, &local_ranks);
    MPI_Comm_free(&node);
  }
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int allowed = AllowedCpus();
  if (allowed > 0 && allowed < cores) return allowed;
  return std::max(1, cores / std::max(1, local_ranks));
}

}  // namespace prt
