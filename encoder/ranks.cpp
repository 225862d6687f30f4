// ranks.cpp: what every Ranks shares (ranks.hpp).
#include "volreel/encoder/ranks.hpp"

#include <cstring>

namespace volreel::encoder {

std::pair<std::size_t, std::size_t> Ranks::share(std::size_t n) const {
  const auto r = static_cast<std::size_t>(rank()), p = static_cast<std::size_t>(size());
  return {n * r / p, n * (r + 1) / p};
}

double Ranks::broadcast_value(double value) const {
  std::vector<std::byte> bytes(sizeof value);
  std::memcpy(bytes.data(), &value, sizeof value);
  broadcast(bytes);
  std::memcpy(&value, bytes.data(), sizeof value);
  return value;
}

const Ranks& single_process() {
  static const SingleProcess one;
  return one;
}

}  // namespace volreel::encoder
