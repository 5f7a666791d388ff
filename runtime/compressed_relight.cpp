// Relighting from compressed columns (Cheslack-Postava et al. 2008 §4.5, Eq. 5–8); see
// compressed_relight.h and docs/compression.md.
#include "runtime/compressed_relight.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>

#include "vocabulary/errors.h"
#include "vocabulary/huge_pages.h"
#include "vocabulary/parallel.h"

namespace prt {
namespace {

// Four floats in one SSE register (GCC/Clang vector extension): one sample's channels in X.
using Float4 = float __attribute__((vector_size(16)));

// The most tiles X is scattered in (see the constructor).
constexpr std::size_t kMaxTiles = 64;

// A light's weights as X's four lanes: a 3-channel T's channel ch lights lane ch only; else the
// lighting's C channels.
Float4 LaneWeights(bool per_channel, std::size_t ch, const float* w, std::size_t C) {
  return per_channel
             ? Float4{ch == 0 ? w[0] : 0.0f, ch == 1 ? w[1] : 0.0f, ch == 2 ? w[2] : 0.0f, 0.0f}
             : Float4{w[0], C > 1 ? w[1] : 0.0f, C > 2 ? w[2] : 0.0f, C > 3 ? w[3] : 0.0f};
}

// Terms [b, e) (index − shift: the element of X, 4 floats each) times w4 added to X, a cache line
// of terms at a time with the terms `ahead` terms on prefetched (the hardware prefetcher,
// left alone, restarts on every short piece).
template <class Term>
inline void AddTerms4(float* x, const Term* b, const Term* e, Float4 w4, std::size_t shift,
                      std::ptrdiff_t ahead) {
  const auto add = [x, w4, shift](const Term& term) {
    float* xi = x + 4 * (static_cast<std::size_t>(term.index) - shift);
    Float4 xv;
    std::memcpy(&xv, xi, sizeof xv);
    xv += w4 * term.value;
    std::memcpy(xi, &xv, sizeof xv);
  };
  const Term* p = b;
  for (; e - p >= 8; p += 8) {
    __builtin_prefetch(p + ahead);
    for (int u = 0; u < 8; ++u) add(p[u]);
  }
  for (; p != e; ++p) add(*p);
}

// A value for an error message: 7 significant digits (std::to_string writes 1e39 in full).
std::string Number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.7g", v);
  return b;
}

}  // namespace

CompressedRelighter::CompressedRelighter(const CompressedTransport& t, std::string name)
    : name_(std::move(name)), header_(t.header), max_depth_(MaxColumnDepth(t.header.domain)) {
  ValidateHeader(header_, name_);
  spatial_ = header_.spatial_count();
  const std::size_t S = header_.sample_count;
  slot_.assign(header_.column_count(), -1);
  // A 3-channel transport's channels are copies of channel 0's segments (ValidateHeader): X
  // and the outputs have channel 0's V samples.
  const std::size_t channel_segments = header_.domain.segments.size() / header_.channels;
  coefficient_of_sample_.resize(spatial_);
  {
    std::size_t off = 0;
    for (std::size_t s = 0; s < channel_segments; ++s) {
      const SpatialSegment& seg = header_.domain.segments[s];
      const bool permuted = seg.kind == SpatialSegment::Kind::kMesh1D && !seg.order.empty();
      for (uint32_t k = 0; k < seg.count; ++k)
        coefficient_of_sample_[off + (permuted ? seg.order[k] : k)] =
            static_cast<uint32_t>(off + k);
      off += seg.count;
    }
  }
  // 8 bytes per stored term (100 MB for the demo's pack) of fresh memory, reserved in huge pages
  // so that its first touch costs 512 times fewer page faults (docs/viewer.md).
  ReserveFreshHuge(terms_, t.term_count());
  std::vector<std::vector<uint8_t>> levels(max_depth_ + 1);
  {
    std::size_t off = 0;
    for (std::size_t s = 0; s < channel_segments; ++s) {
      const SpatialSegment& seg = header_.domain.segments[s];
      Segment b{off, off + seg.count, 0, 0, MaxSegmentDepth(seg)};
      SegmentShape(seg, b.w, b.h);
      segments_.push_back(b);
      off += seg.count;
    }
  }
  const std::size_t V = spatial_;
  for (const auto& c : t.columns) {
    ValidateColumn(header_, c, name_);
    if (slot_[c.column] >= 0) throw InputError(name_, "duplicate column");
    auto& lv = levels[c.depth];
    if (lv.empty()) {
      lv.resize(S);
      ColumnScaleMap(header_.domain, c.depth, lv.data());
    }
    slot_[c.column] = static_cast<int32_t>(columns_.size());
    Column col{c.depth, static_cast<uint32_t>(terms_.size()), 0,
               static_cast<uint32_t>(late_terms_.size()), 0};
    std::size_t si = 0;  // segment of index i (indices increase within a channel)
    std::size_t channel = 0;
    for (std::size_t k = 0; k < c.index.size(); ++k) {
      const uint32_t i = c.index[k];
      // Row i is position e = i − channel·V of its channel: X's element e.
      if (i / V != channel) {
        channel = i / V;
        si = 0;
      }
      const std::size_t e = i - channel * V;
      const double value = DequantiseTerm(c.q[k], DitherOffset(header_.dither_seed, c.column, i),
                                          c.scale, header_.bits, lv[i]);
      // |value| ≤ (A + ½)/A · scale with a finite float scale (ValidateColumn): only a scale
      // within 0.4 % of FLT_MAX reaches past the float range.
      if (!(std::abs(value) <= static_cast<double>(std::numeric_limits<float>::max())))
        throw InputError(name_, "column " + std::to_string(c.column) + ": the term of sample " +
                                    std::to_string(i) + " dequantises to " + Number(value) +
                                    ", outside the float range");
      const Term term{i, static_cast<float>(value)};
      while (e >= segments_[si].hi) ++si;
      // Late: in the low band that the segment's inverse step c.depth + 1 writes. A segment
      // whose maximum depth is at most c.depth is not touched by any step before the column's
      // lights are due, so all of its terms are early; depth-0 columns are scattered after
      // every step, all their terms in terms_.
      const Segment& b = segments_[si];
      bool late = false;
      if (c.depth > 0 && c.depth < b.max_depth) {
        const std::size_t p = e - b.lo;
        const auto pw = static_cast<std::size_t>(b.w);
        late = p % pw < static_cast<std::size_t>(SizeAtDepth(b.w, c.depth)) &&
               p / pw < static_cast<std::size_t>(SizeAtDepth(b.h, c.depth));
      }
      (late ? late_terms_ : terms_).push_back(term);
    }
    col.end = static_cast<uint32_t>(terms_.size());
    col.late_end = static_cast<uint32_t>(late_terms_.size());
    columns_.push_back(col);
  }
  // Tiles of at least 16,384 coefficients (256 KB of X with three channels, within the core's
  // L2) and at most 64 per column (the offsets cost 4·65 bytes per column); past 1 Mi samples a
  // tile is V/64 coefficients. Fewer, longer pieces per column measured faster than 4,096 (64 KB):
  // each piece starts a new stream in the column's terms (demo pack, exact, one thread: 11.7–12.3
  // against 14.0–15.1 ms; two threads alike). A column's terms in a tile are one piece per colour
  // channel of T (its rows are channel-major, so channel c's terms come after channel c − 1's).
  const std::size_t P = header_.channels;
  tile_ = std::max<std::size_t>(16384, (V + kMaxTiles - 1) / kMaxTiles);
  tiles_ = std::max<std::size_t>(1, (V + tile_ - 1) / tile_);
  tile_offsets_.resize(columns_.size() * P * (tiles_ + 1));
  for (std::size_t c = 0; c < columns_.size(); ++c) {
    uint32_t k = columns_[c].begin;
    for (std::size_t ch = 0; ch < P; ++ch) {
      for (std::size_t tile = 0; tile <= tiles_; ++tile) {
        const std::size_t bound = ch * V + std::min(tile * tile_, V);
        while (k < columns_[c].end && terms_[k].index < bound) ++k;
        tile_offsets_[(c * P + ch) * (tiles_ + 1) + tile] = k;
      }
    }
  }
}

int CompressedRelighter::ColumnDepth(uint32_t column) const {
  if (column >= slot_.size() || slot_[column] < 0) return -1;
  return columns_[slot_[column]].depth;
}

std::size_t CompressedRelighter::ColumnTermCount(uint32_t column) const {
  if (column >= slot_.size() || slot_[column] < 0) return 0;
  const Column& c = columns_[slot_[column]];
  return (c.end - c.begin) + (c.late_end - c.late_begin);
}

// One light of Eq. 8: a stored column and its weight per channel.
struct CompressedRelighter::Light {
  int32_t slot;
  const float* weight;
};

namespace {

// The identity as an index array (coefficient order: sample i is element i of X).
struct IdentityIndex {
  std::size_t operator[](std::size_t i) const { return i; }
};

// Whether any of x[0, count) is NaN or Inf (all exponent bits set): integer operations OR-ed
// into a flag, a loop the compiler vectorises (16-byte vectors without AVX), so a finite frame
// pays one streaming read of X.
bool AnyNonFinite(const float* x, std::size_t count) {
  uint32_t bad = 0;
  for (std::size_t i = 0; i != count; ++i) {
    uint32_t u;
    std::memcpy(&u, x + i, sizeof u);
    bad |= static_cast<uint32_t>((~u & 0x7f800000u) == 0);
  }
  return bad != 0;
}

}  // namespace

// X's elements [lo, hi) of a segment to the frame's output: sample i reads element index[i]
// (its coefficient; the identity in coefficient order) and writes, or adds, its C channels.
template <class Index>
void CompressedRelighter::Copy(std::size_t lo, std::size_t hi, const float* base,
                               const Index& index, std::size_t C, std::size_t K, std::size_t S,
                               const Output& out) {
  const float* __restrict xs = base;
  if (out.add != nullptr && C == 3 && K == 4) {
    double* __restrict o0 = out.add[0];
    double* __restrict o1 = out.add[1];
    double* __restrict o2 = out.add[2];
    if (out.assign) {
      for (std::size_t i = lo; i != hi; ++i) {
        const float* xi = xs + 4 * static_cast<std::size_t>(index[i]);
        o0[i] = static_cast<double>(xi[0]);
        o1[i] = static_cast<double>(xi[1]);
        o2[i] = static_cast<double>(xi[2]);
      }
    } else {
      for (std::size_t i = lo; i != hi; ++i) {
        const float* xi = xs + 4 * static_cast<std::size_t>(index[i]);
        o0[i] += static_cast<double>(xi[0]);
        o1[i] += static_cast<double>(xi[1]);
        o2[i] += static_cast<double>(xi[2]);
      }
    }
  } else if (out.add == nullptr && C == 3 && K == 4) {
    float* __restrict o0 = out.radiance;
    float* __restrict o1 = o0 + S;
    float* __restrict o2 = o1 + S;
    for (std::size_t i = lo; i != hi; ++i) {
      const float* xi = xs + 4 * static_cast<std::size_t>(index[i]);
      o0[i] = xi[0];
      o1[i] = xi[1];
      o2[i] = xi[2];
    }
  } else {
    for (std::size_t i = lo; i != hi; ++i) {
      const float* xi = xs + K * static_cast<std::size_t>(index[i]);
      for (std::size_t c = 0; c < C; ++c) {
        if (out.add == nullptr) {
          out.radiance[c * S + i] = xi[c];
        } else if (out.assign) {
          out.add[c][i] = static_cast<double>(xi[c]);
        } else {
          out.add[c][i] += static_cast<double>(xi[c]);
        }
      }
    }
  }
}

void CompressedRelighter::CheckChannels(int channels, const char* what) const {
  if (header_.channels != 1 && channels != static_cast<int>(header_.channels))
    throw std::invalid_argument(
        std::string(what) + ": a transport of " + std::to_string(header_.channels) +
        " colour channels needs lighting of as many channels, not " + std::to_string(channels));
}

void CompressedRelighter::ThrowNonFinite(int channels, const Output& out) const {
  const std::size_t S = spatial_;  // values per output channel
  for (int c = 0; c < channels; ++c) {
    for (std::size_t i = 0; i < S; ++i) {
      const double v =
          out.add != nullptr ? out.add[c][i] : static_cast<double>(out.radiance[c * S + i]);
      if (std::isfinite(v)) continue;
      // Position i of the output is sample i, or in coefficient order the sample whose
      // coefficient is i.
      std::size_t sample = i;
      if (out.order == SampleOrder::kCoefficients)
        sample = static_cast<std::size_t>(
            std::find(coefficient_of_sample_.begin(), coefficient_of_sample_.end(), i) -
            coefficient_of_sample_.begin());
      throw NumericalError(name_ + ": the relit radiance of sample " + std::to_string(sample) +
                           " (channel " + std::to_string(c) + ") is " +
                           (std::isnan(v) ? "NaN" : "Inf") +
                           ": T·L overflows the relighter's float range (3.4e38); the lighting "
                           "is too bright for this transport");
    }
  }
  throw NumericalError(name_ + ": the relit radiance overflows the relighter's float range");
}

// Eq. 8 in its recursive form (Eq. 6–7): X ← S'_{t→t−1}(X) + Σ_{j∈N(t−1)} L̂_j C_j, from the
// deepest level to depth 0, then (for SampleOrder::kSamples) undo the Hilbert permutation. One
// coefficient-domain buffer X receives every light, so the frame pays one full inverse
// transform whatever the number of lights, and nothing of size S is allocated per depth.
// The recursion adds a depth-t column after inverse step t + 1, but inverse step t' reads and
// writes only the low band at depth t' − 1 of each segment it transforms. A column's term
// outside the low band at depth t of its segment (a detail coefficient, or any coefficient of a
// segment whose maximum depth is ≤ t) is thus untouched by every step that precedes the column,
// and adding it before the first step leaves X the same. So a frame has three phases:
//   1. X is zeroed and receives the early terms (terms_) of every column of depth ≥ 1, all
//      depths in one pass over X;
//   2. from the deepest light's depth up: a depth's late terms (late_terms_: its low band, a
//      prefix of S/2^t coefficients per segment), then one inverse step per segment;
//   3. the depth-0 columns, all of whose terms come after the last step.
// Phases 1 and 3 run tile by tile (each column's indices are sorted, so a column's terms in a
// tile are one contiguous piece, found once at construction), the tiles split into one
// contiguous run per thread when they have many terms, else on the calling thread, where the
// inverse steps then find X in cache. Phase 2 and the way back run on the calling thread.
// X holds the channels of a sample side by side (3 channels padded to 4 floats): a term then
// updates one 16-byte element, a single cache line, with one SIMD multiply-add, and one float
// inverse step per level (InverseWavelet2DStepInterleaved) transforms every channel at once.
// A 3-channel transport (rows channel-major, its channels' segments identical) has the same X:
// row c·V + e is channel c of element e, so a term of channel c adds to one lane of its element
// with that lane's lighting (the other lanes' weights are 0), and the inverse steps and the way
// back are those of a one-channel frame of V samples. Only the scatter sees the 3·V rows: a
// column's terms in a tile are one piece per channel.
void CompressedRelighter::RelightLights(std::vector<Light>& lights, int channels,
                                        Output out) const {
  const std::size_t S = spatial_;          // elements of X: samples
  const std::size_t P = header_.channels;  // T's colour channels: pieces per column and tile
  const bool per_channel = P != 1;         // CheckChannels: then channels = 3
  const auto C = static_cast<std::size_t>(channels);
  const std::size_t K = C == 3 ? 4 : C;  // floats per sample in X
  std::unique_ptr<FrameBuffers> buffers = TakeBuffers();
  buffers->x.resize(S * K);
  float* x = buffers->x.data();
  // Deepest lights first (stable: lights of one depth keep their order, so sums are
  // reproducible); lights [0, deep_end) have depth ≥ 1.
  std::stable_sort(lights.begin(), lights.end(), [&](const Light& a, const Light& b) {
    return columns_[a.slot].depth > columns_[b.slot].depth;
  });
  const auto deep_end = static_cast<std::size_t>(
      std::partition_point(lights.begin(), lights.end(),
                           [&](const Light& l) { return columns_[l.slot].depth > 0; }) -
      lights.begin());
  const std::size_t threads = std::clamp<std::size_t>(ParallelConcurrency(), 1, tiles_);
  const std::size_t stride = tiles_ + 1;
  std::array<std::size_t, kMaxTiles + 1> tile_work{};
  // Software prefetch 2 KB ahead in the column being added, and the first 2 KB of the next
  // light's piece before it starts: the hardware prefetcher, left alone, restarts on every piece
  // and held N = 300 on the demo's pack at ~2/3 of this speed (docs/viewer.md).
  constexpr std::ptrdiff_t kPrefetchTerms = 256;
  // Fewer terms than this (256 KB of them) are scattered on the calling thread: a second thread
  // would cost more in waking it and in fetching its half of X back across the cores for the
  // inverse steps than it saves (docs/viewer.md).
  constexpr std::size_t kParallelTerms = std::size_t{1} << 15;
  // Lights [l0, l1)'s terms_ into X, tile by tile; with `zero`, each tile is zeroed first.
  const auto scatter = [&](std::size_t l0, std::size_t l1, bool zero) {
    std::size_t count = 0;
    for (std::size_t k = l0; k < l1; ++k)
      count += columns_[lights[k].slot].end - columns_[lights[k].slot].begin;
    if (count == 0 && !zero) return;
    const std::size_t ranges = count >= kParallelTerms ? threads : 1;
    // Each thread's run of tiles carries an equal share of the work: the terms of these lights
    // in its tiles, plus, when zeroing, a tile's coefficients (a 64 KB memset costs about what
    // 4096 terms do). Equal tile counts would not do: the Mallat layout puts the coarse
    // coefficients, which nearly every column stores, in the first tiles (at N = 100 on a keep
    // 0.01 pack the first half of the tiles held 78 % of the terms, and the second thread idled).
    std::array<std::size_t, kMaxTiles + 2> first_tile{};
    first_tile[ranges] = tiles_;
    if (ranges > 1) {
      std::size_t total = 0;
      for (std::size_t t = 0; t < tiles_; ++t) {
        std::size_t w = zero ? std::min(S, (t + 1) * tile_) - t * tile_ : 0;
        for (std::size_t k = l0; k < l1; ++k)
          for (std::size_t ch = 0; ch < P; ++ch) {
            const uint32_t* off = tile_offsets_.data() + (lights[k].slot * P + ch) * stride + t;
            w += off[1] - off[0];
          }
        total += w;
        tile_work[t] = total;  // cumulative: the work of tiles [0, t]
      }
      std::size_t t = 0;
      for (std::size_t r = 1; r < ranges; ++r) {
        const std::size_t target = total * r / ranges;
        // The boundary whose prefix of work lies nearest the target.
        while (t < tiles_ && tile_work[t] <= target) ++t;
        const std::size_t below = t == 0 ? 0 : tile_work[t - 1];
        const std::size_t bound = t < tiles_ && tile_work[t] - target < target - below ? t + 1 : t;
        first_tile[r] = std::max(first_tile[r - 1], bound);
      }
    }
    const auto body = [&, l0, l1, zero](std::size_t r) {
      // Locals, not the lambda's references: the stores into X (memcpy, which may alias
      // anything) would otherwise make the compiler reload these through the closure per term.
      float* const xl = x;
      const Term* const terms = terms_.data();
      const std::size_t t0 = first_tile[r], t1 = first_tile[r + 1];
      for (std::size_t t = t0; t < t1; ++t) {
        if (zero) {
          const std::size_t lo = t * tile_, hi = std::min(S, lo + tile_);
          std::memset(xl + K * lo, 0, sizeof(float) * K * (hi - lo));
        }
        for (std::size_t piece = l0 * P; piece < l1 * P; ++piece) {
          // Light k's terms of T's channel ch in tile t: rows ch·S + [t·tile, …), elements
          // [t·tile, …) of X.
          const std::size_t k = piece / P, ch = piece % P;
          const uint32_t* off = tile_offsets_.data() + (lights[k].slot * P + ch) * stride + t;
          const Term* b = terms + off[0];
          const Term* e = terms + off[1];
          if (piece + 1 < l1 * P) {  // the next piece, while this one is added
            const uint32_t* n = tile_offsets_.data() +
                                (lights[(piece + 1) / P].slot * P + (piece + 1) % P) * stride + t;
            const std::ptrdiff_t len = std::min<std::ptrdiff_t>(kPrefetchTerms, n[1] - n[0]);
            for (std::ptrdiff_t q = 0; q < len; q += 8) __builtin_prefetch(terms + n[0] + q);
          }
          const float* w = lights[k].weight;
          // Row index − shift is the element of X (0 for a one-channel T).
          const std::size_t shift = ch * S;
          if (K == 4) {
            AddTerms4(xl, b, e, LaneWeights(per_channel, ch, w, C), shift, kPrefetchTerms);
          } else if (K == 1) {
            const float w0 = w[0];
            for (const Term* p = b; p != e; ++p) xl[p->index] += w0 * p->value;
          } else {
            for (const Term* p = b; p != e; ++p) {
              float* __restrict xi = xl + K * static_cast<std::size_t>(p->index);
              const float v = p->value;
              for (std::size_t c = 0; c < C; ++c) xi[c] += w[c] * v;
            }
          }
        }
      }
    };
    if (ranges == 1) {
      body(0);
    } else {
      ParallelFor(ranges, body);
    }
  };
  const WaveletFilter filter = ToWaveletFilter(header_.column_wavelet);
  const std::size_t segments = segments_.size();
  const bool split = InverseWavelet1DStepSplitSupported(filter, static_cast<int>(K));
  if (buffers->scratch.size() < S * K) buffers->scratch.resize(S * K);
  float* scratch = buffers->scratch.data();
  std::vector<bool>& in_scratch = buffers->low_in_scratch;  // per segment
  in_scratch.assign(segments, false);

  // Phase 1 (with no column of depth ≥ 1, the depth-0 columns: no step follows).
  scatter(0, deep_end > 0 ? deep_end : lights.size(), true);
  if (deep_end > 0) {
    // Phase 2. X is at depth d at the top of each iteration: its low bands receive the late
    // terms of the depth-d lights (a mesh segment's low band may be in the scratch buffer),
    // then inverse step d takes every segment that has it to depth d − 1. A mesh segment (1D)
    // alternates its low band between X and the scratch buffer, its high bands staying in X
    // (InverseWavelet1DStepSplit): no copy back per step. Steps deeper than the deepest light
    // would transform zeros (no early term lies in their low bands) and are skipped.
    std::size_t next = 0;
    for (int d = columns_[lights[0].slot].depth; d >= 1; --d) {
      for (; next < deep_end && columns_[lights[next].slot].depth == d; ++next) {
        const Column& col = columns_[lights[next].slot];
        const float* w = lights[next].weight;
        std::size_t si = 0;  // the segment of the term (sorted within T's channel)
        std::size_t ch = 0;  // T's channel of the term: row ch·S + element
        for (uint32_t q = col.late_begin; q < col.late_end; ++q) {
          const Term& term = late_terms_[q];
          if (term.index / S != ch) {
            ch = term.index / S;
            si = 0;
          }
          const std::size_t element = term.index - ch * S;
          while (element >= segments_[si].hi) ++si;
          float* xi = (in_scratch[si] ? scratch : x) + K * element;
          if (per_channel) {
            xi[ch] += w[ch] * term.value;
          } else {
            for (std::size_t c = 0; c < C; ++c) xi[c] += w[c] * term.value;
          }
        }
      }
      for (std::size_t si = 0; si < segments; ++si) {
        const auto [off, hi, w, h, max_depth] = segments_[si];
        if (d <= max_depth) {
          if (split && h == 1) {
            const std::size_t ns = (static_cast<std::size_t>(SizeAtDepth(w, d - 1)) + 1) / 2;
            float* low = in_scratch[si] ? scratch : x;
            float* dst = in_scratch[si] ? x : scratch;
            InverseWavelet1DStepSplit(filter, low + off * K, x + (off + ns) * K, dst + off * K, w,
                                      static_cast<int>(K), d);
            in_scratch[si] = !in_scratch[si];
          } else {
            InverseWavelet2DStepInterleaved(filter, x + off * K, w, h, static_cast<int>(K), d,
                                            scratch + off * K);
          }
        }
      }
    }
    // Phase 3: the depth-0 lights add into X; mesh segments left in the scratch buffer by the
    // last step come back first.
    if (deep_end < lights.size()) {
      for (std::size_t si = 0; si < segments; ++si) {
        if (in_scratch[si]) {
          const std::size_t lo = segments_[si].lo, hi = segments_[si].hi;
          std::memcpy(x + lo * K, scratch + lo * K, sizeof(float) * (hi - lo) * K);
          in_scratch[si] = false;
        }
      }
      scatter(deep_end, lights.size(), false);
    }
  }
  // Back to sample order: sequential writes, each sample's channels gathered from its one
  // element of X in one read; in coefficient order a sequential copy (no permutation).
  // Set when an element of X is NaN or Inf (finite inputs only reach them by overflowing X).
  std::atomic<bool> non_finite{false};
  const auto gather = [&, C, K, S](std::size_t lo, std::size_t hi, const float* base) {
    if (AnyNonFinite(base + lo * K, (hi - lo) * K))
      non_finite.store(true, std::memory_order_relaxed);
    if (out.order == SampleOrder::kCoefficients) {
      Copy(lo, hi, base, IdentityIndex{}, C, K, S, out);
    } else {
      Copy(lo, hi, base, coefficient_of_sample_.data(), C, K, S, out);
    }
  };
  // On the calling thread while X fits in its caches (the inverse steps just left it there; a
  // second thread would fetch its half from the other core), in parallel beyond.
  // A segment's samples are its coefficients' range; its depth-0 coefficients are in X or, for
  // a mesh whose last step wrote there, in the scratch buffer.
  const bool serial = S * K * sizeof(float) <= (std::size_t{4} << 20);
  for (std::size_t si = 0; si < segments; ++si) {
    const float* base = in_scratch[si] ? scratch : x;
    const std::size_t lo = segments_[si].lo, hi = segments_[si].hi;
    if (serial) {
      gather(lo, hi, base);
    } else {
      ParallelForRange(lo, hi, 4096, [&](std::size_t a, std::size_t b) { gather(a, b, base); });
    }
  }
  ReturnBuffers(std::move(buffers));
  if (non_finite.load(std::memory_order_relaxed)) ThrowNonFinite(channels, out);
}

// A range's plan (RelightLightsRange). Output element i of inverse step t (depth t → t − 1)
// needs the low and high coefficients near i/2, so the positions a range needs at each depth of
// a segment are an interval, about half the one below plus the filter's reach: R_0 = the range
// ∩ the segment; step t runs on the window W_{t−1} = [R_{t−1}.lo − m, R_{t−1}.hi + m) (start
// even, clipped to the signal) as on a signal of its own (its outputs exact but near a
// clipped-off end, which the margin m keeps outside R_{t−1}), reading low coefficients
// R_t = [W.lo/2, W.lo/2 + ⌈|W|/2⌉) and as many high ones (⌊|W|/2⌋) from the high band of depth
// t, which starts at SizeAtDepth(w, t). Every step down from the segment's maximum depth D runs
// (those deeper than a frame's deepest light transform zeros: no term of a shallower column
// lies in their low bands), so the plan does not depend on the lights.
struct CompressedRelighter::RangePlan {
  struct Interval {
    std::size_t lo = 0, hi = 0;
  };
  struct Seg {
    std::size_t si = 0;
    // R_0 … R_D and W_0 … W_{D−1} (step t's outputs): local positions of a mesh, rows of a
    // grid (whose steps run on whole rows; its windows are bands of rows).
    std::vector<Interval> need, window;
    Interval out;  // the range's local positions in the segment
  };
  std::size_t first = 0, last = 0;
  std::vector<Seg> segs;
  // Global elements of X that the steps read before any step writes (every high-band window
  // and R_D), merged where less than kMergeGap apart and cut into pieces of at most kRangePiece:
  // zeroed, then given the early terms, all the lights piece by piece.
  std::vector<Interval> early;
  // Per part k (the early pieces, then one per segment), stored column and T's channel, the
  // [begin, end) of its terms in that part, at offsets[2·((k·columns + slot)·P + ch)]: in an
  // early piece, its terms_ there; in a segment's part, the terms the column adds after the
  // steps of its depth: for a depth-0 column those in R_0 (terms_), else its late terms in
  // R_depth (late_terms_; none where the segment's D is at most the depth).
  std::vector<uint32_t> offsets;
  std::size_t bytes() const {
    std::size_t b =
        sizeof(*this) + sizeof(Interval) * early.capacity() + sizeof(uint32_t) * offsets.capacity();
    for (const Seg& g : segs)
      b += sizeof(Seg) + sizeof(Interval) * (g.need.capacity() + g.window.capacity());
    return b;
  }
};

std::size_t CompressedRelighter::memory_bytes() const {
  std::size_t b =
      sizeof(Term) * (terms_.capacity() + late_terms_.capacity()) +
      sizeof(Column) * columns_.capacity() + sizeof(int32_t) * slot_.capacity() +
      sizeof(uint32_t) * (coefficient_of_sample_.capacity() + tile_offsets_.capacity()) +
      sizeof(Segment) * segments_.capacity();
  {
    const std::lock_guard<std::mutex> lock(range_mutex_);
    for (const auto& p : range_plans_) b += p->bytes();
  }
  const std::lock_guard<std::mutex> lock(pool_mutex_);
  for (const auto& f : pool_)
    b += sizeof(float) * (f->x.capacity() + f->scratch.capacity() + f->scratch2.capacity());
  return b;
}

std::unique_ptr<CompressedRelighter::FrameBuffers> CompressedRelighter::TakeBuffers() const {
  const std::lock_guard<std::mutex> lock(pool_mutex_);
  if (pool_.empty()) return std::make_unique<FrameBuffers>();
  std::unique_ptr<FrameBuffers> b = std::move(pool_.back());
  pool_.pop_back();
  return b;
}

void CompressedRelighter::ReturnBuffers(std::unique_ptr<FrameBuffers> b) const {
  const std::lock_guard<std::mutex> lock(pool_mutex_);
  pool_.push_back(std::move(b));
}

void CompressedRelighter::Relight(std::span<const float> lighting_hat, int channels,
                                  std::span<float> radiance, SampleOrder order) const {
  const std::size_t S = spatial_, M = header_.column_count();
  if (channels < 1 || lighting_hat.size() != M * channels || radiance.size() != S * channels)
    throw std::invalid_argument("CompressedRelighter::Relight: buffer sizes");
  CheckChannels(channels, "CompressedRelighter::Relight");
  // Weights per column, channel-interleaved, for the columns that are stored and lit.
  std::vector<float> w;
  std::vector<Light> lights;
  w.reserve(M * channels);
  for (uint32_t j = 0; j < M; ++j) {
    if (slot_[j] < 0) continue;
    bool nz = false;
    for (int c = 0; c < channels; ++c) nz = nz || lighting_hat[c * M + j] != 0.0f;
    if (!nz) continue;
    lights.push_back({slot_[j], nullptr});
    for (int c = 0; c < channels; ++c) w.push_back(lighting_hat[c * M + j]);
  }
  for (std::size_t k = 0; k < lights.size(); ++k) lights[k].weight = w.data() + k * channels;
  RelightLights(lights, channels, {radiance.data(), nullptr, order});
}

std::vector<CompressedRelighter::Light> CompressedRelighter::LightsOf(
    std::span<const uint32_t> columns, std::span<const float> weights, int channels) const {
  if (channels < 1 || weights.size() != columns.size() * channels)
    throw std::invalid_argument("CompressedRelighter::RelightSparse: buffer sizes");
  CheckChannels(channels, "CompressedRelighter::RelightSparse");
  std::vector<Light> lights;
  lights.reserve(columns.size());
  for (std::size_t k = 0; k < columns.size(); ++k) {
    if (columns[k] >= slot_.size()) throw std::out_of_range("CompressedRelighter: column index");
    if (slot_[columns[k]] >= 0)
      lights.push_back({slot_[columns[k]], weights.data() + k * channels});
  }
  return lights;
}

void CompressedRelighter::RelightSparse(std::span<const uint32_t> columns,
                                        std::span<const float> weights, int channels,
                                        std::span<float> radiance, SampleOrder order) const {
  if (radiance.size() != spatial_ * channels)
    throw std::invalid_argument("CompressedRelighter::RelightSparse: buffer sizes");
  std::vector<Light> lights = LightsOf(columns, weights, channels);
  RelightLights(lights, channels, {radiance.data(), nullptr, order});
}

namespace {

// Elements of margin, at each level, between what a range needs of a 1D inverse step's output
// and the ends of the window the step is run on as a signal of its own: a window end that is not
// the signal's end gets a false symmetric extension, which changes the outputs within the
// filter's reach of it (LeGall 5/3's two lifting steps: 2 elements; CDF 9/7's four: 4).
constexpr std::size_t RangeMargin(WaveletFilter f) {
  return f == WaveletFilter::kLeGall53 ? 8 : 16;
}

}  // namespace

bool CompressedRelighter::RangesAreLocal() const {
  const WaveletFilter filter = ToWaveletFilter(header_.column_wavelet);
  return filter == WaveletFilter::kLeGall53 || filter == WaveletFilter::kCdf97;
}

void CompressedRelighter::RelightSparseAddRange(std::span<const uint32_t> columns,
                                                std::span<const float> weights, int channels,
                                                std::size_t first, std::size_t count,
                                                std::span<double* const> out, bool assign) const {
  if (out.size() != static_cast<std::size_t>(channels))
    throw std::invalid_argument(
        "CompressedRelighter::RelightSparseAddRange: one array per channel");
  if (first > spatial_ || count > spatial_ - first)
    throw std::out_of_range(
        "CompressedRelighter::RelightSparseAddRange: range outside the samples");
  std::vector<Light> lights = LightsOf(columns, weights, channels);
  if (count == 0) return;
  if (RangesAreLocal()) {
    RelightLightsRange(lights, channels, first, first + count, out.data(), assign);
    return;
  }
  // The whole frame, then the range.
  std::vector<std::vector<double>> full(static_cast<std::size_t>(channels),
                                        std::vector<double>(spatial_));
  std::vector<double*> ptr;
  for (auto& f : full) ptr.push_back(f.data());
  RelightLights(lights, channels, {nullptr, ptr.data(), SampleOrder::kCoefficients, true});
  for (std::size_t c = 0; c < full.size(); ++c)
    for (std::size_t p = first; p < first + count; ++p)
      out[c][p] = assign ? full[c][p] : out[c][p] + full[c][p];
}

namespace {

// Early intervals closer than this (elements) are one: fewer offsets per column, a few more
// elements zeroed and terms added that no step reads.
constexpr std::size_t kMergeGap = 32;
// Ranges whose plans are kept (a host splits each frame the same way, into about as many
// ranges as it has threads).
constexpr std::size_t kRangePlans = 32;
// The most elements of X in one piece of a range's scatter. Unlike the whole frame's 4,096-element
// tiles, pieces this long measured faster: a range's windows are many short intervals, each a new
// start in every column's terms, and cutting the long ones adds starts (demo pack, exact lighting,
// one thread: a range over every sample 13.7 ms with 4,096, 10.4 with 16,384, 9.2 with 65,536;
// halves 9.7 / 8.6 / 8.5 ms).
constexpr std::size_t kRangePiece = 65536;
// Terms prefetched ahead, as RelightLights does.
constexpr std::ptrdiff_t kRangePrefetchTerms = 256;

}  // namespace

std::shared_ptr<const CompressedRelighter::RangePlan> CompressedRelighter::BuildRangePlan(
    std::size_t first, std::size_t last) const {
  using Interval = RangePlan::Interval;
  auto plan = std::make_shared<RangePlan>();
  plan->first = first;
  plan->last = last;
  const std::size_t m = RangeMargin(ToWaveletFilter(header_.column_wavelet));
  std::vector<Interval> early;
  for (std::size_t si = 0; si < segments_.size(); ++si) {
    const Segment& b = segments_[si];
    if (!(b.lo < last && first < b.hi)) continue;
    RangePlan::Seg g;
    g.si = si;
    const auto D = static_cast<std::size_t>(b.max_depth);
    // A grid's intervals are rows (the unit of positions w); its length per depth the height.
    const bool grid = b.h > 1;
    const auto unit = grid ? static_cast<std::size_t>(b.w) : std::size_t{1};
    const int axis = grid ? b.h : b.w;
    g.need.resize(D + 1);
    g.window.resize(D);
    g.out = {std::max(first, b.lo) - b.lo, std::min(last, b.hi) - b.lo};
    g.need[0] = {g.out.lo / unit, (g.out.hi + unit - 1) / unit};
    const auto rows = [&](std::size_t lo, std::size_t hi) {
      return Interval{b.lo + lo * unit, b.lo + hi * unit};
    };
    for (std::size_t t = 1; t <= D; ++t) {
      const Interval r = g.need[t - 1];
      const auto len = static_cast<std::size_t>(SizeAtDepth(axis, static_cast<int>(t) - 1));
      const std::size_t lo = (r.lo > m ? r.lo - m : 0) & ~std::size_t{1};
      const std::size_t hi = std::min(len, r.hi + m);
      g.window[t - 1] = {lo, hi};
      g.need[t] = {lo / 2, lo / 2 + (hi - lo + 1) / 2};
      // The high band of depth t starts at SizeAtDepth(axis, t): a mesh's positions, a grid's
      // rows (whose first rows' right-hand parts are high bands too: whole rows are taken).
      const std::size_t high = static_cast<std::size_t>(SizeAtDepth(axis, static_cast<int>(t)));
      if ((hi - lo) / 2 > 0) early.push_back(rows(high + lo / 2, high + lo / 2 + (hi - lo) / 2));
      if (grid) early.push_back(rows(g.need[t].lo, g.need[t].hi));
    }
    early.push_back(rows(g.need[D].lo, g.need[D].hi));
    plan->segs.push_back(std::move(g));
  }
  std::sort(early.begin(), early.end(),
            [](const Interval& a, const Interval& b) { return a.lo < b.lo; });
  std::vector<Interval> merged;
  for (const Interval& e : early) {
    if (!merged.empty() && e.lo <= merged.back().hi + kMergeGap) {
      merged.back().hi = std::max(merged.back().hi, e.hi);
    } else {
      merged.push_back(e);
    }
  }
  for (const Interval& e : merged)
    for (std::size_t lo = e.lo; lo < e.hi; lo += kRangePiece)
      plan->early.push_back({lo, std::min(e.hi, lo + kRangePiece)});
  const std::size_t P = header_.channels, S = spatial_;
  const std::size_t E = plan->early.size(), G = plan->segs.size();
  const std::size_t per_part = columns_.size() * P;
  plan->offsets.assign(2 * (E + G) * per_part, 0);
  const auto bounds = [](const std::vector<Term>& terms, uint32_t b, uint32_t e, std::size_t lo,
                         std::size_t hi, uint32_t* out) {
    const auto less = [](const Term& t, std::size_t v) { return t.index < v; };
    const Term* p0 = std::lower_bound(terms.data() + b, terms.data() + e, lo, less);
    const Term* p1 = std::lower_bound(p0, terms.data() + e, hi, less);
    out[0] = static_cast<uint32_t>(p0 - terms.data());
    out[1] = static_cast<uint32_t>(p1 - terms.data());
  };
  for (std::size_t slot = 0; slot < columns_.size(); ++slot) {
    const Column& c = columns_[slot];
    for (std::size_t ch = 0; ch < P; ++ch) {
      const auto part = [&](std::size_t k) {
        return plan->offsets.data() + 2 * (k * per_part + slot * P + ch);
      };
      const std::size_t shift = ch * S;
      if (c.depth > 0)
        for (std::size_t k = 0; k < E; ++k)
          bounds(terms_, c.begin, c.end, shift + plan->early[k].lo, shift + plan->early[k].hi,
                 part(k));
      for (std::size_t k = 0; k < G; ++k) {
        const RangePlan::Seg& g = plan->segs[k];
        const Segment& b = segments_[g.si];
        const std::size_t unit = b.h > 1 ? static_cast<std::size_t>(b.w) : 1;
        uint32_t* f = part(E + k);
        if (c.depth == 0) {
          bounds(terms_, c.begin, c.end, shift + b.lo + g.need[0].lo * unit,
                 shift + b.lo + g.need[0].hi * unit, f);
        } else if (c.depth < b.max_depth) {
          // A grid's late terms are in the low band's columns of these rows.
          const Interval r = g.need[c.depth];
          bounds(late_terms_, c.late_begin, c.late_end, shift + b.lo + r.lo * unit,
                 shift + b.lo + r.hi * unit, f);
        }
      }
    }
  }
  return plan;
}

std::shared_ptr<const CompressedRelighter::RangePlan> CompressedRelighter::PlanRange(
    std::size_t first, std::size_t last) const {
  {
    const std::lock_guard<std::mutex> lock(range_mutex_);
    for (std::size_t i = range_plans_.size(); i-- > 0;) {
      if (range_plans_[i]->first == first && range_plans_[i]->last == last) {
        std::shared_ptr<const RangePlan> p = range_plans_[i];
        range_plans_.erase(range_plans_.begin() + static_cast<std::ptrdiff_t>(i));
        range_plans_.push_back(p);
        return p;
      }
    }
  }
  // Built outside the lock: another thread may build the same plan meanwhile; both are equal.
  std::shared_ptr<const RangePlan> p = BuildRangePlan(first, last);
  const std::lock_guard<std::mutex> lock(range_mutex_);
  if (range_plans_.size() >= kRangePlans) range_plans_.erase(range_plans_.begin());
  range_plans_.push_back(p);
  return p;
}

// Eq. 8 (Cheslack-Postava et al. 2008 §4.5, Eq. 6–7, as RelightLights runs it) for the positions
// [first, last) of the coefficient order only, with the range's plan (RangePlan above):
//   1. X's early intervals are zeroed and receive the terms of every column of depth ≥ 1 that
//      fall in them;
//   2. from each segment's maximum depth D up, a depth's late terms in R_t join the low band,
//      then step t runs on its window W_{t−1}, the low band alternating between two scratch
//      buffers (the high bands stay in X);
//   3. the depth-0 columns' terms in R_0 join, and R_0 is written out.
// The work is the range's share of the terms and of the steps plus about 2m elements per level
// and segment: a host that splits a frame into ranges splits its cost. Runs on the calling
// thread.
void CompressedRelighter::RelightLightsRange(std::vector<Light>& lights, int channels,
                                             std::size_t first, std::size_t last,
                                             double* const* out, bool assign) const {
  const std::shared_ptr<const RangePlan> plan_ptr = PlanRange(first, last);
  const RangePlan& plan = *plan_ptr;
  const std::size_t S = spatial_;
  const std::size_t P = header_.channels;
  const bool per_channel = P != 1;
  const auto C = static_cast<std::size_t>(channels);
  const std::size_t K = C == 3 ? 4 : C;
  const WaveletFilter filter = ToWaveletFilter(header_.column_wavelet);
  const bool split = InverseWavelet1DStepSplitSupported(filter, static_cast<int>(K));
  const std::size_t E = plan.early.size(), G = plan.segs.size();
  // Lights by depth, deepest first (stable: a depth's lights keep their order, as in
  // RelightLights, so sums are reproducible).
  std::stable_sort(lights.begin(), lights.end(), [&](const Light& a, const Light& b) {
    return columns_[a.slot].depth > columns_[b.slot].depth;
  });
  std::unique_ptr<FrameBuffers> buffers = TakeBuffers();
  for (auto* v : {&buffers->x, &buffers->scratch, &buffers->scratch2})
    if (v->size() < S * K) v->resize(S * K);
  float* const buf[3] = {buffers->x.data(), buffers->scratch.data(), buffers->scratch2.data()};
  float* const x = buf[0];
  for (const RangePlan::Interval& e : plan.early)
    std::memset(x + K * e.lo, 0, sizeof(float) * K * (e.hi - e.lo));

  // Terms [b, e) of T's channel ch (rows ch·S + element) with weights w, added to `dst`.
  const auto add = [&](const Term* b, const Term* e, std::size_t ch, const float* w, float* dst) {
    const std::size_t shift = ch * S;
    if (K == 4) {
      AddTerms4(dst, b, e, LaneWeights(per_channel, ch, w, C), shift, kRangePrefetchTerms);
    } else {
      for (const Term* p = b; p != e; ++p) {
        float* xi = dst + K * (static_cast<std::size_t>(p->index) - shift);
        if (per_channel) {
          xi[ch] += w[ch] * p->value;
        } else {
          for (std::size_t c = 0; c < C; ++c) xi[c] += w[c] * p->value;
        }
      }
    }
  };
  const std::size_t per_part = columns_.size() * P;
  const auto part = [&](std::size_t k, const Light& l, std::size_t ch) {
    return plan.offsets.data() + 2 * (k * per_part + static_cast<std::size_t>(l.slot) * P + ch);
  };

  // Phase 1, piece by piece (all lights per piece: the piece of X stays in cache), the next
  // light's terms prefetched while one light's are added.
  std::size_t deep_end = 0;
  while (deep_end < lights.size() && columns_[lights[deep_end].slot].depth > 0) ++deep_end;
  for (std::size_t k = 0; k < E; ++k)
    for (std::size_t l = 0; l < deep_end; ++l)
      for (std::size_t ch = 0; ch < P; ++ch) {
        const uint32_t* o = part(k, lights[l], ch);
        if (l + 1 < deep_end) {  // the next light's first 2 KB in this piece
          const uint32_t* n = part(k, lights[l + 1], ch);
          const std::ptrdiff_t len = std::min<std::ptrdiff_t>(kRangePrefetchTerms, n[1] - n[0]);
          for (std::ptrdiff_t q = 0; q < len; q += 8) __builtin_prefetch(terms_.data() + n[0] + q);
        }
        add(terms_.data() + o[0], terms_.data() + o[1], ch, lights[l].weight, x);
      }
  // Phase 2. at[k]: where segment k's low band lives (0 = X, 1 and 2 the scratch buffers).
  int d_top = 0;
  for (const RangePlan::Seg& g : plan.segs) d_top = std::max(d_top, segments_[g.si].max_depth);
  std::vector<uint8_t>& at = buffers->range_at;
  at.assign(G, 0);
  std::vector<float>& tmp = buffers->range_tmp;
  std::size_t next = 0;
  // Lights deeper than every segment of the range have no late terms in it.
  while (next < deep_end && columns_[lights[next].slot].depth > d_top) ++next;
  for (int d = d_top; d >= 1; --d) {
    for (; next < deep_end && columns_[lights[next].slot].depth == d; ++next)
      for (std::size_t ch = 0; ch < P; ++ch)
        for (std::size_t k = 0; k < G; ++k) {
          const uint32_t* o = part(E + k, lights[next], ch);
          add(late_terms_.data() + o[0], late_terms_.data() + o[1], ch, lights[next].weight,
              buf[at[k]]);
        }
    for (std::size_t k = 0; k < G; ++k) {
      const RangePlan::Seg& g = plan.segs[k];
      const Segment& b = segments_[g.si];
      if (d > b.max_depth) continue;
      const RangePlan::Interval win = g.window[static_cast<std::size_t>(d) - 1];
      const std::size_t n = win.hi - win.lo;
      const uint8_t to = at[k] == 1 ? 2 : 1;
      if (b.h > 1) {
        // A grid: the window's rows of the four bands (low rows: LL from the low band's buffer,
        // HL from X; high rows: LH and HH from X) as a Wt × n region, one in-place step, and its
        // n rows out. Rows are whole, so only the vertical direction meets a window end.
        const auto w = static_cast<std::size_t>(b.w);
        const auto wt = static_cast<std::size_t>(SizeAtDepth(b.w, d - 1));
        const auto lw = static_cast<std::size_t>(SizeAtDepth(b.w, d));
        const auto lh = static_cast<std::size_t>(SizeAtDepth(b.h, d));
        const std::size_t nl = (n + 1) / 2, area = K * wt * n;
        if (tmp.size() < 2 * area) tmp.resize(2 * area);
        for (std::size_t r = 0; r < n; ++r) {
          const std::size_t row = r < nl ? win.lo / 2 + r : lh + win.lo / 2 + (r - nl);
          const float* src = (r < nl ? buf[at[k]] : x) + K * (b.lo + row * w);
          std::memcpy(tmp.data() + K * r * wt, src, sizeof(float) * K * lw);
          std::memcpy(tmp.data() + K * (r * wt + lw), x + K * (b.lo + row * w + lw),
                      sizeof(float) * K * (wt - lw));
        }
        InverseWavelet2DStepInterleaved(filter, tmp.data(), static_cast<int>(wt),
                                        static_cast<int>(n), static_cast<int>(K), 1,
                                        tmp.data() + area);
        for (std::size_t r = 0; r < n; ++r)
          std::memcpy(buf[to] + K * (b.lo + (win.lo + r) * w), tmp.data() + K * r * wt,
                      sizeof(float) * K * wt);
        at[k] = to;
        continue;
      }
      const float* low = buf[at[k]] + K * (b.lo + win.lo / 2);
      const float* high =
          x + K * (b.lo + static_cast<std::size_t>(SizeAtDepth(b.w, d)) + win.lo / 2);
      float* dst = buf[to] + K * (b.lo + win.lo);
      if (split) {
        InverseWavelet1DStepSplit(filter, low, high, dst, static_cast<int>(n), static_cast<int>(K),
                                  1);
      } else {
        // The window's bands side by side (a length-n signal at depth 1), one in-place step.
        if (tmp.size() < 2 * K * n) tmp.resize(2 * K * n);
        const std::size_t nl = (n + 1) / 2;
        std::memcpy(tmp.data(), low, sizeof(float) * K * nl);
        std::memcpy(tmp.data() + K * nl, high, sizeof(float) * K * (n - nl));
        InverseWavelet2DStepInterleaved(filter, tmp.data(), static_cast<int>(n), 1,
                                        static_cast<int>(K), 1, tmp.data() + K * n);
        std::memcpy(dst, tmp.data(), sizeof(float) * K * n);
      }
      at[k] = to;
    }
  }
  // Phase 3.
  for (std::size_t k = 0; k < G; ++k)
    for (std::size_t l = deep_end; l < lights.size(); ++l)
      for (std::size_t ch = 0; ch < P; ++ch) {
        const uint32_t* o = part(E + k, lights[l], ch);
        add(terms_.data() + o[0], terms_.data() + o[1], ch, lights[l].weight, buf[at[k]]);
      }
  // Out, with the finite check.
  for (std::size_t k = 0; k < G; ++k) {
    const RangePlan::Seg& g = plan.segs[k];
    const Segment& b = segments_[g.si];
    const float* src = buf[at[k]];
    for (std::size_t p = b.lo + g.out.lo; p < b.lo + g.out.hi; ++p) {
      const float* xi = src + K * p;
      for (std::size_t c = 0; c < C; ++c) {
        if (!std::isfinite(xi[c])) {
          ReturnBuffers(std::move(buffers));
          const auto sample = static_cast<std::size_t>(
              std::find(coefficient_of_sample_.begin(), coefficient_of_sample_.end(), p) -
              coefficient_of_sample_.begin());
          throw NumericalError(name_ + ": the relit radiance of sample " + std::to_string(sample) +
                               " (channel " + std::to_string(c) + ") is " +
                               (std::isnan(xi[c]) ? "NaN" : "Inf") +
                               ": T·L overflows the relighter's float range (3.4e38); the "
                               "lighting is too bright for this transport");
        }
        out[c][p] = assign ? static_cast<double>(xi[c]) : out[c][p] + static_cast<double>(xi[c]);
      }
    }
  }
  ReturnBuffers(std::move(buffers));
}

void CompressedRelighter::RelightSparseAdd(std::span<const uint32_t> columns,
                                           std::span<const float> weights, int channels,
                                           std::span<double* const> out, SampleOrder order,
                                           bool assign) const {
  if (out.size() != static_cast<std::size_t>(channels))
    throw std::invalid_argument("CompressedRelighter::RelightSparseAdd: one array per channel");
  std::vector<Light> lights = LightsOf(columns, weights, channels);
  RelightLights(lights, channels, {nullptr, out.data(), order, assign});
}

}  // namespace prt
