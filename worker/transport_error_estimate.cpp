// Monte-Carlo error of relit radiance (see transport_error_estimate.h).
#include "worker/transport_error_estimate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <stdexcept>

namespace prt {

namespace {

// Σ_j a_j·b_j over `n` floats: eight float lanes summed into double every 256 terms, so that the
// loop vectorises and a row of 6n² terms keeps ~1e-7 relative accuracy.
double Dot(const float* a, const float* b, std::size_t n) {
  double total = 0;
  std::size_t j = 0;
  while (j < n) {
    const std::size_t end = std::min(n, j + 256);
    float lane[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (; j + 8 <= end; j += 8)
      for (int k = 0; k < 8; ++k) lane[k] += a[j + k] * b[j + k];
    for (; j < end; ++j) lane[0] += a[j] * b[j];
    for (float x : lane) total += x;
  }
  return total;
}

}  // namespace

void ExactSum::Add(double v) {
  if (!std::isfinite(v) || v < 0) {
    special_ += v;  // NaN or ∞ (never for rows checked finite): the same whatever the order
    return;
  }
  // v = M · 2^(p − 1074) with M < 2^53, from its bits (subnormals included).
  const uint64_t bits = std::bit_cast<uint64_t>(v);
  const uint64_t exponent = bits >> 52;
  uint64_t M = bits & ((uint64_t{1} << 52) - 1);
  uint64_t p = 0;
  if (exponent > 0) {
    M |= uint64_t{1} << 52;
    p = exponent - 1;
  }
  // M·2^(p mod 32) spans three 32-bit digits from digit p / 32.
  const std::size_t k = static_cast<std::size_t>(p / 32);
  const unsigned s = static_cast<unsigned>(p % 32);
  digits_[k] += (M << s) & 0xffffffffu;
  digits_[k + 1] += (s == 0 ? M >> 32 : M >> (32 - s)) & 0xffffffffu;
  digits_[k + 2] += s == 0 ? 0 : M >> (64 - s);
  // Each digit grows by less than 2^32 per Add: carried before it could pass 2^63.
  if (++adds_ == (uint64_t{1} << 31)) Carry();
}

void ExactSum::Add(const ExactSum& o) {
  ExactSum other = o;
  other.Carry();
  Carry();
  for (std::size_t k = 0; k < kDigits; ++k) digits_[k] += other.digits_[k];
  special_ += o.special_;
  Carry();
}

void ExactSum::Carry() {
  uint64_t carry = 0;
  for (uint64_t& d : digits_) {
    d += carry;
    carry = d >> 32;
    d &= 0xffffffffu;
  }
  if (carry != 0) throw std::overflow_error("ExactSum: beyond 2^1102");
  adds_ = 0;
}

double ExactSum::Value() const {
  ExactSum c = *this;
  c.Carry();
  // The top three non-zero digits (96 bits) make the double: the same on every machine.
  std::size_t top = kDigits;
  while (top > 0 && c.digits_[top - 1] == 0) --top;
  if (top == 0) return special_;
  double v = 0;
  for (std::size_t k = top; k-- > (top >= 3 ? top - 3 : 0);)
    v += std::ldexp(static_cast<double>(c.digits_[k]), static_cast<int>(32 * k) - 1074);
  return v + special_;
}

std::vector<double> ExactSum::Digits() const {
  ExactSum c = *this;
  c.Carry();
  std::vector<double> out(c.digits_.begin(), c.digits_.end());
  out.push_back(special_);
  return out;
}

void ExactSum::SetDigits(const double* digits) {
  std::fill(digits_.begin(), digits_.end(), 0);
  for (std::size_t k = 0; k < kDigits; ++k) {
    const double d = digits[k];
    if (!(d >= 0 && d < 0x1p64 && d == std::floor(d)))
      throw std::invalid_argument("ExactSum::SetDigits: not a digit sum");
    digits_[k] = static_cast<uint64_t>(d);
  }
  special_ = digits[kDigits];
  // Digit sums of fewer than 2^21 processes are below 2^53: carrying them may need the headroom.
  uint64_t carry = 0;
  for (uint64_t& d : digits_) {
    const uint64_t low = (d & 0xffffffffu) + (carry & 0xffffffffu);
    carry = (d >> 32) + (carry >> 32) + (low >> 32);
    d = low & 0xffffffffu;
  }
  if (carry != 0) throw std::overflow_error("ExactSum::SetDigits: beyond 2^1102");
  adds_ = 0;
}

std::array<double, 3> MeshRadianceVariance(const TransportVariance& variance, std::size_t mesh,
                                           const CubemapRgb& light) {
  if (mesh >= variance.sums.size() || light.TexelCount() != variance.texels())
    throw std::invalid_argument("MeshRadianceVariance: mesh or cubemap size mismatch");
  std::array<double, 3> out{0, 0, 0};
  const std::vector<double> s = variance.MeshSums(mesh);
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& l = light.Channel(c);
    double sum = 0;
    for (std::size_t j = 0; j < s.size(); ++j) sum += double(l[j]) * l[j] * s[j];
    out[c] = sum;
  }
  return out;
}

RadianceNormAccumulator::RadianceNormAccumulator(std::vector<CubemapRgb> lights,
                                                 std::vector<uint64_t> mesh_rows, int channels,
                                                 SampleGroupMap sample_group)
    : lights_(std::move(lights)), sample_group_(std::move(sample_group)), channels_(channels) {
  mesh_first_.push_back(0);
  for (uint64_t r : mesh_rows) mesh_first_.push_back(mesh_first_.back() + r);
  if (sample_group_ && sample_group_->size() != mesh_first_.back())
    throw std::invalid_argument("RadianceNormAccumulator: the sample groups miss samples");
  for (const CubemapRgb& l : lights_) grey_.push_back(l.r == l.g && l.r == l.b);
  exact_.assign(lights_.size() * mesh_rows.size() * 3, ExactSum());
  norms_.assign(lights_.size(),
                std::vector<std::array<double, 3>>(mesh_rows.size(), {0.0, 0.0, 0.0}));
}

void RadianceNormAccumulator::AddRows(uint64_t first, uint64_t count, const float* rows) {
  if (lights_.empty() || count == 0) return;
  const std::size_t T = lights_.front().TexelCount();
  using Sums = std::vector<ExactSum>;  // [light][mesh][channel], flattened
  const std::size_t meshes = mesh_first_.size() - 1;
  // Each row's (Σ_j T_j·L_j)² is a double computed from that row alone; the sums of them are
  // exact (ExactSum), so TBB's split of the rows, the chunks the rows arrive in and the ranks
  // they are spread over do not change a bit of the result.
  const Sums sums = tbb::parallel_reduce(
      tbb::blocked_range<uint64_t>(0, count, 16), Sums(exact_.size()),
      [&](const tbb::blocked_range<uint64_t>& r, Sums acc) {
        for (uint64_t i = r.begin(); i != r.end(); ++i) {
          const uint64_t V = mesh_first_.back();
          const uint64_t row = channels_ == 1 ? first + i : (first + i) % V;
          const int only = channels_ == 1 ? -1 : static_cast<int>((first + i) / V);
          std::size_t m = 0;
          if (sample_group_) {
            if (row >= sample_group_->size())
              throw std::out_of_range("RadianceNormAccumulator: row beyond the samples");
            m = (*sample_group_)[row];
          } else {
            while (m + 1 < mesh_first_.size() && row >= mesh_first_[m + 1]) ++m;
          }
          if (m >= meshes) throw std::out_of_range("RadianceNormAccumulator: row beyond meshes");
          for (std::size_t l = 0; l < lights_.size(); ++l) {
            double b = 0;
            for (int c = 0; c < 3; ++c) {
              if (only >= 0 && c != only) continue;
              // A grey light (the uniform sky) needs one product for its three channels.
              if (c == 0 || only >= 0 || !grey_[l])
                b = Dot(rows + i * T, lights_[l].Channel(c).data(), T);
              acc[(l * meshes + m) * 3 + static_cast<std::size_t>(c)].Add(b * b);
            }
          }
        }
        return acc;
      },
      [](Sums a, const Sums& b) {
        for (std::size_t k = 0; k < a.size(); ++k) a[k].Add(b[k]);
        return a;
      });
  for (std::size_t k = 0; k < exact_.size(); ++k) exact_[k].Add(sums[k]);
  UpdateNorms();
}

void RadianceNormAccumulator::UpdateNorms() {
  const std::size_t meshes = mesh_first_.size() - 1;
  for (std::size_t l = 0; l < lights_.size(); ++l)
    for (std::size_t m = 0; m < meshes; ++m)
      for (std::size_t c = 0; c < 3; ++c)
        norms_[l][m][c] = exact_[(l * meshes + m) * 3 + c].Value();
}

std::vector<double> RadianceNormAccumulator::Flat() const {
  std::vector<double> out;
  for (const ExactSum& e : exact_) {
    const std::vector<double> d = e.Digits();
    out.insert(out.end(), d.begin(), d.end());
  }
  return out;
}

void RadianceNormAccumulator::Set(const std::vector<double>& flat) {
  if (flat.size() != exact_.size() * ExactSum::kFlatSize)
    throw std::invalid_argument("RadianceNormAccumulator::Set: not the sums of this shape");
  for (std::size_t k = 0; k < exact_.size(); ++k)
    exact_[k].SetDigits(flat.data() + k * ExactSum::kFlatSize);
  UpdateNorms();
}

}  // namespace prt
