// dictionary_file_test.cpp: the dictionary file round-trips, is little-endian with the layout of
// format/SPEC.md, and every truncation, flipped byte or bad field gives a FormatError that names
// the file and the offset, never a crash.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "test_util.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"

namespace {

using namespace volreel::format;

DictionaryFile small_dictionary(std::uint32_t M = 2, std::uint32_t K = 3) {
  DictionaryFile d;
  d.block_size = M;
  d.atom_count = K;
  volreel::SplitMix64 rng(11);
  d.atoms.resize(std::size_t{K} * M * M * M);
  for (float& v : d.atoms) v = static_cast<float>(rng.normal());
  const std::size_t m = std::size_t{M} * M * M;
  for (std::size_t a = 0; a < K; ++a) {  // unit atoms, as the reader requires
    double norm = 0;
    for (std::size_t v = 0; v < m; ++v)
      norm += std::pow(static_cast<double>(d.atoms[a * m + v]), 2);
    for (std::size_t v = 0; v < m; ++v)
      d.atoms[a * m + v] =
          static_cast<float>(static_cast<double>(d.atoms[a * m + v]) / std::sqrt(norm));
  }
  d.training.tolerance = 0.125;
  d.training.value_min = -3.5;
  d.training.value_max = 7.25;
  d.training.max_sparsity = 15;
  d.training.coreset_voxels = 1234567;
  d.training.coreset_levels = 6;
  d.training.iterations = 8;
  d.training.seed = 0x0123456789ABCDEFull;
  d.training.flat = true;
  d.training.training_frames = 16;
  d.training.rms_error = 0.01;
  d.training.mean_sparsity = 3.5;
  d.program_version = "0.1.0";
  return d;
}

std::uint32_t u32_at(const std::vector<std::byte>& b, std::size_t offset) {
  return std::to_integer<std::uint32_t>(b[offset]) |
         std::to_integer<std::uint32_t>(b[offset + 1]) << 8 |
         std::to_integer<std::uint32_t>(b[offset + 2]) << 16 |
         std::to_integer<std::uint32_t>(b[offset + 3]) << 24;
}

/// Expects parse to throw a FormatError whose message contains `fragment`; returns the error's
/// offset.
std::uint64_t expect_error(const std::vector<std::byte>& bytes, const std::string& fragment) {
  try {
    parse_dictionary_file(bytes, "test.bin");
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("test.bin"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    return e.offset();
  }
  ADD_FAILURE() << "no error; expected one mentioning '" << fragment << "'";
  return 0;
}

/// Rewrites the CRC so that a deliberately bad field is what the reader sees first.
void fix_crc(std::vector<std::byte>& bytes) {
  const std::size_t at = bytes.size() - 4;
  const std::uint32_t crc = crc32c(std::span(bytes.data(), at));
  std::memcpy(bytes.data() + at, &crc, 4);
}

TEST(DictionaryFile, RoundTripsThroughAFile) {
  volreel::test::TempDir dir("dictfile");
  const DictionaryFile d = small_dictionary();
  write_dictionary_file(dir / "dictionary.bin", d);
  EXPECT_FALSE(
      std::filesystem::exists(dir.path() / ("dictionary.bin.tmp-" + std::to_string(getpid()))));
  const DictionaryFile r = read_dictionary_file(dir / "dictionary.bin");
  EXPECT_EQ(r.block_size, d.block_size);
  EXPECT_EQ(r.atom_count, d.atom_count);
  EXPECT_EQ(r.atoms, d.atoms);
  EXPECT_EQ(r.training.tolerance, d.training.tolerance);
  EXPECT_EQ(r.training.value_min, d.training.value_min);
  EXPECT_EQ(r.training.value_max, d.training.value_max);
  EXPECT_EQ(r.training.max_sparsity, d.training.max_sparsity);
  EXPECT_EQ(r.training.coreset_voxels, d.training.coreset_voxels);
  EXPECT_EQ(r.training.coreset_levels, d.training.coreset_levels);
  EXPECT_EQ(r.training.iterations, d.training.iterations);
  EXPECT_EQ(r.training.seed, d.training.seed);
  EXPECT_EQ(r.training.flat, d.training.flat);
  EXPECT_EQ(r.training.training_frames, d.training.training_frames);
  EXPECT_EQ(r.training.rms_error, d.training.rms_error);
  EXPECT_EQ(r.training.mean_sparsity, d.training.mean_sparsity);
  EXPECT_EQ(r.program_version, d.program_version);
  EXPECT_EQ(std::filesystem::file_size(dir / "dictionary.bin"), dictionary_file_size(3, 8));
}

TEST(DictionaryFile, IsLittleEndianWithTheSpecifiedLayout) {
  const DictionaryFile d = small_dictionary(2, 3);
  const auto b = serialize_dictionary_file(d);
  ASSERT_EQ(b.size(), 128u + 3 * 8 * 4 + 4);
  EXPECT_EQ(std::memcmp(b.data(), "VREELDIC", 8), 0);
  EXPECT_EQ(u32_at(b, 8), 1u);            // format version
  EXPECT_EQ(u32_at(b, 12), 128u);         // header bytes
  EXPECT_EQ(u32_at(b, 16), 3u);           // K
  EXPECT_EQ(u32_at(b, 20), 2u);           // M
  EXPECT_EQ(u32_at(b, 24), 8u);           // m
  EXPECT_EQ(u32_at(b, 28), 15u);          // Smax
  EXPECT_EQ(u32_at(b, 72), 0x89ABCDEFu);  // seed, low word first
  EXPECT_EQ(u32_at(b, 76), 0x01234567u);
  EXPECT_EQ(u32_at(b, 80), 1u);                   // flags: flat
  EXPECT_EQ(std::to_integer<char>(b[104]), '0');  // program version
  std::uint32_t first_atom_bits;
  std::memcpy(&first_atom_bits, &d.atoms[0], 4);
  EXPECT_EQ(u32_at(b, 128), first_atom_bits);
  EXPECT_EQ(u32_at(b, b.size() - 4), crc32c(std::span(b.data(), b.size() - 4)));
}

TEST(DictionaryFile, EveryTruncationIsAClearError) {
  const auto good = serialize_dictionary_file(small_dictionary());
  for (std::size_t n = 0; n < good.size(); ++n) {
    const std::vector<std::byte> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    if (n < 8) {
      expect_error(cut, "truncated");
      continue;
    }
    // Past the magic the error may be the header check or the size check, but always an error.
    try {
      parse_dictionary_file(cut, "test.bin");
      ADD_FAILURE() << "a file cut to " << n << " bytes was accepted";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("test.bin"), std::string::npos);
    }
  }
  expect_error(std::vector<std::byte>(good.begin(), good.end() - 1), "truncated");
}

TEST(DictionaryFile, EveryFlippedByteIsDetected) {
  const auto good = serialize_dictionary_file(small_dictionary());
  for (std::size_t i = 0; i < good.size(); ++i) {
    auto bad = good;
    bad[i] ^= std::byte{0x40};
    EXPECT_THROW(parse_dictionary_file(bad, "test.bin"), FormatError) << "byte " << i;
  }
  auto bad = good;
  bad[200] ^= std::byte{1};  // inside the atoms: only the CRC can tell
  EXPECT_EQ(expect_error(bad, "CRC-32C"), good.size() - 4);
}

TEST(DictionaryFile, HalfAtomsRoundTripAndTakeHalfTheBytes) {
  const DictionaryFile original = small_dictionary(3, 4);
  const DictionaryFile half = with_half_atoms(original);
  ASSERT_TRUE(half.half_atoms);
  ASSERT_EQ(half.atoms.size(), original.atoms.size());
  for (std::size_t i = 0; i < half.atoms.size(); ++i) {
    // binary16 keeps 11 significant bits: rounding errs by at most 2^-11 of the value (normals).
    EXPECT_LE(std::abs(half.atoms[i] - original.atoms[i]), std::abs(original.atoms[i]) * 0x1p-11f)
        << i;
  }
  EXPECT_NE(half.atoms, original.atoms);               // something was rounded
  EXPECT_EQ(with_half_atoms(half).atoms, half.atoms);  // and rounding again changes nothing
  const auto bytes = serialize_dictionary_file(half);
  EXPECT_EQ(bytes.size(), dictionary_file_size(4, 27, true));
  EXPECT_EQ(bytes.size(), 128u + 2 * 4 * 27 + 4);
  EXPECT_EQ(u32_at(bytes, 80), dictionary_flag_flat | dictionary_flag_half);
  const DictionaryFile back = parse_dictionary_file(bytes, "half.bin");
  EXPECT_TRUE(back.half_atoms);
  EXPECT_EQ(back.atoms, half.atoms);  // exactly what the encoder coded against
  // Serializing unrounded atoms with the flag stores the same rounded values.
  DictionaryFile flagged = original;
  flagged.half_atoms = true;
  EXPECT_EQ(serialize_dictionary_file(flagged), bytes);
  // Damage: every truncation and every flipped byte is an error; the flag off makes the size wrong.
  for (std::size_t n = 0; n < bytes.size(); ++n)
    EXPECT_THROW(
        parse_dictionary_file(
            std::vector<std::byte>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n)),
            "half.bin"),
        FormatError)
        << n;
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    auto bad = bytes;
    bad[i] ^= std::byte{0x40};
    EXPECT_THROW(parse_dictionary_file(bad, "half.bin"), FormatError) << "byte " << i;
  }
  auto unflagged = bytes;
  const std::uint32_t flags = dictionary_flag_flat;
  std::memcpy(unflagged.data() + 80, &flags, 4);
  fix_crc(unflagged);
  expect_error(unflagged, "float32");
  // An infinity in binary16 is refused like a non-finite float32.
  auto infinite = bytes;
  const std::uint16_t inf = 0x7C00;
  std::memcpy(infinite.data() + 128 + 2 * 5, &inf, 2);
  fix_crc(infinite);
  EXPECT_EQ(expect_error(infinite, "finite binary16"), 128u + 2 * 5);
}

TEST(DictionaryFile, BadFieldsNameTheirOffset) {
  const auto good = serialize_dictionary_file(small_dictionary());
  auto bad = good;
  std::memcpy(bad.data(), "NOTADICT", 8);
  EXPECT_EQ(expect_error(bad, "magic"), 0u);

  bad = good;
  const std::uint32_t version = 99;
  std::memcpy(bad.data() + 8, &version, 4);
  fix_crc(bad);
  EXPECT_EQ(expect_error(bad, "version 99"), 8u);

  bad = good;
  const std::uint32_t atom_length = 9;
  std::memcpy(bad.data() + 24, &atom_length, 4);
  fix_crc(bad);
  EXPECT_EQ(expect_error(bad, "atom length"), 24u);

  bad = good;
  const std::uint32_t huge = 0xFFFFFFFFu;
  std::memcpy(bad.data() + 16, &huge, 4);
  EXPECT_EQ(expect_error(bad, "atom count"), 16u);

  // With the DCT basis appended the codes index K + M³ − 1 atoms: a K that pushes them past
  // 65536 is refused at the count, not after the file is read.
  bad = good;
  std::uint32_t flags = 0, block = 0;
  std::memcpy(&flags, bad.data() + 80, 4);
  std::memcpy(&block, bad.data() + 20, 4);
  flags |= dictionary_flag_dct;
  std::memcpy(bad.data() + 80, &flags, 4);
  const std::uint32_t too_many = dictionary_max_atoms - (block * block * block - 1) + 1;
  std::memcpy(bad.data() + 16, &too_many, 4);
  fix_crc(bad);
  EXPECT_EQ(expect_error(bad, "DCT atoms follow"), 16u);

  bad = good;
  bad.push_back(std::byte{0});
  expect_error(bad, "extra bytes");

  bad = good;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bad.data() + 128 + 4 * 5, &nan, 4);
  fix_crc(bad);
  EXPECT_EQ(expect_error(bad, "finite"), 128u + 20u);
}

TEST(DictionaryFile, MissingFileAndBadWritesAreErrors) {
  volreel::test::TempDir dir("dictfile-missing");
  EXPECT_THROW(read_dictionary_file(dir / "nope.bin"), FormatError);
  // Folders that do not exist yet are made, as for a container; under a file nothing can be.
  write_dictionary_file(dir / "no-such-dir" / "d.bin", small_dictionary());
  EXPECT_EQ(read_dictionary_file(dir / "no-such-dir" / "d.bin").atom_count,
            small_dictionary().atom_count);
  std::ofstream(dir / "file") << "x";
  EXPECT_THROW(write_dictionary_file(dir / "file" / "d.bin", small_dictionary()), FormatError);
  DictionaryFile inconsistent = small_dictionary();
  inconsistent.atoms.pop_back();
  EXPECT_THROW(serialize_dictionary_file(inconsistent), FormatError);
}

TEST(DictionaryFile, DictionaryRoundTrip) {
  volreel::test::TempDir dir("dictfile-eigen");
  volreel::dictionary::Dictionary d;
  d.block_size = 3;
  d.atoms = Eigen::MatrixXf::Random(27, 40);
  volreel::dictionary::normalize_atoms(d.atoms);
  for (Eigen::Index k = 0; k < d.atoms.cols(); ++k) {
    EXPECT_NEAR(d.atoms.col(k).norm(), 1.0f, 1e-5f);
    EXPECT_NEAR(d.atoms.col(k).mean(), 0.0f, 1e-6f);
  }
  volreel::dictionary::save_dictionary(dir / "d.bin", d, {});
  const auto r = volreel::dictionary::load_dictionary(dir / "d.bin");
  EXPECT_EQ(r.block_size, 3);
  EXPECT_EQ(r.atoms, d.atoms);
}

}  // namespace
