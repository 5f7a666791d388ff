// Adaptive-depth column transform (Cheslack-Postava et al. 2008 §4.2, §4.4).
#include "worker/adaptive_column_transform.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <numeric>

#include "formats/column_coding.h"
#include "vocabulary/wavelets.h"

namespace prt {

// Selection by a histogram of the magnitudes' float bits instead of a sort: |c| as an unsigned
// integer (sign bit cleared) orders like |c| and like c², so one pass counts the non-zeros in
// 2^11 bins of the top bits (8 exponent and 3 mantissa bits) and sums the total; the bin where
// the count from the top reaches `budget` is found; a second pass sums the squares of the bins
// above it and gathers that bin's squares, of which only the largest remaining ones are selected.
// Two linear passes and a selection among one bin's values, where std::nth_element over every
// non-zero was 40 % of the farm's compress phase (docs/farm-compression.md).
ApproximationEnergy MeasureApproximation(const float* c, std::size_t n, std::size_t budget) {
  constexpr int kShift = 20;  // 31-bit key → 2^11 bins
  constexpr std::size_t kBins = std::size_t{1} << (31 - kShift);
  ApproximationEnergy e;
  // Two histograms, alternate values to each, and zeros (runs of them: the samples below a
  // texel's horizon, flat regions' details) counted apart, four at a time where they come in
  // fours: an increment of the bin the previous value incremented waits for that store, and with
  // one histogram and zeros in bin 0 most increments did. The total in four partial sums so that
  // the additions do not wait on each other either; a zero adds nothing. With the second pass's
  // changes below, 43–45 → 26 µs per call on real columns (bench/compress_microbench.cpp,
  // docs/farm-compression.md), the same results bit for bit.
  std::array<uint32_t, kBins> count{}, count_odd{};
  std::size_t zeros = 0;
  double sum[4] = {0, 0, 0, 0};
  const auto add = [&](std::size_t i, int lane, std::array<uint32_t, kBins>& histogram) {
    const uint32_t key = std::bit_cast<uint32_t>(c[i]) & 0x7FFFFFFFu;
    if (key == 0) {
      ++zeros;
      return;
    }
    ++histogram[key >> kShift];
    sum[lane] += static_cast<double>(c[i]) * c[i];
  };
  std::size_t q = 0;
  for (; q + 4 <= n; q += 4) {
    uint64_t quad[2];  // four zeros (or negative zeros) at once: a run below the horizon
    std::memcpy(quad, c + q, sizeof quad);
    if (((quad[0] | quad[1]) & 0x7FFFFFFF7FFFFFFFull) == 0) {
      zeros += 4;
      continue;
    }
    add(q, 0, count);
    add(q + 1, 1, count_odd);
    add(q + 2, 2, count);
    add(q + 3, 3, count_odd);
  }
  for (; q < n; ++q) add(q, 0, count);
  for (std::size_t b = 0; b < kBins; ++b) count[b] += count_odd[b];
  const std::size_t nonzero = n - zeros;
  e.total = (sum[0] + sum[1]) + (sum[2] + sum[3]);
  if (nonzero <= budget) {
    e.kept = e.total;
    e.terms = static_cast<uint32_t>(nonzero);
    e.keeps_all = true;
    return e;
  }
  if (budget == 0) return e;
  // The threshold bin: fewer than `budget` values lie above it, at least `budget` from it up.
  std::size_t above = 0, bin = kBins;
  while (above + count[bin - 1] < budget) above += count[--bin];
  const uint32_t threshold = static_cast<uint32_t>(bin - 1);
  thread_local std::vector<double> edge;
  edge.clear();
  // The sum in a local, in index order as before: as a member of `e` it lived in memory (the
  // vector's push_back may alias it), every addition waiting on the previous one's store.
  // Most values lie below the threshold bin (the budget is a few per cent of them): four at a
  // time are tested at once and skipped together, the others taken one by one in index order.
  double kept = 0;
  const auto take = [&](std::size_t i) {
    const uint32_t b = (std::bit_cast<uint32_t>(c[i]) & 0x7FFFFFFFu) >> kShift;
    if (b < threshold) return;
    const double v = static_cast<double>(c[i]) * c[i];
    if (b > threshold) {
      kept += v;
    } else {
      edge.push_back(v);
    }
  };
  using U4 = uint32_t __attribute__((vector_size(16)));
  const U4 abs_mask = {0x7FFFFFFFu, 0x7FFFFFFFu, 0x7FFFFFFFu, 0x7FFFFFFFu};
  const U4 threshold4 = {threshold, threshold, threshold, threshold};
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    U4 bits;
    std::memcpy(&bits, c + i, sizeof bits);
    const U4 at_or_above = ((bits & abs_mask) >> kShift) >= threshold4;  // lanes: all ones or 0
    uint64_t any[2];
    std::memcpy(any, &at_or_above, sizeof any);
    if ((any[0] | any[1]) == 0) continue;
    for (std::size_t k = i; k < i + 4; ++k) take(k);
  }
  for (; i < n; ++i) take(i);
  const std::size_t rest = budget - above;  // 1 … edge.size()
  std::nth_element(edge.begin(), edge.begin() + static_cast<std::ptrdiff_t>(rest - 1), edge.end(),
                   std::greater<double>());
  for (std::size_t k = 0; k < rest; ++k) kept += edge[k];
  e.kept = kept;
  e.terms = static_cast<uint32_t>(budget);
  return e;
}

std::vector<uint32_t> LargestTerms(const float* c, std::size_t n, std::size_t budget) {
  std::vector<uint32_t> idx;
  for (std::size_t i = 0; i < n; ++i)
    if (c[i] != 0.0f) idx.push_back(static_cast<uint32_t>(i));
  if (idx.size() > budget) {
    std::nth_element(idx.begin(), idx.begin() + budget, idx.end(), [c](uint32_t a, uint32_t b) {
      const float fa = std::fabs(c[a]), fb = std::fabs(c[b]);
      return fa > fb || (fa == fb && a < b);
    });
    idx.resize(budget);
  }
  std::sort(idx.begin(), idx.end());
  return idx;
}

int PickDepth(std::span<const ApproximationEnergy> per_depth) {
  int best = -1;
  // Depths that keep all the energy: the fewest terms (then the shallowest) wins.
  for (std::size_t d = 0; d < per_depth.size(); ++d) {
    if (!per_depth[d].keeps_all) continue;
    if (best < 0 || per_depth[d].terms < per_depth[best].terms) best = static_cast<int>(d);
  }
  if (best >= 0) return best;
  // Otherwise the largest kept fraction of the energy (then the shallowest).
  best = 0;
  for (std::size_t d = 1; d < per_depth.size(); ++d)
    if (per_depth[d].kept_fraction() > per_depth[best].kept_fraction()) best = static_cast<int>(d);
  return best;
}

int TransformColumnAdaptive(const SpatialDomain& domain, ColumnWavelet wavelet, std::size_t budget,
                            float* column, std::vector<ApproximationEnergy>* per_depth) {
  const std::size_t n = domain.sample_count();
  const int max_depth = MaxColumnDepth(domain);
  const WaveletFilter f = ToWaveletFilter(wavelet);
  thread_local std::vector<float> work, best;
  work.resize(n);
  best.resize(n);
  SamplesToCoefficientOrder(domain, column, work.data());
  std::vector<ApproximationEnergy> measured;
  measured.reserve(max_depth + 1);
  measured.push_back(MeasureApproximation(work.data(), n, budget));
  std::copy(work.begin(), work.end(), best.begin());
  int chosen = 0;
  for (int t = 1; t <= max_depth; ++t) {
    // One more forward step on every segment deep enough for it.
    std::size_t off = 0;
    for (const auto& s : domain.segments) {
      const bool grid = s.kind == SpatialSegment::Kind::kGrid2D;
      const int w = grid ? static_cast<int>(s.width) : static_cast<int>(s.count);
      const int h = grid ? static_cast<int>(s.height) : 1;
      if (t <= MaxSegmentDepth(s)) ForwardWavelet2DStep(f, work.data() + off, w, h, t);
      off += s.count;
    }
    measured.push_back(MeasureApproximation(work.data(), n, budget));
    const int pick = PickDepth(measured);
    if (pick != chosen) {
      chosen = pick;
      std::copy(work.begin(), work.end(), best.begin());
    }
  }
  std::copy(best.begin(), best.end(), column);
  if (per_depth) *per_depth = std::move(measured);
  return chosen;
}

}  // namespace prt
