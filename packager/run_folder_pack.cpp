// prt-pack's library side: run folder → PackInput, and the inspect / verify reports.
#include "packager/run_folder_pack.h"

#include <toml++/toml.h>

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>

#include "packager/prtpack_format.h"
#include "packager/prtpack_transport.h"
#include "vocabulary/compressed_transport.h"
#include "vocabulary/errors.h"
#include "vocabulary/transport_file.h"

namespace prt::pack {
namespace {

namespace fs = std::filesystem;

nlohmann::json SceneJson(const std::string& text, const std::string& file) {
  try {
    const toml::table table = toml::parse(text, file);
    std::ostringstream out;
    out << toml::json_formatter{table};
    nlohmann::json j = nlohmann::json::parse(out.str());
    j["file"] = "scene.toml";
    return j;
  } catch (const std::exception&) {
    return {{"file", "scene.toml"}, {"toml", text}};
  }
}

nlohmann::json ParametersJson(const CompressedTransportHeader& h, uint32_t columns_per_block) {
  return {{"cubemap_n", h.cubemap_n},
          {"sample_count", h.sample_count},
          {"row_wavelet", ToString(h.row_wavelet)},
          {"column_wavelet", ToString(h.column_wavelet)},
          {"scheme", ToString(h.scheme)},
          {"bits", h.bits},
          {"keep_fraction", h.keep_fraction},
          {"terms_per_column", h.terms_per_column},
          {"dither_seed", h.dither_seed},
          {"columns_per_block", columns_per_block}};
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

bool IsCompressedTransportHeader(const std::vector<uint8_t>& params) {
  return params.size() >= 8 && std::string(params.begin(), params.begin() + 8) == "PRTCTHD1";
}

}  // namespace

PackInput PackInputFromRunFolder(const std::string& run_dir, const RunPackOptions& options) {
  const fs::path dir(run_dir);
  if (!fs::is_directory(dir)) throw InputError(run_dir, "not a run folder (no such directory)");
  PackInput in;
  const SceneGeometry geometry = ReadSceneGeometryFile((dir / kGeometryFileName).string());
  for (const SceneMesh& m : geometry.meshes) {
    in.meshes.push_back({m.name, m.mesh, m.albedo, m.is_ground,
                         static_cast<uint32_t>(std::max(0, m.grid_resolution))});
  }
  nlohmann::json meta = nlohmann::json::object();
  const fs::path scene = dir / kSceneCopyFileName;
  if (fs::exists(scene)) meta["scene"] = SceneJson(ReadWholeFile(scene.string()), scene.string());
  const fs::path report = dir / kReportFileName;
  if (fs::exists(report)) {
    const std::string text = ReadWholeFile(report.string());
    nlohmann::json r = nlohmann::json::parse(text, nullptr, false);
    if (r.is_discarded()) throw InputError(report.string(), "not valid JSON");
    meta["report"] = std::move(r);
  }
  const fs::path transport = options.transport_file.empty() ? dir / kCompressedTransportFileName
                                                            : fs::path(options.transport_file);
  if (fs::exists(transport)) {
    const std::string bytes = ReadWholeFile(transport.string());
    const CompressedTransport t = DecodeCompressedTransport(
        std::span(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
        transport.string());
    if (t.header.sample_count != geometry.vertex_count()) {
      throw InputError(transport.string(),
                       "transport has " + std::to_string(t.header.sample_count) +
                           " samples but the geometry has " +
                           std::to_string(geometry.vertex_count()) + " vertices");
    }
    in.transport = MakeTransportInput(t, options.columns_per_block);
    meta["parameters"] = ParametersJson(t.header, options.columns_per_block);
  } else if (!options.geometry_only) {
    throw InputError(transport.string(),
                     "no compressed transport in the run folder (pass --geometry-only to pack "
                     "geometry and metadata without it)");
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
    out << "transport: " << t.row_count << " samples x " << t.column_count << " columns in "
        << t.blocks.size() << " blocks (encoding " << t.encoding << "), " << Bytes(braw)
        << " raw -> " << Bytes(bstored) << " stored";
    if (bstored > 0) {
      std::snprintf(line, sizeof line, " (%.2fx)", double(braw) / double(bstored));
      out << line;
    }
    out << "\n";
    if (meta.contains("parameters")) out << "parameters: " << meta["parameters"].dump() << "\n";
  } else {
    out << "transport: none\n";
  }
  if (meta.contains("report")) out << "report: " << meta["report"].dump() << "\n";
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
  return r.name() + ": OK (" + std::to_string(r.sections().size()) +
         " sections, every checksum and structural rule holds" + extra + ")";
}

}  // namespace prt::pack
