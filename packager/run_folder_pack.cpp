// prt-pack's library side: run folder → PackInput, and the inspect / verify reports.
#include "packager/run_folder_pack.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "formats/compressed_transport.h"
#include "formats/cpca_transport.h"
#include "formats/geometry_file.h"
#include "formats/glossy_factors.h"
#include "formats/image_file.h"
#include "formats/transport_file.h"
#include "formats/visibility_blocks.h"
#include "packager/prtpack_format.h"
#include "packager/prtpack_transport.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/scene.h"

namespace prt::pack {
namespace {

namespace fs = std::filesystem;

nlohmann::json SceneJson(const std::string& text, const std::string& file) {
  try {
    const toml::table table = toml::parse(text, file);
    std::ostringstream out;
    out << toml::json_formatter{table};
    nlohmann::json j = nlohmann::json::parse(out.str());
    j["file"] = kSceneCopyFileName;
    return j;
  } catch (const std::exception&) {
    return {{"file", kSceneCopyFileName}, {"toml", text}};
  }
}

// META "parameters"; "channels" only for a transport of 3 channels, so that a one-channel pack
// keeps the bytes it had before transports had channels.
nlohmann::json ParametersJson(const CompressedTransportHeader& h, uint32_t columns_per_block) {
  nlohmann::json j = {{"cubemap_n", h.cubemap_n},
                      {"sample_count", h.sample_count},
                      {"row_wavelet", ToString(h.row_wavelet)},
                      {"column_wavelet", ToString(h.column_wavelet)},
                      {"scheme", ToString(h.scheme)},
                      {"bits", h.bits},
                      {"keep_fraction", h.keep_fraction},
                      {"terms_per_column", h.terms_per_column},
                      {"dither_seed", h.dither_seed},
                      {"columns_per_block", columns_per_block}};
  if (h.channels != 1) j["channels"] = h.channels;
  return j;
}

// META "parameters" of a CPCA transport (docs/cpca.md): the header's settings (no column blocks:
// `bits` and `keep_fraction` are the basis vectors' quantiser bits and kept terms) and the
// clustering's.
nlohmann::json CpcaParametersJson(const CompressedTransportHeader& h) {
  nlohmann::json j = {
      {"cubemap_n", h.cubemap_n},
      {"sample_count", h.sample_count},
      {"row_wavelet", ToString(h.row_wavelet)},
      {"scheme", ToString(h.scheme)},
      {"bits", h.bits},
      {"keep_fraction", h.keep_fraction},
      {"dither_seed", h.dither_seed},
      {"clusters", h.cpca_clusters},
      {"bases", h.cpca_bases},
      {"coefficient_bits", h.cpca_coefficient_bits},
      {"cpca_method",
       h.cpca_method == CpcaMethod::kDenseRecluster ? "dense-recluster" : "standard"}};
  if (h.channels != 1) j["channels"] = h.channels;
  return j;
}

// A transport's rows against the run's samples: channels × the image's pixels in an image run,
// else channels × the geometry's vertices.
// Glossy vertex transport: terms × (channels × the vertices).
void CheckTransportRows(const CompressedTransportHeader& h, const SceneGeometry& geometry,
                        const std::optional<ImageSamplesInfo>& image, const std::string& file,
                        const std::string& image_file, int terms) {
  if (image) {
    if (static_cast<uint64_t>(h.sample_count) != uint64_t{h.channels} * image->pixels())
      throw InputError(file, "transport has " + std::to_string(h.sample_count) +
                                 " rows but the image " + image_file + " has " +
                                 std::to_string(image->pixels()) + " pixels");
  } else if (static_cast<uint64_t>(h.sample_count) !=
             uint64_t{h.channels} * uint64_t(terms) * geometry.vertex_count()) {
    throw InputError(file, "transport has " + std::to_string(h.sample_count) + " rows (" +
                               std::to_string(h.channels) + " colour channel(s) × " +
                               std::to_string(h.spatial_count()) +
                               " samples) but the geometry has " +
                               std::to_string(geometry.vertex_count()) + " vertices" +
                               (terms > 1 ? " × " + std::to_string(terms) + " BRDF terms" : ""));
  }
}

std::string Bytes(uint64_t n) {
  char buf[32];
  if (n >= (uint64_t(1) << 20)) {
    std::snprintf(buf, sizeof buf, "%.2f MiB", double(n) / double(1 << 20));
  } else if (n >= 1024) {
    std::snprintf(buf, sizeof buf, "%.1f KiB", double(n) / 1024.0);
  } else {
    std::snprintf(buf, sizeof buf, "%" PRIu64 " B", n);
  }
  return buf;
}

const char* CodecName(uint32_t c) {
  switch (c) {
    case 0:
      return "none";
    case 1:
      return "zstd";
    case 2:
      return "draco";
    default:
      return "?";
  }
}

// Vertices [first, first + count) of `all` as blocks of their own (the arrays sliced, offsets
// rebased): one mesh's share of the run's visibility.
VisibilityBlocks SliceVisibility(const VisibilityBlocks& all, std::size_t first,
                                 std::size_t count) {
  VisibilityBlocks out = MakeVisibilityBlocks(all.n, all.bits);
  out.vertex_count = count;
  const std::size_t e0 = all.Entry(first, 0), e1 = all.Entry(first + count, 0);
  out.kind.assign(all.kind.begin() + static_cast<std::ptrdiff_t>(e0),
                  all.kind.begin() + static_cast<std::ptrdiff_t>(e1));
  const uint64_t c0 = all.change_begin[e0], c1 = all.change_begin[e1];
  out.change_begin.resize(e1 - e0 + 1);
  for (std::size_t e = e0; e <= e1; ++e) out.change_begin[e - e0] = all.change_begin[e] - c0;
  out.change_pos.assign(all.change_pos.begin() + static_cast<std::ptrdiff_t>(c0),
                        all.change_pos.begin() + static_cast<std::ptrdiff_t>(c1));
  if (!all.change_value.empty()) {
    out.change_value.assign(all.change_value.begin() + static_cast<std::ptrdiff_t>(c0),
                            all.change_value.begin() + static_cast<std::ptrdiff_t>(c1));
  }
  return out;
}

// Each mesh's glossy material (docs/scene-format.md, "Glossy materials") from the run's scene
// copy, in pack order; Lambert with the mesh's albedo where the scene says nothing (or cannot be
// parsed any more).
nlohmann::json MaterialsJson(const SceneGeometry& geometry, const std::string& scene_text,
                             const std::string& scene_file) {
  std::optional<SceneDescription> scene;
  try {
    scene = ParseScene(scene_text, scene_file, "");
  } catch (const std::exception&) {
  }
  nlohmann::json out = nlohmann::json::array();
  for (const SceneMesh& m : geometry.meshes) {
    GlossyMaterialSettings g;
    if (scene && m.is_ground) {
      g = scene->ground.glossy;
    } else if (scene) {
      for (const MeshInstance& mi : scene->meshes)
        if (mi.name == m.name) g = mi.glossy;
    }
    out.push_back({{"name", m.name},
                   {"brdf", g.brdf},
                   {"diffuse", {m.albedo[0], m.albedo[1], m.albedo[2]}},
                   {"specular", {g.specular[0], g.specular[1], g.specular[2]}},
                   {"exponent", g.exponent},
                   {"exponent_v", g.exponent_v}});
    // GGX only (older materials keep their bytes): roughness r, α = r².
    if (g.brdf == "ggx") out.back()["roughness"] = g.roughness;
  }
  return out;
}

// "error estimates: compression 1.38% (relative Frobenius), Monte-Carlo B 0.12% uniform,
// 0.85% sunrise.exr …" from META "error_estimates" ("" when the pack has none).
std::string ErrorEstimatesLine(const nlohmann::json& meta) {
  if (!meta.contains("error_estimates") || !meta["error_estimates"].is_object()) {
    return "error estimates: none (a pack of an older prt-farm run)\n";
  }
  const nlohmann::json& e = meta["error_estimates"];
  std::string out = "error estimates:";
  char buf[160];
  if (e.contains("compression") && e["compression"].is_object()) {
    std::snprintf(buf, sizeof buf, " compression %.3f%% of T (relative Frobenius)",
                  100 * e["compression"].value("relative_frobenius_error", 0.0));
    out += buf;
  }
  if (e.contains("monte_carlo") && e["monte_carlo"].is_object()) {
    const nlohmann::json& mc = e["monte_carlo"];
    // The sparse method's total (rays and reconstruction) where there is one.
    const bool total = e.contains("total") && e["total"].is_object();
    const nlohmann::json& shown = total ? e["total"] : mc;
    if (!mc.value("estimable", false)) {
      out += "; Monte-Carlo: not estimated (" + mc.value("why_not", std::string("?")) + ")";
    } else if (shown.contains("environments") && shown["environments"].is_array()) {
      out += total ? "; Monte-Carlo and reconstruction, relative RMS of B:"
                   : "; Monte-Carlo, relative RMS of B:";
      bool first = true;
      for (const nlohmann::json& env : shown["environments"]) {
        if (!env.is_object()) continue;
        std::snprintf(buf, sizeof buf, "%s %.3f%% %s", first ? "" : ",",
                      100 * env.value("relative_rms", 0.0),
                      env.value("name", std::string("?")).c_str());
        out += buf;
        first = false;
      }
    }
  }
  return out + "\n";
}

bool IsCompressedTransportHeader(const std::vector<uint8_t>& params) {
  return params.size() >= 8 && std::string(params.begin(), params.begin() + 8) == "PRTCTHD1";
}

}  // namespace

PackInput PackInputFromRunFolder(const std::string& run_dir, const RunPackOptions& options) {
  const fs::path dir(run_dir);
  if (!fs::is_directory(dir)) throw InputError(run_dir, "not a run folder (no such directory)");
  PackInput in;
  const SceneGeometry geometry = ReadSceneGeometryFile((dir / kGeometryFileName).string());
  in.meshes = PackMeshesOf(geometry);
  nlohmann::json meta = nlohmann::json::object();
  const fs::path scene = dir / kSceneCopyFileName;
  std::string scene_text;
  if (fs::exists(scene)) {
    scene_text = ReadWholeFile(scene.string());
    meta["scene"] = SceneJson(scene_text, scene.string());
  }
  meta["materials"] = MaterialsJson(geometry, scene_text, scene.string());
  const fs::path visibility = dir / kVisibilityFileName;
  if (fs::exists(visibility)) {
    const std::string bytes = ReadWholeFile(visibility.string());
    const VisibilityBlocks all = DecodeVisibilityBlocks(
        std::span(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
        visibility.string());
    if (all.vertex_count != geometry.vertex_count()) {
      throw InputError(visibility.string(),
                       "holds " + std::to_string(all.vertex_count) + " visibility maps but the " +
                           "geometry has " + std::to_string(geometry.vertex_count()) + " vertices");
    }
    VisibilityInput vis;
    std::size_t first = 0;
    for (const SceneMesh& m : geometry.meshes) {
      vis.per_mesh.push_back(
          EncodeVisibilityBlocks(SliceVisibility(all, first, m.mesh.positions.size())));
      first += m.mesh.positions.size();
    }
    in.visibility = std::move(vis);
    const VisibilityBlockCounts c = CountVisibilityBlocks(all);
    nlohmann::json v = {{"n", all.n},
                        {"bits", all.bits},
                        {"vertices", all.vertex_count},
                        {"raw_bitmap_bytes", all.vertex_count * all.texels_per_map() *
                                                 static_cast<std::size_t>(all.bits) / 8},
                        {"encoded_bytes", bytes.size()},
                        {"blocks", {{"zero", c.zero}, {"one", c.one}, {"mixed", c.mixed}}},
                        {"changes", c.changes}};
    meta["visibility"] = std::move(v);
  }
  const fs::path report = dir / kReportFileName;
  if (fs::exists(report)) {
    const std::string text = ReadWholeFile(report.string());
    nlohmann::json r = nlohmann::json::parse(text, nullptr, false);
    if (r.is_discarded()) throw InputError(report.string(), "not valid JSON");
    meta["report"] = std::move(r);
  }
  // What the run measured of its own accuracy (docs/prtpack-format.md, "error_estimates"):
  // the compression's exact relative Frobenius error and the Monte-Carlo error of T as relative
  // RMS errors of relit radiance (the farm's accuracy.json).
  if (meta.contains("report") && meta["report"].is_object()) {
    const nlohmann::json& rep = meta["report"];
    nlohmann::json e = nlohmann::json::object();
    if (rep.contains("compression") && rep["compression"].is_object() &&
        rep["compression"].contains("relative_frobenius_error")) {
      e["compression"] = {
          {"relative_frobenius_error", rep["compression"]["relative_frobenius_error"]},
          {"scheme", rep["compression"].value("scheme", std::string())},
          {"keep_fraction", rep["compression"].value("keep_fraction", 0.0)}};
    }
    if (rep.contains("accuracy") && rep["accuracy"].is_object()) {
      for (const char* key : {"monte_carlo", "reconstruction", "total"})
        if (rep["accuracy"].contains(key)) e[key] = rep["accuracy"][key];
    }
    if (!e.empty()) meta["error_estimates"] = std::move(e);
  }
  if (meta.contains("visibility") && meta.contains("report") && meta["report"].is_object() &&
      meta["report"].contains("visibility") && meta["report"]["visibility"].is_object()) {
    meta["visibility"]["supersample"] = meta["report"]["visibility"].value("supersample", 1);
  }
  // Image relighting: the farm's image.prti becomes the IMGE section.
  const fs::path image_file = dir / kImageFileName;
  if (fs::exists(image_file)) {
    in.image =
        ReadImageSamplesFile(image_file.string(), static_cast<uint32_t>(geometry.meshes.size()));
    const Camera& k = in.image->camera;
    meta["image"] = {{"width", k.width},
                     {"height", k.height},
                     {"eye", {k.eye.x, k.eye.y, k.eye.z}},
                     {"target", {k.target.x, k.target.y, k.target.z}},
                     {"up", {k.up.x, k.up.y, k.up.z}},
                     {"fov", k.fov_deg},
                     {"background_pixels", in.image->background_pixels()}};
    if (in.image->supersample > 1) meta["image"]["supersample"] = in.image->supersample;
  }
  // Glossy vertex transport: the farm's glossy.prtf becomes the GLSY section (without f).
  const fs::path glossy_file = dir / kGlossyFactorFileName;
  int terms = 1;
  if (fs::exists(glossy_file)) {
    in.glossy = ParseGlossyFactors(ReadWholeFile(glossy_file.string()), glossy_file.string());
    if (in.glossy->mesh_factor.size() != geometry.meshes.size())
      throw InputError(glossy_file.string(),
                       "names " + std::to_string(in.glossy->mesh_factor.size()) +
                           " meshes; the geometry has " + std::to_string(geometry.meshes.size()));
    terms = in.glossy->terms;
    nlohmann::json list = nlohmann::json::array();
    for (std::size_t m = 0; m < geometry.meshes.size(); ++m) {
      if (!in.glossy->glossy(m)) continue;
      const BrdfFactors& f = in.glossy->factors[in.glossy->mesh_factor[m]];
      list.push_back({{"mesh", geometry.meshes[m].name},
                      {"material", f.description},
                      {"relative_error", f.relative_error}});
    }
    meta["glossy"] = {{"terms", terms}, {"meshes", list}};
  }
  const fs::path transport = options.transport_file.empty() ? dir / kCompressedTransportFileName
                                                            : fs::path(options.transport_file);
  if (fs::exists(transport)) {
    const std::string text = ReadWholeFile(transport.string());
    const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(text.data()),
                                         text.size());
    std::size_t body = 0;
    // channels × V rows, channel-major (formats/compressed_transport.h); V: the pixels of an
    // image run, else the vertices. Scheme cpca: a CPCA body (the CPCA section), else columns.
    if (DecodeCompressedFileStart(bytes, transport.string(), body).scheme ==
        CompressionScheme::kCpca) {
      CpcaTransport t = DecodeCpcaTransport(bytes, transport.string());
      CheckTransportRows(t.header, geometry, in.image, transport.string(), image_file.string(),
                         terms);
      meta["parameters"] = CpcaParametersJson(t.header);
      in.cpca = std::move(t);
    } else {
      const CompressedTransport t = DecodeCompressedTransport(bytes, transport.string());
      CheckTransportRows(t.header, geometry, in.image, transport.string(), image_file.string(),
                         terms);
      in.transport = MakeTransportInput(t, options.columns_per_block);
      meta["parameters"] = ParametersJson(t.header, options.columns_per_block);
    }
  } else if (!options.geometry_only && !in.visibility) {
    throw InputError(transport.string(),
                     "no compressed transport (nor visibility.prtv) in the run folder (pass "
                     "--geometry-only to pack geometry and metadata without it)");
  }
  in.metadata_json = meta.dump();
  return in;
}

std::string InspectPack(const PackReader& r) {
  std::ostringstream out;
  char line[256];
  out << r.name() << ": .prtpack " << r.version_major() << "." << r.version_minor() << ", "
      << Bytes(r.file_size()) << ", " << r.sections().size() << " sections\n";
  std::snprintf(line, sizeof line, "  %3s  %-4s %5s  %-5s  %12s  %12s  %12s  %7s  %-16s\n", "#",
                "type", "id", "codec", "offset", "stored", "raw", "ratio", "xxh64");
  out << line;
  uint64_t stored = 0, raw = 0;
  for (std::size_t i = 0; i < r.sections().size(); ++i) {
    const SectionInfo& s = r.sections()[i];
    std::snprintf(line, sizeof line,
                  "  %3zu  %-4s %5u  %-5s  %12" PRIu64 "  %12" PRIu64 "  %12" PRIu64
                  "  %6.2fx  %016" PRIx64 "%s\n",
                  i, s.type.c_str(), s.id, CodecName(s.codec), s.offset, s.stored_size, s.raw_size,
                  s.stored_size ? double(s.raw_size) / double(s.stored_size) : 1.0, s.checksum,
                  s.known ? "" : "  (unknown: skipped)");
    out << line;
    stored += s.stored_size;
    raw += s.raw_size;
  }
  out << "  total: " << Bytes(raw) << " decoded in " << Bytes(stored) << " stored\n";
  const nlohmann::json meta = nlohmann::json::parse(r.ReadMetadata());
  // The scene's name: [scene] name in scene.toml, else a top-level name, else the report's.
  const nlohmann::json* name = nullptr;
  if (meta.contains("scene") && meta["scene"].is_object()) {
    const nlohmann::json& sc = meta["scene"];
    if (sc.contains("scene") && sc["scene"].is_object() && sc["scene"].contains("name")) {
      name = &sc["scene"]["name"];
    } else if (sc.contains("name")) {
      name = &sc["name"];
    }
  }
  if (name == nullptr && meta.contains("report") && meta["report"].is_object() &&
      meta["report"].contains("scene_name")) {
    name = &meta["report"]["scene_name"];
  }
  if (name != nullptr) out << "scene: " << name->dump() << "\n";
  for (std::size_t m = 0; m < r.mesh_count(); ++m) {
    const MeshMaterial mat = r.ReadMaterial(m);
    const SectionInfo* mesh = nullptr;
    for (const SectionInfo& s : r.sections()) {
      if (s.type_code == kTypeMesh && s.id == m) mesh = &s;
    }
    std::string counts;
    if (meta.contains("meshes") && meta["meshes"].is_array() && m < meta["meshes"].size()) {
      const auto& j = meta["meshes"][m];
      counts = j.value("vertices", nlohmann::json()).dump() + " vertices, " +
               j.value("triangles", nlohmann::json()).dump() + " triangles, ";
    }
    std::snprintf(line, sizeof line, "albedo (%.3f, %.3f, %.3f)%s", mat.albedo[0], mat.albedo[1],
                  mat.albedo[2], mat.is_ground ? ", ground plane" : "");
    out << "mesh " << m << " \"" << mat.name << "\": " << counts << line << ", "
        << Bytes(mesh ? mesh->stored_size : 0) << " Draco\n";
  }
  if (r.has_transport()) {
    const TransportIndex t = r.ReadTransportIndex();
    uint64_t braw = 0, bstored = 0;
    for (const TransportBlockInfo& b : t.blocks) {
      braw += b.raw_size;
      bstored += b.stored_size;
    }
    out << "transport: " << t.row_count / t.channels << " samples x " << t.channels
        << (t.channels == 1 ? " channel (one row per sample for r, g, b)"
                            : " colour channels (rows channel-major)")
        << " x " << t.column_count << " columns in " << t.blocks.size() << " blocks (encoding "
        << t.encoding << "), " << Bytes(braw) << " raw -> " << Bytes(bstored) << " stored";
    if (bstored > 0) {
      std::snprintf(line, sizeof line, " (%.2fx)", double(braw) / double(bstored));
      out << line;
    }
    out << "\n";
    if (meta.contains("parameters")) out << "parameters: " << meta["parameters"].dump() << "\n";
  } else if (r.has_cpca()) {
    const CpcaTransport t = r.ReadCpcaTransport();
    const CompressedTransportHeader& h = t.header;
    const SectionInfo* section = nullptr;
    for (const SectionInfo& s : r.sections())
      if (s.type_code == kTypeCpca) section = &s;
    const uint64_t sraw = section ? section->raw_size : 0,
                   sstored = section ? section->stored_size : 0;
    out << "transport: CPCA (clustered PCA), " << h.spatial_count() << " samples x " << h.channels
        << (h.channels == 1 ? " channel (one row per sample for r, g, b)"
                            : " colour channels (rows channel-major)")
        << " x " << h.column_count() << " columns (" << ToString(h.row_wavelet)
        << "): " << h.cpca_clusters << " clusters x " << h.cpca_bases << " bases, "
        << t.term_count() << " mean and basis terms (" << int(h.bits) << " bits), "
        << t.coefficients.size() << " coefficients (" << int(h.cpca_coefficient_bits) << " bits), "
        << Bytes(sraw) << " raw -> " << Bytes(sstored) << " stored";
    if (sstored > 0) {
      std::snprintf(line, sizeof line, " (%.2fx)", double(sraw) / double(sstored));
      out << line;
    }
    out << "\n";
    if (meta.contains("parameters")) out << "parameters: " << meta["parameters"].dump() << "\n";
  } else {
    out << "transport: none\n";
  }
  if (r.has_image()) {
    const ImageSamplesInfo im = r.ReadImage();
    const std::size_t bg = im.background_pixels();
    out << "image: " << im.camera.width << "x" << im.camera.height
        << " pixels are the samples (image relighting), " << bg << " background; camera eye ("
        << im.camera.eye.x << ", " << im.camera.eye.y << ", " << im.camera.eye.z << "), fov "
        << im.camera.fov_deg << "\n";
    if (im.has_glossy_pixels()) {
      std::size_t glossy = 0;
      for (uint32_t m : im.pixel_mesh)
        if (m != kImageBackground && im.glossy_mesh[m]) ++glossy;
      out << "glossy pixels: " << glossy << " (rows carry the BRDF with the camera's view;";
      for (std::size_t m = 0; m < im.glossy_mesh.size(); ++m)
        if (im.glossy_mesh[m])
          out << " mesh " << m << " weight (" << im.glossy_weight[m][0] << ", "
              << im.glossy_weight[m][1] << ", " << im.glossy_weight[m][2] << ")";
      out << ")\n";
    }
    if (im.supersample > 1) {
      // Edge pixels: those whose 3×3 neighbourhood sees more than one mesh (or background).
      const int w = im.camera.width, h = im.camera.height;
      std::size_t edges = 0, partial = 0;
      double edge_cov = 0;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const std::size_t p = static_cast<std::size_t>(y) * w + x;
          bool edge = false;
          for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
              const int u = x + dx, v = y + dy;
              if (u >= 0 && v >= 0 && u < w && v < h &&
                  im.pixel_mesh[static_cast<std::size_t>(v) * w + u] != im.pixel_mesh[p])
                edge = true;
            }
          if (im.coverage[p] > 0.f && im.coverage[p] < 1.f) ++partial;
          if (!edge) continue;
          ++edges;
          edge_cov += im.coverage[p];
        }
      std::snprintf(line, sizeof line, "%.3f", edges > 0 ? edge_cov / double(edges) : 0.0);
      out << "supersample: " << im.supersample << "x" << im.supersample
          << " rays per pixel (box filter); " << partial << " pixels partly covered; " << edges
          << " edge pixels, mean coverage " << line << "\n";
    }
  }
  if (r.has_visibility()) {
    uint64_t vraw = 0, vstored = 0;
    for (const SectionInfo& s : r.sections()) {
      if (s.type_code != kTypeVisibility) continue;
      vraw += s.raw_size;
      vstored += s.stored_size;
    }
    out << "visibility: " << r.mesh_count() << " VISB sections, " << Bytes(vraw)
        << " block-coded -> " << Bytes(vstored) << " stored (zstd)";
    if (meta.contains("visibility") && meta["visibility"].is_object()) {
      const nlohmann::json& v = meta["visibility"];
      const double verts = v.value("vertices", 0.0);
      const double bitmap = v.value("raw_bitmap_bytes", 0.0);
      std::snprintf(line, sizeof line,
                    "; n = %d, %d bit(s), %.0f maps; bitmaps %s (%.0f B/vertex), stored %.1f "
                    "B/vertex (%.1fx smaller)",
                    v.value("n", 0), v.value("bits", 0), verts,
                    Bytes(static_cast<uint64_t>(bitmap)).c_str(), verts > 0 ? bitmap / verts : 0.0,
                    verts > 0 ? double(vstored) / verts : 0.0,
                    vstored > 0 ? bitmap / double(vstored) : 0.0);
      out << line;
    }
    out << "\n";
    if (meta.contains("visibility"))
      out << "visibility blocks: " << meta["visibility"].dump() << "\n";
  } else {
    out << "visibility: none\n";
  }
  if (meta.contains("materials") && meta["materials"].is_array()) {
    out << "materials:";
    for (const nlohmann::json& m : meta["materials"]) {
      if (!m.is_object()) continue;
      out << " " << m.value("name", std::string("?")) << " " << m.value("brdf", std::string("?"));
    }
    out << "\n";
  }
  if (meta.contains("report") && meta["report"].is_object()) {
    const nlohmann::json& rep = meta["report"];
    std::snprintf(line, sizeof line,
                  "run: %s, n = %d, %d ray(s) per texel, %.3g rays, %.1f s on %d rank(s)\n",
                  rep.value("method", std::string("?")).c_str(), rep.value("cubemap_n", 0),
                  rep.value("rays_per_texel", 0), rep.value("rays_traced_including_reused", 0.0),
                  rep.value("wall_seconds", 0.0), rep.value("ranks", 0));
    out << line;
  }
  out << ErrorEstimatesLine(meta);
  return out.str();
}

std::string VerifyPack(const PackReader& r) {
  r.VerifyAll();
  std::string extra;
  if (r.has_transport()) {
    const TransportIndex t = r.ReadTransportIndex();
    if (IsCompressedTransportHeader(t.params)) {
      const CompressedTransport ct = ReadCompressedTransport(r);
      extra = ", " + std::to_string(ct.columns.size()) + " compressed columns decoded";
    }
  }
  if (r.has_cpca()) {
    const CpcaTransport t = r.ReadCpcaTransport();
    extra = ", CPCA transport decoded (" + std::to_string(t.row_count()) + " rows, " +
            std::to_string(t.clusters.size()) + " clusters x " + std::to_string(t.bases()) +
            " bases, " + std::to_string(t.term_count()) + " terms)";
  }
  if (r.has_visibility()) {
    const VisibilityBlocks v = r.ReadAllVisibility();
    extra += ", " + std::to_string(v.vertex_count) + " visibility maps decoded";
  }
  if (r.has_image()) {
    const ImageSamplesInfo im = r.ReadImage();
    extra += ", a " + std::to_string(im.camera.width) + "×" + std::to_string(im.camera.height) +
             " image";
  }
  return r.name() + ": OK (" + std::to_string(r.sections().size()) +
         " sections, every checksum and structural rule holds" + extra + ")";
}

}  // namespace prt::pack
