// Byte layout of a .prtpack file (docs/prtpack-format.md): constants and field offsets shared by
// the writer, the reader and the fuzz harness; their values are read and written with
// vocabulary/bytes.h (LoadAt, StoreAt: little-endian, bounds-checked).
// Internal to packager/: applications use prtpack_reader.h or prtpack.h.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/bytes.h"

namespace prt::pack {

inline constexpr std::array<uint8_t, 8> kMagic = {0x89, 'P', 'R', 'T', 'P', 'A', 'C', 'K'};
inline constexpr uint16_t kVersionMajor = 1;
// The newest minor version this code reads and writes. 1.1 defines the TRNS channel count
// (kTransportChannels); a pack that does not need it (no transport, or a one-channel transport)
// is written as 1.0, byte-identical to what 1.0 writers wrote.
// 1.2 adds the IMGE section (image relighting, kTypeImage), written only by packs that have one.
// 1.3 adds the CPCA section (clustered-PCA transport, kTypeCpca), written only by packs that have
// one (instead of TRNS).
inline constexpr uint16_t kVersionMinor = 6;
inline constexpr uint16_t kVersionMinorChannels = 1;
inline constexpr uint16_t kVersionMinorImage = 2;
inline constexpr uint16_t kVersionMinorCpca = 3;
// 1.4: an IMGE section holding PRTIMG02 (glossy pixels: per-mesh weights,
// docs/image-relighting.md).
inline constexpr uint16_t kVersionMinorGlossyPixels = 4;
// 1.5: an IMGE section holding PRTIMG03 (supersampled pixels: per-pixel coverage and weights,
// docs/image-relighting.md, "Supersampling"); a 1.4 reader refuses its magic.
inline constexpr uint16_t kVersionMinorSupersampled = 5;
// 1.6: a GLSY section (glossy vertex transport, docs/glossy-transport.md): the BRDF factor table
// whose m terms the TRNS/CPCA rows hold (m × V rows, term-major).
inline constexpr uint16_t kVersionMinorGlossyTerms = 6;
inline constexpr uint32_t kHeaderSize = 64;
inline constexpr uint32_t kEntrySize = 64;
inline constexpr uint32_t kDefaultAlignment = 64;
inline constexpr uint32_t kMaxSectionCount = 65536;
inline constexpr uint32_t kMaxMeshNameLength = 4096;
inline constexpr uint32_t kMaxTransportParams = 1u << 30;
inline constexpr uint32_t kTransportHeaderSize = 40;
// TRNS header field offsets.
inline constexpr std::size_t kTransportEncoding = 0, kTransportBlockCount = 4,
                             kTransportRowCount = 8, kTransportColumnCount = 16,
                             kTransportParamsSize = 24,
                             kTransportChannels = 28,  // 1.1; reserved (0) in 1.0
    kTransportIndexChecksum = 32;
inline constexpr uint32_t kBlockEntrySize = 48;
// CPCA (1.3) decoded payload: a 32-byte header, the encoded CompressedTransportHeader (params),
// then the EncodeCpcaBody bytes (formats/cpca_transport.h) to the end.
inline constexpr uint32_t kCpcaHeaderSize = 32;
inline constexpr std::size_t kCpcaParamsSize = 0, kCpcaChannels = 4, kCpcaRowCount = 8,
                             kCpcaClusters = 16, kCpcaBases = 20, kCpcaBodySize = 24;
inline constexpr uint32_t kMaterialHeaderSize = 24;
// A MESH may declare at most this many raw bytes per stored byte (plus 4 KiB).
inline constexpr uint64_t kMaxMeshExpansion = 256;

// Header field offsets.
inline constexpr std::size_t kHdrMajor = 8, kHdrMinor = 10, kHdrHeaderSize = 12,
                             kHdrSectionCount = 16, kHdrEntrySize = 20, kHdrTableOffset = 24,
                             kHdrFileSize = 32, kHdrAlignment = 40, kHdrFlags = 44,
                             kHdrReserved = 48, kHdrChecksum = 56;
// Section entry field offsets.
inline constexpr std::size_t kSecType = 0, kSecFlags = 4, kSecCodec = 8, kSecId = 12,
                             kSecOffset = 16, kSecStored = 24, kSecRaw = 32, kSecChecksum = 40;

inline constexpr uint32_t kFlagCritical = 1u;
inline constexpr uint32_t kMaterialFlagGround = 1u;

enum class Codec : uint32_t { kNone = 0, kZstd = 1, kDraco = 2 };

inline constexpr uint32_t FourCC(const char (&s)[5]) {
  return uint32_t(uint8_t(s[0])) | uint32_t(uint8_t(s[1])) << 8 | uint32_t(uint8_t(s[2])) << 16 |
         uint32_t(uint8_t(s[3])) << 24;
}
inline constexpr uint32_t kTypeMeta = FourCC("META");
inline constexpr uint32_t kTypeMesh = FourCC("MESH");
inline constexpr uint32_t kTypeMaterial = FourCC("MATL");
inline constexpr uint32_t kTypeTransport = FourCC("TRNS");
inline constexpr uint32_t kTypeVisibility = FourCC("VISB");
// Image relighting (1.2): the camera and each pixel's mesh, formats/image_file.h's bytes; CRITICAL
// (a reader that does not know it would take pixel rows for vertex rows).
inline constexpr uint32_t kTypeImage = FourCC("IMGE");
// Clustered-PCA transport (1.3, issue #24): instead of TRNS, the CpcaTransport of
// formats/cpca_transport.h; CRITICAL (a reader that skipped it would take the pack for one
// without transport, or relight its visibility alone).
inline constexpr uint32_t kTypeCpca = FourCC("CPCA");
// Glossy vertex transport (1.6, issue #39): formats/glossy_factors.h's bytes without the f tables;
// CRITICAL (a reader that skipped it would take m × V term rows for V vertex rows).
inline constexpr uint32_t kTypeGlossy = FourCC("GLSY");

inline std::string FourCCString(uint32_t v) {
  std::string s(4, ' ');
  for (int i = 0; i < 4; ++i) {
    const auto c = static_cast<char>((v >> (8 * i)) & 0xFF);
    s[static_cast<std::size_t>(i)] = (c >= 32 && c < 127) ? c : '?';
  }
  return s;
}

inline constexpr uint64_t AlignUp(uint64_t v, uint64_t a) {
  return (v + a - 1) / a * a;
}

// XXH64 (seed 0) of bytes; of the header's first 56 bytes followed by the section table.
uint64_t Checksum(const uint8_t* data, std::size_t size);
uint64_t HeaderChecksum(const uint8_t* header, const uint8_t* table, std::size_t table_size);
// XXH64 of a TRNS section's bytes 0..31, its parameters and its block index (the caller has
// checked that index_offset + block_count * 48 lies inside the section).
uint64_t TransportIndexChecksum(const uint8_t* section, std::size_t params_size,
                                std::size_t index_offset, std::size_t block_count);

// Recomputes every checksum of a (possibly damaged) pack wherever its structure allows: block
// checksums and the index checksum of TRNS, every section checksum, then the header checksum.
// Safe on any bytes (ranges are checked; what is out of range is left alone). For tests and
// fuzzing, so that a mutated file reaches the decoders behind the checksums.
void ResealChecksums(std::vector<uint8_t>& file);

}  // namespace prt::pack
