// Per-block triple products for glossy relighting under changing view and lighting (Inger,
// Farbman & Lischinski 2013, Algorithm 1, §4.1–4.4), and the pixel-basis reference it is
// measured against.
//
// Outgoing radiance of a vertex x towards the eye e, per channel c (Eq. 1–2, pixel basis):
//   B_c = Σ_k L'_c[k] · V[k] · ρ̃_c(ω_k),   ω_o = normalize(e − x),
// L' = radiance × texel solid angle (block_lighting.h), V the vertex's visibility level / (2^bits
// − 1) (visibility_blocks.h), ρ̃ the cosine-weighted BRDF (brdf.h) at texel centres.
// Algorithm 1 splits the sum into 16×16 blocks and per block:
//   line 1   visibility all zero                          → 0, nothing sampled
//   line 6   visibility all one                           → Σ_uv A_uv L_uv over the BRDF's
//            1/4/16 DCT coefficients A (or Σ_k L'[k] ρ̃[k] when it needs all 256 samples)
//   line 9   visibility mixed, BRDF one coefficient ρ̃₁    → ρ̃₁ · Σ_i V_d[i] · L_int[i] over the
//            stored changes (Eq. 5–6)
//   line 11  visibility mixed, BRDF 4/16/256 samples      → pixel basis over the visible runs
//            of V (§4.4), the BRDF reconstructed from its DCT coefficients or sampled per pixel.
// Per-block products run in float; block sums accumulate in double. Vertices run in parallel
// (TBB); results do not depend on the thread count. A block product or a vertex's radiance that
// is not a finite float (finite lighting and BRDF values whose product overflows float) throws
// NumericalError naming the vertex (and the block where known); nothing is replaced by 0.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "formats/visibility_blocks.h"
#include "runtime/block_lighting.h"
#include "runtime/brdf.h"

namespace prt {

// The optimisations of the per-frame kernel (issue 41; docs/viewer.md, "Triple products: where a
// frame goes"). Each is a flag of TripleProductOptions::disable, so that a benchmark measures what
// each one pays on its own; every combination computes Algorithm 1 with the same cases, sampling
// rates and DCT projections (results agree to float rounding, triple_product_test).
enum TripleProductSpeedup : uint32_t {
  // The vertex's set-up for all its non-zero blocks at once (listed from its kind bytes): the
  // sampling rate and the lobes at the block centres in float, instead of per block in double.
  kSpeedupVertexSetup = 1u << 0,
  // Lobe powers x^s as exp2(s·log2 x) by polynomials (FastPowUnit) instead of std::pow.
  kSpeedupFastPow = 1u << 1,
  // The specular lobe at 8 directions per AVX2 instruction (block centres, the 4 and 16 samples
  // of Eq. 4), chosen at run time where the CPU has AVX2 and FMA.
  kSpeedupSimdLobes = 1u << 2,
  // Line 9's Σ V_d·L_int over the changes, and line 11's visible runs, with AVX2 (two 8-float
  // registers per 64-byte suffix line).
  kSpeedupSimdChanges = 1u << 3,
  // The next vertices' visibility (kind bytes, change offsets, change positions) prefetched
  // while this vertex runs.
  kSpeedupPrefetch = 1u << 4,
  // With the exact cosine on 1-bit maps (AVX2): the rate-1 blocks of lines 6 and 9 add their
  // suffix lines into running sums for the whole vertex, its share taken once at the end,
  // instead of a product per block.
  kSpeedupVertexSums = 1u << 5,
  kAllSpeedups = (1u << 6) - 1,
};
// A short name of one speedup bit ("vertex set-up", ...).
const char* TripleProductSpeedupName(uint32_t bit);

struct TripleProductOptions {
  // false: the paper — the diffuse lobe is one DCT coefficient (its value at the block centre)
  // in every block. true: the diffuse cosine is integrated exactly in lines 6, 9 and 11 through
  // the vector suffix sums of block_lighting.h (iv) (the cosine is linear in ω wherever V > 0,
  // since visibility is 0 below the horizon); the specular lobe is treated as in the paper.
  bool exact_cosine = false;
  // Appendix A samples the specular lobe at all 256 texels within π/8 of the mirror direction
  // from this exponent on, at 16 below it (the paper: 250).
  double full_rate_exponent = 250.0;
  // The speedups (TripleProductSpeedup bits) turned off. generic = true runs the block-by-block
  // code TripleProductVertexBlocks also runs (the kernel before issue 41), whatever `disable`.
  uint32_t disable = 0;
  bool generic = false;
};

// The case of Algorithm 1 a block took (its line in the pseudocode; kZero is line 1).
enum class TripleProductCase : uint8_t { kZero = 1, kLine6 = 6, kLine9 = 9, kLine11 = 11 };

// One block's share of a vertex's radiance (TripleProductVertexBlocks).
struct TripleProductBlockTerm {
  TripleProductCase line = TripleProductCase::kZero;
  uint16_t rate = 0;           // BRDF samples: 1, 4, 16 or 256; 0 in zero blocks
  std::array<float, 3> rgb{};  // the block's contribution to B
};

// What Algorithm 1 did (Tables 1 and 2 of the paper).
struct TripleProductStats {
  uint64_t blocks_zero = 0;              // line 1
  uint64_t blocks_line6 = 0;             // visibility all one
  uint64_t blocks_line9 = 0;             // mixed visibility, constant BRDF
  uint64_t blocks_line11 = 0;            // mixed visibility, non-constant BRDF
  uint64_t brdf_rate[4] = {0, 0, 0, 0};  // BRDF sampled 1, 4, 16, 256 times (non-zero blocks)
  TripleProductStats& operator+=(const TripleProductStats& o);
};

// The scene as Algorithm 1 sees it: per vertex a position, a unit normal (the normal the
// visibility was traced with), a material index, and its visibility maps.
struct GlossyScene {
  std::span<const Vec3> positions;
  std::span<const Vec3> normals;
  std::span<const uint16_t> material_index;
  std::span<const Material> materials;
  const VisibilityBlocks* visibility = nullptr;
};

// Algorithm 1 for one vertex seen from `eye`; adds to *stats when not null.
std::array<double, 3> TripleProductVertex(const GlossyScene& scene, const CubemapBlocks& blocks,
                                          const BlockLighting& light, std::size_t vertex,
                                          const Vec3& eye, TripleProductStats* stats = nullptr,
                                          const TripleProductOptions& options = {});
// The same, block by block: out[b] is block b's case, BRDF rate and contribution (their sum is
// TripleProductVertex before its clamp at 0). out.size() must be blocks.block_count().
void TripleProductVertexBlocks(const GlossyScene& scene, const CubemapBlocks& blocks,
                               const BlockLighting& light, std::size_t vertex, const Vec3& eye,
                               std::span<TripleProductBlockTerm> out,
                               const TripleProductOptions& options = {});
// Every vertex (3 floats each into out_rgb), parallel over vertices. Throws
// std::invalid_argument when sizes disagree (vertex counts, n, material indices).
TripleProductStats RelightTripleProduct(const GlossyScene& scene, const CubemapBlocks& blocks,
                                        const BlockLighting& light, const Vec3& eye,
                                        std::span<float> out_rgb,
                                        const TripleProductOptions& options = {});

// Vertices [first, first + count) only, into out_rgb (3·count floats): the same values as
// RelightTripleProduct gives those vertices (a host splitting a frame between its threads).
TripleProductStats RelightTripleProductRange(const GlossyScene& scene, const CubemapBlocks& blocks,
                                             const BlockLighting& light, const Vec3& eye,
                                             std::size_t first, std::size_t count,
                                             std::span<float> out_rgb,
                                             const TripleProductOptions& options = {});

// The reference: the same sum in the pixel basis over all 6·n·n texels (the BRDF evaluated at
// every texel centre, the visibility decoded to pixels). skip_occluded evaluates the BRDF only
// where V > 0 (a cheaper reference; the paper's baseline is the full sum).
std::array<double, 3> PixelBasisReferenceVertex(const GlossyScene& scene,
                                                const CubemapBlocks& blocks,
                                                const BlockLighting& light, std::size_t vertex,
                                                const Vec3& eye, bool skip_occluded = false);
// The reference block by block (out.size() == blocks.block_count()).
void PixelBasisReferenceVertexBlocks(const GlossyScene& scene, const CubemapBlocks& blocks,
                                     const BlockLighting& light, std::size_t vertex,
                                     const Vec3& eye, std::span<std::array<double, 3>> out);
void RelightPixelBasisReference(const GlossyScene& scene, const CubemapBlocks& blocks,
                                const BlockLighting& light, const Vec3& eye,
                                std::span<float> out_rgb, bool skip_occluded = false);

}  // namespace prt
