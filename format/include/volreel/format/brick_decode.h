// brick_decode.h: the bit layout of a sparse-coded brick payload and the per-block decode, in
// plain C-like arithmetic on 32-bit words so that the same text compiles as C++ (the CPU reference
// decoder, unit-tested) and as GLSL (the decode compute shader), in the manner of NanoVDB's
// PNanoVDB.h. Layout in format/SPEC.md, "Brick payload"; MTV-Player §3.2 and Fig. 3.
//
// A payload is an array of little-endian 32-bit words:
//   words 0..3            f32 mean_bias, mean_scale, coef_bias, coef_scale (bit patterns)
//   word 4                the layout word: bits b of a quantized mean, t of a sparsity field,
//                         c of a quantized coefficient, a of an atom index (vr_layout_*)
//   entry[216]            per block, t + b bits each, one bit stream from bit 0 of word 5
//                         (low bit first): sparsity s in the low t bits, quantized mean q above;
//                         zero bits up to the next word
//   code[Σ s]             per coefficient, c + a bits each, one bit stream from the next word:
//                         quantized value q in the low c bits, atom index above; zero bits up to
//                         the next word
// Dequantization: mean = mean_bias + mean_scale·q, coefficient = coef_bias + coef_scale·q.
//
// The host side (C++) defines VR_CPU before including nothing else: the functions read from a
// `const vr_uint*` span; a GLSL includer defines VR_GLSL and provides
//   vr_uint vr_load_word(vr_uint index)    (the payload storage buffer)
//   float   vr_load_atom(vr_uint index)    (the dictionary storage buffer, atom-major)
// and uses the same functions without the pointer parameters (see VR_PAYLOAD_ARG below).
#ifndef VOLREEL_FORMAT_BRICK_DECODE_H
#define VOLREEL_FORMAT_BRICK_DECODE_H

#ifndef VR_GLSL
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
#define VR_LOAD_WORD(i) vr_load_word(i)
#define VR_LOAD_ATOM(i) vr_load_atom(i)
#define vr_as_float(bits) uintBitsToFloat(bits)
#endif

/* Constants of format version 3 (SPEC.md). */
#define VR_BRICK_SIZE 36u        /* stored voxels per axis: interior + 2·apron */
#define VR_BRICK_INTERIOR 34u    /* interior voxels per axis */
#define VR_BLOCK_SIZE 6u         /* M */
#define VR_BLOCK_LENGTH 216u     /* m = M³ values per block */
#define VR_BLOCKS_PER_AXIS 6u    /* blocks per brick axis */
#define VR_BLOCKS_PER_BRICK 216u /* 6³ blocks per brick, x fastest */
#define VR_HEADER_WORDS 5u       /* the four f32 dequantization values and the layout word */
#define VR_MEAN_BITS 12u         /* the most bits of a quantized mean */
#define VR_MAX_SPARSITY_BITS 8u  /* the widest sparsity field: at most 255 atoms a block */
#define VR_MAX_COEF_BITS 16u     /* the most bits of a quantized coefficient */
#define VR_MAX_ATOM_BITS 16u     /* the widest atom index */

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

/* Word 4, the layout word (a reader checks every field's range and that bits 18..31 are zero):
 *   bits 0..3    mean bits b         (0..12)  bits of each block's quantized mean
 *   bits 4..7    sparsity bits t     (0..8)   width of each block's sparsity field
 *   bits 8..12   coefficient bits c  (1..16)  bits of each quantized coefficient
 *   bits 13..17  atom bits a         (1..16)  width of each atom index
 *   bits 18..31  zero (reserved) */
VR_INLINE vr_uint vr_layout_word(VR_PAYLOAD_PARAM_ONLY) {
  return VR_LOAD_WORD(4u);
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
VR_INLINE vr_uint vr_make_layout(vr_uint mean_bits, vr_uint sparsity_bits, vr_uint coef_bits,
                                 vr_uint atom_bits) {
  return mean_bits | (sparsity_bits << 4u) | (coef_bits << 8u) | (atom_bits << 13u);
}
/* Width of a block entry, t + b (0..20), and of a code, a + c (2..32). */
VR_INLINE vr_uint vr_layout_entry_bits(vr_uint layout_word) {
  return vr_layout_sparsity_bits(layout_word) + vr_layout_mean_bits(layout_word);
}
VR_INLINE vr_uint vr_layout_code_bits(vr_uint layout_word) {
  return vr_layout_coef_bits(layout_word) + vr_layout_atom_bits(layout_word);
}

/* Block entry `block` (0..215): sparsity in the low t bits, quantized mean above. */
VR_INLINE vr_uint vr_block_entry(VR_PAYLOAD_PARAM vr_uint layout_word, vr_uint block) {
  vr_uint entry_bits = vr_layout_entry_bits(layout_word);
  return vr_read_bits(VR_PAYLOAD_ARG VR_HEADER_WORDS, block * entry_bits, entry_bits);
}
VR_INLINE vr_uint vr_entry_sparsity(vr_uint layout_word, vr_uint entry) {
  return entry & ((1u << vr_layout_sparsity_bits(layout_word)) - 1u);
}
VR_INLINE vr_uint vr_entry_mean(vr_uint layout_word, vr_uint entry) {
  return entry >> vr_layout_sparsity_bits(layout_word);
}

/* Words of the 216 entries, zero bits to the next word included, and the word where the codes
 * begin. */
VR_INLINE vr_uint vr_entry_words(vr_uint layout_word) {
  return (VR_BLOCKS_PER_BRICK * vr_layout_entry_bits(layout_word) + 31u) / 32u;
}
VR_INLINE vr_uint vr_code_first_word(vr_uint layout_word) {
  return VR_HEADER_WORDS + vr_entry_words(layout_word);
}

/* Code k (counted over the whole brick): quantized coefficient in the low c bits, atom index
 * above. */
VR_INLINE vr_uint vr_code(VR_PAYLOAD_PARAM vr_uint layout_word, vr_uint code) {
  vr_uint code_bits = vr_layout_code_bits(layout_word);
  return vr_read_bits(VR_PAYLOAD_ARG vr_code_first_word(layout_word), code * code_bits, code_bits);
}
VR_INLINE vr_uint vr_code_atom(vr_uint layout_word, vr_uint code) {
  return code >> vr_layout_coef_bits(layout_word);
}
VR_INLINE vr_uint vr_code_value(vr_uint layout_word, vr_uint code) {
  return code & ((1u << vr_layout_coef_bits(layout_word)) - 1u);
}

/* Payload words of a brick with this layout_word whose blocks hold `codes` coefficients in all. */
VR_INLINE vr_uint vr_payload_words(vr_uint layout_word, vr_uint codes) {
  return vr_code_first_word(layout_word) + (codes * vr_layout_code_bits(layout_word) + 31u) / 32u;
}

/* Decodes value v (0..215, x fastest inside the block) of block `block` whose first code is
 * `first_code` (the sum of the sparsities of blocks 0..block-1: a prefix sum). Steps:
 *  1. read the layout_word word and the block entry: sparsity s, quantized mean q;
 *  2. value = mean_bias + mean_scale·q;
 *  3. for each of the s codes: atom a, quantized coefficient c;
 *     value += (coef_bias + coef_scale·c) · atoms[a·216 + v]. */
VR_INLINE float vr_decode_value(VR_PAYLOAD_PARAM VR_ATOMS_PARAM vr_uint block, vr_uint first_code,
                                vr_uint v) {
  float mean_bias = vr_as_float(VR_LOAD_WORD(0u));
  float mean_scale = vr_as_float(VR_LOAD_WORD(1u));
  float coef_bias = vr_as_float(VR_LOAD_WORD(2u));
  float coef_scale = vr_as_float(VR_LOAD_WORD(3u));
  vr_uint layout_word = vr_layout_word(VR_PAYLOAD_ARG_ONLY);
  vr_uint entry = vr_block_entry(VR_PAYLOAD_ARG layout_word, block);
  vr_uint s = vr_entry_sparsity(layout_word, entry);
  float value = mean_bias + mean_scale * float(vr_entry_mean(layout_word, entry));
  for (vr_uint k = 0u; k < s; ++k) {
    vr_uint code = vr_code(VR_PAYLOAD_ARG layout_word, first_code + k);
    float coefficient = coef_bias + coef_scale * float(vr_code_value(layout_word, code));
    value += coefficient * VR_LOAD_ATOM(vr_code_atom(layout_word, code) * VR_BLOCK_LENGTH + v);
  }
  return value;
}

/* Position of value v of block b inside the 36³ brick (x fastest): returns the linear voxel
 * index z·36² + y·36 + x. */
VR_INLINE vr_uint vr_brick_voxel(vr_uint block, vr_uint v) {
  vr_uint bx = block % VR_BLOCKS_PER_AXIS, by = (block / VR_BLOCKS_PER_AXIS) % VR_BLOCKS_PER_AXIS,
          bz = block / (VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS);
  vr_uint x = bx * VR_BLOCK_SIZE + v % VR_BLOCK_SIZE,
          y = by * VR_BLOCK_SIZE + (v / VR_BLOCK_SIZE) % VR_BLOCK_SIZE,
          z = bz * VR_BLOCK_SIZE + v / (VR_BLOCK_SIZE * VR_BLOCK_SIZE);
  return (z * VR_BRICK_SIZE + y) * VR_BRICK_SIZE + x;
}

#endif /* VOLREEL_FORMAT_BRICK_DECODE_H */
