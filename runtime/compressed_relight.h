// Relighting B = T·L straight from adaptively compressed columns (Cheslack-Postava et al. 2008
// §4.5, Eq. 8): the viewer's side of formats/compressed_transport.h, on the column coding both
// ends share (formats/column_coding.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "formats/column_coding.h"
#include "formats/compressed_transport.h"

namespace prt {

// Where a relight's per-sample outputs go. kSamples: global sample order (meshes in order, each
// mesh's vertices in its file's order). kCoefficients: the depth-0 coefficient layout, i.e. each
// mesh segment's vertices along its Hilbert order (position k of a segment holds its vertex
// order[k]) and each grid in row-major order: the order the inverse steps leave X in, so that the
// way back is a sequential copy instead of a gather through the permutation. A renderer that
// remaps its vertex buffers once at load (CompressedRelighter::coefficient_of_sample()) then
// takes the relit radiance as it comes (docs/viewer.md, "Relighting speed").
enum class SampleOrder : uint8_t { kSamples, kCoefficients };

// Relighting from adaptively compressed columns (§4.5, Eq. 8). Construction dequantises every
// term once and groups columns by depth; Relight then computes, per channel,
//   B = Σ_l S'_{l→l−1}( Σ_{j∈N(l)} L̂_j · C_j )
// by adding the lights of depth-l columns into one column-wavelet-domain buffer per channel
// (float) and running one single-step inverse per level from the deepest level down (one full
// inverse transform in all, whatever the number of lights); the terms no earlier inverse step
// touches are added in one pass before the first step (RelightLights). Parallel inside
// (vocabulary/parallel.h: the scatter over tiles of coefficients, from 2^15 terms; the inverse
// steps and, below 4 MB of X, the gather back to sample order run on the calling thread, where X is
// cached). Thread-compatible (const methods are safe to call from several threads with separate
// outputs).
//
// Colour channels of T (formats/compressed_transport.h): with a one-channel transport every
// lighting channel c relights the same rows, B_c = T̂·L̂_c. With a 3-channel transport (rows
// channel-major, row c·V + v is colour channel c of spatial sample v) the lighting must have 3
// channels and B_c(v) = Σ_j T̂[c·V + v][j]·L̂_c[j]. The channels' segments are copies, so X is
// the same V samples × 4 floats: a term of channel c adds to lane c of its sample only, and the
// inverse steps and the way back are a one-channel frame's; a frame costs a one-channel frame
// plus the scatter of the extra terms (about 3× as many). Either way the outputs have
// sample_count() = V values per channel.
//
// Non-finite values (docs/viewer.md, "NaN and Inf"): every dequantised term must be a finite float
// (InputError naming `name` and the column otherwise; the pack reader's checks, a finite scale and
// |q| ≤ A, leave only a scale within 0.4 % of FLT_MAX to fail here). X accumulates in float, so
// finite lights of finite terms can still overflow it; a relight whose output would hold a NaN or
// Inf throws NumericalError naming `name` and the sample instead (found at no cost in frames that
// are finite: X is scanned for NaN/Inf as the gather copies it back to sample order).
class CompressedRelighter {
 public:
  // `name` names the transport (the pack's path) in errors.
  explicit CompressedRelighter(const CompressedTransport& t,
                               std::string name = "CompressedRelighter");

  const std::string& name() const { return name_; }
  const CompressedTransportHeader& header() const { return header_; }
  // Spatial samples V: the values per channel of every output.
  std::size_t sample_count() const { return spatial_; }
  // Rows of T (channels × V) and T's colour channels (1 or 3).
  std::size_t row_count() const { return header_.sample_count; }
  uint32_t channels() const { return header_.channels; }
  std::size_t column_count() const { return header_.column_count(); }
  // Depth chosen for a column (0 for absent/all-zero columns); -1 when absent.
  int ColumnDepth(uint32_t column) const;
  // Stored terms of a column (0 for absent columns).
  std::size_t ColumnTermCount(uint32_t column) const;
  // Bytes held: the dequantised terms (8 per term), the tables, the per-frame buffers pooled.
  std::size_t memory_bytes() const;

  // Sample (global order, V of them) → its position in the depth-0 coefficient layout, the
  // position its radiance takes in SampleOrder::kCoefficients outputs (the same in every colour
  // channel: the channels' segments are copies).
  std::span<const uint32_t> coefficient_of_sample() const { return coefficient_of_sample_; }

  // Dense lighting in the row-wavelet basis: lighting_hat = channels × column_count floats,
  // radiance = channels × sample_count floats (channel-major, samples in `order`), B = T̂·L̂ per
  // channel. A 3-channel transport needs channels = 3 (std::invalid_argument otherwise).
  void Relight(std::span<const float> lighting_hat, int channels, std::span<float> radiance,
               SampleOrder order = SampleOrder::kSamples) const;
  // Sparse lighting (a non-linear lighting approximation): terms (columns[k], weights[k·channels
  // + c]); columns need not be sorted; duplicates add.
  void RelightSparse(std::span<const uint32_t> columns, std::span<const float> weights,
                     int channels, std::span<float> radiance,
                     SampleOrder order = SampleOrder::kSamples) const;
  // The same, into one double array of sample_count() values per channel (out[c]), with no
  // intermediate float image: what the viewer's TransportOperator accumulates into. Added to
  // out[c]'s values, or with `assign` written over them (out[c] need not be initialised).
  void RelightSparseAdd(std::span<const uint32_t> columns, std::span<const float> weights,
                        int channels, std::span<double* const> out,
                        SampleOrder order = SampleOrder::kSamples, bool assign = false) const;
  // A region of interest: RelightSparseAdd's values at positions [first, first + count) of the
  // SampleOrder::kCoefficients order only (out[c] has sample_count() entries; only the range is
  // read or written), equal to RelightSparseAdd's to float rounding. For a host that splits a
  // frame into ranges across its threads (prt_runtime_relight_range): safe to call concurrently
  // for any ranges, each with its own buffers.
  // Its cost is the range's share of the frame where the column wavelet is LeGall 5/3 or
  // CDF 9/7 (RangesAreLocal): only the terms and the inverse steps' windows that reach the range
  // are computed (a grid segment's windows are bands of whole rows). With the periodic Haar and
  // D4 it computes the whole frame and copies the range out.
  void RelightSparseAddRange(std::span<const uint32_t> columns, std::span<const float> weights,
                             int channels, std::size_t first, std::size_t count,
                             std::span<double* const> out, bool assign = false) const;
  // Whether RelightSparseAddRange computes only its range.
  bool RangesAreLocal() const;

 private:
  // A column's terms in two parts (see RelightLights): those no inverse step deeper than the
  // column's depth touches, in terms_ (every term of a depth-0 column), and the rest, the
  // low-band coefficients of segments transformed below their maximum depth, in late_terms_.
  struct Column {
    uint8_t depth;
    uint32_t begin, end;            // range in terms_
    uint32_t late_begin, late_end;  // range in late_terms_
  };
  struct Light;
  // Where a frame's radiance goes: channel-major floats, or added into per-channel doubles.
  struct Output {
    float* radiance = nullptr;
    double* const* add = nullptr;
    SampleOrder order = SampleOrder::kSamples;
    bool assign = false;  // with `add`: write instead of adding
  };
  void RelightLights(std::vector<Light>& lights, int channels, Output out) const;
  // RelightSparseAddRange's local frame: positions [first, last) into out[c] (RangesAreLocal).
  void RelightLightsRange(std::vector<Light>& lights, int channels, std::size_t first,
                          std::size_t last, double* const* out, bool assign) const;
  // What a range needs, worked out once per range (the inverse steps' windows, where each
  // column's terms in them begin and end) and kept for the next frames: see the .cpp.
  struct RangePlan;
  std::shared_ptr<const RangePlan> PlanRange(std::size_t first, std::size_t last) const;
  std::shared_ptr<const RangePlan> BuildRangePlan(std::size_t first, std::size_t last) const;
  template <class Index>
  static void Copy(std::size_t lo, std::size_t hi, const float* base, const Index& index,
                   std::size_t C, std::size_t K, std::size_t S, const Output& out);
  // Throws std::invalid_argument unless `channels` lighting channels can relight this transport.
  void CheckChannels(int channels, const char* what) const;
  // Throws the NumericalError for the first non-finite output value.
  [[noreturn]] void ThrowNonFinite(int channels, const Output& out) const;

  std::string name_;
  std::vector<Light> LightsOf(std::span<const uint32_t> columns, std::span<const float> weights,
                              int channels) const;

  CompressedTransportHeader header_;
  std::size_t spatial_ = 0;  // V = rows / channels
  int max_depth_ = 0;
  std::vector<int32_t> slot_;  // column → index into columns_, or −1
  // Sample (global order) → its coefficient in the depth-0 layout (the Hilbert order's inverse).
  std::vector<uint32_t> coefficient_of_sample_;
  std::vector<Column> columns_;
  // Each segment of the domain as the relighter uses it, derived once from the header: its
  // coefficient range [lo, hi) in the global order, its w×h shape (a mesh is count×1) and its
  // maximum depth. A 3-channel transport's channel 0 segments only (X's V samples).
  struct Segment {
    std::size_t lo, hi;
    int w, h, max_depth;
  };
  std::vector<Segment> segments_;
  // A stored term: coefficient index and dequantised value side by side, so that a column is
  // one sequential stream of 8-byte terms.
  struct Term {
    uint32_t index;
    float value;
  };
  std::vector<Term> terms_;
  std::vector<Term> late_terms_;
  // X is scattered tile by tile: tile_ consecutive coefficients (16,384, 256 KB of X with three
  // channels, so that every term's read-modify-write stays within L2 of the core that owns
  // the tile), all of a depth's lights per tile.
  // tile_offsets_[(slot·P + c)·(tiles_ + 1) + t], P = T's colour channels, is the first term
  // of column `slot` whose index is at least c·V + t·tile_ (entry tiles_: at least (c + 1)·V;
  // the last one is the column's end).
  std::size_t tile_ = 0, tiles_ = 0;
  std::vector<uint32_t> tile_offsets_;
  // Per-frame buffers (X and the inverse steps' scratch), kept between frames: a fresh
  // allocation of this size is mmap'ed and page-faulted in every frame. A pool, not one pair,
  // since concurrent Relight calls (and a thread that runs another relight while it waits in a
  // parallel loop) each need their own.
  struct FrameBuffers {
    std::vector<float> x, scratch;
    // RelightLightsRange: the second low-band buffer, where each segment's low band is, and
    // the copy of a window's bands for filters without a split step.
    std::vector<float> scratch2;
    std::vector<uint8_t> range_at;
    std::vector<float> range_tmp;
    std::vector<bool> low_in_scratch;  // per segment: its low band lives in `scratch`
  };
  std::unique_ptr<FrameBuffers> TakeBuffers() const;
  void ReturnBuffers(std::unique_ptr<FrameBuffers> b) const;
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<FrameBuffers>> pool_;
  // The last ranges' plans, the most recently used last (at most kRangePlans of them).
  mutable std::mutex range_mutex_;
  mutable std::vector<std::shared_ptr<const RangePlan>> range_plans_;
};

}  // namespace prt
