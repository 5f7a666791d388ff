// Clustered-PCA transport (Sloan, Hall, Hart & Snyder 2003; all-frequency from cubemaps as in
// Mahajan et al. 2007 and Huang & Ramamoorthi 2010 §6; issue #24): the third representation of
// T next to the 2D and adaptive 4D columns of compressed_transport.h, written to the same
// run/transport.prtc with a header of scheme kCpca. Format and algorithm: docs/cpca.md.
//
// Every row r of T (channels × V rows, channel-major as in compressed_transport.h), in the
// orthonormal row-wavelet basis of the columns (Haar by default: the basis of the lighting, so
// that T̂·L̂ = T·L), is approximated by its cluster c = cluster_of[r]:
//   T̂_r ≈ m_c + Σ_{i<S} w_{r,i} · u_{c,i}
// with m_c the cluster's mean, u_{c,i} its S basis vectors (PCA of the cluster's rows, then
// truncated to their largest terms and quantised) and w_r the row's S coefficients (least
// squares against the stored basis, quantised per cluster and basis vector).
//
// Relighting (Overbeck et al. 2006 §6.3, Eq. 7–8) projects the lighting on each cluster's mean
// and basis once, P_{c,i} = u_{c,i}·L̂, then each row costs S multiply-adds: B_r = m_c·L̂ +
// Σ_i w_{r,i} P_{c,i} (runtime/cpca_relight.h).
//
// Decoders are safe on untrusted input: every count, index and value is validated and no
// allocation exceeds what the bytes read can describe; they throw prt::InputError naming `name`.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "formats/compressed_transport.h"

namespace prt {

// A sparse, quantised vector over the 6n² row-wavelet coefficients: value k is
//   index[k] ↦ q[k] · scale / (2^(bits−1) − 1)
// with `bits` the header's. An all-zero vector has scale 0 and no terms.
struct CpcaVector {
  float scale = 0;
  std::vector<uint32_t> index;  // strictly increasing, < 6n²
  std::vector<int32_t> q;       // non-zero, |q| ≤ 2^(bits−1) − 1

  std::size_t term_count() const { return index.size(); }
};

struct CpcaCluster {
  CpcaVector mean;
  std::vector<CpcaVector> basis;  // S vectors (empty ones where the cluster has no variance)
  // Per basis vector i: the coefficients' quantiser scale, w = q · scale / (2^(cbits−1) − 1)
  // with cbits = header.cpca_coefficient_bits. 0 when no member uses vector i.
  std::vector<float> coefficient_scale;
};

struct CpcaTransport {
  CompressedTransportHeader header;   // scheme kCpca
  std::vector<uint32_t> cluster_of;   // per row (header.sample_count), < clusters.size()
  std::vector<CpcaCluster> clusters;  // header.cpca_clusters
  std::vector<int32_t> coefficients;  // row-major, rows × S, |q| ≤ 2^(cbits−1) − 1

  uint32_t bases() const { return header.cpca_bases; }
  std::size_t row_count() const { return header.sample_count; }
  // Stored basis and mean terms over all clusters.
  std::size_t term_count() const;
  // Dequantised value of a vector term / a row's coefficient i.
  float Value(const CpcaVector& v, std::size_t k) const;
  float Coefficient(std::size_t row, std::size_t i) const;
};

// Throws InputError(name, ...) unless t is consistent: the header valid with scheme kCpca,
// cluster_of and coefficients of the right sizes, every cluster id < K, every vector and
// coefficient in range (the rules above), finite non-negative scales.
void ValidateCpcaTransport(const CpcaTransport& t, const std::string& name);

// The whole file (the .prtc of scheme cpca): EncodeCompressedFileStart's header, then magic
// "PCPC", and the body of docs/cpca.md. Encode validates what it writes.
std::vector<uint8_t> EncodeCpcaTransport(const CpcaTransport& t);
CpcaTransport DecodeCpcaTransport(std::span<const uint8_t> bytes, const std::string& name);
// The body alone (what follows the header), for the .prtpack section that stores the header
// apart; `h` is the decoded header (scheme kCpca).
std::vector<uint8_t> EncodeCpcaBody(const CpcaTransport& t);
CpcaTransport DecodeCpcaBody(const CompressedTransportHeader& h, std::span<const uint8_t> bytes,
                             const std::string& name);

// The dequantised row r of T̂ (6n² floats): m_c + Σ_i w_{r,i} u_{c,i} (tests, error figures).
void DecodeCpcaRow(const CpcaTransport& t, std::size_t row, std::span<float> out);
// ‖T̂ − T̃‖_F / ‖T̂‖_F with T̃ what t decodes to, row by row (DecodeCpcaRow), and T̂ = rows_hat
// (row_count() × 6n² floats, the row-wavelet basis); ‖T̃‖_F when T̂ = 0. NaN if a decoded value
// is not finite.
double CpcaDecodedRelativeError(const CpcaTransport& t, const float* rows_hat);

}  // namespace prt
