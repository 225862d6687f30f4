// atlas_layout.h: where a brick slot lies in the brick atlas, in plain arithmetic on 32-bit words
// so that the same text compiles as C++ (the stream scheduler, the CPU renderer, the Vulkan host
// code) and as GLSL (the decode and render shaders), like format/brick_decode.h.
//
// The atlas holds a fixed number of slots of S³ voxels, S the container's brick size (a brick with
// its 1-voxel apron; 36 or up to 66). On the GPU it is one 3D image of grid_x·S × grid_y·S ×
// grid_z·S voxels; slot s occupies the cell (s mod grid_x, (s / grid_x) mod grid_y,
// s / (grid_x·grid_y)) of that grid. A CPU copy of the atlas stores slot s as S³ contiguous values
// (x fastest) at s·S³.
#ifndef VOLREEL_PLAYER_ATLAS_LAYOUT_H
#define VOLREEL_PLAYER_ATLAS_LAYOUT_H

#ifndef VR_GLSL
#include <cstdint>
typedef std::uint32_t vr_uint;
#define VR_INLINE inline
#else
#define vr_uint uint
#define VR_INLINE
#endif

#define VR_ATLAS_NO_SLOT 0xFFFFFFFFu

/* Grid cell of slot s along x, y and z; multiply by the slot size S for the first voxel. */
VR_INLINE vr_uint vr_atlas_cell_x(vr_uint slot, vr_uint grid_x) {
  return slot % grid_x;
}
VR_INLINE vr_uint vr_atlas_cell_y(vr_uint slot, vr_uint grid_x, vr_uint grid_y) {
  return (slot / grid_x) % grid_y;
}
VR_INLINE vr_uint vr_atlas_cell_z(vr_uint slot, vr_uint grid_x, vr_uint grid_y) {
  return slot / (grid_x * grid_y);
}

#endif /* VOLREEL_PLAYER_ATLAS_LAYOUT_H */
