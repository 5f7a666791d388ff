// The reference sparse-row reconstruction (Huang & Ramamoorthi 2010, §5): the implementation
// ReconstructSparseRow had before its fast path, step by step over the neighbours' rows and
// solved through L1Solver::Solve. Same contract as ReconstructSparseRow
// (worker/sparse_reconstruction.h); the fast path must give the same outcome, features, weights
// and rows (sparse_reconstruction_test.cpp). For tests and prt-sparse-reconstruct-bench only.
#pragma once

#include "worker/sparse_reconstruction.h"

namespace prt {

SparseOutcome ReconstructSparseRowReference(const TransportSampler& sampler,
                                            const SpatialSample& sample, uint64_t sample_index,
                                            std::span<const DenseNeighbor> neighbors,
                                            const SparseOptions& options, L1Solver& solver,
                                            float* row, SparseStats& stats,
                                            float* variance = nullptr,
                                            std::vector<NeighborWeight>* weights = nullptr);

}  // namespace prt
