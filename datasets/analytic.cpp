// analytic.cpp: deterministic analytic time-varying fields (moving blobs, rotating bands,
// drifting value noise, a plume rising into a still stratified box) built only from closed-form
// expressions and volreel's SplitMix64.
#include "volreel/datasets/analytic.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/series.hpp"

namespace volreel::datasets {

AnalyticField parse_analytic_field(const std::string& name) {
  if (name == "blobs") return AnalyticField::blobs;
  if (name == "rotating") return AnalyticField::rotating;
  if (name == "noise") return AnalyticField::noise;
  if (name == "plume") return AnalyticField::plume;
  throw InputError("unknown analytic field '" + name +
                   "': expected blobs, rotating, noise or plume");
}

std::string to_string(AnalyticField field) {
  switch (field) {
    case AnalyticField::blobs:
      return "blobs";
    case AnalyticField::rotating:
      return "rotating";
    case AnalyticField::noise:
      return "noise";
    case AnalyticField::plume:
      return "plume";
  }
  return "?";
}

namespace {

constexpr double two_pi = 2.0 * std::numbers::pi;

/// Normalised coordinate of voxel i on an axis of n voxels, in [0, 1].
double coordinate(std::int64_t i, std::int64_t n) {
  return n > 1 ? static_cast<double>(i) / static_cast<double>(n - 1) : 0.5;
}

void blobs(const AnalyticParams& p, double phase, std::span<float> out) {
  constexpr int count = 5;
  struct Blob {
    std::array<double, 3> centre, amplitude_of_path, frequency, offset;
    double radius, weight;
  };
  std::array<Blob, count> list;
  SplitMix64 rng(p.seed);
  for (auto& b : list) {
    for (int a = 0; a < 3; ++a) {
      b.centre[static_cast<std::size_t>(a)] = rng.uniform(0.3, 0.7);
      b.amplitude_of_path[static_cast<std::size_t>(a)] = rng.uniform(0.1, 0.25);
      b.frequency[static_cast<std::size_t>(a)] = static_cast<double>(1 + rng.below(2));
      b.offset[static_cast<std::size_t>(a)] = rng.uniform(0.0, two_pi);
    }
    b.radius = rng.uniform(0.06, 0.18);
    b.weight = rng.uniform(0.4, 1.0) * (rng.below(4) == 0 ? -1.0 : 1.0);
  }
  std::array<std::array<double, 3>, count> centres;
  for (std::size_t n = 0; n < list.size(); ++n)
    for (std::size_t a = 0; a < 3; ++a)
      centres[n][a] =
          list[n].centre[a] +
          list[n].amplitude_of_path[a] * std::sin(list[n].frequency[a] * phase + list[n].offset[a]);
  const Dims d = p.dims;
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < d.z; ++k)
    for (std::int64_t j = 0; j < d.y; ++j)
      for (std::int64_t i = 0; i < d.x; ++i) {
        const double x = coordinate(i, d.x), y = coordinate(j, d.y), z = coordinate(k, d.z);
        double v = 0;
        for (std::size_t n = 0; n < list.size(); ++n) {
          const double dx = x - centres[n][0], dy = y - centres[n][1], dz = z - centres[n][2];
          v += list[n].weight *
               std::exp(-(dx * dx + dy * dy + dz * dz) / (2 * list[n].radius * list[n].radius));
        }
        out[d.index(i, j, k)] = static_cast<float>(v);
      }
}

void rotating(const AnalyticParams& p, double phase, std::span<float> out) {
  SplitMix64 rng(p.seed);
  const double bands = 3.0 + static_cast<double>(rng.below(3));
  const double twist = rng.uniform(0.5, 2.0);
  const double angle = phase;
  const double c = std::cos(angle), s = std::sin(angle);
  const Dims d = p.dims;
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < d.z; ++k)
    for (std::int64_t j = 0; j < d.y; ++j)
      for (std::int64_t i = 0; i < d.x; ++i) {
        const double x = coordinate(i, d.x) - 0.5, y = coordinate(j, d.y) - 0.5,
                     z = coordinate(k, d.z) - 0.5;
        const double u = c * x - s * y;
        const double r = std::sqrt(x * x + y * y + z * z);
        const double v =
            0.7 * std::sin(two_pi * bands * u + twist * two_pi * z) * std::exp(-4 * r * r) +
            0.3 * std::cos(two_pi * 2 * r - 0.5 * phase);
        out[d.index(i, j, k)] = static_cast<float>(v);
      }
}

/// Reproducible lattice value in [-1, 1] for integer coordinates (hash through SplitMix64).
double lattice(std::uint64_t seed, std::int64_t i, std::int64_t j, std::int64_t k, std::int64_t t) {
  std::uint64_t h = seed;
  for (std::int64_t c : {i, j, k, t})
    h = SplitMix64(h ^ static_cast<std::uint64_t>(c) * 0x9E3779B97F4A7C15ull).next();
  return static_cast<double>(h >> 11) * 0x1.0p-52 - 1.0;
}

double smooth(double f) {
  return f * f * (3 - 2 * f);
}

/// Value noise of 4 octaves at normalised coordinates (x, y, z), blended between the lattice times
/// t0 and t0 + 1 by tw; about [-1, 1].
double value_noise(std::uint64_t seed, double x, double y, double z, std::int64_t t0, double tw) {
  double v = 0, amplitude = 0.5;
  for (int octave = 0; octave < 4; ++octave) {
    const double cells = 4.0 * std::pow(2.0, octave);
    const double cx = x * cells, cy = y * cells, cz = z * cells;
    const double fx = std::floor(cx), fy = std::floor(cy), fz = std::floor(cz);
    const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy),
               iz = static_cast<std::int64_t>(fz);
    const double wx = smooth(cx - fx), wy = smooth(cy - fy), wz = smooth(cz - fz);
    const std::uint64_t octave_seed = seed * 131 + static_cast<std::uint64_t>(octave);
    double sum = 0;
    for (int corner = 0; corner < 16; ++corner) {
      const int a = corner & 1, b = (corner >> 1) & 1, c = (corner >> 2) & 1, e = corner >> 3;
      const double w =
          (a ? wx : 1 - wx) * (b ? wy : 1 - wy) * (c ? wz : 1 - wz) * (e ? tw : 1 - tw);
      sum += w * lattice(octave_seed, ix + a, iy + b, iz + c, t0 + e);
    }
    v += amplitude * sum;
    amplitude *= 0.5;
  }
  return v;
}

void noise(const AnalyticParams& p, double time, std::span<float> out) {
  const Dims d = p.dims;
  const double tf = std::floor(time);
  const double tw = smooth(time - tf);
  const auto t0 = static_cast<std::int64_t>(tf);
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < d.z; ++k)
    for (std::int64_t j = 0; j < d.y; ++j)
      for (std::int64_t i = 0; i < d.x; ++i)
        out[d.index(i, j, k)] = static_cast<float>(value_noise(
            p.seed, coordinate(i, d.x), coordinate(j, d.y), coordinate(k, d.z), t0, tw));
}

/// A turbulent plume rising from a source near the floor into a stably stratified box. Outside the
/// plume the field does not change in time (a still background with its own fine structure); the
/// plume widens with height, its front rises from 15 % to 95 % of the box over the sequence, and
/// inside it value noise drifts. The plume's edge has compact support, so the still part is
/// exactly still.
void plume(const AnalyticParams& p, double fraction, std::span<float> out) {
  SplitMix64 rng(p.seed);
  const double source_x = rng.uniform(0.3, 0.7), source_y = rng.uniform(0.3, 0.7);
  const double sway = rng.uniform(0.0, two_pi);
  constexpr double floor_z = 0.05, front_width = 0.08;
  const double front = 0.15 + 0.8 * fraction;
  const double time = 8.0 * fraction;  // lattice periods of the plume's noise over the sequence
  const double tf = std::floor(time);
  const double tw = smooth(time - tf);
  const auto t0 = static_cast<std::int64_t>(tf);
  const Dims d = p.dims;
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < d.z; ++k)
    for (std::int64_t j = 0; j < d.y; ++j)
      for (std::int64_t i = 0; i < d.x; ++i) {
        const double x = coordinate(i, d.x), y = coordinate(j, d.y), z = coordinate(k, d.z);
        double v = 0.6 * (1 - z) + 0.15 * value_noise(p.seed + 17, x, y, z, 0, 0.0);
        const double height = std::max(z - floor_z, 0.0);
        const double radius = 0.06 + 0.25 * height;
        const double axis_x = source_x + 0.4 * height * height * std::sin(two_pi * 2 * z + sway);
        const double dx = x - axis_x, dy = y - source_y;
        const double r2 = (dx * dx + dy * dy) / (radius * radius);
        const double below_front = std::clamp((front - z) / front_width, 0.0, 1.0);
        if (r2 < 1 && below_front > 0 && z > floor_z) {
          const double profile = (1 - r2) * (1 - r2) * smooth(below_front);
          v += profile *
               (0.8 + 0.6 * value_noise(p.seed + 29, 2 * x, 2 * y, 2 * z - 0.6 * time, t0, tw));
        }
        out[d.index(i, j, k)] = static_cast<float>(v);
      }
}

}  // namespace

void analytic_frame(const AnalyticParams& params, std::size_t t, std::span<float> out) {
  if (out.size() != params.dims.voxels())
    throw InputError("analytic_frame: output has the wrong size");
  const double fraction =
      params.frames > 0 ? static_cast<double>(t) / static_cast<double>(params.frames) : 0.0;
  switch (params.field) {
    case AnalyticField::blobs:
      blobs(params, two_pi * fraction, out);
      break;
    case AnalyticField::rotating:
      rotating(params, two_pi * fraction, out);
      break;
    case AnalyticField::noise:
      noise(params, 0.25 * static_cast<double>(t), out);
      break;
    case AnalyticField::plume:
      plume(params, fraction, out);
      break;
  }
}

void generate_analytic(const AnalyticParams& params, RawSeriesWriter& writer,
                       const Progress& progress) {
  std::vector<float> frame(params.dims.voxels());
  for (std::size_t t = 0; t < params.frames; ++t) {
    analytic_frame(params, t, frame);
    writer.write_frame(t, static_cast<double>(t) / static_cast<double>(params.frames), frame);
    progress.report(static_cast<double>(t + 1), static_cast<double>(params.frames),
                    "frame " + std::to_string(t + 1));
  }
  writer.set_generator({{"method", "analytic"},
                        {"field", to_string(params.field)},
                        {"seed", params.seed},
                        {"frames", params.frames}});
  writer.finish();
}

}  // namespace volreel::datasets
