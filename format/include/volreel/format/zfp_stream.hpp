// zfp_stream.hpp: zfp compression of one 3D float field, the zfp objects (stream, field, bit
// stream) owned by one object — the container's zfp bricks, the zfp reference codec of the
// benchmarks and their tests all go through it.
#pragma once

#include <cstddef>
#include <memory>

namespace volreel::format {

/// How zfp trades size for error.
struct ZfpMode {
  enum class Kind { accuracy, rate };
  Kind kind = Kind::accuracy;
  double parameter = 0;  ///< accuracy: absolute error tolerance; rate: bits per value

  static ZfpMode accuracy(double tolerance) { return {Kind::accuracy, tolerance}; }
  static ZfpMode rate(double bits_per_value) { return {Kind::rate, bits_per_value}; }
};

/// A zfp stream for fields of nx × ny × nz floats (x fastest), in one mode. Not copyable.
class ZfpStream {
 public:
  ZfpStream(ZfpMode mode, std::size_t nx, std::size_t ny, std::size_t nz);
  ~ZfpStream();
  ZfpStream(const ZfpStream&) = delete;
  ZfpStream& operator=(const ZfpStream&) = delete;

  /// The most bytes compress() can write.
  std::size_t maximum_size() const;

  /// Compresses `values` into out[0, capacity); returns the bytes written, 0 when zfp fails.
  /// `capacity` should be maximum_size().
  std::size_t compress(const float* values, void* out, std::size_t capacity);

  /// Decompresses the stream in[0, size) into `values`; returns the bytes zfp consumed, 0 when it
  /// fails. zfp reads without bounds checks: a stream that is not trusted needs maximum_size()
  /// readable bytes (pad a copy), and a consumed count beyond `size` means it was too short.
  std::size_t decompress(const void* in, std::size_t size, float* values);

 private:
  struct Objects;
  std::unique_ptr<Objects> objects_;
};

}  // namespace volreel::format
