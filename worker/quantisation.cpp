// Non-linear scaling, per-column normalisation and subtractive-dither quantisation
// (Cheslack-Postava et al. 2008 §4.3). See quantisation.h for the exact formulas.
#include "worker/quantisation.h"

#include <algorithm>
#include <cmath>

#include "formats/column_coding.h"

namespace prt {

int32_t QuantiseDithered(double u, double dither, int bits) {
  const int A = QuantiserMax(bits);
  const double q = std::floor(u * A + dither + 0.5);
  return static_cast<int32_t>(std::clamp(q, static_cast<double>(-A), static_cast<double>(A)));
}

double DequantiseDithered(int32_t q, double dither, int bits) {
  return (static_cast<double>(q) - dither) / QuantiserMax(bits);
}

CompressedColumn QuantiseColumn(uint32_t column, int depth, const float* coefficients,
                                std::span<const uint32_t> kept, const uint8_t* scale_map, int bits,
                                uint64_t dither_seed) {
  CompressedColumn c;
  c.column = column;
  c.depth = static_cast<uint8_t>(depth);
  double m = 0;
  for (uint32_t i : kept)
    m = std::max(m, std::fabs(static_cast<double>(coefficients[i])) * ScaleFactor(scale_map[i]));
  if (!(m > 0) || !std::isfinite(m)) return c;
  // The stored float scale must not be below m, so that |u| ≤ 1 and |q| ≤ A without clamping.
  float mf = static_cast<float>(m);
  if (static_cast<double>(mf) < m) mf = std::nextafter(mf, INFINITY);
  if (!std::isfinite(mf) || !(mf > 0)) return c;
  c.scale = mf;
  const double inv = 1.0 / static_cast<double>(mf);
  c.index.reserve(kept.size());
  c.q.reserve(kept.size());
  for (uint32_t i : kept) {
    const double u = static_cast<double>(coefficients[i]) * ScaleFactor(scale_map[i]) * inv;
    const int32_t q = QuantiseDithered(u, DitherOffset(dither_seed, column, i), bits);
    if (q != 0) {
      c.index.push_back(i);
      c.q.push_back(q);
    }
  }
  return c;
}

}  // namespace prt
