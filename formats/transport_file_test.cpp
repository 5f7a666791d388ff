#include "formats/transport_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "formats/geometry_file.h"
#include "formats/run_folder.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

class TransportFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("prt_transport_file_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

// A value that differs for every (row, col) and is exactly representable in float32.
float Value(uint64_t row, uint64_t col) {
  return static_cast<float>(row * 1000 + col) * 0.25f - 3.0f;
}

TransportFileInfo SmallInfo() {
  TransportFileInfo info;
  info.rows = 23;  // 3 blocks of 8 rows, the last one with 7
  info.cubemap_n = 2;
  info.rows_per_block = 8;
  info.rays_per_texel = 4;
  info.seed = 7;
  return info;
}

void FlipByte(const std::string& path, uint64_t offset) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(static_cast<std::streamoff>(offset));
  char c = 0;
  f.read(&c, 1);
  c = static_cast<char>(c ^ 0x10);
  f.seekp(static_cast<std::streamoff>(offset));
  f.write(&c, 1);
}

TEST_F(TransportFileTest, InfoGeometryOfBlocks) {
  const TransportFileInfo info = SmallInfo();
  EXPECT_EQ(info.cols(), 24u);
  EXPECT_EQ(info.block_count(), 3u);
  EXPECT_EQ(info.RowsInBlock(0), 8u);
  EXPECT_EQ(info.RowsInBlock(2), 7u);
  EXPECT_EQ(info.RowsInBlock(3), 0u);
  EXPECT_EQ(info.data_offset(), kTransportDataAlignment);
  EXPECT_EQ(info.file_bytes(), kTransportDataAlignment + 23u * 24u * 4u);
}

TEST_F(TransportFileTest, RoundTripRowsWrittenOutOfOrder) {
  const TransportFileInfo info = SmallInfo();
  const std::string path = Path("t.prtt");
  {
    auto writer = TransportFileWriter::Create(path, info);
    // Jobs arrive in any order and straddle block boundaries.
    for (auto [first, count] :
         std::vector<std::pair<uint64_t, uint64_t>>{{15, 8}, {0, 5}, {5, 10}}) {
      std::vector<float> rows(count * info.cols());
      for (uint64_t r = 0; r < count; ++r) {
        for (uint64_t c = 0; c < info.cols(); ++c) rows[r * info.cols() + c] = Value(first + r, c);
      }
      writer.WriteRows(first, count, rows.data());
    }
    writer.Finalize();
  }
  EXPECT_EQ(fs::file_size(path), info.file_bytes());
  TransportFileReader reader(path);
  EXPECT_EQ(reader.info(), info);
  EXPECT_EQ(reader.FindCorruptBlock(), -1);
  for (uint64_t b = 0; b < info.block_count(); ++b) {
    const std::vector<float> block = reader.ReadBlock(b);
    ASSERT_EQ(block.size(), info.RowsInBlock(b) * info.cols());
    EXPECT_EQ(reader.BlockChecksum(b), Checksum64(block.data(), block.size() * sizeof(float)));
    for (uint64_t r = 0; r < info.RowsInBlock(b); ++r) {
      for (uint64_t c = 0; c < info.cols(); ++c) {
        ASSERT_EQ(block[r * info.cols() + c], Value(info.FirstRowOfBlock(b) + r, c));
      }
    }
  }
  // Rows across a block boundary.
  std::vector<float> rows(6 * info.cols());
  reader.ReadRows(6, 6, rows.data());
  for (uint64_t r = 0; r < 6; ++r) EXPECT_EQ(rows[r * info.cols() + 5], Value(6 + r, 5));
  // The floats are little-endian float32 at data_offset, row-major (the documented layout).
  std::ifstream raw(path, std::ios::binary);
  raw.seekg(static_cast<std::streamoff>(info.data_offset() + (9 * info.cols() + 3) * 4));
  unsigned char b[4];
  raw.read(reinterpret_cast<char*>(b), 4);
  const uint32_t bits = b[0] | (b[1] << 8) | (b[2] << 16) | (static_cast<uint32_t>(b[3]) << 24);
  float v;
  std::memcpy(&v, &bits, 4);
  EXPECT_EQ(v, Value(9, 3));
}

TEST_F(TransportFileTest, SameRowsGiveByteIdenticalFiles) {
  const TransportFileInfo info = SmallInfo();
  std::vector<float> all(info.rows * info.cols());
  for (uint64_t i = 0; i < all.size(); ++i) all[i] = std::sin(static_cast<float>(i));
  auto a = TransportFileWriter::Create(Path("a.prtt"), info);
  a.WriteRows(0, info.rows, all.data());
  a.Finalize();
  auto b = TransportFileWriter::Create(Path("b.prtt"), info);
  for (uint64_t r = info.rows; r-- > 0;) b.WriteRows(r, 1, all.data() + r * info.cols());
  b.Finalize();
  EXPECT_EQ(ReadWholeFile(Path("a.prtt")), ReadWholeFile(Path("b.prtt")));
}

TEST_F(TransportFileTest, ChecksumMismatchNamesTheDamagedBlock) {
  const TransportFileInfo info = SmallInfo();
  const std::string path = Path("t.prtt");
  {
    std::vector<float> all(info.rows * info.cols(), 0.5f);
    auto writer = TransportFileWriter::Create(path, info);
    writer.WriteRows(0, info.rows, all.data());
    writer.Finalize();
  }
  // One bit of row 17 (block 2) flips on disk.
  FlipByte(path, info.data_offset() + 17 * info.row_bytes() + 2);
  TransportFileReader reader(path);  // the header is still intact
  EXPECT_EQ(reader.FindCorruptBlock(), 2);
  EXPECT_NO_THROW(reader.ReadBlock(1));
  try {
    reader.ReadBlock(2);
    FAIL() << "a damaged block was read without error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("checksum mismatch in block 2"), std::string::npos)
        << e.what();
    EXPECT_EQ(e.file(), path);
  }
  std::vector<float> rows(info.cols());
  EXPECT_THROW(reader.ReadRows(20, 1, rows.data()), InputError);
  EXPECT_NO_THROW(reader.ReadRows(3, 1, rows.data()));
}

TEST_F(TransportFileTest, DamagedHeaderTableOrTruncationIsRejected) {
  const TransportFileInfo info = SmallInfo();
  const std::string path = Path("t.prtt");
  const auto make = [&] {
    std::vector<float> all(info.rows * info.cols(), 1.0f);
    auto writer = TransportFileWriter::Create(path, info);
    writer.WriteRows(0, info.rows, all.data());
    writer.Finalize();
  };
  make();
  FlipByte(path, 17);  // inside `rows`
  EXPECT_THROW(TransportFileReader{path}, InputError);
  make();
  FlipByte(path, kTransportHeaderBytes + 8 + 3);  // block 1's checksum in the table
  EXPECT_THROW(TransportFileReader{path}, InputError);
  make();
  FlipByte(path, 0);  // magic
  EXPECT_THROW(TransportFileReader{path}, InputError);
  make();
  fs::resize_file(path, info.file_bytes() - 4);
  EXPECT_THROW(TransportFileReader{path}, InputError);
  EXPECT_THROW(TransportFileReader{Path("missing.prtt")}, InputError);
}

TEST_F(TransportFileTest, IncompleteFileIsRefusedUntilFinalizedAndReopenKeepsRows) {
  const TransportFileInfo info = SmallInfo();
  const std::string path = Path("t.prtt");
  std::vector<float> row(info.cols(), 2.0f);
  {
    auto writer = TransportFileWriter::Create(path, info);
    writer.WriteRows(4, 1, row.data());
    writer.Sync();
  }
  try {
    TransportFileReader reader(path);
    FAIL() << "an incomplete transport file was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--resume"), std::string::npos) << e.what();
  }
  TransportFileInfo other = info;
  other.rows_per_block = 4;
  EXPECT_THROW(TransportFileWriter::Reopen(path, other), InputError);
  auto writer = TransportFileWriter::Reopen(path, info);
  std::vector<float> back(info.cols());
  writer.ReadRows(4, 1, back.data());
  EXPECT_EQ(back, row);
  writer.Finalize();
  TransportFileReader reader(path);
  std::vector<float> rows(info.rows * info.cols());
  reader.ReadRows(0, info.rows, rows.data());
  EXPECT_EQ(rows[4 * info.cols()], 2.0f);
  EXPECT_EQ(rows[5 * info.cols()], 0.0f);  // never written rows read as zeros
}

SceneGeometry TwoMeshGeometry() {
  SceneGeometry g;
  SceneMesh tri;
  tri.name = "triangle";
  tri.albedo = {0.25f, 0.5f, 0.75f};
  tri.mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1.0 / 3.0, 0.1}};
  tri.mesh.normals = {{0, 0, 1}, {0, 0, 1}, {0, std::sqrt(0.5), std::sqrt(0.5)}};
  tri.mesh.triangles = {{0, 1, 2}};
  SceneMesh ground;
  ground.name = "ground";
  ground.is_ground = true;
  ground.grid_resolution = 2;
  ground.mesh.positions = {{-1, 0, -1}, {1, 0, -1}, {-1, 0, 1}, {1, 0, 1}};
  ground.mesh.normals.assign(4, {0, 1, 0});
  ground.mesh.triangles = {{0, 2, 1}, {1, 2, 3}};
  g.meshes = {tri, ground};
  g.bounds_min = {-1, 0, -1};
  g.bounds_max = {1, 1.0 / 3.0, 1};
  return g;
}

// Packs the plain file `from` into `to` block by block (what prt-farm's finalize does).
uint64_t PackFile(const std::string& from, const std::string& to) {
  const TransportFileReader plain(from);
  PackedTransportWriter w(to, plain.info());
  for (uint64_t b = 0; b < plain.info().block_count(); ++b) {
    const std::vector<float> block = plain.ReadBlock(b);
    w.Append(b, CompressTransportBlock(block.data(), block.size()), plain.BlockChecksum(b));
  }
  return w.Finish();
}

TEST_F(TransportFileTest, PackedFileReadsTheSameRowsAndIsSmaller) {
  TransportFileInfo info = SmallInfo();
  info.rows = 300;
  info.cubemap_n = 8;
  info.rows_per_block = 64;
  std::vector<float> all(info.rows * info.cols(), 0.0f);
  // Rows like T's: a smooth cosine-like lobe over half the texels, zeros elsewhere.
  for (uint64_t r = 0; r < info.rows; ++r)
    for (uint64_t c = 0; c < info.cols() / 2; ++c)
      all[r * info.cols() + c] = 1e-3f * std::cos(0.01f * static_cast<float>(c + r));
  auto w = TransportFileWriter::Create(Path("plain.prtt"), info);
  w.WriteRows(0, info.rows, all.data());
  w.Finalize();
  const uint64_t bytes = PackFile(Path("plain.prtt"), Path("packed.prtt"));
  EXPECT_EQ(bytes, fs::file_size(Path("packed.prtt")));
  EXPECT_FALSE(fs::exists(Path("packed.prtt.tmp")));
  EXPECT_LT(bytes * 3, fs::file_size(Path("plain.prtt")));

  const TransportFileReader plain(Path("plain.prtt")), packed(Path("packed.prtt"));
  EXPECT_FALSE(plain.packed());
  EXPECT_TRUE(packed.packed());
  EXPECT_EQ(packed.info(), info);
  EXPECT_EQ(packed.FindCorruptBlock(), -1);
  for (uint64_t b = 0; b < info.block_count(); ++b) {
    EXPECT_EQ(packed.ReadBlock(b), plain.ReadBlock(b));
    EXPECT_EQ(packed.BlockChecksum(b), plain.BlockChecksum(b));
    EXPECT_LT(packed.StoredBlockBytes(b), plain.StoredBlockBytes(b));
  }
  std::vector<float> rows(100 * info.cols());
  packed.ReadRows(50, 100, rows.data());
  EXPECT_EQ(std::memcmp(rows.data(), all.data() + 50 * info.cols(), rows.size() * 4), 0);
  // The same rows always pack to the same bytes.
  PackFile(Path("plain.prtt"), Path("again.prtt"));
  EXPECT_EQ(ReadWholeFile(Path("packed.prtt")), ReadWholeFile(Path("again.prtt")));
  // A packed file is final: the farm's writer refuses to reopen it.
  EXPECT_THROW(TransportFileWriter::Reopen(Path("packed.prtt"), info), InputError);
}

// Hostile or damaged packed files: every kind is an InputError naming the file, never a crash,
// an allocation sized by the file, or rows that do not match their checksum.
TEST_F(TransportFileTest, DamagedPackedFilesAreRejected) {
  TransportFileInfo info = SmallInfo();
  auto w = TransportFileWriter::Create(Path("plain.prtt"), info);
  std::vector<float> all(info.rows * info.cols());
  for (uint64_t i = 0; i < all.size(); ++i) all[i] = std::sin(static_cast<float>(i));
  w.WriteRows(0, info.rows, all.data());
  w.Finalize();
  PackFile(Path("plain.prtt"), Path("good.prtt"));
  const std::string good = ReadWholeFile(Path("good.prtt"));
  const uint64_t tables = kTransportHeaderBytes + 8 * info.block_count();
  auto expect_rejected = [&](const std::string& bytes, const std::string& what) {
    const std::string path = Path("bad.prtt");
    WriteFileDurably(path, bytes);
    try {
      const TransportFileReader r(path);
      std::vector<float> out(info.rows * info.cols());
      r.ReadRows(0, info.rows, out.data());
      ADD_FAILURE() << what << ": accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("bad.prtt"), std::string::npos) << what;
    }
  };
  expect_rejected(good.substr(0, good.size() - 1), "truncated by a byte");
  expect_rejected(good + "x", "a byte appended");
  expect_rejected(good.substr(0, 60), "truncated in the header");
  for (uint64_t at : {uint64_t{20}, tables + 3, tables + 8 * info.block_count(),
                      uint64_t{good.size() - 5}, uint64_t{good.size() / 2 + 40}}) {
    std::string bad = good;
    bad[at] = static_cast<char>(bad[at] ^ 0x44);
    expect_rejected(bad, "byte " + std::to_string(at) + " flipped");
  }
}

TEST_F(TransportFileTest, GeometryRoundTripIsExact) {
  const SceneGeometry g = TwoMeshGeometry();
  const std::string path = Path(kGeometryFileName);
  WriteSceneGeometryFile(path, g);
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const SceneGeometry back = ReadSceneGeometryFile(path);
  ASSERT_EQ(back.meshes.size(), 2u);
  EXPECT_EQ(back.bounds_min, g.bounds_min);
  EXPECT_EQ(back.bounds_max, g.bounds_max);
  for (std::size_t m = 0; m < 2; ++m) {
    EXPECT_EQ(back.meshes[m].name, g.meshes[m].name);
    EXPECT_EQ(back.meshes[m].albedo, g.meshes[m].albedo);
    EXPECT_EQ(back.meshes[m].is_ground, g.meshes[m].is_ground);
    EXPECT_EQ(back.meshes[m].grid_resolution, g.meshes[m].grid_resolution);
    EXPECT_EQ(back.meshes[m].mesh.positions, g.meshes[m].mesh.positions);  // bit-exact doubles
    EXPECT_EQ(back.meshes[m].mesh.normals, g.meshes[m].mesh.normals);
    EXPECT_EQ(back.meshes[m].mesh.triangles, g.meshes[m].mesh.triangles);
  }
  EXPECT_EQ(SerializeSceneGeometry(back), SerializeSceneGeometry(g));
}

TEST_F(TransportFileTest, DamagedOrTruncatedGeometryIsRejected) {
  const std::string bytes = SerializeSceneGeometry(TwoMeshGeometry());
  std::string flipped = bytes;
  flipped[100] = static_cast<char>(flipped[100] ^ 1);
  EXPECT_THROW(ParseSceneGeometry(flipped, "g"), InputError);
  EXPECT_THROW(ParseSceneGeometry(bytes.substr(0, bytes.size() - 9), "g"), InputError);
  EXPECT_THROW(ParseSceneGeometry("PRTGEOM1", "g"), InputError);
  EXPECT_THROW(ParseSceneGeometry("", "g"), InputError);
  // A huge vertex count with a valid checksum must not allocate or read out of bounds.
  std::string lying(bytes.substr(0, bytes.size() - 8));
  const std::size_t vertex_count_at = 8 + 4 + 4 + 48 + 4 + 8 + 12 + 4 + 4;
  const uint64_t huge = uint64_t{1} << 60;
  std::memcpy(lying.data() + vertex_count_at, &huge, 8);
  const uint64_t sum = Checksum64(lying.data(), lying.size());
  lying.append(reinterpret_cast<const char*>(&sum), 8);
  try {
    ParseSceneGeometry(lying, "g");
    FAIL() << "a lying vertex count was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
}

TEST_F(TransportFileTest, WriteFileDurablyReplacesContentAndReportsUnwritableFolders) {
  const std::string path = Path("x.json");
  WriteFileDurably(path, "first");
  WriteFileDurably(path, "second");
  EXPECT_EQ(ReadWholeFile(path), "second");
  WriteFileDurably(Path("plain"), "a file");
  EXPECT_THROW(WriteFileDurably(Path("plain") + "/inside", "x"), FileIoError);
}

}  // namespace
}  // namespace prt
