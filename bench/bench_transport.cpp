#include "bench/bench_transport.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "bench/bench_scene.h"
#include "formats/geometry_file.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "vocabulary/errors.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/row_transform.h"
#include "worker/transport_sampler.h"

namespace prt::bench {

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

std::vector<float> AlbedoPerSample(const SceneGeometry& g) {
  std::vector<float> a;
  for (const SceneMesh& m : g.meshes)
    for (std::size_t v = 0; v < m.mesh.positions.size(); ++v)
      for (int c = 0; c < 3; ++c) a.push_back(m.albedo[c]);
  return a;
}

BenchTransport SceneTransport(const std::string& name, int n, int rays, const std::string& cache,
                              double order_normal_weight) {
  BenchTransport t;
  t.name = name;
  t.n = n;
  const SceneDescription scene = BenchScene(name, n);
  const SceneGeometry geometry = BuildSceneGeometry(scene);
  t.domain = SpatialDomainOf(geometry, order_normal_weight);
  t.order_normal_weight = order_normal_weight;
  t.albedo = AlbedoPerSample(geometry);
  t.S = t.domain.sample_count();
  const std::size_t M = static_cast<std::size_t>(6) * n * n;
  t.T.resize(t.S * M);
  const std::string file = cache.empty() ? std::string()
                                         : cache + "/" + name + "_n" + std::to_string(n) + "_r" +
                                               std::to_string(rays) + ".f32";
  if (!file.empty() && std::filesystem::exists(file) &&
      std::filesystem::file_size(file) == t.T.size() * sizeof(float)) {
    std::ifstream in(file, std::ios::binary);
    in.read(reinterpret_cast<char*>(t.T.data()),
            static_cast<std::streamsize>(t.T.size() * sizeof(float)));
    if (!in) throw std::runtime_error(file + ": short read of the cached transport");
    t.source = name + " (cached " + file + ")";
    return t;
  }
  const EmbreeScene embree(geometry);
  const TransportSampler sampler(embree, n, {rays, 1});
  const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
  const auto t0 = Clock::now();
  sampler.ComputeRows(samples, 0, t.T.data());
  std::ostringstream os;
  os << name << ", " << rays << " rays per texel, traced in " << Seconds(t0) << " s";
  t.source = os.str();
  if (!file.empty()) {
    std::filesystem::create_directories(cache);
    std::ofstream out(file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(t.T.data()),
              static_cast<std::streamsize>(t.T.size() * sizeof(float)));
    if (!out) throw std::runtime_error(file + ": cannot write the transport cache");
  }
  return t;
}

BenchTransport ReadRunTransport(const std::string& dir, double order_normal_weight) {
  BenchTransport t;
  const TransportFileReader reader(dir + "/" + kTransportFileName);
  t.n = static_cast<int>(reader.info().cubemap_n);
  t.S = reader.info().rows;
  t.T.resize(t.S * reader.info().cols());
  reader.ReadRows(0, t.S, t.T.data());
  const SceneGeometry g = ReadSceneGeometryFile(dir + "/" + kGeometryFileName);
  t.order_normal_weight = order_normal_weight;
  t.name = "run";
  const std::string image = dir + "/" + kImageFileName;
  if (std::filesystem::exists(image)) {
    // An image run (docs/image-relighting.md): the pixels' W×H grid, each pixel's albedo.
    const ImageSamplesInfo info =
        ReadImageSamplesFile(image, static_cast<uint32_t>(g.meshes.size()));
    if (info.pixels() != t.S)
      throw InputError(image, "does not describe the run's " + std::to_string(t.S) + " rows");
    t.domain = ImageDomain(static_cast<uint32_t>(info.camera.width),
                           static_cast<uint32_t>(info.camera.height));
    std::vector<Rgb> mesh_albedo;
    for (const SceneMesh& m : g.meshes) mesh_albedo.push_back(m.albedo);
    for (const Rgb& a : PixelAlbedo(info, mesh_albedo))
      t.albedo.insert(t.albedo.end(), a.begin(), a.end());
    t.name = "image";
  } else {
    t.domain = SpatialDomainOf(g, order_normal_weight);
    t.albedo = AlbedoPerSample(g);
  }
  t.source = dir;
  return t;
}

std::vector<float> TransposeRows(const std::vector<float>& rows, std::size_t S, std::size_t M) {
  std::vector<float> cols(S * M);
  constexpr std::size_t kTile = 64;
  for (std::size_t s0 = 0; s0 < S; s0 += kTile)
    for (std::size_t j0 = 0; j0 < M; j0 += kTile)
      for (std::size_t s = s0; s < std::min(S, s0 + kTile); ++s)
        for (std::size_t j = j0; j < std::min(M, j0 + kTile); ++j)
          cols[j * S + s] = rows[s * M + j];
  return cols;
}

CompressedTransport CompressPreparedColumns(const CompressedTransportHeader& h,
                                            const CompressionOptions& o,
                                            const std::vector<float>& rows_hat,
                                            const std::vector<float>& cols_hat, FixedColumns& fixed,
                                            std::vector<ColumnStats>* stats,
                                            double* squared_error) {
  const std::size_t S = h.sample_count, M = h.column_count();
  const bool per_row = o.scheme == CompressionScheme::k2D && o.budget == CompressionBudget::kColumn;
  std::vector<float> work;
  std::vector<uint8_t> depths(M);
  const float* transformed = nullptr;
  if (per_row) {
    std::vector<float> rows(rows_hat);
    for (std::size_t r = 0; r < S; ++r)
      KeepLargestPerRow(rows.data() + r * M, 1, M, RowTermBudget(o, M));
    work = TransposeRows(rows, S, M);
    TransformColumnBlock(h, static_cast<uint32_t>(M), work.data(), depths.data());
    transformed = work.data();
  } else if (o.scheme == CompressionScheme::kAdaptive4D) {
    work = cols_hat;
    TransformColumnBlock(h, static_cast<uint32_t>(M), work.data(), depths.data());
    transformed = work.data();
  } else {
    if (fixed.columns.empty()) {
      fixed.columns = cols_hat;
      fixed.depths.assign(M, 0);
      TransformColumnBlock(h, static_cast<uint32_t>(M), fixed.columns.data(), fixed.depths.data());
    }
    transformed = fixed.columns.data();
    depths = fixed.depths;
  }
  float threshold = 0.0f;
  if (o.budget == CompressionBudget::kGlobal) {
    std::vector<uint64_t> hist(kMagnitudeBins, 0);
    AddColumnBlockHistogram(h, 0, static_cast<uint32_t>(M), transformed, hist.data());
    threshold = ThresholdFromHistogram(hist.data(), GlobalTermBudget(h));
  }
  CompressedTransport ct;
  ct.header = h;
  ct.columns = QuantiseColumnBlock(h, 0, static_cast<uint32_t>(M), transformed, depths.data(),
                                   threshold, stats);
  if (squared_error)
    *squared_error =
        ColumnBlockError(h, 0, static_cast<uint32_t>(M), transformed, depths.data(), ct.columns);
  return ct;
}

}  // namespace prt::bench
