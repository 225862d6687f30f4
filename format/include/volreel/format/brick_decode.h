// brick_decode.h: the bit layout of a sparse-coded brick payload and the per-block decode, in
// plain C-like arithmetic on 32-bit words so that the same text compiles as C++ (the CPU reference
// decoder, unit-tested) and as GLSL (the decode compute shader), in the manner of NanoVDB's
// PNanoVDB.h. Layout in format/SPEC.md, "Brick payload"; MTV-Player §3.2 and Fig. 3.
//
// A payload is an array of little-endian 32-bit words:
//   words 0..2            f32 mean_bias, mean_scale, coef_scale (bit patterns)
//   word 3                the layout word: bits b of a quantized mean, t of a sparsity field,
//                         c of a magnitude, a of an atom index, and the gaps' Rice shift
//                         (vr_layout_*)
//   word 4                the band word: the magnitudes' Rice parameter of each of 8 atom
//                         bands, 4 bits each (vr_band_rice)
//   word 5                the box word: the coded blocks nx·ny·nz of the brick's n³
//                         (n = brick size / 6; vr_box_*), the magnitude model, how a
//                         block's sparsity moves the band parameters (vr_block_band_word),
//                         whether the codes name atoms from the band split on
//                         (vr_block_first_atom), and where runs of consecutive atoms are coded
//                         as runs (vr_read_gap)
//   entry[nx·ny·nz]       per coded block, t + b bits each, one bit stream from bit 0 of word 6
//                         (low bit first): sparsity s in the low t bits, quantized mean q above;
//                         zero bits up to the next word
//   codes                 one bit stream from the next word, block after block, each block's
//                         codes in increasing atom order: the gap to the atom (or a run of
//                         consecutive atoms) and the magnitude as Rice codes, then the sign
//                         (vr_read_code); zero bits up to the next word
// Dequantization: mean = mean_bias + mean_scale·q, coefficient = coef_scale·q (q ≠ 0 signed).
// The codes have variable length, so a decoder walks a brick's blocks in order, keeping the bit
// position from block to block.
//
// The host side (C++) includes it as it is: the functions read from a
// `const vr_uint*` span; a GLSL includer defines VR_GLSL and provides
//   vr_uint vr_load_word(vr_uint index)    (the payload storage buffer)
//   float   vr_load_atom(vr_uint index)    (the dictionary storage buffer, atom-major)
// and uses the same functions without the pointer parameters (see VR_PAYLOAD_ARG below).
#ifndef VOLREEL_FORMAT_BRICK_DECODE_H
#define VOLREEL_FORMAT_BRICK_DECODE_H

#ifndef VR_GLSL
#include <bit>
#include <cstdint>
#include <cstring>
typedef std::uint32_t vr_uint;
#define VR_INLINE inline
/// Payload and dictionary accessors for the host: explicit pointer parameters.
#define VR_PAYLOAD_PARAM const vr_uint *payload,
#define VR_PAYLOAD_ARG payload,
#define VR_PAYLOAD_PARAM_ONLY const vr_uint* payload
#define VR_PAYLOAD_ARG_ONLY payload
#define VR_ATOMS_PARAM const float *atoms,
#define VR_ATOMS_ARG atoms,
#define VR_INOUT(type, name) type& name
#define VR_LOAD_WORD(i) payload[i]
#define VR_LOAD_ATOM(i) atoms[i]
VR_INLINE float vr_as_float(vr_uint bits) {
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}
#else
#define vr_uint uint
#define VR_INLINE
#define VR_PAYLOAD_PARAM
#define VR_PAYLOAD_ARG
#define VR_PAYLOAD_PARAM_ONLY
#define VR_PAYLOAD_ARG_ONLY
#define VR_ATOMS_PARAM
#define VR_ATOMS_ARG
#define VR_INOUT(type, name) inout type name
#define VR_LOAD_WORD(i) vr_load_word(i)
#define VR_LOAD_ATOM(i) vr_load_atom(i)
#define vr_as_float(bits) uintBitsToFloat(bits)
#endif

/* Constants of format version 10 (SPEC.md). A brick of a container is n·6 voxels a side (n
 * blocks, 2 ≤ n ≤ 11: the manifest's brick_size), its blocks x fastest; the functions below take
 * the number of blocks of a brick, n³. A GLSL includer declares n as a specialization constant,
 * `layout(constant_id = ...) const uint VR_BLOCKS_PER_AXIS`, before including this file. */
#define VR_BLOCK_SIZE 6u           /* M */
#define VR_BLOCK_LENGTH 216u       /* m = M³ values per block */
#define VR_MAX_BLOCKS_PER_AXIS 11u /* the largest brick: 66³ voxels */
#ifdef VR_GLSL
#define VR_BRICK_SIZE (VR_BLOCKS_PER_AXIS * VR_BLOCK_SIZE) /* stored voxels per axis */
#define VR_BRICK_INTERIOR (VR_BRICK_SIZE - 2u)             /* interior voxels per axis */
#define VR_BLOCKS_PER_BRICK (VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS)
#endif
#define VR_HEADER_WORDS 6u      /* three f32 dequantization values, layout, band and box words */
#define VR_MEAN_BITS 15u        /* the most bits of a quantized mean */
#define VR_MAX_SPARSITY_BITS 8u /* the widest sparsity field: at most 255 atoms a block */
#define VR_MAX_COEF_BITS 16u    /* the most magnitude bits: |q| ≤ 2^16 */
#define VR_MAX_ATOM_BITS 16u    /* the widest atom index */
#define VR_MAX_GAP_SHIFT 3u     /* the largest reduction of the gaps' Rice parameter */
#define VR_MAX_BAND_SPLIT 4095u /* the largest split between band 0 and the others */
#define VR_ESCAPE_ZEROS 16u     /* a Rice code whose unary part reaches 16 zeros is an escape */
#define VR_ATOM_BANDS 8u        /* atom bands of the magnitudes' Rice parameters */

/* Bits [bit, bit + width) of the bit stream that starts at bit 0 of word `first_word` (bit i of
 * the stream is bit i mod 32 of word first_word + i/32), width 0..32. A field spans at most two
 * words. */
VR_INLINE vr_uint vr_read_bits(VR_PAYLOAD_PARAM vr_uint first_word, vr_uint bit, vr_uint width) {
  if (width == 0u) return 0u;
  vr_uint word = first_word + (bit >> 5u);
  vr_uint shift = bit & 31u;
  vr_uint value = VR_LOAD_WORD(word) >> shift;
  if (shift + width > 32u) value |= VR_LOAD_WORD(word + 1u) << (32u - shift);
  return width >= 32u ? value : (value & ((1u << width) - 1u));
}

/* Word 3, the layout word (a reader checks every field's range):
 *   bits 0..3    mean bits b         (0..15)  bits of each block's quantized mean
 *   bits 4..7    sparsity bits t     (0..8)   width of each block's sparsity field
 *   bits 8..12   magnitude bits c    (1..16)  every quantized coefficient has |q| ≤ 2^c; an
 *                                             escaped value is |q| − 1 in c bits
 *   bits 13..17  atom bits a         (1..16)  an escaped gap takes a bits (every index < 2^a)
 *   bits 18..19  gap shift g         (0..3)   lowers the gaps' Rice parameter (vr_gap_rice)
 *   bits 20..31  split L             (0..4095) atoms below L form band 0 (vr_atom_band): the
 *                                             learned atoms a dictionary lists before the DCT
 *                                             basis */
VR_INLINE vr_uint vr_layout_word(VR_PAYLOAD_PARAM_ONLY) {
  return VR_LOAD_WORD(3u);
}
VR_INLINE vr_uint vr_layout_mean_bits(vr_uint layout_word) {
  return layout_word & 0xFu;
}
VR_INLINE vr_uint vr_layout_sparsity_bits(vr_uint layout_word) {
  return (layout_word >> 4u) & 0xFu;
}
VR_INLINE vr_uint vr_layout_coef_bits(vr_uint layout_word) {
  return (layout_word >> 8u) & 0x1Fu;
}
VR_INLINE vr_uint vr_layout_atom_bits(vr_uint layout_word) {
  return (layout_word >> 13u) & 0x1Fu;
}
VR_INLINE vr_uint vr_layout_gap_shift(vr_uint layout_word) {
  return (layout_word >> 18u) & 0x3u;
}
VR_INLINE vr_uint vr_layout_band_split(vr_uint layout_word) {
  return layout_word >> 20u;
}
VR_INLINE vr_uint vr_make_layout(vr_uint mean_bits, vr_uint sparsity_bits, vr_uint coef_bits,
                                 vr_uint atom_bits, vr_uint gap_shift, vr_uint band_split) {
  return mean_bits | (sparsity_bits << 4u) | (coef_bits << 8u) | (atom_bits << 13u) |
         (gap_shift << 18u) | (band_split << 20u);
}
/* Word 4, the band word: 4 bits per band, band j at bits 4j..4j+3. */
VR_INLINE vr_uint vr_band_word(VR_PAYLOAD_PARAM_ONLY) {
  return VR_LOAD_WORD(4u);
}
/* Word 5, the box word: the coded blocks of the brick are those with bx < nx, by < ny and
 * bz < nz (each 1..n), the blocks that hold a voxel of the brick's level or the voxel just past
 * its end; bits 0..3 nx, 4..7 ny, 8..11 nz, 12..15 the magnitude model m (0..9,
 * vr_block_band_word), bit 16 the split flag (vr_block_first_atom), bits 17..24 the run limit T
 * (0..255) and 25..27 the runs' Rice parameter (0..7, vr_read_gap), 28..31 zero. Only coded blocks
 * have an entry (in block order) and codes; every value of a block outside the box is mean_bias. */
VR_INLINE vr_uint vr_box_word(VR_PAYLOAD_PARAM_ONLY) {
  return VR_LOAD_WORD(5u);
}
VR_INLINE vr_uint vr_box_blocks(vr_uint box_word, vr_uint axis) {
  return (box_word >> (4u * axis)) & 0xFu;
}
/* Number of coded blocks, nx·ny·nz: the entries of the brick. */
VR_INLINE vr_uint vr_box_entries(vr_uint box_word) {
  return vr_box_blocks(box_word, 0u) * vr_box_blocks(box_word, 1u) * vr_box_blocks(box_word, 2u);
}
VR_INLINE vr_uint vr_make_box(vr_uint nx, vr_uint ny, vr_uint nz) {
  return nx | (ny << 4u) | (nz << 8u);
}
#define VR_BOX_BLOCKS_MASK 0xFFFu /* bits 0..11: nx, ny, nz */
#define VR_MAX_MAGNITUDE_MODEL 9u /* m: 0, or 1 + a sparsity class 0..8 */
#define VR_MAGNITUDE_SWING 2      /* the most a block's sparsity moves a band parameter */
VR_INLINE vr_uint vr_box_magnitude_model(vr_uint box_word) {
  return (box_word >> 12u) & 0xFu;
}
VR_INLINE vr_uint vr_box_with_magnitude_model(vr_uint box_word, vr_uint model) {
  return (box_word & ~0xF000u) | (model << 12u);
}
/* Bit 16, the split flag: every code of the brick names an atom from the layout's band split L on
 * (the DCT basis after a learned dictionary's atoms), and a block's first gap counts from L
 * instead of 0, so that such a brick pays for indices into the basis alone (a bits for its 215
 * atoms, not for all K). */
VR_INLINE vr_uint vr_box_from_split(vr_uint box_word) {
  return (box_word >> 16u) & 1u;
}
VR_INLINE vr_uint vr_box_with_split_flag(vr_uint box_word, vr_uint from_split) {
  return (box_word & ~0x10000u) | (from_split << 16u);
}
/* Bits 17..24, the run limit T, and 25..27, the runs' Rice parameter (vr_read_gap): a run of
 * consecutive atoms may start at a position (next atom − the block's first atom) below T and reach
 * past it; T = 0: no runs. */
#define VR_MAX_RUN_LIMIT 255u
#define VR_MAX_RUN_RICE 7u
VR_INLINE vr_uint vr_box_run_limit(vr_uint box_word) {
  return (box_word >> 17u) & 0xFFu;
}
VR_INLINE vr_uint vr_box_run_rice(vr_uint box_word) {
  return (box_word >> 25u) & 0x7u;
}
VR_INLINE vr_uint vr_box_with_runs(vr_uint box_word, vr_uint limit, vr_uint rice) {
  return (box_word & ~0xFFFE0000u) | (limit << 17u) | (rice << 25u);
}
/* Whether block b of a brick of n blocks a side is coded. */
VR_INLINE bool vr_block_in_box(vr_uint box_word, vr_uint blocks_per_axis, vr_uint block) {
  vr_uint n = blocks_per_axis;
  return block % n < vr_box_blocks(box_word, 0u) && (block / n) % n < vr_box_blocks(box_word, 1u) &&
         block / (n * n) < vr_box_blocks(box_word, 2u);
}

/* Width of a block entry, t + b (0..23). */
VR_INLINE vr_uint vr_layout_entry_bits(vr_uint layout_word) {
  return vr_layout_sparsity_bits(layout_word) + vr_layout_mean_bits(layout_word);
}

/* Entry e (0..nx·ny·nz − 1: the coded blocks in block order): sparsity in the low t bits,
 * quantized mean above. */
VR_INLINE vr_uint vr_block_entry(VR_PAYLOAD_PARAM vr_uint layout_word, vr_uint e) {
  vr_uint entry_bits = vr_layout_entry_bits(layout_word);
  return vr_read_bits(VR_PAYLOAD_ARG VR_HEADER_WORDS, e * entry_bits, entry_bits);
}
VR_INLINE vr_uint vr_entry_sparsity(vr_uint layout_word, vr_uint entry) {
  return entry & ((1u << vr_layout_sparsity_bits(layout_word)) - 1u);
}
VR_INLINE vr_uint vr_entry_mean(vr_uint layout_word, vr_uint entry) {
  return entry >> vr_layout_sparsity_bits(layout_word);
}

/* Words of `entries` entries (vr_box_entries), zero bits to the next word included, and the
 * word where the codes begin. */
VR_INLINE vr_uint vr_entry_words(vr_uint layout_word, vr_uint entries) {
  return (entries * vr_layout_entry_bits(layout_word) + 31u) / 32u;
}
VR_INLINE vr_uint vr_code_first_word(vr_uint layout_word, vr_uint entries) {
  return VR_HEADER_WORDS + vr_entry_words(layout_word, entries);
}

/* The codes: one bit stream from word vr_code_first_word, the coded blocks' codes in block order,
 * each block's in increasing atom order. A code is the gap to its atom (atom − previous atom of the
 * block − 1; the first code of a block: its atom − vr_block_first_atom; below the run limit,
 * runs of gaps 0 coded by their length, vr_read_gap), then the value's magnitude |q| − 1 (q ≠ 0),
 * both as Rice codes (the gap's parameter from the block's sparsity, the magnitude's from the
 * atom's band and, under the magnitude model, the block's sparsity), then the sign of q (1:
 * negative). A Rice code of x with parameter k is u = x >> k zero bits, a one, and the low k bits
 * of x; when u would be 16 or more it is 16 zero bits and x in `escape_bits` bits instead (a bits
 * for a gap, 8 for a run, c bits for a magnitude). */

/* Index of the lowest set bit of x ≠ 0. */
#ifndef VR_GLSL
VR_INLINE vr_uint vr_lowest_bit(vr_uint x) {
  return static_cast<vr_uint>(std::countr_zero(x));
}
/* floor(log2(x)) of x ≥ 1. */
VR_INLINE vr_uint vr_highest_bit(vr_uint x) {
  return static_cast<vr_uint>(std::bit_width(x)) - 1u;
}
#else
#define vr_lowest_bit(x) uint(findLSB(x))
#define vr_highest_bit(x) uint(findMSB(x))
#endif

/* Reads the Rice code at *bit with parameter k and advances *bit past it. */
VR_INLINE vr_uint vr_read_rice(VR_PAYLOAD_PARAM vr_uint first_word, VR_INOUT(vr_uint, bit),
                               vr_uint k, vr_uint escape_bits) {
  vr_uint zeros = vr_lowest_bit(vr_read_bits(VR_PAYLOAD_ARG first_word, bit, VR_ESCAPE_ZEROS) |
                                (1u << VR_ESCAPE_ZEROS));
  if (zeros == VR_ESCAPE_ZEROS) {
    vr_uint x = vr_read_bits(VR_PAYLOAD_ARG first_word, bit + VR_ESCAPE_ZEROS, escape_bits);
    bit += VR_ESCAPE_ZEROS + escape_bits;
    return x;
  }
  vr_uint low = vr_read_bits(VR_PAYLOAD_ARG first_word, bit + zeros + 1u, k);
  bit += zeros + 1u + k;
  return (zeros << k) | low;
}

/* The gaps' Rice parameter in a block of s ≥ 1 codes: about log2 of the mean gap 2^a/(s + 1)
 * less one, lowered by the layout's gap shift g: max(0, a − 1 − floor(log2(s + 1)) − g). */
VR_INLINE vr_uint vr_gap_rice(vr_uint layout_word, vr_uint s) {
  vr_uint lower = 1u + vr_highest_bit(s + 1u) + vr_layout_gap_shift(layout_word);
  vr_uint a = vr_layout_atom_bits(layout_word);
  return a > lower ? a - lower : 0u;
}

/* The atom a block's first gap counts from (next_atom before its first code, vr_read_code): the
 * layout's band split L under the box word's split flag, else 0. */
VR_INLINE vr_uint vr_block_first_atom(vr_uint layout_word, vr_uint box_word) {
  return vr_box_from_split(box_word) != 0u ? vr_layout_band_split(layout_word) : 0u;
}

/* The band of an atom: 0 below the layout's split L (the learned atoms), else
 * 1 + min(6, floor(log2(atom − L + 1))): the DCT basis by frequency (atom − L = 0; 1..2; 3..6;
 * ...; 63 and up), low frequencies having the larger coefficients. */
VR_INLINE vr_uint vr_atom_band(vr_uint layout_word, vr_uint atom) {
  vr_uint split = vr_layout_band_split(layout_word);
  if (atom < split) return 0u;
  vr_uint band = vr_highest_bit(atom - split + 1u);
  return 1u + (band < VR_ATOM_BANDS - 2u ? band : VR_ATOM_BANDS - 2u);
}
/* The magnitudes' Rice parameter of an atom's band (0..15). */
VR_INLINE vr_uint vr_band_rice(vr_uint layout_word, vr_uint band_word, vr_uint atom) {
  return (band_word >> (4u * vr_atom_band(layout_word, atom))) & 0xFu;
}

/* The magnitude model (box word bits 12..15, m): how far a block of s codes moves every band's
 * parameter. m = 0: not at all; m ≥ 1: clamp(floor(log2(s + 1)) − (m − 1), −2, 2), so that
 * blocks of more codes than the centre class m − 1 (much detail: coefficients large against the
 * quantization step) take larger parameters and sparser blocks smaller ones. */
VR_INLINE int vr_magnitude_move(vr_uint box_word, vr_uint s) {
  vr_uint m = vr_box_magnitude_model(box_word);
  if (m == 0u) return 0;
  int d = int(vr_highest_bit(s + 1u)) - int(m - 1u);
  return d < -VR_MAGNITUDE_SWING ? -VR_MAGNITUDE_SWING
                                 : (d > VR_MAGNITUDE_SWING ? VR_MAGNITUDE_SWING : d);
}
/* A band word with every band's parameter moved by d, within 0..15. */
VR_INLINE vr_uint vr_moved_band_word(vr_uint band_word, int d) {
  vr_uint moved = 0u;
  for (vr_uint j = 0u; j < VR_ATOM_BANDS; ++j) {
    int r = int((band_word >> (4u * j)) & 0xFu) + d;
    r = r < 0 ? 0 : (r > 15 ? 15 : r);
    moved |= vr_uint(r) << (4u * j);
  }
  return moved;
}
/* The band word of a block of s codes: the payload's, moved by the magnitude model
 * (vr_magnitude_move). vr_read_code takes it. */
VR_INLINE vr_uint vr_block_band_word(vr_uint band_word, vr_uint box_word, vr_uint s) {
  return vr_moved_band_word(band_word, vr_magnitude_move(box_word, s));
}

/* Reads the gap of a block's next code: atom − next_atom, next_atom the atom after the block's
 * previous code (vr_block_first_atom before its first). `run` is the block's run state, 0 before
 * its first code: 2·(zero gaps still to come) + 1 after a run, 0 otherwise.
 *  - In a run (run ≥ 2): the gap is 0, no bits.
 *  - Right after a run (run = 1): the gap is at least 1 (a run ends where an atom is left out);
 *    gap − 1 is a Rice code with the gaps' parameter (vr_gap_rice).
 *  - Where the code's position next_atom − vr_block_first_atom is below the box word's run limit
 *    T: a run length z as a Rice code with the runs' parameter (escape: z in 8 bits). z ≥ 1: this
 *    code and the next z − 1 have gap 0 (atoms next_atom, next_atom + 1, ...), and unless the block
 *    ends with them the code after them is right after a run; z = 0: gap − 1 as after a run.
 *  - Elsewhere: the gap as a Rice code with the gaps' parameter.
 * A run never reaches past its block's codes (a checking reader requires run < 2 at a block's
 * end). Dense blocks name their low-frequency atoms one after another: a run of z costs
 * about log2(z) bits instead of z. */
VR_INLINE vr_uint vr_read_gap(VR_PAYLOAD_PARAM vr_uint first, vr_uint layout_word, vr_uint box_word,
                              vr_uint s, vr_uint position, VR_INOUT(vr_uint, bit),
                              VR_INOUT(vr_uint, run)) {
  if (run >= 2u) {
    run -= 2u;
    return 0u;
  }
  vr_uint gap_rice = vr_gap_rice(layout_word, s);
  vr_uint atom_bits = vr_layout_atom_bits(layout_word);
  if (run == 0u && position < vr_box_run_limit(box_word)) {
    vr_uint z =
        vr_read_rice(VR_PAYLOAD_ARG first, bit, vr_box_run_rice(box_word), VR_MAX_SPARSITY_BITS);
    if (z != 0u) {
      run = 2u * (z - 1u) + 1u;
      return 0u;
    }
    run = 1u;
  }
  vr_uint after_run = run;
  run = 0u;
  return after_run + vr_read_rice(VR_PAYLOAD_ARG first, bit, gap_rice, atom_bits);
}

/* Reads the next code of a block of s codes, starting at bit `bit` of the code stream that
 * begins at word `first` (vr_code_first_word; the stream runs on over the whole brick); before a
 * block's first code next_atom = vr_block_first_atom and run = 0 (vr_read_gap); band_word is the
 * block's (vr_block_band_word). Sets atom;
 * returns the signed quantized coefficient q (coefficient = coef_scale·q). */
VR_INLINE int vr_read_code(VR_PAYLOAD_PARAM vr_uint first, vr_uint layout_word, vr_uint band_word,
                           vr_uint box_word, vr_uint s, VR_INOUT(vr_uint, bit),
                           VR_INOUT(vr_uint, next_atom), VR_INOUT(vr_uint, run),
                           VR_INOUT(vr_uint, atom)) {
  vr_uint position = next_atom - vr_block_first_atom(layout_word, box_word);
  atom =
      next_atom + vr_read_gap(VR_PAYLOAD_ARG first, layout_word, box_word, s, position, bit, run);
  next_atom = atom + 1u;
  vr_uint magnitude =
      vr_read_rice(VR_PAYLOAD_ARG first, bit, vr_band_rice(layout_word, band_word, atom),
                   vr_layout_coef_bits(layout_word));
  vr_uint negative = vr_read_bits(VR_PAYLOAD_ARG first, bit, 1u);
  bit += 1u;
  int q = int(magnitude + 1u);
  return negative != 0u ? -q : q;
}

/* Decodes value v (0..215, x fastest inside the block) of block `block` of a brick of n blocks a
 * side: walks the codes of blocks 0..block (a reference; the decoders walk the blocks in order
 * once). Steps:
 *  1. read the layout and box words and, coded block by coded block (vr_block_in_box), the
 *     entry: sparsity s, quantized mean q;
 *  2. value = mean_bias + mean_scale·q (a block outside the box: mean_bias, no codes);
 *  3. for each of the block's s codes (vr_read_code, with the block's band word,
 *     vr_block_band_word): atom a, quantized coefficient q;
 *     value += coef_scale·q · atoms[a·216 + v]. */
VR_INLINE float vr_decode_value(VR_PAYLOAD_PARAM VR_ATOMS_PARAM vr_uint blocks_per_axis,
                                vr_uint block, vr_uint v) {
  float mean_bias = vr_as_float(VR_LOAD_WORD(0u));
  float mean_scale = vr_as_float(VR_LOAD_WORD(1u));
  float coef_scale = vr_as_float(VR_LOAD_WORD(2u));
  vr_uint layout_word = vr_layout_word(VR_PAYLOAD_ARG_ONLY);
  vr_uint band_word = vr_band_word(VR_PAYLOAD_ARG_ONLY);
  vr_uint box_word = vr_box_word(VR_PAYLOAD_ARG_ONLY);
  vr_uint first = vr_code_first_word(layout_word, vr_box_entries(box_word));
  vr_uint bit = 0u, e = 0u;
  float value = 0.0f;
  for (vr_uint b = 0u; b <= block; ++b) {
    if (!vr_block_in_box(box_word, blocks_per_axis, b)) {
      value = mean_bias;
      continue;
    }
    vr_uint entry = vr_block_entry(VR_PAYLOAD_ARG layout_word, e);
    e += 1u;
    vr_uint s = vr_entry_sparsity(layout_word, entry);
    value = mean_bias + mean_scale * float(vr_entry_mean(layout_word, entry));
    vr_uint block_band_word = vr_block_band_word(band_word, box_word, s);
    vr_uint next_atom = vr_block_first_atom(layout_word, box_word), run = 0u, atom = 0u;
    for (vr_uint k = 0u; k < s; ++k) {
      int q = vr_read_code(VR_PAYLOAD_ARG first, layout_word, block_band_word, box_word, s, bit,
                           next_atom, run, atom);
      if (b == block) value += coef_scale * float(q) * VR_LOAD_ATOM(atom * VR_BLOCK_LENGTH + v);
    }
  }
  return value;
}

/* Position of value v of block b inside a brick of n blocks a side (n·6 voxels, x fastest):
 * returns the linear voxel index (z·6n + y)·6n + x. */
VR_INLINE vr_uint vr_brick_voxel(vr_uint blocks_per_axis, vr_uint block, vr_uint v) {
  vr_uint n = blocks_per_axis, size = n * VR_BLOCK_SIZE;
  vr_uint bx = block % n, by = (block / n) % n, bz = block / (n * n);
  vr_uint x = bx * VR_BLOCK_SIZE + v % VR_BLOCK_SIZE,
          y = by * VR_BLOCK_SIZE + (v / VR_BLOCK_SIZE) % VR_BLOCK_SIZE,
          z = bz * VR_BLOCK_SIZE + v / (VR_BLOCK_SIZE * VR_BLOCK_SIZE);
  return (z * size + y) * size + x;
}

#endif /* VOLREEL_FORMAT_BRICK_DECODE_H */
