#include "runtime/triple_product.h"

#include <algorithm>
#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace prt {

namespace {

// Vertices per parallel work item of RelightTripleProduct.
constexpr std::size_t kVertexChunk = 256;
// Blocks of a map at the largest n (256): 6·16².
constexpr int kMaxBlocks = 6 * 16 * 16;

// Σ_{k ∈ [a, b)} x[k]·y[k] with eight partial sums (vectorises without -ffast-math).
inline float DotRange(const float* x, const float* y, int a, int b) {
  float s[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  int k = a;
  for (; k + 8 <= b; k += 8)
    for (int i = 0; i < 8; ++i) s[i] += x[k + i] * y[k + i];
  float acc = ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
  for (; k < b; ++k) acc += x[k] * y[k];
  return acc;
}

inline Vec3 Dir(const float* d) {
  return {d[0], d[1], d[2]};
}

void CheckSizes(const GlossyScene& s, const CubemapBlocks& blocks, const BlockLighting& light) {
  if (s.visibility == nullptr) throw std::invalid_argument("triple product: no visibility");
  const std::size_t nv = s.positions.size();
  if (s.normals.size() != nv || s.material_index.size() != nv || s.visibility->vertex_count != nv)
    throw std::invalid_argument("triple product: vertex counts disagree");
  if (s.visibility->n != blocks.n() || light.n != blocks.n())
    throw std::invalid_argument("triple product: cubemap resolutions disagree");
}

void CheckScene(const GlossyScene& s, const CubemapBlocks& blocks, const BlockLighting& light) {
  CheckSizes(s, blocks, light);
  for (uint16_t m : s.material_index)
    if (m >= s.materials.size()) throw std::invalid_argument("triple product: material index");
}

// The runs of a mixed block: calls f(begin, end, level) for each maximal run of non-zero level.
// A 1-bit block's visibility as 256 bits (bit k of word k/64: position k visible): the changes
// toggle, so the visibility is the prefix XOR of a bit per change.
inline void VisibleBits(const VisibilityBlocks& vis, std::size_t e, uint64_t out[4]) {
  uint64_t t[4] = {0, 0, 0, 0};
  for (uint64_t i = vis.change_begin[e]; i < vis.change_begin[e + 1]; ++i) {
    const unsigned pos = vis.change_pos[i];
    t[pos >> 6] ^= uint64_t{1} << (pos & 63u);
  }
  uint64_t carry = 0;
  for (int w = 0; w < 4; ++w) {
    uint64_t x = t[w];
    x ^= x << 1;
    x ^= x << 2;
    x ^= x << 4;
    x ^= x << 8;
    x ^= x << 16;
    x ^= x << 32;
    x ^= carry;
    out[w] = x;
    carry = (x >> 63) != 0 ? ~uint64_t{0} : 0;
  }
}

template <typename F>
inline void ForEachVisibleRun(const VisibilityBlocks& vis, std::size_t e, F&& f) {
  const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
  int level = 0, start = 0;
  for (uint64_t i = first; i < last; ++i) {
    const int pos = vis.change_pos[i];
    if (level != 0 && pos > start) f(start, pos, level);
    level = vis.bits == 1 ? 1 - level : level + vis.change_value[i];
    start = pos;
  }
  if (level != 0) f(start, 256, level);
}

// A value for an error message: 7 significant digits (std::to_string writes 1e39 in full).
std::string Number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.7g", v);
  return b;
}

[[noreturn]] void ThrowNonFiniteVertex(std::size_t vertex, int c, double value) {
  throw NumericalError("triple product: the outgoing radiance of vertex " + std::to_string(vertex) +
                       " (channel " + std::to_string(c) + ") is " +
                       (std::isnan(value) ? "NaN" : "Inf") +
                       ": a block's float product overflowed; the lighting is too bright");
}

// A vertex's radiance (a finite double) as the float the output holds; past 3.4e38 an error.
float ToFloatRadiance(double v, std::size_t vertex, int c) {
  if (!(std::abs(v) <= static_cast<double>(std::numeric_limits<float>::max())))
    throw NumericalError("triple product: the outgoing radiance of vertex " +
                         std::to_string(vertex) + " (channel " + std::to_string(c) +
                         ") = " + Number(v) +
                         " is outside the float range; the lighting is too "
                         "bright");
  return static_cast<float>(v);
}

void Count(TripleProductStats& st, TripleProductCase line, int rate) {
  switch (line) {
    case TripleProductCase::kZero:
      ++st.blocks_zero;
      return;
    case TripleProductCase::kLine6:
      ++st.blocks_line6;
      break;
    case TripleProductCase::kLine9:
      ++st.blocks_line9;
      break;
    case TripleProductCase::kLine11:
      ++st.blocks_line11;
      break;
  }
  ++st.brdf_rate[rate == 1 ? 0 : (rate == 4 ? 1 : (rate == 16 ? 2 : 3))];
}

// ---- The lobes at a direction, two ways ----------------------------------------------------
// DoubleLobes: brdf.h's DiffuseLobe / SpecularLobe in double (the kernel before issue 41).
struct DoubleLobes {
  const Material& m;
  const ShadingFrame& f;
  float Diffuse(const float* w) const { return static_cast<float>(DiffuseLobe(f, Dir(w))); }
  float Specular(const float* w) const { return static_cast<float>(SpecularLobe(m, f, Dir(w))); }
};

// x^s for x in [0, 1] (a little above 1 from rounding is fine) and s > 0 as exp2(s·log2 x):
// log2 from the float's exponent and the odd series of atanh in t = (m − 1)/(m + 1), |t| ≤
// 0.1716 (five terms: truncation < 1e-9); 2^y from the exponent bits and e^z, z = f·ln 2, |f| ≤
// ½, to degree 7 (truncation < 6e-9). The result's relative error is that of float arithmetic
// on y = s·log2 x: about 1e-7·(1 + |y|), below 3e-6 wherever x^s > 1e-9.
// std::bit_cast, which Emscripten 3.1.6's library (the web build) lacks.
template <class To, class From>
inline To BitCast(const From& from) {
  static_assert(sizeof(To) == sizeof(From));
  To to;
  std::memcpy(&to, &from, sizeof to);
  return to;
}

inline float FastLog2(float x) {  // x normal, > 0
  const auto bits = BitCast<uint32_t>(x);
  int e = static_cast<int>((bits >> 23) & 255u) - 127;
  float m = BitCast<float>((bits & 0x007fffffu) | 0x3f800000u);  // [1, 2)
  if (m > 1.41421356f) {
    m *= 0.5f;
    ++e;
  }
  const float t = (m - 1.f) / (m + 1.f), t2 = t * t;
  float p = 1.f / 9.f;
  p = p * t2 + 1.f / 7.f;
  p = p * t2 + 1.f / 5.f;
  p = p * t2 + 1.f / 3.f;
  p = p * t2 + 1.f;
  return static_cast<float>(e) + t * p * 2.88539008f;  // 2 / ln 2
}
inline float FastExp2(float y) {  // y ≤ ½; 0 below 2^−126
  if (!(y > -126.f)) return 0.f;
  const float r = std::floor(y + 0.5f);
  const float z = (y - r) * 0.693147181f;
  float p = 1.f / 5040.f;
  p = p * z + 1.f / 720.f;
  p = p * z + 1.f / 120.f;
  p = p * z + 1.f / 24.f;
  p = p * z + 1.f / 6.f;
  p = p * z + 0.5f;
  p = p * z + 1.f;
  p = p * z + 1.f;
  return p * BitCast<float>(static_cast<uint32_t>(static_cast<int>(r) + 127) << 23);
}
inline float FastPowUnit(float x, float s) {
  if (!(x >= 1.17549435e-38f)) return 0.f;  // 0, subnormals, NaN
  return FastExp2(std::min(s * FastLog2(x), 0.5f));
}

// FloatLobes: the same lobes in float from the frame's float copy, the powers by FastPowUnit (or
// std::pow when that speedup is off). Ashikhmin–Shirley's 1 − (n·h)² is h_u² + h_v² (h is unit
// and (t, b, n) orthonormal), which has no cancellation near the peak.
struct FloatLobes {
  BrdfModel model;
  bool spec, fast_pow;
  float n[3], t[3], b[3], v[3], r[3];
  float nv;
  float s, su, sv, phong_norm, as_norm;

  FloatLobes(const Material& m, const ShadingFrame& f, bool fast) {
    model = m.model;
    spec = HasSpecular(m);
    fast_pow = fast;
    const Vec3* src[5] = {&f.normal, &f.tangent, &f.bitangent, &f.view, &f.reflect};
    float* dst[5] = {n, t, b, v, r};
    for (int i = 0; i < 5; ++i) {
      dst[i][0] = static_cast<float>(src[i]->x);
      dst[i][1] = static_cast<float>(src[i]->y);
      dst[i][2] = static_cast<float>(src[i]->z);
    }
    nv = static_cast<float>(Dot(f.normal, f.view));
    s = static_cast<float>(m.exponent);
    su = static_cast<float>(m.exponent);
    sv = static_cast<float>(m.exponent_v);
    phong_norm = static_cast<float>((m.exponent + 2.0) * (0.5 / std::numbers::pi));
    as_norm = static_cast<float>(std::sqrt((m.exponent + 1.0) * (m.exponent_v + 1.0)) /
                                 (8.0 * std::numbers::pi));
  }
  static float Dot3(const float* a, const float* w) {
    return a[0] * w[0] + a[1] * w[1] + a[2] * w[2];
  }
  float Pow(float x, float e) const {
    return fast_pow ? FastPowUnit(x, e)
                    : static_cast<float>(std::pow(static_cast<double>(x), static_cast<double>(e)));
  }
  float Diffuse(const float* w) const {
    const float c = Dot3(n, w);
    return c > 0 ? c * 0.318309886f : 0.f;
  }
  // The specular lobe (cosine folded in) with n·w and r·w already known.
  float SpecularFrom(const float* w, float nw, float rw) const {
    if (!spec || nw <= 0) return 0.f;
    if (model == BrdfModel::kPhong) return rw > 0 ? phong_norm * Pow(rw, s) * nw : 0.f;
    if (nv <= 0) return 0.f;
    float h[3] = {w[0] + v[0], w[1] + v[1], w[2] + v[2]};
    const float len = std::sqrt(Dot3(h, h));
    if (!(len > 0)) return 0.f;
    for (float& x : h) x /= len;
    const float nh = Dot3(n, h), hw = Dot3(h, w);
    if (nh <= 0 || hw <= 0) return 0.f;
    const float hu = Dot3(t, h), hv = Dot3(b, h);
    const float s2 = hu * hu + hv * hv;
    const float e = s2 > 0 ? (su * hu * hu + sv * hv * hv) / s2 : su;
    return as_norm * Pow(nh, e) / (hw * std::max(nw, nv)) * nw;
  }
  float Specular(const float* w) const { return SpecularFrom(w, Dot3(n, w), Dot3(r, w)); }
};

// ---- The lobes of many directions at once (issue 41) -------------------------------------------
// SpecularBatch(lobes, x, y, z, count, out): out[i] = lobes.Specular(direction i), directions as
// three arrays. The AVX2 + FMA version takes 8 directions per step with FastPowUnit's arithmetic
// in vector form, chosen at run time (CPUs without it, and WebAssembly, use the scalar loop);
// it reads and writes whole groups of 8, so the arrays must hold count rounded up to 8.
void SpecularBatchScalar(const FloatLobes& L, const float* x, const float* y, const float* z,
                         int count, float* out) {
  for (int i = 0; i < count; ++i) {
    const float w[3] = {x[i], y[i], z[i]};
    out[i] = L.Specular(w);
  }
}

#if defined(__x86_64__) || defined(__i386__)
#define PRT_TP_HAVE_AVX2 1
__attribute__((target("avx2,fma"))) inline __m256 Log2Avx2(__m256 x) {
  const __m256i bits = _mm256_castps_si256(x);
  __m256i e =
      _mm256_sub_epi32(_mm256_and_si256(_mm256_srli_epi32(bits, 23), _mm256_set1_epi32(255)),
                       _mm256_set1_epi32(127));
  __m256 m = _mm256_castsi256_ps(_mm256_or_si256(
      _mm256_and_si256(bits, _mm256_set1_epi32(0x007fffff)), _mm256_set1_epi32(0x3f800000)));
  const __m256 big = _mm256_cmp_ps(m, _mm256_set1_ps(1.41421356f), _CMP_GT_OQ);
  m = _mm256_blendv_ps(m, _mm256_mul_ps(m, _mm256_set1_ps(0.5f)), big);
  e = _mm256_sub_epi32(e, _mm256_castps_si256(big));  // big lanes are −1 as integers
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256 t = _mm256_div_ps(_mm256_sub_ps(m, one), _mm256_add_ps(m, one));
  const __m256 t2 = _mm256_mul_ps(t, t);
  __m256 p = _mm256_set1_ps(1.f / 9.f);
  p = _mm256_fmadd_ps(p, t2, _mm256_set1_ps(1.f / 7.f));
  p = _mm256_fmadd_ps(p, t2, _mm256_set1_ps(1.f / 5.f));
  p = _mm256_fmadd_ps(p, t2, _mm256_set1_ps(1.f / 3.f));
  p = _mm256_fmadd_ps(p, t2, one);
  return _mm256_fmadd_ps(_mm256_mul_ps(t, p), _mm256_set1_ps(2.88539008f), _mm256_cvtepi32_ps(e));
}

// FastPowUnit(x, s) per lane.
__attribute__((target("avx2,fma"))) inline __m256 PowUnitAvx2(__m256 x, __m256 s) {
  const __m256 y = _mm256_min_ps(_mm256_mul_ps(s, Log2Avx2(x)), _mm256_set1_ps(0.5f));
  const __m256 r = _mm256_floor_ps(_mm256_add_ps(y, _mm256_set1_ps(0.5f)));
  const __m256 zz = _mm256_mul_ps(_mm256_sub_ps(y, r), _mm256_set1_ps(0.693147181f));
  __m256 p = _mm256_set1_ps(1.f / 5040.f);
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f / 720.f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f / 120.f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f / 24.f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f / 6.f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(0.5f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f));
  p = _mm256_fmadd_ps(p, zz, _mm256_set1_ps(1.f));
  // r ≥ −126 where the result is kept, so the biased exponent is ≥ 1 there.
  const __m256i ri = _mm256_cvtps_epi32(_mm256_max_ps(r, _mm256_set1_ps(-126.f)));
  const __m256 scale =
      _mm256_castsi256_ps(_mm256_slli_epi32(_mm256_add_epi32(ri, _mm256_set1_epi32(127)), 23));
  const __m256 keep = _mm256_and_ps(_mm256_cmp_ps(y, _mm256_set1_ps(-126.f), _CMP_GT_OQ),
                                    _mm256_cmp_ps(x, _mm256_set1_ps(1.17549435e-38f), _CMP_GE_OQ));
  return _mm256_and_ps(_mm256_mul_ps(p, scale), keep);
}

__attribute__((target("avx2,fma"))) inline __m256 Dot3Avx2(const float* a, __m256 wx, __m256 wy,
                                                           __m256 wz) {
  return _mm256_fmadd_ps(
      _mm256_set1_ps(a[0]), wx,
      _mm256_fmadd_ps(_mm256_set1_ps(a[1]), wy, _mm256_mul_ps(_mm256_set1_ps(a[2]), wz)));
}

__attribute__((target("avx2,fma"))) void SpecularBatchAvx2(const FloatLobes& L, const float* x,
                                                           const float* y, const float* z,
                                                           int count, float* out) {
  const __m256 zero = _mm256_setzero_ps();
  const auto dot = Dot3Avx2;

  for (int i = 0; i < count; i += 8) {
    const __m256 wx = _mm256_loadu_ps(x + i), wy = _mm256_loadu_ps(y + i),
                 wz = _mm256_loadu_ps(z + i);
    const __m256 nw = dot(L.n, wx, wy, wz);
    __m256 val;
    __m256 ok = _mm256_cmp_ps(nw, zero, _CMP_GT_OQ);
    if (L.model == BrdfModel::kPhong) {
      const __m256 rw = dot(L.r, wx, wy, wz);
      ok = _mm256_and_ps(ok, _mm256_cmp_ps(rw, zero, _CMP_GT_OQ));
      val = _mm256_mul_ps(
          _mm256_mul_ps(_mm256_set1_ps(L.phong_norm), PowUnitAvx2(rw, _mm256_set1_ps(L.s))), nw);
    } else {  // Ashikhmin–Shirley (L.nv > 0 here: SpecularBatch checks it)
      __m256 hx = _mm256_add_ps(wx, _mm256_set1_ps(L.v[0]));
      __m256 hy = _mm256_add_ps(wy, _mm256_set1_ps(L.v[1]));
      __m256 hz = _mm256_add_ps(wz, _mm256_set1_ps(L.v[2]));
      const __m256 len =
          _mm256_sqrt_ps(_mm256_fmadd_ps(hx, hx, _mm256_fmadd_ps(hy, hy, _mm256_mul_ps(hz, hz))));
      ok = _mm256_and_ps(ok, _mm256_cmp_ps(len, zero, _CMP_GT_OQ));
      const __m256 safe = _mm256_blendv_ps(_mm256_set1_ps(1.f), len, ok);
      hx = _mm256_div_ps(hx, safe);
      hy = _mm256_div_ps(hy, safe);
      hz = _mm256_div_ps(hz, safe);
      const __m256 nh = dot(L.n, hx, hy, hz);
      const __m256 hw = _mm256_fmadd_ps(hx, wx, _mm256_fmadd_ps(hy, wy, _mm256_mul_ps(hz, wz)));
      ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(nh, zero, _CMP_GT_OQ),
                                           _mm256_cmp_ps(hw, zero, _CMP_GT_OQ)));
      const __m256 hu = dot(L.t, hx, hy, hz), hv = dot(L.b, hx, hy, hz);
      const __m256 hu2 = _mm256_mul_ps(hu, hu), hv2 = _mm256_mul_ps(hv, hv);
      const __m256 s2 = _mm256_add_ps(hu2, hv2);
      const __m256 has = _mm256_cmp_ps(s2, zero, _CMP_GT_OQ);
      const __m256 e = _mm256_blendv_ps(
          _mm256_set1_ps(L.su),
          _mm256_div_ps(
              _mm256_fmadd_ps(_mm256_set1_ps(L.su), hu2, _mm256_mul_ps(_mm256_set1_ps(L.sv), hv2)),
              _mm256_blendv_ps(_mm256_set1_ps(1.f), s2, has)),
          has);
      const __m256 den = _mm256_mul_ps(_mm256_blendv_ps(_mm256_set1_ps(1.f), hw, ok),
                                       _mm256_max_ps(nw, _mm256_set1_ps(L.nv)));
      val = _mm256_mul_ps(
          _mm256_div_ps(_mm256_mul_ps(_mm256_set1_ps(L.as_norm), PowUnitAvx2(nh, e)), den), nw);
    }
    _mm256_storeu_ps(out + i, _mm256_and_ps(val, ok));
  }
}

// Line 9 with the exact cosine on 1-bit maps: acc[0..16) += Σ over change pairs (a, z) of
// q[a] − q[z] (and + q[a] for an unpaired last change), one 64-byte suffix line per change in two
// 8-float registers.
__attribute__((target("avx2,fma"))) inline void ChangePairsAvx2(const float* q, const uint8_t* pos,
                                                                uint64_t count, __m256& lo,
                                                                __m256& hi) {
  constexpr int kS = BlockLighting::kRgbXyzStride;
  // Two pairs a step into two sets of sums: the adds of one pair do not wait for the last's.
  __m256 lo0 = _mm256_setzero_ps(), hi0 = lo0, lo1 = lo0, hi1 = lo0;
  uint64_t i = 0;
  for (; i + 4 <= count; i += 4) {
    const float* a0 = q + pos[i] * kS;
    const float* z0 = q + pos[i + 1] * kS;
    const float* a1 = q + pos[i + 2] * kS;
    const float* z1 = q + pos[i + 3] * kS;
    lo0 = _mm256_add_ps(lo0, _mm256_sub_ps(_mm256_load_ps(a0), _mm256_load_ps(z0)));
    hi0 = _mm256_add_ps(hi0, _mm256_sub_ps(_mm256_load_ps(a0 + 8), _mm256_load_ps(z0 + 8)));
    lo1 = _mm256_add_ps(lo1, _mm256_sub_ps(_mm256_load_ps(a1), _mm256_load_ps(z1)));
    hi1 = _mm256_add_ps(hi1, _mm256_sub_ps(_mm256_load_ps(a1 + 8), _mm256_load_ps(z1 + 8)));
  }
  if (i + 2 <= count) {
    const float* a = q + pos[i] * kS;
    const float* z = q + pos[i + 1] * kS;
    lo0 = _mm256_add_ps(lo0, _mm256_sub_ps(_mm256_load_ps(a), _mm256_load_ps(z)));
    hi0 = _mm256_add_ps(hi0, _mm256_sub_ps(_mm256_load_ps(a + 8), _mm256_load_ps(z + 8)));
    i += 2;
  }
  if (i < count) {
    const float* a = q + pos[i] * kS;
    lo1 = _mm256_add_ps(lo1, _mm256_load_ps(a));
    hi1 = _mm256_add_ps(hi1, _mm256_load_ps(a + 8));
  }
  lo = _mm256_add_ps(lo0, lo1);
  hi = _mm256_add_ps(hi0, hi1);
}

__attribute__((target("avx2,fma"))) void AccumulateChangePairsAvx2(const float* q,
                                                                   const uint8_t* pos,
                                                                   uint64_t count, float* acc) {
  __m256 lo, hi;
  ChangePairsAvx2(q, pos, count, lo, hi);
  _mm256_storeu_ps(acc, lo);
  _mm256_storeu_ps(acc + 8, hi);
}

// The whole of line 9 with the exact cosine on a 1-bit map, in registers: with the interleaved
// sums lo = [L, Lx], hi = [Ly, Lz] (block_lighting.h), out_c = kd_c·(n/π)·(Lx, Ly, Lz)_c +
// ks_c·s0·L_c.
__attribute__((target("avx2,fma"))) void Line9ExactAvx2(const float* q, const uint8_t* pos,
                                                        uint64_t count, const float n_pi[3],
                                                        const float kd[3], const float ks[3],
                                                        float s0, float out[3]) {
  __m256 lo, hi;
  ChangePairsAvx2(q, pos, count, lo, hi);
  const __m128 l = _mm256_castps256_ps128(lo), lx = _mm256_extractf128_ps(lo, 1);
  const __m128 ly = _mm256_castps256_ps128(hi), lz = _mm256_extractf128_ps(hi, 1);
  const __m128 cosine =
      _mm_fmadd_ps(_mm_set1_ps(n_pi[0]), lx,
                   _mm_fmadd_ps(_mm_set1_ps(n_pi[1]), ly, _mm_mul_ps(_mm_set1_ps(n_pi[2]), lz)));
  const __m128 r =
      _mm_fmadd_ps(_mm_setr_ps(kd[0], kd[1], kd[2], 0.f), cosine,
                   _mm_mul_ps(_mm_setr_ps(ks[0] * s0, ks[1] * s0, ks[2] * s0, 0.f), l));
  alignas(16) float t[4];
  _mm_store_ps(t, r);
  out[0] = t[0];
  out[1] = t[1];
  out[2] = t[2];
}

__attribute__((target("avx2,fma"))) inline float HorizontalSumAvx2(__m256 v) {
  alignas(32) float t[8];
  _mm256_store_ps(t, v);
  return ((t[0] + t[1]) + (t[2] + t[3])) + ((t[4] + t[5]) + (t[6] + t[7]));
}

// Line 11 on a 1-bit map: the lobes' pixels times the visibility, dotted with the three
// channels' pixels, 8 positions per step; dpix null with the exact cosine. `visible` holds the
// 256 positions' visibility as bits (VisibleBits); each step widens 8 of them to a lane mask.
__attribute__((target("avx2,fma"))) void Line11PixelsAvx2(const uint64_t visible[4],
                                                          const float* const lp[3],
                                                          const float* spix, const float* dpix,
                                                          float sp[3], float dif[3]) {
  __m256 s0 = _mm256_setzero_ps(), s1 = s0, s2 = s0, d0 = s0, d1 = s0, d2 = s0;
  const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  for (int k = 0; k < 256; k += 8) {
    const auto byte = static_cast<int>((visible[k >> 6] >> (k & 63)) & 255u);
    if (byte == 0) continue;
    const __m256 m = _mm256_castsi256_ps(
        _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(byte), lane_bit), lane_bit));
    const __m256 l0 = _mm256_loadu_ps(lp[0] + k), l1 = _mm256_loadu_ps(lp[1] + k),
                 l2 = _mm256_loadu_ps(lp[2] + k);
    const __m256 sv = _mm256_and_ps(_mm256_load_ps(spix + k), m);
    s0 = _mm256_fmadd_ps(l0, sv, s0);
    s1 = _mm256_fmadd_ps(l1, sv, s1);
    s2 = _mm256_fmadd_ps(l2, sv, s2);
    if (dpix != nullptr) {
      const __m256 dv = _mm256_and_ps(_mm256_load_ps(dpix + k), m);
      d0 = _mm256_fmadd_ps(l0, dv, d0);
      d1 = _mm256_fmadd_ps(l1, dv, d1);
      d2 = _mm256_fmadd_ps(l2, dv, d2);
    }
  }
  const auto hsum = HorizontalSumAvx2;
  sp[0] = hsum(s0);
  sp[1] = hsum(s1);
  sp[2] = hsum(s2);
  dif[0] = hsum(d0);
  dif[1] = hsum(d1);
  dif[2] = hsum(d2);
}

// The vertex set-up over its listed blocks (FastVertex), 8 block centres per step: Appendix A's
// rate code (0..3 for 1, 4, 16, 256 samples) from cos = 2(n·c)(n·v) − c·v, the diffuse lobe at
// the centre and, for Phong (phong_s0 not null), the specular lobe there: r_view·c is that same
// cos.
__attribute__((target("avx2,fma"))) void SetupAvx2(const FloatLobes& L, const float* gx,
                                                   const float* gy, const float* gz, int count,
                                                   bool low_exponent, int mid_code, int near_code,
                                                   int32_t* code, float* d0, float* phong_s0) {
  const __m256 c4 = _mm256_set1_ps(0.70710678118654752f), c8 = _mm256_set1_ps(0.92387953251128676f);
  const __m256i mid = _mm256_set1_epi32(mid_code), near = _mm256_set1_epi32(near_code);
  for (int i = 0; i < count; i += 8) {
    const __m256 x = _mm256_load_ps(gx + i), y = _mm256_load_ps(gy + i), z = _mm256_load_ps(gz + i);
    const __m256 nc = Dot3Avx2(L.n, x, y, z), vc = Dot3Avx2(L.v, x, y, z);
    const __m256 cosang = _mm256_sub_ps(
        _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(2.f), nc), _mm256_set1_ps(L.nv)), vc);
    const __m256i above4 = _mm256_castps_si256(_mm256_cmp_ps(cosang, c4, _CMP_GT_OQ));
    const __m256i above8 = _mm256_castps_si256(_mm256_cmp_ps(cosang, c8, _CMP_GT_OQ));
    __m256i c = _mm256_and_si256(above4, mid);
    if (!L.spec) {
      c = _mm256_setzero_si256();
    } else if (!low_exponent) {
      c = _mm256_blendv_epi8(c, near, above8);
    }
    _mm256_store_si256(reinterpret_cast<__m256i*>(code + i), c);
    _mm256_store_ps(d0 + i, _mm256_mul_ps(_mm256_max_ps(nc, _mm256_setzero_ps()),
                                          _mm256_set1_ps(0.318309886f)));
    if (phong_s0 != nullptr) {  // FloatLobes::SpecularFrom(c, n·c, r·c) for Phong
      const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(nc, _mm256_setzero_ps(), _CMP_GT_OQ),
                                      _mm256_cmp_ps(cosang, _mm256_setzero_ps(), _CMP_GT_OQ));
      const __m256 v = _mm256_mul_ps(
          _mm256_mul_ps(_mm256_set1_ps(L.phong_norm), PowUnitAvx2(cosang, _mm256_set1_ps(L.s))),
          nc);
      _mm256_store_ps(phong_s0 + i, _mm256_and_ps(v, ok));
    }
  }
}

// The non-zero blocks of a vertex from its kind bytes, 32 per step; returns their count.
__attribute__((target("avx2,bmi"))) int ListNonZeroAvx2(const uint8_t* kinds, int nb,
                                                        uint16_t* list) {
  int count = 0, b = 0;
  for (; b + 32 <= nb; b += 32) {
    const __m256i k = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kinds + b));
    auto mask =
        ~static_cast<uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(k, _mm256_setzero_si256())));
    while (mask != 0) {
      list[count++] = static_cast<uint16_t>(b + static_cast<int>(_tzcnt_u32(mask)));
      mask &= mask - 1;
    }
  }
  for (; b < nb; ++b) {
    list[count] = static_cast<uint16_t>(b);
    count += kinds[b] != 0;
  }
  return count;
}

// Line 11 with the exact cosine on a 1-bit map, the specular lobe never stored: each row y of
// its reconstruction Σ_uv A_uv φ_u(x) φ_v(y) (BlockDct::Reconstruct) is made in two 8-float
// registers, masked by the row's visibility bits and dotted with the three channels' pixels.
template <int L>
__attribute__((target("avx2,fma"))) void Line11FromDctAvx2(const float* coef,
                                                           const uint64_t visible[4],
                                                           const float* const lp[3], float sp[3]) {
  alignas(32) static const std::array<float, 64> kBasis = [] {
    std::array<float, 64> t{};
    for (int u = 0; u < 4; ++u)
      for (int x = 0; x < 16; ++x) t[u * 16 + x] = BlockDct::Basis(u, x);
    return t;
  }();
  __m256 g_lo[L], g_hi[L];  // g_v(x) = Σ_u A_uv φ_u(x), x < 8 and x ≥ 8
  for (int v = 0; v < L; ++v) {
    g_lo[v] = _mm256_setzero_ps();
    g_hi[v] = _mm256_setzero_ps();
    for (int u = 0; u < L; ++u) {
      const __m256 a = _mm256_set1_ps(coef[v * L + u]);
      g_lo[v] = _mm256_fmadd_ps(a, _mm256_load_ps(&kBasis[u * 16]), g_lo[v]);
      g_hi[v] = _mm256_fmadd_ps(a, _mm256_load_ps(&kBasis[u * 16 + 8]), g_hi[v]);
    }
  }
  const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  __m256 s0 = _mm256_setzero_ps(), s1 = s0, s2 = s0;
  for (int y = 0; y < 16; ++y) {
    const auto row = static_cast<unsigned>((visible[y >> 2] >> ((y & 3) * 16)) & 0xffffu);
    if (row == 0) continue;
    __m256 p_lo = _mm256_setzero_ps(), p_hi = p_lo;
    for (int v = 0; v < L; ++v) {
      const __m256 w = _mm256_set1_ps(kBasis[v * 16 + y]);
      p_lo = _mm256_fmadd_ps(w, g_lo[v], p_lo);
      p_hi = _mm256_fmadd_ps(w, g_hi[v], p_hi);
    }
    const __m256 m_lo = _mm256_castsi256_ps(_mm256_cmpeq_epi32(
        _mm256_and_si256(_mm256_set1_epi32(static_cast<int>(row & 255u)), lane_bit), lane_bit));
    const __m256 m_hi = _mm256_castsi256_ps(_mm256_cmpeq_epi32(
        _mm256_and_si256(_mm256_set1_epi32(static_cast<int>(row >> 8)), lane_bit), lane_bit));
    p_lo = _mm256_and_ps(p_lo, m_lo);
    p_hi = _mm256_and_ps(p_hi, m_hi);
    const int k = y * 16;
    s0 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[0] + k), p_lo, s0);
    s1 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[1] + k), p_lo, s1);
    s2 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[2] + k), p_lo, s2);
    s0 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[0] + k + 8), p_hi, s0);
    s1 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[1] + k + 8), p_hi, s1);
    s2 = _mm256_fmadd_ps(_mm256_loadu_ps(lp[2] + k + 8), p_hi, s2);
  }
  sp[0] = HorizontalSumAvx2(s0);
  sp[1] = HorizontalSumAvx2(s1);
  sp[2] = HorizontalSumAvx2(s2);
}

bool CpuHasAvx2Fma() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                          __builtin_cpu_supports("bmi");
  return has;
}
#endif

// True where the AVX2 paths run (an x86 CPU with AVX2, FMA and BMI).
bool SimdAvailable() {
#ifdef PRT_TP_HAVE_AVX2
  return CpuHasAvx2Fma();
#else
  return false;
#endif
}

void SpecularBatch(const FloatLobes& L, bool simd, const float* x, const float* y, const float* z,
                   int count, float* out) {
  if (!L.spec || (L.model == BrdfModel::kAshikhminShirley && !(L.nv > 0))) {
    for (int i = 0; i < count; ++i) out[i] = 0.f;
    return;
  }
#ifdef PRT_TP_HAVE_AVX2
  if (simd && L.fast_pow && CpuHasAvx2Fma()) return SpecularBatchAvx2(L, x, y, z, count, out);
#endif
  (void)simd;
  SpecularBatchScalar(L, x, y, z, count, out);
}

// ---- One block of Algorithm 1 -----------------------------------------------------------------
// What ProjectBRDF (line 4) gave a block: its rate, the diffuse lobe at its centre, the DCT
// coefficients of the lobes.
struct BlockBrdf {
  int rate = 1, l = 1;
  float d0 = 0;
  alignas(32) float coef[16];   // specular lobe, 1/4/16 DCT coefficients
  alignas(32) float dcoef[16];  // diffuse lobe, 4/16 DCT coefficients (the paper's ProjectBRDF)
};

inline int LevelsOf(int rate) {
  return rate == 1 ? 1 : (rate == 4 ? 2 : (rate == 16 ? 4 : 16));
}

// The per-vertex constants every block of Algorithm 1 reads.
struct VertexTerms {
  const VisibilityBlocks& vis;
  const CubemapBlocks& blocks;
  const BlockLighting& light;
  bool spec, exact;
  bool simd_lobes = false;    // FloatLobes' specular samples through SpecularBatch
  bool simd_changes = false;  // line 9's changes through AccumulateChangePairsAvx2
  float kd[3], ks[3];
  float inv_max;
  float nx, ny, nz;  // n/π: (n/π)·Σ L'ω over a range of positions is the exact diffuse integral
  VertexTerms(const VisibilityBlocks& vis_, const CubemapBlocks& blocks_,
              const BlockLighting& light_, const Material& m, const ShadingFrame& f, bool exact_)
      : vis(vis_), blocks(blocks_), light(light_), spec(HasSpecular(m)), exact(exact_) {
    for (int c = 0; c < 3; ++c) {
      kd[c] = m.diffuse[c];
      ks[c] = spec ? m.specular[c] : 0.f;
    }
    inv_max = 1.0f / static_cast<float>(vis.max_level());
    constexpr float kInvPi = 0.318309886f;
    nx = static_cast<float>(f.normal.x) * kInvPi;
    ny = static_cast<float>(f.normal.y) * kInvPi;
    nz = static_cast<float>(f.normal.z) * kInvPi;
  }
  // Diffuse of channel c from 16 interleaved suffix values (block_lighting.h).
  float CosineOf(const float* q, int c) const {
    return nx * q[4 + c] + ny * q[8 + c] + nz * q[12 + c];
  }
};

// The l×l lobe samples of a block at rate ≤ 16 projected onto the DCT (Eq. 4): the specular
// lobe (unless the l = 1 value is given) and, in the paper's diffuse mode, the diffuse lobe.
template <class Lobes>
void ProjectBlockLobes(const VertexTerms& vt, const Lobes& lobes, int b, BlockBrdf& bb) {
  const float* dirs = vt.blocks.SampleDirections(b, bb.l);
  alignas(32) float samples[16];
  if (vt.spec) {
    if constexpr (std::is_same_v<Lobes, FloatLobes>) {
      if (vt.simd_lobes) {
        const float* soa = vt.blocks.SampleSoA(b);
        const int at = bb.l == 1 ? 0 : (bb.l == 2 ? 1 : 5);
        SpecularBatch(lobes, true, soa + at, soa + 24 + at, soa + 48 + at, bb.l * bb.l, samples);
      } else {
        for (int i = 0; i < bb.l * bb.l; ++i) samples[i] = lobes.Specular(dirs + 3 * i);
      }
    } else {
      for (int i = 0; i < bb.l * bb.l; ++i) samples[i] = lobes.Specular(dirs + 3 * i);
    }
    BlockDct::Project(bb.l, samples, bb.coef);
  } else {
    bb.coef[0] = 0.f;
  }
  if (bb.l > 1 && !vt.exact) {
    for (int i = 0; i < bb.l * bb.l; ++i) samples[i] = lobes.Diffuse(dirs + 3 * i);
    BlockDct::Project(bb.l, samples, bb.dcoef);
  }
}

// Lines 5–11 of Algorithm 1 for one non-zero block, its BRDF projected: out = the block's share
// of B. Lobes evaluates the lobes per pixel in the 256-sample case.
template <class Lobes>
TripleProductCase NonZeroBlock(const VertexTerms& vt, const Lobes& lobes, int b, std::size_t e,
                               VisibilityBlockKind kind, const BlockBrdf& bb, float out[3]) {
  constexpr int kS = BlockLighting::kRgbXyzStride;
  const VisibilityBlocks& vis = vt.vis;
  const BlockLighting& light = vt.light;
  const bool exact = vt.exact, spec = vt.spec;
  const float* kd = vt.kd;
  const float* ks = vt.ks;
  const float inv_max = vt.inv_max;
  const int rate = bb.rate, l = bb.l;
  const float* coef = bb.coef;
  const float* dcoef = bb.dcoef;
  alignas(32) float spix[256];
  alignas(32) float dpix[256];
  alignas(32) float acc[kS];
  const float* q = light.SuffixRgbXyz(b);
  if (kind == VisibilityBlockKind::kOne) {  // line 6: Light-BRDF product
    if (rate <= 16) {
      for (int c = 0; c < 3; ++c) {
        const float* ld = light.Dct(b, c);
        float dif;
        if (exact) {
          dif = vt.CosineOf(q, c);
        } else if (l == 1) {
          dif = bb.d0 * 16.f * ld[0];
        } else {
          dif = 0;
          for (int v = 0; v < l; ++v)
            for (int u = 0; u < l; ++u) dif += dcoef[v * l + u] * ld[v * 4 + u];
        }
        float sp = 0;
        if (spec)
          for (int v = 0; v < l; ++v)
            for (int u = 0; u < l; ++u) sp += coef[v * l + u] * ld[v * 4 + u];
        out[c] = kd[c] * dif + ks[c] * sp;
      }
    } else {
      const float* dirs = vt.blocks.PixelDirections(b);
      for (int k = 0; k < 256; ++k) {
        dpix[k] = lobes.Diffuse(dirs + 3 * k);
        spix[k] = lobes.Specular(dirs + 3 * k);
      }
      for (int c = 0; c < 3; ++c) {
        const float* lp = light.Pixels(b, c);
        out[c] = kd[c] * DotRange(lp, dpix, 0, 256) + ks[c] * DotRange(lp, spix, 0, 256);
      }
    }
    return TripleProductCase::kLine6;
  }
  if (rate == 1) {  // line 9: ρ̃₁ · Light-Vis product, L_int · V_d (Eq. 5–6)
    const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
    const float s0 = spec ? coef[0] * 0.0625f : 0.f;  // the constant is A_00 / 16
    // Σ_i V_d[i]·(all twelve suffix sums at change i): one cache line per change.
#ifdef PRT_TP_HAVE_AVX2
    if (vt.simd_changes && exact && vis.bits == 1) {
      const float n_pi[3] = {vt.nx, vt.ny, vt.nz};
      Line9ExactAvx2(q, vis.change_pos.data() + first, last - first, n_pi, kd, ks, s0, out);
      return TripleProductCase::kLine9;
    }
#endif
    const int width = exact ? kS : 4;
    for (int j = 0; j < kS; ++j) acc[j] = 0.f;
    if (vis.bits == 1) {
      uint64_t i = first;
      for (; i + 2 <= last; i += 2) {
        const float* a = q + vis.change_pos[i] * kS;
        const float* z = q + vis.change_pos[i + 1] * kS;
        for (int j = 0; j < width; ++j) acc[j] += a[j] - z[j];
      }
      if (i < last) {
        const float* a = q + vis.change_pos[i] * kS;
        for (int j = 0; j < width; ++j) acc[j] += a[j];
      }
    } else {
      for (uint64_t i = first; i < last; ++i) {
        const float dv = static_cast<float>(vis.change_value[i]) * inv_max;
        const float* a = q + vis.change_pos[i] * kS;
        for (int j = 0; j < width; ++j) acc[j] += dv * a[j];
      }
    }
    for (int c = 0; c < 3; ++c)
      out[c] = exact ? kd[c] * vt.CosineOf(acc, c) + ks[c] * s0 * acc[c]
                     : (kd[c] * bb.d0 + ks[c] * s0) * acc[c];
    return TripleProductCase::kLine9;
  }
  // line 11: Decompress-Integrate in the pixel basis over the visible runs (§4.4)
  if (rate <= 16) {
    for (int j = 0; j < kS; ++j) acc[j] = 0.f;
    float sp[3] = {0, 0, 0}, dif[3] = {0, 0, 0};
#ifdef PRT_TP_HAVE_AVX2
    if (vt.simd_changes && vis.bits == 1 && exact) {
      uint64_t visible[4];
      VisibleBits(vis, e, visible);
      const float* lp[3] = {light.Pixels(b, 0), light.Pixels(b, 1), light.Pixels(b, 2)};
      if (spec) {
        if (l == 1)
          Line11FromDctAvx2<1>(coef, visible, lp, sp);
        else if (l == 2)
          Line11FromDctAvx2<2>(coef, visible, lp, sp);
        else
          Line11FromDctAvx2<4>(coef, visible, lp, sp);
      }
      const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
      AccumulateChangePairsAvx2(q, vis.change_pos.data() + first, last - first, acc);
      for (int c = 0; c < 3; ++c) out[c] = kd[c] * vt.CosineOf(acc, c) + ks[c] * sp[c];
      return TripleProductCase::kLine11;
    }
#endif
    BlockDct::Reconstruct(l, coef, spix);
    if (!exact) BlockDct::Reconstruct(l, dcoef, dpix);
#ifdef PRT_TP_HAVE_AVX2
    if (vt.simd_changes && vis.bits == 1) {
      uint64_t visible[4];
      VisibleBits(vis, e, visible);
      const float* lp[3] = {light.Pixels(b, 0), light.Pixels(b, 1), light.Pixels(b, 2)};
      Line11PixelsAvx2(visible, lp, spix, exact ? nullptr : dpix, sp, dif);
      if (exact) {
        const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
        AccumulateChangePairsAvx2(q, vis.change_pos.data() + first, last - first, acc);
      }
    } else
#endif
      ForEachVisibleRun(vis, e, [&](int a, int z, int level) {
        const float w = vis.bits == 1 ? 1.f : static_cast<float>(level) * inv_max;
        if (exact) {
          const float *qa = q + a * kS, *qz = q + z * kS;
          for (int j = 0; j < kS; ++j) acc[j] += w * (qa[j] - qz[j]);
        }
        for (int c = 0; c < 3; ++c) {
          const float* lp = light.Pixels(b, c);
          sp[c] += w * DotRange(lp, spix, a, z);
          if (!exact) dif[c] += w * DotRange(lp, dpix, a, z);
        }
      });
    for (int c = 0; c < 3; ++c)
      out[c] = kd[c] * (exact ? vt.CosineOf(acc, c) : dif[c]) + ks[c] * sp[c];
  } else {
    const float* dirs = vt.blocks.PixelDirections(b);
    ForEachVisibleRun(vis, e, [&](int a, int z, int) {
      for (int k = a; k < z; ++k) {
        dpix[k] = lobes.Diffuse(dirs + 3 * k);
        spix[k] = lobes.Specular(dirs + 3 * k);
      }
    });
    for (int c = 0; c < 3; ++c) {
      const float* lp = light.Pixels(b, c);
      float sum = 0;
      ForEachVisibleRun(vis, e, [&](int a, int z, int level) {
        const float w = vis.bits == 1 ? 1.f : static_cast<float>(level) * inv_max;
        sum += w * (kd[c] * DotRange(lp, dpix, a, z) + ks[c] * DotRange(lp, spix, a, z));
      });
      out[c] = sum;
    }
  }
  return TripleProductCase::kLine11;
}

// Algorithm 1, block by block (see triple_product.h), the kernel before issue 41: the BRDF
// projected per block in double (BrdfSamplingRate, SpecularLobe); calls sink(block, line, rate,
// out[3]) for every block of the vertex, zero blocks included.
template <typename Sink>
void Algorithm1(const GlossyScene& scene, const CubemapBlocks& blocks, const BlockLighting& light,
                std::size_t vertex, const Vec3& eye, const TripleProductOptions& options,
                Sink&& sink) {
  const VisibilityBlocks& vis = *scene.visibility;
  const Material& m = scene.materials[scene.material_index[vertex]];
  const ShadingFrame f = MakeShadingFrame(scene.normals[vertex], eye - scene.positions[vertex]);
  const VertexTerms vt(vis, blocks, light, m, f, options.exact_cosine);
  const DoubleLobes lobes{m, f};
  const float zero[3] = {0, 0, 0};
  const std::size_t e0 = vis.Entry(vertex, 0);
  BlockBrdf bb;
  for (int b = 0; b < blocks.block_count(); ++b) {
    const std::size_t e = e0 + b;
    const auto kind = static_cast<VisibilityBlockKind>(vis.kind[e]);
    if (kind == VisibilityBlockKind::kZero) {  // line 1
      sink(b, TripleProductCase::kZero, 0, zero);
      continue;
    }
    // Line 4, ProjectBRDF (§4.1, Appendix A): ρ̃ = diffuse + specular at the rate the rules ask
    // for; with exact_cosine the diffuse part is integrated exactly instead.
    const Vec3& centre = blocks.Centre(b);
    bb.rate = BrdfSamplingRate(m, f, centre, options.full_rate_exponent);
    bb.l = LevelsOf(bb.rate);
    bb.d0 = static_cast<float>(DiffuseLobe(f, centre));
    if (bb.rate <= 16) ProjectBlockLobes(vt, lobes, b, bb);
    float out[3] = {0, 0, 0};
    const TripleProductCase line = NonZeroBlock(vt, lobes, b, e, kind, bb, out);
    sink(b, line, bb.rate, out);
  }
}

#ifdef PRT_TP_HAVE_AVX2
// FastVertex's block loop with the exact cosine on a 1-bit map: the rate-1 blocks of lines 6 and
// 9, most of a vertex's non-zero blocks, add their suffix lines (line 6: the block's total, line
// 0; line 9: Σ over change pairs) into running sums for the whole vertex, [Lx] and [Ly, Lz] as
// they are and L weighted by the block's ρ̃₁, and the vertex's share is taken from the sums once
// at the end: out_c = kd_c·(n/π)·Σ(Lx, Ly, Lz)_c + ks_c·Σ ρ̃₁·L_c. (Line 6 at one BRDF sample is
// ρ̃₁·16·F_00 = ρ̃₁·Σ L', the block's total; the sums reorder float additions only.) Other
// blocks go through NonZeroBlock as in FastVertex.
__attribute__((target("avx2,fma"))) void BlocksWithVertexSumsAvx2(
    const VertexTerms& vt, const FloatLobes& lobes, const uint16_t* list, int count,
    const int32_t* rate_code, const float* d0, const float* s0, std::size_t e0,
    const uint8_t* kinds, double total[3], TripleProductStats& st) {
  const VisibilityBlocks& vis = vt.vis;
  __m256 lo_sum = _mm256_setzero_ps(), hi_sum = _mm256_setzero_ps(), spec = _mm256_setzero_ps();
  static constexpr int kRate[4] = {1, 4, 16, 256};
  BlockBrdf bb;
  for (int i = 0; i < count; ++i) {
    const int b = list[i];
    const std::size_t e = e0 + b;
    const auto kind = static_cast<VisibilityBlockKind>(kinds[b]);
    if (rate_code[i] == 0) {
      const float* q = vt.light.SuffixRgbXyz(b);
      __m256 lo, hi;
      if (kind == VisibilityBlockKind::kOne) {
        lo = _mm256_load_ps(q);
        hi = _mm256_load_ps(q + 8);
        ++st.blocks_line6;
      } else {
        const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
        ChangePairsAvx2(q, vis.change_pos.data() + first, last - first, lo, hi);
        ++st.blocks_line9;
      }
      ++st.brdf_rate[0];
      lo_sum = _mm256_add_ps(lo_sum, lo);
      hi_sum = _mm256_add_ps(hi_sum, hi);
      spec = _mm256_fmadd_ps(_mm256_set1_ps(s0[i]), lo, spec);
      continue;
    }
    bb.rate = kRate[rate_code[i]];
    bb.l = LevelsOf(bb.rate);
    bb.d0 = d0[i];
    if (bb.rate <= 16) ProjectBlockLobes(vt, lobes, b, bb);
    float out[3] = {0, 0, 0};
    const TripleProductCase line = NonZeroBlock(vt, lobes, b, e, kind, bb, out);
    for (int c = 0; c < 3; ++c) total[c] += out[c];
    Count(st, line, bb.rate);
  }
  const __m128 lx = _mm256_extractf128_ps(lo_sum, 1);
  const __m128 ly = _mm256_castps256_ps128(hi_sum), lz = _mm256_extractf128_ps(hi_sum, 1);
  const __m128 cosine =
      _mm_fmadd_ps(_mm_set1_ps(vt.nx), lx,
                   _mm_fmadd_ps(_mm_set1_ps(vt.ny), ly, _mm_mul_ps(_mm_set1_ps(vt.nz), lz)));
  const __m128 r = _mm_fmadd_ps(
      _mm_setr_ps(vt.kd[0], vt.kd[1], vt.kd[2], 0.f), cosine,
      _mm_mul_ps(_mm_setr_ps(vt.ks[0], vt.ks[1], vt.ks[2], 0.f), _mm256_castps256_ps128(spec)));
  alignas(16) float t[4];
  _mm_store_ps(t, r);
  for (int c = 0; c < 3; ++c) total[c] += t[c];
}
#endif

// The optimised kernel (issue 41; TripleProductSpeedup in triple_product.h): the same blocks,
// cases, rates and projections as Algorithm1, with
//   - the non-zero blocks listed first from the vertex's 96 kind bytes, and only they visited;
//   - the vertex set-up for all of them at once in float: Appendix A's angle between the view
//     and the block centre mirrored about n is cos = r·v = 2(n·c)(n·v) − c·v for a unit centre
//     c (no square root), Phong's r_view·c is that same number, the diffuse lobe is n·c/π;
//   - the lobes in float (FloatLobes) with FastPowUnit.
std::array<double, 3> FastVertex(const GlossyScene& scene, const CubemapBlocks& blocks,
                                 const BlockLighting& light, std::size_t vertex, const Vec3& eye,
                                 const TripleProductOptions& options, TripleProductStats* stats) {
  const VisibilityBlocks& vis = *scene.visibility;
  const Material& m = scene.materials[scene.material_index[vertex]];
  const ShadingFrame f = MakeShadingFrame(scene.normals[vertex], eye - scene.positions[vertex]);
  VertexTerms vt(vis, blocks, light, m, f, options.exact_cosine);
  const FloatLobes lobes(m, f, (options.disable & kSpeedupFastPow) == 0);
  const bool simd = (options.disable & kSpeedupSimdLobes) == 0;
  vt.simd_lobes = simd;
#ifdef PRT_TP_HAVE_AVX2
  vt.simd_changes = (options.disable & kSpeedupSimdChanges) == 0 && CpuHasAvx2Fma();
#endif
  const DoubleLobes dlobes{m, f};
  const bool setup = (options.disable & kSpeedupVertexSetup) == 0;
  const int nb = blocks.block_count();
  const std::size_t e0 = vis.Entry(vertex, 0);
  const uint8_t* kinds = &vis.kind[e0];
  if ((options.disable & kSpeedupPrefetch) == 0) {
    // The change positions of the next vertex (its offsets were prefetched a vertex ago) and
    // the offsets and kinds of the ones after: a vertex reads them in block order, but only for
    // its mixed blocks, which the hardware prefetcher does not follow.
    const std::size_t entries = vis.kind.size();
    if (e0 + 2 * nb <= entries) {
      const uint64_t a = vis.change_begin[e0 + nb], z = vis.change_begin[e0 + 2 * nb];
      for (uint64_t i = a; i < z; i += 64) __builtin_prefetch(vis.change_pos.data() + i);
      __builtin_prefetch(kinds + nb);
      __builtin_prefetch(kinds + nb + 64);
    }
    if (e0 + 3 * nb <= entries)
      for (int i = 0; i < nb; i += 8) __builtin_prefetch(vis.change_begin.data() + e0 + 2 * nb + i);
  }
  // The non-zero blocks (line 1 skips the rest).
  static_assert(static_cast<uint8_t>(VisibilityBlockKind::kZero) == 0);
  uint16_t list[kMaxBlocks];
  int count = 0;
  const bool avx2 = simd && SimdAvailable();
#ifdef PRT_TP_HAVE_AVX2
  if (avx2 && setup) {
    count = ListNonZeroAvx2(kinds, nb, list);
  } else
#endif
  {
    for (int b = 0; b < nb; ++b) {
      list[count] = static_cast<uint16_t>(b);
      count += kinds[b] != static_cast<uint8_t>(VisibilityBlockKind::kZero);
    }
  }
  // Appendix A's rate per listed block and the lobes at its centre.
  alignas(32) int32_t rate_code[kMaxBlocks + 8];  // 0..3: 1, 4, 16, 256
  alignas(32) float d0[kMaxBlocks + 8], s0[kMaxBlocks + 8];
  const double s_eff = EffectiveExponent(m);
  const int far_code = 0;
  const int mid_code = 1;
  const int near_code =
      !lobes.spec ? 0 : (s_eff < 30 ? 1 : (s_eff < options.full_rate_exponent ? 2 : 3));
  constexpr float kCosPi4 = 0.70710678118654752f, kCosPi8 = 0.92387953251128676f;
  const bool low_exponent = s_eff < 30;
  if (setup) {
    const float* cx = blocks.CentreX();
    const float* cy = blocks.CentreY();
    const float* cz = blocks.CentreZ();
    const float nv = lobes.nv;
    if (simd) {  // the specular lobe at every listed centre, 8 at a time
      alignas(32) float gx[kMaxBlocks + 8], gy[kMaxBlocks + 8], gz[kMaxBlocks + 8];
      for (int i = 0; i < count; ++i) {
        gx[i] = cx[list[i]];
        gy[i] = cy[list[i]];
        gz[i] = cz[list[i]];
      }
      for (int i = count; i < count + 8; ++i) gx[i] = gy[i] = gz[i] = 0.f;
#ifdef PRT_TP_HAVE_AVX2
      if (avx2) {
        // Phong's centre lobe comes out of the set-up's own cos (r·c for the centre c);
        // Ashikhmin–Shirley needs the half vector: SpecularBatch.
        const bool phong_centres = lobes.spec && lobes.model == BrdfModel::kPhong;
        SetupAvx2(lobes, gx, gy, gz, count, low_exponent, mid_code, near_code, rate_code, d0,
                  phong_centres ? s0 : nullptr);
        if (!phong_centres) SpecularBatch(lobes, true, gx, gy, gz, count, s0);
      } else
#endif
      {
        SpecularBatch(lobes, true, gx, gy, gz, count, s0);
      }
    }
    for (int i = 0; i < count && !avx2; ++i) {
      const int b = list[i];
      const float c[3] = {cx[b], cy[b], cz[b]};
      const float nc = FloatLobes::Dot3(lobes.n, c), vc = FloatLobes::Dot3(lobes.v, c);
      const float cosang = 2.f * nc * nv - vc;
      int code;
      if (!lobes.spec) {
        code = 0;
      } else if (low_exponent) {
        code = cosang > kCosPi4 ? mid_code : far_code;
      } else {
        code = cosang > kCosPi8 ? near_code : (cosang > kCosPi4 ? mid_code : far_code);
      }
      rate_code[i] = code;
      d0[i] = nc > 0 ? nc * 0.318309886f : 0.f;
      if (!simd) s0[i] = code == 0 ? lobes.SpecularFrom(c, nc, cosang) : 0.f;
    }
  } else {
    for (int i = 0; i < count; ++i) {
      const int b = list[i];
      const int rate = BrdfSamplingRate(m, f, blocks.Centre(b), options.full_rate_exponent);
      rate_code[i] = rate == 1 ? 0 : (rate == 4 ? 1 : (rate == 16 ? 2 : 3));
      d0[i] = static_cast<float>(DiffuseLobe(f, blocks.Centre(b)));
      s0[i] = 0.f;
    }
  }
  static constexpr int kRate[4] = {1, 4, 16, 256};
  double total[3] = {0, 0, 0};
  TripleProductStats st;
  st.blocks_zero = static_cast<uint64_t>(nb - count);
#ifdef PRT_TP_HAVE_AVX2
  if (avx2 && setup && vt.simd_changes && vt.exact && vis.bits == 1 &&
      (options.disable & kSpeedupVertexSums) == 0) {
    BlocksWithVertexSumsAvx2(vt, lobes, list, count, rate_code, d0, s0, e0, kinds, total, st);
    if (std::isfinite(total[0]) && std::isfinite(total[1]) && std::isfinite(total[2])) {
      if (stats != nullptr) *stats += st;
      return {total[0], total[1], total[2]};
    }
    // The float sums over many blocks overflowed where the blocks' own products (summed in
    // double) may not: the vertex again block by block, which decides.
    total[0] = total[1] = total[2] = 0.0;
    st = TripleProductStats{};
    st.blocks_zero = static_cast<uint64_t>(nb - count);
  }
#endif
  BlockBrdf bb;
  for (int i = 0; i < count; ++i) {
    const int b = list[i];
    const std::size_t e = e0 + b;
    bb.rate = kRate[rate_code[i]];
    bb.l = LevelsOf(bb.rate);
    bb.d0 = d0[i];
    if (bb.rate == 1 && setup) {
      // Eq. 4 with one sample: A_00 = 16·ρ̃(centre) (BlockDct::Project(1, …) to the bit).
      bb.coef[0] = vt.spec ? 16.f * s0[i] : 0.f;
    } else if (bb.rate <= 16) {
      if (setup)
        ProjectBlockLobes(vt, lobes, b, bb);
      else
        ProjectBlockLobes(vt, dlobes, b, bb);
    }
    float out[3] = {0, 0, 0};
    const auto kind = static_cast<VisibilityBlockKind>(kinds[b]);
    const TripleProductCase line = setup ? NonZeroBlock(vt, lobes, b, e, kind, bb, out)
                                         : NonZeroBlock(vt, dlobes, b, e, kind, bb, out);
    for (int c = 0; c < 3; ++c) total[c] += out[c];
    Count(st, line, bb.rate);
  }
  if (stats != nullptr) *stats += st;
  return {total[0], total[1], total[2]};
}

// The pixel-basis reference block by block: sink(block, rgb) in double.
template <typename Sink>
void Reference(const GlossyScene& scene, const CubemapBlocks& blocks, const BlockLighting& light,
               std::size_t vertex, const Vec3& eye, bool skip_occluded, Sink&& sink) {
  const VisibilityBlocks& vis = *scene.visibility;
  const Material& m = scene.materials[scene.material_index[vertex]];
  const ShadingFrame f = MakeShadingFrame(scene.normals[vertex], eye - scene.positions[vertex]);
  const bool spec = HasSpecular(m);
  const double inv_max = 1.0 / vis.max_level();
  uint8_t levels[256];
  for (int b = 0; b < blocks.block_count(); ++b) {
    DecodeVisibilityBlock(vis, vertex, b, levels);
    const float* dirs = blocks.PixelDirections(b);
    const float* lp[3] = {light.Pixels(b, 0), light.Pixels(b, 1), light.Pixels(b, 2)};
    double total[3] = {0, 0, 0};
    for (int k = 0; k < 256; ++k) {
      if (skip_occluded && levels[k] == 0) continue;
      const Vec3 w = Dir(dirs + 3 * k);
      const double d = DiffuseLobe(f, w);
      const double s = spec ? SpecularLobe(m, f, w) : 0.0;
      const double v = levels[k] * inv_max;
      for (int c = 0; c < 3; ++c)
        total[c] += lp[c][k] * v * (m.diffuse[c] * d + (spec ? m.specular[c] * s : 0.0));
    }
    sink(b, total);
  }
}

}  // namespace

const char* TripleProductSpeedupName(uint32_t bit) {
  switch (bit) {
    case kSpeedupVertexSetup:
      return "vertex set-up";
    case kSpeedupFastPow:
      return "fast pow";
    case kSpeedupSimdLobes:
      return "AVX2 lobes";
    case kSpeedupSimdChanges:
      return "AVX2 changes";
    case kSpeedupPrefetch:
      return "prefetch";
    case kSpeedupVertexSums:
      return "vertex sums";
    default:
      return "unknown";
  }
}

TripleProductStats& TripleProductStats::operator+=(const TripleProductStats& o) {
  blocks_zero += o.blocks_zero;
  blocks_line6 += o.blocks_line6;
  blocks_line9 += o.blocks_line9;
  blocks_line11 += o.blocks_line11;
  for (int i = 0; i < 4; ++i) brdf_rate[i] += o.brdf_rate[i];
  return *this;
}

std::array<double, 3> TripleProductVertex(const GlossyScene& scene, const CubemapBlocks& blocks,
                                          const BlockLighting& light, std::size_t vertex,
                                          const Vec3& eye, TripleProductStats* stats,
                                          const TripleProductOptions& options) {
  std::array<double, 3> total{0, 0, 0};
  if (options.generic) {
    TripleProductStats st;
    Algorithm1(scene, blocks, light, vertex, eye, options,
               [&](int, TripleProductCase line, int rate, const float* out) {
                 Count(st, line, rate);
                 for (int c = 0; c < 3; ++c) total[c] += out[c];
               });
    if (stats != nullptr) *stats += st;
  } else {
    total = FastVertex(scene, blocks, light, vertex, eye, options, stats);
  }
  std::array<double, 3> r{};
  for (int c = 0; c < 3; ++c) {
    // A double sum of at most 6·(n/16)² float block products cannot overflow; it is NaN/Inf only
    // when a block's float product overflowed (finite lighting and BRDF values whose product
    // passes 3.4e38), which is an error, not a black vertex.
    if (!std::isfinite(total[c])) ThrowNonFiniteVertex(vertex, c, total[c]);
    // Negative totals come from the DCT approximation of the lobes (Algorithm 1's lines 6–11):
    // radiance is ≥ 0.
    r[c] = std::max(0.0, total[c]);
  }
  return r;
}

void TripleProductVertexBlocks(const GlossyScene& scene, const CubemapBlocks& blocks,
                               const BlockLighting& light, std::size_t vertex, const Vec3& eye,
                               std::span<TripleProductBlockTerm> out,
                               const TripleProductOptions& options) {
  CheckSizes(scene, blocks, light);
  if (vertex >= scene.positions.size() || scene.material_index[vertex] >= scene.materials.size() ||
      out.size() != static_cast<std::size_t>(blocks.block_count()))
    throw std::invalid_argument("TripleProductVertexBlocks: vertex or output size");
  Algorithm1(scene, blocks, light, vertex, eye, options,
             [&](int b, TripleProductCase line, int rate, const float* rgb) {
               out[b].line = line;
               out[b].rate = static_cast<uint16_t>(rate);
               for (int c = 0; c < 3; ++c) {
                 if (!std::isfinite(rgb[c]))
                   throw NumericalError("triple product: vertex " + std::to_string(vertex) +
                                        ", block " + std::to_string(b) + ", channel " +
                                        std::to_string(c) +
                                        ": the block's product overflows float32");
                 out[b].rgb[c] = rgb[c];
               }
             });
}

TripleProductStats RelightTripleProduct(const GlossyScene& scene, const CubemapBlocks& blocks,
                                        const BlockLighting& light, const Vec3& eye,
                                        std::span<float> out_rgb,
                                        const TripleProductOptions& options) {
  return RelightTripleProductRange(scene, blocks, light, eye, 0, scene.positions.size(), out_rgb,
                                   options);
}

TripleProductStats RelightTripleProductRange(const GlossyScene& scene, const CubemapBlocks& blocks,
                                             const BlockLighting& light, const Vec3& eye,
                                             std::size_t first, std::size_t count,
                                             std::span<float> out_rgb,
                                             const TripleProductOptions& options) {
  CheckScene(scene, blocks, light);
  const std::size_t nv = scene.positions.size();
  if (first > nv || count > nv - first || out_rgb.size() != count * 3)
    throw std::invalid_argument("RelightTripleProduct: vertex range or output size");
  // Fixed chunks of vertices, each with its own statistics, summed in order: the result does not
  // depend on the parallel backend.
  const std::size_t chunks = (count + kVertexChunk - 1) / kVertexChunk;
  std::vector<TripleProductStats> local(chunks);
  ParallelFor(chunks, [&](std::size_t chunk) {
    TripleProductStats& st = local[chunk];
    const std::size_t end = std::min(count, (chunk + 1) * kVertexChunk);
    for (std::size_t i = chunk * kVertexChunk; i < end; ++i) {
      const std::size_t v = first + i;
      const auto b = TripleProductVertex(scene, blocks, light, v, eye, &st, options);
      for (int c = 0; c < 3; ++c) out_rgb[i * 3 + c] = ToFloatRadiance(b[c], v, c);
    }
  });
  TripleProductStats total;
  for (const auto& s : local) total += s;
  return total;
}

std::array<double, 3> PixelBasisReferenceVertex(const GlossyScene& scene,
                                                const CubemapBlocks& blocks,
                                                const BlockLighting& light, std::size_t vertex,
                                                const Vec3& eye, bool skip_occluded) {
  std::array<double, 3> total{0, 0, 0};
  Reference(scene, blocks, light, vertex, eye, skip_occluded, [&](int, const double* rgb) {
    for (int c = 0; c < 3; ++c) total[c] += rgb[c];
  });
  return total;
}

void PixelBasisReferenceVertexBlocks(const GlossyScene& scene, const CubemapBlocks& blocks,
                                     const BlockLighting& light, std::size_t vertex,
                                     const Vec3& eye, std::span<std::array<double, 3>> out) {
  CheckSizes(scene, blocks, light);
  if (vertex >= scene.positions.size() || scene.material_index[vertex] >= scene.materials.size() ||
      out.size() != static_cast<std::size_t>(blocks.block_count()))
    throw std::invalid_argument("PixelBasisReferenceVertexBlocks: vertex or output size");
  Reference(scene, blocks, light, vertex, eye, true, [&](int b, const double* rgb) {
    for (int c = 0; c < 3; ++c) out[b][c] = rgb[c];
  });
}

void RelightPixelBasisReference(const GlossyScene& scene, const CubemapBlocks& blocks,
                                const BlockLighting& light, const Vec3& eye,
                                std::span<float> out_rgb, bool skip_occluded) {
  CheckScene(scene, blocks, light);
  if (out_rgb.size() != scene.positions.size() * 3)
    throw std::invalid_argument("RelightPixelBasisReference: output size");
  ParallelForRange(0, scene.positions.size(), 64, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t v = lo; v < hi; ++v) {
      const auto b = PixelBasisReferenceVertex(scene, blocks, light, v, eye, skip_occluded);
      for (int c = 0; c < 3; ++c) out_rgb[v * 3 + c] = ToFloatRadiance(b[c], v, c);
    }
  });
}

}  // namespace prt
