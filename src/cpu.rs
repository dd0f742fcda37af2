//! Which SIMD kernels run. The build chooses once, for the whole crate, between the AVX2 and FMA
//! kernels (where the target has both: x86-64-v3, the project's baseline) and their portable
//! twins (`build.rs`, which sets the `simd` cfg the kernels are built under); the processor is
//! asked once at run time for AVX-512, whose 512-bit registers double the multiply-adds a cycle
//! of the kernels bound by them (the grid's moments). [`kernels`] says which run.
//!
//! Every kernel with an AVX-512 version makes the same products and sums, in the same order, in
//! each lane as its AVX2 version, so both give the same bits; the tests compare them where the
//! processor has AVX-512. `REGTRACK_SIMD=avx2` in the environment keeps the AVX2 kernels (to
//! compare speeds on one machine).

use std::sync::OnceLock;

/// Whether this build's kernels are the AVX2 and FMA ones (else the portable twins).
pub const AVX2: bool = cfg!(simd = "avx2");

/// The kernels that run, as `regtrack bench` prints them: `AVX-512` (on top of the build's
/// AVX2 and FMA, chosen at run time), `AVX2+FMA`, or `portable`.
pub fn kernels() -> &'static str {
    match (AVX2, avx512()) {
        (true, true) => "AVX-512 (run time) and AVX2+FMA (build)",
        (true, false) if avx512_present() => {
            "AVX2+FMA (build; AVX-512 present, off by REGTRACK_SIMD)"
        }
        (true, false) => "AVX2+FMA (build)",
        (false, _) => "portable (the build's target has no AVX2 and FMA)",
    }
}

/// Whether the AVX-512 kernels run: the processor (and the operating system) has AVX-512F, BW,
/// DQ and VL, and `REGTRACK_SIMD` does not say `avx2`. Detected once.
pub fn avx512() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| {
        let off = std::env::var("REGTRACK_SIMD").is_ok_and(|v| v.eq_ignore_ascii_case("avx2"));
        !off && avx512_present()
    })
}

/// Whether the processor has the AVX-512 subsets the kernels use (whatever `REGTRACK_SIMD`
/// says).
pub fn avx512_present() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512dq")
            && std::arch::is_x86_feature_detected!("avx512vl")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
