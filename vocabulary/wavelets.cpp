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
#include "vocabulary/wavelet_lifting.h"

namespace prt {

namespace wavelet_detail {

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

}  // namespace wavelet_detail

using namespace wavelet_detail;

namespace {

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

}  // namespace

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
