// The Monte-Carlo error of relit radiance, estimated from the rays already traced
// (docs/farm.md, "Accuracy estimates"). For vertex v of mesh m with albedo ρ_m, environment L
// (the lighting cubemap, DESIGN.md "Conventions") and channel c,
//   B_v,c = ρ_m,c · Σ_j T[v][j] · L_j,c
// and the texels' estimates being independent,
//   Var(B_v,c) = ρ_m,c² · Σ_j L_j,c² · Var(T[v][j]),
// so summed over the mesh it needs only S[m][j] = Σ_v Var(T[v][j]) (TransportVariance):
//   Σ_{v∈m} Var(B_v,c) = ρ_m,c² · Σ_j L_j,c² · S[m][j].
// The relative RMS error of B over a mesh is then  sqrt(Σ_c Σ_v Var(B_v,c) / Σ_c Σ_v B_v,c²),
// whose denominator this file accumulates from the rows (RadianceNormAccumulator).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "formats/transport_variance.h"
#include "vocabulary/envmap.h"

namespace prt {

// Σ_j L_j,c² · S[m][j] for each channel (the albedo not applied).
std::array<double, 3> MeshRadianceVariance(const TransportVariance& variance, std::size_t mesh,
                                           const CubemapRgb& light);

// Σ_{v∈m} (Σ_j T[v][j] · L_j,c)² for every light, mesh and channel, from rows of T fed in any
// order and any chunks (the sums are over rows; their order changes only the last bits).
class RadianceNormAccumulator {
 public:
  // channels 3: T has one row per colour channel (docs/interreflection.md), row c·V + v is
  // channel c of sample v and is relit by the light's channel c only.
  RadianceNormAccumulator(std::vector<CubemapRgb> lights, std::vector<uint64_t> mesh_rows,
                          int channels = 1);
  // `count` rows of 6n² floats starting at global row `first` (parallel over rows, TBB).
  void AddRows(uint64_t first, uint64_t count, const float* rows);
  // [light][mesh][channel]
  const std::vector<std::vector<std::array<double, 3>>>& norms() const { return norms_; }
  // The same flattened (light-major, then mesh, then channel), to add sums over processes, and
  // set from such a sum.
  std::vector<double> Flat() const;
  void Set(const std::vector<double>& flat);

 private:
  std::vector<CubemapRgb> lights_;
  std::vector<bool> grey_;            // the light's three channels are equal
  std::vector<uint64_t> mesh_first_;  // first row of each mesh, and the total at the end
  int channels_ = 1;
  std::vector<std::vector<std::array<double, 3>>> norms_;
};

}  // namespace prt
