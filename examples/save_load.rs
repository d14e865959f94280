//! Build a BVH8 once, save it, and load it again in a fraction of the build time: as a checked
//! copy (`Bvh8::from_bytes`) and in place from a memory-mapped file (`Bvh8Ref::from_bytes`, no
//! copy). Traces the same camera rays through the built, the copied and the mapped tree, checks
//! that they answer alike, and writes the mapped tree's image to `out/save_load.png`.
//!
//! ```sh
//! cargo run --release --example save_load                # the 1M-triangle sphereflake
//! cargo run --release --example save_load -- model.obj   # your OBJ file
//! ```

use std::error::Error;
use std::time::Instant;
use strahl::build::{BuildParams, Bvh2};
use strahl::geometry::Triangle;
use strahl::layout::{Bvh8, Bvh8Ref};
use strahl::scene::{self, Mesh};
use strahl::traverse::{Watertight, wide};
use strahl::{Aabb, Ray, Vec3};

const W: u32 = 640;
const H: u32 = 480;

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Camera rays framing `b` from the front-right and above.
fn camera(b: &Aabb) -> Vec<Ray> {
    let c = b.centroid();
    let r = (b.max - b.min).length() * 0.5;
    let eye = c + Vec3::new(0.55, 0.35, 1.0).normalize() * r * 2.0;
    let fw = (c - eye).normalize();
    let right = fw.cross(Vec3::Y).normalize() * 0.45 * W as f32 / H as f32;
    let up = right.normalize().cross(fw) * 0.45;
    (0..W * H)
        .map(|i| {
            let u = ((i % W) as f32 + 0.5) / W as f32 * 2.0 - 1.0;
            let v = 1.0 - ((i / W) as f32 + 0.5) / H as f32 * 2.0;
            Ray::new(eye, fw + right * u + up * v)
        })
        .collect()
}

fn main() -> Result<(), Box<dyn Error>> {
    let arg = std::env::args().nth(1);
    let (name, tris): (String, Vec<Triangle>) = match &arg {
        Some(path) => {
            let mesh = Mesh::from_obj(&std::fs::read_to_string(path)?)?;
            let stem = std::path::Path::new(path)
                .file_stem()
                .map_or("model".into(), |s| s.to_string_lossy().into_owned());
            (stem, mesh.to_soup())
        }
        None => ("sphereflake".into(), scene::sphereflake(3, 3).to_soup()),
    };
    println!("== {name}: {} triangles", tris.len());

    print!("building (balanced(), then the collapse to BVH8) ... ");
    let t = Instant::now();
    let (b2, _) = Bvh2::build(&tris[..], &BuildParams::balanced())?;
    let built = Bvh8::from_bvh2(&b2, &tris[..])?;
    println!(
        "{:.1} ms, {} nodes, {} packs",
        ms(t),
        built.nodes().len(),
        built.packs().len()
    );

    std::fs::create_dir_all("out")?;
    let path = format!("out/{name}.bvh8");
    let t = Instant::now();
    let bytes = built.to_bytes();
    std::fs::write(&path, &bytes)?;
    println!("saved {path}: {:.1} MB in {:.1} ms", bytes.len() as f64 / 1e6, ms(t));
    drop(bytes);

    let t = Instant::now();
    let file_bytes = std::fs::read(&path)?;
    let read_ms = ms(t);
    let t = Instant::now();
    let copied = Bvh8::from_bytes(&file_bytes)?;
    println!(
        "loaded as a checked copy: read {read_ms:.1} ms + from_bytes {:.1} ms (depth {})",
        ms(t),
        copied.depth()
    );
    drop(file_bytes);

    let file = std::fs::File::open(&path)?;
    // SAFETY: the file was written above by this process and nothing else writes it while it is
    // mapped (a change under the map could only alter answers: traversal reads any bytes safely).
    let map = unsafe { memmap2::Mmap::map(&file)? };
    let t = Instant::now();
    let mapped = Bvh8Ref::from_bytes(&map)?;
    let map_ms = ms(t);
    let t = Instant::now();
    let depth = mapped.check()?;
    println!(
        "mapped in place: from_bytes {map_ms:.1} ms (header, length, checksum), check {:.1} ms (depth {depth})",
        ms(t)
    );

    let b = b2.bounds();
    let rays = camera(&b);
    let t = Instant::now();
    let hits: Vec<_> = rays
        .iter()
        .map(|r| wide::intersect::<Watertight, _, 8>(mapped, r))
        .collect();
    let trace_ms = ms(t);
    let same = rays
        .iter()
        .zip(&hits)
        .filter(|(r, h)| built.intersect::<Watertight>(r) == **h && copied.intersect::<Watertight>(r) == **h)
        .count();
    println!(
        "traced {} camera rays through the mapped tree in {trace_ms:.1} ms; {same} answer as the built and the copied tree",
        rays.len()
    );
    if same != rays.len() {
        return Err("the loaded trees answer differently".into());
    }

    let mut img = vec![0u8; (W * H * 3) as usize];
    for ((px, h), r) in img.chunks_exact_mut(3).zip(&hits).zip(&rays) {
        let c = match h {
            Some(h) => {
                let [a, b, c] = tris[h.prim as usize];
                let n = (b - a).cross(c - a).normalize_or_zero();
                let s = 0.15 + 0.85 * n.dot(r.direction.normalize()).abs();
                [s * 0.9, s * 0.8, s * 0.65]
            }
            None => [0.12, 0.14, 0.18],
        };
        for (p, v) in px.iter_mut().zip(c) {
            *p = (v.clamp(0.0, 1.0) * 255.0) as u8;
        }
    }
    let out = std::fs::File::create("out/save_load.png")?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(out), W, H);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header()?.write_image_data(&img)?;
    println!("wrote out/save_load.png");
    Ok(())
}
