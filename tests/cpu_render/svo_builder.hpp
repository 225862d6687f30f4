// svo_builder.hpp: array-encoded SVOs built by hand for the renderer tests (svo_layout.h) —
// "every node of level l drawn", each with a leaf record chosen by the test (keyframes A and B,
// their LOD differences and the factor). The stream scheduler builds the real ones.
#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <functional>
#include <vector>

#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/player/atlas_layout.h"
#include "volreel/player/svo_layout.h"

namespace volreel::test {

/// The leaf record of a spatial node: keyframes A and B; with `corners` other than all 255, the
/// coarse pair C and D blended in by the corner weights (svo_layout.h words 4–8).
struct LeafSpec {
  vr_uint slot_a = 0, slot_b = 0;
  vr_uint d_a = 0, d_b = 0;
  float factor = 0;
  vr_uint slot_c = VR_ATLAS_NO_SLOT, slot_d = VR_ATLAS_NO_SLOT;
  vr_uint d_c = 0, d_d = 0;
  float coarse_factor = 0;
  std::array<std::uint8_t, 8> corners{255, 255, 255, 255, 255, 255, 255, 255};
};
using LeafFor = std::function<LeafSpec(std::uint32_t level, std::array<std::uint32_t, 3> c)>;

struct BuiltSvo {
  std::vector<vr_uint> nodes, leaves, histograms;
  std::array<float, 2> histogram_range{0, 1};
  cpu_render::SvoView view() const { return {nodes, leaves, histograms, histogram_range}; }
};

/// Fills svo.histograms: per leaf, the OR of the 64-bin histograms over [lo, hi] of every stored
/// value (apron included, as the encoder's node histograms) of its slots A and B.
inline void add_leaf_histograms(BuiltSvo& svo, const cpu_render::CpuAtlas& atlas, float lo,
                                float hi) {
  svo.histogram_range = {lo, hi};
  svo.histograms.clear();
  for (std::size_t i = 0; i < svo.leaves.size(); i += VR_SVO_LEAF_WORDS) {
    std::uint64_t h = 0;
    for (std::size_t k = 0; k < 2; ++k)
      for (float v : atlas.slot(svo.leaves[i + k]))
        h |= std::uint64_t{1} << format::histogram_bin(v, lo, hi);
    svo.histograms.push_back(static_cast<vr_uint>(h));
    svo.histograms.push_back(static_cast<vr_uint>(h >> 32));
  }
}

/// Every node of level `draw_level` that exists (inside its level's grid) is drawn from the leaf
/// record `leaf_for(level, c)` gives; children outside the grid are empty. With `through_up`, a
/// drawn node is a node record whose eight children are VR_SVO_CHILD_UP and whose word 9 is its
/// leaf (the same picture, reached the other way); the root (draw_level 0) is always drawn so.
inline BuiltSvo build_uniform_svo(const std::vector<format::LevelGeometry>& geometry,
                                  std::uint32_t draw_level, const LeafFor& leaf_for,
                                  bool through_up = false) {
  BuiltSvo svo;
  const auto add_leaf = [&](std::uint32_t level, std::array<std::uint32_t, 3> c) {
    const LeafSpec s = leaf_for(level, c);
    const auto index = static_cast<vr_uint>(svo.leaves.size() / VR_SVO_LEAF_WORDS);
    vr_uint corners[2] = {0, 0};
    for (vr_uint i = 0; i < 8; ++i) corners[i / 4] |= vr_uint{s.corners[i]} << (8 * (i % 4));
    svo.leaves.insert(
        svo.leaves.end(),
        {s.slot_a, s.slot_b, vr_svo_lod_pack(s.d_a, s.d_b) | (vr_svo_lod_pack(s.d_c, s.d_d) << 16),
         std::bit_cast<vr_uint>(s.factor), s.slot_c, s.slot_d,
         std::bit_cast<vr_uint>(s.coarse_factor), corners[0], corners[1]});
    return index;
  };
  std::function<vr_uint(std::uint32_t, std::array<std::uint32_t, 3>, vr_uint)> add_node =
      [&](std::uint32_t level, std::array<std::uint32_t, 3> c, vr_uint parent) {
        const auto index = static_cast<vr_uint>(svo.nodes.size() / VR_SVO_NODE_WORDS);
        svo.nodes.resize(svo.nodes.size() + VR_SVO_NODE_WORDS, 0);
        svo.nodes[index * VR_SVO_NODE_WORDS] = parent;
        svo.nodes[index * VR_SVO_NODE_WORDS + 9] = VR_SVO_NO_LEAF;
        if (level == draw_level) {
          const vr_uint leaf = add_leaf(level, c);
          svo.nodes[index * VR_SVO_NODE_WORDS + 9] = leaf;
          for (vr_uint o = 0; o < 8; ++o)
            svo.nodes[index * VR_SVO_NODE_WORDS + 1 + o] = vr_svo_child_word(VR_SVO_CHILD_UP, 0);
          return index;
        }
        for (vr_uint o = 0; o < 8; ++o) {
          const std::array<std::uint32_t, 3> cc = {2 * c[0] + (o & 1), 2 * c[1] + ((o >> 1) & 1),
                                                   2 * c[2] + (o >> 2)};
          const auto& grid = geometry[level + 1].grid;
          vr_uint word;
          if (cc[0] >= grid[0] || cc[1] >= grid[1] || cc[2] >= grid[2])
            word = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
          else if (level + 1 == draw_level && !through_up)
            word = vr_svo_child_word(VR_SVO_CHILD_LEAF, add_leaf(level + 1, cc));
          else
            word = vr_svo_child_word(VR_SVO_CHILD_NODE, add_node(level + 1, cc, index));
          svo.nodes[index * VR_SVO_NODE_WORDS + 1 + o] = word;
        }
        return index;
      };
  add_node(0, {0, 0, 0}, VR_SVO_NO_PARENT);
  return svo;
}

}  // namespace volreel::test
