// renderer.cpp: the CPU reference ray caster over the array-encoded SVO and the dense-volume
// oracle, sharing one ray loop (see renderer.hpp for the numbered steps).
#include "volreel/cpu_render/renderer.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "trilinear.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::cpu_render {
namespace {

/// Sample::feedback_entry of a sample not read from an SVO leaf record.
constexpr std::uint32_t no_entry = 0xFFFFFFFFu;

/// A sample: whether the point is drawn at all (an empty child is not), its value and, for the
/// step (renderer.hpp step 2), how often the base step may be doubled there (before the cap) and
/// the region it lies in — the box [lo, lo + size)³ whose exit ends a coarse step.
struct Sample {
  bool drawn = false;
  float value = 0;
  std::uint32_t doublings = 0;
  glm::dvec3 region_lo{0.0};
  double region_size = 0;
  /// Its entry in the feedback table (renderer.hpp; no_entry for the dense oracle) and how many
  /// levels above the region's the data it read lies (its LOD difference, Thiele et al. §3.1).
  std::uint32_t feedback_entry = no_entry;
  std::uint32_t lod_difference = 0;
  /// The level of the data read (RgbaImage::levels; no_level for the dense oracle).
  std::uint8_t data_level = RgbaImage::no_level;
};

/// The largest max_step_doublings (2^16 fine steps: k stays exact in a float on the GPU).
constexpr std::uint32_t max_doublings_allowed = 16;

/// Ray parameter where the ray from `eye` along `dir` leaves the box [lo, hi) (raycast.comp's
/// exit_distance).
double exit_distance(const glm::dvec3& eye, const glm::dvec3& dir, const glm::dvec3& lo,
                     const glm::dvec3& hi) {
  double t = 1e30;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] > 0)
      t = std::min(t, (hi[a] - eye[a]) / dir[a]);
    else if (dir[a] < 0)
      t = std::min(t, (lo[a] - eye[a]) / dir[a]);
  }
  return t;
}

/// (1 − f)·a + f·b; f = 0 and f = 1 return a and b exactly (the other keyframe is not read).
inline float mix_keyframes(float a, float b, float f) {
  return (1.0f - f) * a + f * b;
}

void check_geometry(const VolumeGeometry& g) {
  if (g.levels < 1 || g.levels > format::max_levels)
    throw std::invalid_argument("render: expected 1 to " + std::to_string(format::max_levels) +
                                " octree levels, found " + std::to_string(g.levels));
  if (!format::valid_brick_size(g.shape.size))
    throw std::invalid_argument("render: bricks of " + std::to_string(g.shape.size) +
                                "^3 (a brick size is a multiple of 6 in 12..66)");
  const std::uint64_t root = std::uint64_t{g.shape.interior()} << (g.levels - 1);
  for (int a = 0; a < 3; ++a)
    if (g.dims[static_cast<std::size_t>(a)] == 0 || g.dims[static_cast<std::size_t>(a)] > root)
      throw std::invalid_argument("render: dims[" + std::to_string(a) +
                                  "] = " + std::to_string(g.dims[static_cast<std::size_t>(a)]) +
                                  " is not covered by a root of " + std::to_string(root) +
                                  " voxels (" + std::to_string(g.levels) + " levels)");
}

void check_options(const RenderOptions& o, const player::OrbitCamera& camera) {
  if (!(o.step > 0 && std::isfinite(o.step)))
    throw std::invalid_argument("render: expected a step > 0, found " +
                                format::number_text(o.step));
  if (!(o.reference_step > 0 && std::isfinite(o.reference_step)))
    throw std::invalid_argument("render: expected a reference step > 0, found " +
                                format::number_text(o.reference_step));
  if (o.max_step_doublings > max_doublings_allowed)
    throw std::invalid_argument("render: expected max_step_doublings ≤ " +
                                std::to_string(max_doublings_allowed) + ", found " +
                                std::to_string(o.max_step_doublings));
  if (camera.width <= 0 || camera.height <= 0)
    throw std::invalid_argument("render: expected a positive image size, found " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
}

/// Steps 1–5 of renderer.hpp for every pixel; `sample(p)` gives the value at world point p.
template <class Sampler>
RgbaImage cast_rays(const VolumeGeometry& geometry, const player::OrbitCamera& camera,
                    const TransferFunction& transfer, const RenderOptions& options,
                    const Sampler& sample, std::vector<std::uint32_t>* feedback = nullptr) {
  check_options(options, camera);
  const TransferFunction tf = transfer.opacity_corrected(options.step / options.reference_step);
  RgbaImage image;
  image.width = camera.width;
  image.height = camera.height;
  image.rgba.assign(
      4 * static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height), 0.0f);
  const glm::dvec3 eye = camera.eye();
  const glm::dvec3 box{geometry.dims[0], geometry.dims[1], geometry.dims[2]};
  // The largest coordinates still inside [0, dims).
  const glm::dvec3 inside{std::nextafter(box.x, 0.0), std::nextafter(box.y, 0.0),
                          std::nextafter(box.z, 0.0)};
  const double step = options.step;
  std::uint64_t samples = 0;
  if (options.level_map)
    image.levels.assign(
        static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height),
        RgbaImage::no_level);

#pragma omp parallel for schedule(dynamic, 1) reduction(+ : samples)
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      // 1. The ray, clipped to the box (slab test).
      const glm::dvec3 dir = camera.ray_direction(x + 0.5, y + 0.5);
      double t0 = 0, t1 = std::numeric_limits<double>::infinity();
      for (int a = 0; a < 3; ++a) {
        if (dir[a] == 0) {
          if (eye[a] < 0 || eye[a] >= box[a]) t1 = -1;
          continue;
        }
        const double ta = (0 - eye[a]) / dir[a], tb = (box[a] - eye[a]) / dir[a];
        t0 = std::max(t0, std::min(ta, tb));
        t1 = std::min(t1, std::max(ta, tb));
      }
      // A degenerate camera (NaN direction) gives no finite segment: draw nothing.
      if (!std::isfinite(t0) || !std::isfinite(t1)) t1 = -1;
      float color[3] = {0, 0, 0};
      float alpha = 0;
      std::uint32_t last_entry = no_entry;  // feedback: the entry this ray wrote last
      float most = 0;                       // the level map: the largest opacity added
      std::uint8_t level = RgbaImage::no_level;
      if (t0 < t1) {
        // 2. Samples at multiples of the step inside [t0, t1): k from the first to k_end, the
        //    first k with k·step ≥ t1 (the quotient's rounding corrected).
        double k_end = std::ceil(t1 / step);
        if ((k_end - 1) * step >= t1)
          k_end -= 1;
        else if (k_end * step < t1)
          k_end += 1;
        for (double k = std::ceil(t0 / step), k_next = k; k < k_end; k = k_next) {
          const double t = k * step;
          glm::dvec3 p = eye + t * dir;
          p = glm::clamp(p, glm::dvec3(0.0), inside);
          const Sample s = sample(p);
          k_next = k + 1;
          // Feedback (Thiele et al. §3.1): as the ray begins sampling a leaf, the largest LOD
          // difference of the rays that sample it, plus one.
          if (feedback && s.feedback_entry != last_entry && s.feedback_entry < feedback->size()) {
            last_entry = s.feedback_entry;
            std::atomic_ref<std::uint32_t> entry((*feedback)[s.feedback_entry]);
            std::uint32_t seen = entry.load(std::memory_order_relaxed);
            const std::uint32_t value = s.lod_difference + 1;
            while (seen < value && !entry.compare_exchange_weak(seen, value)) {
            }
          }
          if (!s.drawn) continue;
          ++samples;
          // 2a–c. The next sample: the next multiple of 2^e, but not past the region's exit or
          //       the segment's end (raycast.comp step 3 computes the same in float).
          const std::uint32_t e = std::min(s.doublings, options.max_step_doublings);
          if (e > 0) {
            const double span = std::ldexp(1.0, static_cast<int>(e));
            const double k_exit = std::ceil(
                exit_distance(eye, dir, s.region_lo, s.region_lo + glm::dvec3(s.region_size)) /
                    step -
                0.01);
            k_next = std::max(k + 1, std::min({(std::floor(k / span) + 1) * span, k_exit, k_end}));
          }
          // 3. Transfer function (opacity corrected for the base step), then for the n = k' − k
          //    steps this sample stands for.
          Rgba c = tf.lookup(s.value);
          const float n = static_cast<float>(k_next - k);
          if (n > 1.0f && c[3] < 1.0f) c[3] = 1.0f - std::pow(1.0f - c[3], n);
          if (!(c[3] > 0)) continue;
          // 4. Front to back.
          const float w = (1.0f - alpha) * c[3];
          if (w > most) {
            most = w;
            level = s.data_level;
          }
          color[0] += w * c[0];
          color[1] += w * c[1];
          color[2] += w * c[2];
          alpha += w;
          if (alpha > options.termination_alpha) break;
        }
      }
      // 5. Over the background.
      float* out = image.rgba.data() +
                   4 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(image.width) +
                        static_cast<std::size_t>(x));
      for (std::size_t c = 0; c < 3; ++c)
        out[c] = color[c] + (1.0f - alpha) * options.background[c];
      out[3] = alpha;
      if (!image.levels.empty())
        image.levels[static_cast<std::size_t>(y) * static_cast<std::size_t>(image.width) +
                     static_cast<std::size_t>(x)] = level;
    }
  }
  image.samples = samples;
  return image;
}

/// The value at a point from the SVO and the atlas (Cesium patent [0050]).
class SvoSampler {
 public:
  SvoSampler(const SvoView& svo, const CpuAtlas& atlas, const VolumeGeometry& geometry,
             const TransferFunction& transfer)
      : svo_(svo), atlas_(atlas), levels_(geometry.levels), interior_(geometry.shape.interior()) {
    // Transfer-function culling: a leaf whose histogram hull maps only to zero opacity is not
    // drawn (opacity correction keeps zero at zero, so the uncorrected function decides).
    if (!svo.histograms.empty()) {
      const std::size_t leaves = svo.leaves.size() / VR_SVO_LEAF_WORDS;
      const std::uint64_t visible =
          transfer.visible_bins(svo.histogram_range[0], svo.histogram_range[1]);
      leaf_visible_.resize(leaves);
      for (std::size_t i = 0; i < leaves; ++i) {
        const std::uint64_t h =
            std::uint64_t{svo.histograms[VR_SVO_HISTOGRAM_WORDS * i]} |
            (std::uint64_t{svo.histograms[VR_SVO_HISTOGRAM_WORDS * i + 1]} << 32);
        leaf_visible_[i] = (TransferFunction::histogram_hull(h) & visible) != 0;
      }
    }
  }

  Sample operator()(const glm::dvec3& p) const {
    const std::uint32_t q[3] = {static_cast<std::uint32_t>(p.x), static_cast<std::uint32_t>(p.y),
                                static_cast<std::uint32_t>(p.z)};
    // 1. Descend from the root to the child containing q until a leaf, an "up" or an empty child.
    vr_uint node = 0, level = 0, leaf = 0;
    std::uint32_t c[3] = {0, 0, 0};
    // The region: the child box the descent ends in (for an "up" child, the child's box, not
    // its node's: a coarse step ends where the up child does, as raycast.comp's region does).
    std::uint32_t region[3] = {0, 0, 0};
    vr_uint region_level = 0;
    bool up = false;
    vr_uint up_octant = 0;
    for (;;) {
      const std::uint32_t half = (interior_ / 2) << (levels_ - 1 - level);
      const std::uint32_t child[3] = {q[0] / half, q[1] / half, q[2] / half};
      const vr_uint octant =
          (child[0] - 2 * c[0]) | ((child[1] - 2 * c[1]) << 1) | ((child[2] - 2 * c[2]) << 2);
      const vr_uint word = svo_.nodes[node * VR_SVO_NODE_WORDS + 1 + octant];
      const vr_uint kind = vr_svo_child_kind(word);
      if (kind == VR_SVO_CHILD_EMPTY) return {};
      for (int a = 0; a < 3; ++a) region[a] = child[a];
      region_level = level + 1;
      if (kind == VR_SVO_CHILD_UP) {  // drawn from this node's own leaf record
        leaf = svo_.nodes[node * VR_SVO_NODE_WORDS + 9];
        up = true;
        up_octant = octant;
        break;
      }
      for (int a = 0; a < 3; ++a) c[a] = child[a];
      ++level;
      if (kind == VR_SVO_CHILD_LEAF) {
        leaf = vr_svo_child_index(word);
        break;
      }
      node = vr_svo_child_index(word);
    }
    const vr_uint* record = svo_.leaves.data() + std::size_t{leaf} * VR_SVO_LEAF_WORDS;
    const float f = std::bit_cast<float>(record[3]);
    // The LOD difference: the levels from the region's node (the child an "up" region is) up to
    // the brick read, the finer one while both keyframes are read.
    const vr_uint d_a = vr_svo_lod_a(record[2]), d_b = vr_svo_lod_b(record[2]);
    const vr_uint d = f == 0.0f ? d_a : f == 1.0f ? d_b : std::min(d_a, d_b);
    // (At the finest level an "up" octant is a part of the node's own brick.)
    const std::uint32_t region_node_level = up && level + 1 < levels_ ? level + 1 : level;
    const std::uint32_t entry = VR_SVO_FEEDBACK_ENTRIES * leaf + up_octant;
    const std::uint32_t lod_difference = region_node_level - level + d;
    // A leaf the transfer function hides is not drawn, but its rays count as having reached it
    // (the feedback): hidden, its region would be drawn from an ancestor's data, whose wider
    // histogram may show, and the node would be requested again, frame after frame.
    if (!leaf_visible_.empty() && !leaf_visible_[leaf]) {
      Sample culled;
      culled.feedback_entry = entry;
      culled.lod_difference = lod_difference;
      return culled;
    }
    // 2. Local coordinates u ∈ [0, 1)³ of p in the spatial node (level, c).
    const double size = double(interior_ << (levels_ - 1 - level));
    float u[3];
    for (int a = 0; a < 3; ++a) u[a] = static_cast<float>((p[a] - double(c[a]) * size) / size);
    // 3. Both keyframes at their slot coordinates, each mapped into its brick by its LOD
    //    difference (svo_layout.h), then interpolated with the leaf's factor.
    const auto interior = static_cast<float>(interior_);
    const auto keyframe = [&](vr_uint slot, vr_uint up_levels) {
      return atlas_.sample(
          slot, vr_svo_slot_coord(vr_svo_ancestor_local(c[0], u[0], up_levels), interior),
          vr_svo_slot_coord(vr_svo_ancestor_local(c[1], u[1], up_levels), interior),
          vr_svo_slot_coord(vr_svo_ancestor_local(c[2], u[2], up_levels), interior));
    };
    // A keyframe pair at slots s0, s1 (LOD differences d0, d1) mixed by factor x; a keyframe
    // whose weight is 0 is not read.
    const auto pair_value = [&](vr_uint s0, vr_uint s1, vr_uint d0, vr_uint d1, float x) {
      if (x == 0.0f) return keyframe(s0, d0);
      if (x == 1.0f) return keyframe(s1, d1);
      return mix_keyframes(keyframe(s0, d0), keyframe(s1, d1), x);
    };
    float value =
        pair_value(record[0], record[1], vr_svo_lod_a(record[2]), vr_svo_lod_b(record[2]), f);
    // 3a. Level-of-detail blending: the parent's drawing (the coarse pair) weighted by the
    //     corners' weights interpolated at u.
    if (record[7] != VR_SVO_BLEND_NONE || record[8] != VR_SVO_BLEND_NONE) {
      const float w = vr_svo_blend_weight(record[7], record[8], u[0], u[1], u[2]);
      if (w < 1.0f) {
        const float coarse = pair_value(record[4], record[5], vr_svo_lod_c(record[2]),
                                        vr_svo_lod_d(record[2]), std::bit_cast<float>(record[6]));
        value = coarse + w * (value - coarse);
      }
    }
    // 4. The step's doublings from the leaf's level (svo_layout.h; the cap is the caller's) and
    //    the region's box.
    // (region_level ≤ levels_: the octants of a one-level volume's root are half a brick.)
    const double region_size = double((interior_ / 2) << (levels_ - region_level));
    return {true,
            value,
            vr_svo_step_doublings(levels_, level, record[2], f, max_doublings_allowed),
            glm::dvec3(region[0], region[1], region[2]) * region_size,
            region_size,
            entry,
            lod_difference,
            static_cast<std::uint8_t>(level - vr_svo_coarser_lod(record[2], f))};
  }

 private:
  const SvoView& svo_;
  const CpuAtlas& atlas_;
  std::uint32_t levels_;
  std::uint32_t interior_;                  ///< interior voxels per brick axis
  std::vector<std::uint8_t> leaf_visible_;  ///< per leaf record; empty: no culling
};

/// The value at a point from two dense level volumes.
class DenseSampler {
 public:
  DenseSampler(const DenseLevel& a, const DenseLevel& b, float factor,
               const VolumeGeometry& geometry)
      : a_(a), b_(b), f_(factor), levels_(geometry.levels) {}

  Sample operator()(const glm::dvec3& p) const {
    const float a = f_ == 1.0f ? 0.0f : at(a_, p);
    const float b = f_ == 0.0f ? 0.0f : at(b_, p);
    // The ground truth steps finely everywhere (renderer.hpp): no doublings.
    return {true, f_ == 0.0f ? a : f_ == 1.0f ? b : mix_keyframes(a, b, f_), 0, glm::dvec3(0.0), 0};
  }

 private:
  /// Trilinear at level voxel coordinates p/2^(L−1−k) − 0.5, clamped to the level's edge.
  float at(const DenseLevel& v, const glm::dvec3& p) const {
    const double scale = std::ldexp(1.0, -static_cast<int>(levels_ - 1 - v.level));
    return detail::trilinear(
        v.values.data(), v.dims[0], v.dims[1], v.dims[2], static_cast<float>(p.x * scale - 0.5),
        static_cast<float>(p.y * scale - 0.5), static_cast<float>(p.z * scale - 0.5));
  }
  const DenseLevel& a_;
  const DenseLevel& b_;
  float f_;
  std::uint32_t levels_;
};

}  // namespace

VolumeGeometry VolumeGeometry::of(std::array<std::uint32_t, 3> dims, format::BrickShape shape) {
  return {dims, static_cast<std::uint32_t>(format::level_geometry(dims, shape).size()), shape};
}

void validate_svo(const SvoView& svo, std::uint32_t slot_count, const VolumeGeometry& geometry) {
  check_geometry(geometry);
  const auto bad = [](const std::string& what) { throw std::invalid_argument("SVO: " + what); };
  if (svo.nodes.empty() || svo.nodes.size() % VR_SVO_NODE_WORDS != 0)
    bad("expected a non-empty multiple of " + std::to_string(VR_SVO_NODE_WORDS) +
        " node words, found " + std::to_string(svo.nodes.size()));
  if (svo.leaves.size() % VR_SVO_LEAF_WORDS != 0)
    bad("expected a multiple of " + std::to_string(VR_SVO_LEAF_WORDS) + " leaf words, found " +
        std::to_string(svo.leaves.size()));
  const std::size_t node_count = svo.nodes.size() / VR_SVO_NODE_WORDS;
  const std::size_t leaf_count = svo.leaves.size() / VR_SVO_LEAF_WORDS;
  if (!svo.histograms.empty() && svo.histograms.size() != leaf_count * VR_SVO_HISTOGRAM_WORDS)
    bad("expected " + std::to_string(VR_SVO_HISTOGRAM_WORDS) + " histogram words per leaf (" +
        std::to_string(leaf_count * VR_SVO_HISTOGRAM_WORDS) + "), found " +
        std::to_string(svo.histograms.size()));
  if (svo.nodes[0] != VR_SVO_NO_PARENT)
    bad("node 0 (the root) word 0: expected no parent, found " + std::to_string(svo.nodes[0]));

  // Messages are built only on failure: this runs on every frame. `from` names the referring
  // word (a callable returning the text).
  const auto check_leaf = [&](vr_uint leaf, vr_uint level, const auto& from) {
    if (leaf >= leaf_count)
      bad(from() + ": leaf " + std::to_string(leaf) + " of " + std::to_string(leaf_count));
    const vr_uint* r = svo.leaves.data() + std::size_t{leaf} * VR_SVO_LEAF_WORDS;
    const auto at = [&] { return "leaf " + std::to_string(leaf) + " (from " + from() + ")"; };
    // A keyframe pair: slots at words s0 and s0 + 1, factor at word fw, LOD differences d0, d1
    // (at least min_d), named n0 and n1.
    const auto check_pair = [&](vr_uint s0, vr_uint fw, vr_uint d0, vr_uint d1, vr_uint min_d,
                                const char* n0, const char* n1) {
      const float f = std::bit_cast<float>(r[fw]);
      if (!(f >= 0 && f <= 1))
        bad(at() + " word " + std::to_string(fw) + ": expected a factor in [0, 1], found " +
            format::number_text(f));
      const float weight[2] = {1 - f, f};
      const vr_uint d[2] = {d0, d1};
      for (vr_uint k = 0; k < 2; ++k) {
        if (r[s0 + k] >= slot_count && !(r[s0 + k] == VR_ATLAS_NO_SLOT && weight[k] == 0))
          bad(at() + " word " + std::to_string(s0 + k) + ": slot " + std::to_string(r[s0 + k]) +
              " of " + std::to_string(slot_count));
        if (d[k] > level || d[k] < min_d)
          bad(at() + " word 2: LOD difference " + std::to_string(d[k]) + " of keyframe " +
              (k == 0 ? n0 : n1) + " outside [" + std::to_string(min_d) + ", " +
              std::to_string(level) + "] (the spatial node's level)");
      }
    };
    check_pair(0, 3, vr_svo_lod_a(r[2]), vr_svo_lod_b(r[2]), 0, "A", "B");
    // A blending leaf reads its coarse pair too (an ancestor's: at least one level up).
    if (r[7] != VR_SVO_BLEND_NONE || r[8] != VR_SVO_BLEND_NONE)
      check_pair(4, 6, vr_svo_lod_c(r[2]), vr_svo_lod_d(r[2]), 1, "C", "D");
  };

  // Walk the tree from the root: every record reached once, at a level that exists.
  std::vector<bool> seen(node_count, false);
  struct Item {
    vr_uint node, level;
  };
  std::vector<Item> stack = {{0, 0}};
  seen[0] = true;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const vr_uint* rec = svo.nodes.data() + std::size_t{it.node} * VR_SVO_NODE_WORDS;
    const auto at = [&] { return "node " + std::to_string(it.node); };
    bool up = false;
    for (vr_uint o = 0; o < 8; ++o) {
      const vr_uint word = rec[1 + o], kind = vr_svo_child_kind(word),
                    index = vr_svo_child_index(word);
      const auto child = [&] { return at() + " word " + std::to_string(1 + o); };
      if (kind == VR_SVO_CHILD_UP) up = true;
      if (kind != VR_SVO_CHILD_NODE && kind != VR_SVO_CHILD_LEAF) continue;
      if (it.level + 1 >= geometry.levels)
        bad(child() + ": a child below the finest level (" + std::to_string(geometry.levels) +
            " levels)");
      if (kind == VR_SVO_CHILD_LEAF) {
        check_leaf(index, it.level + 1, child);
        continue;
      }
      if (index >= node_count)
        bad(child() + ": node " + std::to_string(index) + " of " + std::to_string(node_count));
      if (seen[index]) bad(child() + ": node " + std::to_string(index) + " is reached twice");
      if (svo.nodes[std::size_t{index} * VR_SVO_NODE_WORDS] != it.node)
        bad("node " + std::to_string(index) + " word 0: expected parent " +
            std::to_string(it.node) + ", found " +
            std::to_string(svo.nodes[std::size_t{index} * VR_SVO_NODE_WORDS]));
      seen[index] = true;
      stack.push_back({index, it.level + 1});
    }
    if (up || rec[9] != VR_SVO_NO_LEAF)
      check_leaf(rec[9], it.level, [&] { return at() + " word 9"; });
  }
}

RgbaImage render_svo(const SvoView& svo, const CpuAtlas& atlas, const VolumeGeometry& geometry,
                     const player::OrbitCamera& camera, const TransferFunction& transfer,
                     const RenderOptions& options, std::vector<std::uint32_t>* feedback) {
  validate_svo(svo, atlas.slot_count(), geometry);
  if (atlas.shape() != geometry.shape)
    throw std::invalid_argument("render_svo: an atlas of " + std::to_string(atlas.shape().size) +
                                "^3 slots for bricks of " + std::to_string(geometry.shape.size) +
                                "^3");
  if (feedback)
    feedback->assign(VR_SVO_FEEDBACK_ENTRIES * (svo.leaves.size() / VR_SVO_LEAF_WORDS), 0);
  return cast_rays(geometry, camera, transfer, options, SvoSampler(svo, atlas, geometry, transfer),
                   feedback);
}

RgbaImage render_reference(const DenseLevel& a, const DenseLevel& b, float factor,
                           const VolumeGeometry& geometry, const player::OrbitCamera& camera,
                           const TransferFunction& transfer, const RenderOptions& options) {
  check_geometry(geometry);
  const auto geometries = format::level_geometry(geometry.dims, geometry.shape);
  if (geometries.size() != geometry.levels)
    throw std::invalid_argument("render_reference: dims give " + std::to_string(geometries.size()) +
                                " levels, geometry says " + std::to_string(geometry.levels));
  for (const DenseLevel* v : {&a, &b}) {
    const char* name = v == &a ? "A" : "B";
    if (v->level >= geometry.levels)
      throw std::invalid_argument(std::string("render_reference: volume ") + name + " level " +
                                  std::to_string(v->level) + " of " +
                                  std::to_string(geometry.levels));
    if (v->dims != geometries[v->level].dims ||
        v->values.size() != std::size_t{v->dims[0]} * v->dims[1] * v->dims[2])
      throw std::invalid_argument(std::string("render_reference: volume ") + name +
                                  " does not have level " + std::to_string(v->level) +
                                  "'s dims and size");
  }
  if (!(factor >= 0 && factor <= 1))
    throw std::invalid_argument("render_reference: expected a factor in [0, 1], found " +
                                format::number_text(factor));
  RenderOptions dense = options;
  dense.level_map = false;  // one level everywhere: no map
  return cast_rays(geometry, camera, transfer, dense, DenseSampler(a, b, factor, geometry));
}

image::Image to_image(const RgbaImage& image) {
  image::Image out;
  out.width = image.width;
  out.height = image.height;
  out.channels = 3;
  const std::size_t n =
      static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
  out.pixels.resize(3 * n);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < 3; ++c) {
      const float v = std::clamp(image.rgba[4 * i + c], 0.0f, 1.0f);
      out.pixels[3 * i + c] = static_cast<std::uint8_t>(std::lround(v * 255.0f));
    }
  return out;
}

void write_png(const std::filesystem::path& path, const RgbaImage& image) {
  image::write_png(path, to_image(image));
}

double max_abs_difference(const RgbaImage& a, const RgbaImage& b) {
  if (a.width != b.width || a.height != b.height || a.rgba.size() != b.rgba.size())
    return std::numeric_limits<double>::infinity();
  double m = 0;
  for (std::size_t i = 0; i < a.rgba.size(); ++i)
    m = std::max(m, std::abs(double(a.rgba[i]) - double(b.rgba[i])));
  return m;
}

}  // namespace volreel::cpu_render
