//! Camera tiles as packets: which pixel each lane of a packet holds, so that the `K` rays of a
//! packet are a compact `w x h` block (coherent: one direction-sign octant, interval-culled).

use crate::geometry::Ray;
use glam::Vec3;

/// A ray that no kernel accepts (the empty interval): the lane of a pixel outside the image.
const INACTIVE: Ray = Ray::with_range(Vec3::ZERO, Vec3::Z, f32::INFINITY, f32::NEG_INFINITY);

/// A block of `w x h` pixels whose rays fill one packet, row by row: lane `i` holds pixel
/// `(x0 + i % w, y0 + i / w)` of the tile at `(x0, y0)`.
///
/// Presets for every packet size: 4 rays [`X4_1`](Self::X4_1), [`X2_2`](Self::X2_2); 8 rays
/// [`X4_2`](Self::X4_2); 16 rays [`X4_4`](Self::X4_4), [`X8_2`](Self::X8_2).
///
/// ```
/// use strahl::traverse::packet::TileShape;
/// let t = TileShape::X4_2;
/// assert_eq!(t.rays(), 8);
/// // An 8-pixel-wide image, tile by tile: rays 0..8 are the first 4 x 2 block, 8..16 the next.
/// assert_eq!(t.pixel(5, 8), (1, 1));
/// assert_eq!(t.pixel(8, 8), (4, 0));
/// assert_eq!(t.pixel(16, 8), (0, 2));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileShape {
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
}

impl TileShape {
    /// 4 x 1 pixels (4 rays).
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X4_1;
    /// assert_eq!(t.rays(), 4);
    /// assert_eq!((t.pixel(3, 8), t.pixel(4, 8), t.pixel(8, 8)), ((3, 0), (4, 0), (0, 1))); // one row per tile
    /// ```
    pub const X4_1: Self = Self { w: 4, h: 1 };
    /// 2 x 2 pixels (4 rays).
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X2_2;
    /// assert_eq!(t, TileShape::for_rays(4));
    /// assert_eq!((t.pixel(1, 8), t.pixel(2, 8), t.pixel(4, 8)), ((1, 0), (0, 1), (2, 0)));
    /// ```
    pub const X2_2: Self = Self { w: 2, h: 2 };
    /// 4 x 2 pixels (8 rays).
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X4_2;
    /// assert_eq!((t, t.rays()), (TileShape::for_rays(8), 8));
    /// assert_eq!((t.pixel(4, 8), t.pixel(7, 8)), ((0, 1), (3, 1)));
    /// ```
    pub const X4_2: Self = Self { w: 4, h: 2 };
    /// 4 x 4 pixels (16 rays).
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X4_4;
    /// assert_eq!((t, t.rays()), (TileShape::for_rays(16), 16));
    /// assert_eq!((t.pixel(15, 8), t.pixel(16, 8)), ((3, 3), (4, 0)));
    /// ```
    pub const X4_4: Self = Self { w: 4, h: 4 };
    /// 8 x 2 pixels (16 rays).
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X8_2;
    /// assert_eq!(t.rays(), TileShape::X4_4.rays()); // 16 rays, wider and flatter
    /// assert_eq!((t.pixel(7, 16), t.pixel(8, 16), t.pixel(16, 16)), ((7, 0), (0, 1), (8, 0)));
    /// ```
    pub const X8_2: Self = Self { w: 8, h: 2 };

    /// The square-most preset for a packet of `rays` rays (4: 2 x 2, 8: 4 x 2, 16: 4 x 4), else
    /// one row of `rays` pixels.
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// assert_eq!(TileShape::for_rays(16), TileShape::X4_4);
    /// assert_eq!(TileShape::for_rays(3), TileShape { w: 3, h: 1 });
    /// ```
    pub const fn for_rays(rays: usize) -> Self {
        match rays {
            4 => Self::X2_2,
            8 => Self::X4_2,
            16 => Self::X4_4,
            k => Self { w: k as u32, h: 1 },
        }
    }

    /// Rays per tile, `w * h`.
    ///
    /// ```
    /// assert_eq!(strahl::traverse::packet::TileShape::X8_2.rays(), 16);
    /// ```
    pub const fn rays(self) -> usize {
        self.w as usize * self.h as usize
    }

    /// The pixel of ray `i` when an image `width` pixels wide is enumerated tile by tile (tiles in
    /// rows of `ceil(width / w)`), lane by lane within each tile. At the right and bottom edges of
    /// an image whose size is not a multiple of the tile, the pixel may lie outside the image
    /// (that lane is inactive in [`fill`](Self::fill) and [`image_rays`]). A zero-sized shape maps
    /// every ray to `(0, 0)`.
    ///
    /// ```
    /// use strahl::traverse::packet::TileShape;
    /// let t = TileShape::X2_2;
    /// let order: Vec<_> = (0..8).map(|i| t.pixel(i, 4)).collect();
    /// assert_eq!(order, [(0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (3, 0), (2, 1), (3, 1)]);
    /// ```
    pub const fn pixel(self, i: usize, width: u32) -> (u32, u32) {
        let k = self.rays();
        if k == 0 {
            return (0, 0);
        }
        let per_row = width.div_ceil(self.w) as usize;
        let (tile, lane) = (i / k, i % k);
        let (tx, ty) = if per_row == 0 {
            (0, tile)
        } else {
            (tile % per_row, tile / per_row)
        };
        (
            (tx * self.w as usize + lane % self.w as usize) as u32,
            (ty * self.h as usize + lane / self.w as usize) as u32,
        )
    }

    /// Fills `out[..n]`, `n = rays().min(out.len())`, with the rays of the tile whose top left
    /// pixel is `(x0, y0)`: lane `i` gets `camera(x0 + i % w, y0 + i / w)` if that pixel lies in
    /// the `width x height` image, and an inactive ray (an empty interval: it hits nothing)
    /// otherwise. Returns `n`.
    ///
    /// ```
    /// use strahl::{Ray, Vec3, traverse::packet::TileShape};
    /// let camera = |x: u32, y: u32| Ray::new(Vec3::ZERO, Vec3::new(x as f32, y as f32, 1.0));
    /// let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); 8];
    /// // The tile at (2, 0) of a 3 x 2 image: only column 2 is inside.
    /// assert_eq!(TileShape::X4_2.fill(2, 0, 3, 2, &mut rays, camera), 8);
    /// assert_eq!(rays[0].direction, Vec3::new(2.0, 0.0, 1.0));
    /// assert_eq!(rays[4].direction, Vec3::new(2.0, 1.0, 1.0));
    /// assert!(rays[1].tmin > rays[1].tmax); // pixel (3, 0) is outside
    /// ```
    pub fn fill<F: FnMut(u32, u32) -> Ray>(
        self,
        x0: u32,
        y0: u32,
        width: u32,
        height: u32,
        out: &mut [Ray],
        mut camera: F,
    ) -> usize {
        let n = self.rays().min(out.len());
        for (i, r) in out[..n].iter_mut().enumerate() {
            let (x, y) = (
                x0.saturating_add(i as u32 % self.w),
                y0.saturating_add(i as u32 / self.w),
            );
            *r = if x < width && y < height {
                camera(x, y)
            } else {
                INACTIVE
            };
        }
        n
    }
}

/// The rays of a whole `width x height` image in tile order: `shape.rays()` consecutive rays per
/// tile, ray `i` for pixel [`shape.pixel(i, width)`](TileShape::pixel), inactive rays for the
/// lanes of edge tiles outside the image. Feed it to the batch functions with packets of
/// `shape.rays()`.
///
/// ```
/// use strahl::{Ray, Vec3, traverse::packet::{TileShape, image_rays}};
/// let camera = |x: u32, y: u32| Ray::new(Vec3::ZERO, Vec3::new(x as f32, y as f32, 1.0));
/// let rays = image_rays(TileShape::X4_4, 6, 5, camera);
/// assert_eq!(rays.len(), 2 * 2 * 16); // 2 x 2 tiles of 16
/// let (x, y) = TileShape::X4_4.pixel(21, 6);
/// assert_eq!((x, y), (5, 1));
/// assert_eq!(rays[21].direction, Vec3::new(5.0, 1.0, 1.0));
/// ```
#[cfg(feature = "alloc")]
pub fn image_rays<F: FnMut(u32, u32) -> Ray>(
    shape: TileShape,
    width: u32,
    height: u32,
    mut camera: F,
) -> alloc::vec::Vec<Ray> {
    let k = shape.rays();
    if k == 0 {
        return alloc::vec::Vec::new();
    }
    let tiles = width.div_ceil(shape.w) as usize * height.div_ceil(shape.h) as usize;
    let mut out = alloc::vec![INACTIVE; tiles * k];
    for (t, chunk) in out.chunks_mut(k).enumerate() {
        let (x0, y0) = shape.pixel(t * k, width);
        shape.fill(x0, y0, width, height, chunk, &mut camera);
    }
    out
}
