// The scene description (a TOML file, specified in docs/scene-format.md) and the world-space
// geometry built from it. Spatial samples are numbered in this order: the scene's meshes in the
// order the file lists them, each mesh's vertices in its file's order, then the ground plane's
// grid vertices (row-major, x fastest, see docs/scene-format.md). Image-relighting scenes number
// camera pixels row-major from the top-left instead.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "vocabulary/mesh.h"
#include "vocabulary/scene_geometry.h"
#include "vocabulary/vec3.h"

namespace prt {

// Fit a mesh into a box standing on the ground: the mesh is rotated so that `up_axis` becomes
// +Y, scaled uniformly so that the largest extent of its bounding box equals `size`, and moved
// so that the centre of the box's bottom face lies at `center` (by default the ground's centre
// at ground height, so the mesh's lowest point rests on the ground).
struct FitBox {
  double size = 1.0;
  Vec3 center{0, 0, 0};        // bottom-face centre of the fitted box
  std::string up_axis = "+y";  // one of +x -x +y -y +z -z
};

// A mesh's material for glossy relighting, docs/scene-format.md "Glossy materials": the mesh's
// albedo is the diffuse part, `specular` weighs the lobe of `brdf` (runtime/brdf.h). Vertex
// transport runs bake it as [glossy] terms rows per vertex (docs/glossy-transport.md); image runs
// bake it into the rows of the pixels that see the mesh (docs/image-relighting.md, "Glossy
// pixels"); visibility runs relight it by triple products.
struct GlossyMaterialSettings {
  std::string brdf = "lambert";  // lambert | phong | ashikhmin-shirley | ggx
  Rgb specular{0.f, 0.f, 0.f};   // albedo + specular ≤ 1 per channel
  double exponent = 1.0;         // Phong s; Ashikhmin–Shirley n_u
  double exponent_v = 1.0;       // Ashikhmin–Shirley n_v (default: exponent)
  double roughness = 0.5;        // GGX roughness r in (0, 1], α = r² (Blender, glTF, Unreal)
};

struct MeshInstance {
  std::string name;
  std::string path;           // as written in the scene file
  std::string resolved_path;  // where it was found at parse time ("" if not found then)
  int line = 0;               // line of the [[mesh]] entry, for messages
  Rgb albedo{0.8f, 0.8f, 0.8f};
  std::optional<FitBox> fit;
  // Applied after fit, in this order, about the world origin: uniform scale, rotation
  // (degrees about x, then y, then z), translation.
  double scale = 1.0;
  Vec3 rotate_deg{0, 0, 0};
  Vec3 translate{0, 0, 0};
  bool flip_winding = false;  // reverse triangles and negate normals (inward-wound meshes)
  GlossyMaterialSettings glossy;
};

struct GroundPlane {
  bool enabled = false;  // true when the scene has a [ground] table, unless it says otherwise
  double height = 0.0;   // y of the plane
  Vec3 center{0, 0, 0};  // x and z used (the file gives center = [x, z])
  double size = 4.0;     // side length
  int resolution = 64;   // grid vertices per side
  Rgb albedo{0.8f, 0.8f, 0.8f};
  GlossyMaterialSettings glossy;
};

struct Camera {
  Vec3 eye{0, 1, 4};
  Vec3 target{0, 0.5, 0};
  Vec3 up{0, 1, 0};
  double fov_deg = 40.0;  // vertical
  int width = 640;
  int height = 480;
  // Image relighting: k×k stratified primary rays per pixel footprint (box filter), 1…16; 1 is
  // one ray through the pixel centre (docs/image-relighting.md, "Supersampling").
  int supersample = 1;
};

enum class SpatialSamples { kVertices, kCameraPixels };

struct SamplingSettings {
  int rays_per_texel = 4;  // stratified jittered occlusion rays per cubemap texel
  uint64_t seed = 1;
  std::string method = "sparse";  // sparse | brute (the reference)
  // What prt-farm computes: the transport matrix, or per-vertex visibility cubemaps for glossy
  // triple-product relighting ([visibility] settings, docs/farm.md "Visibility job").
  std::string job = "transport";  // transport | visibility
  // Interreflection (docs/interreflection.md): diffuse bounces of light after the direct term,
  // T = T⁰ + T¹ + … + Tᴷ. 0: direct light only (the transport of prt-farm before bounces).
  // PRTCmdLine's NumBounces = 1 means direct only; prtfarm's `bounces` counts interreflections.
  int bounces = 0;
  // How the bounces are computed: "gather" (bounce gathering from the vertices' rows, one farm
  // phase per bounce) or "path" (per-element Monte-Carlo path tracing, the reference).
  std::string estimator = "gather";
  int indirect_n = 0;       // cubemap n of the bounce rows (power of two ≤ n); 0: n/4, at least 1
  int gather_paths = 1024;  // directions per vertex and bounce (gather), paths per vertex (path)
  // Gather: bounce 1 traces T⁰ at hits closer than this × their triangle's longest edge on a
  // triangle twice as coarse as the vertex's own (docs/interreflection.md "Near field"); 0: off.
  double near_field = 1.0;
};

// Per-vertex binary (or anti-aliased) visibility cubemaps, Inger et al. 2013 §4.2
// (worker/visibility_sampler.h); used when [sampling] job = "visibility".
struct VisibilitySettings {
  int n = 64;           // cubemap resolution: 16, 32, 64, 128 or 256
  int supersample = 1;  // rays per texel side (1: one ray through the texel centre)
  int bits = 1;         // 1: binary; 2…8: anti-aliased levels (needs supersample > 1)
};

// Huang & Ramamoorthi 2010 parameters, the paper's values as defaults (docs/scene-format.md
// gives the section each comes from).
struct SparseSettings {
  double initial_fraction = 0.05;  // §4.1: first iteration picks "typically 5%" at random
  double dense_budget = 0.25;      // §7, Fig. 8/9: about 25% of vertices become dense
  int iterations = 4;              // §4.1 "several iterations" (no number given)
  double radius = 0.035;           // §5.3: 0.2 units on a 4-unit ground, as a fraction of the
                                   // scene's bounding-box diagonal (0.2 / 5.7)
  int max_neighbors = 40;          // §5.1: "usually 10–40" dense neighbours
  int features = 350;              // §7: 350 directions at n = 32; default scales with n²
  double lambda = 1e-3;  // L1 weight relative to λ_max = ‖2Aᵀb‖∞ (not in the paper)
  int window = 7;        // §4.2: a dense row's feature test looks at the grid in a 7×7 window
  // Not in the paper (docs/sparse-precomputation.md, measured): the partition-of-unity equation's
  // weight, and the relative residual on the traced features above which a vertex is made dense.
  double unity_weight = 1.0;
  double max_residual = 0.3;
  double min_normal_cos = 0.5;  // neighbours whose normal is farther than 60° are not used
  // The dense budget driven by rank (worker/sparse_precomputation.h, SparsePlan::rank_floor):
  // candidates whose dense neighbours' local rank is at most this are covered and dense_budget
  // is a cap; 0: the fixed budget (the paper's). docs/sparse-precomputation.md measures 2.
  int rank_floor = 2;
  // With bounces: "combination" (a sparse vertex's bounce rows are the combination of its dense
  // neighbours' that its direct row was reconstructed with; only dense vertices gather or trace
  // paths), "features" (sparse vertices evaluate their feature texels, L1) or
  // "full" (every vertex does). docs/sparse-precomputation.md, "With interreflection".
  std::string indirect = "combination";
  // indirect = "features" with gathering: the directions a sparse vertex gathers its features
  // with (0: [sampling] gather_paths). 128 measured about the full count's accuracy at a
  // fraction of its cost (docs/sparse-precomputation.md).
  int feature_paths = 128;
  uint64_t seed = 1;
};

struct CompressionSettings {
  std::string row_wavelet = "haar";         // haar | d4
  std::string column_wavelet = "legall53";  // legall53 | cdf97
  std::string scheme = "adaptive4d";        // 2d | 4d | adaptive4d | cpca
  int bits = 9;
  double keep_fraction = 0.05;  // non-linear approximation budget (fraction of T)
  std::string budget =
      "global";          // global (one threshold, the default) | column (paper: N per column)
  int light_weight = 0;  // global budget: row level l weighted by 2^(−light_weight·l/2)
  // A mesh's column order: a 6D Hilbert curve through (position, normal), the normal's axes
  // spanning this times the mesh's largest extent; 0 = position only (worker/column_order.h).
  double order_normal_weight = 2.0;
  // scheme = "cpca" (docs/cpca.md): clusters K, PCA basis vectors S per cluster, and the bits of
  // the per-row coefficients' quantiser. The basis vectors keep keep_fraction of the 6n² terms
  // each, quantised with `bits`.
  int clusters = 64;
  int bases = 16;
  int coefficient_bits = 16;
};

// Glossy vertex transport (docs/glossy-transport.md): the BRDF in-out factorisation's terms m
// (Huang & Ramamoorthi 2010 §3, Eq. 2; their §7 uses 4). A vertex transport run whose scene has
// a glossy mesh bakes m rows per vertex.
struct GlossyTransportSettings {
  int terms = 4;
};

struct SceneDescription {
  std::string file;  // the scene file itself (or the name given to ParseScene)
  std::string name = "scene";
  int cubemap_n = 32;
  SpatialSamples samples = SpatialSamples::kVertices;
  std::vector<MeshInstance> meshes;
  GroundPlane ground;
  Camera camera;
  SamplingSettings sampling;
  SparseSettings sparse;
  CompressionSettings compression;
  VisibilitySettings visibility;
  GlossyTransportSettings glossy;
  // Environment maps for the demo and benchmarks: resolved where found at parse time, else as
  // written (they are only checked when used: call ResolveScenePath for a precise error).
  std::vector<std::string> environments;
  // Folders a relative path is tried in, in order (the scene's folder, $PRT_DATA_PATH, extra
  // folders given by the caller); after them the path is tried as given.
  std::vector<std::string> search_dirs;
};

// Parses and validates a scene file. Unknown keys, wrong types and out-of-range values throw
// prt::InputError naming the file and the line. Paths resolve relative to the scene file's
// folder, then each folder of $PRT_DATA_PATH (colon-separated), then `extra_data_dirs`, then as
// given; files need not exist yet (BuildSceneGeometry and the users of environments check).
SceneDescription LoadSceneFile(const std::string& path,
                               const std::vector<std::string>& extra_data_dirs = {});
// Same, from text (for tests and embedded scenes); `name` is used in error messages and relative
// paths resolve against `base_dir` (may be empty), $PRT_DATA_PATH, then `extra_data_dirs`.
SceneDescription ParseScene(const std::string& text, const std::string& name,
                            const std::string& base_dir,
                            const std::vector<std::string>& extra_data_dirs = {});

// The default scene (the CGAL bunny fitted on a 64×64 ground grid under sunrise.exr and
// city.exr, n = 32), byte-identical to scenes/default.toml, so binaries run without a file.
const std::string& DefaultSceneText();
// ParseScene(DefaultSceneText(), "<default scene>", "", {data_dir}): `data_dir` is the folder
// holding meshes/ and envmaps/ (a compiled-in default, e.g. the build tree's data/).
SceneDescription LoadDefaultScene(const std::string& data_dir);

// Folders searched for a relative path: base_dir (if not empty), $PRT_DATA_PATH, extra_dirs.
std::vector<std::string> DataSearchDirs(const std::string& base_dir,
                                        const std::vector<std::string>& extra_dirs);
// The first existing file among dir/path for each dir, then path as given (absolute paths only
// as given); "" if none exists. `tried` (optional) receives every candidate looked at.
std::string FindDataFile(const std::string& path, const std::vector<std::string>& dirs,
                         std::vector<std::string>* tried = nullptr);
// FindDataFile over scene.search_dirs; throws InputError naming the scene file (and `line` when
// > 0) and listing every place it looked.
std::string ResolveScenePath(const SceneDescription& scene, const std::string& path, int line = 0);

// Loads every mesh, applies flip_winding, fit, then scale/rotate/translate (normals rotated
// with the mesh), appends the ground grid last and computes the bounds. Throws InputError
// naming the scene file, the [[mesh]] line and the mesh on failure.
SceneGeometry BuildSceneGeometry(const SceneDescription& scene);

// The world transform of one instance given its mesh-space bounding box:
// p_world = translate + R·(scale·(fit_scale·U·p + fit_offset)), n_world = normalize(R·U·n),
// with U the rotation taking fit.up_axis to +Y (identity without fit).
void TransformInstance(const MeshInstance& instance, TriangleMesh& mesh);

// A regular ground grid of res×res vertices, row-major with x fastest (vertex iz·res + ix at
// x = cx − s/2 + s·ix/(res−1), z = cz − s/2 + s·iz/(res−1)), at y = height, normals +Y, two
// triangles per cell wound counter-clockwise seen from above (+Y).
TriangleMesh MakeGroundGrid(const GroundPlane& ground);

}  // namespace prt
