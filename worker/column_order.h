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

#include "vocabulary/compressed_transport.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// Hilbert index of cell (x, y, z) of a 2^bits-cube (bits ∈ [1, 21]): Skilling 2004,
// "Programming the Hilbert curve" (axes → transposed index → interleaved bits). Consecutive
// indices are face-adjacent cells.
uint64_t HilbertIndex3D(uint32_t x, uint32_t y, uint32_t z, int bits);

// order[k] = index of the vertex at position k along the Hilbert curve (positions quantised to a
// 2^bits grid over their bounding box; ties keep file order). Non-finite positions throw
// std::invalid_argument.
std::vector<uint32_t> HilbertOrder(std::span<const Vec3> positions, int bits = 16);

// Segments of the spatial domain.
SpatialSegment MeshSegment(std::span<const Vec3> positions);  // 1D along HilbertOrder
SpatialSegment GridSegment(uint32_t width, uint32_t height);  // 2D, row-major x fastest

// The domain of a scene's vertices in global sample order (scene.h): every mesh a Hilbert-ordered
// 1D segment, the ground plane a res×res grid segment.
SpatialDomain SpatialDomainOf(const SceneGeometry& geometry);
// Image relighting: one width×height grid.
SpatialDomain ImageDomain(uint32_t width, uint32_t height);

}  // namespace prt
