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
    const std::size_t entry = kHeaderSize + i * kEntrySize;
    if (r.sections()[i].type == "VISB" && r.sections()[i].id == 1)
      StoreAt<uint32_t>(twice, entry + kSecId, 0);
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
  StoreAt<uint16_t>(minor, kHdrMinor, 5);
  // From 1.1 on TRNS states its channel count (1.0 writers left 0 there).
  StoreAt<uint32_t>(minor, TransportOffset(bytes) + kTransportChannels, 1);
  ResealChecksums(minor);
  EXPECT_EQ(ErrorOf(minor), "");
  StoreAt<uint16_t>(bytes, kHdrMajor, 2);
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
  const std::size_t entry = kHeaderSize;  // META is section 0
  StoreAt<uint64_t>(lie, entry + kSecRaw, LoadAt<uint64_t>(lie, entry + kSecRaw) + 1000);
  ResealChecksums(lie);
  const std::string e2 = ErrorOf(lie);
  EXPECT_NE(e2.find("zstd frame holds"), std::string::npos) << e2;
  // A MESH whose raw size disagrees with its Draco header.
  std::vector<uint8_t> mesh = bytes;
  StoreAt<uint64_t>(mesh, kHeaderSize + kEntrySize + kSecRaw, 24 * 1000000ull);
  ResealChecksums(mesh);
  const std::string e3 = ErrorOf(mesh);
  EXPECT_NE(e3.find("disagrees with its raw size"), std::string::npos) << e3;
  // A MESH whose Draco header claims a million vertices, consistently with raw_size, from 156
  // stored bytes: refused before Draco sees it.
  std::vector<uint8_t> bomb = bytes;
  const std::size_t mesh_entry = kHeaderSize + kEntrySize;
  uint8_t* draco = bomb.data() + LoadAt<uint64_t>(bomb, mesh_entry + kSecOffset);
  const uint8_t counts[4] = {0x00, 0xC0, 0x84, 0x3D};  // varint 0 faces, 1 000 000 points
  std::copy(counts, counts + 4, draco + 11);
  StoreAt<uint64_t>(bomb, mesh_entry + kSecRaw, 24 * 1000000ull);
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
  EXPECT_EQ(LoadAt<uint32_t>(bytes, TransportOffset(bytes) + kTransportChannels), 3u);
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
    StoreAt<uint32_t>(bad, trns + kTransportChannels, channels);
    ResealChecksums(bad);
    const std::string error = ErrorOf(bad);
    EXPECT_NE(error.find("TRNS"), std::string::npos) << error;
    EXPECT_NE(error.find("channel count " + std::to_string(channels) + " is not 1 or 3"),
              std::string::npos)
        << error;
  }
  std::vector<uint8_t> rows = good;
  StoreAt<uint64_t>(rows, trns + kTransportRowCount, 35);
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
  StoreAt<uint32_t>(one, trns + kTransportChannels, 1);
  ResealChecksums(one);
  EXPECT_EQ(ErrorOf(one), "");
  EXPECT_NE(transport_error(one).find("TRNS parameters have 3 colour channel(s), the section 1"),
            std::string::npos)
      << transport_error(one);
  std::vector<uint8_t> old = good;
  StoreAt<uint16_t>(old, kHdrMinor, 0);
  ResealChecksums(old);
  EXPECT_EQ(PackReader::OpenMemory(old.data(), old.size()).ReadTransportIndex().channels, 1u);
  EXPECT_NE(transport_error(old).find("TRNS parameters have 3 colour channel(s)"),
            std::string::npos)
      << transport_error(old);
  // A 1.0 pack with anything in the reserved field reads as one channel.
  PackInput plain = MakeSmallInput();
  std::vector<uint8_t> reserved = WritePack(plain);
  StoreAt<uint32_t>(reserved, TransportOffset(reserved) + kTransportChannels, 2);
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
using testing::MakeSupersampledImageInput;

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

// Glossy pixels (docs/image-relighting.md, "Glossy pixels"): the IMGE section holds PRTIMG02
// with each mesh's glossy flag and weight, the pack is 1.4, and the C API gives each mesh's
// weight (a glossy mesh's stored one, a diffuse mesh's albedo).
TEST(PrtpackRoundTrip, GlossyPixelPacksAre14AndGiveEachMeshsWeight) {
  PackInput in = MakeImageInput();
  in.image->glossy_mesh = {0, 1};
  in.image->glossy_weight = {Rgb{0.f, 0.f, 0.f}, Rgb{0.9f, 0.6f, 0.3f}};
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_minor(), 4);
  EXPECT_EQ(nlohmann::json::parse(r.ReadMetadata())["format_version"], "1.4");
  const ImageSamplesInfo back = r.ReadImage();
  EXPECT_EQ(back.glossy_mesh, in.image->glossy_mesh);
  EXPECT_EQ(back.glossy_weight, in.image->glossy_weight);
  EXPECT_NO_THROW(r.VerifyAll());
  prtpack* c = prtpack_open_memory(bytes.data(), bytes.size());
  ASSERT_NE(c, nullptr) << prtpack_last_error();
  int glossy = -1;
  float rgb[3] = {-1, -1, -1};
  ASSERT_EQ(prtpack_get_image_weight(c, 1, &glossy, rgb), PRTPACK_OK) << prtpack_last_error();
  EXPECT_EQ(glossy, 1);
  EXPECT_EQ(rgb[0], 0.9f);
  EXPECT_EQ(rgb[2], 0.3f);
  ASSERT_EQ(prtpack_get_image_weight(c, 0, &glossy, rgb), PRTPACK_OK) << prtpack_last_error();
  EXPECT_EQ(glossy, 0);
  EXPECT_EQ(rgb[0], in.meshes[0].albedo[0]);
  EXPECT_NE(prtpack_get_image_weight(c, 2, &glossy, rgb), PRTPACK_OK);
  prtpack_close(c);
  // No glossy mesh: the 1.2 pack of before, byte for byte.
  PackInput plain = MakeImageInput();
  plain.image->glossy_mesh = {0, 0};
  plain.image->glossy_weight = {Rgb{0.f, 0.f, 0.f}, Rgb{0.f, 0.f, 0.f}};
  EXPECT_TRUE(WritePack(plain) == WritePack(MakeImageInput()));
}

// Supersampled pixels (docs/image-relighting.md, "Supersampling"): the IMGE section holds
// PRTIMG03 with k, coverage and per-pixel weights, the pack is 1.5, and the C API gives each
// pixel's weight and coverage (an unsupersampled pack: its mesh's albedo and 1, background 0).
TEST(PrtpackRoundTrip, SupersampledPacksAre15AndGiveEachPixelsWeightAndCoverage) {
  const PackInput in = MakeSupersampledImageInput();
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_minor(), 5);
  EXPECT_EQ(nlohmann::json::parse(r.ReadMetadata())["format_version"], "1.5");
  const ImageSamplesInfo back = r.ReadImage();
  EXPECT_EQ(back.supersample, 4);
  EXPECT_EQ(back.coverage, in.image->coverage);
  EXPECT_NO_THROW(r.VerifyAll());
  prtpack* c = prtpack_open_memory(bytes.data(), bytes.size());
  ASSERT_NE(c, nullptr) << prtpack_last_error();
  int k = 0;
  ASSERT_EQ(prtpack_get_image_supersample(c, &k), PRTPACK_OK);
  EXPECT_EQ(k, 4);
  float rgb[3] = {-1, -1, -1}, cov = -1;
  ASSERT_EQ(prtpack_get_image_pixel(c, 1, rgb, &cov), PRTPACK_OK) << prtpack_last_error();
  EXPECT_EQ(cov, 0.5f);
  EXPECT_EQ(rgb[0], in.image->pixel_weight[1][0]);
  ASSERT_EQ(prtpack_get_image_pixel(c, 3, rgb, &cov), PRTPACK_OK);
  EXPECT_EQ(cov, 0.f);
  EXPECT_EQ(rgb[1], 0.f);
  EXPECT_NE(prtpack_get_image_pixel(c, 12, rgb, &cov), PRTPACK_OK);
  prtpack_close(c);
  // An unsupersampled pack through the same call.
  const std::vector<uint8_t> plain = WritePack(MakeImageInput());
  prtpack* p = prtpack_open_memory(plain.data(), plain.size());
  ASSERT_NE(p, nullptr) << prtpack_last_error();
  ASSERT_EQ(prtpack_get_image_supersample(p, &k), PRTPACK_OK);
  EXPECT_EQ(k, 1);
  ASSERT_EQ(prtpack_get_image_pixel(p, 2, rgb, &cov), PRTPACK_OK);
  EXPECT_EQ(cov, 1.f);
  EXPECT_EQ(rgb[0], in.meshes[1].albedo[0]);
  prtpack_close(p);
  // A corrupted coverage behind valid checksums is refused (the section's bytes re-sealed: a
  // background pixel with coverage).
  PackInput bad = MakeSupersampledImageInput();
  bad.image->coverage[3] = 0.25f;
  EXPECT_THROW(WritePack(bad), std::exception);
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
  StoreAt<uint64_t>(b, at, 12);
  ResealChecksums(b);
  const std::string e = ErrorOf(b);
  EXPECT_NE(e.find("IMGE"), std::string::npos) << e;
  EXPECT_NE(e.find("6 pixels"), std::string::npos) << e;
}

}  // namespace
}  // namespace prt::pack

namespace prt::pack {
namespace {

using testing::MakeSmallCpcaInput;
using testing::MakeSmallCpcaTransport;

void ExpectSameCpca(const CpcaTransport& got, const CpcaTransport& want) {
  EXPECT_EQ(EncodeHeader(got.header), EncodeHeader(want.header));
  EXPECT_EQ(got.cluster_of, want.cluster_of);
  EXPECT_EQ(got.coefficients, want.coefficients);
  ASSERT_EQ(got.clusters.size(), want.clusters.size());
  for (std::size_t k = 0; k < want.clusters.size(); ++k) {
    const CpcaCluster& a = got.clusters[k];
    const CpcaCluster& b = want.clusters[k];
    EXPECT_EQ(a.coefficient_scale, b.coefficient_scale) << "cluster " << k;
    ASSERT_EQ(a.basis.size(), b.basis.size());
    for (std::size_t v = 0; v <= b.basis.size(); ++v) {
      const CpcaVector& x = v == 0 ? a.mean : a.basis[v - 1];
      const CpcaVector& y = v == 0 ? b.mean : b.basis[v - 1];
      EXPECT_EQ(x.scale, y.scale) << "cluster " << k << " vector " << v;
      EXPECT_EQ(x.index, y.index) << "cluster " << k << " vector " << v;
      EXPECT_EQ(x.q, y.q) << "cluster " << k << " vector " << v;
    }
  }
  EXPECT_EQ(EncodeCpcaTransport(got), EncodeCpcaTransport(want));  // bit for bit
}

// A clustered-PCA transport (issue #24) packs as the CPCA section of a 1.3 pack, CRITICAL, in
// place of TRNS, and reads back identical, with 1 and 3 colour channels.
TEST(PrtpackRoundTrip, CpcaTransportPacksAsACriticalSectionOfVersion1_3) {
  for (uint32_t channels : {1u, 3u}) {
    SCOPED_TRACE(channels);
    const PackInput in = MakeSmallCpcaInput(channels);
    const std::vector<uint8_t> bytes = WritePack(in);
    EXPECT_EQ(bytes, WritePack(in));  // deterministic
    const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
    EXPECT_EQ(r.version_major(), 1);
    EXPECT_EQ(r.version_minor(), 3);
    EXPECT_EQ(nlohmann::json::parse(r.ReadMetadata())["format_version"], "1.3");
    EXPECT_TRUE(r.has_cpca());
    EXPECT_FALSE(r.has_transport());
    // META, MESH, MATL, MESH, MATL, CPCA.
    ASSERT_EQ(r.sections().size(), 6u);
    const SectionInfo& s = r.sections()[5];
    EXPECT_EQ(s.type, "CPCA");
    EXPECT_TRUE(s.known);
    EXPECT_EQ(s.flags, kFlagCritical);
    EXPECT_EQ(s.raw_size, EncodeCpcaSection(*in.cpca).size());
    EXPECT_TRUE(s.codec == 0 || (s.codec == 1 && s.stored_size < s.raw_size)) << s.codec;
    const CpcaTransport back = ReadCpcaTransport(r);
    ExpectSameCpca(back, *in.cpca);
    EXPECT_EQ(back.header.channels, channels);
    EXPECT_EQ(back.row_count(), 12u * channels);
    std::vector<float> a(24), b(24);
    for (std::size_t row = 0; row < back.row_count(); ++row) {
      DecodeCpcaRow(back, row, a);
      DecodeCpcaRow(*in.cpca, row, b);
      EXPECT_EQ(a, b) << "row " << row;
    }
    EXPECT_NO_THROW(r.VerifyAll());
    EXPECT_TRUE(testing::SameRead(
        testing::ReadEverything(r),
        testing::ReadEverything(PackReader::OpenMemory(bytes.data(), bytes.size()))));
    // The column readers say what the pack has instead.
    try {
      r.ReadTransportIndex();
      ADD_FAILURE() << "a CPCA pack has a TRNS index";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("its transport is CPCA"), std::string::npos) << e.what();
    }
    EXPECT_THROW(ReadCompressedTransport(r), InputError);
  }
  // A TRNS pack has no CPCA section and stays what it was (1.0, no CPCA bytes).
  const std::vector<uint8_t> columns = WritePack(MakeSmallInput());
  const PackReader r = PackReader::OpenMemory(columns.data(), columns.size());
  EXPECT_FALSE(r.has_cpca());
  EXPECT_EQ(r.version_minor(), 0);
  try {
    r.ReadCpcaTransport();
    ADD_FAILURE() << "a TRNS pack has a CPCA transport";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("has no CPCA section"), std::string::npos) << e.what();
  }
}

// The C interface (prtpack.h) over the same pack: kind, shape, cluster ids, dequantised
// coefficients and sparse vectors equal to CpcaTransport::Value / Coefficient; clear errors.
TEST(PrtpackRoundTrip, CpcaTransportThroughTheCApi) {
  const PackInput in = MakeSmallCpcaInput(3);
  const CpcaTransport& t = *in.cpca;
  const std::vector<uint8_t> bytes = WritePack(in);
  prtpack* c = prtpack_open_memory(bytes.data(), bytes.size());
  ASSERT_NE(c, nullptr) << prtpack_last_error();
  EXPECT_EQ(prtpack_transport_kind(c), PRTPACK_TRANSPORT_CPCA);
  EXPECT_EQ(prtpack_transport_kind(nullptr), PRTPACK_TRANSPORT_NONE);
  prtpack_transport_info ti{};
  EXPECT_EQ(prtpack_get_transport_info(c, &ti), PRTPACK_ERROR);
  EXPECT_NE(std::string(prtpack_last_error()).find("CPCA"), std::string::npos);
  prtpack_cpca_info info{};
  ASSERT_EQ(prtpack_get_cpca_info(c, &info), PRTPACK_OK) << prtpack_last_error();
  EXPECT_EQ(info.row_count, 36u);
  EXPECT_EQ(info.channels, 3u);
  EXPECT_EQ(info.cubemap_n, 2u);
  EXPECT_EQ(info.column_count, 24u);
  EXPECT_EQ(info.row_wavelet, 0u);
  EXPECT_EQ(info.cluster_count, 2u);
  EXPECT_EQ(info.basis_count, 2u);
  EXPECT_EQ(info.term_count, t.term_count());
  for (std::size_t r = 0; r < 36; ++r) {
    EXPECT_EQ(info.cluster_of[r], t.cluster_of[r]);
    for (std::size_t i = 0; i < 2; ++i)
      EXPECT_EQ(info.coefficients[2 * r + i], t.Coefficient(r, i)) << r << " " << i;
  }
  for (std::size_t k = 0; k < 2; ++k) {
    for (std::size_t v = 0; v < 3; ++v) {
      prtpack_cpca_vector vec{};
      ASSERT_EQ(
          v == 0 ? prtpack_get_cpca_mean(c, k, &vec) : prtpack_get_cpca_basis(c, k, v - 1, &vec),
          PRTPACK_OK)
          << prtpack_last_error();
      const CpcaVector& want = v == 0 ? t.clusters[k].mean : t.clusters[k].basis[v - 1];
      ASSERT_EQ(vec.term_count, want.term_count());
      EXPECT_EQ(vec.index == nullptr, want.term_count() == 0);
      for (std::size_t j = 0; j < vec.term_count; ++j) {
        EXPECT_EQ(vec.index[j], want.index[j]);
        EXPECT_EQ(vec.value[j], t.Value(want, j));
      }
    }
  }
  prtpack_cpca_vector vec{};
  EXPECT_EQ(prtpack_get_cpca_mean(c, 2, &vec), PRTPACK_ERROR);
  EXPECT_NE(std::string(prtpack_last_error()).find("cluster 2 out of range"), std::string::npos)
      << prtpack_last_error();
  EXPECT_EQ(prtpack_get_cpca_basis(c, 0, 2, &vec), PRTPACK_ERROR);
  EXPECT_NE(std::string(prtpack_last_error()).find("basis vector 2 out of range"),
            std::string::npos)
      << prtpack_last_error();
  EXPECT_EQ(prtpack_get_cpca_info(c, nullptr), PRTPACK_ERROR);
  EXPECT_EQ(prtpack_get_cpca_mean(nullptr, 0, &vec), PRTPACK_ERROR);
  EXPECT_EQ(prtpack_verify(c), PRTPACK_OK);
  prtpack_close(c);

  const std::vector<uint8_t> columns = WritePack(MakeSmallInput());
  c = prtpack_open_memory(columns.data(), columns.size());
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(prtpack_transport_kind(c), PRTPACK_TRANSPORT_COLUMNS);
  EXPECT_EQ(prtpack_get_cpca_info(c, &info), PRTPACK_ERROR);
  EXPECT_NE(std::string(prtpack_last_error()).find("has no CPCA section"), std::string::npos);
  prtpack_close(c);
  PackInput none = MakeSmallInput();
  none.transport.reset();
  const std::vector<uint8_t> geometry = WritePack(none);
  c = prtpack_open_memory(geometry.data(), geometry.size());
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(prtpack_transport_kind(c), PRTPACK_TRANSPORT_NONE);
  prtpack_close(c);
}

// Where the CPCA payload's header puts what (for patching).
std::vector<uint8_t> CpcaPayload(uint32_t channels = 1) {
  return EncodeCpcaSection(MakeSmallCpcaTransport(channels));
}
PackInput NoTransport() {
  PackInput in = MakeSmallInput();
  in.transport.reset();
  return in;
}

TEST(PrtpackRoundTrip, CpcaWriterRefusesWhatDoesNotFit) {
  PackInput in = MakeSmallCpcaInput();
  in.transport = MakeSmallInput().transport;
  try {
    WritePack(in);
    ADD_FAILURE() << "wrote TRNS and CPCA";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not both"), std::string::npos) << e.what();
  }
  in = MakeSmallCpcaInput();
  in.cpca->cluster_of[4] = 2;  // K = 2
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallCpcaInput();
  in.cpca->coefficients.pop_back();
  EXPECT_THROW(WritePack(in), InputError);
  in = MakeSmallCpcaInput();
  in.extra_sections.push_back({"CPCA", 0, 0, {1, 2, 3}});  // reserved
  EXPECT_THROW(WritePack(in), InputError);
  // An image pack over a CPCA transport: 12 pixels for 12 rows, not 6.
  PackInput image = testing::MakeImageInput();
  image.transport.reset();
  image.cpca = MakeSmallCpcaTransport();
  const std::vector<uint8_t> bytes = WritePack(image);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_minor(), 3);
  EXPECT_EQ(r.ReadImage().pixels(), 12u);
  EXPECT_NO_THROW(r.VerifyAll());
  image.image->camera.width = 2;
  image.image->pixel_mesh.resize(6);
  EXPECT_THROW(WritePack(image), InputError);
}

// Behind valid checksums: a CPCA section next to a TRNS, a second CPCA, section fields that
// disagree with the payload's size or its parameters, and an image of other pixels than the
// CPCA rows, are refused with an InputError naming the pack and the section.
TEST(PrtpackRoundTrip, CpcaReaderRefusesInconsistentSections) {
  const std::vector<uint8_t> good = CpcaPayload();
  EXPECT_EQ(ErrorOf(testing::PackWithRawCpca(NoTransport(), good)), "");
  const std::string both = ErrorOf(testing::PackWithRawCpca(MakeSmallInput(), good));
  EXPECT_NE(both.find("has both a TRNS and a CPCA transport"), std::string::npos) << both;
  PackInput twice = NoTransport();
  twice.extra_sections.push_back({"XCPC", kFlagCritical, 0, good});
  EXPECT_NE(ErrorOf(testing::PackWithRawCpca(twice, good)).find("more than one CPCA"),
            std::string::npos);
  struct Patch {
    std::size_t at;
    uint64_t value;
    int width;
    const char* expect;
  };
  const uint32_t params = LoadAt<uint32_t>(good, kCpcaParamsSize);
  const Patch patches[] = {
      {kCpcaBodySize, LoadAt<uint64_t>(good, kCpcaBodySize) + 1, 8, "disagree with its size"},
      {kCpcaBodySize, 0, 8, "disagree with its size"},
      {kCpcaParamsSize, params + 1, 4, "disagree with its size"},
      {kCpcaParamsSize, 0xFFFFFFFFu, 4, "disagree with its size"},
      {kCpcaChannels, 2, 4, "channel count 2 is not 1 or 3"},
      {kCpcaChannels, 3, 4, "disagree with the section's"},
      {kCpcaRowCount, 13, 8, "disagree with the section's"},
      {kCpcaClusters, 3, 4, "disagree with the section's"},
      {kCpcaBases, 1, 4, "disagree with the section's"},
  };
  for (const Patch& p : patches) {
    std::vector<uint8_t> bad = good;
    if (p.width == 4) StoreAt<uint32_t>(bad, p.at, static_cast<uint32_t>(p.value));
    if (p.width == 8) StoreAt<uint64_t>(bad, p.at, p.value);
    const std::string e = ErrorOf(testing::PackWithRawCpca(NoTransport(), bad));
    EXPECT_NE(e.find(p.expect), std::string::npos) << e;
    EXPECT_NE(e.find("CPCA"), std::string::npos) << e;
  }
  std::vector<uint8_t> shorter(good.begin(), good.begin() + kCpcaHeaderSize - 1);
  EXPECT_NE(ErrorOf(testing::PackWithRawCpca(NoTransport(), shorter)).find("too short"),
            std::string::npos);
  // Parameters of another scheme, consistent with the section's counts.
  std::vector<uint8_t> columns = good;
  columns[kCpcaHeaderSize + 8] = 3;  // header version 3: no CPCA fields
  EXPECT_NE(ErrorOf(testing::PackWithRawCpca(NoTransport(), columns)), "");
  // An image of 6 pixels over 12 CPCA rows.
  PackInput image = testing::MakeImageInput();
  image.transport.reset();
  image.image->camera.width = 2;
  image.image->pixel_mesh.resize(6);
  const std::string e = ErrorOf(testing::PackWithRawCpca(image, good));
  EXPECT_NE(e.find("6 pixels for 12 rows of 1 channel(s) in CPCA"), std::string::npos) << e;
}

}  // namespace
}  // namespace prt::pack

namespace prt::pack {
namespace {

// Glossy vertex packs (docs/glossy-transport.md): the GLSY section holds the factor table (g
// only), the pack is 1.6, the transport has terms × vertices rows, and disagreements are refused.
GlossyFactorTable SmallFactorTable(int terms) {
  GlossyFactorTable t;
  t.terms = terms;
  t.mesh_factor = {0, GlossyFactorTable::kDiffuseMesh};
  t.mesh_weight = {Rgb{0.8f, 0.7f, 0.6f}, Rgb{0.5f, 0.5f, 0.5f}};
  BrdfFactors f;
  f.terms = terms;
  f.view_n = f.light_n = 2;
  for (int i = 0; i < 4 * terms; ++i) {
    f.g.push_back(0.25f * float(i + 1));
    f.f.push_back(-0.5f * float(i));
  }
  f.relative_error = 0.25;
  f.description = "ggx r=0.5";
  t.factors.push_back(f);
  return t;
}

TEST(PrtpackRoundTrip, GlossyVertexPacksAre16AndCarryTheirFactorTable) {
  PackInput in = testing::MakeSmallInput();
  in.transport->row_count = 24;  // 2 terms × the 12 vertices
  in.glossy = SmallFactorTable(2);
  const std::vector<uint8_t> bytes = WritePack(in);
  const PackReader r = PackReader::OpenMemory(bytes.data(), bytes.size());
  EXPECT_EQ(r.version_minor(), 6);
  ASSERT_TRUE(r.has_glossy());
  const GlossyFactorTable back = r.ReadGlossy();
  EXPECT_EQ(back.terms, 2);
  EXPECT_EQ(back.mesh_factor, in.glossy->mesh_factor);
  EXPECT_EQ(back.mesh_weight[0], in.glossy->mesh_weight[0]);
  EXPECT_EQ(back.factors[0].g, in.glossy->factors[0].g);
  EXPECT_TRUE(back.factors[0].f.empty());  // the farm's f tables stay in the run folder
  EXPECT_NO_THROW(r.VerifyAll());
  // terms × vertices must be the transport's rows, and the table must name every mesh.
  PackInput bad = in;
  bad.transport->row_count = 12;
  EXPECT_THROW(WritePack(bad), InputError);
  bad = in;
  bad.glossy->mesh_factor.pop_back();
  bad.glossy->mesh_weight.pop_back();
  EXPECT_THROW(WritePack(bad), InputError);
  // No GLSY: the pack of before, and no glossy table.
  const std::vector<uint8_t> plain = WritePack(testing::MakeSmallInput());
  const PackReader p = PackReader::OpenMemory(plain.data(), plain.size());
  EXPECT_FALSE(p.has_glossy());
  EXPECT_LT(p.version_minor(), 6);
  EXPECT_THROW(p.ReadGlossy(), InputError);
}

}  // namespace
}  // namespace prt::pack
