// Large image buffers on transparent huge pages where the kernel offers them (an internal header
// of the render module).
//
// A fresh image buffer is faulted in 4 KiB at a time, and the kernel zeroes every page: about a
// quarter of a 1280 x 720 render's CPU time went there (issue 33). With transparent huge pages in
// "madvise" mode (Debian's default) a range marked MADV_HUGEPAGE before its first touch is
// faulted in 2 MiB at a time instead (512 times fewer faults; the same bytes). The advice covers
// the 2 MiB-aligned part of the buffer; where the kernel has no THP, madvise fails and nothing
// changes. The values are the same either way: only where the pages come from changes.
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace lensopt {

inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

// Advises huge pages over the 2 MiB-aligned pages inside [data, data + bytes).
inline void advise_huge_pages(void* data, std::size_t bytes) {
#ifdef MADV_HUGEPAGE
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t first = (begin + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const std::uintptr_t last = (begin + bytes) & ~(kHugePageBytes - 1);
  if (last > first) madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE);
#else
  (void)data;
  (void)bytes;
#endif
}

// v.assign(n, value), with huge pages advised before the values are written when v must grow
// by at least two huge pages (smaller buffers gain nothing).
template <typename T>
void resize_with_huge_pages(std::vector<T>& v, std::size_t n, T value = T()) {
  if (n > v.capacity() && n * sizeof(T) >= 2 * kHugePageBytes) {
    std::vector<T>().swap(v);
    v.reserve(n);  // allocated, not touched
    advise_huge_pages(v.data(), n * sizeof(T));
  }
  v.assign(n, value);
}

}  // namespace lensopt
