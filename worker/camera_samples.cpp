// Primary rays of image relighting (worker/camera_samples.h).
#include "worker/camera_samples.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/camera_projection.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// k×k stratified jittered rays per pixel (camera_samples.h): the footprints, coverage, majority
// mesh and representative sample of every pixel. The rays of a pixel are traced in parallel over
// image rows into per-pixel slots, then concatenated in pixel order (deterministic).
template <typename Trace, typename Background>
CameraSamples Supersampled(CameraSamples& out, int k, uint64_t seed, Trace& trace,
                           Background& background) {
  const std::size_t pixels = out.samples.size();
  const int width = out.width;
  const std::size_t k2 = static_cast<std::size_t>(k) * k;
  out.supersample = k;
  out.coverage.assign(pixels, 0.0f);
  std::vector<std::vector<SpatialSample>> subs(pixels);
  std::vector<std::vector<uint32_t>> meshes(pixels);
  std::vector<std::vector<float>> edges(pixels);
  const uint64_t key = SplitMix64(seed ^ 0x53555045525350ull);
  tbb::parallel_for(0, out.height, [&](int y) {
    std::vector<uint32_t> votes;
    for (int x = 0; x < width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * width + x;
      double nearest = std::numeric_limits<double>::infinity();
      std::size_t representative = 0;
      Vec3 centre_dir;
      votes.clear();
      for (int j = 0; j < k; ++j) {
        for (int i = 0; i < k; ++i) {
          // Jitter = pure function of (seed, pixel, stratum); open interval (0, 1).
          const uint64_t bits =
              SplitMix64(key ^ (static_cast<uint64_t>(p) * k2 + static_cast<uint64_t>(j * k + i)));
          const double ju = (static_cast<double>(bits >> 32) + 0.5) * 0x1p-32;
          const double jv = (static_cast<double>(bits & 0xFFFFFFFFull) + 0.5) * 0x1p-32;
          const double sx = (i + ju) / k, sy = (j + jv) / k;
          Vec3 d;
          SurfaceHit s;
          if (!trace(x + sx, y + sy, d, s)) continue;
          const double r2 = (sx - 0.5) * (sx - 0.5) + (sy - 0.5) * (sy - 0.5);
          if (r2 < nearest) {
            nearest = r2;
            representative = subs[p].size();
          }
          subs[p].push_back(s.sample);
          meshes[p].push_back(s.mesh);
          edges[p].push_back(static_cast<float>(s.max_edge));
          if (votes.size() <= s.mesh) votes.resize(s.mesh + 1, 0);
          ++votes[s.mesh];
        }
      }
      SpatialSample& sample = out.samples[p];
      out.coverage[p] =
          static_cast<float>(static_cast<double>(subs[p].size()) / static_cast<double>(k2));
      if (subs[p].empty()) {
        Vec3 d;
        SurfaceHit s;
        trace(x + 0.5, y + 0.5, d, s);  // the centre ray's direction for the far point
        background(sample, d);
        continue;
      }
      sample = subs[p][representative];
      sample.supersampled = true;
      out.pixel_mesh[p] = static_cast<uint32_t>(std::max_element(votes.begin(), votes.end()) -
                                                votes.begin());  // first max: lowest
      out.pixel_edge[p] = edges[p][representative];
    }
  });
  auto fp = std::make_shared<SampleFootprints>();
  fp->offset.reserve(pixels + 1);
  fp->offset.push_back(0);
  for (std::size_t p = 0; p < pixels; ++p) {
    fp->subs.insert(fp->subs.end(), subs[p].begin(), subs[p].end());
    out.sub_mesh.insert(out.sub_mesh.end(), meshes[p].begin(), meshes[p].end());
    fp->edge.insert(fp->edge.end(), edges[p].begin(), edges[p].end());
    fp->offset.push_back(static_cast<uint32_t>(fp->subs.size()));
  }
  fp->cdf.assign(fp->subs.size(), 1.0);
  out.footprints = std::move(fp);
  return std::move(out);
}

}  // namespace

void WeighFootprints(CameraSamples& pixels, std::span<const Rgb> mesh_weight) {
  if (pixels.supersample <= 1 || !pixels.footprints) return;
  SampleFootprints& fp = *pixels.footprints;
  const std::size_t count = pixels.samples.size();
  const double k2 = static_cast<double>(pixels.supersample) * pixels.supersample;
  pixels.pixel_weight.assign(count, Rgb{0.f, 0.f, 0.f});
  for (std::size_t p = 0; p < count; ++p) {
    const uint32_t begin = fp.offset[p], end = fp.offset[p + 1];
    if (begin == end) continue;
    double sum = 0, w[3] = {0, 0, 0};
    for (uint32_t s = begin; s < end; ++s) {
      const Rgb& a = mesh_weight[pixels.sub_mesh[s]];
      for (int c = 0; c < 3; ++c) w[c] += a[c];
      sum += (static_cast<double>(a[0]) + a[1] + a[2]) / 3.0;
    }
    for (int c = 0; c < 3; ++c) pixels.pixel_weight[p][c] = static_cast<float>(w[c] / k2);
    double acc = 0;
    for (uint32_t s = begin; s < end; ++s) {
      const Rgb& a = mesh_weight[pixels.sub_mesh[s]];
      acc += sum > 0 ? (static_cast<double>(a[0]) + a[1] + a[2]) / 3.0 / sum
                     : 1.0 / static_cast<double>(end - begin);
      fp.cdf[s] = acc;
    }
    fp.cdf[end - 1] = 1.0;
  }
}

CameraSamples ComputeCameraSamples(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                                   const Camera& camera, const std::string& name, uint64_t seed) {
  if (!IsFinite(camera.eye) || !IsFinite(camera.target) || !IsFinite(camera.up))
    throw InputError(name, "the camera's eye, target and up must be finite");
  std::optional<CameraProjection> projection;
  try {
    projection.emplace(camera);
  } catch (const std::invalid_argument& e) {
    throw InputError(name, e.what());
  }
  if (camera.supersample < 1 || camera.supersample > 16)
    throw InputError(
        name, "[camera] supersample must be in 1…16, got " + std::to_string(camera.supersample));
  const CameraProjection& cam = *projection;
  CameraSamples out;
  out.width = camera.width;
  out.height = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;
  out.samples.resize(pixels);
  out.pixel_mesh.assign(pixels, kImageBackground);
  out.pixel_edge.assign(pixels, 0.0f);
  const double far = 100.0 * std::max(surfaces.geometry().diagonal(), 1.0);
  // The closest hit along the ray through image point (px, py): false for the environment.
  auto trace = [&](double px, double py, Vec3& d, SurfaceHit& s) {
    d = cam.PixelDirection(px, py);
    OcclusionRay ray;
    for (int i = 0; i < 3; ++i) {
      ray.origin[i] = static_cast<float>(camera.eye[i]);
      ray.direction[i] = static_cast<float>(d[i]);
    }
    ray.tnear = 0.0f;
    ray.tfar = std::numeric_limits<float>::infinity();
    RayHit hit;
    const SceneSurfaces::Outcome o = surfaces.Trace(scene, ray, hit, s);
    if (o == SceneSurfaces::Outcome::kEscaped) return false;
    if (o == SceneSurfaces::Outcome::kBackFace) {  // two-sided for the eye
      s.sample.normal = -s.sample.normal;
      s.sample.geometric_normal = -s.sample.geometric_normal;
    }
    return true;
  };
  auto background = [&](SpatialSample& sample, const Vec3& d) {
    sample.position = camera.eye + d * far;
    sample.normal = -d;
    sample.geometric_normal = -d;
    sample.background = true;
  };
  const int k = camera.supersample;
  if (k > 1) return Supersampled(out, k, seed, trace, background);
  tbb::parallel_for(0, camera.height, [&](int y) {
    for (int x = 0; x < camera.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * camera.width + x;
      Vec3 d;
      SurfaceHit s;
      SpatialSample& sample = out.samples[p];
      if (!trace(x + 0.5, y + 0.5, d, s)) {
        background(sample, d);
        continue;
      }
      sample = s.sample;
      out.pixel_mesh[p] = s.mesh;
      out.pixel_edge[p] = static_cast<float>(s.max_edge);
    }
  });
  return out;
}

}  // namespace prt
