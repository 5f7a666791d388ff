// The lighting of triple-product relighting in the three per-block representations of Inger,
// Farbman & Lischinski 2013, §4.3, recomputed whenever the environment changes:
//   (i)   16 DCT coefficients of each 16×16 block (BlockDct, u, v < 4), for Algorithm 1 line 6;
//   (ii)  the block's row-concatenated vector L projected onto the 1D integral basis,
//         L_int = D^{−T} L (Eq. 6): suffix sums L_int[k] = Σ_{m ≥ k} L[m], with L_int[256] = 0,
//         so that Σ_k L[k]·V[k] = Σ_k L_int[k]·V_d[k] (line 9) and Σ_{a ≤ k < b} L[k] =
//         L_int[a] − L_int[b];
//   (iii) the pixels themselves, row-concatenated (line 11).
// An extension beyond the paper (used when TripleProductOptions::exact_cosine is set):
//   (iv)  suffix sums of the vector L'[k]·ω_k (ω_k the texel-centre direction), so that the
//         diffuse cosine, which is linear in ω above the horizon, is integrated exactly against
//         any visibility: Σ_k L'[k]·V[k]·(n·ω_k) = n · Σ_i V_d[i]·Lω_int[i].
// (ii) and (iv) are also kept interleaved (SuffixRgbXyz): one 64-byte line per block position
// holding all twelve suffix sums, so that a visibility change costs one cache line for all
// three channels and both the constant and the exact cosine (Algorithm 1 lines 6, 9, 11).
// §4: "to account for the fact that not all cubemap pixels correspond to the same solid angle,
// we first scale the incident radiance at each pixel by a suitable correction factor": every
// representation holds L'[k] = L_k · Ω_k, the texel's average radiance times its exact solid
// angle, so Σ_k L'[k]·V[k]·ρ̃(ω_k) is the pixel-basis estimate of ∫ L V ρ̃ dω (Eq. 2).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "vocabulary/cubemap.h"
#include "vocabulary/envmap.h"
#include "vocabulary/vec3.h"

namespace prt {

// Geometry of the 16×16 blocks of a resolution-n cubemap (block numbering of
// formats/visibility_blocks.h): texel indices, texel-centre directions, solid angles, block
// centres and the sample directions of Eq. 4.
class CubemapBlocks {
 public:
  // n: a multiple of 16 in [16, 256] (std::invalid_argument otherwise).
  explicit CubemapBlocks(int n);

  int n() const { return n_; }
  int block_count() const { return blocks_; }
  std::size_t Texel(int block, int k) const {
    return texel_[static_cast<std::size_t>(block) * 256 + k];
  }
  // Unit direction through the continuous centre of the block.
  const Vec3& Centre(int block) const { return centre_[block]; }
  // The same as floats, one array per coordinate (block_count() values each).
  const float* CentreX() const { return centre_xyz_.data(); }
  const float* CentreY() const { return centre_xyz_.data() + blocks_; }
  const float* CentreZ() const {
    return centre_xyz_.data() + 2 * static_cast<std::size_t>(blocks_);
  }
  // 256 unit texel-centre directions of the block, 3 floats each (x, y, z), position order.
  const float* PixelDirections(int block) const {
    return &pixel_dir_[static_cast<std::size_t>(block) * 768];
  }
  // l×l unit directions (l = 1, 2, 4) at BlockDct::SamplePosition, index j·l + i, 3 floats each.
  const float* SampleDirections(int block, int l) const;
  // The 21 sample directions of SampleDirections (l = 1 at 0, 2×2 at 1, 4×4 at 5) as three
  // arrays of 24 floats (x, then y, then z; the last 3 of each are 0), for vector loads.
  const float* SampleSoA(int block) const {
    return &sample_soa_[static_cast<std::size_t>(block) * 72];
  }
  // Exact solid angle of position k of the block.
  float SolidAngle(int block, int k) const {
    return solid_angle_[static_cast<std::size_t>(block) * 256 + k];
  }

 private:
  int n_, blocks_;
  std::vector<uint32_t> texel_;
  std::vector<Vec3> centre_;
  std::vector<float> centre_xyz_;
  std::vector<float> sample_soa_;  // blocks × 72  // x of every block, then y, then z
  std::vector<float> pixel_dir_;   // blocks × 256 × 3
  std::vector<float> sample_dir_;  // blocks × 21 × 3 (l = 1, then 2×2, then 4×4)
  std::vector<float> solid_angle_;
};

struct BlockLighting {
  int n = 0;
  int block_count = 0;
  // Entry (block, channel) = block·3 + channel.
  std::vector<float> dct;         // entries × 16   (i)
  std::vector<float> suffix;      // entries × 257  (ii), L_int[256] = 0
  std::vector<float> pixels;      // entries × 256  (iii)
  std::vector<float> suffix_vec;  // entries × 257 × 3  (iv), (x, y, z) per position
  // (ii) and (iv) interleaved: blocks × 257 positions, one 64-byte aligned line each:
  //   [L_r, L_g, L_b, 0, Lx_r, Lx_g, Lx_b, 0, Ly_r, Ly_g, Ly_b, 0, Lz_r, Lz_g, Lz_b, 0]
  struct alignas(64) SuffixLine {
    float v[16];
  };
  static_assert(sizeof(SuffixLine) == 16 * sizeof(float));
  // The lines in use start suffix_offset lines into the vector, at a 2 MiB boundary advised
  // for a transparent huge page (vocabulary/huge_pages.h): a vertex reads lines of ~30 blocks
  // 16 KiB apart, which in 4 KiB pages costs a TLB miss per block (issue 41).
  std::vector<SuffixLine> suffix_rgbxyz;
  std::size_t suffix_offset = 0;
  static constexpr int kRgbXyzStride = 16;  // floats from one position to the next
  const float* SuffixRgbXyz(int block) const {
    // The lines are contiguous floats (sizeof(SuffixLine) == 16 floats).
    return reinterpret_cast<const float*>(suffix_rgbxyz.data() + suffix_offset +
                                          static_cast<std::size_t>(block) * 257);
  }
  const float* SuffixVec(int block, int c) const {
    return &suffix_vec[(static_cast<std::size_t>(block) * 3 + c) * 257 * 3];
  }
  const float* Dct(int block, int c) const {
    return &dct[(static_cast<std::size_t>(block) * 3 + c) * 16];
  }
  const float* Suffix(int block, int c) const {
    return &suffix[(static_cast<std::size_t>(block) * 3 + c) * 257];
  }
  const float* Pixels(int block, int c) const {
    return &pixels[(static_cast<std::size_t>(block) * 3 + c) * 256];
  }
};

// All three representations of `light` (its n must equal blocks.n(), std::invalid_argument
// otherwise). Sums run in double. Parallel over blocks (TBB); deterministic.
BlockLighting ComputeBlockLighting(const CubemapRgb& light, const CubemapBlocks& blocks);
// The same into existing storage (no allocation when the sizes already match): call it when
// the environment changes.
void UpdateBlockLighting(const CubemapRgb& light, const CubemapBlocks& blocks, BlockLighting& out);

}  // namespace prt
