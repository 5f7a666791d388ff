// BRDF factors and run/glossy.prtf (formats/glossy_factors.h).
#include "formats/glossy_factors.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <utility>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {
namespace {

constexpr char kMagic[8] = {'P', 'R', 'T', 'G', 'L', 'O', 'S', '1'};
constexpr int kMaxTerms = 16;
constexpr int kMaxGrid = 512;

// Bilinear interpolation of an n×n table between cell centres at (u, v) ∈ [0, 1]².
double Bilinear(const float* table, int n, double u, double v) {
  const double x = std::clamp(u * n - 0.5, 0.0, n - 1.0);
  const double y = std::clamp(v * n - 0.5, 0.0, n - 1.0);
  const int x0 = std::min(static_cast<int>(x), n - 2 < 0 ? 0 : n - 2);
  const int y0 = std::min(static_cast<int>(y), n - 2 < 0 ? 0 : n - 2);
  const double fx = x - x0, fy = y - y0;
  const float* r0 = table + static_cast<std::size_t>(y0) * n + x0;
  const float* r1 = r0 + n;
  return (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
}

}  // namespace

Vec3 HemisphereFromSquare(double u, double v) {
  // Shirley & Chiu 1997: the square [-1,1]² to the unit disk by concentric squares.
  const double a = 2 * u - 1, b = 2 * v - 1;
  double r = 0, phi = 0;
  if (a == 0 && b == 0) return {0, 0, 1};
  if (std::abs(a) > std::abs(b)) {
    r = a;
    phi = (std::numbers::pi / 4) * (b / a);
  } else {
    r = b;
    phi = std::numbers::pi / 2 - (std::numbers::pi / 4) * (a / b);
  }
  const double dx = r * std::cos(phi), dy = r * std::sin(phi);
  const double r2 = std::min(1.0, dx * dx + dy * dy);
  const double s = std::sqrt(2 - r2);  // Lambert's azimuthal equal-area projection
  return {dx * s, dy * s, 1 - r2};
}

void SquareFromHemisphere(const Vec3& d, double& u, double& v) {
  const double len = Length(d);
  if (!(len > 0)) {
    u = v = 0.5;
    return;
  }
  double x = d.x / len, y = d.y / len;
  double z = std::max(0.0, d.z / len);
  // std::hypot is several times slower than the plain root, and these are unit-scale values.
  if (d.z < 0) {  // below the horizon: onto it
    const double h = std::sqrt(x * x + y * y);
    if (h > 0) x /= h, y /= h;
    z = 0;
  }
  const double r = std::sqrt(std::max(0.0, 1 - z));  // disk radius
  const double h = std::sqrt(x * x + y * y);
  if (!(h > 0) || r == 0) {
    u = v = 0.5;
    return;
  }
  const double dx = x / h * r, dy = y / h * r;
  double psi = std::atan2(dy, dx);
  constexpr double kQ = std::numbers::pi / 4;
  if (psi < -kQ) psi += 2 * std::numbers::pi;
  double a, b;
  if (psi < kQ) {
    a = r;
    b = psi / kQ * r;
  } else if (psi < 3 * kQ) {
    b = r;
    a = -(psi - 2 * kQ) / kQ * r;
  } else if (psi < 5 * kQ) {
    a = -r;
    b = -(psi - 4 * kQ) / kQ * r;
  } else {
    b = -r;
    a = (psi - 6 * kQ) / kQ * r;
  }
  u = std::clamp((a + 1) / 2, 0.0, 1.0);
  v = std::clamp((b + 1) / 2, 0.0, 1.0);
}

FactorFrame MakeFactorFrame(const Vec3& normal) {
  FactorFrame f;
  const double len = Length(normal);
  f.normal = (std::isfinite(len) && len > 0) ? normal / len : Vec3{0, 1, 0};
  const double k = 1.0 / std::sqrt(6.0);
  Vec3 a{1 * k, std::sqrt(2.0) * k, std::sqrt(3.0) * k};
  Vec3 t = a - f.normal * Dot(a, f.normal);
  if (Length(t) < 1e-3) {
    a = {std::sqrt(3.0) * k, -1 * k, std::sqrt(2.0) * k};
    t = a - f.normal * Dot(a, f.normal);
  }
  f.tangent = Normalize(t);
  f.bitangent = Cross(f.normal, f.tangent);
  return f;
}

double BrdfFactors::G(int term, const Vec3& view_local) const {
  double u, v;
  SquareFromHemisphere(view_local, u, v);
  return Bilinear(g.data() + static_cast<std::size_t>(term) * view_n * view_n, view_n, u, v);
}

double BrdfFactors::F(int term, const Vec3& light_local) const {
  if (!(light_local.z > 0)) return 0.0;  // the cosine: nothing from below the horizon
  double u, v;
  SquareFromHemisphere(light_local, u, v);
  return Bilinear(f.data() + static_cast<std::size_t>(term) * light_n * light_n, light_n, u, v);
}

void BrdfFactors::GAll(const Vec3& view_local, float* out) const {
  double u, v;
  SquareFromHemisphere(view_local, u, v);
  const std::size_t cells = static_cast<std::size_t>(view_n) * view_n;
  for (int i = 0; i < terms; ++i)
    out[i] = static_cast<float>(Bilinear(g.data() + i * cells, view_n, u, v));
}

std::string SerializeGlossyFactors(const GlossyFactorTable& table, bool with_f) {
  ByteWriter w;
  w.PutBytes(kMagic, sizeof kMagic);
  w.Put<uint32_t>(static_cast<uint32_t>(table.terms));
  w.Put<uint32_t>(static_cast<uint32_t>(table.mesh_factor.size()));
  w.Put<uint32_t>(static_cast<uint32_t>(table.factors.size()));
  w.Put<uint32_t>(with_f ? 1u : 0u);
  for (std::size_t m = 0; m < table.mesh_factor.size(); ++m) {
    w.Put<uint32_t>(table.mesh_factor[m]);
    for (int c = 0; c < 3; ++c) w.Put<float>(table.mesh_weight[m][c]);
  }
  for (const BrdfFactors& f : table.factors) {
    w.Put<uint32_t>(static_cast<uint32_t>(f.view_n));
    w.Put<uint32_t>(static_cast<uint32_t>(f.light_n));
    w.Put<double>(f.relative_error);
    w.Put<uint32_t>(static_cast<uint32_t>(f.description.size()));
    w.PutBytes(f.description.data(), f.description.size());
    w.PutBytes(f.g.data(), f.g.size() * sizeof(float));
    if (with_f) w.PutBytes(f.f.data(), f.f.size() * sizeof(float));
  }
  std::string bytes = std::move(w.bytes());
  const uint64_t sum = Checksum64(bytes.data(), bytes.size());
  bytes.append(reinterpret_cast<const char*>(&sum), sizeof sum);
  return bytes;
}

GlossyFactorTable ParseGlossyFactors(std::string_view bytes, const std::string& name) {
  auto fail = [&](const std::string& what) -> void { throw InputError(name, what); };
  if (bytes.size() < sizeof kMagic + 8 ||
      !std::equal(kMagic, kMagic + sizeof kMagic, bytes.begin()))
    fail("not a prtfarm glossy factor file (bad magic)");
  uint64_t sum;
  std::memcpy(&sum, bytes.data() + bytes.size() - 8, 8);
  if (Checksum64(bytes.data(), bytes.size() - 8) != sum)
    fail("checksum mismatch: the glossy factor file is damaged");
  ByteReader r(bytes.substr(0, bytes.size() - 8), [&](const char* what, std::size_t at) {
    throw InputError(name,
                     std::string("truncated at byte ") + std::to_string(at) + " (" + what + ")");
  });
  r.Skip(sizeof kMagic, "magic");
  GlossyFactorTable t;
  t.terms = static_cast<int>(r.Get<uint32_t>("terms"));
  const uint32_t meshes = r.Get<uint32_t>("mesh count");
  const uint32_t count = r.Get<uint32_t>("factor count");
  const uint32_t flags = r.Get<uint32_t>("flags");
  if (t.terms < 1 || t.terms > kMaxTerms)
    fail("terms " + std::to_string(t.terms) + " outside 1…" + std::to_string(kMaxTerms));
  if (flags > 1) fail("unknown flags " + std::to_string(flags));
  if (meshes > r.remaining() / 16) fail("mesh count " + std::to_string(meshes) + " too large");
  if (count > meshes) fail("more factors than meshes");
  t.mesh_factor.resize(meshes);
  t.mesh_weight.resize(meshes);
  for (uint32_t m = 0; m < meshes; ++m) {
    t.mesh_factor[m] = r.Get<uint32_t>("mesh factor");
    if (t.mesh_factor[m] != GlossyFactorTable::kDiffuseMesh && t.mesh_factor[m] >= count)
      fail("mesh " + std::to_string(m) + " names factors " + std::to_string(t.mesh_factor[m]) +
           " of " + std::to_string(count));
    for (int c = 0; c < 3; ++c) {
      const float x = r.Get<float>("mesh weight");
      if (!std::isfinite(x) || x < 0) fail("mesh " + std::to_string(m) + " has a bad weight");
      t.mesh_weight[m][c] = x;
    }
  }
  t.factors.resize(count);
  for (uint32_t i = 0; i < count; ++i) {
    BrdfFactors& f = t.factors[i];
    f.terms = t.terms;
    f.view_n = static_cast<int>(r.Get<uint32_t>("view n"));
    f.light_n = static_cast<int>(r.Get<uint32_t>("light n"));
    if (f.view_n < 2 || f.view_n > kMaxGrid || f.light_n < 2 || f.light_n > kMaxGrid)
      fail("factors " + std::to_string(i) + ": grid outside 2…" + std::to_string(kMaxGrid));
    f.relative_error = r.Get<double>("relative error");
    if (!std::isfinite(f.relative_error) || f.relative_error < 0)
      fail("factors " + std::to_string(i) + ": bad relative error");
    const uint32_t len = r.Get<uint32_t>("description length");
    f.description = std::string(r.Take(len, "description"));
    auto table = [&](int n, std::vector<float>& out, const char* what) {
      const std::size_t values = static_cast<std::size_t>(t.terms) * n * n;
      const std::string_view raw = r.Take(values * sizeof(float), what);
      out.resize(values);
      std::memcpy(out.data(), raw.data(), raw.size());
      for (float x : out)
        if (!std::isfinite(x)) fail("factors " + std::to_string(i) + ": non-finite " + what);
    };
    table(f.view_n, f.g, "g table");
    if (flags & 1u) table(f.light_n, f.f, "f table");
  }
  if (r.remaining() != 0) fail(std::to_string(r.remaining()) + " bytes after the tables");
  return t;
}

}  // namespace prt
