// bytes.hpp: a plain value appended to a byte buffer as it lies in memory (little-endian: every
// volreel file and message is, and volreel builds only where the machine is).
#pragma once

#include <bit>
#include <cstddef>
#include <cstring>
#include <type_traits>
#include <vector>

namespace volreel::format::detail {

static_assert(std::endian::native == std::endian::little, "volreel's bytes are little-endian");

template <class T>
void append_value(std::vector<std::byte>& out, const T& value) {
  static_assert(std::is_trivially_copyable_v<T>);
  const std::size_t at = out.size();
  out.resize(at + sizeof(T));
  std::memcpy(out.data() + at, &value, sizeof(T));
}

}  // namespace volreel::format::detail
