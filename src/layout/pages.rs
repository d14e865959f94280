//! Large tree arrays on transparent huge pages (Linux, feature `hugepages`).
//!
//! Traversal of a tree of a million triangles reads nodes and packs scattered over about 100 MB:
//! on 4 KiB pages many of those reads miss the TLB as well as the cache. Embree allocates its
//! trees with `madvise(MADV_HUGEPAGE)` (we saw 68 MB of `AnonHugePages` in its process on the
//! 1M sphereflake); the wide BVHs get the same: [`advised_with_capacity`] gives an empty vector
//! whose range is advised before it is first touched (the collapse sizes its arrays exactly
//! first, or reuses arrays made so before), so the kernel backs their 2 MiB-aligned
//! parts with huge pages where `/sys/kernel/mm/transparent_hugepage/enabled` is `madvise` or
//! `always`. A hint only: where the kernel says no, or THP is `never`, the memory is an ordinary
//! allocation; results never change. Without the feature, or off Linux, nothing is advised.

use alloc::vec::Vec;

/// Arrays smaller than this stay where they are (no whole huge page fits in them).
pub(crate) const MIN_BYTES: usize = 4 << 20;

/// An empty vector with room for `n` elements, advised for transparent huge pages if that is
/// at least [`MIN_BYTES`] (see the [module docs](self)), to be filled without reallocating.
pub(crate) fn advised_with_capacity<T>(n: usize) -> Vec<T> {
    let mut v = Vec::<T>::with_capacity(n);
    let bytes = n.saturating_mul(core::mem::size_of::<T>());
    if bytes >= MIN_BYTES {
        advise(v.as_mut_ptr().cast(), bytes);
    }
    v
}

/// Advises the whole 4 KiB pages in `ptr .. ptr + bytes` for huge pages; returns whether the
/// kernel accepted.
#[cfg(all(feature = "hugepages", target_os = "linux"))]
fn advise(ptr: *mut u8, bytes: usize) -> bool {
    const PAGE: usize = 4096;
    let start = (ptr as usize).next_multiple_of(PAGE);
    let end = (ptr as usize + bytes) & !(PAGE - 1);
    if end <= start {
        return false;
    }
    // SAFETY: `start .. end` lies inside the live allocation `ptr .. ptr + bytes` (rounded inwards
    // to whole pages), which nothing else references yet. MADV_HUGEPAGE changes no contents and
    // no mapping, only how the kernel backs pages it faults in later; it fails harmlessly
    // (EINVAL) where THP is unavailable.
    unsafe { libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE) == 0 }
}

#[cfg(not(all(feature = "hugepages", target_os = "linux")))]
fn advise(_: *mut u8, _: usize) -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The advised range is accepted on Linux (where THP may still be off: `madvise` then fails
    /// with EINVAL, which the hint tolerates), and the memory stays usable.
    #[test]
    #[cfg(all(feature = "hugepages", target_os = "linux"))]
    fn advise_a_fresh_allocation() {
        let mut v = Vec::<u8>::with_capacity(MIN_BYTES + 12345);
        let thp = std::fs::read_to_string("/sys/kernel/mm/transparent_hugepage/enabled")
            .map(|s| !s.contains("[never]"))
            .unwrap_or(false);
        let ok = advise(v.as_mut_ptr(), v.capacity());
        if thp {
            assert!(ok, "madvise(MADV_HUGEPAGE) refused with THP enabled");
        }
        v.resize(MIN_BYTES + 12345, 7);
        assert!(v.iter().all(|&x| x == 7));
        assert!(!advise(v.as_mut_ptr(), 100), "a range inside one page is not advised");
    }
}
