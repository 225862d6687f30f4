// script_test.cpp: parsing of the player's test scripts (volreel/app/script.hpp).
#include <gtest/gtest.h>

#include "volreel/app/script.hpp"
#include "volreel/datasets/volume.hpp"

namespace volreel::app {
namespace {

using Kind = ScriptAction::Kind;

TEST(Script, ParsesTheDocumentedExample) {
  const auto a = parse_script("0.5 key space; 1.0 key right; 1.5 screenshot a.png; 2.0 quit");
  ASSERT_EQ(a.size(), 4u);
  EXPECT_EQ(a[0].kind, Kind::key);
  EXPECT_EQ(a[0].text, "space");
  EXPECT_DOUBLE_EQ(a[0].at_seconds, 0.5);
  EXPECT_EQ(a[0].at_frame, -1);
  EXPECT_EQ(a[1].text, "right");
  EXPECT_EQ(a[2].kind, Kind::screenshot);
  EXPECT_EQ(a[2].text, "a.png");
  EXPECT_EQ(a[3].kind, Kind::quit);
  EXPECT_DOUBLE_EQ(a[3].at_seconds, 2.0);
}

TEST(Script, FramesRelativeTimesCommentsAndArguments) {
  const auto a = parse_script(
      "# a comment line\n"
      "12f seek 2.5   # trailing comment\n"
      "+3f key [\n"
      "+0.25s orbit 30 -10; 1s settle; 2 settle 5; 3 resize 640 480; 4 sse 2; 5 zoom 0.5\n");
  ASSERT_EQ(a.size(), 8u);
  EXPECT_EQ(a[0].at_frame, 12);
  EXPECT_EQ(a[0].kind, Kind::seek);
  EXPECT_DOUBLE_EQ(a[0].x, 2.5);
  EXPECT_FALSE(a[0].relative);
  EXPECT_TRUE(a[1].relative);
  EXPECT_EQ(a[1].at_frame, 3);
  EXPECT_EQ(key_code(a[1].text), key_code("["));
  EXPECT_TRUE(a[2].relative);
  EXPECT_DOUBLE_EQ(a[2].at_seconds, 0.25);
  EXPECT_DOUBLE_EQ(a[2].x, 30);
  EXPECT_DOUBLE_EQ(a[2].y, -10);
  EXPECT_DOUBLE_EQ(a[3].x, 20);  // default settle timeout
  EXPECT_DOUBLE_EQ(a[4].x, 5);
  EXPECT_EQ(a[5].kind, Kind::resize);
  EXPECT_DOUBLE_EQ(a[5].y, 480);
  EXPECT_EQ(a[6].kind, Kind::sse);
  EXPECT_EQ(a[7].kind, Kind::zoom);
  EXPECT_TRUE(parse_script("").empty());
}

TEST(Script, CameraAndLayoutReports) {
  const auto a = parse_script("0 camera; +2f layout");
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0].kind, Kind::camera);
  EXPECT_EQ(a[1].kind, Kind::layout);
  EXPECT_EQ(a[1].at_frame, 2);
  EXPECT_THROW(parse_script("0 camera 1"), InputError);
  EXPECT_THROW(parse_script("0 layout now"), InputError);
}

TEST(Script, KeyNames) {
  EXPECT_GE(key_code("space"), 0);
  EXPECT_EQ(key_code("a") + 1, key_code("b"));
  EXPECT_EQ(key_code("A"), key_code("a"));
  EXPECT_GE(key_code("home"), 0);
  EXPECT_EQ(key_code("nosuchkey"), -1);
}

TEST(Script, ErrorsNameTheEntry) {
  const auto message = [](const std::string& text) {
    try {
      parse_script(text);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("1 jump").find("'1 jump': unknown action 'jump'"), std::string::npos);
  EXPECT_NE(message("1 speed 100").find("expected a speed in 0.25..8"), std::string::npos);
  EXPECT_NE(message("1 seek -5").find("expected a playhead >= 0"), std::string::npos);
  EXPECT_NE(message("0.1 transfer nope").find("unknown transfer-function preset 'nope' (presets: "),
            std::string::npos);
  EXPECT_NE(message("x key space").find("expected when, a time"), std::string::npos);
  EXPECT_NE(message("1 key nosuchkey").find("unknown key"), std::string::npos);
  EXPECT_NE(message("1 seek").find("takes 1 argument"), std::string::npos);
  EXPECT_NE(message("1 zoom -2").find("positive"), std::string::npos);
  EXPECT_NE(message("1 resize 0 10").find("width and a height"), std::string::npos);
  EXPECT_NE(message("quit").find("expected WHEN ACTION"), std::string::npos);
  // A screenshot is a PNG file in a folder that exists, refused when the script is read rather
  // than when the entry runs.
  EXPECT_NE(message("1 screenshot a.jpg")
                .find("'1 screenshot a.jpg': a.jpg: the screenshot is a "
                      "PNG image; give a name ending in .png"),
            std::string::npos);
  EXPECT_NE(message("1 screenshot no-such-folder/a.png")
                .find("the folder no-such-folder does not exist; make it first"),
            std::string::npos);
  EXPECT_NE(message("1 screenshot .").find("'1 screenshot .': .: is a folder"), std::string::npos);
  EXPECT_NE(message("1 screenshot /dev/null/a.png")
                .find("/dev/null is not a folder; give the PNG a name in a folder"),
            std::string::npos);
  EXPECT_EQ(message("1 screenshot A.PNG"), "no error");
  // Not-a-number and infinity are no time, frame or argument (a NaN time never came, a NaN zoom
  // drew nothing); nor is a frame number past what a count holds.
  for (const std::string when : {"nan", "inf", "-inf", "nanf", "inff", "+nan", "1e300f"})
    EXPECT_NE(
        message(when + " quit").find("expected when, a time in seconds like '0.5' or a frame"),
        std::string::npos)
        << when;
  for (const std::string entry :
       {"1 zoom nan", "1 speed inf", "1 seek nan", "1 sse -inf", "1 orbit nan 0", "1 orbit 0 inf",
        "1 settle nan", "1 resize nan 10"})
    EXPECT_NE(message(entry).find("expected"), std::string::npos) << entry;
}

}  // namespace
}  // namespace volreel::app
