//! A fixed-capacity traversal stack on the call stack that is not zero-initialised.
//!
//! PERF: the wide traversal's stack must hold `MAX_WIDE_DEPTH * 7 + 1` entries (about 4 KB) to be
//! exact for every tree; zeroing that per ray cost 40% of the BVH8 primary-ray throughput on the
//! bunny (10.4 vs 17.8 M rays/s, `cargo bench --bench trace -- bunny/primary/bvh8`). Entries are
//! only read below `len`, where they have been written, so they can stay uninitialised.

use core::mem::MaybeUninit;

/// A stack of `(code, distance)` entries with room for `S`.
pub(crate) struct Stack<const S: usize> {
    codes: [MaybeUninit<u32>; S],
    dists: [MaybeUninit<f32>; S],
    len: usize,
}

impl<const S: usize> Stack<S> {
    /// An empty stack (nothing is written).
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            codes: [const { MaybeUninit::uninit() }; S],
            dists: [const { MaybeUninit::uninit() }; S],
            len: 0,
        }
    }

    /// Entries on the stack.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Pushes an entry keeping the top `len() - base` entries sorted by decreasing distance
    /// (the nearest on top; an equal distance goes below the entries already there). Returns
    /// `false` when full.
    #[inline(always)]
    pub(crate) fn push_sorted(&mut self, base: usize, code: u32, dist: f32) -> bool {
        if self.len >= S {
            return false;
        }
        let mut j = self.len;
        while j > base.min(self.len) && self.dist(j - 1) <= dist {
            self.codes[j] = self.codes[j - 1];
            self.dists[j] = self.dists[j - 1];
            j -= 1;
        }
        self.codes[j] = MaybeUninit::new(code);
        self.dists[j] = MaybeUninit::new(dist);
        self.len += 1;
        true
    }

    /// Pushes an entry on top. Returns `false` when full.
    // NOTE: used by the instance walk (`alloc`) only.
    #[cfg_attr(not(feature = "alloc"), allow(dead_code))]
    #[inline(always)]
    pub(crate) fn push(&mut self, code: u32, dist: f32) -> bool {
        if self.len >= S {
            return false;
        }
        self.codes[self.len] = MaybeUninit::new(code);
        self.dists[self.len] = MaybeUninit::new(dist);
        self.len += 1;
        true
    }

    #[inline(always)]
    fn dist(&self, i: usize) -> f32 {
        debug_assert!(i < self.len);
        // SAFETY: `i < len` (callers index below `len` only), and every slot below `len` was
        // written by `push` or `push_sorted` (which move only initialised slots below `len`).
        unsafe { self.dists[i].assume_init() }
    }

    /// Pops the top entry.
    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<(u32, f32)> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: slot `len` (the old top) is below the old `len`, so it was written (see `dist`).
        Some(unsafe { (self.codes[self.len].assume_init(), self.dists[self.len].assume_init()) })
    }
}

/// A stack of node codes alone (the any-hit walk's: no distances), with room for `S`.
pub(crate) struct CodeStack<const S: usize> {
    codes: [MaybeUninit<u32>; S],
    len: usize,
}

impl<const S: usize> CodeStack<S> {
    /// An empty stack (nothing is written).
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            codes: [const { MaybeUninit::uninit() }; S],
            len: 0,
        }
    }

    /// Room left.
    #[inline(always)]
    pub(crate) fn room(&self) -> usize {
        S - self.len
    }

    /// Pushes a code on top; the caller has checked [`room`](Self::room) (a full stack drops it,
    /// never writes out of bounds).
    #[inline(always)]
    pub(crate) fn push(&mut self, code: u32) {
        if let Some(slot) = self.codes.get_mut(self.len) {
            *slot = MaybeUninit::new(code);
            self.len += 1;
        }
    }

    /// Pops the top code.
    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<u32> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: `len < S` here (`push` only grows it up to `S`, and it was just decremented),
        // and slot `len` (the old top) lies below the old `len`, so `push` wrote it.
        Some(unsafe { self.codes.get_unchecked(self.len).assume_init() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_pop_and_sorted_pushes() {
        let mut s = Stack::<8>::new();
        assert!(s.pop().is_none());
        assert!(s.push_sorted(0, 1, 5.0));
        // A node's children: pushed sorted above `base`.
        let base = s.len();
        for (c, d) in [(10, 3.0), (11, 1.0), (12, 2.0), (13, 1.0)] {
            assert!(s.push_sorted(base, c, d));
        }
        // Nearest first; the tie at 1.0 keeps the earlier child (11) on top.
        assert_eq!(s.pop(), Some((11, 1.0)));
        assert_eq!(s.pop(), Some((13, 1.0)));
        assert_eq!(s.pop(), Some((12, 2.0)));
        assert_eq!(s.pop(), Some((10, 3.0)));
        assert_eq!(s.pop(), Some((1, 5.0)));
        assert_eq!(s.pop(), None);
        for i in 0..8 {
            assert!(s.push_sorted(0, i, i as f32));
        }
        assert!(!s.push_sorted(0, 99, 0.0)); // full
        assert!(!s.push(99, 0.0)); // full
        assert_eq!(s.pop(), Some((0, 0.0)));
        assert!(s.push(42, -1.0)); // on top, whatever its distance
        assert_eq!(s.pop(), Some((42, -1.0)));
        assert_eq!(s.pop(), Some((1, 1.0)));
    }

    #[test]
    fn code_stack_push_pop_and_room() {
        let mut s = CodeStack::<4>::new();
        assert_eq!((s.room(), s.pop()), (4, None));
        for c in [7, 8, 9] {
            s.push(c);
        }
        assert_eq!((s.room(), s.pop()), (1, Some(9)));
        s.push(10);
        s.push(11);
        assert_eq!(s.room(), 0);
        s.push(12); // full: dropped, nothing written past the end
        assert_eq!(s.room(), 0);
        for c in [11, 10, 8, 7] {
            assert_eq!(s.pop(), Some(c));
        }
        assert_eq!((s.room(), s.pop()), (4, None));
    }
}
