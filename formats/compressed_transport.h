// Compressed light transport: the adaptive 4D wavelet form of the transport matrix T
// (Cheslack-Postava et al. 2008, §4) that the farm writes, the packager ships and the viewer
// relights from. Format and algorithm: docs/compression.md.
//
// T has one row per spatial sample and colour channel, and one column per cubemap texel (6·n·n,
// cubemap.h order). With `channels` = 1 one row serves r, g and b; with 3 (interreflection with
// coloured albedos, issue #22) the rows are channel-major: row c·V + v is colour channel c
// (0 r, 1 g, 2 b) of spatial sample v, V = sample_count / channels.
// Rows are 2D wavelet transformed per cubemap face (§4.1), so column j holds, for every spatial
// sample, the coefficient of row-wavelet basis function j. Each column is then a function over
// the spatial domain and is wavelet transformed to its own depth (§4.2), non-linearly
// approximated, scaled by 2^(l·d/2) per column level l (d = segment dimension), normalised and
// dither-quantised (§4.3).
//
// The spatial domain is a list of segments in the global sample order (scene.h): a mesh is a 1D
// signal along the Hilbert order of its vertices, a ground grid or an image is a 2D w×h grid.
// Each segment is transformed on its own; a column's depth is clamped to each segment's maximum.
// With 3 channels the domain is three identical copies of the spatial segments, channel c's at
// offset c·V (PerChannelDomain), so that no column transform mixes two channels.
//
// Decoders here are safe on untrusted input: every count, index and enum is validated, and no
// allocation exceeds what the bytes read can describe. They throw prt::InputError naming `name`.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace prt {

enum class RowWavelet : uint8_t { kHaar = 0, kD4 = 1 };
enum class ColumnWavelet : uint8_t { kLeGall53 = 0, kCdf97 = 1 };
// k2D: row transform only, per-row non-linear approximation (Ng et al. 2003).
// k4D: every column transformed to full depth. kAdaptive4D: per-column depth (§4.2).
// kCpca: clustered PCA of the transformed rows (Sloan et al. 2003; issue #24): not columns at
// all, formats/cpca_transport.h holds its body (a file of this scheme has a CPCA body where the
// others have column blocks; header version 4).
enum class CompressionScheme : uint8_t { k2D = 0, k4D = 1, kAdaptive4D = 2, kCpca = 3 };
// How kCpca was computed (recorded, not needed to decode): Sloan 2003 on every row, or Huang &
// Ramamoorthi 2010 §6's dense pass on the dense vertices and a re-clustering pass on all.
enum class CpcaMethod : uint8_t { kStandard = 0, kDenseRecluster = 1 };
// Which coefficients the non-linear approximation keeps: kColumn, the paper's N terms per
// column (2D: per row); kGlobal, those above one magnitude threshold over the whole matrix.
enum class CompressionBudget : uint8_t { kColumn = 0, kGlobal = 1 };
// How a stored column's terms are coded: kVarint, LEB128 index gaps and `bits`-bit values
// (format version 1); kAdaptiveRice, adaptive Golomb-Rice codes of the index gaps and of the
// value magnitudes, and sign bits (version 2; docs/compression.md).
enum class IndexCoding : uint8_t { kVarint = 0, kAdaptiveRice = 1 };

// Parses "haar"|"d4", "legall53"|"cdf97", "2d"|"4d"|"adaptive4d"|"cpca" (scene.h
// CompressionSettings); throws prt::InputError(file, ...) on anything else.
RowWavelet ParseRowWavelet(const std::string& s, const std::string& file);
ColumnWavelet ParseColumnWavelet(const std::string& s, const std::string& file);
CompressionScheme ParseCompressionScheme(const std::string& s, const std::string& file);
CompressionBudget ParseCompressionBudget(const std::string& s,
                                         const std::string& file);  // column|global
const char* ToString(RowWavelet w);
const char* ToString(ColumnWavelet w);
const char* ToString(CompressionScheme s);
const char* ToString(CompressionBudget b);

// One piece of the spatial domain: `count` consecutive spatial samples of the global order.
struct SpatialSegment {
  enum class Kind : uint8_t { kMesh1D = 0, kGrid2D = 1 };
  Kind kind = Kind::kMesh1D;
  uint32_t count = 0;
  uint32_t width = 0;   // kGrid2D: samples per row (x fastest); width·height == count
  uint32_t height = 0;  // kGrid2D
  // kMesh1D: order[k] = local index (0..count) of the vertex at Hilbert position k; a
  // permutation. Empty means identity. Unused for kGrid2D.
  std::vector<uint32_t> order;
};

struct SpatialDomain {
  std::vector<SpatialSegment> segments;
  std::size_t sample_count() const;
};

// The domain of a `channels` × V row transport (channel-major rows) from the domain of its V
// spatial samples: `channels` copies of `spatial`'s segments, one after the other. channels = 1
// returns `spatial` unchanged. Throws InputError unless channels is 1 or 3.
SpatialDomain PerChannelDomain(const SpatialDomain& spatial, uint32_t channels);
// The first channel's segments of a domain of `channels` copies (the inverse of
// PerChannelDomain; the caller has validated the header).
SpatialDomain SpatialDomainOfChannel(const SpatialDomain& domain, uint32_t channels);

// Largest PCA basis count per cluster a header may declare.
inline constexpr uint32_t kMaxCpcaBases = 256;

// Everything a decoder needs besides the columns.
struct CompressedTransportHeader {
  uint32_t cubemap_n = 32;
  uint32_t sample_count = 0;  // rows of T, channels × V; must equal domain.sample_count()
  // Colour channels of T: 1 (one row per spatial sample serves r, g and b) or 3 (row c·V + v is
  // channel c of spatial sample v). The domain then holds `channels` identical copies of the
  // spatial segments (PerChannelDomain). Format version 3; version 1 and 2 headers read as 1.
  uint32_t channels = 1;
  RowWavelet row_wavelet = RowWavelet::kHaar;
  ColumnWavelet column_wavelet = ColumnWavelet::kLeGall53;
  CompressionScheme scheme = CompressionScheme::kAdaptive4D;
  uint8_t bits = 9;               // quantiser bits, [2, 24]
  double keep_fraction = 0.05;    // non-linear approximation budget (docs/compression.md)
  uint32_t terms_per_column = 0;  // the per-column budget actually used (0: 2D scheme)
  uint64_t dither_seed = 1;       // subtractive dither sequence (compressed_relight.h)
  CompressionBudget budget = CompressionBudget::kColumn;  // recorded, not needed to decode
  // Global budget: a coefficient of a column at row-wavelet level l competes with magnitude
  // |c|·2^(−light_weight·l/2) (docs/compression.md); [0, 16]. Recorded, not needed to decode.
  uint8_t light_weight = 0;
  IndexCoding index_coding = IndexCoding::kAdaptiveRice;
  // Scheme kCpca only (format version 4; formats/cpca_transport.h): clusters K, PCA basis
  // vectors S per cluster, the per-row coefficients' quantiser bits [2, 24] and how the
  // clustering was computed. The basis vectors use `bits` and keep `keep_fraction` of the 6n²
  // terms each; dither_seed seeds the clustering.
  uint32_t cpca_clusters = 0;
  uint32_t cpca_bases = 0;
  uint8_t cpca_coefficient_bits = 16;
  CpcaMethod cpca_method = CpcaMethod::kStandard;
  SpatialDomain domain;

  uint32_t column_count() const { return 6u * cubemap_n * cubemap_n; }
  // V: spatial samples (rows per channel); 0 while `channels` is 0 (an unvalidated header).
  uint32_t spatial_count() const { return channels == 0 ? 0 : sample_count / channels; }
};

// One compressed column: the kept coefficients of column `column` after its column transform to
// `depth`, in the coefficient layout of compressed_relight.h. Value k is
//   c = (q[k] − r(seed, column, index[k])) · scale / (2^(bits−1) − 1) / ScaleFactor(s[index[k]])
// with s = ColumnScaleMap at `depth` (compressed_relight.h): 2^(level·dim/2).
// An all-zero column is not stored at all.
struct CompressedColumn {
  uint32_t column = 0;
  uint8_t depth = 0;
  float scale = 0;              // per-column normalisation: max |ScaleFactor·c| over kept terms
  std::vector<uint32_t> index;  // strictly increasing, < sample_count
  std::vector<int32_t> q;       // non-zero, |q| ≤ 2^(bits−1) − 1
};

// A contiguous range of columns [first_column, first_column + column_span), of which only the
// non-zero ones are stored, sorted by column.
struct CompressedColumnBlock {
  uint32_t first_column = 0;
  uint32_t column_span = 0;
  std::vector<CompressedColumn> columns;
};

struct CompressedTransport {
  CompressedTransportHeader header;
  std::vector<CompressedColumn> columns;  // sorted by column, all-zero columns absent
  std::size_t term_count() const;
};

// Throws prt::InputError(name, ...) if the header is inconsistent (see docs/compression.md),
// among others: channels other than 1 or 3, a sample count that is not a multiple of channels,
// or a domain that is not `channels` identical copies of one channel's segments.
void ValidateHeader(const CompressedTransportHeader& h, const std::string& name);
// Throws if a column breaks any rule above for header h (index order, bounds, q range, depth).
void ValidateColumn(const CompressedTransportHeader& h, const CompressedColumn& c,
                    const std::string& name);

// Binary encodings (little-endian; docs/compression.md). Encoders validate what they write.
std::vector<uint8_t> EncodeHeader(const CompressedTransportHeader& h);
CompressedTransportHeader DecodeHeader(std::span<const uint8_t> bytes, const std::string& name);
std::vector<uint8_t> EncodeColumnBlock(const CompressedTransportHeader& h,
                                       const CompressedColumnBlock& block);
CompressedColumnBlock DecodeColumnBlock(const CompressedTransportHeader& h,
                                        std::span<const uint8_t> bytes, const std::string& name);

// The start every .prtc file has: magic "PRTCTFL1", u32 header bytes, the header. Decode returns
// the header and sets body_offset to the first byte after it (column blocks, or a CPCA body).
std::vector<uint8_t> EncodeCompressedFileStart(const CompressedTransportHeader& h);
CompressedTransportHeader DecodeCompressedFileStart(std::span<const uint8_t> bytes,
                                                    const std::string& name,
                                                    std::size_t& body_offset);

// Whole compressed transport: header, then blocks of `columns_per_block` columns each.
std::vector<uint8_t> EncodeCompressedTransport(const CompressedTransport& t,
                                               uint32_t columns_per_block = 1024);
CompressedTransport DecodeCompressedTransport(std::span<const uint8_t> bytes,
                                              const std::string& name);
// The header of a whole-file encoding, read from the file's first bytes only (the columns are
// neither read nor decoded). Throws InputError naming `path` when it cannot be read or decoded.
CompressedTransportHeader ReadCompressedTransportHeader(const std::string& path);

// The spatial domain's wavelet shape (what a column transform may do with it).
// Segment as a w×h region of the wavelet transform (a mesh is count×1).
void SegmentShape(const SpatialSegment& s, int& w, int& h);

// Largest depth of one segment / of the whole domain (the maximum over segments).
int MaxSegmentDepth(const SpatialSegment& s);
int MaxColumnDepth(const SpatialDomain& d);

}  // namespace prt
