// Relighting from a clustered-PCA transport (Overbeck et al. 2006 §6.3, Eq. 7, 8, 10); see
// runtime/cpca_relight.h and docs/cpca.md.
#include "runtime/cpca_relight.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace prt {

namespace {

void CheckTermIndices(std::span<const LightingTerm> terms, std::size_t columns, const char* who) {
  for (const LightingTerm& t : terms)
    if (t.index >= columns)
      throw std::out_of_range(std::string(who) + ": lighting term " + std::to_string(t.index) +
                              " out of range (" + std::to_string(columns) + " coefficients)");
}

}  // namespace

CpcaProjection::CpcaProjection(const CpcaTransport& t) {
  const std::size_t S = t.bases();
  vectors_ = t.clusters.size() * (S + 1);
  columns_ = t.header.column_count();
  column_begin_.assign(columns_ + 1, 0);
  const auto each = [&](auto&& f) {
    for (std::size_t c = 0; c < t.clusters.size(); ++c) {
      const CpcaCluster& k = t.clusters[c];
      for (std::size_t i = 0; i <= S; ++i) {
        const CpcaVector& v = i == 0 ? k.mean : k.basis[i - 1];
        for (std::size_t e = 0; e < v.term_count(); ++e)
          f(static_cast<uint32_t>(c * (S + 1) + i), v.index[e], t.Value(v, e));
      }
    }
  };
  each([&](uint32_t, uint32_t j, float) { ++column_begin_[j + 1]; });
  for (std::size_t j = 0; j < columns_; ++j) column_begin_[j + 1] += column_begin_[j];
  entry_vector_.resize(column_begin_[columns_]);
  entry_value_.resize(column_begin_[columns_]);
  std::vector<uint32_t> at(column_begin_.begin(), column_begin_.end() - 1);
  each([&](uint32_t k, uint32_t j, float v) {
    entry_vector_[at[j]] = k;
    entry_value_[at[j]++] = v;
  });
  // `each` walks the vectors in order, each by increasing column: the CSR arrays directly.
  vector_begin_.assign(vectors_ + 1, 0);
  row_column_.reserve(entry_vector_.size());
  row_value_.reserve(entry_vector_.size());
  each([&](uint32_t k, uint32_t j, float v) {
    ++vector_begin_[k + 1];
    row_column_.push_back(j);
    row_value_.push_back(v);
  });
  for (std::size_t k = 0; k < vectors_; ++k) vector_begin_[k + 1] += vector_begin_[k];
}

// Eq. 7: P_k += Σ_terms u_k[j]·L̂_j per channel, walking only the lighting's terms' columns.
void CpcaProjection::Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  if (out.size() != vectors_)
    throw std::invalid_argument("CpcaProjection: output has " + std::to_string(out.size()) +
                                " entries, expected " + std::to_string(vectors_));
  CheckTermIndices(terms, columns_, "CpcaProjection");
  double* o0 = out.channel[0].data();
  double* o1 = out.channel[1].data();
  double* o2 = out.channel[2].data();
  if (terms.size() * 8 >= columns_) {
    // Many terms: one dense lighting vector (repeated indices add), then per cluster vector a
    // sparse dot product, in parallel and with no scattered writes.
    std::vector<double> L(3 * columns_, 0.0);
    for (const LightingTerm& t : terms)
      for (int c = 0; c < 3; ++c) L[3 * t.index + c] += t.value[c];
    ParallelForRange(0, vectors_, 64, [&](std::size_t range_begin, std::size_t range_end) {
      for (std::size_t k = range_begin; k < range_end; ++k) {
        double a0 = 0, a1 = 0, a2 = 0;
        for (uint32_t e = vector_begin_[k]; e < vector_begin_[k + 1]; ++e) {
          const double v = row_value_[e];
          const double* l = L.data() + 3 * static_cast<std::size_t>(row_column_[e]);
          a0 += v * l[0];
          a1 += v * l[1];
          a2 += v * l[2];
        }
        o0[k] += a0;
        o1[k] += a1;
        o2[k] += a2;
      }
    });
    return;
  }
  for (const LightingTerm& t : terms) {
    const double l0 = t.value[0], l1 = t.value[1], l2 = t.value[2];
    for (uint32_t e = column_begin_[t.index]; e < column_begin_[t.index + 1]; ++e) {
      const double v = entry_value_[e];
      const uint32_t k = entry_vector_[e];
      o0[k] += v * l0;
      o1[k] += v * l1;
      o2[k] += v * l2;
    }
  }
}

CpcaRelighter::CpcaRelighter(const CpcaTransport& t, std::string name)
    : name_(std::move(name)),
      channels_(t.header.channels),
      clusters_(static_cast<uint32_t>(t.clusters.size())),
      bases_(t.bases()),
      spatial_(t.header.spatial_count()),
      projection_(t) {
  ValidateCpcaTransport(t, name_);
  const std::size_t rows = t.row_count(), S = bases_;
  cluster_of_ = t.cluster_of;
  weights_.assign(rows * (S + 1), 0.0f);
  for (std::size_t r = 0; r < rows; ++r) {
    weights_[r * (S + 1)] = 1.0f;
    for (std::size_t i = 0; i < S; ++i) {
      const float w = t.Coefficient(r, i);
      if (!std::isfinite(w))
        throw InputError(name_, "row " + std::to_string(r) + ": coefficient " + std::to_string(i) +
                                    " is not a finite float");
      weights_[r * (S + 1) + 1 + i] = w;
    }
  }
  cluster_begin_.assign(clusters_ + 1, 0);
  for (uint32_t c : cluster_of_) ++cluster_begin_[c + 1];
  for (uint32_t c = 0; c < clusters_; ++c) cluster_begin_[c + 1] += cluster_begin_[c];
  rows_of_cluster_.resize(rows);
  std::vector<uint32_t> at(cluster_begin_.begin(), cluster_begin_.end() - 1);
  for (std::size_t r = 0; r < rows; ++r)
    rows_of_cluster_[at[cluster_of_[r]]++] = static_cast<uint32_t>(r);
}

// Eq. 8: U_r = Σ_{i≤S} w_{r,i} P_{c(r),i} (i = 0 the mean, w = 1), per sample and channel.
void CpcaRelighter::Blend(const SampleRadiance& P, SampleRadiance& out) const {
  for (auto& c : out.channel) c.resize(spatial_);
  BlendRange(P, out, 0, spatial_, true);
}

void CpcaRelighter::BlendRange(const SampleRadiance& P, SampleRadiance& out, std::size_t first,
                               std::size_t count, bool assign) const {
  if (P.size() != projection_.sample_count())
    throw std::invalid_argument("CpcaRelighter::Blend: projection of the wrong size");
  if (out.size() != spatial_ || first > spatial_ || count > spatial_ - first)
    throw std::invalid_argument("CpcaRelighter::Blend: output or range of the wrong size");
  const std::size_t S1 = bases_ + 1;
  // P per cluster with the channels interleaved and padded (P_{c,i} as 4 doubles), so that a
  // one-channel row's three outputs take one vectorisable pass over its weights.
  const std::size_t K = clusters_;
  std::vector<double> Pi(K * S1 * 4, 0.0);
  for (std::size_t k = 0; k < K * S1; ++k)
    for (int ch = 0; ch < 3; ++ch) Pi[4 * k + ch] = P.channel[ch][k];
  std::atomic<bool> finite{true};
  ParallelForRange(first, first + count, 2048, [&](std::size_t range_begin, std::size_t range_end) {
    bool ok = true;
    for (std::size_t s = range_begin; s < range_end; ++s) {
      if (channels_ == 1) {
        const float* w = weights_.data() + s * S1;
        const double* p = Pi.data() + 4 * static_cast<std::size_t>(cluster_of_[s]) * S1;
        double a[4] = {0, 0, 0, 0};
        for (std::size_t i = 0; i < S1; ++i) {
          const double wi = w[i];
          for (int ch = 0; ch < 4; ++ch) a[ch] += wi * p[4 * i + ch];
        }
        for (int ch = 0; ch < 3; ++ch)
          out.channel[ch][s] = assign ? a[ch] : out.channel[ch][s] + a[ch];
        ok = ok && std::isfinite(out.channel[0][s]) && std::isfinite(out.channel[1][s]) &&
             std::isfinite(out.channel[2][s]);
      } else {
        for (std::size_t ch = 0; ch < 3; ++ch) {
          const std::size_t r = ch * spatial_ + s;
          const float* w = weights_.data() + r * S1;
          const double* p = Pi.data() + 4 * static_cast<std::size_t>(cluster_of_[r]) * S1 + ch;
          double a = 0;
          for (std::size_t i = 0; i < S1; ++i) a += w[i] * p[4 * i];
          out.channel[ch][s] = assign ? a : out.channel[ch][s] + a;
          ok = ok && std::isfinite(out.channel[ch][s]);
        }
      }
    }
    if (!ok) finite = false;
  });
  if (finite) return;
  for (int ch = 0; ch < 3; ++ch)
    for (std::size_t s = first; s < first + count; ++s)
      if (!std::isfinite(out.channel[ch][s]))
        throw NumericalError(name_ + ": relit radiance of sample " + std::to_string(s) +
                             " is not finite");
}

// Eq. 10 for a few entries: B += W[:, k]·ΔP_k over the rows of k's cluster.
void CpcaRelighter::BlendDelta(std::span<const uint32_t> vectors,
                               std::span<const std::array<double, 3>> delta,
                               SampleRadiance& out) const {
  if (vectors.size() != delta.size())
    throw std::invalid_argument("CpcaRelighter::BlendDelta: one delta per vector");
  const std::size_t S1 = bases_ + 1;
  // The entries grouped by cluster (stable: a cluster's entries in the order given), then every
  // cluster's rows in one pass that applies all of its entries; clusters' rows are disjoint, so
  // the clusters run in parallel.
  std::vector<uint32_t> order(vectors.size());
  for (std::size_t n = 0; n < vectors.size(); ++n) {
    if (vectors[n] / S1 >= clusters_)
      throw std::out_of_range("CpcaRelighter::BlendDelta: vector out of range");
    order[n] = static_cast<uint32_t>(n);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return vectors[a] / S1 < vectors[b] / S1; });
  std::vector<std::size_t> group{0};  // [group[g], group[g + 1]) of `order`: one cluster
  for (std::size_t n = 1; n <= order.size(); ++n)
    if (n == order.size() || vectors[order[n]] / S1 != vectors[order[n - 1]] / S1)
      group.push_back(n);
  if (order.empty()) return;
  ParallelFor(group.size() - 1, [&](std::size_t g) {
    const uint32_t c = static_cast<uint32_t>(vectors[order[group[g]]] / S1);
    // The group's entries once: which weight each takes, and its ΔP.
    const std::size_t m = group[g + 1] - group[g];
    std::vector<uint32_t> which(m);
    std::vector<std::array<double, 3>> d(m);
    for (std::size_t n = 0; n < m; ++n) {
      which[n] = static_cast<uint32_t>(vectors[order[group[g] + n]] % S1);
      d[n] = delta[order[group[g] + n]];
    }
    for (uint32_t e = cluster_begin_[c]; e < cluster_begin_[c + 1]; ++e) {
      const uint32_t r = rows_of_cluster_[e];
      const float* w = weights_.data() + static_cast<std::size_t>(r) * S1;
      double a[3] = {0, 0, 0};
      for (std::size_t n = 0; n < m; ++n) {
        const double wi = w[which[n]];
        for (int ch = 0; ch < 3; ++ch) a[ch] += wi * d[n][ch];
      }
      if (channels_ == 1) {
        for (int ch = 0; ch < 3; ++ch) out.channel[ch][r] += a[ch];
      } else {
        const std::size_t ch = r / spatial_, sm = r % spatial_;
        out.channel[ch][sm] += a[ch];
      }
    }
  });
}

void CpcaRelighter::Assign(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  SampleRadiance P(projection_.sample_count());
  projection_.Accumulate(terms, P);
  Blend(P, out);
}

void CpcaRelighter::AccumulateRange(std::span<const LightingTerm> terms, SampleRadiance& out,
                                    std::size_t first, std::size_t count, bool assign) const {
  // Step 1 whole (K·(S+1) projections: small), step 2 for the range's rows only.
  SampleRadiance P(projection_.sample_count());
  projection_.Accumulate(terms, P);
  BlendRange(P, out, first, count, assign);
}

void CpcaRelighter::Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  if (out.size() != spatial_)
    throw std::invalid_argument("CpcaRelighter: output has " + std::to_string(out.size()) +
                                " samples, expected " + std::to_string(spatial_));
  SampleRadiance add;
  Assign(terms, add);
  out += add;
}

CpcaIncrementalRelighter::CpcaIncrementalRelighter(const CpcaRelighter& relighter, int n,
                                                   std::size_t lighting_terms,
                                                   std::size_t basis_terms)
    : relighter_(relighter),
      step1_(relighter.projection(), n, lighting_terms),
      basis_terms_(basis_terms > 0 ? basis_terms
                                   : std::max<std::size_t>(1, relighter.bases() / 4)) {}

void CpcaIncrementalRelighter::Initialize(const WaveletLighting& lighting) {
  step1_.Initialize(lighting);
  represented_ = step1_.Radiance();
  relighter_.Blend(represented_, image_);
}

IncrementalFrame CpcaIncrementalRelighter::Update(const WaveletLighting& lighting) {
  if (image_.size() != relighter_.sample_count()) {
    // Not initialised: start from nothing lit.
    represented_ = SampleRadiance(relighter_.projection().sample_count());
    image_ = SampleRadiance(relighter_.sample_count());
  }
  IncrementalFrame frame = step1_.Update(lighting);  // step 1: PBI on L (Eq. 7)
  const SampleRadiance& P = step1_.Radiance();
  const std::size_t S1 = relighter_.bases() + 1;
  std::vector<uint32_t> chosen;
  std::vector<std::array<double, 3>> delta;
  std::vector<double> weight(S1 - 1);
  bool complete = true;
  for (uint32_t c = 0; c < relighter_.clusters(); ++c) {
    const std::size_t base = static_cast<std::size_t>(c) * S1;
    const auto diff = [&](std::size_t k) {
      return std::array<double, 3>{P.channel[0][k] - represented_.channel[0][k],
                                   P.channel[1][k] - represented_.channel[1][k],
                                   P.channel[2][k] - represented_.channel[2][k]};
    };
    // The mean's entry always (every row's weight 1), then the basis_terms basis entries with
    // the largest change |ΔP| (L1 over the channels): the basic incremental update of Eq. 10.
    std::vector<uint32_t> pick{0};
    for (std::size_t i = 1; i < S1; ++i) {
      const auto d = diff(base + i);
      weight[i - 1] = std::abs(d[0]) + std::abs(d[1]) + std::abs(d[2]);
    }
    for (uint32_t i : SelectLargest(weight, basis_terms_)) pick.push_back(i + 1);
    for (uint32_t i : pick) {
      const std::size_t k = base + i;
      const auto d = diff(k);
      if (d[0] == 0 && d[1] == 0 && d[2] == 0) continue;
      chosen.push_back(static_cast<uint32_t>(k));
      delta.push_back(d);
      for (int ch = 0; ch < 3; ++ch) represented_.channel[ch][k] = P.channel[ch][k];
    }
    for (std::size_t i = 1; i < S1 && complete; ++i)
      if (weight[i - 1] != 0 &&
          std::find(pick.begin(), pick.end(), static_cast<uint32_t>(i)) == pick.end())
        complete = false;
  }
  relighter_.BlendDelta(chosen, delta, image_);  // step 2: U += W·ΔP (Eq. 10)
  frame.exact = frame.exact && complete;
  return frame;
}

std::vector<float> ClusterColours(const CpcaRelighter& relighter) {
  std::vector<float> rgb(3 * relighter.sample_count());
  for (std::size_t s = 0; s < relighter.sample_count(); ++s) {
    // Golden-ratio hues with a hashed lightness, so that neighbouring ids differ.
    const uint32_t c = relighter.ClusterOf(s);
    const double h = std::fmod(c * 0.618033988749895, 1.0) * 6.0;
    const double v = 0.55 + 0.45 * static_cast<double>((c * 2654435761u) >> 29) / 7.0;
    const double x = 1.0 - std::fabs(std::fmod(h, 2.0) - 1.0);
    double r = 0, g = 0, b = 0;
    switch (static_cast<int>(h)) {
      case 0:
        r = 1, g = x;
        break;
      case 1:
        r = x, g = 1;
        break;
      case 2:
        g = 1, b = x;
        break;
      case 3:
        g = x, b = 1;
        break;
      case 4:
        r = x, b = 1;
        break;
      default:
        r = 1, b = x;
        break;
    }
    rgb[3 * s] = static_cast<float>(v * r);
    rgb[3 * s + 1] = static_cast<float>(v * g);
    rgb[3 * s + 2] = static_cast<float>(v * b);
  }
  return rgb;
}

std::size_t CpcaRelighter::memory_bytes() const {
  return projection_.memory_bytes() +
         sizeof(uint32_t) * (cluster_of_.size() + cluster_begin_.size() + rows_of_cluster_.size()) +
         sizeof(float) * weights_.size();
}

}  // namespace prt
