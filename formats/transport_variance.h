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
//
// Exact sums, the same bytes for any rank count, job split or resume (docs/farm.md,
// "Determinism"): each row's variance (a float) is rounded once to a 128-bit unsigned fixed-point
// number in units of 2^-88 (ExactVarianceSum) and added as an integer, so that sums of jobs,
// ranks and logged records are exact and do not depend on the order they are added in; the
// doubles a reader wants are taken from the integer sum once (Value()). No overflow is possible:
//   a row's texel variance is at most 8/9 (the collapsed-strata estimate of
//   worker/transport_sampler.cpp is at most 2·Ω²/π² for a texel of solid angle Ω ≤ 2π/3; AddRow
//   refuses a value above kMaxRowVariance = 16), a mesh has fewer than kMaxMeshRows = 2^36 rows
//   (checked), so a sum is below 2^36 · 2^4 · 2^88 = 2^128.
// Resolution: 2^-88 ≈ 3.2e-27 per row, far below any variance a float row can carry (at
// n = 4096 a texel's variance is ~1e-15 or less, and float rows hold 7 digits).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace prt {

// One texel's sum over rows: hi·2^64 + lo, in units of 2^-kVarianceFractionBits.
struct ExactVarianceSum {
  uint64_t lo = 0;
  uint64_t hi = 0;

  // `v` (finite, 0 ≤ v < 2^40) rounded to the nearest unit.
  static ExactVarianceSum FromValue(double v);
  // Exact; throws std::overflow_error past 2^128 (impossible within the bounds above).
  void Add(const ExactVarianceSum& o);
  // The sum as a double (the nearest or next to it: two roundings, the same on every machine).
  double Value() const;
  bool operator==(const ExactVarianceSum&) const = default;
};

inline constexpr int kVarianceFractionBits = 88;
inline constexpr double kMaxRowVariance = 16.0;
inline constexpr uint64_t kMaxMeshRows = uint64_t{1} << 36;

// The group of each sample when a run's groups are not contiguous runs of samples: an image
// run's pixels, grouped by the mesh each sees (farm/farm_context.h, RowGroupsOf). Shared by
// every job's sums, never copied.
using SampleGroupMap = std::shared_ptr<const std::vector<uint32_t>>;

struct TransportVariance {
  uint32_t cubemap_n = 0;
  uint32_t rays_per_texel = 0;  // 1: no variance could be estimated (every sum is 0)
  // Per mesh (geometry order): its rows, the rows whose variance the sums hold (all of them
  // once a run is complete; the sparse method's reconstructed texels hold none, see
  // docs/farm.md), and its 6n² exact sums.
  std::vector<uint64_t> mesh_rows;
  std::vector<uint64_t> rows_covered;
  std::vector<std::vector<ExactVarianceSum>> sums;
  // Null: mesh m holds the mesh_rows[m] samples after the meshes before it (a vertex run).
  // Else sample s belongs to group (*sample_group)[s] (not part of the encoded forms).
  SampleGroupMap sample_group;

  uint64_t texels() const { return 6ull * cubemap_n * cubemap_n; }
  // Mesh m's 6n² sums as doubles: S[m][j].
  std::vector<double> MeshSums(std::size_t m) const;
  // Adds another set of sums of the same shape (a job's record). Exact: any order gives the same.
  void Add(const TransportVariance& other);
  // Adds one row's per-texel variances (texels() floats) to the mesh holding global sample
  // `sample` (meshes in order, mesh_rows[m] samples each, or sample_group's). Throws NumericalError
  // on a value that is not finite or outside [0, kMaxRowVariance].
  void AddRow(uint64_t sample, const float* variance);
  // The sums as 32-bit digits in 64-bit words, 4 per texel (least significant first, meshes in
  // order): adding such vectors word by word (MPI_SUM over fewer than 2^32 processes) cannot
  // overflow, so any reduction order gives the same words; AddDigits carries them back and adds
  // them to these sums. rows_covered is not part of it.
  std::vector<uint64_t> Digits() const;
  void AddDigits(std::span<const uint64_t> digits);
};

// An empty set of sums (zeros) for meshes of the given vertex counts.
// `sample_group` (optional): each sample's group; group m must hold mesh_rows[m] samples.
TransportVariance MakeTransportVariance(uint32_t cubemap_n, uint32_t rays_per_texel,
                                        std::vector<uint64_t> mesh_rows,
                                        SampleGroupMap sample_group = nullptr);

// The file's format version 2 (docs/transport-format.md): the exact sums. Also the form a job's
// sums travel in from a worker to rank 0.
std::string EncodeTransportVariance(const TransportVariance& v);
// Version 2, or version 1 (doubles, written by prt-farm before the sums were exact: each is
// rounded to the exact form). Throws InputError naming `name` on a damaged, truncated or
// inconsistent file; safe on hostile input (sizes are checked before allocation, no sum may
// exceed what its covered rows can hold).
TransportVariance DecodeTransportVariance(std::string_view bytes, const std::string& name);

// One record of checkpoints/variance.log: the job (`phase` name, item range) and its sums.
struct VarianceLogRecord {
  std::string phase;
  uint64_t first = 0;
  uint64_t count = 0;
  TransportVariance sums;
};
// Length-prefixed and checksummed so that a torn last record is detected. Records of exact sums
// ("PVL2"); a log of an older prt-farm ("PVLG", doubles) is still read.
std::string EncodeVarianceLogRecord(const VarianceLogRecord& r);
// Every intact record of a log's bytes, in order; stops at the first torn or damaged one.
std::vector<VarianceLogRecord> DecodeVarianceLog(std::string_view bytes, const std::string& name);

}  // namespace prt
