// compress_microbench: Google Benchmark of the farm's per-column compression kernels on real
// transport columns (docs/farm-compression.md).
//
//   build/bench/compress_microbench [google-benchmark flags] RUN/transport.prtt
//
// The raw transport of a farm run kept with --keep-raw (e.g. `mpirun -np 2 build/farm/prt-farm
// --out RUN --keep-raw`). Every 64th column is taken and transformed to every depth of a 1D
// LeGall 5/3 column transform over the samples (the shape of a mesh segment's), 17 vectors per
// column. BM_MeasureApproximation: the budget-term energy of one such vector (§4.4's depth
// search calls it once per column per depth), budget 2090 (the demo's 5 % of 41,802);
// BM_TransformColumnAdaptive: the whole adaptive-depth transform of one column.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "formats/transport_file.h"
#include "vocabulary/tbb_parallel.h"
#include "vocabulary/wavelets.h"
#include "worker/adaptive_column_transform.h"

namespace {

std::string g_raw;
constexpr std::size_t kBudget = 2090;

struct Columns {
  std::size_t samples = 0;
  std::vector<std::vector<float>> raw;    // sample order
  std::vector<std::vector<float>> depth;  // raw.size() × 17: depths 0 … 16
};

const Columns& Get() {
  static const Columns c = [] {
    Columns out;
    const prt::TransportFileReader reader(g_raw);
    const std::size_t S = reader.info().rows, M = reader.info().cols();
    out.samples = S;
    std::vector<float> rows(S * M);
    reader.ReadRows(0, S, rows.data());
    for (std::size_t j = 0; j < M; j += 64) {
      std::vector<float> col(S);
      for (std::size_t s = 0; s < S; ++s) col[s] = rows[s * M + j];
      out.raw.push_back(col);
      for (int t = 0; t <= 16; ++t) {
        if (t > 0)
          prt::ForwardWavelet2DStep(prt::WaveletFilter::kLeGall53, col.data(), static_cast<int>(S),
                                    1, t);
        out.depth.push_back(col);
      }
    }
    return out;
  }();
  return c;
}

void BM_MeasureApproximation(benchmark::State& state) {
  const Columns& c = Get();
  std::size_t i = 0;
  for (auto _ : state) {
    const std::vector<float>& v = c.depth[i];
    benchmark::DoNotOptimize(prt::MeasureApproximation(v.data(), c.samples, kBudget));
    i = i + 1 == c.depth.size() ? 0 : i + 1;
  }
  state.counters["values/s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * c.samples), benchmark::Counter::kIsRate);
}

void BM_TransformColumnAdaptive(benchmark::State& state) {
  const Columns& c = Get();
  prt::SpatialDomain domain;
  prt::SpatialSegment mesh;
  mesh.kind = prt::SpatialSegment::Kind::kMesh1D;
  mesh.count = static_cast<uint32_t>(c.samples);
  domain.segments = {mesh};
  std::vector<float> work(c.samples);
  std::size_t i = 0;
  for (auto _ : state) {
    work = c.raw[i];
    benchmark::DoNotOptimize(
        prt::TransformColumnAdaptive(domain, prt::ColumnWavelet::kLeGall53, kBudget, work.data()));
    i = i + 1 == c.raw.size() ? 0 : i + 1;
  }
}

}  // namespace

BENCHMARK(BM_MeasureApproximation)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_TransformColumnAdaptive)->Unit(benchmark::kMicrosecond);

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  benchmark::Initialize(&argc, argv);
  if (argc > 1) g_raw = argv[1];
  if (g_raw.empty() || !std::filesystem::exists(g_raw)) {
    std::fprintf(stderr,
                 "compress_microbench: name the raw transport of a run kept with --keep-raw "
                 "(RUN/transport.prtt)\n");
    return 2;
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
