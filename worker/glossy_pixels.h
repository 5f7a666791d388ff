// Glossy pixels of image relighting (docs/image-relighting.md, "Glossy pixels"): for a fixed
// camera a pixel's view direction ω_o is known when T is computed, so a pixel whose first hit
// has a glossy material (Phong, Ashikhmin–Shirley, GGX; runtime/brdf.h) gets its exact row
//   T(p, ω) = V(p, ω) · [k_d/π + k_s·f_s(ω, ω_o(p))] · max(0, n·ω)
// with no factorisation, and relights as B_c(p) = w_c · Σ_ω T(p, ω)·L_c(ω). The material's
// colours are split as albedo = k_d·w, specular = k_s·w with w = albedo + specular, so one row
// per pixel serves the three channels; this needs specular proportional to albedo (both grey,
// or the same hue), and ResolveGlossyPixels refuses other materials. No MPI here.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "runtime/brdf.h"
#include "vocabulary/scene.h"
#include "worker/transport_sampler.h"

namespace prt {

struct GlossyPixels {
  // Per mesh of the geometry (SceneGeometry::meshes order): the material the sampler weighs a
  // glossy pixel's rays with (diffuse = k_d and specular = k_s in every channel; Lambert for a
  // diffuse mesh), whether the mesh's pixels are glossy, and their weight w.
  std::vector<Material> materials;
  std::vector<uint8_t> glossy;
  std::vector<Rgb> weight;
  bool any() const;
};

// The glossy pixels of an image scene: a mesh (or the ground) is glossy when its brdf is not
// "lambert" and its specular is not 0. Throws InputError naming the scene file and the mesh
// when specular is not proportional to albedo. For a vertex scene every mesh is diffuse.
GlossyPixels ResolveGlossyPixels(const SceneDescription& scene, const SceneGeometry& geometry);
// The same for any scene (a vertex run's glossy meshes, docs/glossy-transport.md).
GlossyPixels ResolveGlossyMaterials(const SceneDescription& scene, const SceneGeometry& geometry);

// Marks the samples of pixels that see a glossy mesh (SpatialSample::glossy_material = the mesh
// index into GlossyPixels::materials, which GlossySampling::materials takes).
void MarkGlossyPixels(const GlossyPixels& glossy, std::span<const uint32_t> pixel_mesh,
                      std::vector<SpatialSample>& samples);

// What a bounce ray sees at each mesh of an image run with glossy pixels and bounces: a glossy
// mesh reflects its diffuse part plus its lobe's hemispherical reflectance, spread as if diffuse,
//   ρ_bounce = albedo + specular · ρ_hh(lobe) = w · (k_d + k_s · LobeReflectance(material)),
// (the vertices' support rows are diffuse: the lobe's energy is kept, not its direction;
// docs/image-relighting.md "Glossy pixels" measures it); a diffuse mesh its albedo.
std::vector<Rgb> BounceAlbedo(const GlossyPixels& glossy, const SceneGeometry& geometry);

// Bytes for the broadcast from rank 0 (same machine layout on every rank), and back. Parse
// throws std::runtime_error on a size that does not fit.
std::string SerializeGlossyPixels(const GlossyPixels& glossy);
GlossyPixels ParseGlossyPixels(const std::string& bytes);

}  // namespace prt
