// netcdf_reader.cpp: reads a time series from a NetCDF file (classic or NetCDF-4), the format of
// climate and ocean models: one variable of dimensions (time, z, y, x) — x the last, fastest — or
// (z, y, x) for a single frame. The variable and the time dimension are chosen by name or found;
// CF conventions are read: coordinate variables give the spacing and the times, scale_factor and
// add_offset unpack values, _FillValue and missing_value mark missing ones (refused, or replaced
// by --replace-nan), as are values equal to NetCDF's default fill (data never written). Any
// numeric type is converted to float32 by the NetCDF library.
//
// The Debian NetCDF library is not thread-safe, so every call holds one global mutex.
#include <netcdf.h>
#include <array>
#include <cctype>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <optional>
#include <vector>

#include "detail.hpp"
#include "volreel/format/error.hpp"

namespace volreel::datasets::detail {

namespace fs = std::filesystem;

std::optional<long double> classic_values_end(const std::vector<unsigned char>& header,
                                              int variables, std::size_t records) {
  std::size_t at = 0;
  bool failed = false;
  const auto take = [&](std::size_t bytes) -> std::uint64_t {
    if (failed || bytes > header.size() - std::min(at, header.size())) {
      failed = true;
      return 0;
    }
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < bytes; ++i) v = (v << 8) | header[at + i];  // big-endian
    at += bytes;
    return v;
  };
  const auto skip = [&](std::uint64_t bytes) {
    if (bytes > header.size() - std::min(at, header.size()))
      failed = true;
    else
      at += static_cast<std::size_t>(bytes);
  };
  const auto padded = [](std::uint64_t bytes) { return (bytes + 3) / 4 * 4; };
  if (header.size() < 4 || header[0] != 'C' || header[1] != 'D' || header[2] != 'F')
    return std::nullopt;
  const unsigned version = header[3];
  if (version != 1 && version != 2 && version != 5) return std::nullopt;
  at = 4;
  const std::size_t count = version == 5 ? 8 : 4;   // nelems, dim lengths, dimids, vsize
  const std::size_t offset = version == 1 ? 4 : 8;  // begin
  const auto type_bytes = [](std::uint64_t type) -> std::uint64_t {
    switch (type) {
      case 1:
      case 2:
      case 7:
        return 1;  // byte, char, ubyte
      case 3:
      case 8:
        return 2;  // short, ushort
      case 4:
      case 5:
      case 9:
        return 4;  // int, float, uint
      case 6:
      case 10:
      case 11:
        return 8;  // double, int64, uint64
      default:
        return 0;
    }
  };
  // A count past the header cannot be (and would wrap the arithmetic below): the walk fails.
  const auto length = [&] {
    const std::uint64_t n = take(count);
    if (n > header.size()) failed = true;
    return failed ? 0 : n;
  };
  const auto name = [&] { skip(padded(length())); };
  const auto attributes = [&] {
    take(4);  // NC_ATTRIBUTE, or 0 (absent)
    const std::uint64_t n = take(count);
    for (std::uint64_t i = 0; i < n && !failed; ++i) {
      name();
      const std::uint64_t bytes = type_bytes(take(4));
      if (bytes == 0) failed = true;
      skip(padded(length() * bytes));
    }
  };
  take(count);  // numrecs (the library's count is used: it also handles streaming files)
  take(4);      // NC_DIMENSION, or 0 (absent)
  const std::uint64_t dimensions = take(count);
  std::vector<std::uint64_t> lengths;
  for (std::uint64_t i = 0; i < dimensions && !failed && i < header.size(); ++i) {
    name();
    lengths.push_back(take(count));  // 0: the record dimension
  }
  attributes();  // global attributes
  take(4);       // NC_VARIABLE, or 0 (absent)
  if (take(count) != static_cast<std::uint64_t>(variables) || failed) return std::nullopt;
  struct Var {
    long double size = 0, begin = 0;
    bool record = false;
  };
  std::vector<Var> vars;
  for (int v = 0; v < variables && !failed; ++v) {
    Var var;
    name();
    const std::uint64_t rank = take(count);
    var.size = 1;
    for (std::uint64_t d = 0; d < rank && !failed; ++d) {
      const std::uint64_t id = take(count);
      if (id >= lengths.size()) return std::nullopt;
      if (lengths[id] == 0)
        var.record = true;
      else
        var.size *= static_cast<long double>(lengths[id]);
    }
    attributes();
    const std::uint64_t bytes = type_bytes(take(4));
    take(count);  // vsize: redundant, and wrong for large variables; computed instead
    var.begin = static_cast<long double>(take(offset));
    if (bytes == 0) return std::nullopt;
    var.size *= static_cast<long double>(bytes);
    vars.push_back(var);
  }
  if (failed) return std::nullopt;
  // Dimension lengths multiply past any file (and past long double's range): the largest end a
  // byte count holds says as much.
  for (const Var& v : vars)
    if (!(v.size < classic_end_limit)) return classic_end_limit;
  // A record holds every record variable's values, each padded to 4 bytes unless it is the only
  // one.
  long double record_bytes = 0;
  const auto record_variables =
      std::count_if(vars.begin(), vars.end(), [](const Var& v) { return v.record; });
  for (const Var& v : vars)
    if (v.record) record_bytes += record_variables == 1 ? v.size : std::ceil(v.size / 4) * 4;
  long double end = static_cast<long double>(at);  // the header
  for (const Var& v : vars) {
    if (v.record && records == 0) continue;
    end = std::max(end, v.begin + v.size +
                            (v.record ? static_cast<long double>(records - 1) * record_bytes : 0));
  }
  return std::isfinite(end) ? std::min(end, classic_end_limit) : classic_end_limit;
}

namespace {

/// A byte count as text: the integer below classic_end_limit, past it a bound.
std::string bytes_text(long double bytes) {
  return bytes < classic_end_limit ? std::to_string(static_cast<unsigned long long>(bytes))
                                   : std::string("more than 2^63");
}

std::mutex& netcdf_mutex() {
  static std::mutex m;
  return m;
}

class NetcdfReader final : public SeriesReader {
 public:
  NetcdfReader(fs::path file, const OpenOptions& options)
      : file_(std::move(file)), replace_nan_(options.replace_nan) {
    std::lock_guard lock(netcdf_mutex());
    check(nc_open(file_.c_str(), NC_NOWRITE, &ncid_),
          "cannot open it as NetCDF (its header may be damaged or cut short)");
    try {
      check_classic_size();
      open(options);
    } catch (...) {
      nc_close(ncid_);
      throw;
    }
  }
  ~NetcdfReader() override {
    std::lock_guard lock(netcdf_mutex());
    nc_close(ncid_);
  }
  NetcdfReader(const NetcdfReader&) = delete;
  NetcdfReader& operator=(const NetcdfReader&) = delete;

  void read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                 std::span<float> out) const override {
    check_slab(info_, t, z_begin, z_end, out.size());
    std::vector<std::size_t> start(static_cast<std::size_t>(rank_), 0),
        count(static_cast<std::size_t>(rank_), 1);
    const auto z = static_cast<std::size_t>(rank_ - 3);
    start[z] = z_begin;
    count[z] = z_end - z_begin;
    count[z + 1] = static_cast<std::size_t>(info_.dims.y);
    count[z + 2] = static_cast<std::size_t>(info_.dims.x);
    if (rank_ == 4) start[0] = t;
    if (mapped_) {
      // The file's spatial dimensions in another order than (z, y, x): the slab read in the
      // file's order (one call: a mapped read goes value by value), then placed in [z][y][x].
      const std::size_t strides[3] = {1, static_cast<std::size_t>(info_.dims.x),
                                      static_cast<std::size_t>(info_.dims.plane())};
      const std::size_t sizes[3] = {static_cast<std::size_t>(info_.dims.x),
                                    static_cast<std::size_t>(info_.dims.y), z_end - z_begin};
      std::size_t n[3], stride[3];  // per spatial dimension in file order
      for (int d = 0; d < 3; ++d) {
        const int axis = axis_of_dim_[static_cast<std::size_t>(d)];
        const auto at = static_cast<std::size_t>(rank_ - 3 + d);
        start[at] = axis == 2 ? z_begin : 0;
        count[at] = n[d] = sizes[axis];
        stride[d] = strides[axis];
      }
      std::vector<float> file_order(out.size());
      {
        std::lock_guard lock(netcdf_mutex());
        check(nc_get_vara_float(ncid_, varid_, start.data(), count.data(), file_order.data()),
              "variable '" + variable_ + "' frame " + std::to_string(t));
      }
      std::size_t k = 0;
      for (std::size_t i = 0; i < n[0]; ++i)
        for (std::size_t j = 0; j < n[1]; ++j)
          for (std::size_t l = 0; l < n[2]; ++l)
            out[i * stride[0] + j * stride[1] + l * stride[2]] = file_order[k++];
    } else {
      std::lock_guard lock(netcdf_mutex());
      check(nc_get_vara_float(ncid_, varid_, start.data(), count.data(), out.data()),
            "variable '" + variable_ + "' frame " + std::to_string(t));
    }
    // Missing values are refused, naming what they hold, unless replaced; packed values are
    // unpacked.
    for (std::size_t i = 0; i < out.size(); ++i) {
      float& v = out[i];
      const bool invalid = (valid_min_ && v < *valid_min_) || (valid_max_ && v > *valid_max_);
      if ((fill_ && v == *fill_) || (missing_ && v == *missing_) || invalid) {
        if (!replace_nan_) {
          char value[32];
          std::snprintf(value, sizeof value, "%.9g", static_cast<double>(v));
          const std::string what =
              fill_ && v == *fill_ ? (fill_default_ ? "NetCDF's default fill value (never written)"
                                                    : "the variable's _FillValue")
              : missing_ && v == *missing_ ? "the variable's missing_value"
                                           : "outside the variable's " + valid_text_;
          fail("variable '" + variable_ + "' frame " + std::to_string(t) + ": voxel " +
               voxel_name(i, info_.dims, z_begin) + " holds " + value + ", " + what +
               ": a missing value; use --replace-nan V to substitute a value");
        }
        v = *replace_nan_;
        continue;
      }
      if (scale_ != 1 || offset_ != 0)
        v = static_cast<float>(static_cast<double>(v) * scale_ + offset_);
    }
    check_finite(out, info_.dims,
                 "'" + file_.string() + "' variable '" + variable_ + "' frame " + std::to_string(t),
                 replace_nan_, z_begin);
  }

 private:
  fs::path file_;
  std::optional<float> replace_nan_;
  int ncid_ = -1, varid_ = -1, rank_ = 0;
  std::string variable_;
  std::optional<float> fill_, missing_;
  std::optional<float> valid_min_, valid_max_;  ///< CF valid_range, valid_min, valid_max
  std::string valid_text_;                      ///< "valid_range [a, b]", for messages
  /// The spatial dimensions named x, y and z in another order than (z, y, x): read by name.
  bool mapped_ = false;
  std::array<int, 3> axis_of_dim_{2, 1, 0};  ///< per spatial dimension in file order: 0 x .. 2 z
  bool fill_default_ = false;  ///< fill_ is NetCDF's default for the type, not an attribute
  double scale_ = 1, offset_ = 0;

  [[noreturn]] void fail(const std::string& what) const {
    throw InputError("'" + file_.string() + "': " + what);
  }
  void check(int status, const std::string& what) const {
    if (status != NC_NOERR) fail(what + ": " + nc_strerror(status));
  }

  /// A classic-format file (CDF-1, 2 or 5) stores every variable's values in full after its
  /// header, and NetCDF reads past a truncated end as zeros: the file must be at least as long
  /// as its variables' data (records included). NetCDF-4 (HDF5) files are checked by HDF5.
  void check_classic_size() const {
    int format = 0;
    check(nc_inq_format(ncid_, &format), "format");
    if (format != NC_FORMAT_CLASSIC && format != NC_FORMAT_64BIT_OFFSET && format != NC_FORMAT_CDF5)
      return;
    int variables = 0, unlimited = -1;
    check(nc_inq_nvars(ncid_, &variables), "variables");
    check(nc_inq_unlimdim(ncid_, &unlimited), "the unlimited dimension");
    const std::size_t records = unlimited >= 0 ? dimension_length(unlimited) : 0;
    long double need = 0;
    for (int v = 0; v < variables; ++v) {
      nc_type type = 0;
      std::size_t type_bytes = 0;
      check(nc_inq_vartype(ncid_, v, &type), "variable " + std::to_string(v));
      check(nc_inq_type(ncid_, type, nullptr, &type_bytes), "variable " + std::to_string(v));
      long double values = 1;
      bool record = false;
      for (const int d : variable_dimensions(v)) {
        if (d == unlimited)
          record = true;
        else
          values *= static_cast<long double>(dimension_length(d));
      }
      // A fixed-size variable's values are padded to 4 bytes (a record's are not, when it is
      // the only record variable: a lower bound leaves that out).
      const long double bytes = values * static_cast<long double>(type_bytes);
      need += record ? bytes * static_cast<long double>(records) : std::ceil(bytes / 4) * 4;
    }
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(file_, ec);
    if (ec) return;
    if (static_cast<long double>(size) < need)
      fail("the file is " + std::to_string(size) + " bytes, but its variables' values alone take " +
           bytes_text(need) + " (and the header more): it is truncated");
    // Exactly, from the header's offsets: where the last value ends (a header larger than the
    // first MiB, or one that cannot be walked, keeps the bound above).
    std::vector<unsigned char> header(std::min<std::uintmax_t>(size, std::uintmax_t{1} << 20));
    read_exact(file_, 0, header);
    const std::optional<long double> end = classic_values_end(header, variables, records);
    if (end && static_cast<long double>(size) < *end)
      fail("the file is " + std::to_string(size) +
           " bytes, but its header places values up to byte " + bytes_text(*end) +
           ": it is truncated");
  }

  std::string dimension_name(int dimid) const {
    char name[NC_MAX_NAME + 1] = {};
    check(nc_inq_dimname(ncid_, dimid, name), "dimension " + std::to_string(dimid));
    return name;
  }
  std::size_t dimension_length(int dimid) const {
    std::size_t n = 0;
    check(nc_inq_dimlen(ncid_, dimid, &n), "dimension '" + dimension_name(dimid) + "'");
    return n;
  }
  std::vector<int> variable_dimensions(int varid) const {
    int rank = 0;
    check(nc_inq_varndims(ncid_, varid, &rank), "variable " + std::to_string(varid));
    std::vector<int> dims(static_cast<std::size_t>(rank));
    if (rank > 0) check(nc_inq_vardimid(ncid_, varid, dims.data()), "variable dimensions");
    return dims;
  }
  std::string variable_name(int varid) const {
    char name[NC_MAX_NAME + 1] = {};
    check(nc_inq_varname(ncid_, varid, name), "variable " + std::to_string(varid));
    return name;
  }
  /// A numeric attribute of variable `varid` as a double, if it has one value.
  std::optional<double> number_attribute(int varid, const char* name) const {
    nc_type type = 0;
    std::size_t length = 0;
    if (nc_inq_att(ncid_, varid, name, &type, &length) != NC_NOERR || length != 1 ||
        type == NC_CHAR || type == NC_STRING)
      return std::nullopt;
    double v = 0;
    check(nc_get_att_double(ncid_, varid, name, &v),
          "attribute '" + std::string(name) + "' of '" + variable_name(varid) + "'");
    return v;
  }
  /// A numeric attribute of exactly `n` values; none when absent or of another length or type.
  std::optional<std::vector<double>> numbers_attribute(int varid, const char* name,
                                                       std::size_t n) const {
    nc_type type = 0;
    std::size_t length = 0;
    if (nc_inq_att(ncid_, varid, name, &type, &length) != NC_NOERR || length != n ||
        type == NC_CHAR || type == NC_STRING)
      return std::nullopt;
    std::vector<double> v(n);
    check(nc_get_att_double(ncid_, varid, name, v.data()),
          "attribute '" + std::string(name) + "' of '" + variable_name(varid) + "'");
    return v;
  }
  /// The value NetCDF gives data never written to a variable of `type` without a _FillValue (CF:
  /// missing too); none for bytes, whose default fill is a valid value (NetCDF's guidance).
  static std::optional<float> default_fill(nc_type type) {
    switch (type) {
      case NC_SHORT:
        return static_cast<float>(NC_FILL_SHORT);
      case NC_USHORT:
        return static_cast<float>(NC_FILL_USHORT);
      case NC_INT:
        return static_cast<float>(NC_FILL_INT);
      case NC_UINT:
        return static_cast<float>(NC_FILL_UINT);
      case NC_FLOAT:
        return NC_FILL_FLOAT;
      case NC_DOUBLE:
        return static_cast<float>(NC_FILL_DOUBLE);
      default:
        return std::nullopt;
    }
  }

  /// The values of the coordinate variable of dimension `dimid` (a 1D variable of its name).
  std::optional<std::vector<double>> coordinate(int dimid) const {
    int varid = -1;
    if (nc_inq_varid(ncid_, dimension_name(dimid).c_str(), &varid) != NC_NOERR) return std::nullopt;
    const std::vector<int> dims = variable_dimensions(varid);
    if (dims.size() != 1 || dims[0] != dimid) return std::nullopt;
    std::vector<double> values(dimension_length(dimid));
    if (!values.empty())
      check(nc_get_var_double(ncid_, varid, values.data()),
            "coordinate variable '" + dimension_name(dimid) + "'");
    return values;
  }

  /// The variable's candidates: numeric variables of 3 or 4 dimensions that are not coordinates.
  std::vector<std::string> candidates() const {
    int count = 0;
    check(nc_inq_nvars(ncid_, &count), "variables");
    std::vector<std::string> out;
    for (int v = 0; v < count; ++v) {
      const auto dims = variable_dimensions(v);
      if (dims.size() == 3 || dims.size() == 4) out.push_back(variable_name(v));
    }
    return out;
  }

  void open(const OpenOptions& options) {
    const std::vector<std::string> found = candidates();
    std::string listed;
    for (const auto& c : found) listed += (listed.empty() ? "" : ", ") + c;
    int variables = 0;
    check(nc_inq_nvars(ncid_, &variables), "variables");
    if (listed.empty())
      listed =
          variables == 0 ? "none: the file holds no variable at all (a damaged header?)" : "none";
    variable_ = options.variable;
    if (variable_.empty()) {
      if (found.empty()) {
        // Every variable with its dimensions: what the file holds instead.
        std::string all;
        for (int v = 0; v < variables; ++v) {
          std::string dims;
          for (const int d : variable_dimensions(v))
            dims += (dims.empty() ? "" : ", ") + dimension_name(d);
          all += (all.empty() ? "" : "; ") + variable_name(v) + " (" + dims + ")";
        }
        fail("holds no variable of 3 or 4 dimensions ((time,) z, y, x), which volreel reads" +
             (all.empty() ? std::string(", and no variable at all (a damaged header?)")
                          : ": its variables are " + all));
      }
      if (found.size() != 1)
        fail("say which variable to read with --variable NAME (variables of 3 or 4 dimensions: " +
             listed + ")");
      variable_ = found.front();
    }
    if (nc_inq_varid(ncid_, variable_.c_str(), &varid_) != NC_NOERR)
      fail("has no variable '" + variable_ + "' (variables of 3 or 4 dimensions: " + listed + ")");
    nc_type type = 0;
    check(nc_inq_vartype(ncid_, varid_, &type), "variable '" + variable_ + "'");
    if (type == NC_CHAR || type == NC_STRING || type >= NC_FIRSTUSERTYPEID)
      fail("variable '" + variable_ + "' is not numeric");
    const std::vector<int> dims = variable_dimensions(varid_);
    rank_ = static_cast<int>(dims.size());
    std::string shape;
    for (int d : dims)
      shape += (shape.empty() ? "" : ", ") + dimension_name(d) + " = " +
               std::to_string(dimension_length(d));
    // The time dimension: named, else the unlimited one, else one called time or t.
    int unlimited = -1;
    check(nc_inq_unlimdim(ncid_, &unlimited), "the unlimited dimension");
    int time_dim = -1;
    for (int d : dims) {
      const std::string name = dimension_name(d);
      if (!options.time_dimension.empty()
              ? name == options.time_dimension
              : (d == unlimited || name == "time" || name == "t" || name == "Time"))
        time_dim = d;
    }
    if (!options.time_dimension.empty() && time_dim < 0)
      fail("variable '" + variable_ + "' (" + shape + ") has no dimension '" +
           options.time_dimension + "' (--time-dim)");
    if (time_dim >= 0 && rank_ != 4)
      fail("variable '" + variable_ + "' (" + shape +
           "): expected (time, z, y, x) with a time dimension, or (z, y, x)");
    if (time_dim < 0 && rank_ != 3)
      fail("variable '" + variable_ + "' (" + shape +
           "): expected (z, y, x) or (time, z, y, x); name the time dimension with --time-dim");
    if (time_dim >= 0 && dims[0] != time_dim)
      fail("variable '" + variable_ + "' (" + shape + "): the time dimension '" +
           dimension_name(time_dim) + "' must come first");
    const auto length = [&](int axis) {
      const std::size_t n = dimension_length(dims[static_cast<std::size_t>(axis)]);
      if (n == 0 || n > (std::size_t{1} << 24))
        fail("variable '" + variable_ + "' (" + shape + "): expected sizes in 1..16777216");
      return static_cast<std::int64_t>(n);
    };
    // Spatial dimensions named x, y and z (any case) are read by their names in any order;
    // otherwise the last is x and the first y then z before it.
    std::array<int, 3> by_name{-1, -1, -1};  // per axis x, y, z: its position among the three
    for (int d = 0; d < 3; ++d) {
      std::string name = dimension_name(dims[static_cast<std::size_t>(rank_ - 3 + d)]);
      for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      const int axis = name == "x" ? 0 : name == "y" ? 1 : name == "z" ? 2 : -1;
      if (axis >= 0 && by_name[static_cast<std::size_t>(axis)] < 0)
        by_name[static_cast<std::size_t>(axis)] = d;
    }
    std::string notes;
    if (by_name[0] >= 0 && by_name[1] >= 0 && by_name[2] >= 0 &&
        (by_name[0] != 2 || by_name[1] != 1 || by_name[2] != 0)) {
      mapped_ = true;
      for (int a = 0; a < 3; ++a)
        axis_of_dim_[static_cast<std::size_t>(by_name[static_cast<std::size_t>(a)])] = a;
      notes += ", its x, y and z read by their names";
    }
    const auto axis_length = [&](int axis) {
      return length(rank_ - 3 + (mapped_ ? by_name[static_cast<std::size_t>(axis)] : 2 - axis));
    };
    info_.dims = Dims{axis_length(0), axis_length(1), axis_length(2)};
    info_.frames = rank_ == 4 ? dimension_length(dims[0]) : 1;
    if (info_.frames == 0) fail("variable '" + variable_ + "' has no time steps");
    info_.variable = variable_;
    // CF: spacing from the coordinate variables (uniform, or their mean step), times from the
    // time coordinate.
    for (int a = 0; a < 3; ++a) {
      const int dim = dims[static_cast<std::size_t>(
          rank_ - 3 + (mapped_ ? by_name[static_cast<std::size_t>(a)] : 2 - a))];
      const auto values = coordinate(dim);
      if (!values || values->size() < 2) continue;
      const double step =
          std::abs(values->back() - values->front()) / static_cast<double>(values->size() - 1);
      if (!(step > 0) || !std::isfinite(step)) continue;
      for (std::size_t i = 1; i < values->size(); ++i)
        if (std::abs(std::abs((*values)[i] - (*values)[i - 1]) - step) > 1e-3 * step) {
          notes += ", non-uniform '" + dimension_name(dim) + "': mean step used";
          break;
        }
      info_.spacing[static_cast<std::size_t>(a)] = step;
    }
    std::optional<std::vector<double>> times;
    if (rank_ == 4) times = coordinate(dims[0]);
    if (times) {
      for (std::size_t i = 1; i < times->size(); ++i)
        if (!((*times)[i] > (*times)[i - 1]) || !std::isfinite((*times)[i]))
          fail("time coordinate '" + dimension_name(dims[0]) + "': expected increasing numbers, " +
               "found " + format::number_text((*times)[i]) + " after " +
               format::number_text((*times)[i - 1]));
      info_.timestamps = *times;
    } else {
      for (std::size_t t = 0; t < info_.frames; ++t)
        info_.timestamps.push_back(static_cast<double>(t));
    }
    if (const auto v = number_attribute(varid_, "_FillValue")) {
      fill_ = static_cast<float>(*v);
    } else {
      fill_ = default_fill(type);
      fill_default_ = true;
    }
    if (const auto v = number_attribute(varid_, "missing_value")) missing_ = static_cast<float>(*v);
    // CF: values outside valid_range (or below valid_min, above valid_max) are missing; like the
    // fill value, in the stored (packed) values.
    char text[96];
    if (const auto r = numbers_attribute(varid_, "valid_range", 2)) {
      valid_min_ = static_cast<float>((*r)[0]);
      valid_max_ = static_cast<float>((*r)[1]);
      std::snprintf(text, sizeof text, "valid_range [%.9g, %.9g]", (*r)[0], (*r)[1]);
      valid_text_ = text;
    } else {
      const auto lo = number_attribute(varid_, "valid_min");
      const auto hi = number_attribute(varid_, "valid_max");
      if (lo) valid_min_ = static_cast<float>(*lo);
      if (hi) valid_max_ = static_cast<float>(*hi);
      if (lo && hi)
        std::snprintf(text, sizeof text, "valid_min %.9g and valid_max %.9g", *lo, *hi);
      else if (lo || hi)
        std::snprintf(text, sizeof text, "%s %.9g", lo ? "valid_min" : "valid_max", lo ? *lo : *hi);
      if (lo || hi) valid_text_ = text;
    }
    scale_ = number_attribute(varid_, "scale_factor").value_or(1.0);
    offset_ = number_attribute(varid_, "add_offset").value_or(0.0);
    info_.source =
        "NetCDF " + file_.string() + " (variable " + variable_ + ": " + shape + notes + ")";
  }
};

}  // namespace

std::unique_ptr<SeriesReader> open_netcdf(const fs::path& file, const OpenOptions& options) {
  return std::make_unique<NetcdfReader>(file, options);
}

}  // namespace volreel::datasets::detail
