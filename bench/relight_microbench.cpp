// relight_microbench: Google Benchmark of the viewer's B = T·L step on a packed asset, and of its
// fixed per-frame parts (docs/viewer.md, "Relighting speed").
//
//   build/bench/relight_microbench [google-benchmark flags] [pack]   (default: demo-out's pack)
//
// BM_Relight/N: CompressedRelighter::RelightSparse with the N largest area-weighted sunrise
// terms (NWA), 3 channels, into float radiance; BM_Apply/N: the viewer's TransportOperator::Apply
// of the same terms (double SampleRadiance in the session's coefficient order); BM_Assign/N: the
// same into a buffer kept between frames; BM_Apply_PackOrder/N: Apply in the pack's sample order
// (the gather through the Hilbert permutation); BM_InverseSteps: the Eq. 8
// inverse column steps of every level over 3 interleaved channels, alone; *_128bit: the same
// with the wavelet synthesis on 128-bit vectors (no AVX kernel). The counter
// "T_bytes/s" is the stored bytes of the N columns (8 per term) divided by the time: compare it
// with the copy bandwidth printed by viewer_bench.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_scenes.h"
#include "runtime/compressed_relight.h"
#include "runtime/lighting.h"
#include "viewer/viewer_session.h"
#include "vocabulary/tbb_parallel.h"
#include "vocabulary/wavelets.h"

namespace {

std::string g_pack = "demo-out/default.prtpack";

struct Fixture {
  std::unique_ptr<prt::ViewerSession> session;
  std::unique_ptr<prt::WaveletLighting> sunrise;
  std::unique_ptr<prt::HaarLightingBasis> basis;
};

Fixture& Get() {
  static Fixture f = [] {
    Fixture x;
    x.session = prt::ViewerSession::Open(g_pack);
    const int n = x.session->cubemap_n();
    const auto envs = prt::bench::BenchEnvironments(n, {"sunrise"});
    x.sunrise = std::make_unique<prt::WaveletLighting>(prt::ProjectLighting(envs[0].cube));
    x.basis = std::make_unique<prt::HaarLightingBasis>(n);
    return x;
  }();
  return f;
}

// The N terms as RelightSparse takes them, and the stored bytes of their columns.
struct Terms {
  std::vector<prt::LightingTerm> terms;
  std::vector<uint32_t> columns;
  std::vector<float> weights;
};

Terms TermsOf(std::size_t n) {
  Fixture& f = Get();
  Terms t;
  t.terms = prt::NonlinearLightingApproximation(*f.sunrise, *f.basis, n);
  for (const prt::LightingTerm& l : t.terms) {
    t.columns.push_back(l.index);
    for (int c = 0; c < 3; ++c) t.weights.push_back(static_cast<float>(l.value[c]));
  }
  return t;
}

double StoredBytes(const Terms& t) {
  const prt::CompressedRelighter& r = Get().session->relighter();
  double bytes = 0;
  for (uint32_t c : t.columns) bytes += 8.0 * static_cast<double>(r.ColumnTermCount(c));
  return bytes;
}

void BM_Relight(benchmark::State& state) {
  const Terms t = TermsOf(static_cast<std::size_t>(state.range(0)));
  const prt::CompressedRelighter& r = Get().session->relighter();
  std::vector<float> radiance(3 * r.sample_count());
  for (auto _ : state) {
    r.RelightSparse(t.columns, t.weights, 3, radiance);
    benchmark::DoNotOptimize(radiance.data());
    benchmark::ClobberMemory();
  }
  state.counters["T_bytes/s"] =
      benchmark::Counter(StoredBytes(t), benchmark::Counter::kIsIterationInvariantRate);
}

void BM_Apply(benchmark::State& state) {
  const Terms t = TermsOf(static_cast<std::size_t>(state.range(0)));
  const prt::TransportOperator& op = Get().session->transport();
  for (auto _ : state) {
    prt::SampleRadiance b = op.Apply(t.terms);
    benchmark::DoNotOptimize(b.channel[0].data());
  }
  state.counters["T_bytes/s"] =
      benchmark::Counter(StoredBytes(t), benchmark::Counter::kIsIterationInvariantRate);
}

// The viewer's frame loop: Assign into a radiance buffer kept between frames (no clearing).
void BM_Assign(benchmark::State& state) {
  const Terms t = TermsOf(static_cast<std::size_t>(state.range(0)));
  const prt::TransportOperator& op = Get().session->transport();
  prt::SampleRadiance b;
  for (auto _ : state) {
    op.Assign(t.terms, b);
    benchmark::DoNotOptimize(b.channel[0].data());
  }
  state.counters["T_bytes/s"] =
      benchmark::Counter(StoredBytes(t), benchmark::Counter::kIsIterationInvariantRate);
}

// Apply in the pack's sample order: the gather through the Hilbert permutation that the
// session's coefficient order avoids (the session's operator is SampleOrder::kCoefficients).
void BM_Apply_PackOrder(benchmark::State& state) {
  const Terms t = TermsOf(static_cast<std::size_t>(state.range(0)));
  const prt::CompressedTransportOperator op(Get().session->relighter(), prt::SampleOrder::kSamples);
  for (auto _ : state) {
    prt::SampleRadiance b = op.Apply(t.terms);
    benchmark::DoNotOptimize(b.channel[0].data());
  }
  state.counters["T_bytes/s"] =
      benchmark::Counter(StoredBytes(t), benchmark::Counter::kIsIterationInvariantRate);
}

void BM_InverseSteps(benchmark::State& state) {
  const prt::CompressedRelighter& r = Get().session->relighter();
  const prt::CompressedTransportHeader& h = r.header();
  const std::size_t S = r.sample_count();
  std::vector<float> x(4 * S, 1.0f), scratch(4 * S);
  const prt::WaveletFilter f = prt::ToWaveletFilter(h.column_wavelet);
  const int depth = prt::MaxColumnDepth(h.domain);
  for (auto _ : state) {
    for (int step = depth; step >= 1; --step) {
      std::size_t off = 0;
      for (const prt::SpatialSegment& s : h.domain.segments) {
        const bool grid = s.kind == prt::SpatialSegment::Kind::kGrid2D;
        const int w = static_cast<int>(grid ? s.width : s.count);
        const int hh = grid ? static_cast<int>(s.height) : 1;
        if (step <= prt::MaxSegmentDepth(s))
          prt::InverseWavelet2DStepInterleaved(f, x.data() + 4 * off, w, hh, 4, step,
                                               scratch.data() + 4 * off);
        off += s.count;
      }
    }
    benchmark::DoNotOptimize(x.data());
  }
  state.counters["samples"] = static_cast<double>(S);
}

// The same with the wavelet synthesis on 128-bit vectors only (prt::SetWaveletAvx(false)): the
// AVX kernel's gain, measured in the same run.
void BM_Relight_128bit(benchmark::State& state) {
  const bool had = prt::SetWaveletAvx(false);
  BM_Relight(state);
  prt::SetWaveletAvx(had);
}
void BM_InverseSteps_128bit(benchmark::State& state) {
  const bool had = prt::SetWaveletAvx(false);
  BM_InverseSteps(state);
  prt::SetWaveletAvx(had);
}

}  // namespace

BENCHMARK(BM_Relight)->Arg(1)->Arg(30)->Arg(100)->Arg(300)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Apply)->Arg(1)->Arg(30)->Arg(100)->Arg(300)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Assign)->Arg(1)->Arg(30)->Arg(100)->Arg(300)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Apply_PackOrder)->Arg(1)->Arg(30)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_InverseSteps)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Relight_128bit)->Arg(1)->Arg(30)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_InverseSteps_128bit)->Unit(benchmark::kMicrosecond);

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  benchmark::Initialize(&argc, argv);
  if (argc > 1) g_pack = argv[1];
  if (!std::filesystem::exists(g_pack)) {
    std::fprintf(stderr,
                 "relight_microbench: %s not found (run scripts/demo.sh, or name a .prtpack)\n",
                 g_pack.c_str());
    return 2;
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
