// Round trips through the .prtpack writer and reader: meshes (same order, same triangles, within
// the documented quantisation), transport blocks bit for bit, metadata, versions, unknown
// sections, alignment and input errors (docs/prtpack-format.md).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "packager/prtpack.h"
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

// Where the TRNS section of `bytes` starts.
uint64_t TransportOffset(const std::vector<uint8_t>& bytes) {
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  for (const SectionInfo& s : r.sections())
    if (s.type_code == kTypeTransport) return s.offset;
  ADD_FAILURE() << "no TRNS";
  return 0;
}

TEST(PrtpackRoundTrip, UnknownMajorVersionIsRefusedAndMinorIsRead) {
  std::vector<uint8_t> bytes = WritePack(MakeSmallInput());
  std::vector<uint8_t> minor = bytes;
  StoreU16(minor.data() + kHdrMinor, 5);
  // From 1.1 on TRNS states its channel count (1.0 writers left 0 there).
  StoreU32(minor.data() + TransportOffset(bytes) + kTransportChannels, 1);
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

// A 3-channel transport (issue #22: row c·V + v is colour channel c of vertex v) packs as
// version 1.1 with its channel count in TRNS; its compressed columns read back unchanged.
TEST(PrtpackRoundTrip, ThreeChannelTransportPacksAsVersion1_1) {
  PackInput in = MakeSmallInput();
  in.transport = testing::MakeSmallCompressedTransportInput(3);
  EXPECT_EQ(in.transport->channels, 3u);
  EXPECT_EQ(in.transport->row_count, 36u);
  EXPECT_EQ(in.transport->encoding, 3u);  // the .prtc header's version with channels
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_major(), 1);
  EXPECT_EQ(r.version_minor(), 1);
  EXPECT_EQ(LoadU32(bytes.data() + TransportOffset(bytes) + kTransportChannels), 3u);
  const TransportIndex index = r.ReadTransportIndex();
  EXPECT_EQ(index.channels, 3u);
  EXPECT_EQ(index.row_count, 36u);
  EXPECT_EQ(nlohmann::json::parse(r.ReadMetadata())["format_version"], "1.1");
  const CompressedTransport want = testing::MakeSmallCompressedTransport(3);
  const CompressedTransport back = ReadCompressedTransport(r);
  EXPECT_EQ(back.header.channels, 3u);
  EXPECT_EQ(back.header.spatial_count(), 12u);
  EXPECT_EQ(EncodeHeader(back.header), EncodeHeader(want.header));
  ASSERT_EQ(back.columns.size(), want.columns.size());
  for (std::size_t k = 0; k < back.columns.size(); ++k) {
    EXPECT_EQ(back.columns[k].index, want.columns[k].index);
    EXPECT_EQ(back.columns[k].q, want.columns[k].q);
  }
  EXPECT_NO_THROW(r.VerifyAll());
  // A one-channel transport keeps 1.0 (and 1.0's bytes: PrtpackCorruption's fixtures).
  in.transport = testing::MakeSmallCompressedTransportInput(1);
  const std::vector<uint8_t> one = WritePack(in);
  const PackReader r1 = PackReader::OpenMemory(one.data(), one.size());
  EXPECT_EQ(r1.version_minor(), 0);
  EXPECT_EQ(r1.ReadTransportIndex().channels, 1u);
  EXPECT_EQ(nlohmann::json::parse(r1.ReadMetadata())["format_version"], "1.0");
}

// Hostile channel counts behind valid checksums: in a 1.1 pack 0, 2 or 4 channels, or a row
// count the channels do not divide, are refused with an InputError naming TRNS; a 1.0 pack's
// field is reserved (ignored: 1 channel), so 3-channel parameters in a 1.0 pack disagree with
// its TRNS section, and so does a TRNS of 1 channel over 3-channel parameters.
TEST(PrtpackRoundTrip, BadChannelCountsAreRefusedClearly) {
  PackInput in = MakeSmallInput();
  in.transport = testing::MakeSmallCompressedTransportInput(3);
  const std::vector<uint8_t> good = WritePack(in);
  const uint64_t trns = TransportOffset(good);
  for (uint32_t channels : {0u, 2u, 4u, 0xffffffffu}) {
    std::vector<uint8_t> bad = good;
    StoreU32(bad.data() + trns + kTransportChannels, channels);
    ResealChecksums(bad);
    const std::string error = ErrorOf(bad);
    EXPECT_NE(error.find("TRNS"), std::string::npos) << error;
    EXPECT_NE(error.find("channel count " + std::to_string(channels) + " is not 1 or 3"),
              std::string::npos)
        << error;
  }
  std::vector<uint8_t> rows = good;
  StoreU64(rows.data() + trns + kTransportRowCount, 35);
  ResealChecksums(rows);
  EXPECT_NE(ErrorOf(rows).find("row count 35 is not a multiple of its channel count 3"),
            std::string::npos)
      << ErrorOf(rows);
  // The index is fine, but the parameters (3 channels, 36 rows) disagree with the section.
  auto transport_error = [](const std::vector<uint8_t>& bytes) -> std::string {
    try {
      ReadCompressedTransport(PackReader::OpenMemory(bytes.data(), bytes.size()));
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  std::vector<uint8_t> one = good;
  StoreU32(one.data() + trns + kTransportChannels, 1);
  ResealChecksums(one);
  EXPECT_EQ(ErrorOf(one), "");
  EXPECT_NE(transport_error(one).find("TRNS parameters have 3 colour channel(s), the section 1"),
            std::string::npos)
      << transport_error(one);
  std::vector<uint8_t> old = good;
  StoreU16(old.data() + kHdrMinor, 0);
  ResealChecksums(old);
  EXPECT_EQ(PackReader::OpenMemory(old.data(), old.size()).ReadTransportIndex().channels, 1u);
  EXPECT_NE(transport_error(old).find("TRNS parameters have 3 colour channel(s)"),
            std::string::npos)
      << transport_error(old);
  // A 1.0 pack with anything in the reserved field reads as one channel.
  PackInput plain = MakeSmallInput();
  std::vector<uint8_t> reserved = WritePack(plain);
  StoreU32(reserved.data() + TransportOffset(reserved) + kTransportChannels, 2);
  ResealChecksums(reserved);
  EXPECT_EQ(ErrorOf(reserved), "");
  EXPECT_EQ(PackReader::OpenMemory(reserved.data(), reserved.size()).ReadTransportIndex().channels,
            1u);
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
  in = MakeSmallInput();
  in.transport->channels = 2;
  EXPECT_THROW(WritePack(in), InputError);
  in.transport->channels = 3;
  in.transport->row_count = 13;
  EXPECT_THROW(WritePack(in), InputError);
  WriterOptions o;
  o.alignment = 100;
  EXPECT_THROW(WritePack(MakeSmallInput(), o), InputError);
}

}  // namespace
}  // namespace prt::pack

namespace prt::pack {
namespace {

using testing::MakeImageInput;

TEST(PrtpackRoundTrip, ImagePacksCarryTheirPixelsAsACriticalSection) {
  const PackInput in = MakeImageInput();
  ASSERT_EQ(in.transport->row_count, 12u);
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_minor(), 2);
  EXPECT_EQ(nlohmann::json::parse(r.ReadMetadata())["format_version"], "1.2");
  ASSERT_TRUE(r.has_image());
  const ImageSamplesInfo back = r.ReadImage();
  EXPECT_EQ(back.pixel_mesh, in.image->pixel_mesh);
  EXPECT_EQ(back.camera.eye, in.image->camera.eye);
  EXPECT_EQ(back.camera.fov_deg, 35.0);
  EXPECT_EQ(r.ReadTransportIndex().channels, 1u);  // written explicitly from 1.1 on
  bool critical = false;
  for (const SectionInfo& s : r.sections())
    if (s.type == "IMGE") critical = (s.flags & kFlagCritical) != 0;
  EXPECT_TRUE(critical);
  EXPECT_NO_THROW(r.VerifyAll());
  EXPECT_FALSE(
      PackReader::OpenMemory(WritePack(MakeSmallInput()).data(), WritePack(MakeSmallInput()).size())
          .has_image());

  // The C API sees the same.
  prtpack* c = prtpack_open_memory(bytes.data(), bytes.size());
  ASSERT_NE(c, nullptr) << prtpack_last_error();
  EXPECT_EQ(prtpack_has_image(c), 1);
  prtpack_image_info info{};
  ASSERT_EQ(prtpack_get_image(c, &info), PRTPACK_OK) << prtpack_last_error();
  EXPECT_EQ(info.width, 4u);
  EXPECT_EQ(info.height, 3u);
  EXPECT_EQ(info.eye[2], 4.0);
  EXPECT_EQ(info.pixel_mesh[3], PRTPACK_BACKGROUND);
  EXPECT_EQ(info.pixel_mesh[2], 1u);
  prtpack_close(c);
}

TEST(PrtpackRoundTrip, ImagePacksThatDisagreeWithTheirTransportAreRefused) {
  // The writer: 12 pixels for 12 rows is right; 6 is not, nor a pixel naming a third mesh.
  PackInput in = MakeImageInput();
  in.image->camera.width = 2;
  in.image->pixel_mesh.resize(6);
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeImageInput();
  in.image->pixel_mesh[0] = 2;
  EXPECT_THROW(WritePack(in), InputError);
  // The reader, behind valid checksums: an image of 6 pixels over 12 rows.
  in = MakeImageInput();
  in.transport.reset();
  in.image->camera.width = 2;
  in.image->pixel_mesh.resize(6);
  PackInput with = MakeSmallInput();
  std::vector<uint8_t> image_only = WritePack(in);
  const PackReader r = PackReader::OpenMemory(image_only.data(), image_only.size());
  EXPECT_NO_THROW(r.ReadImage());  // no transport to disagree with
  in.transport = with.transport;
  in.transport->row_count = 6;  // the writer's check passes; then the TRNS is made 12 rows
  std::vector<uint8_t> b = WritePack(in);
  const std::size_t at = TransportOffset(b) + kTransportRowCount;
  StoreU64(b.data() + at, 12);
  ResealChecksums(b);
  const std::string e = ErrorOf(b);
  EXPECT_NE(e.find("IMGE"), std::string::npos) << e;
  EXPECT_NE(e.find("6 pixels"), std::string::npos) << e;
}

}  // namespace
}  // namespace prt::pack
