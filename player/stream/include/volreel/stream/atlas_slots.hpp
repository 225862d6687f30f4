// atlas_slots.hpp: which keyframe node each brick slot of the atlas holds (Cesium patent [0035];
// docs/design.md, "Streaming", step 3). Two index-based doubly linked lists, no allocation per
// operation:
//   occupied        slots holding a keyframe node that is currently selected;
//   over-writeable  slots that may be given to another keyframe node, stalest at the front.
// A slot on the over-writeable list keeps its keyframe node until it is overwritten, so a node that
// comes back before that re-occupies its slot without a new request. Slots never used start on the
// over-writeable list (in slot order), so they are taken before any slot that holds data.
//
// A slot sampled by a GPU frame must not be overwritten before that frame has completed: the
// scheduler marks the slots each frame samples (mark_used) and the renderer reports completed
// frames (retire); acquire() only hands out a slot whose last sampling frame has retired.
#pragma once

#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "volreel/player/atlas_layout.h"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {

class AtlasSlots {
 public:
  enum class State : std::uint8_t { occupied, overwriteable };

  /// capacity: number of brick slots (≥ 1).
  explicit AtlasSlots(std::uint32_t capacity);

  std::uint32_t capacity() const { return static_cast<std::uint32_t>(slots_.size()); }
  std::uint32_t occupied_count() const { return occupied_count_; }

  /// The slot holding key (occupied or still over-writeable), if any.
  std::optional<std::uint32_t> find(const KeyframeKey& key) const;
  /// Whether key is held in an occupied slot.
  bool is_occupied(const KeyframeKey& key) const;
  /// The key a slot holds, if any (over-writeable slots keep theirs until overwritten).
  std::optional<KeyframeKey> key(std::uint32_t slot) const;
  State state(std::uint32_t slot) const { return slots_[slot].state; }

  /// Re-occupation without a new request: if key is still in a slot, that slot moves to the back
  /// of the occupied list (it stays there if already occupied). Returns the slot, or nullopt if
  /// the key is not in the atlas.
  std::optional<std::uint32_t> reoccupy(const KeyframeKey& key);

  /// A slot for key's new data: the stalest slot of the over-writeable list (the first from the
  /// front that no unretired GPU frame samples) moves to the back of the occupied list and forgets
  /// its old key. Returns nullopt if there is none. If key is already in a slot, returns that slot
  /// (re-occupied) instead.
  std::optional<std::uint32_t> acquire(const KeyframeKey& key);

  /// Makes key's slot over-writeable (to the back of the over-writeable list), keeping its data
  /// for a later re-occupation. No effect if key is not occupied.
  void release(const KeyframeKey& key);
  void release_slot(std::uint32_t slot);

  /// Records that GPU frame `frame_number` samples slot.
  void mark_used(std::uint32_t slot, std::uint64_t frame_number);
  /// Every GPU frame ≤ completed_frame_number has finished: their slots may be overwritten.
  void retire(std::uint64_t completed_frame_number);
  /// Whether slot may be overwritten now (no unretired frame samples it).
  bool retired(std::uint32_t slot) const;

  /// Slots in list order, front first (for tests and statistics).
  std::vector<std::uint32_t> occupied_slots() const { return list_slots(occupied_); }
  std::vector<std::uint32_t> overwriteable_slots() const { return list_slots(overwriteable_); }

 private:
  static constexpr std::uint32_t none = VR_ATLAS_NO_SLOT;
  struct List {
    std::uint32_t front = none, back = none;
  };
  struct Slot {
    std::uint32_t prev = none, next = none;
    State state = State::overwriteable;
    bool has_key = false;
    KeyframeKey key;
    std::uint64_t last_used_plus_one = 0;  ///< 0: never sampled
  };
  std::vector<Slot> slots_;
  List occupied_, overwriteable_;
  std::uint32_t occupied_count_ = 0;
  std::uint64_t retired_plus_one_ = 0;  ///< 0: no frame retired yet
  std::unordered_map<KeyframeKey, std::uint32_t, KeyframeKeyHash> where_;

  void unlink(std::uint32_t slot);
  void push_back(List& list, std::uint32_t slot);
  std::vector<std::uint32_t> list_slots(const List& list) const;
};

}  // namespace volreel::stream
