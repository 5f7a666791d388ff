// Image relighting's samples (worker/camera_samples.h): a pixel's row is the row of a vertex at
// the point it sees, a plane under a uniform sky is flat to the estimator's error, background
// pixels are zero rows, back faces face the eye, bad cameras are InputErrors.
#include "worker/camera_samples.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
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

// Supersampling ([camera] supersample = k; docs/image-relighting.md, "Supersampling").

// The sampler of a supersampled image: the footprints weighed by the meshes' albedos.
struct SupersampledImage {
  SupersampledImage(const SceneGeometry& g, const Camera& cam, int n, int rays)
      : scene(g), surfaces(g), pixels(ComputeCameraSamples(scene, surfaces, cam)) {
    std::vector<Rgb> albedo;
    for (const SceneMesh& m : g.meshes) albedo.push_back(m.albedo);
    WeighFootprints(pixels, albedo);
    TransportSamplerOptions so;
    so.rays_per_texel = rays;
    sampler = std::make_unique<TransportSampler>(scene, n, so, GlossySampling{}, pixels.footprints);
  }
  EmbreeScene scene;
  SceneSurfaces surfaces;
  CameraSamples pixels;
  std::unique_ptr<TransportSampler> sampler;
};

// A white 4×4 plane seen straight from above: its edges run along the image's columns and rows.
Camera StraightDown(int k) {
  Camera cam;
  cam.eye = {0.013, 3, 0.021};
  cam.target = {0.013, 0, 0.021};
  cam.up = {0, 0, -1};
  cam.width = 40;
  cam.height = 32;
  cam.fov_deg = 83;
  cam.supersample = k;
  return cam;
}

TEST(CameraSupersample, CoveredPixelsOfAnUnoccludedWhitePlaneRelightToOneUnderAUniformSky) {
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 9, {1.f, 1.f, 1.f})});
  const SupersampledImage im(g, StraightDown(4), 8, 4);
  const CameraSamples& pixels = im.pixels;
  ASSERT_EQ(pixels.supersample, 4);
  ASSERT_TRUE(pixels.footprints);
  const std::size_t T = im.sampler->layout().texel_count();
  std::vector<float> row(T), variance(T);
  std::size_t covered = 0;
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    if (pixels.coverage[p] != 1.f) continue;
    ++covered;
    ASSERT_TRUE(pixels.samples[p].supersampled);
    EXPECT_EQ(pixels.footprints->offset[p + 1] - pixels.footprints->offset[p], 16u);
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(pixels.pixel_weight[p][c], 1.f);
    im.sampler->ComputeRow(pixels.samples[p], p, row.data(), variance.data());
    const double sum = std::accumulate(row.begin(), row.end(), 0.0);
    const double var = std::accumulate(variance.begin(), variance.end(), 0.0);
    // B = w·(R·L) + (1 − cov)·E = 1·Σ R + 0: the closed form 1, to the estimator's error.
    EXPECT_NEAR(sum, 1.0, 5 * std::sqrt(var) + 1e-6) << p;
  }
  EXPECT_GT(covered, 300u);
}

TEST(CameraSupersample, SilhouettePixelsCoverTheirAnalyticFractionAndBlendTheEnvironment) {
  const SceneGeometry g =
      Scene({Grid("ground", {-2, 0, 2}, {4, 0, 0}, {0, 0, -4}, {0, 1, 0}, 9, {1.f, 1.f, 1.f})});
  const int k = 4;
  const Camera cam = StraightDown(k);
  const SupersampledImage im(g, cam, 8, 4);
  const CameraSamples& pixels = im.pixels;
  const CameraProjection proj(cam);
  const std::size_t T = im.sampler->layout().texel_count();
  std::vector<float> row(T);
  // The fraction of pixel (x, y)'s square whose rays meet the plane inside the square, on a
  // 64×64 grid of points (the plane is seen straight on: the region is a rectangle).
  auto analytic = [&](int x, int y) {
    int in = 0;
    for (int j = 0; j < 64; ++j)
      for (int i = 0; i < 64; ++i) {
        const Vec3 d = proj.PixelDirection(x + (i + 0.5) / 64, y + (j + 0.5) / 64);
        const Vec3 hit = cam.eye + d * (-cam.eye.y / d.y);
        in += std::abs(hit.x) < 2 && std::abs(hit.z) < 2 ? 1 : 0;
      }
    return in / 4096.0;
  };
  std::size_t straddling = 0, background = 0;
  double abs_err = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * cam.width + x;
      const double a = analytic(x, y);
      const double cov = pixels.coverage[p];
      if (a == 0 || a == 1) {
        EXPECT_EQ(cov, a) << x << ", " << y;
        background += a == 0 ? 1 : 0;
        continue;
      }
      ++straddling;
      // One stratum per k² of the pixel; an edge along a column of strata crosses k of them.
      EXPECT_LE(std::abs(cov - a), 2.0 / k + 1e-9) << x << ", " << y;
      abs_err += std::abs(cov - a);
      EXPECT_EQ(pixels.pixel_mesh[p], cov > 0 ? 0u : kImageBackground);
      if (cov == 0) continue;
      // Every sub-sample sees the white plane: w = cov · albedo exactly.
      for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(pixels.pixel_weight[p][c], float(cov));
      // Under a uniform sky of 1: B = w·Σ R + (1 − cov)·1 = cov + 1 − cov = 1.
      im.sampler->ComputeRow(pixels.samples[p], p, row.data());
      const double sum = std::accumulate(row.begin(), row.end(), 0.0);
      EXPECT_NEAR(pixels.pixel_weight[p][0] * sum + (1 - cov), 1.0, 0.01) << x << ", " << y;
    }
  EXPECT_GT(straddling, 50u);
  EXPECT_GT(background, 50u);
  EXPECT_LE(abs_err / double(straddling), 1.0 / (k * k));
  EXPECT_EQ(pixels.background_count(), static_cast<std::size_t>(std::count(
                                           pixels.coverage.begin(), pixels.coverage.end(), 0.f)));
}

// GroundAndWall's wall standing on the ground, 48×36 at k = 3: pixels along its foot see both.
Camera WallFootCamera() {
  Camera cam;
  cam.eye = {0.2, 0.9, 3.0};
  cam.target = {0.0, 0.0, -0.5};
  cam.width = 48;
  cam.height = 36;
  cam.fov_deg = 40;
  cam.supersample = 3;
  return cam;
}

TEST(CameraSupersample, APixelStraddlingTwoMeshesIsTheLambdaWeightedMixOfItsSubSamplesRows) {
  // The wall (albedo 0.5, facing the camera) standing on the ground (0.8): pixels along its
  // foot see both; λ = ā / Σ ā weighs the ground's sub-samples 1.6× the wall's.
  const SceneGeometry g = GroundAndWall();
  const Camera cam = WallFootCamera();
  // 64 rays per texel: each ray picks one sub-sample, so the row's noise includes the spread
  // between the sub-samples' rows (about 5 % of the row sum at 4 rays here, 0.8 % at 64).
  const SupersampledImage im(g, cam, 8, 64);
  const CameraSamples& pixels = im.pixels;
  const SampleFootprints& fp = *pixels.footprints;
  TransportSamplerOptions ro;
  ro.rays_per_texel = 1024;
  const TransportSampler reference(im.scene, 8, ro);
  const std::size_t T = im.sampler->layout().texel_count();
  std::vector<float> row(T), sub(T), values(T), unocc(T);
  std::vector<uint32_t> all(T);
  std::iota(all.begin(), all.end(), 0u);
  int checked = 0;
  for (std::size_t p = 0; p < pixels.samples.size() && checked < 6; ++p) {
    bool wall = false, ground = false;
    for (uint32_t s = fp.offset[p]; s < fp.offset[p + 1]; ++s)
      (pixels.sub_mesh[s] == 0 ? wall : ground) = true;
    if (!wall || !ground || pixels.coverage[p] != 1.f) continue;
    ++checked;
    im.sampler->ComputeRow(pixels.samples[p], p, row.data());
    // The listed-texel path gives the same bytes, and U ≥ T.
    im.sampler->ComputeTexels(pixels.samples[p], p, all, values.data(), unocc.data());
    EXPECT_EQ(std::memcmp(values.data(), row.data(), T * 4), 0) << p;
    for (std::size_t j = 0; j < T; ++j) ASSERT_GE(unocc[j], row[j]) << p;
    // The brute-force reference: every sub-sample's own row at 256 rays per texel.
    std::vector<double> mix(T, 0.0);
    double previous = 0;
    for (uint32_t s = fp.offset[p]; s < fp.offset[p + 1]; ++s) {
      const double lambda = fp.cdf[s] - previous;
      previous = fp.cdf[s];
      const auto first = pixels.sub_mesh.begin() + fp.offset[p];
      const auto last = pixels.sub_mesh.begin() + fp.offset[p + 1];
      const double walls = static_cast<double>(std::count(first, last, 0u));
      const double grounds = static_cast<double>(std::count(first, last, 1u));
      EXPECT_NEAR(lambda, (pixels.sub_mesh[s] == 0 ? 0.5 : 0.8) / (0.5 * walls + 0.8 * grounds),
                  1e-6);
      SpatialSample point = fp.subs[s];
      point.supersampled = false;
      reference.ComputeRow(point, s + 1000000, sub.data());
      for (std::size_t j = 0; j < T; ++j) mix[j] += lambda * sub[j];
    }
    // Per cube face and in total (the row's noise averages out over a face's 64 texels).
    const std::size_t face = T / 6;
    double diff = 0, total = 0, sum = 0, want = 0;
    for (int f = 0; f < 6; ++f) {
      double a = 0, b = 0;
      for (std::size_t j = f * face; j < (f + 1) * face; ++j) {
        a += row[j];
        b += mix[j];
      }
      diff += std::abs(a - b);
      total += b;
      sum += a;
      want += b;
    }
    EXPECT_NEAR(sum, want, 0.02 * want) << p;
    EXPECT_LT(diff, 0.05 * total) << p;
  }
  EXPECT_EQ(checked, 6);
}

TEST(CameraSupersample, OneRayPerPixelKeepsTheSamplesAndSupersamplingIsDeterministic) {
  const SceneGeometry g = GroundAndWall();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  Camera cam;
  cam.width = 12;
  cam.height = 9;
  const CameraSamples one = ComputeCameraSamples(scene, surfaces, cam);
  EXPECT_EQ(one.supersample, 1);
  EXPECT_FALSE(one.footprints);
  EXPECT_TRUE(one.coverage.empty());
  for (const SpatialSample& s : one.samples) EXPECT_FALSE(s.supersampled);
  cam.supersample = 5;
  const CameraSamples a = ComputeCameraSamples(scene, surfaces, cam, "camera", 7);
  const CameraSamples b = ComputeCameraSamples(scene, surfaces, cam, "camera", 7);
  const CameraSamples c = ComputeCameraSamples(scene, surfaces, cam, "camera", 8);
  ASSERT_EQ(a.footprints->subs.size(), b.footprints->subs.size());
  for (std::size_t i = 0; i < a.footprints->subs.size(); ++i)
    ASSERT_EQ(a.footprints->subs[i].position, b.footprints->subs[i].position) << i;
  EXPECT_EQ(a.coverage, b.coverage);
  EXPECT_NE(Length(a.footprints->subs[0].position - c.footprints->subs[0].position), 0.0);
  cam.supersample = 17;
  EXPECT_THROW(ComputeCameraSamples(scene, surfaces, cam, "scene.toml"), InputError);
}

TEST(CameraSupersample, GlossySubSamplesCarryTheirMaterialAndView) {
  // The wall's pixels glossy (GGX r = 0.3, k_d 0.4, k_s 0.6; the material table's entry 0), the
  // ground's diffuse: a pixel along the wall's foot mixes a glossy and a diffuse row, each
  // sub-sample with its own view direction towards the eye.
  const SceneGeometry g = GroundAndWall();
  const Camera cam = WallFootCamera();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  CameraSamples pixels = ComputeCameraSamples(scene, surfaces, cam);
  WeighFootprints(pixels, std::vector<Rgb>{Rgb{1.f, 1.f, 1.f}, Rgb{0.8f, 0.8f, 0.8f}});
  Material ggx;
  ggx.model = BrdfModel::kGgx;
  ggx.roughness = 0.3;
  ggx.diffuse = {0.4f, 0.4f, 0.4f};
  ggx.specular = {0.6f, 0.6f, 0.6f};
  SampleFootprints& fp = *pixels.footprints;
  for (std::size_t s = 0; s < fp.subs.size(); ++s)
    if (pixels.sub_mesh[s] == 0) fp.subs[s].glossy_material = 0;
  TransportSamplerOptions so;
  so.rays_per_texel = 256;
  const GlossySampling gs{{ggx}, cam.eye};
  const TransportSampler sampler(scene, 8, so, gs, pixels.footprints);
  so.rays_per_texel = 1024;
  const TransportSampler reference(scene, 8, so, gs);
  const std::size_t T = sampler.layout().texel_count();
  std::vector<float> row(T), sub(T);
  int checked = 0;
  for (std::size_t p = 0; p < pixels.samples.size() && checked < 4; ++p) {
    bool wall = false, ground = false;
    for (uint32_t s = fp.offset[p]; s < fp.offset[p + 1]; ++s)
      (pixels.sub_mesh[s] == 0 ? wall : ground) = true;
    if (!wall || !ground || pixels.coverage[p] != 1.f) continue;
    ++checked;
    sampler.ComputeRow(pixels.samples[p], p, row.data());
    double want = 0, previous = 0;
    for (uint32_t s = fp.offset[p]; s < fp.offset[p + 1]; ++s) {
      const double lambda = fp.cdf[s] - previous;
      previous = fp.cdf[s];
      SpatialSample point = fp.subs[s];
      point.supersampled = false;
      reference.ComputeRow(point, s + 1000000, sub.data());
      want += lambda * std::accumulate(sub.begin(), sub.end(), 0.0);
    }
    // The lobe's noise (a GGX peak inside 8×8-texel faces): within 1.5 % at 256 rays here.
    EXPECT_NEAR(std::accumulate(row.begin(), row.end(), 0.0), want, 0.03 * want) << p;
  }
  EXPECT_EQ(checked, 4);
}
}  // namespace
}  // namespace prt
