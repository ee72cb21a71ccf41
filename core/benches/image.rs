//! Measures frame → upright luma conversion for a 640×480 camera frame: RGBA (rotation 0 and 90°,
//! the portrait-phone case), NV21 rotated 90° (an Android back camera in portrait), 270° and
//! mirrored (the front camera), and upright. `MONOTRACK_KERNELS=portable` times the forms an
//! aarch64 phone runs.

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::camera::Rotation;
use monotrack_core::image::{Frame, FrameDesc, GrayImage, PixelFormat};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let (w, h) = (640u32, 480u32);
    let rgba: Vec<u8> = (0..w * h * 4).map(|i| (i * 31 % 251) as u8).collect();
    let mut out = GrayImage::default();
    for rot in [Rotation::R0, Rotation::R90] {
        let mut d = FrameDesc::packed(w, h, PixelFormat::Rgba8);
        d.rotation = rot;
        let f = Frame::new(&rgba, d).unwrap();
        c.bench_function(&format!("rgba_640x480_to_luma_rot{}", rot.degrees()), |b| {
            b.iter(|| black_box(&f).to_luma(&mut out))
        });
    }
    for (rot, mirrored) in [
        (Rotation::R90, false),
        (Rotation::R270, true),
        (Rotation::R0, false),
    ] {
        let d = FrameDesc {
            rotation: rot,
            mirrored,
            ..FrameDesc::packed(w, h, PixelFormat::Nv21)
        };
        let nv21: Vec<u8> = (0..d.required_len().unwrap())
            .map(|i| (i * 31 % 251) as u8)
            .collect();
        let f = Frame::new(&nv21, d).unwrap();
        let name = format!(
            "nv21_640x480_to_luma_rot{}{}",
            rot.degrees(),
            if mirrored { "_mirrored" } else { "" }
        );
        c.bench_function(&name, |b| b.iter(|| black_box(&f).to_luma(&mut out)));
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(2));
    targets = bench
}
criterion_main!(benches);
