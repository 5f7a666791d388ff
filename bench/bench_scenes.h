// Shared by the benchmark programs: the benchmark scenes (the default scene and real meshes on a
// ground plane), the real environment maps, relit radiance B = albedo ⊙ (T·L), the relative RMS
// error every accuracy figure uses, and rendering relit vertices to an image.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "bench/bench_scene.h"
#include "vocabulary/envmap.h"
#include "vocabulary/image_io.h"
#include "vocabulary/scene.h"

namespace prt::bench {

// The real environment maps used for accuracy figures, resampled to n: sunrise, city, studio,
// interior (Blender's, from the data folder).
struct NamedEnvironment {
  std::string name;
  CubemapRgb cube;
};
std::vector<NamedEnvironment> BenchEnvironments(int n,
                                                const std::vector<std::string>& names = {
                                                    "sunrise", "city", "studio", "interior"});

// Relit radiance per sample (3 floats per sample): B_s = albedo_s ⊙ Σ_j T[s][j]·L_j, in double.
// `rows` is samples × texels, row-major.
std::vector<float> RelitRadiance(const SceneGeometry& geometry, const std::vector<float>& rows,
                                 const CubemapRgb& light);
// The same with one albedo per sample (an image run's pixels: their meshes', 0 for background).
std::vector<float> RelitRadiance(std::span<const Rgb> albedo, const std::vector<float>& rows,
                                 const CubemapRgb& light);

// Relative RMS error ‖B − B_ref‖ / ‖B_ref‖ over samples [first, last) and all three channels.
double RelativeRmsError(const std::vector<float>& b, const std::vector<float>& ref,
                        std::size_t first, std::size_t last);

// [first, last) sample range of the scene's meshes (not ground) and of the ground.
struct SampleRanges {
  std::size_t model_first = 0, model_last = 0, ground_first = 0, ground_last = 0;
};
SampleRanges RangesOf(const SceneGeometry& geometry);

// Rasterises the scene from its camera with the given per-sample colours (3 floats per sample),
// over the environment as background when `background` is non-null.
ImageRgb RenderVertexColours(const SceneDescription& scene, const SceneGeometry& geometry,
                             const std::vector<float>& rgb, const CubemapRgb* background);

// Small helpers the benchmark programs share: a comma-separated list, the process's CPU seconds
// (all threads: the ratio of two CPU times is robust on a shared machine), a dot product in
// double, and `count` distinct vertices of [first, last) by a seeded shuffle, sorted.
std::vector<std::string> Split(const std::string& s);
double CpuSeconds();
double DotRow(const float* a, const float* b, std::size_t n);
std::vector<uint64_t> PickVertices(uint64_t first, uint64_t last, std::size_t count, uint64_t seed);

// Figure 2 of Huang & Ramamoorthi 2010: per-sample colours showing where the dense vertices went,
// coloured by the local rank estimated there (false colour, 0 … the largest rank); dense
// vertices with no rank estimate (the initial random set) white, sparse vertices grey.
std::vector<float> DenseVertexColours(const std::vector<uint8_t>& is_dense,
                                      const std::vector<int>& local_rank);

}  // namespace prt::bench
