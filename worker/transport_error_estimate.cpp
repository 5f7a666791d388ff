// Monte-Carlo error of relit radiance (see transport_error_estimate.h).
#include "worker/transport_error_estimate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

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

std::array<double, 3> MeshRadianceVariance(const TransportVariance& variance, std::size_t mesh,
                                           const CubemapRgb& light) {
  if (mesh >= variance.sums.size() || light.TexelCount() != variance.texels())
    throw std::invalid_argument("MeshRadianceVariance: mesh or cubemap size mismatch");
  std::array<double, 3> out{0, 0, 0};
  const std::vector<double>& s = variance.sums[mesh];
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& l = light.Channel(c);
    double sum = 0;
    for (std::size_t j = 0; j < s.size(); ++j) sum += double(l[j]) * l[j] * s[j];
    out[c] = sum;
  }
  return out;
}

RadianceNormAccumulator::RadianceNormAccumulator(std::vector<CubemapRgb> lights,
                                                 std::vector<uint64_t> mesh_rows, int channels)
    : lights_(std::move(lights)), channels_(channels) {
  mesh_first_.push_back(0);
  for (uint64_t r : mesh_rows) mesh_first_.push_back(mesh_first_.back() + r);
  for (const CubemapRgb& l : lights_) grey_.push_back(l.r == l.g && l.r == l.b);
  norms_.assign(lights_.size(),
                std::vector<std::array<double, 3>>(mesh_rows.size(), {0.0, 0.0, 0.0}));
}

void RadianceNormAccumulator::AddRows(uint64_t first, uint64_t count, const float* rows) {
  if (lights_.empty() || count == 0) return;
  const std::size_t T = lights_.front().TexelCount();
  using Sums = std::vector<double>;  // [light][mesh][channel], flattened
  const std::size_t meshes = mesh_first_.size() - 1;
  const std::size_t size = lights_.size() * meshes * 3;
  const Sums sums = tbb::parallel_reduce(
      tbb::blocked_range<uint64_t>(0, count, 16), Sums(size, 0.0),
      [&](const tbb::blocked_range<uint64_t>& r, Sums acc) {
        for (uint64_t i = r.begin(); i != r.end(); ++i) {
          const uint64_t V = mesh_first_.back();
          const uint64_t row = channels_ == 1 ? first + i : (first + i) % V;
          const int only = channels_ == 1 ? -1 : static_cast<int>((first + i) / V);
          std::size_t m = 0;
          while (m + 1 < mesh_first_.size() && row >= mesh_first_[m + 1]) ++m;
          if (m >= meshes) throw std::out_of_range("RadianceNormAccumulator: row beyond meshes");
          for (std::size_t l = 0; l < lights_.size(); ++l) {
            double b = 0;
            for (int c = 0; c < 3; ++c) {
              if (only >= 0 && c != only) continue;
              // A grey light (the uniform sky) needs one product for its three channels.
              if (c == 0 || only >= 0 || !grey_[l])
                b = Dot(rows + i * T, lights_[l].Channel(c).data(), T);
              acc[(l * meshes + m) * 3 + static_cast<std::size_t>(c)] += b * b;
            }
          }
        }
        return acc;
      },
      [](Sums a, const Sums& b) {
        for (std::size_t k = 0; k < a.size(); ++k) a[k] += b[k];
        return a;
      });
  for (std::size_t l = 0; l < lights_.size(); ++l)
    for (std::size_t m = 0; m < meshes; ++m)
      for (int c = 0; c < 3; ++c) norms_[l][m][c] += sums[(l * meshes + m) * 3 + c];
}

std::vector<double> RadianceNormAccumulator::Flat() const {
  std::vector<double> out;
  for (const auto& light : norms_)
    for (const auto& mesh : light) out.insert(out.end(), mesh.begin(), mesh.end());
  return out;
}

void RadianceNormAccumulator::Set(const std::vector<double>& flat) {
  std::size_t k = 0;
  for (auto& light : norms_)
    for (auto& mesh : light)
      for (double& v : mesh) {
        if (k >= flat.size()) throw std::invalid_argument("RadianceNormAccumulator::Set: too few");
        v = flat[k++];
      }
  if (k != flat.size()) throw std::invalid_argument("RadianceNormAccumulator::Set: too many");
}

}  // namespace prt
