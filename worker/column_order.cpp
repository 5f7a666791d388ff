// Hilbert order of mesh vertices and the spatial domain of a scene (docs/compression.md).
#include "worker/column_order.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace prt {

// Skilling 2004: transform axes to the "transposed" Hilbert index, then interleave its bits
// (most significant first, axis 0 first), in any number of dimensions.
uint64_t HilbertIndex(std::span<const uint32_t> axes, int bits) {
  const std::size_t n = axes.size();
  if (n < 1 || n > 8 || bits < 1 || static_cast<std::size_t>(bits) * n > 64)
    throw std::invalid_argument("HilbertIndex: need 1-8 axes and bits·axes <= 64");
  uint32_t X[8];
  std::copy(axes.begin(), axes.end(), X);
  const uint32_t M = 1u << (bits - 1);
  for (uint32_t Q = M; Q > 1; Q >>= 1) {  // inverse undo
    const uint32_t P = Q - 1;
    for (std::size_t i = 0; i < n; ++i) {
      if (X[i] & Q) {
        X[0] ^= P;
      } else {
        const uint32_t t = (X[0] ^ X[i]) & P;
        X[0] ^= t;
        X[i] ^= t;
      }
    }
  }
  for (std::size_t i = 1; i < n; ++i) X[i] ^= X[i - 1];  // Gray encode
  uint32_t t = 0;
  for (uint32_t Q = M; Q > 1; Q >>= 1)
    if (X[n - 1] & Q) t ^= Q - 1;
  for (std::size_t i = 0; i < n; ++i) X[i] ^= t;
  uint64_t h = 0;
  for (int b = bits - 1; b >= 0; --b)
    for (std::size_t i = 0; i < n; ++i) h = (h << 1) | ((X[i] >> b) & 1u);
  return h;
}

uint64_t HilbertIndex3D(uint32_t x, uint32_t y, uint32_t z, int bits) {
  if (bits < 1 || bits > 21) throw std::invalid_argument("HilbertIndex3D: bits not in [1,21]");
  const uint32_t axes[3] = {x, y, z};
  return HilbertIndex(axes, bits);
}

std::vector<uint32_t> HilbertOrder(std::span<const Vec3> positions, int bits) {
  return HilbertOrder(positions, {}, 0.0, bits);
}

std::vector<uint32_t> HilbertOrder(std::span<const Vec3> positions, std::span<const Vec3> normals,
                                   double normal_weight, int bits) {
  const std::size_t n = positions.size();
  const bool six = normal_weight > 0;
  if (six && normals.size() != n)
    throw std::invalid_argument("HilbertOrder: one normal per position needed");
  if (six) bits = std::min(bits, 10);  // 6 axes × 10 bits fill a 64-bit key
  std::vector<uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  if (n < 2) return order;
  Vec3 lo = positions[0], hi = positions[0];
  for (const Vec3& p : positions) {
    if (!IsFinite(p)) throw std::invalid_argument("HilbertOrder: non-finite position");
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  // One scale for all axes keeps the curve's cells cubes; a normal's axes span normal_weight
  // times the largest extent (normal_weight 1: opposite normals as far apart as the whole box).
  const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  const double span = six ? std::max(extent, normal_weight * extent) : extent;
  const double cells = static_cast<double>((1u << bits) - 1);
  const double s = span > 0 ? cells / span : 0.0;
  auto q = [&](double v, double o) {
    return static_cast<uint32_t>(std::clamp(std::floor((v - o) * s + 0.5), 0.0, cells));
  };
  const double nscale = 0.5 * normal_weight * extent;  // component −1…1 → 0…w·extent
  std::vector<uint64_t> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3& p = positions[i];
    if (!six) {
      key[i] = HilbertIndex3D(q(p.x, lo.x), q(p.y, lo.y), q(p.z, lo.z), bits);
      continue;
    }
    const Vec3& m = normals[i];
    const double mx = std::isfinite(m.x) ? m.x : 0.0, my = std::isfinite(m.y) ? m.y : 0.0,
                 mz = std::isfinite(m.z) ? m.z : 0.0;
    const uint32_t axes[6] = {q(p.x, lo.x),
                              q(p.y, lo.y),
                              q(p.z, lo.z),
                              q((mx + 1) * nscale, 0),
                              q((my + 1) * nscale, 0),
                              q((mz + 1) * nscale, 0)};
    key[i] = HilbertIndex(axes, bits);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return key[a] < key[b]; });
  return order;
}

SpatialSegment MeshSegment(std::span<const Vec3> positions, std::span<const Vec3> normals,
                           double normal_weight) {
  SpatialSegment s;
  s.kind = SpatialSegment::Kind::kMesh1D;
  s.count = static_cast<uint32_t>(positions.size());
  s.order = HilbertOrder(positions, normals, normal_weight);
  return s;
}

SpatialSegment GridSegment(uint32_t width, uint32_t height) {
  SpatialSegment s;
  s.kind = SpatialSegment::Kind::kGrid2D;
  s.count = width * height;
  s.width = width;
  s.height = height;
  return s;
}

SpatialDomain SpatialDomainOf(const SceneGeometry& geometry, double order_normal_weight,
                              uint32_t channels) {
  SpatialDomain d;
  for (const SceneMesh& m : geometry.meshes) {
    const uint32_t r = static_cast<uint32_t>(m.grid_resolution);
    if (m.is_ground && r > 0 && static_cast<std::size_t>(r) * r == m.mesh.positions.size()) {
      d.segments.push_back(GridSegment(r, r));
    } else if (!m.mesh.positions.empty()) {
      // A mesh without a normal per vertex is ordered by position alone.
      const bool normals = m.mesh.normals.size() == m.mesh.positions.size();
      d.segments.push_back(
          MeshSegment(m.mesh.positions, m.mesh.normals, normals ? order_normal_weight : 0.0));
    }
  }
  return PerChannelDomain(d, channels);
}

SpatialDomain ImageDomain(uint32_t width, uint32_t height, uint32_t channels) {
  SpatialDomain d;
  d.segments.push_back(GridSegment(width, height));
  return PerChannelDomain(d, channels);
}

}  // namespace prt
