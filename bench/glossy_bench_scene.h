// What the glossy benchmarks share (glossy_bench, prt-tp-bench): a benchmark scene's per-vertex
// visibility maps traced with the worker's VisibilitySampler (or read from the cache an earlier
// run wrote), the per-vertex arrays Algorithm 1 of Inger et al. 2013 reads, a camera flyby, and
// the image PSNR of the paper's Figure 5 (displayed images, pixels the meshes cover).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/visibility_blocks.h"
#include "vocabulary/image_io.h"
#include "vocabulary/scene.h"

namespace prt::bench {

struct GlossyBenchScene {
  std::string name;
  SceneDescription scene;
  std::vector<Vec3> positions, normals;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<uint16_t> material_index;  // 0: the model's meshes, 1: the ground
  Rgb model_albedo{}, ground_albedo{};
  VisibilityBlocks visibility;
  double trace_seconds = 0;
  uint64_t rays_traced = 0;
  bool from_cache = false;
};

// The benchmark scene `name` (bench_scene.h) with visibility at resolution n, traced (1 bit,
// the sampler's defaults) or read from <cache_dir>/<name>_n<n>.visb (+ .time) when present;
// a traced map set is written there. Throws InputError on a cache that does not fit the scene.
GlossyBenchScene LoadGlossyBenchScene(const std::string& name, int n, const std::string& cache_dir);

// A flyby: the scene camera's eye turned about the vertical through its target, from −50° to
// +50° over `views` views (the eye's height varying a little).
std::vector<Camera> Flyby(const Camera& base, int views);
// A full orbit: `frames` eyes turned by 360°/frames about the vertical through the target.
std::vector<Camera> Orbit(const Camera& base, int frames);

// A rasterised frame and which pixels a mesh covers.
struct GlossyFrame {
  ImageRgb image;
  std::vector<uint8_t> covered;
};
GlossyFrame RenderGlossyFrame(const Camera& cam, const std::vector<Vec3>& positions,
                              const std::vector<std::array<uint32_t, 3>>& triangles,
                              const std::vector<float>& rgb);

// Image PSNR. The paper (§5, Figure 5) reports "the PSNR of our result" on the displayed image
// against the reference image without further definition; we take the displayed-image
// convention: both images tone-mapped the same way (exposure putting the reference's 99th
// percentile of covered pixels at 1, clamp to [0, 1], sRGB encoding, i.e. the 8-bit PNG values /
// 255), peak 1, MSE over the three channels of the pixels the meshes cover (background pixels,
// identical in both, are left out: the figure does not depend on how much sky the camera sees).
// Also: the whole frame (background included, as a PSNR of the full PNG would be) and a linear
// HDR PSNR (no tone mapping, peak = the reference's brightest covered pixel), which also sees
// errors in highlights that the displayed image clamps.
struct PsnrSet {
  double covered = 0, frame = 0, linear = 0;
  PsnrSet& operator+=(const PsnrSet& o) {
    covered += o.covered;
    frame += o.frame;
    linear += o.linear;
    return *this;
  }
};
double ExposureOf(const GlossyFrame& ref);
PsnrSet Psnr(const GlossyFrame& test, const GlossyFrame& ref, double exposure);

}  // namespace prt::bench
