#include "runtime/triple_product.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace prt {

namespace {

// Vertices per parallel work item of RelightTripleProduct.
constexpr std::size_t kVertexChunk = 256;

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

// Algorithm 1, block by block (see triple_product.h): calls sink(block, line, rate, out[3]) for
// every block of the vertex, zero blocks included.
template <typename Sink>
void Algorithm1(const GlossyScene& scene, const CubemapBlocks& blocks, const BlockLighting& light,
                std::size_t vertex, const Vec3& eye, const TripleProductOptions& options,
                Sink&& sink) {
  const VisibilityBlocks& vis = *scene.visibility;
  const Material& m = scene.materials[scene.material_index[vertex]];
  const ShadingFrame f = MakeShadingFrame(scene.normals[vertex], eye - scene.positions[vertex]);
  const bool spec = HasSpecular(m);
  const float kd[3] = {m.diffuse[0], m.diffuse[1], m.diffuse[2]};
  const float ks[3] = {spec ? m.specular[0] : 0.f, spec ? m.specular[1] : 0.f,
                       spec ? m.specular[2] : 0.f};
  const float inv_max = 1.0f / static_cast<float>(vis.max_level());
  const bool exact = options.exact_cosine;
  constexpr float kInvPi = 0.318309886f;
  // n/π: (n/π)·Σ L'ω over a range of positions is the exact diffuse integral over it.
  const float nx = static_cast<float>(f.normal.x) * kInvPi,
              ny = static_cast<float>(f.normal.y) * kInvPi,
              nz = static_cast<float>(f.normal.z) * kInvPi;
  constexpr int kS = BlockLighting::kRgbXyzStride;
  // Diffuse of channel c from 16 interleaved suffix values (block_lighting.h).
  auto cosine_of = [&](const float* q, int c) {
    return nx * q[4 + c] + ny * q[8 + c] + nz * q[12 + c];
  };
  alignas(32) float coef[16];   // specular lobe, 1/4/16 DCT coefficients
  alignas(32) float dcoef[16];  // diffuse lobe, 4/16 DCT coefficients (the paper's ProjectBRDF)
  alignas(32) float spix[256];
  alignas(32) float dpix[256];
  alignas(32) float acc[kS];
  const float zero[3] = {0, 0, 0};
  const std::size_t e0 = vis.Entry(vertex, 0);
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
    const int rate = BrdfSamplingRate(m, f, centre, options.full_rate_exponent);
    const int l = rate == 1 ? 1 : (rate == 4 ? 2 : (rate == 16 ? 4 : 16));
    const float d0 = static_cast<float>(DiffuseLobe(f, centre));
    if (rate <= 16) {
      const float* dirs = blocks.SampleDirections(b, l);
      float samples[16];
      if (spec) {
        for (int i = 0; i < l * l; ++i)
          samples[i] = static_cast<float>(SpecularLobe(m, f, Dir(dirs + 3 * i)));
        BlockDct::Project(l, samples, coef);
      } else {
        coef[0] = 0.f;
      }
      if (l > 1 && !exact) {
        for (int i = 0; i < l * l; ++i)
          samples[i] = static_cast<float>(DiffuseLobe(f, Dir(dirs + 3 * i)));
        BlockDct::Project(l, samples, dcoef);
      }
    }
    const float* q = light.SuffixRgbXyz(b);
    float out[3] = {0, 0, 0};
    TripleProductCase line;
    if (kind == VisibilityBlockKind::kOne) {  // line 6: Light-BRDF product
      line = TripleProductCase::kLine6;
      if (rate <= 16) {
        for (int c = 0; c < 3; ++c) {
          const float* ld = light.Dct(b, c);
          float dif;
          if (exact) {
            dif = cosine_of(q, c);
          } else if (l == 1) {
            dif = d0 * 16.f * ld[0];
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
        const float* dirs = blocks.PixelDirections(b);
        for (int k = 0; k < 256; ++k) {
          const Vec3 w = Dir(dirs + 3 * k);
          dpix[k] = static_cast<float>(DiffuseLobe(f, w));
          spix[k] = static_cast<float>(SpecularLobe(m, f, w));
        }
        for (int c = 0; c < 3; ++c) {
          const float* lp = light.Pixels(b, c);
          out[c] = kd[c] * DotRange(lp, dpix, 0, 256) + ks[c] * DotRange(lp, spix, 0, 256);
        }
      }
    } else if (rate == 1) {  // line 9: ρ̃₁ · Light-Vis product, L_int · V_d (Eq. 5–6)
      line = TripleProductCase::kLine9;
      const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
      const float s0 = spec ? coef[0] * 0.0625f : 0.f;  // the constant is A_00 / 16
      // Σ_i V_d[i]·(all twelve suffix sums at change i): one cache line per change.
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
        out[c] = exact ? kd[c] * cosine_of(acc, c) + ks[c] * s0 * acc[c]
                       : (kd[c] * d0 + ks[c] * s0) * acc[c];
    } else {  // line 11: Decompress-Integrate in the pixel basis over the visible runs (§4.4)
      line = TripleProductCase::kLine11;
      if (rate <= 16) {
        BlockDct::Reconstruct(l, coef, spix);
        if (!exact) BlockDct::Reconstruct(l, dcoef, dpix);
        for (int j = 0; j < kS; ++j) acc[j] = 0.f;
        float sp[3] = {0, 0, 0}, dif[3] = {0, 0, 0};
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
          out[c] = kd[c] * (exact ? cosine_of(acc, c) : dif[c]) + ks[c] * sp[c];
      } else {
        const float* dirs = blocks.PixelDirections(b);
        ForEachVisibleRun(vis, e, [&](int a, int z, int) {
          for (int k = a; k < z; ++k) {
            const Vec3 w = Dir(dirs + 3 * k);
            dpix[k] = static_cast<float>(DiffuseLobe(f, w));
            spix[k] = static_cast<float>(SpecularLobe(m, f, w));
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
    }
    sink(b, line, rate, out);
  }
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
  TripleProductStats st;
  double total[3] = {0, 0, 0};
  Algorithm1(scene, blocks, light, vertex, eye, options,
             [&](int, TripleProductCase line, int rate, const float* out) {
               Count(st, line, rate);
               for (int c = 0; c < 3; ++c) total[c] += out[c];
             });
  if (stats != nullptr) *stats += st;
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
