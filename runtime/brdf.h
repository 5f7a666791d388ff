// BRDFs sampled on the fly per 16×16 cubemap block (Inger, Farbman & Lischinski 2013, §4.1 and
// Appendix A): no pre-rotated BRDF copies are stored; at each vertex and block the cosine-
// weighted BRDF ρ̃(ω) = ρ(ω, ω_o)·max(0, n·ω) is sampled at 1, 2×2 or 4×4 positions and projected
// onto the first 1, 4 or 16 DCT basis functions of the block (Eq. 4), or sampled at all 256
// texel centres where it is not band limited there.
//
// Every material is ρ̃_c(ω) = diffuse_c·DiffuseLobe(ω) + specular_c·SpecularLobe(ω) per colour
// channel c, so one scalar projection of each lobe serves all three channels:
//   DiffuseLobe  = max(0, n·ω) / π                                           (Lambert)
//   Phong        = (s + 2)/(2π) · max(0, r·ω)^s · max(0, n·ω),  r = 2(n·ω_o)n − ω_o
//                  (the normalised modified Phong lobe: ∫ lobe dω ≤ 1 for every ω_o)
//   Ashikhmin–Shirley (2000) anisotropic specular lobe, exponents (n_u, n_v) along the tangent
//                  and bitangent, without the Fresnel factor (specular_c scales it):
//                  √((n_u+1)(n_v+1))/(8π) · (n·h)^((n_u cos²φ_h + n_v sin²φ_h)/(1−(n·h)²))
//                  / ((h·ω)·max(n·ω, n·ω_o)) · max(0, n·ω)
//   GGX          Walter et al. 2007 microfacet lobe, α = roughness² (Blender, glTF, Unreal), no
//                  Fresnel (F = 1), separable Smith masking-shadowing; Blender Cycles' Glossy BSDF
//                  with the GGX distribution (docs/conventions.md, "The GGX material"):
//                  f_s = D(h)·G1(ω)·G1(ω_o) / (4 |n·ω| |n·ω_o|),  h = normalize(ω + ω_o)
//                  D(m) = α² / (π ((n·m)²(α² − 1) + 1)²)
//                  G1(v) = 2 / (1 + √(1 + α² tan²θ_v))
//                  and the lobe is f_s·max(0, n·ω) (0 where n·ω_o ≤ 0).
#pragma once

#include <array>
#include <cstdint>

#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

enum class BrdfModel : uint8_t { kLambert = 0, kPhong = 1, kAshikhminShirley = 2, kGgx = 3 };

struct Material {
  BrdfModel model = BrdfModel::kLambert;
  Rgb diffuse{0.8f, 0.8f, 0.8f};  // albedo of the Lambert part
  Rgb specular{0.f, 0.f, 0.f};    // weight of the specular lobe (diffuse + specular ≤ 1)
  double exponent = 1.0;          // Phong s; Ashikhmin–Shirley n_u
  double exponent_v = 1.0;        // Ashikhmin–Shirley n_v
  double roughness = 0.5;         // GGX r in (0, 1]: α = r²
};

// The material of a scene's [[mesh]] or [ground] keys (docs/scene-format.md, "Glossy
// materials"), every model included: diffuse = albedo, the lobe of g.brdf weighted by
// g.specular. Throws std::invalid_argument on an unknown brdf name.
Material MaterialOfSettings(const GlossyMaterialSettings& g, const Rgb& albedo);

// GGX pieces (Walter et al. 2007, Eq. 33 and 34), α = roughness²: the normal distribution D of
// a microfacet normal whose cosine with n is `cos_m`, and the Smith G1 of a direction whose
// cosine with n is `cos_v` (0 for cos ≤ 0). ∫ D(m)·(n·m) dm = 1 over the hemisphere.
double GgxDistribution(double alpha, double cos_m);
double GgxSmithG1(double alpha, double cos_v);

// The local frame at a vertex for one outgoing (view) direction.
struct ShadingFrame {
  Vec3 normal, tangent, bitangent;
  Vec3 view;     // ω_o, unit, from the vertex towards the eye
  Vec3 reflect;  // ω_o mirrored about the normal
};
// normal and view need not be unit (both are normalised); the tangent comes from
// OrthonormalBasis(normal).
ShadingFrame MakeShadingFrame(const Vec3& normal, const Vec3& view);

inline double DiffuseLobe(const ShadingFrame& f, const Vec3& w) {
  const double c = Dot(f.normal, w);
  return c > 0 ? c * 0.31830988618379067 : 0.0;
}
// The material's specular lobe with the cosine folded in (0 for Lambert); w unit.
double SpecularLobe(const Material& m, const ShadingFrame& f, const Vec3& w);
// ρ̃ of one channel: diffuse_c·DiffuseLobe + specular_c·SpecularLobe.
double CosineWeightedBrdf(const Material& m, const ShadingFrame& f, const Vec3& w, int channel);

bool HasSpecular(const Material& m);
// The lobe's hemispherical–hemispherical reflectance (specular weight 1):
//   ρ_hh = (1/π) ∫_H E(ω_o) cos θ_o dω_o,  E(ω_o) = ∫_H f_s(ω, ω_o) cos θ dω,
// the fraction of uniform (cosine-distributed) irradiance the lobe reflects. By quadrature: ω_o
// at the centres of 4×4 cosine-distributed strata, ω on a 512×512 grid uniform in (cos θ, φ).
// Accurate to about 1 % for lobes wider than 1° (GGX r ≥ 0.15). What an image run's glossy
// surface sends back when another surface's bounce ray reaches it (docs/image-relighting.md,
// "Glossy pixels"). 0 for Lambert.
double LobeReflectance(const Material& m);
// The exponent the sampling rules look at (Phong s, Ashikhmin–Shirley max(n_u, n_v); GGX the
// Phong exponent of the same peak width, 2/α² − 2, Walter et al. 2007 §5.2).
double EffectiveExponent(const Material& m);

// Appendix A: how many samples of the specular lobe a block needs (1, 4, 16 or 256), from the
// angle between the view direction and the block centre reflected about the normal, R:
//   no specular lobe:  1
//   s < 30:            4 if ∠(V, R) < π/4, else 1
//   30 ≤ s < 250:      16 if ∠ < π/8, 4 if π/8 ≤ ∠ < π/4, else 1
//   s ≥ 250:           256 if ∠ < π/8, 4 if π/8 ≤ ∠ < π/4 (not in the paper), else 1
int BrdfSamplingRate(const Material& m, const ShadingFrame& f, const Vec3& block_centre);
// The same with the exponent from which the lobe near the mirror direction takes all 256 samples
// instead of 16 (the paper: 250) as a parameter.
int BrdfSamplingRate(const Material& m, const ShadingFrame& f, const Vec3& block_centre,
                     double full_rate_exponent);

// The orthonormal 16×16 DCT-II of a block, position k = y·16 + x:
//   φ_u(x) = α_u cos(π(2x + 1)u / 32), α_0 = 1/4, α_u = √2/4,   F_uv = Σ_xy f(x, y) φ_u(x) φ_v(y)
// and Eq. 4's subsampled projection onto its first l×l functions (l = 1, 2, 4): f is sampled at
// the l×l continuous positions x_i = (i + ½)·16/l − ½ (the block centre for l = 1) and the
// l×l system Σ_uv A_uv φ_u(x_i) φ_v(y_j) = f(x_i, y_j) is solved with the precomputed inverse.
// Coefficient (u, v) is stored at index v·l + u.
class BlockDct {
 public:
  static float Basis(int u, int x);  // φ_u(x), u < 4, x < 16
  static double SamplePosition(int l, int i);
  // samples: l×l values (index j·l + i for position (x_i, y_j)); coeffs: l×l.
  static void Project(int l, const float* samples, float* coeffs);
  // The first 4×4 coefficients (index v·4 + u) of 256 block values.
  static void Forward16(const float* pixels, float* coeffs16);
  // 256 block values of the l×l coefficients.
  static void Reconstruct(int l, const float* coeffs, float* pixels);
};

}  // namespace prt
