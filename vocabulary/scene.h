// The scene description (a TOML file, specified in docs/scene-format.md) and the world-space
// geometry built from it. Spatial samples are numbered in this order: the scene's meshes in the
// order the file lists them, each mesh's vertices in its file's order, then the ground plane's
// grid vertices (row-major, see docs/scene-format.md). Image-relighting scenes number camera
// pixels row-major from the top-left instead.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "vocabulary/mesh.h"
#include "vocabulary/vec3.h"

namespace prt {

using Rgb = std::array<float, 3>;

// Fit a mesh into a box standing on the ground: its bounding box is scaled uniformly so that its
// largest extent equals `size`, rotated so that `up_axis` becomes +Y, centred on `center` in x/z,
// and moved so that its lowest point rests on y = ground height.
struct FitBox {
  double size = 1.0;
  Vec3 center{0, 0, 0};
  std::string up_axis = "+y";  // one of +x −x +y −y +z −z
};

struct MeshInstance {
  std::string name;
  std::string path;         // resolved relative to the scene file
  Rgb albedo{0.8f, 0.8f, 0.8f};
  std::optional<FitBox> fit;
  // Applied after fit, in this order: scale, rotate (degrees about x, y, z), translate.
  double scale = 1.0;
  Vec3 rotate_deg{0, 0, 0};
  Vec3 translate{0, 0, 0};
  bool flip_winding = false;  // for inward-wound meshes
};

struct GroundPlane {
  bool enabled = false;
  double height = 0.0;          // y of the plane
  Vec3 center{0, 0, 0};         // x and z used
  double size = 4.0;            // side length
  int resolution = 64;          // grid vertices per side
  Rgb albedo{0.8f, 0.8f, 0.8f};
};

struct Camera {
  Vec3 eye{0, 1, 4};
  Vec3 target{0, 0.5, 0};
  Vec3 up{0, 1, 0};
  double fov_deg = 40.0;  // vertical
  int width = 640;
  int height = 480;
};

enum class SpatialSamples { kVertices, kCameraPixels };

struct SamplingSettings {
  int rays_per_texel = 4;   // stratified jittered occlusion rays per cubemap texel
  uint64_t seed = 1;
  std::string method = "brute";  // brute | sparse
};

// Huang & Ramamoorthi 2010 parameters (the paper's values as defaults; docs/scene-format.md).
struct SparseSettings {
  double initial_fraction = 0.05;
  double dense_budget = 0.25;
  int iterations = 4;
  double radius = 0.1;      // relative to the scene's bounding-box diagonal
  int max_neighbors = 40;
  int features = 350;       // at n = 32, scaled with n²
  double lambda = 1e-3;
  uint64_t seed = 1;
};

struct CompressionSettings {
  std::string row_wavelet = "haar";        // haar | d4
  std::string column_wavelet = "legall53"; // legall53 | cdf97
  std::string scheme = "adaptive4d";       // 2d | 4d | adaptive4d
  int bits = 9;
  double keep_fraction = 0.05;             // non-linear approximation budget per column
};

struct SceneDescription {
  std::string file;          // the scene file itself
  std::string name = "scene";
  int cubemap_n = 32;
  SpatialSamples samples = SpatialSamples::kVertices;
  std::vector<MeshInstance> meshes;
  GroundPlane ground;
  Camera camera;
  SamplingSettings sampling;
  SparseSettings sparse;
  CompressionSettings compression;
  std::vector<std::string> environments;  // resolved paths, for the demo and benchmarks
};

// Parses and validates a scene file. Unknown keys, wrong types and out-of-range values throw
// prt::InputError naming the file and the line.
SceneDescription LoadSceneFile(const std::string& path);
// Same, from text (for tests and embedded scenes); `name` is used in error messages and relative
// paths resolve against `base_dir`.
SceneDescription ParseScene(const std::string& text, const std::string& name,
                            const std::string& base_dir);

// One world-space mesh of the scene with its material.
struct SceneMesh {
  std::string name;
  TriangleMesh mesh;   // world space; normals unit
  Rgb albedo{0.8f, 0.8f, 0.8f};
  bool is_ground = false;
  int grid_resolution = 0;  // ground only: grid vertices per side
};

struct SceneGeometry {
  std::vector<SceneMesh> meshes;   // scene meshes in file order, ground plane last
  Vec3 bounds_min{0, 0, 0};
  Vec3 bounds_max{0, 0, 0};
  std::size_t vertex_count() const;
  double diagonal() const { return Length(bounds_max - bounds_min); }
};

// Loads every mesh, applies fit and transforms, builds the ground grid.
SceneGeometry BuildSceneGeometry(const SceneDescription& scene);

// A regular ground grid of res×res vertices, row-major with x fastest, spanning
// [cx − s/2, cx + s/2] × [cz − s/2, cz + s/2] at y = height, normals +Y, two triangles per cell.
TriangleMesh MakeGroundGrid(const GroundPlane& ground);

}  // namespace prt
