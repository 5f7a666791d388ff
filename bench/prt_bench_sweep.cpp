// prt-bench's sweep points and per-sample helpers (see prt_bench_sweep.h).
#include "bench/prt_bench_sweep.h"

namespace prt::bench {

std::vector<Rgb> SampleAlbedo(const SceneGeometry& g) {
  std::vector<Rgb> a;
  for (const SceneMesh& m : g.meshes) a.insert(a.end(), m.mesh.positions.size(), m.albedo);
  return a;
}

std::vector<float> ShadeChannelMajor(std::span<const float> radiance, const std::vector<Rgb>& a) {
  const std::size_t S = a.size();
  std::vector<float> out(3 * S);
  for (std::size_t s = 0; s < S; ++s)
    for (int c = 0; c < 3; ++c) out[3 * s + c] = a[s][c] * radiance[c * S + s];
  return out;
}

std::vector<float> ChannelMajor(const CubemapRgb& cube) {
  std::vector<float> L;
  for (int c = 0; c < 3; ++c) L.insert(L.end(), cube.Channel(c).begin(), cube.Channel(c).end());
  return L;
}

std::vector<Point> SweepPoints(const Options& o) {
  std::vector<Point> pts;
  const auto sparse = [&](double b, double f, double rs) {
    Point p;
    p.family = "sparse";
    p.dense_budget = b;
    p.feature_scale = f;
    p.radius_scale = rs;
    pts.push_back(p);
  };
  if (!o.dense_budgets.empty() && !o.feature_scales.empty() && !o.radius_scales.empty()) {
    const double b0 = o.dense_budgets[0], f0 = o.feature_scales[0], r0 = o.radius_scales[0];
    for (double b : o.dense_budgets) sparse(b, f0, r0);
    for (std::size_t i = 1; i < o.feature_scales.size(); ++i) sparse(b0, o.feature_scales[i], r0);
    for (std::size_t i = 1; i < o.radius_scales.size(); ++i) sparse(b0, f0, o.radius_scales[i]);
  }
  const auto compression = [&](const std::string& s, double k, double bits) {
    Point p;
    p.family = s;
    p.keep = k;
    p.bits = static_cast<int>(bits);
    pts.push_back(p);
  };
  if (!o.bits.empty() && !o.keeps.empty()) {
    for (const std::string& s : o.schemes)
      for (double k : o.keeps) compression(s, k, o.bits[0]);
    for (std::size_t i = 1; i < o.bits.size(); ++i)
      for (const std::string& s : o.schemes) compression(s, o.keeps[o.keeps.size() / 2], o.bits[i]);
  }
  for (const char* mode : {"nwa", "pbi"})
    for (double t : o.terms) {
      Point p;
      p.family = mode;
      p.terms = static_cast<std::size_t>(t);
      pts.push_back(p);
    }
  return pts;
}

}  // namespace prt::bench
