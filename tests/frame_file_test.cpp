// frame_file_test.cpp: the frame file and manifest readers against damaged input — a flipped byte
// in every section and every truncation give a FormatError naming the file and offset, never a
// crash (the suite also runs under AddressSanitizer) — plus the layout's fixed offsets.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "frame_edit.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/container.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel {
namespace {

dictionary::Dictionary small_dictionary() {
  dictionary::Dictionary d;
  d.atoms.resize(216, 32);
  SplitMix64 rng(9);
  for (Eigen::Index i = 0; i < d.atoms.size(); ++i)
    d.atoms.data()[i] = static_cast<float>(rng.normal());
  dictionary::normalize_atoms(d.atoms);
  return d;
}

/// A small frame (2 levels, 5 nodes) of either codec.
std::vector<std::byte> small_frame(format::Codec codec, const dictionary::Dictionary& d) {
  datasets::AnalyticParams p;
  p.field = datasets::AnalyticField::blobs;
  p.dims = {40, 36, 20};
  Volume v(p.dims);
  datasets::analytic_frame(p, 0, v.data);
  encoder::CodingSettings s;
  s.codec = codec;
  s.tolerance = 0.05;
  s.level_tolerance_factor = 1;  // the root brick has codes too (PayloadErrorsNameTheBrick)
  s.zfp_accuracy = 0.05;
  s.value_min = -1;
  s.value_max = 1;
  return encoder::FrameEncoder(codec == format::Codec::ksvd ? &d : nullptr, s).encode(0, v);
}

format::AtomTable table(const dictionary::Dictionary& d) {
  return {{d.atoms.data(), static_cast<std::size_t>(d.atoms.size())},
          static_cast<std::uint32_t>(d.atom_count())};
}

/// Parses, checks the CRC and decodes every brick; returns the error message (empty: accepted).
std::string read_everything(std::span<const std::byte> bytes, const dictionary::Dictionary& d,
                            bool check_crc) {
  try {
    const format::FrameView f(bytes, "frames/000000.vrf");
    if (check_crc) f.check_payload_crc();
    format::validate_payloads(f, table(d));
    for (std::uint32_t l = 0; l < f.level_count(); ++l) format::decode_level(f, l, table(d));
  } catch (const format::FormatError& e) {
    return e.what();
  }
  return {};
}

TEST(FrameLayout, OffsetsAndGeometry) {
  EXPECT_EQ(sizeof(format::FrameHeader), 144u);
  EXPECT_EQ(sizeof(format::Node), 16u);
  EXPECT_EQ(sizeof(format::LevelEntry), 32u);
  EXPECT_EQ(format::morton3(1, 0, 0), 1u);
  EXPECT_EQ(format::morton3(0, 1, 0), 2u);
  EXPECT_EQ(format::morton3(0, 0, 1), 4u);
  EXPECT_EQ(format::morton3(3, 3, 3), 63u);
  const auto g = format::level_geometry({128, 128, 128}, {});
  ASSERT_EQ(g.size(), 3u);  // 4³ -> 2³ -> 1 bricks
  EXPECT_EQ(g[2].grid[0], 4u);
  EXPECT_EQ(g[1].dims[0], 64u);
  EXPECT_EQ(g[0].dims[0], 32u);
  const auto odd = format::level_geometry({35, 34, 1}, {});
  ASSERT_EQ(odd.size(), 2u);
  EXPECT_EQ(odd[0].dims[0], 18u);
  EXPECT_EQ(odd[0].dims[2], 1u);
  // Bricks of 66³ (interior 64): 128³ is 2³ bricks under one root.
  const auto big = format::level_geometry({128, 128, 128}, {66});
  ASSERT_EQ(big.size(), 2u);
  EXPECT_EQ(big[1].grid[0], 2u);
  EXPECT_EQ(big[0].dims[0], 64u);
  EXPECT_EQ(big[0].grid[0], 1u);
  // Little-endian on disk: the magic's bytes and the version's first byte.
  const auto d = small_dictionary();
  const auto bytes = small_frame(format::Codec::ksvd, d);
  EXPECT_EQ(std::memcmp(bytes.data(), "VREELFRM", 8), 0);
  EXPECT_EQ(static_cast<int>(bytes[8]), 10);
  EXPECT_EQ(static_cast<int>(bytes[9]), 0);
}

class DamagedFrame : public ::testing::TestWithParam<format::Codec> {};

TEST_P(DamagedFrame, EveryFlippedByteIsCaught) {
  const auto d = small_dictionary();
  const auto good = small_frame(GetParam(), d);
  ASSERT_EQ(read_everything(good, d, true), "");
  const format::FrameView view(good, "x");
  const std::uint64_t payload = view.header().payload_offset;
  // Every byte of header, level table, node table and brick offsets; payload bytes at a stride
  // (zfp payloads are larger and slower to decode); the CRC.
  const std::size_t stride = GetParam() == format::Codec::ksvd ? 7 : 101;
  for (std::size_t at = 0; at < good.size();
       at += at < payload || at + 4 >= good.size() ? 1u : stride) {
    for (unsigned mask : {0x01u, 0xFFu}) {
      auto bad = good;
      bad[at] ^= static_cast<std::byte>(mask);
      const std::string e = read_everything(bad, d, true);
      ASSERT_NE(e, "") << "byte " << at << " ^ " << int(mask) << " went unnoticed";
      ASSERT_NE(e.find("frames/000000.vrf"), std::string::npos) << e;
      // Without the file CRC, payload validation alone must never crash (ASan checks reads).
      read_everything(bad, d, false);
    }
  }
}

TEST_P(DamagedFrame, EveryTruncationIsCaught) {
  const auto d = small_dictionary();
  const auto good = small_frame(GetParam(), d);
  for (std::size_t size = 0; size < good.size(); size += size < 600 ? 1 : 13) {
    const std::vector<std::byte> cut(good.begin(),
                                     good.begin() + static_cast<std::ptrdiff_t>(size));
    const std::string e = read_everything(cut, d, false);
    ASSERT_NE(e, "") << "truncation to " << size << " bytes went unnoticed";
  }
  // Messages say where and what.
  const std::vector<std::byte> cut(good.begin(), good.begin() + 200);
  const std::string e = read_everything(cut, d, false);
  EXPECT_NE(e.find("offset"), std::string::npos) << e;
  EXPECT_NE(e.find("expected"), std::string::npos) << e;
}

INSTANTIATE_TEST_SUITE_P(Codecs, DamagedFrame,
                         ::testing::Values(format::Codec::ksvd, format::Codec::zfp),
                         [](const auto& param_info) {
                           return param_info.param == format::Codec::ksvd ? std::string("ksvd")
                                                                          : std::string("zfp");
                         });

TEST(DamagedFrame, BrickChecksumsCatchPayloadDamage) {
  const auto d = small_dictionary();
  auto bytes = small_frame(format::Codec::ksvd, d);
  const format::FrameView good(bytes, "x");
  std::uint32_t brick = 0;  // the largest payload
  for (std::uint32_t b = 1; b < good.brick_count(); ++b)
    if (good.brick_bytes(b).size() > good.brick_bytes(brick).size()) brick = b;
  const std::uint64_t at = good.brick_offset(brick) + 40;
  ASSERT_LT(at, good.brick_offset(brick + 1));
  bytes[at] ^= std::byte{0x10};
  const format::FrameView view(bytes, "frames/000000.vrf");  // the index is intact
  try {
    view.checked_brick_bytes(brick);
    ADD_FAILURE() << "a damaged payload was handed out";
  } catch (const format::FormatError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("brick " + std::to_string(brick)), std::string::npos) << m;
    EXPECT_NE(m.find("offset " + std::to_string(good.brick_offset(brick))), std::string::npos) << m;
    EXPECT_NE(m.find("payload corrupt"), std::string::npos) << m;
  }
  std::vector<float> out(view.shape().voxels());
  EXPECT_THROW(format::decode_brick(view, brick, table(d), out), format::FormatError);
  for (std::uint32_t b = 0; b < view.brick_count(); ++b)  // the others still decode
    if (b != brick) {
      EXPECT_NO_THROW(format::decode_brick(view, b, table(d), out));
    }
}

TEST(DamagedFrame, EmptyPayloadsAreErrors) {
  const auto d = small_dictionary();
  std::vector<float> out(format::BrickShape{}.voxels());
  for (const format::Codec codec : {format::Codec::ksvd, format::Codec::zfp})
    EXPECT_THROW(format::decode_payload({}, codec, 1e-3, table(d), {}, out, "x", 0),
                 format::FormatError);
  // A brick size that is not one, or an output of another size, is refused.
  std::vector<std::byte> constant(4);
  const float one = 1.0f;
  std::memcpy(constant.data(), &one, 4);
  EXPECT_NO_THROW(
      format::decode_payload(constant, format::Codec::ksvd, 0, table(d), {}, out, "x", 0));
  EXPECT_THROW(
      format::decode_payload(constant, format::Codec::ksvd, 0, table(d), {40}, out, "x", 0),
      format::FormatError);
  EXPECT_THROW(
      format::decode_payload(constant, format::Codec::ksvd, 0, table(d), {42}, out, "x", 0),
      format::FormatError);
}

TEST(DamagedFrame, AZfpHeaderNamesNoAtomsOrBlocks) {
  const auto d = small_dictionary();
  const std::vector<std::byte> good = small_frame(format::Codec::zfp, d);
  EXPECT_EQ(read_everything(good, d, true), "");
  const auto expect_refused = [&](std::size_t offset, std::uint32_t value,
                                  const std::string& what) {
    std::vector<std::byte> bad = good;
    std::memcpy(bad.data() + offset, &value, 4);
    try {
      const format::FrameView f(bad, "frames/000000.vrf");
      ADD_FAILURE() << "a zfp frame header with " << what << " " << value << " was accepted";
    } catch (const format::FormatError& e) {
      EXPECT_EQ(e.offset(), offset) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expect_refused(offsetof(format::FrameHeader, atom_count), 215, "atom count 0 (zfp)");
  expect_refused(offsetof(format::FrameHeader, block_size), 6, "block size 0 (zfp)");
}

TEST(DamagedFrame, HeaderDimsThatDisagreeWithTheLevelTableAreNamed) {
  // The level table lies under the index CRC and the header's dims do not: where they disagree,
  // the error names the header's dims (offset and value), not the intact level table.
  const auto d = small_dictionary();
  const std::vector<std::byte> good = small_frame(format::Codec::ksvd, d);
  const format::FrameView view(good, "x");
  const std::uint32_t x = view.header().dims[0];
  std::vector<std::byte> bad = good;
  const std::uint32_t wider = x + 1;
  std::memcpy(bad.data() + offsetof(format::FrameHeader, dims), &wider, 4);
  try {
    const format::FrameView f(bad, "frames/000000.vrf");
    ADD_FAILURE() << "dims " << wider << " accepted beside the level table of " << x;
  } catch (const format::FormatError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.offset(), offsetof(format::FrameHeader, dims)) << what;
    EXPECT_NE(what.find("header dims and brick size that give level"), std::string::npos) << what;
    EXPECT_NE(what.find("under a good index CRC"), std::string::npos) << what;
    EXPECT_NE(what.find("found dims " + std::to_string(wider) + "x"), std::string::npos) << what;
  }
}

TEST(DamagedFrame, BricksDecodedTogetherFailAsOneAtATime) {
  // decode_bricks (two payloads' codes read in step) against decode_brick: the same values, and
  // the error of the first bad brick in the order given, whether its CRC or its payload is bad.
  const auto d = small_dictionary();
  auto bytes = small_frame(format::Codec::ksvd, d);
  const auto error_of = [&](const format::FrameView& f, std::vector<std::uint32_t> order) {
    std::vector<std::vector<float>> out(order.size(), std::vector<float>(f.shape().voxels()));
    std::vector<format::BrickToDecode> bricks;
    for (std::size_t i = 0; i < order.size(); ++i) bricks.push_back({&f, order[i], out[i]});
    try {
      format::decode_bricks(bricks, table(d));
    } catch (const format::FormatError& e) {
      return std::string(e.what());
    }
    for (std::size_t i = 0; i < order.size(); ++i) {
      std::vector<float> one(f.shape().voxels());
      format::decode_brick(f, order[i], table(d), one);
      EXPECT_EQ(std::memcmp(one.data(), out[i].data(), 4 * one.size()), 0) << "brick " << order[i];
    }
    return std::string();
  };
  {
    const format::FrameView view(bytes, "x");
    ASSERT_GE(view.brick_count(), 4u);
    EXPECT_EQ(error_of(view, {0, 1, 2, 3}), "");
    EXPECT_EQ(error_of(view, {3, 0, 2}), "");
  }
  // Brick 3's layout word with 0 atom bits (CRCs sealed again), then a byte of brick 1 changed
  // (its CRC no longer matches).
  const format::FrameView sealed(bytes, "x");
  const std::uint64_t word = sealed.brick_offset(3) + 12, byte = sealed.brick_offset(1) + 30;
  vr_uint layout_word;
  std::memcpy(&layout_word, bytes.data() + word, 4);
  layout_word &= ~(0x1Fu << 13);
  std::memcpy(bytes.data() + word, &layout_word, 4);
  test::reseal_frame(bytes);
  bytes[byte] ^= std::byte{0x40};
  const format::FrameView view(bytes, "x");
  std::string one[4];
  for (std::uint32_t b : {1u, 3u}) {
    std::vector<float> out(view.shape().voxels());
    try {
      format::decode_brick(view, b, table(d), out);
    } catch (const format::FormatError& e) {
      one[b] = e.what();
    }
  }
  EXPECT_NE(one[1].find("CRC"), std::string::npos) << one[1];
  EXPECT_NE(one[3].find("atom bits 1..16"), std::string::npos) << one[3];
  EXPECT_EQ(error_of(view, {0, 1, 2, 3}), one[1]);
  EXPECT_EQ(error_of(view, {3, 2, 1, 0}), one[3]);
  EXPECT_EQ(error_of(view, {0, 3, 1}), one[3]);
  EXPECT_EQ(error_of(view, {2, 1}), one[1]);
}

TEST(DamagedFrame, PayloadErrorsNameTheBrick) {
  const auto d = small_dictionary();
  auto bytes = small_frame(format::Codec::ksvd, d);
  const format::FrameView view(bytes, "x");
  // Brick 0's layout word with 0 atom bits: caught by payload validation (not the index CRC).
  vr_uint layout_word;
  const std::uint64_t word = view.brick_offset(0) + 12;
  std::memcpy(&layout_word, bytes.data() + word, 4);
  layout_word &= ~(0x1Fu << 13);
  std::memcpy(bytes.data() + word, &layout_word, 4);
  test::reseal_frame(bytes);
  const std::string e = read_everything(bytes, d, false);
  EXPECT_NE(e.find("atom bits 1..16"), std::string::npos) << e;
  EXPECT_NE(e.find("offset " + std::to_string(word)), std::string::npos) << e;
}

format::Manifest sample_manifest() {
  format::Manifest m;
  m.program_version = "test";
  m.dims = {40, 36, 20};
  m.variable = "blobs";
  m.timestamps = {0, 0.5};
  m.levels = 2;
  m.tolerance = 0.05;
  m.value_min = -1;
  m.value_max = 1;
  m.dictionary = format::ManifestDictionary{"dictionary.bin", 28036, 12345, 32};
  m.frames = {format::ManifestFrame{"frames/000000.vrf", 1000, 1}, std::nullopt};
  m.encoder = nlohmann::json::object();
  m.container_id = 0x0123456789abcdefu;
  return m;
}

TEST(Manifest, RoundTripAndDamage) {
  const auto m = sample_manifest();
  const std::string text = format::manifest_text(format::manifest_to_json(m));
  const auto back = format::manifest_from_json(text, "manifest.json");
  EXPECT_EQ(back.dims, m.dims);
  EXPECT_EQ(back.frames.size(), 2u);
  EXPECT_TRUE(back.frames[0].has_value());
  EXPECT_FALSE(back.frames[1].has_value());
  EXPECT_EQ(back.dictionary->atom_count, 32u);
  // Every flipped byte and every truncation: a FormatError or a valid manifest, nothing else.
  for (std::size_t at = 0; at < text.size(); ++at) {
    std::string bad = text;
    bad[at] = static_cast<char>(bad[at] ^ 0x04);
    try {
      format::manifest_from_json(bad, "manifest.json");
    } catch (const format::FormatError& e) {
      ASSERT_NE(std::string(e.what()).find("manifest.json"), std::string::npos);
    }
  }
  for (std::size_t size = 0; size + 1 < text.size(); ++size)
    EXPECT_THROW(format::manifest_from_json(text.substr(0, size), "manifest.json"),
                 format::FormatError)
        << size;
  // Specific fields.
  auto j = format::manifest_to_json(m);
  j["levels"] = 7;
  try {
    format::manifest_from_json(format::manifest_text(j), "manifest.json");
    FAIL();
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("expected \"levels\": 2 for these dims, found 7"),
              std::string::npos)
        << e.what();
  }
  j = format::manifest_to_json(m);
  j["frames"][0]["file"] = "../../etc/passwd";
  EXPECT_THROW(format::manifest_from_json(format::manifest_text(j), "manifest.json"),
               format::FormatError);
}

/// Values SPEC.md forbids, each with the checksum recomputed, are refused naming the field; an
/// edit without it names the checksum.
TEST(Manifest, ForbiddenValuesAndEditsAreRefused) {
  const auto m = sample_manifest();
  const auto refused = [&](nlohmann::json j, const std::string& needle, bool sign = true) {
    const std::string text = sign ? format::manifest_text(j) : j.dump(1);
    try {
      format::manifest_from_json(text, "manifest.json");
      ADD_FAILURE() << "accepted; expected an error mentioning " << needle;
    } catch (const format::FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  const nlohmann::json good = format::manifest_to_json(m);
  EXPECT_NO_THROW(format::manifest_from_json(format::manifest_text(good), "manifest.json"));
  auto j = good;
  for (int size : {0, 7}) {
    j["block_size"] = size;
    refused(j, "\"block_size\": an integer in 6..6");
  }
  j = good;
  for (double eps : {-1.0, 0.0}) {
    j["tolerance"] = eps;
    refused(j, "\"tolerance\": a positive number");
  }
  j = good;
  j["value_range"] = {-1e39, 1e39};
  refused(j, "\"value_range\"");
  // A short array of numbers is shown: which value was wrong.
  j = good;
  j["dims"] = {0, 64, 40};
  refused(j, "\"dims\": three integers in 1..16777216, found an array of 3 values, [0,64,40]");
  j = good;
  j["value_range"] = {1, 0};
  refused(j, "found an array of 2 values, [1,0]");
  j = good;
  j["timestamps"] = {1.0, 0.5};
  refused(j, "\"timestamps\": increasing numbers");
  j = good;
  j["timestamps"] = {1.0, 1.0};
  refused(j, "\"timestamps\": increasing numbers");
  j = good;
  j.erase("encoder");
  refused(j, "\"encoder\": an object");
  j = good;
  j["encoder"] = "x";
  refused(j, "\"encoder\": an object");
  j = good;
  j["container_id"] = "0000000000000000";
  refused(j, "\"container_id\": a nonzero identifier");
  j = good;
  j["complete"] = !j["complete"].get<bool>();
  refused(j, "manifest_crc32c", false);
  const std::string bom = "\xEF\xBB\xBF" + format::manifest_text(good);
  EXPECT_THROW(format::manifest_from_json(bom, "manifest.json"), format::FormatError);
  // A number beyond double's range is a syntax error with a message, not an escaping exception.
  try {
    format::manifest_from_json(R"({"format": "volreel-container", "x": 1e999})", "manifest.json");
    ADD_FAILURE() << "accepted 1e999";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("not valid JSON: number overflow"), std::string::npos)
        << e.what();
  }
  // 200,000 nested arrays, well formed: refused while parsing, no deep recursion anywhere.
  const std::string deep = std::string(200000, '[') + std::string(200000, ']');
  try {
    format::manifest_from_json(deep, "manifest.json");
    ADD_FAILURE() << "accepted 200,000 nested arrays";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("nested at most 64"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace volreel
