// Parallel loops without a threading library: every parallel loop of the core vocabulary and the
// runtime (runtime/) goes through ParallelFor, which runs on the calling thread unless a backend
// is installed. Programs that link TBB install it (vocabulary/tbb_parallel.h); a host that embeds
// the runtime installs its own job system (prt_runtime_set_task_runner, runtime/prt_runtime.h).
// The backend is process-wide; install it before the loops run, never while one runs.
//
// Results never depend on the backend or the thread count: callers split work into fixed parts
// whose results are combined in order.
#pragma once

#include <algorithm>
#include <cstddef>
#include <type_traits>
#include <utility>

namespace prt {

// run(user, count, task, task_data) calls task(task_data, i) once for every i in [0, count), on
// any threads, and returns when all have returned.
struct ParallelBackend {
  void (*run)(void* user, std::size_t count, void (*task)(void*, std::size_t),
              void* task_data) = nullptr;
  void* user = nullptr;
  std::size_t concurrency = 1;  // threads `run` uses: loops split into about this many parts
};

// Installs `backend` (run == nullptr: the calling thread, concurrency 1).
void SetParallelBackend(const ParallelBackend& backend);
const ParallelBackend& CurrentParallelBackend();
// Threads the backend uses (1 without one).
std::size_t ParallelConcurrency();

namespace detail {
void RunParallel(std::size_t count, void (*task)(void*, std::size_t), void* data);
}  // namespace detail

// f(i) for every i in [0, count), possibly concurrently.
template <class F>
void ParallelFor(std::size_t count, F&& f) {
  if (count == 0) return;
  if (count == 1 || ParallelConcurrency() <= 1) {
    for (std::size_t i = 0; i < count; ++i) f(i);
    return;
  }
  using Fn = std::remove_reference_t<F>;
  detail::RunParallel(
      count, [](void* d, std::size_t i) { (*static_cast<Fn*>(d))(i); },
      const_cast<void*>(static_cast<const void*>(&f)));
}

// f(lo, hi) over [begin, end) split into pieces of at least `grain` items, about 4 per thread
// (none when there is no backend: one call for the whole range).
template <class F>
void ParallelForRange(std::size_t begin, std::size_t end, std::size_t grain, F&& f) {
  if (end <= begin) return;
  const std::size_t n = end - begin;
  const std::size_t threads = ParallelConcurrency();
  std::size_t parts = threads <= 1 ? 1 : threads * 4;
  if (grain > 0) parts = std::min(parts, (n + grain - 1) / grain);
  if (parts <= 1) {
    f(begin, end);
    return;
  }
  ParallelFor(parts, [&](std::size_t p) { f(begin + n * p / parts, begin + n * (p + 1) / parts); });
}

}  // namespace prt
