#include "runtime/brdf.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace prt {

namespace {

struct DctTables {
  float basis[4][16];
  float inverse[5][4][4];  // [l][u][i]: A_u = Σ_i inverse[l][u][i] f(x_i) (1D)
  DctTables() {
    for (int u = 0; u < 4; ++u)
      for (int x = 0; x < 16; ++x) basis[u][x] = static_cast<float>(Phi(u, x));
    for (int l : {1, 2, 4}) {
      // M[i][u] = φ_u(x_i); invert by Gauss–Jordan in double.
      double m[4][8] = {};
      for (int i = 0; i < l; ++i) {
        for (int u = 0; u < l; ++u) m[i][u] = Phi(u, BlockDct::SamplePosition(l, i));
        m[i][l + i] = 1.0;
      }
      for (int c = 0; c < l; ++c) {
        int p = c;
        for (int r = c + 1; r < l; ++r)
          if (std::abs(m[r][c]) > std::abs(m[p][c])) p = r;
        for (int k = 0; k < 2 * l; ++k) std::swap(m[c][k], m[p][k]);
        const double d = m[c][c];
        for (int k = 0; k < 2 * l; ++k) m[c][k] /= d;
        for (int r = 0; r < l; ++r) {
          if (r == c) continue;
          const double f = m[r][c];
          for (int k = 0; k < 2 * l; ++k) m[r][k] -= f * m[c][k];
        }
      }
      for (int u = 0; u < l; ++u)
        for (int i = 0; i < l; ++i) inverse[l][u][i] = static_cast<float>(m[u][l + i]);
    }
  }
  static double Phi(int u, double x) {
    const double a = u == 0 ? 0.25 : std::numbers::sqrt2 / 4.0;
    return a * std::cos(std::numbers::pi * (2.0 * x + 1.0) * u / 32.0);
  }
};

const DctTables& Tables() {
  static const DctTables t;
  return t;
}

}  // namespace

ShadingFrame MakeShadingFrame(const Vec3& normal, const Vec3& view) {
  ShadingFrame f;
  f.normal = Normalize(normal);
  if (Length(f.normal) == 0) f.normal = {0, 1, 0};
  OrthonormalBasis(f.normal, f.tangent, f.bitangent);
  f.view = Normalize(view);
  if (Length(f.view) == 0) f.view = f.normal;
  f.reflect = 2.0 * Dot(f.normal, f.view) * f.normal - f.view;
  return f;
}

bool HasSpecular(const Material& m) {
  return m.model != BrdfModel::kLambert &&
         (m.specular[0] > 0 || m.specular[1] > 0 || m.specular[2] > 0);
}

double EffectiveExponent(const Material& m) {
  if (m.model == BrdfModel::kAshikhminShirley) return std::max(m.exponent, m.exponent_v);
  if (m.model == BrdfModel::kGgx) {
    const double a = m.roughness * m.roughness;
    return std::max(0.0, 2.0 / (a * a) - 2.0);
  }
  return m.exponent;
}

Material MaterialOfSettings(const GlossyMaterialSettings& g, const Rgb& albedo) {
  Material m;
  m.diffuse = albedo;
  if (g.brdf == "lambert") return m;
  if (g.brdf == "phong") {
    m.model = BrdfModel::kPhong;
  } else if (g.brdf == "ashikhmin-shirley") {
    m.model = BrdfModel::kAshikhminShirley;
  } else if (g.brdf == "ggx") {
    m.model = BrdfModel::kGgx;
  } else {
    throw std::invalid_argument("unknown brdf '" + g.brdf +
                                "' (lambert, phong, ashikhmin-shirley or ggx)");
  }
  m.specular = g.specular;
  m.exponent = g.exponent;
  m.exponent_v = g.exponent_v;
  m.roughness = g.roughness;
  return m;
}

double GgxDistribution(double alpha, double cos_m) {
  if (!(cos_m > 0)) return 0.0;
  const double a2 = alpha * alpha;
  const double d = cos_m * cos_m * (a2 - 1.0) + 1.0;
  return a2 / (std::numbers::pi * d * d);
}

double GgxSmithG1(double alpha, double cos_v) {
  if (!(cos_v > 0)) return 0.0;
  const double c2 = std::min(1.0, cos_v * cos_v);
  const double tan2 = (1.0 - c2) / c2;
  return 2.0 / (1.0 + std::sqrt(1.0 + alpha * alpha * tan2));
}

double LobeReflectance(const Material& m) {
  if (m.model == BrdfModel::kLambert) return 0.0;
  constexpr int kOut = 4, kGrid = 512;
  const Vec3 n{0, 0, 1};
  double sum = 0;
  for (int i = 0; i < kOut * kOut; ++i) {
    // Cosine-distributed ω_o (Malley): a uniform disk point lifted to the hemisphere.
    const double r = std::sqrt((i % kOut + 0.5) / kOut),
                 phi_o = 2 * std::numbers::pi * (i / kOut + 0.5) / kOut;
    const Vec3 view{r * std::cos(phi_o), r * std::sin(phi_o), std::sqrt(1 - r * r)};
    const ShadingFrame f = MakeShadingFrame(n, view);
    double e = 0;
    for (int k = 0; k < kGrid * kGrid; ++k) {
      const double z = (k % kGrid + 0.5) / kGrid, s = std::sqrt(1 - z * z);
      const double phi = 2 * std::numbers::pi * (k / kGrid + 0.5) / kGrid;
      e += SpecularLobe(m, f, Vec3{s * std::cos(phi), s * std::sin(phi), z});
    }
    sum += e * 2 * std::numbers::pi / (kGrid * kGrid);
  }
  return sum / (kOut * kOut);
}

double SpecularLobe(const Material& m, const ShadingFrame& f, const Vec3& w) {
  const double nw = Dot(f.normal, w);
  if (nw <= 0) return 0.0;
  switch (m.model) {
    case BrdfModel::kLambert:
      return 0.0;
    case BrdfModel::kPhong: {
      const double rw = Dot(f.reflect, w);
      if (rw <= 0) return 0.0;
      return (m.exponent + 2.0) * (0.5 / std::numbers::pi) * std::pow(rw, m.exponent) * nw;
    }
    case BrdfModel::kAshikhminShirley: {
      const double nv = Dot(f.normal, f.view);
      if (nv <= 0) return 0.0;
      const Vec3 h = Normalize(w + f.view);
      const double nh = Dot(f.normal, h), hw = Dot(h, w);
      if (nh <= 0 || hw <= 0) return 0.0;
      const double hu = Dot(h, f.tangent), hv = Dot(h, f.bitangent);
      const double s2 = std::max(1e-12, 1.0 - nh * nh);
      const double e = (m.exponent * hu * hu + m.exponent_v * hv * hv) / s2;
      const double norm =
          std::sqrt((m.exponent + 1.0) * (m.exponent_v + 1.0)) / (8.0 * std::numbers::pi);
      return norm * std::pow(nh, e) / (hw * std::max(nw, nv)) * nw;
    }
    case BrdfModel::kGgx: {
      // f_s·(n·ω) = D(h)·G1(ω)·G1(ω_o) / (4 (n·ω_o)): the n·ω of the denominator cancels.
      const double nv = Dot(f.normal, f.view);
      if (nv <= 0) return 0.0;
      const Vec3 h = Normalize(w + f.view);
      const double alpha = m.roughness * m.roughness;
      return GgxDistribution(alpha, Dot(f.normal, h)) * GgxSmithG1(alpha, nw) *
             GgxSmithG1(alpha, nv) / (4.0 * nv);
    }
  }
  return 0.0;
}

double CosineWeightedBrdf(const Material& m, const ShadingFrame& f, const Vec3& w, int channel) {
  const double s = HasSpecular(m) ? m.specular[channel] * SpecularLobe(m, f, w) : 0.0;
  return m.diffuse[channel] * DiffuseLobe(f, w) + s;
}

// Appendix A (see brdf.h).
int BrdfSamplingRate(const Material& m, const ShadingFrame& f, const Vec3& block_centre) {
  return BrdfSamplingRate(m, f, block_centre, 250.0);
}

int BrdfSamplingRate(const Material& m, const ShadingFrame& f, const Vec3& block_centre,
                     double full_rate_exponent) {
  if (!HasSpecular(m)) return 1;
  const Vec3 r = 2.0 * Dot(f.normal, block_centre) * f.normal - block_centre;
  const double cos_angle = Dot(Normalize(r), f.view);
  constexpr double kCosPi4 = 0.70710678118654752, kCosPi8 = 0.92387953251128676;
  const double s = EffectiveExponent(m);
  if (s < 30) return cos_angle > kCosPi4 ? 4 : 1;
  if (cos_angle > kCosPi8) return s < full_rate_exponent ? 16 : 256;
  return cos_angle > kCosPi4 ? 4 : 1;
}

float BlockDct::Basis(int u, int x) {
  return Tables().basis[u][x];
}

double BlockDct::SamplePosition(int l, int i) {
  return (i + 0.5) * 16.0 / l - 0.5;
}

namespace {

// BlockDct::Project for a fixed l: the loops unroll (issue 41: a rate-4 or rate-16 block projects
// its lobe samples every frame).
template <int L>
void ProjectFixed(const float* samples, float* coeffs) {
  const auto& inv = Tables().inverse[L];
  float tmp[L * L];  // rows: tmp[j][u] = Σ_i inv[u][i] f(i, j)
  for (int j = 0; j < L; ++j)
    for (int u = 0; u < L; ++u) {
      float acc = 0;
      for (int i = 0; i < L; ++i) acc += inv[u][i] * samples[j * L + i];
      tmp[j * L + u] = acc;
    }
  for (int v = 0; v < L; ++v)
    for (int u = 0; u < L; ++u) {
      float acc = 0;
      for (int j = 0; j < L; ++j) acc += inv[v][j] * tmp[j * L + u];
      coeffs[v * L + u] = acc;
    }
}

}  // namespace

void BlockDct::Project(int l, const float* samples, float* coeffs) {
  switch (l) {
    case 1:
      return ProjectFixed<1>(samples, coeffs);
    case 2:
      return ProjectFixed<2>(samples, coeffs);
    default:
      return ProjectFixed<4>(samples, coeffs);
  }
}

void BlockDct::Forward16(const float* pixels, float* coeffs16) {
  const auto& b = Tables().basis;
  double rows[16][4];  // Σ_x f(x, y) φ_u(x)
  for (int y = 0; y < 16; ++y)
    for (int u = 0; u < 4; ++u) {
      double acc = 0;
      for (int x = 0; x < 16; ++x) acc += static_cast<double>(pixels[y * 16 + x]) * b[u][x];
      rows[y][u] = acc;
    }
  for (int v = 0; v < 4; ++v)
    for (int u = 0; u < 4; ++u) {
      double acc = 0;
      for (int y = 0; y < 16; ++y) acc += rows[y][u] * b[v][y];
      coeffs16[v * 4 + u] = static_cast<float>(acc);
    }
}

namespace {

// BlockDct::Reconstruct for a fixed l, so that the loops unroll and vectorise over x (issue 41:
// line 11 reconstructs a lobe per block; the loops with a run-time l did neither).
template <int L>
void ReconstructFixed(const float* coeffs, float* pixels) {
  const auto& b = Tables().basis;
  float cols[L][16];  // g_v(x) = Σ_u A_uv φ_u(x)
  for (int v = 0; v < L; ++v)
    for (int x = 0; x < 16; ++x) {
      float acc = 0;
      for (int u = 0; u < L; ++u) acc += coeffs[v * L + u] * b[u][x];
      cols[v][x] = acc;
    }
  for (int y = 0; y < 16; ++y) {
    float w[L];
    for (int v = 0; v < L; ++v) w[v] = b[v][y];
    for (int x = 0; x < 16; ++x) {
      float acc = 0;
      for (int v = 0; v < L; ++v) acc += w[v] * cols[v][x];
      pixels[y * 16 + x] = acc;
    }
  }
}

}  // namespace

void BlockDct::Reconstruct(int l, const float* coeffs, float* pixels) {
  switch (l) {
    case 1:
      return ReconstructFixed<1>(coeffs, pixels);
    case 2:
      return ReconstructFixed<2>(coeffs, pixels);
    default:
      return ReconstructFixed<4>(coeffs, pixels);
  }
}

}  // namespace prt
