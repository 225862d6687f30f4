// block_ranges.comp: the value range of every 6³ block of the atlas slots just written, so that
// the ray caster (raycast.comp) can skip samples whose block the transfer function makes
// invisible without fetching texels. Block b of a slot covers stored voxels [6b, 6b + 6) per
// axis; its range is taken over [6b − 2, 6b + 8) (clamped to the slot): every texel a trilinear
// sample whose lower neighbour lies in the block can touch, and one more on each side for filter
// hardware that rounds the neighbour differently. Ranges are in the atlas's normalized
// texel units (r16_unorm: 0..1).
//
// Bindings (set 0): 0 parameters, 1 slots to update, 2 ranges (vec2 per block, n³ per slot,
// slot-major), 3 the atlas (read with texelFetch). One workgroup per listed slot.
// Specialization constant 0: the blocks per brick axis n (slots of 6n voxels a side).
#version 450
#extension GL_GOOGLE_include_directive : require

#define VR_GLSL 1
#include "volreel/player/atlas_layout.h"

#define BLOCK_VOXELS 6

layout(local_size_x = 64) in;
layout(constant_id = 0) const uint BLOCKS_PER_AXIS = 6u;
#define SLOT_SIZE (BLOCKS_PER_AXIS * uint(BLOCK_VOXELS))

layout(std430, set = 0, binding = 0) readonly buffer Params { uvec4 grid_count; } params;
layout(std430, set = 0, binding = 1) readonly buffer Slots { uint slots[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Ranges { vec2 ranges[]; };
layout(set = 0, binding = 3) uniform sampler3D atlas;

void main() {
  const uint slot = slots[gl_WorkGroupID.x];
  const uint grid_x = params.grid_count.x, grid_y = params.grid_count.y;
  const ivec3 origin = ivec3(vr_atlas_cell_x(slot, grid_x), vr_atlas_cell_y(slot, grid_x, grid_y),
                             vr_atlas_cell_z(slot, grid_x, grid_y)) * int(SLOT_SIZE);
  const uint blocks = BLOCKS_PER_AXIS * BLOCKS_PER_AXIS * BLOCKS_PER_AXIS;
  for (uint b = gl_LocalInvocationIndex; b < blocks; b += gl_WorkGroupSize.x) {
    ivec3 block = ivec3(int(b % BLOCKS_PER_AXIS), int((b / BLOCKS_PER_AXIS) % BLOCKS_PER_AXIS),
                        int(b / (BLOCKS_PER_AXIS * BLOCKS_PER_AXIS)));
    ivec3 lo = max(block * BLOCK_VOXELS - 2, ivec3(0));
    ivec3 hi = min(block * BLOCK_VOXELS + BLOCK_VOXELS + 2, ivec3(int(SLOT_SIZE)));
    float mn = 1e30, mx = -1e30;
    for (int z = lo.z; z < hi.z; ++z)
      for (int y = lo.y; y < hi.y; ++y)
        for (int x = lo.x; x < hi.x; ++x) {
          float v = texelFetch(atlas, origin + ivec3(x, y, z), 0).r;
          mn = min(mn, v);
          mx = max(mx, v);
        }
    ranges[slot * blocks + b] = vec2(mn, mx);
  }
}
