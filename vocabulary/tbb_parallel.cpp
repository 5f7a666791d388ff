#include "vocabulary/tbb_parallel.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "vocabulary/parallel.h"

namespace prt {

void UseTbbParallelism() {
  ParallelBackend b;
  b.run = [](void*, std::size_t count, void (*task)(void*, std::size_t), void* data) {
    tbb::parallel_for(std::size_t{0}, count, [&](std::size_t i) { task(data, i); });
  };
  b.concurrency = static_cast<std::size_t>(tbb::this_task_arena::max_concurrency());
  SetParallelBackend(b);
}

}  // namespace prt
