// Image relighting's samples (worker/camera_samples.h): a pixel's row is the row of a vertex at
// the point it sees, a plane under a uniform sky is flat to the estimator's error, background
// pixels are zero rows, back faces face the eye, bad cameras are InputErrors.
#include "worker/camera_samples.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numeric>
#include <vector>

#include "vocabulary/camera_projection.h"
#include "vocabulary/errors.h"
#include "worker/grid_scene_test_support.h"
#include "worker/path_trace_reference.h"

namespace prt {
namespace {

using grid_scenes::Grid;
using grid_scenes::Scene;

// A 4×4 ground at y = 0 (normal +Y) and a 1×1 wall standing on it (normal −Z, towards a camera
// at −Z... the camera looks from +z), the classic occluder of the transport tests.
SceneGeometry GroundAndWall() {
  return Scene(
      {Grid("wall", {-0.5, 0.0, -0.5}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, 9, {0.5f, 0.5f, 0.5f}),
       Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 33, {0.8f, 0.8f, 0.8f})});
}

TEST(CameraSamples, PixelRowIsTheRowOfAVertexAtThePointItSees) {
  const SceneGeometry g = GroundAndWall();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> vertices = SpatialSamplesOf(g);
  // Ground vertex (i, j) = (20, 12) lies in the wall's shadow region on the camera's side; an
  // odd image puts the centre pixel's ray exactly through the camera's target.
  const uint64_t wall_vertices = 81;
  const uint64_t v = wall_vertices + 12 * 33 + 20;
  Camera cam;
  cam.eye = {0.3, 1.7, 3.1};
  cam.target = vertices[v].position;
  cam.width = 31;
  cam.height = 21;
  cam.fov_deg = 30;
  const CameraSamples pixels = ComputeCameraSamples(scene, surfaces, cam);
  const std::size_t centre = static_cast<std::size_t>(10) * 31 + 15;
  ASSERT_EQ(pixels.pixel_mesh[centre], 1u);  // the ground
  const SpatialSample& s = pixels.samples[centre];
  EXPECT_LT(Length(s.position - vertices[v].position), 1e-6);
  EXPECT_LT(Length(s.normal - vertices[v].normal), 1e-12);
  EXPECT_LT(Length(s.geometric_normal - vertices[v].geometric_normal), 1e-12);

  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  const TransportSampler sampler(scene, 16, so);
  const std::size_t T = sampler.layout().texel_count();
  std::vector<float> pixel_row(T), vertex_row(T);
  // Same index (the jitter's seed): the same rays up to the point's float rounding.
  sampler.ComputeRow(s, v, pixel_row.data());
  sampler.ComputeRow(vertices[v], v, vertex_row.data());
  double diff = 0, norm = 0, sum = 0;
  for (std::size_t j = 0; j < T; ++j) {
    diff += std::abs(double(pixel_row[j]) - vertex_row[j]);
    norm += std::abs(double(vertex_row[j]));
    sum += pixel_row[j];
  }
  EXPECT_LE(diff, 1e-4 * norm);
  // The wall shadows part of its sky: the row is a real occluded one.
  EXPECT_LT(sum, 0.97);
  EXPECT_GT(sum, 0.3);
}

TEST(CameraSamples, PlaneUnderUniformSkyIsFlatAndTheSkyIsBackground) {
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 17, {0.8f, 0.8f, 0.8f})});
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  Camera cam;
  cam.eye = {0, 1.5, 3.5};
  cam.target = {0, 0, 0};
  cam.width = 48;
  cam.height = 32;
  cam.fov_deg = 50;
  const CameraSamples pixels = ComputeCameraSamples(scene, surfaces, cam);
  ASSERT_EQ(pixels.samples.size(), 48u * 32u);
  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  const TransportSampler sampler(scene, 8, so);
  const std::size_t T = sampler.layout().texel_count();
  std::vector<float> row(T), variance(T);
  const CameraProjection proj(cam);
  std::size_t ground = 0, sky = 0;
  double spread = 0, sigma2 = 0;  // Σ (sum − 1)² and Σ σ² over the ground pixels
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    const SampleStats st = sampler.ComputeRow(pixels.samples[p], p, row.data(), variance.data());
    const double sum = std::accumulate(row.begin(), row.end(), 0.0);
    // The row sum's own Monte-Carlo variance (texels are independent estimates).
    const double var = std::accumulate(variance.begin(), variance.end(), 0.0);
    // A pixel is ground exactly when its ray meets the 4×4 square.
    const Vec3 d =
        proj.PixelDirection(static_cast<double>(p % 48) + 0.5, static_cast<double>(p / 48) + 0.5);
    const double t = d.y < 0 ? -cam.eye.y / d.y : -1;
    const Vec3 hit = cam.eye + d * t;
    const bool on_square = t > 0 && std::abs(hit.x) < 2 - 1e-9 && std::abs(hit.z) < 2 - 1e-9;
    if (pixels.pixel_mesh[p] == kImageBackground) {
      ++sky;
      EXPECT_TRUE(pixels.samples[p].background);
      EXPECT_FALSE(on_square) << p;
      EXPECT_EQ(sum, 0.0);
      EXPECT_EQ(st.rays_traced, 0u);
    } else {
      ++ground;
      EXPECT_TRUE(on_square || std::abs(std::abs(hit.x) - 2) < 1e-6 ||
                  std::abs(std::abs(hit.z) - 2) < 1e-6)
          << p;
      // (1/π)∫ cos over the unoccluded hemisphere = 1, to the estimator's error (the exact-
      // solid-angle strata leave the cosine's variation inside a stratum, ~0.2% here).
      EXPECT_NEAR(sum, 1.0, 5 * std::sqrt(var) + 1e-6) << "pixel " << p;
      spread += (sum - 1) * (sum - 1);
      sigma2 += var;
      EXPECT_LT(Length(pixels.samples[p].position - hit), 1e-5);
    }
  }
  EXPECT_GT(ground, 500u);
  // Flat: the pixels scatter about 1 as their own error bars say, no more (the estimate's
  // collapsed strata may overstate σ, so only an upper bound).
  const double g_count = static_cast<double>(ground);
  EXPECT_LT(std::sqrt(spread / g_count), 1.5 * std::sqrt(sigma2 / g_count));
  EXPECT_LT(std::sqrt(spread / g_count), 3e-3);
  EXPECT_GT(sky, 100u);
  EXPECT_EQ(sky, pixels.background_count());
}

TEST(CameraSamples, BackgroundPixelsHaveZeroRowsInEveryKernel) {
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 9, {0.8f, 0.8f, 0.8f})});
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  Camera cam;
  cam.eye = {0, 0.5, 3};
  cam.target = {0, 1.5, 0};  // looking up: mostly sky
  cam.width = 8;
  cam.height = 8;
  const CameraSamples pixels = ComputeCameraSamples(scene, surfaces, cam);
  ASSERT_EQ(pixels.background_count(), 64u);
  const SpatialSample& s = pixels.samples[0];
  EXPECT_TRUE(std::isfinite(s.position.x));
  EXPECT_GT(Length(s.position - cam.eye), 10 * g.diagonal());
  const TransportSampler sampler(scene, 4, {});
  std::vector<float> values(3, 1.0f), unocc(3, 1.0f);
  const std::vector<uint32_t> texels{0, 17, 40};
  sampler.ComputeTexels(s, 0, texels, values.data(), unocc.data());
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(values[i], 0.0f);
    EXPECT_EQ(unocc[i], 0.0f);
  }
  PathTraceOptions po;
  po.bounces = 2;
  po.paths = 8;
  const PathTraceReference reference(scene, surfaces, 4, po);
  std::vector<float> row(96, 1.0f);
  reference.ComputeRow(s, 0, 1, row.data());
  for (float x : row) EXPECT_EQ(x, 0.0f);
}

TEST(CameraSamples, BackFacesFaceTheEye) {
  // The camera below the ground looks up at its back side.
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 9, {0.8f, 0.8f, 0.8f})});
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  Camera cam;
  cam.eye = {0, -1, 0.5};
  cam.target = {0, 0, 0};
  cam.width = 5;
  cam.height = 5;
  const CameraSamples pixels = ComputeCameraSamples(scene, surfaces, cam);
  const SpatialSample& s = pixels.samples[12];
  ASSERT_EQ(pixels.pixel_mesh[12], 0u);
  EXPECT_NEAR(s.normal.y, -1.0, 1e-12);
  EXPECT_NEAR(s.geometric_normal.y, -1.0, 1e-12);
}

TEST(CameraSamples, DegenerateCamerasAreInputErrors) {
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 3, {0.8f, 0.8f, 0.8f})});
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  Camera same;
  same.target = same.eye;
  EXPECT_THROW(ComputeCameraSamples(scene, surfaces, same, "scene.toml"), InputError);
  Camera nan_eye;
  nan_eye.eye.x = std::nan("");
  EXPECT_THROW(ComputeCameraSamples(scene, surfaces, nan_eye, "scene.toml"), InputError);
  Camera fov;
  fov.fov_deg = 180;
  EXPECT_THROW(ComputeCameraSamples(scene, surfaces, fov, "scene.toml"), InputError);
}

}  // namespace
}  // namespace prt
