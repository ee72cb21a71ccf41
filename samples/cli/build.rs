//! Tells the CLI's tests whether the build machine has `ffmpeg` on its PATH, as the `has_ffmpeg`
//! cfg: the test that reads a video through it is then reported as ignored, with the reason,
//! where it cannot run, rather than passing empty. The CLI itself looks for ffmpeg at run time.
fn main() {
    println!("cargo::rustc-check-cfg=cfg(has_ffmpeg)");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=PATH");
    let found = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if found {
        println!("cargo::rustc-cfg=has_ffmpeg");
    }
}
