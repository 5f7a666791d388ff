// The BRDF in-out factorisation of a glossy material (Huang & Ramamoorthi 2010 §3, Eq. 2;
// Liu et al. 2004; Wang et al. 2004), computed by the farm once per material
// (docs/glossy-transport.md):
//
//   M[o][l] = ρ̃(ω_l, ω_o) = [k_d/π + k_s·f_s(ω_l, ω_o)]·max(0, n·ω_l)   (local frame, n = +z)
//
// tabulated at the cell centres of a view_n² view grid and an svd_light_n² light grid, both
// equal-area (formats/glossy_factors.h, so the plain SVD minimises the L² error over the two
// hemispheres); the truncated SVD M ≈ Σ_{i<m} σ_i u_i v_iᵀ gives g_i = σ_i·u_i on the view grid,
// and f_i(ω) = Σ_o u_i(o)·ρ̃(ω, ω_o) / σ_i, evaluated exactly at the centres of a finer
// light_n² grid (what the sampler looks up per ray). The SVD comes from the eigenvectors of the
// view_n² × view_n² matrix M·Mᵀ. Signs: Σ_o g_i(o) ≥ 0. Deterministic (single-threaded linear
// algebra, per-entry parallel BRDF evaluation).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "formats/glossy_factors.h"
#include "runtime/brdf.h"
#include "worker/glossy_pixels.h"
#include "worker/transport_sampler.h"

namespace prt {

struct FactorisationOptions {
  int terms = 4;
  int view_n = 32;
  int svd_light_n = 64;
  int light_n = 128;
  // Directions of the error check (both sides), drawn by a fixed seed off the grids.
  int check_views = 512;
  int check_lights = 4096;
};

// The material's diffuse[0] and specular[0] are k_d and k_s (GlossyPixels' convention: the
// colour is the mesh weight w). relative_error is the error of what the sampler and the
// runtime evaluate, Σ_i G_i·F_i through the tables' bilinear lookups, against ρ̃ at random
// directions: ‖ρ̃ − Σ G F‖ / ‖ρ̃‖ over the check pairs (LookupError). Throws
// std::invalid_argument on terms outside 1…16 or grids outside 2…512. `truncation`, when given,
// receives TruncationErrors(material, options, 16) from the same SVD.
BrdfFactors FactorBrdf(const Material& material, const FactorisationOptions& options,
                       std::vector<double>* truncation = nullptr);

// The lookup error of the first `terms` (1…factors.terms) of `factors`: the truncated SVD's
// leading terms are the best m-term factorisation for every m, so one factorisation with m = 16
// answers every smaller m. The check directions come from options.check_views/check_lights.
double LookupError(const Material& material, const BrdfFactors& factors, int terms,
                   const FactorisationOptions& options);

// The truncation error alone, ‖M − M_m‖_F / ‖M‖_F on the SVD grid, for m = 1…max_terms
// (index m − 1): how fast the factorisation converges (bench and report).
std::vector<double> TruncationErrors(const Material& material, const FactorisationOptions& options,
                                     int max_terms);

// The factor table of a vertex run (docs/glossy-transport.md): one BrdfFactors per glossy mesh
// of `glossy` (ResolveGlossyMaterials; its materials carry k_d and k_s), every mesh's weight w.
// Empty (terms 0) when no mesh is glossy. `truncation`, when given, receives each factor's
// truncation errors (m = 1…16, FactorBrdf's), in factor order.
GlossyFactorTable FactorGlossyMeshes(const GlossyPixels& glossy,
                                     const FactorisationOptions& options,
                                     std::vector<std::vector<double>>* truncation = nullptr);

// A vertex run's samples with terms: the vertices once per term, term-major (sample t·V + v is
// vertex v's term t). A glossy mesh's vertex names its factors and term; a diffuse mesh's vertex
// is its ordinary (Lambert) row in term 0 and a zero row (background: nothing traced) after it.
std::vector<SpatialSample> TermSamples(const std::vector<SpatialSample>& vertices,
                                       const SceneGeometry& geometry,
                                       const GlossyFactorTable& table);
// Each of those samples' mesh (the farm's row groups).
std::vector<uint32_t> TermSampleMeshes(const SceneGeometry& geometry, int terms);

// A short description of the material ("ggx r=0.35 kd=0.4 ks=0.6").
std::string DescribeMaterial(const Material& material);

}  // namespace prt
