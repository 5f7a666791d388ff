// prt-farm's setup phase (docs/farm.md, "Phases"): rank 0 loads and validates the scene,
// prepares the run folder (or verifies the checkpoints of --resume) and broadcasts the parameters
// and the world-space geometry; every rank builds its Embree scene and sampler from those bytes.
// Rank 0's steps, in the order PrepareOnRank0 runs them: LoadScene, ResolveSampling,
// ResolveInterreflection, MakeRunManifest (farm/run_manifest.h), StartReport, then
// PrepareRunFolder's OpenFolder, PlanRunStages, RemoveStaleOutputs and ReopenCheckpoints.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "farm/compression_phase.h"
#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/mpi_support.h"
#include "farm/run_manifest.h"
#include "farm/stage_inputs.h"
#include "farm/stage_plan.h"
#include "formats/compressed_transport.h"
#include "formats/geometry_file.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "vocabulary/scene.h"
#include "worker/bounce_gather.h"
#include "worker/brdf_factorisation.h"
#include "worker/camera_samples.h"
#include "worker/glossy_pixels.h"
#include "worker/surface_hit.h"

#ifndef PRT_DEFAULT_DATA_DIR
#define PRT_DEFAULT_DATA_DIR ""
#endif

namespace prt {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDefaultSceneName = "<default scene>";
// Rank 0's `size` bytes (the serialized geometry) on every rank.
void BroadcastBytes(FarmContext& ctx, std::string& bytes, uint64_t size) {
  bytes.resize(static_cast<std::size_t>(size));
  ctx.collectives.ShareFromRank0(bytes.data(), bytes.size(), "share the geometry");
}

// Whether every rank sees rank 0's run folder (docs/farm.md, "Where the rows go"): rank 0 writes a
// probe file holding a fresh random token, every rank reads it back. A folder on node-local
// disks at the same path holds another token (or none) on the other nodes, so a rank that reads
// the right token sees the same file system. Collective; sets ctx.rows_in_place on every rank.
void AgreeOnSharedFolder(FarmContext& ctx) {
  ctx.rows_in_place = false;
  if (ctx.size == 1 || ctx.params.visibility) return;
  int want = ctx.options.rows_via_rank0 ? 0 : 1;
  ctx.collectives.ShareValueFromRank0(want, "share --rows-via-rank0");
  if (!want) {
    if (ctx.rank == 0)
      spdlog::info("--rows-via-rank0: every row travels to rank 0, which writes it");
    return;
  }
  const std::string probe = (fs::path(ctx.folder.dir) / ".shared-folder-probe").string();
  uint64_t token = 0;
  int local = 1;
  if (ctx.rank == 0) {
    std::random_device rd;
    token = (static_cast<uint64_t>(rd()) << 32) ^ rd() ^
            static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
    try {
      WriteFileDurably(probe, std::to_string(token));
    } catch (const std::exception& e) {
      spdlog::warn("cannot write the shared-folder probe: {}", e.what());
      local = 0;
    }
  }
  ctx.collectives.ShareValueFromRank0(token, "share the probe token");
  if (ctx.rank != 0) {
    std::ifstream in(probe);
    std::string text;
    local = (in >> text) && text == std::to_string(token) ? 1 : 0;
  }
  const int mine = local ? ctx.size : ctx.rank;
  const int all = ctx.collectives.AgreeMin(local, "agree on the shared folder");
  const int first_blind = ctx.collectives.AgreeMin(mine, "the first rank blind to the folder");
  ctx.rows_in_place = all == 1;
  if (ctx.rank == 0) {
    std::error_code ec;
    fs::remove(probe, ec);
    ctx.report.rows_in_place = ctx.rows_in_place;
    if (ctx.rows_in_place) {
      spdlog::info("every rank sees {}: ranks write and read their own rows there", ctx.folder.dir);
    } else {
      spdlog::warn(
          "rank {} does not see the run folder {} that rank 0 writes (not a shared file "
          "system?): every row travels to rank 0 over MPI",
          first_blind, ctx.folder.dir);
    }
  }
}

// The scene file's text and its description (the built-in default scene without a path), its
// assets looked up in --data-dir and the build's data folder; the report's "scene".
SceneDescription LoadScene(FarmContext& ctx, std::string& scene_text) {
  const FarmOptions& o = ctx.options;
  std::vector<std::string> data_dirs = o.data_dirs;
  if (std::strlen(PRT_DEFAULT_DATA_DIR) > 0) data_dirs.emplace_back(PRT_DEFAULT_DATA_DIR);

  SceneDescription scene;
  if (o.scene_path.empty()) {
    scene_text = DefaultSceneText();
    scene = ParseScene(scene_text, kDefaultSceneName, "", data_dirs);
    ctx.report.scene = kDefaultSceneName;
  } else {
    std::error_code ec;
    if (!fs::is_regular_file(o.scene_path, ec)) {
      throw InputError(o.scene_path, fs::exists(o.scene_path, ec)
                                         ? "the scene is not a regular file"
                                         : "scene file not found");
    }
    scene_text = ReadWholeFile(o.scene_path);
    scene = LoadSceneFile(o.scene_path, data_dirs);
    ctx.report.scene = o.scene_path;
  }
  return scene;
}

// What the run samples, the options overriding the scene: the method (brute or sparse, and its
// plan), the job (transport or visibility), vertices or camera pixels, n, rays per texel and
// the seed; the world-space geometry (returned, and its bytes in `geometry_bytes`) and the row
// count. Sets ctx.method, ctx.params and ctx.plan, and `resolved`'s sampling fields.
SceneGeometry ResolveSampling(FarmContext& ctx, const SceneDescription& scene,
                              ResolvedSampling& resolved, std::string& geometry_bytes) {
  const FarmOptions& o = ctx.options;
  ctx.method = o.method.empty() ? scene.sampling.method : o.method;
  if (ctx.method != "brute" && ctx.method != "sparse") {
    throw InputError(scene.file, "unknown method '" + ctx.method + "' (brute or sparse)");
  }
  const std::string job = o.job.empty() ? scene.sampling.job : o.job;
  if (job != "transport" && job != "visibility") {
    throw InputError(scene.file, "unknown job '" + job + "' (transport or visibility)");
  }
  const bool visibility = job == "visibility";
  if (visibility) ctx.method = kVisibilityPhaseName;
  const bool image = scene.samples == SpatialSamples::kCameraPixels;
  if (!image && scene.camera.supersample > 1)
    throw InputError(scene.file,
                     "[camera] supersample = " + std::to_string(scene.camera.supersample) +
                         " needs [scene] samples = \"camera\" (image relighting); a "
                         "vertex run's rows are at the vertices: set supersample = 1");
  if (image && visibility)
    throw InputError(scene.file,
                     "samples = \"camera\" needs job \"transport\" (visibility cubemaps are "
                     "per vertex, for glossy meshes)");
  if (visibility) {
    for (const MeshInstance& mi : scene.meshes)
      if (mi.glossy.brdf == "ggx")
        throw InputError(
            scene.file,
            "[[mesh]] '" + mi.name +
                "': brdf = \"ggx\" with job \"visibility\": "
                "triple products do not evaluate GGX; set [scene] samples = \"camera\" "
                "(glossy pixels, exact for one view, docs/image-relighting.md) or brdf = "
                "\"phong\"");
    if (scene.ground.enabled && scene.ground.glossy.brdf == "ggx")
      throw InputError(scene.file,
                       "[ground]: brdf = \"ggx\" with job \"visibility\": triple products do "
                       "not evaluate GGX; set [scene] samples = \"camera\" or brdf = \"phong\"");
  }
  const VisibilitySettings& vis = scene.visibility;
  const int n = visibility ? vis.n : scene.cubemap_n;
  const int rays = visibility             ? vis.supersample * vis.supersample
                   : o.rays_per_texel > 0 ? o.rays_per_texel
                                          : scene.sampling.rays_per_texel;
  if (visibility) {
    spdlog::info("scene {} ('{}'): visibility cubemaps at n = {}, {} ray(s) per texel, {} bit(s)",
                 ctx.report.scene, scene.name, n, rays, vis.bits);
  } else {
    spdlog::info("scene {} ('{}'): n = {}, {} rays per texel, method {}", ctx.report.scene,
                 scene.name, n, rays, ctx.method);
  }
  SceneGeometry geometry = BuildSceneGeometry(scene);
  geometry_bytes = SerializeSceneGeometry(geometry);
  uint64_t rows = 0;
  for (const SceneMesh& m : geometry.meshes) rows += m.mesh.positions.size();
  if (rows == 0) throw InputError(scene.file, "the scene has no spatial samples");
  if (image) {
    // Image relighting (docs/image-relighting.md): one row per camera pixel, raster order.
    ctx.params.image = 1;
    ctx.params.camera = scene.camera;
    rows = static_cast<uint64_t>(scene.camera.width) * scene.camera.height;
    spdlog::info("image relighting: {}×{} camera pixels are the samples", scene.camera.width,
                 scene.camera.height);
  }

  ctx.params.rows = rows;
  ctx.params.geometry_bytes = geometry_bytes.size();
  const uint64_t seed = o.seed ? *o.seed : scene.sampling.seed;
  ctx.params.seed = seed;
  ctx.params.cubemap_n = n;
  ctx.params.rays_per_texel = rays;
  if (visibility) {
    ctx.params.visibility = 1;
    ctx.params.visibility_supersample = vis.supersample;
    ctx.params.visibility_bits = vis.bits;
  } else if (ctx.method == "sparse") {
    ctx.params.sparse = 1;
    ctx.plan = PlanFromSettings(scene.sparse, geometry.diagonal(), scene.cubemap_n);
  }
  resolved.job = job;
  resolved.method = visibility ? std::string("brute") : ctx.method;
  resolved.cubemap_n = n;
  resolved.rays_per_texel = rays;
  resolved.seed = seed;
  resolved.rows = rows;
  return geometry;
}

// Interreflection (docs/interreflection.md): the bounces, their estimator (gathering or path
// tracing), the indirect grid's n, the [sparse] indirect mode and the channels (3 where an
// albedo is coloured), checked against the job and the samples. Sets ctx.params and
// `resolved`'s interreflection fields.
void ResolveInterreflection(FarmContext& ctx, const SceneDescription& scene,
                            const SceneGeometry& geometry, ResolvedSampling& resolved) {
  const FarmOptions& o = ctx.options;
  const bool visibility = resolved.job == "visibility";
  const bool image = scene.samples == SpatialSamples::kCameraPixels;
  const int n = resolved.cubemap_n;
  const int bounces = o.bounces ? *o.bounces : scene.sampling.bounces;
  if (bounces > 0 && visibility)
    throw InputError(scene.file, "bounces = " + std::to_string(bounces) +
                                     " needs job \"transport\" (visibility maps are direct)");
  const int indirect_n =
      scene.sampling.indirect_n > 0 ? scene.sampling.indirect_n : std::max(1, n / 4);
  if (bounces > 0 && indirect_n > n)
    throw InputError(scene.file, "indirect_n " + std::to_string(indirect_n) +
                                     " is larger than the cubemap's n " + std::to_string(n));
  ctx.params.path_estimator = bounces > 0 && scene.sampling.estimator == "path" ? 1 : 0;
  // Image runs gather their pixels' bounce light from mesh-vertex support rows
  // (docs/image-relighting.md, "Interreflection"): the pixels gather themselves ("full", their
  // default) or are combined ("combination"); "features" (a sparse pixel evaluating feature
  // texels) is not built.
  if (image && bounces > 0 && !ctx.params.path_estimator && ctx.params.sparse &&
      scene.sparse.indirect == "features")
    throw InputError(scene.file,
                     "samples = \"camera\" with bounces gathered does not take [sparse] indirect "
                     "= \"features\": set it to \"full\" (the default for image runs: every "
                     "surface pixel gathers, a small part of the run next to the vertices' "
                     "support rows) or \"combination\" (only the dense pixels gather and the "
                     "others combine them: cheaper, but further from the reference)");
  // Supersampled pixels gather their bounce light from their footprints
  // (docs/image-relighting.md, "Supersampling"); the per-pixel path tracer does not take them.
  if (image && bounces > 0 && scene.camera.supersample > 1 && ctx.params.path_estimator)
    throw InputError(
        scene.file,
        "[camera] supersample = " + std::to_string(scene.camera.supersample) +
            " with bounces = " + std::to_string(bounces) +
            " and [sampling] estimator = \"path\": the path tracer does not trace supersampled "
            "pixels; set estimator = \"gather\" (the default: the bounce light gathered from "
            "the footprint, about the path tracer's cost), [camera] supersample = 1 (one ray "
            "through each pixel centre: aliased edges, the same rows' cost) or [sampling] bounces "
            "= 0 (direct light only: the interreflected light is lost)");
  // Glossy pixels gather their bounce light through their lobe (GatherLobe): every glossy
  // pixel must gather itself, with the gather estimator. `glossy`: an image run's glossy meshes
  // with bounces (none otherwise), also for the row channels below.
  const GlossyPixels glossy =
      image && bounces > 0 && !visibility ? ResolveGlossyPixels(scene, geometry) : GlossyPixels{};
  for (std::size_t i = 0; i < glossy.glossy.size(); ++i) {
    if (!glossy.glossy[i]) continue;
    const std::string mesh = "mesh '" + geometry.meshes[i].name +
                             "' has glossy pixels and bounces = " + std::to_string(bounces);
    if (ctx.params.path_estimator)
      throw InputError(scene.file,
                       mesh +
                           ": the path tracer weighs a pixel's bounce light by the diffuse "
                           "BRDF only; set [sampling] estimator = \"gather\" (the default: "
                           "the glossy pixels gather through their lobe) or bounces = 0 "
                           "(direct light only: the interreflected light is lost)");
    if (ctx.params.sparse && scene.sparse.indirect != "full")
      throw InputError(scene.file,
                       mesh + ": [sparse] indirect = \"" + scene.sparse.indirect +
                           "\" would give a sparse glossy pixel its diffuse neighbours' bounce "
                           "light; set indirect = \"full\" (the default for image runs: every "
                           "surface pixel gathers, +7 % of the run) or method = \"brute\"");
  }
  // [sparse] indirect (docs/sparse-precomputation.md, "With interreflection"): 1 combination,
  // 2 features.
  ctx.params.sparse_indirect = 0;
  if (bounces > 0 && ctx.params.sparse && scene.sparse.indirect != "full")
    ctx.params.sparse_indirect = scene.sparse.indirect == "features" ? 2 : 1;
  ctx.params.sparse_feature_paths = scene.sparse.feature_paths;
  ctx.params.bounces = bounces;
  ctx.params.indirect_n = indirect_n;
  ctx.params.gather_paths = scene.sampling.gather_paths;
  ctx.params.near_field = scene.sampling.near_field;
  // One row per channel when some surface a bounce ray reaches is coloured: a mesh's albedo, or
  // an image run's glossy mesh's weight (a coloured metal has albedo 0; BounceAlbedo).
  bool coloured = HasColouredAlbedo(geometry);
  for (std::size_t i = 0; i < glossy.glossy.size(); ++i) {
    const Rgb& w = glossy.weight[i];
    if (glossy.glossy[i] && (w[0] != w[1] || w[0] != w[2])) coloured = true;
  }
  ctx.params.channels = bounces > 0 && coloured ? 3 : 1;
  if (bounces > 0) {
    if (ctx.params.path_estimator)
      spdlog::info(
          "interreflection: {} bounce(s) by per-element path tracing, {} paths per "
          "vertex, {} channel(s)",
          bounces, scene.sampling.gather_paths, ctx.params.channels);
    else
      spdlog::info(
          "interreflection: {} bounce(s) gathered on the n = {} grid, {} directions per "
          "vertex, {} channel(s)",
          bounces, indirect_n, scene.sampling.gather_paths, ctx.params.channels);
  }

  resolved.bounces = bounces;
  resolved.estimator = scene.sampling.estimator;
  resolved.indirect_n = indirect_n;
  resolved.gather_paths = scene.sampling.gather_paths;
  resolved.near_field = scene.sampling.near_field;
  resolved.channels = ctx.params.channels;
}

// The report's settings (report.json: the scene's name, method, n, rays, seed, rows; the
// visibility job's section).
void StartReport(FarmContext& ctx, const SceneDescription& scene,
                 const ResolvedSampling& resolved) {
  const FarmOptions& o = ctx.options;
  const bool visibility = resolved.job == "visibility";
  const VisibilitySettings& vis = scene.visibility;
  const int n = resolved.cubemap_n;
  const uint64_t rows = resolved.rows;
  FarmReport& rep = ctx.report;
  rep.scene_name = scene.name;
  rep.method = ctx.method;
  rep.cubemap_n = n;
  rep.rays_per_texel = resolved.rays_per_texel;
  if (visibility) {
    rep.visibility.enabled = true;
    rep.visibility.n = n;
    rep.visibility.supersample = vis.supersample;
    rep.visibility.bits = vis.bits;
    rep.visibility.vertices = rows;
  }
  rep.seed = resolved.seed;
  rep.rows = rows;
  rep.rows_per_block = o.rows_per_block;
}

// Whether `path` is a complete transport file (plain or packed): its header says so.
bool TransportComplete(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return false;
  try {
    TransportFileReader r(path);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

// What the run folder holds for the inputs of `manifest` (RunFolderState).
RunFolderState LookAtFolder(const FarmContext& ctx, const RunManifest& manifest) {
  const RunFolder& f = ctx.folder;
  std::error_code ec;
  RunFolderState state;
  if (ctx.params.visibility) {
    state.rows_complete = fs::exists(f.visibility, ec);
    state.rows_unfinished = fs::exists(f.journal, ec) || fs::exists(f.visibility_chunks, ec);
    return state;
  }
  state.rows_complete = TransportComplete(f.transport);
  state.rows_unfinished = !state.rows_complete && fs::exists(f.partial, ec);
  // transport.prtc is current when its header is the one the manifest's compression stage
  // was keyed with.
  if (!ctx.options.no_compress && fs::exists(f.compressed, ec)) {
    try {
      state.compressed_current =
          CompressedHeaderKey(ReadCompressedTransportHeader(f.compressed)) ==
          manifest.Stage(kStageCompression)->at("header_xxh64").get<std::string>();
    } catch (const InputError&) {
      state.compressed_current = false;  // damaged: written again
    }
  }
  if (const nlohmann::ordered_json* ind = manifest.Stage(kStageIndirect)) {
    const nlohmann::ordered_json* rows_stage = manifest.Stage(kStageRows);
    const bool image_rows = rows_stage && rows_stage->contains("camera");
    state.indirect_complete = true;
    for (const std::string& file : IndirectFiles(f, ind->at("bounces").get<int>(),
                                                 ind->at("estimator") == "path", image_rows))
      state.indirect_complete = state.indirect_complete && TransportComplete(file);
    state.indirect_unfinished = !state.indirect_complete && fs::exists(f.indirect, ec);
  }
  if (fs::exists(f.accuracy, ec)) {
    try {
      const nlohmann::json a = nlohmann::json::parse(ReadWholeFile(f.accuracy));
      state.estimate_current =
          a.value("key", std::string()) == manifest.StageKeyHex(kStageEstimate);
    } catch (const std::exception&) {
      state.estimate_current = false;
    }
  }
  return state;
}

// The run folder created (its checkpoints folder too); with --resume, the older run's manifest
// (none: a fresh run) and its report (ctx.previous_report: the figures of the stages it
// re-uses). A folder holding a run is refused without --resume or --force (UsageError).
std::optional<RunManifest> OpenFolder(FarmContext& ctx) {
  const FarmOptions& o = ctx.options;
  const RunFolder& f = ctx.folder;
  std::error_code ec;
  if (fs::exists(f.dir, ec) && !fs::is_directory(f.dir, ec)) {
    throw FileIoError(f.dir, "the output path exists and is not a folder");
  }
  fs::create_directories(f.checkpoints, ec);
  if (ec) throw FileIoError(f.checkpoints, "cannot create the run folder: " + ec.message());

  const bool has_run = fs::exists(f.journal) || fs::exists(f.partial) || fs::exists(f.transport) ||
                       fs::exists(f.visibility) || fs::exists(f.compressed);
  std::optional<RunManifest> older;
  if (o.resume && fs::exists(f.manifest)) {
    older = RunManifest::FromJsonText(ReadWholeFile(f.manifest), f.manifest);
  } else if (o.resume) {
    spdlog::info("--resume: {} holds no checkpoints yet; starting a fresh run", f.dir);
  } else if (has_run && !o.force) {
    throw UsageError(f.dir +
                     " already holds a prt-farm run; pass --resume to continue it (or to "
                     "re-run what a change to the scene touches) or --force to start over");
  }
  // The report of the run being continued: the figures of the stages it re-uses.
  if (older && fs::exists(f.report)) {
    try {
      ctx.previous_report = ReadWholeFile(f.report);
    } catch (const std::exception&) {
    }
  }
  return older;
}

// Each stage's decision (run, resume, re-use; farm/stage_plan.h) from the older manifest, this
// one and what the folder holds, logged; ctx.stage_plan, the estimate key and the params that
// say which stages run.
void PlanRunStages(FarmContext& ctx, const RunManifest& manifest,
                   const std::optional<RunManifest>& older) {
  const FarmOptions& o = ctx.options;
  const RunFolder& f = ctx.folder;
  std::error_code ec;
  StagePlanOptions po;
  po.force = o.force;
  po.compress = !o.no_compress && !ctx.params.visibility;
  po.visibility = ctx.params.visibility != 0;
  const RunFolderState state = LookAtFolder(ctx, manifest);
  ctx.stage_plan = PlanStages(older ? &*older : nullptr, manifest, state, po);
  const StagePlan& plan = ctx.stage_plan;
  ctx.estimate_key = manifest.StageKeyHex(kStageEstimate);
  for (const StageDecision& d : plan.stages) {
    if (o.resume || d.action != StageAction::kRun || d.name == kStageAssets) {
      spdlog::info("stage {}: {}{}{}", d.name, ToString(d.action), d.reason.empty() ? "" : " (",
                   d.reason.empty() ? "" : d.reason + ")");
    }
  }
  // A vertex run leaves no image.prti behind (prt-pack would take its rows for pixels).
  if (!ctx.params.image) fs::remove(f.image, ec);
  const StageAction rows_action = plan.Get(kStageRows).action;
  ctx.params.run_rows = rows_action == StageAction::kReuse ? 0 : 1;
  ctx.params.run_compression = plan.Runs(kStageCompression) ? 1 : 0;
  ctx.params.run_estimate = plan.Runs(kStageEstimate) ? 1 : 0;
}

// Outputs that no longer match their inputs go before anything else is written: a run that
// fails from here on leaves no stale asset (the report says what is missing). `fresh`: the
// rows are sampled from scratch. Also sets whether the indirect stage runs, and its key.
void RemoveStaleOutputs(FarmContext& ctx, const RunManifest& manifest, bool fresh) {
  const FarmOptions& o = ctx.options;
  const RunFolder& f = ctx.folder;
  const StagePlan& plan = ctx.stage_plan;
  std::error_code ec;
  if (fresh) {
    for (const std::string& p : {f.transport, f.partial, f.journal, f.manifest, f.report,
                                 f.visibility, f.visibility_chunks, f.variance, f.variance_log}) {
      fs::remove(p, ec);
    }
    fs::remove_all(f.sparse, ec);
  }
  if (fresh || plan.Runs(kStageCompression) || o.no_compress) fs::remove(f.compressed, ec);
  // The indirect stage from scratch: its bounce files and journal go (a resumed one keeps
  // them; its journal is keyed by the stage's inputs).
  ctx.params.run_indirect = plan.Runs(kStageIndirect) ? 1 : 0;
  ctx.indirect_key = manifest.StageKey(kStageIndirect);
  if (!plan.Has(kStageIndirect) ||
      (plan.Has(kStageIndirect) && plan.Get(kStageIndirect).action == StageAction::kRun)) {
    fs::remove_all(f.indirect, ec);
    fs::remove(f.indirect_journal, ec);
  }
  if (fresh || plan.Runs(kStageEstimate)) fs::remove(f.accuracy, ec);
}

// transport.prtt.partial reopened (RowsStage(ctx).writer) and its journal read: a sparse run keeps
// every journaled job for its phases to verify; a brute-force run's jobs are verified here against
// the rows' checksums, and those that verify are returned (the others counted as rejected).
std::vector<JournalEntry> ReopenPartialRows(FarmContext& ctx, const RunManifest& manifest,
                                            const TransportFileInfo& info) {
  const RunFolder& f = ctx.folder;
  std::vector<JournalEntry> reused;
  RowsStage(ctx).writer.emplace(TransportFileWriter::Reopen(f.partial, info));
  const JournalContents journal = ReadJournal(f.journal);
  if (journal.has_header && journal.run_key != manifest.Key()) {
    throw InputError(f.journal, "journal of a different run; use --force to start over");
  }
  ctx.report.damaged_journal_lines = journal.damaged_lines;
  if (journal.damaged_lines > 0) {
    spdlog::warn("{}: {} damaged or torn journal line(s) ignored (those jobs are redone)",
                 f.journal, journal.damaged_lines);
  }
  std::vector<float> rows;
  for (const JournalEntry& e : journal.entries) {
    if (ctx.params.sparse) {
      // Verified against the files when its phase is planned (SparseSamplingPhase).
      if (!e.phase.empty()) RowsStage(ctx).journal_entries.push_back(e);
      continue;
    }
    if (e.rows.end() > info.rows || e.rows.count * info.row_bytes() > kMaxJobBytes * 4) {
      ++ctx.report.checkpoints_rejected;
      continue;
    }
    rows.resize(static_cast<std::size_t>(e.rows.count * info.cols()));
    RowsStage(ctx).writer->ReadRows(e.rows.first, e.rows.count, rows.data());
    if (Checksum64(rows.data(), rows.size() * sizeof(float)) == e.rows_checksum) {
      reused.push_back(e);
    } else {
      ++ctx.report.checkpoints_rejected;
    }
  }
  if (ctx.report.checkpoints_rejected > 0) {
    spdlog::warn("{} journaled job(s) did not verify against {} and are redone",
                 ctx.report.checkpoints_rejected, f.partial);
  }
  return reused;
}

// The rows' stage resumed or started: the journal's entries that the phases will re-use
// (brute force: those whose rows verify against transport.prtt.partial now; sparse and
// visibility: verified by their phases), the reopened or created rows file, the variance
// accumulator and the journal this run appends to.
void ReopenCheckpoints(FarmContext& ctx, const RunManifest& manifest, const SceneGeometry& geometry,
                       bool fresh) {
  const FarmOptions& o = ctx.options;
  const RunFolder& f = ctx.folder;
  std::error_code ec;
  const TransportFileInfo info{manifest.Stage(kStageRows)->at("samples").get<uint64_t>(),
                               static_cast<uint32_t>(ctx.params.cubemap_n), o.rows_per_block,
                               static_cast<uint32_t>(ctx.params.rays_per_texel), ctx.params.seed};
  std::vector<JournalEntry> reused;
  if (!fresh && ctx.params.visibility) {
    // The chunks are verified against visibility.chunks by the visibility phase.
    const JournalContents journal = ReadJournal(f.journal);
    if (journal.has_header && journal.run_key != manifest.Key()) {
      throw InputError(f.journal, "journal of a different run; use --force to start over");
    }
    ctx.report.damaged_journal_lines = journal.damaged_lines;
    for (const JournalEntry& e : journal.entries) {
      if (e.phase == kVisibilityPhaseName) RowsStage(ctx).journal_entries.push_back(e);
    }
    fs::remove(f.visibility, ec);  // written again by the finalize phase
  } else if (!fresh) {
    if (fs::exists(f.partial)) {
      reused = ReopenPartialRows(ctx, manifest, info);
    } else {
      spdlog::warn("--resume: {} is missing; every job is redone", f.partial);
    }
  }
  if (!RowsStage(ctx).writer && !ctx.params.visibility) {
    RowsStage(ctx).writer.emplace(TransportFileWriter::Create(f.partial, info));
  }
  // An image run's groups are the meshes its pixels see: its sums are opened once the pixels
  // are traced (SetupPhase::Run).
  RowsStage(ctx).variance_fresh = fresh;
  if (!ctx.params.visibility && !ctx.GroupsByMap()) {
    RowsStage(ctx).variance = std::make_unique<VarianceAccumulator>(
        f, geometry.MeshVertexCounts(), ctx.params.cubemap_n, ctx.params.rays_per_texel, fresh);
  }
  ctx.journal = std::make_unique<CheckpointJournal>(
      f.journal, manifest.Key(),
      ctx.params.sparse || ctx.params.visibility ? RowsStage(ctx).journal_entries : reused);
  // Brute force: the jobs whose rows verified are the method's re-used checkpoints.
  if (!ctx.params.sparse && !ctx.params.visibility)
    RowsStage(ctx).journal_entries = std::move(reused);
  if (!fresh && ctx.params.visibility) {
    spdlog::info("--resume: {} journaled visibility job(s) are verified against {}",
                 RowsStage(ctx).journal_entries.size(), f.visibility_chunks);
  } else if (!fresh && ctx.params.sparse) {
    spdlog::info("--resume: {} journaled sparse job(s) are verified phase by phase",
                 RowsStage(ctx).journal_entries.size());
  } else if (!fresh) {
    uint64_t rows_reused = 0;
    for (const JournalEntry& e : RowsStage(ctx).journal_entries) rows_reused += e.rows.count;
    spdlog::info("--resume: {} finished job(s) ({} of {} samples) re-used from checkpoints",
                 RowsStage(ctx).journal_entries.size(), rows_reused, info.rows);
  }
}

// Rank 0 makes the run folder this run's (docs/farm.md, "Stages and re-runs"): looks at what
// it holds, plans the stages against the older run's manifest, removes the outputs that no
// longer match their inputs, writes the scene, geometry and manifest, and reopens (or creates)
// the rows' files and the checkpoint journal.
void PrepareRunFolder(FarmContext& ctx, const RunManifest& manifest, const std::string& scene_text,
                      const std::string& geometry_bytes, const SceneGeometry& geometry) {
  const FarmOptions& o = ctx.options;
  const RunFolder& f = ctx.folder;
  const std::optional<RunManifest> older = OpenFolder(ctx);
  PlanRunStages(ctx, manifest, older);
  const StagePlan& plan = ctx.stage_plan;
  const StageAction rows_action = plan.Get(kStageRows).action;
  if (plan.NothingToDo()) {
    ctx.params.complete = 1;
    ctx.folder_ready = true;
    if (plan.Get(kStageAssets).action == StageAction::kReuse) {
      if (!o.quiet) {
        std::fprintf(stderr,
                     "prt-farm: --resume: %s is complete and its inputs are unchanged; "
                     "nothing to do (use --force to start over)\n",
                     f.dir.c_str());
      }
      ctx.params.complete = 2;  // not even the report changes
      return;
    }
    // Only what prt-pack reads changed (names, albedos, materials, camera, comments).
    WriteFileDurably(f.scene_copy, scene_text);
    WriteFileDurably(f.geometry, geometry_bytes);
    WriteFileDurably(f.manifest, manifest.ToJsonText());
    return;
  }

  const bool fresh = rows_action == StageAction::kRun;
  RemoveStaleOutputs(ctx, manifest, fresh);
  // From here on the folder is this run's: a failure report may replace an older report.
  ctx.folder_ready = true;
  WriteFileDurably(f.scene_copy, scene_text);
  WriteFileDurably(f.geometry, geometry_bytes);
  WriteFileDurably(f.manifest, manifest.ToJsonText());
  if (rows_action == StageAction::kReuse) return;  // nothing to sample
  ReopenCheckpoints(ctx, manifest, geometry, fresh);
}

// Rank 0's half of the setup: the scene loaded and resolved against the options, the
// manifest (every stage's inputs and key, farm/run_manifest.h), the report's settings, then
// the run folder. Throws InputError (exit code 2) for a bad scene, FileIoError (3) for the
// folder.
// Glossy vertex transport (docs/glossy-transport.md): the factorisation of every glossy mesh,
// its error logged and reported, the rows counted once per term. Throws InputError for what is
// not built yet (bounces with glossy vertices).
void ResolveGlossyTerms(FarmContext& ctx, const SceneDescription& scene,
                        const SceneGeometry& geometry, ResolvedSampling& resolved,
                        std::string& factor_bytes) {
  const GlossyPixels glossy = ResolveGlossyMaterials(scene, geometry);
  if (!glossy.any()) return;
  for (std::size_t i = 0; i < glossy.glossy.size(); ++i)
    if (glossy.glossy[i] && ctx.params.bounces > 0)
      throw InputError(scene.file,
                       "mesh '" + geometry.meshes[i].name +
                           "' is glossy and bounces = " + std::to_string(ctx.params.bounces) +
                           ": glossy vertex transport bakes the direct term only (the bounce "
                           "gather through each term's f_i is not built yet, "
                           "docs/glossy-transport.md); set bounces = 0, brdf = \"lambert\", or "
                           "[scene] samples = \"camera\" (glossy pixels with bounces)");
  FactorisationOptions fo;
  fo.terms = scene.glossy.terms;
  const double t0 = FarmNow();
  std::vector<std::vector<double>> truncation;  // per factor, from the same SVD
  const GlossyFactorTable table = FactorGlossyMeshes(glossy, fo, &truncation);
  nlohmann::json meshes = nlohmann::json::array();
  for (std::size_t i = 0; i < glossy.glossy.size(); ++i) {
    if (!glossy.glossy[i]) continue;
    const BrdfFactors& f = table.factors[table.mesh_factor[i]];
    std::vector<double> trunc = truncation[table.mesh_factor[i]];
    trunc.resize(8, 0.0);  // m = 1…8 in the report (the SVD gives up to 16)
    spdlog::info(
        "glossy mesh '{}' ({}): {} BRDF terms, factorisation error {:.1f}% (truncation "
        "m=1/2/4/8: {:.1f}/{:.1f}/{:.1f}/{:.1f}%)",
        geometry.meshes[i].name, f.description, fo.terms, 100 * f.relative_error, 100 * trunc[0],
        100 * trunc[1], 100 * trunc[3], 100 * trunc[7]);
    meshes.push_back({{"mesh", geometry.meshes[i].name},
                      {"material", f.description},
                      {"relative_error", f.relative_error},
                      {"truncation_error_by_terms", trunc}});
  }
  factor_bytes = SerializeGlossyFactors(table, true);
  ctx.params.factor_bytes = factor_bytes.size();
  ctx.params.terms = fo.terms;
  ctx.params.rows *= static_cast<uint64_t>(fo.terms);
  resolved.rows = ctx.params.rows;
  resolved.terms = fo.terms;
  resolved.glossy_factors = Checksum64(factor_bytes.data(), factor_bytes.size());
  if (ctx.params.sparse) {  // each term's neighbours in its own copy of the scene
    double extent = geometry.diagonal();
    for (int a = 0; a < 3; ++a)
      extent =
          std::max({extent, std::abs(geometry.bounds_min[a]), std::abs(geometry.bounds_max[a])});
    ctx.plan.term_offset = 4 * extent + 1;
  }
  ctx.report.SetSection("glossy", nlohmann::json{{"terms", fo.terms},
                                                 {"view_n", fo.view_n},
                                                 {"light_n", fo.light_n},
                                                 {"svd_light_n", fo.svd_light_n},
                                                 {"seconds", FarmNow() - t0},
                                                 {"meshes", meshes}}
                                      .dump());
}

void PrepareOnRank0(FarmContext& ctx, std::string& geometry_bytes, std::string& glossy_bytes,
                    std::string& factor_bytes) {
  // 1. The scene (bad input: exit code 2).
  std::string scene_text;
  SceneDescription scene = LoadScene(ctx, scene_text);
  ResolvedSampling resolved;
  const SceneGeometry geometry = ResolveSampling(ctx, scene, resolved, geometry_bytes);
  ResolveInterreflection(ctx, scene, geometry, resolved);
  const bool visibility = resolved.job == "visibility";
  // Glossy pixels (docs/image-relighting.md): every rank weighs those pixels' rays alike.
  if (ctx.params.image) {
    const GlossyPixels glossy = ResolveGlossyPixels(scene, geometry);
    if (glossy.any()) {
      glossy_bytes = SerializeGlossyPixels(glossy);
      ctx.params.glossy_bytes = glossy_bytes.size();
      for (std::size_t i = 0; i < glossy.glossy.size(); ++i)
        if (glossy.glossy[i])
          spdlog::info("glossy pixels: mesh '{}' ({}): rows carry its BRDF with the camera's view",
                       geometry.meshes[i].name,
                       geometry.meshes[i].is_ground ? scene.ground.glossy.brdf
                                                    : scene.meshes[i].glossy.brdf);
    }
  }
  if (!ctx.params.image && !visibility)
    ResolveGlossyTerms(ctx, scene, geometry, resolved, factor_bytes);
  const RunManifest manifest =
      MakeRunManifest(scene, scene_text, geometry, geometry_bytes, resolved, ctx.options,
                      visibility ? nullptr : &ctx.results.Put(CompressionPlan{}));
  StartReport(ctx, scene, resolved);

  ctx.scene = std::move(scene);  // the compression phase reads its [compression] settings

  // 2. The run folder (I/O errors: exit code 3).
  PrepareRunFolder(ctx, manifest, scene_text, geometry_bytes, geometry);
  if (!factor_bytes.empty()) WriteFileDurably(ctx.folder.glossy, factor_bytes);
}

// Every rank: the factor table from rank 0's bytes, the samples once per term, each row's mesh as
// its group, and (rank 0) the variance sums over those groups.
void SetUpGlossyTerms(FarmContext& ctx, const std::string& factor_bytes) {
  auto table =
      std::make_shared<GlossyFactorTable>(ParseGlossyFactors(factor_bytes, kGlossyFactorFileName));
  ctx.samples = TermSamples(ctx.samples, ctx.geometry, *table);
  ctx.glossy_pixels.materials.assign(ctx.geometry.meshes.size(), Material{});
  ctx.glossy_pixels.glossy.clear();
  for (std::size_t m = 0; m < ctx.geometry.meshes.size(); ++m)
    ctx.glossy_pixels.glossy.push_back(table->glossy(m) ? 1 : 0);
  ctx.glossy_pixels.weight = table->mesh_weight;
  ctx.glossy_factors = std::move(table);
  if (ctx.params.terms > 1) {
    ctx.pixel_groups =
        std::make_shared<std::vector<uint32_t>>(TermSampleMeshes(ctx.geometry, ctx.params.terms));
    if (ctx.rank == 0)
      RowsStage(ctx).variance = std::make_unique<VarianceAccumulator>(
          ctx.folder, ctx.RowGroups(), ctx.params.cubemap_n, ctx.params.rays_per_texel,
          RowsStage(ctx).variance_fresh);
  }
}

class SetupPhase final : public FarmPhase {
 public:
  const char* name() const override { return "setup"; }
  const char* stage() const override { return kStageAssets; }

  void Run(FarmContext& ctx) override {
    std::string geometry_bytes, glossy_bytes, factor_bytes;
    int status = kExitOk;
    if (ctx.rank == 0) {
      try {
        PrepareOnRank0(ctx, geometry_bytes, glossy_bytes, factor_bytes);
      } catch (...) {
        std::string message;
        status = ExitCodeOf(std::current_exception(), message);
        spdlog::error("{}", message);
        ctx.report.error = message;
      }
    }
    ctx.collectives.ShareValueFromRank0(status, "share the setup status");
    if (status != kExitOk) throw CollectiveStop{status};
    ctx.collectives.ShareValueFromRank0(ctx.params, "share the run's parameters");
    if (ctx.params.complete) return;  // a finished run: RunFarm stops after this phase
    if (ctx.params.sparse) {
      ctx.collectives.ShareValueFromRank0(ctx.plan, "share the sparse plan");
      ctx.method = "sparse";
    }
    if (ctx.params.visibility) ctx.method = kVisibilityPhaseName;
    BroadcastBytes(ctx, geometry_bytes, ctx.params.geometry_bytes);
    if (ctx.params.glossy_bytes > 0) BroadcastBytes(ctx, glossy_bytes, ctx.params.glossy_bytes);
    if (ctx.params.factor_bytes > 0) BroadcastBytes(ctx, factor_bytes, ctx.params.factor_bytes);

    // Every rank, rank 0 included, samples the geometry decoded from the same bytes.
    int local = kExitOk;
    try {
      ctx.geometry = ParseSceneGeometry(geometry_bytes, kGeometryFileName);
      if (ctx.params.image) {
        // Every rank traces the same primary rays (a few per pixel's worth of one texel).
        ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        const SceneSurfaces surfaces(ctx.geometry);
        CameraSamples pixels = ComputeCameraSamples(*ctx.embree, surfaces, ctx.params.camera,
                                                    "the scene's camera", ctx.params.seed);
        if (ctx.params.glossy_bytes > 0) ctx.glossy_pixels = ParseGlossyPixels(glossy_bytes);
        if (pixels.supersample > 1) {
          // Supersampling (docs/image-relighting.md): λ and w from each mesh's relighting weight
          // (its albedo, a glossy mesh's w); the sub-samples of glossy meshes carry their BRDF.
          std::vector<Rgb> mesh_weight;
          for (std::size_t m = 0; m < ctx.geometry.meshes.size(); ++m)
            mesh_weight.push_back(m < ctx.glossy_pixels.glossy.size() && ctx.glossy_pixels.glossy[m]
                                      ? ctx.glossy_pixels.weight[m]
                                      : ctx.geometry.meshes[m].albedo);
          WeighFootprints(pixels, mesh_weight);
          if (ctx.params.glossy_bytes > 0)
            MarkGlossyPixels(ctx.glossy_pixels, pixels.sub_mesh, pixels.footprints->subs);
          ctx.footprints = pixels.footprints;
        }
        ctx.samples = std::move(pixels.samples);
        ctx.pixel_mesh = std::move(pixels.pixel_mesh);
        ctx.pixel_edge = std::move(pixels.pixel_edge);
        ImageSamplesInfo image_info{ctx.params.camera, ctx.pixel_mesh, {}, {}};
        if (pixels.supersample > 1) {
          image_info.supersample = pixels.supersample;
          image_info.coverage = std::move(pixels.coverage);
          image_info.pixel_weight = std::move(pixels.pixel_weight);
        }
        if (ctx.params.glossy_bytes > 0) {
          MarkGlossyPixels(ctx.glossy_pixels, ctx.pixel_mesh, ctx.samples);
          image_info.glossy_mesh = ctx.glossy_pixels.glossy;
          image_info.glossy_weight = ctx.glossy_pixels.weight;
        }
        auto groups = std::make_shared<std::vector<uint32_t>>(ctx.pixel_mesh);
        for (uint32_t& g : *groups)
          if (g == kImageBackground) g = static_cast<uint32_t>(ctx.geometry.meshes.size());
        ctx.pixel_groups = std::move(groups);
        if (ctx.rank == 0 && !ctx.params.visibility) {
          RowsStage(ctx).variance = std::make_unique<VarianceAccumulator>(
              ctx.folder, ctx.RowGroups(), ctx.params.cubemap_n, ctx.params.rays_per_texel,
              RowsStage(ctx).variance_fresh);
        }
        if (ctx.rank == 0) {
          WriteImageSamplesFile(ctx.folder.image, image_info);
          const std::size_t background = BackgroundPixels(ctx.pixel_mesh);
          spdlog::info("image relighting: {} of {} pixels see the environment (background)",
                       background, ctx.pixel_mesh.size());
          nlohmann::json section{{"width", ctx.params.camera.width},
                                 {"height", ctx.params.camera.height},
                                 {"background_pixels", background}};
          if (image_info.supersample > 1) {
            std::size_t partial = 0;
            for (float c : image_info.coverage) partial += c > 0.f && c < 1.f ? 1 : 0;
            section["supersample"] = image_info.supersample;
            section["partly_covered_pixels"] = partial;
            section["footprint_samples"] = ctx.footprints->subs.size();
            spdlog::info("image relighting: {}×{} rays per pixel, {} pixels partly covered",
                         image_info.supersample, image_info.supersample, partial);
          }
          ctx.report.SetSection("image", section.dump());
        }
      } else {
        ctx.samples = SpatialSamplesOf(ctx.geometry);
        if (ctx.params.factor_bytes > 0) SetUpGlossyTerms(ctx, factor_bytes);
      }
      if (ctx.samples.size() != ctx.params.rows) {
        throw std::logic_error("sample count " + std::to_string(ctx.samples.size()) +
                               " differs from the run's row count " +
                               std::to_string(ctx.params.rows));
      }
      if (ctx.computes_here() && ctx.params.visibility) {
        if (!ctx.embree) ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        VisibilitySamplerOptions vo;
        vo.n = ctx.params.cubemap_n;
        vo.supersample = ctx.params.visibility_supersample;
        vo.bits = ctx.params.visibility_bits;
        ctx.visibility_sampler = std::make_unique<VisibilitySampler>(*ctx.embree, vo);
      } else if (ctx.computes_here()) {
        if (!ctx.embree) ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        TransportSamplerOptions so;
        so.rays_per_texel = ctx.params.rays_per_texel;
        so.seed = ctx.params.seed;
        ctx.sampler = std::make_unique<TransportSampler>(
            *ctx.embree, ctx.params.cubemap_n, so,
            GlossySampling{ctx.glossy_pixels.materials, ctx.params.camera.eye, ctx.glossy_factors},
            ctx.footprints);
      }
    } catch (...) {
      std::string message;
      local = ExitCodeOf(std::current_exception(), message);
      spdlog::error("rank {}: {}", ctx.rank, message);
      if (ctx.rank == 0) ctx.report.error = message;
    }
    AgreeOrStop(ctx, local);
    AgreeOnSharedFolder(ctx);
    // The rows stage's state exists on every rank before any job runs: the job threads then only
    // look it up (ctx.results is not written while they run).
    RowsStage(ctx);
  }
};

}  // namespace

// Always first: it decides what the run is.
void AddSetupPhase(const FarmContext&, PhaseList& phases) {
  phases.push_back(std::make_unique<SetupPhase>());
}

}  // namespace prt
