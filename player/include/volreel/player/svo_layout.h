// svo_layout.h: the array-encoded sparse voxel octree the renderers walk (Cesium patent [0049]–
// [0050]; docs/design.md, "Streaming", step 5), in plain arithmetic on 32-bit words so that the
// same text compiles as C++ (the SVO builder, the CPU reference renderer) and as GLSL (the render
// shader).
//
// Geometry. The spatial octree is the frames' brick octree (format/SPEC.md): L levels, level 0 the
// root, level L−1 the finest. With bricks of I interior voxels a side (the container's brick
// size − 2: 34 for 36³ bricks), a node at level l and brick coordinates c = (x, y, z) covers
// finest voxels [c·I·2^(L−1−l), (c+1)·I·2^(L−1−l)) on each axis; its children at level l+1 are
// 2c + (i & 1, (i >> 1) & 1, (i >> 2) & 1) for octant i = 0..7. The root covers
// [0, I·2^(L−1))³, which may extend past the volume's dims: samples outside the dims are empty.
//
// Two arrays of 32-bit words:
//
// Node records, VR_SVO_NODE_WORDS words each; record 0 is the root:
//   word 0        parent record index (VR_SVO_NO_PARENT for the root)
//   words 1..8    child of octant i at word 1 + i: bits 30..31 its kind, bits 0..29 an index
//                   VR_SVO_CHILD_NODE  the child is a node record (index = its record)
//                   VR_SVO_CHILD_LEAF  the child is drawn from a leaf record (index = the leaf),
//                                      whose keyframes are relative to the child node
//                   VR_SVO_CHILD_UP    the tree does not go deeper here: the child's region is
//                                      drawn from this node's own leaf record (word 9)
//                   VR_SVO_CHILD_EMPTY nothing to draw (outside the volume or no data): transparent
//                 A node record at the finest level (the root when L = 1) has the same 8
//                 geometric octants as children, each VR_SVO_CHILD_UP or VR_SVO_CHILD_EMPTY.
//   word 9        this node's own leaf record (relative to this node), or VR_SVO_NO_LEAF when
//                 no child is VR_SVO_CHILD_UP
//
// Leaf records, VR_SVO_LEAF_WORDS words each:
//   word 0        atlas slot of keyframe node A (atlas_layout.h)
//   word 1        atlas slot of keyframe node B
//   word 2        bits 0..7: LOD difference dA of A; bits 8..15: dB of B — how many levels above
//                 the spatial node the keyframe node's brick lies (0: the node's own brick);
//                 bits 16..23: dC of C, bits 24..31: dD of D (the coarse pair below)
//   word 3        interpolation factor f (float bits): fine = (1 − f)·A + f·B
//   words 4, 5    atlas slots of the coarse pair C and D: the parent's drawing of this region
//   word 6        the coarse pair's factor g (float bits): coarse = (1 − g)·C + g·D
//   words 7, 8    level-of-detail blend weights, one byte per corner of the region's spatial node
//                 (corner i at (i & 1, (i >> 1) & 1, (i >> 2) & 1); word 7 holds corners 0..3,
//                 word 8 corners 4..7, low byte first), w = byte / 255. At local coordinates u the
//                 value is coarse + w(u)·(fine − coarse), w(u) the trilinear interpolation of the
//                 corners' weights (Thiele et al. §4: spatial and temporal LOD blending). All
//                 bytes 255 (VR_SVO_BLEND_NONE in both words): the fine pair alone, C and D unused
//                 (their slots may be VR_ATLAS_NO_SLOT).
//
// Feedback table (ray-guided feedback, written by a renderer, read by the scheduler):
// VR_SVO_FEEDBACK_ENTRIES 32-bit entries per leaf record, one per region the leaf draws — entry
// 8·leaf for a VR_SVO_CHILD_LEAF child (the child's spatial node), entry 8·leaf + i for octant i
// drawn from a node's own leaf as VR_SVO_CHILD_UP (the child of octant i, or the node itself at
// the finest level and for a root drawn as a leaf). An entry is 0 when no ray reached the region
// (a leaf culled by its histogram counts as reached), else 1 + the largest LOD difference of its
// samples: the levels from the region's node up to the brick read (the finer of A and B while both
// are read).
//
// Leaf histograms (a third array, optional), VR_SVO_HISTOGRAM_WORDS words per leaf record: the OR
// of the 64-bin value histograms (format's Node::histogram, bins over the sequence's value range)
// of the spatial nodes whose bricks A and B are (and C and D where the leaf blends), low word
// first. A renderer may skip a leaf's
// region when no bin from the lowest to the highest set bit (the hull: trilinear interpolation
// creates values between those present) maps to a nonzero opacity.
//
// Sampling a point with local coordinates u ∈ [0,1)³ inside a spatial node at brick coordinates c
// from a keyframe with LOD difference d: the brick's own local coordinates are
//   u' = ((c mod 2^d) + u) / 2^d                                           (vr_svo_ancestor_local)
// and its stored voxel coordinate (texel units, texel centres at +0.5) inside the (I + 2)³ slot is
//   1 + I·u'                                                                   (vr_svo_slot_coord)
// — the 1 skips the apron, which makes trilinear filtering seamless across bricks.
#ifndef VOLREEL_PLAYER_SVO_LAYOUT_H
#define VOLREEL_PLAYER_SVO_LAYOUT_H

#ifndef VR_GLSL
#include <cstdint>
typedef std::uint32_t vr_uint;
#define VR_INLINE inline
#else
#define vr_uint uint
#define VR_INLINE
#endif

#define VR_SVO_NODE_WORDS 10u
#define VR_SVO_LEAF_WORDS 9u
#define VR_SVO_BLEND_NONE 0xFFFFFFFFu
#define VR_SVO_HISTOGRAM_WORDS 2u
#define VR_SVO_FEEDBACK_ENTRIES 8u
#define VR_SVO_NO_PARENT 0xFFFFFFFFu
#define VR_SVO_NO_LEAF 0xFFFFFFFFu
#define VR_SVO_CHILD_NODE 0u
#define VR_SVO_CHILD_LEAF 1u
#define VR_SVO_CHILD_UP 2u
#define VR_SVO_CHILD_EMPTY 3u
#define VR_SVO_INDEX_MASK 0x3FFFFFFFu

VR_INLINE vr_uint vr_svo_child_word(vr_uint kind, vr_uint index) {
  return (kind << 30u) | (index & VR_SVO_INDEX_MASK);
}
VR_INLINE vr_uint vr_svo_child_kind(vr_uint word) {
  return word >> 30u;
}
VR_INLINE vr_uint vr_svo_child_index(vr_uint word) {
  return word & VR_SVO_INDEX_MASK;
}
VR_INLINE vr_uint vr_svo_lod_pack(vr_uint d_a, vr_uint d_b) {
  return (d_a & 0xFFu) | ((d_b & 0xFFu) << 8u);
}
VR_INLINE vr_uint vr_svo_lod_a(vr_uint packed) {
  return packed & 0xFFu;
}
VR_INLINE vr_uint vr_svo_lod_b(vr_uint packed) {
  return (packed >> 8u) & 0xFFu;
}
VR_INLINE vr_uint vr_svo_lod_c(vr_uint packed) {
  return (packed >> 16u) & 0xFFu;
}
VR_INLINE vr_uint vr_svo_lod_d(vr_uint packed) {
  return packed >> 24u;
}
/* The LOD difference of the coarser keyframe a leaf's fine pair reads: dA when f = 0, dB when
   f = 1, else the larger — the level of detail the region is drawn at (level maps, spatial
   blending's neighbours). */
VR_INLINE vr_uint vr_svo_coarser_lod(vr_uint packed, float f) {
  vr_uint d_a = vr_svo_lod_a(packed), d_b = vr_svo_lod_b(packed);
  return f == 0.0f ? d_a : (f == 1.0f ? d_b : (d_a > d_b ? d_a : d_b));
}
/* Corner i's blend weight (0..255) from words 7 and 8. */
VR_INLINE vr_uint vr_svo_blend_corner(vr_uint w7, vr_uint w8, vr_uint i) {
  return ((i < 4u ? w7 : w8) >> (8u * (i & 3u))) & 0xFFu;
}
/* The blend weight at local coordinates u ∈ [0,1]³: the corners' weights interpolated
   trilinearly, in [0, 1]. */
VR_INLINE float vr_svo_blend_weight(vr_uint w7, vr_uint w8, float ux, float uy, float uz) {
  float w = 0.0f;
  for (vr_uint i = 0u; i < 8u; ++i) {
    float c = float(vr_svo_blend_corner(w7, w8, i)) * (1.0f / 255.0f);
    c *= (i & 1u) != 0u ? ux : 1.0f - ux;
    c *= (i & 2u) != 0u ? uy : 1.0f - uy;
    c *= (i & 4u) != 0u ? uz : 1.0f - uz;
    w += c;
  }
  return w;
}

/* One axis of u' = ((c mod 2^d) + u) / 2^d, for every d (not only d ≤ 1). */
VR_INLINE float vr_svo_ancestor_local(vr_uint c, float u, vr_uint d) {
  vr_uint span = 1u << d;
  return (float(c & (span - 1u)) + u) / float(span);
}
/* One axis of the stored voxel coordinate inside a slot (texel units) of brick-local u', for
   bricks of `interior` interior voxels a side. */
VR_INLINE float vr_svo_slot_coord(float u_brick, float interior) {
  return 1.0f + interior * u_brick;
}

/* Ray step from the leaf's level (docs/design.md, "Streaming", step 7): how many times the base
   step may be doubled in the region of a leaf record — the levels between the finest level and the
   level of the finer brick the sample reads, at most `cap`:
     e = min((levels − 1 − leaf_level) + d, cap),  d = dA when f = 0, dB when f = 1, else min(dA,
   dB) where leaf_level is the level of the spatial node the record is relative to (a
   VR_SVO_CHILD_UP region's node, a VR_SVO_CHILD_LEAF child). A brick of level k has voxels of
   2^(levels−1−k) finest voxels, so a step of base·2^e keeps the base step's samples per stored
   voxel. */
VR_INLINE vr_uint vr_svo_step_doublings(vr_uint levels, vr_uint leaf_level, vr_uint packed_lods,
                                        float f, vr_uint cap) {
  vr_uint d_a = vr_svo_lod_a(packed_lods), d_b = vr_svo_lod_b(packed_lods);
  vr_uint d = f == 0.0f ? d_a : (f == 1.0f ? d_b : (d_a < d_b ? d_a : d_b));
  vr_uint e = levels - 1u - leaf_level + d;
  return e < cap ? e : cap;
}

#endif /* VOLREEL_PLAYER_SVO_LAYOUT_H */
