// The run folder's manifest of stage inputs (see run_manifest.h).
#include "farm/run_manifest.h"

#include <cstdio>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

using Json = nlohmann::ordered_json;

// Every leaf of `now` and `before` whose value differs, as "path a -> b" (objects recursed,
// arrays and numbers compared whole).
void Differences(const Json& now, const Json& before, const std::string& prefix, std::string& out) {
  auto add = [&out](const std::string& what, const Json& a, const Json& b) {
    if (!out.empty()) out += ", ";
    out += what + " " + (a.is_null() ? std::string("(none)") : a.dump()) + " -> " +
           (b.is_null() ? std::string("(none)") : b.dump());
  };
  if (now.is_object() && before.is_object()) {
    for (auto it = now.begin(); it != now.end(); ++it) {
      const Json b = before.contains(it.key()) ? before.at(it.key()) : Json();
      Differences(it.value(), b, prefix + it.key() + ".", out);
    }
    for (auto it = before.begin(); it != before.end(); ++it) {
      if (!now.contains(it.key())) add(prefix + it.key(), it.value(), Json());
    }
    return;
  }
  if (now != before) add(prefix.substr(0, prefix.size() - 1), before, now);
}

}  // namespace

const Json* RunManifest::Stage(const std::string& name) const {
  for (const auto& [stage, inputs] : stages)
    if (stage == name) return &inputs;
  return nullptr;
}

void RunManifest::SetStage(const std::string& name, Json inputs) {
  for (auto& [stage, value] : stages) {
    if (stage == name) {
      value = std::move(inputs);
      return;
    }
  }
  stages.emplace_back(name, std::move(inputs));
}

uint64_t RunManifest::StageKey(const std::string& name) const {
  const Json* inputs = Stage(name);
  if (inputs == nullptr) return 0;
  // The compression and the estimate are computed from the rows; the rows and the assets
  // depend on nothing before them.
  // With interreflection, the compression reads the indirect stage's rows too (whose key
  // chains the rows').
  const bool reads_rows =
      name == kStageCompression || name == kStageEstimate || name == kStageIndirect;
  const bool reads_indirect = name == kStageCompression && Stage(kStageIndirect) != nullptr;
  const std::string text = std::to_string(reads_indirect ? StageKey(kStageIndirect)
                                          : reads_rows   ? StageKey(kStageRows)
                                                         : 0) +
                           name + inputs->dump();
  return Checksum64(text.data(), text.size());
}

std::string RunManifest::StageKeyHex(const std::string& name) const {
  return Hex16(StageKey(name));
}

std::string RunManifest::ToJsonText() const {
  Json j;
  j["format_version"] = format_version;
  Json s = Json::object();
  for (const auto& [stage, inputs] : stages)
    s[stage] = {{"key", StageKeyHex(stage)}, {"inputs", inputs}};
  j["stages"] = std::move(s);
  return j.dump(2) + "\n";
}

RunManifest RunManifest::FromJsonText(const std::string& text, const std::string& file) {
  RunManifest m;
  try {
    const Json j = Json::parse(text);
    m.format_version = j.at("format_version").get<int>();
    if (m.format_version == 1) {
      // prt-farm before stages: one key over the whole scene text. Nothing can be re-used
      // stage by stage (the caller says so and runs every stage).
      (void)j.at("scene_xxh64").get<uint64_t>();
      return m;
    }
    if (m.format_version != kManifestFormatVersion) {
      throw InputError(file, "manifest format " + std::to_string(m.format_version) +
                                 " is newer than this prt-farm (" +
                                 std::to_string(kManifestFormatVersion) + ")");
    }
    for (auto it = j.at("stages").begin(); it != j.at("stages").end(); ++it) {
      if (!it.value().at("inputs").is_object())
        throw InputError(file, "stage inputs not an object");
      m.stages.emplace_back(it.key(), it.value().at("inputs"));
    }
  } catch (const Json::exception& e) {
    throw InputError(file, std::string("not a prt-farm checkpoint manifest: ") + e.what());
  }
  return m;
}

std::string RunManifest::StageDifferences(const std::string& stage,
                                          const RunManifest& older) const {
  const Json* now = Stage(stage);
  const Json* before = older.Stage(stage);
  if (now == nullptr) return "";
  if (before == nullptr) return "not recorded";
  std::string out;
  Differences(*now, *before, "", out);
  return out;
}

}  // namespace prt
