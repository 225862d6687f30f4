// decode_test.cpp: the Vulkan atlas decoder against the CPU reference decoder
// (format::decode_payload), slot by slot, read back from the atlas, for both 16-bit formats:
// thousands of random ksvd bricks (sparsity 0..15, extreme codes and atom indices, both signs),
// constant bricks, zfp bricks through the CPU path; batches that fill the atlas, wrap the staging
// ring and overwrite slots; bad uploads rejected before anything is submitted.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <numeric>
#include <ostream>
#include <stdexcept>
#include <string>
#include <tuple>

#include "brick_samples.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/zfp_stream.hpp"
#include "volreel/vulkan/atlas_decoder.hpp"
#include "vulkan_test_util.hpp"

namespace volreel::vulkan {

// Test names and failure messages show the format's name.
void PrintTo(AtlasFormat format, std::ostream* os) {
  *os << atlas_format_name(format);
}

namespace {

using Payload = std::vector<std::byte>;

/// A zfp payload (fixed accuracy) of a smooth random field, as the encoder writes it.
Payload zfp_payload(SplitMix64& rng, double accuracy, format::BrickShape shape = {}) {
  const std::size_t voxels = shape.voxels(), n = shape.size;
  std::vector<float> field(voxels);
  const double fx = rng.uniform(0.05, 0.3), fy = rng.uniform(0.05, 0.3), phase = rng.uniform(0, 6);
  for (std::size_t i = 0; i < voxels; ++i) {
    const double x = static_cast<double>(i % n), y = static_cast<double>((i / n) % n),
                 z = static_cast<double>(i / (n * n));
    field[i] = static_cast<float>(3 * std::sin(fx * x + phase) * std::cos(fy * y) + 0.05 * z);
  }
  format::ZfpStream zfp(format::ZfpMode::accuracy(accuracy), shape.size, shape.size, shape.size);
  Payload buffer(zfp.maximum_size());
  const std::size_t size = zfp.compress(field.data(), buffer.data(), buffer.size());
  buffer.resize((size + 3) / 4 * 4);
  return buffer;
}

struct Brick {
  Payload payload;
  format::Codec codec = format::Codec::ksvd;
  std::vector<float> expected;  ///< format::decode_payload's output
};

constexpr double zfp_accuracy = 1e-3;

/// Brick i of a reproducible mix: mostly ksvd of the five styles, every 9th a constant, every
/// 13th a zfp brick when `with_zfp`; bricks of `shape`.
Brick make_brick(SplitMix64& rng, std::uint32_t atom_count, const format::AtomTable& atoms,
                 std::size_t i, bool with_zfp, format::BrickShape shape = {}) {
  Brick b;
  if (i % 9 == 4) {
    const float constants[] = {0.0f, -0.0f, 7.25f, -9.5f, static_cast<float>(rng.uniform(-8, 8))};
    b.payload = test::constant_payload(constants[(i / 9) % 5]);
  } else if (with_zfp && i % 13 == 6) {
    b.codec = format::Codec::zfp;
    b.payload = zfp_payload(rng, zfp_accuracy, shape);
  } else {
    b.payload = test::random_ksvd_payload(rng, atom_count, static_cast<int>(i % 5), shape);
  }
  b.expected.resize(shape.voxels());
  format::decode_payload(b.payload, b.codec, zfp_accuracy, atoms, shape, b.expected, "test brick",
                         0);
  return b;
}

BrickUpload upload(const Brick& b, std::uint32_t slot) {
  return {b.payload, b.codec, zfp_accuracy, slot};
}

/// Range of every expected value, widened a little (r16_unorm clamps outside it).
std::pair<float, float> value_range(const std::vector<Brick>& bricks) {
  float lo = 0, hi = 0;
  for (const Brick& b : bricks)
    for (float v : b.expected) {
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
  const float margin = 0.01f * (hi - lo);
  return {lo - margin, hi + margin};
}

/// An atlas of `format` with `slots` slots of `slot_size`³ over the bricks' value range.
AtlasOptions atlas_for(const std::vector<Brick>& bricks, AtlasFormat format, std::size_t slots,
                       std::uint32_t slot_size = 36) {
  const auto [lo, hi] = value_range(bricks);
  AtlasOptions ao;
  ao.format = format;
  ao.slot_size = slot_size;
  ao.max_slots = static_cast<std::uint32_t>(slots);
  ao.value_min = lo;
  ao.value_max = hi;
  return ao;
}

/// Compares read-back slots with the expected bricks; the tolerance is one unit of the 16-bit
/// format at the value (its rounding, with room for the device's float rounding to flip it).
struct Comparison {
  double max_error = 0, max_units = 0;
  std::size_t bad = 0;
};
Comparison compare(const Atlas& atlas, std::span<const float> gpu,
                   const std::vector<const Brick*>& bricks) {
  const std::size_t voxels = std::size_t{atlas.slot_size()} * atlas.slot_size() * atlas.slot_size();
  Comparison c;
  for (std::size_t s = 0; s < bricks.size(); ++s)
    for (std::size_t i = 0; i < voxels; ++i) {
      const float want = bricks[s]->expected[i], got = gpu[s * voxels + i];
      const double unit = 2.0 * static_cast<double>(atlas.rounding_bound(want));
      const double error = std::fabs(double{got} - double{want});
      c.max_error = std::max(c.max_error, error);
      c.max_units = std::max(c.max_units, error / unit);
      if (error > unit + 1e-6 * std::max(1.0, std::fabs(double{want})) && ++c.bad <= 5)
        ADD_FAILURE() << "brick " << s << " voxel " << i << ": GPU " << got << ", CPU " << want
                      << " (unit " << unit << ")";
    }
  return c;
}

using Kernel = DecoderOptions::Kernel;

/// Both atlas formats, each with both decode kernels (image stores; a buffer copied into the
/// slots, the default on lavapipe).
class DecodeTest : public test::VulkanTest,
                   public ::testing::WithParamInterface<std::tuple<AtlasFormat, Kernel>> {
 protected:
  static AtlasFormat format() { return std::get<0>(GetParam()); }
  static Kernel kernel() { return std::get<1>(GetParam()); }
};

// Thousands of bricks, in batches of 1 to 200, through an atlas of 216 slots filled 14 times.
TEST_P(DecodeTest, MatchesTheCpuReferenceDecoder) {
  Context& ctx = context();
  SplitMix64 rng(17);
  const std::uint32_t atom_count = 1024;
  const std::vector<float> atom_values = test::random_atoms(rng, atom_count);
  const format::AtomTable atoms{atom_values, atom_count};
  const std::size_t slots = 216, total = 14 * slots;  // a 6×6×6 atlas filled 14 times
  std::vector<Brick> bricks;
  for (std::size_t i = 0; i < total; ++i)
    bricks.push_back(make_brick(rng, atom_count, atoms, i, false));
  const AtlasOptions ao = atlas_for(bricks, format(), slots);
  Atlas atlas(ctx, ao);
  ASSERT_EQ(atlas.slot_count(), slots);
  DecoderOptions options;
  options.kernel = kernel();
  options.bricks_per_copy = 50;  // batches of 64 to 200 bricks take several copies
  AtlasDecoder decoder(ctx, atlas, options);
  ASSERT_EQ(decoder.kernel(), kernel());
  decoder.set_dictionary(atoms);
  const std::size_t batch_sizes[] = {1, 7, 64, 200, 3, 130};
  Comparison worst;
  for (std::size_t first = 0, round = 0; first < total; first += slots, ++round) {
    // 1. Fill every slot with the next 256 bricks, in batches of varying size.
    std::vector<std::uint32_t> order(slots);
    std::iota(order.begin(), order.end(), 0u);
    std::rotate(order.begin(), order.begin() + static_cast<std::ptrdiff_t>((round * 37) % slots),
                order.end());
    std::vector<const Brick*> in_slot(slots);
    for (std::size_t k = 0, b = 0; k < slots; ++b) {
      std::vector<BrickUpload> batch;
      for (std::size_t n = 0; n < batch_sizes[b % 6] && k < slots; ++n, ++k) {
        in_slot[order[k]] = &bricks[first + k];
        batch.push_back(upload(bricks[first + k], order[k]));
      }
      decoder.submit(batch);
    }
    // 2. Read every slot back.
    std::vector<std::uint32_t> all(slots);
    std::iota(all.begin(), all.end(), 0u);
    const Comparison c = compare(atlas, decoder.read_slots(all), in_slot);
    worst.max_error = std::max(worst.max_error, c.max_error);
    worst.max_units = std::max(worst.max_units, c.max_units);
    ASSERT_EQ(c.bad, 0u) << "round " << round;
  }
  std::printf("%s: %zu bricks, range [%g, %g], largest error %.3g (%.2f units of the format)\n",
              atlas_format_name(format()), total, double{ao.value_min}, double{ao.value_max},
              worst.max_error, worst.max_units);
  EXPECT_EQ(decoder.stats().bricks, total);
}

// A small atlas, a 2-buffer ring of 1 MiB: zfp bricks (186 KB uploaded each) make every submit
// span several staging buffers, and each round overwrites every slot without waiting.
TEST_P(DecodeTest, OverwritesSlotsAndWrapsTheStagingRing) {
  Context& ctx = context();
  SplitMix64 rng(23);
  const std::uint32_t atom_count = 300;
  const std::vector<float> atom_values = test::random_atoms(rng, atom_count);
  const format::AtomTable atoms{atom_values, atom_count};
  const std::size_t slots = 27, rounds = 6;
  std::vector<Brick> bricks;
  for (std::size_t i = 0; i < slots * rounds; ++i)
    bricks.push_back(make_brick(rng, atom_count, atoms, i, true));
  for (std::size_t i = 0; i < slots * rounds; i += 3)  // more zfp bricks
    if (bricks[i].codec == format::Codec::ksvd) {
      bricks[i].codec = format::Codec::zfp;
      bricks[i].payload = zfp_payload(rng, zfp_accuracy);
      format::decode_payload(bricks[i].payload, bricks[i].codec, zfp_accuracy, atoms, {},
                             bricks[i].expected, "test brick", 0);
    }
  Atlas atlas(ctx, atlas_for(bricks, format(), slots));
  ASSERT_EQ(atlas.slot_count(), slots);
  DecoderOptions options;
  options.upload_budget_bytes = 1 << 20;
  options.ring_size = 2;
  options.kernel = kernel();
  AtlasDecoder decoder(ctx, atlas, options);
  decoder.set_dictionary(atoms);
  std::vector<const Brick*> in_slot(slots);
  Ticket previous = 0;
  for (std::size_t r = 0; r < rounds; ++r) {
    std::vector<BrickUpload> batch;
    for (std::size_t s = 0; s < slots; ++s) {
      const std::uint32_t slot = static_cast<std::uint32_t>((s * 7 + r) % slots);
      in_slot[slot] = &bricks[r * slots + s];
      batch.push_back(upload(bricks[r * slots + s], slot));
    }
    const Ticket t = decoder.submit(batch);
    EXPECT_GT(t, previous + 1) << "a round of zfp bricks spans several staging buffers";
    previous = t;
    if (r == 2) {  // one check in the middle, then keep going without waiting
      std::vector<std::uint32_t> all(slots);
      std::iota(all.begin(), all.end(), 0u);
      EXPECT_EQ(compare(atlas, decoder.read_slots(all), in_slot).bad, 0u);
    }
  }
  std::vector<std::uint32_t> all(slots);
  std::iota(all.begin(), all.end(), 0u);
  EXPECT_EQ(compare(atlas, decoder.read_slots(all), in_slot).bad, 0u);
  EXPECT_GT(decoder.stats().submissions, 2 * rounds);
  EXPECT_GT(decoder.stats().uploaded_bytes, std::uint64_t{rounds} * options.upload_budget_bytes);
  // Slot by slot too.
  for (std::uint32_t s : {0u, 13u, 26u}) {
    const std::vector<float> one = decoder.read_slot(s);
    EXPECT_EQ(compare(atlas, one, {in_slot[s]}).bad, 0u);
  }
}

// Bricks of 12³ (8 blocks), 42³ and 66³ (1331 blocks, the largest): ksvd, constant and zfp bricks
// in an atlas of those slots, every kernel.
TEST_P(DecodeTest, EveryBrickSizeMatchesTheCpuReferenceDecoder) {
  Context& ctx = context();
  SplitMix64 rng(29);
  const std::uint32_t atom_count = 500;
  const std::vector<float> atom_values = test::random_atoms(rng, atom_count);
  const format::AtomTable atoms{atom_values, atom_count};
  for (const std::uint32_t size : {12u, 42u, 66u}) {
    SCOPED_TRACE("bricks of " + std::to_string(size) + "^3");
    const format::BrickShape shape{size};
    const std::size_t slots = 8, total = 20;
    std::vector<Brick> bricks;
    for (std::size_t i = 0; i < total; ++i)
      bricks.push_back(make_brick(rng, atom_count, atoms, i, true, shape));
    Atlas atlas(ctx, atlas_for(bricks, format(), slots, size));
    ASSERT_EQ(atlas.slot_count(), slots);
    ASSERT_EQ(atlas.slot_origin(1).x, static_cast<std::int32_t>(size));
    DecoderOptions options;
    options.kernel = kernel();
    options.bricks_per_copy = 3;
    AtlasDecoder decoder(ctx, atlas, options);
    decoder.set_dictionary(atoms);
    std::vector<const Brick*> in_slot(slots);
    for (std::size_t first = 0; first < total; first += slots) {
      std::vector<BrickUpload> batch;
      for (std::size_t k = 0; k < slots && first + k < total; ++k) {
        const auto slot = static_cast<std::uint32_t>((k * 3 + first) % slots);
        in_slot[slot] = &bricks[first + k];
        batch.push_back(upload(bricks[first + k], slot));
      }
      decoder.submit(batch);
      std::vector<std::uint32_t> written;
      for (const BrickUpload& u : batch) written.push_back(u.slot);
      std::vector<const Brick*> expected;
      for (std::uint32_t slot : written) expected.push_back(in_slot[slot]);
      EXPECT_EQ(compare(atlas, decoder.read_slots(written), expected).bad, 0u);
    }
    // A brick whose box of coded blocks is wider than this size's bricks (a larger size's, or a
    // damaged box word) is refused before anything is submitted.
    Payload wrong = test::random_ksvd_payload(rng, atom_count, 1, shape);
    const vr_uint too_wide = vr_make_box(shape.blocks_per_axis() + 1, 1, 1);
    std::memcpy(wrong.data() + 4 * 5, &too_wide, 4);
    const BrickUpload bad{wrong, format::Codec::ksvd, 0, 0};
    const Ticket last = decoder.last_ticket();
    EXPECT_THROW(decoder.submit({&bad, 1}), format::FormatError);
    EXPECT_EQ(decoder.last_ticket(), last);
  }
}

// A brick of 66³ with 63 codes in every block (83,853 codes): more loop iterations than lavapipe
// runs in one shader loop (65,535), so that on a CPU device it is decoded on the CPU and uploaded
// as values, and still matches the reference decoder with every kernel.
TEST_P(DecodeTest, BricksOfManyCodesMatchTheCpuReferenceDecoder) {
  Context& ctx = context();
  SplitMix64 rng(31);
  const std::uint32_t atom_count = 300;
  const std::vector<float> atom_values = test::random_atoms(rng, atom_count);
  const format::AtomTable atoms{atom_values, atom_count};
  const format::BrickShape shape{66};
  format::KsvdPayloadParts parts;
  parts.sparsity.assign(shape.blocks(), 63);
  parts.mean.assign(shape.blocks(), 3);
  parts.dequantization[0] = 0.1f;
  parts.dequantization[1] = 0.01f;
  parts.dequantization[2] = 0.02f;
  parts.mean_bits = 4;
  parts.sparsity_bits = 6;
  parts.coef_bits = 4;
  parts.atom_bits = 9;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    for (std::uint32_t k = 0; k < 63; ++k) {
      parts.atoms.push_back(k + (b % 7) * 30);
      parts.values.push_back(static_cast<std::int32_t>(rng.below(16)) + 1);
    }
  Brick brick;
  brick.payload = format::pack_ksvd_payload(parts);
  brick.expected.resize(shape.voxels());
  format::decode_payload(brick.payload, brick.codec, 0, atoms, shape, brick.expected, "many", 0);
  Atlas atlas(ctx, atlas_for({brick}, format(), 2, shape.size));
  DecoderOptions options;
  options.kernel = kernel();
  AtlasDecoder decoder(ctx, atlas, options);
  decoder.set_dictionary(atoms);
  const BrickUpload u = upload(brick, 1);
  decoder.submit({&u, 1});
  EXPECT_EQ(compare(atlas, decoder.read_slot(1), {&brick}).bad, 0u);
}

INSTANTIATE_TEST_SUITE_P(
    FormatsAndKernels, DecodeTest,
    ::testing::Combine(::testing::Values(AtlasFormat::r16_unorm, AtlasFormat::r16_sfloat),
                       ::testing::Values(Kernel::image_store, Kernel::buffer_copy, Kernel::host)),
    [](const ::testing::TestParamInfo<std::tuple<AtlasFormat, Kernel>>& param) {
      return std::string(std::get<0>(param.param) == AtlasFormat::r16_unorm ? "R16Unorm"
                                                                            : "R16Sfloat") +
             (std::get<1>(param.param) == Kernel::image_store   ? "ImageStore"
              : std::get<1>(param.param) == Kernel::buffer_copy ? "BufferCopy"
                                                                : "Host");
    });

class DecoderTest : public test::VulkanTest {};

TEST_F(DecoderTest, TicketsPollAndWait) {
  Context& ctx = context();
  AtlasOptions ao;
  ao.max_slots = 4;
  ao.value_min = -10;
  ao.value_max = 10;
  Atlas atlas(ctx, ao);
  AtlasDecoder decoder(ctx, atlas);
  EXPECT_TRUE(decoder.poll(0));
  const Payload c = test::constant_payload(2.5f);
  const BrickUpload one{c, format::Codec::ksvd, 0, 3};
  const Ticket a = decoder.submit({&one, 1});
  const Ticket b = decoder.submit({&one, 1});
  EXPECT_EQ(b, a + 1);
  EXPECT_EQ(decoder.submit({}), b);  // an empty batch submits nothing
  decoder.wait(b);
  EXPECT_TRUE(decoder.poll(a));
  EXPECT_TRUE(decoder.poll(b));
  const std::vector<float> v = decoder.read_slot(3);
  for (float x : v) ASSERT_NEAR(x, 2.5f, 20.0 / 65535);
  const std::vector<float> untouched = decoder.read_slot(0);  // cleared to the bottom of the range
  EXPECT_FLOAT_EQ(untouched[0], -10.0f);
}

TEST_F(DecoderTest, RejectsBadUploadsBeforeSubmitting) {
  Context& ctx = context();
  SplitMix64 rng(3);
  AtlasOptions ao;
  ao.max_slots = 8;
  Atlas atlas(ctx, ao);
  AtlasDecoder decoder(ctx, atlas);
  const Payload good = test::random_ksvd_payload(rng, 16, 3);  // atom 15 in most blocks
  const BrickUpload no_dictionary{good, format::Codec::ksvd, 0, 0};
  EXPECT_THROW(decoder.submit({&no_dictionary, 1}), std::invalid_argument);
  const std::vector<float> atom_values = test::random_atoms(rng, 8);
  decoder.set_dictionary({atom_values, 8});
  // Atom indices up to 15 against a dictionary of 8.
  EXPECT_THROW(decoder.submit({&no_dictionary, 1}), format::FormatError);
  const Payload ok = test::random_ksvd_payload(rng, 8, 1);
  Payload short_payload(ok.begin(), ok.end() - 4);
  Payload nan_header = ok;
  const float nan = std::nanf("");
  std::memcpy(nan_header.data() + 8, &nan, 4);
  const Payload nan_constant = test::constant_payload(nan);
  for (const Payload* bad :
       std::initializer_list<const Payload*>{&short_payload, &nan_header, &nan_constant}) {
    const BrickUpload batch[] = {{ok, format::Codec::ksvd, 0, 1},
                                 {*bad, format::Codec::ksvd, 0, 2}};
    EXPECT_THROW(decoder.submit(batch), format::FormatError);
  }
  const BrickUpload outside{ok, format::Codec::ksvd, 0, 8};
  EXPECT_THROW(decoder.submit({&outside, 1}), std::invalid_argument);
  const BrickUpload twice[] = {{ok, format::Codec::ksvd, 0, 5}, {ok, format::Codec::ksvd, 0, 5}};
  EXPECT_THROW(decoder.submit(twice), std::invalid_argument);
  EXPECT_EQ(decoder.last_ticket(), 0u);  // nothing was submitted
  const BrickUpload fine{ok, format::Codec::ksvd, 0, 7};
  EXPECT_EQ(decoder.submit({&fine, 1}), 1u);
}

}  // namespace
}  // namespace volreel::vulkan
