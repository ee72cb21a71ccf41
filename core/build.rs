//! Tells core's tests which x86-64 kernel forms the build machine runs, as cfgs: the tests of
//! those forms are then reported as ignored, with the reason, on a CPU without them (and in cross
//! builds, which run elsewhere) rather than passing empty. The library itself picks its kernels at
//! run time and reads no cfg set here.
//!
//! - `host_avx2_fma`: AVX2 and FMA (every native x86-64 form needs them);
//! - `host_avx512`: AVX-512F, BW and VL as well;
//! - `host_avx512_vnni`: AVX-512F, BW and VNNI as well;
//! - `host_avx512_bf16`: AVX-512F, VL and BF16 as well.
fn main() {
    for cfg in [
        "host_avx2_fma",
        "host_avx512",
        "host_avx512_vnni",
        "host_avx512_bf16",
    ] {
        println!("cargo::rustc-check-cfg=cfg({cfg})");
    }
    println!("cargo::rerun-if-changed=build.rs");
    // A build script runs on the build machine: its own target_arch is the host's.
    #[cfg(target_arch = "x86_64")]
    if std::env::var("TARGET").ok() == std::env::var("HOST").ok() {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx2") && has!("fma") {
            println!("cargo::rustc-cfg=host_avx2_fma");
            if has!("avx512f") && has!("avx512bw") && has!("avx512vl") {
                println!("cargo::rustc-cfg=host_avx512");
            }
            if has!("avx512f") && has!("avx512bw") && has!("avx512vnni") {
                println!("cargo::rustc-cfg=host_avx512_vnni");
            }
            if has!("avx512f") && has!("avx512vl") && has!("avx512bf16") {
                println!("cargo::rustc-cfg=host_avx512_bf16");
            }
        }
    }
}
