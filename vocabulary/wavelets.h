// Wavelet transforms that every stage speaks: the row transform of the transport matrix and the
// lighting (2D on each cubemap face), and the column transform over the spatial domain (1D or 2D
// on an image / ground-plane grid). See docs/wavelets.md for the conventions in one page.
//
// Filters (all orthonormal or √2-normalised, so that coefficient energies are comparable across
// levels, which the non-linear approximations of Ng et al. 2003 and the adaptive-depth search of
// Cheslack-Postava et al. 2008 §4.2 rely on):
//   kHaar        orthonormal Haar; squares n×n, n a power of two (Ng et al. 2003).
//   kDaubechies4 orthonormal Daubechies-4 with PERIODIC extension; n a power of two. Exact
//                orthonormality on every power-of-two length (at length 2 it reduces to Haar).
//   kLeGall53    LeGall 5/3 (JPEG 2000 reversible filter, real-valued) by lifting.
//   kCdf97       CDF 9/7 (JPEG 2000 irreversible filter) by lifting.
// The two lifting filters use whole-sample symmetric extension and work on ANY length (odd too)
// and on any rectangle w×h. Their low band is scaled to DC gain √2 and the high band to Nyquist
// gain √2 per 1D step (the orthonormal Haar scaling), which makes CDF 9/7 nearly orthonormal.
//
// Layout (Mallat / non-standard decomposition, Ng et al. 2003, Overbeck et al. 2006 §5.1): one
// step on a region of size w×h splits it, by one horizontal then one vertical 1D step, into
//   LL = [0, ⌈w/2⌉) × [0, ⌈h/2⌉)      HL = [⌈w/2⌉, w) × [0, ⌈h/2⌉)   (horizontal detail)
//   LH = [0, ⌈w/2⌉) × [⌈h/2⌉, h)      HH = [⌈w/2⌉, w) × [⌈h/2⌉, h)
// (x = column, y = row, data[y·w + x]); the next step recurses on LL only. In 1D a step on the
// prefix of length m puts the low part at [0, ⌈m/2⌉) and the high part at [⌈m/2⌉, m). A 1D
// step on a length-1 axis is the identity.
//
// Depth, step, level:
//   depth k  number of steps applied, 0 (identity) … max depth. After depth k the low part has
//            size SizeAtDepth(w, k) × SizeAtDepth(h, k), with SizeAtDepth(m, k) = ⌈m / 2^k⌉.
//   step t   the single step from depth t−1 to depth t (t = 1 … max); it acts on the LL region
//            of size SizeAtDepth(·, t−1). Inverse step t goes from depth t back to depth t−1
//            (the single-step inverse S'_{l→l+1} of Cheslack-Postava et al. Eq. 5–8).
//   level    of a coefficient in a depth-k transform: 0 for the scaling (low) part, 1 for the
//            coarsest detail (made by step k) … k for the finest detail (made by step 1). For
//            a fully transformed Haar face of size n this is 0 = scaling, 1 = coarsest …
//            log2 n = finest, as in Ng et al. 2003 / Overbeck et al. 2006.
//
// Cost: every transform converts the touched region to double once, runs all its steps in
// double, and converts back; temporary storage comes from a WaveletWorkspace that only grows
// (no allocation once it is large enough). Use one workspace per thread; the default argument
// is a thread_local workspace. Invalid sizes, depths and steps throw std::invalid_argument
// (programming errors, never caused by user input).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "vocabulary/wavelet_filter.h"

namespace prt {

class CubemapLayout;

// Orientation of a 2D coefficient; kLL is the scaling (low) part.
enum class WaveletBand : std::uint8_t { kLL = 0, kHL = 1, kLH = 2, kHH = 3 };

// Scratch memory for the transforms: grows to the largest request, never shrinks.
class WaveletWorkspace {
 public:
  // At least `count` doubles, valid until the next call.
  double* Doubles(std::size_t count) {
    if (buffer_.size() < count) buffer_.resize(count);
    return buffer_.data();
  }
  std::size_t capacity() const { return buffer_.size(); }

 private:
  std::vector<double> buffer_;
};

// The calling thread's own workspace (the default argument of every transform).
WaveletWorkspace& ThreadWaveletWorkspace();

// ---- sizes, depths, levels (the same for every filter) -------------------------------------

// ⌈length / 2^depth⌉, for length ≥ 1, depth ≥ 0.
inline int SizeAtDepth(int length, int depth) {
  return depth >= 31 ? 1 : ((length - 1) >> depth) + 1;
}
// Largest depth of a 1D transform of `length` samples: ⌈log2 length⌉ (0 for length 1). For
// Haar and D4 the length must be a power of two (throws otherwise); then it is log2 length.
int WaveletMaxDepth(WaveletFilter filter, int length);
// Largest depth of a 2D transform: ⌈log2 max(w, h)⌉ for lifting filters; Haar and D4 need
// w == h, a power of two.
int WaveletMaxDepth2D(WaveletFilter filter, int width, int height);

// Sizes made by step t (1-based) of a 1D transform.
struct WaveletStep1D {
  int step;    // t
  int length;  // size of the part the step acts on, SizeAtDepth(N, t−1)
  int low;     // ⌈length/2⌉, stored at [0, low)
  int high;    // ⌊length/2⌋, stored at [low, length)
};
std::vector<WaveletStep1D> WaveletSteps1D(int length, int depth);

// Sizes made by step t (1-based) of a 2D transform: the region width×height splits into
// LL low_width×low_height, HL high_width×low_height, LH low_width×high_height,
// HH high_width×high_height (any of them may be empty when a side is 1).
struct WaveletStep2D {
  int step;
  int width, height;
  int low_width, low_height;
  int high_width, high_height;
};
std::vector<WaveletStep2D> WaveletSteps2D(int width, int height, int depth);

// Level of coefficient `index` of a length-N signal transformed to depth k (see top of file):
// 0 = scaling part, 1 = coarsest detail … k = finest detail.
int CoefficientLevel1D(int length, int depth, int index);
// Fills levels[0 … length) with CoefficientLevel1D for every index, in O(length).
void CoefficientLevelMap1D(int length, int depth, std::uint8_t* levels);

struct CoefficientClass {
  int level;         // 0 = scaling, 1 = coarsest detail … depth = finest
  WaveletBand band;  // kLL exactly when level == 0
};
// Level and band of coefficient (x, y) of a w×h region transformed to depth k.
CoefficientClass CoefficientClass2D(int width, int height, int depth, int x, int y);
// Fills levels[y·w + x] with the level of every coefficient, in O(w·h).
void CoefficientLevelMap2D(int width, int height, int depth, std::uint8_t* levels);

// ---- transforms ------------------------------------------------------------------------------
// All in place on float data, computed in double. `depth` ∈ [0, max depth], `step` ∈ [1, max].

// 1D: data[0 … length). Haar and D4 need a power-of-two length.
void ForwardWavelet1D(WaveletFilter filter, float* data, int length, int depth,
                      WaveletWorkspace& ws = ThreadWaveletWorkspace());
void InverseWavelet1D(WaveletFilter filter, float* data, int length, int depth,
                      WaveletWorkspace& ws = ThreadWaveletWorkspace());

// One single 1D step t on the prefix SizeAtDepth(length, t−1): Forward takes depth t−1 to t,
// Inverse takes depth t back to t−1 (for 1D column transforms and Eq. 8 relighting).
void ForwardWavelet1DStep(WaveletFilter filter, float* data, int length, int step,
                          WaveletWorkspace& ws = ThreadWaveletWorkspace());
void InverseWavelet1DStep(WaveletFilter filter, float* data, int length, int step,
                          WaveletWorkspace& ws = ThreadWaveletWorkspace());

// 2D non-standard decomposition of a row-major width×height array (data[y·width + x]).
// Haar and D4 need width == height, a power of two (a cubemap face).
void ForwardWavelet2D(WaveletFilter filter, float* data, int width, int height, int depth,
                      WaveletWorkspace& ws = ThreadWaveletWorkspace());
void InverseWavelet2D(WaveletFilter filter, float* data, int width, int height, int depth,
                      WaveletWorkspace& ws = ThreadWaveletWorkspace());
// One single step t: Forward takes depth t−1 to depth t, Inverse takes depth t to depth t−1
// (Cheslack-Postava et al. Eq. 8 applies one inverse step per level to the accumulated image).
// Only the region SizeAtDepth(width, t−1) × SizeAtDepth(height, t−1) is read or written.
void ForwardWavelet2DStep(WaveletFilter filter, float* data, int width, int height, int step,
                          WaveletWorkspace& ws = ThreadWaveletWorkspace());
void InverseWavelet2DStep(WaveletFilter filter, float* data, int width, int height, int step,
                          WaveletWorkspace& ws = ThreadWaveletWorkspace());

// The same inverse step t on a width×height region whose elements are `channels` interleaved
// floats (data[(y·width + x)·channels + c]), computed in float for all channels at once: the
// runtime's Eq. 8 (runtime/compressed_relight.h), where a step runs once per level per frame
// and float keeps well inside the 9-bit quantisation of the terms it sums. The double transforms
// above stay the reference. `scratch` holds at least width·height·channels floats.
void InverseWavelet2DStepInterleaved(WaveletFilter filter, float* data, int width, int height,
                                     int channels, int step, float* scratch);

// Inverse step t of a 1D signal of `length` elements (`channels` interleaved floats each) whose
// low band (the first ⌈len/2⌉ elements of the len = SizeAtDepth(length, t − 1) being
// synthesised) is at `low` and whose high band (the next ⌊len/2⌋) is at `high`, written to
// out[0, len): the same numbers as InverseWavelet2DStepInterleaved on a length×1 region, without
// its copy back. `out` may be `high − ⌈len/2⌉·channels` (the high band's own buffer, whose low
// band then lives elsewhere), so a caller can alternate two buffers from step to step
// (Cheslack-Postava et al. 2008 §4.5 Eq. 8 in runtime/compressed_relight.cpp). LeGall 5/3
// with 1 or 4 channels only (InverseWavelet1DStepSplitSupported).
bool InverseWavelet1DStepSplitSupported(WaveletFilter filter, int channels);
void InverseWavelet1DStepSplit(WaveletFilter filter, const float* low, const float* high,
                               float* out, int length, int channels, int step);
// The 4-channel LeGall 5/3 synthesis above and in InverseWavelet2DStepInterleaved runs two
// elements per 256-bit vector where the CPU has AVX (the same bits as the 128-bit code). For
// tests and benchmarks: turns that off (or back on where available); returns the old setting.
bool SetWaveletAvx(bool enable);

// A whole cubemap vector, 6·n² floats in the layout face·n² + y·n + x (vocabulary/cubemap.h),
// each face transformed independently by the 2D transform above.
void ForwardWaveletCubemap(WaveletFilter filter, float* data, int n, int depth,
                           WaveletWorkspace& ws = ThreadWaveletWorkspace());
void InverseWaveletCubemap(WaveletFilter filter, float* data, int n, int depth,
                           WaveletWorkspace& ws = ThreadWaveletWorkspace());

// Haar shorthands for a face (n×n, n a power of two) and a cubemap vector.
inline void ForwardHaarFace(float* face, int n, int depth,
                            WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  ForwardWavelet2D(WaveletFilter::kHaar, face, n, n, depth, ws);
}
inline void InverseHaarFace(float* face, int n, int depth,
                            WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  InverseWavelet2D(WaveletFilter::kHaar, face, n, n, depth, ws);
}
inline void ForwardHaarFaceStep(float* face, int n, int step,
                                WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  ForwardWavelet2DStep(WaveletFilter::kHaar, face, n, n, step, ws);
}
inline void InverseHaarFaceStep(float* face, int n, int step,
                                WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  InverseWavelet2DStep(WaveletFilter::kHaar, face, n, n, step, ws);
}
inline void ForwardHaarCubemap(float* data, int n, int depth,
                               WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  ForwardWaveletCubemap(WaveletFilter::kHaar, data, n, depth, ws);
}
inline void InverseHaarCubemap(float* data, int n, int depth,
                               WaveletWorkspace& ws = ThreadWaveletWorkspace()) {
  InverseWaveletCubemap(WaveletFilter::kHaar, data, n, depth, ws);
}

// ---- Haar coefficient supports on a cubemap face (NWA area weighting, PBI bands) -------------

// The face texels a Haar coefficient (x, y) of an n×n face transformed to depth k depends on:
// the square [x0, x0+side) × [y0, y0+side). Level-ℓ details (ℓ ≥ 1) have side n / 2^(ℓ−1)
// at full depth; scaling coefficients have side 2^k.
struct HaarSupport {
  int x0, y0, side;
};
HaarSupport HaarCoefficientSupport(int n, int depth, int x, int y);
// Support area in texels: side².
inline long long HaarSupportTexels(int n, int depth, int x, int y) {
  const HaarSupport s = HaarCoefficientSupport(n, depth, x, y);
  return static_cast<long long>(s.side) * s.side;
}
// Support area in steradians (sum of the exact solid angles of the texels it covers) of the
// coefficient with cubemap index face·n² + y·n + x; n = layout.n().
double HaarSupportSolidAngle(const CubemapLayout& layout, int depth, std::size_t index);
// The same for every coefficient of the cubemap vector (6·n² values, same index layout).
std::vector<double> HaarSupportSolidAngles(const CubemapLayout& layout, int depth);

}  // namespace prt
