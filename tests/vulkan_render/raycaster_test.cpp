// raycaster_test.cpp: the Vulkan ray caster against the CPU reference renderer
// (cpu_render::render_svo) on a small ksvd-coded scene of two frames and four octree levels:
// fully loaded states with B from an ancestor d = 0..3 levels up and factors 0, 0.5, 1, with the
// atlas filled from CPU-decoded bricks and decoded on the GPU (vulkan::AtlasDecoder) from the same
// payloads; the step from the leaf's level (coarse leaves next to fine ones) as the CPU takes it;
// transfer-function culling leaves the image unchanged; frames in flight; bad input rejected; the
// streaming frame loop end to end on a container on disk.
//
// Image agreement is measured on the 8-bit RGB images both write (cpu_render::to_image):
// PSNR = 10·log10(255²/MSE) over all channels and the mean per-channel SSIM (psnr::compare_images).
// The two renderers take the same samples (coarse steps included: both step by the leaf's level,
// RenderOptions::max_step_doublings = 3 by default); they differ by the atlas's 16-bit storage,
// the GPU's fixed-point filter weights and float rounding where a coarse step ends at a region.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

#include "../blobs_container.hpp"
#include "../cpu_render/svo_builder.hpp"
#include "../dictionary_test_data.hpp"
#include "../keyframe_series.hpp"
#include "../test_util.hpp"
#include "../vulkan/vulkan_test_util.hpp"
#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/atlas_decoder.hpp"
#include "volreel/vulkan_render/raycaster.hpp"
#include "volreel/vulkan_render/vulkan_frame_loop.hpp"

namespace volreel {
namespace {

using cpu_render::CpuAtlas;
using cpu_render::RgbaImage;
using cpu_render::TransferFunction;
using cpu_render::VolumeGeometry;
using test::build_uniform_svo;
using test::LeafSpec;
using test::random_dictionary;
using vulkan_render::FrameInput;
using vulkan_render::OutputFormat;
using vulkan_render::Raycaster;
using vulkan_render::RaycasterOptions;
using Coord = std::array<std::uint32_t, 3>;

constexpr double min_psnr = 40.0, min_ssim = 0.98;

// --- The scene: two frames of an analytic field, ksvd-coded, every brick decoded ------------

struct Scene {
  std::array<std::uint32_t, 3> dims{};
  VolumeGeometry geometry;
  std::vector<format::LevelGeometry> levels;
  dictionary::Dictionary dictionary;
  std::array<std::vector<std::byte>, 2> bytes;
  std::array<format::FrameView, 2> views;
  std::vector<std::uint32_t> level_first;
  std::uint32_t bricks_per_frame = 0;
  float lo = 0, hi = 0;            // range of the decoded values
  float data_lo = 0, data_hi = 0;  // range of the original values (histogram bins)
  std::unique_ptr<CpuAtlas> cpu_atlas;

  format::AtomTable atoms() const {
    return {{dictionary.atoms.data(), static_cast<std::size_t>(dictionary.atoms.size())},
            static_cast<std::uint32_t>(dictionary.atom_count())};
  }
  std::uint32_t slot(std::size_t frame, std::uint32_t level, Coord c) const {
    const auto& g = levels[level].grid;
    return static_cast<std::uint32_t>(frame) * bricks_per_frame + level_first[level] +
           (c[2] * g[1] + c[1]) * g[0] + c[0];
  }
  std::uint32_t slot_count() const { return 2 * bricks_per_frame; }
  /// Calls f(frame, level, c, payload) for every brick of both frames.
  template <class F>
  void for_each_brick(F f) const {
    for (std::size_t t = 0; t < 2; ++t)
      for (std::uint32_t i = 0; i < views[t].node_count(); ++i) {
        const format::Node node = views[t].node(i);
        if (node.brick == format::no_brick) continue;
        const auto& p = views[t].position(i);
        f(t, p.level, Coord{p.x, p.y, p.z}, views[t].brick_bytes(node.brick));
      }
  }
};

/// 240 × 40 × 30 in bricks of `shape` (36³: grids 8×2×1 → 4×1×1 → 2×1×1 → 1, four levels, 23
/// bricks per frame).
std::unique_ptr<Scene> make_scene(format::BrickShape shape) {
  {
    auto s = std::make_unique<Scene>();
    s->dims = {240, 40, 30};
    s->geometry = VolumeGeometry::of(s->dims, shape);
    s->levels = format::level_geometry(s->dims, shape);
    for (const auto& l : s->levels) {
      s->level_first.push_back(s->bricks_per_frame);
      s->bricks_per_frame += l.grid[0] * l.grid[1] * l.grid[2];
    }
    datasets::AnalyticParams p;
    p.field = datasets::AnalyticField::blobs;
    p.dims = {240, 40, 30};
    p.frames = 8;
    std::array<Volume, 2> frames;
    s->data_lo = INFINITY;
    s->data_hi = -INFINITY;
    for (std::size_t t = 0; t < 2; ++t) {
      frames[t] = Volume(p.dims);
      datasets::analytic_frame(p, 3 * t, frames[t].data);  // frames 0 and 3
      for (float v : frames[t].data) {
        s->data_lo = std::min(s->data_lo, v);
        s->data_hi = std::max(s->data_hi, v);
      }
    }
    s->dictionary = random_dictionary(256, 7);
    encoder::CodingSettings coding;
    coding.brick_size = shape.size;
    coding.tolerance = 0.01 * double(s->data_hi - s->data_lo);
    coding.value_min = s->data_lo;
    coding.value_max = s->data_hi;
    const encoder::FrameEncoder frame_encoder(&s->dictionary, coding);
    for (std::size_t t = 0; t < 2; ++t) {
      s->bytes[t] = frame_encoder.encode(t, frames[t]);
      s->views[t] = format::FrameView(s->bytes[t], "frame" + std::to_string(t));
    }
    s->cpu_atlas = std::make_unique<CpuAtlas>(s->slot_count(), shape);
    std::size_t bricks = 0;
    s->for_each_brick([&](std::size_t t, std::uint32_t l, Coord c, std::span<const std::byte> b) {
      s->cpu_atlas->decode_into(s->slot(t, l, c), b, format::Codec::ksvd, 0, s->atoms());
      ++bricks;
    });
    if (bricks != s->slot_count()) throw std::logic_error("the test scene lost a brick");
    s->lo = INFINITY;
    s->hi = -INFINITY;
    for (std::uint32_t slot = 0; slot < s->slot_count(); ++slot)
      for (float v : s->cpu_atlas->slot(slot)) {
        s->lo = std::min(s->lo, v);
        s->hi = std::max(s->hi, v);
      }
    return s;
  }
}

const Scene& scene() {
  static const std::unique_ptr<Scene> made = make_scene({});
  return *made;
}

/// Every value visible, colour and opacity changing across the range.
TransferFunction test_transfer(const Scene& s) {
  const float mid = 0.5f * (s.data_lo + s.data_hi);
  return TransferFunction({{s.data_lo, 0.1f, 0.2f, 1.0f, 0.01f},
                           {mid, 0.1f, 0.9f, 0.3f, 0.04f},
                           {s.data_hi, 1.0f, 0.2f, 0.1f, 0.12f}},
                          s.data_lo, s.data_hi);
}

player::OrbitCamera test_camera(int width = 96, int height = 64) {
  auto camera = player::OrbitCamera::framing({240, 40, 30}, width, height);
  camera.distance *= 0.6;  // the volume fills the image
  return camera;
}

double drawn_fraction(const RgbaImage& image) {
  std::size_t drawn = 0;
  for (std::size_t i = 3; i < image.rgba.size(); i += 4) drawn += image.rgba[i] > 0.05f ? 1u : 0u;
  return double(drawn) / double(image.rgba.size() / 4);
}

psnr::ImageComparison compare(const RgbaImage& a, const RgbaImage& b) {
  return psnr::compare_images(cpu_render::to_image(a), cpu_render::to_image(b));
}

/// Copies the CPU atlas's slots into the GPU atlas (16-bit unorm over the atlas's range).
void upload_cpu_atlas(vulkan::Context& context, const vulkan::Atlas& atlas, const CpuAtlas& cpu) {
  const std::size_t voxels = cpu.slot_values();
  const vulkan::Buffer staging(
      context, cpu.slot_count() * voxels * 2, VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
      VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  auto* texels = reinterpret_cast<std::uint16_t*>(staging.mapped());
  const float lo = atlas.value_min(), range = atlas.value_max() - atlas.value_min();
  std::vector<VkBufferImageCopy> regions;
  for (std::uint32_t s = 0; s < cpu.slot_count(); ++s) {
    const auto values = cpu.slot(s);
    for (std::size_t i = 0; i < voxels; ++i) {
      const float n = std::clamp((values[i] - lo) / range, 0.0f, 1.0f);
      texels[s * voxels + i] = static_cast<std::uint16_t>(std::lround(n * 65535.0f));
    }
    VkBufferImageCopy r{};
    r.bufferOffset = s * voxels * 2;
    r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    r.imageOffset = atlas.slot_origin(s);
    r.imageExtent = {atlas.slot_size(), atlas.slot_size(), atlas.slot_size()};
    regions.push_back(r);
  }
  context.submit_and_wait([&](VkCommandBuffer cb) {
    const VkImage image = atlas.image().handle();
    vulkan::image_barrier(cb, image, VK_IMAGE_LAYOUT_GENERAL, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
    vkCmdCopyBufferToImage(cb, staging.handle(), image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                           static_cast<std::uint32_t>(regions.size()), regions.data());
    vulkan::image_barrier(cb, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_GENERAL,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                          VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT);
  });
}

/// Both GPU atlases of the scene (CPU-decoded and GPU-decoded), made once per test run.
struct GpuScene {
  std::unique_ptr<vulkan::Atlas> from_cpu, from_gpu;
};

vulkan::AtlasOptions atlas_options(const Scene& s) {
  vulkan::AtlasOptions o;
  const float margin = 0.01f * (s.hi - s.lo);
  o.value_min = s.lo - margin;
  o.value_max = s.hi + margin;
  o.slot_size = s.geometry.shape.size;
  // A 4×4×4 grid of slots, more than the scene of 36³ bricks needs; at least the scene's slots.
  o.memory_budget_bytes =
      std::uint64_t{std::max(64u, s.slot_count())} * 2 * s.geometry.shape.voxels();
  return o;
}

GpuScene& gpu_scene_storage() {
  static GpuScene g;
  return g;
}

/// Releases the scene's atlases before the shared context goes (environments are torn down in
/// the reverse order of registration), so that leak checkers see everything released.
class GpuSceneEnvironment : public ::testing::Environment {
 public:
  void TearDown() override {
    gpu_scene_storage().from_cpu.reset();
    gpu_scene_storage().from_gpu.reset();
  }
};
[[maybe_unused]] ::testing::Environment* const vulkan_environment =
    ::testing::AddGlobalTestEnvironment(new test::VulkanEnvironment);
[[maybe_unused]] ::testing::Environment* const scene_environment =
    ::testing::AddGlobalTestEnvironment(new GpuSceneEnvironment);

GpuScene& gpu_scene(vulkan::Context& context) {
  GpuScene& g = gpu_scene_storage();
  if (g.from_cpu) return g;
  const Scene& s = scene();
  g.from_cpu = std::make_unique<vulkan::Atlas>(context, atlas_options(s));
  g.from_gpu = std::make_unique<vulkan::Atlas>(context, atlas_options(s));
  if (g.from_cpu->slot_count() < s.slot_count())
    throw std::logic_error("the test atlas has " + std::to_string(g.from_cpu->slot_count()) +
                           " slots, the scene " + std::to_string(s.slot_count()));
  upload_cpu_atlas(context, *g.from_cpu, *s.cpu_atlas);
  vulkan::AtlasDecoder decoder(context, *g.from_gpu);
  decoder.set_dictionary(s.atoms());
  std::vector<vulkan::BrickUpload> batch;
  s.for_each_brick([&](std::size_t t, std::uint32_t l, Coord c, std::span<const std::byte> b) {
    batch.push_back({b, format::Codec::ksvd, 0, s.slot(t, l, c)});
  });
  decoder.wait(decoder.submit(batch));
  return g;
}

FrameInput frame_input(const Scene& s, const test::BuiltSvo& svo, const TransferFunction& tf,
                       const player::OrbitCamera& camera) {
  FrameInput in;
  in.svo_nodes = svo.nodes;
  in.svo_leaves = svo.leaves;
  in.geometry = s.geometry;
  in.camera = camera;
  in.transfer = &tf;
  in.histogram_range = {s.data_lo, s.data_hi};
  return in;
}

RgbaImage render_gpu(vulkan::Context& context, const vulkan::Atlas& atlas, const FrameInput& in,
                     OutputFormat format = OutputFormat::rgba16_sfloat,
                     vulkan_render::AtlasFilter filter = vulkan_render::AtlasFilter::automatic) {
  RaycasterOptions o;
  o.width = in.camera.width;
  o.height = in.camera.height;
  o.output = format;
  o.filter = filter;
  Raycaster raycaster(context, atlas, o);
  return raycaster.read_back(raycaster.render(in, true));
}

class VulkanRender : public test::VulkanTest {};

// --- Fully loaded: every finest node drawn, B from an ancestor d levels up, factor f ------------

struct Case {
  std::uint32_t d;
  float f;
};

class FullyLoaded : public test::VulkanTest, public ::testing::WithParamInterface<Case> {};

TEST_P(FullyLoaded, MatchesTheCpuReferenceRenderer) {
  const Scene& s = scene();
  const auto [d, f] = GetParam();
  const std::uint32_t finest = s.geometry.levels - 1;
  ASSERT_GE(s.geometry.levels, 4u);
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l - d, {c[0] >> d, c[1] >> d, c[2] >> d}), 0, d, f};
  });
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  const RgbaImage want =
      cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf);
  ASSERT_GT(drawn_fraction(want), 0.15);
  GpuScene& g = gpu_scene(context());
  const FrameInput in = frame_input(s, svo, tf, camera);
  for (const vulkan::Atlas* atlas : {g.from_cpu.get(), g.from_gpu.get()})
    for (const auto filter :
         {vulkan_render::AtlasFilter::sampler, vulkan_render::AtlasFilter::fetch}) {
      const std::string which =
          std::string(atlas == g.from_cpu.get() ? "CPU-decoded atlas" : "GPU-decoded atlas") +
          (filter == vulkan_render::AtlasFilter::sampler ? ", sampler" : ", fetches");
      const RgbaImage got = render_gpu(context(), *atlas, in, OutputFormat::rgba16_sfloat, filter);
      const psnr::ImageComparison c = compare(got, want);
      std::printf("  d %u f %.1f, %s: PSNR %.1f dB, SSIM %.4f, max |diff| %.4f\n", d, double(f),
                  which.c_str(), c.psnr, c.ssim, cpu_render::max_abs_difference(got, want));
      EXPECT_GE(c.psnr, min_psnr) << which;
      EXPECT_GE(c.ssim, min_ssim) << which;
      // Stricter, on the float images: 16-bit atlas storage and half-float output only (a
      // half-texel offset or a wrong LOD mapping moves colours by far more). Filter hardware
      // rounds its weights (8 bits is common), so the sampler gets more room.
      EXPECT_LE(cpu_render::max_abs_difference(got, want),
                filter == vulkan_render::AtlasFilter::fetch ? 3e-3 : 1e-2)
          << which;
    }
}

// Bricks of 24³ (five levels) and 66³ (three): the ray caster's specialization constant and the
// decoder's, against the CPU reference renderer on atlases decoded on the CPU and on the GPU.
TEST_F(VulkanRender, OtherBrickSizesMatchTheCpuReferenceRenderer) {
  for (const std::uint32_t size : {24u, 66u}) {
    SCOPED_TRACE("bricks of " + std::to_string(size) + "^3");
    const std::unique_ptr<Scene> made = make_scene({size});
    const Scene& s = *made;
    ASSERT_EQ(s.geometry.levels, size == 24 ? 5u : 3u);
    const std::uint32_t finest = s.geometry.levels - 1, d = 1;
    const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l - d, {c[0] >> d, c[1] >> d, c[2] >> d}), 0, d,
                      0.5f};
    });
    const TransferFunction tf = test_transfer(s);
    const auto camera = test_camera();
    const RgbaImage want =
        cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf);
    ASSERT_GT(drawn_fraction(want), 0.15);
    vulkan::Atlas from_cpu(context(), atlas_options(s)), from_gpu(context(), atlas_options(s));
    ASSERT_GE(from_cpu.slot_count(), s.slot_count());
    upload_cpu_atlas(context(), from_cpu, *s.cpu_atlas);
    {
      vulkan::AtlasDecoder decoder(context(), from_gpu);
      decoder.set_dictionary(s.atoms());
      std::vector<vulkan::BrickUpload> batch;
      s.for_each_brick([&](std::size_t t, std::uint32_t l, Coord c, std::span<const std::byte> b) {
        batch.push_back({b, format::Codec::ksvd, 0, s.slot(t, l, c)});
      });
      decoder.wait(decoder.submit(batch));
    }
    const FrameInput in = frame_input(s, svo, tf, camera);
    for (const vulkan::Atlas* atlas : {&from_cpu, &from_gpu}) {
      const RgbaImage got = render_gpu(context(), *atlas, in, OutputFormat::rgba16_sfloat,
                                       vulkan_render::AtlasFilter::fetch);
      const psnr::ImageComparison c = compare(got, want);
      std::printf("  bricks of %u^3, %s atlas: PSNR %.1f dB, max |diff| %.4f\n", size,
                  atlas == &from_cpu ? "CPU-decoded" : "GPU-decoded", c.psnr,
                  cpu_render::max_abs_difference(got, want));
      EXPECT_GE(c.psnr, min_psnr);
      EXPECT_LE(cpu_render::max_abs_difference(got, want), 3e-3);
    }
    // An atlas of another slot size is refused.
    EXPECT_THROW(render_gpu(context(), *gpu_scene(context()).from_cpu, in), std::invalid_argument);
  }
}

INSTANTIATE_TEST_SUITE_P(LodDifferenceAndFactor, FullyLoaded,
                         ::testing::Values(Case{0, 0.0f}, Case{0, 0.5f}, Case{0, 1.0f},
                                           Case{1, 0.0f}, Case{1, 0.5f}, Case{1, 1.0f},
                                           Case{2, 0.0f}, Case{2, 0.5f}, Case{2, 1.0f},
                                           Case{3, 0.0f}, Case{3, 0.5f}, Case{3, 1.0f}),
                         [](const ::testing::TestParamInfo<Case>& param) {
                           return "d" + std::to_string(param.param.d) + "_f" +
                                  std::to_string(static_cast<int>(param.param.f * 10));
                         });

// --- Ray-guided feedback: the table the CPU ray caster writes ------------------------------------

TEST_F(VulkanRender, FeedbackTableMatchesTheCpuRenderers) {
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto camera = test_camera();
  // A translucent transfer function (every region a ray crosses is sampled) and an opaque one
  // (rays end in the first bright region, so regions behind it stay 0).
  const float mid = 0.5f * (s.data_lo + s.data_hi);
  const TransferFunction translucent = test_transfer(s);
  const TransferFunction opaque({{s.data_lo, 0.2f, 0.4f, 1.0f, 0.0f},
                                 {mid, 0.2f, 0.4f, 1.0f, 1.0f},
                                 {s.data_hi, 1.0f, 0.3f, 0.1f, 1.0f}},
                                s.data_lo, s.data_hi);
  // Leaf children at the finest level (entries 1, or 2 for B one level up), and a level above
  // drawn through "up" octants (one entry per octant, 2: the octant's child is one level finer).
  const auto finest_leaves = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l - 1, {c[0] >> 1, c[1] >> 1, c[2] >> 1}), 0, 1,
                    (c[0] + c[1]) % 2 == 0 ? 1.0f : 0.0f};
  });
  const auto up_octants = build_uniform_svo(
      s.levels, finest - 1,
      [&](std::uint32_t l, Coord c) {
        return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
      },
      true);
  GpuScene& g = gpu_scene(context());
  for (const test::BuiltSvo* svo : {&finest_leaves, &up_octants})
    for (const TransferFunction* tf : {&translucent, &opaque}) {
      const std::string which =
          std::string(svo == &finest_leaves ? "leaf children" : "up octants") +
          (tf == &translucent ? ", translucent" : ", opaque");
      std::vector<std::uint32_t> want;
      cpu_render::render_svo({svo->nodes, svo->leaves}, *s.cpu_atlas, s.geometry, camera, *tf, {},
                             &want);
      FrameInput in = frame_input(s, *svo, *tf, camera);
      in.feedback = true;
      RaycasterOptions o;
      o.width = camera.width;
      o.height = camera.height;
      o.frames_in_flight = 1;  // the second frame reuses the first one's table
      Raycaster raycaster(context(), *g.from_cpu, o);
      const vulkan_render::Ticket ticket = raycaster.render(in);
      const std::vector<std::uint32_t> got = raycaster.feedback(ticket);
      ASSERT_EQ(got.size(), want.size()) << which;
      std::size_t sampled = 0, unsampled = 0, differ = 0;
      for (std::size_t i = 0; i < want.size(); ++i) {
        (want[i] != 0 ? sampled : unsampled) += std::size_t{1};
        differ += got[i] != want[i] ? std::size_t{1} : std::size_t{0};
      }
      std::printf("  %s: %zu regions sampled, %zu not, %zu entries differ\n", which.c_str(),
                  sampled, unsampled, differ);
      EXPECT_GT(sampled, 8u) << which;
      // Both LOD differences occur (f = 1 reads B one level up: 2; f = 0: 1; an up octant: 2).
      EXPECT_NE(std::count(want.begin(), want.end(), 2u), 0) << which;
      if (svo == &finest_leaves) {
        EXPECT_NE(std::count(want.begin(), want.end(), 1u), 0) << which;
      }
      // Float and double place a ray's first sample in a region differently only at grazing
      // edges.
      EXPECT_LE(differ, sampled / 50 + 1) << which;
      // A second frame clears the table first: the same values again.
      const vulkan_render::Ticket again = raycaster.render(in);
      EXPECT_EQ(raycaster.feedback(again), got) << which;
    }
  // A frame rendered without feedback has no table.
  FrameInput in = frame_input(s, finest_leaves, opaque, camera);
  RaycasterOptions o;
  o.width = camera.width;
  o.height = camera.height;
  Raycaster raycaster(context(), *g.from_cpu, o);
  EXPECT_THROW(raycaster.feedback(raycaster.render(in)), std::invalid_argument);
}

// --- Level-of-detail blending: corner weights mix in the parent's drawing ----------------------

TEST_F(VulkanRender, LodBlendingMatchesTheCpuReferenceRenderer) {
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  // Every finest node drawn from frames 0 and 1 halfway, its coarse pair the parent's bricks
  // (frame 0, and frame 1's grandparent at a factor 0.25), with corner weights that differ by
  // corner and by node (some all 255: those leaves do not blend).
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    LeafSpec spec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
    spec.slot_c = s.slot(0, l - 1, {c[0] >> 1, c[1] >> 1, c[2] >> 1});
    spec.slot_d = s.slot(1, l - 2, {c[0] >> 2, c[1] >> 2, c[2] >> 2});
    spec.d_c = 1;
    spec.d_d = 2;
    spec.coarse_factor = 0.25f;
    const std::uint32_t k = c[0] + 3 * c[1] + 5 * c[2];
    if (k % 4 != 3)
      for (std::uint32_t i = 0; i < 8; ++i)
        spec.corners[i] = static_cast<std::uint8_t>((37 * (i + k)) % 256);
    return spec;
  });
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  const RgbaImage want =
      cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf);
  ASSERT_GT(drawn_fraction(want), 0.15);
  // The blend is seen: without it the image differs.
  const auto plain = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  EXPECT_GT(cpu_render::max_abs_difference(
                want, cpu_render::render_svo({plain.nodes, plain.leaves}, *s.cpu_atlas, s.geometry,
                                             camera, tf)),
            0.02);
  GpuScene& g = gpu_scene(context());
  const FrameInput in = frame_input(s, svo, tf, camera);
  for (const auto filter :
       {vulkan_render::AtlasFilter::sampler, vulkan_render::AtlasFilter::fetch}) {
    const RgbaImage got =
        render_gpu(context(), *g.from_cpu, in, OutputFormat::rgba16_sfloat, filter);
    const psnr::ImageComparison c = compare(got, want);
    std::printf("  blended, %s: PSNR %.1f dB, max |diff| %.4f\n",
                filter == vulkan_render::AtlasFilter::sampler ? "sampler" : "fetches", c.psnr,
                cpu_render::max_abs_difference(got, want));
    EXPECT_GE(c.psnr, min_psnr);
    EXPECT_GE(c.ssim, min_ssim);
    EXPECT_LE(cpu_render::max_abs_difference(got, want),
              filter == vulkan_render::AtlasFilter::fetch ? 3e-3 : 1e-2);
  }
}

TEST_F(VulkanRender, LodDifferenceAndFactorChangeTheImage) {
  // The cases above differ from each other: a shader that ignored d or f would fail them.
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  GpuScene& g = gpu_scene(context());
  const auto render = [&](std::uint32_t d, float f) {
    const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l - d, {c[0] >> d, c[1] >> d, c[2] >> d}), 0, d,
                      f};
    });
    return render_gpu(context(), *g.from_gpu, frame_input(s, svo, tf, camera));
  };
  const RgbaImage a = render(0, 0), m = render(0, 0.5f), b = render(0, 1), b3 = render(3, 1);
  EXPECT_GT(cpu_render::max_abs_difference(a, m), 0.05);
  EXPECT_GT(cpu_render::max_abs_difference(m, b), 0.05);
  EXPECT_GT(cpu_render::max_abs_difference(b, b3), 0.02);
}

TEST_F(VulkanRender, NodesDrawnAtEveryLevelThroughUpChildren) {
  // Coarser trees, and the same pictures reached through "up" children (word 9).
  const Scene& s = scene();
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera(64, 64);
  GpuScene& g = gpu_scene(context());
  for (std::uint32_t level = 0; level < s.geometry.levels; ++level)
    for (bool up : {false, true}) {
      const auto svo = build_uniform_svo(
          s.levels, level,
          [&](std::uint32_t l, Coord c) {
            return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
          },
          up);
      const RgbaImage want =
          cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf);
      const RgbaImage got = render_gpu(context(), *g.from_gpu, frame_input(s, svo, tf, camera));
      const psnr::ImageComparison c = compare(got, want);
      EXPECT_GE(c.psnr, min_psnr) << "level " << level << (up ? " (up)" : "");
      EXPECT_GE(c.ssim, min_ssim) << "level " << level << (up ? " (up)" : "");
    }
}

TEST_F(VulkanRender, EmptyChildrenAndRgba8Output) {
  // Only octant 0 of the root drawn; 8-bit output equals the CPU image rounded to 8 bits.
  const Scene& s = scene();
  auto svo = build_uniform_svo(s.levels, 1, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.0f};
  });
  for (vr_uint o = 1; o < 8; ++o) svo.nodes[1 + o] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  cpu_render::RenderOptions options;
  options.background = {0.2f, 0.3f, 0.4f};
  const RgbaImage want = cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry,
                                                camera, tf, options);
  FrameInput in = frame_input(s, svo, tf, camera);
  in.options = options;
  const RgbaImage got =
      render_gpu(context(), *gpu_scene(context()).from_gpu, in, OutputFormat::rgba8_unorm);
  const psnr::ImageComparison c = compare(got, want);
  EXPECT_GE(c.psnr, min_psnr);
  EXPECT_GE(c.ssim, min_ssim);
  EXPECT_EQ(got.pixel(95, 0)[0], std::round(0.2f * 255) / 255);  // background
}

TEST_F(VulkanRender, StepFromTheLeafLevelMatchesTheCpuRenderer) {
  // Finest leaves on a 3D checkerboard: half read both keyframes 3 levels up (steps 8x the base
  // step), half their own bricks (the base step), so coarse steps end at fine regions all along
  // the rays. The GPU takes the CPU's samples: it is closer to the CPU's coarse-step image than
  // the CPU's fixed-step image is, and its own fixed-step image differs.
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  ASSERT_GE(finest, 3u);
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    if ((c[0] + c[1] + c[2]) % 2 == 1)
      return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
    const Coord up = {c[0] >> 3, c[1] >> 3, c[2] >> 3};
    return LeafSpec{s.slot(0, l - 3, up), s.slot(1, l - 3, up), 3, 3, 0.5f};
  });
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  cpu_render::RenderOptions fixed;
  fixed.max_step_doublings = 0;
  const RgbaImage want =
      cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf);
  const RgbaImage want_fixed =
      cpu_render::render_svo({svo.nodes, svo.leaves}, *s.cpu_atlas, s.geometry, camera, tf, fixed);
  ASSERT_GT(drawn_fraction(want), 0.15);
  ASSERT_LT(double(want.samples), 0.8 * double(want_fixed.samples));
  const vulkan::Atlas& atlas = *gpu_scene(context()).from_gpu;
  FrameInput in = frame_input(s, svo, tf, camera);
  for (const auto filter :
       {vulkan_render::AtlasFilter::sampler, vulkan_render::AtlasFilter::fetch}) {
    const char* which = filter == vulkan_render::AtlasFilter::fetch ? "fetches" : "sampler";
    in.options = {};
    const RgbaImage got = render_gpu(context(), atlas, in, OutputFormat::rgba16_sfloat, filter);
    in.options = fixed;
    const RgbaImage got_fixed =
        render_gpu(context(), atlas, in, OutputFormat::rgba16_sfloat, filter);
    const psnr::ImageComparison c = compare(got, want), c_fixed = compare(got, want_fixed);
    std::printf(
        "  %s: PSNR %.1f dB, SSIM %.4f, max |diff| %.4f against the CPU's coarse steps; "
        "%.1f dB against its fixed step; GPU coarse vs fixed max |diff| %.4f\n",
        which, c.psnr, c.ssim, cpu_render::max_abs_difference(got, want), c_fixed.psnr,
        cpu_render::max_abs_difference(got, got_fixed));
    EXPECT_GE(c.psnr, min_psnr) << which;
    EXPECT_GE(c.ssim, min_ssim) << which;
    EXPECT_LE(cpu_render::max_abs_difference(got, want),
              filter == vulkan_render::AtlasFilter::fetch ? 3e-3 : 1e-2)
        << which;
    EXPECT_GT(c.psnr, c_fixed.psnr + 3.0) << which;
    EXPECT_GE(compare(got_fixed, want_fixed).psnr, min_psnr) << which;
    EXPECT_GT(cpu_render::max_abs_difference(got, got_fixed), 1e-3) << which;
  }
}

// --- Transfer-function culling ------------------------------------------------------------

TEST_F(VulkanRender, TransferFunctionCullingKeepsTheImage) {
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l - 1, {c[0] >> 1, c[1] >> 1, c[2] >> 1}), 0, 1,
                    0.5f};
  });
  // Values below 40 % of the range are invisible.
  const float cut = s.data_lo + 0.4f * (s.data_hi - s.data_lo);
  const TransferFunction tf(
      {{s.data_lo, 0, 0, 0, 0}, {cut, 0.2f, 0.5f, 1.0f, 0.0f}, {s.data_hi, 1.0f, 0.8f, 0.2f, 1.0f}},
      s.data_lo, s.data_hi);
  // Each slot's histogram from its decoded values (apron included: the hull holds every value
  // trilinear filtering can produce there), 64 bins over the data range.
  std::vector<std::uint64_t> slot_histograms(s.slot_count(), 0);
  for (std::uint32_t slot = 0; slot < s.slot_count(); ++slot)
    for (float v : s.cpu_atlas->slot(slot))
      slot_histograms[slot] |= std::uint64_t{1} << format::histogram_bin(v, s.data_lo, s.data_hi);
  std::vector<std::uint64_t> leaf_histograms;
  vulkan_render::leaf_histograms(svo.leaves, slot_histograms, leaf_histograms);
  const std::uint64_t visible = tf.visible_bins(s.data_lo, s.data_hi);
  std::size_t culled = 0;
  for (std::uint64_t h : leaf_histograms) {
    const int lo = std::countr_zero(h), hi = 63 - std::countl_zero(h);
    const std::uint64_t hull = (~std::uint64_t{0} << lo) & (~std::uint64_t{0} >> (63 - hi));
    culled += (hull & visible) == 0 ? 1u : 0u;
  }
  std::printf("  %zu of %zu leaves culled\n", culled, leaf_histograms.size());
  EXPECT_GT(culled, 0u) << "the test culls nothing";
  EXPECT_LT(culled, leaf_histograms.size()) << "the test culls everything";

  const auto camera = test_camera();
  FrameInput in = frame_input(s, svo, tf, camera);
  const vulkan::Atlas& atlas = *gpu_scene(context()).from_gpu;
  const RgbaImage plain = render_gpu(context(), atlas, in);
  in.leaf_histograms = leaf_histograms;
  const RgbaImage culling = render_gpu(context(), atlas, in);
  std::printf("  %.1f %% of the pixels drawn\n", 100 * drawn_fraction(plain));
  EXPECT_GT(drawn_fraction(plain), 0.01);
  EXPECT_EQ(cpu_render::max_abs_difference(plain, culling), 0.0);
  // Block skipping too (every slot's block ranges computed first), with either filter.
  std::vector<std::uint32_t> all_slots(s.slot_count());
  for (std::uint32_t i = 0; i < s.slot_count(); ++i) all_slots[i] = i;
  in.changed_slots = all_slots;
  in.skip_invisible_blocks = true;
  for (const auto filter :
       {vulkan_render::AtlasFilter::sampler, vulkan_render::AtlasFilter::fetch}) {
    FrameInput without = in;
    without.changed_slots = {};
    without.skip_invisible_blocks = false;
    const RgbaImage reference =
        render_gpu(context(), atlas, without, OutputFormat::rgba16_sfloat, filter);
    const RgbaImage blocks = render_gpu(context(), atlas, in, OutputFormat::rgba16_sfloat, filter);
    EXPECT_EQ(cpu_render::max_abs_difference(reference, blocks), 0.0)
        << (filter == vulkan_render::AtlasFilter::fetch ? "fetches" : "sampler");
  }
  in.changed_slots = {};
  in.skip_invisible_blocks = false;
  // Everything culled: a histogram in an invisible bin only gives the background.
  std::vector<std::uint64_t> all_low(leaf_histograms.size(), 1);
  in.leaf_histograms = all_low;
  const RgbaImage none = render_gpu(context(), atlas, in);
  EXPECT_EQ(drawn_fraction(none), 0.0);
  // The culled leaves count as reached in the feedback table, as in the CPU ray caster.
  for (const std::vector<std::uint64_t>* h : {&leaf_histograms, &all_low}) {
    in.leaf_histograms = *h;
    in.feedback = true;
    RaycasterOptions o;
    o.width = camera.width;
    o.height = camera.height;
    Raycaster raycaster(context(), atlas, o);
    const std::vector<std::uint32_t> got = raycaster.feedback(raycaster.render(in));
    std::vector<vr_uint> words;
    for (const std::uint64_t w : *h) {
      words.push_back(static_cast<vr_uint>(w));
      words.push_back(static_cast<vr_uint>(w >> 32));
    }
    cpu_render::SvoView view{svo.nodes, svo.leaves, words, {s.data_lo, s.data_hi}};
    std::vector<std::uint32_t> want;
    cpu_render::render_svo(view, *s.cpu_atlas, s.geometry, camera, tf, {}, &want);
    const auto reached = std::count_if(want.begin(), want.end(), [](auto v) { return v != 0; });
    EXPECT_GT(reached, 8) << (h == &all_low ? "all culled" : "some culled");
    std::size_t differ = 0;
    for (std::size_t i = 0; i < want.size() && i < got.size(); ++i)
      differ += got[i] != want[i] ? 1u : 0u;
    EXPECT_EQ(got.size(), want.size());
    EXPECT_LE(differ, std::size_t(reached) / 50 + 1)
        << (h == &all_low ? "all culled" : "some culled");
  }
}

// --- Frames in flight, bad input ----------------------------------------------------------

TEST_F(VulkanRender, FramesInFlightKeepTheirOwnBuffers) {
  const Scene& s = scene();
  const std::uint32_t finest = s.geometry.levels - 1;
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera();
  const vulkan::Atlas& atlas = *gpu_scene(context()).from_gpu;
  std::vector<test::BuiltSvo> svos;
  for (float f : {0.0f, 0.5f, 1.0f})
    svos.push_back(build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, f};
    }));
  RaycasterOptions o;
  o.width = camera.width;
  o.height = camera.height;
  o.frames_in_flight = 3;
  Raycaster raycaster(context(), atlas, o);
  std::vector<vulkan_render::Ticket> tickets;
  for (const auto& svo : svos)
    tickets.push_back(raycaster.render(frame_input(s, svo, tf, camera), true));
  EXPECT_EQ(tickets, (std::vector<vulkan_render::Ticket>{1, 2, 3}));
  for (std::size_t i = 0; i < svos.size(); ++i) {
    const RgbaImage alone = render_gpu(context(), atlas, frame_input(s, svos[i], tf, camera),
                                       OutputFormat::rgba8_unorm);
    EXPECT_EQ(cpu_render::max_abs_difference(raycaster.read_back(tickets[i]), alone), 0.0)
        << "frame " << i;
  }
  const auto ms = raycaster.gpu_milliseconds(tickets.back());
  if (ms) {
    EXPECT_GE(*ms, 0.0);
  }
  // A fourth frame reuses the first entry: frame 1 can no longer be read.
  tickets.push_back(raycaster.render(frame_input(s, svos[0], tf, camera)));
  EXPECT_TRUE(raycaster.poll(1));
  EXPECT_THROW(raycaster.read_back(1), std::invalid_argument);
  EXPECT_THROW(raycaster.read_back(tickets.back()), std::invalid_argument);  // no readback
  raycaster.wait_all();
  // Resizing keeps working.
  raycaster.resize(32, 24);
  const auto small = test_camera(32, 24);
  const RgbaImage image =
      raycaster.read_back(raycaster.render(frame_input(s, svos[1], tf, small), true));
  EXPECT_EQ(image.width, 32);
  EXPECT_EQ(image.height, 24);
}

TEST_F(VulkanRender, RejectsBadInput) {
  const Scene& s = scene();
  const TransferFunction tf = test_transfer(s);
  const auto camera = test_camera(16, 16);
  const auto good = build_uniform_svo(s.levels, 1, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  RaycasterOptions o;
  o.width = 16;
  o.height = 16;
  Raycaster raycaster(context(), *gpu_scene(context()).from_gpu, o);
  const auto rejects = [&](const FrameInput& in, const char* needle) {
    try {
      raycaster.render(in);
      ADD_FAILURE() << "accepted input with " << needle;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  auto bad_slot = good;
  bad_slot.leaves[0] = 999;
  rejects(frame_input(s, bad_slot, tf, camera), "slot");
  auto bad_node = good;
  bad_node.nodes[1] = vr_svo_child_word(VR_SVO_CHILD_NODE, 77);
  rejects(frame_input(s, bad_node, tf, camera), "node 77");
  rejects(frame_input(s, good, tf, test_camera(16, 8)), "resize");
  FrameInput no_tf = frame_input(s, good, tf, camera);
  no_tf.transfer = nullptr;
  rejects(no_tf, "transfer");
  FrameInput short_histograms = frame_input(s, good, tf, camera);
  const std::uint64_t one = 1;
  short_histograms.leaf_histograms = {&one, 1};
  rejects(short_histograms, "histogram");
  FrameInput too_coarse = frame_input(s, good, tf, camera);
  too_coarse.options.max_step_doublings = 17;
  rejects(too_coarse, "max_step_doublings");
  EXPECT_EQ(raycaster.last_ticket(), 0u);  // nothing was submitted
  EXPECT_THROW(Raycaster(context(), *gpu_scene(context()).from_gpu, RaycasterOptions{0, 4}),
               std::invalid_argument);
}

// --- The streaming frame loop on a container on disk --------------------------------------

/// Runs the streaming frame loop on `container` until every visible node is at its target LOD,
/// mirroring every upload into a CPU atlas; the last frame must equal render_svo of its SVO.
void expect_frame_loop_matches_cpu(const vulkan::Context& context,
                                   const format::Container& container, double playhead) {
  const format::Manifest& m = container.manifest();
  const glm::dvec3 size{m.dims[0], m.dims[1], m.dims[2]};
  loop::FrameLoopOptions o;
  o.atlas_bytes = std::uint64_t{125} * 93312;  // every keyframe node of the view fits
  o.width = 80;
  o.height = 60;
  o.pipelined = true;
  vulkan_render::VulkanFrameLoop loop(context, container, o);
  CpuAtlas mirror(loop.atlas().slot_count());
  auto camera = player::OrbitCamera::framing(size, 80, 60);
  const auto tf = TransferFunction::preset("cool-warm", static_cast<float>(m.value_min),
                                           static_cast<float>(m.value_max));
  loop::FrameReport report;
  bool converged = false;
  for (int i = 0; i < 2000 && !converged; ++i) {
    report = loop.frame(camera, playhead, tf, true);
    for (const stream::BrickUpload& u : loop.last_update().uploads)
      mirror.decode_into(u.slot, u.payload, m.codec, m.zfp_accuracy, container.atoms());
    EXPECT_TRUE(report.new_errors.empty()) << report.new_errors.front();
    converged = report.stats.fraction_at_target == 1.0 && report.stats.requests_in_flight == 0 &&
                report.stats.arrivals_waiting == 0 && report.stats.uploads == 0;
  }
  ASSERT_TRUE(converged) << "at target " << report.stats.fraction_at_target << ", in flight "
                         << report.stats.requests_in_flight << ", waiting "
                         << report.stats.arrivals_waiting << ", uploads " << report.stats.uploads
                         << ", occupied " << report.stats.atlas_occupied << " of "
                         << report.stats.atlas_capacity << ", selected " << report.stats.selected
                         << ", holes " << report.stats.holes;
  EXPECT_GT(report.stats.atlas_occupied, 0u);
  const RgbaImage got = loop.read_back(report.ticket);
  const RgbaImage want =
      cpu_render::render_svo({loop.last_update().svo_nodes, loop.last_update().svo_leaves}, mirror,
                             loop.geometry(), camera, tf, o.render);
  EXPECT_GT(drawn_fraction(want), 0.1);
  const psnr::ImageComparison c = compare(got, want);
  std::printf("  frame loop: %u atlas slots occupied, PSNR %.1f dB, SSIM %.4f\n",
              report.stats.atlas_occupied, c.psnr, c.ssim);
  EXPECT_GE(c.psnr, min_psnr);
  EXPECT_GE(c.ssim, min_ssim);
  // With the leaf histograms of the files (the default) the picture is the same.
  loop.set_transfer_culling(false);
  const auto plain = loop.frame(camera, playhead, tf, true);
  EXPECT_GE(compare(loop.read_back(plain.ticket), got).psnr, 50.0);
  loop.finish();
}

TEST_F(VulkanRender, FrameLoopConvergesAndMatchesTheCpuRenderer) {
  // A zfp container of 6 frames, between keyframes 2 and 3: time interpolation.
  test::TempDir dir("vulkan-render-loop");
  test::write_blobs_container(dir.path(), {70, 50, 40}, 6);
  expect_frame_loop_matches_cpu(context(), format::Container(dir / "test.vreel"), 2.25);
}

TEST_F(VulkanRender, FrameLoopFeedbackLeavesOccludedNodesUnloaded) {
  // Ray-guided feedback from the GPU's table: with a transfer function opaque everywhere the
  // rays end in the first region they enter, the 4 × 4 × 4 finest nodes behind the three faces
  // the camera sees are hidden and never loaded, and the picture is the one drawn without
  // feedback. Pipelined: the table of a frame arrives frames later. One request at a time, each
  // read on a simulated clock that advances one second a frame and taking three, so that feedback
  // comes before the nodes behind are requested however fast the machine reads and renders.
  test::TempDir dir("vulkan-render-feedback");
  test::write_blobs_container(dir.path(), {136, 136, 136}, 2);
  const format::Container container(dir / "test.vreel");
  const format::Manifest& m = container.manifest();
  const float lo = static_cast<float>(m.value_min), hi = static_cast<float>(m.value_max);
  const TransferFunction opaque({{lo, 0.2f, 0.4f, 1.0f, 1.0f}, {hi, 1.0f, 0.5f, 0.2f, 1.0f}}, lo,
                                hi);
  const auto camera = player::OrbitCamera::framing({136, 136, 136}, 256, 192);
  struct Run {
    std::uint64_t bytes = 0;
    std::uint32_t hidden = 0, occupied = 0;
    RgbaImage image;
  };
  const auto run = [&](bool feedback) {
    loop::FrameLoopOptions o;
    o.width = 256;
    o.height = 192;
    o.pipelined = true;
    o.atlas_bytes = std::uint64_t{125} * 93312;
    o.scheduler.ray_feedback = feedback;
    o.scheduler.loader.max_in_flight = 1;
    double now = 0;
    o.scheduler.loader.clock = [&now] { return now; };
    o.scheduler.loader.latency_s = 3;
    vulkan_render::VulkanFrameLoop l(context(), container, o);
    loop::FrameReport r;
    int quiet = 0;  // frames in a row with nothing requested, in flight or uploaded
    for (int i = 0; i < 2000 && quiet < 8; ++i, now += 1) {
      r = l.frame(camera, 0.5, opaque, true);
      const bool still = r.stats.requests_in_flight == 0 && r.stats.arrivals_waiting == 0 &&
                         r.stats.uploads == 0 && r.stats.requests_sent == 0;
      quiet = still ? quiet + 1 : 0;
    }
    EXPECT_EQ(quiet, 8) << "feedback " << feedback << ": did not settle";
    Run out{r.stats.bytes_loaded, r.stats.hidden_nodes, r.stats.atlas_occupied,
            l.read_back(r.ticket)};
    l.finish();
    return out;
  };
  const Run with = run(true), without = run(false);
  const psnr::ImageComparison c = compare(with.image, without.image);
  std::printf(
      "  feedback: %u nodes hidden, %u keyframe nodes and %llu bytes loaded (without: %u, %llu); "
      "PSNR %.1f dB\n",
      with.hidden, with.occupied, static_cast<unsigned long long>(with.bytes), without.occupied,
      static_cast<unsigned long long>(without.bytes), c.psnr);
  // 27 finest nodes lie behind the faces; some are loaded before their parent is refined and
  // the rays can tell them apart (kept then: the atlas has room).
  EXPECT_GE(with.hidden, 20u);
  EXPECT_EQ(without.hidden, 0u);
  EXPECT_LE(with.occupied + 15, without.occupied);
  EXPECT_LT(double(with.bytes), 0.95 * double(without.bytes));
  EXPECT_GT(drawn_fraction(without.image), 0.1);
  EXPECT_GE(c.psnr, 40.0);
}

TEST_F(VulkanRender, AViewWaitedForDrawsCompleteOnItsFirstFrame) {
  // loop::wait_for_view streams and decodes without drawing; the first frame then draws every
  // brick those steps decoded (their block ranges included) as a loop that drew all along does.
  test::TempDir dir("vulkan-render-wait");
  test::write_blobs_container(dir.path(), {70, 50, 40}, 4);
  const format::Container container(dir / "test.vreel");
  const format::Manifest& m = container.manifest();
  loop::FrameLoopOptions o;
  o.width = 80;
  o.height = 60;
  const auto camera = player::OrbitCamera::framing({70, 50, 40}, 80, 60);
  // Clear in the lower 30 % of the range (the background): block skipping matters.
  const float lo = static_cast<float>(m.value_min), hi = static_cast<float>(m.value_max);
  const TransferFunction tf(
      {{lo, 0, 0, 0, 0}, {lo + 0.3f * (hi - lo), 0.2f, 0.4f, 1, 0}, {hi, 1, 0.5f, 0.2f, 0.8f}}, lo,
      hi);
  // A small atlas (two views need 52 keyframe nodes): the second view reuses slots.
  o.atlas_bytes = std::uint64_t{40} * 93312;
  const auto converge = [&](loop::FrameLoop& l, double playhead) {
    loop::FrameReport r;
    for (int i = 0; i < 2000; ++i) {
      r = l.frame(camera, playhead, tf, true);
      if (r.stats.fraction_at_target == 1.0 && r.stats.requests_in_flight == 0 &&
          r.stats.arrivals_waiting == 0 && r.stats.uploads == 0)
        break;
    }
    return r;
  };
  for (const auto decode :
       {loop::FrameLoopOptions::Decode::gpu, loop::FrameLoopOptions::Decode::cpu}) {
    o.gpu.decode = decode;
    const char* name = decode == loop::FrameLoopOptions::Decode::cpu ? "cpu" : "gpu";
    vulkan_render::VulkanFrameLoop waited(context(), container, o);
    vulkan_render::VulkanFrameLoop drawing(context(), container, o);
    for (const double playhead : {0.5, 2.5}) {
      const loop::ViewWait wait = loop::wait_for_view(waited, camera, playhead, 60);
      ASSERT_TRUE(wait.complete) << name << " decode, playhead " << playhead;
      const loop::FrameReport first = waited.frame(camera, playhead, tf, true);
      EXPECT_EQ(first.stats.fraction_at_target, 1.0);
      const RgbaImage got = waited.read_back(first.ticket);
      EXPECT_GT(drawn_fraction(got), 0.01);
      const loop::FrameReport r = converge(drawing, playhead);
      const psnr::ImageComparison c = compare(got, drawing.read_back(r.ticket));
      EXPECT_GE(c.psnr, 50.0) << name << " decode, playhead " << playhead;
    }
    EXPECT_EQ(waited.raycaster().last_ticket(), 2u) << "one frame drawn per view";
    waited.finish();
    drawing.finish();
  }
}

TEST_F(VulkanRender, SparseKeyframesMatchTheCpuRenderer) {
  // Sparse keyframe lists: the still nodes have keyframes 0 and 8 only, the others one at every
  // step; at 2.25 the still nodes interpolate 0 and 8, the others 2 and 3.
  test::TempDir dir("vulkan-render-gap");
  test::write_keyframe_series(dir / "series", {70, 40, 40}, 9);
  encoder::EncodeJob job;
  job.coding.codec = format::Codec::zfp;
  job.coding.zfp_accuracy = 1e-3;
  job.max_keyframe_gap = 8;
  const auto series = datasets::open_series(dir / "series");
  const auto summary = encoder::encode_series(*series, dir / "gap.vreel", job);
  ASSERT_GT(summary.nodes_interpolated, 0u);
  expect_frame_loop_matches_cpu(context(), format::Container(dir / "gap.vreel"), 2.25);
}

}  // namespace
}  // namespace volreel
