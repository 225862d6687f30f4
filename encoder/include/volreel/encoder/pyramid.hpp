// pyramid.hpp: the brick hierarchy of one frame (MTV-Player §3.2): levels averaging 2×2×2 voxels
// (Cesium patent [0031]) from the frame up to one root brick, and the stored voxels of a brick
// (34³ interior with a 1-voxel apron).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "volreel/datasets/volume.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder {

/// The levels of a frame's brick hierarchy as dense volumes: [0] the root level … [L−1] the frame.
struct Pyramid {
  std::vector<format::LevelGeometry> geometry;
  std::vector<std::vector<float>> levels;
};
/// Level l−1 voxel (i,j,k) = mean of level-l voxels (2i+a, 2j+b, 2k+c), a,b,c ∈ {0,1}, indices
/// clamped to the level (edge replication where a size is odd).
Pyramid build_pyramid(const Volume& frame);
/// Stored voxels of brick (x, y, z) of level l into out (36³, x fastest): level voxel
/// (34x − 1 + a, 34y − 1 + b, 34z − 1 + c) for a, b, c in [0, 36), clamped to the level.
void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out);

}  // namespace volreel::encoder
