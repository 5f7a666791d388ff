// run/transport.variance (docs/transport-format.md, "transport.variance"): the Monte-Carlo
// variance of the rows of T, summed over each mesh's rows, per cubemap texel:
//   S[m][j] = Σ_{v ∈ mesh m} Var(T[v][j])
// with Var(T[v][j]) each traced texel's variance estimated from its own rays
// (TransportSampler::ComputeRow's variance output). Because the texels' estimates are
// independent, the variance of relit radiance summed over a mesh is, for any environment L and
// the mesh's albedo ρ_m,  Σ_{v∈m} Var(B_v,c) = ρ_m,c² · Σ_j L_j,c² · S[m][j],  so the estimate of
// the Monte-Carlo error of B under any environment needs only these 6n² numbers per mesh.
//
// The same record, for the rows of one sampling job, is what the farm appends to
// checkpoints/variance.log while it samples (resume re-uses the records of re-used jobs).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace prt {

struct TransportVariance {
  uint32_t cubemap_n = 0;
  uint32_t rays_per_texel = 0;  // 1: no variance could be estimated (every sum is 0)
  // Per mesh (geometry order): its rows, the rows whose variance the sums hold (all of them
  // once a run is complete; the sparse method's reconstructed texels hold none, see
  // docs/farm.md), and its 6n² sums.
  std::vector<uint64_t> mesh_rows;
  std::vector<uint64_t> rows_covered;
  std::vector<std::vector<double>> sums;

  uint64_t texels() const { return 6ull * cubemap_n * cubemap_n; }
  // Adds another set of sums of the same shape (a job's record).
  void Add(const TransportVariance& other);
  // Adds one row's per-texel variances (texels() floats) to the mesh holding global sample
  // `sample` (meshes in order, mesh_rows[m] samples each).
  void AddRow(uint64_t sample, const float* variance);
};

// An empty set of sums (zeros) for meshes of the given vertex counts.
TransportVariance MakeTransportVariance(uint32_t cubemap_n, uint32_t rays_per_texel,
                                        std::vector<uint64_t> mesh_rows);

std::string EncodeTransportVariance(const TransportVariance& v);
// Throws InputError naming `name` on a damaged, truncated or inconsistent file; safe on hostile
// input (sizes are checked before allocation, every value must be finite and ≥ 0).
TransportVariance DecodeTransportVariance(std::string_view bytes, const std::string& name);

// One record of checkpoints/variance.log: the job (`phase` name, item range) and its sums.
struct VarianceLogRecord {
  std::string phase;
  uint64_t first = 0;
  uint64_t count = 0;
  TransportVariance sums;
};
// Length-prefixed and checksummed so that a torn last record is detected.
std::string EncodeVarianceLogRecord(const VarianceLogRecord& r);
// Every intact record of a log's bytes, in order; stops at the first torn or damaged one.
std::vector<VarianceLogRecord> DecodeVarianceLog(std::string_view bytes, const std::string& name);

}  // namespace prt
