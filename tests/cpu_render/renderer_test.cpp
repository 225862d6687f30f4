// renderer_test.cpp: the CPU reference renderer — the LOD-difference mapping for d = 0..3, the
// SVO ray caster against the dense-volume oracle (fully loaded, time interpolation, LOD
// differences 1–3 for either keyframe, dims not a multiple of 34, a single-level volume), "up"
// children, an empty transfer function, opacity correction, the step from the leaf's level
// (rule, uniform and piecewise-constant media against fine steps and 1 − exp(−σL), sample
// counts), SVO validation and PNG output.
//
// Coarse states take coarser steps than the oracle (which always takes the fine step): they are
// compared sample for sample with max_step_doublings = 0, and as they render by PSNR.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "../test_util.hpp"
#include "svo_builder.hpp"
#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/player/svo_layout.h"
#include "volreel/psnr/metrics.hpp"

namespace volreel {
namespace {

using cpu_render::CpuAtlas;
using cpu_render::DenseLevel;
using cpu_render::RgbaImage;
using cpu_render::TransferFunction;
using cpu_render::VolumeGeometry;
using test::build_uniform_svo;
using test::LeafSpec;

using Coord = std::array<std::uint32_t, 3>;

// --- The LOD-difference mapping ------------------------------------------------------------

TEST(CpuRenderLodMapping, AncestorLocalHandComputed) {
  // u' = ((c mod 2^d) + u) / 2^d.
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(5, 0.25f, 0), 0.25f);
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(4, 0.25f, 1), 0.125f);     // (0 + 0.25)/2
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(5, 0.25f, 1), 0.625f);     // (1 + 0.25)/2
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(5, 0.25f, 2), 0.3125f);    // (1 + 0.25)/4
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(7, 0.75f, 2), 0.9375f);    // (3 + 0.75)/4
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(13, 0.25f, 3), 0.65625f);  // (5 + 0.25)/8
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(8, 0.0f, 3), 0.0f);        // (0 + 0)/8
  // Stored voxel coordinates: the apron is skipped.
  EXPECT_FLOAT_EQ(vr_svo_slot_coord(0.0f, 34.0f), 1.0f);
  EXPECT_FLOAT_EQ(vr_svo_slot_coord(0.5f, 34.0f), 18.0f);
  EXPECT_FLOAT_EQ(vr_svo_slot_coord(0.5f, 64.0f), 33.0f);
  // A case that a one-level mapping (fract((c + u)/2) applied for any d, or c mod 2 instead of
  // c mod 2^d) gets wrong: node 6 at d = 2 lies in the third quarter of its ancestor.
  EXPECT_FLOAT_EQ(vr_svo_ancestor_local(6, 0.5f, 2), 0.625f);  // (2 + 0.5)/4
}

TEST(CpuRenderLodMapping, FinestVoxelCentresLandOnTheirAncestorVoxels) {
  // The centre of finest voxel g = Ic + i (world g + 0.5; I the interior) lies at level-(L−1−d)
  // voxel coordinate (g + 0.5)/2^d − 0.5; in the ancestor brick c >> d, whose stored voxel 1 is
  // level voxel I·(c >> d), that is stored voxel (g + 0.5)/2^d − 0.5 − I·(c >> d) + 1. The SVO
  // mapping must give the same texel coordinate (slot_coord − 0.5) for every d and brick size.
  for (const vr_uint interior : {34u, 64u, 10u})
    for (vr_uint d = 0; d <= 3; ++d)
      for (vr_uint c = 0; c < 16; ++c)
        for (vr_uint i = 0; i < interior; ++i) {
          const double I = interior, g = I * c + i;
          const double expected = (g + 0.5) / double(1u << d) - 0.5 - I * double(c >> d) + 1.0;
          const float u = (float(i) + 0.5f) / float(interior);
          const double got =
              double(vr_svo_slot_coord(vr_svo_ancestor_local(c, u, d), float(interior))) - 0.5;
          ASSERT_NEAR(got, expected, 1e-4)
              << "interior " << interior << " d " << d << " c " << c << " i " << i;
        }
}

// --- Scenes: two frames of an analytic field, their exact pyramids and an atlas ----------------

struct Scene {
  Dims dims;
  VolumeGeometry geometry;
  std::vector<format::LevelGeometry> levels;
  std::array<Volume, 2> frames;
  std::array<encoder::Pyramid, 2> pyramids;
  float lo = 0, hi = 0;
  std::vector<std::uint32_t> level_first;  // first brick number of each level
  std::uint32_t bricks_per_frame = 0;

  std::uint32_t slot(std::size_t frame, std::uint32_t level, Coord c) const {
    const auto& g = levels[level].grid;
    return static_cast<std::uint32_t>(frame) * bricks_per_frame + level_first[level] +
           (c[2] * g[1] + c[1]) * g[0] + c[0];
  }
  DenseLevel dense(std::size_t frame, std::uint32_t level) const {
    return {levels[level].dims, pyramids[frame].levels[level], level};
  }
  template <class F>
  void for_each_brick(F f) const {
    for (std::uint32_t l = 0; l < levels.size(); ++l) {
      const auto& g = levels[l].grid;
      for (std::uint32_t z = 0; z < g[2]; ++z)
        for (std::uint32_t y = 0; y < g[1]; ++y)
          for (std::uint32_t x = 0; x < g[0]; ++x) f(l, Coord{x, y, z});
    }
  }
  /// Every brick of every level of both frames, exactly (no coding).
  CpuAtlas exact_atlas() const {
    CpuAtlas atlas(2 * bricks_per_frame);
    std::vector<float> brick(atlas.slot_values());
    for (std::size_t t = 0; t < 2; ++t)
      for_each_brick([&](std::uint32_t l, Coord c) {
        encoder::extract_brick(pyramids[t], l, c[0], c[1], c[2], brick);
        atlas.store(slot(t, l, c), brick);
      });
    return atlas;
  }
};

std::shared_ptr<const Scene> make_scene(Dims dims, datasets::AnalyticField field) {
  auto s = std::make_shared<Scene>();
  s->dims = dims;
  const std::array<std::uint32_t, 3> d = {static_cast<std::uint32_t>(dims.x),
                                          static_cast<std::uint32_t>(dims.y),
                                          static_cast<std::uint32_t>(dims.z)};
  s->geometry = VolumeGeometry::of(d);
  s->levels = format::level_geometry(d, {});
  datasets::AnalyticParams p;
  p.field = field;
  p.dims = dims;
  p.frames = 8;
  s->lo = INFINITY;
  s->hi = -INFINITY;
  for (std::size_t t = 0; t < 2; ++t) {
    s->frames[t] = Volume(dims);
    // Frames 0 and 3: far enough apart that time interpolation is visible.
    datasets::analytic_frame(p, 3 * t, s->frames[t].data);
    s->pyramids[t] = encoder::build_pyramid(s->frames[t]);
    for (float v : s->frames[t].data) {
      s->lo = std::min(s->lo, v);
      s->hi = std::max(s->hi, v);
    }
  }
  for (const auto& l : s->levels) {
    s->level_first.push_back(s->bricks_per_frame);
    s->bricks_per_frame += l.grid[0] * l.grid[1] * l.grid[2];
  }
  return s;
}

/// 240 × 40 × 30: no axis a multiple of 34; grids 8×2×1 → 4×1×1 → 2×1×1 → 1: four levels.
const Scene& elongated() {
  static const auto scene = make_scene({240, 40, 30}, datasets::AnalyticField::blobs);
  return *scene;
}

/// Every value visible, colour and opacity changing across the range.
TransferFunction test_transfer(const Scene& s) {
  const float mid = 0.5f * (s.lo + s.hi);
  return TransferFunction({{s.lo, 0.1f, 0.2f, 1.0f, 0.01f},
                           {mid, 0.1f, 0.9f, 0.3f, 0.04f},
                           {s.hi, 1.0f, 0.2f, 0.1f, 0.12f}},
                          s.lo, s.hi);
}

player::OrbitCamera test_camera(const Scene& s, int width = 96, int height = 64) {
  auto camera = player::OrbitCamera::framing(
      glm::dvec3(double(s.dims.x), double(s.dims.y), double(s.dims.z)), width, height);
  camera.distance *= 0.6;  // the volume fills the image
  return camera;
}

double image_psnr(const RgbaImage& a, const RgbaImage& b) {
  return psnr::compare_images(cpu_render::to_image(a), cpu_render::to_image(b)).psnr;
}

/// The image is not all background (the comparison means something).
double drawn_fraction(const RgbaImage& image) {
  std::size_t drawn = 0;
  for (std::size_t i = 3; i < image.rgba.size(); i += 4) drawn += image.rgba[i] > 0.05f ? 1u : 0u;
  return double(drawn) / double(image.rgba.size() / 4);
}

// Float rounding only: the slot coordinate 1 + 34·u' and the level coordinate p/2^k − 0.5 differ
// by a few ulps, which moves trilinear weights by ~1e-5 over hundreds of composited samples.
constexpr double exact_tolerance = 2e-4;

/// The fixed step everywhere: the oracle's samples, for sample-for-sample comparisons.
cpu_render::RenderOptions fixed_step() {
  cpu_render::RenderOptions o;
  o.max_step_doublings = 0;
  return o;
}

// Coarse steps against the oracle's fine ones, e = 1..3 on the test scenes (measured 56–69 dB).
constexpr double coarse_step_min_psnr = 50.0;

/// max |got − want| over every channel, recorded in the test's XML output (--gtest_output=xml).
double difference(const RgbaImage& got, const RgbaImage& want) {
  const double d = cpu_render::max_abs_difference(got, want);
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", d);
  ::testing::Test::RecordProperty("max_abs_difference", text);
  return d;
}

// --- Fully loaded: every finest node drawn, A = frame 0, B = frame 1 -------------------------

class CpuRenderFullyLoaded : public ::testing::TestWithParam<float> {};

TEST_P(CpuRenderFullyLoaded, SvoEqualsReferenceInterpolatedInTime) {
  const Scene& s = elongated();
  const float f = GetParam();
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, f};
  });
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  const RgbaImage got = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
  const RgbaImage want = cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), f,
                                                      s.geometry, camera, transfer);
  EXPECT_GT(drawn_fraction(want), 0.15);
  EXPECT_LE(difference(got, want), exact_tolerance);
  // Finest leaves take the fine step: every sample of the oracle, no more.
  EXPECT_GT(want.samples, 0u);
  EXPECT_EQ(got.samples, want.samples);
}

INSTANTIATE_TEST_SUITE_P(Factors, CpuRenderFullyLoaded, ::testing::Values(0.0f, 0.5f, 1.0f),
                         [](const auto& param) {
                           return "f" + std::to_string(static_cast<int>(param.param * 100)) + "pct";
                         });

TEST(CpuRenderFullyLoaded, TimeInterpolationChangesTheImage) {
  // The oracle's f = 0, 0.5 and 1 differ: a renderer that ignored the factor would fail above.
  const Scene& s = elongated();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  const auto render = [&](float f) {
    return cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), f, s.geometry,
                                        camera, transfer);
  };
  const RgbaImage a = render(0), m = render(0.5f), b = render(1);
  EXPECT_GT(cpu_render::max_abs_difference(a, m), 0.05);
  EXPECT_GT(cpu_render::max_abs_difference(m, b), 0.05);
}

TEST(CpuRenderFullyLoaded, DecodedContainerMatchesDecodedVolumes) {
  // Frames coded with zfp and decoded: the atlas from decode_into, the oracle from decode_level.
  // Each brick's apron is coded with the brick, so it differs from the neighbour's interior by
  // up to the zfp accuracy; the images agree to that.
  const auto scene = make_scene({100, 70, 40}, datasets::AnalyticField::noise);
  const Scene& s = *scene;
  encoder::CodingSettings coding;
  coding.codec = format::Codec::zfp;
  coding.zfp_accuracy = 1e-4 * double(s.hi - s.lo);
  coding.value_min = s.lo;
  coding.value_max = s.hi;
  const encoder::FrameEncoder frame_encoder(nullptr, coding);
  const format::AtomTable no_atoms;
  CpuAtlas atlas(2 * s.bricks_per_frame);
  std::array<std::vector<std::byte>, 2> bytes;
  std::array<format::FrameView, 2> views;
  const std::uint32_t finest = s.geometry.levels - 1;
  std::array<format::LevelVolume, 2> decoded;
  for (std::size_t t = 0; t < 2; ++t) {
    bytes[t] = frame_encoder.encode(t, s.frames[t]);
    views[t] = format::FrameView(bytes[t], "frame" + std::to_string(t));
    std::size_t finest_bricks = 0;
    for (std::uint32_t i = 0; i < views[t].node_count(); ++i) {
      const auto& pos = views[t].position(i);
      const format::Node node = views[t].node(i);
      if (node.brick == format::no_brick) continue;
      atlas.decode_into(s.slot(t, pos.level, {pos.x, pos.y, pos.z}),
                        views[t].brick_bytes(node.brick), views[t].codec(),
                        views[t].header().codec_parameter, no_atoms, views[t].name(),
                        views[t].brick_offset(node.brick));
      finest_bricks += pos.level == finest ? 1 : 0;
    }
    const auto& g = s.levels[finest].grid;
    ASSERT_EQ(finest_bricks, std::size_t{g[0]} * g[1] * g[2]) << "a finest brick is missing";
    decoded[t] = format::decode_level(views[t], finest, no_atoms);
  }
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  for (float f : {0.0f, 0.5f, 1.0f}) {
    const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, f};
    });
    const RgbaImage got = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
    const RgbaImage want = cpu_render::render_reference(DenseLevel::of(decoded[0], finest),
                                                        DenseLevel::of(decoded[1], finest), f,
                                                        s.geometry, camera, transfer);
    EXPECT_GT(drawn_fraction(want), 0.15);
    EXPECT_LE(difference(got, want), 5e-3) << "f " << f;
    EXPECT_GE(image_psnr(got, want), 50.0) << "f " << f;
  }
}

// --- LOD differences: B (or A) from an ancestor d levels up --------------------------------

class CpuRenderLodDifference : public ::testing::TestWithParam<std::uint32_t> {};

TEST_P(CpuRenderLodDifference, SecondKeyframeFromAnAncestor) {
  const Scene& s = elongated();
  const std::uint32_t d = GetParam(), finest = s.geometry.levels - 1;
  ASSERT_LE(d, finest);
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  for (float f : {1.0f, 0.5f}) {
    // Every finest node drawn; B is its ancestor brick at level finest − d of frame 1.
    const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l - d, {c[0] >> d, c[1] >> d, c[2] >> d}), 0, d,
                      f};
    });
    const RgbaImage got =
        cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer, fixed_step());
    const RgbaImage want = cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest - d),
                                                        f, s.geometry, camera, transfer);
    EXPECT_GT(drawn_fraction(want), 0.15);
    EXPECT_LE(difference(got, want), exact_tolerance) << "f " << f;
    // With the step from the leaf's level: f = 1 reads only B (d levels up), f = 0.5 also A.
    const RgbaImage stepped =
        cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
    std::printf("  d %u f %.1f: coarse steps %.1f dB, %llu of %llu samples\n", d, double(f),
                image_psnr(stepped, want), static_cast<unsigned long long>(stepped.samples),
                static_cast<unsigned long long>(got.samples));
    EXPECT_GE(image_psnr(stepped, want), coarse_step_min_psnr) << "f " << f;
    if (f == 1.0f) {  // about 2^d times fewer (a little more: steps end at region exits)
      EXPECT_LT(double(stepped.samples), 1.5 * double(got.samples) / double(1u << d));
      EXPECT_GT(double(stepped.samples), double(got.samples) / double(1u << d));
    } else {
      EXPECT_EQ(stepped.samples, got.samples) << "f " << f;
    }
    if (f == 1.0f) {
      // The coarse level really looks different from the finest, so the test has power.
      const RgbaImage fine = cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), f,
                                                          s.geometry, camera, transfer);
      EXPECT_GT(cpu_render::max_abs_difference(want, fine), 0.02);
    }
  }
}

TEST_P(CpuRenderLodDifference, FirstKeyframeFromAnAncestor) {
  const Scene& s = elongated();
  const std::uint32_t d = GetParam(), finest = s.geometry.levels - 1;
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l - d, {c[0] >> d, c[1] >> d, c[2] >> d}), s.slot(1, l, c), d, 0,
                    0.25f};
  });
  const RgbaImage got = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
  const RgbaImage want = cpu_render::render_reference(s.dense(0, finest - d), s.dense(1, finest),
                                                      0.25f, s.geometry, camera, transfer);
  EXPECT_LE(difference(got, want), exact_tolerance);
}

TEST_P(CpuRenderLodDifference, NodesDrawnAtACoarserLevel) {
  // Every node of level finest − d drawn with its own bricks: the oracle at that level.
  const Scene& s = elongated();
  const std::uint32_t d = GetParam(), level = s.geometry.levels - 1 - d;
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  const auto svo = build_uniform_svo(s.levels, level, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  const RgbaImage got =
      cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer, fixed_step());
  const RgbaImage want = cpu_render::render_reference(s.dense(0, level), s.dense(1, level), 0.5f,
                                                      s.geometry, camera, transfer);
  EXPECT_LE(difference(got, want), exact_tolerance);
  EXPECT_EQ(got.samples, want.samples);
  const RgbaImage stepped = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
  std::printf("  level %u: coarse steps %.1f dB, %llu of %llu samples\n", level,
              image_psnr(stepped, want), static_cast<unsigned long long>(stepped.samples),
              static_cast<unsigned long long>(got.samples));
  EXPECT_GE(image_psnr(stepped, want), coarse_step_min_psnr);
  // About 2^d times fewer samples (a little more: steps end at region exits).
  EXPECT_LT(double(stepped.samples), 1.5 * double(got.samples) / double(1u << d));
  EXPECT_GT(double(stepped.samples), double(got.samples) / double(1u << d));
}

INSTANTIATE_TEST_SUITE_P(D, CpuRenderLodDifference, ::testing::Values(1u, 2u, 3u),
                         [](const auto& param) { return "d" + std::to_string(param.param); });

// --- Level-of-detail blending: the parent's drawing mixed in by corner weights ---------------

TEST(CpuRenderLodMapping, BlendWeightInterpolatesTheCorners) {
  // Corner i's byte at bits 8·(i mod 4) of word 7 (i < 4) or 8.
  const vr_uint w7 = 0x3322110Au, w8 = 0x77665544u;
  EXPECT_EQ(vr_svo_blend_corner(w7, w8, 0), 0x0Au);
  EXPECT_EQ(vr_svo_blend_corner(w7, w8, 3), 0x33u);
  EXPECT_EQ(vr_svo_blend_corner(w7, w8, 4), 0x44u);
  EXPECT_EQ(vr_svo_blend_corner(w7, w8, 7), 0x77u);
  // At a corner the weight is that corner's; in the middle the mean of all eight; along an edge
  // the linear mix of its two corners.
  for (vr_uint i = 0; i < 8; ++i)
    EXPECT_NEAR(vr_svo_blend_weight(w7, w8, float(i & 1), float((i >> 1) & 1), float(i >> 2)),
                float(vr_svo_blend_corner(w7, w8, i)) / 255.0f, 1e-6f)
        << "corner " << i;
  float mean = 0;
  for (vr_uint i = 0; i < 8; ++i) mean += float(vr_svo_blend_corner(w7, w8, i)) / 255.0f / 8.0f;
  EXPECT_NEAR(vr_svo_blend_weight(w7, w8, 0.5f, 0.5f, 0.5f), mean, 1e-6f);
  EXPECT_NEAR(vr_svo_blend_weight(w7, w8, 0.25f, 0.0f, 0.0f),
              (0.75f * 0x0A + 0.25f * 0x11) / 255.0f, 1e-6f);
  EXPECT_FLOAT_EQ(vr_svo_blend_weight(VR_SVO_BLEND_NONE, VR_SVO_BLEND_NONE, 0.3f, 0.6f, 0.9f),
                  1.0f);
}

TEST(CpuRenderLodBlending, WeightsMixTheParentsDrawingIntoTheNodes) {
  const Scene& s = elongated();
  const std::uint32_t finest = s.geometry.levels - 1;
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  // Every finest node drawn from frame 0's own brick, its coarse pair the parent's brick of
  // frame 0 (one level up), every corner weighted `byte`.
  const auto blended = [&](std::uint8_t byte) {
    return build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      LeafSpec spec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
      spec.slot_c = spec.slot_d = s.slot(0, l - 1, {c[0] >> 1, c[1] >> 1, c[2] >> 1});
      spec.d_c = spec.d_d = 1;
      spec.corners.fill(byte);
      return spec;
    });
  };
  const auto render = [&](std::uint8_t byte) {
    return cpu_render::render_svo(blended(byte).view(), atlas, s.geometry, camera, transfer,
                                  fixed_step());
  };
  // Weight w mixes w·fine + (1 − w)·parent: the reference of the finest level and the one above
  // it interpolated by 1 − w (the oracle mixes values, as the blend does, before the transfer).
  for (const std::uint8_t byte : {std::uint8_t{0}, std::uint8_t{100}, std::uint8_t{255}}) {
    const float w = float(byte) / 255.0f;
    const RgbaImage want = cpu_render::render_reference(s.dense(0, finest), s.dense(0, finest - 1),
                                                        1.0f - w, s.geometry, camera, transfer);
    EXPECT_GT(drawn_fraction(want), 0.15);
    EXPECT_LE(difference(render(byte), want), exact_tolerance) << "weight " << int(byte);
  }
  // The parent really differs from the node, so the weights are seen.
  EXPECT_GT(cpu_render::max_abs_difference(render(0), render(255)), 0.02);
  // Weights that differ by corner lie between the uniform ones where they do.
  const auto corners = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    LeafSpec spec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
    spec.slot_c = spec.slot_d = s.slot(0, l - 1, {c[0] >> 1, c[1] >> 1, c[2] >> 1});
    spec.d_c = spec.d_d = 1;
    spec.corners = {0, 255, 0, 255, 0, 255, 0, 255};  // fine towards +x, the parent towards −x
    return spec;
  });
  const RgbaImage mixed =
      cpu_render::render_svo(corners.view(), atlas, s.geometry, camera, transfer, fixed_step());
  EXPECT_GT(cpu_render::max_abs_difference(mixed, render(0)), 1e-3);
  EXPECT_GT(cpu_render::max_abs_difference(mixed, render(255)), 1e-3);
  // The level map: a pixel shows the level its strongest sample's fine pair is drawn at — the
  // finest here (the coarse pair blended in does not count), the level above for an SVO drawn
  // there.
  cpu_render::RenderOptions mapped = fixed_step();
  mapped.level_map = true;
  const auto levels_of = [&](const test::BuiltSvo& svo) {
    const RgbaImage image =
        cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer, mapped);
    EXPECT_EQ(image.levels.size(), std::size_t{96} * 64);
    std::array<std::size_t, 256> count{};
    for (std::size_t p = 0; p < image.levels.size(); ++p) {
      ++count[image.levels[p]];
      if (image.rgba[4 * p + 3] > 0.05f) {
        EXPECT_NE(image.levels[p], RgbaImage::no_level) << p;
      }
    }
    return count;
  };
  const auto fine_levels = levels_of(blended(0));
  EXPECT_GT(fine_levels[finest], std::size_t{96 * 64 / 8});
  EXPECT_EQ(fine_levels[finest] + fine_levels[RgbaImage::no_level], std::size_t{96} * 64);
  const auto coarse = build_uniform_svo(s.levels, finest - 1, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
  });
  const auto coarse_levels = levels_of(coarse);
  EXPECT_GT(coarse_levels[finest - 1], std::size_t{96 * 64 / 8});
  EXPECT_EQ(coarse_levels[finest - 1] + coarse_levels[RgbaImage::no_level], std::size_t{96} * 64);
  // The dense oracle has no map, and without the option there is none.
  EXPECT_TRUE(cpu_render::render_reference(s.dense(0, finest), s.dense(0, finest), 0.0f, s.geometry,
                                           camera, transfer, mapped)
                  .levels.empty());
  EXPECT_TRUE(render(0).levels.empty());
  // A blending leaf with a coarse slot outside the atlas is refused.
  const auto bad = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    LeafSpec spec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
    spec.slot_c = atlas.slot_count();
    spec.d_c = spec.d_d = 1;
    spec.corners.fill(7);
    return spec;
  });
  EXPECT_THROW(cpu_render::render_svo(bad.view(), atlas, s.geometry, camera, transfer),
               std::invalid_argument);
  // So is a coarse LOD difference of 0 (the coarse pair is an ancestor's).
  const auto flat = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    LeafSpec spec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
    spec.slot_c = spec.slot_d = s.slot(0, l, c);
    spec.corners.fill(7);
    return spec;
  });
  EXPECT_THROW(cpu_render::render_svo(flat.view(), atlas, s.geometry, camera, transfer),
               std::invalid_argument);
}

TEST(CpuRenderLodBlending, SpatialBlendingSmoothsTheErrorStepAtALevelBoundary) {
  const Scene& s = elongated();
  const std::uint32_t finest = s.geometry.levels - 1;
  const CpuAtlas atlas = s.exact_atlas();
  // From nearly straight above, so that the boundary plane x = 136 projects to a line.
  auto camera = test_camera(s);
  camera.elevation = 1.4;
  const auto transfer = test_transfer(s);
  // Finest nodes with x < 4 drawn from their own bricks, the others from their parents'; with
  // blending, the fine nodes next to the coarse ones take the parent's drawing at the corners on
  // that side (x = 1), as the SVO builder weights them.
  const auto svo = [&](bool blend) {
    return build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
      const Coord parent{c[0] >> 1, c[1] >> 1, c[2] >> 1};
      if (c[0] >= 4)
        return LeafSpec{s.slot(0, l - 1, parent), s.slot(0, l - 1, parent), 1, 1, 0.0f};
      LeafSpec spec{s.slot(0, l, c), s.slot(0, l, c), 0, 0, 0.0f};
      if (blend && c[0] == 3) {
        spec.slot_c = spec.slot_d = s.slot(0, l - 1, parent);
        spec.d_c = spec.d_d = 1;
        for (std::uint32_t i = 0; i < 8; ++i) spec.corners[i] = (i & 1) ? 0 : 255;
      }
      return spec;
    });
  };
  cpu_render::RenderOptions mapped = fixed_step();
  mapped.level_map = true;
  const RgbaImage want = cpu_render::render_reference(s.dense(0, finest), s.dense(0, finest), 0.0f,
                                                      s.geometry, camera, transfer);
  // The step of the error (image − ground truth) between horizontally or vertically adjacent
  // pixels whose levels differ: the seam.
  const auto seam = [&](const RgbaImage& image) {
    double sum = 0;
    std::size_t pairs = 0;
    const auto w = static_cast<std::size_t>(image.width);
    for (std::size_t p = 0; p < image.levels.size(); ++p)
      for (const std::size_t q : {p + 1, p + w}) {
        if ((q == p + 1 && (p + 1) % w == 0) || q >= image.levels.size()) continue;
        if (image.levels[p] == RgbaImage::no_level || image.levels[q] == RgbaImage::no_level ||
            image.levels[p] == image.levels[q])
          continue;
        for (std::size_t c = 0; c < 3; ++c) {
          const double d = (image.rgba[4 * p + c] - want.rgba[4 * p + c]) -
                           (image.rgba[4 * q + c] - want.rgba[4 * q + c]);
          sum += d * d;
        }
        ++pairs;
      }
    EXPECT_GT(pairs, 20u);
    return std::sqrt(sum / double(3 * std::max<std::size_t>(pairs, 1)));
  };
  const double hard =
      seam(cpu_render::render_svo(svo(false).view(), atlas, s.geometry, camera, transfer, mapped));
  const double blended =
      seam(cpu_render::render_svo(svo(true).view(), atlas, s.geometry, camera, transfer, mapped));
  std::printf("  error step at the boundary: %.5f without blending, %.5f with\n", hard, blended);
  EXPECT_LT(blended, 0.85 * hard);  // measured 0.71
}

// --- Shapes of trees and volumes -----------------------------------------------------------

TEST(CpuRenderSvoShapes, UpChildrenDrawTheSameAsLeafChildren) {
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s);
  const auto transfer = test_transfer(s);
  for (std::uint32_t level = 1; level < s.geometry.levels; ++level) {
    const auto leaf_for = [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
    };
    const auto leaf = build_uniform_svo(s.levels, level, leaf_for, false);
    const auto up = build_uniform_svo(s.levels, level, leaf_for, true);
    ASSERT_NE(leaf.nodes.size(), up.nodes.size());
    const RgbaImage a =
        cpu_render::render_svo(leaf.view(), atlas, s.geometry, camera, transfer, fixed_step());
    const RgbaImage b =
        cpu_render::render_svo(up.view(), atlas, s.geometry, camera, transfer, fixed_step());
    EXPECT_EQ(cpu_render::max_abs_difference(a, b), 0.0) << "level " << level;
    // Coarse steps end at region exits, which are the up children's boxes, one level finer than
    // the leaf children's: a few steps are split in two, with the opacity corrected for each.
    const RgbaImage c = cpu_render::render_svo(leaf.view(), atlas, s.geometry, camera, transfer);
    const RgbaImage d = cpu_render::render_svo(up.view(), atlas, s.geometry, camera, transfer);
    std::printf("  level %u: leaf vs up children with coarse steps %.1f dB\n", level,
                image_psnr(c, d));
    EXPECT_GE(image_psnr(c, d), 45.0) << "level " << level;
    EXPECT_GE(d.samples, c.samples) << "level " << level;
  }
}

class CpuRenderVolumeShapes : public ::testing::TestWithParam<Dims> {};

TEST_P(CpuRenderVolumeShapes, SvoEqualsReferenceAtEveryLevel) {
  const auto scene = make_scene(GetParam(), datasets::AnalyticField::rotating);
  const Scene& s = *scene;
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s, 64, 64);
  const auto transfer = test_transfer(s);
  for (std::uint32_t level = 0; level < s.geometry.levels; ++level) {
    const auto svo = build_uniform_svo(s.levels, level, [&](std::uint32_t l, Coord c) {
      return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
    });
    const RgbaImage got =
        cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer, fixed_step());
    const RgbaImage want = cpu_render::render_reference(s.dense(0, level), s.dense(1, level), 0.5f,
                                                        s.geometry, camera, transfer);
    EXPECT_GT(drawn_fraction(want), 0.2);
    EXPECT_LE(difference(got, want), exact_tolerance) << "level " << level;
    const RgbaImage stepped =
        cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
    std::printf("  level %u: coarse steps %.1f dB\n", level, image_psnr(stepped, want));
    EXPECT_GE(image_psnr(stepped, want), coarse_step_min_psnr) << "level " << level;
  }
}

// One level (the root drawn through "up" children), two levels with ragged edges, two levels
// with dims an exact multiple of 34.
INSTANTIATE_TEST_SUITE_P(Dims, CpuRenderVolumeShapes,
                         ::testing::Values(Dims{30, 20, 25}, Dims{50, 37, 20}, Dims{68, 34, 34}),
                         [](const auto& param) {
                           return std::to_string(param.param.x) + "x" +
                                  std::to_string(param.param.y) + "x" +
                                  std::to_string(param.param.z);
                         });

TEST(CpuRender, EmptyTransferFunctionGivesTheBackground) {
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  cpu_render::RenderOptions options;
  options.background = {0.25f, 0.5f, 0.75f};
  const auto transparent = TransferFunction::preset("transparent", s.lo, s.hi);
  for (const RgbaImage& image :
       {cpu_render::render_svo(svo.view(), atlas, s.geometry, test_camera(s), transparent, options),
        cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), 0.5f, s.geometry,
                                     test_camera(s), transparent, options)})
    for (int y = 0; y < image.height; ++y)
      for (int x = 0; x < image.width; ++x) {
        const float* p = image.pixel(x, y);
        ASSERT_EQ(p[0], 0.25f);
        ASSERT_EQ(p[1], 0.5f);
        ASSERT_EQ(p[2], 0.75f);
        ASSERT_EQ(p[3], 0.0f);
      }
}

TEST(CpuRender, EmptyChildrenAreTransparent) {
  // Only octant 0 of the root drawn: the rest of the image is background.
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  auto svo = build_uniform_svo(s.levels, 1, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.0f};
  });
  const RgbaImage all =
      cpu_render::render_svo(svo.view(), atlas, s.geometry, test_camera(s), test_transfer(s));
  for (vr_uint o = 1; o < 8; ++o) svo.nodes[1 + o] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
  const RgbaImage part =
      cpu_render::render_svo(svo.view(), atlas, s.geometry, test_camera(s), test_transfer(s));
  // Octant 0 of the root is x < 136: part of the volume disappears, not all of it.
  EXPECT_LT(drawn_fraction(part), drawn_fraction(all) - 0.05);
  EXPECT_GT(drawn_fraction(part), 0.03);
}

TEST(CpuRender, FeedbackMarksTheRegionsRaysSampleAndNotThoseBehindOpaqueMaterial) {
  // Looking down the long axis from +x: 8 finest bricks one behind the other along each ray.
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto leaf_for = [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  };
  auto camera = test_camera(s);
  camera.azimuth = 0;
  camera.elevation = 0;
  camera.distance = 400;
  const TransferFunction clear({{s.lo, 0.5f, 0.5f, 0.5f, 1e-4f}, {s.hi, 1, 1, 1, 1e-4f}}, s.lo,
                               s.hi);
  const TransferFunction opaque({{s.lo, 0.5f, 0.5f, 0.5f, 1}, {s.hi, 1, 1, 1, 1}}, s.lo, s.hi);
  // Leaf children: the leaf record's first entry, LOD difference 0 (entry 1).
  const auto leaves = build_uniform_svo(s.levels, finest, leaf_for);
  const std::size_t count = leaves.leaves.size() / VR_SVO_LEAF_WORDS;
  std::vector<std::uint32_t> through, front;
  cpu_render::render_svo(leaves.view(), atlas, s.geometry, camera, clear, {}, &through);
  cpu_render::render_svo(leaves.view(), atlas, s.geometry, camera, opaque, {}, &front);
  ASSERT_EQ(through.size(), VR_SVO_FEEDBACK_ENTRIES * count);
  ASSERT_EQ(front.size(), through.size());
  std::size_t reached = 0, reached_opaque = 0;
  for (std::size_t i = 0; i < through.size(); ++i) {
    if (i % VR_SVO_FEEDBACK_ENTRIES != 0) {
      EXPECT_EQ(through[i], 0u) << i;  // no "up" regions in this tree
      continue;
    }
    EXPECT_LE(through[i], 1u);
    EXPECT_LE(front[i], through[i]) << "leaf " << i / VR_SVO_FEEDBACK_ENTRIES;
    reached += through[i];
    reached_opaque += front[i];
  }
  EXPECT_EQ(reached, count);  // every brick is in view: rays cross them all
  EXPECT_GT(reached_opaque, 0u);
  EXPECT_LE(reached_opaque, count / 4);  // only the bricks at the +x face (2 of 8 along x)
  // "Up" children: a node's own leaf drawn in its octants, one level finer (entry 2), each
  // octant in its own entry.
  const auto up = build_uniform_svo(s.levels, finest - 1, leaf_for, true);
  std::vector<std::uint32_t> octants;
  cpu_render::render_svo(up.view(), atlas, s.geometry, camera, clear, {}, &octants);
  std::size_t up_entries = 0, above_zero = 0;
  for (std::size_t i = 0; i < octants.size(); ++i) {
    EXPECT_TRUE(octants[i] == 0 || octants[i] == 2) << i << ": " << octants[i];
    up_entries += octants[i] == 2 ? 1u : 0u;
    above_zero += octants[i] == 2 && i % VR_SVO_FEEDBACK_ENTRIES != 0 ? 1u : 0u;
  }
  EXPECT_GT(above_zero, 0u);
  EXPECT_EQ(up_entries, count);  // as many regions as the finest bricks
}

TEST(CpuRender, HistogramCullingKeepsTheImage) {
  // Only the top 65 % of the range visible: leaves whose histogram hull lies below are skipped.
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  const float cut = s.lo + 0.35f * (s.hi - s.lo);
  const TransferFunction high({{cut, 1, 0.5f, 0, 0}, {s.hi, 1, 1, 0.5f, 0.3f}}, s.lo, s.hi);
  const auto camera = test_camera(s);
  const RgbaImage plain = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, high);
  test::add_leaf_histograms(svo, atlas, s.lo, s.hi);
  std::size_t culled = 0;
  for (std::size_t i = 0; i < svo.histograms.size(); i += 2) {
    const std::uint64_t h = svo.histograms[i] | std::uint64_t{svo.histograms[i + 1]} << 32;
    culled += high.visible_hull(h, s.lo, s.hi) ? 0u : 1u;
  }
  EXPECT_GT(culled, 0u);                         // some leaves are skipped ...
  EXPECT_LT(culled, svo.histograms.size() / 2);  // ... not all
  EXPECT_GT(drawn_fraction(plain), 0.01);
  const RgbaImage culling = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, high);
  EXPECT_EQ(cpu_render::max_abs_difference(plain, culling), 0.0);
  // Histograms that claim every leaf holds only the lowest values: nothing is drawn.
  for (std::size_t i = 0; i < svo.histograms.size(); i += 2) {
    svo.histograms[i] = 1;
    svo.histograms[i + 1] = 0;
  }
  std::vector<std::uint32_t> culled_feedback, plain_feedback;
  const RgbaImage none =
      cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, high, {}, &culled_feedback);
  EXPECT_EQ(drawn_fraction(none), 0.0);
  // A culled leaf counts as reached by the rays that cross it (the feedback of a tree drawn
  // without histograms and a transfer function that shows every value just as little).
  auto plain_svo = svo;
  plain_svo.histograms.clear();
  const TransferFunction faint({{s.lo, 1, 1, 1, 1e-6f}, {s.hi, 1, 1, 1, 1e-6f}}, s.lo, s.hi);
  cpu_render::render_svo(plain_svo.view(), atlas, s.geometry, camera, faint, {}, &plain_feedback);
  EXPECT_EQ(culled_feedback, plain_feedback);
  EXPECT_GT(std::count(culled_feedback.begin(), culled_feedback.end(), 1u), 0);
  svo.histograms.pop_back();
  EXPECT_THROW(cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, high),
               std::invalid_argument);
}

TEST(CpuRender, OpacityCorrectionMakesTheStepSizeIrrelevant) {
  const Scene& s = elongated();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto transfer = test_transfer(s);
  const auto render = [&](double step) {
    cpu_render::RenderOptions options;
    options.step = step;
    return cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), 0.5f, s.geometry,
                                        test_camera(s), transfer, options);
  };
  const RgbaImage fine = render(0.25), coarse = render(1.0);
  // Same picture (sampling noise only) ...
  EXPECT_GE(image_psnr(fine, coarse), 35.0);
  // ... where without correction the coarse step would be far more transparent.
  cpu_render::RenderOptions uncorrected;
  uncorrected.step = 1.0;
  uncorrected.reference_step = 0.25;  // pretends the opacities were per quarter voxel
  const RgbaImage wrong =
      cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), 0.5f, s.geometry,
                                   test_camera(s), transfer, uncorrected);
  EXPECT_LT(image_psnr(fine, wrong), 30.0);
}

// --- The step from the leaf's level -------------------------------------------------------

TEST(CpuRenderStep, DoublingsFromTheLeafLevelHandComputed) {
  // e = min(levels − 1 − leaf_level + d, cap), d of the finer keyframe read (svo_layout.h).
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(0, 0), 0.5f, 3), 0u);  // finest
  EXPECT_EQ(vr_svo_step_doublings(4, 1, vr_svo_lod_pack(0, 0), 0.5f, 3), 2u);
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(2, 0), 0.0f, 3), 2u);  // A only
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(2, 0), 1.0f, 3), 0u);  // B only
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(2, 0), 0.5f, 3), 0u);  // the finer
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(2, 3), 1.0f, 3), 3u);
  EXPECT_EQ(vr_svo_step_doublings(4, 3, vr_svo_lod_pack(2, 3), 0.5f, 3), 2u);
  EXPECT_EQ(vr_svo_step_doublings(4, 2, vr_svo_lod_pack(1, 2), 0.25f, 16), 2u);
  EXPECT_EQ(vr_svo_step_doublings(6, 0, vr_svo_lod_pack(0, 0), 0.5f, 3), 3u);  // capped
  EXPECT_EQ(vr_svo_step_doublings(6, 0, vr_svo_lod_pack(0, 0), 0.5f, 16), 5u);
  EXPECT_EQ(vr_svo_step_doublings(6, 0, vr_svo_lod_pack(0, 0), 0.5f, 0), 0u);
}

/// A volume whose bricks hold constant values (slot i holds values[i]); 200 × 120 × 90 gives
/// grids 6×4×3 → 3×2×2 → 2×1×1 → 1: four levels.
struct ConstantScene {
  std::array<std::uint32_t, 3> dims{200, 120, 90};
  VolumeGeometry geometry = VolumeGeometry::of(dims);
  std::vector<format::LevelGeometry> levels = format::level_geometry(dims, {});
  CpuAtlas atlas;
  explicit ConstantScene(const std::vector<float>& values)
      : atlas(static_cast<std::uint32_t>(values.size())) {
    for (std::size_t i = 0; i < values.size(); ++i)
      atlas.store(static_cast<std::uint32_t>(i),
                  std::vector<float>(atlas.slot_values(), values[i]));
  }
  player::OrbitCamera camera() const {
    auto c = player::OrbitCamera::framing(glm::dvec3(dims[0], dims[1], dims[2]), 48, 32);
    c.distance *= 0.6;
    return c;
  }
};

/// The ray of pixel (x, y) clipped to [0, dims) (renderer.hpp step 1): its length, 0 if missed.
double clipped_length(const player::OrbitCamera& camera, std::array<std::uint32_t, 3> dims, int x,
                      int y) {
  const glm::dvec3 eye = camera.eye(), dir = camera.ray_direction(x + 0.5, y + 0.5);
  double t0 = 0, t1 = INFINITY;
  for (int a = 0; a < 3; ++a) {
    const double ta = -eye[a] / dir[a],
                 tb = (double(dims[static_cast<std::size_t>(a)]) - eye[a]) / dir[a];
    t0 = std::max(t0, std::min(ta, tb));
    t1 = std::min(t1, std::max(ta, tb));
  }
  return t0 < t1 ? t1 - t0 : 0.0;
}

TEST(CpuRenderStep, UniformMediumCompositesToOneMinusExpMinusSigmaL) {
  // One value everywhere, opacity α per reference step (1 voxel): σ = −ln(1 − α). At every draw
  // level (e = 3 − level doublings) the composited opacity is 1 − exp(−σ·N·step) for the N fine
  // grid points in [t0, t1) (|N·step − L| ≤ step), exactly as the fine steps give, with about
  // 2^e times fewer samples.
  const ConstantScene s({0.5f});
  const float alpha_ref = 0.005f;
  const double sigma = -std::log(1.0 - double(alpha_ref));
  const TransferFunction transfer(
      {{0, 0.2f, 0.6f, 1.0f, alpha_ref}, {1, 0.2f, 0.6f, 1.0f, alpha_ref}}, 0, 1);
  const auto camera = s.camera();
  cpu_render::RenderOptions options;
  options.termination_alpha = 1.0f;  // no early termination: the whole segment counts
  cpu_render::RenderOptions fixed = options;
  fixed.max_step_doublings = 0;
  ASSERT_EQ(s.geometry.levels, 4u);
  for (std::uint32_t level = 0; level < 4; ++level) {
    const auto svo = build_uniform_svo(s.levels, level, [](std::uint32_t, Coord) {
      return LeafSpec{0, 0, 0, 0, 0.0f};
    });
    const RgbaImage coarse =
        cpu_render::render_svo(svo.view(), s.atlas, s.geometry, camera, transfer, options);
    const RgbaImage fine =
        cpu_render::render_svo(svo.view(), s.atlas, s.geometry, camera, transfer, fixed);
    ASSERT_GT(drawn_fraction(fine), 0.5);
    std::size_t checked = 0;
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const double length = clipped_length(camera, s.dims, x, y);
        const double a = coarse.pixel(x, y)[3];
        ASSERT_NEAR(a, fine.pixel(x, y)[3], 2e-5)
            << "level " << level << " pixel " << x << "," << y;
        if (length < 1) continue;
        const double lo = 1 - std::exp(-sigma * (length - options.step));
        const double hi = 1 - std::exp(-sigma * (length + options.step));
        ASSERT_GE(a, lo - 2e-5) << "level " << level << " pixel " << x << "," << y;
        ASSERT_LE(a, hi + 2e-5) << "level " << level << " pixel " << x << "," << y;
        ++checked;
      }
    EXPECT_GT(checked, std::size_t(camera.width * camera.height / 2));
    EXPECT_LE(cpu_render::max_abs_difference(coarse, fine), 2e-5) << "level " << level;
    // Fewer samples: about 2^e times (steps also end at region exits and at the ray's end).
    const double ratio = double(fine.samples) / double(coarse.samples);
    std::printf("  level %u: %llu samples at the fine step, %llu with e = %u (%.2fx)\n", level,
                static_cast<unsigned long long>(fine.samples),
                static_cast<unsigned long long>(coarse.samples), 3 - level, ratio);
    const double e = 3.0 - level;
    EXPECT_GE(ratio, 0.7 * std::exp2(e)) << "level " << level;
    EXPECT_LE(ratio, std::exp2(e)) << "level " << level;
  }
}

TEST(CpuRenderStep, CoarseStepsEndAtTheRegionsExit) {
  // Finest leaves on a 3D checkerboard: "coarse" ones read a constant brick 3 levels up (e = 3),
  // "fine" ones a denser constant brick (e = 0). The medium is constant per leaf box, so the
  // image equals the fine-step image only if no coarse step runs into the next box (each sample
  // stands for fine points of its own box alone).
  const ConstantScene s({0.25f, 0.75f});
  const TransferFunction transfer({{0, 0.0f, 0.0f, 1.0f, 0.0f}, {1, 1.0f, 0.0f, 0.0f, 0.1f}}, 0, 1);
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto svo = build_uniform_svo(s.levels, finest, [](std::uint32_t, Coord c) {
    const bool coarse = (c[0] + c[1] + c[2]) % 2 == 0;
    return coarse ? LeafSpec{0, 0, 3, 3, 0.0f} : LeafSpec{1, 1, 0, 0, 0.0f};
  });
  const auto camera = s.camera();
  // No early termination: a coarse sample may carry the opacity past the threshold further than
  // the fine one that stops there.
  cpu_render::RenderOptions options;
  options.termination_alpha = 1.0f;
  cpu_render::RenderOptions fixed = options;
  fixed.max_step_doublings = 0;
  const RgbaImage stepped =
      cpu_render::render_svo(svo.view(), s.atlas, s.geometry, camera, transfer, options);
  const RgbaImage fine =
      cpu_render::render_svo(svo.view(), s.atlas, s.geometry, camera, transfer, fixed);
  ASSERT_GT(drawn_fraction(fine), 0.5);
  EXPECT_LE(difference(stepped, fine), 5e-5);
  EXPECT_LT(double(stepped.samples), 0.7 * double(fine.samples));
  // The two media differ (the comparison has power): the dense one alone is far more opaque.
  const auto dense_only = build_uniform_svo(s.levels, finest, [](std::uint32_t, Coord) {
    return LeafSpec{1, 1, 0, 0, 0.0f};
  });
  EXPECT_GT(
      cpu_render::max_abs_difference(
          cpu_render::render_svo(dense_only.view(), s.atlas, s.geometry, camera, transfer), fine),
      0.05);
}

TEST(CpuRender, RejectsBadSvosAndOptions) {
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const auto camera = test_camera(s, 8, 8);
  const auto transfer = test_transfer(s);
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto good = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  EXPECT_NO_THROW(cpu_render::validate_svo(good.view(), atlas.slot_count(), s.geometry));
  const auto rejects = [&](auto mutate, const char* needle) {
    auto svo = good;
    mutate(svo);
    try {
      cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
      ADD_FAILURE() << "accepted an SVO with " << needle;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  rejects([](test::BuiltSvo& v) { v.leaves[0] = 1u << 20; }, "slot");
  rejects([](test::BuiltSvo& v) { v.leaves[2] = vr_svo_lod_pack(0, 9); }, "LOD difference 9");
  rejects([](test::BuiltSvo& v) { v.leaves[3] = std::bit_cast<vr_uint>(1.5f); }, "factor");
  rejects([](test::BuiltSvo& v) { v.nodes[1] = vr_svo_child_word(VR_SVO_CHILD_NODE, 999); },
          "node 999");
  rejects([](test::BuiltSvo& v) { v.nodes[1] = vr_svo_child_word(VR_SVO_CHILD_NODE, 0); },
          "reached twice");
  rejects([](test::BuiltSvo& v) { v.nodes[2] = vr_svo_child_word(VR_SVO_CHILD_UP, 0); }, "word 9");
  rejects([](test::BuiltSvo& v) { v.nodes.pop_back(); }, "node words");
  // A NO_SLOT keyframe is fine where its weight is zero.
  auto only_a = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), VR_ATLAS_NO_SLOT, 0, 0, 0.0f};
  });
  EXPECT_NO_THROW(cpu_render::render_svo(only_a.view(), atlas, s.geometry, camera, transfer));
  cpu_render::RenderOptions bad;
  bad.step = 0;
  EXPECT_THROW(cpu_render::render_svo(good.view(), atlas, s.geometry, camera, transfer, bad),
               std::invalid_argument);
  cpu_render::RenderOptions too_coarse;
  too_coarse.max_step_doublings = 17;
  EXPECT_THROW(cpu_render::render_svo(good.view(), atlas, s.geometry, camera, transfer, too_coarse),
               std::invalid_argument);
  too_coarse.max_step_doublings = 16;
  EXPECT_NO_THROW(
      cpu_render::render_svo(good.view(), atlas, s.geometry, camera, transfer, too_coarse));
  DenseLevel mislabelled = s.dense(1, 0);
  mislabelled.level = 1;  // level 0's dims
  EXPECT_THROW(cpu_render::render_reference(s.dense(0, finest), mislabelled, 0.5f, s.geometry,
                                            camera, transfer),
               std::invalid_argument);
}

TEST(CpuRender, CameraInsideTheVolume) {
  // The eye inside the box: rays start at the eye, both renderers agree.
  const Scene& s = elongated();
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  auto camera = test_camera(s);
  camera.distance = 20;
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  const auto transfer = test_transfer(s);
  const RgbaImage got = cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer);
  const RgbaImage want = cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), 0.5f,
                                                      s.geometry, camera, transfer);
  EXPECT_GT(drawn_fraction(want), 0.9);
  EXPECT_LE(difference(got, want), exact_tolerance);
}

TEST(CpuRender, DegenerateCameraDrawsNothing) {
  // Looking straight down, where the orbit camera's right vector is (nearly) undefined: the
  // renderer returns an image; it never hangs on rays without a finite segment.
  const Scene& s = elongated();
  const std::uint32_t finest = s.geometry.levels - 1;
  auto camera = test_camera(s, 8, 8);
  camera.elevation = std::numbers::pi / 2;
  const RgbaImage image = cpu_render::render_reference(s.dense(0, finest), s.dense(1, finest), 0.5f,
                                                       s.geometry, camera, test_transfer(s));
  EXPECT_EQ(image.width, 8);
}

TEST(CpuRender, WritesAPng) {
  // A 96³ cube of smooth value noise (3 levels), the "turbulence" preset, through the SVO.
  const auto scene = make_scene({96, 96, 96}, datasets::AnalyticField::noise);
  const Scene& s = *scene;
  const CpuAtlas atlas = s.exact_atlas();
  const std::uint32_t finest = s.geometry.levels - 1;
  const auto svo = build_uniform_svo(s.levels, finest, [&](std::uint32_t l, Coord c) {
    return LeafSpec{s.slot(0, l, c), s.slot(1, l, c), 0, 0, 0.5f};
  });
  auto camera = player::OrbitCamera::framing({96, 96, 96}, 256, 256);
  camera.distance *= 0.75;
  const auto transfer = TransferFunction::preset("turbulence", s.lo, s.hi);
  cpu_render::RenderOptions options;
  options.background = {0.08f, 0.08f, 0.1f};
  const RgbaImage image =
      cpu_render::render_svo(svo.view(), atlas, s.geometry, camera, transfer, options);
  EXPECT_GT(drawn_fraction(image), 0.05);
  test::TempDir dir("cpu_render");
  cpu_render::write_png(dir / "frame.png", image);
  const image::Image back = image::read_png(dir / "frame.png");
  EXPECT_EQ(back.width, 256);
  EXPECT_EQ(back.height, 256);
  EXPECT_EQ(back.channels, 3);
  EXPECT_EQ(back.pixels, cpu_render::to_image(image).pixels);
  // VOLREEL_CPU_RENDER_PNG=path keeps a copy to look at.
  if (const char* keep = std::getenv("VOLREEL_CPU_RENDER_PNG")) cpu_render::write_png(keep, image);
}

TEST(CpuRenderAtlas, StoresAndSamples) {
  CpuAtlas atlas(3);
  std::vector<float> brick(atlas.slot_values());
  for (std::size_t i = 0; i < brick.size(); ++i) brick[i] = float(i % 36);  // value = x
  atlas.store(2, brick);
  EXPECT_FLOAT_EQ(atlas.sample(2, 10.5f, 3.5f, 7.5f), 10.0f);  // texel centre
  EXPECT_FLOAT_EQ(atlas.sample(2, 10.75f, 3.5f, 7.5f), 10.25f);
  EXPECT_FLOAT_EQ(atlas.sample(2, 0.0f, 3.5f, 7.5f), 0.0f);  // clamped to the edge
  EXPECT_FLOAT_EQ(atlas.sample(1, 10.5f, 3.5f, 7.5f), 0.0f);
  EXPECT_THROW(atlas.store(3, brick), std::out_of_range);
  EXPECT_THROW(atlas.store(0, std::span<const float>(brick).first(10)), std::invalid_argument);
  // A constant payload (4 bytes) through the decoder.
  const float value = 2.5f;
  std::array<std::byte, 4> payload;
  std::memcpy(payload.data(), &value, 4);
  atlas.decode_into(0, payload, format::Codec::ksvd, 0, format::AtomTable{});
  EXPECT_FLOAT_EQ(atlas.sample(0, 17.0f, 17.0f, 17.0f), 2.5f);
}

}  // namespace
}  // namespace volreel
