//! Sort-first dynamic load balancing: image tiles handed out by an atomic counter (a tile queue),
//! against a static split of the tiles into equal contiguous bands, one per thread.
//!
//! With a skewed scene (cost concentrated in a few tiles), the static split leaves threads idle
//! while one finishes its expensive band; the queue keeps every thread busy until the last tile.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use std::vec::Vec;

/// A rectangle of pixels `[x0, x1) x [y0, y1)`.
///
/// ```
/// use strahl::composite::{Tile, tiles};
/// let t = Tile { x0: 8, y0: 0, x1: 10, y1: 3 }; // columns 8 and 9 of rows 0 to 2
/// assert_eq!(tiles(10, 3, 8)[1], t); // the right-edge tile of a 10 x 3 image
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    /// Left column.
    pub x0: u32,
    /// Top row.
    pub y0: u32,
    /// One past the right column.
    pub x1: u32,
    /// One past the bottom row.
    pub y1: u32,
}

impl Tile {
    /// Pixels in the tile.
    ///
    /// ```
    /// use strahl::composite::Tile;
    /// assert_eq!(Tile { x0: 8, y0: 0, x1: 10, y1: 3 }.pixels(), 6);
    /// assert_eq!(Tile { x0: 8, y0: 0, x1: 2, y1: 3 }.pixels(), 0); // reversed: empty
    /// ```
    pub fn pixels(&self) -> usize {
        self.x1.saturating_sub(self.x0) as usize * self.y1.saturating_sub(self.y0) as usize
    }
}

/// The tiles of a `width x height` image, `size x size` (smaller at the right and bottom edges),
/// in scanline order. A zero `size` is treated as 1.
///
/// ```
/// use strahl::composite::tiles;
/// let t = tiles(10, 5, 4); // 3 x 2 tiles, cut short at the right and bottom
/// assert_eq!(t.len(), 6);
/// assert_eq!((t[2].x0, t[2].x1, t[5].y0, t[5].y1), (8, 10, 4, 5));
/// assert_eq!(t.iter().map(|t| t.pixels()).sum::<usize>(), 50); // they cover the image
/// assert_eq!(tiles(3, 2, 0).len(), 6); // size 0 is 1
/// ```
pub fn tiles(width: u32, height: u32, size: u32) -> Vec<Tile> {
    let size = size.max(1);
    let mut v = Vec::new();
    for y0 in (0..height).step_by(size as usize) {
        for x0 in (0..width).step_by(size as usize) {
            v.push(Tile {
                x0,
                y0,
                // NOTE: saturating, so that a tile at the far edge of a `u32::MAX`-wide image
                // does not wrap around.
                x1: x0.saturating_add(size).min(width),
                y1: y0.saturating_add(size).min(height),
            });
        }
    }
    v
}

/// How tiles are given to threads.
///
/// ```
/// use strahl::composite::{Assignment, render_tiles};
/// for a in [Assignment::Static, Assignment::Dynamic] {
///     let (img, stats) = render_tiles(40, 16, 8, 3, a, |_, out: &mut [u8]| out.fill(1));
///     assert!(img.iter().all(|&p| p == 1)); // 10 tiles of 8 x 8, all rendered
///     assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), 10);
/// }
/// let (_, stats) = render_tiles(40, 16, 8, 3, Assignment::Static, |_, out: &mut [u8]| out.fill(1));
/// assert_eq!(stats.tiles_per_thread, [3, 3, 4]); // equal contiguous runs
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Assignment {
    /// Thread `i` of `T` renders the `i`-th of `T` equal contiguous runs of tiles.
    Static,
    /// Threads take the next tile from a shared atomic counter until none is left.
    Dynamic,
}

/// What a tiled render did.
///
/// ```
/// use strahl::composite::{Assignment, render_tiles};
/// let (_, stats) = render_tiles(16, 16, 4, 2, Assignment::Dynamic, |_, out: &mut [f32]| out.fill(0.5));
/// assert_eq!((stats.tiles_per_thread.len(), stats.busy_seconds.len()), (2, 2));
/// assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), 16);
/// assert!(stats.busy_seconds.iter().all(|&b| b <= stats.wall_seconds));
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileStats {
    /// Tiles rendered by each of the `threads` workers. Where the OS refuses to start a thread,
    /// another (the calling thread, at the latest) does that worker's share, counted here under
    /// the refused worker: every tile is rendered.
    pub tiles_per_thread: Vec<usize>,
    /// Busy seconds of each worker.
    pub busy_seconds: Vec<f64>,
    /// Wall seconds of the whole render.
    pub wall_seconds: f64,
}

impl TileStats {
    /// Load imbalance: the busiest thread's time over the mean (1 is perfect).
    ///
    /// ```
    /// use strahl::composite::TileStats;
    /// let s = TileStats { busy_seconds: vec![1.0, 3.0], ..Default::default() };
    /// assert_eq!(s.imbalance(), 1.5); // the busiest thread's 3 s over the mean of 2 s
    /// assert_eq!(TileStats::default().imbalance(), 1.0); // nothing measured
    /// ```
    pub fn imbalance(&self) -> f64 {
        let n = self.busy_seconds.len().max(1) as f64;
        let mean = self.busy_seconds.iter().sum::<f64>() / n;
        let max = self.busy_seconds.iter().cloned().fold(0.0, f64::max);
        if mean > 0.0 { max / mean } else { 1.0 }
    }
}

/// Renders a `width x height` image of `P` with `threads` threads: `shade(tile, out)` fills `out`
/// (the tile's pixels, row by row). Returns the image in scanline order and statistics.
///
/// ```
/// use strahl::composite::{Assignment, render_tiles};
/// let (img, stats) = render_tiles(37, 11, 8, 2, Assignment::Dynamic, |t, out: &mut [u32]| {
///     for (i, p) in out.iter_mut().enumerate() {
///         let (x, y) = (t.x0 + i as u32 % (t.x1 - t.x0), t.y0 + i as u32 / (t.x1 - t.x0));
///         *p = y * 37 + x;
///     }
/// });
/// assert!(img.iter().enumerate().all(|(i, &p)| p == i as u32));
/// assert_eq!(stats.tiles_per_thread.iter().sum::<usize>(), 5 * 2);
/// ```
pub fn render_tiles<P, F>(
    width: u32,
    height: u32,
    tile: u32,
    threads: usize,
    assignment: Assignment,
    shade: F,
) -> (Vec<P>, TileStats)
where
    P: Copy + Default + Send,
    F: Fn(Tile, &mut [P]) + Sync,
{
    // NOTE: `width * height` always fits in a 64-bit `usize`; where it does not (32-bit), the
    // image is empty (and `render_tiles_into` renders nothing into it).
    let n = (width as usize).checked_mul(height as usize).unwrap_or(0);
    let mut img = std::vec![P::default(); n];
    // NOTE: the image has exactly `width * height` pixels: no size error.
    let stats = render_tiles_into(&mut img, width, height, tile, threads, assignment, shade).unwrap_or_default();
    (img, stats)
}

/// The image given to [`render_tiles_into`] does not have `width * height` pixels.
///
/// ```
/// use strahl::composite::{Assignment, ImageSizeError, render_tiles_into};
/// let mut img = vec![0u8; 10];
/// let err = render_tiles_into(&mut img, 4, 3, 2, 1, Assignment::Static, |_, _| {}).unwrap_err();
/// assert_eq!(err, ImageSizeError { expected: 12, got: 10 });
/// assert_eq!(err.to_string(), "image has 10 pixels, expected width * height = 12");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSizeError {
    /// `width * height` (`usize::MAX` where that does not fit in a `usize`).
    pub expected: usize,
    /// The image's length.
    pub got: usize,
}

impl core::fmt::Display for ImageSizeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "image has {} pixels, expected width * height = {}",
            self.got, self.expected
        )
    }
}

impl std::error::Error for ImageSizeError {}

/// [`render_tiles`] into an image the caller keeps (`width * height` pixels in scanline order),
/// so that a renderer drawing frame after frame allocates nothing per frame. Each thread shades
/// a tile into a buffer of its own, then copies it into the image band of `tile` rows that holds
/// it (one lock per band; the threads take tiles in scanline order, so at most a few wait). Every
/// pixel is written.
///
/// ```
/// use strahl::composite::{Assignment, render_tiles_into};
/// let mut img = vec![0u32; 37 * 11];
/// for frame in 1..3 {
///     render_tiles_into(&mut img, 37, 11, 8, 2, Assignment::Dynamic, |t, out: &mut [u32]| {
///         for (i, p) in out.iter_mut().enumerate() {
///             let (x, y) = (t.x0 + i as u32 % (t.x1 - t.x0), t.y0 + i as u32 / (t.x1 - t.x0));
///             *p = frame * (y * 37 + x);
///         }
///     })
///     .unwrap();
///     assert!(img.iter().enumerate().all(|(i, &p)| p == frame * i as u32));
/// }
/// assert!(render_tiles_into(&mut img, 37, 12, 8, 2, Assignment::Dynamic, |_, _| {}).is_err());
/// ```
pub fn render_tiles_into<P, F>(
    img: &mut [P],
    width: u32,
    height: u32,
    tile: u32,
    threads: usize,
    assignment: Assignment,
    shade: F,
) -> Result<TileStats, ImageSizeError>
where
    P: Copy + Default + Send,
    F: Fn(Tile, &mut [P]) + Sync,
{
    // NOTE: `usize::MAX` where `width * height` does not fit (32-bit targets): no image has that
    // many pixels, so it is an error, not a wrapped size.
    let expected = (width as usize).saturating_mul(height as usize);
    if img.len() != expected || expected == usize::MAX {
        return Err(ImageSizeError {
            expected,
            got: img.len(),
        });
    }
    let size = tile.max(1);
    let all = tiles(width, height, size);
    let threads = threads.clamp(1, all.len().max(1));
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    // Bands of `size` rows (the last may be shorter): tile `t` lies in band `t.y0 / size`.
    let band_len = (width as usize).saturating_mul(size.min(height.max(1)) as usize).max(1);
    let bands: Vec<Mutex<&mut [P]>> = img.chunks_mut(band_len).map(Mutex::new).collect();
    // Worker slot `i` renders run `i` of the static assignment, or pulls tiles from `next` in the
    // dynamic one. The slots are claimed from a counter, so where the OS refuses a thread the
    // calling thread (or another worker) takes its slot over: every tile is rendered either way.
    let slots: Vec<Mutex<(usize, f64)>> = (0..threads).map(|_| Mutex::new((0, 0.0))).collect();
    let claimed = AtomicUsize::new(0);
    crate::par::each(0..threads, |_| {
        let mut buf: Vec<P> = Vec::new();
        loop {
            let i = claimed.fetch_add(1, Ordering::Relaxed);
            let Some(slot) = slots.get(i) else { break };
            let (mut done, mut busy) = (0usize, 0.0);
            let mut work = |t: Tile| {
                let t0 = Instant::now();
                buf.clear();
                buf.resize(t.pixels(), P::default());
                shade(t, &mut buf);
                let w = (t.x1 - t.x0) as usize;
                let band_y0 = t.y0 - t.y0 % size;
                if let Some(band) = bands.get((t.y0 / size) as usize) {
                    let mut band = band.lock().unwrap_or_else(|e| e.into_inner());
                    for (row, y) in (t.y0..t.y1).enumerate() {
                        let at = (y - band_y0) as usize * width as usize + t.x0 as usize;
                        band[at..at + w].copy_from_slice(&buf[row * w..(row + 1) * w]);
                    }
                }
                busy += t0.elapsed().as_secs_f64();
                done += 1;
            };
            match assignment {
                Assignment::Static => {
                    let (a, b) = (i * all.len() / threads, (i + 1) * all.len() / threads);
                    all[a..b].iter().for_each(|&t| work(t));
                }
                Assignment::Dynamic => loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    match all.get(k) {
                        Some(&t) => work(t),
                        None => break,
                    }
                },
            }
            *slot.lock().unwrap_or_else(|e| e.into_inner()) = (done, busy);
        }
    });
    let per_thread: Vec<(usize, f64)> = slots
        .into_iter()
        .map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner()))
        .collect();
    Ok(TileStats {
        wall_seconds: start.elapsed().as_secs_f64(),
        tiles_per_thread: per_thread.iter().map(|p| p.0).collect(),
        busy_seconds: per_thread.iter().map(|p| p.1).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by the `composite` fuzz target: `x0 + size` overflowed at the far edge of a
    /// `u32::MAX`-wide image (a panic in debug builds, a tile with `x1 < x0` in release ones).
    #[test]
    fn tiles_at_the_edge_of_u32_do_not_wrap() {
        let t = tiles(u32::MAX, 1, 0x8000_0000);
        assert_eq!(t.len(), 2);
        assert_eq!((t[1].x0, t[1].x1, t[1].y1), (0x8000_0000, u32::MAX, 1));
        assert!(t.iter().all(|t| t.x0 < t.x1 && t.y0 < t.y1));
    }
}
