#include "vocabulary/parallel.h"

namespace prt {

namespace {
ParallelBackend g_backend;
}  // namespace

void SetParallelBackend(const ParallelBackend& backend) {
  g_backend = backend;
  if (g_backend.run == nullptr || g_backend.concurrency == 0) g_backend.concurrency = 1;
}

const ParallelBackend& CurrentParallelBackend() {
  return g_backend;
}

std::size_t ParallelConcurrency() {
  return g_backend.run == nullptr ? 1 : g_backend.concurrency;
}

namespace detail {
void RunParallel(std::size_t count, void (*task)(void*, std::size_t), void* data) {
  if (g_backend.run == nullptr) {
    for (std::size_t i = 0; i < count; ++i) task(data, i);
    return;
  }
  g_backend.run(g_backend.user, count, task, data);
}
}  // namespace detail

}  // namespace prt
