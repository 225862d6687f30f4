// raycast.comp: the ray caster of volreel's player (docs/design.md, "Streaming", step 7) — one
// invocation per pixel walks its ray through the array-encoded SVO (svo_layout.h; Cesium patent
// [0049]–[0050]) and samples both keyframes of each leaf in the brick atlas (atlas_layout.h) with
// trilinear filtering, the second mapped into its ancestor's brick for any LOD difference.
//
// It takes exactly the samples of the CPU reference renderer (player/cpu_render/renderer.hpp,
// steps 1–5): rays from the eye clipped to [0, dims), samples at t = k·step where the step follows
// the level of the leaf a sample reads (step 2a–c there: the next sample is the next multiple of
// 2^e fine steps, e = vr_svo_step_doublings, but no later than the region's exit or the ray's
// end), an opacity-corrected transfer function (for the base step on the host, then for the
// n = k' − k fine steps a sample stands for: α' = 1 − (1 − α)^n), front-to-back compositing with
// early termination, the background behind.
// Three things make it faster without changing the image:
//   - restart: a sample inside the region of the previous one reuses its leaf; otherwise the walk
//     climbs the parent chain (word 0) to the first node whose box holds the sample and descends
//     from there, not from the root;
//   - skipping: a region that is empty, or whose leaf histogram hull (svo_layout.h) meets no bin
//     that the transfer function makes visible, is left at once: the next sample is the first
//     multiple of the step past the region's exit.
//
//   - block skipping: a sample whose 6³ atlas blocks (every keyframe it reads) hold only values
//     that map to zero opacity (block_ranges.comp) is skipped without fetching texels.
//
// Bindings (set 0): 0 parameters, 1 node words, 2 leaf words, 3 leaf histograms
// (2 words per leaf; ignored unless VR_FLAG_HISTOGRAMS), 4 transfer function (RGBA entries, already
// corrected for the step), 5 the atlas (sampler3D, linear, clamp to edge, normalized coordinates),
// 6 the output image, 7 block value ranges and 8 the prefix count of visible transfer-function
// entries (both ignored unless VR_FLAG_BLOCK_SKIP). VR_OUTPUT_QUALIFIER (rgba8 or rgba16f) is set
// by the build. Specialization constant 0: the blocks per brick axis n (bricks and atlas slots of
// S = 6n voxels a side, interior S − 2).
#version 450
#extension GL_GOOGLE_include_directive : require

#define VR_GLSL 1
#include "volreel/player/atlas_layout.h"
#include "volreel/player/svo_layout.h"

#define VR_FLAG_HISTOGRAMS 1u
#define VR_FLAG_FETCH_FILTER 2u
#define VR_FLAG_BLOCK_SKIP 4u
#define VR_FLAG_FEEDBACK 8u

layout(local_size_x = 8, local_size_y = 8) in;
layout(constant_id = 0) const uint VR_BLOCKS_PER_AXIS = 6u;
#define VR_BRICK_SIZE (VR_BLOCKS_PER_AXIS * 6u)
#define VR_BRICK_INTERIOR (VR_BRICK_SIZE - 2u)

layout(std430, set = 0, binding = 0) readonly buffer Params {
  vec4 eye_step;          // eye (world = finest voxels), step
  vec4 forward_tan;       // unit view direction, tan(fov_y / 2)
  vec4 right_aspect;      // unit right vector, width / height
  vec4 up_termination;    // unit up vector, termination alpha
  vec4 background_lo;     // background RGB, atlas value offset (value = lo + scale·texel)
  vec4 inv_extent_scale;  // 1 / atlas image extent in texels, atlas value scale
  vec4 dims_tf_lo;        // volume dims (voxels), transfer function's lo
  vec4 tf_scale_entries;  // (entries − 1)/(hi − lo), entries, max step doublings, 0
  uvec4 size_levels;      // width, height, octree levels, flags
  uvec4 grid_mask;        // atlas grid x, y; visible-bin mask low word, high word
} params;

layout(std430, set = 0, binding = 1) readonly buffer Nodes { uint node_words[]; };
layout(std430, set = 0, binding = 2) readonly buffer Leaves { uint leaf_words[]; };
layout(std430, set = 0, binding = 3) readonly buffer Histograms { uint histogram_words[]; };
layout(std430, set = 0, binding = 4) readonly buffer Transfer { vec4 transfer[]; };
layout(set = 0, binding = 5) uniform sampler3D atlas;
layout(set = 0, binding = 6, VR_OUTPUT_QUALIFIER) uniform writeonly image2D out_image;
layout(std430, set = 0, binding = 7) readonly buffer Ranges { vec2 block_ranges[]; };
layout(std430, set = 0, binding = 8) readonly buffer Visible { uint visible_prefix[]; };
layout(std430, set = 0, binding = 9) buffer Feedback { uint feedback[]; };

// Kinds of the region a sample falls in (beyond svo_layout.h's child kinds).
#define REGION_EMPTY 0u      // nothing drawn: transparent
#define REGION_DRAWN 1u      // a leaf record drawn
#define REGION_INVISIBLE 2u  // a leaf record whose values the transfer function hides

// Finest voxels per axis of a node of `level`.
// Edge of a level's boxes in finest voxels, for level ≤ levels: a child box of the finest level
// (an octant of a one-level volume's root) is half a brick.
uint node_size(uint levels, uint level) { return (VR_BRICK_INTERIOR / 2u) << (levels - level); }

bool inside_box(uvec3 q, uvec3 c, uint size) {
  uvec3 lo = c * size;
  return all(greaterThanEqual(q, lo)) && all(lessThan(q, lo + uvec3(size)));
}

// Bits from the lowest to the highest set bit of a 64-bit histogram (two words).
uvec2 hull(uvec2 h) {
  if (h.x == 0u && h.y == 0u) return uvec2(0xFFFFFFFFu);  // no histogram: assume anything
  int lo = h.x != 0u ? findLSB(h.x) : 32 + findLSB(h.y);
  int hi = h.y != 0u ? 32 + findMSB(h.y) : findMSB(h.x);
  uvec2 from_lo = lo >= 32 ? uvec2(0u, 0xFFFFFFFFu << uint(lo - 32))
                           : uvec2(0xFFFFFFFFu << uint(lo), 0xFFFFFFFFu);
  uvec2 to_hi = hi >= 32 ? uvec2(0xFFFFFFFFu, 0xFFFFFFFFu >> uint(63 - hi))
                         : uvec2(0xFFFFFFFFu >> uint(31 - hi), 0u);
  return from_lo & to_hi;
}

// Stored voxel coordinate (texel units) in a slot of node-local u for LOD difference d (patent
// [0050]; svo_layout.h, for any d).
vec3 slot_texel(uint d, uvec3 c, vec3 u) {
  const float interior = float(VR_BRICK_INTERIOR);
  return vec3(vr_svo_slot_coord(vr_svo_ancestor_local(c.x, u.x, d), interior),
              vr_svo_slot_coord(vr_svo_ancestor_local(c.y, u.y, d), interior),
              vr_svo_slot_coord(vr_svo_ancestor_local(c.z, u.z, d), interior));
}

// The origin of `slot` in the atlas, texels.
ivec3 slot_origin(uint slot) {
  return ivec3(vr_atlas_cell_x(slot, params.grid_mask.x),
               vr_atlas_cell_y(slot, params.grid_mask.x, params.grid_mask.y),
               vr_atlas_cell_z(slot, params.grid_mask.x, params.grid_mask.y)) *
         int(VR_BRICK_SIZE);
}

// The value range (normalized texel units) of the 6³ block of `slot` (its origin `origin`) that a
// trilinear sample at atlas position `at` (texel units, centres at +0.5) reads
// (block_ranges.comp). The lower neighbour is rounded as keyframe() rounds it; the ranges' margin
// covers filter hardware's own rounding.
vec2 block_range(uint slot, ivec3 origin, vec3 at) {
  ivec3 i = ivec3(floor(at - 0.5)) - origin;
  uvec3 b = min(uvec3(clamp(i, ivec3(0), ivec3(int(VR_BRICK_SIZE) - 1))) / 6u,
                uvec3(VR_BLOCKS_PER_AXIS - 1u));
  uint block = b.x + VR_BLOCKS_PER_AXIS * (b.y + VR_BLOCKS_PER_AXIS * b.z);
  return block_ranges[slot * VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS + block];
}

// Whether some value in [r.x, r.y] (normalized texel units) maps to a nonzero opacity: a count of
// visible table entries over the entries the interval touches, one of margin on each side.
bool range_visible(vec2 r) {
  float n = params.tf_scale_entries.y;
  float lo = params.background_lo.w, scale = params.inv_extent_scale.w;
  float x0 = clamp((lo + scale * r.x - params.dims_tf_lo.w) * params.tf_scale_entries.x, 0.0, n - 1.0);
  float x1 = clamp((lo + scale * r.y - params.dims_tf_lo.w) * params.tf_scale_entries.x, 0.0, n - 1.0);
  int e0 = max(int(floor(x0)) - 1, 0);
  int e1 = min(int(ceil(x1)) + 1, int(n) - 1);
  return visible_prefix[e1 + 1] != visible_prefix[e0];
}

// One keyframe: trilinear sample at atlas position `at` (patent [0050]).
float keyframe(vec3 at) {
  float n;
  if ((params.size_levels.w & VR_FLAG_FETCH_FILTER) != 0u) {
    // Trilinear from the eight neighbours (the apron keeps them inside the slot): much faster
    // than the sampler on CPU implementations, and exact where filter hardware rounds weights.
    vec3 x = at - 0.5;
    ivec3 i = ivec3(floor(x));
    vec3 w = x - vec3(i);
    float c000 = texelFetch(atlas, i, 0).r, c100 = texelFetch(atlas, i + ivec3(1, 0, 0), 0).r;
    float c010 = texelFetch(atlas, i + ivec3(0, 1, 0), 0).r, c110 = texelFetch(atlas, i + ivec3(1, 1, 0), 0).r;
    float c001 = texelFetch(atlas, i + ivec3(0, 0, 1), 0).r, c101 = texelFetch(atlas, i + ivec3(1, 0, 1), 0).r;
    float c011 = texelFetch(atlas, i + ivec3(0, 1, 1), 0).r, c111 = texelFetch(atlas, i + ivec3(1, 1, 1), 0).r;
    n = mix(mix(mix(c000, c100, w.x), mix(c010, c110, w.x), w.y),
            mix(mix(c001, c101, w.x), mix(c011, c111, w.x), w.y), w.z);
  } else {
    n = textureLod(atlas, at * params.inv_extent_scale.xyz, 0.0).r;
  }
  return params.background_lo.w + params.inv_extent_scale.w * n;
}

// The transfer function at value v: linear between entries (TransferFunction::lookup).
vec4 lookup(float v) {
  float t = (v - params.dims_tf_lo.w) * params.tf_scale_entries.x;
  float n = params.tf_scale_entries.y;
  float x = clamp(t, 0.0, n - 1.0);
  if (!(t > 0.0)) x = 0.0;  // NaN too
  uint i = min(uint(x), uint(n) - 2u);
  float w = x - float(i);
  return mix(transfer[i], transfer[i + 1u], w);
}

// Ray parameter where the ray leaves the box [lo, hi).
float exit_distance(vec3 eye, vec3 dir, vec3 lo, vec3 hi) {
  float t = 1e30;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] > 0.0) t = min(t, (hi[a] - eye[a]) / dir[a]);
    else if (dir[a] < 0.0) t = min(t, (lo[a] - eye[a]) / dir[a]);
  }
  return t;
}

void main() {
  uvec2 pixel = gl_GlobalInvocationID.xy;
  if (pixel.x >= params.size_levels.x || pixel.y >= params.size_levels.y) return;
  const uint levels = params.size_levels.z;
  const bool use_histograms = (params.size_levels.w & VR_FLAG_HISTOGRAMS) != 0u;
  const bool block_skip = (params.size_levels.w & VR_FLAG_BLOCK_SKIP) != 0u;
  const bool write_feedback = (params.size_levels.w & VR_FLAG_FEEDBACK) != 0u;
  const uvec2 visible = params.grid_mask.zw;
  const uint max_doublings = uint(params.tf_scale_entries.z);

  // 1. The ray of the pixel centre (OrbitCamera::ray_direction), clipped to the box (slab test).
  vec3 eye = params.eye_step.xyz;
  float step = params.eye_step.w;
  float t_half = params.forward_tan.w;
  float ndc_x = (2.0 * (float(pixel.x) + 0.5) / float(params.size_levels.x) - 1.0) * t_half *
                params.right_aspect.w;
  float ndc_y = (1.0 - 2.0 * (float(pixel.y) + 0.5) / float(params.size_levels.y)) * t_half;
  vec3 dir = normalize(params.forward_tan.xyz + ndc_x * params.right_aspect.xyz +
                       ndc_y * params.up_termination.xyz);
  vec3 box = params.dims_tf_lo.xyz;
  vec3 inside = uintBitsToFloat(floatBitsToUint(box) - 1u);  // largest floats below dims
  float t0 = 0.0, t1 = 1e30;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] == 0.0) {
      if (eye[a] < 0.0 || eye[a] >= box[a]) t1 = -1.0;
      continue;
    }
    float ta = (0.0 - eye[a]) / dir[a], tb = (box[a] - eye[a]) / dir[a];
    t0 = max(t0, min(ta, tb));
    t1 = min(t1, max(ta, tb));
  }

  vec3 color = vec3(0.0);
  float alpha = 0.0;
  if (t0 < t1) {
    // The walk's state: the deepest node record known to hold the sample (restart point), and
    // the region of the last sample: a box (level, c) and what is drawn there.
    uint node = 0u, node_level = 0u;
    uvec3 node_c = uvec3(0u);
    uint region = REGION_EMPTY, region_level = 0u, region_size = 0u;
    uvec3 region_c = uvec3(0u);
    bool have_region = false;
    uint leaf = 0u, leaf_level = 0u;  // leaf record and the spatial node it is relative to
    uvec3 leaf_c = uvec3(0u);
    uint entry = 0u;  // the region's entry in the feedback table (svo_layout.h)
    uint doublings = 0u;     // of a drawn region's step (capped)
    float region_k_exit = 0.0;  // first fine-grid k past a drawn region (when doublings > 0)

    // 2. Samples at multiples of the step inside [t0, t1): k from the first to k_end, the first k
    //    with k·step ≥ t1 (the quotient's rounding corrected).
    float k_end = ceil(t1 / step);
    if ((k_end - 1.0) * step >= t1) k_end -= 1.0;
    else if (k_end * step < t1) k_end += 1.0;
    for (float k = ceil(t0 / step), k_next = k; k < k_end; k = k_next) {
      k_next = k + 1.0;
      float t = k * step;
      vec3 p = clamp(eye + t * dir, vec3(0.0), inside);
      uvec3 q = uvec3(p);

      if (!have_region || !inside_box(q, region_c, region_size)) {
        // 2a. Climb to the first node record whose box holds q (the root holds every q).
        while (node != 0u && !inside_box(q, node_c, node_size(levels, node_level))) {
          node = node_words[node * VR_SVO_NODE_WORDS];
          node_level -= 1u;
          node_c >>= 1u;
        }
        // 2b. Descend to the child holding q until a leaf, an "up" or an empty child.
        for (;;) {
          uint half_size = node_size(levels, node_level) >> 1u;
          uvec3 child = q / half_size;
          uvec3 bit = child - 2u * node_c;
          uint octant = bit.x | (bit.y << 1u) | (bit.z << 2u);
          uint word = node_words[node * VR_SVO_NODE_WORDS + 1u + octant];
          uint kind = vr_svo_child_kind(word);
          region_level = node_level + 1u;
          region_size = half_size;
          region_c = child;
          if (kind == VR_SVO_CHILD_EMPTY) {
            region = REGION_EMPTY;
            break;
          }
          if (kind == VR_SVO_CHILD_UP) {  // drawn from this node's own leaf record
            region = REGION_DRAWN;
            leaf = node_words[node * VR_SVO_NODE_WORDS + 9u];
            leaf_level = node_level;
            leaf_c = node_c;
            entry = VR_SVO_FEEDBACK_ENTRIES * leaf + octant;
            break;
          }
          if (kind == VR_SVO_CHILD_LEAF) {
            region = REGION_DRAWN;
            leaf = vr_svo_child_index(word);
            leaf_level = node_level + 1u;
            leaf_c = child;
            entry = VR_SVO_FEEDBACK_ENTRIES * leaf;
            break;
          }
          node = vr_svo_child_index(word);
          node_level += 1u;
          node_c = child;
        }
        have_region = true;
        // Ray-guided feedback (Thiele et al. §3.1): a ray that begins sampling a drawn region
        // raises its entry to 1 + the LOD difference it samples — the levels from the region's
        // node (an "up" octant's child, but the node itself at the finest level) up to the
        // finer keyframe's brick read. A region the transfer function hides (2c) counts as
        // sampled, as in the CPU ray caster: hiding it would draw its parent's data there, whose
        // wider histogram may show, and the node would be requested again, frame after frame.
        if (region == REGION_DRAWN && write_feedback) {
          uint lods = leaf_words[leaf * VR_SVO_LEAF_WORDS + 2u];
          float f = uintBitsToFloat(leaf_words[leaf * VR_SVO_LEAF_WORDS + 3u]);
          uint d_a = vr_svo_lod_a(lods), d_b = vr_svo_lod_b(lods);
          uint d = f == 0.0 ? d_a : (f == 1.0 ? d_b : min(d_a, d_b));
          uint node_level_of_region =
              region_level > leaf_level && region_level < levels ? region_level : leaf_level;
          atomicMax(feedback[entry], 1u + node_level_of_region - leaf_level + d);
        }
        // 2c. A leaf whose values map only to zero opacity is as good as empty.
        if (region == REGION_DRAWN && use_histograms) {
          uvec2 h = uvec2(histogram_words[leaf * VR_SVO_HISTOGRAM_WORDS],
                          histogram_words[leaf * VR_SVO_HISTOGRAM_WORDS + 1u]);
          uvec2 seen = hull(h) & visible;
          if (seen.x == 0u && seen.y == 0u) region = REGION_INVISIBLE;
        }
        // 2e. The drawn region's step: doublings from the leaf's level, and where it ends.
        if (region == REGION_DRAWN) {
          uint record = leaf * VR_SVO_LEAF_WORDS;
          doublings = vr_svo_step_doublings(levels, leaf_level, leaf_words[record + 2u],
                                            uintBitsToFloat(leaf_words[record + 3u]), max_doublings);
          if (doublings > 0u) {
            float size = float(region_size);
            vec3 lo = vec3(region_c) * size;
            region_k_exit = ceil(exit_distance(eye, dir, lo, lo + vec3(size)) / step - 0.01);
          }
        }
      }

      if (region != REGION_DRAWN) {
        // 2d. Skip to the first sample past the region's exit. One sample is re-examined when
        //     rounding puts it on the boundary; k always advances.
        float size = float(region_size);
        vec3 lo = vec3(region_c) * size;
        float t_exit = exit_distance(eye, dir, lo, lo + vec3(size));
        k_next = max(k + 1.0, ceil(t_exit / step - 0.01));
        continue;
      }

      // 3. The next sample: the next multiple of 2^doublings, not past the region or the ray.
      if (doublings > 0u) {
        float span = float(1u << doublings);
        k_next = max(k + 1.0, min(min((floor(k / span) + 1.0) * span, region_k_exit), k_end));
      }

      // 4. Local coordinates in the leaf's spatial node, both keyframes, the leaf's factor.
      float size = float(node_size(levels, leaf_level));
      vec3 u = (p - vec3(leaf_c) * size) / size;
      uint record = leaf * VR_SVO_LEAF_WORDS;
      float f = uintBitsToFloat(leaf_words[record + 3u]);
      uint lods = leaf_words[record + 2u];
      // Each keyframe's slot origin and atlas position, once for the block skip and the sample.
      uint slot_a = leaf_words[record], slot_b = leaf_words[record + 1u];
      ivec3 origin_a = ivec3(0), origin_b = ivec3(0);
      vec3 at_a = vec3(0.0), at_b = vec3(0.0);
      if (f != 1.0) {
        origin_a = slot_origin(slot_a);
        at_a = vec3(origin_a) + slot_texel(vr_svo_lod_a(lods), leaf_c, u);
      }
      if (f != 0.0) {
        origin_b = slot_origin(slot_b);
        at_b = vec3(origin_b) + slot_texel(vr_svo_lod_b(lods), leaf_c, u);
      }
      // 4a. Level-of-detail blending (svo_layout.h words 4–8): the coarse pair C, D, weighted
      //     by 1 − blend, blend the corners' weights interpolated at u.
      uint w7 = leaf_words[record + 7u], w8 = leaf_words[record + 8u];
      float blend = 1.0;
      if (w7 != VR_SVO_BLEND_NONE || w8 != VR_SVO_BLEND_NONE)
        blend = vr_svo_blend_weight(w7, w8, u.x, u.y, u.z);
      float g = uintBitsToFloat(leaf_words[record + 6u]);
      uint slot_c = leaf_words[record + 4u], slot_d = leaf_words[record + 5u];
      ivec3 origin_c = ivec3(0), origin_d = ivec3(0);
      vec3 at_c = vec3(0.0), at_d = vec3(0.0);
      if (blend < 1.0) {
        if (g != 1.0) {
          origin_c = slot_origin(slot_c);
          at_c = vec3(origin_c) + slot_texel(vr_svo_lod_c(lods), leaf_c, u);
        }
        if (g != 0.0) {
          origin_d = slot_origin(slot_d);
          at_d = vec3(origin_d) + slot_texel(vr_svo_lod_d(lods), leaf_c, u);
        }
      }
      if (block_skip) {
        // 4b. Every keyframe's block read holds only values the transfer function hides: so
        //     does their blend. Skip the fetches, keep the sample positions.
        vec2 r = vec2(1e30, -1e30);
        if (f != 1.0) {
          vec2 ra = block_range(slot_a, origin_a, at_a);
          r = vec2(min(r.x, ra.x), max(r.y, ra.y));
        }
        if (f != 0.0) {
          vec2 rb = block_range(slot_b, origin_b, at_b);
          r = vec2(min(r.x, rb.x), max(r.y, rb.y));
        }
        if (blend < 1.0 && g != 1.0) {
          vec2 rc = block_range(slot_c, origin_c, at_c);
          r = vec2(min(r.x, rc.x), max(r.y, rc.y));
        }
        if (blend < 1.0 && g != 0.0) {
          vec2 rd = block_range(slot_d, origin_d, at_d);
          r = vec2(min(r.x, rd.x), max(r.y, rd.y));
        }
        if (!range_visible(r)) continue;
      }
      float a = f == 1.0 ? 0.0 : keyframe(at_a);
      float b = f == 0.0 ? 0.0 : keyframe(at_b);
      float value = f == 0.0 ? a : f == 1.0 ? b : (1.0 - f) * a + f * b;
      if (blend < 1.0) {
        float ca = g == 1.0 ? 0.0 : keyframe(at_c);
        float cb = g == 0.0 ? 0.0 : keyframe(at_d);
        float coarse = g == 0.0 ? ca : g == 1.0 ? cb : (1.0 - g) * ca + g * cb;
        value = coarse + blend * (value - coarse);
      }

      // 5. Transfer function (corrected for the base step), corrected for the n = k' − k fine
      //    steps the sample stands for; front to back, early termination.
      vec4 c = lookup(value);
      float n = k_next - k;
      if (n > 1.0 && c.a < 1.0) c.a = 1.0 - pow(1.0 - c.a, n);
      if (!(c.a > 0.0)) continue;
      float w = (1.0 - alpha) * c.a;
      color += w * c.rgb;
      alpha += w;
      if (alpha > params.up_termination.w) break;
    }
  }
  // 6. Over the background.
  imageStore(out_image, ivec2(pixel), vec4(color + (1.0 - alpha) * params.background_lo.rgb, alpha));
}
