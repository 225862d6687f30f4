// decoder.hpp: the CPU reference decoder — a brick of a frame file to S³ float32 values (S the
// container's brick size), and a
// frame at any level of its octree to a dense volume. This is the oracle the GPU decoder is
// tested against; the per-value arithmetic is brick_decode.h, shared with GLSL.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "volreel/format/frame_file.hpp"

namespace volreel::format {

/// The dictionary a ksvd frame's codes index: K atoms of 216 float32 values, atom-major.
struct AtomTable {
  std::span<const float> values;  ///< K·216
  std::uint32_t count = 0;        ///< K
  /// The last 215 atoms are block_dct_atoms(6) (dictionary_file.hpp) bit for bit: the decoder
  /// sums their codes as a separable transform instead of atom by atom (the same values up to
  /// float rounding). Set it only for such atoms: atom_table() checks.
  bool dct_basis = false;
};

/// The atoms of the DCT basis a ksvd block can index (M = 6: 6³ − 1).
constexpr std::uint32_t dct_basis_atoms = 215;

/// {values, count}, with dct_basis set when its last 215 atoms are block_dct_atoms(6) bit for bit.
AtomTable atom_table(std::span<const float> values, std::uint32_t count);

/// The structure of a ksvd brick payload (brick_decode.h's layout), once checked.
struct KsvdPayloadLayout {
  std::uint32_t word = 0;           ///< the layout word (word 3)
  std::uint32_t band_word = 0;      ///< the magnitudes' Rice parameters (word 4)
  std::uint32_t box_word = 0;       ///< the coded blocks (word 5, vr_box_word)
  std::uint32_t mean_bits = 0;      ///< b, 0..15
  std::uint32_t sparsity_bits = 0;  ///< t, 0..8
  std::uint32_t coef_bits = 0;      ///< c, 1..16: every |q| ≤ 2^c
  std::uint32_t atom_bits = 0;      ///< a, 1..16
  std::uint32_t codes = 0;          ///< Σ sparsities
  std::uint64_t code_bits = 0;      ///< length of the code stream, without its zero padding
};

/// The largest magnitude a decoded value may reach, and the largest magnitude of an atom value
/// (atoms have unit norm; binary16 storage rounds them by less than 1e-3).
constexpr double max_decoded_magnitude = 1e38;
constexpr double max_atom_magnitude = 1.01;

/// Checks a ksvd payload before anything decodes it (the CPU decoder here, or the GPU): the header
/// and entries present, finite dequantization values that bound every decoded value by
/// max_decoded_magnitude, the layout word (every width in range), and the
/// box word (1..n coded blocks on each axis of a brick of `shape`), the code stream read to its
/// end: in each block atom indices increasing and < atom_count, every magnitude ≤ 2^c, the
/// stream inside the payload, the payload exactly the words of the header, entries (one per coded
/// block) and codes, and the padding after the last code
/// zero. Throws FormatError naming `name` and the offset `at` + the bad field's offset in the
/// payload.
KsvdPayloadLayout check_ksvd_payload(std::span<const std::byte> payload, std::uint32_t atom_count,
                                     BrickShape shape, const std::filesystem::path& name,
                                     std::uint64_t at);
/// The same on a payload already copied into 32-bit words (`bytes` long; bytes/4 words).
KsvdPayloadLayout check_ksvd_payload(std::span<const std::uint32_t> words, std::size_t bytes,
                                     std::uint32_t atom_count, BrickShape shape,
                                     const std::filesystem::path& name, std::uint64_t at);

/// The box word of a ksvd payload (brick_decode.h, vr_box_word: its coded blocks) of at least the
/// header's bytes, unchecked (check_ksvd_payload checks it); 0 for a shorter payload.
std::uint32_t ksvd_box_word(std::span<const std::byte> payload);

/// The parts of a ksvd brick payload before packing: the three dequantization values (mean_bias,
/// mean_scale, coef_scale), the field widths (mean bits b 0..15, sparsity bits t 0..8, magnitude
/// bits c 1..16, atom bits a 1..16), the entropy coder's parameters, per block of the brick
/// (n³ blocks for bricks of 6n voxels a side) its sparsity (< 2^t) and quantized mean (< 2^b),
/// the coded blocks' box (brick_decode.h, vr_box_word: blocks outside it have sparsity 0 and are
/// stored without an entry, decoding to mean_bias) and the codes of all blocks in block order,
/// each block's in increasing atom order (atom index < 2^a, or in L .. L + 2^a − 1 under the split
/// flag with L = band_split; quantized value q ≠ 0 with |q| ≤ 2^c).
struct KsvdPayloadParts {
  float dequantization[3] = {0, 0, 0};
  std::uint32_t mean_bits = 12;
  std::uint32_t sparsity_bits = 4;
  std::uint32_t coef_bits = 6;
  std::uint32_t atom_bits = 10;
  /// The magnitudes' Rice parameter of each atom band (brick_decode.h, vr_atom_band), 0..15;
  /// -1: the one giving the band the fewest bits.
  std::array<int, 8> band_rice{-1, -1, -1, -1, -1, -1, -1, -1};
  int gap_shift = -1;  ///< the gaps' Rice shift 0..3; -1: the one giving the fewest bits
  /// The run limit T 0..255 and the runs' Rice parameter 0..7 (brick_decode.h, vr_read_gap); -1:
  /// the one giving the fewest bits with the other parameters (each fixed or chosen alone).
  int run_limit = -1;
  int run_rice = -1;
  /// The magnitude model 0..9 (brick_decode.h, vr_magnitude_move: how a block's sparsity moves
  /// the band parameters); -1: the one giving the fewest bits, with the band parameters.
  int magnitude_model = -1;
  /// The split flag (brick_decode.h, vr_block_first_atom): every atom is at least band_split, and
  /// atom − band_split < 2^atom_bits (the DCT basis alone after a learned dictionary's atoms).
  bool from_split = false;
  /// Atoms below this form band 0 (0..4095): the learned atoms before the DCT basis.
  std::uint32_t band_split = 0;
  std::vector<std::uint32_t> sparsity = std::vector<std::uint32_t>(BrickShape{}.blocks());
  std::vector<std::uint32_t> mean = std::vector<std::uint32_t>(BrickShape{}.blocks());
  /// Coded blocks on each axis, 1..n; 0 on an axis: all n.
  std::array<std::uint32_t, 3> box{0, 0, 0};
  std::vector<std::uint32_t> atoms;  ///< one per code
  std::vector<std::int32_t> values;  ///< one per code
};

/// The Rice codes of one block's gaps (brick_decode.h, vr_read_gap), code by code: the packer's
/// writing and its choice of parameters, and the code statistics, all take them from here.
class BlockGaps {
 public:
  /// A block's s atoms (increasing, from first_atom on) under run limit `run_limit`.
  BlockGaps(const std::uint32_t* atoms, std::uint32_t s, std::uint32_t first_atom,
            std::uint32_t run_limit)
      : atoms_(atoms), s_(s), next_atom_(first_atom), run_end_(first_atom + run_limit) {}
  /// The codes of code j's gap (j = 0, 1, ... in turn): a run length before it, when `run` ≥ 0,
  /// then a Rice value with the gaps' parameter, when `gap` ≥ 0.
  struct Codes {
    std::int64_t run = -1, gap = -1;
  };
  Codes next() {
    Codes c;
    const std::uint32_t atom = atoms_[j_];
    if (zeros_left_ > 0) {
      --zeros_left_;
    } else if (after_run_) {
      c.gap = atom - next_atom_ - 1;
      after_run_ = false;
    } else if (next_atom_ < run_end_) {
      std::uint32_t z = 0;
      while (j_ + z < s_ && atoms_[j_ + z] == next_atom_ + z) ++z;
      c.run = z;
      if (z > 0)
        zeros_left_ = z - 1, after_run_ = true;
      else
        c.gap = atom - next_atom_ - 1;
    } else {
      c.gap = atom - next_atom_;
    }
    next_atom_ = atom + 1;
    ++j_;
    return c;
  }

 private:
  const std::uint32_t* atoms_;
  std::uint32_t s_, next_atom_, run_end_, j_ = 0, zeros_left_ = 0;
  bool after_run_ = false;
};

/// Bits of a Rice code of x with parameter k whose escape holds `escape_bits` bits (format/SPEC.md,
/// "The codes": an escape when x >> k reaches 16).
std::uint64_t rice_bits(std::uint32_t x, std::uint32_t k, std::uint32_t escape_bits);

/// The fewest bits that hold every value 0..count − 1 (0 for count ≤ 1).
std::uint32_t bits_for_count(std::uint64_t count);

/// Packs the parts into a payload of brick_decode.h's layout, choosing the entropy coder's
/// parameters where the parts leave them at −1. Throws std::invalid_argument when a width is out
/// of range, a field does not fit its bits, a block's atoms do not increase, a value is 0, the
/// codes do not number Σ sparsity or the blocks are not those of a brick.
std::vector<std::byte> pack_ksvd_payload(const KsvdPayloadParts& parts);

/// The parts of a ksvd payload (the inverse of pack_ksvd_payload, with the entropy coder's
/// parameters as stored), after check_ksvd_payload.
KsvdPayloadParts unpack_ksvd_payload(std::span<const std::byte> payload, std::uint32_t atom_count,
                                     BrickShape shape, const std::filesystem::path& name,
                                     std::uint64_t at);

/// Decodes one brick payload (a 4-byte constant, a ksvd payload or a zfp stream of codec `codec`
/// with accuracy `zfp_accuracy`) of a brick of `shape` into out (shape.voxels() values, x
/// fastest). `name` and `offset` (the payload's file offset) are used in errors. Throws
/// FormatError on a bad payload.
void decode_payload(std::span<const std::byte> payload, Codec codec, double zfp_accuracy,
                    const AtomTable& atoms, BrickShape shape, std::span<float> out,
                    const std::filesystem::path& name, std::uint64_t offset);

/// A brick payload to decode, where its values go, and what its errors name (decode_payloads).
struct PayloadJob {
  std::span<const std::byte> payload;
  std::span<float> out;
  std::filesystem::path name;
  std::uint64_t offset = 0;  ///< the payload's file offset
  double zfp_accuracy = 0;   ///< codec zfp: the frame's tolerance
};

/// The job of brick b of a frame (its payload checked against its CRC, as decode_brick does).
PayloadJob brick_job(const FrameView& frame, std::uint32_t brick, std::span<float> out);

/// decode_payload on each job, with the same codec, atoms and brick shape. ksvd payloads are
/// decoded two at a time, their code streams read in step: reading a code is a chain of
/// dependent steps, and two independent chains keep a core busier than one (the same values as
/// decode_payload, bit for bit). Returns how many payloads had their codes read in step. Throws
/// the FormatError of the first bad payload; the outputs of the others are then unspecified.
std::size_t decode_payloads(std::span<const PayloadJob> jobs, Codec codec, const AtomTable& atoms,
                            BrickShape shape);

/// A brick of a frame to decode and where its values go (decode_bricks).
struct BrickToDecode {
  const FrameView* frame = nullptr;
  std::uint32_t brick = 0;
  std::span<float> out;
};

/// decode_brick on each, through decode_payloads (ksvd bricks two at a time, their codes read in
/// step). The frames must share the first's codec and brick size (else FormatError). Throws the
/// error of the first bad brick in order: its index, its CRC or its payload.
void decode_bricks(std::span<const BrickToDecode> bricks, const AtomTable& atoms);

/// Decodes brick b into out (frame.shape().voxels() values, x fastest). Validates the payload first
/// (length against its block sparsities, atom indices < K, finite dequantization values) and throws
/// FormatError naming the frame file and the payload's offset. zfp frames ignore `atoms`.
void decode_brick(const FrameView& frame, std::uint32_t brick, const AtomTable& atoms,
                  std::span<float> out);

/// A dense volume at one level of the octree.
struct LevelVolume {
  std::array<std::uint32_t, 3> dims{};
  std::vector<float> data;  ///< dims[0]·dims[1]·dims[2], x fastest
};

/// Decodes level `level` (0 = root .. level_count−1 = full resolution) of a frame: the interior
/// of every brick of that level; regions under an empty (constant) ancestor take its value. Every
/// node of the level must have a brick at this time step (else FormatError: a step with
/// interpolated nodes decodes through TimeStepDecoder, time_step.hpp).
/// Parallel (OpenMP) over bricks. Throws FormatError on a bad payload.
LevelVolume decode_level(const FrameView& frame, std::uint32_t level, const AtomTable& atoms);
/// The same into an existing buffer of the level's size.
void decode_level(const FrameView& frame, std::uint32_t level, const AtomTable& atoms,
                  std::span<float> out);

/// Copies a decoded brick of the node at `p` into a volume of level `level` (dims: the level's
/// size): its interior when the node is of that level, else its first value over the region it
/// covers (an empty node above the level).
void place_in_level(const NodePosition& p, std::uint32_t level, std::array<std::uint32_t, 3> dims,
                    BrickShape shape, std::span<const float> brick, std::span<float> out);
/// The nodes whose bricks make level `level` of a frame: the level's nodes and the empty nodes
/// above it. Throws FormatError when the frame has no such level.
std::vector<std::uint32_t> level_work(const FrameView& frame, std::uint32_t level);

/// Checks every brick payload of the frame by decoding it; throws FormatError on the first bad one.
void validate_payloads(const FrameView& frame, const AtomTable& atoms);

}  // namespace volreel::format
