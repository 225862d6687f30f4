// brick_decode.h: the bit layout of a sparse-coded brick payload and the per-block decode, in
// plain C-like arithmetic on 32-bit words so that the same text compiles as C++ (the CPU reference
// decoder, unit-tested) and as GLSL (the decode compute shader), in the manner of NanoVDB's
// PNanoVDB.h. Layout in format/SPEC.md, "Brick payload"; MTV-Player §3.2 and Fig. 3.
//
// A payload is an array of little-endian 32-bit words:
//   words 0..3            f32 mean_bias, mean_scale, coef_bias, coef_scale (bit patterns)
//   word 4                u32 bits 0..3: mean bits b (0..12); bits 4..31 zero
//   entry[216]            per block, w = 4 + b bits each, packed from bit 0 of word 5 upwards
//                         (entry e is bits [e·w, e·w + w) of the words, low bit first): bits 0..3
//                         sparsity s (0..15), bits 4..4+b quantized mean q (0..2^b − 1); zero
//                         bits up to the next 16-bit unit
//   u16 [Σ s]             per coefficient: bits 6..15 atom index (0..1023), bits 0..5 value q
//                         (unit u is in word u/2, low half first)
//   padding to a multiple of 4 bytes
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

/* Constants of format version 2 (SPEC.md). */
#define VR_BRICK_SIZE 36u        /* stored voxels per axis: interior + 2·apron */
#define VR_BRICK_INTERIOR 34u    /* interior voxels per axis */
#define VR_BLOCK_SIZE 6u         /* M */
#define VR_BLOCK_LENGTH 216u     /* m = M³ values per block */
#define VR_BLOCKS_PER_AXIS 6u    /* blocks per brick axis */
#define VR_BLOCKS_PER_BRICK 216u /* 6³ blocks per brick, x fastest */
#define VR_HEADER_WORDS 5u       /* the four f32 dequantization values and the mean bits */
#define VR_MEAN_BITS 12u         /* the most bits of a quantized mean */
#define VR_SPARSITY_BITS 4u
#define VR_COEF_BITS 6u
#define VR_ATOM_BITS 10u
#define VR_MAX_SPARSITY 15u
#define VR_COEF_LEVELS 63u /* quantized coefficients are 0..63 */
/* The longest payload in words: 16-bit entries and 15 codes in every block. */
#define VR_MAX_PAYLOAD_WORDS 1733u /* (20 + 2·216 + 2·216·15) / 4 */

/* 16-bit unit u of the payload, u counted from byte 0. */
VR_INLINE vr_uint vr_load_u16(VR_PAYLOAD_PARAM vr_uint unit) {
  vr_uint word = VR_LOAD_WORD(unit >> 1u);
  return (unit & 1u) != 0u ? (word >> 16u) : (word & 0xFFFFu);
}

/* Word 4: the bits b of each quantized mean (0..12; a reader checks the range and that bits
 * 4..31 are zero), and the width of a block entry, 4 + b (4..16). */
VR_INLINE vr_uint vr_mean_bits(VR_PAYLOAD_PARAM_ONLY) {
  return VR_LOAD_WORD(4u) & 0xFu;
}
VR_INLINE vr_uint vr_entry_bits(vr_uint mean_bits) {
  return VR_SPARSITY_BITS + mean_bits;
}

/* Block entry b (0..215) of width w = vr_entry_bits(b): sparsity in bits 0..3, quantized mean
 * above. An entry spans at most two words (w ≤ 16). */
VR_INLINE vr_uint vr_block_entry(VR_PAYLOAD_PARAM vr_uint entry_bits, vr_uint block) {
  vr_uint bit = block * entry_bits;
  vr_uint word = VR_HEADER_WORDS + (bit >> 5u);
  vr_uint shift = bit & 31u;
  vr_uint value = VR_LOAD_WORD(word) >> shift;
  if (shift + entry_bits > 32u) value |= VR_LOAD_WORD(word + 1u) << (32u - shift);
  return value & ((1u << entry_bits) - 1u);
}
VR_INLINE vr_uint vr_entry_sparsity(vr_uint entry) {
  return entry & 0xFu;
}
VR_INLINE vr_uint vr_entry_mean(vr_uint entry) {
  return entry >> VR_SPARSITY_BITS;
}

/* 16-bit units of the 216 entries of width w, zero bits to the next unit included. */
VR_INLINE vr_uint vr_entry_units(vr_uint entry_bits) {
  return (VR_BLOCKS_PER_BRICK * entry_bits + 15u) / 16u;
}

/* The 16-bit unit where coefficient k (counted over the whole brick) is stored. */
VR_INLINE vr_uint vr_code_unit(vr_uint entry_bits, vr_uint code) {
  return 2u * VR_HEADER_WORDS + vr_entry_units(entry_bits) + code;
}
VR_INLINE vr_uint vr_code_atom(vr_uint code16) {
  return code16 >> 6u;
}
VR_INLINE vr_uint vr_code_value(vr_uint code16) {
  return code16 & 0x3Fu;
}

/* Payload bytes of a brick with entries of width w whose blocks hold `codes` coefficients in all
 * (before padding to 4). */
VR_INLINE vr_uint vr_payload_bytes(vr_uint entry_bits, vr_uint codes) {
  return 4u * VR_HEADER_WORDS + 2u * vr_entry_units(entry_bits) + 2u * codes;
}

/* Decodes value v (0..215, x fastest inside the block) of block `block` whose first code is
 * `first_code` (the sum of the sparsities of blocks 0..block-1: a prefix sum). Steps:
 *  1. read the block entry (of width 4 + the mean bits of word 4): sparsity s, quantized mean q;
 *  2. value = mean_bias + mean_scale·q;
 *  3. for each of the s codes: atom a, quantized coefficient c;
 *     value += (coef_bias + coef_scale·c) · atoms[a·216 + v]. */
VR_INLINE float vr_decode_value(VR_PAYLOAD_PARAM VR_ATOMS_PARAM vr_uint block, vr_uint first_code,
                                vr_uint v) {
  float mean_bias = vr_as_float(VR_LOAD_WORD(0u));
  float mean_scale = vr_as_float(VR_LOAD_WORD(1u));
  float coef_bias = vr_as_float(VR_LOAD_WORD(2u));
  float coef_scale = vr_as_float(VR_LOAD_WORD(3u));
  vr_uint entry_bits = vr_entry_bits(vr_mean_bits(VR_PAYLOAD_ARG_ONLY));
  vr_uint entry = vr_block_entry(VR_PAYLOAD_ARG entry_bits, block);
  vr_uint s = vr_entry_sparsity(entry);
  float value = mean_bias + mean_scale * float(vr_entry_mean(entry));
  for (vr_uint k = 0u; k < s; ++k) {
    vr_uint code16 = vr_load_u16(VR_PAYLOAD_ARG vr_code_unit(entry_bits, first_code + k));
    float coefficient = coef_bias + coef_scale * float(vr_code_value(code16));
    value += coefficient * VR_LOAD_ATOM(vr_code_atom(code16) * VR_BLOCK_LENGTH + v);
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
