// pyramid.hpp: the brick hierarchy of one frame (MTV-Player §3.2): levels averaging 2×2×2 voxels
// (Cesium patent [0031]) from the frame up to one root brick, and the stored voxels of a brick
// (its interior with a 1-voxel apron, format::BrickShape).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <span>
#include <vector>

#include "volreel/datasets/volume.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder {

/// The levels of a frame's brick hierarchy as dense volumes: [0] the root level … [L−1] the frame.
struct Pyramid {
  format::BrickShape shape;
  std::vector<format::LevelGeometry> geometry;
  std::vector<std::vector<float>> levels;
};
/// Level l−1 voxel (i,j,k) = mean of level-l voxels (2i+a, 2j+b, 2k+c), a,b,c ∈ {0,1}, indices
/// clamped to the level (edge replication where a size is odd).
/// The levels are those of bricks of `shape` (format::level_geometry).
Pyramid build_pyramid(const Volume& frame, format::BrickShape shape = {});
/// Stored voxels of brick (x, y, z) of level l into out (S³ for bricks of S = pyramid.shape.size
/// voxels a side, interior I = S − 2; x fastest): level voxel (Ix − 1 + a, Iy − 1 + b,
/// Iz − 1 + c) for a, b, c in [0, S), clamped to the level.
void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out);

/// Level l−1 planes [k_begin, k_end) of a level whose finer level l has dims `fine_dims`, from
/// the finer planes (global z) that `fine_plane` returns: the averages build_pyramid computes.
/// `out` holds the coarse planes from k_begin on. With `detail_out`, also each coarse voxel's
/// detail: the mean squared difference between the frame's voxels under it and its value (the
/// 8 finer voxels' squared differences from their mean, plus their own detail from `fine_detail`
/// where the finer level is not the frame's).
void downsample_planes(const std::array<std::uint32_t, 3>& fine_dims,
                       const std::array<std::uint32_t, 3>& dims,
                       const std::function<const float*(std::size_t z)>& fine_plane,
                       std::size_t k_begin, std::size_t k_end, float* out,
                       const std::function<const float*(std::size_t z)>& fine_detail = {},
                       float* detail_out = nullptr);

/// The same levels as build_pyramid, held a window of planes at a time, so that a frame larger
/// than memory is worked through in pieces: the finest level's planes come from a reader (a
/// series' read_slab), each coarser level's are averaged from the finer planes as soon as these
/// are there. The window of level l is planes [begin(l), end(l)); a brick of level l may be
/// extracted while its S planes (clamped to the level) are in it.
class PyramidWindow {
 public:
  /// read(z_begin, z_end, out): the finest level's planes [z_begin, z_end) into out.
  using ReadPlanes = std::function<void(std::size_t z_begin, std::size_t z_end, std::span<float>)>;
  /// `geometry`: format::level_geometry of the frame's dims and `shape`. `detail`: the levels
  /// above the frame's also hold each voxel's detail (brick_detail).
  PyramidWindow(std::vector<format::LevelGeometry> geometry, ReadPlanes read,
                format::BrickShape shape = {}, bool detail = false);
  format::BrickShape shape() const { return shape_; }

  const std::vector<format::LevelGeometry>& geometry() const { return geometry_; }
  std::size_t planes(std::size_t level) const { return geometry_[level].dims[2]; }
  std::size_t begin(std::size_t level) const { return levels_[level].begin; }
  std::size_t end(std::size_t level) const { return levels_[level].end; }
  /// Reads the finest level up to plane finest_end (clamped to the level) and averages every
  /// coarser plane whose finer planes are then all there.
  void advance(std::size_t finest_end);
  /// Lets level l's planes below `begin` go, except those the next coarser level still needs.
  void release(std::size_t level, std::size_t begin);
  /// extract_brick's voxels of brick (x, y, z) of level l from the window (InputError-free:
  /// std::logic_error if a plane it needs is not in the window).
  void extract_brick(std::size_t level, std::uint32_t x, std::uint32_t y, std::uint32_t z,
                     std::span<float> out) const;
  /// The mean over brick (x, y, z)'s own voxels (its interior, inside the level) of their detail
  /// (downsample_planes): the mean squared difference between the frame and what a level above
  /// the frame's draws in its place. 0 on the frame's level and without `detail`. Its planes
  /// must be in the window.
  double brick_detail(std::size_t level, std::uint32_t x, std::uint32_t y, std::uint32_t z) const;
  /// The most bytes of planes the window held at once.
  std::size_t peak_bytes() const { return peak_bytes_; }
  /// Bytes of `planes` planes of every level of `geometry` as a window stores them (with `detail`,
  /// the levels above the frame's hold their detail too): what a window holding that many planes
  /// of each level takes.
  static double planes_bytes(const std::vector<format::LevelGeometry>& geometry, double planes,
                             bool detail);

 private:
  struct Level {
    std::size_t begin = 0, end = 0;
    std::deque<std::vector<float>> planes;  ///< planes[z − begin]
    std::vector<std::vector<float>> spare;  ///< a released plane's storage, reused
  };
  const float* plane(std::size_t level, std::size_t z) const;
  /// The detail plane stored after a level's plane z (null on the frame's level and without
  /// detail).
  const float* detail(std::size_t level, std::size_t z) const;
  /// Floats a plane of `level` holds (plane_values).
  std::size_t stored_values(std::size_t level) const;
  void append_planes(std::size_t level, std::size_t end);

  std::vector<format::LevelGeometry> geometry_;
  format::BrickShape shape_;
  bool detail_ = false;
  ReadPlanes read_;
  std::vector<Level> levels_;
  std::size_t bytes_ = 0, peak_bytes_ = 0;
};

}  // namespace volreel::encoder
