#include "viewer/npy_writer.h"

#include <bit>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <stdexcept>

#include "vocabulary/errors.h"

namespace prt {

std::vector<char> EncodeNpyFloat32(std::span<const float> data, std::size_t rows,
                                   std::size_t cols) {
  if (data.size() != rows * cols)
    throw std::invalid_argument("EncodeNpyFloat32: " + std::to_string(data.size()) +
                                " values for shape (" + std::to_string(rows) + ", " +
                                std::to_string(cols) + ")");
  static_assert(std::endian::native == std::endian::little, "npy writer assumes little-endian");
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" +
                       std::to_string(rows) + ", " + std::to_string(cols) + "), }";
  // magic (6) + version (2) + length (2) + header + '\n' ≡ 0 (mod 64).
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  // Built with resize + memcpy (GCC 12's stringop-overflow misfires on vector::insert here).
  const auto len = static_cast<uint16_t>(header.size());
  std::vector<char> out(10 + header.size() + 4 * data.size());
  std::memcpy(out.data(), "\x93NUMPY", 6);
  out[6] = 1;
  out[7] = 0;
  out[8] = static_cast<char>(len & 0xff);
  out[9] = static_cast<char>(len >> 8);
  std::memcpy(out.data() + 10, header.data(), header.size());
  if (!data.empty()) std::memcpy(out.data() + 10 + header.size(), data.data(), 4 * data.size());
  return out;
}

void WriteNpyFloat32(const std::string& path, std::span<const float> data, std::size_t rows,
                     std::size_t cols) {
  const std::vector<char> bytes = EncodeNpyFloat32(data, rows, cols);
  // Written to path.tmp and renamed, so that a failed write (a full disk) keeps an earlier file.
  const std::string tmp = path + ".tmp";
  std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
  if (!f) throw InputError(path, std::string("cannot be written: ") + std::strerror(errno));
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  f.close();
  if (!f) {
    const int e = errno;
    std::remove(tmp.c_str());
    throw InputError(path, std::string("write failed: ") + std::strerror(e));
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    throw InputError(path, std::string("cannot rename the temporary file: ") + std::strerror(e));
  }
}

}  // namespace prt
