//! Build script: only with the bench-only `tinybvh` feature, compiles the C interface to the
//! tinybvh peer (`benches/peers/tinybvh.cpp`) against the `tiny_bvh.h` in `$TINYBVH_DIR`
//! (`benches/peers/tinybvh_fetch.sh` fetches it). Without the feature it does nothing.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "tinybvh")]
    tinybvh();
}

#[cfg(feature = "tinybvh")]
fn tinybvh() {
    println!("cargo:rerun-if-changed=benches/peers/tinybvh.cpp");
    println!("cargo:rerun-if-env-changed=TINYBVH_DIR");
    let Some(dir) = std::env::var_os("TINYBVH_DIR") else {
        panic!(
            "the `tinybvh` feature needs TINYBVH_DIR, a directory holding tiny_bvh.h: \
             run `bash benches/peers/tinybvh_fetch.sh` and export what it prints"
        );
    };
    println!(
        "cargo:rerun-if-changed={}",
        std::path::Path::new(&dir).join("tiny_bvh.h").display()
    );
    cc::Build::new()
        .cpp(true)
        .std("c++20")
        .include(&dir)
        .file("benches/peers/tinybvh.cpp")
        .flag_if_supported("-march=native")
        .flag_if_supported("-w")
        .opt_level(3)
        .compile("strahl_tinybvh_peer");
}
