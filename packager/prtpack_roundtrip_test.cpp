// Round trips through the .prtpack writer and reader: meshes (same order, same triangles, within
// the documented quantisation), transport blocks bit for bit, metadata, versions, unknown
// sections, alignment and input errors (docs/prtpack-format.md).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "packager/prtpack_format.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_test_util.h"
#include "packager/prtpack_transport.h"
#include "packager/prtpack_writer.h"
#include "vocabulary/errors.h"

namespace prt::pack {
namespace {

using testing::MakeSmallInput;
using testing::ReadEverything;

std::string ErrorOf(const std::vector<uint8_t>& bytes, const ReaderOptions& o = {}) {
  try {
    testing::ReadEverything(PackReader::OpenMemory(bytes.data(), bytes.size(), "<memory>", o));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(PrtpackRoundTrip, SmallPackReadsBackWhatWasWritten) {
  const PackInput in = MakeSmallInput();
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_major(), 1);
  EXPECT_EQ(r.version_minor(), 0);
  EXPECT_EQ(r.file_size(), bytes.size());
  ASSERT_EQ(r.mesh_count(), 2u);
  // META, MESH, MATL, MESH, MATL, TRNS.
  ASSERT_EQ(r.sections().size(), 6u);
  for (const SectionInfo& s : r.sections()) EXPECT_EQ(s.offset % 64, 0u) << s.type;
  const testing::FullRead all = ReadEverything(r);

  for (std::size_t m = 0; m < 2; ++m) {
    const UnpackedMesh& u = all.meshes[m];
    const TriangleMesh& src = in.meshes[m].mesh;
    EXPECT_EQ(u.name, in.meshes[m].name);
    EXPECT_EQ(u.albedo, in.meshes[m].albedo);
    EXPECT_EQ(u.is_ground, in.meshes[m].is_ground);
    EXPECT_EQ(u.grid_resolution, in.meshes[m].grid_resolution);
    ASSERT_EQ(u.vertex_count(), src.positions.size());
    ASSERT_EQ(u.triangle_count(), src.triangles.size());
    for (std::size_t t = 0; t < src.triangles.size(); ++t) {
      for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(u.triangles[3 * t + c], src.triangles[t][c]);
    }
    // Octahedron vertices sit on the bbox faces: 16-bit quantisation is exact up to float.
    const double extent = 2.0 * (m == 0 ? 1.0 : 3.0);
    for (std::size_t i = 0; i < src.positions.size(); ++i) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(u.positions[3 * i + std::size_t(c)], src.positions[i][c],
                    0.5 * extent / 65535 + 1e-6);
        EXPECT_NEAR(u.normals[3 * i + std::size_t(c)], src.normals[i][c], 2e-3);
      }
    }
    const TriangleMesh back = u.ToTriangleMesh();
    EXPECT_EQ(back.triangles, src.triangles);
  }

  const nlohmann::json meta = nlohmann::json::parse(all.metadata);
  EXPECT_EQ(meta["scene"]["name"], "tiny");
  EXPECT_EQ(meta["parameters"]["bits"], 9);
  EXPECT_EQ(meta["report"]["rays"], 42);
  EXPECT_EQ(meta["format"], "prtpack");
  ASSERT_EQ(meta["meshes"].size(), 2u);
  EXPECT_EQ(meta["meshes"][0]["vertices"], 6);
  EXPECT_EQ(meta["meshes"][1]["triangles"], 8);
  EXPECT_EQ(meta["meshes"][0]["position_bits"], 16);

  const TransportInput& t = *in.transport;
  EXPECT_EQ(all.index.encoding, 7u);
  EXPECT_EQ(all.index.row_count, 12u);
  EXPECT_EQ(all.index.column_count, 9u);
  EXPECT_EQ(all.index.params, t.params);
  ASSERT_EQ(all.blocks.size(), 3u);
  uint64_t first = 0;
  for (std::size_t b = 0; b < 3; ++b) {
    EXPECT_EQ(all.blocks[b], t.blocks[b].bytes) << "block " << b;  // bit for bit
    EXPECT_EQ(all.index.blocks[b].first_column, first);
    EXPECT_EQ(all.index.blocks[b].column_count, t.blocks[b].column_count);
    EXPECT_EQ(all.index.blocks[b].offset % 64, 0u);
    first += t.blocks[b].column_count;
  }
  EXPECT_EQ(all.index.blocks[0].codec, 1u);  // compressible → zstd
  EXPECT_LT(all.index.blocks[0].stored_size, all.index.blocks[0].raw_size);
  EXPECT_EQ(all.index.blocks[1].codec, 0u);  // random → stored as is
  // Into caller memory: size must match.
  std::vector<uint8_t> dst(t.blocks[0].bytes.size());
  r.ReadTransportBlockInto(all.index, 0, dst.data(), dst.size());
  EXPECT_EQ(dst, t.blocks[0].bytes);
  EXPECT_THROW(r.ReadTransportBlockInto(all.index, 0, dst.data(), dst.size() - 1), InputError);
  EXPECT_THROW(r.ReadTransportBlock(all.index, 3), InputError);
  EXPECT_THROW(r.ReadMesh(2), InputError);
}

// VISB (docs/prtpack-format.md): one zstd section per mesh, decoded maps equal to the input's
// exactly; the writer refuses visibility that does not fit the meshes; the reader refuses a pack
// whose VISB sections do not cover every mesh.
TEST(PrtpackRoundTrip, VisibilitySectionsAreLossless) {
  const PackInput in = testing::MakeSmallGlossyInput();
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  ASSERT_TRUE(r.has_visibility());
  std::size_t visb = 0;
  for (const SectionInfo& s : r.sections()) {
    if (s.type != "VISB") continue;
    ++visb;
    EXPECT_TRUE(s.known);
    EXPECT_EQ(s.flags, 0u);  // not critical: older readers skip it
    EXPECT_EQ(s.codec, 1u);  // zstd
    EXPECT_EQ(s.raw_size, in.visibility->per_mesh[s.id].size());
    EXPECT_LT(s.stored_size, s.raw_size);
  }
  EXPECT_EQ(visb, 2u);
  for (std::size_t m = 0; m < 2; ++m) {
    const VisibilityBlocks got = r.ReadVisibility(m);
    EXPECT_EQ(EncodeVisibilityBlocks(got), in.visibility->per_mesh[m]);  // bit for bit
  }
  const testing::FullRead all = testing::ReadEverything(r);
  ASSERT_EQ(all.visibility.size(), 12u);
  const VisibilityBlocks mesh1 = DecodeVisibilityBlocks(in.visibility->per_mesh[1]);
  EXPECT_EQ(all.visibility[6 + 2], DecodeVisibilityMap(mesh1, 2));
  EXPECT_THROW(r.ReadVisibility(2), InputError);
  const std::vector<uint8_t> plain = WritePack(MakeSmallInput());
  EXPECT_FALSE(PackReader::OpenMemory(plain.data(), plain.size()).has_visibility());
  EXPECT_THROW(PackReader::OpenMemory(plain.data(), plain.size()).ReadAllVisibility(), InputError);

  PackInput bad = in;
  bad.visibility->per_mesh.pop_back();
  EXPECT_THROW(WritePack(bad), InputError);  // not one per mesh
  bad = in;
  bad.visibility->per_mesh[1] = testing::MakeSmallVisibility(5, 1);
  EXPECT_THROW(WritePack(bad), InputError);  // 5 maps for 6 vertices
  bad = in;
  bad.visibility->per_mesh[0].pop_back();
  EXPECT_THROW(WritePack(bad), InputError);  // does not decode

  // Mesh 1's VISB relabelled as a second id 0: refused at open.
  std::vector<uint8_t> twice = bytes;
  for (std::size_t i = 0; i < r.sections().size(); ++i) {
    uint8_t* entry = twice.data() + kHeaderSize + i * kEntrySize;
    if (r.sections()[i].type == "VISB" && r.sections()[i].id == 1) StoreU32(entry + kSecId, 0);
  }
  ResealChecksums(twice);
  EXPECT_THROW(PackReader::OpenMemory(twice.data(), twice.size()), InputError);
}

TEST(PrtpackRoundTrip, WritingIsDeterministic) {
  EXPECT_EQ(WritePack(MakeSmallInput()), WritePack(MakeSmallInput()));
}

TEST(PrtpackRoundTrip, CompressedTransportBlocksDecodeOnTheirOwn) {
  CompressedTransport ct;
  ct.header.cubemap_n = 2;  // 24 columns
  ct.header.sample_count = 12;
  ct.header.terms_per_column = 3;
  SpatialSegment seg;
  seg.count = 12;
  ct.header.domain.segments.push_back(seg);
  for (uint32_t col : {0u, 4u, 5u, 17u, 23u}) {
    CompressedColumn c;
    c.column = col;
    c.depth = 0;
    c.scale = 0.5f + float(col);
    c.index = {1, 2 + col % 10};
    c.q = {5, -static_cast<int32_t>(col % 200) - 1};
    ct.columns.push_back(c);
  }
  const TransportInput ti = MakeTransportInput(ct, 5);
  ASSERT_EQ(ti.blocks.size(), 5u);  // 24 columns in blocks of 5: 5 5 5 5 4
  PackInput in = MakeSmallInput();
  in.transport = ti;
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  const CompressedTransport back = ReadCompressedTransport(r);
  EXPECT_EQ(back.header.sample_count, 12u);
  EXPECT_EQ(back.header.cubemap_n, 2u);
  ASSERT_EQ(back.columns.size(), ct.columns.size());
  for (std::size_t k = 0; k < ct.columns.size(); ++k) {
    EXPECT_EQ(back.columns[k].column, ct.columns[k].column);
    EXPECT_EQ(back.columns[k].scale, ct.columns[k].scale);
    EXPECT_EQ(back.columns[k].index, ct.columns[k].index);
    EXPECT_EQ(back.columns[k].q, ct.columns[k].q);
  }
  // One block alone: block 3 holds columns 15..19, of which only 17 is stored.
  const TransportIndex index = r.ReadTransportIndex();
  const CompressedColumnBlock b3 = ReadCompressedColumnBlock(r, index, back.header, 3);
  EXPECT_EQ(b3.first_column, 15u);
  EXPECT_EQ(b3.column_span, 5u);
  ASSERT_EQ(b3.columns.size(), 1u);
  EXPECT_EQ(b3.columns[0].column, 17u);
}

TEST(PrtpackRoundTrip, PageAlignmentAndFileOpen) {
  WriterOptions o;
  o.alignment = 4096;
  const auto path = std::filesystem::temp_directory_path() / "prtpack_roundtrip_test.prtpack";
  WritePackFile(path.string(), MakeSmallInput(), o);
  const PackReader r = PackReader::OpenFile(path.string());
  for (const SectionInfo& s : r.sections()) EXPECT_EQ(s.offset % 4096, 0u) << s.type;
  const testing::FullRead a = ReadEverything(r);
  const std::vector<uint8_t> mem = WritePack(MakeSmallInput());
  EXPECT_TRUE(testing::SameRead(a, ReadEverything(PackReader::OpenMemory(mem.data(), mem.size()))));
  std::filesystem::remove(path);
  try {
    PackReader::OpenFile(path.string());
    FAIL() << "opened a missing file";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cannot open"), std::string::npos) << e.what();
  }
}

TEST(PrtpackRoundTrip, UnknownMajorVersionIsRefusedAndMinorIsRead) {
  std::vector<uint8_t> bytes = WritePack(MakeSmallInput());
  std::vector<uint8_t> minor = bytes;
  StoreU16(minor.data() + kHdrMinor, 5);
  ResealChecksums(minor);
  EXPECT_EQ(ErrorOf(minor), "");
  StoreU16(bytes.data() + kHdrMajor, 2);
  ResealChecksums(bytes);
  EXPECT_EQ(ErrorOf(bytes),
            "<memory>: unsupported .prtpack major version 2 (this reader reads 1.x)");
}

TEST(PrtpackRoundTrip, UnknownSectionsAreSkippedUnlessCritical) {
  PackInput in = MakeSmallInput();
  in.extra_sections.push_back({"XTRA", 0, 0, {9, 8, 7}});
  std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  ASSERT_EQ(r.sections().size(), 7u);
  EXPECT_EQ(r.sections()[5].type, "XTRA");
  EXPECT_FALSE(r.sections()[5].known);
  EXPECT_EQ(ErrorOf(bytes), "");
  in.extra_sections[0].flags = kFlagCritical;
  EXPECT_EQ(ErrorOf(WritePack(in)), "<memory>: unknown critical section 'XTRA'");
  in.extra_sections[0].type = "MESH";
  EXPECT_THROW(WritePack(in), InputError);
  in.extra_sections[0].type = "VISB";  // known now: only through PackInput::visibility
  EXPECT_THROW(WritePack(in), InputError);
}

TEST(PrtpackRoundTrip, DecodedSizesAreBoundedBeforeAllocation) {
  const std::vector<uint8_t> bytes = WritePack(MakeSmallInput());
  ReaderOptions small;
  small.max_section_bytes = 100;  // META and TRNS declare more
  const std::string e = ErrorOf(bytes, small);
  EXPECT_NE(e.find("above the limit 100"), std::string::npos) << e;
  // A META whose zstd frame claims a size other than raw_size is refused before decoding.
  std::vector<uint8_t> lie = bytes;
  const uint8_t* entry = lie.data() + kHeaderSize;  // META is section 0
  StoreU64(lie.data() + kHeaderSize + kSecRaw, LoadU64(entry + kSecRaw) + 1000);
  ResealChecksums(lie);
  const std::string e2 = ErrorOf(lie);
  EXPECT_NE(e2.find("zstd frame holds"), std::string::npos) << e2;
  // A MESH whose raw size disagrees with its Draco header.
  std::vector<uint8_t> mesh = bytes;
  StoreU64(mesh.data() + kHeaderSize + kEntrySize + kSecRaw, 24 * 1000000ull);
  ResealChecksums(mesh);
  const std::string e3 = ErrorOf(mesh);
  EXPECT_NE(e3.find("disagrees with its raw size"), std::string::npos) << e3;
  // A MESH whose Draco header claims a million vertices, consistently with raw_size, from 156
  // stored bytes: refused before Draco sees it.
  std::vector<uint8_t> bomb = bytes;
  uint8_t* mesh_entry = bomb.data() + kHeaderSize + kEntrySize;
  uint8_t* draco = bomb.data() + LoadU64(mesh_entry + kSecOffset);
  const uint8_t counts[4] = {0x00, 0xC0, 0x84, 0x3D};  // varint 0 faces, 1 000 000 points
  std::copy(counts, counts + 4, draco + 11);
  StoreU64(mesh_entry + kSecRaw, 24 * 1000000ull);
  ResealChecksums(bomb);
  const std::string e4 = ErrorOf(bomb);
  EXPECT_NE(e4.find("more than Draco can compress"), std::string::npos) << e4;
}

TEST(PrtpackRoundTrip, WriterRejectsBadInputs) {
  PackInput in = MakeSmallInput();
  in.metadata_json = "[1, 2]";
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.meshes[0].mesh.triangles[0][1] = 6;
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.meshes[0].mesh.normals.pop_back();
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.meshes[1].mesh.positions[2].y = std::nan("");
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.meshes.clear();
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.transport->blocks[1].column_count = 0;
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallInput();
  in.meshes[0].albedo[1] = 1.5f;
  EXPECT_THROW(WritePack(in), InputError);
  WriterOptions o;
  o.alignment = 100;
  EXPECT_THROW(WritePack(MakeSmallInput(), o), InputError);
}

}  // namespace
}  // namespace prt::pack
