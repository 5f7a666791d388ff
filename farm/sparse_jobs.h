// The jobs of prt-farm's sparse method (docs/farm.md, "Sparse method"; Huang & Ramamoorthi 2010
// §4–5) as self-contained byte messages, and the kernel a worker runs on one. No MPI here: rank 0
// encodes a job with everything the worker needs (sample ids, neighbour lists, the dense rows a
// job reads), any rank computes it with ComputeSparseJob, and rank 0 decodes the result.
//
//   dense   sample ids                         → T, visibility and feature rows (§4.2)
//   rank    candidates' neighbour lists and the
//           union of their downsampled dense rows → one weight (local rank, §4.1) per candidate
//   sparse  sparse vertices, neighbour lists and
//           the union of their dense neighbours'
//           T, visibility and feature rows      → outcome per vertex, rows of the reconstructed
//                                                 ones (§5)
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "formats/transport_variance.h"
#include "worker/sparse_precomputation.h"

namespace prt {

enum class SparseJobKind : uint32_t { kDense = 1, kRank = 2, kSparse = 3 };

// What a job did (journaled with it, summed into report.json's "sparse" object).
struct SparseJobCounters {
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
  uint64_t texels_above_horizon = 0;  // dense rows, and reconstructed sparse rows
  uint64_t grid_texels = 0;           // dense: first pass
  uint64_t feature_texels = 0;        // dense: second pass
  uint64_t borrowed_texels = 0;       // dense: filled from neighbours without tracing
  uint64_t reconstructed = 0;         // sparse outcomes
  uint64_t fallback_too_few_neighbors = 0;
  uint64_t fallback_solve_failed = 0;
  uint64_t solved_lars = 0;
  uint64_t solved_admm = 0;
  uint64_t zero_systems = 0;
  uint64_t features_traced = 0;
  uint64_t fallback_poor_fit = 0;  // appended: older journal lines read it as 0

  static constexpr std::size_t kCount = 16;
  std::vector<uint64_t> ToVector() const;
  // Missing trailing values read as 0.
  static SparseJobCounters FromVector(std::span<const uint64_t> v);
  SparseJobCounters& operator+=(const SparseJobCounters& o);
};

// The envelope every job and result starts with.
struct SparseJobHeader {
  uint32_t kind = 0;   // SparseJobKind
  uint32_t phase = 0;  // rank 0's phase number (echoed back)
  uint64_t first = 0;  // item range in the phase's list (echoed back)
  uint64_t count = 0;
};

// Where the rows stay where they are computed (docs/farm.md, "Where the rows go"): the worker
// reads the rows a job needs from the run folder and writes the rows it computes there itself,
// through this interface (farm/sparse_phase.cpp implements it on the run's files); the messages
// then carry sample ids, checksums and counters instead of rows. Calls may come from several
// threads at once.
class SparseRowFiles {
 public:
  virtual ~SparseRowFiles() = default;
  // A dense sample's T, visibility and feature rows (texels each) and its downsampled row.
  virtual void ReadDense(uint32_t sample, float* transport, float* visibility,
                         uint8_t* feature) = 0;
  virtual void ReadLow(uint32_t sample, float* low) = 0;
  virtual void WriteDense(uint32_t sample, const float* transport, const float* visibility,
                          const uint8_t* feature, const float* low) = 0;
  // A reconstructed row of T.
  virtual void WriteRow(uint32_t sample, const float* transport) = 0;
  // The job's variance sums, under the step's name and the job's item range.
  virtual void RecordVariance(const std::string& step, uint64_t first, uint64_t count,
                              const std::string& encoded_sums) = 0;
  // A cross-validation job's records (farm/sparse_phase.cpp, CrossValidate): for items
  // first… of its list, each vertex's outcome and reconstruction minus its traced row, written
  // at their place; `rows` holds the reconstructed rows in order. Returns the XXH64 of the
  // records' bytes (the journal's checksum).
  virtual uint64_t WriteCrossValidation(uint64_t first, std::span<const uint32_t> vertices,
                                        std::span<const uint8_t> outcomes, const float* rows) = 0;
  // Makes everything written durable (before the result leaves the worker).
  virtual void Sync() = 0;
  virtual int low_resolution() const = 0;  // m of the downsampled rows (6·m·m floats)
};

// A job's in-place flags (the trailer of every job message; 0: rows travel in the messages).
inline constexpr uint32_t kReadRowsInPlace = 1;   // read the rows the job needs from the files
inline constexpr uint32_t kWriteRowsInPlace = 2;  // write the rows it computes into the files
// A cross-validation job: write its records (reconstruction − traced row) into the files instead
// of returning the reconstructions.
inline constexpr uint32_t kCrossValidateInPlace = 4;

// ---- jobs (rank 0 → worker)
struct DenseJob {
  std::vector<uint32_t> ids;  // samples to sample densely
  uint32_t in_place = 0;      // kWriteRowsInPlace: T, aux and low rows go into the files
  std::string step;           // the step's name (the variance records' key)
};
struct RankJob {
  uint32_t low_dim = 0;             // 6·m·m
  std::vector<uint32_t> offsets;    // candidate c's neighbours: nb[offsets[c] .. offsets[c+1])
  std::vector<uint32_t> neighbors;  // indices into the union below, nearest first
  std::vector<float> low_rows;      // union of downsampled dense rows, low_dim each
  uint32_t in_place = 0;            // kReadRowsInPlace: low_rows is empty, read union_ids' rows
  std::vector<uint32_t> union_ids;  // with kReadRowsInPlace: the union's sample ids
};
struct SparseJob {
  uint32_t texels = 0;              // texel_count
  std::vector<uint32_t> vertices;   // sample ids to reconstruct
  std::vector<uint32_t> offsets;    // as in RankJob
  std::vector<uint32_t> neighbors;  // indices into the union, nearest first
  std::vector<float> transport;     // union rows, texels each
  std::vector<float> visibility;    // union rows
  std::vector<uint8_t> feature;     // union rows
  std::vector<uint32_t> union_ids;  // the union rows' sample ids (their normals)
  // kReadRowsInPlace: transport, visibility and feature are empty (read from the files);
  // kWriteRowsInPlace: the reconstructed rows go into the files.
  uint32_t in_place = 0;
  std::string step;
};

// ---- results (worker → rank 0)
struct SparseJobResult {
  SparseJobHeader header;
  double busy_seconds = 0;
  SparseJobCounters counters;
  // dense: ids.size() rows each of transport / visibility / feature
  std::vector<float> transport;
  std::vector<float> visibility;
  std::vector<uint8_t> feature;
  // rank: one weight per candidate
  std::vector<int32_t> weights;
  // sparse: one SparseOutcome per vertex; `transport` holds the reconstructed rows in order
  std::vector<uint8_t> outcomes;
  // sparse: per vertex, CombinationSlots(plan) pairs (dense sample id, α as float bits): the
  // combination its row was reconstructed with (ReconstructSparseRow's weights), unused pairs
  // (kNoSample, 0); all unused for a fallback. The bounces reuse it (run/sparse/combination.bin).
  std::vector<uint32_t> combination;
  // dense and sparse: the traced texels' Monte-Carlo variance summed per mesh (an encoded
  // TransportVariance, formats/transport_variance.h; empty when not asked for)
  std::string variance;
  // 1: the worker wrote the job's rows (and variance record) into the files itself; `transport`,
  // `visibility`, `feature` and `variance` are empty and `checksum` is the journal's checksum of
  // what it wrote (DenseResultChecksum or SparseResultChecksum).
  uint32_t in_place = 0;
  uint64_t checksum = 0;
};

// Each encoder appends its message to `prefix` (moved in: the job loop's envelope, so that a job
// of 20 MiB is never copied to put 32 bytes in front of it) and returns the whole.
std::string EncodeDenseJob(const SparseJobHeader& h, const DenseJob& job, std::string prefix = {});
std::string EncodeRankJob(const SparseJobHeader& h, const RankJob& job, std::string prefix = {});
std::string EncodeSparseJob(const SparseJobHeader& h, const SparseJob& job,
                            std::string prefix = {});
std::string EncodeSparseJobResult(const SparseJobResult& r, std::string prefix = {});
// Throws std::runtime_error on a truncated or foreign message (and on a checksum mismatch).
SparseJobResult DecodeSparseJobResult(std::string_view bytes);
SparseJobHeader PeekSparseJobHeader(std::string_view job_bytes);

// Runs one encoded job on this rank (TBB threads) and returns the encoded result. Throws
// NumericalError for a non-finite value, std::runtime_error for a malformed job.
// `variance_shape` (optional): empty variance sums of the run's row groups
// (FarmContext::EmptyVarianceSums); with them, dense and sparse results carry their traced
// texels' variance sums (SparseJobResult::variance).
// `files` (optional): the run's files, for jobs with in-place flags (a job with flags and no files
// is a std::runtime_error).
std::string ComputeSparseJob(const TransportSampler& sampler,
                             std::span<const SpatialSample> samples, const SparsePlan& plan,
                             std::string_view job_bytes, std::string prefix = {},
                             const TransportVariance* variance_shape = nullptr,
                             SparseRowFiles* files = nullptr);

// XXH64 of what a dense job leaves on disk, per sample in order: T row, visibility row, feature
// row. `rows` samples, `texels` each.
uint64_t DenseResultChecksum(std::size_t rows, std::size_t texels, const float* transport,
                             const float* visibility, const uint8_t* feature);
// XXH64 of a sparse job's outcomes followed by its reconstructed rows and its combination
// records.
uint64_t SparseResultChecksum(std::span<const uint8_t> outcomes, std::span<const float> rows,
                              std::span<const uint32_t> combination);

// The combination records (SparseJobResult::combination, run/sparse/combination.bin): pairs per
// sparse vertex, and the id of an unused pair.
inline constexpr uint32_t kNoSample = 0xFFFFFFFFu;
inline std::size_t CombinationSlots(const SparsePlan& plan) {
  return static_cast<std::size_t>(std::max(1, plan.max_neighbors));
}

// run/sparse/combination.bin, written by the sparse phase and read by the bounce phases: the
// magic "PRTCMB1\0", uint64 samples N, uint64 slots S, N·S pairs (uint32 dense sample, float32
// α bits), then the XXH64 of everything before it. A sample without a combination (dense, or a
// fallback) has S unused pairs.
std::string EncodeCombinationFile(uint64_t samples, uint64_t slots,
                                  std::span<const uint32_t> pairs);
// Reads it for a run of `samples` samples: the pairs (N·S·2 values) and S. Throws InputError
// naming the file on a short, damaged or foreign file, a sample count that differs, or a pair
// naming a sample ≥ N or a non-finite α.
std::vector<uint32_t> ReadCombinationFile(const std::string& path, uint64_t samples,
                                          uint64_t& slots);

// Morton key (10 bits per axis, interleaved into 30) of p in the box [lo, hi]: the order of
// the sparse vertices, so that a job's vertices are close together and share neighbours.
uint32_t MortonKey(const Vec3& p, const Vec3& lo, const Vec3& hi);

}  // namespace prt
