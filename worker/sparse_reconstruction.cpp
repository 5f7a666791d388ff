#include "worker/sparse_reconstruction.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "worker/local_rank.h"

namespace prt {

SparseStats& SparseStats::operator+=(const SparseStats& o) {
  trace += o.trace;
  reconstructed += o.reconstructed;
  fallback_too_few_neighbors += o.fallback_too_few_neighbors;
  fallback_solve_failed += o.fallback_solve_failed;
  fallback_poor_fit += o.fallback_poor_fit;
  neighbors_dropped_by_normal += o.neighbors_dropped_by_normal;
  solved_lars += o.solved_lars;
  solved_admm += o.solved_admm;
  zero_systems += o.zero_systems;
  features_traced += o.features_traced;
  texels_above_horizon += o.texels_above_horizon;
  return *this;
}

namespace {
// Contiguous runs [first, last) of the texels above a horizon: a horizon cuts each face row in
// one interval, so there are at most about 6·n runs, and the loops over the neighbours' rows
// below touch only the half of each row that matters.
using Runs = std::vector<std::pair<uint32_t, uint32_t>>;
Runs RunsOf(const uint8_t* above, std::size_t total) {
  Runs runs;
  for (std::size_t j = 0; j < total;) {
    if (!above[j]) {
      ++j;
      continue;
    }
    const std::size_t first = j;
    while (j < total && above[j]) ++j;
    runs.push_back({static_cast<uint32_t>(first), static_cast<uint32_t>(j)});
  }
  return runs;
}

// Per-thread buffers of the functions below, reused from row to row: a sparse row used to
// allocate and zero ten full-sphere arrays, which showed as memset and page faults in the profile.
// Only the texels on the runs are ever read, so only those are cleared. Thread-local is safe:
// nothing a row calls (the sampler's texel tracing, the L1 solver) runs parallel loops, so a
// thread never starts another row while it is inside one.
struct RowScratch {
  std::vector<float> s, s2, var, unocc, acc, vmin, traced, traced_unocc, traced_var, unocc_list;
  std::vector<uint16_t> feat;
  std::vector<uint8_t> above, fully;
  std::vector<uint32_t> untraced;  // texels above the horizon that are not features
  std::vector<double> A, b, key0, G, c;
  struct Cand {
    double key;
    uint32_t texel;
  };
  std::vector<Cand> cands;
};
RowScratch& ThreadScratch() {
  thread_local RowScratch scratch;
  return scratch;
}

template <typename V>
void Grow(V& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
}

void ClearOnRuns(std::vector<float>& v, std::size_t total, const Runs& runs) {
  Grow(v, total);
  for (const auto& [first, last] : runs) std::fill(v.begin() + first, v.begin() + last, 0.0f);
}

// Per-texel statistics over a vertex's neighbours (Huang & Ramamoorthi 2010 §5.2): the variance
// of T (var), how many neighbours had the texel as a feature (feat), and, with `vmin`, the least
// visibility (the unity row's test). Each texel's sums run over the neighbours in their order with
// the same float operations as the separate passes over the runs this replaced: the results are
// theirs bit for bit, whatever the vector width (element-wise operations only; no fused
// multiply-add is enabled) and whatever other vertices share the batch.
//
// Where the time went: the neighbours' rows (~35 × 3,000 texels × 9 bytes, 1 MB per vertex)
// came from memory once per vertex. A batch of consecutive vertices shares most of its
// neighbours, so the kernel walks the texels in blocks of kStatBlock and lets every vertex of the
// batch add its neighbours' values for the block while they are in the first-level cache: the
// rows come from memory about once per batch.
constexpr std::size_t kStatBlock = 16;

struct StatTask {
  const DenseNeighbor* neighbors = nullptr;
  std::size_t count = 0;
  const uint8_t* block_on = nullptr;  // per block: holds a texel above the vertex's horizon
  float* var = nullptr;
  uint16_t* feat = nullptr;
  float* vmin = nullptr;  // optional
};

// GCC/Clang vector extensions: element-wise arithmetic, lowered to SSE2 by default and to AVX2
// in the kernel's AVX2 clone.
using Float8 = float __attribute__((vector_size(32)));
using Byte16 = uint8_t __attribute__((vector_size(16)));
using Short16 = uint16_t __attribute__((vector_size(32)));

__attribute__((target_clones("avx2", "default"))) void StatisticsOfBlocks(const StatTask* tasks,
                                                                          std::size_t task_count,
                                                                          std::size_t blocks) {
  static_assert(kStatBlock == 16);
  const Float8 zero = {}, one = zero + 1.0f;
  for (std::size_t b = 0; b < blocks; ++b) {
    const std::size_t j0 = b * kStatBlock;
    for (std::size_t k = 0; k < task_count; ++k) {
      const StatTask& task = tasks[k];
      if (!task.block_on[b]) continue;
      const float inv = task.count == 0 ? 0.0f : 1.0f / static_cast<float>(task.count);
      Float8 s0 = zero, s1 = zero, q0 = zero, q1 = zero, m0 = one, m1 = one;
      Short16 fc = {};
      for (std::size_t i = 0; i < task.count; ++i) {
        const DenseNeighbor& nb = task.neighbors[i];
        Float8 t0, t1, v0, v1;
        Byte16 f;
        std::memcpy(&t0, nb.transport + j0, sizeof t0);
        std::memcpy(&t1, nb.transport + j0 + 8, sizeof t1);
        std::memcpy(&f, nb.feature + j0, sizeof f);
        s0 += t0;
        s1 += t1;
        q0 += t0 * t0;
        q1 += t1 * t1;
        fc += __builtin_convertvector(f, Short16);
        if (task.vmin != nullptr) {  // std::min(vm, v): v < vm ? v : vm
          std::memcpy(&v0, nb.visibility + j0, sizeof v0);
          std::memcpy(&v1, nb.visibility + j0 + 8, sizeof v1);
          m0 = v0 < m0 ? v0 : m0;
          m1 = v1 < m1 ? v1 : m1;
        }
      }
      // std::max(0, s2/n − m²): 0 < x ? x : 0.
      const Float8 a0 = s0 * inv, a1 = s1 * inv;
      const Float8 x0 = q0 * inv - a0 * a0, x1 = q1 * inv - a1 * a1;
      const Float8 var0 = zero < x0 ? x0 : zero, var1 = zero < x1 ? x1 : zero;
      std::memcpy(task.var + j0, &var0, sizeof var0);
      std::memcpy(task.var + j0 + 8, &var1, sizeof var1);
      std::memcpy(task.feat + j0, &fc, sizeof fc);
      if (task.vmin != nullptr) {
        std::memcpy(task.vmin + j0, &m0, sizeof m0);
        std::memcpy(task.vmin + j0 + 8, &m1, sizeof m1);
      }
    }
  }
}

// The Gram form of the fit (worker/l1_solver.h): G = AᵀA (k×k, column-major, both triangles),
// c = Aᵀb and bᵀb, for A row-major with `stride` ≥ k columns (padding zero). Every entry is a sum
// over the rows in their order, so the result does not depend on the vector width, the batch or
// the thread; G's 4×4 blocks are held in registers over the rows (the product Eigen's
// rankUpdate formed in ~40 % of the solve's time with SSE2 alone).
using Double4 = double __attribute__((vector_size(32)));

__attribute__((target_clones("avx2", "default"))) double GramOfRows(const double* __restrict A,
                                                                    const double* __restrict b,
                                                                    int rows, int k, int stride,
                                                                    double* __restrict G,
                                                                    double* __restrict c) {
  const auto ku = static_cast<std::size_t>(k);
  const auto su = static_cast<std::size_t>(stride);
  for (int pb = 0; pb < k; pb += 4) {
    for (int qb = 0; qb <= pb; qb += 4) {
      Double4 acc[4] = {};
      for (int i = 0; i < rows; ++i) {
        const double* row = A + static_cast<std::size_t>(i) * su;
        Double4 aq;
        std::memcpy(&aq, row + qb, sizeof aq);
        for (int r = 0; r < 4; ++r) acc[r] += row[pb + r] * aq;
      }
      for (int r = 0; r < 4 && pb + r < k; ++r)
        for (int t = 0; t < 4 && qb + t < k; ++t) {
          const auto p = static_cast<std::size_t>(pb + r), q = static_cast<std::size_t>(qb + t);
          G[p + ku * q] = acc[r][t];
          G[q + ku * p] = acc[r][t];
        }
    }
  }
  for (int pb = 0; pb < k; pb += 4) {
    Double4 acc = {};
    for (int i = 0; i < rows; ++i) {
      Double4 a;
      std::memcpy(&a, A + static_cast<std::size_t>(i) * su + pb, sizeof a);
      acc += b[i] * a;
    }
    for (int t = 0; t < 4 && pb + t < k; ++t) c[pb + t] = acc[t];
  }
  double bb = 0;
  for (int i = 0; i < rows; ++i) bb += b[i] * b[i];
  return bb;
}

// The same statistics texel by texel on the runs, for layouts whose texel count is not a
// multiple of the block (6·n² is one for even n ≥ 4; tests use tiny cubemaps).
void StatisticsOnRuns(const StatTask& task, const Runs& runs) {
  const float inv = task.count == 0 ? 0.0f : 1.0f / static_cast<float>(task.count);
  for (const auto& [first, last] : runs)
    for (std::size_t j = first; j < last; ++j) {
      float s = 0, s2 = 0, vm = 1;
      uint16_t fc = 0;
      for (std::size_t i = 0; i < task.count; ++i) {
        const DenseNeighbor& nb = task.neighbors[i];
        s += nb.transport[j];
        s2 += nb.transport[j] * nb.transport[j];
        fc = static_cast<uint16_t>(fc + nb.feature[j]);
        vm = std::min(vm, nb.visibility[j]);
      }
      const float m = s * inv;
      task.var[j] = std::max(0.0f, s2 * inv - m * m);
      task.feat[j] = fc;
      if (task.vmin != nullptr) task.vmin[j] = vm;
    }
}

// Blocks of kStatBlock texels holding a texel of the runs.
void BlocksOf(const Runs& runs, std::size_t total, std::vector<uint8_t>& block_on) {
  block_on.assign((total + kStatBlock - 1) / kStatBlock, 0);
  for (const auto& [first, last] : runs)
    for (std::size_t b = first / kStatBlock; b <= (last - 1) / kStatBlock; ++b) block_on[b] = 1;
}

// `count` texels, best first by the keys below; with `min_extra` < count, only as many as there
// are texels with a positive primary key plus `min_extra`, at most `count`. Returned sorted.
//
// The key of a texel is key0 + 1e-12·h with key0 = var·feat + 1e-3·var and h ∈ [0, 1) a hash of
// (seed, texel); rounding is monotone, so key0 ≤ key ≤ fl(key0 + 1e-12). A texel whose upper
// bound is below the take-th largest key0 cannot be chosen, and only the others need their hash
// and the exact selection: the same texels as ranking every key, for a fraction of the hashes
// wherever the neighbours' values vary (where they all agree, key0 = 0 and every texel competes
// on its hash, as before).
std::vector<uint32_t> ChooseFromStatistics(const Runs& runs, const std::vector<float>& var,
                                           const std::vector<uint16_t>& feat, int count,
                                           int min_extra, uint64_t seed) {
  RowScratch& scratch = ThreadScratch();
  std::vector<RowScratch::Cand>& cands = scratch.cands;
  std::vector<double>& key0 = scratch.key0;
  cands.clear();
  key0.clear();
  std::size_t primary = 0;
  for (const auto& [first, last] : runs) {
    for (std::size_t j = first; j < last; ++j) {
      // Primary: the paper's product of variance and feature count; then variance alone; then a
      // deterministic spread so that a region where all neighbours agree still gets constraints.
      const double v = var[j];
      primary += v * feat[j] > 0;
      cands.push_back({v * feat[j] + 1e-3 * v, static_cast<uint32_t>(j)});
    }
  }
  std::size_t take =
      std::min<std::size_t>(static_cast<std::size_t>(std::max(count, 0)), cands.size());
  if (min_extra < count)
    take = std::min(take, primary + static_cast<std::size_t>(std::max(min_extra, 0)));
  std::vector<uint32_t> out;
  out.reserve(take);
  if (take == cands.size()) {
    for (const RowScratch::Cand& c : cands) out.push_back(c.texel);
    return out;  // the runs are in texel order
  }
  if (take > 0) {
    key0.reserve(cands.size());
    for (const RowScratch::Cand& c : cands) key0.push_back(c.key);
    std::nth_element(key0.begin(), key0.begin() + static_cast<std::ptrdiff_t>(take - 1), key0.end(),
                     std::greater<>());
    const double bound = key0[take - 1];  // take texels have key0 ≥ bound, hence key ≥ bound
    std::size_t kept = 0;
    for (const RowScratch::Cand& c : cands) {
      if (c.key + 1e-12 < bound) continue;
      cands[kept++] = {c.key + 1e-12 * HashUniform(seed, c.texel), c.texel};
    }
    cands.resize(kept);
    auto better = [](const RowScratch::Cand& a, const RowScratch::Cand& b) {
      return a.key != b.key ? a.key > b.key : a.texel < b.texel;
    };
    std::nth_element(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(take), cands.end(),
                     better);
    for (std::size_t i = 0; i < take; ++i) out.push_back(cands[i].texel);
    std::sort(out.begin(), out.end());
  }
  return out;
}
}  // namespace

std::vector<uint32_t> ChooseFeatureDirections(const CubemapLayout& layout, const Vec3& normal,
                                              std::span<const DenseNeighbor> neighbors,
                                              InterpolationMode /*mode*/, int count,
                                              uint64_t seed) {
  const std::size_t total = layout.texel_count();
  std::vector<uint8_t> above(total);
  layout.AboveHorizonMask(normal, above.data());
  std::vector<float> var(total);
  std::vector<uint16_t> feat(total);
  const Runs runs = RunsOf(above.data(), total);
  const StatTask task{neighbors.data(), neighbors.size(), nullptr,
                      var.data(),       feat.data(),      nullptr};
  StatisticsOnRuns(task, runs);
  return ChooseFromStatistics(runs, var, feat, count, count, seed);
}

namespace {
// A vertex of a batch between its preparation and its statistics, and the rest of its row.
struct RowState {
  std::vector<DenseNeighbor> same_side;
  std::vector<uint32_t> kept;  // index into the caller's neighbours of each one used
  std::span<const DenseNeighbor> neighbors;
  std::vector<uint8_t> above, fully, block_on;
  Runs runs;
  std::size_t above_count = 0;
  bool active = false;
  std::vector<float> var, vmin;
  std::vector<uint16_t> feat;
};

// The normal test, the neighbour count and the horizon; false on a fallback (counted).
bool PrepareRow(const TransportSampler& sampler, const SparseRowTask& task,
                const SparseOptions& options, RowState& st, SparseStats& stats) {
  std::span<const DenseNeighbor> neighbors = task.neighbors;
  st.same_side.clear();
  st.kept.clear();
  if (options.min_normal_cos > -1) {
    const Vec3 nx = Normalize(task.sample->normal);
    for (std::size_t i = 0; i < neighbors.size(); ++i)
      if (Dot(nx, Normalize(neighbors[i].normal)) >= options.min_normal_cos) {
        st.same_side.push_back(neighbors[i]);
        st.kept.push_back(static_cast<uint32_t>(i));
      }
    stats.neighbors_dropped_by_normal += neighbors.size() - st.same_side.size();
    neighbors = st.same_side;
  }
  st.neighbors = neighbors;
  if (static_cast<int>(neighbors.size()) < options.min_neighbors) {
    ++stats.fallback_too_few_neighbors;
    return false;
  }
  const std::size_t total = sampler.layout().texel_count();
  st.above.resize(total);
  st.fully.resize(total);
  st.above_count =
      SampleHorizonMask(sampler, *task.sample, task.sample_index, st.above.data(), st.fully.data());
  st.runs = RunsOf(st.above.data(), total);
  BlocksOf(st.runs, total, st.block_on);
  Grow(st.var, total);
  Grow(st.feat, total);
  if (options.mode == InterpolationMode::kVisibility && options.unity_weight > 0)
    Grow(st.vmin, total);
  return true;
}

// Features, their rays, the fit and the row of a prepared vertex whose statistics are done.
SparseOutcome FinishRow(const TransportSampler& sampler, const SparseRowTask& task,
                        const SparseOptions& options, L1Solver& solver, RowState& st,
                        SparseStats& stats) {
  const SpatialSample& sample = *task.sample;
  const uint64_t sample_index = task.sample_index;
  float* row = task.row;
  float* variance = task.variance;
  std::vector<NeighborWeight>* weights = task.weights;
  const std::span<const DenseNeighbor> neighbors = st.neighbors;
  const std::vector<uint32_t>& kept = st.kept;
  const std::vector<uint8_t>& fully = st.fully;
  const Runs& runs = st.runs;
  const std::size_t above_count = st.above_count;
  const std::size_t total = sampler.layout().texel_count();
  RowScratch& scratch = ThreadScratch();
  const bool vis = options.mode == InterpolationMode::kVisibility;
  const bool unity = vis && options.unity_weight > 0;
  const std::vector<uint32_t> feats = ChooseFromStatistics(runs, st.var, st.feat, options.features,
                                                           options.min_features, sample_index);
  const int m = static_cast<int>(feats.size());
  const int k = static_cast<int>(neighbors.size());
  std::vector<float>& traced = scratch.traced;
  std::vector<float>& traced_unocc = scratch.traced_unocc;
  std::vector<float>& traced_var = scratch.traced_var;
  traced.resize(feats.size());
  traced_unocc.resize(feats.size());
  if (variance != nullptr) traced_var.resize(feats.size());
  stats.trace +=
      sampler.ComputeTexels(sample, sample_index, feats, traced.data(), traced_unocc.data(),
                            variance != nullptr ? traced_var.data() : nullptr);
  if (variance != nullptr) {
    std::fill(variance, variance + total, 0.0f);
    for (std::size_t i = 0; i < feats.size(); ++i) variance[feats[i]] = traced_var[i];
  }
  stats.features_traced += feats.size();

  // Unoccluded values U_x(j) of every texel above this vertex's horizon: the traced ones from
  // their rays, the others exact where the texel is entirely above, the sampler's estimate
  // where it straddles the horizon (each texel's value depends on that texel alone).
  std::vector<float>& unocc = scratch.unocc;  // read only above the horizon, all written here
  Grow(unocc, total);
  std::vector<uint32_t>& untraced = scratch.untraced;
  untraced.clear();
  {
    std::size_t f = 0;
    for (const auto& [first, last] : runs)
      for (std::size_t j = first; j < last; ++j) {
        if (f < feats.size() && feats[f] == j) {
          unocc[j] = traced_unocc[f++];
          continue;
        }
        untraced.push_back(static_cast<uint32_t>(j));
      }
  }
  std::vector<float>& unocc_list = scratch.unocc_list;
  unocc_list.resize(untraced.size());
  UnoccludedValues(sampler, sample, sample_index, untraced, fully.data(), unocc_list.data());
  for (std::size_t i = 0; i < untraced.size(); ++i) unocc[untraced[i]] = unocc_list[i];

  // Equations in transport units for both modes, so that each constraint weighs what it adds to
  // the relit radiance: visibility mode fits Σ α_k v_k(j) · U_x(j) to T_x(j) (the neighbours'
  // visibility under this vertex's own cosine); transport mode fits Σ α_k T_k(j) to T_x(j).
  // The unity row's weight: the untraced texels where every neighbour is unoccluded.
  double unity_w = 0;
  if (unity) {
    const float* vm = st.vmin.data();
    double w2 = 0;
    for (uint32_t j : untraced)  // in texel order, as the sum always ran
      if (vm[j] >= 1.0f) w2 += static_cast<double>(unocc[j]) * unocc[j];
    unity_w = options.unity_weight * std::sqrt(w2);
  }
  const int rows = m + (unity_w > 0 ? 1 : 0);
  // A row-major with its columns padded to a multiple of 4 (zeros), for GramOfRows.
  const int stride = (k + 3) / 4 * 4;
  const auto su = static_cast<std::size_t>(stride);
  std::vector<double>& A = scratch.A;
  std::vector<double>& b = scratch.b;
  A.assign(static_cast<std::size_t>(rows) * su, 0.0);
  b.resize(static_cast<std::size_t>(rows));
  if (rows > m) {
    b[static_cast<std::size_t>(m)] = unity_w;
    std::fill_n(A.data() + static_cast<std::size_t>(m) * su, k, unity_w);
  }
  for (int i = 0; i < m; ++i) b[static_cast<std::size_t>(i)] = traced[static_cast<std::size_t>(i)];
  for (int i = 0; i < m; ++i) {
    const uint32_t j = feats[static_cast<std::size_t>(i)];
    const double u = unocc[j];
    double* a = A.data() + static_cast<std::size_t>(i) * su;
    for (int c = 0; c < k; ++c) {
      const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
      a[c] = vis ? nb.visibility[j] * u : nb.transport[j];
    }
  }
  std::vector<double> alpha;
  if (options.solver == SolverKind::kLeastSquares) {
    std::vector<double> cm(static_cast<std::size_t>(rows) * k);  // column-major
    for (int i = 0; i < rows; ++i)
      for (int c = 0; c < k; ++c)
        cm[static_cast<std::size_t>(i) + static_cast<std::size_t>(rows) * c] =
            A[static_cast<std::size_t>(i) * su + c];
    alpha = L1Solver::LeastSquares(cm, {b.data(), b.size()}, rows, k);
  } else {
    std::vector<double>& G = scratch.G;
    std::vector<double>& cv = scratch.c;
    G.resize(static_cast<std::size_t>(k) * k);
    cv.resize(static_cast<std::size_t>(k));
    const double bb = GramOfRows(A.data(), b.data(), rows, k, stride, G.data(), cv.data());
    const L1Result r = solver.SolveGram(G, cv, bb, k);
    if (r.status == L1Status::kFailed) {
      ++stats.fallback_solve_failed;
      return SparseOutcome::kSolveFailed;
    }
    stats.solved_lars += r.status == L1Status::kLars;
    stats.solved_admm += r.status == L1Status::kAdmm;
    stats.zero_systems += r.status == L1Status::kZeroSystem;
    alpha = r.alpha;
  }
  if (options.max_residual > 0) {  // over the traced features only
    double rr = 0, bb = 0;
    for (int i = 0; i < m; ++i) {
      double f = -b[static_cast<std::size_t>(i)];
      const double* a = A.data() + static_cast<std::size_t>(i) * su;
      for (int c = 0; c < k; ++c) f += a[c] * alpha[static_cast<std::size_t>(c)];
      rr += f * f;
      bb += b[static_cast<std::size_t>(i)] * b[static_cast<std::size_t>(i)];
    }
    if (bb > 0 && rr > options.max_residual * options.max_residual * bb) {
      ++stats.fallback_poor_fit;
      return SparseOutcome::kPoorFit;
    }
  }

  // Eq. 4 on this vertex's own hemisphere (neighbour-outer, contiguous over texels), then the
  // traced values exactly.
  std::vector<float>& acc = scratch.acc;
  ClearOnRuns(acc, total, runs);
  for (int c = 0; c < k; ++c) {
    const float a = static_cast<float>(alpha[static_cast<std::size_t>(c)]);
    if (a == 0.0f) continue;
    const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
    const float* __restrict src = vis ? nb.visibility : nb.transport;
    float* __restrict ap = acc.data();
    for (const auto& [first, last] : runs)
      for (std::size_t j = first; j < last; ++j) ap[j] += a * src[j];
  }
  {
    std::size_t j = 0;
    for (const auto& [first, last] : runs) {
      std::fill(row + j, row + first, 0.0f);
      for (j = first; j < last; ++j) {
        const float u = unocc[j];
        const float t = vis ? std::clamp(acc[j], 0.0f, 1.0f) * u : std::clamp(acc[j], 0.0f, u);
        row[j] = std::isfinite(t) ? t : 0.0f;
      }
    }
    std::fill(row + j, row + total, 0.0f);
  }
  for (int i = 0; i < m; ++i)
    row[feats[static_cast<std::size_t>(i)]] = traced[static_cast<std::size_t>(i)];
  if (weights != nullptr) {
    weights->clear();
    for (int c = 0; c < k; ++c) {
      const auto a = static_cast<float>(alpha[static_cast<std::size_t>(c)]);
      if (a == 0.0f || !std::isfinite(a)) continue;
      weights->push_back(
          {kept.empty() ? static_cast<uint32_t>(c) : kept[static_cast<std::size_t>(c)], a});
    }
  }
  ++stats.reconstructed;
  stats.texels_above_horizon += above_count;
  return SparseOutcome::kReconstructed;
}
}  // namespace

void ReconstructSparseRows(const TransportSampler& sampler, std::span<SparseRowTask> tasks,
                           const SparseOptions& options, L1Solver& solver, SparseStats& stats) {
  thread_local std::vector<RowState> states;
  if (states.size() < tasks.size()) states.resize(tasks.size());
  const std::size_t total = sampler.layout().texel_count();
  const bool with_vmin = options.mode == InterpolationMode::kVisibility && options.unity_weight > 0;
  std::vector<StatTask> stat_tasks;
  stat_tasks.reserve(tasks.size());
  for (std::size_t i = 0; i < tasks.size(); ++i) {
    RowState& st = states[i];
    st.active = PrepareRow(sampler, tasks[i], options, st, stats);
    if (!st.active) {
      tasks[i].outcome = SparseOutcome::kTooFewNeighbors;
      continue;
    }
    StatTask t{st.neighbors.data(), st.neighbors.size(), st.block_on.data(),
               st.var.data(),       st.feat.data(),      with_vmin ? st.vmin.data() : nullptr};
    if (total % kStatBlock == 0)
      stat_tasks.push_back(t);
    else
      StatisticsOnRuns(t, st.runs);
  }
  if (total % kStatBlock == 0)
    StatisticsOfBlocks(stat_tasks.data(), stat_tasks.size(), total / kStatBlock);
  for (std::size_t i = 0; i < tasks.size(); ++i)
    if (states[i].active)
      tasks[i].outcome = FinishRow(sampler, tasks[i], options, solver, states[i], stats);
}

SparseOutcome ReconstructSparseRow(const TransportSampler& sampler, const SpatialSample& sample,
                                   uint64_t sample_index, std::span<const DenseNeighbor> neighbors,
                                   const SparseOptions& options, L1Solver& solver, float* row,
                                   SparseStats& stats, float* variance,
                                   std::vector<NeighborWeight>* weights) {
  SparseRowTask task{&sample, sample_index, neighbors, row, variance, weights};
  ReconstructSparseRows(sampler, {&task, 1}, options, solver, stats);
  return task.outcome;
}

}  // namespace prt
