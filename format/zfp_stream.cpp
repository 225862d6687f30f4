// zfp_stream.cpp: see zfp_stream.hpp.
#include "volreel/format/zfp_stream.hpp"

#include <zfp.h>

#include <new>

namespace volreel::format {

struct ZfpStream::Objects {
  zfp_stream* zfp = nullptr;
  zfp_field* field = nullptr;
  ~Objects() {
    if (field) zfp_field_free(field);
    if (zfp) zfp_stream_close(zfp);
  }

  /// Runs `code` with a bit stream over buffer[0, size) attached and rewound; returns its result.
  template <typename Code>
  std::size_t with_bits(void* buffer, std::size_t size, Code code) {
    bitstream* bits = stream_open(buffer, size);
    if (bits == nullptr) return 0;
    zfp_stream_set_bit_stream(zfp, bits);
    zfp_stream_rewind(zfp);
    const std::size_t result = code();
    zfp_stream_set_bit_stream(zfp, nullptr);
    stream_close(bits);
    return result;
  }
};

ZfpStream::ZfpStream(ZfpMode mode, std::size_t nx, std::size_t ny, std::size_t nz)
    : objects_(std::make_unique<Objects>()) {
  objects_->zfp = zfp_stream_open(nullptr);
  objects_->field = zfp_field_3d(nullptr, zfp_type_float, nx, ny, nz);
  if (objects_->zfp == nullptr || objects_->field == nullptr) throw std::bad_alloc();
  if (mode.kind == ZfpMode::Kind::accuracy)
    zfp_stream_set_accuracy(objects_->zfp, mode.parameter);
  else
    zfp_stream_set_rate(objects_->zfp, mode.parameter, zfp_type_float, 3, zfp_false);
}

ZfpStream::~ZfpStream() = default;

std::size_t ZfpStream::maximum_size() const {
  return zfp_stream_maximum_size(objects_->zfp, objects_->field);
}

std::size_t ZfpStream::compress(const float* values, void* out, std::size_t capacity) {
  // zfp only reads the field when compressing; its API takes a non-const pointer.
  zfp_field_set_pointer(objects_->field, const_cast<float*>(values));
  return objects_->with_bits(out, capacity,
                             [&] { return zfp_compress(objects_->zfp, objects_->field); });
}

std::size_t ZfpStream::decompress(const void* in, std::size_t size, float* values) {
  zfp_field_set_pointer(objects_->field, values);
  // zfp only reads the bit stream when decompressing; its API takes a non-const pointer.
  return objects_->with_bits(const_cast<void*>(in), size,
                             [&] { return zfp_decompress(objects_->zfp, objects_->field); });
}

}  // namespace volreel::format
