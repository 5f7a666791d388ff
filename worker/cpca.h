// Clustered PCA of the transport's rows (Sloan, Hall, Hart & Snyder 2003), for all-frequency
// transport in the row-wavelet basis as in Huang & Ramamoorthi 2010 §6, with its integration
// with sparse precomputation (the dense pass and the re-clustering pass of §6, Figure 7).
// Output: formats/cpca_transport.h. Algorithm and measurements: docs/cpca.md.
//
// Standard CPCA (Sloan 2003 §4): LBG iterations, each assigning every row to the cluster whose
// affine subspace (mean + current basis) reconstructs it best and recomputing every cluster's
// mean and PCA basis from its members; the basis dimension grows in stages, 0 (plain VQ), 1, 2,
// 4, … S, with iterations_per_stage LBG iterations after each increment, "adding bases
// incrementally to avoid local minima". A cluster's basis is found by subspace iteration on its
// scatter matrix Σ (x − μ)(x − μ)ᵀ, warm-started from the previous iteration's.
// Huang §6: the same on the dense rows only, then every sparse row joins the cluster of its
// first dense neighbour and the re-clustering pass runs LBG iterations (no basis increment) on
// all rows, a row choosing among its own cluster and its dense neighbours' clusters.
//
// Distributed (the farm's compression phase): every process holds a contiguous range of whole
// units of kCpcaUnitRows rows (CpcaRowRange) and computes distances and per-cluster sums for its
// own rows only; the sums travel as 64-bit fixed-point integers (CpcaReducer::SumInt64), each
// unit's sum rounded once, so the result is bit-identical for any number of processes and equal
// to the in-process CompressCpca. Deterministic for a seed.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include "formats/compressed_transport.h"
#include "formats/cpca_transport.h"

namespace prt {

// Reductions over the processes that hold rows; in one process they are the identity.
class CpcaReducer {
 public:
  virtual ~CpcaReducer() = default;
  // Element-wise sum over the processes, in place (integers: exact, in any order).
  virtual void SumInt64(std::span<int64_t> v) = 0;
  // Element-wise maximum, in place.
  virtual void MaxDouble(std::span<double> v) = 0;
};

class LocalCpcaReducer final : public CpcaReducer {
 public:
  void SumInt64(std::span<int64_t>) override {}
  void MaxDouble(std::span<double>) override {}
};

// Rows per unit: sums are rounded to fixed point once per unit and cluster.
inline constexpr uint64_t kCpcaUnitRows = 1024;
// The rows [first, last) process p of P holds: whole units, as even as units allow.
std::pair<uint64_t, uint64_t> CpcaRowRange(uint64_t rows, int p, int P);

struct CpcaOptions {
  uint32_t clusters = 64;
  uint32_t bases = 16;
  int bits = 9;                  // basis and mean quantiser bits
  double keep_fraction = 0.05;   // terms kept per basis/mean vector, as a fraction of 6n²
  int coefficient_bits = 16;     // per-row coefficient quantiser bits
  uint64_t seed = 1;             // initial cluster seeds, subspace starts
  int iterations_per_stage = 3;  // LBG iterations after each basis increment
  int power_iterations = 2;      // subspace iterations per basis update
  // The projection distance is computed to the `candidates` clusters of nearest mean plus the
  // row's own (0: to every cluster, Sloan's exhaustive search).
  uint32_t candidates = 8;
  int recluster_iterations = 1;  // Huang §6 re-clustering pass: LBG iterations on all rows
};

// The options of a header of scheme kCpca (the header's clusters, bases, bits, keep fraction,
// coefficient bits and seed; the rest at their defaults).
CpcaOptions CpcaOptionsFrom(const CompressedTransportHeader& h);

// Huang §6's input: which rows are dense, and for every other row the dense rows its row is a
// linear combination of (global row indices, most weight first). Rows are channels × V: a
// sample's flags and neighbours apply to its row in every channel (CpcaSparseStructure::Of).
struct CpcaSparseStructure {
  std::vector<uint8_t> is_dense;                  // per row
  std::vector<std::vector<uint32_t>> neighbours;  // per row; empty for dense rows
  // From per-sample flags and neighbour lists (sample indices) for `channels` channel-major
  // copies of the samples.
  static CpcaSparseStructure Of(std::span<const uint8_t> sample_is_dense,
                                std::span<const std::vector<uint32_t>> sample_neighbours,
                                uint32_t channels);
};

struct CpcaStats {
  double seconds = 0;                 // the whole computation
  double seconds_dense = 0;           // Huang: the dense pass (standard: everything)
  double seconds_recluster = 0;       // Huang: the re-clustering pass and the final update
  int lbg_iterations = 0;             // over all stages and passes
  uint64_t distance_evaluations = 0;  // projection distances computed (this process)
  uint64_t rows_dense_pass = 0;       // rows the LBG stages ran on (all processes)
  uint32_t empty_clusters = 0;        // clusters left without members
  // ‖T̂ − T̃‖_F / ‖T̂‖_F over all rows, T̃ what the stored transport decodes to (exact: the row
  // transform is orthonormal, so it is the error in the texel basis too).
  double relative_error = 0;
  double energy = 0;  // ‖T̂‖²_F
};

// This process's share of the result: the clusters (the same on every process), and the cluster
// ids and quantised coefficients of its rows.
struct CpcaLocalResult {
  std::vector<CpcaCluster> clusters;
  std::vector<uint32_t> cluster_of;   // count
  std::vector<int32_t> coefficients;  // count × S
  CpcaStats stats;
};

// rows: this process's rows [first, first + count) of the h.sample_count rows, in the
// row-wavelet basis (worker/transport_compressor.h PrepareRows), count × 6n² floats; `first`
// and `first + count` on unit boundaries (CpcaRowRange). `sparse` (optional): Huang §6 on
// these dense rows, else standard CPCA. progress(done, total) is called on every process after
// each LBG iteration. Throws std::invalid_argument on bad arguments, NumericalError on a
// non-finite row.
CpcaLocalResult ComputeCpca(const CompressedTransportHeader& h, const CpcaOptions& o,
                            const float* rows, uint64_t first, uint64_t count, CpcaReducer& reducer,
                            const CpcaSparseStructure* sparse = nullptr,
                            const std::function<void(int, int)>& progress = {});

// In one process: every row of T̂ (h.sample_count × 6n², row-wavelet basis) → the transport.
CpcaTransport CompressCpca(const float* rows_hat, const CompressedTransportHeader& h,
                           const CpcaOptions& o, const CpcaSparseStructure* sparse = nullptr,
                           CpcaStats* stats = nullptr);

}  // namespace prt
