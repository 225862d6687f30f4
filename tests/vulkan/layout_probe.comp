// layout_probe.comp: evaluates the shared-layout functions of brick_decode.h and atlas_layout.h
// in GLSL for test inputs, so that vulkan_test can compare them with the C++ results. One
// workgroup per block b, one invocation per value v; index i = 216·b + v. Output sections of
// 46656 words each (see layout_test.cpp).
#version 450
#extension GL_GOOGLE_include_directive : require
#define VR_GLSL 1

layout(local_size_x = 216) in;
layout(std430, set = 0, binding = 0) readonly buffer Payload { uint payload_words[]; };
layout(std430, set = 0, binding = 1) readonly buffer Atoms { float atom_values[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Results { uint results[]; };

uint vr_load_word(uint index) { return payload_words[index]; }
float vr_load_atom(uint index) { return atom_values[index]; }

#include "volreel/format/brick_decode.h"
#include "volreel/player/atlas_layout.h"

const uint N = 46656u;

void main() {
  const uint b = gl_WorkGroupID.x, v = gl_LocalInvocationIndex, i = b * 216u + v;
  const uint entry_bits = vr_entry_bits(vr_mean_bits());
  uint first_code = 0u;
  for (uint c = 0u; c < b; ++c) first_code += vr_entry_sparsity(vr_block_entry(entry_bits, c));
  // Entries of every width 4..16 (the payload is long enough for 216 entries of 16 bits).
  const uint entry = vr_block_entry(4u + (i / 216u) % 13u, i % VR_BLOCKS_PER_BRICK);
  const uint width = 4u + i % 13u;
  results[0u * N + i] = vr_brick_voxel(b, v);
  results[1u * N + i] = floatBitsToUint(vr_decode_value(b, first_code, v));
  results[2u * N + i] = vr_load_u16(i % (2u * VR_HEADER_WORDS + VR_BLOCKS_PER_BRICK));
  results[3u * N + i] = vr_entry_sparsity(entry) | (vr_entry_mean(entry) << 8u);
  results[4u * N + i] = vr_code_atom(i & 0xFFFFu) | (vr_code_value(i & 0xFFFFu) << 16u);
  results[5u * N + i] = vr_code_unit(width, i) ^ (vr_payload_bytes(width, i) << 12u) ^
                        (vr_entry_units(width) << 24u);
  results[6u * N + i] = vr_atlas_cell_x(i, 7u) | (vr_atlas_cell_y(i, 7u, 5u) << 8u) |
                        (vr_atlas_cell_z(i, 7u, 5u) << 16u);
  results[7u * N + i] = vr_atlas_cell_x(i, 56u) | (vr_atlas_cell_y(i, 56u, 56u) << 8u) |
                        (vr_atlas_cell_z(i, 56u, 56u) << 16u);
  if (i == 0u) {
    const uint constants[16] = uint[16](
        VR_BRICK_SIZE, VR_BRICK_INTERIOR, VR_BLOCK_SIZE, VR_BLOCK_LENGTH, VR_BLOCKS_PER_AXIS,
        VR_BLOCKS_PER_BRICK, VR_HEADER_WORDS, VR_MEAN_BITS, VR_COEF_BITS, VR_ATOM_BITS,
        VR_MAX_SPARSITY, VR_MAX_PAYLOAD_WORDS, VR_COEF_LEVELS, VR_ATLAS_SLOT_SIZE, VR_ATLAS_NO_SLOT,
        vr_mean_bits() | (vr_entry_bits(vr_mean_bits()) << 8u) | (VR_SPARSITY_BITS << 16u));
    for (uint k = 0u; k < 16u; ++k) results[8u * N + k] = constants[k];
  }
}
