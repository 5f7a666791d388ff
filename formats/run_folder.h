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
// Image relighting: the camera and each pixel's mesh (formats/image_file.h).
inline constexpr const char* kImageFileName = "image.prti";
// Glossy vertex transport: the BRDF factor table (formats/glossy_factors.h).
inline constexpr const char* kGlossyFactorFileName = "glossy.prtf";
inline constexpr const char* kSceneCopyFileName = "scene.toml";                // the scene as given
inline constexpr const char* kReportFileName = "report.json";                  // what the run did
inline constexpr const char* kCompressedTransportFileName = "transport.prtc";  // compressed T
inline constexpr const char* kVisibilityFileName = "visibility.prtv";          // visibility job
inline constexpr const char* kVisibilityChunksFileName = "visibility.chunks";  // its job results
inline constexpr const char* kCheckpointsDirName = "checkpoints";
inline constexpr const char* kManifestFileName = "manifest.json";  // in checkpoints/
inline constexpr const char* kJournalFileName = "journal.txt";     // in checkpoints/
inline constexpr const char* kSparseDirName = "sparse";            // the sparse method's side files
// The rows' per-texel Monte-Carlo variance summed per mesh (formats/transport_variance.h), and
// the sampling jobs' pieces of it while they run (in checkpoints/).
inline constexpr const char* kVarianceFileName = "transport.variance";
inline constexpr const char* kVarianceLogFileName = "variance.log";  // in checkpoints/
inline constexpr const char* kAccuracyFileName = "accuracy.json";    // the error estimates
// Interreflection (docs/interreflection.md): indirect/bounce-<k>.prtt, bounce k's rows on the
// indirect grid, channels × samples rows (channel-major), written in place while the bounce
// runs (".partial" until complete).
inline constexpr const char* kIndirectDirName = "indirect";

// The paths of a run folder's files.
struct RunFolder {
  explicit RunFolder(const std::string& d) : dir(d) {
    const std::filesystem::path p(d);
    transport = (p / kTransportFileName).string();
    partial = transport + kTransportPartialSuffix;
    geometry = (p / kGeometryFileName).string();
    scene_copy = (p / kSceneCopyFileName).string();
    image = (p / kImageFileName).string();
    glossy = (p / kGlossyFactorFileName).string();
    report = (p / kReportFileName).string();
    checkpoints = (p / kCheckpointsDirName).string();
    manifest = (p / kCheckpointsDirName / kManifestFileName).string();
    journal = (p / kCheckpointsDirName / kJournalFileName).string();
    compressed = (p / kCompressedTransportFileName).string();
    sparse = (p / kSparseDirName).string();
    visibility = (p / kVisibilityFileName).string();
    visibility_chunks = (p / kVisibilityChunksFileName).string();
    variance = (p / kVarianceFileName).string();
    variance_log = (p / kCheckpointsDirName / kVarianceLogFileName).string();
    accuracy = (p / kAccuracyFileName).string();
    indirect = (p / kIndirectDirName).string();
    indirect_journal = (p / kCheckpointsDirName / "indirect-journal.txt").string();
  }
  // indirect/path-traced.prtt: Σ_k Tᵏ by per-element path tracing ([sampling] estimator =
  // "path"), channels × samples rows at the cubemap's n (on the indirect grid with method
  // "sparse" and [sparse] indirect = "combination").
  std::string PathTracedFile() const {
    return (std::filesystem::path(indirect) / "path-traced.prtt").string();
  }
  // indirect/path-traced-dense.prtt: with [sparse] indirect = "features", the dense vertices'
  // path-traced rows on the indirect grid (the others 0) that phase path-trace-sparse reads.
  std::string PathTracedDenseFile() const {
    return (std::filesystem::path(indirect) / "path-traced-dense.prtt").string();
  }
  // The sparse phase's combinations, reused by the bounces (farm/sparse_jobs.h).
  std::string SparseCombinationFile() const { return sparse + "/combination.bin"; }
  // indirect/bounce-<k>-dense.prtt: with [sparse] indirect = "features", the dense vertices'
  // rows of bounce k (the others 0) that phase bounce-<k>-sparse reads.
  std::string BounceDenseFile(int k) const {
    return (std::filesystem::path(indirect) / ("bounce-" + std::to_string(k) + "-dense.prtt"))
        .string();
  }
  // indirect/bounce-<k>.prtt
  std::string BounceFile(int k) const {
    return (std::filesystem::path(indirect) / ("bounce-" + std::to_string(k) + ".prtt")).string();
  }
  // Bounce gathering for an image run's pixels (docs/image-relighting.md, "Interreflection"):
  // the mesh vertices' support rows that are never shipped, on the indirect grid:
  // indirect/vertex-direct.prtt (T⁰ at the vertices, one channel) and
  // indirect/vertex-bounce-<k>.prtt (bounce k at the vertices, channels × vertices rows, k < K),
  // and the pixels' gathered Σ_k Tᵏ, indirect/pixel-gather.prtt (channels × pixels rows).
  std::string VertexDirectFile() const {
    return (std::filesystem::path(indirect) / "vertex-direct.prtt").string();
  }
  std::string VertexBounceFile(int k) const {
    return (std::filesystem::path(indirect) / ("vertex-bounce-" + std::to_string(k) + ".prtt"))
        .string();
  }
  std::string PixelGatherFile() const {
    return (std::filesystem::path(indirect) / "pixel-gather.prtt").string();
  }
  std::string dir;
  std::string image;              // image.prti (image-relighting runs only)
  std::string glossy;             // glossy.prtf (vertex runs with glossy meshes only)
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
  std::string variance;           // transport.variance
  std::string variance_log;       // checkpoints/variance.log
  std::string accuracy;           // accuracy.json
  std::string indirect;           // indirect/
  std::string indirect_journal;   // checkpoints/indirect-journal.txt (keyed by the stage)
};

}  // namespace prt
