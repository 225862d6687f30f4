// ranks.cpp: what every Ranks shares (ranks.hpp).
#include "volreel/encoder/ranks.hpp"

#include <cstring>

namespace volreel::encoder {

std::pair<std::size_t, std::size_t> Ranks::share(std::size_t n) const {
  return share_of(n, static_cast<std::size_t>(rank()), static_cast<std::size_t>(size()));
}

std::pair<std::size_t, std::size_t> Ranks::share_of(std::size_t n, std::size_t part,
                                                    std::size_t parts) {
  return {n * part / parts, n * (part + 1) / parts};
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
