// Radius-restricted k-nearest-neighbour search over 3D points (FLANN k-d tree), used by the
// sparse precomputation to find a vertex's dense neighbours (Huang & Ramamoorthi 2010, §4.1 and
// §5.3: "dense vertices within some spatial radius", capped at k). Built once per phase.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

class NeighborIndex {
 public:
  // `points` are copied; `ids` (same length) are what queries return (e.g. global sample
  // indices of dense vertices). Throws std::invalid_argument on mismatched sizes.
  NeighborIndex(std::span<const Vec3> points, std::span<const uint32_t> ids);
  ~NeighborIndex();
  NeighborIndex(const NeighborIndex&) = delete;
  NeighborIndex& operator=(const NeighborIndex&) = delete;

  std::size_t size() const;

  // Ids of the points within `radius` of `query` (Euclidean), nearest first, at most max_k.
  // Exact (FLANN with an exact search on a single k-d tree); thread-safe.
  std::vector<uint32_t> RadiusSearch(const Vec3& query, double radius, int max_k) const;
  // The max_k nearest regardless of radius, nearest first.
  std::vector<uint32_t> Nearest(const Vec3& query, int max_k) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace prt
