// A .prtpack that holds per-vertex visibility (VISB sections) opened for glossy relighting under
// changing view, lighting and materials: the second asset kind of prtfarm (docs/viewer.md,
// "Glossy assets"). Each frame evaluates Algorithm 1 of Inger, Farbman & Lischinski 2013
// (runtime/triple_product.h) for every vertex towards the camera's eye, with the per-block
// lighting of runtime/block_lighting.h and the materials of the pack's META "materials"
// (docs/scene-format.md, "Glossy materials"). The runtime's C API relights glossy packs through
// it; prt-view's GlossySession (viewer/glossy_session.h) adds the rasteriser.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "formats/visibility_blocks.h"
#include "runtime/block_lighting.h"
#include "runtime/brdf.h"
#include "runtime/camera_metadata.h"
#include "runtime/triple_product.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"

namespace prt {

namespace pack {
class PackReader;
}  // namespace pack

// The Material of one mesh from its scene settings: `albedo` is the diffuse part; Lambert has no
// specular lobe. Throws std::invalid_argument on an unknown brdf name.
Material MaterialFromSettings(const GlossyMaterialSettings& settings, const Rgb& albedo);

// The per-mesh materials of a pack's META JSON ("materials": [{name, brdf, diffuse, specular,
// exponent, exponent_v}], pack mesh order). Meshes without an entry (or a pack without the key)
// are Lambert with `albedo[i]`. Throws prt::InputError(name, ...) on a malformed entry: unknown
// brdf, colour outside [0, 1], non-positive or non-finite exponent.
std::vector<Material> GlossyMaterialsFromMetadata(const std::string& metadata_json,
                                                  const std::vector<Rgb>& albedo,
                                                  const std::string& name);

class GlossyRelightSession {
 public:
  // Reads meshes, materials, metadata and every mesh's visibility. Throws prt::InputError naming
  // the file on: an unreadable or corrupt pack (PackReader's errors), no VISB sections.
  static std::unique_ptr<GlossyRelightSession> Open(const std::string& pack_path);
  // The same from a pack the caller already opened (`pack_path` names it in errors).
  static std::unique_ptr<GlossyRelightSession> FromReader(const pack::PackReader& reader,
                                                          const std::string& pack_path);

  GlossyRelightSession(const GlossyRelightSession&) = delete;
  GlossyRelightSession& operator=(const GlossyRelightSession&) = delete;
  virtual ~GlossyRelightSession();

  const std::string& path() const { return path_; }
  int cubemap_n() const { return visibility_.n; }
  std::size_t sample_count() const { return positions_.size(); }
  std::size_t mesh_count() const { return mesh_names_.size(); }
  const std::vector<std::string>& mesh_names() const { return mesh_names_; }
  // The scene's [camera] from the pack's metadata, else Camera{}.
  const Camera& camera() const { return camera_; }
  const VisibilityBlocks& visibility() const { return visibility_; }
  const CubemapBlocks& blocks() const { return *blocks_; }
  std::span<const Vec3> positions() const { return positions_; }
  std::span<const Vec3> normals() const { return normals_; }
  std::span<const std::array<uint32_t, 3>> triangles() const { return triangles_; }
  // One material per mesh (pack order); editable between frames.
  std::vector<Material>& materials() { return materials_; }
  const std::vector<Material>& materials() const { return materials_; }

  // The lighting of `cube` (resolution cubemap_n()) in the block representations.
  BlockLighting Lighting(const CubemapRgb& cube) const;
  // Outgoing radiance of every vertex towards `eye` (3 floats per vertex) by Algorithm 1, or by
  // the pixel-basis reference over all 6n² texels (RelightPixelBasisReference). Throws
  // NumericalError naming the pack and the vertex when the radiance overflows float.
  TripleProductStats Relight(const BlockLighting& light, const Vec3& eye, std::span<float> rgb,
                             const TripleProductOptions& options = {}) const;
  // Vertices [first, first + count) only (3·count floats), as Relight gives them.
  TripleProductStats RelightRange(const BlockLighting& light, const Vec3& eye, std::size_t first,
                                  std::size_t count, std::span<float> rgb,
                                  const TripleProductOptions& options = {}) const;
  void RelightReference(const BlockLighting& light, const Vec3& eye, std::span<float> rgb) const;

 protected:
  GlossyRelightSession() = default;
  // Reads the pack into this session (Open's work; GlossySession's Open calls it too).
  // `scene_toml_camera`: CameraFromMetadata's TOML fallback (runtime/camera_metadata.h).
  void Load(const pack::PackReader& reader, const std::string& pack_path,
            const SceneTomlCameraFn& scene_toml_camera = {});
  GlossyScene Scene() const;

 private:
  std::string path_;
  Camera camera_;
  VisibilityBlocks visibility_;
  std::unique_ptr<CubemapBlocks> blocks_;
  std::vector<std::string> mesh_names_;
  std::vector<Vec3> positions_, normals_;
  std::vector<std::array<uint32_t, 3>> triangles_;
  std::vector<uint16_t> material_index_;
  std::vector<Material> materials_;
};

}  // namespace prt
