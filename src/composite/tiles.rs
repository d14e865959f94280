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
    pub fn pixels(&self) -> usize {
        (self.x1 - self.x0) as usize * (self.y1 - self.y0) as usize
    }
}

/// The tiles of a `width x height` image, `size x size` (smaller at the right and bottom edges),
/// in scanline order. A zero `size` is treated as 1.
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
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Assignment {
    /// Thread `i` of `T` renders the `i`-th of `T` equal contiguous runs of tiles.
    Static,
    /// Threads take the next tile from a shared atomic counter until none is left.
    Dynamic,
}

/// What a tiled render did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileStats {
    /// Tiles rendered by each thread.
    pub tiles_per_thread: Vec<usize>,
    /// Busy seconds of each thread.
    pub busy_seconds: Vec<f64>,
    /// Wall seconds of the whole render.
    pub wall_seconds: f64,
}

impl TileStats {
    /// Load imbalance: the busiest thread's time over the mean (1 is perfect).
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
    let per_thread: Vec<(usize, f64)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|i| {
                let (all, next, shade, bands) = (&all, &next, &shade, &bands);
                s.spawn(move || {
                    let (mut done, mut busy) = (0usize, 0.0);
                    let mut buf: Vec<P> = Vec::new();
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
                    (done, busy)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
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
