#include "runtime/block_lighting.h"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

#include "runtime/brdf.h"
#include "vocabulary/huge_pages.h"
#include "vocabulary/parallel.h"

namespace prt {

CubemapBlocks::CubemapBlocks(int n) : n_(n) {
  if (n < 16 || n > 256 || n % 16 != 0)
    throw std::invalid_argument("CubemapBlocks: n must be a multiple of 16 in [16, 256]");
  const CubemapLayout layout(n);
  const int side = n / 16;
  blocks_ = 6 * side * side;
  texel_.resize(static_cast<std::size_t>(blocks_) * 256);
  solid_angle_.resize(texel_.size());
  pixel_dir_.resize(texel_.size() * 3);
  sample_dir_.resize(static_cast<std::size_t>(blocks_) * 21 * 3);
  centre_.resize(blocks_);
  for (int b = 0; b < blocks_; ++b) {
    const int face = b / (side * side), rem = b % (side * side);
    const int by = rem / side, bx = rem % side;
    auto direction = [&](double px, double py) {  // continuous pixel position in the block
      const double u = -1.0 + 2.0 * (bx * 16 + px + 0.5) / n;
      const double v = -1.0 + 2.0 * (by * 16 + py + 0.5) / n;
      return CubemapLayout::FaceDirection(face, u, v);
    };
    for (int k = 0; k < 256; ++k) {
      const std::size_t j = layout.Index(face, bx * 16 + (k & 15), by * 16 + (k >> 4));
      const std::size_t e = static_cast<std::size_t>(b) * 256 + k;
      texel_[e] = static_cast<uint32_t>(j);
      solid_angle_[e] = static_cast<float>(layout.TexelSolidAngle(j));
      const Vec3 d = layout.TexelCenter(j);
      pixel_dir_[e * 3] = static_cast<float>(d.x);
      pixel_dir_[e * 3 + 1] = static_cast<float>(d.y);
      pixel_dir_[e * 3 + 2] = static_cast<float>(d.z);
    }
    centre_[b] = direction(7.5, 7.5);
    int s = 0;
    for (int l : {1, 2, 4})
      for (int j = 0; j < l; ++j)
        for (int i = 0; i < l; ++i, ++s) {
          const Vec3 d = direction(BlockDct::SamplePosition(l, i), BlockDct::SamplePosition(l, j));
          float* out = &sample_dir_[(static_cast<std::size_t>(b) * 21 + s) * 3];
          out[0] = static_cast<float>(d.x);
          out[1] = static_cast<float>(d.y);
          out[2] = static_cast<float>(d.z);
        }
  }
  sample_soa_.assign(static_cast<std::size_t>(blocks_) * 72, 0.f);
  for (int b = 0; b < blocks_; ++b)
    for (int i = 0; i < 21; ++i)
      for (int c = 0; c < 3; ++c)
        sample_soa_[static_cast<std::size_t>(b) * 72 + c * 24 + i] =
            sample_dir_[(static_cast<std::size_t>(b) * 21 + i) * 3 + c];
  centre_xyz_.resize(static_cast<std::size_t>(blocks_) * 3);
  for (int b = 0; b < blocks_; ++b) {
    centre_xyz_[b] = static_cast<float>(centre_[b].x);
    centre_xyz_[blocks_ + b] = static_cast<float>(centre_[b].y);
    centre_xyz_[2 * static_cast<std::size_t>(blocks_) + b] = static_cast<float>(centre_[b].z);
  }
}

const float* CubemapBlocks::SampleDirections(int block, int l) const {
  const int offset = l == 1 ? 0 : (l == 2 ? 1 : 5);
  return &sample_dir_[(static_cast<std::size_t>(block) * 21 + offset) * 3];
}

// §4.3: the three lighting representations of each block.
void UpdateBlockLighting(const CubemapRgb& light, const CubemapBlocks& blocks, BlockLighting& out) {
  if (light.n != blocks.n() || light.r.size() != light.TexelCount() ||
      light.g.size() != light.TexelCount() || light.b.size() != light.TexelCount())
    throw std::invalid_argument("UpdateBlockLighting: lighting cubemap does not match the blocks");
  const std::size_t entries = static_cast<std::size_t>(blocks.block_count()) * 3;
  out.n = blocks.n();
  out.block_count = blocks.block_count();
  out.dct.resize(entries * 16);
  out.suffix.resize(entries * 257);
  out.pixels.resize(entries * 256);
  out.suffix_vec.resize(entries * 257 * 3);
  const std::size_t lines = static_cast<std::size_t>(blocks.block_count()) * 257;
  constexpr std::size_t kHuge = std::size_t{2} << 20;
  constexpr std::size_t kHugeLines = kHuge / sizeof(BlockLighting::SuffixLine);
  if (out.suffix_rgbxyz.size() != lines + kHugeLines) {
    ReserveFreshHuge(out.suffix_rgbxyz, lines + kHugeLines);
    out.suffix_rgbxyz.resize(lines + kHugeLines);
    const auto addr = reinterpret_cast<std::uintptr_t>(out.suffix_rgbxyz.data());
    out.suffix_offset = ((kHuge - addr % kHuge) % kHuge) / sizeof(BlockLighting::SuffixLine);
  }
  std::fill_n(out.suffix_rgbxyz.begin() + static_cast<std::ptrdiff_t>(out.suffix_offset), lines,
              BlockLighting::SuffixLine{});
  ParallelFor(static_cast<std::size_t>(blocks.block_count()), [&](std::size_t bi) {
    const int b = static_cast<int>(bi);
    for (int c = 0; c < 3; ++c) {
      const std::vector<float>& ch = light.Channel(c);
      const std::size_t e = static_cast<std::size_t>(b) * 3 + c;
      float* px = &out.pixels[e * 256];
      for (int k = 0; k < 256; ++k)
        px[k] = static_cast<float>(static_cast<double>(ch[blocks.Texel(b, k)]) *
                                   blocks.SolidAngle(b, k));
      float* suffix = &out.suffix[e * 257];
      double acc = 0;
      suffix[256] = 0.f;
      for (int k = 255; k >= 0; --k) {
        acc += px[k];
        suffix[k] = static_cast<float>(acc);
      }
      BlockDct::Forward16(px, &out.dct[e * 16]);
      float* sv = &out.suffix_vec[e * 257 * 3];
      const float* dirs = blocks.PixelDirections(b);
      double vx = 0, vy = 0, vz = 0;
      sv[256 * 3] = sv[256 * 3 + 1] = sv[256 * 3 + 2] = 0.f;
      for (int k = 255; k >= 0; --k) {
        vx += static_cast<double>(px[k]) * dirs[3 * k];
        vy += static_cast<double>(px[k]) * dirs[3 * k + 1];
        vz += static_cast<double>(px[k]) * dirs[3 * k + 2];
        sv[3 * k] = static_cast<float>(vx);
        sv[3 * k + 1] = static_cast<float>(vy);
        sv[3 * k + 2] = static_cast<float>(vz);
      }
    }
    float* q = reinterpret_cast<float*>(out.suffix_rgbxyz.data() + out.suffix_offset +
                                        static_cast<std::size_t>(b) * 257);
    for (int c = 0; c < 3; ++c) {
      const std::size_t e = static_cast<std::size_t>(b) * 3 + c;
      const float* suffix = &out.suffix[e * 257];
      const float* sv = &out.suffix_vec[e * 257 * 3];
      for (int k = 0; k <= 256; ++k) {
        q[k * 16 + c] = suffix[k];
        for (int a = 0; a < 3; ++a) q[k * 16 + 4 * (a + 1) + c] = sv[3 * k + a];
      }
    }
  });
}

BlockLighting ComputeBlockLighting(const CubemapRgb& light, const CubemapBlocks& blocks) {
  BlockLighting out;
  UpdateBlockLighting(light, blocks, out);
  return out;
}

}  // namespace prt
