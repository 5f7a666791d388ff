// prt-farm's setup phase (docs/farm.md, "Phases"): rank 0 loads and validates the scene,
// prepares the run folder (or verifies the checkpoints of --resume) and broadcasts the parameters
// and the world-space geometry; every rank builds its Embree scene and sampler from those bytes.
#include <spdlog/spdlog.h>

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "farm/compression_phase.h"
#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/mpi_support.h"
#include "farm/run_manifest.h"
#include "formats/compressed_transport.h"
#include "formats/geometry_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/scene.h"

#ifndef PRT_DEFAULT_DATA_DIR
#define PRT_DEFAULT_DATA_DIR ""
#endif

namespace prt {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDefaultSceneName = "<default scene>";
constexpr uint64_t kMaxBroadcastBytes = uint64_t{1} << 30;

void BroadcastBytes(FarmContext& ctx, std::string& bytes, uint64_t size) {
  bytes.resize(static_cast<std::size_t>(size));
  for (uint64_t at = 0; at < size; at += kMaxBroadcastBytes) {
    const auto n = static_cast<int>(std::min(kMaxBroadcastBytes, size - at));
    CheckMpi(MPI_Bcast(bytes.data() + at, n, MPI_BYTE, 0, ctx.comm), "MPI_Bcast geometry");
  }
}

class SetupPhase final : public FarmPhase {
 public:
  const char* name() const override { return "setup"; }

  void Run(FarmContext& ctx) override {
    std::string geometry_bytes;
    int status = kExitOk;
    if (ctx.rank == 0) {
      try {
        PrepareOnRank0(ctx, geometry_bytes);
      } catch (...) {
        std::string message;
        status = ExitCodeOf(std::current_exception(), message);
        spdlog::error("{}", message);
        ctx.report.error = message;
      }
    }
    CheckMpi(MPI_Bcast(&status, 1, MPI_INT, 0, ctx.comm), "MPI_Bcast status");
    if (status != kExitOk) throw CollectiveStop{status};
    CheckMpi(MPI_Bcast(&ctx.params, sizeof(SetupParams), MPI_BYTE, 0, ctx.comm), "MPI_Bcast");
    if (ctx.params.complete) return;  // a finished run: RunFarm stops after this phase
    if (ctx.params.sparse) {
      CheckMpi(MPI_Bcast(&ctx.plan, sizeof(SparsePlan), MPI_BYTE, 0, ctx.comm), "MPI_Bcast plan");
      ctx.method = "sparse";
    }
    if (ctx.params.visibility) ctx.method = kVisibilityPhaseName;
    BroadcastBytes(ctx, geometry_bytes, ctx.params.geometry_bytes);

    // Every rank, rank 0 included, samples the geometry decoded from the same bytes.
    int local = kExitOk;
    try {
      ctx.geometry = ParseSceneGeometry(geometry_bytes, kGeometryFileName);
      ctx.samples = SpatialSamplesOf(ctx.geometry);
      if (ctx.samples.size() != ctx.params.rows) {
        throw std::logic_error("sample count " + std::to_string(ctx.samples.size()) +
                               " differs from the geometry's vertex count " +
                               std::to_string(ctx.params.rows));
      }
      if (ctx.computes_here() && ctx.params.visibility) {
        ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        VisibilitySamplerOptions vo;
        vo.n = ctx.params.cubemap_n;
        vo.supersample = ctx.params.visibility_supersample;
        vo.bits = ctx.params.visibility_bits;
        ctx.visibility_sampler = std::make_unique<VisibilitySampler>(*ctx.embree, vo);
      } else if (ctx.computes_here()) {
        ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        TransportSamplerOptions so;
        so.rays_per_texel = ctx.params.rays_per_texel;
        so.seed = ctx.params.seed;
        ctx.sampler = std::make_unique<TransportSampler>(*ctx.embree, ctx.params.cubemap_n, so);
      }
    } catch (...) {
      std::string message;
      local = ExitCodeOf(std::current_exception(), message);
      spdlog::error("rank {}: {}", ctx.rank, message);
      if (ctx.rank == 0) ctx.report.error = message;
    }
    AgreeOrStop(ctx, local);
  }

 private:
  static void PrepareOnRank0(FarmContext& ctx, std::string& geometry_bytes) {
    const FarmOptions& o = ctx.options;
    std::vector<std::string> data_dirs = o.data_dirs;
    if (std::strlen(PRT_DEFAULT_DATA_DIR) > 0) data_dirs.emplace_back(PRT_DEFAULT_DATA_DIR);

    // 1. The scene (bad input: exit code 2).
    std::string scene_text;
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
    if (scene.samples != SpatialSamples::kVertices) {
      throw InputError(scene.file,
                       "samples = \"camera\" (image relighting) is not supported by prt-farm yet");
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
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    geometry_bytes = SerializeSceneGeometry(geometry);
    uint64_t rows = 0;
    for (const SceneMesh& m : geometry.meshes) rows += m.mesh.positions.size();
    if (rows == 0) throw InputError(scene.file, "the scene has no spatial samples");

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

    RunManifest manifest;
    manifest.method = ctx.method;
    manifest.cubemap_n = n;
    manifest.rays_per_texel = rays;
    if (visibility) manifest.visibility_bits = vis.bits;
    manifest.seed = seed;
    manifest.rows = rows;
    manifest.rows_per_block = o.rows_per_block;
    manifest.scene_checksum = Checksum64(scene_text.data(), scene_text.size());
    manifest.geometry_checksum = Checksum64(geometry_bytes.data(), geometry_bytes.size());

    FarmReport& rep = ctx.report;
    rep.scene_name = scene.name;
    rep.method = ctx.method;
    rep.cubemap_n = n;
    rep.rays_per_texel = rays;
    if (visibility) {
      rep.visibility.enabled = true;
      rep.visibility.n = n;
      rep.visibility.supersample = vis.supersample;
      rep.visibility.bits = vis.bits;
      rep.visibility.vertices = rows;
    }
    rep.seed = seed;
    rep.rows = rows;
    rep.rows_per_block = o.rows_per_block;

    ctx.scene = std::move(scene);  // the compression phase reads its [compression] settings

    // 2. The run folder (I/O errors: exit code 3).
    PrepareRunFolder(ctx, manifest, scene_text, geometry_bytes, geometry);
  }

  static void PrepareRunFolder(FarmContext& ctx, const RunManifest& manifest,
                               const std::string& scene_text, const std::string& geometry_bytes,
                               const SceneGeometry& geometry) {
    const FarmOptions& o = ctx.options;
    const RunFolder& f = ctx.folder;
    std::error_code ec;
    if (fs::exists(f.dir, ec) && !fs::is_directory(f.dir, ec)) {
      throw FileIoError(f.dir, "the output path exists and is not a folder");
    }
    fs::create_directories(f.checkpoints, ec);
    if (ec) throw FileIoError(f.checkpoints, "cannot create the run folder: " + ec.message());

    const std::string vis_final = f.visibility;
    const std::string vis_chunks = f.visibility_chunks;
    const bool has_run = fs::exists(f.journal) || fs::exists(f.partial) ||
                         fs::exists(f.transport) || fs::exists(vis_final);
    bool fresh = true;
    if (o.resume && fs::exists(f.manifest)) {
      const RunManifest old = RunManifest::FromJsonText(ReadWholeFile(f.manifest), f.manifest);
      if (old.Key() != manifest.Key()) {
        throw InputError(f.manifest, "the checkpoints in " + f.dir +
                                         " belong to a different run (" +
                                         manifest.DifferencesFrom(old) +
                                         "); use --force to start over, or another --out");
      }
      fresh = false;
      // A finished transport run (the compression phase wrote transport.prtc and removed the raw
      // matrix): its inputs were checked just above, so the finished asset stays untouched.
      if (!ctx.params.visibility && !o.no_compress && !fs::exists(f.partial, ec) &&
          !fs::exists(f.transport, ec) && fs::exists(f.journal, ec) &&
          fs::exists(f.compressed, ec)) {
        // No silent staleness: the finished asset must be what these settings would write now.
        // The raw matrix is gone, so other compression settings cannot be applied without
        // tracing again (docs/farm.md, "Checkpoints and resume").
        const std::string changed = CompressedHeaderDifferences(
            ReadCompressedTransportHeader(f.compressed),
            PlanCompression(ctx.scene, geometry, manifest.cubemap_n, o).header);
        if (!changed.empty()) {
          throw InputError(f.compressed,
                           "was compressed with other settings (" + changed +
                               ") and the raw transport.prtt is gone (the run did not use "
                               "--keep-raw), so it cannot be compressed again without tracing: "
                               "use --force to run it again, or the settings it was made with");
        }
        ctx.params.complete = 1;
        if (!o.quiet) {
          std::fprintf(stderr,
                       "prt-farm: --resume: %s is complete (%s written, raw matrix removed) and "
                       "its inputs are unchanged; nothing to do (use --force to start over)\n",
                       f.dir.c_str(), kCompressedTransportFileName);
        }
        return;
      }
    } else if (o.resume) {
      spdlog::info("--resume: {} holds no checkpoints yet; starting a fresh run", f.dir);
    } else if (has_run && !o.force) {
      throw UsageError(f.dir +
                       " already holds a prt-farm run; pass --resume to continue it or "
                       "--force to start over");
    }

    const TransportFileInfo info{manifest.rows, static_cast<uint32_t>(manifest.cubemap_n),
                                 manifest.rows_per_block,
                                 static_cast<uint32_t>(manifest.rays_per_texel), manifest.seed};
    if (fresh) {
      for (const std::string& p :
           {f.transport, f.partial, f.journal, f.manifest, f.report, vis_final, vis_chunks}) {
        fs::remove(p, ec);
      }
      fs::remove_all(f.sparse, ec);
    }
    // The compressed transport of an earlier run (compression_phase.h) goes only now, once the
    // scene and settings are valid: a --force with a bad scene must not lose a finished run.
    if (fresh) fs::remove(f.compressed, ec);
    // From here on the folder is this run's: a failure report may replace an older report.
    ctx.folder_ready = true;
    WriteFileDurably(f.scene_copy, scene_text);
    WriteFileDurably(f.geometry, geometry_bytes);
    WriteFileDurably(f.manifest, manifest.ToJsonText());

    std::vector<JournalEntry> reused;
    if (!fresh && ctx.params.visibility) {
      // The chunks are verified against visibility.chunks by the visibility phase.
      const JournalContents journal = ReadJournal(f.journal);
      if (journal.has_header && journal.run_key != manifest.Key()) {
        throw InputError(f.journal, "journal of a different run; use --force to start over");
      }
      ctx.report.damaged_journal_lines = journal.damaged_lines;
      for (const JournalEntry& e : journal.entries) {
        if (e.phase == kVisibilityPhaseName) ctx.journal_entries.push_back(e);
      }
      fs::remove(vis_final, ec);  // written again by the finalize phase
    } else if (!fresh) {
      if (!fs::exists(f.partial) && fs::exists(f.transport)) {
        // A finished run: its rows are re-verified and re-used, the file finalized again.
        fs::rename(f.transport, f.partial);
        SyncDirectory(f.dir);
      }
      if (fs::exists(f.partial)) {
        ctx.writer.emplace(TransportFileWriter::Reopen(f.partial, info));
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
            if (!e.phase.empty()) ctx.journal_entries.push_back(e);
            continue;
          }
          if (e.rows.end() > info.rows || e.rows.count * info.row_bytes() > kMaxJobBytes * 4) {
            ++ctx.report.checkpoints_rejected;
            continue;
          }
          rows.resize(static_cast<std::size_t>(e.rows.count * info.cols()));
          ctx.writer->ReadRows(e.rows.first, e.rows.count, rows.data());
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
      } else {
        spdlog::warn("--resume: {} is missing; every job is redone", f.partial);
      }
    }
    if (!ctx.writer && !ctx.params.visibility) {
      ctx.writer.emplace(TransportFileWriter::Create(f.partial, info));
    }
    ctx.journal = std::make_unique<CheckpointJournal>(
        f.journal, manifest.Key(),
        ctx.params.sparse || ctx.params.visibility ? ctx.journal_entries : reused);
    // Brute force: the jobs whose rows verified are the method's re-used checkpoints.
    if (!ctx.params.sparse && !ctx.params.visibility) ctx.journal_entries = std::move(reused);
    if (!fresh && ctx.params.visibility) {
      spdlog::info("--resume: {} journaled visibility job(s) are verified against {}",
                   ctx.journal_entries.size(), vis_chunks);
    } else if (!fresh && ctx.params.sparse) {
      spdlog::info("--resume: {} journaled sparse job(s) are verified phase by phase",
                   ctx.journal_entries.size());
    } else if (!fresh) {
      uint64_t rows_reused = 0;
      for (const JournalEntry& e : ctx.journal_entries) rows_reused += e.rows.count;
      spdlog::info("--resume: {} finished job(s) ({} of {} samples) re-used from checkpoints",
                   ctx.journal_entries.size(), rows_reused, manifest.rows);
    }
  }
};

}  // namespace

std::unique_ptr<FarmPhase> MakeSetupPhase() {
  return std::make_unique<SetupPhase>();
}

}  // namespace prt
