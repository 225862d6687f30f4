// heap_test.cpp: the fixed-capacity min-max heap against a sorted reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "volreel/datasets/prng.hpp"
#include "volreel/stream/min_max_heap.hpp"

namespace volreel::stream {
namespace {

TEST(StreamHeap, MatchesASortedReferenceUnderRandomOperations) {
  for (std::size_t capacity : {1u, 2u, 3u, 7u, 16u, 100u}) {
    SplitMix64 rng(capacity * 7919 + 1);
    MinMaxHeap<int> heap(capacity);
    std::multiset<int> reference;
    for (int op = 0; op < 20000; ++op) {
      const std::uint64_t what = rng.next() % 10;
      if (what < 6) {
        const int x = static_cast<int>(rng.next() % 1000);
        const bool kept = heap.push(x);
        // Reference: insert, then drop the minimum when over capacity.
        reference.insert(x);
        bool ref_kept = true;
        if (reference.size() > capacity) {
          // Dropping x itself when it is (one of) the smallest.
          if (x <= *reference.begin()) ref_kept = false;
          reference.erase(reference.begin());
        }
        ASSERT_EQ(kept, ref_kept) << "capacity " << capacity << " op " << op;
      } else if (what < 8) {
        if (reference.empty()) continue;
        ASSERT_EQ(heap.pop_min(), *reference.begin());
        reference.erase(reference.begin());
      } else {
        if (reference.empty()) continue;
        ASSERT_EQ(heap.pop_max(), *reference.rbegin());
        reference.erase(std::prev(reference.end()));
      }
      ASSERT_EQ(heap.size(), reference.size());
      if (!reference.empty()) {
        ASSERT_EQ(heap.min(), *reference.begin());
        ASSERT_EQ(heap.max(), *reference.rbegin());
      }
      std::vector<int> items(heap.items().begin(), heap.items().end());
      std::sort(items.begin(), items.end());
      ASSERT_TRUE(std::equal(items.begin(), items.end(), reference.begin(), reference.end()));
    }
  }
}

TEST(StreamHeap, AFullHeapKeepsTheLargestAndDrainsInOrder) {
  MinMaxHeap<double> heap(4);
  for (double x : {5.0, 1.0, 9.0, 3.0, 7.0, 2.0, 8.0}) heap.push(x);
  EXPECT_TRUE(heap.full());
  std::vector<double> drained;
  while (!heap.empty()) drained.push_back(heap.pop_max());
  EXPECT_EQ(drained, (std::vector<double>{9.0, 8.0, 7.0, 5.0}));
}

TEST(StreamHeap, CustomComparisonOrdersByPriority) {
  struct Item {
    double priority;
    int id;
  };
  const auto less = [](const Item& a, const Item& b) { return a.priority < b.priority; };
  MinMaxHeap<Item, decltype(less)> heap(2, less);
  heap.push({0.5, 1});
  heap.push({0.9, 2});
  EXPECT_FALSE(heap.push({0.1, 3}));  // lower than the minimum of a full heap: dropped
  EXPECT_TRUE(heap.push({0.7, 4}));   // drops id 1
  EXPECT_EQ(heap.pop_min().id, 4);
  EXPECT_EQ(heap.pop_max().id, 2);
}

}  // namespace
}  // namespace volreel::stream
