//! Running work on scoped threads without a panic where a thread cannot be started (`std`).

use alloc::vec::Vec;

/// Runs `f(item)` for every item: the first on the calling thread, the others on scoped threads
/// (joined before this returns). An item whose thread cannot be started (an OS limit on threads,
/// say) is dropped unrun: callers pull their work from a shared counter, so the calling thread's
/// `f` takes over what that thread would have done. A panic in any `f` is passed on.
pub(crate) fn each<T: Send>(items: impl IntoIterator<Item = T>, f: impl Fn(T) + Sync) {
    let mut items = items.into_iter();
    let Some(first) = items.next() else { return };
    let f = &f;
    std::thread::scope(|s| {
        for item in items {
            let _ = std::thread::Builder::new().spawn_scoped(s, move || f(item));
        }
        f(first);
    });
}

/// Runs `f(job)` for every job on up to `threads` threads, each thread taking the next job in
/// order from a shared counter (put the largest first for balance).
pub(crate) fn each_job<J: Send>(jobs: Vec<J>, threads: usize, f: impl Fn(J) + Sync) {
    use core::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let workers = threads.clamp(1, jobs.len().max(1));
    let jobs: Vec<Mutex<Option<J>>> = jobs.into_iter().map(|j| Mutex::new(Some(j))).collect();
    let next = AtomicUsize::new(0);
    each(0..workers, |_| {
        while let Some(slot) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
            if let Some(job) = slot.lock().ok().and_then(|mut g| g.take()) {
                f(job);
            }
        }
    });
}

/// The parts `lo..hi` of `s` for `ranges` (disjoint, sorted by start, within `s`: callers
/// check), as separate mutable slices.
pub(crate) fn split_ranges<T>(s: &mut [T], ranges: impl IntoIterator<Item = (usize, usize)>) -> Vec<&mut [T]> {
    let (mut rest, mut at) = (s, 0usize);
    let mut parts = Vec::new();
    for (lo, hi) in ranges {
        let (_, tail) = core::mem::take(&mut rest).split_at_mut(lo - at);
        let (mine, tail) = tail.split_at_mut(hi - lo);
        rest = tail;
        at = hi;
        parts.push(mine);
    }
    parts
}

#[cfg(test)]
mod tests {
    use alloc::vec::Vec;
    use core::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn every_item_runs_once_and_work_is_shared() {
        let hits: [AtomicUsize; 5] = Default::default();
        super::each(0..5, |i| {
            hits[i].fetch_add(1, Ordering::Relaxed);
        });
        assert!(hits.iter().all(|h| h.load(Ordering::Relaxed) == 1));
        // Work from a shared counter: all 1000 units done, whoever does them.
        let (next, done) = (AtomicUsize::new(0), AtomicUsize::new(0));
        super::each(0..3, |_| {
            while next.fetch_add(1, Ordering::Relaxed) < 1000 {
                done.fetch_add(1, Ordering::Relaxed);
            }
        });
        assert_eq!(done.load(Ordering::Relaxed), 1000);
        // Jobs: each run once, on any number of threads.
        for threads in [1, 2, 7] {
            let ran: [AtomicUsize; 9] = Default::default();
            super::each_job((0..9).collect(), threads, |j: usize| {
                ran[j].fetch_add(1, Ordering::Relaxed);
            });
            assert!(ran.iter().all(|h| h.load(Ordering::Relaxed) == 1));
        }
        let mut v: Vec<u32> = (0..10).collect();
        let parts = super::split_ranges(&mut v, [(1, 3), (3, 4), (7, 10)]);
        let got: Vec<&[u32]> = parts.iter().map(|p| &p[..]).collect();
        assert_eq!(got, [&[1, 2][..], &[3], &[7, 8, 9]]);
        super::each(core::iter::empty::<u8>(), |_| unreachable!());
    }
}
