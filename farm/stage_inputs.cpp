// Stage inputs of a run (see stage_inputs.h).
#include "farm/stage_inputs.h"

#include <cstdio>
#include <filesystem>

#include "formats/compressed_transport.h"
#include "formats/geometry_file.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/hash.h"
#include "worker/column_order.h"
#include "worker/glossy_pixels.h"

namespace prt {

namespace {

using Json = nlohmann::ordered_json;

Json SparseJson(const SparseSettings& s) {
  return {{"initial_fraction", s.initial_fraction},
          {"dense_budget", s.dense_budget},
          {"iterations", s.iterations},
          {"radius", s.radius},
          {"max_neighbors", s.max_neighbors},
          {"features", s.features},
          {"lambda", s.lambda},
          {"window", s.window},
          {"unity_weight", s.unity_weight},
          {"max_residual", s.max_residual},
          {"min_normal_cos", s.min_normal_cos},
          {"rank_floor", s.rank_floor},
          {"seed", s.seed}};
}

// Every mesh's albedo, in order (what the bounce light and the estimate's B depend on).
Json AlbedoJson(const SceneGeometry& geometry) {
  Json albedo = Json::array();
  for (const SceneMesh& mesh : geometry.meshes)
    albedo.push_back({mesh.albedo[0], mesh.albedo[1], mesh.albedo[2]});
  return albedo;
}

}  // namespace

std::string CompressedHeaderKey(const CompressedTransportHeader& header) {
  const std::vector<uint8_t> bytes = EncodeHeader(header);
  return Hex16(Checksum64(bytes.data(), bytes.size()));
}

CompressionPlan PlanCompression(const SceneDescription& scene, const SceneGeometry& geometry,
                                int cubemap_n, const FarmOptions& options, int channels,
                                int terms) {
  CompressionPlan plan;
  plan.options = CompressionOptionsFrom(scene.compression, scene.file);
  if (!options.compression_scheme.empty())
    plan.options.scheme =
        ParseCompressionScheme(options.compression_scheme, "--compression-scheme");
  const auto c = static_cast<uint32_t>(channels);
  // Image relighting: the pixels in raster order are one W×H grid, the 2D domain of the column
  // transform (Cheslack-Postava et al. 2008 §4.1).
  const SpatialDomain domain =
      scene.samples == SpatialSamples::kCameraPixels
          ? ImageDomain(static_cast<uint32_t>(scene.camera.width),
                        static_cast<uint32_t>(scene.camera.height), c)
          : SpatialDomainOf(geometry, scene.compression.order_normal_weight, c);
  // Glossy vertex transport: the m terms' rows are m copies of the vertices (term-major), each
  // its own copy of the segments, so that no column transform mixes two terms; to the codec and
  // every relighter they are m·V samples of one channel (docs/glossy-transport.md).
  SpatialDomain layered;
  for (int t = 0; t < terms; ++t)
    layered.segments.insert(layered.segments.end(), domain.segments.begin(), domain.segments.end());
  plan.header = MakeCompressedHeader(plan.options, cubemap_n, terms > 1 ? layered : domain, c);
  return plan;
}

uint64_t TracedGeometryChecksum(const SceneGeometry& geometry) {
  SceneGeometry traced = geometry;
  for (SceneMesh& m : traced.meshes) {
    m.name.clear();
    m.albedo = Rgb{0, 0, 0};
  }
  const std::string bytes = SerializeSceneGeometry(traced);
  return Checksum64(bytes.data(), bytes.size());
}

uint64_t EnvironmentFileChecksum(const std::string& path) {
  try {
    const std::string bytes = ReadWholeFile(path);
    return Checksum64(bytes.data(), bytes.size());
  } catch (const std::exception&) {
    return 0;
  }
}

RunManifest MakeRunManifest(const SceneDescription& scene, const std::string& scene_text,
                            const SceneGeometry& geometry, const std::string& geometry_bytes,
                            const ResolvedSampling& s, const FarmOptions& options,
                            CompressionPlan* compression) {
  RunManifest m;
  const bool visibility = s.job == "visibility";
  Json rows = {{"job", s.job},
               {"geometry_xxh64", Hex16(TracedGeometryChecksum(geometry))},
               {"samples", s.rows},
               {"cubemap_n", s.cubemap_n},
               {"rays_per_texel", s.rays_per_texel},
               {"seed", s.seed}};
  if (scene.samples == SpatialSamples::kCameraPixels) {
    const Camera& k = scene.camera;
    rows["camera"] = {{"eye", {k.eye.x, k.eye.y, k.eye.z}},
                      {"target", {k.target.x, k.target.y, k.target.z}},
                      {"up", {k.up.x, k.up.y, k.up.z}},
                      {"fov", k.fov_deg},
                      {"width", k.width},
                      {"height", k.height}};
    // Supersampled pixels (keyed only when k > 1, so other runs keep their keys): k, and each
    // mesh's mean relighting weight, which sets the footprint's mixing weights λ.
    if (k.supersample > 1 && !visibility) {
      rows["camera"]["supersample"] = k.supersample;
      const GlossyPixels weights = ResolveGlossyPixels(scene, geometry);
      Json lambda = Json::array();
      for (std::size_t i = 0; i < geometry.meshes.size(); ++i) {
        const Rgb a = i < weights.glossy.size() && weights.glossy[i] ? weights.weight[i]
                                                                     : geometry.meshes[i].albedo;
        lambda.push_back((static_cast<double>(a[0]) + a[1] + a[2]) / 3.0);
      }
      rows["camera"]["footprint_weights"] = std::move(lambda);
    }
    // Glossy pixels carry their materials in the rows (keyed only where there are any, so the
    // keys of diffuse image runs stay as they were).
    const GlossyPixels glossy = ResolveGlossyPixels(scene, geometry);
    if (glossy.any() && !visibility) {
      Json list = Json::array();
      for (std::size_t i = 0; i < glossy.glossy.size(); ++i) {
        if (!glossy.glossy[i]) {
          list.push_back(nullptr);
          continue;
        }
        const Material& mat = glossy.materials[i];
        list.push_back({{"model", static_cast<int>(mat.model)},
                        {"k_d", mat.diffuse[0]},
                        {"k_s", mat.specular[0]},
                        {"exponent", mat.exponent},
                        {"exponent_v", mat.exponent_v},
                        {"roughness", mat.roughness}});
      }
      rows["glossy_pixels"] = std::move(list);
    }
  }
  if (visibility) {
    rows["visibility_bits"] = scene.visibility.bits;
  } else {
    rows["method"] = s.method;
    rows["rows_per_block"] = options.rows_per_block;
    if (s.method == "sparse") rows["sparse"] = SparseJson(scene.sparse);
  }
  // Glossy vertex transport (keyed only where there are terms, so other runs keep their keys).
  if (s.terms > 1 || s.glossy_factors != 0) {
    rows["glossy_terms"] = s.terms;
    rows["glossy_factors_xxh64"] = Hex16(s.glossy_factors);
  }
  m.SetStage(kStageRows, std::move(rows));

  if (!visibility && s.bounces > 0) {
    m.SetStage(kStageIndirect, {{"estimator", s.estimator},
                                {"bounces", s.bounces},
                                {"indirect_n", s.indirect_n},
                                {"paths", s.gather_paths},
                                {"near_field", s.near_field},
                                {"sparse", s.method == "sparse" ? scene.sparse.indirect : "full"},
                                {"sparse_feature_paths", scene.sparse.feature_paths},
                                {"channels", s.channels},
                                {"albedo", AlbedoJson(geometry)}});
  }

  if (!visibility) {
    CompressionPlan plan =
        PlanCompression(scene, geometry, s.cubemap_n, options, s.channels, s.terms);
    // CPCA of a sparse run: Huang §6's dense pass and re-clustering (farm/cpca_phase.h).
    if (plan.header.scheme == CompressionScheme::kCpca && s.method == "sparse")
      plan.header.cpca_method = plan.options.cpca_method = CpcaMethod::kDenseRecluster;
    const CompressedTransportHeader& h = plan.header;
    m.SetStage(kStageCompression, {{"scheme", ToString(h.scheme)},
                                   {"row_wavelet", ToString(h.row_wavelet)},
                                   {"column_wavelet", ToString(h.column_wavelet)},
                                   {"bits", h.bits},
                                   {"keep_fraction", h.keep_fraction},
                                   {"budget", ToString(h.budget)},
                                   {"light_weight", h.light_weight},
                                   {"terms_per_column", h.terms_per_column},
                                   {"dither_seed", h.dither_seed},
                                   {"order_normal_weight", scene.compression.order_normal_weight},
                                   {"header_xxh64", CompressedHeaderKey(h)}});

    Json envs = Json::array();
    for (const std::string& path : scene.environments) {
      envs.push_back({{"path", std::filesystem::path(path).filename().string()},
                      {"xxh64", Hex16(EnvironmentFileChecksum(path))}});
    }
    m.SetStage(kStageEstimate, {{"environments", envs}, {"albedo", AlbedoJson(geometry)}});
    if (compression != nullptr) *compression = std::move(plan);
  }

  m.SetStage(
      kStageAssets,
      {{"scene_xxh64", Hex16(Checksum64(scene_text.data(), scene_text.size()))},
       {"geometry_file_xxh64", Hex16(Checksum64(geometry_bytes.data(), geometry_bytes.size()))}});
  return m;
}

}  // namespace prt
