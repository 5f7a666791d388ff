#include "runtime/triple_product.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

namespace prt {
namespace {

constexpr int kN = 64;

CubemapRgb TestLight() {
  CubemapRgb l;
  l.n = kN;
  const CubemapLayout layout(kN);
  for (int c = 0; c < 3; ++c) l.Channel(c).resize(l.TexelCount());
  for (std::size_t j = 0; j < l.TexelCount(); ++j) {
    const Vec3 d = layout.TexelCenter(j);
    l.r[j] = static_cast<float>(1.0 + 0.5 * std::sin(3 * d.x) + 0.3 * d.y);
    l.g[j] = static_cast<float>(0.8 + 0.4 * std::cos(5 * d.z));
    l.b[j] = static_cast<float>(0.5 + 0.5 * d.y * d.y);
  }
  const std::size_t sun = layout.TexelOf(Normalize(Vec3{0.22, 1, 0.27}));
  l.r[sun] = l.g[sun] = l.b[sun] = 800.f;
  return l;
}

// What Algorithm 1 computes, written out in the pixel basis: Σ_k L'[k]·V[k]·ρ̂[k] with ρ̂ the
// block's BRDF approximation (diffuse and specular lobes from their 1/4/16 subsampled DCT
// coefficients, one coefficient being the value at the block centre, or the exact BRDF where it
// needs 256 samples).
std::array<double, 3> ApproximatedIntegrand(const GlossyScene& s, const CubemapBlocks& blocks,
                                            const BlockLighting& light, std::size_t v,
                                            const Vec3& eye) {
  const Material& m = s.materials[s.material_index[v]];
  const ShadingFrame f = MakeShadingFrame(s.normals[v], eye - s.positions[v]);
  std::array<double, 3> out{0, 0, 0};
  uint8_t levels[256];
  for (int b = 0; b < blocks.block_count(); ++b) {
    DecodeVisibilityBlock(*s.visibility, v, b, levels);
    const int rate = BrdfSamplingRate(m, f, blocks.Centre(b));
    float spec[256], dif[256];
    if (rate <= 16) {
      const int l = rate == 1 ? 1 : (rate == 4 ? 2 : 4);
      float samples[16], coef[16];
      const float* d = blocks.SampleDirections(b, l);
      for (int i = 0; i < l * l; ++i)
        samples[i] = static_cast<float>(SpecularLobe(m, f, {d[3 * i], d[3 * i + 1], d[3 * i + 2]}));
      BlockDct::Project(l, samples, coef);
      BlockDct::Reconstruct(l, coef, spec);
      for (int i = 0; i < l * l; ++i)
        samples[i] = static_cast<float>(DiffuseLobe(f, {d[3 * i], d[3 * i + 1], d[3 * i + 2]}));
      BlockDct::Project(l, samples, coef);
      BlockDct::Reconstruct(l, coef, dif);
    }
    const float* dirs = blocks.PixelDirections(b);
    for (int k = 0; k < 256; ++k) {
      const Vec3 w{dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]};
      const double vis = levels[k] / static_cast<double>(s.visibility->max_level());
      for (int c = 0; c < 3; ++c) {
        const double rho =
            rate <= 16 ? m.diffuse[c] * dif[k] + (HasSpecular(m) ? m.specular[c] * spec[k] : 0)
                       : CosineWeightedBrdf(m, f, w, c);
        out[c] += light.Pixels(b, c)[k] * vis * rho;
      }
    }
  }
  return out;
}

struct Fixture {
  CubemapBlocks blocks{kN};
  BlockLighting light = ComputeBlockLighting(TestLight(), blocks);
  std::vector<Vec3> positions, normals;
  std::vector<uint16_t> material_index;
  std::vector<Material> materials;
  VisibilityBlocks vis;
  GlossyScene scene() const { return {positions, normals, material_index, materials, &vis}; }
};

// Visibility maps with normal +Y: `pattern` decides, per texel above the horizon, the level.
template <typename F>
std::vector<uint8_t> Map(F&& pattern) {
  const CubemapLayout layout(kN);
  std::vector<uint8_t> m(layout.texel_count());
  for (std::size_t j = 0; j < m.size(); ++j) {
    const Vec3 d = layout.TexelCenter(j);
    m[j] = d.y > 0 ? pattern(j, d) : 0;
  }
  return m;
}

Material Phong(double s) {
  Material m;
  m.model = BrdfModel::kPhong;
  m.diffuse = {0.3f, 0.35f, 0.4f};
  m.specular = {0.5f, 0.45f, 0.4f};
  m.exponent = s;
  return m;
}

// Each case of Algorithm 1 on its own, against the same integrand summed in the pixel basis,
// and against the exact pixel-basis reference.
TEST(TripleProduct, EachCaseMatchesThePixelBasis) {
  for (int bits : {1, 6}) {
    Fixture fx;
    fx.vis = MakeVisibilityBlocks(kN, bits);
    const uint8_t top = static_cast<uint8_t>((1 << bits) - 1);
    fx.materials = {Material{}, Phong(20), Phong(100), Phong(400)};
    // A shadow edge through the upper hemisphere (and, anti-aliased, a soft penumbra).
    auto edge = [&](std::size_t, const Vec3& d) -> uint8_t {
      const double t = 0.5 + 4 * (d.x + 0.3 * d.z - 0.1);
      if (bits == 1) return t > 0.5 ? top : 0;
      return static_cast<uint8_t>(std::lround(std::clamp(t, 0.0, 1.0) * top));
    };
    struct Case {
      const char* name;
      std::vector<uint8_t> map;
      uint16_t material;
    };
    const std::vector<Case> cases = {
        {"all zero", Map([](std::size_t, const Vec3&) -> uint8_t { return 0; }), 2},
        {"line 6 Lambert", Map([&](std::size_t, const Vec3&) { return top; }), 0},
        {"line 6 Phong 100", Map([&](std::size_t, const Vec3&) { return top; }), 2},
        {"line 6 Phong 400", Map([&](std::size_t, const Vec3&) { return top; }), 3},
        {"line 9 Lambert", Map(edge), 0},
        {"line 11 Phong 20", Map(edge), 1},
        {"line 11 Phong 100", Map(edge), 2},
        {"line 11 Phong 400", Map(edge), 3},
    };
    for (const Case& c : cases) {
      AppendVisibilityMap(fx.vis, c.map);
      fx.positions.push_back({0, 0, 0});
      fx.normals.push_back({0, 1, 0});
      fx.material_index.push_back(c.material);
    }
    const GlossyScene scene = fx.scene();
    const Vec3 eye = Normalize(Vec3{-0.25, 1, -0.25}) * 5.0;  // mirrors onto a block centre
    TripleProductStats all;
    for (std::size_t v = 0; v < cases.size(); ++v) {
      TripleProductStats st;
      const auto got = TripleProductVertex(scene, fx.blocks, fx.light, v, eye, &st);
      const auto want = ApproximatedIntegrand(scene, fx.blocks, fx.light, v, eye);
      const auto ref = PixelBasisReferenceVertex(scene, fx.blocks, fx.light, v, eye);
      const auto ref_skip = PixelBasisReferenceVertex(scene, fx.blocks, fx.light, v, eye, true);
      for (int ch = 0; ch < 3; ++ch) {
        EXPECT_NEAR(got[ch], want[ch], 2e-5 * std::abs(want[ch]) + 1e-6) << cases[v].name << bits;
        EXPECT_NEAR(ref_skip[ch], ref[ch], 1e-9 * std::abs(ref[ch]) + 1e-9);
        // The approximation itself stays close to the exact sum (Appendix A sampling): within 5%
        // for these cases, except Phong s = 20, whose lobe is still 16% off with 4 coefficients
        // next to a one-texel sun of 800× the sky (the paper's rule, measured here).
        const double tol = cases[v].material == 1 ? 0.2 : 0.05;
        EXPECT_NEAR(got[ch], ref[ch], tol * std::abs(ref[ch]) + 1e-6) << cases[v].name << bits;
      }
      const std::string name = cases[v].name;
      if (name == "all zero") {
        EXPECT_EQ(st.blocks_zero, static_cast<uint64_t>(fx.blocks.block_count()));
        EXPECT_EQ(got[0], 0.0);
      } else if (name.starts_with("line 6")) {
        EXPECT_GT(st.blocks_line6, 0u);
        EXPECT_EQ(st.blocks_line9 + st.blocks_line11, 0u);
      } else if (name == "line 9 Lambert") {
        EXPECT_GT(st.blocks_line9, 0u);
        EXPECT_EQ(st.blocks_line11, 0u);
      } else {
        EXPECT_GT(st.blocks_line11, 0u);
      }
      all += st;
    }
    // The 400-exponent lobe needed all 256 samples somewhere, Phong 100 needed 16.
    EXPECT_GT(all.brdf_rate[3], 0u);
    EXPECT_GT(all.brdf_rate[2], 0u);
    // The whole-scene entry point agrees with the per-vertex one and with the thread count.
    std::vector<float> rgb(cases.size() * 3), ref(cases.size() * 3);
    const TripleProductStats st = RelightTripleProduct(scene, fx.blocks, fx.light, eye, rgb);
    RelightPixelBasisReference(scene, fx.blocks, fx.light, eye, ref);
    EXPECT_EQ(st.blocks_line11, all.blocks_line11);
    for (std::size_t v = 0; v < cases.size(); ++v) {
      const auto one = TripleProductVertex(scene, fx.blocks, fx.light, v, eye);
      EXPECT_EQ(rgb[v * 3], static_cast<float>(one[0]));
      EXPECT_NEAR(ref[v * 3], PixelBasisReferenceVertex(scene, fx.blocks, fx.light, v, eye)[0],
                  1e-6 * std::abs(ref[v * 3]) + 1e-9);
    }
  }
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// With the exact-cosine option the diffuse lobe is integrated exactly in every case, so a
// Lambert scene matches the pixel-basis reference to float precision whatever the visibility.
TEST(TripleProduct, ExactCosineMakesLambertExact) {
  for (int bits : {1, 6}) {
    Fixture fx;
    fx.vis = MakeVisibilityBlocks(kN, bits);
    const uint8_t top = static_cast<uint8_t>((1 << bits) - 1);
    Material lambert;
    lambert.diffuse = {0.9f, 0.6f, 0.3f};
    fx.materials = {lambert, Phong(100)};
    std::mt19937 rng(4);
    for (int v = 0; v < 6; ++v) {
      const double a = std::uniform_real_distribution<double>(-1, 1)(rng);
      AppendVisibilityMap(fx.vis, Map([&](std::size_t j, const Vec3& d) -> uint8_t {
                            if (v == 0) return top;
                            const double t = 0.5 + 3 * (d.x * a + d.z - 0.2 * v + 0.5);
                            const auto q =
                                static_cast<uint8_t>(std::lround(std::clamp(t, 0.0, 1.0) * top));
                            return (j % 7 == 0 && v > 3) ? 0 : q;
                          }));
      fx.positions.push_back({0, 0, 0});
      fx.normals.push_back({0, 1, 0});
      fx.material_index.push_back(static_cast<uint16_t>(v == 5 ? 1 : 0));
    }
    const GlossyScene scene = fx.scene();
    const Vec3 eye = Normalize(Vec3{-0.25, 1, -0.25}) * 5.0;
    for (std::size_t v = 0; v < 5; ++v) {  // Lambert vertices
      const auto got =
          TripleProductVertex(scene, fx.blocks, fx.light, v, eye, nullptr, {.exact_cosine = true});
      const auto ref = PixelBasisReferenceVertex(scene, fx.blocks, fx.light, v, eye);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(got[c], ref[c], 1e-4 * ref[c] + 1e-6) << v << " " << bits;
    }
    // Phong: the diffuse part exact, the specular part as in the paper; still near the reference.
    const auto got =
        TripleProductVertex(scene, fx.blocks, fx.light, 5, eye, nullptr, {.exact_cosine = true});
    const auto ref = PixelBasisReferenceVertex(scene, fx.blocks, fx.light, 5, eye);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], ref[c], 0.05 * ref[c]);
  }
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// Per block and per vertex, Algorithm 1 against the pixel-basis reference with error bounds that
// follow from the approximations the rules make (L'·V ≥ 0 throughout, so a per-texel bound on the
// BRDF error times Σ_k L'[k]·V[k] bounds the block's error):
//   - zero blocks: exactly 0 on both sides;
//   - 256 samples (rate 256), and the diffuse term under exact_cosine: the same sum in float,
//     within float rounding;
//   - the diffuse lobe approximated by a constant (the paper: its value at the block centre c):
//     |max(0, n·ω) − max(0, n·c)| ≤ |ω − c| ≤ r_b, the block's chord radius, so the error is
//     ≤ k_d/π · r_b · Σ L'V; by its 4/16-coefficient interpolant (rates 4, 16): the interpolant
//     reproduces constants, so its error is ≤ (Λ_l + 1)·r_b with Λ_l the Lebesgue constant of the
//     l×l DCT interpolation (computed below from BlockDct);
//   - the Phong lobe at one sample (the rules give rate 1 only where ∠(V, R_c) ≥ π/4): every texel
//     is at least π/4 − θ_b from the mirror direction (θ_b the block's angular radius), so the lobe
//     and its constant are both ≤ (s+2)/2π · cos^s(π/4 − θ_b) and the error is ≤ k_s times that
//     times Σ L'V;
//   - the Phong lobe at 4 or 16 samples: |interpolant| ≤ Λ_l·max_i lobe(ω_i) over the samples, so
//     the error is ≤ k_s·(Λ_l·max_i lobe(ω_i) + max_k lobe(ω_k))·Σ L'V.
double Lebesgue(int l) {
  static const auto values = [] {
    std::array<double, 5> out{};
    for (int ll : {1, 2, 4}) {
      double sums[256] = {};
      for (int i = 0; i < ll * ll; ++i) {
        float samples[16] = {}, coef[16], pix[256];
        samples[i] = 1.f;
        BlockDct::Project(ll, samples, coef);
        BlockDct::Reconstruct(ll, coef, pix);
        for (int k = 0; k < 256; ++k) sums[k] += std::abs(pix[k]);
      }
      out[ll] = *std::max_element(sums, sums + 256) * (1 + 1e-5);
    }
    return out;
  }();
  return values[l];
}

struct BlockBound {
  double bound[3] = {0, 0, 0};
};

BlockBound BoundOf(const GlossyScene& s, const CubemapBlocks& blocks, const BlockLighting& light,
                   std::size_t v, const Vec3& eye, int b, const TripleProductBlockTerm& term,
                   bool exact) {
  const Material& m = s.materials[s.material_index[v]];
  const ShadingFrame f = MakeShadingFrame(s.normals[v], eye - s.positions[v]);
  uint8_t levels[256];
  DecodeVisibilityBlock(*s.visibility, v, b, levels);
  const float* dirs = blocks.PixelDirections(b);
  const Vec3 c = blocks.Centre(b);
  const int l = term.rate == 4 ? 2 : (term.rate == 16 ? 4 : 1);
  double sample_max = 0;
  const float* sd = blocks.SampleDirections(b, l);
  for (int i = 0; i < l * l; ++i)
    sample_max =
        std::max(sample_max, SpecularLobe(m, f, {sd[3 * i], sd[3 * i + 1], sd[3 * i + 2]}));
  double chord = 0, lobe_max = 0, lv[3] = {0, 0, 0}, total_abs[3] = {0, 0, 0}, all[3] = {0, 0, 0};
  for (int k = 0; k < 256; ++k) {
    const Vec3 w{dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]};
    chord = std::max(chord, Length(w - c));
    lobe_max = std::max(lobe_max, SpecularLobe(m, f, w));
    const double vis = levels[k] / static_cast<double>(s.visibility->max_level());
    for (int ch = 0; ch < 3; ++ch) {
      lv[ch] += light.Pixels(b, ch)[k] * vis;
      all[ch] += light.Pixels(b, ch)[k];
      total_abs[ch] += light.Pixels(b, ch)[k] * vis * CosineWeightedBrdf(m, f, w, ch);
    }
  }
  const double theta = 2 * std::asin(std::min(1.0, chord / 2));
  BlockBound out;
  for (int ch = 0; ch < 3; ++ch) {
    // Float rounding of sums over ≤ 256 positions (and of suffix differences).
    double bound = 4e-6 * (total_abs[ch] + m.diffuse[ch] / std::numbers::pi * all[ch]) + 1e-9;
    if (term.rate != 256) {
      if (!exact)
        bound +=
            m.diffuse[ch] / std::numbers::pi * (l == 1 ? 1.0 : Lebesgue(l) + 1) * chord * lv[ch];
      if (HasSpecular(m)) {
        const double lobe_bound =
            term.rate == 1
                ? (m.exponent + 2) / (2 * std::numbers::pi) *
                      std::pow(std::cos(std::max(0.0, std::numbers::pi / 4 - theta)), m.exponent)
                : 1.25 * lobe_max;
        bound += m.specular[ch] * lobe_bound * lv[ch];
      }
    }
    out.bound[ch] = bound;
  }
  return out;
}

// `count` vertices with random normals (tilted up to `tilt` from +Y), each map a random straight
// shadow edge through the upper hemisphere (anti-aliased when bits > 1) under the horizon mask of
// traced maps; materials cycle through fx.materials; positions at the origin or, with
// `jitter`, scattered by up to 0.1 on the ground plane.
void AddShadowEdgeVertices(Fixture& fx, int bits, int count, double tilt, bool jitter,
                           std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  const uint8_t top = static_cast<uint8_t>((1 << bits) - 1);
  const CubemapLayout layout(kN);
  for (int v = 0; v < count; ++v) {
    const Vec3 normal = Normalize(Vec3{tilt * u(rng), 1, tilt * u(rng)});
    const Vec3 edge = Normalize(Vec3{u(rng), 0.3 * u(rng), u(rng)});
    const double offset = 0.3 * u(rng);
    std::vector<uint8_t> map(layout.texel_count());
    for (std::size_t j = 0; j < map.size(); ++j) {
      const Vec3 d = layout.TexelCenter(j);
      if (Dot(d, normal) <= 0) continue;  // the horizon mask of traced maps
      const double t = 0.5 + 6 * (Dot(d, edge) - offset);
      map[j] = bits == 1 ? (t > 0.5 ? top : 0)
                         : static_cast<uint8_t>(std::lround(std::clamp(t, 0.0, 1.0) * top));
    }
    AppendVisibilityMap(fx.vis, map);
    fx.positions.push_back(jitter ? Vec3{0.1 * u(rng), 0, 0.1 * u(rng)} : Vec3{0, 0, 0});
    fx.normals.push_back(normal);
    fx.material_index.push_back(static_cast<uint16_t>(v % fx.materials.size()));
  }
}

TEST(TripleProduct, EveryBlockWithinTheBoundOfItsCase) {
  for (int bits : {1, 6}) {
    Fixture fx;
    fx.vis = MakeVisibilityBlocks(kN, bits);
    Material lambert;
    lambert.diffuse = {0.9f, 0.6f, 0.3f};
    fx.materials = {lambert, Phong(10), Phong(60), Phong(200), Phong(400)};
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-1, 1);
    AddShadowEdgeVertices(fx, bits, 20, 0.4, false, rng);
    const GlossyScene scene = fx.scene();
    std::vector<TripleProductBlockTerm> terms(fx.blocks.block_count());
    std::vector<std::array<double, 3>> ref(fx.blocks.block_count());
    uint64_t seen[4][5] = {};  // [line 1/6/9/11][rate 0/1/4/16/256]
    for (const bool exact : {false, true}) {
      for (std::size_t v = 0; v < fx.positions.size(); ++v) {
        const Vec3 eye = Normalize(Vec3{u(rng), 1, u(rng)}) * 5.0;
        TripleProductVertexBlocks(scene, fx.blocks, fx.light, v, eye, terms,
                                  {.exact_cosine = exact});
        PixelBasisReferenceVertexBlocks(scene, fx.blocks, fx.light, v, eye, ref);
        double sum[3] = {0, 0, 0}, ref_sum[3] = {0, 0, 0}, bound_sum[3] = {0, 0, 0};
        for (int b = 0; b < fx.blocks.block_count(); ++b) {
          const TripleProductBlockTerm& t = terms[b];
          const int li = t.line == TripleProductCase::kZero
                             ? 0
                             : (t.line == TripleProductCase::kLine6
                                    ? 1
                                    : (t.line == TripleProductCase::kLine9 ? 2 : 3));
          const int ri =
              t.rate == 0 ? 0 : (t.rate == 1 ? 1 : (t.rate == 4 ? 2 : (t.rate == 16 ? 3 : 4)));
          ++seen[li][ri];
          if (t.line == TripleProductCase::kZero) {
            for (int c = 0; c < 3; ++c) {
              EXPECT_EQ(t.rgb[c], 0.f);
              EXPECT_EQ(ref[b][c], 0.0);
            }
            continue;
          }
          const BlockBound bb = BoundOf(scene, fx.blocks, fx.light, v, eye, b, t, exact);
          for (int c = 0; c < 3; ++c) {
            EXPECT_LE(std::abs(t.rgb[c] - ref[b][c]), bb.bound[c])
                << "vertex " << v << " block " << b << " line " << static_cast<int>(t.line)
                << " rate " << t.rate << " bits " << bits << " exact " << exact;
            sum[c] += t.rgb[c];
            ref_sum[c] += ref[b][c];
            bound_sum[c] += bb.bound[c];
          }
        }
        // Per vertex: the blocks add up to the block-by-block kernel and the reference, and the
        // vertex's error is within the sum of its blocks' bounds.
        const auto whole = TripleProductVertex(scene, fx.blocks, fx.light, v, eye, nullptr,
                                               {.exact_cosine = exact, .generic = true});
        const auto whole_ref = PixelBasisReferenceVertex(scene, fx.blocks, fx.light, v, eye);
        for (int c = 0; c < 3; ++c) {
          EXPECT_NEAR(whole[c], std::max(0.0, sum[c]), 1e-9 + 1e-9 * std::abs(sum[c]));
          EXPECT_NEAR(whole_ref[c], ref_sum[c], 1e-9 + 1e-9 * std::abs(ref_sum[c]));
          EXPECT_LE(std::abs(whole[c] - whole_ref[c]), bound_sum[c]) << v << " " << exact;
        }
        // The optimised kernel with every combination of its speedups (issue 41) is the same
        // Algorithm 1 in float: within float rounding of the block-by-block kernel (a lobe
        // value to ~1e-6 relative; a block whose rate test sits within rounding of a threshold
        // may take the neighbouring rate, which the case bounds still cover), with the same
        // block counts.
        TripleProductStats st_generic;
        TripleProductVertex(scene, fx.blocks, fx.light, v, eye, &st_generic,
                            {.exact_cosine = exact, .generic = true});
        for (uint32_t off = 0; off <= kAllSpeedups; ++off) {
          TripleProductStats st_fast;
          const auto fast = TripleProductVertex(scene, fx.blocks, fx.light, v, eye, &st_fast,
                                                {.exact_cosine = exact, .disable = off});
          EXPECT_EQ(st_fast.blocks_zero, st_generic.blocks_zero);
          EXPECT_EQ(st_fast.blocks_line6, st_generic.blocks_line6);
          EXPECT_EQ(st_fast.blocks_line9 + st_fast.blocks_line11,
                    st_generic.blocks_line9 + st_generic.blocks_line11);
          for (int c = 0; c < 3; ++c) {
            EXPECT_NEAR(fast[c], whole[c], 1e-6 + 2e-5 * std::abs(whole[c]))
                << "vertex " << v << " speedups off " << off << " exact " << exact;
            EXPECT_LE(std::abs(fast[c] - whole_ref[c]), bound_sum[c] * 1.001 + 1e-7);
          }
        }
      }
    }
    // Every case and rate was exercised.
    EXPECT_GT(seen[0][0], 0u);
    EXPECT_GT(seen[1][1], 0u);
    EXPECT_GT(seen[1][2] + seen[1][3], 0u);
    EXPECT_GT(seen[1][4], 0u);
    EXPECT_GT(seen[2][1], 0u);
    EXPECT_GT(seen[3][2], 0u);
    EXPECT_GT(seen[3][3], 0u);
    EXPECT_GT(seen[3][4], 0u);
  }
}

// The optimised kernel (issue 41: TripleProductSpeedup) against the block-by-block kernel for
// every material model, random normals and eyes (grazing and below-the-horizon views included),
// 1-bit and 6-bit maps, both diffuse terms and every combination of its speedups: the same
// Algorithm 1 to float rounding (lobes in float with FastPowUnit: ~1e-6 relative per value), the
// same block counts, and RelightTripleProductRange equal to the whole frame's vertices.
TEST(TripleProduct, OptimisedKernelIsTheBlockByBlockKernel) {
  Material lambert;
  Material as_a;
  as_a.model = BrdfModel::kAshikhminShirley;
  as_a.diffuse = {0.2f, 0.3f, 0.25f};
  as_a.specular = {0.5f, 0.4f, 0.3f};
  as_a.exponent = 10;
  as_a.exponent_v = 200;
  Material as_b = as_a;
  as_b.exponent = 200;
  as_b.exponent_v = 20;
  for (int bits : {1, 6}) {
    Fixture fx;
    fx.vis = MakeVisibilityBlocks(kN, bits);
    fx.materials = {lambert, Phong(10), Phong(100), Phong(400), as_a, as_b};
    std::mt19937 rng(29 + bits);
    std::uniform_real_distribution<double> u(-1, 1);
    AddShadowEdgeVertices(fx, bits, 36, 0.6, true, rng);
    const GlossyScene scene = fx.scene();
    for (const bool exact : {false, true}) {
      for (int trial = 0; trial < 3; ++trial) {
        // trial 2 looks from just below the ground's horizon.
        const Vec3 eye = trial < 2 ? Normalize(Vec3{u(rng), trial == 0 ? 1.0 : 0.15, u(rng)}) * 5.0
                                   : Vec3{3, -0.05, 1};
        std::vector<float> generic(fx.positions.size() * 3);
        const TripleProductStats sg = RelightTripleProduct(
            scene, fx.blocks, fx.light, eye, generic, {.exact_cosine = exact, .generic = true});
        for (uint32_t off = 0; off <= kAllSpeedups; ++off) {
          std::vector<float> fast(generic.size());
          const TripleProductStats sf = RelightTripleProduct(
              scene, fx.blocks, fx.light, eye, fast, {.exact_cosine = exact, .disable = off});
          EXPECT_EQ(sf.blocks_zero, sg.blocks_zero);
          EXPECT_EQ(sf.blocks_line6, sg.blocks_line6);
          EXPECT_EQ(sf.blocks_line9 + sf.blocks_line11, sg.blocks_line9 + sg.blocks_line11);
          float peak = 0;
          for (float x : generic) peak = std::max(peak, x);
          for (std::size_t i = 0; i < fast.size(); ++i)
            ASSERT_NEAR(fast[i], generic[i], 1e-6 * peak + 2e-5 * std::abs(generic[i]))
                << "vertex " << i / 3 << " (material " << fx.material_index[i / 3]
                << ") speedups off " << off << " exact " << exact << " bits " << bits;
        }
        // A range is the whole frame's vertices.
        std::vector<float> whole(generic.size()), part(3 * 7);
        RelightTripleProduct(scene, fx.blocks, fx.light, eye, whole, {.exact_cosine = exact});
        RelightTripleProductRange(scene, fx.blocks, fx.light, eye, 11, 7, part,
                                  {.exact_cosine = exact});
        for (std::size_t i = 0; i < part.size(); ++i) EXPECT_EQ(part[i], whole[33 + i]);
      }
    }
  }
}

}  // namespace
}  // namespace prt
