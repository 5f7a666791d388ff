#include "viewer/triple_product.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <stdexcept>

namespace prt {

namespace {

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

void CheckScene(const GlossyScene& s, const CubemapBlocks& blocks, const BlockLighting& light) {
  if (s.visibility == nullptr) throw std::invalid_argument("triple product: no visibility");
  const std::size_t nv = s.positions.size();
  if (s.normals.size() != nv || s.material_index.size() != nv || s.visibility->vertex_count != nv)
    throw std::invalid_argument("triple product: vertex counts disagree");
  if (s.visibility->n != blocks.n() || light.n != blocks.n())
    throw std::invalid_argument("triple product: cubemap resolutions disagree");
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

}  // namespace

TripleProductStats& TripleProductStats::operator+=(const TripleProductStats& o) {
  blocks_zero += o.blocks_zero;
  blocks_line6 += o.blocks_line6;
  blocks_line9 += o.blocks_line9;
  blocks_line11 += o.blocks_line11;
  for (int i = 0; i < 4; ++i) brdf_rate[i] += o.brdf_rate[i];
  return *this;
}

// Algorithm 1, block by block (see triple_product.h).
std::array<double, 3> TripleProductVertex(const GlossyScene& scene, const CubemapBlocks& blocks,
                                          const BlockLighting& light, std::size_t vertex,
                                          const Vec3& eye, TripleProductStats* stats,
                                          const TripleProductOptions& options) {
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
  const float nx = static_cast<float>(f.normal.x) * kInvPi,
              ny = static_cast<float>(f.normal.y) * kInvPi,
              nz = static_cast<float>(f.normal.z) * kInvPi;
  // (n/π)·Lω_int[k]: the exact diffuse integral of the suffix from position k.
  auto cosine_suffix = [&](const float* sv, int k) {
    return nx * sv[3 * k] + ny * sv[3 * k + 1] + nz * sv[3 * k + 2];
  };
  TripleProductStats st;
  double total[3] = {0, 0, 0};
  alignas(32) float coef[16];
  alignas(32) float spix[256];
  alignas(32) float dpix[256];
  const std::size_t e0 = vis.Entry(vertex, 0);
  for (int b = 0; b < blocks.block_count(); ++b) {
    const std::size_t e = e0 + b;
    const auto kind = static_cast<VisibilityBlockKind>(vis.kind[e]);
    if (kind == VisibilityBlockKind::kZero) {  // line 1
      ++st.blocks_zero;
      continue;
    }
    // Line 4, ProjectBRDF (§4.1, Appendix A): diffuse part constant over the block, specular
    // part at the rate the rules ask for.
    const Vec3& centre = blocks.Centre(b);
    const int rate = BrdfSamplingRate(m, f, centre);
    const int l = rate == 1 ? 1 : (rate == 4 ? 2 : (rate == 16 ? 4 : 16));
    ++st.brdf_rate[rate == 1 ? 0 : (rate == 4 ? 1 : (rate == 16 ? 2 : 3))];
    const float d0 = static_cast<float>(DiffuseLobe(f, centre));
    if (rate <= 16) {
      if (spec) {
        const float* dirs = blocks.SampleDirections(b, l);
        float samples[16];
        for (int i = 0; i < l * l; ++i)
          samples[i] = static_cast<float>(SpecularLobe(m, f, Dir(dirs + 3 * i)));
        BlockDct::Project(l, samples, coef);
      } else {
        coef[0] = 0.f;
      }
    }
    float out[3] = {0, 0, 0};
    if (kind == VisibilityBlockKind::kOne) {  // line 6: Light-BRDF product
      ++st.blocks_line6;
      if (rate <= 16) {
        for (int c = 0; c < 3; ++c) {
          const float* ld = light.Dct(b, c);
          float acc =
              exact ? kd[c] * cosine_suffix(light.SuffixVec(b, c), 0) : kd[c] * d0 * 16.f * ld[0];
          if (spec) {
            float sp = 0;
            for (int v = 0; v < l; ++v)
              for (int u = 0; u < l; ++u) sp += coef[v * l + u] * ld[v * 4 + u];
            acc += ks[c] * sp;
          }
          out[c] = acc;
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
      ++st.blocks_line9;
      const uint64_t first = vis.change_begin[e], last = vis.change_begin[e + 1];
      const float s0 = spec ? coef[0] * 0.0625f : 0.f;  // the constant is A_00 / 16
      for (int c = 0; c < 3; ++c) {
        const float* li = light.Suffix(b, c);
        float acc = 0;
        if (vis.bits == 1) {
          for (uint64_t i = first; i < last; ++i)
            acc += ((i - first) & 1) ? -li[vis.change_pos[i]] : li[vis.change_pos[i]];
        } else {
          for (uint64_t i = first; i < last; ++i)
            acc += static_cast<float>(vis.change_value[i]) * li[vis.change_pos[i]];
          acc *= inv_max;
        }
        if (!exact) {
          out[c] = (kd[c] * d0 + ks[c] * s0) * acc;
        } else {
          const float* sv = light.SuffixVec(b, c);
          float dif = 0;
          if (vis.bits == 1) {
            for (uint64_t i = first; i < last; ++i) {
              const float t = cosine_suffix(sv, vis.change_pos[i]);
              dif += ((i - first) & 1) ? -t : t;
            }
          } else {
            for (uint64_t i = first; i < last; ++i)
              dif += static_cast<float>(vis.change_value[i]) * cosine_suffix(sv, vis.change_pos[i]);
            dif *= inv_max;
          }
          out[c] = kd[c] * dif + ks[c] * s0 * acc;
        }
      }
    } else {  // line 11: Decompress-Integrate in the pixel basis over the visible runs (§4.4)
      ++st.blocks_line11;
      if (rate <= 16) {
        BlockDct::Reconstruct(l, coef, spix);
        for (int c = 0; c < 3; ++c) {
          const float* li = light.Suffix(b, c);
          const float* lp = light.Pixels(b, c);
          const float* sv = light.SuffixVec(b, c);
          float dif = 0, sp = 0;
          ForEachVisibleRun(vis, e, [&](int a, int z, int level) {
            const float w = vis.bits == 1 ? 1.f : static_cast<float>(level) * inv_max;
            dif += w * (exact ? cosine_suffix(sv, a) - cosine_suffix(sv, z) : d0 * (li[a] - li[z]));
            sp += w * DotRange(lp, spix, a, z);
          });
          out[c] = kd[c] * dif + ks[c] * sp;
        }
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
          float acc = 0;
          ForEachVisibleRun(vis, e, [&](int a, int z, int level) {
            const float w = vis.bits == 1 ? 1.f : static_cast<float>(level) * inv_max;
            acc += w * (kd[c] * DotRange(lp, dpix, a, z) + ks[c] * DotRange(lp, spix, a, z));
          });
          out[c] = acc;
        }
      }
    }
    for (int c = 0; c < 3; ++c) total[c] += out[c];
  }
  if (stats != nullptr) *stats += st;
  std::array<double, 3> r{};
  for (int c = 0; c < 3; ++c) r[c] = std::isfinite(total[c]) ? std::max(0.0, total[c]) : 0.0;
  return r;
}

TripleProductStats RelightTripleProduct(const GlossyScene& scene, const CubemapBlocks& blocks,
                                        const BlockLighting& light, const Vec3& eye,
                                        std::span<float> out_rgb,
                                        const TripleProductOptions& options) {
  CheckScene(scene, blocks, light);
  if (out_rgb.size() != scene.positions.size() * 3)
    throw std::invalid_argument("RelightTripleProduct: output size");
  tbb::enumerable_thread_specific<TripleProductStats> local;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, scene.positions.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      TripleProductStats& st = local.local();
                      for (std::size_t v = r.begin(); v != r.end(); ++v) {
                        const auto b =
                            TripleProductVertex(scene, blocks, light, v, eye, &st, options);
                        for (int c = 0; c < 3; ++c) out_rgb[v * 3 + c] = static_cast<float>(b[c]);
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
  const VisibilityBlocks& vis = *scene.visibility;
  const Material& m = scene.materials[scene.material_index[vertex]];
  const ShadingFrame f = MakeShadingFrame(scene.normals[vertex], eye - scene.positions[vertex]);
  const bool spec = HasSpecular(m);
  const double inv_max = 1.0 / vis.max_level();
  double total[3] = {0, 0, 0};
  uint8_t levels[256];
  for (int b = 0; b < blocks.block_count(); ++b) {
    DecodeVisibilityBlock(vis, vertex, b, levels);
    const float* dirs = blocks.PixelDirections(b);
    const float* lp[3] = {light.Pixels(b, 0), light.Pixels(b, 1), light.Pixels(b, 2)};
    for (int k = 0; k < 256; ++k) {
      if (skip_occluded && levels[k] == 0) continue;
      const Vec3 w = Dir(dirs + 3 * k);
      const double d = DiffuseLobe(f, w);
      const double s = spec ? SpecularLobe(m, f, w) : 0.0;
      const double v = levels[k] * inv_max;
      for (int c = 0; c < 3; ++c)
        total[c] += lp[c][k] * v * (m.diffuse[c] * d + (spec ? m.specular[c] * s : 0.0));
    }
  }
  return {total[0], total[1], total[2]};
}

void RelightPixelBasisReference(const GlossyScene& scene, const CubemapBlocks& blocks,
                                const BlockLighting& light, const Vec3& eye,
                                std::span<float> out_rgb, bool skip_occluded) {
  CheckScene(scene, blocks, light);
  if (out_rgb.size() != scene.positions.size() * 3)
    throw std::invalid_argument("RelightPixelBasisReference: output size");
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, scene.positions.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t v = r.begin(); v != r.end(); ++v) {
                        const auto b =
                            PixelBasisReferenceVertex(scene, blocks, light, v, eye, skip_occluded);
                        for (int c = 0; c < 3; ++c) out_rgb[v * 3 + c] = static_cast<float>(b[c]);
                      }
                    });
}

}  // namespace prt
