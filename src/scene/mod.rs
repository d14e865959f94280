//! Built-in scenes for tests, benches and examples: the bundled Stanford bunny, an OBJ reader, and
//! procedural meshes (icosphere, triangle fan; for the BVH builders a thin-triangle soup, a
//! clustered soup, a fractal terrain and Haines' sphereflake), plus a small deterministic random
//! number generator.
//!
//! Needs the `alloc` feature. Generated meshes share vertices through indices, so edges shared by
//! two triangles are bit-identical in both: exactly what the watertightness tests need.

use alloc::vec::Vec;
use glam::Vec3;

use crate::geometry::{IndexedMesh, Triangle, Triangles};

mod procedural;
pub use procedural::{clustered_soup, sphereflake, terrain, thin_soup};

/// An owned indexed triangle mesh.
///
/// ```
/// use strahl::{geometry::Triangles, scene};
/// let s = scene::icosphere(1);
/// assert_eq!(s.indices.len(), 80);
/// assert_eq!(s.as_indexed().len(), 80);
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Three vertex indices per triangle.
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// Borrows the mesh as an [`IndexedMesh`].
    ///
    /// ```
    /// use strahl::{Vec3, geometry::Triangles, scene};
    /// let f = scene::fan(4, 1.0);
    /// let m = f.as_indexed();
    /// assert_eq!(m.len(), 4);
    /// assert_eq!(m.triangle(0).unwrap()[0], Vec3::new(0.0, 0.0, 1.0)); // the apex
    /// ```
    pub fn as_indexed(&self) -> IndexedMesh<'_> {
        IndexedMesh::new(&self.positions, &self.indices)
    }

    /// The triangles as a soup (triangles with an out-of-range index are skipped).
    ///
    /// ```
    /// use strahl::{Vec3, scene::Mesh};
    /// let m = Mesh { positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y], indices: vec![[0, 1, 2], [0, 1, 9]] };
    /// assert_eq!(m.to_soup(), vec![[Vec3::ZERO, Vec3::X, Vec3::Y]]); // [0, 1, 9] is skipped
    /// ```
    pub fn to_soup(&self) -> Vec<Triangle> {
        let m = self.as_indexed();
        (0..m.len()).filter_map(|i| m.triangle(i)).collect()
    }

    /// Reads the `v` and `f` lines of a Wavefront OBJ text (other lines are ignored). Polygons are
    /// fanned into triangles; negative (relative) indices are resolved; `v/vt/vn` forms are read.
    ///
    /// ```
    /// let m = strahl::scene::Mesh::from_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n").unwrap();
    /// assert_eq!(m.indices, vec![[0, 1, 3], [0, 3, 2]]);
    /// assert!(strahl::scene::Mesh::from_obj("v 0 0 zero\n").is_err());
    /// ```
    pub fn from_obj(text: &str) -> Result<Mesh, ObjError> {
        let mut m = Mesh::default();
        for (n, line) in text.lines().enumerate() {
            let line_no = n + 1;
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let mut c = [0.0f32; 3];
                    for slot in &mut c {
                        *slot = it
                            .next()
                            .and_then(|s| s.parse().ok())
                            .ok_or(ObjError { line: line_no })?;
                    }
                    m.positions.push(Vec3::from_array(c));
                }
                Some("f") => {
                    let mut poly = [0u32; 64];
                    let mut k = 0;
                    for tok in it {
                        let idx: i64 = tok
                            .split('/')
                            .next()
                            .and_then(|s| s.parse().ok())
                            .ok_or(ObjError { line: line_no })?;
                        let nv = m.positions.len() as i64;
                        let abs = if idx < 0 { nv + idx } else { idx - 1 };
                        if abs < 0 || abs >= nv || k == poly.len() {
                            return Err(ObjError { line: line_no });
                        }
                        poly[k] = abs as u32;
                        k += 1;
                    }
                    if k < 3 {
                        return Err(ObjError { line: line_no });
                    }
                    for j in 1..k - 1 {
                        m.indices.push([poly[0], poly[j], poly[j + 1]]);
                    }
                }
                _ => {}
            }
        }
        Ok(m)
    }
}

/// An OBJ line that could not be read.
///
/// ```
/// use strahl::scene::{Mesh, ObjError};
/// let err = Mesh::from_obj("v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap_err(); // no vertex 3
/// assert_eq!(err, ObjError { line: 3 });
/// assert_eq!(err.to_string(), "OBJ line 3: malformed vertex or face");
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObjError {
    /// 1-based line number.
    pub line: usize,
}

impl core::fmt::Display for ObjError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "OBJ line {}: malformed vertex or face", self.line)
    }
}

impl core::error::Error for ObjError {}

/// The Stanford bunny, low resolution (1,839 vertices, 3,674 triangles), bundled with the crate.
///
/// ```
/// let b = strahl::scene::bunny();
/// assert_eq!((b.positions.len(), b.indices.len()), (1839, 3674));
/// ```
pub fn bunny() -> Mesh {
    Mesh::from_obj(include_str!("../../assets/bunny.obj")).expect("the bundled bunny.obj is valid")
}

/// A unit icosphere: an icosahedron whose faces are split in four `subdivisions` times, vertices
/// projected to the unit sphere. `20 * 4^subdivisions` triangles, closed, consistently wound
/// (counter-clockwise seen from outside).
///
/// ```
/// let s = strahl::scene::icosphere(2);
/// assert_eq!(s.indices.len(), 320);
/// assert!(s.positions.iter().all(|p| (p.length() - 1.0).abs() < 1e-6));
/// ```
pub fn icosphere(subdivisions: u32) -> Mesh {
    let t = (1.0 + libm::sqrtf(5.0)) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut indices: Vec<[u32; 3]> = alloc::vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        // Midpoints shared between the two triangles of an edge, keyed by the sorted vertex pair.
        let mut mids: alloc::collections::BTreeMap<(u32, u32), u32> = alloc::collections::BTreeMap::new();
        let mut mid = |a: u32, b: u32, pos: &mut Vec<Vec3>| -> u32 {
            *mids.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                (pos.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(indices.len() * 4);
        for &[a, b, c] in &indices {
            let ab = mid(a, b, &mut positions);
            let bc = mid(b, c, &mut positions);
            let ca = mid(c, a, &mut positions);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        indices = next;
    }
    Mesh { positions, indices }
}

/// A fan of `n` triangles around one shared apex: the apex at `(0, 0, height)`, the rim on the
/// unit circle in the plane `z = 0`. Seen from above (`+z`), the fan covers the rim polygon
/// without gaps, every spoke shared by two triangles.
///
/// ```
/// let f = strahl::scene::fan(64, 0.25);
/// assert_eq!((f.positions.len(), f.indices.len()), (65, 64));
/// ```
pub fn fan(n: u32, height: f32) -> Mesh {
    let mut positions = alloc::vec![Vec3::new(0.0, 0.0, height)];
    for i in 0..n {
        let a = i as f32 / n as f32 * core::f32::consts::TAU;
        positions.push(Vec3::new(libm::cosf(a), libm::sinf(a), 0.0));
    }
    let indices = (0..n).map(|i| [0, 1 + i, 1 + (i + 1) % n]).collect();
    Mesh { positions, indices }
}

/// SplitMix64: a tiny, fast, deterministic random number generator for scenes, tests and benches
/// (not for cryptography).
///
/// ```
/// let mut r = strahl::scene::Rng::new(7);
/// let x = r.f32();
/// assert!((0.0..1.0).contains(&x));
/// ```
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator seeded with `seed`.
    ///
    /// ```
    /// use strahl::scene::Rng;
    /// let (mut a, mut b) = (Rng::new(42), Rng::new(42));
    /// assert_eq!([a.u64(), a.u64()], [b.u64(), b.u64()]); // same seed, same sequence
    /// assert_ne!(Rng::new(1).u64(), Rng::new(2).u64());
    /// ```
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    ///
    /// ```
    /// // The first output of the reference SplitMix64 (Steele, Lea and Flood 2014) seeded with 0.
    /// assert_eq!(strahl::scene::Rng::new(0).u64(), 0xe220_a839_7b1d_cdaf);
    /// ```
    pub fn u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    ///
    /// ```
    /// use strahl::scene::Rng;
    /// let bits = Rng::new(3).u64();
    /// assert_eq!(Rng::new(3).f32(), (bits >> 40) as f32 / 16_777_216.0); // the top 24 bits
    /// let mut r = Rng::new(3);
    /// assert!((0..1000).map(|_| r.f32()).all(|x| (0.0..1.0).contains(&x)));
    /// ```
    pub fn f32(&mut self) -> f32 {
        (self.u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Uniform in `[lo, hi)`.
    ///
    /// ```
    /// let mut r = strahl::scene::Rng::new(5);
    /// let xs: Vec<f32> = (0..1000).map(|_| r.range(-2.0, 3.0)).collect();
    /// assert!(xs.iter().all(|x| (-2.0..3.0).contains(x)));
    /// let mean = xs.iter().sum::<f32>() / 1000.0;
    /// assert!((mean - 0.5).abs() < 0.2); // the middle of the range
    /// ```
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// Uniform on the unit sphere.
    ///
    /// ```
    /// let mut r = strahl::scene::Rng::new(9);
    /// let vs: Vec<_> = (0..1000).map(|_| r.unit_vector()).collect();
    /// assert!(vs.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
    /// let mean = vs.iter().sum::<strahl::Vec3>() / 1000.0;
    /// assert!(mean.length() < 0.1); // no preferred direction
    /// ```
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, core::f32::consts::TAU);
        let r = libm::sqrtf(1.0 - z * z);
        Vec3::new(r * libm::cosf(a), r * libm::sinf(a), z)
    }
}

/// Which features of a mesh [`aimed_rays`] aims at.
///
/// ```
/// use strahl::scene::{self, Aim};
/// let m = scene::icosphere(0); // 12 vertices, 30 edges
/// assert_eq!(scene::aimed_rays(&m, Aim::Vertices, 1, 3.0, 1).len(), 12);
/// assert_eq!(scene::aimed_rays(&m, Aim::Edges, 1, 3.0, 1).len(), 2 * 30); // two targets an edge
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aim {
    /// Points on shared edges: each edge's midpoint and one random point.
    Edges,
    /// The vertices themselves.
    Vertices,
}

/// Rays aimed exactly at the edges or vertices of `mesh` (the hardest rays for a ray/triangle test:
/// they must not slip between adjacent triangles).
///
/// Each target gets `per_target` rays from random origins outside the surface, within 60 degrees of
/// the target's outward (area-weighted) normal, at 0.5 to 2 times `distance`. The target lies at
/// `t = 1`, and each ray only accepts `t` in `[0.9, 1.1)`, so that on a closed mesh a ray that
/// slips through a crack cannot be rescued by the far side.
///
/// ```
/// use strahl::scene::{self, Aim};
/// let m = scene::icosphere(1);
/// let rays = scene::aimed_rays(&m, Aim::Vertices, 2, 3.0, 7);
/// assert_eq!(rays.len(), 2 * m.positions.len());
/// ```
pub fn aimed_rays(mesh: &Mesh, aim: Aim, per_target: usize, distance: f32, seed: u64) -> Vec<crate::Ray> {
    let mut rng = Rng::new(seed);
    let pos = |i: u32| mesh.positions.get(i as usize).copied().unwrap_or(Vec3::ZERO);
    let mut normal = alloc::vec![Vec3::ZERO; mesh.positions.len()];
    for &[a, b, c] in &mesh.indices {
        let n = (pos(b) - pos(a)).cross(pos(c) - pos(a));
        for i in [a, b, c] {
            if let Some(slot) = normal.get_mut(i as usize) {
                *slot += n;
            }
        }
    }
    let normal_of = |i: u32| normal.get(i as usize).copied().unwrap_or(Vec3::Z);
    let mut targets: Vec<(Vec3, Vec3)> = Vec::new();
    match aim {
        Aim::Vertices => {
            for i in 0..mesh.positions.len() as u32 {
                targets.push((pos(i), normal_of(i).normalize_or(Vec3::Z)));
            }
        }
        Aim::Edges => {
            for &[a, b, c] in &mesh.indices {
                for (i, j) in [(a, b), (b, c), (c, a)] {
                    if i < j {
                        let (pi, pj) = (pos(i), pos(j));
                        let n = (normal_of(i) + normal_of(j)).normalize_or(Vec3::Z);
                        targets.push((pi + (pj - pi) * 0.5, n));
                        targets.push((pi + (pj - pi) * rng.f32(), n));
                    }
                }
            }
        }
    }
    let mut rays = Vec::with_capacity(targets.len() * per_target);
    for (p, n) in targets {
        for _ in 0..per_target {
            let out = loop {
                let v = rng.unit_vector();
                if v.dot(n) > 0.5 {
                    break v;
                }
            };
            let origin = p + out * distance * rng.range(0.5, 2.0);
            rays.push(crate::Ray::with_range(origin, p - origin, 0.9, 1.1));
        }
    }
    rays
}
