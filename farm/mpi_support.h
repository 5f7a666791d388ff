// What every MPI phase of the farm shares: MPI error checks, the exit code of a failure, and the
// number of threads a rank uses. Only farm/ includes this (it is the only place that knows MPI).
#pragma once

#include <mpi.h>

#include <exception>
#include <string>

namespace prt {

// Throws RankFailure("<what>: <MPI's error string>") unless rc is MPI_SUCCESS.
void CheckMpi(int rc, const std::string& what);

// The FarmExitCode of a failure (farm_options.h) and its message: UsageError → usage,
// InputError → bad input, FileIoError and filesystem errors → I/O, RankFailure and anything
// else → rank failed ("<context>: ..." for exceptions that are not prtfarm's own).
int ExitCodeOf(std::exception_ptr e, std::string& message,
               const std::string& context = "internal error");

// CPUs this process may run on (mpirun binds each rank to one core by default when there are at
// most 2 ranks, and to a socket otherwise); 0 when unknown.
int AllowedCpus();

// Threads per rank for --threads 0: the CPUs the rank is bound to when mpirun bound it to part of
// the node, else the node's cores divided by the ranks on the node.
int AutoThreads(MPI_Comm comm);

}  // namespace prt
