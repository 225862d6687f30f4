// dictionary_file.hpp: the dictionary file (`dictionary.bin`): K prototype blocks (atoms) of
// M³ float32 values plus how they were trained, protected by a CRC-32C. Byte diagram in
// format/SPEC.md, "Dictionary file".
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace volreel::format {

static_assert(std::endian::native == std::endian::little,
              "volreel's files are little-endian and are read and written by memcpy; a big-endian "
              "port needs byte swaps in format/");

/// The first 8 bytes of every dictionary file.
inline constexpr std::array<char, 8> dictionary_magic = {'V', 'R', 'E', 'E', 'L', 'D', 'I', 'C'};
/// Version of the dictionary file layout (independent of the program version). Readers refuse
/// other versions.
inline constexpr std::uint32_t dictionary_format_version = 1;

/// How a dictionary was trained. Provenance only: decoding needs the atoms, not these.
struct DictionaryTraining {
  double tolerance = 0;  ///< ε: RMS error per value of a block, in data units
  double value_min = 0;  ///< value range of the training frames
  double value_max = 0;
  std::uint32_t max_sparsity = 0;    ///< Smax, atoms per block at most
  std::uint64_t coreset_voxels = 0;  ///< C
  std::uint32_t coreset_levels = 0;  ///< halvings below C (the paper's 6)
  std::uint32_t iterations = 0;      ///< K-SVD iterations per level (flat: in all)
  std::uint64_t seed = 0;
  bool flat = false;  ///< trained on the largest coreset only
  std::uint32_t training_frames = 0;
  double rms_error = 0;      ///< final RMS error per value, estimated over the training frames
  double mean_sparsity = 0;  ///< final atoms per block, estimated over the training frames
};

/// A dictionary file in memory.
struct DictionaryFile {
  std::uint32_t block_size = 0;  ///< M: atoms are M×M×M blocks
  std::uint32_t atom_count = 0;  ///< K
  /// K·M³ values: atom 0 (x fastest, then y, then z inside the block), atom 1, ...
  std::vector<float> atoms;
  /// Stored as IEEE 754 binary16 (2 bytes a value, flag bit 1) instead of float32: half the
  /// bytes. serialize_dictionary_file rounds to the nearest half; use with_half_atoms to get the
  /// values a reader will see before coding with them.
  bool half_atoms = false;
  /// The last M³ − 1 atoms are block_dct_atoms(M) (flag bit 2): the orthonormal 3D DCT-II basis
  /// without its constant atom. They are not stored: a reader generates them, so that the
  /// dictionary spans every zero-mean block at the cost of no bytes. atom_count and atoms include
  /// them.
  bool dct_atoms = false;
  DictionaryTraining training;
  std::string program_version;  ///< the volreel version that wrote it, at most 15 characters
  /// The identifier of the container whose copy this is (its manifest's container_id), so that a
  /// reader can tell another container's dictionary; 0 for a dictionary of its own (volreel train).
  std::uint64_t container_id = 0;
};

/// On-disk header, 128 bytes, little-endian, at offset 0. Offsets in the comments.
struct DictionaryFileHeader {
  char magic[8];                  //   0  "VREELDIC"
  std::uint32_t format_version;   //   8  dictionary_format_version
  std::uint32_t header_bytes;     //  12  128 (sizeof this struct)
  std::uint32_t atom_count;       //  16  K
  std::uint32_t block_size;       //  20  M
  std::uint32_t atom_length;      //  24  m = M³
  std::uint32_t max_sparsity;     //  28  Smax
  double tolerance;               //  32  ε (RMS per value, data units)
  double value_min;               //  40
  double value_max;               //  48
  std::uint64_t coreset_voxels;   //  56  C
  std::uint32_t coreset_levels;   //  64
  std::uint32_t iterations;       //  68
  std::uint64_t seed;             //  72
  std::uint32_t flags;            //  80  bit 0 flat training, 1 binary16 atoms, 2 DCT basis
  std::uint32_t training_frames;  //  84
  double rms_error;               //  88
  double mean_sparsity;           //  96
  char program_version[16];       // 104  NUL-padded
  std::uint64_t container_id;     // 120  the container's identifier, or 0
};
static_assert(sizeof(DictionaryFileHeader) == 128);
static_assert(offsetof(DictionaryFileHeader, format_version) == 8);
static_assert(offsetof(DictionaryFileHeader, atom_count) == 16);
static_assert(offsetof(DictionaryFileHeader, tolerance) == 32);
static_assert(offsetof(DictionaryFileHeader, coreset_voxels) == 56);
static_assert(offsetof(DictionaryFileHeader, seed) == 72);
static_assert(offsetof(DictionaryFileHeader, flags) == 80);
static_assert(offsetof(DictionaryFileHeader, rms_error) == 88);
static_assert(offsetof(DictionaryFileHeader, program_version) == 104);
static_assert(offsetof(DictionaryFileHeader, container_id) == 120);

inline constexpr std::uint32_t dictionary_flag_flat = 1u;
inline constexpr std::uint32_t dictionary_flag_half = 2u;
inline constexpr std::uint32_t dictionary_flag_dct = 4u;
/// Limits a reader accepts (a header beyond them is corrupt, not merely large).
inline constexpr std::uint32_t dictionary_max_block_size = 64;
inline constexpr std::uint32_t dictionary_max_atoms = 1u << 16;

/// Total file size for K atoms of m values: header + atoms (float32, or binary16 if `half`) + CRC.
constexpr std::uint64_t dictionary_file_size(std::uint64_t atom_count, std::uint64_t atom_length,
                                             bool half = false) {
  return sizeof(DictionaryFileHeader) + atom_count * atom_length * (half ? 2u : sizeof(float)) +
         sizeof(std::uint32_t);
}

/// The dictionary as it will be read back once stored in binary16: half_atoms set and every atom
/// value rounded to the nearest binary16 (Eigen::half, round to nearest even), except the
/// generated DCT atoms, which a reader makes in float32. A dictionary that is already half comes
/// back unchanged.
DictionaryFile with_half_atoms(DictionaryFile dictionary);

/// The orthonormal 3D DCT-II basis of an M³ block without the constant atom: M³ − 1 atoms of M³
/// values (x fastest), zero-mean and of unit norm, ordered by u + v + w (the frequencies along x,
/// y, z), then w, v, u. Atom (u, v, w) is φ_u(x)·φ_v(y)·φ_w(z), φ_u(x) = sqrt((u = 0 ? 1 : 2)/M) ·
/// cos(π(2x + 1)u / 2M), computed in double and rounded to float once: every reader gets the same
/// values.
std::vector<float> block_dct_atoms(std::uint32_t block_size);

/// The frequencies (u, v, w) of block_dct_atoms(block_size)'s atoms, in their order.
std::vector<std::array<std::uint32_t, 3>> block_dct_frequencies(std::uint32_t block_size);

/// φ_u(x) of block_dct_atoms, in double: phi[u·M + x].
std::vector<double> block_dct_phi(std::uint32_t block_size);

/// A dictionary of the DCT basis alone: no learned atom, nothing stored but the header (132 bytes).
/// What a series too small to pay for a learned dictionary is coded against.
DictionaryFile dct_dictionary(std::uint32_t block_size, const std::string& program_version);

/// The dictionary with the DCT basis appended (dct_atoms set); unchanged if it already has it.
/// Throws FormatError if the total would exceed dictionary_max_atoms.
DictionaryFile with_dct_atoms(DictionaryFile dictionary);

/// The dictionary as volreel encode stores it in a container: atoms rounded to binary16 when
/// `half` (with_half_atoms), then the DCT basis appended (with_dct_atoms). Frames are coded
/// against exactly these atoms.
DictionaryFile container_dictionary(DictionaryFile dictionary, bool half);

/// The file's bytes. Throws FormatError (file "<memory>") if `dictionary` is inconsistent
/// (atoms.size() != K·M³, K or M out of range, a version string over 15 characters).
std::vector<std::byte> serialize_dictionary_file(const DictionaryFile& dictionary);

/// Parses a dictionary file's bytes; `name` is used in messages. Throws FormatError naming the
/// offset and what was expected on a wrong magic, unknown version, inconsistent header,
/// truncated or overlong file, CRC mismatch, or a non-finite atom value. Never crashes on bad
/// input.
DictionaryFile parse_dictionary_file(std::span<const std::byte> bytes,
                                     const std::filesystem::path& name);

/// Writes the file atomically (temporary name, then rename). Throws FormatError on failure.
void write_dictionary_file(const std::filesystem::path& path, const DictionaryFile& dictionary);

/// Reads and checks a dictionary file. Throws FormatError as parse_dictionary_file does, or if
/// the file cannot be read.
DictionaryFile read_dictionary_file(const std::filesystem::path& path);

}  // namespace volreel::format
