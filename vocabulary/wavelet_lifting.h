// The 1D lifting and filter kernels of the wavelet transforms, shared by wavelets.cpp (the
// transforms) and wavelet_synthesis_simd.cpp (the relighter's vectorised synthesis steps).
// Internal to vocabulary/: wavelets.h is the interface.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>

#include "vocabulary/wavelet_filter.h"

namespace prt::wavelet_detail {

constexpr double kSqrt2 = std::numbers::sqrt2;
constexpr double kInvSqrt2 = 1.0 / std::numbers::sqrt2;

// Daubechies-4 scaling filter h (Daubechies 1988), wavelet filter g_k = (−1)^k h_{3−k}.
constexpr double kSqrt3 = std::numbers::sqrt3;
constexpr double kD4H0 = (1 + kSqrt3) / (4 * std::numbers::sqrt2);
constexpr double kD4H1 = (3 + kSqrt3) / (4 * std::numbers::sqrt2);
constexpr double kD4H2 = (3 - kSqrt3) / (4 * std::numbers::sqrt2);
constexpr double kD4H3 = (1 - kSqrt3) / (4 * std::numbers::sqrt2);
constexpr double kD4G0 = kD4H3;
constexpr double kD4G1 = -kD4H2;
constexpr double kD4G2 = kD4H1;
constexpr double kD4G3 = -kD4H0;

// Lifting factorisations (Daubechies & Sweldens 1998; JPEG 2000 Part 1 Annex F). Steps
// alternate: step 0 updates the odd (high) samples from their even neighbours, step 1 the even
// (low) samples from their odd neighbours, and so on. After lifting the low band has DC gain
// `k` and the high band Nyquist gain 2/k; the final scales make both √2.
struct LiftingScheme {
  int steps;
  double coef[4];
  double low_scale;
  double high_scale;
};
constexpr double kCdf97K = 1.230174104914001;
constexpr LiftingScheme kLeGall53Scheme{2, {-0.5, 0.25, 0, 0}, kSqrt2, kInvSqrt2};
constexpr LiftingScheme kCdf97Scheme{
    4,
    {-1.586134342059924, -0.052980118572961, 0.882911075530934, 0.443506852043971},
    kSqrt2 / kCdf97K,
    kCdf97K / kSqrt2};

inline const LiftingScheme& SchemeOf(WaveletFilter f) {
  return f == WaveletFilter::kLeGall53 ? kLeGall53Scheme : kCdf97Scheme;
}

inline bool IsPowerOfTwo(int n) {
  return n >= 1 && (n & (n - 1)) == 0;
}

inline int Log2(int n) {
  int d = 0;
  while ((1 << d) < n) ++d;
  return d;
}

[[noreturn]] inline void Fail(const char* where, const std::string& what) {
  throw std::invalid_argument(std::string(where) + ": " + what);
}

// ---- 1D kernels ------------------------------------------------------------------------------
// A "line" of `len` elements; element i starts at p + i·stride and holds `width` doubles. With
// kScalar the elements are single contiguous doubles (stride 1, width 1), which is the
// horizontal pass; otherwise elements are rows of a region, which makes the vertical pass a
// sequence of contiguous row operations.

template <bool kScalar, typename T = double>
struct Line {
  T* p;
  std::ptrdiff_t stride;
  int width;
  T* operator[](int i) const { return p + static_cast<std::ptrdiff_t>(i) * Stride(); }
  std::ptrdiff_t Stride() const { return kScalar ? 1 : stride; }
  int Width() const { return kScalar ? 1 : width; }
};

template <bool kScalar, typename T = double>
inline void CopyElem(const Line<kScalar, T>& from, int i, const Line<kScalar, T>& to, int j) {
  const T* a = from[i];
  T* b = to[j];
  for (int x = 0; x < from.Width(); ++x) b[x] = a[x];
}

template <bool kScalar, typename T = double>
inline void ScaleElems(const Line<kScalar, T>& l, int begin, int end, double scale) {
  const T c = static_cast<T>(scale);
  for (int i = begin; i < end; ++i) {
    T* a = l[i];
    for (int x = 0; x < l.Width(); ++x) a[x] *= c;
  }
}

// d[n] += c·(s[n] + s[n+1]) with s[ns] ≡ s[ns−1] (symmetric extension at an even length's end).
template <bool kScalar, typename T = double>
void LiftOdd(const Line<kScalar, T>& s, const Line<kScalar, T>& d, int ns, int nd, double coef) {
  const T c = static_cast<T>(coef);
  const int full = ns > nd ? nd : nd - 1;
  const int w = s.Width();
  for (int n = 0; n < full; ++n) {
    T* dn = d[n];
    const T* s0 = s[n];
    const T* s1 = s[n + 1];
    for (int x = 0; x < w; ++x) dn[x] += c * (s0[x] + s1[x]);
  }
  if (full < nd) {
    T* dn = d[nd - 1];
    const T* s0 = s[nd - 1];
    for (int x = 0; x < w; ++x) dn[x] += 2 * c * s0[x];
  }
}

// s[n] += c·(d[n−1] + d[n]) with d[−1] ≡ d[0] and d[nd] ≡ d[nd−1] (symmetric extension).
template <bool kScalar, typename T = double>
void LiftEven(const Line<kScalar, T>& s, const Line<kScalar, T>& d, int ns, int nd, double coef) {
  const T c = static_cast<T>(coef);
  if (nd == 0) return;
  const int w = s.Width();
  {
    T* s0 = s[0];
    const T* d0 = d[0];
    for (int x = 0; x < w; ++x) s0[x] += 2 * c * d0[x];
  }
  for (int n = 1; n < nd; ++n) {
    T* sn = s[n];
    const T* d0 = d[n - 1];
    const T* d1 = d[n];
    for (int x = 0; x < w; ++x) sn[x] += c * (d0[x] + d1[x]);
  }
  if (ns > nd) {
    T* sn = s[nd];
    const T* d0 = d[nd - 1];
    for (int x = 0; x < w; ++x) sn[x] += 2 * c * d0[x];
  }
}

// One analysis step of the lifting filters (Cheslack-Postava et al. §4.1: JPEG 2000's 5/3 and
// 9/7). `in` (len elements, read only) → `out`: low at [0, ⌈len/2⌉), high after it.
template <bool kScalar, typename T = double>
void AnalyzeLifting(const LiftingScheme& ls, const Line<kScalar, T>& in,
                    const Line<kScalar, T>& out, int len) {
  const int ns = (len + 1) / 2;
  const int nd = len / 2;
  for (int j = 0; j < ns; ++j) CopyElem(in, 2 * j, out, j);
  for (int j = 0; j < nd; ++j) CopyElem(in, 2 * j + 1, out, ns + j);
  if (nd == 0) return;  // length 1: identity
  const Line<kScalar, T> s = out;
  const Line<kScalar, T> d{out[ns], out.stride, out.width};
  for (int k = 0; k < ls.steps; ++k) {
    if (k % 2 == 0) {
      LiftOdd(s, d, ns, nd, ls.coef[k]);
    } else {
      LiftEven(s, d, ns, nd, ls.coef[k]);
    }
  }
  ScaleElems(out, 0, ns, ls.low_scale);
  ScaleElems(out, ns, len, ls.high_scale);
}

// Inverse of AnalyzeLifting: `in` (overwritten) → interleaved samples in `out`.
template <bool kScalar, typename T = double>
void SynthesizeLifting(const LiftingScheme& ls, const Line<kScalar, T>& in,
                       const Line<kScalar, T>& out, int len) {
  const int ns = (len + 1) / 2;
  const int nd = len / 2;
  if (nd > 0) {
    ScaleElems(in, 0, ns, 1.0 / ls.low_scale);
    ScaleElems(in, ns, len, 1.0 / ls.high_scale);
    const Line<kScalar, T> s = in;
    const Line<kScalar, T> d{in[ns], in.stride, in.width};
    for (int k = ls.steps - 1; k >= 0; --k) {
      if (k % 2 == 0) {
        LiftOdd(s, d, ns, nd, -ls.coef[k]);
      } else {
        LiftEven(s, d, ns, nd, -ls.coef[k]);
      }
    }
  }
  for (int j = 0; j < ns; ++j) CopyElem(in, j, out, 2 * j);
  for (int j = 0; j < nd; ++j) CopyElem(in, ns + j, out, 2 * j + 1);
}

// Orthonormal Haar step (Ng et al. 2003): a = (x0 + x1)/√2, d = (x0 − x1)/√2. len even.
template <bool kScalar, typename T = double>
void AnalyzeHaar(const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  const int half = len / 2;
  const int w = in.Width();
  for (int j = 0; j < half; ++j) {
    const T* x0 = in[2 * j];
    const T* x1 = in[2 * j + 1];
    T* a = out[j];
    T* d = out[half + j];
    for (int x = 0; x < w; ++x) {
      a[x] = static_cast<T>(kInvSqrt2 * (x0[x] + x1[x]));
      d[x] = static_cast<T>(kInvSqrt2 * (x0[x] - x1[x]));
    }
  }
}

template <bool kScalar, typename T = double>
void SynthesizeHaar(const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  const int half = len / 2;
  const int w = in.Width();
  for (int j = 0; j < half; ++j) {
    const T* a = in[j];
    const T* d = in[half + j];
    T* x0 = out[2 * j];
    T* x1 = out[2 * j + 1];
    for (int x = 0; x < w; ++x) {
      x0[x] = static_cast<T>(kInvSqrt2 * (a[x] + d[x]));
      x1[x] = static_cast<T>(kInvSqrt2 * (a[x] - d[x]));
    }
  }
}

// Orthonormal Daubechies-4 step with periodic extension (Daubechies 1988):
// a[j] = Σ_k h_k x[(2j+k) mod len], d[j] = Σ_k g_k x[(2j+k) mod len]. len even.
template <bool kScalar, typename T = double>
void AnalyzeD4(const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  const int half = len / 2;
  const int w = in.Width();
  for (int j = 0; j < half; ++j) {
    const T* x0 = in[2 * j];
    const T* x1 = in[2 * j + 1];
    const int wrap = 2 * j + 2 < len ? 0 : len;  // periodic extension, only at the last j
    const T* x2 = in[2 * j + 2 - wrap];
    const T* x3 = in[2 * j + 3 - wrap];
    T* a = out[j];
    T* d = out[half + j];
    for (int x = 0; x < w; ++x) {
      a[x] = static_cast<T>(kD4H0 * x0[x] + kD4H1 * x1[x] + kD4H2 * x2[x] + kD4H3 * x3[x]);
      d[x] = static_cast<T>(kD4G0 * x0[x] + kD4G1 * x1[x] + kD4G2 * x2[x] + kD4G3 * x3[x]);
    }
  }
}

// x[2i] = h0 a[i] + g0 d[i] + h2 a[i−1] + g2 d[i−1],
// x[2i+1] = h1 a[i] + g1 d[i] + h3 a[i−1] + g3 d[i−1]   (indices of a, d mod len/2).
template <bool kScalar, typename T = double>
void SynthesizeD4(const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  const int half = len / 2;
  const int w = in.Width();
  for (int i = 0; i < half; ++i) {
    const int p = i == 0 ? half - 1 : i - 1;  // periodic extension
    const T* a = in[i];
    const T* d = in[half + i];
    const T* ap = in[p];
    const T* dp = in[half + p];
    T* x0 = out[2 * i];
    T* x1 = out[2 * i + 1];
    for (int x = 0; x < w; ++x) {
      x0[x] = static_cast<T>(kD4H0 * a[x] + kD4G0 * d[x] + kD4H2 * ap[x] + kD4G2 * dp[x]);
      x1[x] = static_cast<T>(kD4H1 * a[x] + kD4G1 * d[x] + kD4H3 * ap[x] + kD4G3 * dp[x]);
    }
  }
}

template <bool kScalar, typename T = double>
void Analyze(WaveletFilter f, const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  switch (f) {
    case WaveletFilter::kHaar:
      AnalyzeHaar(in, out, len);
      break;
    case WaveletFilter::kDaubechies4:
      AnalyzeD4(in, out, len);
      break;
    default:
      AnalyzeLifting(SchemeOf(f), in, out, len);
      break;
  }
}

template <bool kScalar, typename T = double>
void Synthesize(WaveletFilter f, const Line<kScalar, T>& in, const Line<kScalar, T>& out, int len) {
  switch (f) {
    case WaveletFilter::kHaar:
      SynthesizeHaar(in, out, len);
      break;
    case WaveletFilter::kDaubechies4:
      SynthesizeD4(in, out, len);
      break;
    default:
      SynthesizeLifting(SchemeOf(f), in, out, len);
      break;
  }
}

// ---- argument checks (wavelets.cpp) -----------------------------------------------------------

int CheckedMaxDepth1D(const char* where, WaveletFilter f, int length);
int CheckedMaxDepth2D(const char* where, WaveletFilter f, int w, int h);
void CheckDepth(const char* where, int depth, int max_depth);
void CheckStep(const char* where, int step, int max_depth);
inline std::size_t Area(int w, int h) {
  return static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
}

}  // namespace prt::wavelet_detail
