// cmd_bench_decode.cpp: `volreel bench decode NAME.vreel` — brick decoding throughput of the CPU
// reference decoder (one thread and all threads) and of the Vulkan compute decoder into the atlas
// (MTV-Player §4.2), per batch size, with the upload rate; and the error of both 16-bit atlas
// formats against the CPU decoder on the container's own bricks.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.hpp"
#include "volreel/format/container.hpp"
#include "volreel/vulkan/atlas_decoder.hpp"

namespace volreel::cli {

namespace {

struct BenchDecodeOptions {
  std::string container;
  std::vector<std::size_t> batches = {1, 4, 16, 64, 256, 1024};
  std::size_t frames = 8;
  double min_seconds = 1.0;
  std::string format = "unorm";
  double atlas_mib = 256;
  double upload_mib = 8;
  std::uint32_t ring = 3;
  std::string kernel = "auto";
};

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct BrickRef {
  const format::FrameView* frame;
  std::uint32_t brick;
};

/// Runs `pass` (one pass over all bricks) until `min_seconds` have passed; returns seconds/pass.
template <typename Pass>
double time_passes(double min_seconds, Pass&& pass) {
  pass();  // warm-up
  std::size_t passes = 0;
  const auto start = Clock::now();
  do {
    pass();
    ++passes;
  } while (seconds_since(start) < min_seconds);
  return seconds_since(start) / static_cast<double>(passes);
}

void run_bench_decode(const BenchDecodeOptions& o) {
  // 1. The bricks of the first frames.
  const format::Container container(o.container);
  const format::Manifest& m = container.manifest();
  const std::size_t frames =
      std::min(o.frames ? o.frames : container.frame_count(), container.frame_count());
  std::vector<format::FrameFile> files;
  files.reserve(frames);
  // Every payload checked here, one frame at a time, so that the timed decoding on all threads
  // (where an error could only end the program) decodes only good bricks.
  const format::AtomTable table = container.atoms();
  for (std::size_t t = 0; t < frames; ++t) {
    files.push_back(container.open_frame(t));
    files.back().view().check_payload_crc();
    format::validate_payloads(files.back().view(), table);
  }
  std::vector<BrickRef> bricks;
  std::uint64_t compressed = 0;
  for (const format::FrameFile& f : files)
    for (std::uint32_t b = 0; b < f.view().brick_count(); ++b) {
      bricks.push_back({&f.view(), b});
      compressed += f.view().brick_bytes(b).size();
    }
  if (bricks.empty()) throw InputError(o.container + " has no bricks in its first frames");
  const format::AtomTable& atoms = table;
  const std::size_t brick_voxels = m.shape().voxels();
  const double brick_mvoxel = static_cast<double>(brick_voxels) * 1e-6;
  const double total_mvoxel = static_cast<double>(bricks.size()) * brick_mvoxel;

  vulkan::ContextOptions context_options;
  const vulkan::Context context(context_options);
  std::printf("volreel bench decode\nmachine: %s\nvulkan:  %s\n", describe_machine().c_str(),
              context.describe().c_str());
  std::printf(
      "input:   %s: %ux%ux%u, %s, %zu of %zu frames, %zu bricks (%.1f MVoxel stored), %.2f MB "
      "compressed "
      "(%.0f bytes/brick)\n",
      o.container.c_str(), m.dims[0], m.dims[1], m.dims[2],
      m.codec == format::Codec::ksvd ? "ksvd" : "zfp", frames, container.frame_count(),
      bricks.size(), total_mvoxel, static_cast<double>(compressed) * 1e-6,
      static_cast<double>(compressed) / static_cast<double>(bricks.size()));

  // 2. Reference values: every brick decoded on the CPU.
  std::vector<float> reference(bricks.size() * brick_voxels);
#pragma omp parallel for schedule(dynamic, 4)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(bricks.size()); ++i) {
    const BrickRef& r = bricks[static_cast<std::size_t>(i)];
    format::decode_brick(
        *r.frame, r.brick, atoms,
        {reference.data() + static_cast<std::size_t>(i) * brick_voxels, brick_voxels});
  }
  float lo = static_cast<float>(m.value_min), hi = static_cast<float>(m.value_max);
  for (float v : reference) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  // The atlas range: the decoded range (it may overshoot the manifest's) with a 1 % margin.
  const float margin = 0.01f * (hi - lo);
  const auto make_atlas_options = [&](vulkan::AtlasFormat format) {
    vulkan::AtlasOptions ao;
    ao.format = format;
    ao.slot_size = m.brick_size;
    ao.memory_budget_bytes = static_cast<std::uint64_t>(o.atlas_mib * 1048576.0);
    ao.value_min = lo - margin;
    ao.value_max = hi + margin;
    return ao;
  };
  vulkan::DecoderOptions decoder_options;
  decoder_options.upload_budget_bytes = static_cast<std::uint64_t>(o.upload_mib * 1048576.0);
  decoder_options.ring_size = o.ring;
  if (o.kernel == "image") decoder_options.kernel = vulkan::DecoderOptions::Kernel::image_store;
  if (o.kernel == "copy") decoder_options.kernel = vulkan::DecoderOptions::Kernel::buffer_copy;
  if (o.kernel == "host") decoder_options.kernel = vulkan::DecoderOptions::Kernel::host;
  const auto upload_of = [&](std::size_t i, std::uint32_t slot) {
    const BrickRef& r = bricks[i];
    return vulkan::BrickUpload{r.frame->brick_bytes(r.brick), r.frame->codec(),
                               r.frame->header().codec_parameter, slot};
  };

  // 3. Error of each 16-bit format against the CPU decoder, on every brick (PSNR over the
  //    manifest's value range, the MTV paper's definition).
  std::printf(
      "\n16-bit atlas error against the CPU decoder (%zu bricks; PSNR = 10 log10(range^2 / MSE), "
      "range [%g, %g] of the manifest):\n",
      bricks.size(), m.value_min, m.value_max);
  for (vulkan::AtlasFormat format :
       {vulkan::AtlasFormat::r16_unorm, vulkan::AtlasFormat::r16_sfloat}) {
    const vulkan::Atlas atlas(context, make_atlas_options(format));
    vulkan::AtlasDecoder decoder(context, atlas, decoder_options);
    if (m.codec == format::Codec::ksvd) decoder.set_dictionary(atoms);
    double max_error = 0, squared = 0;
    const std::size_t chunk = std::min<std::size_t>(atlas.slot_count(), 1024);
    for (std::size_t first = 0; first < bricks.size(); first += chunk) {
      const std::size_t n = std::min(chunk, bricks.size() - first);
      std::vector<vulkan::BrickUpload> batch;
      std::vector<std::uint32_t> slots;
      for (std::size_t i = 0; i < n; ++i) {
        batch.push_back(upload_of(first + i, static_cast<std::uint32_t>(i)));
        slots.push_back(static_cast<std::uint32_t>(i));
      }
      decoder.submit(batch);
      const std::vector<float> gpu = decoder.read_slots(slots);
      for (std::size_t i = 0; i < gpu.size(); ++i) {
        const double e =
            static_cast<double>(gpu[i]) - static_cast<double>(reference[first * brick_voxels + i]);
        max_error = std::max(max_error, std::fabs(e));
        squared += e * e;
      }
    }
    const double mse = squared / static_cast<double>(reference.size());
    const double range = m.value_max - m.value_min;
    std::printf("  %-10s max |error| %.3g  RMSE %.3g  PSNR %.1f dB\n",
                vulkan::atlas_format_name(format), max_error, std::sqrt(mse),
                10 * std::log10(range * range / std::max(mse, 1e-300)));
  }

  // 4. Throughput per batch size.
  const vulkan::AtlasFormat format =
      o.format == "sfloat" ? vulkan::AtlasFormat::r16_sfloat : vulkan::AtlasFormat::r16_unorm;
  const vulkan::Atlas atlas(context, make_atlas_options(format));
  vulkan::AtlasDecoder decoder(context, atlas, decoder_options);
  if (m.codec == format::Codec::ksvd) decoder.set_dictionary(atoms);
  std::printf(
      "\natlas:   %s, %u slots (%ux%ux%u), upload budget %.1f MiB x %u staging buffers, kernel "
      "%s\n",
      vulkan::atlas_format_name(format), atlas.slot_count(), atlas.grid().x, atlas.grid().y,
      atlas.grid().z, static_cast<double>(decoder.options().upload_budget_bytes) / 1048576.0,
      decoder.options().ring_size, vulkan::kernel_name(decoder.kernel()));
  const int threads = omp_get_max_threads();
  std::vector<float> scratch(2 * brick_voxels);
  // Bricks i .. i + count − 1 (count ≤ 2) decoded together (format::decode_bricks: their codes
  // read in step).
  const auto decode_run = [&](std::size_t i, std::size_t count, std::span<float> out) {
    format::BrickToDecode run[2];
    for (std::size_t j = 0; j < count; ++j)
      run[j] = {bricks[i + j].frame, bricks[i + j].brick,
                out.subspan(j * brick_voxels, brick_voxels)};
    format::decode_bricks({run, count}, atoms);
  };
  const double cpu1 = time_passes(o.min_seconds, [&] {
    for (std::size_t i = 0; i < bricks.size(); i += 2)
      decode_run(i, std::min<std::size_t>(2, bricks.size() - i), scratch);
  });
  const double alone1 = time_passes(o.min_seconds, [&] {
    for (const BrickRef& r : bricks)
      format::decode_brick(*r.frame, r.brick, atoms, {scratch.data(), brick_voxels});
  });
  std::printf(
      "CPU reference decoder, 1 thread: %.1f MVoxel/s, %.0f bricks/s (one brick at a time: %.1f "
      "MVoxel/s)\n",
      total_mvoxel / cpu1, static_cast<double>(bricks.size()) / cpu1, total_mvoxel / alone1);
  if (m.codec == format::Codec::ksvd) {
    // Where the time goes: the same passes reading and checking every code (check_ksvd_payload,
    // the decoder's own reading) without summing atoms.
    const double read1 = time_passes(o.min_seconds, [&] {
      for (const BrickRef& r : bricks) {
        const std::span<const std::byte> payload = r.frame->brick_bytes(r.brick);
        if (payload.size() != 4)  // 4 bytes: a constant brick
          format::check_ksvd_payload(payload, atoms.count, m.shape(), o.container, 0);
      }
    });
    std::printf(
        "  of which reading the codes (check_ksvd_payload alone): %.0f %% of the time one brick at "
        "a time\n",
        100 * std::min(1.0, read1 / alone1));
  }
  std::printf("\n");
  std::printf("%7s | %-28s | %-44s\n", "",
              ("CPU decoder, " + std::to_string(threads) + " threads").c_str(),
              "Vulkan decoder (upload + decode, all submitted, then waited)");
  std::printf("%7s | %12s %15s | %12s %15s %15s\n", "batch", "MVoxel/s", "bricks/s", "MVoxel/s",
              "bricks/s", "upload MB/s");
  std::vector<std::size_t> measured;  // batches larger than the bricks (or slots) are one row
  std::vector<std::string> clamped;   // what each such batch became, said after the table
  for (std::size_t requested : o.batches) {
    const std::size_t batch = std::clamp<std::size_t>(
        requested, 1, std::min<std::size_t>(bricks.size(), atlas.slot_count()));
    if (batch != requested)
      clamped.push_back(std::to_string(requested) + " as " + std::to_string(batch));
    if (std::find(measured.begin(), measured.end(), batch) != measured.end()) continue;
    measured.push_back(batch);
    // CPU, all threads, a batch at a time (the threads meet at the end of each batch).
    std::vector<std::vector<float>> outputs(static_cast<std::size_t>(threads),
                                            std::vector<float>(2 * brick_voxels));
    const double cpu = time_passes(o.min_seconds, [&] {
      for (std::size_t first = 0; first < bricks.size(); first += batch) {
        const std::size_t end = std::min(bricks.size(), first + batch);
        // Two bricks a thread at a time; a batch's odd last brick alone.
        const auto pairs = static_cast<std::ptrdiff_t>((end - first + 1) / 2);
#pragma omp parallel for schedule(dynamic, 1)
        for (std::ptrdiff_t p = 0; p < pairs; ++p) {
          const std::size_t i = first + 2 * static_cast<std::size_t>(p);
          decode_run(i, std::min<std::size_t>(2, end - i),
                     outputs[static_cast<std::size_t>(omp_get_thread_num())]);
        }
      }
    });
    // Vulkan: every batch submitted (the ring blocks when all staging buffers are in flight), then
    // one wait; slots reused round-robin.
    std::vector<vulkan::BrickUpload> uploads;
    std::uint64_t bytes_before = 0;
    double host_before = 0;
    std::size_t passes = 0;  // the warm-up's included
    const double gpu = time_passes(o.min_seconds, [&] {
      if (passes++ == 1) {  // the first timed pass: the counters from here on
        bytes_before = decoder.stats().uploaded_bytes;
        host_before = decoder.stats().cpu_decode_seconds;
      }
      std::uint32_t slot = 0;
      for (std::size_t first = 0; first < bricks.size(); first += batch) {
        uploads.clear();
        for (std::size_t i = first; i < std::min(bricks.size(), first + batch); ++i) {
          uploads.push_back(upload_of(i, slot));
          slot = (slot + 1) % atlas.slot_count();
        }
        decoder.submit(uploads);
      }
      decoder.wait_all();
    });
    const auto timed = static_cast<double>(passes - 1);
    const double bytes_per_pass =
        static_cast<double>(decoder.stats().uploaded_bytes - bytes_before) / timed;
    std::printf("%7zu | %12.1f %15.0f | %12.1f %15.0f %15.1f", batch, total_mvoxel / cpu,
                static_cast<double>(bricks.size()) / cpu, total_mvoxel / gpu,
                static_cast<double>(bricks.size()) / gpu, bytes_per_pass * 1e-6 / gpu);
    if (decoder.kernel() == vulkan::DecoderOptions::Kernel::host)
      std::printf("   (%.0f%% decoding on the CPU, the rest copying into the atlas)",
                  100 * (decoder.stats().cpu_decode_seconds - host_before) / (gpu * timed));
    std::printf("\n");
  }
  std::printf(
      "\nMVoxel/s counts the stored voxels of each brick (its S^3, apron included). upload MB/s: "
      "bytes "
      "written to\n"
      "the staging buffers (records + payloads) per second of the whole upload + decode.\n");
  if (!clamped.empty()) {
    std::string list;
    for (const std::string& c : clamped) list += (list.empty() ? "" : ", ") + c;
    std::printf(
        "batch %s: a batch holds at most the %zu bricks measured (--frames) and the atlas's %u "
        "slots (--atlas-mib)\n",
        list.c_str(), bricks.size(), atlas.slot_count());
  }
  for (const vulkan::ValidationMessage& message : context.validation_messages())
    std::fprintf(stderr, "volreel: Vulkan validation: %s\n", message.text.c_str());
}

}  // namespace

void add_bench_decode_command(CLI::App& bench) {
  auto o = std::make_shared<BenchDecodeOptions>();
  CLI::App* cmd = bench.add_subcommand("decode",
                                       "Brick decoding throughput: the CPU reference decoder (1 "
                                       "thread and all threads) and the Vulkan compute decoder\n"
                                       "into the atlas (MTV-Player 4.2), MVoxel/s and bricks/s per "
                                       "batch size, upload MB/s, and the error of the\n"
                                       "R16_UNORM and R16_SFLOAT atlas formats against the CPU "
                                       "decoder. Prints the machine and the Vulkan device.");
  cmd->add_option("CONTAINER", o->container, "Container directory NAME.vreel")->required();
  cmd->add_option("--batch", o->batches, "Bricks per batch (comma-separated list)")
      ->delimiter(',')
      ->check(in_range(1, 1e6))
      ->capture_default_str();
  cmd->add_option("--frames", o->frames, "Use the bricks of the first N frames (0: all)")
      ->check(in_range(0, 1e9))
      ->capture_default_str();
  cmd->add_option("--min-seconds", o->min_seconds, "Repeat each measurement for at least this long")
      ->check(in_range(0, 3600))
      ->capture_default_str();
  cmd->add_option("--format", o->format, "Atlas format of the throughput runs: unorm or sfloat")
      ->check(CLI::IsMember({"unorm", "sfloat"}))
      ->capture_default_str();
  cmd->add_option("--atlas-mib", o->atlas_mib, "Atlas memory budget, MiB")
      ->check(in_range(1, 1048576))
      ->capture_default_str();
  cmd->add_option("--upload-mib", o->upload_mib,
                  "Upload budget per staging buffer (per frame), MiB, at least 1")
      ->check(in_range(1, 65536))
      ->capture_default_str();
  cmd->add_option("--ring", o->ring, "Staging buffers in the ring")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  cmd->add_option("--kernel", o->kernel,
                  "Decode kernel: auto (host on CPU devices, image stores otherwise), image, copy "
                  "or host (the CPU decoder, its texels copied into the atlas)")
      ->check(CLI::IsMember({"auto", "image", "copy", "host"}))
      ->capture_default_str();
  cmd->callback([o] { run_bench_decode(*o); });
}

}  // namespace volreel::cli
