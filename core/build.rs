//! Tells core's tests which x86-64 kernel forms the build machine runs, as the `host_avx2_fma`
//! cfg: the tests of those forms are then reported as ignored, with the reason, on a CPU without
//! them (and in cross builds, which run elsewhere) rather than passing empty. The library itself
//! picks its kernels at run time and reads no cfg set here.
fn main() {
    println!("cargo::rustc-check-cfg=cfg(host_avx2_fma)");
    println!("cargo::rerun-if-changed=build.rs");
    // A build script runs on the build machine: its own target_arch is the host's.
    #[cfg(target_arch = "x86_64")]
    if std::env::var("TARGET").ok() == std::env::var("HOST").ok()
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        println!("cargo::rustc-cfg=host_avx2_fma");
    }
}
