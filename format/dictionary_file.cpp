// dictionary_file.cpp: writing and checking dictionary files (format/SPEC.md, "Dictionary file").
#include "volreel/format/dictionary_file.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::format {

namespace {

std::string hex32(std::uint32_t value) {
  char text[16];
  std::snprintf(text, sizeof text, "0x%08X", value);
  return text;
}

std::string quoted_bytes(const char* bytes, std::size_t n) {
  std::string text = "\"";
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(bytes[i]);
    if (c >= 32 && c < 127) {
      text += static_cast<char>(c);
    } else {
      char esc[8];
      std::snprintf(esc, sizeof esc, "\\x%02X", c);
      text += esc;
    }
  }
  return text + "\"";
}

std::uint16_t to_half_bits(float value) {
  return Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(value));
}
float from_half_bits(std::uint16_t bits) {
  return static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(bits));
}

}  // namespace

DictionaryFile with_half_atoms(DictionaryFile d) {
  if (d.half_atoms) return d;
  d.half_atoms = true;
  const std::size_t generated = d.dct_atoms ? block_dct_atoms(d.block_size).size() : std::size_t{0};
  for (std::size_t i = 0; i + generated < d.atoms.size(); ++i)
    d.atoms[i] = from_half_bits(to_half_bits(d.atoms[i]));
  return d;
}

DictionaryFile container_dictionary(DictionaryFile d, bool half) {
  if (half) d = with_half_atoms(std::move(d));
  return with_dct_atoms(std::move(d));
}

std::vector<double> block_dct_phi(std::uint32_t block_size) {
  const std::uint32_t n = block_size;
  std::vector<double> phi(std::size_t{n} * n);
  for (std::uint32_t u = 0; u < n; ++u)
    for (std::uint32_t x = 0; x < n; ++x)
      phi[u * n + x] = std::sqrt((u == 0 ? 1.0 : 2.0) / n) *
                       std::cos(std::numbers::pi * (2.0 * x + 1.0) * u / (2.0 * n));
  return phi;
}

std::vector<std::array<std::uint32_t, 3>> block_dct_frequencies(std::uint32_t block_size) {
  const std::uint32_t n = block_size;
  std::vector<std::array<std::uint32_t, 3>> frequencies;
  for (std::uint32_t total = 1; n > 0 && total <= 3 * (n - 1); ++total)
    for (std::uint32_t w = 0; w < n; ++w)
      for (std::uint32_t v = 0; v < n; ++v) {
        if (w + v > total || total - w - v >= n) continue;
        frequencies.push_back({total - w - v, v, w});
      }
  return frequencies;
}

std::vector<float> block_dct_atoms(std::uint32_t block_size) {
  const std::uint32_t n = block_size;
  const std::vector<double> phi = block_dct_phi(n);
  std::vector<float> atoms;
  atoms.reserve(std::size_t{n} * n * n * (std::size_t{n} * n * n - (n > 0 ? 1 : 0)));
  for (const auto& [u, v, w] : block_dct_frequencies(n))
    for (std::uint32_t z = 0; z < n; ++z)
      for (std::uint32_t y = 0; y < n; ++y)
        for (std::uint32_t x = 0; x < n; ++x)
          atoms.push_back(static_cast<float>(phi[u * n + x] * phi[v * n + y] * phi[w * n + z]));
  return atoms;
}

DictionaryFile dct_dictionary(std::uint32_t block_size, const std::string& program_version) {
  DictionaryFile d;
  d.block_size = block_size;
  d.atom_count = 0;
  d.program_version = program_version;
  return with_dct_atoms(std::move(d));
}

DictionaryFile with_dct_atoms(DictionaryFile d) {
  if (d.dct_atoms) return d;
  const std::vector<float> dct = block_dct_atoms(d.block_size);
  const std::uint64_t m = std::uint64_t{d.block_size} * d.block_size * d.block_size;
  const std::uint64_t total = d.atom_count + (m > 0 ? m - 1 : 0);
  if (total > dictionary_max_atoms)
    throw FormatError("<memory>", "atom count " + std::to_string(total) +
                                      " with the DCT basis is over " +
                                      std::to_string(dictionary_max_atoms));
  d.atoms.insert(d.atoms.end(), dct.begin(), dct.end());
  d.atom_count = static_cast<std::uint32_t>(total);
  d.dct_atoms = true;
  return d;
}

std::vector<std::byte> serialize_dictionary_file(const DictionaryFile& d) {
  const std::filesystem::path memory = "<memory>";
  const std::uint64_t m = std::uint64_t{d.block_size} * d.block_size * d.block_size;
  if (d.block_size == 0 || d.block_size > dictionary_max_block_size)
    throw FormatError(memory, "block size " + std::to_string(d.block_size) + " is outside 1.." +
                                  std::to_string(dictionary_max_block_size));
  if (d.atom_count == 0 || d.atom_count > dictionary_max_atoms)
    throw FormatError(memory, "atom count " + std::to_string(d.atom_count) + " is outside 1.." +
                                  std::to_string(dictionary_max_atoms));
  if (d.atoms.size() != d.atom_count * m)
    throw FormatError(memory, std::to_string(d.atoms.size()) + " atom values for " +
                                  std::to_string(d.atom_count) + " atoms of " + std::to_string(m) +
                                  " values");
  // The generated DCT atoms are not stored; a reader makes them again, so they must be exactly
  // block_dct_atoms(M).
  const std::vector<float> dct = d.dct_atoms ? block_dct_atoms(d.block_size) : std::vector<float>{};
  const std::uint32_t stored = d.atom_count - static_cast<std::uint32_t>(dct.size() / m);
  if (d.dct_atoms && (d.atom_count < dct.size() / m ||
                      !std::equal(dct.begin(), dct.end(),
                                  d.atoms.end() - static_cast<std::ptrdiff_t>(dct.size()))))
    throw FormatError(memory,
                      "a dictionary marked with the DCT basis needs its learned atoms (none or "
                      "more) followed by exactly block_dct_atoms(M)");
  if (d.program_version.size() > 15)
    throw FormatError(memory,
                      "program version '" + d.program_version + "' is longer than 15 characters");

  DictionaryFileHeader h{};
  std::memcpy(h.magic, dictionary_magic.data(), sizeof h.magic);
  h.format_version = dictionary_format_version;
  h.header_bytes = sizeof(DictionaryFileHeader);
  h.atom_count = stored;
  h.block_size = d.block_size;
  h.atom_length = static_cast<std::uint32_t>(m);
  h.max_sparsity = d.training.max_sparsity;
  h.tolerance = d.training.tolerance;
  h.value_min = d.training.value_min;
  h.value_max = d.training.value_max;
  h.coreset_voxels = d.training.coreset_voxels;
  h.coreset_levels = d.training.coreset_levels;
  h.iterations = d.training.iterations;
  h.seed = d.training.seed;
  h.flags = (d.training.flat ? dictionary_flag_flat : 0u) |
            (d.half_atoms ? dictionary_flag_half : 0u) | (d.dct_atoms ? dictionary_flag_dct : 0u);
  h.training_frames = d.training.training_frames;
  h.rms_error = d.training.rms_error;
  h.mean_sparsity = d.training.mean_sparsity;
  std::memcpy(h.program_version, d.program_version.data(), d.program_version.size());
  h.container_id = d.container_id;

  std::vector<std::byte> bytes(dictionary_file_size(stored, m, d.half_atoms));
  std::memcpy(bytes.data(), &h, sizeof h);
  const std::size_t stored_values = std::size_t{stored} * m;
  if (d.half_atoms) {
    for (std::size_t i = 0; i < stored_values; ++i) {
      const std::uint16_t bits = to_half_bits(d.atoms[i]);
      std::memcpy(bytes.data() + sizeof h + 2 * i, &bits, 2);
    }
  } else {
    if (stored_values > 0)
      std::memcpy(bytes.data() + sizeof h, d.atoms.data(), stored_values * sizeof(float));
  }
  const std::size_t crc_offset = bytes.size() - sizeof(std::uint32_t);
  const std::uint32_t crc = crc32c(std::span(bytes.data(), crc_offset));
  std::memcpy(bytes.data() + crc_offset, &crc, sizeof crc);
  return bytes;
}

DictionaryFile parse_dictionary_file(std::span<const std::byte> bytes,
                                     const std::filesystem::path& name) {
  // 1. The header must be there before any field is looked at.
  if (bytes.size() < sizeof(DictionaryFileHeader))
    throw FormatError(name, bytes.size(),
                      "a dictionary file of at least " +
                          std::to_string(sizeof(DictionaryFileHeader)) + " bytes (its header)",
                      "end of file (truncated: " + std::to_string(bytes.size()) + " bytes)");
  DictionaryFileHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);

  // 2. Identity and version.
  if (std::memcmp(h.magic, dictionary_magic.data(), sizeof h.magic) != 0)
    throw FormatError(
        name, 0,
        "magic " + quoted_bytes(dictionary_magic.data(), 8) + " (a volreel dictionary file)",
        quoted_bytes(h.magic, 8));
  if (h.format_version != dictionary_format_version)
    throw FormatError(name, offsetof(DictionaryFileHeader, format_version),
                      "dictionary format version " + std::to_string(dictionary_format_version),
                      "version " + std::to_string(h.format_version));
  if (h.header_bytes != sizeof(DictionaryFileHeader))
    throw FormatError(name, offsetof(DictionaryFileHeader, header_bytes),
                      "header size " + std::to_string(sizeof(DictionaryFileHeader)),
                      std::to_string(h.header_bytes));

  // 3. Header consistency, before sizes derived from it are trusted.
  // No stored atom is allowed only with the DCT basis (a dictionary of generated atoms alone).
  const bool dct_only_allowed = (h.flags & dictionary_flag_dct) != 0;
  if ((h.atom_count == 0 && !dct_only_allowed) || h.atom_count > dictionary_max_atoms)
    throw FormatError(name, offsetof(DictionaryFileHeader, atom_count),
                      std::string("atom count in ") + (dct_only_allowed ? "0.." : "1..") +
                          std::to_string(dictionary_max_atoms),
                      std::to_string(h.atom_count));
  if (h.block_size == 0 || h.block_size > dictionary_max_block_size)
    throw FormatError(name, offsetof(DictionaryFileHeader, block_size),
                      "block size in 1.." + std::to_string(dictionary_max_block_size),
                      std::to_string(h.block_size));
  const std::uint64_t m = std::uint64_t{h.block_size} * h.block_size * h.block_size;
  if (h.atom_length != m)
    throw FormatError(name, offsetof(DictionaryFileHeader, atom_length),
                      "atom length " + std::to_string(m) + " (block size " +
                          std::to_string(h.block_size) + " cubed)",
                      std::to_string(h.atom_length));
  if ((h.flags & ~(dictionary_flag_flat | dictionary_flag_half | dictionary_flag_dct)) != 0)
    throw FormatError(name, offsetof(DictionaryFileHeader, flags),
                      "flags with only bits 0, 1 and 2 defined", hex32(h.flags));
  // With the DCT basis the codes index K + M³ − 1 atoms, at most dictionary_max_atoms.
  if (dct_only_allowed && h.atom_count + (m - 1) > dictionary_max_atoms)
    throw FormatError(name, offsetof(DictionaryFileHeader, atom_count),
                      "atom count in 0.." + std::to_string(dictionary_max_atoms - (m - 1)) + " (" +
                          std::to_string(m - 1) + " DCT atoms follow them)",
                      std::to_string(h.atom_count));
  const bool half = (h.flags & dictionary_flag_half) != 0;
  const std::size_t value_bytes = half ? 2 : sizeof(float);

  // 4. Size: header + atoms + CRC, exactly.
  const std::uint64_t expected = dictionary_file_size(h.atom_count, m, half);
  const char* const value_type = half ? "binary16" : "float32";
  if (bytes.size() < expected)
    throw FormatError(name, bytes.size(),
                      std::to_string(expected) + " bytes (128-byte header, " +
                          std::to_string(h.atom_count) + " atoms of " + std::to_string(m) + " " +
                          value_type + ", 4-byte CRC)",
                      "end of file (truncated: " + std::to_string(bytes.size()) + " bytes)");
  if (bytes.size() > expected)
    throw FormatError(name, expected, "end of file after " + std::to_string(expected) + " bytes",
                      std::to_string(bytes.size() - expected) + " extra bytes");

  // 5. Checksum over everything before it.
  const std::size_t crc_offset = static_cast<std::size_t>(expected) - sizeof(std::uint32_t);
  std::uint32_t stored;
  std::memcpy(&stored, bytes.data() + crc_offset, sizeof stored);
  const std::uint32_t computed = crc32c(bytes.first(crc_offset));
  if (stored != computed)
    throw FormatError(
        name, crc_offset,
        "CRC-32C " + hex32(computed) + " of bytes 0.." + std::to_string(crc_offset - 1),
        "stored " + hex32(stored) + " (the file is corrupt)");

  // 6. Atoms, which must be finite (a CRC does not catch a writer that wrote NaN).
  DictionaryFile d;
  d.block_size = h.block_size;
  d.atom_count = h.atom_count;
  d.half_atoms = half;
  d.atoms.resize(static_cast<std::size_t>(h.atom_count * m));
  if (half) {
    for (std::size_t i = 0; i < d.atoms.size(); ++i) {
      std::uint16_t bits;
      std::memcpy(&bits, bytes.data() + sizeof h + 2 * i, 2);
      d.atoms[i] = from_half_bits(bits);
    }
  } else if (!d.atoms.empty()) {  // none stored: the DCT basis alone
    std::memcpy(d.atoms.data(), bytes.data() + sizeof h, d.atoms.size() * sizeof(float));
  }
  for (std::size_t i = 0; i < d.atoms.size(); ++i)
    if (!std::isfinite(d.atoms[i]))
      throw FormatError(name, sizeof h + i * value_bytes,
                        std::string("a finite ") + value_type + " (atom " + std::to_string(i / m) +
                            ", value " + std::to_string(i % m) + ")",
                        number_text(d.atoms[i]));

  // 7. Every stored atom of unit norm (binary16 rounding moves a norm by less than 1e-3).
  for (std::size_t a = 0; a < h.atom_count; ++a) {
    double norm = 0;
    for (std::size_t v = 0; v < m; ++v) {
      const double x = static_cast<double>(d.atoms[a * m + v]);
      norm += x * x;
    }
    norm = std::sqrt(norm);
    if (!(std::abs(norm - 1) <= 1e-2))
      throw FormatError(name, sizeof h + a * m * value_bytes,
                        "atom " + std::to_string(a) + " of unit L2 norm (within 0.01)",
                        "norm " + number_text(norm));
  }

  if ((h.flags & dictionary_flag_dct) != 0) d = with_dct_atoms(std::move(d));
  d.container_id = h.container_id;

  d.training.tolerance = h.tolerance;
  d.training.value_min = h.value_min;
  d.training.value_max = h.value_max;
  d.training.max_sparsity = h.max_sparsity;
  d.training.coreset_voxels = h.coreset_voxels;
  d.training.coreset_levels = h.coreset_levels;
  d.training.iterations = h.iterations;
  d.training.seed = h.seed;
  d.training.flat = (h.flags & dictionary_flag_flat) != 0;
  d.training.training_frames = h.training_frames;
  d.training.rms_error = h.rms_error;
  d.training.mean_sparsity = h.mean_sparsity;
  d.program_version.assign(h.program_version, strnlen(h.program_version, sizeof h.program_version));
  return d;
}

void write_dictionary_file(const std::filesystem::path& path, const DictionaryFile& dictionary) {
  const auto bytes = serialize_dictionary_file(dictionary);
  // Folders that do not exist yet are made, as for a container (detail::check_writable found
  // that they can be).
  if (path.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(path.parent_path(), ec);
    if (ec)
      throw FormatError(
          path, "cannot create its folder '" + path.parent_path().string() + "': " + ec.message());
  }
  detail::write_file_atomically(path, bytes);
}

DictionaryFile read_dictionary_file(const std::filesystem::path& path) {
  const auto bytes = detail::read_whole_file(path, detail::max_dictionary_bytes);
  return parse_dictionary_file(bytes, path);
}

}  // namespace volreel::format
