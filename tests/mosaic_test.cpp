// mosaic_test.cpp: `volreel gen mosaic` (datasets/mosaic.hpp): a mosaic of a small real container
// is a valid container (verify_container finds nothing), its keyframes store every node and the
// frames between fewer, its bricks are the pool's bytes, and bad requests are refused by name.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <span>

#include "keyframe_series.hpp"
#include "test_util.hpp"
#include "volreel/datasets/mosaic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/encoder/series_encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel {
namespace {

namespace fs = std::filesystem;

/// A 2-frame ksvd (DCT dictionary) or zfp container of 70×40×40 voxels at dir/src.vreel.
fs::path source_container(const fs::path& dir, format::Codec codec) {
  test::write_keyframe_series(dir / "series", Dims{70, 40, 40}, 2);
  encoder::EncodeJob job;
  job.coding.codec = codec;
  if (codec == format::Codec::ksvd) {
    format::write_dictionary_file(dir / "dct.bin", format::dct_dictionary(6, "test"));
    job.coding.tolerance = 2e-3;
    job.dictionary_file = dir / "dct.bin";
  } else {
    job.coding.zfp_accuracy = 1e-3;
  }
  encoder::encode_series(*datasets::open_series(dir / "series"), dir / "src.vreel", job);
  return dir / "src.vreel";
}

datasets::MosaicParams mosaic_params(const fs::path& source, const fs::path& out) {
  datasets::MosaicParams p;
  p.source = source;
  p.out = out;
  p.dims = {80, 70, 100};
  p.frames = 11;
  p.max_keyframe_gap = 4;
  p.program_version = "test";
  return p;
}

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}

void check_mosaic(format::Codec codec) {
  test::TempDir dir(codec == format::Codec::ksvd ? "mosaic-ksvd" : "mosaic-zfp");
  const fs::path src = source_container(dir.path(), codec);
  const fs::path out = dir / "m.vreel";
  const datasets::MosaicReport report = datasets::write_mosaic(mosaic_params(src, out));

  const std::vector<std::string> problems = format::verify_container(out);
  EXPECT_TRUE(problems.empty()) << problems.front();

  const format::Container source(src), c(out);
  const format::Manifest& m = c.manifest();
  EXPECT_EQ(m.dims, (std::array<std::uint32_t, 3>{80, 70, 100}));
  EXPECT_EQ(c.frame_count(), 11u);
  EXPECT_EQ(m.max_keyframe_gap, 4u);
  EXPECT_TRUE(m.complete);
  EXPECT_EQ(m.codec, codec);
  EXPECT_EQ(m.tolerance, source.manifest().tolerance);
  EXPECT_EQ(m.zfp_accuracy, source.manifest().zfp_accuracy);
  EXPECT_EQ(m.value_min, source.manifest().value_min);
  EXPECT_EQ(m.value_max, source.manifest().value_max);
  EXPECT_NE(m.container_id, source.manifest().container_id);
  EXPECT_EQ(c.atoms().count, source.atoms().count);
  EXPECT_TRUE(std::equal(c.atoms().values.begin(), c.atoms().values.end(),
                         source.atoms().values.begin(), source.atoms().values.end()));
  // 80×70×100: grids 3×3×3 (27), 2×2×2 (8), the root.
  EXPECT_EQ(report.levels, 3u);
  EXPECT_EQ(report.nodes_per_frame, 36u);
  EXPECT_EQ(report.container_bytes, c.total_bytes());

  const std::vector<datasets::MosaicBrick> pool = datasets::mosaic_pool(src, 8);
  ASSERT_FALSE(pool.empty());
  EXPECT_LE(pool.size(), 8u);
  EXPECT_EQ(report.pool_brick_bytes.size(), pool.size());
  for (std::size_t i = 1; i < pool.size(); ++i)
    EXPECT_LE(pool[i - 1].payload.size(), pool[i].payload.size()) << "the smallest first";
  // The pool brick whose bytes these are, or pool.size().
  const auto pool_index = [&](std::span<const std::byte> bytes) {
    for (std::size_t i = 0; i < pool.size(); ++i)
      if (std::equal(bytes.begin(), bytes.end(), pool[i].payload.begin(), pool[i].payload.end()))
        return i;
    return pool.size();
  };
  for (std::size_t i = 0; i < pool.size(); ++i)
    EXPECT_EQ(pool_index(pool[i].payload), i) << "pool bricks are distinct";

  std::uint64_t bricks = 0;
  std::size_t frames_with_fewer = 0;
  std::set<std::size_t> used;
  std::vector<std::size_t> frame0, frame8;
  for (std::size_t t = 0; t < c.frame_count(); ++t) {
    const format::FrameFile f = c.open_frame(t);
    const format::FrameView& v = f.view();
    EXPECT_EQ(v.node_count(), 36u);
    bricks += v.brick_count();
    if (t % 4 == 0 || t == 10)
      EXPECT_EQ(v.brick_count(), v.node_count()) << "keyframe " << t << " stores every node";
    else if (v.brick_count() < v.node_count())
      ++frames_with_fewer;
    for (std::uint32_t i = 0; i < v.node_count(); ++i) {
      if (!v.has_brick(i)) continue;
      const std::size_t k = pool_index(v.checked_brick_bytes(v.node(i).brick));
      EXPECT_LT(k, pool.size()) << "frame " << t << " node " << i << ": not a pool brick";
      used.insert(k);
      if (t == 0) frame0.push_back(k);
      if (t == 8) frame8.push_back(k);
    }
  }
  EXPECT_EQ(bricks, report.bricks);
  EXPECT_GE(frames_with_fewer, 5u) << "of the 7 frames between keyframes";
  EXPECT_GT(used.size(), 1u) << "content varies in space";
  EXPECT_NE(frame0, frame8) << "content varies between keyframe stretches";

  // A step between keyframes decodes as the player draws it (interpolated nodes included).
  format::TimeStepDecoder steps(c);
  const format::LevelVolume v = steps.decode(5, m.levels - 1);
  EXPECT_EQ(v.data.size(), std::size_t{80} * 70 * 100);
}

TEST(Mosaic, KsvdMosaicIsAValidContainerOfThePoolsBricks) {
  check_mosaic(format::Codec::ksvd);
}

TEST(Mosaic, ZfpMosaicIsAValidContainerOfThePoolsBricks) {
  check_mosaic(format::Codec::zfp);
}

TEST(Mosaic, EveryFrameStoresEveryNodeWithGapOne) {
  test::TempDir dir("mosaic-gap1");
  const fs::path src = source_container(dir.path(), format::Codec::zfp);
  datasets::MosaicParams p = mosaic_params(src, dir / "m.vreel");
  p.max_keyframe_gap = 1;
  p.frames = 3;
  p.pool_bricks = 1;
  p.threads = 1;
  const auto report = datasets::write_mosaic(p);
  EXPECT_EQ(report.bricks, 3u * 36u);
  EXPECT_EQ(report.pool_brick_bytes.size(), 1u);
  EXPECT_TRUE(format::verify_container(dir / "m.vreel").empty());
}

TEST(Mosaic, RefusesBadRequestsByName) {
  test::TempDir dir("mosaic-errors");
  const fs::path src = source_container(dir.path(), format::Codec::zfp);
  const auto fails_with = [&](datasets::MosaicParams p) {
    return error_of([&] { datasets::write_mosaic(p); });
  };
  datasets::MosaicParams p = mosaic_params(src, dir / "m.vreel");

  p.frames = 0;
  EXPECT_NE(fails_with(p).find("at least 1 frame"), std::string::npos) << fails_with(p);
  p = mosaic_params(src, dir / "m.vreel");
  p.dims = {0, 10, 10};
  EXPECT_NE(fails_with(p).find("size"), std::string::npos) << fails_with(p);
  p = mosaic_params(src, dir / "m.vreel");
  p.max_keyframe_gap = 0;
  EXPECT_NE(fails_with(p).find("keyframe gap"), std::string::npos) << fails_with(p);
  p = mosaic_params(dir / "series", dir / "m.vreel");
  EXPECT_NE(fails_with(p).find("not a volreel container"), std::string::npos) << fails_with(p);
  p = mosaic_params(dir / "nothing.vreel", dir / "m.vreel");
  EXPECT_NE(fails_with(p).find("not a volreel container"), std::string::npos) << fails_with(p);
  p = mosaic_params(src, dir / "m.vreel");
  p.pool_bricks = 0;
  EXPECT_NE(fails_with(p).find("at least 1 brick"), std::string::npos) << fails_with(p);
  EXPECT_FALSE(fs::exists(dir / "m.vreel")) << "a failed mosaic leaves nothing behind";

  // An existing output is never replaced.
  p = mosaic_params(src, dir / "m.vreel");
  datasets::write_mosaic(p);
  const auto before = test::read_bytes(dir / "m.vreel" / "manifest.json");
  EXPECT_NE(fails_with(p).find("already exists"), std::string::npos) << fails_with(p);
  EXPECT_EQ(test::read_bytes(dir / "m.vreel" / "manifest.json"), before);
  p.out = src;
  EXPECT_NE(fails_with(p).find("already exists"), std::string::npos) << fails_with(p);
}

}  // namespace
}  // namespace volreel
