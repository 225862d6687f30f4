// decode_bricks.comp: decodes a batch of compressed bricks into their atlas slots (MTV-Player
// §4.2, Fig. 4). One workgroup per brick; each of its 54 invocations reconstructs 4 consecutive
// values of a block (the paper decodes 2 per thread), so that the codes read from shared memory
// and the coefficients are reused 4 times and the atom values are read as one vec4.
//
// Bindings: 0 the batch (uint words: 4 words of record per brick {payload word offset, slot,
// kind, payload words}, then the payloads), 1 the dictionary (atom-major; 216 floats = 54 vec4
// per atom), 2 the atlas. Kinds: 0 ksvd (format/include/volreel/format/brick_decode.h),
// 1 constant (one float), 2 raw (S³ floats decoded on the CPU, e.g. zfp). Specialization
// constant 0: the blocks per brick axis n (S = 6n, the container's brick size).
// VR_ATLAS_QUALIFIER (r16 or r16f) is set by the build, and VR_ATLAS_UNORM for r16: one SPIR-V
// module per atlas format.
#version 450
#extension GL_GOOGLE_include_directive : require

#define VR_GLSL 1
#define VR_KIND_KSVD 0u
#define VR_KIND_CONSTANT 1u
#define VR_KIND_RAW 2u
#define VR_INVOCATIONS 54u         /* 216 values of a block / 4 */

layout(local_size_x = 54) in;
layout(constant_id = 0) const uint VR_BLOCKS_PER_AXIS = 6u;

layout(std430, set = 0, binding = 0) readonly buffer Batch { uint batch_words[]; };
layout(std430, set = 0, binding = 1) readonly buffer Atoms { vec4 atom_quads[]; };
layout(set = 0, binding = 2, VR_ATLAS_QUALIFIER) uniform writeonly image3D atlas;

layout(push_constant) uniform Params {
  uint grid_x;       // atlas slots per axis (atlas_layout.h)
  uint grid_y;
  float value_min;   // r16: stored n = (v − value_min)·inv_range
  float inv_range;
} params;

uint vr_load_word(uint index);   // below: brick_decode.h reads the payload through it
float vr_load_atom(uint index) { return atom_quads[index >> 2u][index & 3u]; }

#include "volreel/format/brick_decode.h"
#include "volreel/player/atlas_layout.h"

// The brick's payload is read from the batch where it lies (a payload has no size limit that
// would fit shared memory); a zero word follows each ksvd payload in the batch, for the look-ahead
// of a Rice code at the stream's end.

uint g_base;  // word offset of the brick's payload in the batch
uint vr_load_word(uint index) { return batch_words[g_base + index]; }

void store_voxel(ivec3 origin, uint voxel, float value) {
  ivec3 p = origin + ivec3(int(voxel % VR_BRICK_SIZE), int((voxel / VR_BRICK_SIZE) % VR_BRICK_SIZE),
                           int(voxel / (VR_BRICK_SIZE * VR_BRICK_SIZE)));
#ifdef VR_ATLAS_UNORM
  value = clamp((value - params.value_min) * params.inv_range, 0.0, 1.0);
#endif
  imageStore(atlas, p, vec4(value, 0.0, 0.0, 0.0));
}

void main() {
  const uint t = gl_LocalInvocationIndex;
  const uint record = 4u * gl_WorkGroupID.x;
  const uint base = batch_words[record];
  g_base = base;
  const uint slot = batch_words[record + 1u];
  const uint kind = batch_words[record + 2u];
  const ivec3 origin = ivec3(vr_atlas_cell_x(slot, params.grid_x),
                             vr_atlas_cell_y(slot, params.grid_x, params.grid_y),
                             vr_atlas_cell_z(slot, params.grid_x, params.grid_y)) *
                       int(VR_BRICK_SIZE);
  const uint voxels = VR_BRICK_SIZE * VR_BRICK_SIZE * VR_BRICK_SIZE;

  // Constant and raw bricks: no codes (kind is the same for the whole workgroup).
  if (kind == VR_KIND_CONSTANT) {
    const float value = uintBitsToFloat(batch_words[base]);
    for (uint voxel = t; voxel < voxels; voxel += VR_INVOCATIONS) store_voxel(origin, voxel, value);
    return;
  }
  if (kind == VR_KIND_RAW) {
    for (uint voxel = t; voxel < voxels; voxel += VR_INVOCATIONS)
      store_voxel(origin, voxel, uintBitsToFloat(batch_words[base + voxel]));
    return;
  }

  // Block by block, invocation t reconstructs values 4t..4t+3 as vr_decode_value does:
  // mean_bias + mean_scale·q, plus coef_scale·q·atom[a][v] for each code. The codes have variable
  // length: every invocation reads the same bits (uniform control flow) and keeps the same
  // position from block to block.
  const uint layout_word = vr_layout_word();
  const float mean_bias = vr_as_float(vr_load_word(0u));
  const float mean_scale = vr_as_float(vr_load_word(1u));
  const float coef_scale = vr_as_float(vr_load_word(2u));
  const uint band_word = vr_band_word();
  const uint box_word = vr_box_word();
  const uint first = vr_code_first_word(layout_word, vr_box_entries(box_word));
  uint bit = 0u, e = 0u;
  for (uint b = 0u; b < VR_BLOCKS_PER_BRICK; ++b) {
    // A block outside the box of coded blocks: mean_bias, no entry, no codes.
    const bool in_box = vr_block_in_box(box_word, VR_BLOCKS_PER_AXIS, b);
    const uint entry = in_box ? vr_block_entry(layout_word, e) : 0u;
    e += in_box ? 1u : 0u;
    const uint s = vr_entry_sparsity(layout_word, entry);
    vec4 value = vec4(mean_bias + mean_scale * float(vr_entry_mean(layout_word, entry)));
    const uint block_band_word = vr_block_band_word(band_word, box_word, s);
    uint next_atom = vr_block_first_atom(layout_word, box_word), run = 0u, atom = 0u;
    for (uint k = 0u; k < s; ++k) {
      const int q = vr_read_code(first, layout_word, block_band_word, box_word, s, bit, next_atom,
                                 run, atom);
      value += coef_scale * float(q) * atom_quads[atom * (VR_BLOCK_LENGTH / 4u) + t];
    }
    for (uint i = 0u; i < 4u; ++i)
      store_voxel(origin, vr_brick_voxel(VR_BLOCKS_PER_AXIS, b, 4u * t + i), value[i]);
  }
}
