// NumPy .npy output (format version 1.0, https://numpy.org/neps/nep-0001-npy-format.html): the
// magic "\x93NUMPY", version 1.0, a little-endian uint16 header length, a Python dict literal
// {'descr': '<f4', 'fortran_order': False, 'shape': (rows, cols), } padded with spaces and a
// newline so that the data starts at a multiple of 64 bytes, then the float32 data row-major.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

namespace prt {

// The bytes of a rows × cols little-endian float32 .npy v1.0 file. Throws std::invalid_argument
// when data.size() != rows·cols.
std::vector<char> EncodeNpyFloat32(std::span<const float> data, std::size_t rows, std::size_t cols);
// Writes them to `path`; throws prt::InputError naming the file when it cannot be written.
void WriteNpyFloat32(const std::string& path, std::span<const float> data, std::size_t rows,
                     std::size_t cols);

}  // namespace prt
