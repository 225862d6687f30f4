// series_encoder.cpp: the series-to-container loop — the manifest with the coding choices a
// resumed encode must repeat, the dictionary as the container stores it, resume (frames already
// written and valid are kept) and the frame loop.
#include "volreel/encoder/series_encoder.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <string>

#include "detail.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/encode.hpp"
#include "volreel/encoder/keyframes.hpp"
#include "volreel/encoder/tolerance.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/json_input.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel::encoder {

namespace fs = std::filesystem;
using detail::Clock;
using detail::seconds_since;

namespace {

/// The JSON document of `path` (format::read_json_file), or null where it cannot be read or
/// parsed: for the checks that only ask whether a file is a container's manifest and what it says.
nlohmann::json json_file_or_null(const fs::path& path) {
  try {
    return format::read_json_file(path);
  } catch (const std::exception&) {
    return nullptr;
  }
}

}  // namespace

void refuse_existing_output(const fs::path& out, bool resume, bool overwrite) {
  std::error_code ec;
  const fs::file_status status = fs::status(out, ec);
  if (fs::exists(status) && !fs::is_directory(status))
    throw InputError("'" + out.string() +
                     "' is not a directory: --out names the container directory to write (e.g. "
                     "NAME.vreel); remove that file or choose another name");
  const fs::path manifest = out / "manifest.json";
  if (!resume && !overwrite && fs::exists(manifest))
    throw InputError(
        "'" + out.string() +
        "' already holds a container: give --resume to continue it or --overwrite to replace it");
  // What a container holds is replaced; nothing else is touched, so a directory that holds files
  // volreel did not write where its frames or manifest go is refused, with or without --overwrite.
  if (fs::exists(fs::symlink_status(manifest, ec))) {
    const nlohmann::json doc = json_file_or_null(manifest);
    const bool ours = doc.is_object() && doc.contains("container_id") && doc.contains("frames");
    if (!ours)
      throw InputError("'" + manifest.string() +
                       "' is not a volreel container's manifest: volreel replaces only its own "
                       "containers; choose another --out");
  }
  const fs::path frames = out / "frames";
  if (fs::exists(fs::symlink_status(frames, ec))) {
    if (!fs::is_directory(fs::symlink_status(frames, ec)))
      throw InputError(
          "'" + frames.string() +
          "' is not a directory: volreel writes its frames there; choose another --out");
    for (const auto& entry : fs::directory_iterator(frames, ec)) {
      const std::string name = entry.path().filename().string();
      const bool frame = name.size() >= 10 && name.ends_with(".vrf") &&
                         name.find_first_not_of("0123456789") == name.size() - 4;
      if (!(entry.is_regular_file(ec) && (frame || name.find(".tmp-") != std::string::npos)))
        throw InputError("'" + entry.path().string() +
                         "' was not written by volreel (a container's frames/ holds NNNNNN.vrf "
                         "files only): volreel replaces only its own containers; choose another "
                         "--out");
    }
  }
  // Without a manifest there is no container here: a dictionary.bin is someone's file (e.g. the
  // dictionary given, trained into this directory), which encode would replace; unless it is a
  // container's own copy (its header names a container: an encode stopped before its first
  // manifest wrote it).
  const fs::path dictionary = out / "dictionary.bin";
  bool dictionary_copy = false;
  if (!fs::exists(fs::symlink_status(manifest, ec)) &&
      fs::exists(fs::symlink_status(dictionary, ec))) {
    try {
      dictionary_copy = format::read_dictionary_file(dictionary).container_id != 0;
    } catch (const std::exception&) {
    }
    if (!dictionary_copy)
      throw InputError("'" + dictionary.string() +
                       "' is there but no container manifest: encode writes the container's own "
                       "dictionary.bin; move that file away or choose another --out");
  }
  // Nor is a directory that holds other files and no container (a data folder, e.g. the series
  // itself): a container would be mixed into it. Hidden names (another process's write check,
  // the Python module's temporary series, .nfs files, a desktop's) and a mount point's lost+found
  // are not such files.
  if (fs::is_directory(status) && !fs::exists(fs::symlink_status(manifest, ec))) {
    for (const auto& entry : fs::directory_iterator(out, ec)) {
      const std::string name = entry.path().filename().string();
      if (name != "frames" && !name.starts_with('.') && name != "lost+found" &&
          !(name == "dictionary.bin" && dictionary_copy) && name.find(".tmp-") == std::string::npos)
        throw InputError("'" + out.string() + "' holds '" + name +
                         "' and is not a volreel container: encode writes a container into a "
                         "new or empty directory (e.g. NAME.vreel); choose another --out");
    }
  }
  format::detail::check_writable(out, "--out");
}

namespace {

std::vector<std::byte> read_file_bytes(const fs::path& path) {
  return format::detail::read_whole_file(path, format::detail::max_dictionary_bytes);
}

/// The coding choices recorded in a manifest's provenance, with the values containers written
/// before a field existed used: the pursuit, the mean bits, and the variable-rate rule ("tolerance"
/// when absent) with its parameters.
nlohmann::json coding_choices_of(const format::Manifest& m) {
  nlohmann::json r = nlohmann::json::object();
  if (m.codec != format::Codec::ksvd) return r;
  // Containers written before the field existed all used OMP.
  r["pursuit"] =
      m.encoder.is_object() && m.encoder.contains("pursuit")
          ? m.encoder["pursuit"]
          : nlohmann::json(dictionary::pursuit_name(dictionary::AtomSelection::correlation));
  for (const char* key : {"mean_bits", "mean_step_factor"})
    if (m.encoder.is_object() && m.encoder.contains(key)) r[key] = m.encoder[key];
  if (m.fixed_sparsity != 0) return r;
  const bool has = m.encoder.is_object() && m.encoder.contains("rate_rule");
  r["rate_rule"] =
      has ? m.encoder["rate_rule"] : nlohmann::json(rate_rule_name(VariableRateRule::tolerance));
  for (const char* key : {"lagrangian_factor", "weight_owned_voxels"})
    if (m.encoder.is_object() && m.encoder.contains(key)) r[key] = m.encoder[key];
  // Containers written before the field existed coded every level to ε.
  if (r["rate_rule"] == rate_rule_name(VariableRateRule::lagrangian))
    r["level_tolerance_factor"] =
        m.encoder.is_object() && m.encoder.contains("level_tolerance_factor")
            ? m.encoder["level_tolerance_factor"]
            : nlohmann::json(1.0);
  // Containers written before the field existed coded levels above the finest to ε·F^d alone.
  if (r["rate_rule"] == rate_rule_name(VariableRateRule::lagrangian))
    r["level_detail_ratio"] = m.encoder.is_object() && m.encoder.contains("level_detail_ratio")
                                  ? m.encoder["level_detail_ratio"]
                                  : nlohmann::json(0.0);
  return r;
}

/// The settings that differ between an existing container's manifest and this run's, as
/// "name old (this run: new)" joined by "; " (empty: the same, so --resume may continue it).
std::string settings_difference(const format::Manifest& old, const format::Manifest& now) {
  std::vector<std::string> out;
  // What sets each: the options, or the input.
  static const std::map<std::string, std::string> set_by = {
      {"dims", "the series"},
      {"brick size", "--brick-size"},
      {"codec", "--codec"},
      {"tolerance", "--tolerance, --psnr, --bps or --max-error"},
      {"fixed sparsity", "--fixed-sparsity"},
      {"zfp accuracy", "--zfp-accuracy"},
      {"value range", "the series and --max-frames"},
      {"frames", "the series or --max-frames"},
      {"spacing", "--spacing or the series"},
      {"max keyframe gap", "--max-keyframe-gap"},
      {"pursuit", "--pursuit"},
      {"mean_bits", "--mean-bits"},
      {"rate_rule", "--rate-rule"},
      {"level_tolerance_factor", "--level-factor"},
      {"level_detail_ratio", "--level-detail"},
      {"dictionary", "--dictionary"}};
  const auto differ = [&](const std::string& name, const nlohmann::json& a,
                          const nlohmann::json& b) {
    if (a == b) return;
    const auto by = set_by.find(name);
    out.push_back(name + " " + a.dump() + " (this run: " + b.dump() +
                  (by == set_by.end() ? std::string() : "; set by " + by->second) + ")");
  };
  const auto text = [](const auto& v) { return nlohmann::json(v); };
  const auto codec = [](format::Codec c) { return nlohmann::json(codec_name(c)); };
  differ("dims", text(old.dims), text(now.dims));
  differ("brick size", text(old.brick_size), text(now.brick_size));
  differ("codec", codec(old.codec), codec(now.codec));
  differ("tolerance", text(old.tolerance), text(now.tolerance));
  differ("fixed sparsity", text(old.fixed_sparsity), text(now.fixed_sparsity));
  differ("zfp accuracy", text(old.zfp_accuracy), text(now.zfp_accuracy));
  differ("value range", text(std::vector<double>{old.value_min, old.value_max}),
         text(std::vector<double>{now.value_min, now.value_max}));
  differ("frames", text(old.frames.size()), text(now.frames.size()));
  differ("spacing", text(old.spacing), text(now.spacing));
  differ("max keyframe gap", text(old.max_keyframe_gap), text(now.max_keyframe_gap));
  const auto dictionary = [](const format::Manifest& m) {
    return m.dictionary
               ? nlohmann::json{{"crc32c", m.dictionary->crc32c}, {"bytes", m.dictionary->bytes}}
               : nlohmann::json(nullptr);
  };
  // The coding choices recorded in the provenance (pursuit, mean bits, rate rule and its
  // parameters).
  const nlohmann::json a = coding_choices_of(old), b = coding_choices_of(now);
  std::set<std::string> keys;
  for (const auto& [key, value] : a.items()) keys.insert(key);
  for (const auto& [key, value] : b.items()) keys.insert(key);
  for (const auto& key : keys)
    differ(key, a.contains(key) ? a[key] : nlohmann::json(nullptr),
           b.contains(key) ? b[key] : nlohmann::json(nullptr));
  // The stored dictionary carries the container identifier, a hash of the settings: where one
  // of them differs, so does the dictionary's checksum, and naming it would blame a dictionary
  // the user did not change.
  if (out.empty()) differ("dictionary", dictionary(old), dictionary(now));
  std::string joined;
  for (const auto& d : out) joined += (joined.empty() ? "" : "; ") + d;
  return joined;
}

/// The manifest of a new, incomplete container of the first `frames` frames of a series coded
/// with `coding` (its value range set): the volume, the codec and its parameters, and the
/// provenance with the coding choices a resumed encode must repeat.
format::Manifest new_manifest(const datasets::SeriesInfo& info, std::size_t frames,
                              const CodingSettings& coding, std::uint32_t max_keyframe_gap,
                              const nlohmann::json& provenance) {
  format::Manifest m;
  m.program_version = VOLREEL_VERSION;
  m.dims = {static_cast<std::uint32_t>(info.dims.x), static_cast<std::uint32_t>(info.dims.y),
            static_cast<std::uint32_t>(info.dims.z)};
  m.spacing = info.spacing;
  m.variable = info.variable;
  m.source = info.source;
  m.timestamps.assign(info.timestamps.begin(),
                      info.timestamps.begin() +
                          static_cast<std::ptrdiff_t>(std::min(frames, info.timestamps.size())));
  while (m.timestamps.size() < frames)
    m.timestamps.push_back(static_cast<double>(m.timestamps.size()));
  m.brick_size = coding.brick_size;
  m.levels = static_cast<std::uint32_t>(format::level_geometry(m.dims, m.shape()).size());
  m.codec = coding.codec;
  m.block_size = coding.codec == format::Codec::ksvd ? 6 : 0;
  m.tolerance =
      coding.codec == format::Codec::ksvd && coding.fixed_sparsity == 0 ? coding.tolerance : 0;
  m.fixed_sparsity = static_cast<std::uint32_t>(coding.fixed_sparsity);
  m.zfp_accuracy = coding.codec == format::Codec::zfp ? coding.zfp_accuracy : 0;
  m.value_min = coding.value_min;
  m.value_max = coding.value_max;
  m.frames.assign(frames, std::nullopt);
  m.max_keyframe_gap = std::max<std::uint32_t>(max_keyframe_gap, 1);
  m.encoder = provenance;
  if (!m.encoder.is_object()) m.encoder = nlohmann::json::object();
  if (coding.codec == format::Codec::ksvd) {
    // How each block chose its atoms and each brick its mean bits: a resumed encode must choose
    // them the same way.
    m.encoder["pursuit"] = dictionary::pursuit_name(coding.selection);
    m.encoder["mean_bits"] =
        coding.mean_bits >= 0 ? nlohmann::json(coding.mean_bits) : nlohmann::json("auto");
    if (coding.mean_bits < 0 && coding.fixed_sparsity == 0)
      m.encoder["mean_step_factor"] = coding.mean_step_factor;
  }
  if (coding.codec == format::Codec::ksvd && coding.fixed_sparsity == 0) {
    // How variable rate spent its atoms: a resumed encode must spend them the same way.
    m.encoder["rate_rule"] = rate_rule_name(coding.rule);
    if (coding.rule == VariableRateRule::lagrangian) {
      m.encoder["lagrangian_factor"] = coding.lagrangian_factor;
      m.encoder["weight_owned_voxels"] = coding.weight_owned_voxels;
      m.encoder["level_tolerance_factor"] = coding.level_tolerance_factor;
      m.encoder["level_detail_ratio"] = coding.level_detail_ratio;
    }
  }
  return m;
}

/// The dictionary file as the container stores it, and the dictionary the frames are coded
/// against (its atoms as stored).
struct StoredDictionary {
  format::DictionaryFile file;
  std::vector<std::byte> bytes;
  dictionary::Dictionary dictionary;
};

/// Reads and validates the job's dictionary file, as the container stores it: its atoms rounded to
/// binary16 if the job asks, the DCT basis appended (format::container_dictionary).
StoredDictionary stored_dictionary(const EncodeJob& job) {
  if (job.dictionary_file.empty()) throw InputError("the ksvd codec needs a dictionary file");
  StoredDictionary d;
  d.file = format::parse_dictionary_file(read_file_bytes(job.dictionary_file),
                                         job.dictionary_file);  // validates it
  if ((job.half_atoms && !d.file.half_atoms) || !d.file.dct_atoms)
    d.file = format::container_dictionary(std::move(d.file), job.half_atoms);
  // As stored without an identifier (the container's comes in once it is known).
  d.file.container_id = 0;
  d.bytes = format::serialize_dictionary_file(d.file);
  d.dictionary = dictionary::from_file(d.file);
  return d;
}

/// An existing container at `out`: resume it (the same settings; its frame list goes into m) or
/// refuse unless told to overwrite. Then the frames directory without leftover temporaries, and
/// the dictionary file. Returns whether the encode resumes.
bool prepare_container(const fs::path& out, const EncodeJob& job, format::Manifest& m,
                       const std::vector<std::byte>& dictionary_bytes) {
  const fs::path manifest_path = out / "manifest.json";
  bool resuming = false;
  if (fs::exists(manifest_path)) {
    if (job.resume) {
      const format::Container old(out, true);
      if (const std::string d = settings_difference(old.manifest(), m); !d.empty())
        throw InputError("'" + out.string() + "' was encoded with other settings: " + d +
                         "; to continue it with --resume give the options it was encoded with, "
                         "or --overwrite to start again");
      m.frames = old.manifest().frames;
      resuming = true;
    }
  }
  refuse_existing_output(out, job.resume, job.overwrite);
  if (!resuming && fs::exists(out)) {
    std::error_code ec;
    fs::remove_all(out / "frames", ec);
    fs::remove(manifest_path, ec);
    fs::remove(out / "dictionary.bin", ec);
  }
  fs::create_directories(out / "frames");
  // Leftover temporaries of an interrupted run.
  for (const auto& entry : fs::directory_iterator(out / "frames"))
    if (entry.path().filename().string().find(".tmp-") != std::string::npos)
      fs::remove(entry.path());
  if (m.dictionary) {
    bool present = false;
    if (resuming && fs::exists(out / "dictionary.bin")) {
      const auto existing = read_file_bytes(out / "dictionary.bin");
      present = existing == dictionary_bytes;
    }
    if (!present) format::write_container_file(out, "dictionary.bin", dictionary_bytes);
  }
  return resuming;
}

/// Which frames of [first, last) of a resumed container are already there and valid: the
/// manifest's CRC, or (written but not yet in the manifest) a full structural and CRC check.
/// Updates m's frame list there (valid frames in, the rest out) and returns a flag per frame.
std::vector<char> frames_already_written(const fs::path& out, format::Codec codec,
                                         format::Manifest& m, std::size_t first, std::size_t last) {
  std::vector<char> done(m.frames.size(), 0);
  for (std::size_t t = first; t < last; ++t) {
    const fs::path path = out / format::frame_file_name(t);
    if (!fs::exists(path)) {
      m.frames[t].reset();
      continue;
    }
    try {
      const format::FrameFile f(path);
      f.view().check_payload_crc();
      const std::uint32_t crc = format::manifest_crc(f.view().bytes());
      const auto& h = f.view().header();
      const bool matches = h.frame_index == t && h.codec == static_cast<std::uint32_t>(codec) &&
                           h.container_id == m.container_id &&
                           (!m.frames[t] || (m.frames[t]->crc32c == crc &&
                                             m.frames[t]->bytes == f.view().bytes().size()));
      if (matches) {
        m.frames[t] =
            format::ManifestFrame{format::frame_file_name(t), f.view().bytes().size(), crc};
        done[t] = 1;
      } else {
        m.frames[t].reset();
      }
    } catch (const format::FormatError&) {
      m.frames[t].reset();
    }
  }
  return done;
}

/// Adds one encoded frame's statistics to the summary.
/// The finest level of an encoded frame against the frame: {squared error summed, largest error}.
std::pair<double, double> finest_level_error(const std::vector<std::byte>& bytes,
                                             const format::AtomTable& atoms, const Volume& frame,
                                             std::size_t t) {
  const format::FrameView view(bytes, format::frame_file_name(t));
  const auto decoded = format::decode_level(view, view.level_count() - 1, atoms);
  double squared = 0, worst = 0;
  for (std::size_t i = 0; i < frame.data.size(); ++i) {
    const double e = static_cast<double>(decoded.data[i]) - static_cast<double>(frame.data[i]);
    squared += e * e;
    worst = std::max(worst, std::abs(e));
  }
  return {squared, worst};
}

void add_frame(const FrameStats& st, EncodeSummary& summary) {
  ++summary.encoded;
  summary.unquantized_squared_error += st.unquantized_squared_error;
  summary.quantized_squared_error += st.quantized_squared_error;
  summary.seconds_pyramid += st.seconds_pyramid;
  summary.seconds_bricks += st.seconds_bricks;
  summary.seconds_omp += st.seconds_omp;
  summary.seconds_quantize += st.seconds_quantize;
  summary.breakdown += st.breakdown;
  for (std::size_t k = 0; k < st.sparsity_histogram.size(); ++k)
    summary.sparsity_histogram[k] += st.sparsity_histogram[k];
  for (std::size_t k = 0; k < st.mean_bits_histogram.size(); ++k)
    summary.mean_bits_histogram[k] += st.mean_bits_histogram[k];
  for (std::size_t k = 0; k < st.coef_bits_histogram.size(); ++k)
    summary.coef_bits_histogram[k] += st.coef_bits_histogram[k];
  summary.code_bits += st.code_bits;
  summary.bricks_stored += st.bricks;
  summary.nodes_interpolated += st.interpolated_nodes;
  summary.blocks_over_bound += st.blocks_over_bound;
  summary.split_bricks += st.split_bricks;
}

}  // namespace

std::uint64_t estimated_manifest_bytes(const datasets::SeriesInfo& info, std::size_t frames,
                                       const CodingSettings& coding, std::uint32_t max_keyframe_gap,
                                       const nlohmann::json& provenance, std::uint32_t atom_count) {
  format::Manifest m = new_manifest(info, frames, coding, max_keyframe_gap, provenance);
  // A variable-rate ε not chosen yet takes as many digits as a chosen one.
  if (m.codec == format::Codec::ksvd && m.fixed_sparsity == 0) m.tolerance = 1.0 / 3.0;
  m.container_id = ~std::uint64_t{0} >> 1;
  m.complete = true;
  if (coding.codec == format::Codec::ksvd)
    m.dictionary = format::ManifestDictionary{"dictionary.bin", 1000000, 4000000000u, atom_count};
  for (std::size_t t = 0; t < frames; ++t)  // a frame's size as a megabyte's digits
    m.frames[t] = format::ManifestFrame{format::frame_file_name(t), 1000000, 4000000000u};
  const std::string text = format::manifest_text(format::manifest_to_json(m));
  // The manifest's own CRC is a decimal number: counted at its widest (10 digits), so that the
  // estimate, and the ε a size target finds, do not hang on the CRC of the text (of the series'
  // path, say, which differs from run to run for the Python module's spooled frames).
  const auto crc = nlohmann::json::parse(text).at("manifest_crc32c").get<std::uint32_t>();
  return text.size() - std::to_string(crc).size() + std::to_string(~std::uint32_t{0}).size();
}

double EncodeSummary::quantization_loss_db() const {
  if (!(unquantized_squared_error > 0)) return 0;
  return 10 * std::log10(quantized_squared_error / unquantized_squared_error);
}

std::optional<double> EncodeSummary::finest_owned_codes_bps() const {
  if (skipped != 0 || container_bytes == 0) return std::nullopt;
  return bps * breakdown.finest_owned_codes / static_cast<double>(container_bytes);
}

std::pair<double, double> value_range(const datasets::SeriesReader& series, std::size_t frames,
                                      const Progress& progress, const Ranks& ranks) {
  const std::size_t n = frames ? std::min(frames, series.info().frames) : series.info().frames;
  // A slab of at most 64 MiB at a time (a plane at least), so that no frame is read whole; the
  // processes share the slabs of all frames (one large frame too).
  const Dims dims = series.info().dims;
  const std::size_t slab =
      std::clamp<std::size_t>((std::size_t{64} << 20) / 4 / dims.plane(), 1, dims.planes());
  const std::size_t per_frame = (dims.planes() + slab - 1) / slab;
  const auto [first, last] = ranks.share(n * per_frame);
  std::vector<float> values(slab * dims.plane());
  std::array<double, 1> lo = {std::numeric_limits<double>::infinity()}, hi = {-lo[0]};
  for (std::size_t u = first; u < last; ++u) {
    const std::size_t t = u / per_frame, z = u % per_frame * slab;
    const std::size_t z_end = std::min(z + slab, dims.planes());
    const std::span<float> part(values.data(), (z_end - z) * dims.plane());
    series.read_slab(t, z, z_end, part);
    const auto [mn, mx] = std::minmax_element(part.begin(), part.end());
    lo[0] = std::min(lo[0], static_cast<double>(*mn));
    hi[0] = std::max(hi[0], static_cast<double>(*mx));
    const auto frames_of = [&](std::size_t units) {
      return static_cast<double>(units) / static_cast<double>(per_frame);
    };
    progress.report(frames_of(u + 1 - first), frames_of(last - first), "value range");
  }
  ranks.min(lo);
  ranks.max(hi);
  return {lo[0], hi[0]};
}

void check_value_range(double value_min, double value_max, const std::string& source) {
  const double largest = std::max(std::abs(value_min), std::abs(value_max));
  if (largest <= max_input_magnitude) return;
  char text[240];
  std::snprintf(text, sizeof text,
                ": expected values of magnitude at most %.0e (the decoders' sums must stay finite "
                "in float32), found values up to %.4g: scale the data (divide it by a power of "
                "ten) first",
                max_input_magnitude, largest);
  throw InputError(source + text);
}

fs::path replacement_folder(const fs::path& out) {
  return out / format::detail::replacement_folder_name;
}

bool complete_replacement(const fs::path& out) {
  const nlohmann::json doc = json_file_or_null(replacement_folder(out) / "manifest.json");
  return doc.is_object() && doc.contains("complete") && doc["complete"] == true;
}

bool replaces_container(const fs::path& out, bool overwrite, bool resume) {
  std::error_code ec;
  return fs::exists(out / "manifest.json", ec) &&
         (overwrite || (resume && fs::exists(replacement_folder(out) / "manifest.json", ec)));
}

void commit_replacement(const fs::path& out) {
  const fs::path next = replacement_folder(out);
  const fs::path old_frames = next / "replaced-frames";
  std::error_code ec;
  // Whether the new container has a dictionary: its manifest says (a move stopped halfway may
  // have moved the file already).
  const nlohmann::json doc = json_file_or_null(next / "manifest.json");
  const bool dictionary =
      !(doc.is_object() && doc.contains("dictionary") && doc["dictionary"].is_null());
  try {
    fs::remove(out / "manifest.json");
    if (fs::exists(next / "frames")) {  // not yet moved
      fs::remove_all(old_frames, ec);
      if (fs::exists(fs::symlink_status(out / "frames"))) fs::rename(out / "frames", old_frames);
      fs::rename(next / "frames", out / "frames");
    }
    if (fs::exists(next / "dictionary.bin"))
      fs::rename(next / "dictionary.bin", out / "dictionary.bin");
    else if (!dictionary)
      fs::remove(out / "dictionary.bin");
    fs::rename(next / "manifest.json", out / "manifest.json");
  } catch (const fs::filesystem_error& e) {
    throw InputError("moving the complete container in " + next.string() + " over " + out.string() +
                     " failed (" + e.code().message() + "): the next volreel encode with --out " +
                     out.string() + " finishes the move");
  }
  fs::remove_all(next, ec);
}

namespace {

/// Runs f on rank 0 alone; an exception there is thrown on every rank, with its message, so that
/// no rank waits for a root that gave up. Returns f's flag on every rank.
bool on_root(const Ranks& ranks, const std::function<bool()>& f) {
  std::vector<std::byte> answer(1, std::byte{0});
  if (ranks.root()) {
    try {
      answer[0] = std::byte{static_cast<unsigned char>(f() ? 1 : 0)};
    } catch (const std::exception& e) {
      if (ranks.size() == 1) throw;
      const std::string what = e.what();
      answer.assign(1, std::byte{2});
      for (char ch : what) answer.push_back(static_cast<std::byte>(ch));
      ranks.broadcast(answer);
      throw;
    }
  }
  ranks.broadcast(answer);
  if (answer[0] == std::byte{2})
    throw InputError(
        std::string(reinterpret_cast<const char*>(answer.data()) + 1, answer.size() - 1));
  return answer[0] == std::byte{1};
}

/// The additive figures of a summary, in a fixed order, for summing across ranks.
std::vector<double> additive_figures(const EncodeSummary& s) {
  std::vector<double> v = {static_cast<double>(s.encoded),
                           static_cast<double>(s.skipped),
                           s.unquantized_squared_error,
                           s.quantized_squared_error,
                           static_cast<double>(s.breakdown.frame_tables),
                           static_cast<double>(s.breakdown.constant_bricks),
                           static_cast<double>(s.breakdown.brick_headers),
                           static_cast<double>(s.breakdown.block_entries),
                           static_cast<double>(s.breakdown.codes),
                           static_cast<double>(s.breakdown.alignment),
                           static_cast<double>(s.breakdown.zfp_streams),
                           static_cast<double>(s.breakdown.coarse_levels),
                           s.breakdown.aprons_and_padding,
                           s.breakdown.finest_owned_codes,
                           static_cast<double>(s.code_bits),
                           static_cast<double>(s.blocks_over_bound),
                           s.seconds_pyramid,
                           s.seconds_bricks,
                           s.seconds_omp,
                           s.seconds_quantize,
                           static_cast<double>(s.delivered.frames),
                           s.delivered.squared_error,
                           s.delivered.voxels,
                           static_cast<double>(s.delivered.frames_coded_again),
                           static_cast<double>(s.delivered.frames_at_finest),
                           static_cast<double>(s.bricks_stored),
                           static_cast<double>(s.nodes_interpolated),
                           s.process_seconds};
  for (std::size_t n : s.sparsity_histogram) v.push_back(static_cast<double>(n));
  for (std::size_t n : s.mean_bits_histogram) v.push_back(static_cast<double>(n));
  for (std::size_t n : s.coef_bits_histogram) v.push_back(static_cast<double>(n));
  v.push_back(static_cast<double>(s.split_bricks));
  return v;
}

void set_additive_figures(EncodeSummary& s, std::span<const double> v) {
  std::size_t i = 0;
  const auto count = [&] { return static_cast<std::size_t>(std::llround(v[i++])); };
  s.encoded = count();
  s.skipped = count();
  s.unquantized_squared_error = v[i++];
  s.quantized_squared_error = v[i++];
  s.breakdown.frame_tables = count();
  s.breakdown.constant_bricks = count();
  s.breakdown.brick_headers = count();
  s.breakdown.block_entries = count();
  s.breakdown.codes = count();
  s.breakdown.alignment = count();
  s.breakdown.zfp_streams = count();
  s.breakdown.coarse_levels = count();
  s.breakdown.aprons_and_padding = v[i++];
  s.breakdown.finest_owned_codes = v[i++];
  s.code_bits = count();
  s.blocks_over_bound = count();
  s.seconds_pyramid = v[i++];
  s.seconds_bricks = v[i++];
  s.seconds_omp = v[i++];
  s.seconds_quantize = v[i++];
  s.delivered.frames = count();
  s.delivered.squared_error = v[i++];
  s.delivered.voxels = v[i++];
  s.delivered.frames_coded_again = count();
  s.delivered.frames_at_finest = count();
  s.bricks_stored = count();
  s.nodes_interpolated = count();
  s.process_seconds = v[i++];
  for (std::size_t& n : s.sparsity_histogram) n = count();
  for (std::size_t& n : s.mean_bits_histogram) n = count();
  for (std::size_t& n : s.coef_bits_histogram) n = count();
  s.split_bricks = count();
}

/// Every rank's summary into one, on every rank: sums, the slowest rank's time, the worst frame.
void combine_summaries(const Ranks& ranks, EncodeSummary& s) {
  s.processes = static_cast<std::size_t>(ranks.size());
  s.process_seconds = s.seconds;
  if (ranks.size() == 1) return;
  std::vector<double> sums = additive_figures(s);
  ranks.sum(sums);
  set_additive_figures(s, sums);
  std::array<double, 3> largest = {s.seconds, s.delivered.max_abs_error,
                                   static_cast<double>(s.team_size)};
  ranks.max(largest);
  s.seconds = largest[0];
  s.delivered.max_abs_error = largest[1];
  s.team_size = static_cast<std::size_t>(largest[2]);
  std::array<double, 2> smallest = {s.delivered.worst_frame_psnr, s.delivered.tolerance_scale};
  ranks.min(smallest);
  // The worst frame: the smallest index among the ranks whose worst is the worst PSNR.
  const bool mine = s.delivered.frames > 0 && s.delivered.worst_frame_psnr == smallest[0];
  std::array<double, 1> frame = {mine ? static_cast<double>(s.delivered.worst_frame)
                                      : std::numeric_limits<double>::infinity()};
  ranks.min(frame);
  s.delivered.worst_frame_psnr = smallest[0];
  s.delivered.tolerance_scale = smallest[1];
  if (std::isfinite(frame[0])) s.delivered.worst_frame = static_cast<std::size_t>(frame[0]);
}

}  // namespace

EncodeSummary encode_series(const datasets::SeriesReader& series, const fs::path& out,
                            const EncodeJob& job, const Progress& progress) {
  const Ranks& ranks = job.ranks ? *job.ranks : single_process();
  const auto& info = series.info();
  const std::size_t frames = job.max_frames ? std::min(job.max_frames, info.frames) : info.frames;
  if (frames == 0) throw InputError("the series has no frames");
  CodingSettings coding = job.coding;
  if (coding.value_min == 0 && coding.value_max == 0)
    std::tie(coding.value_min, coding.value_max) = value_range(series, frames, {}, ranks);
  check_value_range(coding.value_min, coding.value_max, info.source);

  format::Manifest m = new_manifest(info, frames, coding, job.max_keyframe_gap, job.provenance);
  std::optional<StoredDictionary> dict;
  if (coding.codec == format::Codec::ksvd) {
    dict = stored_dictionary(job);
  }
  // The identifier that binds the frames and the dictionary to this container.
  const std::span<const std::byte> dictionary_bytes =
      dict ? std::span<const std::byte>(dict->bytes) : std::span<const std::byte>();
  m.container_id = format::container_identifier(m, dictionary_bytes);
  // A container begun before the identifier left out the input's path carries the older one:
  // resumed with the same settings (and the input named as before), it keeps it, so that its
  // frames and dictionary still belong to it.
  if (job.resume && fs::exists(out / "manifest.json")) {
    try {
      const std::uint64_t older = format::container_identifier(m, dictionary_bytes, true);
      if (format::Container(out, true).manifest().container_id == older) m.container_id = older;
    } catch (const format::FormatError&) {
      // prepare_container says what is wrong with it
    }
  }
  coding.container_id = m.container_id;
  if (dict) {
    dict->file.container_id = m.container_id;
    dict->bytes = format::serialize_dictionary_file(dict->file);
    m.dictionary = format::ManifestDictionary{
        "dictionary.bin", dict->bytes.size(), format::manifest_crc(dict->bytes),
        static_cast<std::uint32_t>(dict->dictionary.atom_count())};
  }
  // The encoder at the ε of the frame at hand (a smaller one after a frame missed psnr_target).
  std::optional<FrameEncoder> encoder;
  encoder.emplace(dict ? &dict->dictionary : nullptr, coding);
  double encoder_scale = 1;  // its ε against coding.tolerance
  const bool holds_psnr =
      job.psnr_target > 0 && coding.codec == format::Codec::ksvd && coding.fixed_sparsity == 0;
  const double range = coding.value_max - coding.value_min;
  // The smallest ε a try for psnr_target takes, against the job's.
  const double smallest_scale =
      holds_psnr ? smallest_relative_tolerance *
                       tolerance_range(coding.value_min, coding.value_max) / coding.tolerance
                 : 0.0;
  const format::AtomTable atoms = encoder->atoms();  // the dictionary's; a later ε keeps them

  // 1. An existing container: resume (same settings) or refuse unless told to overwrite. Rank 0
  //    prepares the folder, its manifest and dictionary while the others wait.
  const std::vector<std::byte> no_dictionary;
  const bool resuming = on_root(ranks, [&] {
    const bool r = prepare_container(out, job, m, dict ? dict->bytes : no_dictionary);
    m.complete = false;
    format::write_manifest(out, m);
    return r;
  });

  // 2. The stretches this process codes, [s, e] with s = k·G and e = s + G (the series' last
  //    frame at most), for k in its share; it writes frames (s, e] of each (and frame 0), so that
  //    every frame file is written by one process. Frames of its share already there and valid
  //    are kept when resuming.
  const std::size_t gap = std::max<std::uint32_t>(job.max_keyframe_gap, 1);
  if (job.piecewise && gap > 1)
    throw InputError(
        "coding frames piecewise needs --max-keyframe-gap 1 (a stretch with gaps "
        "holds its frames whole), not " +
        std::to_string(gap));
  const std::size_t stretches = frames == 1 ? 1 : (frames - 1 + gap - 1) / gap;
  //    Teams: frames coded piecewise, fewer stretches than processes: consecutive processes form
  //    a team per stretch share and code each of its frames together, brick by brick, the
  //    team's first process (its writer) writing. Otherwise every process is a team of its own.
  const auto process_count = static_cast<std::size_t>(ranks.size());
  const std::size_t teams = job.piecewise ? std::min(process_count, stretches) : process_count;
  std::size_t team_index = 0;
  while (Ranks::share_of(process_count, team_index, teams).second <=
         static_cast<std::size_t>(ranks.rank()))
    ++team_index;
  const std::unique_ptr<Ranks> team = ranks.split(static_cast<int>(team_index));
  const bool writer = team->root();
  const auto [first_stretch, last_stretch] = Ranks::share_of(stretches, team_index, teams);
  const std::size_t first_frame = first_stretch == 0 ? 0 : first_stretch * gap + 1;
  const std::size_t end_frame =
      last_stretch == first_stretch ? first_frame : std::min(last_stretch * gap, frames - 1) + 1;
  EncodeSummary summary;
  summary.frames = frames;
  summary.team_size = static_cast<std::size_t>(team->size());
  // 1: not to be written by this team (a team's other members code what its writer writes).
  std::vector<char> done(frames, 1);
  std::fill(done.begin() + static_cast<std::ptrdiff_t>(first_frame),
            done.begin() + static_cast<std::ptrdiff_t>(end_frame), 0);
  if (resuming) {
    std::vector<char> there(frames, 0);
    if (writer) there = frames_already_written(out, coding.codec, m, first_frame, end_frame);
    if (team->size() > 1) {  // what the writer found, to every member
      std::vector<std::byte> found(frames);
      std::transform(there.begin(), there.end(), found.begin(),
                     [](char c) { return std::byte(c != 0); });
      team->broadcast(found);
      std::transform(found.begin(), found.end(), there.begin(),
                     [](std::byte b) { return static_cast<char>(b != std::byte{0}); });
    }
    for (std::size_t t = first_frame; t < end_frame; ++t)
      if (there[t]) {
        done[t] = 1;
        if (writer) ++summary.skipped;
      }
  }

  // 3. Encode, a stretch of at most G + 1 frames in memory at a time. Each frame is coded in full
  //    (coded again at a smaller ε while it falls short of psnr_target); then each node keeps its
  //    brick at the steps its interpolation cannot stand in for (keyframes.hpp); s and e store
  //    every node, so a stretch is resumed whole and decodes without frames outside it. A
  //    stretch's ends are coded from the job's ε and the frames between from the ε their
  //    predecessor needed: every frame's coding depends on its stretch alone, so a resumed
  //    stretch, or one coded by another process, comes out the same.
  const double voxels = static_cast<double>(info.dims.voxels());
  const double voxel_count = voxels;
  const auto frame_psnr = [&](double e) {
    return e > 0 ? 10 * std::log10(range * range / (e / voxel_count))
                 : std::numeric_limits<double>::infinity();
  };
  struct Step {
    Volume volume;
    CodedFrame coded;
    double scale = 1;  ///< the ε it was coded at, against the job's
    /// With a PSNR target: the PSNR of the frame as coded (every node stored).
    double psnr = std::numeric_limits<double>::infinity();
  };
  // Codes frame t (read into step.volume) from ε·scale, again at a smaller ε while it misses
  // psnr_target.
  // A piecewise frame is read plane by plane as it is coded (progress: within the frame).
  std::function<void(double)> frame_progress;
  const auto code = [&](std::size_t t, Step& step) {
    if (!job.piecewise) {
      encoder->code_into(t, step.volume, step.coded, gap > 1);
      return;
    }
    PlaneCoding options;
    options.measure_finest = true;
    options.progress = frame_progress;
    options.members = static_cast<std::size_t>(team->size());
    options.member = static_cast<std::size_t>(team->rank());
    encoder->code_planes(
        t, info.dims,
        [&](std::size_t z_begin, std::size_t z_end, std::span<float> planes) {
          series.read_slab(t, z_begin, z_end, planes);
        },
        step.coded, options);
    if (options.members == 1) return;
    // The writer completes the frame from the others' bricks; every member learns its error
    // (the PSNR target's decision is the team's).
    const std::vector<std::byte> part =
        writer ? std::vector<std::byte>{} : team_part(step.coded, options);
    const std::vector<std::vector<std::byte>> parts = team->gather_to_root(part);
    if (writer) join_team_parts(step.coded, std::span(parts).subspan(1), options);
    step.coded.stats.finest_squared_error =
        team->broadcast_value(step.coded.stats.finest_squared_error);
  };
  // Frame t read whole into step's volume (its storage reused).
  const auto read_whole = [&](std::size_t t, Step& step) {
    if (step.volume.data.size() != info.dims.voxels()) step.volume = Volume(info.dims);
    series.read_frame(t, step.volume.data);
  };
  const auto code_step = [&](std::size_t t, Step& step, double scale) {
    if (!job.piecewise) read_whole(t, step);
    const auto use_scale = [&](double wanted) {
      if (wanted == encoder_scale) return;
      CodingSettings scaled = coding;
      scaled.tolerance = coding.tolerance * wanted;
      encoder.emplace(dict ? &dict->dictionary : nullptr, scaled);
      encoder_scale = wanted;
    };
    use_scale(scale);
    code(t, step);
    // The best try so far: its PSNR and ε (against the job's). A smaller ε usually raises the
    // PSNR, but not always by much, nor always at all: quantization steps, mean bits and the
    // blocks that take an atom change in steps (on volumes a few voxels thick a slightly smaller ε
    // was measured 0.05 dB worse). A try that gains nothing is followed by one at half its ε; two
    // in a row mean the payload's finest steps are reached.
    double best = -std::numeric_limits<double>::infinity(), best_scale = scale;
    int stalls = 0;
    const auto keep_best = [&] {
      step.psnr = best;
      if (scale == best_scale) return;
      scale = best_scale;  // the frame keeps the best try (coded again: the same bytes)
      use_scale(scale);
      code(t, step);
    };
    for (int retry = 0; holds_psnr; ++retry) {
      const double squared =
          job.piecewise
              ? step.coded.stats.finest_squared_error
              : finest_level_error(encoder->write(step.coded), atoms, step.volume, t).first;
      // To 1e-9 dB: summed brick by brick (piecewise) or over the whole frame, the error differs
      // in its last bits, and the decisions below must not.
      const double psnr = std::round(frame_psnr(squared) * 1e9) / 1e9;
      step.psnr = psnr;
      if (psnr >= job.psnr_target) break;
      if (psnr >= best + min_retry_gain_db) {
        best = psnr;
        best_scale = scale;
        stalls = 0;
      } else {
        ++stalls;
      }
      // Out of reach (reported with what the frame reached): ε at its floor, or twice no gain.
      if (stalls >= 2 || scale <= smallest_scale) {
        if (!done[t] && writer) ++summary.delivered.frames_at_finest;
        keep_best();
        break;
      }
      if (retry == max_tolerance_retries) {  // reported with the --tolerance to try
        keep_best();
        break;
      }
      if (retry == 0 && !done[t] && writer) ++summary.delivered.frames_coded_again;
      // 0.1 dB more than the shortfall, so that the next try lands above the target; after a try
      // that gained nothing, half its ε.
      // On a grid of 2^-20 octaves, for the same reason: the next ε of a frame coded piecewise is
      // that of the frame coded whole, so that both write the same bytes (but where a PSNR or ε
      // falls within rounding of a grid line).
      const double next =
          stalls > 0 ? scale / 2 : scale * std::pow(10.0, -(job.psnr_target - psnr + 0.1) / 20);
      scale = std::max(std::exp2(std::floor(std::log2(next) * 0x1p20) / 0x1p20), smallest_scale);
      use_scale(scale);
      code(t, step);
    }
    step.scale = scale;
    summary.delivered.tolerance_scale = std::min(summary.delivered.tolerance_scale, scale);
  };
  // Frames of a few bricks each (detail::frames_side_by_side), without a PSNR target (whose
  // retries make a frame's ε depend on the frame before), whole and on one process: coded side
  // by side, one thread each, a batch at a time ahead of their stretch (with a size target every
  // stretch adds one frame), as many as the memory holds besides the stretch.
  // (A machine whose memory is not known bounds nothing, as for the keyframe gap.)
  const std::uint64_t memory = job.memory ? job.memory : default_encode_memory();
  const std::size_t batch =
      holds_psnr || job.piecewise || ranks.size() != 1
          ? 0
          : detail::side_by_side_batch(info.dims, encoder->shape(), static_cast<std::uint32_t>(gap),
                                       memory ? memory : std::numeric_limits<std::uint64_t>::max());
  const bool side_by_side = batch > 0;
  if (side_by_side) summary.frames_at_once = std::min(batch, detail::side_by_side_frames());
  // A decoder of the frames of a stretch from s, as bytes (frame s not among them where
  // `without_first`).
  const auto stretch_decoder = [&](const std::vector<std::vector<std::byte>>& bytes, std::size_t s,
                                   bool without_first) {
    return format::TimeStepDecoder(
        frames, static_cast<std::uint32_t>(gap), atoms, [&bytes, s, without_first](std::size_t t) {
          if (t < s || t - s >= bytes.size() || (t == s && without_first))
            throw std::logic_error("a stretch's step refers to a frame not coded with it");
          return format::FrameFile(bytes[t - s], format::frame_file_name(t), bytes[t - s].size());
        });
  };
  // Frame t's finest level decoded (into `decoded`) against step's original: the squared error
  // and the largest.
  const auto decoded_error = [&](format::TimeStepDecoder& decoder, std::size_t t, const Step& step,
                                 std::vector<float>& decoded) {
    decoder.decode(t, static_cast<std::uint32_t>(step.coded.geometry.size() - 1), decoded);
    double squared = 0, worst = 0;
    for (std::size_t i = 0; i < decoded.size(); ++i) {
      const double d = static_cast<double>(decoded[i]) - static_cast<double>(step.volume.data[i]);
      squared += d * d;
      worst = std::max(worst, std::abs(d));
    }
    return std::pair{squared, worst};
  };
  // Whether a frame of the stretch from s whose keep flags interpolate a node misses psnr_target
  // (or, where its coding missed it too, decodes worse than coded), decoded as a reader does.
  const auto interpolation_misses_psnr = [&](const std::vector<Step>& steps,
                                             const std::vector<std::vector<char>>& keep,
                                             std::size_t s) {
    std::vector<std::vector<std::byte>> trial(steps.size());
    for (std::size_t i = 0; i < steps.size(); ++i)
      trial[i] = encoder->write(steps[i].coded, keep[i]);
    format::TimeStepDecoder decoder = stretch_decoder(trial, s, false);
    std::vector<float> decoded(info.dims.voxels());
    for (std::size_t i = 0; i < steps.size(); ++i) {
      if (std::all_of(keep[i].begin(), keep[i].end(), [](char k) { return k != 0; })) continue;
      const double squared = decoded_error(decoder, s + i, steps[i], decoded).first;
      // Below the target, or below the frame's own coding where that missed it already.
      if (frame_psnr(squared) < std::min(job.psnr_target, steps[i].psnr)) return true;
    }
    return false;
  };
  std::optional<Step> carried;  // the last frame of the previous stretch
  std::vector<Step> pool;       // the other frames of the previous stretch: their buffers reused
  std::size_t coded_frames = 0;
  const std::size_t share_frames = writer ? end_frame - first_frame : 0;
  double reported = 0;          // this process's frames added to the job's progress count
  const auto from_pool = [&] {  // a step whose buffers are reused, where there is one
    Step step;
    if (!pool.empty()) {
      step = std::move(pool.back());
      pool.pop_back();
    }
    return step;
  };
  // Frames coded ahead: frame t and the next ones of this process's share that are neither
  // written nor coded yet, read one after another, then coded side by side; `coded` is called
  // for each afterwards, in order, from this thread (where the progress callback may stop the
  // encode).
  std::map<std::size_t, Step> ahead;
  const auto code_ahead = [&](std::size_t t, const std::function<void(std::size_t)>& coded) {
    std::vector<std::size_t> next{t};
    for (std::size_t u = t + 1; u < end_frame && next.size() + ahead.size() < batch; ++u)
      if (!done[u] && !ahead.contains(u)) next.push_back(u);
    std::vector<Step> batch_steps(next.size());
    for (std::size_t i = 0; i < next.size(); ++i) {
      batch_steps[i] = from_pool();
      read_whole(next[i], batch_steps[i]);
      batch_steps[i].scale = 1;  // the job's ε: no PSNR target
    }
    detail::for_each_side_by_side(next.size(),
                                  [&](std::size_t i) { code(next[i], batch_steps[i]); });
    for (std::size_t i = 0; i < next.size(); ++i) {
      ahead[next[i]] = std::move(batch_steps[i]);
      coded(next[i]);
    }
  };
  for (std::size_t k = first_stretch; k < last_stretch; ++k) {
    const std::size_t s = k * gap, e = std::min(s + gap, frames - 1);
    if (std::all_of(done.begin() + static_cast<std::ptrdiff_t>(s),
                    done.begin() + static_cast<std::ptrdiff_t>(e + 1),
                    [](char d) { return d != 0; })) {
      carried.reset();
      continue;
    }
    const auto start = Clock::now();
    std::vector<Step> steps(e - s + 1);
    // Without gaps a stretch's first frame serves nothing when another process writes it (no
    // keyframe choice, and its last frame stores every node): it is not coded here.
    const bool skip_first = gap == 1 && done[s] && !carried;
    const auto report = [&](std::size_t t, double frames_coded) {
      if (!writer) return;  // a team's progress is its writer's
      char status[64];
      std::snprintf(
          status, sizeof status, "coding frame %zu, %.1f MVoxel/s", t,
          voxels * frames_coded / 1e6 / std::max(1e-9, summary.seconds + seconds_since(start)));
      const double mine = std::min(frames_coded + static_cast<double>(summary.skipped),
                                   static_cast<double>(share_frames));
      if (ranks.size() == 1) {
        progress.report(mine, static_cast<double>(share_frames), status);
        return;
      }
      // One bar for the job: the frames every process has done (rank 0's status).
      ranks.add_progress(mine - reported);
      reported = mine;
      if (ranks.root())
        progress.report(ranks.progress_count(), static_cast<double>(frames), status);
    };
    for (std::size_t t = s; t <= e; ++t) {
      if (t == s && carried) {
        steps[0] = std::move(*carried);
        continue;
      }
      if (t == s && skip_first) continue;
      if (side_by_side) {
        if (!ahead.contains(t))
          code_ahead(t, [&](std::size_t u) {
            if (!done[u]) ++coded_frames;
            report(u, static_cast<double>(coded_frames));
          });
        const auto coded = ahead.find(t);
        steps[t - s] = std::move(coded->second);
        ahead.erase(coded);
        continue;
      }
      steps[t - s] = from_pool();
      frame_progress = [&](double fraction) {
        if (!done[t]) report(t, static_cast<double>(coded_frames) + fraction);
      };
      code_step(t, steps[t - s], t == s || t == e ? 1.0 : steps[t - s - 1].scale);
      if (!done[t]) ++coded_frames;
      report(t, static_cast<double>(coded_frames));
    }
    std::vector<std::vector<char>> keep(steps.size());
    if (gap > 1 && steps.size() > 2) {
      std::vector<const CodedFrame*> coded;
      for (const Step& st : steps) coded.push_back(&st.coded);
      KeyframeRule rule;
      rule.within_coded_error = holds_psnr;
      keep = choose_keyframes(coded, atoms, rule);
      // The rule lets an interpolated brick err up to brick_factor times the coded one, so that
      // fewer are stored; a frame coded just above a PSNR target then falls below it by up to
      // 10·log10(brick_factor) dB. Where one does, the stretch's choice is made again with no
      // interpolation worse than its coding.
      if (holds_psnr && writer && !job.piecewise && interpolation_misses_psnr(steps, keep, s)) {
        rule.brick_factor = 1.0;
        keep = choose_keyframes(coded, atoms, rule);
      }
    }
    summary.seconds += seconds_since(start);
    // The stretch's last frame starts the next one; the others' buffers are reused.
    const auto next_stretch = [&] {
      carried = std::move(steps.back());
      steps.pop_back();
      pool = std::move(steps);
    };
    if (!writer) {  // the writer holds the frames whole
      next_stretch();
      continue;
    }
    // Every frame of the stretch as bytes (the measurement below reads them from memory, since
    // the frames this process does not write may not be on disk yet); this process writes its own.
    std::vector<std::vector<std::byte>> bytes(steps.size());
    std::vector<char> wrote(steps.size(), 0);
    for (std::size_t t = s; t <= e; ++t) {
      if (t == s && skip_first) continue;
      const auto write_start = Clock::now();
      FrameStats st;
      bytes[t - s] = encoder->write(steps[t - s].coded, keep[t - s], &st);
      if (done[t]) continue;
      // Never write a frame that a reader would refuse.
      try {
        format::validate_payloads(format::FrameView(bytes[t - s], format::frame_file_name(t)),
                                  atoms);
      } catch (const format::FormatError& err) {
        throw std::runtime_error("frame " + std::to_string(t) +
                                 " was coded into bytes that do not decode, so it was not "
                                 "written (" +
                                 err.what() + ")");
      }
      format::write_container_file(out, format::frame_file_name(t), bytes[t - s]);
      m.frames[t] = format::ManifestFrame{format::frame_file_name(t), bytes[t - s].size(),
                                          format::manifest_crc(bytes[t - s])};
      // One process alone keeps the manifest current, so that an interrupted encode resumes
      // from it; with several, rank 0 writes it once every frame is there.
      if (ranks.size() == 1) format::write_manifest(out, m);
      done[t] = 1;
      wrote[t - s] = 1;
      summary.seconds += seconds_since(write_start);
      add_frame(st, summary);
    }
    // The delivered error of every step this process wrote, decoded as a reader does
    // (interpolated nodes included).
    format::TimeStepDecoder decoder = stretch_decoder(bytes, s, skip_first);
    std::vector<float> decoded(job.piecewise ? 0 : info.dims.voxels());
    for (std::size_t t = s; t <= e; ++t) {
      if (!wrote[t - s]) continue;
      const Step& step = steps[t - s];
      double squared = 0, worst = 0;
      if (job.piecewise) {  // measured as it was coded: every node keeps its brick
        squared = step.coded.stats.finest_squared_error;
        worst = step.coded.stats.finest_max_error;
      } else {
        std::tie(squared, worst) = decoded_error(decoder, t, step, decoded);
      }
      DeliveredQuality& q = summary.delivered;
      ++q.frames;
      q.squared_error += squared;
      q.voxels += voxel_count;
      q.max_abs_error = std::max(q.max_abs_error, worst);
      if (frame_psnr(squared) < q.worst_frame_psnr) {
        q.worst_frame_psnr = frame_psnr(squared);
        q.worst_frame = t;
      }
    }
    next_stretch();
  }

  // 4. The manifest, complete: rank 0 lists every frame from what each process wrote or kept.
  std::vector<std::uint64_t> records;  // frame, bytes, CRC of each frame of this share
  for (std::size_t t = writer ? first_frame : end_frame; t < end_frame; ++t) {
    if (!m.frames[t]) throw std::logic_error("a frame of this process's share has no record");
    records.insert(records.end(), {t, m.frames[t]->bytes, m.frames[t]->crc32c});
  }
  // The rest of this process's frames (those found written) in the job's count before the
  // gather, so that rank 0 reads every process's count after it.
  if (ranks.size() > 1) ranks.add_progress(static_cast<double>(share_frames) - reported);
  records = ranks.gather(records);
  combine_summaries(ranks, summary);
  if (ranks.size() > 1 && ranks.root())
    progress.report(ranks.progress_count(), static_cast<double>(frames), "every frame written");
  on_root(ranks, [&] {
    for (auto& f : m.frames) f.reset();
    for (std::size_t i = 0; i + 2 < records.size(); i += 3)
      m.frames[records[i]] =
          format::ManifestFrame{format::frame_file_name(records[i]), records[i + 1],
                                static_cast<std::uint32_t>(records[i + 2])};
    for (std::size_t t = 0; t < frames; ++t)
      if (!m.frames[t]) throw std::logic_error("no process wrote frame " + std::to_string(t));
    m.complete = true;
    format::write_manifest(out, m);
    return true;
  });
  const format::Container written(out);
  summary.container_bytes = written.total_bytes();
  summary.bps =
      8.0 * static_cast<double>(summary.container_bytes) / (voxels * static_cast<double>(frames));
  summary.mvoxels_per_s =
      summary.seconds > 0 ? voxels * static_cast<double>(summary.encoded) / 1e6 / summary.seconds
                          : 0;
  summary.coding = job.coding;
  return summary;
}

double DeliveredQuality::sequence_psnr(double range) const {
  if (!(squared_error > 0) || !(voxels > 0)) return std::numeric_limits<double>::infinity();
  return 10 * std::log10(range * range / (squared_error / voxels));
}

}  // namespace volreel::encoder
