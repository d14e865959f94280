//! The tile renderer where the OS refuses threads: it once started one scoped thread per
//! requested thread with `spawn`, which panics when a thread cannot be started. To make "the OS
//! refuses a thread" repeatable without exhausting the machine's process ids, the test caps the
//! process's address space (`RLIMIT_AS`) for the duration of the call (Linux; alone in its test
//! binary, since the cap holds for the whole process).
#![cfg(target_os = "linux")]
use strahl::composite::{Assignment, render_tiles};

#[repr(C)]
struct Rlimit {
    cur: u64,
    max: u64,
}
unsafe extern "C" {
    fn getrlimit(resource: i32, rlim: *mut Rlimit) -> i32;
    fn setrlimit(resource: i32, rlim: *const Rlimit) -> i32;
}
const RLIMIT_AS: i32 = 9;

fn vm_bytes() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = s.lines().find(|l| l.starts_with("VmSize:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

/// Renders a 64 x 64 image in 1-pixel tiles on 2,000 requested threads while the address space
/// is capped so that only a few hundred thread stacks fit: every tile is still rendered, in both
/// assignments, and the counts add up.
#[test]
fn render_tiles_finishes_where_the_os_refuses_threads() {
    let mut old = Rlimit { cur: 0, max: 0 };
    // SAFETY: plain libc calls on a valid struct.
    assert_eq!(unsafe { getrlimit(RLIMIT_AS, &mut old) }, 0);
    // Room for malloc arenas and a few hundred 2 MiB thread stacks, not 2,000.
    let cap = Rlimit {
        cur: vm_bytes() + (1536 << 20),
        max: old.max,
    };
    // SAFETY: as above; the old limit is restored below, before any assertion can unwind.
    assert_eq!(unsafe { setrlimit(RLIMIT_AS, &cap) }, 0);
    let runs = [Assignment::Dynamic, Assignment::Static].map(|a| {
        std::panic::catch_unwind(|| {
            render_tiles(64, 64, 1, 2000, a, |t, out: &mut [u32]| {
                out[0] = t.y0 * 64 + t.x0;
            })
        })
    });
    // SAFETY: as above.
    assert_eq!(unsafe { setrlimit(RLIMIT_AS, &old) }, 0);
    for r in runs {
        let (img, stats) = r.expect("render_tiles panicked where a thread could not be started");
        assert!(img.iter().enumerate().all(|(i, &p)| p == i as u32));
        assert_eq!(stats.tiles_per_thread.len(), 2000);
        assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), 64 * 64);
    }
}
