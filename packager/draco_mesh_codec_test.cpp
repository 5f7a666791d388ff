// Order preservation and quantisation error of the MESH codec on every real mesh in
// ${PRT_DATA_DIR}/meshes and ${PRT_SHARED_DATA_DIR}/meshes (docs/prtpack-format.md, "MESH"):
// vertex i of the unpacked mesh is vertex i of the input within the documented position bound,
// triangles are identical, and the normal quantisation changes cosine-weighted radiance under a
// sun-and-sky environment by < 0.1 % relative RMS.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

#include "packager/prtpack_reader.h"
#include "packager/prtpack_writer.h"
#include "vocabulary/mesh_io.h"

namespace prt::pack {
namespace {

std::vector<std::string> RealMeshes() {
  std::vector<std::string> files;
  for (const char* dir : {PRT_DATA_DIR "/meshes", PRT_SHARED_DATA_DIR "/meshes"}) {
    if (!std::filesystem::is_directory(dir)) continue;
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      files.push_back(e.path().string());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Directions and weights of a lighting environment: a sky of radiance 1 + 0.5·y on a Fibonacci
// sphere (equal solid angles 4π/K) and a sun carrying 60 % of the irradiance of an upward face.
struct Environment {
  std::vector<Vec3> dirs;
  std::vector<double> weights;  // radiance × solid angle
};

Environment SunAndSky() {
  Environment env;
  const int k = 256;
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < k; ++i) {
    const double y = 1.0 - 2.0 * (i + 0.5) / k;
    const double r = std::sqrt(1.0 - y * y);
    env.dirs.push_back({r * std::cos(golden * i), y, r * std::sin(golden * i)});
    env.weights.push_back((1.0 + 0.5 * y) * 4.0 * std::numbers::pi / k);
  }
  env.dirs.push_back(Normalize(Vec3{0.3, 0.8, 0.52}));
  env.weights.push_back(1.5 * std::numbers::pi);
  return env;
}

// Unshadowed diffuse radiance B = (1/π) Σ_k w_k max(0, n·ω_k) (DESIGN.md transport, V = 1).
double CosineRadiance(const Environment& env, const Vec3& n) {
  double b = 0;
  for (std::size_t k = 0; k < env.dirs.size(); ++k) {
    b += env.weights[k] * std::max(0.0, Dot(n, env.dirs[k]));
  }
  return b / std::numbers::pi;
}

TEST(DracoMeshCodec, EveryRealMeshKeepsVertexOrderWithinQuantisation) {
  const std::vector<std::string> files = RealMeshes();
  ASSERT_GE(files.size(), 6u) << "real meshes missing: run scripts/install-deps.sh";
  const Environment env = SunAndSky();
  const WriterOptions options;
  // Draco quantises the largest bbox extent into 2^bits − 1 steps, rounding to nearest: the
  // error vector is ≤ √3 · extent / (2 (2^bits − 1)) ≤ √3 / (2 (2^bits − 1)) of the diagonal.
  const double bound = std::sqrt(3.0) / (2.0 * ((1 << options.position_bits) - 1));
  double worst_position = 0, worst_angle = 0, worst_radiance = 0;
  for (const std::string& file : files) {
    PackInput in;
    PackMeshInput m;
    m.name = std::filesystem::path(file).filename().string();
    m.mesh = LoadMesh(file);
    in.meshes.push_back(m);
    const std::vector<uint8_t> bytes = WritePack(in, options);
    const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size(), file);
    const UnpackedMesh u = r.ReadMesh(0);
    const TriangleMesh& src = m.mesh;
    ASSERT_EQ(u.vertex_count(), src.positions.size()) << file;
    ASSERT_EQ(u.triangle_count(), src.triangles.size()) << file;
    for (std::size_t t = 0; t < src.triangles.size(); ++t) {
      for (std::size_t c = 0; c < 3; ++c) {
        ASSERT_EQ(u.triangles[3 * t + c], src.triangles[t][c]) << file << " triangle " << t;
      }
    }
    Vec3 lo = src.positions[0], hi = src.positions[0];
    for (const Vec3& p : src.positions) {
      lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
      hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
    }
    const double diagonal = Length(hi - lo);
    double max_position = 0, max_angle = 0, d2 = 0, b2 = 0;
    for (std::size_t i = 0; i < src.positions.size(); ++i) {
      const Vec3 p{u.positions[3 * i], u.positions[3 * i + 1], u.positions[3 * i + 2]};
      const Vec3 n{u.normals[3 * i], u.normals[3 * i + 1], u.normals[3 * i + 2]};
      max_position = std::max(max_position, Length(p - src.positions[i]) / diagonal);
      const double cosine = std::clamp(Dot(Normalize(n), src.normals[i]), -1.0, 1.0);
      max_angle = std::max(max_angle, std::acos(cosine) * 180.0 / std::numbers::pi);
      const double b = CosineRadiance(env, src.normals[i]);
      const double db = CosineRadiance(env, n) - b;
      d2 += db * db;
      b2 += b * b;
    }
    const double radiance = std::sqrt(d2 / b2);
    std::printf(
        "%-28s %6zu v %6zu t  Draco %8zu B (%.1f B/v)  max |Δp|/diag %.3g (bound %.3g)  "
        "max normal error %.4f°  radiance rel RMS %.2g\n",
        m.name.c_str(), src.positions.size(), src.triangles.size(),
        std::size_t(r.sections()[1].stored_size),
        double(r.sections()[1].stored_size) / double(src.positions.size()), max_position, bound,
        max_angle, radiance);
    // float32 rounding of the input adds < 1e-7 of the coordinates' magnitude.
    EXPECT_LE(max_position, bound * 1.001 + 1e-7 * Length(hi) / diagonal + 1e-7) << file;
    EXPECT_LT(max_angle, 0.05) << file;
    EXPECT_LT(radiance, 1e-3) << file;
    worst_position = std::max(worst_position, max_position);
    worst_angle = std::max(worst_angle, max_angle);
    worst_radiance = std::max(worst_radiance, radiance);
  }
  std::printf("worst over %zu meshes: |Δp|/diag %.3g, normal %.4f°, radiance rel RMS %.2g\n",
              files.size(), worst_position, worst_angle, worst_radiance);
}

}  // namespace
}  // namespace prt::pack
