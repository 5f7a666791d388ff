// The checkpoint manifest (see run_manifest.h).
#include "farm/run_manifest.h"

#include <filesystem>
#include <nlohmann/json.hpp>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

nlohmann::json ToJson(const RunManifest& m) {
  nlohmann::json j{{"format_version", m.format_version},
                   {"method", m.method},
                   {"cubemap_n", m.cubemap_n},
                   {"rays_per_texel", m.rays_per_texel},
                   {"seed", m.seed},
                   {"rows", m.rows},
                   {"rows_per_block", m.rows_per_block},
                   {"scene_xxh64", m.scene_checksum},
                   {"geometry_xxh64", m.geometry_checksum}};
  if (m.method == "visibility") j["visibility_bits"] = m.visibility_bits;
  return j;
}

}  // namespace

std::string RunManifest::ToJsonText() const {
  return ToJson(*this).dump(2) + "\n";
}

RunManifest RunManifest::FromJsonText(const std::string& text, const std::string& file) {
  RunManifest m;
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    m.format_version = j.at("format_version").get<int>();
    m.method = j.at("method").get<std::string>();
    m.cubemap_n = j.at("cubemap_n").get<int>();
    m.rays_per_texel = j.at("rays_per_texel").get<int>();
    m.seed = j.at("seed").get<uint64_t>();
    m.rows = j.at("rows").get<uint64_t>();
    m.rows_per_block = j.at("rows_per_block").get<uint32_t>();
    m.scene_checksum = j.at("scene_xxh64").get<uint64_t>();
    m.geometry_checksum = j.at("geometry_xxh64").get<uint64_t>();
    m.visibility_bits = j.value("visibility_bits", 0);
  } catch (const nlohmann::json::exception& e) {
    throw InputError(file, std::string("not a prt-farm checkpoint manifest: ") + e.what());
  }
  return m;
}

uint64_t RunManifest::Key() const {
  const std::string text = ToJsonText();
  return Checksum64(text.data(), text.size());
}

std::string RunManifest::DifferencesFrom(const RunManifest& older) const {
  const nlohmann::json now = ToJson(*this);
  const nlohmann::json before = ToJson(older);
  std::string out;
  for (auto it = now.begin(); it != now.end(); ++it) {
    const nlohmann::json b = before.contains(it.key()) ? before.at(it.key()) : nlohmann::json();
    if (b != it.value()) {
      if (!out.empty()) out += ", ";
      out += it.key() + " " + b.dump() + " -> " + it.value().dump();
    }
  }
  return out;
}

}  // namespace prt
