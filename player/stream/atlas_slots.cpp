// atlas_slots.cpp: occupied and over-writeable slot lists (Cesium patent [0035]).
#include "volreel/stream/atlas_slots.hpp"

#include <cassert>

namespace volreel::stream {

AtlasSlots::AtlasSlots(std::uint32_t capacity) : slots_(capacity) {
  assert(capacity >= 1);
  for (std::uint32_t s = 0; s < capacity; ++s) push_back(overwriteable_, s);
}

std::optional<std::uint32_t> AtlasSlots::find(const KeyframeKey& key) const {
  const auto it = where_.find(key);
  if (it == where_.end()) return std::nullopt;
  return it->second;
}

bool AtlasSlots::is_occupied(const KeyframeKey& key) const {
  const auto s = find(key);
  return s && slots_[*s].state == State::occupied;
}

std::optional<KeyframeKey> AtlasSlots::key(std::uint32_t slot) const {
  if (!slots_[slot].has_key) return std::nullopt;
  return slots_[slot].key;
}

std::optional<std::uint32_t> AtlasSlots::reoccupy(const KeyframeKey& key) {
  const auto s = find(key);
  if (!s) return std::nullopt;
  Slot& slot = slots_[*s];
  if (slot.state == State::overwriteable) {
    unlink(*s);
    slot.state = State::occupied;
    push_back(occupied_, *s);
    ++occupied_count_;
  }
  return s;
}

std::optional<std::uint32_t> AtlasSlots::acquire(const KeyframeKey& key) {
  if (const auto s = reoccupy(key)) return s;
  // The stalest over-writeable slot that no unretired GPU frame samples. Only slots released in
  // the last few frames (those still in flight) are skipped, so the walk is short.
  std::uint32_t s = overwriteable_.front;
  while (s != none && !retired(s)) s = slots_[s].next;
  if (s == none) return std::nullopt;
  Slot& slot = slots_[s];
  if (slot.has_key) where_.erase(slot.key);
  unlink(s);
  slot.state = State::occupied;
  slot.has_key = true;
  slot.key = key;
  where_[key] = s;
  push_back(occupied_, s);
  ++occupied_count_;
  return s;
}

void AtlasSlots::release(const KeyframeKey& key) {
  if (const auto s = find(key)) release_slot(*s);
}

void AtlasSlots::release_slot(std::uint32_t s) {
  Slot& slot = slots_[s];
  if (slot.state != State::occupied) return;
  unlink(s);
  slot.state = State::overwriteable;
  push_back(overwriteable_, s);
  --occupied_count_;
}

void AtlasSlots::mark_used(std::uint32_t slot, std::uint64_t frame_number) {
  Slot& s = slots_[slot];
  if (frame_number + 1 > s.last_used_plus_one) s.last_used_plus_one = frame_number + 1;
}

void AtlasSlots::retire(std::uint64_t completed_frame_number) {
  if (completed_frame_number + 1 > retired_plus_one_)
    retired_plus_one_ = completed_frame_number + 1;
}

bool AtlasSlots::retired(std::uint32_t slot) const {
  return slots_[slot].last_used_plus_one <= retired_plus_one_;
}

void AtlasSlots::unlink(std::uint32_t s) {
  Slot& slot = slots_[s];
  List& list = slot.state == State::occupied ? occupied_ : overwriteable_;
  if (slot.prev != none)
    slots_[slot.prev].next = slot.next;
  else
    list.front = slot.next;
  if (slot.next != none)
    slots_[slot.next].prev = slot.prev;
  else
    list.back = slot.prev;
  slot.prev = slot.next = none;
}

void AtlasSlots::push_back(List& list, std::uint32_t s) {
  Slot& slot = slots_[s];
  slot.prev = list.back;
  slot.next = none;
  if (list.back != none)
    slots_[list.back].next = s;
  else
    list.front = s;
  list.back = s;
}

std::vector<std::uint32_t> AtlasSlots::list_slots(const List& list) const {
  std::vector<std::uint32_t> out;
  for (std::uint32_t s = list.front; s != none; s = slots_[s].next) out.push_back(s);
  return out;
}

}  // namespace volreel::stream
