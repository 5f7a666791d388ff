// Image relighting's spatial samples (Ng et al. 2003: a fixed view, each pixel a row of T): the
// surface point each pixel of the scene's camera sees (docs/image-relighting.md, no MPI here).
//
// Pixel footprint: one primary ray through the pixel's centre (vocabulary/camera_projection.h),
// traced to its closest hit. The pixel's sample is that hit as SceneSurfaces resolves it (the
// point interpolated on the triangle in double, the interpolated shading normal, the triangle's
// geometric normal), so its row of T is exactly the row of a vertex placed there. A primary ray
// that reaches a back face (the inside of an open mesh) sees that side: the normals are turned to
// the camera, as a renderer shades a two-sided surface. A ray that hits nothing makes a
// background pixel: SpatialSample::background, a zero row, and the viewer draws the environment
// map there at its own resolution.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/image_file.h"
#include "vocabulary/scene.h"
#include "worker/embree_scene.h"
#include "worker/surface_hit.h"
#include "worker/transport_sampler.h"

namespace prt {

struct CameraSamples {
  int width = 0;
  int height = 0;
  // width·height samples, row-major from the top-left (the rows of T, scene.h's order).
  std::vector<SpatialSample> samples;
  // Per pixel: the index of the mesh it sees (SceneGeometry::meshes, its albedo), or
  // kImageBackground.
  std::vector<uint32_t> pixel_mesh;
  // Per pixel: the longest edge of the triangle it sees, 0 for background (the bounce gather's
  // near field compares hits with it, as with a vertex's SceneSurfaces::VertexEdge).
  std::vector<float> pixel_edge;
  std::size_t background_count() const { return BackgroundPixels(pixel_mesh); }
};

// Traces the primary rays of `camera` (parallel over rows, TBB). A background pixel's sample
// lies 100 scene diagonals out along its ray (finite, and farther from any surface sample than
// any neighbour radius) with its normals towards the camera. Throws InputError naming `name` on a
// degenerate camera (CameraProjection's conditions) or one whose eye is not finite.
CameraSamples ComputeCameraSamples(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                                   const Camera& camera, const std::string& name = "camera");

}  // namespace prt
