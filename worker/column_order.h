// Locality-preserving order of spatial samples for the column transform (Cheslack-Postava et al.
// 2008 §4.1 asks for samples parameterised over the filter's domain). A ground grid and an image
// are 2D domains already; an arbitrary mesh gets a 1D order: its vertices sorted along a 3D
// Hilbert curve through their bounding box, so that neighbours in the order are neighbours in
// space and a column restricted to the mesh is a piecewise-smooth 1D signal. Documented in
// docs/compression.md.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "formats/compressed_transport.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// Hilbert index of cell (x, y, z) of a 2^bits-cube (bits ∈ [1, 21]): Skilling 2004,
// "Programming the Hilbert curve" (axes → transposed index → interleaved bits). Consecutive
// indices are face-adjacent cells.
uint64_t HilbertIndex3D(uint32_t x, uint32_t y, uint32_t z, int bits);
// The same in axes.size() ∈ [1, 8] dimensions (bits · axes ≤ 64).
uint64_t HilbertIndex(std::span<const uint32_t> axes, int bits);

// order[k] = index of the vertex at position k along the Hilbert curve (positions quantised to a
// 2^bits grid over their bounding box; ties keep file order). Non-finite positions throw
// std::invalid_argument.
std::vector<uint32_t> HilbertOrder(std::span<const Vec3> positions, int bits = 16);
// With normal_weight > 0: along a 6D Hilbert curve through (position, normal), a normal's axes
// spanning normal_weight × the largest extent of the positions (1: opposite normals as far apart
// as the whole box), so that the two sides of a thin part (close in space, opposite normals) are
// not interleaved (bits capped at 10).
std::vector<uint32_t> HilbertOrder(std::span<const Vec3> positions, std::span<const Vec3> normals,
                                   double normal_weight, int bits = 16);

// Segments of the spatial domain.
SpatialSegment MeshSegment(std::span<const Vec3> positions,  // 1D along HilbertOrder
                           std::span<const Vec3> normals = {}, double normal_weight = 0.0);
SpatialSegment GridSegment(uint32_t width, uint32_t height);  // 2D, row-major x fastest

// The domain of a scene's vertices in global sample order (scene.h): every mesh a Hilbert-ordered
// 1D segment (HilbertOrder with the normals and `order_normal_weight`, the scene's
// [compression] order_normal_weight; by position alone for a mesh without one normal per
// vertex), the ground plane a res×res grid segment. With `channels` = 3 (a transport with one row
// per spatial sample and colour channel, channel-major: row c·V + v) the domain of its 3·V rows:
// those segments three times, channel c's at offset c·V (PerChannelDomain), so that no column
// transform mixes channels; 1 gives the V spatial samples' domain. Throws InputError unless
// channels is 1 or 3.
SpatialDomain SpatialDomainOf(
    const SceneGeometry& geometry,
    double order_normal_weight = CompressionSettings{}.order_normal_weight, uint32_t channels = 1);
// Image relighting: one width×height grid (pixels row-major from the top-left), `channels` times
// (PerChannelDomain).
SpatialDomain ImageDomain(uint32_t width, uint32_t height, uint32_t channels = 1);

}  // namespace prt
