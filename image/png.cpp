// png.cpp: 8-bit PNG reading and writing (libpng), see image.hpp.
//
// libpng reports errors by longjmp. The functions that call setjmp (read_png_c, write_png_c)
// hold only trivially destructible locals and are reached through no C++ frame with destructors,
// so a longjmp never skips a destructor; their C++ callers turn the error text into an exception.
#include <png.h>

#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <new>
#include <string>
#include <system_error>
#include <vector>

#include "volreel/datasets/volume.hpp"
#include "volreel/image/image.hpp"

namespace volreel::image {
namespace {

/// State shared with libpng's error callback; trivially destructible, owned by the C++ caller.
struct PngState {
  char message[256] = {};
};

extern "C" void png_error_callback(png_structp png, png_const_charp text) {
  auto* state = static_cast<PngState*>(png_get_error_ptr(png));
  if (state != nullptr) std::snprintf(state->message, sizeof state->message, "%s", text);
  png_longjmp(png, 1);
}

extern "C" void png_warning_callback(png_structp, png_const_charp) {}

/// Where read_png_c puts the image; the vectors are sized by the caller's callback so that no
/// C++ object with a destructor lives in read_png_c's frame.
struct ReadTarget {
  std::vector<std::uint8_t>* pixels;
  std::vector<png_bytep>* rows;
};

/// Sizes target for width × height × channels; false if the memory cannot be had.
bool size_target(const ReadTarget& target, png_uint_32 width, png_uint_32 height,
                 int channels) noexcept {
  try {
    const std::size_t row_bytes =
        static_cast<std::size_t>(width) * static_cast<std::size_t>(channels);
    target.pixels->assign(row_bytes * height, 0);
    target.rows->resize(height);
    for (png_uint_32 y = 0; y < height; ++y)
      (*target.rows)[y] = target.pixels->data() + row_bytes * y;
    return true;
  } catch (const std::bad_alloc&) {
    return false;
  }
}

/// Reads an open PNG file into target as 8-bit gray, gray+alpha, RGB or RGBA. Returns false with
/// state.message set on failure. Only trivially destructible locals: see the file comment.
bool read_png_c(std::FILE* file, PngState& state, const ReadTarget& target, int& width_out,
                int& height_out, int& channels_out) {
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, png_error_callback,
                                           png_warning_callback);
  if (png == nullptr) {
    std::snprintf(state.message, sizeof state.message, "cannot create the libpng reader");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    std::snprintf(state.message, sizeof state.message, "cannot create the libpng info structure");
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_init_io(png, file);
  png_read_info(png, info);

  // 1. Ask libpng for 8 bits per channel: palette -> RGB, low-bit gray -> 8-bit, tRNS -> alpha,
  //    16-bit -> 8-bit rounded (v·255/65535), interlacing undone.
  const int color_type = png_get_color_type(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color_type == PNG_COLOR_TYPE_GRAY && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (png_get_valid(png, info, PNG_INFO_tRNS)) png_set_tRNS_to_alpha(png);
  if (bit_depth == 16) png_set_scale_16(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);

  // 2. Read the pixels and the chunks after them (so a damaged end of file is reported too).
  const png_uint_32 width = png_get_image_width(png, info);
  const png_uint_32 height = png_get_image_height(png, info);
  const int channels = png_get_channels(png, info);
  if (png_get_bit_depth(png, info) != 8 || channels < 1 || channels > 4 ||
      png_get_rowbytes(png, info) !=
          static_cast<std::size_t>(width) * static_cast<std::size_t>(channels) ||
      width > static_cast<png_uint_32>(std::numeric_limits<int>::max()) ||
      height > static_cast<png_uint_32>(std::numeric_limits<int>::max())) {
    std::snprintf(state.message, sizeof state.message,
                  "unsupported layout after conversion to 8 bits");
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  if (!size_target(target, width, height, channels)) {
    std::snprintf(state.message, sizeof state.message, "out of memory for %ux%u pixels", width,
                  height);
    png_destroy_read_struct(&png, &info, nullptr);
    return false;
  }
  png_read_image(png, target.rows->data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  width_out = static_cast<int>(width);
  height_out = static_cast<int>(height);
  channels_out = channels;
  return true;
}

/// Writes image to an open file as an 8-bit PNG; false with state.message set on failure.
bool write_png_c(std::FILE* file, PngState& state, const Image& image, png_bytepp rows) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, png_error_callback,
                                            png_warning_callback);
  if (png == nullptr) {
    std::snprintf(state.message, sizeof state.message, "cannot create the libpng writer");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_write_struct(&png, nullptr);
    std::snprintf(state.message, sizeof state.message, "cannot create the libpng info structure");
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  static constexpr int kColorTypes[5] = {0, PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA,
                                         PNG_COLOR_TYPE_RGB, PNG_COLOR_TYPE_RGB_ALPHA};
  png_init_io(png, file);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width),
               static_cast<png_uint_32>(image.height), 8, kColorTypes[image.channels],
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

/// Closes a FILE* when it goes out of scope (in the C++ callers only).
struct FileCloser {
  std::FILE* file = nullptr;
  ~FileCloser() {
    if (file != nullptr) std::fclose(file);
  }
};

}  // namespace

void validate_image(const Image& image, const std::string& what) {
  if (image.width <= 0 || image.height <= 0 || image.channels < 1 || image.channels > 4) {
    throw InputError(what + ": image is " + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + " with " + std::to_string(image.channels) +
                     " channels; need a positive size and 1 to 4 channels");
  }
  const std::size_t expected = static_cast<std::size_t>(image.width) *
                               static_cast<std::size_t>(image.height) *
                               static_cast<std::size_t>(image.channels);
  if (image.pixels.size() != expected) {
    throw InputError(what + ": image has " + std::to_string(image.pixels.size()) +
                     " bytes of pixels, expected " + std::to_string(expected));
  }
}

Image read_png(const std::filesystem::path& path) {
  FileCloser file{std::fopen(path.c_str(), "rb")};
  if (file.file == nullptr) {
    throw InputError(path.string() + ": cannot open: " + std::strerror(errno));
  }
  png_byte signature[8] = {};
  if (std::fread(signature, 1, sizeof signature, file.file) != sizeof signature ||
      png_sig_cmp(signature, 0, sizeof signature) != 0) {
    throw InputError(path.string() + ": not a PNG file (the 8-byte PNG signature is missing)");
  }
  std::rewind(file.file);

  Image image;
  std::vector<png_bytep> rows;
  PngState state;
  if (!read_png_c(file.file, state, ReadTarget{&image.pixels, &rows}, image.width, image.height,
                  image.channels)) {
    throw InputError(path.string() + ": damaged or unsupported PNG: " + state.message);
  }
  return image;
}

void write_png(const std::filesystem::path& path, const Image& image) {
  validate_image(image, path.string());
  std::filesystem::path temporary = path;
  temporary += ".tmp";
  std::vector<png_bytep> rows(static_cast<std::size_t>(image.height));
  const std::size_t row_bytes =
      static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.channels);
  for (std::size_t y = 0; y < rows.size(); ++y) {
    // libpng's API takes non-const rows but does not write to them.
    rows[y] = const_cast<png_bytep>(image.pixels.data() + row_bytes * y);
  }

  PngState state;
  bool written = false;
  {
    FileCloser file{std::fopen(temporary.c_str(), "wb")};
    if (file.file == nullptr) {
      throw std::runtime_error(path.string() + ": cannot create it (its temporary '" +
                               temporary.filename().string() + "' first): " + std::strerror(errno));
    }
    written = write_png_c(file.file, state, image, rows.data());
    const bool closed = std::fclose(file.file) == 0;
    file.file = nullptr;
    if (written && !closed) {
      std::snprintf(state.message, sizeof state.message, "closing failed: %s",
                    std::strerror(errno));
      written = false;
    }
  }
  if (!written) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw std::runtime_error(path.string() + ": writing the PNG failed: " + state.message);
  }
  std::error_code error;
  std::filesystem::rename(temporary, path, error);
  if (error) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw std::runtime_error(path.string() + ": cannot rename " + temporary.string() +
                             " to it: " + error.message());
  }
}

}  // namespace volreel::image
