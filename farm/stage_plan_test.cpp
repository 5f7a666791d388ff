// Stage inputs, keys and the re-run plan (farm/run_manifest.h, farm/stage_inputs.h,
// farm/stage_plan.h): for every kind of edit a lighting artist makes, exactly the stages that
// depend on what changed re-run.
#include "farm/stage_plan.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "farm/run_manifest.h"
#include "farm/stage_inputs.h"
#include "formats/geometry_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/scene.h"

namespace prt {
namespace {

// tests/data/tiny.toml with the tables every stage reads.
const std::string kBase = R"(# a comment
[scene]
name = "tiny"
n = 8

[[mesh]]
name = "box"
path = "box.off"
albedo = [0.5, 0.5, 0.5]

[ground]
enabled = true
size = 3.0
resolution = 8
albedo = [0.6, 0.6, 0.6]

[camera]
eye = [0.0, 1.2, 3.2]
fov = 35.0

[sampling]
rays_per_texel = 4
seed = 3
method = "brute"

[compression]
keep_fraction = 0.05
bits = 9

[environments]
paths = ["envmaps/sunrise.exr", "envmaps/city.exr"]
)";

std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

RunManifest ManifestOf(const std::string& text, const FarmOptions& options = {}) {
  const SceneDescription scene =
      ParseScene(text, "edit.toml", std::string(PRT_SOURCE_DIR) + "/tests/data", {PRT_DATA_DIR});
  const SceneGeometry geometry = BuildSceneGeometry(scene);
  const std::string bytes = SerializeSceneGeometry(geometry);
  ResolvedSampling s;
  s.method = options.method.empty() ? scene.sampling.method : options.method;
  s.cubemap_n = scene.cubemap_n;
  s.rays_per_texel =
      options.rays_per_texel > 0 ? options.rays_per_texel : scene.sampling.rays_per_texel;
  s.seed = options.seed ? *options.seed : scene.sampling.seed;
  s.rows = geometry.vertex_count();
  return MakeRunManifest(scene, text, geometry, bytes, s, options);
}

RunFolderState Complete() {
  RunFolderState f;
  f.rows_complete = f.compressed_current = f.estimate_current = true;
  return f;
}

std::string Actions(const StagePlan& plan) {
  std::string out;
  for (const StageDecision& d : plan.stages)
    out += (out.empty() ? "" : " ") + d.name + ":" + ToString(d.action);
  return out;
}

TEST(RunManifestTest, RoundTripKeysAndDifferences) {
  const RunManifest a = ManifestOf(kBase);
  const RunManifest back = RunManifest::FromJsonText(a.ToJsonText(), "m.json");
  for (const char* stage : {kStageRows, kStageCompression, kStageEstimate, kStageAssets}) {
    EXPECT_EQ(back.StageKey(stage), a.StageKey(stage)) << stage;
    EXPECT_NE(a.StageKey(stage), 0u) << stage;
    EXPECT_EQ(a.StageDifferences(stage, back), "") << stage;
  }
  // A change upstream changes every key after it; downstream leaves the keys before it alone.
  const RunManifest rays = ManifestOf(Replace(kBase, "rays_per_texel = 4", "rays_per_texel = 9"));
  const RunManifest keep =
      ManifestOf(Replace(kBase, "keep_fraction = 0.05", "keep_fraction = 0.1"));
  EXPECT_NE(rays.Key(), a.Key());
  EXPECT_NE(rays.StageKey(kStageEstimate), a.StageKey(kStageEstimate));
  EXPECT_EQ(keep.Key(), a.Key());
  EXPECT_NE(keep.StageKey(kStageCompression), a.StageKey(kStageCompression));
  EXPECT_EQ(rays.StageDifferences(kStageRows, a), "rays_per_texel 4 -> 9");
  EXPECT_EQ(keep.StageDifferences(kStageCompression, a).rfind("keep_fraction 0.05 -> 0.1", 0), 0u)
      << keep.StageDifferences(kStageCompression, a);
  EXPECT_THROW(RunManifest::FromJsonText("{}", "m.json"), InputError);
  EXPECT_THROW(RunManifest::FromJsonText("not json", "m.json"), InputError);
  // An older prt-farm's manifest is read with no stages: nothing can be re-used.
  const RunManifest v1 = RunManifest::FromJsonText(
      R"({"format_version": 1, "scene_xxh64": 5, "method": "brute"})", "m.json");
  EXPECT_EQ(Actions(PlanStages(&v1, a, Complete(), {})),
            "rows:ran compression:ran estimate:ran assets:ran");
}

// The table of docs/farm.md "Stages and re-runs": each edit of a finished run, and what re-runs.
TEST(StagePlanTest, EachEditReRunsOnlyWhatItTouches) {
  const RunManifest base = ManifestOf(kBase);
  struct Edit {
    std::string what, from, to, expected;
    FarmOptions options = {};
  };
  FarmOptions seed;
  seed.seed = 7;
  FarmOptions scheme;
  scheme.compression_scheme = "2d";
  FarmOptions method;
  method.method = "sparse";
  const std::vector<Edit> edits = {
      {"nothing", "", "", "rows:reused compression:reused estimate:reused assets:reused"},
      {"comment", "# a comment", "# another comment",
       "rows:reused compression:reused estimate:reused assets:ran"},
      {"camera", "fov = 35.0", "fov = 50.0",
       "rows:reused compression:reused estimate:reused assets:ran"},
      {"material", "albedo = [0.5, 0.5, 0.5]",
       "albedo = [0.5, 0.5, 0.5]\nbrdf = \"phong\"\nspecular = [0.2, 0.2, 0.2]\nexponent = 20",
       "rows:reused compression:reused estimate:reused assets:ran"},
      {"mesh name", "name = \"box\"", "name = \"crate\"",
       "rows:reused compression:reused estimate:reused assets:ran"},
      {"albedo", "albedo = [0.5, 0.5, 0.5]", "albedo = [0.9, 0.2, 0.2]",
       "rows:reused compression:reused estimate:ran assets:ran"},
      {"environments", "\"envmaps/city.exr\"", "\"envmaps/studio.exr\"",
       "rows:reused compression:reused estimate:ran assets:ran"},
      {"keep_fraction", "keep_fraction = 0.05", "keep_fraction = 0.1",
       "rows:reused compression:ran estimate:reused assets:ran"},
      {"bits", "bits = 9", "bits = 12", "rows:reused compression:ran estimate:reused assets:ran"},
      {"scheme", "bits = 9", "bits = 9\nscheme = \"4d\"",
       "rows:reused compression:ran estimate:reused assets:ran"},
      {"--compression-scheme", "", "", "rows:reused compression:ran estimate:reused assets:reused",
       scheme},
      {"rays per texel", "rays_per_texel = 4", "rays_per_texel = 16",
       "rows:ran compression:ran estimate:ran assets:ran"},
      {"--seed", "", "", "rows:ran compression:ran estimate:ran assets:reused", seed},
      {"--method", "", "", "rows:ran compression:ran estimate:ran assets:reused", method},
      {"mesh moved", "albedo = [0.5, 0.5, 0.5]",
       "albedo = [0.5, 0.5, 0.5]\ntranslate = [0.1, 0, 0]",
       "rows:ran compression:ran estimate:ran assets:ran"},
      {"ground resolution", "resolution = 8", "resolution = 9",
       "rows:ran compression:ran estimate:ran assets:ran"},
  };
  for (const Edit& e : edits) {
    SCOPED_TRACE(e.what);
    const std::string text = e.from.empty() ? kBase : Replace(kBase, e.from, e.to);
    const RunManifest now = ManifestOf(text, e.options);
    const StagePlan plan = PlanStages(&base, now, Complete(), {});
    EXPECT_EQ(Actions(plan), e.expected);
    for (const StageDecision& d : plan.stages) {
      // Every stage that runs says why (the changed inputs, or the stage before it).
      if (d.action == StageAction::kRun) {
        EXPECT_FALSE(d.reason.empty()) << d.name;
      }
    }
  }
  // The reasons name what changed.
  const StagePlan keep =
      PlanStages(&base, ManifestOf(Replace(kBase, "keep_fraction = 0.05", "keep_fraction = 0.1")),
                 Complete(), {});
  EXPECT_NE(keep.Get(kStageCompression).reason.find("keep_fraction 0.05 -> 0.1"), std::string::npos)
      << keep.Get(kStageCompression).reason;
  const StagePlan rays =
      PlanStages(&base, ManifestOf(Replace(kBase, "rays_per_texel = 4", "rays_per_texel = 16")),
                 Complete(), {});
  EXPECT_EQ(rays.Get(kStageRows).reason, "changed: rays_per_texel 4 -> 16");
  EXPECT_EQ(rays.Get(kStageCompression).reason, "the rows ran");
}

// What the folder holds decides too: missing outputs are made again, the raw rows are traced
// again when the compression needs them and they were discarded, an unfinished run resumes,
// and --force and --no-compress do what they say.
TEST(StagePlanTest, MissingOutputsDiscardedRowsResumeForceAndNoCompress) {
  const RunManifest base = ManifestOf(kBase);
  const RunManifest keep =
      ManifestOf(Replace(kBase, "keep_fraction = 0.05", "keep_fraction = 0.1"));
  const RunManifest env =
      ManifestOf(Replace(kBase, "\"envmaps/city.exr\"", "\"envmaps/studio.exr\""));
  RunFolderState no_prtc = Complete();
  no_prtc.compressed_current = false;
  EXPECT_EQ(Actions(PlanStages(&base, base, no_prtc, {})),
            "rows:reused compression:ran estimate:reused assets:reused");
  EXPECT_EQ(PlanStages(&base, base, no_prtc, {}).Get(kStageCompression).reason,
            "transport.prtc missing");
  RunFolderState discarded = Complete();
  discarded.rows_complete = false;
  EXPECT_EQ(Actions(PlanStages(&base, base, discarded, {})),
            "rows:reused compression:reused estimate:reused assets:reused");
  EXPECT_TRUE(PlanStages(&base, base, discarded, {}).NothingToDo());
  const StagePlan retrace = PlanStages(&base, keep, discarded, {});
  EXPECT_EQ(Actions(retrace), "rows:ran compression:ran estimate:ran assets:ran");
  EXPECT_NE(retrace.Get(kStageRows).reason.find("--discard-raw"), std::string::npos);
  const StagePlan no_rows = PlanStages(&base, env, discarded, {});
  EXPECT_EQ(Actions(no_rows), "rows:reused compression:reused estimate:skipped assets:ran");
  RunFolderState unfinished;
  unfinished.rows_unfinished = true;
  EXPECT_EQ(Actions(PlanStages(&base, base, unfinished, {})),
            "rows:resumed compression:ran estimate:ran assets:reused");
  StagePlanOptions force;
  force.force = true;
  EXPECT_EQ(Actions(PlanStages(&base, base, Complete(), force)),
            "rows:ran compression:ran estimate:ran assets:ran");
  StagePlanOptions no_compress;
  no_compress.compress = false;
  EXPECT_EQ(Actions(PlanStages(&base, keep, Complete(), no_compress)),
            "rows:reused compression:skipped estimate:reused assets:ran");
  EXPECT_EQ(Actions(PlanStages(nullptr, base, RunFolderState{}, {})),
            "rows:ran compression:ran estimate:ran assets:ran");
  EXPECT_EQ(PlanStages(nullptr, base, RunFolderState{}, {}).Get(kStageRows).reason, "new run");
}

}  // namespace
}  // namespace prt
