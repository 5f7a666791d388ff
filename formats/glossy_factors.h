// Glossy vertex transport: the BRDF in-out factorisation (Huang & Ramamoorthi 2010 §3, Eq. 2–3;
// Liu et al. 2004, Wang et al. 2004) and run/glossy.prtf, the file that carries it from the farm
// to the pack and the runtime (docs/glossy-transport.md). No MPI, no Embree, no Eigen: the
// runtime looks factors up through this header; worker/brdf_factorisation.h computes them.
//
// A glossy material's cosine-weighted BRDF, in the local frame of a vertex,
//   ρ̃(ω, ω_o) = [k_d/π + k_s·f_s(ω, ω_o)]·max(0, n·ω) ≈ Σ_{i<m} g_i(ω_o)·f_i(ω)      (Eq. 2)
// so that the farm bakes m view-independent rows per vertex, T_i(x, ω) = V(x, ω)·f_i(ω), and the
// runtime relights B(x, ω_o) = w ⊙ Σ_i g_i(ω_o)·(T_i·L) (Eq. 3), w = albedo + specular.
//
// Directions are tabulated on the upper hemisphere through an equal-area square: Shirley and
// Chiu's concentric map of [0,1]² to the unit disk, then the disk to the hemisphere by
// z = 1 − r², (x, y) = d·√(2 − r²) (Lambert's azimuthal equal-area projection), so every cell of
// an n×n grid has the solid angle 2π/n². Cell (x, y) has its centre at ((x+½)/n, (y+½)/n) and
// index y·n + x. Tables are read with bilinear interpolation between cell centres (clamped at
// the border, which is the horizon).
//
// The local frame: n the shading normal, t the fixed axis a = (1, √2, √3)/√6 projected onto the
// tangent plane and normalised (a' = (√3, −1, √2)/√6 where a is within 0.06° of ±n), b = n × t.
// Any frame works for an isotropic BRDF as long as the farm (f_i) and the runtime (g_i) build
// the same one from the same normal; this one is continuous except in two tiny caps, where
// OrthonormalBasis (brdf.h's shading frame) flips across the whole z = 0 great circle.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// The equal-area square ↔ hemisphere maps. u, v in [0, 1]; the direction is unit with z ≥ 0.
// A direction below the horizon (z < 0) maps as if it were on it.
Vec3 HemisphereFromSquare(double u, double v);
void SquareFromHemisphere(const Vec3& d, double& u, double& v);

struct FactorFrame {
  Vec3 normal, tangent, bitangent;
  Vec3 ToLocal(const Vec3& w) const { return {Dot(w, tangent), Dot(w, bitangent), Dot(w, normal)}; }
};
// The frame above from a (not necessarily unit) normal; a zero normal gives +Y.
FactorFrame MakeFactorFrame(const Vec3& normal);

// One material's factors: m terms, g on a view_n² grid, f on a light_n² grid.
struct BrdfFactors {
  int terms = 0;
  int view_n = 0;
  int light_n = 0;
  std::vector<float> g;  // terms × view_n², term-major
  std::vector<float> f;  // terms × light_n², term-major (empty in a pack: only the farm needs f)
  // ‖M − Σ_{i<m} g_i f_iᵀ‖_F / ‖M‖_F on the factorisation's grid (worker/brdf_factorisation.h).
  double relative_error = 0;
  // What was factored (for messages and report.json): brdf name and its parameters as text.
  std::string description;
  // Bilinear lookups; the direction is in the local frame (FactorFrame::ToLocal), any length.
  double G(int term, const Vec3& view_local) const;
  double F(int term, const Vec3& light_local) const;
  // All m g_i at once (out: terms values).
  void GAll(const Vec3& view_local, float* out) const;
};

// run/glossy.prtf: the factors of every glossy mesh of a vertex run.
struct GlossyFactorTable {
  int terms = 0;
  // Per mesh (SceneGeometry order): the index of its factors in `factors`, or kDiffuseMesh;
  // and the weight w its relit radiance is multiplied by (albedo + specular; the albedo for a
  // diffuse mesh).
  std::vector<uint32_t> mesh_factor;
  std::vector<Rgb> mesh_weight;
  std::vector<BrdfFactors> factors;
  static constexpr uint32_t kDiffuseMesh = 0xFFFFFFFFu;
  bool glossy(std::size_t mesh) const { return mesh_factor[mesh] != kDiffuseMesh; }
};

// Bytes of the table (with_f = false leaves every f out: what a pack carries). Layout in
// docs/glossy-transport.md: magic "PRTGLOS1", uint32 terms, uint32 mesh count M, uint32 factor
// count F, uint32 flags (bit 0: f present), M × (uint32 factor, float32[3] weight), F × (uint32
// view_n, uint32 light_n, float64 relative error, uint32 description length + bytes, float32
// g[terms·view_n²], float32 f[terms·light_n²] when present), uint64 XXH64 of everything before.
std::string SerializeGlossyFactors(const GlossyFactorTable& table, bool with_f);
// Safe on hostile input: throws InputError naming `name` on a bad magic, checksum, count, size
// (terms 1…16, grids 2…512, every factor index < F, every value finite, weights ≥ 0).
GlossyFactorTable ParseGlossyFactors(std::string_view bytes, const std::string& name);

}  // namespace prt
