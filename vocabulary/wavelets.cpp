// Wavelet transforms: orthonormal Haar and Daubechies-4 (periodic) on power-of-two faces, LeGall
// 5/3 and CDF 9/7 by lifting with whole-sample symmetric extension on any length; 1D and 2D
// non-standard decompositions with partial depth and single steps. Conventions: wavelets.h and
// docs/wavelets.md.
#include "vocabulary/wavelets.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

#include "vocabulary/cubemap.h"

namespace prt {
namespace {

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

const LiftingScheme& SchemeOf(WaveletFilter f) {
  return f == WaveletFilter::kLeGall53 ? kLeGall53Scheme : kCdf97Scheme;
}

bool IsPowerOfTwo(int n) {
  return n >= 1 && (n & (n - 1)) == 0;
}

int Log2(int n) {
  int d = 0;
  while ((1 << d) < n) ++d;
  return d;
}

[[noreturn]] void Fail(const char* where, const std::string& what) {
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

// ---- 2D steps on a double region -------------------------------------------------------------
// `a` holds the region (row stride `stride`), `b` is scratch of the same shape. A forward step on
// the top-left wc×hc block: rows (horizontal 1D step) then columns (vertical 1D step, done as
// whole-row operations), the non-standard decomposition of Ng et al. 2003 / Overbeck et al.
// 2006 §5.1. Results end in `a`.

void CopyBlock(const double* from, double* to, std::ptrdiff_t stride, int wc, int hc) {
  for (int y = 0; y < hc; ++y) {
    std::memcpy(to + y * stride, from + y * stride, sizeof(double) * static_cast<std::size_t>(wc));
  }
}

// Haar in one pass over 2×2 blocks (same result as rows then columns): with the block
//   p q
//   r s   LL = (p+q+r+s)/2, HL = (p−q+r−s)/2, LH = (p+q−r−s)/2, HH = (p−q−r+s)/2.
void ForwardHaarStep2D(double* a, double* b, std::ptrdiff_t stride, int wc, int hc) {
  const int hw = wc / 2, hh = hc / 2;
  for (int j = 0; j < hh; ++j) {
    const double* r0 = a + 2 * j * stride;
    const double* r1 = r0 + stride;
    double* ll = b + j * stride;
    double* hl = ll + hw;
    double* lh = b + (hh + j) * stride;
    double* hh_row = lh + hw;
    for (int i = 0; i < hw; ++i) {
      const double p = r0[2 * i], q = r0[2 * i + 1], r = r1[2 * i], s = r1[2 * i + 1];
      const double top = p + q, bottom = r + s, left = p + r, right = q + s;
      ll[i] = 0.5 * (top + bottom);
      hl[i] = 0.5 * (left - right);
      lh[i] = 0.5 * (top - bottom);
      hh_row[i] = 0.5 * ((p - q) - (r - s));
    }
  }
  CopyBlock(b, a, stride, wc, hc);
}

void InverseHaarStep2D(double* a, double* b, std::ptrdiff_t stride, int wc, int hc) {
  const int hw = wc / 2, hh = hc / 2;
  for (int j = 0; j < hh; ++j) {
    const double* ll = a + j * stride;
    const double* hl = ll + hw;
    const double* lh = a + (hh + j) * stride;
    const double* hh_row = lh + hw;
    double* r0 = b + 2 * j * stride;
    double* r1 = r0 + stride;
    for (int i = 0; i < hw; ++i) {
      const double sum_l = ll[i] + lh[i], dif_l = ll[i] - lh[i];
      const double sum_h = hl[i] + hh_row[i], dif_h = hl[i] - hh_row[i];
      r0[2 * i] = 0.5 * (sum_l + sum_h);
      r0[2 * i + 1] = 0.5 * (sum_l - sum_h);
      r1[2 * i] = 0.5 * (dif_l + dif_h);
      r1[2 * i + 1] = 0.5 * (dif_l - dif_h);
    }
  }
  CopyBlock(b, a, stride, wc, hc);
}

void ForwardStep2D(WaveletFilter f, double* a, double* b, std::ptrdiff_t stride, int wc, int hc) {
  if (f == WaveletFilter::kHaar) {
    ForwardHaarStep2D(a, b, stride, wc, hc);
    return;
  }
  double* src = a;
  if (wc >= 2) {
    for (int y = 0; y < hc; ++y) {
      Analyze<true>(f, {a + y * stride, 1, 1}, {b + y * stride, 1, 1}, wc);
    }
    src = b;
  }
  if (hc >= 2) {
    double* dst = src == a ? b : a;
    Analyze<false>(f, {src, stride, wc}, {dst, stride, wc}, hc);
    src = dst;
  }
  if (src != a) CopyBlock(src, a, stride, wc, hc);
}

void InverseStep2D(WaveletFilter f, double* a, double* b, std::ptrdiff_t stride, int wc, int hc) {
  if (f == WaveletFilter::kHaar) {
    InverseHaarStep2D(a, b, stride, wc, hc);
    return;
  }
  double* src = a;
  if (hc >= 2) {
    Synthesize<false>(f, {a, stride, wc}, {b, stride, wc}, hc);
    src = b;
  }
  if (wc >= 2) {
    double* dst = src == a ? b : a;
    for (int y = 0; y < hc; ++y) {
      Synthesize<true>(f, {src + y * stride, 1, 1}, {dst + y * stride, 1, 1}, wc);
    }
    src = dst;
  }
  if (src != a) CopyBlock(src, a, stride, wc, hc);
}

void LoadBlock(const float* data, std::ptrdiff_t data_stride, double* a, std::ptrdiff_t stride,
               int wc, int hc) {
  for (int y = 0; y < hc; ++y) {
    const float* row = data + y * data_stride;
    double* out = a + y * stride;
    for (int x = 0; x < wc; ++x) out[x] = row[x];
  }
}

void StoreBlock(const double* a, std::ptrdiff_t stride, float* data, std::ptrdiff_t data_stride,
                int wc, int hc) {
  for (int y = 0; y < hc; ++y) {
    const double* in = a + y * stride;
    float* row = data + y * data_stride;
    for (int x = 0; x < wc; ++x) row[x] = static_cast<float>(in[x]);
  }
}

// ---- argument checks -------------------------------------------------------------------------

int CheckedMaxDepth1D(const char* where, WaveletFilter f, int length) {
  if (length < 1) Fail(where, "length must be at least 1, got " + std::to_string(length));
  if (!IsLiftingFilter(f) && !IsPowerOfTwo(length)) {
    Fail(where, std::string(WaveletFilterName(f)) + " needs a power-of-two length, got " +
                    std::to_string(length));
  }
  return Log2(length);  // ⌈log2 length⌉
}

int CheckedMaxDepth2D(const char* where, WaveletFilter f, int w, int h) {
  if (w < 1 || h < 1) {
    Fail(where, "size must be at least 1×1, got " + std::to_string(w) + "×" + std::to_string(h));
  }
  if (!IsLiftingFilter(f) && (w != h || !IsPowerOfTwo(w))) {
    Fail(where, std::string(WaveletFilterName(f)) +
                    " needs a square power-of-two region (a cubemap face), got " +
                    std::to_string(w) + "×" + std::to_string(h));
  }
  return Log2(std::max(w, h));
}

void CheckDepth(const char* where, int depth, int max_depth) {
  if (depth < 0 || depth > max_depth) {
    Fail(where,
         "depth " + std::to_string(depth) + " outside [0, " + std::to_string(max_depth) + "]");
  }
}

void CheckStep(const char* where, int step, int max_depth) {
  if (step < 1 || step > max_depth) {
    Fail(where, "step " + std::to_string(step) + " outside [1, " + std::to_string(max_depth) + "]");
  }
}

std::size_t Area(int w, int h) {
  return static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
}

}  // namespace

const char* WaveletFilterName(WaveletFilter filter) {
  switch (filter) {
    case WaveletFilter::kHaar:
      return "haar";
    case WaveletFilter::kDaubechies4:
      return "d4";
    case WaveletFilter::kLeGall53:
      return "legall53";
    case WaveletFilter::kCdf97:
      return "cdf97";
  }
  return "unknown";
}

bool ParseWaveletFilter(std::string_view name, WaveletFilter* filter) {
  struct Alias {
    const char* name;
    WaveletFilter filter;
  };
  static constexpr Alias kAliases[] = {{"haar", WaveletFilter::kHaar},
                                       {"d4", WaveletFilter::kDaubechies4},
                                       {"daubechies4", WaveletFilter::kDaubechies4},
                                       {"legall53", WaveletFilter::kLeGall53},
                                       {"5/3", WaveletFilter::kLeGall53},
                                       {"53", WaveletFilter::kLeGall53},
                                       {"le_gall_5_3", WaveletFilter::kLeGall53},
                                       {"cdf97", WaveletFilter::kCdf97},
                                       {"9/7", WaveletFilter::kCdf97},
                                       {"97", WaveletFilter::kCdf97},
                                       {"cdf_9_7", WaveletFilter::kCdf97}};
  for (const Alias& a : kAliases) {
    if (name == a.name) {
      *filter = a.filter;
      return true;
    }
  }
  return false;
}

WaveletWorkspace& ThreadWaveletWorkspace() {
  thread_local WaveletWorkspace workspace;
  return workspace;
}

// ---- sizes and levels ------------------------------------------------------------------------

int WaveletMaxDepth(WaveletFilter filter, int length) {
  return CheckedMaxDepth1D("WaveletMaxDepth", filter, length);
}

int WaveletMaxDepth2D(WaveletFilter filter, int width, int height) {
  return CheckedMaxDepth2D("WaveletMaxDepth2D", filter, width, height);
}

std::vector<WaveletStep1D> WaveletSteps1D(int length, int depth) {
  CheckDepth("WaveletSteps1D", depth,
             CheckedMaxDepth1D("WaveletSteps1D", WaveletFilter::kLeGall53, length));
  std::vector<WaveletStep1D> steps;
  for (int t = 1; t <= depth; ++t) {
    const int m = SizeAtDepth(length, t - 1);
    steps.push_back({t, m, (m + 1) / 2, m / 2});
  }
  return steps;
}

std::vector<WaveletStep2D> WaveletSteps2D(int width, int height, int depth) {
  CheckDepth("WaveletSteps2D", depth,
             CheckedMaxDepth2D("WaveletSteps2D", WaveletFilter::kLeGall53, width, height));
  std::vector<WaveletStep2D> steps;
  for (int t = 1; t <= depth; ++t) {
    const int w = SizeAtDepth(width, t - 1);
    const int h = SizeAtDepth(height, t - 1);
    steps.push_back({t, w, h, (w + 1) / 2, (h + 1) / 2, w / 2, h / 2});
  }
  return steps;
}

int CoefficientLevel1D(int length, int depth, int index) {
  CheckDepth("CoefficientLevel1D", depth,
             CheckedMaxDepth1D("CoefficientLevel1D", WaveletFilter::kLeGall53, length));
  if (index < 0 || index >= length) {
    Fail("CoefficientLevel1D",
         "index " + std::to_string(index) + " outside [0, " + std::to_string(length) + ")");
  }
  if (index < SizeAtDepth(length, depth)) return 0;
  // Detail of step t lies in [SizeAtDepth(N, t), SizeAtDepth(N, t−1)); level = k − t + 1.
  int t = depth;
  while (index >= SizeAtDepth(length, t - 1)) --t;
  return depth - t + 1;
}

void CoefficientLevelMap1D(int length, int depth, std::uint8_t* levels) {
  CheckDepth("CoefficientLevelMap1D", depth,
             CheckedMaxDepth1D("CoefficientLevelMap1D", WaveletFilter::kLeGall53, length));
  for (int t = 1; t <= depth; ++t) {
    const auto level = static_cast<std::uint8_t>(depth - t + 1);
    std::fill(levels + SizeAtDepth(length, t), levels + SizeAtDepth(length, t - 1), level);
  }
  std::fill(levels, levels + SizeAtDepth(length, depth), std::uint8_t{0});
}

CoefficientClass CoefficientClass2D(int width, int height, int depth, int x, int y) {
  CheckDepth("CoefficientClass2D", depth,
             CheckedMaxDepth2D("CoefficientClass2D", WaveletFilter::kLeGall53, width, height));
  if (x < 0 || x >= width || y < 0 || y >= height) {
    Fail("CoefficientClass2D", "coefficient (" + std::to_string(x) + ", " + std::to_string(y) +
                                   ") outside " + std::to_string(width) + "×" +
                                   std::to_string(height));
  }
  if (x < SizeAtDepth(width, depth) && y < SizeAtDepth(height, depth)) {
    return {0, WaveletBand::kLL};
  }
  // The smallest region SizeAtDepth(·, t−1) still containing (x, y) is the one of step t.
  int t = depth;
  while (x >= SizeAtDepth(width, t - 1) || y >= SizeAtDepth(height, t - 1)) --t;
  const bool high_x = x >= SizeAtDepth(width, t);
  const bool high_y = y >= SizeAtDepth(height, t);
  const WaveletBand band =
      high_x ? (high_y ? WaveletBand::kHH : WaveletBand::kHL) : WaveletBand::kLH;
  return {depth - t + 1, band};
}

void CoefficientLevelMap2D(int width, int height, int depth, std::uint8_t* levels) {
  CheckDepth("CoefficientLevelMap2D", depth,
             CheckedMaxDepth2D("CoefficientLevelMap2D", WaveletFilter::kLeGall53, width, height));
  for (int t = 1; t <= depth; ++t) {
    const auto level = static_cast<std::uint8_t>(depth - t + 1);
    const int w0 = SizeAtDepth(width, t - 1), h0 = SizeAtDepth(height, t - 1);
    const int w1 = SizeAtDepth(width, t), h1 = SizeAtDepth(height, t);
    for (int y = 0; y < h0; ++y) {
      std::uint8_t* row = levels + Area(width, y);
      std::fill(row + (y < h1 ? w1 : 0), row + w0, level);
    }
  }
  const int wk = SizeAtDepth(width, depth), hk = SizeAtDepth(height, depth);
  for (int y = 0; y < hk; ++y) {
    std::fill(levels + Area(width, y), levels + Area(width, y) + wk, std::uint8_t{0});
  }
}

// ---- transforms ------------------------------------------------------------------------------

void ForwardWavelet1D(WaveletFilter filter, float* data, int length, int depth,
                      WaveletWorkspace& ws) {
  CheckDepth("ForwardWavelet1D", depth, CheckedMaxDepth1D("ForwardWavelet1D", filter, length));
  if (depth == 0) return;
  const auto n = static_cast<std::size_t>(length);
  double* a = ws.Doubles(2 * n);
  double* b = a + n;
  for (std::size_t i = 0; i < n; ++i) a[i] = data[i];
  for (int t = 1; t <= depth; ++t) {
    const int m = SizeAtDepth(length, t - 1);
    Analyze<true>(filter, {a, 1, 1}, {b, 1, 1}, m);
    std::memcpy(a, b, sizeof(double) * static_cast<std::size_t>(m));
  }
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<float>(a[i]);
}

void InverseWavelet1D(WaveletFilter filter, float* data, int length, int depth,
                      WaveletWorkspace& ws) {
  CheckDepth("InverseWavelet1D", depth, CheckedMaxDepth1D("InverseWavelet1D", filter, length));
  if (depth == 0) return;
  const auto n = static_cast<std::size_t>(length);
  double* a = ws.Doubles(2 * n);
  double* b = a + n;
  for (std::size_t i = 0; i < n; ++i) a[i] = data[i];
  for (int t = depth; t >= 1; --t) {
    const int m = SizeAtDepth(length, t - 1);
    Synthesize<true>(filter, {a, 1, 1}, {b, 1, 1}, m);
    std::memcpy(a, b, sizeof(double) * static_cast<std::size_t>(m));
  }
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<float>(a[i]);
}

void ForwardWavelet1DStep(WaveletFilter filter, float* data, int length, int step,
                          WaveletWorkspace& ws) {
  CheckStep("ForwardWavelet1DStep", step,
            CheckedMaxDepth1D("ForwardWavelet1DStep", filter, length));
  const int m = SizeAtDepth(length, step - 1);
  const auto n = static_cast<std::size_t>(m);
  double* a = ws.Doubles(2 * n);
  double* b = a + n;
  for (std::size_t i = 0; i < n; ++i) a[i] = data[i];
  Analyze<true>(filter, {a, 1, 1}, {b, 1, 1}, m);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<float>(b[i]);
}

void InverseWavelet1DStep(WaveletFilter filter, float* data, int length, int step,
                          WaveletWorkspace& ws) {
  CheckStep("InverseWavelet1DStep", step,
            CheckedMaxDepth1D("InverseWavelet1DStep", filter, length));
  const int m = SizeAtDepth(length, step - 1);
  const auto n = static_cast<std::size_t>(m);
  double* a = ws.Doubles(2 * n);
  double* b = a + n;
  for (std::size_t i = 0; i < n; ++i) a[i] = data[i];
  Synthesize<true>(filter, {a, 1, 1}, {b, 1, 1}, m);
  for (std::size_t i = 0; i < n; ++i) data[i] = static_cast<float>(b[i]);
}

void ForwardWavelet2D(WaveletFilter filter, float* data, int width, int height, int depth,
                      WaveletWorkspace& ws) {
  CheckDepth("ForwardWavelet2D", depth,
             CheckedMaxDepth2D("ForwardWavelet2D", filter, width, height));
  if (depth == 0) return;
  const std::size_t area = Area(width, height);
  double* a = ws.Doubles(2 * area);
  double* b = a + area;
  LoadBlock(data, width, a, width, width, height);
  for (int t = 1; t <= depth; ++t) {
    ForwardStep2D(filter, a, b, width, SizeAtDepth(width, t - 1), SizeAtDepth(height, t - 1));
  }
  StoreBlock(a, width, data, width, width, height);
}

void InverseWavelet2D(WaveletFilter filter, float* data, int width, int height, int depth,
                      WaveletWorkspace& ws) {
  CheckDepth("InverseWavelet2D", depth,
             CheckedMaxDepth2D("InverseWavelet2D", filter, width, height));
  if (depth == 0) return;
  const std::size_t area = Area(width, height);
  double* a = ws.Doubles(2 * area);
  double* b = a + area;
  LoadBlock(data, width, a, width, width, height);
  for (int t = depth; t >= 1; --t) {
    InverseStep2D(filter, a, b, width, SizeAtDepth(width, t - 1), SizeAtDepth(height, t - 1));
  }
  StoreBlock(a, width, data, width, width, height);
}

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

void ForwardWavelet2DStep(WaveletFilter filter, float* data, int width, int height, int step,
                          WaveletWorkspace& ws) {
  CheckStep("ForwardWavelet2DStep", step,
            CheckedMaxDepth2D("ForwardWavelet2DStep", filter, width, height));
  const int wc = SizeAtDepth(width, step - 1), hc = SizeAtDepth(height, step - 1);
  const std::size_t area = Area(wc, hc);
  double* a = ws.Doubles(2 * area);
  double* b = a + area;
  LoadBlock(data, width, a, wc, wc, hc);
  ForwardStep2D(filter, a, b, wc, wc, hc);
  StoreBlock(a, wc, data, width, wc, hc);
}

void InverseWavelet2DStep(WaveletFilter filter, float* data, int width, int height, int step,
                          WaveletWorkspace& ws) {
  CheckStep("InverseWavelet2DStep", step,
            CheckedMaxDepth2D("InverseWavelet2DStep", filter, width, height));
  const int wc = SizeAtDepth(width, step - 1), hc = SizeAtDepth(height, step - 1);
  const std::size_t area = Area(wc, hc);
  double* a = ws.Doubles(2 * area);
  double* b = a + area;
  LoadBlock(data, width, a, wc, wc, hc);
  InverseStep2D(filter, a, b, wc, wc, hc);
  StoreBlock(a, wc, data, width, wc, hc);
}

void ForwardWaveletCubemap(WaveletFilter filter, float* data, int n, int depth,
                           WaveletWorkspace& ws) {
  CheckDepth("ForwardWaveletCubemap", depth,
             CheckedMaxDepth2D("ForwardWaveletCubemap", filter, n, n));
  for (int face = 0; face < 6; ++face) {
    ForwardWavelet2D(filter, data + face * Area(n, n), n, n, depth, ws);
  }
}

void InverseWaveletCubemap(WaveletFilter filter, float* data, int n, int depth,
                           WaveletWorkspace& ws) {
  CheckDepth("InverseWaveletCubemap", depth,
             CheckedMaxDepth2D("InverseWaveletCubemap", filter, n, n));
  for (int face = 0; face < 6; ++face) {
    InverseWavelet2D(filter, data + face * Area(n, n), n, n, depth, ws);
  }
}

// ---- Haar supports ---------------------------------------------------------------------------

HaarSupport HaarCoefficientSupport(int n, int depth, int x, int y) {
  CheckDepth("HaarCoefficientSupport", depth,
             CheckedMaxDepth2D("HaarCoefficientSupport", WaveletFilter::kHaar, n, n));
  const CoefficientClass c = CoefficientClass2D(n, n, depth, x, y);
  // A scaling coefficient at depth k averages a 2^k square; a detail made by step t spans 2^t.
  const int t = c.level == 0 ? depth : depth - c.level + 1;
  const int side = 1 << t;
  const int low = n >> t;  // size of the LL region after step t
  const int ix = x >= low ? x - low : x;
  const int iy = y >= low ? y - low : y;
  return {ix * side, iy * side, side};
}

double HaarSupportSolidAngle(const CubemapLayout& layout, int depth, std::size_t index) {
  const int n = layout.n();
  if (index >= layout.texel_count()) {
    Fail("HaarSupportSolidAngle", "coefficient index " + std::to_string(index) + " outside a " +
                                      std::to_string(n) + "² cubemap");
  }
  const std::size_t r = index % layout.face_size();
  const HaarSupport s =
      HaarCoefficientSupport(n, depth, static_cast<int>(r % n), static_cast<int>(r / n));
  const double h = 2.0 / n;
  return FaceRectSolidAngle(-1 + h * s.x0, -1 + h * (s.x0 + s.side), -1 + h * s.y0,
                            -1 + h * (s.y0 + s.side));
}

std::vector<double> HaarSupportSolidAngles(const CubemapLayout& layout, int depth) {
  std::vector<double> out(layout.texel_count());
  const std::size_t fs = layout.face_size();
  for (std::size_t i = 0; i < fs; ++i) out[i] = HaarSupportSolidAngle(layout, depth, i);
  for (int face = 1; face < 6; ++face) {
    std::copy(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(fs),
              out.begin() + static_cast<std::ptrdiff_t>(face * fs));
  }
  return out;
}

}  // namespace prt
