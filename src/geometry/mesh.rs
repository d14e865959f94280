use bytemuck::PodCastError;
use glam::Vec3;

/// A triangle as its three vertices.
///
/// ```
/// use strahl::{Vec3, geometry::Triangle};
/// let t: Triangle = [Vec3::ZERO, Vec3::X * 2.0, Vec3::Y];
/// let area = (t[1] - t[0]).cross(t[2] - t[0]).length() / 2.0;
/// assert_eq!(area, 1.0);
/// assert_eq!(core::mem::size_of::<Triangle>(), 36); // packed: nine `f32`s, no padding
/// ```
pub type Triangle = [Vec3; 3];

/// `true` if no ray can hit `tri`: a vertex is not finite, or the cross product of its edges
/// `(v1 - v0) x (v2 - v0)`, evaluated in `f32`, is exactly zero (coincident or collinear
/// vertices).
///
/// Every triangle kernel applies this same predicate, so scalar and SIMD kernels agree on it.
///
/// ```
/// use strahl::{Vec3, geometry::is_degenerate};
/// assert!(!is_degenerate(&[Vec3::ZERO, Vec3::X, Vec3::Y]));
/// assert!(is_degenerate(&[Vec3::ZERO, Vec3::X, Vec3::X * 2.0]));
/// assert!(is_degenerate(&[Vec3::ZERO, Vec3::X, Vec3::splat(f32::NAN)]));
/// ```
#[inline]
pub fn is_degenerate(tri: &Triangle) -> bool {
    if !(tri[0].is_finite() && tri[1].is_finite() && tri[2].is_finite()) {
        return true;
    }
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let n = e1.cross(e2);
    n.x == 0.0 && n.y == 0.0 && n.z == 0.0
}

/// Errors from reading geometry out of byte buffers.
///
/// ```
/// use strahl::geometry::{GeometryError, TriangleSoup};
/// let words = [0u32; 10];
/// let bytes: &[u8] = bytemuck::cast_slice(&words); // 40 bytes, 4-byte aligned
/// let err = TriangleSoup::from_bytes(bytes).unwrap_err();
/// assert_eq!(err, GeometryError::BadLength { what: "triangles", len: 40, element: 36 });
/// assert_eq!(err.to_string(), "triangles: 40 bytes is not a multiple of the 36-byte element");
/// let err = TriangleSoup::from_bytes(&bytes[1..37]).unwrap_err();
/// assert_eq!(err, GeometryError::Misaligned { what: "triangles" });
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryError {
    /// The byte buffer's length is not a multiple of the element size.
    BadLength {
        /// Which buffer.
        what: &'static str,
        /// Its length in bytes.
        len: usize,
        /// The element size it must be a multiple of.
        element: usize,
    },
    /// The byte buffer is not aligned to 4 bytes.
    Misaligned {
        /// Which buffer.
        what: &'static str,
    },
    /// A stride shorter than the element it steps over ([`StridedMesh`]).
    BadStride {
        /// Which buffer.
        what: &'static str,
        /// The stride in bytes.
        stride: usize,
        /// The element size it must be at least.
        element: usize,
    },
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadLength { what, len, element } => {
                write!(f, "{what}: {len} bytes is not a multiple of the {element}-byte element")
            }
            Self::Misaligned { what } => write!(f, "{what}: buffer is not 4-byte aligned"),
            Self::BadStride { what, stride, element } => {
                write!(
                    f,
                    "{what}: a stride of {stride} bytes is shorter than the {element}-byte element"
                )
            }
        }
    }
}

impl core::error::Error for GeometryError {}

/// `bytes` as a slice of `T`; an empty buffer is an empty slice wherever it points.
fn cast<'a, T: bytemuck::Pod>(what: &'static str, bytes: &'a [u8]) -> Result<&'a [T], GeometryError> {
    // NOTE: an empty `&[u8]` may point anywhere (`&[]` is a dangling pointer at address 1),
    // which bytemuck reports as misaligned; there is nothing to read, so it is no error.
    if bytes.is_empty() {
        return Ok(&[]);
    }
    bytemuck::try_cast_slice(bytes).map_err(|e| match e {
        PodCastError::TargetAlignmentGreaterAndInputNotAligned => GeometryError::Misaligned { what },
        _ => GeometryError::BadLength {
            what,
            len: bytes.len(),
            element: core::mem::size_of::<T>(),
        },
    })
}

/// Read access to a set of triangles, however they are stored.
///
/// Builders and brute-force references take `&impl Triangles`.
///
/// ```
/// use strahl::{Vec3, geometry::{Triangles, TriangleSoup}};
/// // One function for every storage, `[Triangle]` included.
/// fn total_area<T: Triangles + ?Sized>(tris: &T) -> f32 {
///     let area = |[a, b, c]: [Vec3; 3]| (b - a).cross(c - a).length() / 2.0;
///     (0..tris.len()).filter_map(|i| tris.triangle(i)).map(area).sum()
/// }
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::ZERO, Vec3::X * 2.0, Vec3::Z * 2.0]];
/// assert_eq!(total_area(&tris[..]), 2.5);
/// assert_eq!(total_area(&TriangleSoup::new(&tris)), 2.5);
/// ```
pub trait Triangles {
    /// Number of triangles (including invalid ones).
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{IndexedMesh, Triangles}};
    /// let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let indices = [[0, 1, 2], [0, 1, 7]];
    /// let mesh = IndexedMesh::new(&positions, &indices);
    /// assert_eq!(mesh.len(), 2); // triangle 1 refers to a missing vertex 7 but still counts
    /// assert_eq!(mesh.triangle(1), None);
    /// ```
    fn len(&self) -> usize;
    /// `true` if there are no triangles.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{Triangle, TriangleSoup, Triangles}};
    /// let none: [Triangle; 0] = [];
    /// assert!(TriangleSoup::new(&none).is_empty());
    /// let one = [[Vec3::ZERO; 3]]; // degenerate, but still a triangle
    /// assert!(!TriangleSoup::new(&one).is_empty());
    /// ```
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Triangle `i`, or `None` if it cannot be formed (an index out of range).
    /// Out-of-range `i` also gives `None`.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{IndexedMesh, Triangles}};
    /// let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let indices = [[2, 1, 0], [0, 1, 3]];
    /// let mesh = IndexedMesh::new(&positions, &indices);
    /// assert_eq!(mesh.triangle(0), Some([Vec3::Y, Vec3::X, Vec3::ZERO])); // vertex order kept
    /// assert_eq!(mesh.triangle(1), None); // there is no vertex 3
    /// assert_eq!(mesh.triangle(2), None); // there is no triangle 2
    /// ```
    fn triangle(&self, i: usize) -> Option<Triangle>;
    /// Asks the cache for triangle `i` ahead of a [`triangle`](Self::triangle) call: a hint for
    /// code that reads the triangles in an order of its own (the BVH8 collapse reads them leaf by
    /// leaf). Nothing is read; an index out of range is ignored. The default does nothing.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::Triangles};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    /// tris[..].prefetch(0);
    /// tris[..].prefetch(7); // out of range: ignored
    /// assert_eq!(tris[..].triangle(0), Some(tris[0]));
    /// ```
    #[inline]
    fn prefetch(&self, i: usize) {
        let _ = i;
    }
}

/// Triangles as shared vertex positions and three `u32` indices each, borrowed without copying.
///
/// ```
/// use strahl::{Vec3, geometry::{IndexedMesh, Triangles}};
/// let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
/// let indices = [[0, 1, 2], [0, 2, 3], [0, 1, 9]];
/// let mesh = IndexedMesh::new(&positions, &indices);
/// assert_eq!(mesh.len(), 3);
/// assert_eq!(mesh.triangle(1), Some([Vec3::ZERO, Vec3::Y, Vec3::Z]));
/// assert_eq!(mesh.triangle(2), None); // index 9 is out of range: never a panic
///
/// // The same mesh from raw little-endian bytes (say, a file read into memory):
/// let pos_bytes: &[u8] = bytemuck::cast_slice(&positions);
/// let idx_bytes: &[u8] = bytemuck::cast_slice(&indices);
/// let mesh = IndexedMesh::from_bytes(pos_bytes, idx_bytes).unwrap();
/// assert_eq!(mesh.triangle(0), Some([Vec3::ZERO, Vec3::X, Vec3::Y]));
/// ```
#[derive(Clone, Copy, Debug)]
pub struct IndexedMesh<'a> {
    /// Vertex positions.
    pub positions: &'a [Vec3],
    /// Three vertex indices per triangle.
    pub indices: &'a [[u32; 3]],
}

impl<'a> IndexedMesh<'a> {
    /// Borrows positions and indices.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{IndexedMesh, Triangles}};
    /// // A unit square as two triangles sharing the diagonal 0-2.
    /// let positions = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
    /// let indices = [[0, 1, 2], [0, 2, 3]];
    /// let mesh = IndexedMesh::new(&positions, &indices);
    /// assert_eq!(mesh.len(), 2);
    /// assert_eq!(mesh.triangle(1), Some([Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]));
    /// ```
    pub fn new(positions: &'a [Vec3], indices: &'a [[u32; 3]]) -> Self {
        Self { positions, indices }
    }

    /// Views byte buffers of packed `[f32; 3]` positions and `[u32; 3]` indices (native endian,
    /// 4-byte aligned) without copying. An empty buffer is valid wherever it points: empty
    /// indices give an empty mesh, and empty positions with indices give a mesh whose every
    /// triangle is `None` (its vertices are missing), as [`new`](Self::new) with empty slices.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{GeometryError, IndexedMesh, Triangles}};
    /// let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let indices = [[0u32, 1, 2]];
    /// let (p, i): (&[u8], &[u8]) = (bytemuck::cast_slice(&positions), bytemuck::cast_slice(&indices));
    /// let mesh = IndexedMesh::from_bytes(p, i).unwrap();
    /// assert_eq!(mesh.triangle(0), Some(positions));
    /// let err = IndexedMesh::from_bytes(p, &i[..8]).unwrap_err(); // two indices, not a triangle
    /// assert_eq!(err, GeometryError::BadLength { what: "indices", len: 8, element: 12 });
    /// let empty = IndexedMesh::from_bytes(&[], &[]).unwrap(); // say, an empty file
    /// assert!(empty.is_empty());
    /// ```
    pub fn from_bytes(positions: &'a [u8], indices: &'a [u8]) -> Result<Self, GeometryError> {
        Ok(Self {
            positions: cast("positions", positions)?,
            indices: cast("indices", indices)?,
        })
    }
}

impl Triangles for IndexedMesh<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.indices.len()
    }
    #[inline]
    fn triangle(&self, i: usize) -> Option<Triangle> {
        let [a, b, c] = *self.indices.get(i)?;
        let p = self.positions;
        Some([*p.get(a as usize)?, *p.get(b as usize)?, *p.get(c as usize)?])
    }
    /// The index triple (its vertices are only known once it has arrived).
    #[inline]
    fn prefetch(&self, i: usize) {
        prefetch_triple(self.indices, i);
    }
}

/// Asks the cache for index triple `i` of an indexed mesh (ignored out of range).
#[inline]
fn prefetch_triple(indices: &[[u32; 3]], i: usize) {
    if let Some(t) = indices.get(i) {
        crate::math::prefetch(t);
    }
}

/// Triangles over interleaved vertex data, borrowed without copying: each vertex is `stride`
/// bytes with its position as three `f32`s (native endian) at its start, the rest (normals,
/// texture coordinates) skipped, as Embree's vertex buffers with a byte stride; the indices are
/// `u32` triples. Pass the buffer from the position's byte offset (`&bytes[offset..]`); it needs
/// no alignment, and the last vertex needs only its 12 position bytes. An index past the last
/// vertex makes that triangle `None` (left out of trees), never a panic.
///
/// ```
/// use strahl::{Vec3, build::BuildParams, layout::Bvh8, Ray, traverse::Watertight};
/// use strahl::geometry::{GeometryError, StridedMesh, Triangles};
/// // Vertices of position, normal and texture coordinates: 32 bytes each.
/// #[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
/// #[repr(C)]
/// struct Vertex { pos: [f32; 3], normal: [f32; 3], uv: [f32; 2] }
/// let v = |x: f32, y: f32| Vertex { pos: [x, y, 2.0], normal: [0.0, 0.0, -1.0], uv: [x, y] };
/// let vertices = [v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0)];
/// let bytes: &[u8] = bytemuck::cast_slice(&vertices);
/// let mesh = StridedMesh::new(bytes, 32, &[[0, 1, 2], [0, 2, 3], [0, 1, 4]]).unwrap();
/// assert_eq!(mesh.vertices(), 4);
/// assert_eq!(mesh.triangle(1), Some([Vec3::new(-1.0, -1.0, 2.0), Vec3::new(1.0, 1.0, 2.0), Vec3::new(-1.0, 1.0, 2.0)]));
/// assert_eq!(mesh.triangle(2), None); // there is no vertex 4
/// let (bvh8, stats) = Bvh8::build(&mesh, &BuildParams::default()).unwrap();
/// assert_eq!(stats.invalid, 1);
/// assert_eq!(bvh8.intersect::<Watertight>(&Ray::new(Vec3::new(-0.5, 0.5, 0.0), Vec3::Z)).unwrap().prim, 1);
/// // The texture coordinates as positions (byte offset 24 of a vertex) would need 12 bytes:
/// // the last vertex has only 8 there, so it is not a vertex.
/// assert_eq!(StridedMesh::new(&bytes[24..], 32, &[]).unwrap().vertices(), 3);
/// let err = StridedMesh::new(bytes, 8, &[]).unwrap_err();
/// assert_eq!(err, GeometryError::BadStride { what: "vertices", stride: 8, element: 12 });
/// ```
#[derive(Clone, Copy, Debug)]
pub struct StridedMesh<'a> {
    vertices: &'a [u8],
    stride: usize,
    count: usize,
    /// Three vertex indices per triangle.
    pub indices: &'a [[u32; 3]],
}

impl<'a> StridedMesh<'a> {
    /// Borrows a vertex buffer of `stride`-byte vertices (a position's three `f32`s at the start
    /// of each) and the index triples. A stride under 12 bytes is an error; any length and
    /// alignment of `vertices` is valid (the vertices are its whole strides, and a last one of at
    /// least 12 bytes).
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{StridedMesh, Triangles}};
    /// // Packed positions are a stride of 12.
    /// let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
    /// let mesh = StridedMesh::new(bytemuck::cast_slice(&positions), 12, &[[0, 1, 2]]).unwrap();
    /// assert_eq!(mesh.triangle(0), Some(positions));
    /// assert_eq!(StridedMesh::new(&[], 16, &[[0, 1, 2]]).unwrap().triangle(0), None); // no vertices
    /// ```
    pub fn new(vertices: &'a [u8], stride: usize, indices: &'a [[u32; 3]]) -> Result<Self, GeometryError> {
        const POSITION: usize = 12;
        if stride < POSITION {
            return Err(GeometryError::BadStride {
                what: "vertices",
                stride,
                element: POSITION,
            });
        }
        let count = match vertices.len().checked_sub(POSITION) {
            Some(rest) => rest / stride + 1,
            None => 0,
        };
        Ok(Self {
            vertices,
            stride,
            count,
            indices,
        })
    }

    /// The number of vertices in the buffer.
    ///
    /// ```
    /// use strahl::geometry::StridedMesh;
    /// let bytes = [0u8; 100];
    /// // Vertices at 0, 32 and 64; a fourth at 96 would end at 108, past the 100 bytes.
    /// assert_eq!(StridedMesh::new(&bytes, 32, &[]).unwrap().vertices(), 3);
    /// ```
    pub fn vertices(&self) -> usize {
        self.count
    }

    /// The position of vertex `i`, or `None` past the last one.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::StridedMesh};
    /// let data = [1.0f32, 2.0, 3.0, 9.0, 4.0, 5.0, 6.0]; // two vertices of 16 bytes (the last cut short)
    /// let mesh = StridedMesh::new(bytemuck::cast_slice(&data), 16, &[]).unwrap();
    /// assert_eq!((mesh.vertex(0), mesh.vertex(1), mesh.vertex(2)), (Some(Vec3::new(1.0, 2.0, 3.0)), Some(Vec3::new(4.0, 5.0, 6.0)), None));
    /// ```
    #[inline]
    pub fn vertex(&self, i: usize) -> Option<Vec3> {
        if i >= self.count {
            return None;
        }
        // `i < count`, so `i * stride + 12 <= len` (no overflow: it is within the slice).
        let at = i * self.stride;
        let b = self.vertices.get(at..at + 12)?;
        Some(Vec3::from_array(bytemuck::pod_read_unaligned::<[f32; 3]>(b)))
    }
}

impl Triangles for StridedMesh<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.indices.len()
    }
    #[inline]
    fn triangle(&self, i: usize) -> Option<Triangle> {
        let [a, b, c] = *self.indices.get(i)?;
        Some([
            self.vertex(a as usize)?,
            self.vertex(b as usize)?,
            self.vertex(c as usize)?,
        ])
    }
    /// The index triple (its vertices are only known once it has arrived).
    #[inline]
    fn prefetch(&self, i: usize) {
        prefetch_triple(self.indices, i);
    }
}

/// Triangles stored as three vertices each (36 bytes a triangle), borrowed without copying.
///
/// ```
/// use strahl::{Vec3, geometry::{TriangleSoup, Triangles}};
/// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
/// let soup = TriangleSoup::new(&tris);
/// assert_eq!(soup.triangle(0), Some(tris[0]));
/// let soup = TriangleSoup::from_bytes(bytemuck::cast_slice(&tris)).unwrap();
/// assert_eq!(soup.len(), 1);
/// assert!(TriangleSoup::from_bytes(&[0u8; 35]).is_err());
/// ```
#[derive(Clone, Copy, Debug)]
pub struct TriangleSoup<'a> {
    /// The triangles.
    pub triangles: &'a [Triangle],
}

impl<'a> TriangleSoup<'a> {
    /// Borrows triangles.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{TriangleSoup, Triangles}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::X, Vec3::Y]];
    /// let soup = TriangleSoup::new(&tris);
    /// assert_eq!(soup.len(), 2);
    /// assert_eq!(soup.triangle(1), Some(tris[1]));
    /// assert_eq!(soup.triangle(2), None);
    /// ```
    pub fn new(triangles: &'a [Triangle]) -> Self {
        Self { triangles }
    }

    /// Views a byte buffer of packed `[[f32; 3]; 3]` triangles (native endian, 4-byte aligned)
    /// without copying. An empty buffer, wherever it points, is an empty soup.
    ///
    /// ```
    /// use strahl::{Vec3, geometry::{GeometryError, TriangleSoup, Triangles}};
    /// let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y], [Vec3::Z, Vec3::X, Vec3::Y]];
    /// let bytes: &[u8] = bytemuck::cast_slice(&tris); // 72 bytes
    /// let soup = TriangleSoup::from_bytes(bytes).unwrap();
    /// assert_eq!((soup.len(), soup.triangle(1)), (2, Some(tris[1])));
    /// let err = TriangleSoup::from_bytes(&bytes[4..]).unwrap_err(); // 68 bytes
    /// assert_eq!(err, GeometryError::BadLength { what: "triangles", len: 68, element: 36 });
    /// assert!(TriangleSoup::from_bytes(&[]).unwrap().is_empty());
    /// ```
    pub fn from_bytes(bytes: &'a [u8]) -> Result<Self, GeometryError> {
        Ok(Self {
            triangles: cast("triangles", bytes)?,
        })
    }
}

impl Triangles for TriangleSoup<'_> {
    #[inline]
    fn len(&self) -> usize {
        self.triangles.len()
    }
    #[inline]
    fn triangle(&self, i: usize) -> Option<Triangle> {
        self.triangles.get(i).copied()
    }
    #[inline]
    fn prefetch(&self, i: usize) {
        self.triangles.prefetch(i);
    }
}

impl Triangles for [Triangle] {
    #[inline]
    fn len(&self) -> usize {
        <[Triangle]>::len(self)
    }
    #[inline]
    fn triangle(&self, i: usize) -> Option<Triangle> {
        self.get(i).copied()
    }
    /// Both cache lines a triangle (36 bytes) may touch.
    #[inline]
    fn prefetch(&self, i: usize) {
        if let Some(t) = self.get(i) {
            let p: *const u8 = (t as *const Triangle).cast();
            crate::math::prefetch(p);
            crate::math::prefetch(p.wrapping_add(core::mem::size_of::<Triangle>() - 1));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Empty buffers, whatever their address (`&[]` dangles at address 1; a sub-slice may sit at
    /// any offset), are empty geometry; a buffer with bytes still needs 4-byte alignment.
    #[test]
    fn empty_buffers_are_empty_geometry() {
        let words = [0u32; 20];
        let bytes: &[u8] = bytemuck::cast_slice(&words);
        for empty in [&[][..], &bytes[0..0], &bytes[1..1], &bytes[3..3], &bytes[80..]] {
            let soup = TriangleSoup::from_bytes(empty).unwrap();
            assert!(soup.is_empty());
            assert_eq!(soup.triangle(0), None);
            let mesh = IndexedMesh::from_bytes(empty, empty).unwrap();
            assert!(mesh.is_empty() && mesh.positions.is_empty());
            // Indices without positions: every triangle is missing a vertex.
            let mesh = IndexedMesh::from_bytes(empty, &bytes[..12]).unwrap();
            assert_eq!((mesh.len(), mesh.triangle(0)), (1, None));
            // Positions without indices: no triangles.
            let mesh = IndexedMesh::from_bytes(&bytes[..36], empty).unwrap();
            assert_eq!((mesh.len(), mesh.positions.len()), (0, 3));
        }
        assert_eq!(
            TriangleSoup::from_bytes(&bytes[1..37]).unwrap_err(),
            GeometryError::Misaligned { what: "triangles" }
        );
        assert_eq!(
            IndexedMesh::from_bytes(&bytes[2..14], &[]).unwrap_err(),
            GeometryError::Misaligned { what: "positions" }
        );
    }
}
