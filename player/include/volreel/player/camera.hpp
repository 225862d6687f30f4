// camera.hpp: the orbit camera shared by the stream scheduler (screen-space error), the CPU
// reference renderer and the Vulkan renderer. World space is the volume's finest-level voxel
// space: the volume occupies [0, dims) on each axis, voxel i's centre at i + 0.5.
#pragma once

#include <algorithm>
#include <cmath>

#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>

namespace volreel::player {

struct OrbitCamera {
  glm::dvec3 target{0.0};             ///< the point orbited (usually the volume's centre)
  double distance = 1.0;              ///< from target to eye, voxels
  double azimuth = 0.6;               ///< radians, around +z
  double elevation = 0.45;            ///< radians above the xy plane
  double fov_y = glm::radians(45.0);  ///< vertical field of view, radians
  int width = 512, height = 512;      ///< viewport, pixels

  /// A camera that frames a volume of `dims` voxels from the default direction.
  static OrbitCamera framing(glm::dvec3 dims, int width, int height) {
    OrbitCamera c;
    c.target = dims * 0.5;
    c.width = width;
    c.height = height;
    c.distance = 0.5 * glm::length(dims) / std::sin(0.5 * c.fov_y) * 1.05;
    return c;
  }

  glm::dvec3 eye() const {
    const glm::dvec3 dir{std::cos(elevation) * std::cos(azimuth),
                         std::cos(elevation) * std::sin(azimuth), std::sin(elevation)};
    return target + distance * dir;
  }
  glm::dmat4 view() const { return glm::lookAt(eye(), target, glm::dvec3(0, 0, 1)); }
  glm::dmat4 projection(double near_plane = 0.1, double far_plane = 1e7) const {
    return glm::perspective(fov_y, double(width) / double(height), near_plane, far_plane);
  }
  /// Pixels covered by a length of `size` voxels at distance `depth` from the eye (perspective
  /// projection; the screen-space error of a node of voxel size `size` seen at that depth).
  double projected_pixels(double size, double depth) const {
    return size * 0.5 * double(height) / (std::max(depth, 1e-9) * std::tan(0.5 * fov_y));
  }
  /// The view's orthonormal basis: forward (eye to target), right (forward × +z) and up
  /// (right × forward), the axes every renderer and the pan gesture use.
  struct Basis {
    glm::dvec3 forward, right, up;
  };
  Basis basis() const {
    Basis b;
    b.forward = glm::normalize(target - eye());
    b.right = glm::normalize(glm::cross(b.forward, glm::dvec3(0, 0, 1)));
    b.up = glm::cross(b.right, b.forward);
    return b;
  }
  /// World-space direction of the ray through pixel (px, py) (pixel centres at +0.5, y down).
  glm::dvec3 ray_direction(double px, double py) const {
    const double t = std::tan(0.5 * fov_y);
    const double ndc_x = (2.0 * px / width - 1.0) * t * double(width) / double(height);
    const double ndc_y = (1.0 - 2.0 * py / height) * t;
    const Basis b = basis();
    return glm::normalize(b.forward + ndc_x * b.right + ndc_y * b.up);
  }
};

}  // namespace volreel::player
