// Every name inside a run folder, once (docs/farm.md, "Run folder"): prt-farm writes these files,
// prt-pack and the benchmarks read them. Names only; the files' formats have their own headers
// in formats/.
#pragma once

#include <filesystem>
#include <string>

namespace prt {

inline constexpr const char* kTransportFileName = "transport.prtt";  // raw T (.prtt)
inline constexpr const char* kTransportPartialSuffix = ".partial";   // while sampling
inline constexpr const char* kGeometryFileName = "geometry.prtg";    // the samples' geometry
inline constexpr const char* kSceneCopyFileName = "scene.toml";      // the scene as given
inline constexpr const char* kReportFileName = "report.json";        // what the run did
inline constexpr const char* kCompressedTransportFileName = "transport.prtc";  // compressed T
inline constexpr const char* kVisibilityFileName = "visibility.prtv";          // visibility job
inline constexpr const char* kVisibilityChunksFileName = "visibility.chunks";  // its job results
inline constexpr const char* kCheckpointsDirName = "checkpoints";
inline constexpr const char* kManifestFileName = "manifest.json";  // in checkpoints/
inline constexpr const char* kJournalFileName = "journal.txt";     // in checkpoints/
inline constexpr const char* kSparseDirName = "sparse";            // the sparse method's side files

// The paths of a run folder's files.
struct RunFolder {
  explicit RunFolder(const std::string& d) : dir(d) {
    const std::filesystem::path p(d);
    transport = (p / kTransportFileName).string();
    partial = transport + kTransportPartialSuffix;
    geometry = (p / kGeometryFileName).string();
    scene_copy = (p / kSceneCopyFileName).string();
    report = (p / kReportFileName).string();
    checkpoints = (p / kCheckpointsDirName).string();
    manifest = (p / kCheckpointsDirName / kManifestFileName).string();
    journal = (p / kCheckpointsDirName / kJournalFileName).string();
    compressed = (p / kCompressedTransportFileName).string();
    sparse = (p / kSparseDirName).string();
    visibility = (p / kVisibilityFileName).string();
    visibility_chunks = (p / kVisibilityChunksFileName).string();
  }
  std::string dir;
  std::string transport;          // transport.prtt (final, complete)
  std::string partial;            // transport.prtt.partial (rows written in place while running)
  std::string geometry;           // geometry.prtg
  std::string scene_copy;         // scene.toml
  std::string report;             // report.json
  std::string checkpoints;        // checkpoints/
  std::string manifest;           // checkpoints/manifest.json
  std::string journal;            // checkpoints/journal.txt
  std::string compressed;         // transport.prtc
  std::string sparse;             // sparse/
  std::string visibility;         // visibility.prtv
  std::string visibility_chunks;  // visibility.chunks
};

}  // namespace prt
