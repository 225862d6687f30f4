// renderer.hpp: the CPU reference renderer of volreel's player (docs/design.md, "Streaming",
// step 7) — a plain ray caster over the array-encoded SVO (svo_layout.h) and a CpuAtlas, and the
// brute-force oracle that casts the same rays through dense level volumes. It is the reference the
// Vulkan renderer is tested against and the headless fallback.
//
// Both renderers share one ray loop (they take exactly the same samples where the SVO is drawn
// at the finest level):
//   1. The ray of pixel (i, j) leaves OrbitCamera::eye() along ray_direction(i + 0.5, j + 0.5)
//      (world = finest-voxel coordinates) and is clipped to the volume's box [0, dims).
//   2. Samples lie at distances t = k·step from the eye (k integer) inside the clipped segment:
//      fixed in world space, so they do not crawl when the clip distance changes. Not every k is
//      taken: the step follows the level of the data (step size from the node's level):
//        a. A sample reads a leaf whose finer brick lies e levels above the finest
//           (vr_svo_step_doublings, e capped at RenderOptions::max_step_doublings).
//        b. The next sample is k' = the next multiple of 2^e after k (coarse samples sit on a
//           grid nested in the fine one, so they do not crawl either), but no later than the
//           first k whose point lies past the sample's region (the SVO child box the descent
//           ended in, exit rounded as ceil(t_exit/step − 0.01)) and no later than the segment's
//           end: a coarse step never jumps into the next, possibly finer, region — the first
//           sample there is the first fine-grid point inside it. k' ≥ k + 1.
//        c. The sample stands for the n = k' − k fine steps up to the next one.
//      Where every leaf is at the finest level (e = 0) this is every k, as with a fixed step.
//   3. Each sample's value goes through the transfer function with its opacity corrected for the
//      base step (TransferFunction::opacity_corrected(step / reference_step)), then for the n
//      steps it stands for: α' = 1 − (1 − α)^n, that is 1 − (1 − α_ref)^(n·step/reference_step)
//      (the power is taken after the table's linear interpolation, in float: n = 1 leaves α as
//      it is). A uniform medium composites to the same opacity at any step.
// They differ only in how a sample's value is found:
//   render_svo       descends the SVO from the root to the node containing the point (Cesium
//                    patent [0050]), takes its leaf record, samples keyframes A and B trilinearly
//                    in their atlas slots at u' = ((c mod 2^d) + u)/2^d for each one's LOD
//                    difference d (any d), and returns (1 − f)·A + f·B; a leaf that blends
//                    levels of detail (svo_layout.h words 4–8) mixes in its coarse pair C, D
//                    the same way, by 1 − w(u), its corner weights interpolated at u. Empty
//                    children are transparent.
//   render_reference samples dense volumes of levels k_A and k_B trilinearly at level voxel
//                    coordinates p/2^(L−1−k) − 0.5, clamped to the level's edge, and returns
//                    (1 − f)·A + f·B. It always takes every k (e = 0, n = 1): it is the
//                    ground truth that coarse steps approximate. A fully loaded finest-level SVO
//                    takes exactly its samples; coarser states take fewer (compare by PSNR, or
//                    render them with max_step_doublings = 0 to compare sample for sample).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/image/image.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/player/svo_layout.h"

namespace volreel::cpu_render {

/// The spatial octree's geometry: the finest level's dims and the level count L (format's
/// level_geometry(dims, shape).size()). The root covers [0, I·2^(L−1))³ finest voxels, I the
/// bricks' interior.
struct VolumeGeometry {
  std::array<std::uint32_t, 3> dims{};
  std::uint32_t levels = 1;
  format::BrickShape shape;  ///< the bricks' (the container's brick size)
  /// From the finest dims and the bricks' shape (levels by format::level_geometry).
  static VolumeGeometry of(std::array<std::uint32_t, 3> dims, format::BrickShape shape = {});
};

/// The word arrays of an array-encoded SVO (svo_layout.h): node records (10 words each, record
/// 0 the root), leaf records (VR_SVO_LEAF_WORDS words each) and, optionally, leaf histograms (2
/// words each, one per leaf record, bins over histogram_range — the manifest's value range).
struct SvoView {
  std::span<const vr_uint> nodes;
  std::span<const vr_uint> leaves;
  std::span<const vr_uint> histograms;  ///< empty: no transfer-function culling
  std::array<float, 2> histogram_range{0, 1};
};

struct RenderOptions {
  double step = 0.5;            ///< sample spacing along the ray, finest voxels (> 0)
  double reference_step = 1.0;  ///< the length the transfer function's opacities are for (> 0)
  std::array<float, 3> background{0, 0, 0};  ///< RGB behind the volume, [0, 1]
  float termination_alpha = 0.99f;           ///< early ray termination threshold
  /// Step size from the node's level (steps 2a–2c): the step in a leaf whose data lies e levels
  /// above the finest is step·2^min(e, max_step_doublings); 0 keeps the fixed step everywhere.
  /// At most 16. render_reference ignores it (always the fixed step).
  std::uint32_t max_step_doublings = 3;
  /// render_svo: fill RgbaImage::levels (for image metrics at level-of-detail boundaries).
  bool level_map = false;
};

/// A float RGBA image, rows top to bottom, 4 values per pixel.
struct RgbaImage {
  int width = 0, height = 0;
  std::vector<float> rgba;
  /// Samples whose value was computed (drawn SVO regions, every sample of render_reference):
  /// the CPU renderers count them; 0 where nobody counted (a Vulkan read-back).
  std::uint64_t samples = 0;
  /// With RenderOptions::level_map (render_svo only; else empty): per pixel, row-major, the data
  /// level of the sample that added the most opacity to it — the spatial node's level minus the
  /// LOD difference of the coarser keyframe its fine pair reads (vr_svo_coarser_lod), as the SVO
  /// builder's spatial blending counts levels — or no_level where no sample added any.
  std::vector<std::uint8_t> levels;
  static constexpr std::uint8_t no_level = 255;
  const float* pixel(int x, int y) const {
    return rgba.data() + 4 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
                              static_cast<std::size_t>(x));
  }
};

/// Checks the SVO before it is walked: node and leaf indices in range, node records only above
/// the finest level and reached once (a tree, no cycles), leaf records with atlas slots below
/// `slot_count` (VR_ATLAS_NO_SLOT only where its weight, 1 − f or f, is 0), factors in [0, 1],
/// LOD differences no larger than the spatial node's level, in a blending leaf the coarse pair's
/// slots likewise and its LOD differences in [1, level], word 9 set wherever a child is
/// VR_SVO_CHILD_UP, and histograms (when given) 2 words per leaf record. Throws
/// std::invalid_argument naming the record and word.
void validate_svo(const SvoView& svo, std::uint32_t slot_count, const VolumeGeometry& geometry);

/// Renders the SVO and atlas from the camera (camera.width × camera.height pixels). Validates
/// the SVO first (validate_svo) and the options (std::invalid_argument). With leaf histograms,
/// samples in leaves whose histogram hull the transfer function makes invisible are skipped
/// (TransferFunction::visible_hull) — the same image, fewer samples. OpenMP over rows.
///
/// Ray-guided feedback (Thiele, Matthes, Froehlich, §3.1): with `feedback`, it is set to the
/// feedback table of svo_layout.h (VR_SVO_FEEDBACK_ENTRIES entries per leaf record, one per region
/// the leaf draws): 0 where no ray reached the region (occluded behind opaque material, outside
/// the image), else 1 + the largest LOD difference of its samples: how many levels above the
/// region's node the brick read lies. A leaf culled by its histogram counts as reached: hidden,
/// its region would be drawn from an ancestor's data, whose wider histogram may show, and the
/// node requested again, frame after frame.
RgbaImage render_svo(const SvoView& svo, const CpuAtlas& atlas, const VolumeGeometry& geometry,
                     const player::OrbitCamera& camera, const TransferFunction& transfer,
                     const RenderOptions& options = {},
                     std::vector<std::uint32_t>* feedback = nullptr);

/// A dense volume of one octree level (format::decode_level's output or a pyramid level).
struct DenseLevel {
  std::array<std::uint32_t, 3> dims{};  ///< the level's dims (format::level_geometry)
  std::span<const float> values;        ///< dims[0]·dims[1]·dims[2], x fastest
  std::uint32_t level = 0;              ///< 0 = root .. L−1 = finest
  static DenseLevel of(const format::LevelVolume& volume, std::uint32_t level) {
    return {volume.dims, volume.data, level};
  }
};

/// The oracle: the same rays through dense volumes, value (1 − factor)·A + factor·B with A and B
/// sampled at their own levels. Throws std::invalid_argument when a volume's size does not match
/// its dims or its level is not below geometry.levels.
RgbaImage render_reference(const DenseLevel& a, const DenseLevel& b, float factor,
                           const VolumeGeometry& geometry, const player::OrbitCamera& camera,
                           const TransferFunction& transfer, const RenderOptions& options = {});

/// 8-bit RGB (alpha dropped: the background is already composited), rounded and clamped.
image::Image to_image(const RgbaImage& image);
/// Writes the image as an 8-bit RGB PNG (image::write_png).
void write_png(const std::filesystem::path& path, const RgbaImage& image);
/// Largest absolute difference of any channel of any pixel (images of equal size, else +inf).
double max_abs_difference(const RgbaImage& a, const RgbaImage& b);

}  // namespace volreel::cpu_render
