// series_test.cpp: the raw series format, raw files and HDF5 files read back what was written,
// and bad input of every kind gives an InputError that says what was wrong.
#include <sys/stat.h>

#include <gtest/gtest.h>
#include <hdf5.h>
#include <netcdf.h>

#include <cmath>
#include <fstream>
#include <limits>

#include "detail.hpp"
#include "test_util.hpp"
#include "volreel/datasets/series.hpp"

namespace vd = volreel::datasets;
namespace fs = std::filesystem;
using volreel::Dims;
using volreel::InputError;
using volreel::test::TempDir;

namespace {

std::vector<float> ramp(Dims d, float offset) {
  std::vector<float> v(d.voxels());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = offset + 0.5f * static_cast<float>(i);
  return v;
}

/// Runs f, expects an InputError whose message contains every one of `needles`.
template <typename F>
void expect_error(F&& f, std::initializer_list<std::string> needles) {
  try {
    f();
    ADD_FAILURE() << "expected an InputError";
  } catch (const InputError& e) {
    for (const auto& needle : needles)
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos)
          << "message: " << e.what() << "\nlacks: " << needle;
  }
}

void write_bytes(const fs::path& path, const void* data, std::size_t size) {
  std::ofstream f(path, std::ios::binary);
  f.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
}

fs::path write_series(const TempDir& dir, Dims d, int frames) {
  const fs::path path = dir / "series";
  vd::RawSeriesWriter w(path, d, "pressure");
  for (int t = frames - 1; t >= 0; --t)
    w.write_frame(static_cast<std::size_t>(t), 0.25 * t, ramp(d, static_cast<float>(t)));
  w.set_generator({{"method", "test"}});
  w.finish();
  return path;
}

}  // namespace

TEST(Dims, ParsesAndRejects) {
  EXPECT_EQ(volreel::parse_dims("256x256x128"), (Dims{256, 256, 128}));
  EXPECT_EQ(volreel::to_string(Dims{3, 4, 5}), "3x4x5");
  for (const char* bad : {"", "256x256", "0x1x1", "1x1x-1", "axbxc", "1x2x3x", "1x2x3 "})
    expect_error([&] { volreel::parse_dims(bad); }, {"dimensions"});
  expect_error([] { volreel::parse_dims("16777216x1x1"); }, {"at most 1048576 voxels an axis"});
  // A frame whose byte count would overflow is refused, not wrapped.
  expect_error([] { volreel::parse_dims("1048576x1048576x1048576"); },
               {"expected at most 2^48 voxels a frame", "1.15e+18"});
}

TEST(Dtype, ParsesAndRejects) {
  EXPECT_EQ(vd::parse_dtype("u16"), vd::Dtype::u16);
  EXPECT_EQ(vd::dtype_size(vd::Dtype::f64), 8u);
  expect_error([] { vd::parse_dtype("f16"); }, {"unknown dtype 'f16'", "f32"});
}

TEST(RawSeries, RoundTrip) {
  TempDir dir("series-roundtrip");
  const Dims d{5, 4, 3};
  const fs::path path = write_series(dir, d, 3);
  EXPECT_FALSE(fs::exists(path / "000000.f32.tmp"));
  for (const fs::path& p : {path, path / "series.json"}) {
    const auto s = vd::open_series(p);
    EXPECT_EQ(s->info().dims, d);
    ASSERT_EQ(s->info().frames, 3u);
    EXPECT_EQ(s->info().timestamps, (std::vector<double>{0.0, 0.25, 0.5}));
    EXPECT_EQ(s->info().variable, "pressure");
    EXPECT_EQ(s->info().generator.at("method"), "test");
    EXPECT_EQ(s->read_frame(2).data, ramp(d, 2.0f));
  }
}

TEST(RawSeries, WriterRefusesToOverwriteAndToFinishWithGaps) {
  TempDir dir("series-writer");
  const Dims d{2, 2, 2};
  write_series(dir, d, 1);
  expect_error([&] { vd::RawSeriesWriter w(dir / "series", d, "p"); },
               {"already holds a series", "--overwrite"});
  vd::RawSeriesWriter w(dir / "gaps", d, "p");
  w.write_frame(1, 0.0, ramp(d, 0));
  expect_error([&] { w.finish(); }, {"frame 0 was never written"});
  EXPECT_FALSE(fs::exists(dir / "gaps" / "series.json"));
  expect_error([&] { w.write_frame(0, 0.0, std::vector<float>(3)); }, {"has 3 values, expected 8"});
}

TEST(RawSeries, AWriterThatDoesNotFinishLeavesNothingBehind) {
  TempDir dir("series-unfinished");
  const Dims d{2, 2, 2};
  {  // directories it made: removed with its frames
    vd::RawSeriesWriter w(dir / "new" / "deeper", d, "p");
    w.write_frame(0, 0.0, ramp(d, 0));
    EXPECT_TRUE(fs::exists(dir / "new" / "deeper" / "000000.f32"));
  }
  EXPECT_FALSE(fs::exists(dir / "new"));
  {  // a directory that was there stays, with its hidden files
    fs::create_directories(dir / "kept");
    std::ofstream(dir / "kept" / ".hidden") << "mine";
    vd::RawSeriesWriter w(dir / "kept", d, "p");
    w.write_frame(0, 0.0, ramp(d, 0));
  }
  EXPECT_FALSE(fs::exists(dir / "kept" / "000000.f32"));
  EXPECT_TRUE(fs::exists(dir / "kept" / ".hidden"));
  // A folder of other files and no series is never written into (its files could be replaced),
  // overwrite or not.
  std::ofstream(dir / "kept" / "000000.f32") << "mine";
  std::ofstream(dir / "kept" / "notes.txt") << "mine";
  for (const bool overwrite : {false, true}) {
    try {
      vd::RawSeriesWriter w(dir / "kept", d, "p", overwrite);
      ADD_FAILURE() << "wrote into a folder of other files";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("holds 'notes.txt' but no series.json"),
                std::string::npos)
          << e.what();
    }
  }
  EXPECT_EQ(fs::file_size(dir / "kept" / "000000.f32"), 4u);
  // Frame files alone, as an interrupted writer leaves them: replaced with overwrite only, and
  // those past the new series removed.
  fs::remove(dir / "kept" / "notes.txt");
  std::ofstream(dir / "kept" / "000004.f32") << "mine";
  expect_error([&] { vd::RawSeriesWriter w(dir / "kept", d, "p"); },
               {"holds frame files but no series.json", "--overwrite"});
  {
    vd::RawSeriesWriter w(dir / "kept", d, "p", true);
    w.write_frame(0, 0.0, ramp(d, 0));
    w.write_frame(1, 1.0, ramp(d, 1));
    w.finish();
  }
  EXPECT_EQ(fs::file_size(dir / "kept" / "000000.f32"), d.voxels() * 4);
  EXPECT_FALSE(fs::exists(dir / "kept" / "000004.f32"));
  EXPECT_TRUE(fs::exists(dir / "kept" / "series.json"));
  // --overwrite: the old series' frames go, so that a shorter one leaves none of them.
  const fs::path old = write_series(dir, d, 3);
  {
    vd::RawSeriesWriter w(old, d, "p", true);
    w.write_frame(0, 0.0, ramp(d, 5));
    w.finish();
  }
  EXPECT_TRUE(fs::exists(old / "000000.f32"));
  EXPECT_FALSE(fs::exists(old / "000001.f32"));
  EXPECT_FALSE(fs::exists(old / "000002.f32"));
  EXPECT_EQ(vd::open_series(old)->info().frames, 1u);
  // A series written by other means (no generator): its files stay whatever their names.
  fs::create_directories(dir / "hand");
  std::ofstream(dir / "hand" / "series.json")
      << R"({"dims": [2, 2, 2], "frames": ["sim_1.raw", "000001.f32"]})";
  std::ofstream(dir / "hand" / "sim_1.raw") << "data";
  std::ofstream(dir / "hand" / "000001.f32") << "data";
  {
    vd::RawSeriesWriter w(dir / "hand", d, "p", true);
    w.write_frame(0, 0.0, ramp(d, 5));
    w.finish();
  }
  EXPECT_TRUE(fs::exists(dir / "hand" / "sim_1.raw"));
  EXPECT_TRUE(fs::exists(dir / "hand" / "000001.f32"));
}

TEST(RawSeries, OptionsOfRawFilesAreRefusedForASeriesThatDescribesItself) {
  TempDir dir("series-raw-options");
  const Dims d{2, 2, 2};
  const fs::path path = write_series(dir, d, 1);
  vd::OpenOptions o;
  o.dims = d;
  expect_error([&] { vd::open_series(path, o); },
               {"is a series directory", "leave out --dims (options for raw files)"});
  o.frames = 1;
  expect_error([&] { vd::open_series(path / "series.json", o); },
               {"leave out --dims and --frames"});
  EXPECT_TRUE(vd::describes_itself(path));
  EXPECT_TRUE(vd::describes_itself("x.H5"));
  EXPECT_TRUE(vd::describes_itself("x.nc"));
  EXPECT_FALSE(vd::describes_itself(path / "000000.f32"));
  EXPECT_EQ(vd::open_series(path)->info().dims, d);
}

TEST(RawSeries, OptionsOfOtherInputKindsAreRefusedAndSharedByKind) {
  TempDir dir("series-other-options");
  const Dims d{2, 2, 2};
  const fs::path path = write_series(dir, d, 1);
  // HDF5's and NetCDF's options for a series directory or a raw file: refused, not ignored.
  vd::OpenOptions o;
  o.variable = "p";
  expect_error([&] { vd::open_series(path, o); },
               {"is a series directory", "leave out --variable (NetCDF), options for another"});
  o.dataset = "Pressure";
  o.time_dimension = "t";
  vd::OpenOptions raw = o;
  raw.dims = d;
  expect_error([&] { vd::open_series(path / "000000.f32", raw); },
               {"is a raw file", "--dataset (HDF5), --variable (NetCDF) and --time-dim (NetCDF)"});
  // Raw options and others together: one message names them all.
  expect_error([&] { vd::open_series(path, raw); },
               {"leave out --dims (options for raw files); and --dataset (HDF5), --variable"});
  // Two inputs of different kinds (compare A B): each keeps what its kind takes, and an option
  // neither takes stays with both (for open_series to refuse).
  EXPECT_EQ(vd::input_kind("x.nc"), vd::InputKind::netcdf);
  EXPECT_EQ(vd::input_kind("x.hdf5"), vd::InputKind::hdf5);
  EXPECT_EQ(vd::input_kind(path), vd::InputKind::raw_series);
  EXPECT_EQ(vd::input_kind(path / "000000.f32"), vd::InputKind::raw);
  const fs::path nc = "x.nc", raw_file = path / "000000.f32";
  const vd::OpenOptions for_series = vd::options_for(path, raw, &nc);
  EXPECT_TRUE(for_series.variable.empty() && for_series.time_dimension.empty());
  EXPECT_EQ(for_series.dataset, "Pressure");  // neither is HDF5
  EXPECT_TRUE(for_series.dims.has_value());   // neither is raw
  const vd::OpenOptions for_netcdf = vd::options_for(nc, raw, &raw_file);
  EXPECT_FALSE(for_netcdf.dims.has_value());
  EXPECT_EQ(for_netcdf.variable, "p");
  EXPECT_EQ(vd::options_for(nc, raw, nullptr).dims, d);  // the other is not a series
}

TEST(RawSeries, MissingAndShortFramesAreNamed) {
  TempDir dir("series-bad");
  const Dims d{4, 4, 4};
  const fs::path path = write_series(dir, d, 3);
  fs::remove(path / "000001.f32");
  expect_error([&] { vd::open_series(path); }, {"frame 1", "000001.f32", "missing"});
  write_bytes(path / "000001.f32", ramp(d, 0).data(), 100);
  expect_error([&] { vd::open_series(path); }, {"frame 1", "is 100 bytes, expected 256"});
}

TEST(RawSeries, MalformedManifestsAreRejected) {
  TempDir dir("series-manifest");
  const fs::path path = write_series(dir, Dims{2, 2, 2}, 2);
  const auto put = [&](const std::string& text) {
    write_bytes(path / "series.json", text.data(), text.size());
  };
  put("{ not json");
  expect_error([&] { vd::open_series(path); }, {"series.json", "not valid JSON"});
  const std::string head = R"({"format":"volreel-raw-series","version":1,"dtype":"f32",)";
  put(head + R"("dims":[2,2],"frames":["000000.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); },
               {"\"dims\"", "[x, y, z]", "an array of 2 values, [2,2]"});
  put(head + R"("dims":[2,2,2],"frames":["000000.f32","000001.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); },
               {"\"timestamps\"", "an array of 2 numbers", "found an array of 1 value"});
  put(R"({"format":"volreel-raw-series","version":7,"dtype":"f32","dims":[2,2,2],"frames":["000000.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); }, {"\"version\"", "found 7"});
  put(head + R"("dims":[2,2,2],"frames":"x","timestamps":[0]})");
  expect_error([&] { vd::open_series(path); }, {"\"frames\"", "found \"x\""});
  // A fractional size, a missing dtype and a mistyped field are named, never accepted.
  put(head + R"("dims":[64.5,2,2],"frames":["000000.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); }, {"\"dims\"", "integers", "found 64.5"});
  // Sizes within the limit each whose product overflows a frame's byte count.
  put(head + R"("dims":[16777216,16777216,16777216],"frames":["000000.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); },
               {"\"dims\"", "at most 2^48 voxels a frame", "16777216x16777216x16777216"});
  put(R"({"format":"volreel-raw-series","version":1,"dims":[2,2,2],"frames":["000000.f32"],"timestamps":[0]})");
  expect_error([&] { vd::open_series(path); }, {"field \"dtype\" is missing"});
  put(head + R"("dims":[2,2,2],"frames":["000000.f32"],"timestamps":[0],"variable":7})");
  expect_error([&] { vd::open_series(path); }, {"\"variable\"", "a string", "found 7"});
  put(head + R"("dims":[2,2,2],"frames":["000000.f32","000001.f32"],"timestamps":[1,1]})");
  expect_error([&] { vd::open_series(path); }, {"\"timestamps\"", "increasing"});
  // Nesting deep enough to overflow a recursive walk is refused while parsing.
  put(std::string(200000, '[') + std::string(200000, ']'));
  expect_error([&] { vd::open_series(path); }, {"series.json", "nested at most 64"});
  expect_error([&] { vd::open_series(dir / "nowhere"); }, {"does not exist"});
}

TEST(RawSeries, FramesThatAreNotRegularFilesAreNamed) {
  TempDir dir("series-kinds");
  const fs::path path = write_series(dir, Dims{2, 2, 2}, 2);
  fs::remove(path / "000001.f32");
  fs::create_directory(path / "000001.f32");
  expect_error([&] { vd::open_series(path); }, {"000001.f32", "is a directory"});
  fs::remove(path / "000001.f32");
  ASSERT_EQ(::mkfifo((path / "000001.f32").c_str(), 0600), 0);
  expect_error([&] { vd::open_series(path); }, {"000001.f32", "FIFO"});
  // series.json itself a FIFO: refused at once, never waits for a writer.
  fs::remove(path / "series.json");
  ASSERT_EQ(::mkfifo((path / "series.json").c_str(), 0600), 0);
  expect_error([&] { vd::open_series(path); }, {"series.json", "FIFO"});
  // An HDF5 or raw input that is a FIFO: refused before HDF5 (which would block) opens it.
  ASSERT_EQ(::mkfifo((dir / "run.h5").c_str(), 0600), 0);
  expect_error([&] { vd::open_series(dir / "run.h5"); }, {"run.h5", "is a FIFO"});
}

TEST(RawSeries, NonFiniteValuesRefusedOrReplaced) {
  TempDir dir("series-nan");
  const Dims d{3, 2, 2};
  auto data = ramp(d, 0);
  data[d.index(1, 1, 1)] = std::numeric_limits<float>::quiet_NaN();
  data[d.index(2, 0, 0)] = std::numeric_limits<float>::infinity();
  vd::RawSeriesWriter w(dir / "s", d, "p");
  w.write_frame(0, 0, data);
  w.finish();
  expect_error([&] { vd::open_series(dir / "s")->read_frame(0); },
               {"000000.f32", "voxel (2, 0, 0)", "not finite", "--replace-nan"});
  vd::OpenOptions o;
  o.replace_nan = -1.0f;
  const auto v = vd::open_series(dir / "s", o)->read_frame(0);
  EXPECT_EQ(v.at(1, 1, 1), -1.0f);
  EXPECT_EQ(v.at(2, 0, 0), -1.0f);
  EXPECT_EQ(v.at(0, 1, 1), data[d.index(0, 1, 1)]);
}

TEST(RawFile, AllDtypesConvert) {
  TempDir dir("rawfile");
  const Dims d{3, 2, 2};
  vd::OpenOptions o;
  o.dims = d;
  {
    std::vector<std::uint8_t> v(d.voxels());
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint8_t>(250 + i % 6);
    write_bytes(dir / "u8.raw", v.data(), v.size());
    o.dtype = vd::Dtype::u8;
    EXPECT_EQ(vd::open_series(dir / "u8.raw", o)->read_frame(0).data[5], 255.0f);
  }
  {
    std::vector<std::uint16_t> v(2 * d.voxels());
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint16_t>(1000 * i);
    write_bytes(dir / "u16.raw", v.data(), v.size() * 2);
    o.dtype = vd::Dtype::u16;
    o.frames = 2;
    const auto s = vd::open_series(dir / "u16.raw", o);
    EXPECT_EQ(s->info().frames, 2u);
    EXPECT_EQ(s->read_frame(1).data[1], 13000.0f);
    o.frames.reset();
    expect_error([&] { vd::open_series(dir / "u16.raw", o); },
                 {"u16.raw", "is 48 bytes", "needs 24", "holds 2 such frames: pass --frames 2",
                  "or it is the size of --dtype f32"});
    // Read as f32 (the default) with --frames 2, it is 2 frames of u16: the hint says so.
    o.dtype.reset();
    o.frames = 2;
    expect_error([&] { vd::open_series(dir / "u16.raw", o); },
                 {"u16.raw", "is 48 bytes", "needs 96", "it is the size of --dtype u16"});
    o.frames.reset();
    o.dtype = vd::Dtype::u16;
  }
  {
    std::vector<double> v(d.voxels(), 0.125);
    v[7] = 1e300;  // becomes +inf in float32
    write_bytes(dir / "f64.raw", v.data(), v.size() * 8);
    o.dtype = vd::Dtype::f64;
    expect_error([&] { vd::open_series(dir / "f64.raw", o)->read_frame(0); },
                 {"f64.raw", "not finite", "beyond float32's range"});
  }
  vd::OpenOptions no_dims;
  expect_error([&] { vd::open_series(dir / "u8.raw", no_dims); }, {"--dims"});
}

TEST(RawFile, APatternReadsOneFramePerFileInNaturalOrder) {
  TempDir dir("rawglob");
  const Dims d{2, 2, 1};
  // Frames 1, 2, 10: natural order puts p_2 before p_10 (bytewise order would not).
  for (int t : {10, 1, 2}) {
    std::vector<float> v(d.voxels(), static_cast<float>(t));
    write_bytes(dir / ("p_" + std::to_string(t) + ".f32"), v.data(), v.size() * 4);
  }
  // Not matched by the pattern: another variable.
  std::vector<float> other(d.voxels(), -1.0f);
  write_bytes(dir / "q_3.f32", other.data(), other.size() * 4);
  vd::OpenOptions o;
  o.dims = d;
  const std::string pattern = (dir / "p_*.f32").string();
  const auto s = vd::open_series(pattern, o);
  ASSERT_EQ(s->info().frames, 3u);
  EXPECT_EQ(s->read_frame(0).data[0], 1.0f);
  EXPECT_EQ(s->read_frame(1).data[3], 2.0f);
  EXPECT_EQ(s->read_frame(2).data[0], 10.0f);
  EXPECT_NE(s->info().source.find("3 files"), std::string::npos) << s->info().source;
  // Errors: no match, no --dims, --frames, a file of the wrong size, a directory matched.
  expect_error([&] { vd::open_series((dir / "x_*.f32").string(), o); },
               {"x_*.f32", "matches no file"});
  expect_error([&] { vd::open_series(pattern, vd::OpenOptions{}); }, {"p_*.f32", "--dims"});
  vd::OpenOptions frames = o;
  frames.frames = 2;
  expect_error([&] { vd::open_series(pattern, frames); }, {"one frame per file"});
  write_bytes(dir / "p_11.f32", other.data(), 8);
  expect_error([&] { vd::open_series(pattern, o); }, {"p_11.f32", "is 8 bytes", "needs 16"});
  fs::remove(dir / "p_11.f32");
  fs::create_directory(dir / "p_12.f32");
  expect_error([&] { vd::open_series(pattern, o); }, {"p_12.f32", "directory"});
}

TEST(RawFile, SimulationTimesInNamesSortByValue) {
  TempDir dir("rawtimes");
  const Dims d{2, 2, 1};
  // Written in another order; frame k must hold the k-th time. "frame.3.f32" and "frame.12.f32":
  // a '.' before a number is not a decimal point.
  const std::vector<std::string> times = {"0.125", "0.25", "0.5", "1", "1.5", "2.0", "10"};
  for (std::size_t k : {4u, 6u, 0u, 2u, 5u, 1u, 3u}) {
    std::vector<float> v(d.voxels(), static_cast<float>(k));
    write_bytes(dir / ("p_t" + times[k] + ".f32"), v.data(), v.size() * 4);
  }
  vd::OpenOptions o;
  o.dims = d;
  const auto s = vd::open_series((dir / "p_t*.f32").string(), o);
  ASSERT_EQ(s->info().frames, times.size());
  for (std::size_t k = 0; k < times.size(); ++k)
    EXPECT_EQ(s->read_frame(k).data[0], static_cast<float>(k)) << "frame " << k;
  for (int t : {12, 3}) {
    std::vector<float> v(d.voxels(), static_cast<float>(t));
    write_bytes(dir / ("frame." + std::to_string(t) + ".f32"), v.data(), v.size() * 4);
  }
  const auto f = vd::open_series((dir / "frame.*.f32").string(), o);
  EXPECT_EQ(f->read_frame(0).data[0], 3.0f);
  EXPECT_EQ(f->read_frame(1).data[0], 12.0f);
}

namespace {

void h5_write(hid_t file, const std::string& name, const std::vector<hsize_t>& shape,
              const std::vector<double>& data) {
  const hid_t space = H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr);
  const hid_t ds =
      H5Dcreate2(file, name.c_str(), H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data());
  H5Dclose(ds);
  H5Sclose(space);
}

std::vector<double> counting(std::size_t n, double start) {
  std::vector<double> v(n);
  for (std::size_t i = 0; i < n; ++i) v[i] = start + static_cast<double>(i);
  return v;
}

}  // namespace

TEST(Hdf5, PatternOfThreeDimensionalDatasets) {
  TempDir dir("hdf5");
  const fs::path path = dir / "cutout.h5";
  const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  // JHTDB cutout style: [z][y][x][1], numbered 1..3, written out of order; plus an unrelated one.
  for (int t : {3, 1, 2}) {
    char name[32];
    std::snprintf(name, sizeof name, "Pressure_%04d", t);
    h5_write(f, name, {2, 3, 4, 1}, counting(24, 100.0 * t));
  }
  h5_write(f, "xcoor", {4}, counting(4, 0));
  H5Fclose(f);

  vd::OpenOptions o;
  o.dataset = "Pressure_####";
  const auto s = vd::open_series(path, o);
  EXPECT_EQ(s->info().dims, (Dims{4, 3, 2}));
  ASSERT_EQ(s->info().frames, 3u);
  EXPECT_EQ(s->info().timestamps, (std::vector<double>{1, 2, 3}));
  const auto v = s->read_frame(1);
  EXPECT_EQ(v.at(3, 2, 1), 223.0f);  // frame "0002": 200 + index of (x3, y2, z1) = 23
  o.dataset = "Pressure_*";
  EXPECT_EQ(vd::open_series(path, o)->info().frames, 3u);
  o.dataset = "Velocity_####";
  expect_error([&] { vd::open_series(path, o); }, {"no dataset matches 'Velocity_####'"});
  // A dataset the '*' matches without a frame number (a mean beside the frames), or two of one
  // number, has no place among the frames: refused, naming them.
  const fs::path mixed = dir / "mixed.h5";
  const hid_t m = H5Fcreate(mixed.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  for (const char* name : {"Pressure_0001", "Pressure_0002", "Pressure_mean", "Pressure_02"})
    h5_write(m, name, {2, 3, 4, 1}, counting(24, 0));
  H5Fclose(m);
  o.dataset = "Pressure_*";
  expect_error([&] { vd::open_series(mixed, o); },
               {"mixed.h5", "'Pressure_mean', which has no frame number", "Pressure_####"});
  o.dataset = "Pressure_0*";
  expect_error([&] { vd::open_series(mixed, o); },
               {"'Pressure_0002' and 'Pressure_02'", "same frame number 2"});
  o.dataset = "Pressure_####";
  EXPECT_EQ(vd::open_series(mixed, o)->info().frames, 2u);
  o.dataset.clear();
  expect_error([&] { vd::open_series(path, o); }, {"holds 4 datasets", "--dataset"});
  o.dataset = "xcoor";
  expect_error([&] { vd::open_series(path, o); }, {"rank 1"});
  // A dataset created and never written (chunked: HDF5 allocates its storage on the first
  // write) would read as its fill value, zeros.
  const fs::path unwritten = dir / "unwritten.h5";
  const hid_t u = H5Fcreate(unwritten.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hsize_t shape[3] = {4, 5, 6}, chunk[3] = {2, 5, 6};
  const hid_t space = H5Screate_simple(3, shape, nullptr);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl, 3, chunk);
  H5Dclose(H5Dcreate2(u, "p", H5T_IEEE_F32LE, space, H5P_DEFAULT, dcpl, H5P_DEFAULT));
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Fclose(u);
  o.dataset = "p";
  expect_error([&] { vd::open_series(unwritten, o); }, {"unwritten.h5", "was never written"});
  // A dataset whose values lie in an external raw file (H5Pset_external): no storage in the
  // file, and written all the same.
  const fs::path external = dir / "external.h5";
  const std::vector<float> raw = [] {
    std::vector<float> counted(4 * 5 * 6);
    for (std::size_t i = 0; i < counted.size(); ++i) counted[i] = static_cast<float>(i);
    return counted;
  }();
  write_bytes(dir / "external.f32", raw.data(), raw.size() * 4);
  const hid_t x = H5Fcreate(external.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t xspace = H5Screate_simple(3, shape, nullptr);
  const hid_t xdcpl = H5Pcreate(H5P_DATASET_CREATE);
  H5Pset_external(xdcpl, (dir / "external.f32").c_str(), 0, raw.size() * 4);
  H5Dclose(H5Dcreate2(x, "p", H5T_IEEE_F32LE, xspace, H5P_DEFAULT, xdcpl, H5P_DEFAULT));
  H5Pclose(xdcpl);
  H5Sclose(xspace);
  H5Fclose(x);
  const auto e = vd::open_series(external, o);
  EXPECT_EQ(e->read_frame(0).data[7], 7.0f);
}

TEST(Hdf5, FourDimensionalDatasetAndMismatches) {
  TempDir dir("hdf5-4d");
  const fs::path path = dir / "series.h5";
  const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  h5_write(f, "p", {5, 2, 3, 4}, counting(120, 0));
  h5_write(f, "a_1", {2, 2, 2}, counting(8, 0));
  h5_write(f, "a_2", {2, 2, 3}, counting(12, 0));
  H5Fclose(f);
  vd::OpenOptions o;
  o.dataset = "p";
  const auto s = vd::open_series(path, o);
  EXPECT_EQ(s->info().dims, (Dims{4, 3, 2}));
  ASSERT_EQ(s->info().frames, 5u);
  EXPECT_EQ(s->read_frame(4).data.front(), 96.0f);
  EXPECT_EQ(s->read_frame(4).data.back(), 119.0f);
  o.dataset = "a_*";
  expect_error([&] { vd::open_series(path, o); }, {"a_2", "3x2x2 but earlier frames are 2x2x2"});
  // A dataset of no time steps (its first dimension 0) is refused at open.
  const fs::path empty = dir / "empty.h5";
  const hid_t e = H5Fcreate(empty.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  h5_write(e, "pressure", {0, 2, 3, 4}, {});
  H5Fclose(e);
  o.dataset = "pressure";
  expect_error([&] { vd::open_series(empty, o); }, {"empty.h5", "0 time steps"});
}

TEST(Hdf5, CorruptFilesAreRejected) {
  TempDir dir("hdf5-bad");
  const fs::path path = dir / "bad.h5";
  const std::string junk = "this is not an HDF5 file at all";
  write_bytes(path, junk.data(), junk.size());
  expect_error([&] { vd::open_series(path); },
               {"bad.h5", "is named as an HDF5 file but is not one", "signature"});
  // The same for NetCDF: a raw file named .nc is not taken for NetCDF (whose reader then said
  // "Unknown file format", after the options had been refused as a raw file's).
  const fs::path nc = dir / "raw.nc";
  write_bytes(nc, junk.data(), junk.size());
  vd::OpenOptions raw_options;
  raw_options.dims = Dims{2, 2, 2};
  for (const auto& options : {vd::OpenOptions{}, raw_options})
    expect_error([&] { vd::open_series(nc, options); },
                 {"raw.nc", "is named as a NetCDF file but is not one", "signature"});
  // Not the name but the bytes: an HDF5 file named .dat is read as HDF5.
  const fs::path named = dir / "cutout.dat";
  {
    const hid_t h = H5Fcreate(named.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    h5_write(h, "p", {2, 3, 4}, counting(24, 0));
    H5Fclose(h);
  }
  EXPECT_EQ(vd::input_kind(named), vd::InputKind::hdf5);
  vd::OpenOptions p;
  p.dataset = "p";
  EXPECT_EQ(vd::open_series(named, p)->info().dims, (Dims{4, 3, 2}));

  // A real file cut in half.
  const fs::path good = dir / "good.h5";
  const hid_t f = H5Fcreate(good.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  h5_write(f, "p", {4, 16, 16, 16}, counting(16384, 0));
  H5Fclose(f);
  const auto size = fs::file_size(good);
  fs::resize_file(good, size / 2);
  vd::OpenOptions o;
  o.dataset = "p";
  try {
    const auto s = vd::open_series(good, o);
    s->read_frame(3);
    ADD_FAILURE() << "a truncated HDF5 file was read without error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("good.h5"), std::string::npos) << e.what();
  }
}

namespace volreel {
namespace {

/// A CF-style NetCDF file: temp(time, lev, lat, lon) packed as shorts with scale_factor,
/// add_offset and a _FillValue; salt(time, lev, lat, lon) as floats; lev non-uniform; a 3D
/// variable depth(lev, lat, lon).
void write_netcdf(const fs::path& file, bool with_fill, int format = NC_NETCDF4) {
  int nc = 0, time = 0, lev = 0, lat = 0, lon = 0;
  ASSERT_EQ(nc_create(file.c_str(), NC_CLOBBER | format, &nc), NC_NOERR);
  nc_def_dim(nc, "time", NC_UNLIMITED, &time);
  nc_def_dim(nc, "lev", 3, &lev);
  nc_def_dim(nc, "lat", 4, &lat);
  nc_def_dim(nc, "lon", 5, &lon);
  int vtime = 0, vlev = 0, vlat = 0, vlon = 0, vtemp = 0, vsalt = 0, vdepth = 0;
  nc_def_var(nc, "time", NC_DOUBLE, 1, &time, &vtime);
  nc_def_var(nc, "lev", NC_DOUBLE, 1, &lev, &vlev);
  nc_def_var(nc, "lat", NC_DOUBLE, 1, &lat, &vlat);
  nc_def_var(nc, "lon", NC_DOUBLE, 1, &lon, &vlon);
  const int d4[4] = {time, lev, lat, lon};
  nc_def_var(nc, "temp", NC_SHORT, 4, d4, &vtemp);
  nc_def_var(nc, "salt", NC_FLOAT, 4, d4, &vsalt);
  nc_def_var(nc, "depth", NC_FLOAT, 3, d4 + 1, &vdepth);
  int vempty = 0;  // never written: NetCDF's default fill
  nc_def_var(nc, "empty", NC_FLOAT, 3, d4 + 1, &vempty);
  const double scale = 0.5, offset = 10;
  const short fill = -999;
  nc_put_att_double(nc, vtemp, "scale_factor", NC_DOUBLE, 1, &scale);
  nc_put_att_double(nc, vtemp, "add_offset", NC_DOUBLE, 1, &offset);
  nc_put_att_short(nc, vtemp, "_FillValue", NC_SHORT, 1, &fill);
  nc_enddef(nc);
  const double times[2] = {3600, 7200}, levs[3] = {0, 10, 30}, lats[4] = {-3, -1, 1, 3},
               lons[5] = {0, 0.5, 1, 1.5, 2};
  const std::size_t start1 = 0, two = 2;
  nc_put_vara_double(nc, vtime, &start1, &two, times);
  nc_put_var_double(nc, vlev, levs);
  nc_put_var_double(nc, vlat, lats);
  nc_put_var_double(nc, vlon, lons);
  std::vector<short> temp(2 * 60);
  std::vector<float> salt(2 * 60), depth(60, 1.0f);
  for (std::size_t i = 0; i < temp.size(); ++i) {
    temp[i] = static_cast<short>(i);
    salt[i] = 35.0f + static_cast<float>(i) * 0.01f;
  }
  if (with_fill) temp[60 + 7] = fill;  // frame 1, lev 0, lat 1, lon 2
  const std::size_t start[4] = {0, 0, 0, 0}, count[4] = {2, 3, 4, 5};
  nc_put_vara_short(nc, vtemp, start, count, temp.data());
  nc_put_vara_float(nc, vsalt, start, count, salt.data());
  nc_put_var_float(nc, vdepth, depth.data());
  ASSERT_EQ(nc_close(nc), NC_NOERR);
}

TEST(NetCdf, ReadsAVariableWithItsCfCoordinatesAndPacking) {
  test::TempDir dir("netcdf");
  const fs::path file = dir.path() / "ocean.nc";
  write_netcdf(file, false);
  datasets::OpenOptions o;
  o.variable = "temp";
  const auto s = datasets::open_series(file, o);
  EXPECT_EQ(s->info().dims, (Dims{5, 4, 3}));
  EXPECT_EQ(s->info().frames, 2u);
  EXPECT_EQ(s->info().timestamps, (std::vector<double>{3600, 7200}));
  EXPECT_DOUBLE_EQ(s->info().spacing[0], 0.5);   // lon
  EXPECT_DOUBLE_EQ(s->info().spacing[1], 2.0);   // lat
  EXPECT_DOUBLE_EQ(s->info().spacing[2], 15.0);  // lev: non-uniform, the mean step
  EXPECT_NE(s->info().source.find("non-uniform 'lev'"), std::string::npos) << s->info().source;
  EXPECT_EQ(s->info().variable, "temp");
  const Volume v = s->read_frame(1);
  // Packed: stored i -> i * 0.5 + 10; x (lon) fastest.
  EXPECT_FLOAT_EQ(v.at(0, 0, 0), 60 * 0.5f + 10);
  EXPECT_FLOAT_EQ(v.at(2, 1, 0), (60 + 7) * 0.5f + 10);
  EXPECT_FLOAT_EQ(v.at(4, 3, 2), (60 + 59) * 0.5f + 10);
  // Another variable; a 3D variable is one frame.
  o.variable = "salt";
  EXPECT_FLOAT_EQ(datasets::open_series(file, o)->read_frame(0).at(1, 0, 0), 35.01f);
  o.variable = "depth";
  EXPECT_EQ(datasets::open_series(file, o)->info().frames, 1u);
}

/// A classic NetCDF header (CDF-1, 2 or 5) of one float variable over dimensions of `lengths`
/// (0: the record dimension), its values from byte `begin`.
std::vector<unsigned char> classic_header(int version, const std::vector<std::uint64_t>& lengths,
                                          std::uint64_t begin) {
  std::vector<unsigned char> h = {'C', 'D', 'F', static_cast<unsigned char>(version)};
  const int count = version == 5 ? 8 : 4, offset = version == 1 ? 4 : 8;
  const auto put = [&](std::uint64_t v, int bytes) {
    for (int i = bytes - 1; i >= 0; --i) h.push_back(static_cast<unsigned char>(v >> (8 * i)));
  };
  const auto name = [&](const std::string& text) {
    put(text.size(), count);
    h.insert(h.end(), text.begin(), text.end());
    while (h.size() % 4 != 0) h.push_back(0);
  };
  put(2, count);  // records
  put(0x0A, 4);   // NC_DIMENSION
  put(lengths.size(), count);
  for (std::size_t i = 0; i < lengths.size(); ++i) {
    name("d" + std::to_string(i));
    put(lengths[i], count);
  }
  put(0, 4), put(0, count);  // no global attributes
  put(0x0B, 4);              // NC_VARIABLE
  put(1, count);
  name("v");
  put(lengths.size(), count);
  for (std::size_t i = 0; i < lengths.size(); ++i) put(i, count);
  put(0, 4), put(0, count);  // no attributes
  put(5, 4);                 // NC_FLOAT
  put(0, count);             // vsize
  put(begin, offset);
  return h;
}

TEST(NetCdf, TheHeaderWalkEndsValuesWhereTheOffsetsSayAndNeverPastTwoToTheSixtyThree) {
  using vd::detail::classic_values_end;
  // Two records of 2·3·4 floats from byte 100.
  for (const int version : {1, 2, 5}) {
    const auto header = classic_header(version, {0, 2, 3, 4}, 100);
    EXPECT_EQ(classic_values_end(header, 1, 2), 100.0L + 2 * 96) << version;
    EXPECT_EQ(classic_values_end(header, 1, 0), static_cast<long double>(header.size()));
    EXPECT_FALSE(classic_values_end(header, 2, 2)) << "another variable count";
    EXPECT_FALSE(classic_values_end({header.begin(), header.end() - 3}, 1, 2)) << "cut short";
  }
  // Dimensions whose product passes any file, and long double's range: the bound.
  EXPECT_EQ(classic_values_end(classic_header(5, {1ull << 62, 1ull << 62}, 0), 1, 0),
            vd::detail::classic_end_limit);
  EXPECT_EQ(
      classic_values_end(
          classic_header(5, std::vector<std::uint64_t>(300, std::uint64_t{1} << 62), 0), 1, 0),
      vd::detail::classic_end_limit);
}

TEST(NetCdf, MissingValuesAndWrongChoicesAreClearErrors) {
  test::TempDir dir("netcdf-errors");
  const fs::path file = dir.path() / "ocean.nc";
  write_netcdf(file, true);
  datasets::OpenOptions o;
  expect_error([&] { datasets::open_series(file, o); },
               {"ocean.nc", "--variable", "temp, salt, depth, empty"});
  o.variable = "pressure";
  expect_error([&] { datasets::open_series(file, o); }, {"no variable 'pressure'", "temp"});
  o.variable = "temp";
  o.time_dimension = "step";
  expect_error([&] { datasets::open_series(file, o); }, {"no dimension 'step'", "--time-dim"});
  o.time_dimension.clear();
  const auto s = datasets::open_series(file, o);
  EXPECT_NO_THROW(s->read_frame(0));
  expect_error([&] { s->read_frame(1); },
               {"ocean.nc", "variable 'temp' frame 1", "voxel (2, 1, 0)",
                "holds -999, the variable's _FillValue", "--replace-nan"});
  o.replace_nan = -1.0f;
  EXPECT_EQ(datasets::open_series(file, o)->read_frame(1).at(2, 1, 0), -1.0f);
  // Data never written reads as NetCDF's default fill: missing, not 9.97e36.
  o.variable = "empty";
  o.replace_nan.reset();
  expect_error(
      [&] { datasets::open_series(file, o)->read_frame(0); },
      {"variable 'empty' frame 0", "NetCDF's default fill value (never written)", "--replace-nan"});
  // A classic file cut short: NetCDF reads what is missing as zeros; refused at open.
  const fs::path classic = dir.path() / "classic.nc";
  write_netcdf(classic, false, 0);  // CDF-1
  o.variable = "salt";
  EXPECT_FLOAT_EQ(datasets::open_series(classic, o)->read_frame(1).at(4, 3, 2), 35.0f + 1.19f);
  fs::resize_file(classic, fs::file_size(classic) / 2);
  expect_error([&] { datasets::open_series(classic, o); },
               {"classic.nc", "bytes, but its variables' values alone take", "truncated"});
  // Cut by a single byte, in each classic variant: the header's offsets say where values end.
  for (const int format : {0, NC_64BIT_OFFSET, NC_64BIT_DATA}) {
    write_netcdf(classic, false, format);
    EXPECT_NO_THROW(datasets::open_series(classic, o)) << "format " << format;
    fs::resize_file(classic, fs::file_size(classic) - 1);
    expect_error([&] { datasets::open_series(classic, o); },
                 {"classic.nc", "its header places values up to byte", "truncated"});
  }
  // Not a NetCDF file.
  const fs::path bad = dir.path() / "bad.nc";
  std::ofstream(bad) << "not netcdf";
  expect_error([&] { datasets::open_series(bad, o); }, {"bad.nc", "NetCDF"});
  // A header cut short, which the library reads as a file of no variables.
  write_netcdf(classic, false, 0);
  fs::resize_file(classic, 60);
  expect_error(
      [&] { datasets::open_series(classic, o); },
      {"classic.nc", "no variable 'salt'", "holds no variable at all (a damaged header?)"});
  // No variable of 3 or 4 dimensions: said so with what there is, not "say which variable".
  const fs::path five = dir.path() / "five.nc";
  int nc = 0, dims[5] = {}, var = 0;
  ASSERT_EQ(nc_create(five.c_str(), NC_CLOBBER, &nc), NC_NOERR);
  const char* names[5] = {"time", "e", "z", "y", "x"};
  for (int d = 0; d < 5; ++d) nc_def_dim(nc, names[d], 2, &dims[d]);
  nc_def_var(nc, "p", NC_FLOAT, 5, dims, &var);
  nc_enddef(nc);
  nc_close(nc);
  expect_error([&] { datasets::open_series(five, datasets::OpenOptions{}); },
               {"five.nc", "holds no variable of 3 or 4 dimensions",
                "its variables are p (time, e, z, y, x)"});
}

TEST(NetCdf, AxesNamedXYZAreReadByNameAndValidRangeMarksMissingValues) {
  test::TempDir dir("netcdf-axes");
  const fs::path file = dir.path() / "xyz.nc";
  // p(time, x, y, z): z varies fastest in the file; value = 100·x + 10·y + z + 1000·t.
  constexpr int nt = 2, nx = 5, ny = 4, nz = 3;
  int nc = 0, dt = 0, dx = 0, dy = 0, dz = 0, vp = 0, vq = 0;
  ASSERT_EQ(nc_create(file.c_str(), NC_CLOBBER | NC_NETCDF4, &nc), NC_NOERR);
  nc_def_dim(nc, "time", nt, &dt);
  nc_def_dim(nc, "X", nx, &dx);
  nc_def_dim(nc, "y", ny, &dy);
  nc_def_dim(nc, "z", nz, &dz);
  const int d4[4] = {dt, dx, dy, dz};
  nc_def_var(nc, "p", NC_FLOAT, 4, d4, &vp);
  nc_def_var(nc, "q", NC_FLOAT, 4, d4, &vq);
  const float range[2] = {0, 1200};
  nc_put_att_float(nc, vq, "valid_range", NC_FLOAT, 2, range);
  nc_enddef(nc);
  const auto value = [](int t, int x, int y, int z) {
    return static_cast<float>(1000 * t + 100 * x + 10 * y + z);
  };
  std::vector<float> values;
  for (int t = 0; t < nt; ++t)
    for (int x = 0; x < nx; ++x)
      for (int y = 0; y < ny; ++y)
        for (int z = 0; z < nz; ++z) values.push_back(value(t, x, y, z));
  nc_put_var_float(nc, vp, values.data());
  nc_put_var_float(nc, vq, values.data());
  nc_close(nc);

  datasets::OpenOptions o;
  o.variable = "p";
  const auto s = datasets::open_series(file, o);
  EXPECT_EQ(s->info().dims, (Dims{nx, ny, nz}));
  EXPECT_NE(s->info().source.find("read by their names"), std::string::npos) << s->info().source;
  const Volume v = s->read_frame(1);
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        ASSERT_EQ(v.at(x, y, z), value(1, x, y, z)) << x << " " << y << " " << z;
  // Piecewise reading takes the same values: planes 1..2 of frame 0.
  std::vector<float> slab(static_cast<std::size_t>(nx * ny * 2));
  s->read_slab(0, 1, 3, slab);
  EXPECT_EQ(slab[0], 1.0f);                                             // (0, 0, 1)
  EXPECT_EQ(slab[static_cast<std::size_t>(nx * ny + nx + 2)], 212.0f);  // (2, 1, 2)
  // Frame 1 of q holds values above its valid_range's 1200: missing.
  o.variable = "q";
  const auto q = datasets::open_series(file, o);
  EXPECT_NO_THROW(q->read_frame(0));
  expect_error([&] { q->read_frame(1); },
               {"xyz.nc", "variable 'q' frame 1", "outside the variable's valid_range [0, 1200]",
                "--replace-nan"});
}

}  // namespace
}  // namespace volreel

namespace volreel {
namespace {

/// Every slab of every frame equals the planes read_frame delivers, and a slab out of range or of
/// the wrong size is an InputError.
void expect_slabs_equal_frames(const datasets::SeriesReader& s) {
  const Dims d = s.info().dims;
  for (std::size_t t = 0; t < s.info().frames; ++t) {
    const Volume whole = s.read_frame(t);
    for (std::size_t z0 = 0; z0 < d.planes(); ++z0)
      for (std::size_t z1 = z0 + 1; z1 <= d.planes(); ++z1) {
        std::vector<float> slab((z1 - z0) * d.plane());
        s.read_slab(t, z0, z1, slab);
        ASSERT_TRUE(std::equal(slab.begin(), slab.end(),
                               whole.data.begin() + static_cast<std::ptrdiff_t>(z0 * d.plane())))
            << s.info().source << " frame " << t << " planes [" << z0 << ", " << z1 << ")";
      }
  }
  std::vector<float> plane(d.plane());
  expect_error([&] { s.read_slab(0, d.planes(), d.planes() + 1, plane); }, {"not a slab"});
  expect_error([&] { s.read_slab(s.info().frames, 0, 1, plane); }, {"out of range"});
  expect_error([&] { s.read_slab(0, 0, 2, plane); }, {"wrong size"});
}

TEST(Slabs, EveryReaderReadsPlanesAsItsFrames) {
  test::TempDir dir("slabs");
  const Dims d{5, 3, 4};
  expect_slabs_equal_frames(*datasets::open_series(write_series(dir, d, 2)));
  {  // one raw file of u16 frames back to back, and a pattern of f64 files
    std::vector<std::uint16_t> u16(2 * d.voxels());
    for (std::size_t i = 0; i < u16.size(); ++i) u16[i] = static_cast<std::uint16_t>(7 * i);
    write_bytes(dir / "u16.raw", u16.data(), u16.size() * 2);
    datasets::OpenOptions o;
    o.dims = d;
    o.dtype = datasets::Dtype::u16;
    o.frames = 2;
    expect_slabs_equal_frames(*datasets::open_series(dir / "u16.raw", o));
    for (int t = 0; t < 2; ++t) {
      const std::vector<double> v = counting(d.voxels(), 1000.0 * t);
      write_bytes(dir / ("f_" + std::to_string(t) + ".f64"), v.data(), v.size() * 8);
    }
    o.dtype = datasets::Dtype::f64;
    o.frames.reset();
    expect_slabs_equal_frames(*datasets::open_series((dir / "f_*.f64").string(), o));
  }
  {  // HDF5: 3D datasets and one 4D dataset
    const fs::path path = dir / "s.h5";
    const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    h5_write(f, "a_1", {4, 3, 5}, counting(60, 0));
    h5_write(f, "a_2", {4, 3, 5}, counting(60, 500));
    h5_write(f, "p", {2, 4, 3, 5}, counting(120, 7));
    H5Fclose(f);
    datasets::OpenOptions o;
    o.dataset = "a_*";
    expect_slabs_equal_frames(*datasets::open_series(path, o));
    o.dataset = "p";
    expect_slabs_equal_frames(*datasets::open_series(path, o));
  }
  {  // NetCDF: a packed 4D variable and a 3D one
    const fs::path file = dir.path() / "ocean.nc";
    write_netcdf(file, false);
    datasets::OpenOptions o;
    o.variable = "temp";
    expect_slabs_equal_frames(*datasets::open_series(file, o));
    o.variable = "depth";
    expect_slabs_equal_frames(*datasets::open_series(file, o));
  }
}

TEST(Slabs, ANonFiniteValueIsNamedByItsPlaneInTheFrame) {
  test::TempDir dir("slabs-nan");
  const Dims d{3, 2, 4};
  auto data = ramp(d, 0);
  data[d.index(1, 0, 3)] = std::numeric_limits<float>::quiet_NaN();
  datasets::RawSeriesWriter w(dir / "s", d, "p");
  w.write_frame(0, 0, data);
  w.finish();
  const auto s = datasets::open_series(dir / "s");
  std::vector<float> slab(2 * d.plane());
  s->read_slab(0, 0, 2, slab);  // planes without it read
  expect_error([&] { s->read_slab(0, 2, 4, slab); }, {"000000.f32", "voxel (1, 0, 3)"});
}

}  // namespace
}  // namespace volreel
