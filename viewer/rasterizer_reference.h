// The straightforward rasteriser RasterizeTriangles replaced (viewer/rasterizer_reference.cpp):
// for tests (pixel-for-pixel comparison) and bench/raster_bench.cpp (old against new) only; it
// lives in its own library, prt_raster_reference, that prt-view does not link.
#pragma once

#include "viewer/rasterizer.h"

namespace prt {

// The same contract as RasterizeTriangles (rasterizer.h): row bands, double arithmetic at every
// pixel, the background function called per uncovered pixel.
RasterImage RasterizeTrianglesReference(const Camera& camera, std::span<const Vec3> positions,
                                        std::span<const std::array<uint32_t, 3>> triangles,
                                        std::span<const float> vertex_rgb,
                                        const RasterOptions& options = {});

}  // namespace prt
