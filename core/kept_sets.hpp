// core/kept_sets.hpp — two sets of one state, so that a step's start can be
// kept without a copy (the watchdog's undo): keep() marks the current set,
// the next write (writable) moves to the other one and leaves the kept set
// as it was, and back_to_kept() makes the kept set current again. Both
// contact caches hold their entries so (narrowphase/contact_cache.hpp, and
// the CUDA twin's device arrays).
#pragma once

namespace marbles {

template <class Set>
class KeptSets {
 public:
  const Set& current() const { return m_set[m_current]; }
  Set& current() { return m_set[m_current]; }
  // The set that is not current: the kept one after a write since keep(),
  // or one a keep once made and that writes take in turn.
  const Set& other() const { return m_set[1 - m_current]; }
  Set& other() { return m_set[1 - m_current]; }
  void keep() { m_kept = m_current; }
  // The kept set current again (it stays kept); none kept: nothing changes.
  void back_to_kept() {
    if (m_kept < 2) m_current = m_kept;
  }
  // The set a write changes: the current one, unless it is kept (then the
  // other, from here on the current one).
  Set& writable() {
    if (m_current == m_kept) m_current = 1 - m_current;
    return m_set[m_current];
  }
  // The set the next writable() returns, without moving to it: current()
  // stays what it was (for memory of that set lent or trimmed before the
  // write, while the current set may still be read).
  Set& next_written() { return m_set[m_current == m_kept ? 1 - m_current : m_current]; }
  // The current set, edited in place: nothing is kept from here on.
  Set& edited() {
    m_kept = 2;
    return m_set[m_current];
  }

 private:
  Set m_set[2];
  unsigned m_current = 0, m_kept = 2;  // m_kept 2: none kept
};

}  // namespace marbles
