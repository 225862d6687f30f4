// layout_probe.comp: evaluates the shared-layout functions of brick_decode.h and atlas_layout.h
// in GLSL for test inputs, so that vulkan_test can compare them with the C++ results. One
// workgroup per block b of a brick of n³ blocks (n: specialization constant 0), one invocation per
// value v; index i = 216·b + v. Output sections of 216·n³ words each (see layout_test.cpp). The
// payload buffer ends with a zero word (the look-ahead of the last Rice code).
#version 450
#extension GL_GOOGLE_include_directive : require
#define VR_GLSL 1

layout(local_size_x = 216) in;
layout(constant_id = 0) const uint VR_BLOCKS_PER_AXIS = 6u;
layout(std430, set = 0, binding = 0) readonly buffer Payload { uint payload_words[]; };
layout(std430, set = 0, binding = 1) readonly buffer Atoms { float atom_values[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Results { uint results[]; };

uint vr_load_word(uint index) { return payload_words[index]; }
float vr_load_atom(uint index) { return atom_values[index]; }

#include "volreel/format/brick_decode.h"
#include "volreel/player/atlas_layout.h"

const uint N = VR_BLOCKS_PER_BRICK * 216u;

void main() {
  const uint b = gl_WorkGroupID.x, v = gl_LocalInvocationIndex, i = b * 216u + v;
  const uint layout_word = vr_layout_word();
  const uint box_word = vr_box_word();
  const uint entries = vr_box_entries(box_word);
  uint codes = 0u;
  for (uint e = 0u; e < entries; ++e)
    codes += vr_entry_sparsity(layout_word, vr_block_entry(layout_word, e));
  // Code v of block b (atom in the low 16 bits, q in the high 16), read as the decoders do.
  uint code = 0xFFFFFFFFu;
  const uint band_word = vr_band_word();
  const uint first = vr_code_first_word(layout_word, entries);
  uint bit = 0u, e = 0u;
  for (uint c = 0u; c <= b; ++c) {
    if (!vr_block_in_box(box_word, VR_BLOCKS_PER_AXIS, c)) continue;
    const uint s = vr_entry_sparsity(layout_word, vr_block_entry(layout_word, e++));
    const uint block_band_word = vr_block_band_word(band_word, box_word, s);
    uint next_atom = vr_block_first_atom(layout_word, box_word), run = 0u, atom = 0u;
    for (uint k = 0u; k < s; ++k) {
      const int q = vr_read_code(first, layout_word, block_band_word, box_word, s, bit, next_atom,
                                 run, atom);
      if (c == b && k == v) code = atom | (uint(q) << 16u);
    }
  }
  // Layout words of every width and parameter.
  const uint other = vr_make_layout(i % 16u, (i / 16u) % 9u, 1u + (i / 144u) % 16u,
                                    1u + (i / 2304u) % 16u, (i / 3u) % 4u, i % 4096u);
  const uint entry = vr_block_entry(layout_word, i % entries);
  uint rice_bit = (i * 7u) % 900u;
  const uint rice = vr_read_rice(0u, rice_bit, i % 16u, 1u + i % 16u);
  results[0u * N + i] = vr_brick_voxel(VR_BLOCKS_PER_AXIS, b, v);
  results[1u * N + i] = floatBitsToUint(vr_decode_value(VR_BLOCKS_PER_AXIS, b, v));
  results[2u * N + i] = vr_read_bits(0u, (i * 13u) % 1024u, i % 33u);
  results[3u * N + i] = vr_entry_sparsity(layout_word, entry) |
                        (vr_entry_mean(layout_word, entry) << 8u);
  results[4u * N + i] = code;
  results[5u * N + i] = vr_layout_entry_bits(other) | (vr_gap_rice(other, 1u + i % 255u) << 5u) |
                        (vr_band_rice(other, i * 2654435761u, i % 300u) << 10u) |
                        (vr_entry_words(other, VR_BLOCKS_PER_BRICK) << 15u) |
                        (vr_code_first_word(other, VR_BLOCKS_PER_BRICK) << 23u);
  results[6u * N + i] = vr_atlas_cell_x(i, 7u) | (vr_atlas_cell_y(i, 7u, 5u) << 8u) |
                        (vr_atlas_cell_z(i, 7u, 5u) << 16u);
  results[7u * N + i] = vr_atlas_cell_x(i, 56u) | (vr_atlas_cell_y(i, 56u, 56u) << 8u) |
                        (vr_atlas_cell_z(i, 56u, 56u) << 16u);
  results[9u * N + i] = rice ^ (rice_bit << 20u);
  // Band words moved by every magnitude model and sparsity.
  results[10u * N + i] =
      vr_block_band_word(i * 2654435761u, vr_box_with_magnitude_model(0u, i % 10u), i % 256u);
  if (i == 0u) {
    const uint constants[16] = uint[16](
        VR_BRICK_SIZE, VR_BRICK_INTERIOR, VR_BLOCK_SIZE, VR_BLOCK_LENGTH, VR_BLOCKS_PER_AXIS,
        VR_BLOCKS_PER_BRICK, VR_HEADER_WORDS, VR_MEAN_BITS, VR_MAX_SPARSITY_BITS, VR_MAX_COEF_BITS,
        VR_MAX_ATOM_BITS, box_word, VR_ATLAS_NO_SLOT, layout_word, codes,
        vr_code_first_word(layout_word, entries));
    for (uint k = 0u; k < 16u; ++k) results[8u * N + k] = constants[k];
  }
}
