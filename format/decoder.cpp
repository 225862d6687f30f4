// decoder.cpp: the CPU reference decoder (see decoder.hpp).
#include "volreel/format/decoder.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <functional>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "volreel/format/brick_decode.h"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/zfp_stream.hpp"

namespace volreel::format {

namespace {

std::string str(std::uint64_t v) {
  return std::to_string(v);
}

/// x86-64 builds with GCC carry an AVX2 version of the decoder's inner loop besides the baseline
/// (SSE2) one, chosen when the program loads. AVX2 without FMA: both versions multiply, then add,
/// so a build for baseline x86-64 (the default) decodes to the same bits on every machine. (Clang
/// does not take target_clones on a function declared before its definition; its builds, the
/// fuzzers', keep the baseline version.) The in-step code reader, integer work only, also has an
/// x86-64-v3 version: BMI2's shifts by any register, where two interleaved readers otherwise take
/// turns with the one shift-count register.
#if defined(__x86_64__) && defined(__ELF__) && !defined(__clang__)
#define VOLREEL_SIMD_CLONES gnu::target_clones("avx2", "default"),
#define VOLREEL_BMI_CLONES gnu::target_clones("arch=x86-64-v3", "default"),
#else
#define VOLREEL_SIMD_CLONES
#define VOLREEL_BMI_CLONES
#endif

/// One code as read: its atom and signed quantized coefficient.
struct ParsedCode;

/// block[v] = mean + Σ coef_scale·q_k·atom_k[v] over a block's codes. The codes of atoms below
/// `dct_first` are summed atom by atom, a third of the block at a time so that the sums stay in
/// registers while the codes' atoms stream past; those of the DCT basis (atoms from dct_first on,
/// AtomTable::dct_basis), when a block has 16 or more, as a separable transform: each code adds
/// its (v, u) plane of 36 values to the plane of its w, then the planes go through the 6-point
/// transform along z, about 5 vector products a code instead of 27.
[[VOLREEL_SIMD_CLONES gnu::noinline]] void decode_block(float* __restrict block, float mean,
                                                        const ParsedCode* __restrict codes,
                                                        vr_uint count,
                                                        const float* __restrict atoms,
                                                        float coef_scale, vr_uint dct_first);

/// Zero words after a payload's copy: the look-ahead of the code stream's refills and the overrun
/// of a damaged stream's last code read zeros (a code that starts inside the stream loads at most
/// 15 bytes past the stream's end, CodeStream; the rest is margin).
constexpr std::size_t payload_padding_words = 6;

/// The code stream of a payload read through a 64-bit bit buffer: the codes of brick_decode.h's
/// vr_read_code (which the GPU decoders run, and which the tests hold this reader to), with one
/// unaligned load a code instead of up to five word reads with a branch each. The buffer holds
/// the stream's bits up to a byte boundary (count_ of them from its low bit); a refill ORs in the
/// 8 bytes from that boundary on and moves the boundary by whole bytes, leaving 56 to 63 bits.
/// The load's address depends on the codes before the previous one only, so that it is not in
/// the chain of dependent steps from one code to the next (a 64-bit window loaded at each code's
/// bit was). A gap takes at most 32 bits (16 zeros and 16 escaped bits, or at most 15 zeros, the
/// one and 15 low bits) and a run length before it at most 24 (16 zeros and 8 escaped bits), 56
/// together; a magnitude with its sign at most 33: after more than 23 bits of gap (rare) the
/// reader refills again before the magnitude. A code that starts inside the stream loads at most 15
/// bytes past the stream's end (the refill before it leaves at most 63 bits in the buffer, so the
/// load starts at most 7 bytes past the stream's last bit): the payload's zero padding words take
/// them.
class CodeStream {
 public:
  /// first_atom: vr_block_first_atom of the payload; box_word: its box word (the runs).
  CodeStream(const vr_uint* payload, vr_uint first_word, vr_uint atom_bits, vr_uint first_atom,
             vr_uint box_word)
      : start_(reinterpret_cast<const unsigned char*>(payload + first_word)),
        next_(start_),
        atom_limit_(first_atom + (1u << atom_bits)),
        run_end_(first_atom + vr_box_run_limit(box_word)),
        run_rice_(vr_box_run_rice(box_word)) {}
  /// Bits read so far.
  std::uint64_t bit() const { return 8 * static_cast<std::uint64_t>(next_ - start_) - count_; }
  /// The magnitudes' parameters of the block whose codes come next (BandRice::block).
  void set_band_rice(const std::uint8_t* band_rice) { band_rice_ = band_rice; }

  /// The next code of a block whose gaps have Rice parameter `gap_rice` (vr_gap_rice), after the
  /// block's codes up to next_atom − 1, in the block's run state `run` (0 before its first code);
  /// as vr_read_code.
  int read(vr_uint gap_rice, vr_uint atom_bits, vr_uint coef_bits, vr_uint& next_atom, vr_uint& run,
           vr_uint& atom) {
    vr_uint magnitude;
    return read(gap_rice, atom_bits, coef_bits, next_atom, run, atom, magnitude);
  }
  /// The same, and the magnitude's Rice value |q| − 1 in `magnitude`.
  int read(vr_uint gap_rice, vr_uint atom_bits, vr_uint coef_bits, vr_uint& next_atom, vr_uint& run,
           vr_uint& atom, vr_uint& magnitude) {
    refill();
    std::uint64_t w = buffer_;
    vr_uint used = 0;
    // The gap, as vr_read_gap; a gap coded as itself (no run limit, or past it) first.
    if (run == 0 && next_atom >= run_end_) {
      atom = next_atom + rice(w, used, gap_rice, atom_bits);
    } else if (run >= 2) {
      run -= 2;
      atom = next_atom;
    } else {
      // Below the run limit a run length first (run 0); right after a run (run 1) none.
      const vr_uint z = run == 0 ? rice(w, used, run_rice_, VR_MAX_SPARSITY_BITS) : 0;
      if (z != 0) {  // a run starts: this code's gap is 0, z − 1 more to come
        run = 2 * z - 1;
        atom = next_atom;
      } else {  // no run here, or right after one: the gap is at least 1
        run = 0;
        atom = next_atom + 1 + rice(w, used, gap_rice, atom_bits);
      }
    }
    next_atom = atom + 1;
    if (used > 56 - 33) {  // fewer than 33 bits left in the buffer
      consume(used);
      refill();
      w = buffer_;
      used = 0;
    }
    // An atom index past first atom + 2^a is never valid (the caller refuses it); its Rice
    // parameter is that of first atom + 2^a, so that the table stays small.
    magnitude = rice(w, used, band_rice_[std::min(atom, atom_limit_)], coef_bits);
    const vr_uint negative = static_cast<vr_uint>(w) & 1u;
    consume(used + 1);
    const int q = static_cast<int>(magnitude + 1);
    return negative ? -q : q;
  }

 private:
  /// At least 56 bits in the buffer. The bits past count_ are the stream's too (or zero), so ORing
  /// the next bytes over them changes nothing.
  void refill() {
    std::uint64_t w;
    std::memcpy(&w, next_, sizeof w);
    buffer_ |= w << count_;
    next_ += (63 - count_) >> 3;
    count_ |= 56;
  }
  void consume(vr_uint bits) {
    buffer_ >>= bits;
    count_ -= bits;
  }
  /// The Rice code at the start of the bits w (vr_read_rice): w moves past it, `used` counts its
  /// bits.
  static vr_uint rice(std::uint64_t& w, vr_uint& used, vr_uint k, vr_uint escape_bits) {
    const vr_uint zeros = vr_lowest_bit(static_cast<vr_uint>(w) | (1u << VR_ESCAPE_ZEROS));
    vr_uint value, length;
    if (zeros == VR_ESCAPE_ZEROS) {
      length = VR_ESCAPE_ZEROS + escape_bits;
      value = static_cast<vr_uint>(w >> VR_ESCAPE_ZEROS) & ((1u << escape_bits) - 1u);
    } else {
      length = zeros + 1 + k;
      value = (zeros << k) | (static_cast<vr_uint>(w >> (zeros + 1)) & ((1u << k) - 1u));
    }
    w >>= length;
    used += length;
    return value;
  }

  const unsigned char* start_;
  const unsigned char* next_;  ///< the byte after the buffer's count_ bits
  const std::uint8_t* band_rice_ = nullptr;
  vr_uint atom_limit_;
  vr_uint run_end_;   ///< first atom + run limit: a run may start below it
  vr_uint run_rice_;  ///< the runs' Rice parameter
  std::uint64_t buffer_ = 0;
  vr_uint count_ = 0;
};

/// The magnitudes' Rice parameter (vr_band_rice) of every atom index 0..F + 2^a of a payload
/// (F: vr_block_first_atom), one table for each move of its magnitude model (vr_magnitude_move,
/// −2..2), and the table of each sparsity class floor(log2(s + 1)) (0..8): one load a code
/// instead of the band's logarithm, and one load a block for its table.
class BandRice {
 public:
  /// For a payload's layout, band and box words.
  void reset(vr_uint layout_word, vr_uint band_word, vr_uint box_word) {
    const vr_uint atom_bits = vr_layout_atom_bits(layout_word);
    const vr_uint split = vr_layout_band_split(layout_word);
    const std::size_t stride =
        std::size_t{vr_block_first_atom(layout_word, box_word)} + (std::size_t{1} << atom_bits) + 1;
    if (split != split_) bands_.clear(), split_ = split;  // each atom's band, for this split
    for (std::size_t atom = bands_.size(); atom < stride; ++atom)
      bands_.push_back(
          static_cast<std::uint8_t>(vr_atom_band(layout_word, static_cast<vr_uint>(atom))));
    const bool moves = vr_box_magnitude_model(box_word) != 0;
    tables_.resize((moves ? 2 * VR_MAGNITUDE_SWING + 1 : 1) * stride);
    for (int move = moves ? -VR_MAGNITUDE_SWING : 0; move <= (moves ? VR_MAGNITUDE_SWING : 0);
         ++move) {
      const vr_uint moved = vr_moved_band_word(band_word, move);
      std::uint8_t rice[VR_ATOM_BANDS];
      for (vr_uint band = 0; band < VR_ATOM_BANDS; ++band) rice[band] = (moved >> (4 * band)) & 0xF;
      std::uint8_t* table = tables_.data() + index(moves ? move : 0, moves) * stride;
      for (std::size_t atom = 0; atom < stride; ++atom) table[atom] = rice[bands_[atom]];
    }
    for (vr_uint c = 0; c < classes; ++c)  // s = 2^c − 1 is of class c
      class_table_[c] =
          tables_.data() + index(vr_magnitude_move(box_word, (1u << c) - 1u), moves) * stride;
  }
  /// The table of a block of s codes (s < 2^VR_MAX_SPARSITY_BITS).
  const std::uint8_t* block(vr_uint s) const { return class_table_[vr_highest_bit(s + 1u)]; }

 private:
  static constexpr vr_uint classes = VR_MAX_SPARSITY_BITS + 1;
  /// The table of a move: the only one without moves.
  static std::size_t index(int move, bool moves) {
    return moves ? static_cast<std::size_t>(move + VR_MAGNITUDE_SWING) : 0;
  }
  std::vector<std::uint8_t> bands_, tables_;
  vr_uint split_ = 0;
  const std::uint8_t* class_table_[classes] = {};
};

/// One code as read: its atom and signed quantized coefficient.
struct ParsedCode {
  vr_uint atom;
  int q;
};

typedef float Lanes [[gnu::vector_size(32)]];  // 8 floats: one AVX2 register or two SSE ones
constexpr vr_uint lanes = 8;
constexpr vr_uint plane_values = VR_BLOCK_SIZE * VR_BLOCK_SIZE;      // 36: a (y, x) plane
constexpr vr_uint plane_lanes = (plane_values + lanes - 1) / lanes;  // 5 vectors, 40 values
constexpr vr_uint plane_padded = plane_lanes * lanes;

/// The DCT basis's atoms in separable form: atom j = φ_u(x)·φ_v(y)·φ_w(z) is its plane
/// φ_v(y)·φ_u(x) (36 values, 4 zeros after) times φ_w(z).
struct DctTables {
  alignas(32) float plane[dct_basis_atoms][plane_padded];
  vr_uint w[dct_basis_atoms];
  float phi[VR_BLOCK_SIZE][VR_BLOCK_SIZE];  ///< φ_w(z) at [w][z]
  std::vector<float> atoms;                 ///< block_dct_atoms(6)
};

const DctTables& dct_tables() {
  static const DctTables tables = [] {
    DctTables t{};
    const std::vector<double> phi = block_dct_phi(VR_BLOCK_SIZE);
    const auto frequencies = block_dct_frequencies(VR_BLOCK_SIZE);
    for (vr_uint j = 0; j < dct_basis_atoms; ++j) {
      const auto [u, v, w] = frequencies[j];
      t.w[j] = w;
      for (vr_uint y = 0; y < VR_BLOCK_SIZE; ++y)
        for (vr_uint x = 0; x < VR_BLOCK_SIZE; ++x)
          t.plane[j][y * VR_BLOCK_SIZE + x] =
              static_cast<float>(phi[v * VR_BLOCK_SIZE + y] * phi[u * VR_BLOCK_SIZE + x]);
    }
    for (vr_uint w = 0; w < VR_BLOCK_SIZE; ++w)
      for (vr_uint z = 0; z < VR_BLOCK_SIZE; ++z)
        t.phi[w][z] = static_cast<float>(phi[w * VR_BLOCK_SIZE + z]);
    t.atoms = block_dct_atoms(VR_BLOCK_SIZE);
    return t;
  }();
  return tables;
}

void decode_block(float* __restrict block, float mean, const ParsedCode* __restrict codes,
                  vr_uint count, const float* __restrict atoms, float coef_scale,
                  vr_uint dct_first) {
  constexpr vr_uint part = 9;  // 27 = 3 parts of 9 vectors: 216 values
  vr_uint learned = 0;         // the codes of learned atoms come first (atoms increase)
  while (learned < count && codes[learned].atom < dct_first) ++learned;
  // The separable sum pays for itself from about 16 codes of the basis a block (measured on
  // blocks of random atoms and of low frequencies alike): fewer go atom by atom.
  const vr_uint summed = count - learned >= 16 ? learned : count;
  for (vr_uint p = 0; p < VR_BLOCK_LENGTH / lanes; p += part) {
    Lanes sum[part];
    for (vr_uint i = 0; i < part; ++i) sum[i] = mean - Lanes{};  // x − (+0) keeps a −0
    for (vr_uint k = 0; k < summed; ++k) {
      const Lanes c = coef_scale * static_cast<float>(codes[k].q) - Lanes{};
      const float* atom = atoms + std::size_t{codes[k].atom} * VR_BLOCK_LENGTH + p * lanes;
      for (vr_uint i = 0; i < part; ++i) {
        Lanes a;
        std::memcpy(&a, atom + i * lanes, sizeof a);
        sum[i] += c * a;
      }
    }
    std::memcpy(block + p * lanes, sum, sizeof sum);
  }
  if (summed == count) return;
  // The DCT basis's codes: planes[w] = Σ c·φ_v(y)φ_u(x) over the codes of frequency w, then
  // block[z][y][x] += Σ_w φ_w(z)·planes[w][y][x].
  const DctTables& t = dct_tables();
  Lanes planes[VR_BLOCK_SIZE][plane_lanes];
  std::memset(planes, 0, sizeof planes);
  vr_uint used = 0;  // bit w: plane w has a code
  for (vr_uint k = learned; k < count; ++k) {
    const vr_uint j = codes[k].atom - dct_first, w = t.w[j];
    const Lanes c = coef_scale * static_cast<float>(codes[k].q) - Lanes{};
    used |= 1u << w;
    for (vr_uint i = 0; i < plane_lanes; ++i) {
      Lanes a;
      std::memcpy(&a, t.plane[j] + i * lanes, sizeof a);
      planes[w][i] += c * a;
    }
  }
  for (vr_uint z = 0; z < VR_BLOCK_SIZE; ++z) {
    Lanes sum[plane_lanes] = {};
    for (vr_uint w = 0; w < VR_BLOCK_SIZE; ++w) {
      if ((used >> w & 1u) == 0) continue;
      const Lanes f = t.phi[w][z] - Lanes{};
      for (vr_uint i = 0; i < plane_lanes; ++i) sum[i] += f * planes[w][i];
    }
    float values[plane_padded];
    std::memcpy(values, sum, sizeof values);
    float* row = block + z * plane_values;
    for (vr_uint v = 0; v < plane_values; ++v) row[v] += values[v];
  }
}

/// Steps 1 and 2 of check_ksvd_payload on `payload` (word_count words): the header, the box of
/// coded blocks and room for their entries; the layout without codes and code_bits.
KsvdPayloadLayout parse_ksvd_header(const vr_uint* payload, std::size_t word_count,
                                    std::size_t bytes, BrickShape shape,
                                    const std::filesystem::path& name, std::uint64_t at) {
  const auto fail = [&](std::uint64_t offset, const std::string& expected,
                        const std::string& found) {
    throw FormatError(name, at + offset, "brick payload " + expected, found);
  };
  // 1. Header: three finite dequantization values and the layout word.
  if (bytes < 4 * VR_HEADER_WORDS || bytes % 4 != 0 || word_count != bytes / 4)
    fail(0, "of at least " + str(4 * VR_HEADER_WORDS) + " bytes, a multiple of 4",
         str(bytes) + " bytes");
  for (vr_uint w = 0; w < 3; ++w)
    if (!std::isfinite(vr_as_float(payload[w])))
      fail(4 * w, "finite dequantization value", "NaN or infinity");
  KsvdPayloadLayout layout;
  layout.word = payload[3];
  layout.band_word = payload[4];
  layout.box_word = payload[5];
  layout.mean_bits = vr_layout_mean_bits(layout.word);
  layout.sparsity_bits = vr_layout_sparsity_bits(layout.word);
  layout.coef_bits = vr_layout_coef_bits(layout.word);
  layout.atom_bits = vr_layout_atom_bits(layout.word);
  if (layout.mean_bits > VR_MEAN_BITS || layout.sparsity_bits > VR_MAX_SPARSITY_BITS ||
      layout.coef_bits < 1 || layout.coef_bits > VR_MAX_COEF_BITS || layout.atom_bits < 1 ||
      layout.atom_bits > VR_MAX_ATOM_BITS)
    fail(12,
         "layout word with mean bits 0.." + str(VR_MEAN_BITS) + ", sparsity bits 0.." +
             str(VR_MAX_SPARSITY_BITS) + ", magnitude bits 1.." + str(VR_MAX_COEF_BITS) +
             ", atom bits 1.." + str(VR_MAX_ATOM_BITS),
         "mean " + str(layout.mean_bits) + ", sparsity " + str(layout.sparsity_bits) +
             ", magnitude " + str(layout.coef_bits) + ", atom " + str(layout.atom_bits));
  // Every decoded value is a mean plus at most 2^t − 1 coefficients of magnitude at most
  // |coef_scale|·2^c times atom values of magnitude at most max_atom_magnitude (unit-norm atoms,
  // binary16 rounding), so this bound keeps every value finite, on the CPU and on the GPU.
  const auto magnitude = [&](vr_uint w) {
    return std::abs(static_cast<double>(vr_as_float(payload[w])));
  };
  const double bound = magnitude(0) +
                       magnitude(1) * static_cast<double>((1u << layout.mean_bits) - 1u) +
                       static_cast<double>((1u << layout.sparsity_bits) - 1u) * magnitude(2) *
                           static_cast<double>(1u << layout.coef_bits) * max_atom_magnitude;
  if (!(bound <= max_decoded_magnitude))
    fail(0,
         "dequantization values whose decoded values stay below " +
             number_text(max_decoded_magnitude) + " in magnitude",
         "values that reach " + number_text(bound));
  // 2. The box of coded blocks and their entries.
  const vr_uint n = shape.blocks_per_axis(), box = layout.box_word;
  if ((box >> 28) != 0 || vr_box_magnitude_model(box) > VR_MAX_MAGNITUDE_MODEL ||
      vr_box_blocks(box, 0) < 1 || vr_box_blocks(box, 0) > n || vr_box_blocks(box, 1) < 1 ||
      vr_box_blocks(box, 1) > n || vr_box_blocks(box, 2) < 1 || vr_box_blocks(box, 2) > n)
    fail(20,
         "box word of 1.." + str(n) + " coded blocks on each axis, magnitude model 0.." +
             str(VR_MAX_MAGNITUDE_MODEL) + " and zero bits 28..31",
         str(vr_box_blocks(box, 0)) + " x " + str(vr_box_blocks(box, 1)) + " x " +
             str(vr_box_blocks(box, 2)) + " blocks, magnitude model " +
             str(vr_box_magnitude_model(box)) + ((box >> 28) != 0 ? ", nonzero bits" : ""));
  const vr_uint first = vr_code_first_word(layout.word, vr_box_entries(box));
  if (bytes < 4 * std::uint64_t{first})
    fail(0,
         "of at least " + str(4 * std::uint64_t{first}) + " bytes for " + str(vr_box_entries(box)) +
             " " + str(vr_layout_entry_bits(layout.word)) + "-bit block entries",
         str(bytes) + " bytes");
  return layout;
}

/// The end of the atom indices a payload's codes may name: the dictionary's K atoms, and no index
/// its a bits cannot write from the block's first atom F (format/SPEC.md, "Decoding", step 5; the
/// packer never writes one, and readers that look up an atom's band by a table of F + 2^a
/// entries, as CodeStream does, would read a different Rice parameter for it than
/// brick_decode.h's vr_read_code computes).
vr_uint codes_atom_end(std::uint32_t atom_count, vr_uint first_atom, vr_uint atom_bits) {
  return static_cast<vr_uint>(std::min<std::uint64_t>(
      atom_count, std::uint64_t{first_atom} + (std::uint64_t{1} << atom_bits)));
}

/// The most bits one code takes (a 24-bit run length, a 32-bit gap, a 32-bit magnitude and the
/// sign): a stretch of `count` codes from bit `bit` cannot start a code past a stream of
/// `stream_bits` when this holds.
constexpr std::uint64_t max_code_bits = 89;
bool stretch_inside(std::uint64_t bit, vr_uint count, std::uint64_t stream_bits) {
  return bit + max_code_bits * count <= stream_bits;
}

/// The per-code checks (atom < atom_end, |q| ≤ 2^c) of a stretch of one block's codes read
/// without them: a block's atoms increase, so the stretch's last atom is its largest; |q| ≤ 2^c
/// is a Rice value |q| − 1 < 2^c, so the OR of the stretch's values `magnitudes` is below 2^c when
/// each is.
bool stretch_good(vr_uint last_atom, vr_uint magnitudes, vr_uint atom_end, vr_uint coef_bits) {
  return last_atom < atom_end && (magnitudes >> coef_bits) == 0;
}

/// Whether a block's run state after its last code is that of a stream the packer writes: no run
/// of consecutive atoms (vr_read_gap) reaching past the block's codes.
bool run_ended(vr_uint run) {
  return run < 2;
}

/// check_ksvd_payload on `payload` (word_count words followed by payload_padding_words zero
/// words), appending the codes to *codes when it is not null.
KsvdPayloadLayout parse_ksvd_payload(const vr_uint* payload, std::size_t word_count,
                                     std::size_t bytes, std::uint32_t atom_count, BrickShape shape,
                                     const std::filesystem::path& name, std::uint64_t at,
                                     std::vector<ParsedCode>* codes) {
  const auto fail = [&](std::uint64_t offset, const std::string& expected,
                        const std::string& found) {
    throw FormatError(name, at + offset, "brick payload " + expected, found);
  };
  KsvdPayloadLayout layout = parse_ksvd_header(payload, word_count, bytes, shape, name, at);
  const vr_uint blocks = shape.blocks(), n = shape.blocks_per_axis(), box = layout.box_word;
  const vr_uint first = vr_code_first_word(layout.word, vr_box_entries(box));
  // 3. The code stream, read as the decoders read it (the zero words after the payload take the
  //    look-ahead of the reader's refills and a damaged stream's overrun).
  const std::uint64_t stream_bits = (std::uint64_t{word_count} - first) * 32;
  const vr_uint largest = 1u << layout.coef_bits;
  thread_local BandRice band_rice;
  band_rice.reset(layout.word, layout.band_word, box);
  const vr_uint first_atom = vr_block_first_atom(layout.word, box);
  const vr_uint atom_end = codes_atom_end(atom_count, first_atom, layout.atom_bits);
  CodeStream stream(payload, first, layout.atom_bits, first_atom, box);
  for (vr_uint b = 0, e = 0; b < blocks; ++b) {
    if (!vr_block_in_box(box, n, b)) continue;
    const vr_uint s = vr_entry_sparsity(layout.word, vr_block_entry(payload, layout.word, e++));
    layout.codes += s;
    if (s == 0) continue;
    const vr_uint gap_rice = vr_gap_rice(layout.word, s);
    stream.set_band_rice(band_rice.block(s));
    vr_uint next_atom = first_atom, run = 0, atom = 0;
    if (stretch_inside(stream.bit(), s, stream_bits)) {
      // No code of the block can start past the stream: its codes read without the checks, then
      // checked once (stretch_good). Where that fails, the block is read again code by code, to
      // name the code.
      const CodeStream block_start = stream;
      const std::size_t codes_before = codes ? codes->size() : 0;
      vr_uint magnitudes = 0;
      for (vr_uint k = 0; k < s; ++k) {
        vr_uint magnitude = 0;
        const int q = stream.read(gap_rice, layout.atom_bits, layout.coef_bits, next_atom, run,
                                  atom, magnitude);
        magnitudes |= magnitude;
        if (codes) codes->push_back({atom, q});
      }
      if (stretch_good(atom, magnitudes, atom_end, layout.coef_bits) && run_ended(run)) continue;
      stream = block_start;
      next_atom = first_atom;
      run = 0;
      if (codes) codes->resize(codes_before);
    }
    for (vr_uint k = 0; k < s; ++k) {
      // A code's byte; a stream that ran past its end (a damaged one) is named at that end.
      const std::uint64_t code_at =
          std::min<std::uint64_t>(4 * std::uint64_t{first} + stream.bit() / 8, bytes);
      if (stream.bit() >= stream_bits)
        fail(code_at, "codes inside the payload (block " + str(b) + ", code " + str(k) + ")",
             "the payload's end");
      const int q = stream.read(gap_rice, layout.atom_bits, layout.coef_bits, next_atom, run, atom);
      if (atom >= atom_end)
        fail(code_at,
             "atom index < " + str(atom_end) + " (block " + str(b) + ", code " + str(k) + ")",
             str(atom));
      const vr_uint m = static_cast<vr_uint>(q < 0 ? -static_cast<std::int64_t>(q) : q);
      if (m > largest)
        fail(code_at,
             "magnitude ≤ 2^" + str(layout.coef_bits) + " (block " + str(b) + ", code " + str(k) +
                 ")",
             str(m));
      if (codes) codes->push_back({atom, q});
    }
    if (!run_ended(run))
      fail(std::min<std::uint64_t>(4 * std::uint64_t{first} + stream.bit() / 8, bytes),
           "runs of consecutive atoms that end with their block (block " + str(b) + ")",
           "a run reaching " + str(run / 2) + " code(s) past the block's " + str(s) + " codes");
  }
  const std::uint64_t bit = stream.bit();
  layout.code_bits = bit;
  const std::uint64_t need = 4 * (std::uint64_t{first} + (std::uint64_t{bit} + 31) / 32);
  if (bytes != need)
    fail(0, str(need) + " bytes for " + str(layout.codes) + " codes in " + str(bit) + " bits",
         str(bytes) + " bytes");
  if (bit % 32 != 0 && (payload[word_count - 1] >> (bit % 32)) != 0)
    fail(bytes - 4, "zero bits after the last code", "nonzero bits");
  return layout;
}

/// A payload copied into words, followed by payload_padding_words zero words. Payloads are 4-byte
/// aligned inside the file and the map is page-aligned, but an in-memory view may have any
/// alignment; the zero words take a Rice code's look-ahead at the stream's end and a damaged
/// stream's overrun (brick_decode.h).
void copy_padded(std::span<const std::byte> bytes, std::vector<vr_uint>& words) {
  words.assign(bytes.size() / 4 + payload_padding_words, 0u);
  if (bytes.size() >= 4) std::memcpy(words.data(), bytes.data(), bytes.size() / 4 * 4);
}

void require_atoms(const AtomTable& atoms, const std::filesystem::path& name) {
  if (atoms.values.size() < std::size_t{atoms.count} * VR_BLOCK_LENGTH)
    throw FormatError(
        name, "dictionary holds fewer than the " + str(atoms.count) + " atoms the frame needs");
}

/// Every value of every block of a checked payload and its codes (brick_decode.h's arithmetic,
/// vectorized over the block: each atom added to all 216 values at once, or the DCT basis's codes
/// as a separable transform).
void sum_blocks(const vr_uint* payload, const KsvdPayloadLayout& layout, const ParsedCode* codes,
                const AtomTable& atoms, BrickShape shape, std::span<float> out) {
  const float* atom_values = atoms.values.data();
  const vr_uint dct_first = atoms.dct_basis && atoms.count >= dct_basis_atoms
                                ? atoms.count - dct_basis_atoms
                                : atoms.count;
  const float mean_bias = vr_as_float(payload[0]), mean_scale = vr_as_float(payload[1]);
  const float coef_scale = vr_as_float(payload[2]);
  const vr_uint n = shape.blocks_per_axis(), size = shape.size;
  std::size_t code = 0;
  alignas(64) float outside[VR_BLOCK_LENGTH];  // a block outside the box: mean_bias everywhere
  std::fill_n(outside, VR_BLOCK_LENGTH, mean_bias);
  for (vr_uint b = 0, e = 0; b < shape.blocks(); ++b) {
    alignas(64) float coded[VR_BLOCK_LENGTH];
    const float* block = outside;
    if (vr_block_in_box(layout.box_word, n, b)) {
      const vr_uint entry = vr_block_entry(payload, layout.word, e++);
      const vr_uint s = vr_entry_sparsity(layout.word, entry);
      const float mean =
          mean_bias + mean_scale * static_cast<float>(vr_entry_mean(layout.word, entry));
      decode_block(coded, mean, codes + code, s, atom_values, coef_scale, dct_first);
      code += s;
      block = coded;
    }
    // Scatter the block into the brick, row by row.
    const vr_uint bx = b % n, by = (b / n) % n, bz = b / (n * n);
    for (vr_uint z = 0; z < 6; ++z)
      for (vr_uint y = 0; y < 6; ++y)
        std::memcpy(out.data() + ((bz * 6 + z) * size + by * 6 + y) * size + bx * 6,
                    block + (z * 6 + y) * 6, 6 * sizeof(float));
  }
}

void decode_ksvd(std::span<const std::byte> bytes, const AtomTable& atoms, BrickShape shape,
                 std::span<float> out, const std::filesystem::path& name, std::uint64_t at) {
  thread_local std::vector<vr_uint> payload;
  copy_padded(bytes, payload);
  // 1. Structure, dequantization values, atom indices and magnitudes; the codes, read once.
  thread_local std::vector<ParsedCode> codes;
  codes.clear();
  const KsvdPayloadLayout layout = parse_ksvd_payload(
      payload.data(), bytes.size() / 4, bytes.size(), atoms.count, shape, name, at, &codes);
  require_atoms(atoms, name);
  // 2. Every value of every block.
  sum_blocks(payload.data(), layout, codes.data(), atoms, shape, out);
}

/// A payload's code stream read a code at a time, so that two payloads' codes can be read in
/// step (read_in_step): the same reading and checks as parse_ksvd_payload, step 3, but a check
/// that fails returns false instead of naming what was wrong (that reader then runs again alone).
class SteppedCodes {
 public:
  /// After parse_ksvd_header on `payload` (word_count words and the zero padding words).
  SteppedCodes(const vr_uint* payload, std::size_t word_count, const KsvdPayloadLayout& layout,
               BrickShape shape, std::uint32_t atom_count, BandRice& band_rice)
      : payload_(payload),
        layout_(layout),
        n_(shape.blocks_per_axis()),
        blocks_(shape.blocks()),
        first_(vr_code_first_word(layout.word, vr_box_entries(layout.box_word))),
        stream_bits_((std::uint64_t{word_count} - first_) * 32),
        word_count_(word_count),
        atom_end_(codes_atom_end(atom_count, vr_block_first_atom(layout.word, layout.box_word),
                                 layout.atom_bits)),
        largest_(1u << layout.coef_bits),
        band_rice_(&band_rice),
        first_atom_(vr_block_first_atom(layout.word, layout.box_word)),
        stream_(payload, first_, layout.atom_bits, first_atom_, layout.box_word) {
    band_rice.reset(layout.word, layout.band_word, layout.box_word);
    for (vr_uint b = 0, e = 0; b < blocks_; ++b)
      if (vr_block_in_box(layout_.box_word, n_, b))
        layout_.codes +=
            vr_entry_sparsity(layout_.word, vr_block_entry(payload_, layout_.word, e++));
  }

  const KsvdPayloadLayout& layout() const { return layout_; }
  /// Codes not read yet.
  std::uint32_t left() const { return layout_.codes - read_; }

  /// Codes left in the current block; after begin_block, at least one.
  vr_uint in_block() const { return in_block_; }

  /// Moves to the next coded block that has codes (left() > 0: there is one).
  void begin_block() {
    while (in_block_ == 0) {
      const vr_uint b = block_++;
      if (!vr_block_in_box(layout_.box_word, n_, b)) continue;
      in_block_ = vr_entry_sparsity(layout_.word, vr_block_entry(payload_, layout_.word, entry_++));
      if (in_block_ == 0) continue;
      gap_rice_ = vr_gap_rice(layout_.word, in_block_);
      stream_.set_band_rice(band_rice_->block(in_block_));
      next_atom_ = first_atom_;
      run_ = 0;
    }
  }

  /// Reads the current block's next code into *out, without counting it (taken counts it); false
  /// where parse_ksvd_payload would throw.
  bool code(ParsedCode* out) {
    if (stream_.bit() >= stream_bits_) return false;
    vr_uint atom = 0;
    const int q =
        stream_.read(gap_rice_, layout_.atom_bits, layout_.coef_bits, next_atom_, run_, atom);
    *out = {atom, q};
    const vr_uint m = static_cast<vr_uint>(q < 0 ? -static_cast<std::int64_t>(q) : q);
    return atom < atom_end_ && m <= largest_;
  }

  /// Whether the current block's next `count` codes can be read with unchecked_code
  /// (stretch_inside).
  bool fits(vr_uint count) const { return stretch_inside(stream_.bit(), count, stream_bits_); }
  /// The current block's next code (fits), without the checks of code: those of a stretch of the
  /// block's codes are good's.
  void unchecked_code(ParsedCode* out, vr_uint& magnitudes) {
    vr_uint atom = 0, magnitude = 0;
    const int q = stream_.read(gap_rice_, layout_.atom_bits, layout_.coef_bits, next_atom_, run_,
                               atom, magnitude);
    *out = {atom, q};
    magnitudes |= magnitude;
  }
  /// code's checks over a stretch of unchecked codes of one block, the last of them `last`
  /// (stretch_good).
  bool good(const ParsedCode& last, vr_uint magnitudes) const {
    return stretch_good(last.atom, magnitudes, atom_end_, layout_.coef_bits);
  }

  /// Counts `count` codes of the current block as read; at the block's end, its runs' check.
  void taken(vr_uint count) {
    in_block_ -= count;
    read_ += count;
    runs_good_ = runs_good_ && (in_block_ != 0 || run_ended(run_));
  }

  /// Reads the current block's next `count` codes (at most in_block()) into out: unchecked and
  /// then checked once where they fit, code by code otherwise; false where parse_ksvd_payload
  /// would throw.
  bool codes(vr_uint count, ParsedCode* out) {
    if (fits(count)) {
      vr_uint magnitudes = 0;
      for (vr_uint k = 0; k < count; ++k) unchecked_code(out + k, magnitudes);
      if (!good(out[count - 1], magnitudes)) return false;
    } else {
      for (vr_uint k = 0; k < count; ++k)
        if (!code(out + k)) return false;
    }
    taken(count);  // after the codes: at the block's end, the runs' check takes its run state
    return true;
  }

  /// Reads every code left into out, a block at a time; false where parse_ksvd_payload would
  /// throw.
  bool rest(ParsedCode* out) {
    while (left() > 0) {
      begin_block();
      const vr_uint count = in_block_;
      if (!codes(count, out)) return false;
      out += count;
    }
    return true;
  }

  /// After every code: the payload's length and the zero bits after the last code, as
  /// parse_ksvd_payload checks them; sets the layout's code_bits.
  bool finish() {
    const std::uint64_t bit = stream_.bit();
    layout_.code_bits = bit;
    if (!runs_good_) return false;
    if (word_count_ != std::uint64_t{first_} + (bit + 31) / 32) return false;
    return bit % 32 == 0 || (payload_[word_count_ - 1] >> (bit % 32)) == 0;
  }

 private:
  const vr_uint* payload_;
  KsvdPayloadLayout layout_;
  vr_uint n_, blocks_, first_;
  std::uint64_t stream_bits_, word_count_;
  vr_uint atom_end_, largest_;
  const BandRice* band_rice_;
  vr_uint first_atom_;
  CodeStream stream_;
  vr_uint block_ = 0, entry_ = 0, in_block_ = 0, gap_rice_ = 0, next_atom_ = 0, run_ = 0;
  std::uint32_t read_ = 0;
  bool runs_good_ = true;  ///< every block read to its end ended its runs (run_ended)
};

/// Reads both payloads' codes into a and b, a code of each in turn while both have some: reading
/// a code is a chain of dependent steps (where the gap ends gives where the magnitude starts and
/// the atom, whose band gives the magnitude's Rice parameter), so two independent chains keep a
/// core busy where one leaves it waiting. False where either payload is bad.
[[VOLREEL_BMI_CLONES gnu::noinline]] bool read_in_step(SteppedCodes& first_reader,
                                                       ParsedCode* __restrict a,
                                                       SteppedCodes& second_reader,
                                                       ParsedCode* __restrict b) {
  // Copies the stores to a and b cannot alias: their state stays in registers.
  SteppedCodes first = first_reader, second = second_reader;
  while (first.left() > 0 && second.left() > 0) {
    // A block of each at a time, as far as the shorter one goes: no block bookkeeping inside.
    first.begin_block();
    second.begin_block();
    const vr_uint count = std::min(first.in_block(), second.in_block());
    if (first.fits(count) && second.fits(count)) {
      // Far enough from both streams' ends: the checks once for the stretch.
      vr_uint magnitudes_a = 0, magnitudes_b = 0;
      for (vr_uint k = 0; k < count; ++k) {
        first.unchecked_code(a++, magnitudes_a);
        second.unchecked_code(b++, magnitudes_b);
      }
      if (!first.good(a[-1], magnitudes_a) || !second.good(b[-1], magnitudes_b)) return false;
    } else {
      for (vr_uint k = 0; k < count; ++k) {
        const bool read_a = first.code(a++);
        const bool read_b = second.code(b++);
        if (!(read_a && read_b)) return false;
      }
    }
    first.taken(count);
    second.taken(count);
  }
  // The longer one's codes left, as one reader alone reads them.
  const bool good = first.rest(a) && second.rest(b) && first.finish() && second.finish();
  first_reader = first;
  second_reader = second;
  return good;
}

/// decode_ksvd on two payloads, their codes read in step; false when it decoded them one at a
/// time instead. A bad payload is decoded again alone, first then second, so that its error names
/// what was wrong.
bool decode_ksvd_pair(const PayloadJob& first, const PayloadJob& second, const AtomTable& atoms,
                      BrickShape shape) {
  thread_local std::vector<vr_uint> words[2];
  thread_local std::vector<ParsedCode> codes[2];
  thread_local BandRice band_rice[2];
  const PayloadJob* jobs[2] = {&first, &second};
  const auto alone = [&] {
    for (const PayloadJob* job : jobs)
      decode_ksvd(job->payload, atoms, shape, job->out, job->name, job->offset);
    return false;
  };
  std::optional<SteppedCodes> readers[2];
  try {
    for (int i = 0; i < 2; ++i) {
      const std::span<const std::byte> bytes = jobs[i]->payload;
      copy_padded(bytes, words[i]);
      const KsvdPayloadLayout header = parse_ksvd_header(
          words[i].data(), bytes.size() / 4, bytes.size(), shape, jobs[i]->name, jobs[i]->offset);
      readers[i].emplace(words[i].data(), bytes.size() / 4, header, shape, atoms.count,
                         band_rice[i]);
      if (codes[i].size() < readers[i]->left()) codes[i].resize(readers[i]->left());
    }
  } catch (const FormatError&) {
    return alone();  // throws the first bad payload's error
  }
  if (!read_in_step(*readers[0], codes[0].data(), *readers[1], codes[1].data())) return alone();
  require_atoms(atoms, first.name);
  for (int i = 0; i < 2; ++i)
    sum_blocks(words[i].data(), readers[i]->layout(), codes[i].data(), atoms, shape, jobs[i]->out);
  return true;
}

/// A little-endian bit stream growing word by word (the inverse of vr_read_bits).
class BitWriter {
 public:
  void put(vr_uint width, vr_uint value) {
    if (width == 0) return;
    const std::size_t word = static_cast<std::size_t>(bits_ / 32);
    const vr_uint shift = static_cast<vr_uint>(bits_ % 32);
    if (word + 1 >= words_.size()) words_.resize(word + 2, 0u);
    words_[word] |= value << shift;
    if (shift + width > 32) words_[word + 1] |= value >> (32 - shift);
    bits_ += width;
  }
  /// A Rice code of x with parameter k (brick_decode.h, vr_read_rice).
  void rice(vr_uint x, vr_uint k, vr_uint escape_bits) {
    const vr_uint zeros = x >> k;
    if (zeros >= VR_ESCAPE_ZEROS) {
      put(VR_ESCAPE_ZEROS, 0);
      put(escape_bits, x);
      return;
    }
    put(zeros + 1, 1u << zeros);
    put(k, x & ((1u << k) - 1u));
  }
  std::uint64_t bits() const { return bits_; }
  /// The stream's words, zero bits up to the next word.
  std::vector<vr_uint> words() const {
    std::vector<vr_uint> w(words_.begin(),
                           words_.begin() + static_cast<std::ptrdiff_t>((bits_ + 31) / 32));
    return w;
  }

 private:
  std::vector<vr_uint> words_;
  std::uint64_t bits_ = 0;
};

/// Writes the code stream of `parts` under `layout` and the band and box words.
void write_codes(const KsvdPayloadParts& parts, vr_uint layout, vr_uint payload_band_word,
                 vr_uint box, BitWriter& out) {
  std::size_t k = 0;
  for (std::size_t b = 0; b < parts.sparsity.size(); ++b) {
    const vr_uint s = parts.sparsity[b];
    if (s == 0) continue;
    const vr_uint gap_rice = vr_gap_rice(layout, s);
    const vr_uint band_word = vr_block_band_word(payload_band_word, box, s);
    BlockGaps gaps(parts.atoms.data() + k, s, vr_block_first_atom(layout, box),
                   vr_box_run_limit(box));
    for (vr_uint j = 0; j < s; ++j, ++k) {
      const BlockGaps::Codes codes = gaps.next();
      if (codes.run >= 0)
        out.rice(static_cast<vr_uint>(codes.run), vr_box_run_rice(box), VR_MAX_SPARSITY_BITS);
      if (codes.gap >= 0) out.rice(static_cast<vr_uint>(codes.gap), gap_rice, parts.atom_bits);
      const vr_uint magnitude = static_cast<vr_uint>(std::abs(std::int64_t{parts.values[k]}) - 1);
      out.rice(magnitude, vr_band_rice(layout, band_word, parts.atoms[k]), parts.coef_bits);
      out.put(1, parts.values[k] < 0 ? 1u : 0u);
    }
  }
}

/// Counts of the values one Rice parameter codes, so that the bits of every parameter are summed
/// over the distinct values rather than over the codes (a dense brick has 10⁵ codes and few
/// distinct gaps and magnitudes).
class RiceTally {
 public:
  void add(vr_uint x) {
    if (x < small) {
      ++counts_[x];
      end_ = std::max(end_, x + 1);
    } else {
      large_.push_back(x);
    }
  }
  /// Σ rice_bits(x, k, escape_bits) over the values added.
  std::uint64_t bits(vr_uint k, vr_uint escape_bits) const {
    std::uint64_t sum = 0;
    for (vr_uint x = 0; x < end_; ++x)
      if (counts_[x] != 0) sum += counts_[x] * rice_bits(x, k, escape_bits);
    for (const vr_uint x : large_) sum += rice_bits(x, k, escape_bits);
    return sum;
  }
  bool empty() const { return end_ == 0 && large_.empty(); }

 private:
  static constexpr vr_uint small = 64;
  std::array<std::uint64_t, small> counts_{};
  vr_uint end_ = 0;
  std::vector<vr_uint> large_;
};

/// The entropy coder's parameters with the fewest bits for `parts` (or those the parts fix:
/// magnitude_model ≥ 0, a band_rice ≥ 0, gap_shift ≥ 0, run_limit ≥ 0, run_rice ≥ 0): the
/// magnitude model (brick_decode.h, vr_magnitude_move) and band word, then the gap shift, run
/// limit and runs' parameter together. The magnitudes are tallied by band and sparsity class
/// floor(log2(s + 1)), each model adding up the bits of its moved parameters; for each run limit
/// of run_limit_candidates, the run lengths and the gaps by sparsity class (BlockGaps), each shift
/// taking its class's parameter (vr_gap_rice).
struct CoderChoice {
  vr_uint magnitude_model, band_word, gap_shift, run_limit, run_rice;
};
/// The run limits the packer tries: 0 (no runs) and limits spaced by about √2, up to every
/// position an 8-bit index names.
constexpr std::array<vr_uint, 17> run_limit_candidates{0,  1,  2,  3,  4,  6,   8,   12, 16,
                                                       24, 32, 48, 64, 96, 128, 192, 255};
CoderChoice choose_coder(const KsvdPayloadParts& parts, vr_uint first_atom,
                         const std::function<vr_uint(vr_uint)>& layout_of) {
  constexpr vr_uint classes = VR_MAX_SPARSITY_BITS + 1;  // floor(log2(s + 1)) ≤ 8
  static_assert(VR_MAX_MAGNITUDE_MODEL == classes);
  const vr_uint layout = layout_of(0);
  std::vector<RiceTally> magnitudes(VR_ATOM_BANDS * classes);
  std::size_t k = 0;
  for (std::size_t b = 0; b < parts.sparsity.size(); ++b) {
    const vr_uint s = parts.sparsity[b], c = vr_highest_bit(s + 1u);
    for (vr_uint j = 0; j < s; ++j, ++k) {
      const vr_uint magnitude = static_cast<vr_uint>(std::abs(std::int64_t{parts.values[k]}) - 1);
      magnitudes[vr_atom_band(layout, parts.atoms[k]) * classes + c].add(magnitude);
    }
  }
  std::array<std::array<std::array<std::uint64_t, 16>, classes>, VR_ATOM_BANDS> bits{};
  for (vr_uint band = 0; band < VR_ATOM_BANDS; ++band)
    for (vr_uint c = 0; c < classes; ++c) {
      const RiceTally& tally = magnitudes[band * classes + c];
      if (!tally.empty())
        for (vr_uint r = 0; r < 16; ++r) bits[band][c][r] = tally.bits(r, parts.coef_bits);
    }
  // The band word and bits of model m: a band's parameter r costs, in the blocks of class c,
  // the bits of r moved by the class's move.
  const auto candidate = [&](vr_uint m) {
    const vr_uint box = vr_box_with_magnitude_model(0, m);
    vr_uint band_word = 0;
    std::uint64_t total = 0;
    for (vr_uint band = 0; band < VR_ATOM_BANDS; ++band) {
      std::array<std::uint64_t, 16> band_bits{};
      for (vr_uint c = 0; c < classes; ++c) {
        const int move = vr_magnitude_move(box, (1u << c) - 1u);  // s = 2^c − 1 is of class c
        for (vr_uint r = 0; r < 16; ++r)
          band_bits[r] += bits[band][c][vr_moved_band_word(r, move) & 0xFu];  // r as band 0
      }
      const vr_uint r =
          parts.band_rice[band] >= 0
              ? static_cast<vr_uint>(parts.band_rice[band])
              : static_cast<vr_uint>(std::min_element(band_bits.begin(), band_bits.end()) -
                                     band_bits.begin());
      band_word |= r << (4 * band);
      total += band_bits[r];
    }
    return std::pair{band_word, total};
  };
  CoderChoice choice{0, 0, 0, 0, 0};
  std::uint64_t fewest = ~std::uint64_t{0};
  for (vr_uint m = 0; m <= VR_MAX_MAGNITUDE_MODEL; ++m) {
    if (parts.magnitude_model >= 0 && m != static_cast<vr_uint>(parts.magnitude_model)) continue;
    const auto [band_word, total] = candidate(m);
    if (total < fewest) choice.magnitude_model = m, fewest = total, choice.band_word = band_word;
  }
  // The gaps: for each run limit, the run lengths' tally and the gaps' by sparsity class.
  const vr_uint fixed_limit = static_cast<vr_uint>(std::max(parts.run_limit, 0));
  fewest = ~std::uint64_t{0};
  const std::span<const vr_uint> limits = parts.run_limit >= 0
                                              ? std::span<const vr_uint>(&fixed_limit, 1)
                                              : std::span<const vr_uint>(run_limit_candidates);
  for (const vr_uint limit : limits) {
    RiceTally runs;
    std::array<RiceTally, classes> gaps;
    k = 0;
    for (std::size_t b = 0; b < parts.sparsity.size(); ++b) {
      const vr_uint s = parts.sparsity[b], c = vr_highest_bit(s + 1u);
      BlockGaps block(parts.atoms.data() + k, s, first_atom, limit);
      for (vr_uint j = 0; j < s; ++j) {
        const BlockGaps::Codes codes = block.next();
        if (codes.run >= 0) runs.add(static_cast<vr_uint>(codes.run));
        if (codes.gap >= 0) gaps[c].add(static_cast<vr_uint>(codes.gap));
      }
      k += s;
    }
    // Run lengths: the parameter of the fewest bits (0 when there are none).
    std::uint64_t run_bits = 0;
    vr_uint run_rice = parts.run_rice >= 0 ? static_cast<vr_uint>(parts.run_rice) : 0;
    if (!runs.empty()) {
      run_bits = ~std::uint64_t{0};
      for (vr_uint r = 0; r <= VR_MAX_RUN_RICE; ++r) {
        if (parts.run_rice >= 0 && r != static_cast<vr_uint>(parts.run_rice)) continue;
        const std::uint64_t bits_r = runs.bits(r, VR_MAX_SPARSITY_BITS);
        if (bits_r < run_bits) run_bits = bits_r, run_rice = r;
      }
    }
    for (vr_uint g = 0; g <= VR_MAX_GAP_SHIFT; ++g) {
      if (parts.gap_shift >= 0 && g != static_cast<vr_uint>(parts.gap_shift)) continue;
      std::uint64_t total = run_bits;
      for (vr_uint c = 0; c < classes; ++c)
        if (!gaps[c].empty())
          total += gaps[c].bits(vr_gap_rice(layout_of(g), (1u << c) - 1u), parts.atom_bits);
      if (total < fewest)
        fewest = total, choice.gap_shift = g, choice.run_limit = limit, choice.run_rice = run_rice;
    }
  }
  return choice;
}

}  // namespace

AtomTable atom_table(std::span<const float> values, std::uint32_t count) {
  AtomTable table{values, count};
  const std::vector<float>& dct = dct_tables().atoms;
  if (count >= dct_basis_atoms && values.size() >= std::size_t{count} * VR_BLOCK_LENGTH) {
    const float* tail = values.data() + std::size_t{count - dct_basis_atoms} * VR_BLOCK_LENGTH;
    table.dct_basis = std::memcmp(tail, dct.data(), dct.size() * sizeof(float)) == 0;
  }
  return table;
}

std::uint64_t rice_bits(std::uint32_t x, std::uint32_t k, std::uint32_t escape_bits) {
  const std::uint32_t zeros = x >> k;
  return zeros >= VR_ESCAPE_ZEROS ? VR_ESCAPE_ZEROS + escape_bits : zeros + 1 + k;
}

std::uint32_t bits_for_count(std::uint64_t count) {
  std::uint32_t bits = 0;
  while (bits < 64 && (std::uint64_t{1} << bits) < count) ++bits;
  return bits;
}

std::vector<std::byte> pack_ksvd_payload(const KsvdPayloadParts& parts) {
  if (parts.mean_bits > VR_MEAN_BITS || parts.sparsity_bits > VR_MAX_SPARSITY_BITS ||
      parts.coef_bits < 1 || parts.coef_bits > VR_MAX_COEF_BITS || parts.atom_bits < 1 ||
      parts.atom_bits > VR_MAX_ATOM_BITS || parts.gap_shift > int{VR_MAX_GAP_SHIFT} ||
      parts.band_split > VR_MAX_BAND_SPLIT ||
      parts.magnitude_model > static_cast<int>(VR_MAX_MAGNITUDE_MODEL) ||
      parts.run_limit > static_cast<int>(VR_MAX_RUN_LIMIT) ||
      parts.run_rice > static_cast<int>(VR_MAX_RUN_RICE) ||
      std::any_of(parts.band_rice.begin(), parts.band_rice.end(), [](int k) { return k > 15; }))
    throw std::invalid_argument(
        "payload widths out of range: mean " + str(parts.mean_bits) + ", sparsity " +
        str(parts.sparsity_bits) + ", magnitude " + str(parts.coef_bits) + ", atom " +
        str(parts.atom_bits) + " bits, gap shift " + std::to_string(parts.gap_shift) +
        ", magnitude model " + std::to_string(parts.magnitude_model) + ", run limit " +
        std::to_string(parts.run_limit) + ", run parameter " + std::to_string(parts.run_rice) +
        " or a band's Rice parameter over 15");
  const std::size_t blocks = parts.sparsity.size();
  bool brick_blocks = false;  // n³ for a brick size 6n
  for (std::uint32_t size = min_brick_size; size <= max_brick_size; size += brick_block_size)
    brick_blocks = brick_blocks || BrickShape{size}.blocks() == blocks;
  if (blocks != parts.mean.size() || !brick_blocks)
    throw std::invalid_argument(str(parts.sparsity.size()) + " sparsities and " +
                                str(parts.mean.size()) +
                                " means: not one each per block of a brick (n³, n = 2..11)");
  const auto n = static_cast<vr_uint>(std::lround(std::cbrt(static_cast<double>(blocks))));
  vr_uint box_n[3];
  for (std::size_t a = 0; a < 3; ++a) {
    if (parts.box[a] > n)
      throw std::invalid_argument("box of " + str(parts.box[0]) + " x " + str(parts.box[1]) +
                                  " x " + str(parts.box[2]) + " blocks in a brick of " + str(n) +
                                  " a side");
    box_n[a] = parts.box[a] == 0 ? n : parts.box[a];
  }
  const vr_uint blocks_box = vr_make_box(box_n[0], box_n[1], box_n[2]);
  std::uint64_t codes = 0;
  for (std::size_t b = 0; b < blocks; ++b) {
    if (!vr_block_in_box(blocks_box, n, static_cast<vr_uint>(b)) && parts.sparsity[b] != 0)
      throw std::invalid_argument("block " + str(b) + " outside the box of coded blocks has " +
                                  str(parts.sparsity[b]) + " atoms");
    if ((std::uint64_t{parts.sparsity[b]} >> parts.sparsity_bits) != 0 ||
        (std::uint64_t{parts.mean[b]} >> parts.mean_bits) != 0)
      throw std::invalid_argument("block " + str(b) + ": sparsity " + str(parts.sparsity[b]) +
                                  " or mean " + str(parts.mean[b]) + " does not fit its bits");
    codes += parts.sparsity[b];
  }
  if (codes != parts.atoms.size() || codes != parts.values.size())
    throw std::invalid_argument(str(parts.atoms.size()) + " atoms and " + str(parts.values.size()) +
                                " values for sparsities summing to " + str(codes));
  std::size_t k = 0;
  const vr_uint first_atom = parts.from_split ? parts.band_split : 0;
  for (std::size_t b = 0; b < blocks; ++b)
    for (vr_uint j = 0; j < parts.sparsity[b]; ++j, ++k) {
      const std::int64_t magnitude = std::abs(std::int64_t{parts.values[k]});
      if (parts.atoms[k] < first_atom ||
          (std::uint64_t{parts.atoms[k] - first_atom} >> parts.atom_bits) != 0 || magnitude == 0 ||
          magnitude > (std::int64_t{1} << parts.coef_bits) ||
          (j > 0 && parts.atoms[k] <= parts.atoms[k - 1]))
        throw std::invalid_argument("code " + str(k) + " (block " + str(b) + "): atom " +
                                    str(parts.atoms[k]) + " or value " +
                                    std::to_string(parts.values[k]) +
                                    " does not fit its bits, is zero, is out of order or is below "
                                    "the band split under the split flag");
    }
  // The entropy coder's parameters: the magnitude model and each band's parameter with the
  // fewest bits for the magnitudes, then the gap shift, run limit and runs' parameter with the
  // fewest bits for the gaps and runs.
  const auto layout_of = [&](vr_uint gap_shift) {
    return vr_make_layout(parts.mean_bits, parts.sparsity_bits, parts.coef_bits, parts.atom_bits,
                          gap_shift, parts.band_split);
  };
  const auto [magnitude_model, band_word, gap_shift, run_limit, run_rice] =
      choose_coder(parts, first_atom, layout_of);
  const vr_uint box = vr_box_with_runs(
      vr_box_with_split_flag(vr_box_with_magnitude_model(blocks_box, magnitude_model),
                             parts.from_split ? 1u : 0u),
      run_limit, run_rice);
  const vr_uint layout = layout_of(gap_shift);

  BitWriter entries, stream;
  for (std::size_t b = 0; b < blocks; ++b)
    if (vr_block_in_box(box, n, static_cast<vr_uint>(b)))
      entries.put(vr_layout_entry_bits(layout),
                  parts.sparsity[b] | (parts.mean[b] << parts.sparsity_bits));
  write_codes(parts, layout, band_word, box, stream);
  const std::vector<vr_uint> entry_words = entries.words(), code_words = stream.words();
  std::vector<std::byte> payload(4 * (VR_HEADER_WORDS + entry_words.size() + code_words.size()));
  std::memcpy(payload.data(), parts.dequantization, 12);
  std::memcpy(payload.data() + 12, &layout, 4);
  std::memcpy(payload.data() + 16, &band_word, 4);
  std::memcpy(payload.data() + 20, &box, 4);
  std::size_t at = 4 * VR_HEADER_WORDS;
  for (const std::vector<vr_uint>* part : {&entry_words, &code_words})
    for (const vr_uint w : *part) {
      std::memcpy(payload.data() + at, &w, 4);
      at += 4;
    }
  return payload;
}

KsvdPayloadParts unpack_ksvd_payload(std::span<const std::byte> bytes, std::uint32_t atom_count,
                                     BrickShape shape, const std::filesystem::path& name,
                                     std::uint64_t at) {
  std::vector<vr_uint> words(bytes.size() / 4 + payload_padding_words, 0u);
  if (bytes.size() >= 4) std::memcpy(words.data(), bytes.data(), bytes.size() / 4 * 4);
  const vr_uint* payload = words.data();
  std::vector<ParsedCode> codes;  // read once, by the check
  const KsvdPayloadLayout layout = parse_ksvd_payload(payload, bytes.size() / 4, bytes.size(),
                                                      atom_count, shape, name, at, &codes);
  KsvdPayloadParts parts;
  parts.sparsity.resize(shape.blocks());
  parts.mean.resize(shape.blocks());
  std::memcpy(parts.dequantization, payload, 12);
  parts.mean_bits = layout.mean_bits;
  parts.sparsity_bits = layout.sparsity_bits;
  parts.coef_bits = layout.coef_bits;
  parts.atom_bits = layout.atom_bits;
  for (vr_uint band = 0; band < VR_ATOM_BANDS; ++band)
    parts.band_rice[band] = static_cast<int>((layout.band_word >> (4 * band)) & 0xF);
  parts.gap_shift = static_cast<int>(vr_layout_gap_shift(layout.word));
  parts.magnitude_model = static_cast<int>(vr_box_magnitude_model(layout.box_word));
  parts.run_limit = static_cast<int>(vr_box_run_limit(layout.box_word));
  parts.run_rice = static_cast<int>(vr_box_run_rice(layout.box_word));
  parts.from_split = vr_box_from_split(layout.box_word) != 0;
  parts.band_split = vr_layout_band_split(layout.word);
  const vr_uint n = shape.blocks_per_axis();
  for (std::size_t a = 0; a < 3; ++a)
    parts.box[a] = vr_box_blocks(layout.box_word, static_cast<vr_uint>(a));
  for (vr_uint b = 0, e = 0; b < shape.blocks(); ++b) {
    if (!vr_block_in_box(layout.box_word, n, b)) continue;  // sparsity and mean 0
    const vr_uint entry = vr_block_entry(payload, layout.word, e++);
    parts.sparsity[b] = vr_entry_sparsity(layout.word, entry);
    parts.mean[b] = vr_entry_mean(layout.word, entry);
  }
  for (const ParsedCode& code : codes) {
    parts.atoms.push_back(code.atom);
    parts.values.push_back(code.q);
  }
  return parts;
}

std::uint32_t ksvd_box_word(std::span<const std::byte> payload) {
  if (payload.size() < 4 * VR_HEADER_WORDS) return 0;
  std::uint32_t word;
  std::memcpy(&word, payload.data() + 4 * 5, 4);
  return word;
}

KsvdPayloadLayout check_ksvd_payload(std::span<const std::byte> bytes, std::uint32_t atom_count,
                                     BrickShape shape, const std::filesystem::path& name,
                                     std::uint64_t at) {
  std::vector<vr_uint> words(bytes.size() / 4);
  if (!words.empty()) std::memcpy(words.data(), bytes.data(), 4 * words.size());
  return check_ksvd_payload(words, bytes.size(), atom_count, shape, name, at);
}

KsvdPayloadLayout check_ksvd_payload(std::span<const std::uint32_t> words, std::size_t bytes,
                                     std::uint32_t atom_count, BrickShape shape,
                                     const std::filesystem::path& name, std::uint64_t at) {
  std::vector<vr_uint> padded(words.size() + payload_padding_words, 0u);
  std::copy(words.begin(), words.end(), padded.begin());
  return parse_ksvd_payload(padded.data(), words.size(), bytes, atom_count, shape, name, at,
                            nullptr);
}

namespace {

void decode_zfp(std::span<const std::byte> bytes, double accuracy, BrickShape shape,
                std::span<float> out, const std::filesystem::path& name, std::uint64_t at) {
  ZfpStream zfp(ZfpMode::accuracy(accuracy), shape.size, shape.size, shape.size);
  // zfp reads without bounds checks: give it a zero-padded copy as long as the longest stream.
  std::vector<std::byte> padded(std::max<std::size_t>(zfp.maximum_size(), bytes.size()) + 64);
  if (!bytes.empty()) std::memcpy(padded.data(), bytes.data(), bytes.size());
  const std::size_t used = zfp.decompress(padded.data(), padded.size(), out.data());
  if (used == 0 || used > bytes.size() + 8)
    throw FormatError(name, at, "brick payload: a zfp stream of " + str(bytes.size()) + " bytes",
                      "a stream that needs " + str(used) + " bytes");
  for (std::size_t i = 0; i < out.size(); ++i)
    if (!std::isfinite(out[i]))
      throw FormatError(name, at, "brick payload: finite decoded values", "NaN or infinity");
}

}  // namespace

void decode_payload(std::span<const std::byte> bytes, Codec codec, double zfp_accuracy,
                    const AtomTable& atoms, BrickShape shape, std::span<float> out,
                    const std::filesystem::path& name, std::uint64_t offset) {
  if (!valid_brick_size(shape.size) || out.size() != shape.voxels())
    throw FormatError(name, "decode_payload needs a brick size in 12..66, a multiple of 6 (not " +
                                str(shape.size) + "), and an output of its cube of values (not " +
                                str(out.size()) + ")");
  // A 4-byte payload is a constant brick (either codec).
  if (bytes.size() == 4) {
    float v;
    std::memcpy(&v, bytes.data(), 4);
    if (!std::isfinite(v))
      throw FormatError(name, offset, "brick payload: a finite constant", "NaN or infinity");
    std::fill(out.begin(), out.end(), v);
    return;
  }
  if (codec == Codec::ksvd)
    decode_ksvd(bytes, atoms, shape, out, name, offset);
  else
    decode_zfp(bytes, zfp_accuracy, shape, out, name, offset);
}

std::size_t decode_payloads(std::span<const PayloadJob> jobs, Codec codec, const AtomTable& atoms,
                            BrickShape shape) {
  const auto is_ksvd_stream = [&](const PayloadJob& job) {
    return codec == Codec::ksvd && job.payload.size() != 4 && valid_brick_size(shape.size) &&
           job.out.size() == shape.voxels();
  };
  std::size_t i = 0, in_step = 0;
  while (i < jobs.size()) {
    if (i + 1 < jobs.size() && is_ksvd_stream(jobs[i]) && is_ksvd_stream(jobs[i + 1])) {
      if (decode_ksvd_pair(jobs[i], jobs[i + 1], atoms, shape)) in_step += 2;
      i += 2;
    } else {
      const PayloadJob& job = jobs[i++];
      decode_payload(job.payload, codec, job.zfp_accuracy, atoms, shape, job.out, job.name,
                     job.offset);
    }
  }
  return in_step;
}

PayloadJob brick_job(const FrameView& frame, std::uint32_t brick, std::span<float> out) {
  if (brick >= frame.brick_count())
    throw FormatError(frame.name(),
                      "no brick " + str(brick) + " (frame has " + str(frame.brick_count()) + ")");
  return {frame.checked_brick_bytes(brick), out, frame.name(), frame.brick_offset(brick),
          frame.header().codec_parameter};
}

void decode_bricks(std::span<const BrickToDecode> bricks, const AtomTable& atoms) {
  if (bricks.empty()) return;
  const FrameView& first = *bricks[0].frame;
  const auto describe = [](const FrameView& f) {
    return std::string(f.codec() == Codec::ksvd ? "ksvd" : "zfp") + ", bricks of " +
           str(f.shape().size) + "³";
  };
  std::vector<PayloadJob> jobs;
  jobs.reserve(bricks.size());
  for (const BrickToDecode& b : bricks) {
    try {
      if (b.frame->codec() != first.codec() || b.frame->shape().size != first.shape().size)
        throw FormatError(b.frame->name(), 0,
                          "frame header: the codec and brick size of " + first.name().string() +
                              " (" + describe(first) + ")",
                          describe(*b.frame));
      jobs.push_back(brick_job(*b.frame, b.brick, b.out));
    } catch (const FormatError&) {
      decode_payloads(jobs, first.codec(), atoms, first.shape());  // an earlier brick's error first
      throw;
    }
  }
  decode_payloads(jobs, first.codec(), atoms, first.shape());
}

void decode_brick(const FrameView& frame, std::uint32_t brick, const AtomTable& atoms,
                  std::span<float> out) {
  const PayloadJob job = brick_job(frame, brick, out);
  decode_payload(job.payload, frame.codec(), job.zfp_accuracy, atoms, frame.shape(), out, job.name,
                 job.offset);
}

void place_in_level(const NodePosition& p, std::uint32_t level, std::array<std::uint32_t, 3> dims,
                    BrickShape shape, std::span<const float> brick, std::span<float> out) {
  const std::size_t brick_size = shape.size;
  const std::size_t nx = dims[0], ny = dims[1], nz = dims[2];
  const std::size_t scale = std::size_t{1}
                            << (level - p.level);  // a node voxel covers scale³ voxels of `level`
  const std::size_t span_voxels = shape.interior() * scale;
  const std::size_t x0 = p.x * span_voxels, y0 = p.y * span_voxels, z0 = p.z * span_voxels;
  const std::size_t x1 = std::min(nx, x0 + span_voxels), y1 = std::min(ny, y0 + span_voxels),
                    z1 = std::min(nz, z0 + span_voxels);
  for (std::size_t z = z0; z < z1; ++z)
    for (std::size_t y = y0; y < y1; ++y) {
      float* row = out.data() + (z * ny + y) * nx;
      if (p.level == level) {
        const float* src =
            brick.data() + ((z - z0 + 1) * brick_size + (y - y0 + 1)) * brick_size + 1;
        std::memcpy(row + x0, src, (x1 - x0) * sizeof(float));
      } else {
        std::fill(row + x0, row + x1, brick[0]);
      }
    }
}

std::vector<std::uint32_t> level_work(const FrameView& frame, std::uint32_t level) {
  if (level >= frame.level_count())
    throw FormatError(frame.name(), "no level " + str(level) + " (frame has " +
                                        str(frame.level_count()) + " levels)");
  std::vector<std::uint32_t> work;
  for (std::uint32_t l = 0; l <= level; ++l) {
    const LevelEntry& e = frame.level(l);
    for (std::uint32_t i = e.first_node; i < e.first_node + e.node_count; ++i)
      if (l == level || frame.node(i).type() == NodeType::empty) work.push_back(i);
  }
  return work;
}

void decode_level(const FrameView& frame, std::uint32_t level, const AtomTable& atoms,
                  std::span<float> out) {
  // 1. Nodes of this level and empty nodes above it, in one list.
  const std::vector<std::uint32_t> work = level_work(frame, level);
  const LevelEntry& target = frame.level(level);
  if (out.size() != std::size_t{target.dims[0]} * target.dims[1] * target.dims[2])
    throw FormatError(frame.name(), "decode_level: output of the wrong size");
  for (std::uint32_t i : work)
    if (!frame.has_brick(i))
      throw FormatError(frame.name(), "node " + str(i) +
                                          " has no brick at this time step (it is interpolated "
                                          "between its keyframes: decode the time step through "
                                          "its container, format::TimeStepDecoder)");
  // 2. Decode each brick and copy its interior (or its constant region) into the volume.
  std::exception_ptr error;
  const auto n = static_cast<std::ptrdiff_t>(work.size());
  // Two bricks at a time (decode_payloads reads their codes in step).
  const std::ptrdiff_t pairs = (n + 1) / 2;
#pragma omp parallel
  {
    const std::size_t voxels = frame.shape().voxels();
    std::vector<float> bricks(2 * voxels);
#pragma omp for schedule(dynamic, 2)
    for (std::ptrdiff_t p = 0; p < pairs; ++p) {
      const std::size_t first = 2 * static_cast<std::size_t>(p);
      const std::size_t count = std::min<std::size_t>(2, work.size() - first);
      BrickToDecode pair[2];
      for (std::size_t j = 0; j < count; ++j)
        pair[j] = {&frame, frame.node(work[first + j]).brick, {bricks.data() + j * voxels, voxels}};
      try {
        decode_bricks({pair, count}, atoms);
      } catch (const FormatError&) {
#pragma omp critical(volreel_decode_error)
        if (!error) error = std::current_exception();
        continue;
      }
      for (std::size_t j = 0; j < count; ++j)
        place_in_level(frame.position(work[first + j]), level,
                       {target.dims[0], target.dims[1], target.dims[2]}, frame.shape(), pair[j].out,
                       out);
    }
  }
  if (error) std::rethrow_exception(error);
}

LevelVolume decode_level(const FrameView& frame, std::uint32_t level, const AtomTable& atoms) {
  if (level >= frame.level_count())
    throw FormatError(frame.name(), "no level " + str(level) + " (frame has " +
                                        str(frame.level_count()) + " levels)");
  LevelVolume v;
  const LevelEntry& e = frame.level(level);
  v.dims = {e.dims[0], e.dims[1], e.dims[2]};
  v.data.resize(std::size_t{e.dims[0]} * e.dims[1] * e.dims[2]);
  decode_level(frame, level, atoms, v.data);
  return v;
}

void validate_payloads(const FrameView& frame, const AtomTable& atoms) {
  std::vector<float> brick(frame.shape().voxels());
  for (std::uint32_t b = 0; b < frame.brick_count(); ++b) decode_brick(frame, b, atoms, brick);
}

}  // namespace volreel::format
