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
#include <cstddef>
#include <cstdint>
#include <vector>

#include "formats/transport_variance.h"
#include "vocabulary/envmap.h"

namespace prt {

// An exact sum of doubles (Kulisch's long accumulator, "The Arithmetic of the Digital Computer",
// 1983): every finite v ≥ 0 added as an integer multiple of 2^-1074 held in 32-bit digits, so that
// the sum does not depend on the order its terms (or partial sums) are added in. Digits() is the
// sum as kFlatSize doubles — each digit below 2^32, then the sum of non-finite or negative terms —
// whose element-wise sum over fewer than 2^21 processes (MPI_SUM of doubles, any order) is exact
// and which SetDigits takes back.
class ExactSum {
 public:
  static constexpr std::size_t kDigits = 68;  // 2^-1074 … 2^1102
  static constexpr std::size_t kFlatSize = kDigits + 1;
  void Add(double v);
  void Add(const ExactSum& other);
  // The sum rounded to a double (from its top 96 bits: the same on every machine).
  double Value() const;
  std::vector<double> Digits() const;
  void SetDigits(const double* digits);  // kFlatSize values

 private:
  void Carry();
  std::array<uint64_t, kDigits> digits_{};
  uint64_t adds_ = 0;     // since the last Carry
  double special_ = 0.0;  // NaN, ±∞ and negative terms (none for rows checked finite)
};

// Σ_j L_j,c² · S[m][j] for each channel (the albedo not applied).
std::array<double, 3> MeshRadianceVariance(const TransportVariance& variance, std::size_t mesh,
                                           const CubemapRgb& light);

// Σ_{v∈m} (Σ_j T[v][j] · L_j,c)² for every light, mesh and channel, from rows of T fed in any
// order and any chunks: exact sums (ExactSum) of each row's square, so the result has the same
// bits whatever the order, the chunks or the number of processes (docs/farm.md, "Determinism").
class RadianceNormAccumulator {
 public:
  // channels 3: T has one row per colour channel (docs/interreflection.md), row c·V + v is
  // channel c of sample v and is relit by the light's channel c only. `sample_group`
  // (optional): each sample's mesh when the meshes' samples interleave (an image run's pixels);
  // mesh m must hold mesh_rows[m] of them.
  RadianceNormAccumulator(std::vector<CubemapRgb> lights, std::vector<uint64_t> mesh_rows,
                          int channels = 1, SampleGroupMap sample_group = nullptr);
  // `count` rows of 6n² floats starting at global row `first` (parallel over rows, TBB).
  void AddRows(uint64_t first, uint64_t count, const float* rows);
  // [light][mesh][channel]
  const std::vector<std::vector<std::array<double, 3>>>& norms() const { return norms_; }
  // The exact sums flattened (light-major, then mesh, then channel; ExactSum::kFlatSize doubles
  // each, ExactSum::Digits), to add over processes element by element (MPI_SUM: exact, in any
  // order), and set from such a sum.
  std::vector<double> Flat() const;
  void Set(const std::vector<double>& flat);

 private:
  std::vector<CubemapRgb> lights_;
  std::vector<bool> grey_;            // the light's three channels are equal
  std::vector<uint64_t> mesh_first_;  // first row of each mesh, and the total at the end
  SampleGroupMap sample_group_;       // or each sample's mesh
  int channels_ = 1;
  std::vector<ExactSum> exact_;                            // [light][mesh][channel], flattened
  std::vector<std::vector<std::array<double, 3>>> norms_;  // exact_ as doubles
  void UpdateNorms();
};

}  // namespace prt
