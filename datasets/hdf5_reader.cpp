// hdf5_reader.cpp: reads a time series from an HDF5 file, either one 3D dataset per time step
// matched by a name pattern (e.g. JHTDB cutouts' "Pressure_0001", shape [z][y][x] or
// [z][y][x][1]) or one 4D dataset [t][z][y][x]. Any numeric type is converted to float32 by HDF5.
//
// The Debian HDF5 library is not built thread-safe, so every HDF5 call holds one global mutex.
#include <hdf5.h>

#include <algorithm>
#include <cctype>
#include <mutex>
#include <vector>

#include "detail.hpp"

namespace volreel::datasets::detail {

namespace fs = std::filesystem;

namespace {

std::mutex& hdf5_mutex() {
  static std::mutex m;
  return m;
}

/// Owns one HDF5 identifier; closes it with the given function.
class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

struct FrameSource {
  std::string dataset;  ///< dataset name
  hsize_t index;        ///< index along the first axis for a 4D dataset, unused for 3D
  double timestamp;
};

/// Does `name` match `pattern`, where a run of '#' matches exactly that many digits and '*'
/// matches any text? On a match, returns the number formed by the digits the pattern's '#' or
/// '*' matched (or -1 if none).
bool matches(const std::string& pattern, const std::string& name, long long& number) {
  const auto hash = pattern.find('#');
  const auto star = pattern.find('*');
  number = -1;
  if (hash == std::string::npos && star == std::string::npos) return pattern == name;
  const auto pos = hash != std::string::npos ? hash : star;
  const auto run_end = hash != std::string::npos
                           ? std::min(pattern.find_first_not_of('#', hash), pattern.size())
                           : star + 1;
  const std::string prefix = pattern.substr(0, pos);
  const std::string suffix = pattern.substr(run_end);
  if (name.size() < prefix.size() + suffix.size()) return false;
  if (name.compare(0, prefix.size(), prefix) != 0) return false;
  if (name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0) return false;
  const std::string middle =
      name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
  const bool all_digits =
      !middle.empty() && std::all_of(middle.begin(), middle.end(),
                                     [](unsigned char c) { return std::isdigit(c) != 0; });
  if (hash != std::string::npos && (!all_digits || middle.size() != run_end - hash)) return false;
  if (all_digits && middle.size() < 18) number = std::stoll(middle);
  return true;
}

herr_t collect_dataset(hid_t group, const char* name, const H5L_info_t*, void* data) {
  Handle object(H5Oopen(group, name, H5P_DEFAULT), H5Oclose);
  if (object.valid() && H5Iget_type(object.get()) == H5I_DATASET)
    static_cast<std::vector<std::string>*>(data)->push_back(name);
  return 0;
}

class Hdf5Reader final : public SeriesReader {
 public:
  Hdf5Reader(fs::path file, const OpenOptions& options)
      : file_(std::move(file)), replace_nan_(options.replace_nan) {
    std::lock_guard lock(hdf5_mutex());
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors are reported by us, not printed by HDF5
    Handle f(H5Fopen(file_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
    if (!f.valid()) throw InputError("'" + file_.string() + "' cannot be opened as an HDF5 file");
    std::vector<std::string> names;
    H5Literate(f.get(), H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, collect_dataset, &names);
    if (names.empty()) throw InputError("'" + file_.string() + "' holds no dataset at its root");

    std::string pattern = options.dataset;
    if (pattern.empty()) {
      if (names.size() == 1) {
        pattern = names.front();
      } else {
        std::string list;
        for (std::size_t i = 0; i < names.size() && i < 8; ++i) list += (i ? ", " : "") + names[i];
        throw InputError("'" + file_.string() + "' holds " + std::to_string(names.size()) +
                         " datasets (" + list + (names.size() > 8 ? ", ..." : "") +
                         "): choose with --dataset NAME (one 4D dataset) or a pattern such as "
                         "--dataset 'Pressure_####'");
      }
    }
    std::vector<std::pair<long long, std::string>> matched;
    for (const auto& name : names) {
      long long number;
      if (matches(pattern, name, number)) matched.emplace_back(number, name);
    }
    if (matched.empty())
      throw InputError("'" + file_.string() + "': no dataset matches '" + pattern + "'");
    std::sort(matched.begin(), matched.end());
    // Frames are ordered by their numbers: a name the pattern matched without one (a
    // "Pressure_mean" beside "Pressure_0001"), or two names of one number, would be a frame in
    // no defined place.
    const bool numbered = matched.back().first >= 0;
    for (std::size_t i = 0; i < matched.size(); ++i) {
      if (numbered && matched[i].first < 0)
        throw InputError("'" + file_.string() + "': the pattern '" + pattern + "' matches '" +
                         matched[i].second + "', which has no frame number, besides '" +
                         matched.back().second +
                         "', which has one: write the pattern so that it matches the frames "
                         "alone ('#' for each digit, e.g. Pressure_####)");
      if (i > 0 && matched[i].first >= 0 && matched[i].first == matched[i - 1].first)
        throw InputError("'" + file_.string() + "': the pattern '" + pattern + "' matches '" +
                         matched[i - 1].second + "' and '" + matched[i].second +
                         "', of the same frame number " + std::to_string(matched[i].first) +
                         ": write the pattern so that it matches one of them ('#' for each "
                         "digit)");
    }

    for (const auto& [number, name] : matched) {
      Handle ds(H5Dopen2(f.get(), name.c_str(), H5P_DEFAULT), H5Dclose);
      Handle space(H5Dget_space(ds.get()), H5Sclose);
      const int rank = H5Sget_simple_extent_ndims(space.get());
      if (rank < 3 || rank > 4)
        throw InputError(
            where(name) +
            (rank == 0 ? std::string("is a scalar") : "has rank " + std::to_string(rank)) +
            ", expected 3 ([z][y][x]) or 4");
      hsize_t shape[4] = {0, 0, 0, 1};
      H5Sget_simple_extent_dims(space.get(), shape, nullptr);
      Handle type(H5Dget_type(ds.get()), H5Tclose);
      const auto cls = H5Tget_class(type.get());
      if (cls != H5T_FLOAT && cls != H5T_INTEGER) throw InputError(where(name) + "is not numeric");
      // [z][y][x][1] (a cutout with one component) is one frame; other 4D shapes are [t][z][y][x].
      const bool single_4d = rank == 4 && shape[3] != 1;
      const Dims dims =
          single_4d ? Dims{static_cast<std::int64_t>(shape[3]), static_cast<std::int64_t>(shape[2]),
                           static_cast<std::int64_t>(shape[1])}
                    : Dims{static_cast<std::int64_t>(shape[2]), static_cast<std::int64_t>(shape[1]),
                           static_cast<std::int64_t>(shape[0])};
      if (dims.voxels() == 0) throw InputError(where(name) + "is empty");
      // Storage never allocated: nothing was written, and HDF5 would hand out its fill value
      // (zeros by default) as data.
      // (Storage in external files, H5Pset_external's raw data, is never allocated in the file.)
      H5D_space_status_t allocated = H5D_SPACE_STATUS_ERROR;
      Handle dcpl(H5Dget_create_plist(ds.get()), H5Pclose);
      if (H5Sget_simple_extent_npoints(space.get()) > 0 && H5Pget_external_count(dcpl.get()) == 0 &&
          H5Dget_space_status(ds.get(), &allocated) >= 0 &&
          allocated == H5D_SPACE_STATUS_NOT_ALLOCATED)
        throw InputError(where(name) +
                         "was never written (HDF5 allocated no storage for it): its values "
                         "would all be the fill value; write the data, or name another dataset");
      if (frames_.empty()) {
        info_.dims = dims;
      } else if (dims != info_.dims) {
        throw InputError(where(name) + "is " + to_string(dims) + " but earlier frames are " +
                         to_string(info_.dims));
      }
      if (single_4d) {
        if (matched.size() != 1)
          throw InputError(where(name) + "is 4D but the pattern matched several datasets");
        four_d_ = true;
        for (hsize_t t = 0; t < shape[0]; ++t) frames_.push_back({name, t, static_cast<double>(t)});
      } else {
        frames_.push_back(
            {name, 0,
             number >= 0 ? static_cast<double>(number) : static_cast<double>(frames_.size())});
      }
    }
    info_.frames = frames_.size();
    for (const auto& frame : frames_) info_.timestamps.push_back(frame.timestamp);
    info_.variable = four_d_ ? matched.front().second : pattern;
    info_.source =
        "HDF5 " + file_.string() + " (" + (four_d_ ? "4D dataset " : "datasets ") + pattern + ")";
  }

  void read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                 std::span<float> out) const override {
    check_slab(info_, t, z_begin, z_end, out.size());
    const FrameSource& frame = frames_[t];
    {
      std::lock_guard lock(hdf5_mutex());
      Handle f(H5Fopen(file_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
      if (!f.valid()) throw InputError("'" + file_.string() + "' cannot be opened as an HDF5 file");
      Handle ds(H5Dopen2(f.get(), frame.dataset.c_str(), H5P_DEFAULT), H5Dclose);
      if (!ds.valid()) throw InputError(where(frame.dataset) + "cannot be opened");
      // The planes as a hyperslab: [t][z][y][x] of the 4D dataset (its frame), or [z][y][x] of
      // a 3D one and [z][y][x][1] of a one-component cutout.
      Handle file_space(H5Dget_space(ds.get()), H5Sclose);
      const hsize_t start[5] = {frame.index, z_begin, 0, 0, 0};
      const hsize_t count[5] = {1, static_cast<hsize_t>(z_end - z_begin),
                                static_cast<hsize_t>(info_.dims.y),
                                static_cast<hsize_t>(info_.dims.x), 1};
      const int skip = four_d_ ? 0 : 1;
      const int rank = four_d_ ? 4 : H5Sget_simple_extent_ndims(file_space.get());
      herr_t status = rank == 3 || rank == 4 ? 0 : -1;
      if (status >= 0)
        status = H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start + skip, nullptr,
                                     count + skip, nullptr);
      if (status >= 0) {
        Handle memory_space(H5Screate_simple(rank, count + skip, nullptr), H5Sclose);
        status = H5Dread(ds.get(), H5T_NATIVE_FLOAT, memory_space.get(), file_space.get(),
                         H5P_DEFAULT, out.data());
      }
      if (status < 0)
        throw InputError(where(frame.dataset) + "could not be read (corrupt or truncated file?)");
    }
    check_finite(out, info_.dims, where(frame.dataset) + "frame " + std::to_string(t), replace_nan_,
                 z_begin);
  }

 private:
  std::string where(const std::string& dataset) const {
    return "'" + file_.string() + "' dataset '" + dataset + "' ";
  }

  fs::path file_;
  std::vector<FrameSource> frames_;
  bool four_d_ = false;
  std::optional<float> replace_nan_;
};

}  // namespace

std::unique_ptr<SeriesReader> open_hdf5(const fs::path& file, const OpenOptions& options) {
  return std::make_unique<Hdf5Reader>(file, options);
}

}  // namespace volreel::datasets::detail
