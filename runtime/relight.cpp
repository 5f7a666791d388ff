// Relighting from Haar-basis transport rows (Ng et al. 2003 Eq. 1; Overbeck et al. 2006 Eq. 4:
// ΔB = T·ΔL touches only the columns named by ΔL's terms).
#include "runtime/relight.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#include "runtime/compressed_relight.h"
#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace prt {

SampleRadiance::SampleRadiance(std::size_t samples) {
  for (auto& c : channel) c.assign(samples, 0.0);
}

void SampleRadiance::SetZero() {
  for (auto& c : channel) std::fill(c.begin(), c.end(), 0.0);
}

SampleRadiance& SampleRadiance::operator+=(const SampleRadiance& other) {
  if (other.size() != size()) throw std::invalid_argument("SampleRadiance += : size mismatch");
  for (int c = 0; c < 3; ++c) {
    double* __restrict d = channel[c].data();
    const double* __restrict s = other.channel[c].data();
    const std::size_t n = size();
    for (std::size_t i = 0; i < n; ++i) d[i] += s[i];
  }
  return *this;
}

void TransportOperator::Assign(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  if (out.size() != sample_count()) {
    out = SampleRadiance(sample_count());
  } else {
    out.SetZero();
  }
  Accumulate(terms, out);
}

SampleRadiance TransportOperator::Apply(std::span<const LightingTerm> terms) const {
  SampleRadiance out;
  Assign(terms, out);
  return out;
}

void TransportOperator::AccumulateRange(std::span<const LightingTerm> terms, SampleRadiance& out,
                                        std::size_t first, std::size_t count, bool assign) const {
  const std::size_t samples = sample_count();
  if (out.size() != samples || first > samples || count > samples - first)
    throw std::out_of_range("AccumulateRange: output or range outside the samples");
  const SampleRadiance all = Apply(terms);
  for (int c = 0; c < 3; ++c)
    for (std::size_t s = first; s < first + count; ++s)
      out.channel[c][s] = assign ? all.channel[c][s] : out.channel[c][s] + all.channel[c][s];
}

namespace {

void CheckTerms(std::span<const LightingTerm> terms, std::size_t coefficients,
                const SampleRadiance& out, std::size_t samples) {
  if (out.size() != samples) {
    throw std::invalid_argument("TransportOperator::Accumulate: output has " +
                                std::to_string(out.size()) + " samples, expected " +
                                std::to_string(samples));
  }
  for (const LightingTerm& t : terms) {
    if (t.index >= coefficients) {
      throw std::out_of_range("TransportOperator::Accumulate: coefficient " +
                              std::to_string(t.index) + " out of range (" +
                              std::to_string(coefficients) + " coefficients)");
    }
  }
}

// A value for an error message: 7 significant digits (std::to_string writes 1e39 in full).
std::string Number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.7g", v);
  return b;
}

std::size_t BlockCount(std::size_t samples, std::size_t block) {
  return (samples + block - 1) / block;
}

void CheckChannelCount(uint32_t channels, const char* what) {
  if (channels != 1 && channels != 3)
    throw std::invalid_argument(std::string(what) + ": channel count " + std::to_string(channels) +
                                " is not 1 or 3");
}

}  // namespace

DenseTransport::DenseTransport(std::span<const float> rows, std::size_t samples,
                               std::size_t coefficients, uint32_t channels)
    : samples_(samples), coefficients_(coefficients), channels_(channels) {
  CheckChannelCount(channels, "DenseTransport");
  if (rows.size() != channels * samples * coefficients) {
    throw std::invalid_argument("DenseTransport: " + std::to_string(rows.size()) + " values for " +
                                std::to_string(channels) + " × " + std::to_string(samples) + " × " +
                                std::to_string(coefficients));
  }
  const std::size_t nb = BlockCount(samples, kBlockSamples);
  blocks_.assign(channels * nb * coefficients * kBlockSamples, 0.0f);
  // Transpose each block of rows into column-major order (parallel over blocks of every channel:
  // block (c, b) holds rows c·samples + [b·kBlockSamples, …)).
  ParallelFor(channels * nb, [&](std::size_t cb) {
    const std::size_t c = cb / nb, b = cb % nb;
    const std::size_t s0 = b * kBlockSamples;
    const std::size_t s1 = std::min(samples, s0 + kBlockSamples);
    float* dst = blocks_.data() + cb * coefficients * kBlockSamples;
    for (std::size_t s = s0; s < s1; ++s) {
      const float* row = rows.data() + (c * samples + s) * coefficients;
      for (std::size_t j = 0; j < coefficients; ++j) {
        if (!std::isfinite(row[j])) {
          throw std::invalid_argument(
              "DenseTransport: NaN/Inf at sample " + std::to_string(s) +
              (channels > 1 ? " (channel " + std::to_string(c) + ")" : std::string()) +
              ", coefficient " + std::to_string(j));
        }
        dst[j * kBlockSamples + (s - s0)] = row[j];
      }
    }
  });
}

void DenseTransport::Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  CheckTerms(terms, coefficients_, out, samples_);
  if (terms.empty() || samples_ == 0) return;
  const std::size_t nb = BlockCount(samples_, kBlockSamples);
  ParallelForRange(0, nb, 1, [&](std::size_t range_begin, std::size_t range_end) {
    for (std::size_t b = range_begin; b != range_end; ++b) {
      const std::size_t s0 = b * kBlockSamples;
      const std::size_t len = std::min(samples_, s0 + kBlockSamples) - s0;
      // Accumulate the block locally (fixed size, stays in L1), then add once.
      alignas(64) double acc[3][kBlockSamples] = {};
      if (channels_ == 1) {
        const float* base = blocks_.data() + b * coefficients_ * kBlockSamples;
        for (const LightingTerm& t : terms) {
          const float* __restrict col = base + static_cast<std::size_t>(t.index) * kBlockSamples;
          const double vr = t.value[0], vg = t.value[1], vb = t.value[2];
          for (std::size_t i = 0; i < kBlockSamples; ++i) {
            const double x = static_cast<double>(col[i]);
            acc[0][i] += x * vr;
            acc[1][i] += x * vg;
            acc[2][i] += x * vb;
          }
        }
      } else {
        // Channel c's rows are block (c, b): lit by lighting channel c only.
        for (int c = 0; c < 3; ++c) {
          const float* base = blocks_.data() + (static_cast<std::size_t>(c) * nb + b) *
                                                   coefficients_ * kBlockSamples;
          double* __restrict a = acc[c];
          for (const LightingTerm& t : terms) {
            const float* __restrict col = base + static_cast<std::size_t>(t.index) * kBlockSamples;
            const double v = t.value[c];
            for (std::size_t i = 0; i < kBlockSamples; ++i) a[i] += static_cast<double>(col[i]) * v;
          }
        }
      }
      for (int c = 0; c < 3; ++c) {
        double* __restrict o = out.channel[c].data() + s0;
        for (std::size_t i = 0; i < len; ++i) o[i] += acc[c][i];
      }
    }
  });
}

SparseTransport::SparseTransport(std::span<const uint64_t> row_offsets,
                                 std::span<const uint32_t> indices, std::span<const float> values,
                                 std::size_t coefficients, uint32_t channels)
    : samples_(0), coefficients_(coefficients), channels_(channels) {
  CheckChannelCount(channels, "SparseTransport");
  if (row_offsets.empty() || row_offsets.front() != 0 || row_offsets.back() != indices.size() ||
      indices.size() != values.size()) {
    throw std::invalid_argument("SparseTransport: inconsistent CSR offsets/indices/values");
  }
  const std::size_t rows = row_offsets.size() - 1;
  if (rows % channels != 0) {
    throw std::invalid_argument("SparseTransport: " + std::to_string(rows) +
                                " rows are not a multiple of " + std::to_string(channels) +
                                " channels");
  }
  samples_ = rows / channels;
  for (std::size_t s = 0; s < rows; ++s) {
    if (row_offsets[s + 1] < row_offsets[s]) {
      throw std::invalid_argument("SparseTransport: row offsets decrease at sample " +
                                  std::to_string(s));
    }
  }
  for (std::size_t k = 0; k < indices.size(); ++k) {
    if (indices[k] >= coefficients) {
      throw std::invalid_argument("SparseTransport: coefficient index " +
                                  std::to_string(indices[k]) + " out of range");
    }
    if (!std::isfinite(values[k])) {
      throw std::invalid_argument("SparseTransport: NaN/Inf value at non-zero " +
                                  std::to_string(k));
    }
  }
  const std::size_t nb = BlockCount(samples_, kBlockSamples);
  const std::size_t stride = coefficients + 1;
  column_start_.assign(channels * nb * stride, 0);
  local_sample_.resize(values.size());
  values_.resize(values.size());
  // Counting sort of each block's non-zeros by column; blocks occupy the same value range as in
  // the CSR input (rows of a block are contiguous there), so blocks fill independently. Block
  // (c, b) holds rows c·samples + [b·kBlockSamples, …).
  ParallelFor(channels * nb, [&](std::size_t cb) {
    const std::size_t row0 = (cb / nb) * samples_;
    const std::size_t s0 = row0 + (cb % nb) * kBlockSamples;
    const std::size_t s1 = std::min(row0 + samples_, s0 + kBlockSamples);
    const uint64_t first = row_offsets[s0];
    uint64_t* start = column_start_.data() + cb * stride;
    for (std::size_t s = s0; s < s1; ++s) {
      for (uint64_t k = row_offsets[s]; k < row_offsets[s + 1]; ++k) ++start[indices[k] + 1];
    }
    start[0] = first;
    for (std::size_t j = 0; j < coefficients; ++j) start[j + 1] += start[j];
    std::vector<uint64_t> fill(start, start + coefficients);
    for (std::size_t s = s0; s < s1; ++s) {
      for (uint64_t k = row_offsets[s]; k < row_offsets[s + 1]; ++k) {
        const uint64_t dst = fill[indices[k]]++;
        local_sample_[dst] = static_cast<uint16_t>(s - s0);
        values_[dst] = values[k];
      }
    }
  });
}

void SparseTransport::Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const {
  CheckTerms(terms, coefficients_, out, samples_);
  if (terms.empty() || samples_ == 0) return;
  const std::size_t nb = BlockCount(samples_, kBlockSamples);
  const std::size_t stride = coefficients_ + 1;
  if (channels_ != 1) {
    // Block (c, b) adds lighting channel c to radiance channel c only; blocks of one b in
    // different channels write different arrays, so they run in parallel too.
    ParallelForRange(0, channels_ * nb, 1, [&](std::size_t range_begin, std::size_t range_end) {
      for (std::size_t cb = range_begin; cb != range_end; ++cb) {
        const std::size_t c = cb / nb;
        double* __restrict o = out.channel[c].data() + (cb % nb) * kBlockSamples;
        const uint64_t* start = column_start_.data() + cb * stride;
        for (const LightingTerm& t : terms) {
          const double v = t.value[c];
          for (uint64_t k = start[t.index]; k < start[t.index + 1]; ++k)
            o[local_sample_[k]] += static_cast<double>(values_[k]) * v;
        }
      }
    });
    return;
  }
  ParallelForRange(0, nb, 1, [&](std::size_t range_begin, std::size_t range_end) {
    for (std::size_t b = range_begin; b != range_end; ++b) {
      const std::size_t s0 = b * kBlockSamples;
      double* __restrict r = out.channel[0].data() + s0;
      double* __restrict g = out.channel[1].data() + s0;
      double* __restrict bl = out.channel[2].data() + s0;
      const uint64_t* start = column_start_.data() + b * stride;
      for (const LightingTerm& t : terms) {
        const double vr = t.value[0], vg = t.value[1], vb = t.value[2];
        for (uint64_t k = start[t.index]; k < start[t.index + 1]; ++k) {
          const std::size_t i = local_sample_[k];
          const double x = static_cast<double>(values_[k]);
          r[i] += x * vr;
          g[i] += x * vg;
          bl[i] += x * vb;
        }
      }
    }
  });
}

CompressedTransportOperator::CompressedTransportOperator(const CompressedRelighter& relighter,
                                                         SampleOrder order)
    : relighter_(relighter), order_(order) {
  if (relighter.header().row_wavelet != RowWavelet::kHaar) {
    throw std::invalid_argument(
        "CompressedTransportOperator: the transport rows use the D4 row wavelet; the viewer's "
        "lighting is in the Haar basis");
  }
}

std::size_t CompressedTransportOperator::sample_count() const {
  return relighter_.sample_count();
}

std::size_t CompressedTransportOperator::coefficient_count() const {
  return relighter_.column_count();
}

void CompressedTransportOperator::Accumulate(std::span<const LightingTerm> terms,
                                             SampleRadiance& out) const {
  Relight(terms, out, false);
}

void CompressedTransportOperator::Assign(std::span<const LightingTerm> terms,
                                         SampleRadiance& out) const {
  // Resized without clearing: RelightSparseAdd with `assign` writes every value.
  for (auto& c : out.channel) c.resize(sample_count());
  Relight(terms, out, true);
}

void CompressedTransportOperator::Weights(std::span<const LightingTerm> terms,
                                          std::vector<uint32_t>& columns,
                                          std::vector<float>& weights) const {
  columns.resize(terms.size());
  weights.resize(3 * terms.size());
  for (std::size_t k = 0; k < terms.size(); ++k) {
    columns[k] = terms[k].index;
    for (int c = 0; c < 3; ++c) {
      const double v = terms[k].value[c];
      CheckFloatLighting(v, terms[k].index, c, relighter_.name());
      weights[3 * k + c] = static_cast<float>(v);
    }
  }
}

void CompressedTransportOperator::AccumulateRange(std::span<const LightingTerm> terms,
                                                  SampleRadiance& out, std::size_t first,
                                                  std::size_t count, bool assign) const {
  if (order_ != SampleOrder::kCoefficients) {
    TransportOperator::AccumulateRange(terms, out, first, count, assign);
    return;
  }
  const std::size_t samples = sample_count();
  CheckTerms(terms, coefficient_count(), out, samples);
  if (first > samples || count > samples - first)
    throw std::out_of_range("AccumulateRange: range outside the samples");
  if (count == 0 || (terms.empty() && !assign)) return;
  std::vector<uint32_t> columns;
  std::vector<float> weights;
  Weights(terms, columns, weights);
  double* const channels[3] = {out.channel[0].data(), out.channel[1].data(), out.channel[2].data()};
  relighter_.RelightSparseAddRange(columns, weights, 3, first, count, channels, assign);
}

void CompressedTransportOperator::Relight(std::span<const LightingTerm> terms, SampleRadiance& out,
                                          bool assign) const {
  const std::size_t samples = sample_count();
  CheckTerms(terms, coefficient_count(), out, samples);
  if (samples == 0 || (terms.empty() && !assign)) return;
  std::vector<uint32_t> columns;
  std::vector<float> weights;
  Weights(terms, columns, weights);
  double* const channels[3] = {out.channel[0].data(), out.channel[1].data(), out.channel[2].data()};
  relighter_.RelightSparseAdd(columns, weights, 3, channels, order_, assign);
}

void CheckFloatLighting(double value, std::size_t coefficient, int channel,
                        const std::string& source) {
  if (std::abs(value) <= static_cast<double>(std::numeric_limits<float>::max())) return;
  throw NumericalError(source + ": lighting coefficient " + std::to_string(coefficient) +
                       " (channel " + std::to_string(channel) + ") is " +
                       (std::isnan(value)
                            ? std::string("NaN")
                            : Number(value) + ", outside the float range of the relighter") +
                       "; the environment is too bright");
}

std::vector<float> ShadeSamples(const SampleRadiance& radiance, std::span<const Rgb> albedo,
                                const std::string& source, std::span<const uint32_t> sample_name) {
  const std::size_t n = radiance.size();
  if (albedo.size() > 1 && albedo.size() != n) {
    throw std::invalid_argument("ShadeSamples: " + std::to_string(albedo.size()) + " albedos for " +
                                std::to_string(n) + " samples");
  }
  if (!sample_name.empty() && sample_name.size() != n)
    throw std::invalid_argument("ShadeSamples: sample names for another sample count");
  std::vector<float> rgb(3 * n);
  bool finite = true;
  for (std::size_t s = 0; s < n; ++s) {
    for (int c = 0; c < 3; ++c) {
      const double a = albedo.empty() ? 1.0 : albedo[albedo.size() == 1 ? 0 : s][c];
      const auto v = static_cast<float>(a * radiance.channel[c][s]);
      finite = finite && std::isfinite(v);
      rgb[3 * s + c] = v;
    }
  }
  if (finite) return rgb;
  // The first sample that does not fit: its radiance may itself be NaN/Inf (an operator that let
  // one through) or a finite double beyond the float range (finite T and L whose product
  // overflows float, e.g. 1e39).
  for (std::size_t s = 0; s < n; ++s) {
    for (int c = 0; c < 3; ++c) {
      if (std::isfinite(rgb[3 * s + c])) continue;
      const double a = albedo.empty() ? 1.0 : albedo[albedo.size() == 1 ? 0 : s][c];
      const double r = radiance.channel[c][s];
      const std::size_t name = sample_name.empty() ? s : sample_name[s];
      const std::string where = source + ": the shaded radiance of sample " + std::to_string(name) +
                                " (channel " + std::to_string(c) + ")";
      if (!std::isfinite(r))
        throw NumericalError(where + ": T·L is " + (std::isnan(r) ? "NaN" : "Inf"));
      throw NumericalError(where + ", albedo " + Number(a) + " × T·L " + Number(r) +
                           ", is outside the float range (3.4e38); the lighting is too bright");
    }
  }
  return rgb;
}

}  // namespace prt
