// The farm's visibility jobs (farm/visibility_jobs.h) without MPI: a job's chunk is exactly the
// kernel's encoding of its samples, results survive encoding and damage is detected, journal
// lines round trip, and chunks assemble into the same bytes in any job split and order.
#include "farm/visibility_jobs.h"

#include <gtest/gtest.h>

#include "vocabulary/errors.h"
#include "worker/embree_scene.h"

namespace prt {
namespace {

// A 6×6 ground grid under a floating square: part of the ground is shadowed.
SceneGeometry GroundUnderSquare() {
  SceneGeometry g;
  SceneMesh square;
  square.name = "square";
  square.mesh.positions = {{-0.5, 0.6, -0.5}, {0.5, 0.6, -0.5}, {0.5, 0.6, 0.5}, {-0.5, 0.6, 0.5}};
  square.mesh.normals.assign(4, Vec3{0, -1, 0});
  square.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  g.meshes.push_back(square);
  GroundPlane gp;
  gp.enabled = true;
  gp.size = 2;
  gp.resolution = 6;
  SceneMesh ground;
  ground.name = "ground";
  ground.is_ground = true;
  ground.grid_resolution = 6;
  ground.mesh = MakeGroundGrid(gp);
  g.meshes.push_back(ground);
  g.bounds_min = {-1, 0, -1};
  g.bounds_max = {1, 0.6, 1};
  return g;
}

struct Fixture {
  SceneGeometry geometry = GroundUnderSquare();
  std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
  EmbreeScene embree{geometry};
  VisibilitySampler sampler{embree, VisibilitySamplerOptions{16, 1, 1}};
};

TEST(VisibilityJobs, ChunkIsTheKernelsEncodingAndSurvivesTheMessage) {
  Fixture f;
  const VisibilityJobResult r = ComputeVisibilityJob(f.sampler, f.samples, 10, 7);
  const VisibilityBlocks ref =
      f.sampler.ComputeBlocks(std::span<const SpatialSample>(f.samples).subspan(10, 7));
  EXPECT_EQ(r.chunk, EncodeVisibilityBlocks(ref));
  EXPECT_EQ(r.first, 10u);
  EXPECT_EQ(r.count, 7u);
  EXPECT_GT(r.rays_traced, 0u);
  // Ground vertices: the lower hemisphere (half the texels) is never traced.
  EXPECT_GE(r.texels_below_horizon, 7u * 6 * 16 * 16 / 2 - 7u * 16 * 16);

  const std::vector<uint8_t> msg = EncodeVisibilityJobResult(r);
  const VisibilityJobResult back = DecodeVisibilityJobResult(msg);
  EXPECT_EQ(back.chunk, r.chunk);
  EXPECT_EQ(back.rays_traced, r.rays_traced);
  EXPECT_EQ(back.texels_below_horizon, r.texels_below_horizon);
  EXPECT_DOUBLE_EQ(back.busy_seconds, r.busy_seconds);

  std::vector<uint8_t> damaged = msg;
  damaged.back() ^= 1;
  EXPECT_THROW(DecodeVisibilityJobResult(damaged), std::runtime_error);
  damaged = msg;
  damaged.pop_back();
  EXPECT_THROW(DecodeVisibilityJobResult(damaged), std::runtime_error);
  EXPECT_THROW(DecodeVisibilityJobResult(std::span<const uint8_t>(msg.data(), 20)),
               std::runtime_error);
  EXPECT_THROW(ComputeVisibilityJob(f.sampler, f.samples, 38, 5), std::out_of_range);
}

TEST(VisibilityJobs, JournalLineRoundTrips) {
  VisibilityJobResult r;
  r.first = 5;
  r.count = 3;
  r.rays_traced = 1234;
  r.texels_below_horizon = 99;
  r.busy_seconds = 0.25;
  r.chunk.assign(17, 7);
  const JournalEntry e = VisibilityJournalEntry(r, 1, 4096, 0xabcdef);
  JournalEntry parsed;
  ASSERT_TRUE(ParseJournalLine(FormatJournalLine(e), parsed));
  VisibilityChunkRef ref;
  ASSERT_TRUE(ChunkOfJournalEntry(parsed, ref));
  EXPECT_EQ(ref.first, 5u);
  EXPECT_EQ(ref.count, 3u);
  EXPECT_EQ(ref.offset, 4096u);
  EXPECT_EQ(ref.length, 17u);
  EXPECT_EQ(ref.checksum, 0xabcdefu);
  EXPECT_EQ(ref.rays_traced, 1234u);
  EXPECT_EQ(ref.texels_below_horizon, 99u);
  parsed.phase = "dense-initial";
  EXPECT_FALSE(ChunkOfJournalEntry(parsed, ref));
}

TEST(VisibilityJobs, ChunksAssembleToTheSameBytesForAnySplitAndOrder) {
  Fixture f;
  const uint64_t total = f.samples.size();
  const std::vector<uint8_t> whole = EncodeVisibilityBlocks(f.sampler.ComputeBlocks(f.samples));
  for (const std::vector<uint64_t>& cuts :
       {std::vector<uint64_t>{0, total}, std::vector<uint64_t>{0, 1, 13, 14, 30, total}}) {
    std::vector<VisibilityJobResult> results;
    for (std::size_t i = 0; i + 1 < cuts.size(); ++i) {
      results.push_back(ComputeVisibilityJob(f.sampler, f.samples, cuts[i], cuts[i + 1] - cuts[i]));
    }
    std::vector<VisibilityChunk> chunks;
    for (auto it = results.rbegin(); it != results.rend(); ++it) {
      chunks.push_back({it->first, it->count, it->chunk});
    }
    VisibilityBlockCounts counts;
    EXPECT_EQ(AssembleVisibilityChunks(chunks, total, 16, 1, "test", &counts), whole);
    EXPECT_EQ(counts.zero + counts.one + counts.mixed, total * 6 * 1);
    EXPECT_GT(counts.mixed, 0u);  // the square shadows part of the ground
    // A missing or doubled chunk is refused.
    if (chunks.size() > 1) {
      std::vector<VisibilityChunk> missing(chunks.begin() + 1, chunks.end());
      EXPECT_THROW(AssembleVisibilityChunks(missing, total, 16, 1, "test"), InputError);
      std::vector<VisibilityChunk> doubled = chunks;
      doubled.push_back(chunks[1]);
      EXPECT_THROW(AssembleVisibilityChunks(doubled, total, 16, 1, "test"), InputError);
    }
  }
}

}  // namespace
}  // namespace prt
