// The relighter's synthesis steps (Cheslack-Postava et al. 2008 §4.5, Eq. 8: one single-step
// inverse per level per frame): LeGall 5/3 fused and vectorised on interleaved channels (SSE,
// and AVX where the CPU has it), bit for bit the generic lifting's result. wavelets.h declares
// them; wavelet_lifting.h holds the generic kernels they fall back on.
#include <algorithm>
#include <cstddef>
#include <cstring>
#include <utility>

#include "vocabulary/wavelet_lifting.h"
#include "vocabulary/wavelets.h"

namespace prt {

using namespace wavelet_detail;

namespace {

// Elements of the fused kernel: one float, or four (GCC/Clang vector extension: one SSE register).
using Float4 = float __attribute__((vector_size(16)));
template <typename V>
inline V LoadElem(const float* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
template <typename V>
inline void StoreElem(float* p, V v) {
  std::memcpy(p, &v, sizeof v);
}

// LeGall 5/3 synthesis (SynthesizeLifting with kLeGall53Scheme) fused into one pass: `in` holds
// len elements V (low band at [0, ns), high band after it), `out` receives them interleaved.
// Unscaled s' = s/√2, d' = √2·d; even update S[n] = s'[n] − ¼(d'[n−1] + d'[n]); odd predict
// out[2n+1] = d'[n] + ½(S[n] + S[n+1]); the symmetric extensions of LiftEven and LiftOdd are
// d'[−1] ≡ d'[0], d'[nd] ≡ d'[nd−1] and S[ns] ≡ S[ns−1].
// The low band s and the high band d may lie apart (InverseWavelet1DStepSplit); `out` may be
// the buffer that holds d, starting ns elements before it: every element is read before the
// stores that could reach it (at iteration n the stores go to 2n, 2n + 1 <= ns + n, the loads
// to ns + n + 1 and beyond are still to come).
template <typename V>
struct LeGall53Synthesis {
  const float a = static_cast<float>(1.0 / kLeGall53Scheme.low_scale);
  const float c = static_cast<float>(1.0 / kLeGall53Scheme.high_scale);
  const float b = static_cast<float>(-kLeGall53Scheme.coef[1] / kLeGall53Scheme.high_scale);
  const float p = static_cast<float>(-kLeGall53Scheme.coef[0]);

  // Elements 2n, 2n + 1, … of the output from element n on, given cur = S[n] (nd ≥ 1).
  void From(const float* s, const float* d, float* out, int len, int n, V cur) const {
    constexpr std::ptrdiff_t kW = sizeof(V) / sizeof(float);
    const int ns = (len + 1) / 2, nd = len / 2;
    // Interior: S[n + 1] needs d[n] and d[n + 1], both inside the high band.
    for (; n + 1 < nd; ++n) {
      const V dn = LoadElem<V>(d + n * kW);
      const V next = a * LoadElem<V>(s + (n + 1) * kW) + b * (dn + LoadElem<V>(d + (n + 1) * kW));
      StoreElem(out + 2 * n * kW, cur);
      StoreElem(out + (2 * n + 1) * kW, c * dn + p * (cur + next));
      cur = next;
    }
    // The last odd sample: S[nd] exists only for odd lengths (d[nd] ≡ d[nd − 1]).
    const V dl = LoadElem<V>(d + n * kW);
    const V next = nd < ns ? a * LoadElem<V>(s + nd * kW) + b * (dl + dl) : cur;
    StoreElem(out + 2 * n * kW, cur);
    StoreElem(out + (2 * n + 1) * kW, c * dl + p * (cur + next));
    if (nd < ns) StoreElem(out + 2 * nd * kW, next);
  }
};

template <typename V>
void SynthesizeLeGall53Fused(const float* s, const float* d, float* out, int len) {
  if (len / 2 == 0) {  // length 1: identity, as SynthesizeLifting
    StoreElem(out, LoadElem<V>(s));
    return;
  }
  const LeGall53Synthesis<V> k;
  const V d0 = LoadElem<V>(d);
  k.From(s, d, out, len, 0, k.a * LoadElem<V>(s) + k.b * (d0 + d0));  // S[0], d[−1] ≡ d[0]
}

#if defined(__x86_64__)
// SynthesizeLeGall53Fused<Float4> with two elements per 256-bit vector (AVX; chosen at run time,
// the build targets baseline x86-64): the same operations on every element in the same order,
// so the same bits. Only the interior runs two at a time; the ends are the generic code's.
// Aliasing as SynthesizeLeGall53Fused's: the pair at n stores out[2n, 2n + 4) after it has
// loaded d up to n + 3, and later pairs load d from n + 3 on, which sits at out[ns + n + 3] >
// 2n + 3 while n < ns.
using Float8 = float __attribute__((vector_size(32)));

__attribute__((target("avx"))) void SynthesizeLeGall53Float4Avx(const float* s, const float* d,
                                                                float* out, int len) {
  const int nd = len / 2;
  if (nd < 5) {
    SynthesizeLeGall53Fused<Float4>(s, d, out, len);
    return;
  }
  const LeGall53Synthesis<Float4> k;
  const float a = k.a, b = k.b, c = k.c, p = k.p;
  Float4 s0, s1, d0, d1;
  std::memcpy(&s0, s, sizeof s0);
  std::memcpy(&s1, s + 4, sizeof s1);
  std::memcpy(&d0, d, sizeof d0);
  std::memcpy(&d1, d + 4, sizeof d1);
  // Element 0 as the generic code computes it: S[0] (d[−1] ≡ d[0]), S[1], out[0], out[1].
  const Float4 S0 = a * s0 + b * (d0 + d0);
  const Float4 S1 = a * s1 + b * (d0 + d1);
  const Float4 O0 = c * d0 + p * (S0 + S1);
  std::memcpy(out, &S0, sizeof S0);
  std::memcpy(out + 4, &O0, sizeof O0);
  const Float8 a8 = {a, a, a, a, a, a, a, a}, b8 = {b, b, b, b, b, b, b, b};
  const Float8 c8 = {c, c, c, c, c, c, c, c}, p8 = {p, p, p, p, p, p, p, p};
  // Unaligned 256-bit loads (a lambda returning the vector would not be compiled for AVX).
  Float8 l0, l1, l2;
#define PRT_LOAD8(v, q) std::memcpy(&(v), (q), sizeof(Float8))
  // Sv = (S[n], S[n + 1]), S[m] = a·s[m] + b·(d[m − 1] + d[m]) for m ≥ 1.
  int n = 1;
  PRT_LOAD8(l0, s + 4 * n);
  PRT_LOAD8(l1, d + 4 * (n - 1));
  PRT_LOAD8(l2, d + 4 * n);
  Float8 Sv = a8 * l0 + b8 * (l1 + l2);
  for (; n + 3 <= nd - 1; n += 2) {
    PRT_LOAD8(l0, s + 4 * (n + 2));
    PRT_LOAD8(l1, d + 4 * (n + 1));
    PRT_LOAD8(l2, d + 4 * (n + 2));
    const Float8 S2 = a8 * l0 + b8 * (l1 + l2);
    Float8 dv;
    PRT_LOAD8(dv, d + 4 * n);
    const Float8 Snext = __builtin_shufflevector(Sv, S2, 4, 5, 6, 7, 8, 9, 10, 11);
    const Float8 O = c8 * dv + p8 * (Sv + Snext);
    const Float8 lo = __builtin_shufflevector(Sv, O, 0, 1, 2, 3, 8, 9, 10, 11);
    const Float8 hi = __builtin_shufflevector(Sv, O, 4, 5, 6, 7, 12, 13, 14, 15);
    std::memcpy(out + 8 * n, &lo, sizeof lo);
    std::memcpy(out + 8 * n + 8, &hi, sizeof hi);
    Sv = S2;
  }
#undef PRT_LOAD8
  // The rest as the generic code, from S[n] (Sv's first element).
  k.From(s, d, out, len, n, Float4{Sv[0], Sv[1], Sv[2], Sv[3]});
}
#endif

bool g_wavelet_avx = [] {
#if defined(__x86_64__)
  __builtin_cpu_init();  // a static initializer may run before the one that fills the CPU model
  return __builtin_cpu_supports("avx") != 0;
#else
  return false;
#endif
}();

// SynthesizeLeGall53Fused<Float4>, two elements at a time where the CPU has AVX.
void SynthesizeLeGall53Float4(const float* s, const float* d, float* out, int len) {
#if defined(__x86_64__)
  if (g_wavelet_avx) {
    SynthesizeLeGall53Float4Avx(s, d, out, len);
    return;
  }
#endif
  SynthesizeLeGall53Fused<Float4>(s, d, out, len);
}

// One horizontal synthesis of `len` elements of `channels` floats, fused where it can be.
void SynthesizeInterleavedRow(WaveletFilter filter, float* in, float* out, int len, int channels) {
  if (filter == WaveletFilter::kLeGall53) {
    switch (channels) {
      case 1:
        SynthesizeLeGall53Fused<float>(in, in + (len + 1) / 2, out, len);
        return;
      case 4:
        SynthesizeLeGall53Float4(in, in + 4 * ((len + 1) / 2), out, len);
        return;
      default:
        break;
    }
  }
  Synthesize<false, float>(filter, {in, channels, channels}, {out, channels, channels}, len);
}

// The LeGall 5/3 synthesis of SynthesizeLeGall53Fused with elements that are whole rows: `len`
// rows of `width` floats, `stride` floats apart, low band rows first (the vertical pass of a
// grid's inverse step). Column blocks of kBlock floats keep S[n] in a local row; each float
// goes through the same operations as the per-element kernel.
void SynthesizeLeGall53Rows(const float* in, float* out, std::ptrdiff_t stride, int len,
                            int width) {
  const int ns = (len + 1) / 2, nd = len / 2;
  if (nd == 0) {
    std::memcpy(out, in, sizeof(float) * static_cast<std::size_t>(width));
    return;
  }
  const LeGall53Synthesis<float> k;
  const float a = k.a, b = k.b, c = k.c, p = k.p;
  const float* s = in;
  const float* d = in + ns * stride;
  constexpr int kBlock = 64;
  float cur[kBlock], next[kBlock];
  for (int j0 = 0; j0 < width; j0 += kBlock) {
    const int bw = std::min(kBlock, width - j0);
    for (int j = 0; j < bw; ++j) {  // S[0], d[−1] ≡ d[0]
      const float d0 = d[j0 + j];
      cur[j] = a * s[j0 + j] + b * (d0 + d0);
    }
    for (int n = 0; n < nd; ++n) {
      const float* dn = d + n * stride + j0;
      float* even = out + 2 * n * stride + j0;
      float* odd = even + stride;
      if (n + 1 < nd) {
        const float* sn1 = s + (n + 1) * stride + j0;
        const float* dn1 = dn + stride;
        for (int j = 0; j < bw; ++j) next[j] = a * sn1[j] + b * (dn[j] + dn1[j]);
      } else if (nd < ns) {  // S[nd] of an odd length, d[nd] ≡ d[nd − 1]
        const float* snd = s + nd * stride + j0;
        for (int j = 0; j < bw; ++j) next[j] = a * snd[j] + b * (dn[j] + dn[j]);
      } else {  // S[ns] ≡ S[ns − 1]
        for (int j = 0; j < bw; ++j) next[j] = cur[j];
      }
      for (int j = 0; j < bw; ++j) {
        even[j] = cur[j];
        odd[j] = c * dn[j] + p * (cur[j] + next[j]);
        cur[j] = next[j];
      }
    }
    if (nd < ns) std::memcpy(out + 2 * nd * stride + j0, cur, sizeof(float) * bw);
  }
}

}  // namespace

// The vertical pass first, then the horizontal one (as InverseStep2D); each reads one buffer and
// writes the other, so the result ends in `data` or is copied back once.
void InverseWavelet2DStepInterleaved(WaveletFilter filter, float* data, int width, int height,
                                     int channels, int step, float* scratch) {
  CheckStep("InverseWavelet2DStepInterleaved", step,
            CheckedMaxDepth2D("InverseWavelet2DStepInterleaved", filter, width, height));
  if (channels < 1) Fail("InverseWavelet2DStepInterleaved", "channels must be at least 1");
  const int wc = SizeAtDepth(width, step - 1), hc = SizeAtDepth(height, step - 1);
  const std::ptrdiff_t row = static_cast<std::ptrdiff_t>(width) * channels;
  const int row_floats = wc * channels;
  float* src = data;
  float* dst = scratch;
  if (hc >= 2) {  // elements: the region's rows, wc·channels floats each
    if (filter == WaveletFilter::kLeGall53) {
      SynthesizeLeGall53Rows(src, dst, row, hc, row_floats);
    } else {
      Synthesize<false, float>(filter, {src, row, row_floats}, {dst, row, row_floats}, hc);
    }
    std::swap(src, dst);
  }
  if (wc >= 2) {  // elements: one sample's channels
    for (int y = 0; y < hc; ++y) {
      SynthesizeInterleavedRow(filter, src + y * row, dst + y * row, wc, channels);
    }
    std::swap(src, dst);
  }
  if (src != data) {
    for (int y = 0; y < hc; ++y)
      std::memcpy(data + y * row, src + y * row,
                  sizeof(float) * static_cast<std::size_t>(row_floats));
  }
}

bool InverseWavelet1DStepSplitSupported(WaveletFilter filter, int channels) {
  return filter == WaveletFilter::kLeGall53 && (channels == 1 || channels == 4);
}

void InverseWavelet1DStepSplit(WaveletFilter filter, const float* low, const float* high,
                               float* out, int length, int channels, int step) {
  if (!InverseWavelet1DStepSplitSupported(filter, channels))
    Fail("InverseWavelet1DStepSplit", "only LeGall 5/3 on 1 or 4 interleaved channels");
  CheckStep("InverseWavelet1DStepSplit", step,
            CheckedMaxDepth2D("InverseWavelet1DStepSplit", filter, length, 1));
  const int len = SizeAtDepth(length, step - 1);
  if (len < 2) {
    std::memcpy(out, low, sizeof(float) * static_cast<std::size_t>(channels));
    return;
  }
  if (channels == 1) {
    SynthesizeLeGall53Fused<float>(low, high, out, len);
  } else {
    SynthesizeLeGall53Float4(low, high, out, len);
  }
}

bool SetWaveletAvx(bool enable) {
  const bool before = g_wavelet_avx;
#if defined(__x86_64__)
  g_wavelet_avx = enable && __builtin_cpu_supports("avx") != 0;
#else
  (void)enable;
#endif
  return before;
}

}  // namespace prt
