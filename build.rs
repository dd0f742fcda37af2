//! Chooses this build's SIMD kernels, once, for the whole crate: where the target has AVX2 and
//! FMA (x86-64-v3, the project's baseline set in `.cargo/config.toml`), the code built under
//! `#[cfg(simd = "avx2")]` runs (intrinsics); elsewhere its portable twins (plain Rust, the same
//! arithmetic), which are also built for the tests that compare the two bit for bit
//! (`#[cfg(any(test, not(simd = "avx2")))]`). The AVX-512 kernels beside the AVX2 ones are chosen
//! at run time (`regtrack::cpu`). `regtrack bench` prints which run (`regtrack::cpu::kernels`).

fn main() {
    println!("cargo::rustc-check-cfg=cfg(simd, values(\"avx2\"))");
    println!("cargo::rerun-if-changed=build.rs");
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let features = std::env::var("CARGO_CFG_TARGET_FEATURE").unwrap_or_default();
    let has = |f: &str| features.split(',').any(|x| x == f);
    if arch == "x86_64" && has("avx2") && has("fma") {
        println!("cargo::rustc-cfg=simd=\"avx2\"");
    }
}
