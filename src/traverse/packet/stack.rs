//! A fixed-capacity stack of `(code, distance, lane mask)` entries for the masked packet walks,
//! on the call stack and not zero-initialised (see `traverse::stack` for why: zeroing a stack of
//! this size costs more than a coherent packet's whole walk).

use core::mem::MaybeUninit;

/// A node still to visit: its code, the nearest entry distance of the lanes that hit its box, and
/// the mask of those lanes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Entry {
    pub(crate) code: u32,
    pub(crate) dist: f32,
    pub(crate) mask: u32,
}

/// A stack of [`Entry`] with room for `S`.
pub(crate) struct MaskStack<const S: usize> {
    entries: [MaybeUninit<Entry>; S],
    len: usize,
}

impl<const S: usize> MaskStack<S> {
    /// An empty stack (nothing is written).
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            entries: [const { MaybeUninit::uninit() }; S],
            len: 0,
        }
    }

    /// Entries on the stack.
    #[inline(always)]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Pushes `e` keeping the entries above `base` sorted by decreasing distance (the nearest on
    /// top; an equal distance goes below those already there). Returns `false` when full.
    #[inline(always)]
    pub(crate) fn push_sorted(&mut self, base: usize, e: Entry) -> bool {
        if self.len >= S {
            return false;
        }
        let mut j = self.len;
        while j > base.min(self.len) && self.get(j - 1).dist <= e.dist {
            self.entries[j] = self.entries[j - 1];
            j -= 1;
        }
        self.entries[j] = MaybeUninit::new(e);
        self.len += 1;
        true
    }

    #[inline(always)]
    fn get(&self, i: usize) -> Entry {
        debug_assert!(i < self.len);
        // SAFETY: `i < len` (callers index below `len` only), and every slot below `len` was
        // written by `push_sorted` (which moves only initialised slots below `len`).
        unsafe { self.entries[i].assume_init() }
    }

    /// Pops the top entry.
    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<Entry> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        Some(self.get_top())
    }

    #[inline(always)]
    fn get_top(&self) -> Entry {
        // SAFETY: slot `len` (the old top) is below the old `len`, so it was written.
        unsafe { self.entries[self.len].assume_init() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorted_pushes_and_overflow() {
        let e = |code, dist| Entry { code, dist, mask: code };
        let mut s = MaskStack::<4>::new();
        assert!(s.pop().is_none());
        assert!(s.push_sorted(0, e(1, 5.0)));
        let base = s.len();
        for (c, d) in [(10, 3.0), (11, 1.0), (12, 1.0)] {
            assert!(s.push_sorted(base, e(c, d)));
        }
        assert!(!s.push_sorted(base, e(99, 0.0))); // full
        for want in [11, 12, 10, 1] {
            let x = s.pop().unwrap();
            assert_eq!((x.code, x.mask), (want, want));
        }
        assert!(s.pop().is_none());
    }
}
