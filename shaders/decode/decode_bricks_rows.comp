// decode_bricks_rows.comp: the decode pass for CPU Vulkan implementations (lavapipe), where a
// workgroup of 8 invocations is one SIMD row of the CPU and shared memory, barriers, storage-image
// stores and storage-buffer accesses (a scalar loop over the lanes each) are expensive. Same
// arithmetic as decode_bricks.comp (format/include/volreel/format/brick_decode.h), organized for
// the fewest memory operations:
//  - one workgroup of 8 invocations per brick, no shared memory and no barrier: the workgroup walks
//    the 216 blocks in order, keeping the code stream's bit position (the codes have variable
//    length); each code (the same for the whole workgroup) is read once;
//  - invocation i reconstructs the rows (6 values along x) i, i + 8, ..., i + 32 of the block's
//    36 in registers; the dictionary is a uniform texel buffer of RGBA32F (a gather on a CPU),
//    each atom 36 rows of 6 values padded to 8 (two texels a row; AtlasDecoder::set_dictionary
//    lays it out);
//  - a row is stored as one uvec4: three pairs of 16-bit texels (packUnorm2x16 / packHalf2x16, the
//    rounding of a store into the R16 image) and an unused word, into binding 2, a storage buffer
//    holding, per brick of the dispatch, n columns (block x) of S×S rows of 8 texels (S = 6n the
//    brick size); the host copies each column into its slot with vkCmdCopyBufferToImage
//    (bufferRowLength 8).
// Bindings: 0 the batch (4-word records {payload word offset, slot, kind, payload words}, then the
// payloads), 1 the dictionary, 2 the decoded bricks. Kinds as in decode_bricks.comp.
// Specialization constant 0: the blocks per brick axis n.
// VR_ATLAS_UNORM for R16_UNORM (else R16_SFLOAT).
#version 450
#extension GL_GOOGLE_include_directive : require

#define VR_GLSL 1
#define VR_KIND_KSVD 0u
#define VR_KIND_CONSTANT 1u
#define VR_KIND_RAW 2u
#define VR_LANES 8u   /* invocations per workgroup */
#define VR_ROWS 36u              /* rows of 6 values in a block */
#define VR_ROW_ROUNDS 5u         /* rows per invocation: ceil(36 / 8) */
#define VR_ATOM_TEXELS_PER_ROW 2u /* an atom row of 6 values padded to 8: two RGBA32F texels */
#define VR_ATOM_TEXELS 72u       /* texels of an atom */
#define VR_COLUMN_ROWS (VR_BRICK_SIZE * VR_BRICK_SIZE) /* rows (uvec4) of a column 6 voxels wide */
#define VR_BRICK_ROWS (VR_BLOCKS_PER_AXIS * VR_COLUMN_ROWS) /* uvec4 of a decoded brick: n columns */

layout(local_size_x = 8) in;
layout(constant_id = 0) const uint VR_BLOCKS_PER_AXIS = 6u;

layout(std430, set = 0, binding = 0) readonly buffer Batch { uint batch_words[]; };
layout(set = 0, binding = 1) uniform samplerBuffer atom_texels;
layout(std430, set = 0, binding = 2) writeonly buffer Decoded { uvec4 decoded_rows[]; };

layout(push_constant) uniform Params {
  uint first_record; // record of workgroup 0 (a batch is decoded in chunks of the output buffer)
  uint unused;
  float value_min;   // r16: stored n = (v − value_min)·inv_range
  float inv_range;
} params;

uint g_base;  // word offset of the brick's payload in the batch
uint vr_load_word(uint index) { return batch_words[g_base + index]; }
float vr_load_atom(uint index);  // below

#include "volreel/format/brick_decode.h"

// Atom a's value v = 6·row + x is at float 8·row + x of atom a's 72 texels.
float vr_load_atom(uint index) {
  const uint a = index / VR_BLOCK_LENGTH, v = index % VR_BLOCK_LENGTH;
  const uint f = v / VR_BLOCK_SIZE * 8u + v % VR_BLOCK_SIZE;
  return texelFetch(atom_texels, int(a * VR_ATOM_TEXELS + f / 4u))[f & 3u];
}

uint pack_pair(float a, float b) {
#ifdef VR_ATLAS_UNORM
  return packUnorm2x16((vec2(a, b) - params.value_min) * params.inv_range);
#else
  return packHalf2x16(vec2(a, b));
#endif
}

void main() {
  const uint lane = gl_LocalInvocationID.x;
  const uint record = 4u * (params.first_record + gl_WorkGroupID.x);
  g_base = batch_words[record];
  const uint kind = batch_words[record + 2u];
  const uint out_base = gl_WorkGroupID.x * VR_BRICK_ROWS;

  // Constant and raw bricks: no codes (kind is the same for the whole workgroup).
  if (kind == VR_KIND_CONSTANT) {
    const float value = uintBitsToFloat(batch_words[g_base]);
    const uint pair = pack_pair(value, value);
    for (uint i = lane; i < VR_BRICK_ROWS; i += VR_LANES)
      decoded_rows[out_base + i] = uvec4(pair, pair, pair, 0u);
    return;
  }
  if (kind == VR_KIND_RAW) {
    // Row i of the decoded brick: column i / S², (y, z) = (i % S, i % S² / S).
    for (uint i = lane; i < VR_BRICK_ROWS; i += VR_LANES) {
      const uint first = (i % VR_COLUMN_ROWS) * VR_BRICK_SIZE + i / VR_COLUMN_ROWS * VR_BLOCK_SIZE;
      uvec4 row = uvec4(0u);
      for (uint p = 0u; p < 3u; ++p)
        row[p] = pack_pair(uintBitsToFloat(batch_words[g_base + first + 2u * p]),
                           uintBitsToFloat(batch_words[g_base + first + 2u * p + 1u]));
      decoded_rows[out_base + i] = row;
    }
    return;
  }

  // The rows of 6 values (x) of a block this invocation reconstructs: row j = lane + 8r for
  // rounds r = 0..4 (the last round: lanes 0..3 only), value v = 6j + x of the block, j = y + 6z.
  // Each row is stored as one uvec4 of three texel pairs (and one unused word). All positions are
  // computed here, once: integer division is slow on a CPU's SIMD units. The rounds are written
  // out (VR_DECLARE, VR_STORE) so that the accumulators stay in registers.
#define VR_ROW(r) min(lane + VR_LANES * (r), VR_ROWS - 1u)
#define VR_DECLARE(r)                                                                    \
  const uint texel##r = VR_ATOM_TEXELS_PER_ROW * VR_ROW(r);                             \
  const uint rowpos##r = VR_ROW(r) / VR_BLOCK_SIZE * VR_BRICK_SIZE + VR_ROW(r) % VR_BLOCK_SIZE; \
  vec4 low##r;                                                                           \
  vec2 high##r;
  VR_DECLARE(0) VR_DECLARE(1) VR_DECLARE(2) VR_DECLARE(3) VR_DECLARE(4)
  const bool last_round_stores = lane + VR_LANES * (VR_ROW_ROUNDS - 1u) < VR_ROWS;

  const float mean_bias = vr_as_float(vr_load_word(0u));
  const float mean_scale = vr_as_float(vr_load_word(1u));
  const float coef_scale = vr_as_float(vr_load_word(2u));
  const uint layout_word = vr_layout_word();
  const uint band_word = vr_band_word();
  const uint box_word = vr_box_word();
  const uint first = vr_code_first_word(layout_word, vr_box_entries(box_word));
  const uint first_atom = vr_block_first_atom(layout_word, box_word);
  const uint box_x = vr_box_blocks(box_word, 0u), box_y = vr_box_blocks(box_word, 1u),
             box_z = vr_box_blocks(box_word, 2u);
  uint bit = 0u;
  uint e = 0u;
  for (uint bz = 0u; bz < VR_BLOCKS_PER_AXIS; ++bz)
    for (uint by = 0u; by < VR_BLOCKS_PER_AXIS; ++by)
      for (uint bx = 0u; bx < VR_BLOCKS_PER_AXIS; ++bx) {
        // A block outside the box of coded blocks: mean_bias, no entry, no codes.
        const bool in_box = bx < box_x && by < box_y && bz < box_z;
        const uint entry = in_box ? vr_block_entry(layout_word, e) : 0u;
        e += in_box ? 1u : 0u;
        const uint s = vr_entry_sparsity(layout_word, entry);
        const float mean = mean_bias + mean_scale * float(vr_entry_mean(layout_word, entry));
        low0 = low1 = low2 = low3 = low4 = vec4(mean);
        high0 = high1 = high2 = high3 = high4 = vec2(mean);
        const uint block_band_word = vr_block_band_word(band_word, box_word, s);
        uint next_atom = first_atom, run = 0u, atom_index = 0u;
        for (uint k = 0u; k < s; ++k) {
          const float coefficient =
              coef_scale * float(vr_read_code(first, layout_word, block_band_word, box_word, s, bit,
                                               next_atom, run, atom_index));
          const int atom = int(atom_index * VR_ATOM_TEXELS);
#define VR_ACCUMULATE(r)                                                         \
  low##r += coefficient * texelFetch(atom_texels, atom + int(texel##r));         \
  high##r += coefficient * texelFetch(atom_texels, atom + int(texel##r) + 1).xy;
          VR_ACCUMULATE(0) VR_ACCUMULATE(1) VR_ACCUMULATE(2) VR_ACCUMULATE(3) VR_ACCUMULATE(4)
        }
        // Row (y, z) of block (bx, by, bz) in column bx of the brick: uvec4 index
        // (6bz + z)·S + 6by + y.
        const uint origin = out_base + bx * VR_COLUMN_ROWS +
                            bz * VR_BLOCK_SIZE * VR_BRICK_SIZE + by * VR_BLOCK_SIZE;
#define VR_STORE(r)                                                            \
  decoded_rows[origin + rowpos##r] = uvec4(pack_pair(low##r.x, low##r.y),      \
                                           pack_pair(low##r.z, low##r.w),      \
                                           pack_pair(high##r.x, high##r.y), 0u);
        VR_STORE(0) VR_STORE(1) VR_STORE(2) VR_STORE(3)
        if (last_round_stores) { VR_STORE(4) }
      }
}
