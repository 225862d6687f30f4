// min_max_heap.hpp: a fixed-capacity min-max heap (Atkinson, Sack, Santoro, Strothotte, "Min-max
// heaps and generalized priority queues", CACM 1986), the structure the Cesium patent uses to keep
// the keyframe nodes with the highest priorities ([0036], [0061]): capacity = atlas slots,
// refilled every frame; inserting into a full heap drops its minimum (or the new element if that
// is lower still). Insert, pop_min and pop_max are O(log N); min and max are O(1).
//
// Layout: a binary heap in an array whose even depths (the root's among them) are min levels and
// odd depths max levels: an element on a min level is ≤ every element of its subtree, one on a max
// level ≥ every element of its subtree.
#pragma once

#include <bit>
#include <cassert>
#include <cstddef>
#include <functional>
#include <span>
#include <utility>
#include <vector>

namespace volreel::stream {

template <class T, class Compare = std::less<T>>
class MinMaxHeap {
 public:
  /// capacity ≥ 1: the most elements the heap keeps.
  explicit MinMaxHeap(std::size_t capacity, Compare less = Compare())
      : capacity_(capacity), less_(std::move(less)) {
    assert(capacity >= 1);
    items_.reserve(capacity);
  }

  std::size_t size() const { return items_.size(); }
  std::size_t capacity() const { return capacity_; }
  bool empty() const { return items_.empty(); }
  bool full() const { return items_.size() == capacity_; }
  void clear() { items_.clear(); }
  /// The elements in heap order (not sorted).
  std::span<const T> items() const { return items_; }

  /// Inserts x. When full, the minimum is dropped to make room if x is greater than it; otherwise
  /// x is dropped. Returns whether x was kept.
  bool push(T x) {
    if (full()) {
      if (!less_(items_[0], x)) return false;
      // Replace the minimum by x and restore the order below the root.
      items_[0] = std::move(x);
      trickle_down(0);
      return true;
    }
    items_.push_back(std::move(x));
    bubble_up(items_.size() - 1);
    return true;
  }

  /// Precondition: !empty().
  const T& min() const { return items_[0]; }
  const T& max() const { return items_[max_index()]; }

  /// Removes and returns the minimum. Precondition: !empty().
  T pop_min() { return remove(0); }
  /// Removes and returns the maximum. Precondition: !empty().
  T pop_max() { return remove(max_index()); }

 private:
  std::size_t capacity_;
  Compare less_;
  std::vector<T> items_;

  static bool on_min_level(std::size_t i) { return (std::bit_width(i + 1) - 1) % 2 == 0; }
  static std::size_t parent(std::size_t i) { return (i - 1) / 2; }

  std::size_t max_index() const {
    assert(!items_.empty());
    if (items_.size() == 1) return 0;
    if (items_.size() == 2) return 1;
    return less_(items_[1], items_[2]) ? 2 : 1;
  }

  T remove(std::size_t i) {
    assert(i < items_.size());
    T out = std::move(items_[i]);
    const std::size_t last = items_.size() - 1;
    if (i != last) {
      items_[i] = std::move(items_[last]);
      items_.pop_back();
      trickle_down(i);
      // A moved-in element can also be out of order with the ancestors of i (not for i = 0 or the
      // max position, where it is bounded by the root; kept general for safety).
      bubble_up(i);
    } else {
      items_.pop_back();
    }
    return out;
  }

  // `before(a, b)`: a belongs above b on a min level (Min) or on a max level (!Min).
  template <bool Min>
  bool before(const T& a, const T& b) const {
    return Min ? less_(a, b) : less_(b, a);
  }

  void bubble_up(std::size_t i) {
    if (i == 0) return;
    const std::size_t p = parent(i);
    if (on_min_level(i)) {
      if (less_(items_[p], items_[i])) {
        std::swap(items_[i], items_[p]);
        bubble_up_along<false>(p);
      } else {
        bubble_up_along<true>(i);
      }
    } else {
      if (less_(items_[i], items_[p])) {
        std::swap(items_[i], items_[p]);
        bubble_up_along<true>(p);
      } else {
        bubble_up_along<false>(i);
      }
    }
  }

  // Moves i up through its grandparents (levels of the same kind).
  template <bool Min>
  void bubble_up_along(std::size_t i) {
    while (i > 2) {
      const std::size_t g = parent(parent(i));
      if (!before<Min>(items_[i], items_[g])) break;
      std::swap(items_[i], items_[g]);
      i = g;
    }
  }

  void trickle_down(std::size_t i) {
    if (on_min_level(i))
      trickle_down_along<true>(i);
    else
      trickle_down_along<false>(i);
  }

  template <bool Min>
  void trickle_down_along(std::size_t i) {
    const std::size_t n = items_.size();
    for (;;) {
      const std::size_t first_child = 2 * i + 1;
      if (first_child >= n) return;
      // The first among the children and grandchildren (smallest on a min level).
      std::size_t m = first_child;
      for (std::size_t c = first_child; c < first_child + 2 && c < n; ++c) {
        if (before<Min>(items_[c], items_[m])) m = c;
        for (std::size_t g = 2 * c + 1; g < 2 * c + 3 && g < n; ++g)
          if (before<Min>(items_[g], items_[m])) m = g;
      }
      if (!before<Min>(items_[m], items_[i])) return;
      std::swap(items_[m], items_[i]);
      if (m <= first_child + 1) return;  // a child: its subtree is in order
      // A grandchild: the element moved down may belong above m's parent (a level of the other
      // kind).
      const std::size_t p = parent(m);
      if (before<Min>(items_[p], items_[m])) std::swap(items_[p], items_[m]);
      i = m;
    }
  }
};

}  // namespace volreel::stream
