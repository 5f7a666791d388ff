// BRDF in-out factorisation by truncated SVD (worker/brdf_factorisation.h).
#include "worker/brdf_factorisation.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>

#include "vocabulary/hash.h"
#include "vocabulary/parallel.h"

namespace prt {
namespace {

// The cell centres of an n×n equal-area grid.
std::vector<Vec3> GridDirections(int n) {
  std::vector<Vec3> d(static_cast<std::size_t>(n) * n);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) d[y * n + x] = HemisphereFromSquare((x + 0.5) / n, (y + 0.5) / n);
  return d;
}

// ρ̃(ω, ω_o) in the local frame (n = +z; the tangent is +x, as OrthonormalBasis(+z) gives).
double CosineWeighted(const Material& m, const ShadingFrame& view, const Vec3& w) {
  const double c = w.z;
  if (!(c > 0)) return 0.0;
  return m.diffuse[0] * c * std::numbers::inv_pi + m.specular[0] * SpecularLobe(m, view, w);
}

// M (views × lights), row-major in an Eigen matrix.
Eigen::MatrixXd Tabulate(const Material& m, const std::vector<Vec3>& views,
                         const std::vector<Vec3>& lights) {
  Eigen::MatrixXd M(views.size(), lights.size());
  ParallelFor(views.size(), [&](std::size_t o) {
    const ShadingFrame f = MakeShadingFrame({0, 0, 1}, views[o]);
    for (std::size_t l = 0; l < lights.size(); ++l) M(o, l) = CosineWeighted(m, f, lights[l]);
  });
  return M;
}

void CheckOptions(const FactorisationOptions& o) {
  auto grid = [](int n, const char* what) {
    if (n < 2 || n > 512)
      throw std::invalid_argument(std::string("FactorBrdf: ") + what + " outside 2…512");
  };
  if (o.terms < 1 || o.terms > 16) throw std::invalid_argument("FactorBrdf: terms outside 1…16");
  grid(o.view_n, "view_n");
  grid(o.svd_light_n, "svd_light_n");
  grid(o.light_n, "light_n");
}

// The eigen-decomposition of M·Mᵀ: eigenvalues descending, eigenvectors as columns.
void Decompose(const Eigen::MatrixXd& M, Eigen::VectorXd& values, Eigen::MatrixXd& vectors) {
  const Eigen::MatrixXd gram = M * M.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram);
  if (eig.info() != Eigen::Success) throw std::runtime_error("FactorBrdf: eigensolver failed");
  values = eig.eigenvalues().reverse();
  vectors = eig.eigenvectors().rowwise().reverse();
}

// ‖M − M_m‖_F / ‖M‖_F for m = 1…max_terms from the eigenvalues σ² of M·Mᵀ (descending).
std::vector<double> Truncation(const Eigen::VectorXd& values, int max_terms) {
  const double total = std::max(values.sum(), 1e-300);
  std::vector<double> out;
  double kept = 0;
  for (int m = 1; m <= max_terms && m <= values.size(); ++m) {
    kept += std::max(0.0, values[m - 1]);
    out.push_back(std::sqrt(std::max(0.0, total - kept) / total));
  }
  return out;
}

}  // namespace

std::string DescribeMaterial(const Material& m) {
  char buf[160];
  const char* name = m.model == BrdfModel::kGgx                ? "ggx"
                     : m.model == BrdfModel::kPhong            ? "phong"
                     : m.model == BrdfModel::kAshikhminShirley ? "ashikhmin-shirley"
                                                               : "lambert";
  if (m.model == BrdfModel::kGgx)
    std::snprintf(buf, sizeof buf, "%s r=%.3g kd=%.3g ks=%.3g", name, m.roughness, m.diffuse[0],
                  m.specular[0]);
  else
    std::snprintf(buf, sizeof buf, "%s s=%.4g/%.4g kd=%.3g ks=%.3g", name, m.exponent, m.exponent_v,
                  m.diffuse[0], m.specular[0]);
  return buf;
}

std::vector<double> TruncationErrors(const Material& material, const FactorisationOptions& options,
                                     int max_terms) {
  CheckOptions(options);
  const Eigen::MatrixXd M =
      Tabulate(material, GridDirections(options.view_n), GridDirections(options.svd_light_n));
  Eigen::VectorXd values;
  Eigen::MatrixXd vectors;
  Decompose(M, values, vectors);
  return Truncation(values, max_terms);
}

BrdfFactors FactorBrdf(const Material& material, const FactorisationOptions& options,
                       std::vector<double>* truncation) {
  CheckOptions(options);
  const std::vector<Vec3> views = GridDirections(options.view_n);
  const Eigen::MatrixXd M = Tabulate(material, views, GridDirections(options.svd_light_n));
  Eigen::VectorXd values;
  Eigen::MatrixXd vectors;
  Decompose(M, values, vectors);
  if (truncation != nullptr) *truncation = Truncation(values, 16);

  BrdfFactors out;
  out.terms = options.terms;
  out.view_n = options.view_n;
  out.light_n = options.light_n;
  out.description = DescribeMaterial(material);
  const std::size_t nv = views.size();
  const std::vector<Vec3> fine = GridDirections(options.light_n);
  const Eigen::MatrixXd Mfine = Tabulate(material, views, fine);  // views × fine lights
  out.g.assign(options.terms * nv, 0.f);
  out.f.assign(options.terms * fine.size(), 0.f);
  for (int i = 0; i < options.terms && i < values.size(); ++i) {
    const double sigma = std::sqrt(std::max(0.0, values[i]));
    if (!(sigma > 1e-12 * std::sqrt(std::max(values[0], 1e-300)))) break;  // rank reached
    Eigen::VectorXd u = vectors.col(i);
    if (u.sum() < 0) u = -u;
    const Eigen::VectorXd v = Mfine.transpose() * u / sigma;
    for (std::size_t o = 0; o < nv; ++o) out.g[i * nv + o] = static_cast<float>(sigma * u[o]);
    for (std::size_t l = 0; l < fine.size(); ++l)
      out.f[i * fine.size() + l] = static_cast<float>(v[l]);
  }

  out.relative_error = LookupError(material, out, options.terms, options);
  return out;
}

double LookupError(const Material& material, const BrdfFactors& factors, int terms,
                   const FactorisationOptions& options) {
  if (terms < 1 || terms > factors.terms)
    throw std::invalid_argument("LookupError: terms outside 1…" + std::to_string(factors.terms));
  // At random direction pairs off the grids.
  uint64_t state = 0x474C4F5353595345ull;
  auto uniform = [&]() { return static_cast<double>(SplitMix64(++state) >> 11) * 0x1p-53; };
  std::vector<Vec3> cv(options.check_views), cl(options.check_lights);
  for (Vec3& d : cv) d = HemisphereFromSquare(uniform(), uniform());
  for (Vec3& d : cl) d = HemisphereFromSquare(uniform(), uniform());
  std::vector<double> err(cv.size()), norm(cv.size());
  ParallelFor(cv.size(), [&](std::size_t o) {
    const ShadingFrame f = MakeShadingFrame({0, 0, 1}, cv[o]);
    std::vector<float> g(factors.terms);
    factors.GAll(cv[o], g.data());
    double e = 0, n = 0;
    for (const Vec3& w : cl) {
      const double exact = CosineWeighted(material, f, w);
      double approx = 0;
      for (int i = 0; i < terms; ++i) approx += g[i] * factors.F(i, w);
      e += (exact - approx) * (exact - approx);
      n += exact * exact;
    }
    err[o] = e;
    norm[o] = n;
  });
  double e = 0, n = 0;
  for (std::size_t o = 0; o < cv.size(); ++o) e += err[o], n += norm[o];
  return n > 0 ? std::sqrt(e / n) : 0.0;
}

GlossyFactorTable FactorGlossyMeshes(const GlossyPixels& glossy,
                                     const FactorisationOptions& options,
                                     std::vector<std::vector<double>>* truncation) {
  GlossyFactorTable t;
  if (!glossy.any()) return t;
  t.terms = options.terms;
  for (std::size_t m = 0; m < glossy.glossy.size(); ++m) {
    t.mesh_weight.push_back(glossy.weight[m]);
    if (!glossy.glossy[m]) {
      t.mesh_factor.push_back(GlossyFactorTable::kDiffuseMesh);
      continue;
    }
    t.mesh_factor.push_back(static_cast<uint32_t>(t.factors.size()));
    std::vector<double> errors;
    t.factors.push_back(FactorBrdf(glossy.materials[m], options, &errors));
    if (truncation != nullptr) truncation->push_back(std::move(errors));
  }
  return t;
}

std::vector<SpatialSample> TermSamples(const std::vector<SpatialSample>& vertices,
                                       const SceneGeometry& geometry,
                                       const GlossyFactorTable& table) {
  const std::vector<uint32_t> mesh = TermSampleMeshes(geometry, 1);
  if (mesh.size() != vertices.size())
    throw std::logic_error("TermSamples: the samples are not the geometry's vertices");
  std::vector<SpatialSample> out;
  out.reserve(vertices.size() * table.terms);
  for (int t = 0; t < table.terms; ++t)
    for (std::size_t v = 0; v < vertices.size(); ++v) {
      SpatialSample s = vertices[v];
      if (table.glossy(mesh[v])) {
        s.glossy_material = table.mesh_factor[mesh[v]];
        s.term = static_cast<uint8_t>(t);
      } else if (t > 0) {
        s.background = true;  // a diffuse vertex has no term t > 0: a zero row
      }
      out.push_back(s);
    }
  return out;
}

std::vector<uint32_t> TermSampleMeshes(const SceneGeometry& geometry, int terms) {
  std::vector<uint32_t> one;
  for (std::size_t m = 0; m < geometry.meshes.size(); ++m)
    one.insert(one.end(), geometry.meshes[m].mesh.positions.size(), static_cast<uint32_t>(m));
  std::vector<uint32_t> out;
  out.reserve(one.size() * terms);
  for (int t = 0; t < terms; ++t) out.insert(out.end(), one.begin(), one.end());
  return out;
}

}  // namespace prt
