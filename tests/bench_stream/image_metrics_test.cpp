// image_metrics_test.cpp: the image metrics of `volreel bench stream` beyond PSNR and SSIM on
// hand-made images — the level-of-detail boundary pixels (Chebyshev radius, 255 as no level,
// agreement with a direct search on a random map), the seam error over them, the popping between
// consecutive frames (zero when the streamed image moves as the truth does, the RMS of a jump
// otherwise) — and their run averages, JSON keys and CSV columns.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "../test_util.hpp"
#include "volreel/stream_bench/run_report.hpp"
#include "volreel/stream_bench/run_summary.hpp"

namespace volreel {
namespace {

using stream_bench::FrameRecord;
using stream_bench::RunResult;

constexpr std::uint8_t none = 255;

/// A width × height RGB image, every channel of every pixel `value`.
image::Image rgb(int width, int height, std::uint8_t value) {
  image::Image im;
  im.width = width;
  im.height = height;
  im.channels = 3;
  im.pixels.assign(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3, value);
  return im;
}

/// Sets every channel of pixel (x, y).
void set(image::Image& im, int x, int y, std::uint8_t r, std::uint8_t g, std::uint8_t b) {
  const auto p = 3 * (static_cast<std::size_t>(y) * static_cast<std::size_t>(im.width) +
                      static_cast<std::size_t>(x));
  im.pixels[p] = r;
  im.pixels[p + 1] = g;
  im.pixels[p + 2] = b;
}

/// The boundary pixels' positions as "x,y" strings, row by row.
std::vector<std::string> positions(const std::vector<std::uint8_t>& boundary, int width) {
  std::vector<std::string> out;
  for (std::size_t p = 0; p < boundary.size(); ++p)
    if (boundary[p])
      out.push_back(std::to_string(static_cast<int>(p) % width) + "," +
                    std::to_string(static_cast<int>(p) / width));
  return out;
}

TEST(StreamBenchLodBoundary, TwoLevelsSideBySideWithinTheRadius) {
  // Columns 0-3 at level 1, columns 4-7 at level 2, three rows.
  const int w = 8, h = 3;
  std::vector<std::uint8_t> map(w * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) map[static_cast<std::size_t>(y * w + x)] = x < 4 ? 1 : 2;
  const auto columns = [&](int radius) {
    const std::vector<std::uint8_t> b = stream_bench::lod_boundary(map, w, h, radius);
    std::string cols;
    for (int x = 0; x < w; ++x) {
      for (int y = 1; y < h; ++y)  // every row the same
        EXPECT_EQ(b[static_cast<std::size_t>(y * w + x)], b[static_cast<std::size_t>(x)]);
      cols += b[static_cast<std::size_t>(x)] ? '1' : '0';
    }
    return cols;
  };
  EXPECT_EQ(columns(2), "00111100");
  EXPECT_EQ(columns(1), "00011000");
  EXPECT_EQ(columns(0), "00000000");
  EXPECT_EQ(columns(5), "11111111");
  // No level (255) beside a level is no boundary.
  for (int y = 0; y < h; ++y)
    for (int x = 4; x < w; ++x) map[static_cast<std::size_t>(y * w + x)] = none;
  EXPECT_EQ(columns(2), "00000000");
}

TEST(StreamBenchLodBoundary, ChebyshevNeighbourhoodAndNoLevelPixels) {
  // Level 1 everywhere but one pixel at level 3 in the middle and one without a level.
  const int w = 11, h = 11;
  std::vector<std::uint8_t> map(w * h, 1);
  map[5 * w + 5] = 3;
  map[3 * w + 4] = none;
  const std::vector<std::uint8_t> b = stream_bench::lod_boundary(map, w, h, 2);
  const std::vector<std::string> got = positions(b, w);
  // The 5×5 square around (5, 5), corners included (Chebyshev distance 2), without (4, 3).
  std::vector<std::string> want;
  for (int y = 3; y <= 7; ++y)
    for (int x = 3; x <= 7; ++x)
      if (!(x == 4 && y == 3)) want.push_back(std::to_string(x) + "," + std::to_string(y));
  EXPECT_EQ(got, want);
}

TEST(StreamBenchLodBoundary, AgreesWithADirectSearchOnARandomMap) {
  const int w = 23, h = 17;
  std::vector<std::uint8_t> map(static_cast<std::size_t>(w * h));
  std::uint32_t state = 12345;
  for (std::uint8_t& v : map) {
    state = state * 1664525u + 1013904223u;
    // Mostly large regions would hide mistakes; a few values and many 255s test both tests.
    const std::uint32_t k = (state >> 24) % 5;
    v = k == 4 ? none : static_cast<std::uint8_t>(k);
  }
  for (int radius = 0; radius <= 3; ++radius) {
    const std::vector<std::uint8_t> b = stream_bench::lod_boundary(map, w, h, radius);
    std::size_t count = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::uint8_t v = map[static_cast<std::size_t>(y * w + x)];
        bool want = false;
        for (int yy = y - radius; yy <= y + radius; ++yy)
          for (int xx = x - radius; xx <= x + radius; ++xx) {
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            const std::uint8_t u = map[static_cast<std::size_t>(yy * w + xx)];
            want = want || (v != none && u != none && u != v);
          }
        EXPECT_EQ(b[static_cast<std::size_t>(y * w + x)] != 0, want)
            << "radius " << radius << " at " << x << "," << y;
        count += want ? 1 : 0;
      }
    if (radius > 0) {
      EXPECT_GT(count, 0u);
    }
  }
}

TEST(StreamBenchLodBoundary, RefusesAMapOfTheWrongSize) {
  const std::vector<std::uint8_t> map(5, 1);
  EXPECT_THROW(stream_bench::lod_boundary(map, 2, 3), std::invalid_argument);
  EXPECT_THROW(stream_bench::lod_boundary(map, 5, 1, -1), std::invalid_argument);
}

TEST(StreamBenchSeam, RmsOverTheBoundaryPixelsOnly) {
  // 4 × 1 pixels at levels 1 1 2 2: with radius 1 the middle two are the boundary.
  const image::Image reference = rgb(4, 1, 100);
  image::Image streamed = reference;
  set(streamed, 0, 0, 200, 0, 0);      // far from the seam: not counted
  set(streamed, 1, 0, 106, 100, 100);  // error (6, 0, 0)
  set(streamed, 2, 0, 100, 100, 94);   // error (0, 0, −6)
  set(streamed, 3, 0, 0, 255, 0);      // far from the seam: not counted
  const std::vector<std::uint8_t> map = {1, 1, 2, 2};
  // The step of the error between pixels 1 and 2: (6, 0, 6).
  EXPECT_DOUBLE_EQ(stream_bench::seam_rms(reference, streamed, map, 1), std::sqrt(72.0 / 3.0));
  // Radius 2 (the default) reaches every pixel: the steps 0→1 (94, −100, −100), 1→2 and 2→3
  // (100, −155, 94).
  const double all = (94.0 * 94 + 2 * 100.0 * 100 + 72 + 100.0 * 100 + 155.0 * 155 + 94.0 * 94) / 9;
  EXPECT_DOUBLE_EQ(stream_bench::seam_rms(reference, streamed, map), std::sqrt(all));
  // An error that is the same on both sides of the boundary is no seam.
  image::Image offset = reference;
  for (auto& v : offset.pixels) v = static_cast<std::uint8_t>(v + 20);
  EXPECT_DOUBLE_EQ(stream_bench::seam_rms(reference, offset, map), 0.0);
  // Neighbours below count too: a 1 × 2 image at levels 1 and 2.
  image::Image column = rgb(1, 2, 100), column_streamed = column;
  set(column_streamed, 0, 1, 110, 100, 100);
  const std::vector<std::uint8_t> column_map = {1, 2};
  EXPECT_DOUBLE_EQ(stream_bench::seam_rms(column, column_streamed, column_map),
                   std::sqrt(100.0 / 3.0));
  // No boundary: NaN.
  EXPECT_TRUE(std::isnan(stream_bench::seam_rms(reference, streamed, map, 0)));
  const std::vector<std::uint8_t> flat = {2, 2, 2, 2}, lone = {none, 1, none, none};
  EXPECT_TRUE(std::isnan(stream_bench::seam_rms(reference, streamed, flat)));
  EXPECT_TRUE(std::isnan(stream_bench::seam_rms(reference, streamed, lone)));
  // No map: NaN; a map of the wrong size or images that differ: an error.
  EXPECT_TRUE(std::isnan(stream_bench::seam_rms(reference, streamed, {})));
  const std::vector<std::uint8_t> short_map = {1, 2};
  EXPECT_THROW(stream_bench::seam_rms(reference, streamed, short_map), std::invalid_argument);
  EXPECT_THROW(stream_bench::seam_rms(reference, rgb(2, 2, 100), map), std::invalid_argument);
}

/// A 8 × 2 ground truth with a bright bar in column `x`.
image::Image bar(int x) {
  image::Image im = rgb(8, 2, 50);
  for (int y = 0; y < 2; ++y) set(im, x, y, 200, 180, 160);
  return im;
}

TEST(StreamBenchPopping, ZeroWhenTheImageMovesWithTheTruthAndTheRmsOfAJump) {
  // The streamed frames are the truth plus a constant error, moving as the truth moves.
  std::vector<image::Image> truth, streamed;
  for (int t = 0; t < 3; ++t) {
    truth.push_back(bar(2 + t));
    image::Image s = truth.back();
    for (std::uint8_t& v : s.pixels) v = static_cast<std::uint8_t>(v + 10);
    streamed.push_back(s);
  }
  EXPECT_DOUBLE_EQ(stream_bench::popping_rms(truth[0], streamed[0], truth[1], streamed[1]), 0.0);
  EXPECT_DOUBLE_EQ(stream_bench::popping_rms(truth[1], streamed[1], truth[2], streamed[2]), 0.0);
  // The image changing while the truth stays (data still moving is not the image's excuse): the
  // change itself, not compared with anything. A pixel jumps by 30 in every channel: 6 of 48
  // values (two pixels) off by 30.
  image::Image jumped = streamed[2];
  for (int y = 0; y < 2; ++y) set(jumped, 0, y, 90, 90, 90);  // 60 + 30
  EXPECT_DOUBLE_EQ(stream_bench::popping_rms(truth[2], streamed[2], truth[2], jumped),
                   std::sqrt(6.0 * 900 / 48));
  // The same jump while the truth moves: the truth's own change cancels.
  EXPECT_DOUBLE_EQ(stream_bench::popping_rms(truth[1], streamed[1], truth[2], jumped),
                   std::sqrt(6.0 * 900 / 48));
  // A streamed image that stays while the truth moves pops by the truth's change.
  const double moved = std::sqrt((2 * (150.0 * 150 + 130.0 * 130 + 110.0 * 110)) * 2 / 48);
  EXPECT_DOUBLE_EQ(stream_bench::popping_rms(truth[0], streamed[0], truth[1], streamed[0]), moved);
  // Frames of different sizes are no pair; a frame whose images differ is an error.
  EXPECT_TRUE(
      std::isnan(stream_bench::popping_rms(rgb(4, 4, 1), rgb(4, 4, 2), truth[0], streamed[0])));
  EXPECT_THROW(stream_bench::popping_rms(truth[0], streamed[0], truth[1], rgb(4, 4, 0)),
               std::invalid_argument);
}

TEST(StreamBenchPopping, ImageChangeIsTheRmsOfTheDifference) {
  const image::Image a = bar(2);
  image::Image b = a;
  EXPECT_DOUBLE_EQ(stream_bench::image_change_rms(a, b), 0.0);
  set(b, 0, 0, 80, 80, 80);  // one pixel's 3 of 48 values change by 30 (from 50)
  EXPECT_DOUBLE_EQ(stream_bench::image_change_rms(a, b), std::sqrt(3.0 * 900 / 48));
  EXPECT_TRUE(std::isnan(stream_bench::image_change_rms(a, rgb(4, 4, 1))));
  EXPECT_TRUE(std::isnan(stream_bench::image_change_rms(image::Image{}, image::Image{})));
}

/// A frame at `time` with `uploads` bricks uploaded, its popping and seam error.
FrameRecord frame(double time, std::size_t uploads, double popping, double seam) {
  FrameRecord f;
  f.time = time;
  f.stats.target_nodes = 1;
  f.stats.uploads = uploads;
  f.popping = popping;
  f.seam = seam;
  f.psnr = 30;
  return f;
}

TEST(StreamBenchPopping, RunAveragesJsonAndCsv) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  RunResult r;
  r.name = "patent";
  // The first frame's popping is left out even when set; frame 3 has no pair (NaN).
  r.frames = {frame(0.0, 5, 50, nan),  frame(0.1, 2, 4, 1.5), frame(0.2, 0, 1, nan),
              frame(0.3, 3, nan, 2.5), frame(0.4, 1, 8, 3.5), frame(0.5, 0, 3, nan)};
  stream_bench::summarize(r, {});
  // Quadratic means.
  EXPECT_DOUBLE_EQ(r.mean_popping, std::sqrt((16.0 + 64) / 2));
  EXPECT_DOUBLE_EQ(r.max_popping, 8);
  EXPECT_EQ(r.popping_frames, 2u);
  EXPECT_DOUBLE_EQ(r.mean_popping_all, std::sqrt((16.0 + 1 + 64 + 9) / 4));
  EXPECT_DOUBLE_EQ(r.mean_seam, (1.5 + 2.5 + 3.5) / 3);
  EXPECT_EQ(r.seam_frames, 3u);

  const nlohmann::json j = stream_bench::summary_json(r);
  EXPECT_DOUBLE_EQ(j["mean_popping"].get<double>(), std::sqrt(40.0));
  EXPECT_DOUBLE_EQ(j["max_popping"].get<double>(), 8);
  EXPECT_DOUBLE_EQ(j["mean_popping_all"].get<double>(), std::sqrt(22.5));
  EXPECT_EQ(j["popping_frames"], 2u);
  EXPECT_DOUBLE_EQ(j["mean_seam"].get<double>(), 2.5);
  EXPECT_EQ(j["seam_frames"], 3u);

  test::TempDir dir("stream-bench-metrics-csv");
  stream_bench::write_csv(dir / "run.csv", r, {});
  std::ifstream in(dir / "run.csv");
  std::vector<std::vector<std::string>> cells;
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> row;
    std::size_t start = 0;
    for (std::size_t comma; (comma = line.find(',', start)) != std::string::npos; start = comma + 1)
      row.push_back(line.substr(start, comma - start));
    row.push_back(line.substr(start));
    cells.push_back(row);
  }
  ASSERT_EQ(cells.size(), 7u);
  std::size_t popping = 0, seam = 0;
  for (std::size_t c = 0; c < cells[0].size(); ++c) {
    popping = cells[0][c] == "popping" ? c : popping;
    seam = cells[0][c] == "seam" ? c : seam;
  }
  ASSERT_GT(popping, 0u);
  ASSERT_GT(seam, 0u);
  for (const auto& row : cells) ASSERT_EQ(row.size(), cells[0].size());
  EXPECT_EQ(cells[2][popping], "4.0000");
  EXPECT_EQ(cells[2][seam], "1.5000");
  EXPECT_EQ(cells[4][popping], "nan");
  EXPECT_EQ(cells[3][seam], "nan");

  // A seek at 0.35 s: its first frame (0.4 s) is a cut, left out of both popping figures.
  RunResult seeking = r;
  stream_bench::summarize(seeking, {{0.35, 7.0}});
  EXPECT_DOUBLE_EQ(seeking.mean_popping, 4.0);
  EXPECT_DOUBLE_EQ(seeking.max_popping, 4.0);
  EXPECT_EQ(seeking.popping_frames, 1u);
  EXPECT_DOUBLE_EQ(seeking.mean_popping_all, std::sqrt((16.0 + 1 + 9) / 3));

  // A frame without uploads whose leaves still blend (a fade in progress) counts as well.
  RunResult fading = r;
  fading.frames[2].stats.blended_leaves = 2;
  stream_bench::summarize(fading, {});
  EXPECT_DOUBLE_EQ(fading.mean_popping, std::sqrt((16.0 + 1 + 64) / 3));
  EXPECT_EQ(fading.popping_frames, 3u);

  // Working-set popping: over the frames popping_all counts (a frame of no change counts 0; the
  // first frame, cuts and frames after holes left out), NaN ones (not measured) not at all.
  EXPECT_TRUE(std::isnan(r.mean_working_set_popping));
  EXPECT_EQ(r.working_set_popping_frames, 0u);
  RunResult measured = r;
  const double ws[] = {9, 2, 0, 6, 4, nan};
  for (std::size_t i = 0; i < 6; ++i) measured.frames[i].working_set_popping = ws[i];
  measured.frames[2].stats.holes = 1;  // frame 3 follows a frame with holes
  stream_bench::summarize(measured, {});
  EXPECT_DOUBLE_EQ(measured.mean_working_set_popping, std::sqrt((4.0 + 0 + 16) / 3));
  EXPECT_DOUBLE_EQ(measured.max_working_set_popping, 4);
  EXPECT_EQ(measured.working_set_popping_frames, 3u);
  const nlohmann::json jm = stream_bench::summary_json(measured);
  EXPECT_DOUBLE_EQ(jm["max_working_set_popping"].get<double>(), 4);
  EXPECT_EQ(jm["working_set_popping_frames"], 3u);

  // Frame 1's predecessor had holes (nothing drawn there yet): frame 1 shows an appearance and is
  // left out too.
  RunResult appearing = r;
  appearing.frames[0].stats.holes = 3;
  stream_bench::summarize(appearing, {});
  EXPECT_DOUBLE_EQ(appearing.mean_popping, 8.0);
  EXPECT_EQ(appearing.popping_frames, 1u);
  EXPECT_DOUBLE_EQ(appearing.mean_popping_all, std::sqrt((1.0 + 64 + 9) / 3));

  // No frame with uploads, no seam: NaN, and null in the JSON.
  RunResult quiet;
  quiet.frames = {frame(0.0, 0, nan, nan), frame(0.1, 0, 2, nan)};
  stream_bench::summarize(quiet, {});
  EXPECT_TRUE(std::isnan(quiet.mean_popping));
  EXPECT_TRUE(std::isnan(quiet.max_popping));
  EXPECT_DOUBLE_EQ(quiet.mean_popping_all, 2);
  EXPECT_TRUE(std::isnan(quiet.mean_seam));
  EXPECT_EQ(quiet.seam_frames, 0u);
  const nlohmann::json q = stream_bench::summary_json(quiet);
  EXPECT_TRUE(q["mean_popping"].is_null());
  EXPECT_TRUE(q["max_popping"].is_null());
  EXPECT_TRUE(q["mean_seam"].is_null());
}

}  // namespace
}  // namespace volreel
