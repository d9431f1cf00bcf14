// core/kept_sets.hpp's two sets against a model of what they promise, on
// random sequences of keeps, writes, in-place edits, undos and lends
// (next_written: the memory of the set the next write takes, lent before
// that write while the current set may still be read).
#include <gtest/gtest.h>

#include <optional>
#include <random>

#include "core/kept_sets.hpp"

namespace marbles {
namespace {

constexpr int kTrashed = -1;  // what a lent set holds

TEST(KeptSets, WritesLendsAndUndosAgainstAModel) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 200; ++trial) {
    KeptSets<int> sets;
    sets.current() = 0;
    // The model: what current() reads, what back_to_kept() brings back, and
    // whether the current set is the kept one (no write since the keep or
    // the undo), the one set a lend must never touch.
    int current = 0;
    std::optional<int> kept;
    bool current_is_kept = false;
    int next_value = 1;
    for (int op = 0; op < 60; ++op) {
      switch (rng() % 5) {
        case 0:
          sets.keep();
          kept = current;
          current_is_kept = true;
          break;
        case 1:
          sets.back_to_kept();
          if (kept) current = *kept, current_is_kept = true;
          break;
        case 2: {  // a write: the set the lend named
          int* lent = &sets.next_written();
          int* written = &sets.writable();
          ASSERT_EQ(lent, written) << "trial " << trial << " op " << op;
          *written = current = next_value++;
          current_is_kept = false;
          break;
        }
        case 3:
          sets.edited() = current = next_value++;
          kept.reset();
          current_is_kept = false;
          break;
        case 4: {  // a lend: the set's contents dead until the next write
          const int* before = &sets.current();
          int& lent = sets.next_written();
          ASSERT_EQ(&sets.current(), before) << "a lend moved the current set: trial " << trial << " op " << op;
          if (current_is_kept) ASSERT_NE(&lent, before) << "the kept set lent: trial " << trial << " op " << op;
          else ASSERT_EQ(&lent, before) << "a lend past the set the store writes: trial " << trial << " op " << op;
          lent = kTrashed;
          if (!current_is_kept) current = kTrashed;
          break;
        }
      }
      ASSERT_EQ(sets.current(), current) << "trial " << trial << " op " << op;
    }
    // The kept set survives every write and lend since its keep.
    if (kept) {
      sets.back_to_kept();
      EXPECT_EQ(sets.current(), *kept) << "trial " << trial;
    }
  }
}

}  // namespace
}  // namespace marbles
