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
//
// Supersampling ([camera] supersample = k > 1; docs/image-relighting.md, "Supersampling"): k×k
// stratified jittered primary rays per pixel square (stratum (i, j), the jitter a pure function
// of the seed, the pixel and the stratum, so every rank traces the same rays). The surface hits
// are the pixel's footprint (SampleFootprints); the pixel's coverage is the fraction of rays that
// hit a surface, its mesh the one most rays see (ties: the lowest index; background when none
// hit), its sample the surface hit nearest the pixel centre (marked `supersampled`: its row is
// the footprint's mix, WeighFootprints).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
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

  // Supersampling (k = camera.supersample > 1); otherwise 1 and the rest empty.
  int supersample = 1;
  // Per pixel: the fraction of its k² rays that hit a surface.
  std::vector<float> coverage;
  // The surface sub-samples of every pixel (indexed by pixel; cdf filled by WeighFootprints, edge
  // their triangles' longest edges) and their meshes (parallel to footprints->subs).
  std::shared_ptr<SampleFootprints> footprints;
  std::vector<uint32_t> sub_mesh;
  // Per pixel (WeighFootprints): w_c(p) = (1/k²) Σ_s a_c(s), background sub-samples 0.
  std::vector<Rgb> pixel_weight;
};

// Traces the primary rays of `camera` (parallel over rows, TBB). A background pixel's sample
// lies 100 scene diagonals out along its ray (finite, and farther from any surface sample than
// any neighbour radius) with its normals towards the camera. Throws InputError naming `name` on a
// degenerate camera (CameraProjection's conditions) or one whose eye is not finite.
// camera.supersample = k > 1 traces k×k rays per pixel (above), jittered from `seed`.
CameraSamples ComputeCameraSamples(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                                   const Camera& camera, const std::string& name = "camera",
                                   uint64_t seed = 1);

// Supersampled pixels' weights from each mesh's relighting weight a (its albedo, or a glossy
// mesh's w; mesh_weight[m] for mesh m): the mixing weights λ_s = ā(s) / Σ ā over the pixel's
// surface sub-samples (ā the mean of the channels; uniform when every ā is 0) into
// footprints->cdf, and pixel_weight. A no-op when supersample is 1.
void WeighFootprints(CameraSamples& pixels, std::span<const Rgb> mesh_weight);

}  // namespace prt
