// Dense-vertex selection by local rank (Huang & Ramamoorthi 2010, §4.1): a vertex's weight is the
// rank of the local transport matrix formed by the dense vertices near it; the next dense
// vertices are drawn by weighted random sampling with weight = rank.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace prt {

// Numerical rank of the matrix whose rows are `rows` (each `dim` floats): the number of singular
// values σ_i with σ_i > rel_threshold · σ_max, from the eigenvalues of the k×k Gram matrix in
// double (σ_i² = eig_i). 0 for an empty or all-zero matrix.
int LocalRank(std::span<const float* const> rows, std::size_t dim, double rel_threshold = 0.05);

// Reduces a cubemap row (6·n·n texels, layout of vocabulary/cubemap.h) to 6·m·m texels by box
// averaging (m divides n), for cheap rank estimation: the rank of the low-resolution local
// matrix is what matters for choosing where dense vertices go.
void DownsampleRow(const float* row, int n, int m, float* out);

// Weighted random sampling of `count` distinct items without replacement (Efraimidis &
// Spirakis 2006: key = u^(1/w), take the largest keys). Items with weight ≤ 0 are never chosen
// unless there are not enough positive ones. Deterministic for a given seed; returns ids sorted.
std::vector<uint32_t> WeightedSampleWithoutReplacement(std::span<const uint32_t> ids,
                                                       std::span<const double> weights,
                                                       std::size_t count, uint64_t seed);

// A deterministic uniform double in [0, 1) from (seed, a, b): SplitMix64-style hash.
double HashUniform(uint64_t seed, uint64_t a, uint64_t b = 0);

}  // namespace prt
