//! Prints a decoded input and runs the checker on it. The target is taken from the path
//! (`seeds/<target>/...`, `artifacts/<target>/...`, `corpus/<target>/...`); `kernels` otherwise:
//!
//! ```text
//! cargo run --example replay -- seeds/kernels/grid-aim-edge artifacts/kernels/crash-...
//! cargo run --example replay -- seeds/volume/grid-u8-skip seeds/composite/grid-f32-16-ranks
//! ```

use strahl_fuzz::{
    BvhCase, CompositeCase, KernelCase, VolumeCase, check_bvh, check_composite, check_kernels, check_volume,
};

fn main() {
    for path in std::env::args().skip(1) {
        let data = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let target = ["volume", "composite", "bvh"]
            .into_iter()
            .find(|t| path.contains(&format!("/{t}/")) || path.starts_with(&format!("{t}/")))
            .unwrap_or("kernels");
        println!("== {path} ({} bytes, target {target})", data.len());
        match target {
            "volume" => {
                let case = VolumeCase::decode(&data);
                println!("{case:#?}");
                println!("{:?}", check_volume(&case));
            }
            "composite" => {
                let case = CompositeCase::decode(&data);
                println!("{case:?}");
                println!("{:?}", check_composite(&case));
            }
            "bvh" => {
                let case = BvhCase::decode(&data);
                println!("{case:?}");
                check_bvh(&case);
            }
            _ => {
                let case = KernelCase::decode(&data);
                println!("{case}");
                check_kernels(&case);
            }
        }
        println!("ok");
    }
}
