// Transparent huge pages for large, freshly allocated buffers: the farm's transposer blocks and
// exchange buffers, the viewer's dequantised terms. On the development VM a first touch of fresh
// memory costs far more than the copy into it (page faults through the hypervisor and the
// kernel's page clearing: 1 GiB copied into fresh 4 KiB pages 6.7 s, into 2 MiB pages 1.8 s;
// docs/farm-compression.md), and the compression phase touches the raw matrix's size of fresh
// memory two or three times. Linux only; elsewhere, and where THP is off, a no-op.
#pragma once

#include <cstddef>
#include <vector>

namespace prt {

// madvise(MADV_HUGEPAGE) on the 2 MiB-aligned part of [data, data + bytes). Contents are kept
// (the advice never discards memory); best used before the first touch, when the kernel can
// back each whole 2 MiB piece with one huge page at its first fault. Returns true when the
// advice was given (some aligned 2 MiB piece exists and the kernel accepted it).
bool AdviseHugePages(void* data, std::size_t bytes);

// When `v` cannot hold n elements without reallocating: drops its contents and reserves n
// elements of fresh memory, advised for huge pages before their first touch (AdviseHugePages).
// Otherwise leaves `v` as it is. For buffers the caller then overwrites (resize, assign).
template <class T>
void ReserveFreshHuge(std::vector<T>& v, std::size_t n) {
  if (v.capacity() >= n) return;
  std::vector<T>().swap(v);
  v.reserve(n);
  AdviseHugePages(v.data(), v.capacity() * sizeof(T));
}

}  // namespace prt
