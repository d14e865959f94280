//! Running work on scoped threads without a panic where a thread cannot be started (`std`).

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

#[cfg(test)]
mod tests {
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
        super::each(core::iter::empty::<u8>(), |_| unreachable!());
    }
}
