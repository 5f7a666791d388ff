// A .prtpack reader on damaged input (docs/prtpack-format.md, "Verification"): every single-byte
// corruption of a small pack either reads identically (the byte was padding) or fails with a
// clear InputError; every truncation fails; and mutated copies of the seed corpus whose
// checksums were recomputed (so that they reach the decoders) never crash the reader.
// This is also the GCC build's stand-in for the libFuzzer harness (reader_fuzz.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "packager/prtpack_format.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_test_util.h"
#include "packager/prtpack_transport.h"
#include "packager/prtpack_writer.h"
#include "vocabulary/errors.h"
#include "vocabulary/mesh_io.h"

namespace prt::pack {
namespace {

// Bytes of `file` that no checksum covers: between the table and the first section, between
// sections, and between TRNS blocks (the writer zeroes them).
std::vector<bool> PaddingMask(const std::vector<uint8_t>& file) {
  std::vector<bool> padding(file.size(), true);
  const PackReader r = PackReader::OpenMemory(file.data(), file.size());
  const uint64_t table_end = kHeaderSize + r.sections().size() * kEntrySize;
  std::fill(padding.begin(), padding.begin() + std::ptrdiff_t(table_end), false);
  for (const SectionInfo& s : r.sections()) {
    std::fill(padding.begin() + std::ptrdiff_t(s.offset),
              padding.begin() + std::ptrdiff_t(s.offset + s.stored_size), false);
  }
  return padding;
}

// ReaderOptions small enough that a corrupted size never allocates much.
ReaderOptions Bounded() {
  ReaderOptions o;
  o.max_section_bytes = 64 << 20;
  return o;
}

// Reads all of `bytes`; returns "" and fills `out` on success, else the InputError's message.
// Any other exception fails the test.
std::string TryRead(const std::vector<uint8_t>& bytes, testing::FullRead* out) {
  try {
    *out = testing::ReadEverything(
        PackReader::OpenMemory(bytes.data(), bytes.size(), "<memory>", Bounded()));
    return "";
  } catch (const InputError& e) {
    return std::string(e.what()).empty() ? "(empty message)" : e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "not an InputError: " << e.what();
    return "unexpected";
  }
}

void ExpectEveryFlippedByteIsPaddingOrDetected(const PackInput& input) {
  const std::vector<uint8_t> file = WritePack(input);
  testing::FullRead reference;
  ASSERT_EQ(TryRead(file, &reference), "");
  const std::vector<bool> padding = PaddingMask(file);
  std::size_t detected = 0, identical = 0;
  for (std::size_t i = 0; i < file.size(); ++i) {
    std::vector<uint8_t> bad = file;
    bad[i] ^= 0xFF;
    testing::FullRead got;
    const std::string error = TryRead(bad, &got);
    if (error.empty()) {
      EXPECT_TRUE(padding[i]) << "byte " << i << " changed without detection";
      EXPECT_TRUE(testing::SameRead(got, reference)) << "byte " << i << " changed the content";
      ++identical;
    } else {
      EXPECT_FALSE(padding[i]) << "padding byte " << i << " refused: " << error;
      EXPECT_GT(error.size(), 12u);
      ++detected;
    }
  }
  std::printf(
      "prtpack corruption: %zu bytes, %zu flips detected, %zu padding flips read "
      "identically\n",
      file.size(), detected, identical);
  EXPECT_GT(detected, file.size() / 2);
}

TEST(PrtpackCorruption, EveryFlippedByteIsPaddingOrDetected) {
  ExpectEveryFlippedByteIsPaddingOrDetected(testing::MakeSmallInput());
}

// The same with VISB sections (docs/prtpack-format.md, VISB): a flip in them is caught by the
// checksum, and the visibility of every accepted read equals the original maps exactly.
TEST(PrtpackCorruption, EveryFlippedByteOfAGlossyPackIsPaddingOrDetected) {
  ExpectEveryFlippedByteIsPaddingOrDetected(testing::MakeSmallGlossyInput());
}

// A 1.1 pack with a 3-channel compressed transport: every flip of its TRNS channel count or
// row count is caught (the index checksum covers them).
PackInput SmallThreeChannelInput() {
  PackInput in = testing::MakeSmallInput();
  in.transport = testing::MakeSmallCompressedTransportInput(3);
  return in;
}

TEST(PrtpackCorruption, EveryFlippedByteOfAThreeChannelPackIsPaddingOrDetected) {
  ExpectEveryFlippedByteIsPaddingOrDetected(SmallThreeChannelInput());
}

// A 1.3 pack with a CPCA transport (zstd-compressed section): every flip is caught by the
// section checksum, and every accepted read decodes the same CpcaTransport.
TEST(PrtpackCorruption, EveryFlippedByteOfACpcaPackIsPaddingOrDetected) {
  ExpectEveryFlippedByteIsPaddingOrDetected(testing::MakeSmallCpcaInput(1));
  ExpectEveryFlippedByteIsPaddingOrDetected(testing::MakeSmallCpcaInput(3));
}

void ExpectEveryTruncationFailsClearly(const PackInput& input) {
  const std::vector<uint8_t> file = WritePack(input);
  for (std::size_t n = 0; n < file.size(); ++n) {
    std::vector<uint8_t> cut(file.begin(), file.begin() + std::ptrdiff_t(n));
    testing::FullRead got;
    const std::string error = TryRead(cut, &got);
    ASSERT_FALSE(error.empty()) << "truncated at " << n << " read fine";
    if (n >= kHeaderSize) {
      EXPECT_NE(error.find("truncated"), std::string::npos) << error;
    }
  }
  std::vector<uint8_t> longer = file;
  longer.push_back(0);
  testing::FullRead got;
  EXPECT_NE(TryRead(longer, &got).find("trailing bytes"), std::string::npos);
}

TEST(PrtpackCorruption, EveryTruncationFailsClearly) {
  ExpectEveryTruncationFailsClearly(testing::MakeSmallInput());
  ExpectEveryTruncationFailsClearly(testing::MakeSmallGlossyInput());
  ExpectEveryTruncationFailsClearly(SmallThreeChannelInput());
  ExpectEveryTruncationFailsClearly(testing::MakeSmallCpcaInput());
}

// Hostile CPCA payloads behind valid checksums (the section stored with codec none, its type
// patched, ResealChecksums): every byte of the payload (its header, the encoded parameters and
// the CPCA body) replaced by 0x00, 0x01, 0x7F, 0x80 and 0xFF; every truncation, with and without
// the body size made to agree; parameters whose counts were made hostile consistently with the
// section. Each must read back or fail with an InputError naming the CPCA section, never crash
// or allocate without bound (ReaderOptions: 64 MiB).
TEST(PrtpackCorruption, HostileCpcaPayloadsAreRefusedClearly) {
  PackInput no_transport = testing::MakeSmallInput();
  no_transport.transport.reset();
  auto pack_with = [&](const std::vector<uint8_t>& payload) {
    return testing::PackWithRawCpca(no_transport, payload);
  };
  const std::vector<uint8_t> good = EncodeCpcaSection(testing::MakeSmallCpcaTransport());
  testing::FullRead reference;
  const std::vector<uint8_t> base = pack_with(good);
  ASSERT_EQ(TryRead(base, &reference), "");
  ASSERT_FALSE(reference.cpca.empty());
  EXPECT_EQ(reference.cpca, EncodeCpcaTransport(testing::MakeSmallCpcaTransport()));
  const PackReader r = PackReader::OpenMemory(base.data(), base.size());
  uint64_t at = 0;
  for (const SectionInfo& s : r.sections())
    if (s.type_code == kTypeCpca) at = s.offset;
  ASSERT_GT(at, 0u);
  std::size_t refused = 0, read_ok = 0;
  auto expect_clean = [&](const std::vector<uint8_t>& bytes, const std::string& what) {
    testing::FullRead got;
    const std::string error = TryRead(bytes, &got);
    (error.empty() ? read_ok : refused)++;
    if (!error.empty()) {
      EXPECT_NE(error.find("CPCA"), std::string::npos) << what << ": " << error;
    }
    return error;
  };
  for (std::size_t i = 0; i < good.size(); ++i) {
    for (uint8_t value :
         {uint8_t(0x00), uint8_t(0x01), uint8_t(0x7F), uint8_t(0x80), uint8_t(0xFF)}) {
      if (good[i] == value) continue;
      std::vector<uint8_t> bad = base;
      bad[at + i] = value;
      ResealChecksums(bad);
      expect_clean(bad, "byte " + std::to_string(i) + " = " + std::to_string(value));
    }
  }
  const uint32_t params_size = LoadAt<uint32_t>(good, kCpcaParamsSize);
  const std::size_t body_at = kCpcaHeaderSize + params_size;
  for (std::size_t n = 0; n < good.size(); ++n) {
    std::vector<uint8_t> cut(good.begin(), good.begin() + std::ptrdiff_t(n));
    EXPECT_NE(expect_clean(pack_with(cut), "cut at " + std::to_string(n)), "") << n;
    if (n >= body_at) {  // the body cut, its size made to agree: the body decoder refuses it
      StoreAt<uint64_t>(cut, kCpcaBodySize, n - body_at);
      EXPECT_NE(expect_clean(pack_with(cut), "body cut at " + std::to_string(n)), "") << n;
    }
  }
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_NE(expect_clean(pack_with(longer), "one more byte"), "");
  StoreAt<uint64_t>(longer, kCpcaBodySize, LoadAt<uint64_t>(good, kCpcaBodySize) + 1);
  EXPECT_NE(expect_clean(pack_with(longer), "trailing body byte"), "");
  // Hostile counts in the parameters (encoded header version 4: samples at byte 16, clusters at
  // 48, bases at 52, the one segment's count at 63) and the same in the section's header, so
  // that they reach DecodeHeader and the CPCA body decoder's bounds.
  const std::size_t params = kCpcaHeaderSize;
  ASSERT_EQ(LoadAt<uint32_t>(good, params + 16), 12u);
  ASSERT_EQ(LoadAt<uint32_t>(good, params + 48), 2u);
  ASSERT_EQ(LoadAt<uint32_t>(good, params + 52), 2u);
  ASSERT_EQ(LoadAt<uint32_t>(good, params + 63), 12u);
  for (uint32_t rows : {12u, 13u, 1u << 20, 1u << 28, 0xFFFFFFFFu}) {
    for (uint32_t clusters : {1u, 2u, 3u, 12u, 13u, 1u << 20, 0xFFFFFFFFu}) {
      for (uint32_t bases : {0u, 1u, 2u, 3u, 24u, 25u, 256u, 0xFFFFFFFFu}) {
        std::vector<uint8_t> bad = good;
        StoreAt<uint32_t>(bad, params + 16, rows);
        StoreAt<uint32_t>(bad, params + 48, clusters);
        StoreAt<uint32_t>(bad, params + 52, bases);
        StoreAt<uint32_t>(bad, params + 63, rows);
        StoreAt<uint64_t>(bad, kCpcaRowCount, rows);
        StoreAt<uint32_t>(bad, kCpcaClusters, clusters);
        StoreAt<uint32_t>(bad, kCpcaBases, bases);
        const std::string error = expect_clean(
            pack_with(bad), "rows " + std::to_string(rows) + ", clusters " +
                                std::to_string(clusters) + ", bases " + std::to_string(bases));
        if (rows != 12 || clusters != 2 || bases != 2) {
          EXPECT_NE(error, "");
        }
      }
    }
  }
  std::printf("hostile CPCA payloads: %zu refused with InputError, %zu read\n", refused, read_ok);
  EXPECT_GT(refused, good.size());
}

// Hostile VISB payloads behind valid checksums (ResealChecksums): every byte of each VISB
// section's decoded content replaced, re-compressed and resealed, must read back or fail with
// an InputError, never crash or allocate without bound.
TEST(PrtpackCorruption, HostileVisibilityPayloadsAreRefusedClearly) {
  const PackInput glossy = testing::MakeSmallGlossyInput();
  const std::vector<uint8_t> good = glossy.visibility->per_mesh[0];
  // The writer validates visibility, so hostile payloads go in as unknown sections (codec
  // none) whose type is then patched to VISB and the checksums resealed.
  auto pack_with = [&](const std::vector<uint8_t>& mesh0) {
    PackInput in = testing::MakeSmallInput();
    in.extra_sections.push_back({"XVIS", 0, 0, mesh0});
    in.extra_sections.push_back({"XVIS", 0, 1, glossy.visibility->per_mesh[1]});
    std::vector<uint8_t> file = WritePack(in);
    const uint32_t sections = LoadAt<uint32_t>(file, kHdrSectionCount);
    for (uint32_t i = 0; i < sections; ++i) {
      const std::size_t type = kHeaderSize + std::size_t(i) * kEntrySize + kSecType;
      if (LoadAt<uint32_t>(file, type) == FourCC("XVIS"))
        StoreAt<uint32_t>(file, type, kTypeVisibility);
    }
    ResealChecksums(file);
    return file;
  };
  testing::FullRead reference;
  const std::vector<uint8_t> base = pack_with(good);
  ASSERT_EQ(TryRead(base, &reference), "");
  ASSERT_EQ(reference.visibility.size(), 12u);
  // Where mesh 0's payload lies in `base` (same length edits are patched in place).
  const PackReader r = PackReader::OpenMemory(base.data(), base.size());
  uint64_t at = 0;
  for (const SectionInfo& s : r.sections())
    if (s.type_code == kTypeVisibility && s.id == 0) at = s.offset;
  ASSERT_GT(at, 0u);
  std::size_t refused = 0, read_ok = 0;
  for (std::size_t i = 0; i < good.size(); ++i) {
    for (uint8_t value : {uint8_t(0x00), uint8_t(0x7F), uint8_t(0xFF)}) {
      if (good[i] == value) continue;
      std::vector<uint8_t> bad = base;
      bad[at + i] = value;
      ResealChecksums(bad);
      testing::FullRead got;
      const std::string error = TryRead(bad, &got);
      (error.empty() ? read_ok : refused)++;
      if (!error.empty()) {
        EXPECT_NE(error.find("VISB"), std::string::npos) << "byte " << i << ": " << error;
      }
    }
  }
  // Truncated and extended payloads.
  for (std::size_t n = 0; n < good.size(); ++n) {
    testing::FullRead got;
    EXPECT_NE(
        TryRead(pack_with(std::vector<uint8_t>(good.begin(), good.begin() + std::ptrdiff_t(n))),
                &got),
        "")
        << "VISB cut at " << n;
  }
  std::vector<uint8_t> longer = good;
  longer.push_back(0);
  testing::FullRead got;
  EXPECT_NE(TryRead(pack_with(longer), &got), "");
  std::printf("hostile VISB payloads: %zu refused with InputError, %zu read\n", refused, read_ok);
  EXPECT_GT(refused, 0u);
}

// The seed corpus in packager/fuzz_corpus/ is written by this test when PRT_WRITE_FUZZ_CORPUS
// is set (run it after a format change); otherwise it only checks the generator still works.
TEST(PrtpackCorruption, WriteSeedCorpus) {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
  PackInput in = testing::MakeSmallInput();
  seeds.emplace_back("small.prtpack", WritePack(in));
  in.extra_sections.push_back({"XTRA", 0, 0, {1, 2, 3, 4}});
  seeds.emplace_back("extra_section.prtpack", WritePack(in));
  in.transport.reset();
  in.extra_sections.clear();
  seeds.emplace_back("no_transport.prtpack", WritePack(in));
  in = testing::MakeSmallInput();
  in.transport = testing::MakeSmallCompressedTransportInput();
  seeds.emplace_back("compressed_transport.prtpack", WritePack(in));
  seeds.emplace_back("visibility.prtpack", WritePack(testing::MakeSmallGlossyInput()));
  seeds.emplace_back("compressed_transport_rgb.prtpack", WritePack(SmallThreeChannelInput()));
  seeds.emplace_back("image.prtpack", WritePack(testing::MakeImageInput()));
  seeds.emplace_back("image_supersampled.prtpack",
                     WritePack(testing::MakeSupersampledImageInput()));
  seeds.emplace_back("cpca.prtpack", WritePack(testing::MakeSmallCpcaInput()));
  PackInput real;
  // A real mesh from the Debian data package the build extracts (always present, unlike
  // ../shared/data); the committed corpus also holds bunny_lowres.prtpack from an earlier run.
  real.metadata_json = R"({"scene":{"name":"camel"}})";
  real.meshes.push_back({"camel",
                         LoadMesh(std::string(PRT_DATA_DIR) + "/meshes/camel.off"),
                         {0.8f, 0.8f, 0.8f},
                         false,
                         0});
  seeds.emplace_back("camel.prtpack", WritePack(real));
  const char* dir = std::getenv("PRT_WRITE_FUZZ_CORPUS");
  for (const auto& [name, bytes] : seeds) {
    testing::FullRead got;
    EXPECT_EQ(TryRead(bytes, &got), "") << name;
    if (dir != nullptr) {
      std::ofstream out(std::filesystem::path(dir) / name, std::ios::binary);
      out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
  }
}

std::vector<uint8_t> ReadCorpusFile(const std::string& name) {
  std::ifstream in(std::filesystem::path(PRT_SOURCE_DIR) / "packager/fuzz_corpus" / name,
                   std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The corpus's 1.0 packs were written before transports had channels (commit 8ad5212 and
// earlier): they still open, read as one channel, and a one-channel pack written today is the
// same file byte for byte.
TEST(PrtpackCorruption, OneChannelPacksAreTheVersion1_0FixturesByteForByte) {
  const std::vector<uint8_t> small = ReadCorpusFile("small.prtpack");
  const std::vector<uint8_t> compressed = ReadCorpusFile("compressed_transport.prtpack");
  ASSERT_FALSE(small.empty());
  ASSERT_FALSE(compressed.empty());
  EXPECT_EQ(WritePack(testing::MakeSmallInput()), small);
  PackInput in = testing::MakeSmallInput();
  in.transport = testing::MakeSmallCompressedTransportInput();
  EXPECT_EQ(WritePack(in), compressed);
  for (const std::vector<uint8_t>* bytes : {&small, &compressed}) {
    const PackReader r = PackReader::OpenMemory(bytes->data(), bytes->size());
    EXPECT_EQ(r.version_minor(), 0);
    EXPECT_EQ(r.ReadTransportIndex().channels, 1u);
  }
  const PackReader r = PackReader::OpenMemory(compressed.data(), compressed.size());
  EXPECT_EQ(ReadCompressedTransport(r).header.channels, 1u);
  const std::vector<uint8_t> rgb = ReadCorpusFile("compressed_transport_rgb.prtpack");
  const PackReader r3 = PackReader::OpenMemory(rgb.data(), rgb.size());
  EXPECT_EQ(r3.version_minor(), 1);
  EXPECT_EQ(ReadCompressedTransport(r3).header.channels, 3u);
}

std::vector<std::vector<uint8_t>> SeedCorpus() {
  const std::filesystem::path dir = std::filesystem::path(PRT_SOURCE_DIR) / "packager/fuzz_corpus";
  std::vector<std::filesystem::path> paths;
  for (const auto& e : std::filesystem::directory_iterator(dir)) paths.push_back(e.path());
  std::sort(paths.begin(), paths.end());
  std::vector<std::vector<uint8_t>> seeds;
  for (const auto& p : paths) {
    std::ifstream in(p, std::ios::binary);
    seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  return seeds;
}

TEST(PrtpackCorruption, SeedCorpusReadsAndMutatedResealedCopiesNeverCrash) {
  const std::vector<std::vector<uint8_t>> seeds = SeedCorpus();
  ASSERT_GE(seeds.size(), 3u);
  for (const auto& s : seeds) {
    testing::FullRead got;
    EXPECT_EQ(TryRead(s, &got), "");
  }
  std::mt19937_64 rng(12345);
  std::size_t read_ok = 0, refused = 0;
  const int kCopies = 3000;
  for (int k = 0; k < kCopies; ++k) {
    std::vector<uint8_t> m = seeds[std::size_t(k) % seeds.size()];
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits && !m.empty(); ++e) {
      const std::size_t at = rng() % m.size();
      switch (rng() % 5) {
        case 0:
          m[at] ^= uint8_t(1u << (rng() % 8));
          break;  // bit flip
        case 1:
          m[at] = uint8_t(rng());
          break;  // random byte
        case 2:
          m[at] = (rng() & 1) ? 0xFF : 0x00;
          break;  // extreme byte
        case 3:
          m.resize(at);
          break;  // truncation
        default:
          m.insert(m.begin() + std::ptrdiff_t(at), uint8_t(rng()));
          break;  // insertion
      }
    }
    if (rng() % 4 != 0) ResealChecksums(m);  // mostly: get past the checksums
    testing::FullRead got;
    (TryRead(m, &got).empty() ? read_ok : refused)++;
  }
  std::printf("prtpack mutation: %d mutated copies, %zu read, %zu refused with InputError\n",
              kCopies, read_ok, refused);
}

}  // namespace
}  // namespace prt::pack
