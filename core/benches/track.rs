//! Measures the fast tracker's image stages on 640×480 frames: the NCC region search (template of a
//! 180×200 face region decimated to ~32 px, ±50 % search window), the image pyramid, and pyramidal
//! Lucas–Kanade on 68 points (11×11 window, 3 levels) — the optical-flow filter's cost per face;
//! the pyramid also at 1280×720 (the shared video's frames), whole and around one face as the
//! tracker builds it.
//! Frames: a smooth synthetic texture moved by (6.5, −4.25) px between the two frames.
// Inputs made with the platform's maths library are fine here (core/clippy.toml).
#![allow(clippy::disallowed_methods)]

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::track::flow::{FlowFilter, LkConfig, Pyramid, PyramidalLk};
use monotrack_core::track::ncc::NccMatcher;
use std::hint::black_box;

fn frame(shift: [f32; 2]) -> GrayImage {
    frame_sized(640, 480, shift)
}

fn frame_sized(w: usize, h: usize, shift: [f32; 2]) -> GrayImage {
    let mut img = GrayImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f32 + 0.5 - shift[0], y as f32 + 0.5 - shift[1]);
            let v = 128.0
                + 30.0 * (0.113 * fx + 0.071 * fy).sin()
                + 25.0 * (0.047 * fx - 0.131 * fy + 1.0).sin()
                + 15.0 * (0.29 * fx + 0.23 * fy + 2.0).sin()
                + 50.0 * (-((fx - 300.0).powi(2) + (fy - 220.0).powi(2)) / 3000.0).exp();
            img.data_mut()[y * w + x] = v.clamp(0.0, 255.0) as u8;
        }
    }
    img
}

fn landmarks() -> Vec<[f32; 2]> {
    // 68 points spread over a 180×200 face-sized region like the iBUG layout's extent.
    (0..68)
        .map(|i| {
            let a = i as f32 * 0.37;
            [
                270.0 + 80.0 * (a.sin() * (1.0 + 0.1 * (i % 5) as f32)),
                220.0 + 90.0 * (a * 1.3).cos(),
            ]
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let prev = frame([0.0, 0.0]);
    let next = frame([6.5, -4.25]);
    let region = Rect::new(180.0, 120.0, 180.0, 200.0);

    let mut ncc = NccMatcher::new(32);
    assert!(ncc.set_template(&prev, &region));
    c.bench_function("ncc_search_640x480", |b| {
        b.iter(|| ncc.search(black_box(&next), 0.5).unwrap())
    });
    c.bench_function("ncc_template_cut", |b| {
        b.iter(|| ncc.set_template(black_box(&prev), &region))
    });
    // A 300 px face in a 1280×720 frame (the shared video's size): the same decimated template,
    // a window of 2.25× the pixels to decimate.
    let (hd0, hd1) = (
        frame_sized(1280, 720, [0.0, 0.0]),
        frame_sized(1280, 720, [9.5, -6.0]),
    );
    let mut ncc_hd = NccMatcher::new(32);
    assert!(ncc_hd.set_template(&hd0, &Rect::new(490.0, 210.0, 300.0, 300.0)));
    c.bench_function("ncc_search_1280x720_300px_face", |b| {
        b.iter(|| ncc_hd.search(black_box(&hd1), 0.5).unwrap())
    });

    let mut p0 = Pyramid::new();
    let mut p1 = Pyramid::new();
    p0.build(&prev, 3);
    // Built here too, so the benches below run when a filter skips this one.
    p1.build(&next, 3);
    c.bench_function("pyramid_3_levels_640x480", |b| {
        b.iter(|| p1.build(black_box(&next), 3))
    });
    // The shared video's frame size.
    let hd = &hd0;
    let mut p_hd = Pyramid::new();
    c.bench_function("pyramid_3_levels_1280x720", |b| {
        b.iter(|| p_hd.build(black_box(hd), 3))
    });
    // What the tracker builds for one 300 px face in that frame: the face's box widened by a
    // quarter of its side plus the coarsest level's window (`track::flow_region`).
    let face = Rect::new(490.0, 210.0, 300.0, 300.0);
    let m = 0.25 * 300.0 + 28.0;
    let around = Rect::new(face.x - m, face.y - m, face.w + 2.0 * m, face.h + 2.0 * m);
    c.bench_function("pyramid_3_levels_1280x720_300px_face_region", |b| {
        b.iter(|| p_hd.build_region(black_box(hd), 3, &around))
    });

    let from = landmarks();
    let mut to = vec![[0.0f32; 2]; from.len()];
    let mut st = vec![false; from.len()];
    let mut err = vec![0.0f32; from.len()];
    let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
    c.bench_function("lk_68_points", |b| {
        b.iter(|| {
            lk.track(&p0, &p1, black_box(&from), &mut to, &mut st, &mut err)
                .unwrap()
        })
    });

    let mut filter = FlowFilter::new(LkConfig::default()).unwrap();
    let moved: Vec<[f32; 2]> = from.iter().map(|p| [p[0] + 6.5, p[1] - 4.25]).collect();
    let mut pts = from.clone();
    c.bench_function("flow_filter_68_points_with_pyramid", |b| {
        b.iter(|| {
            // One frame of the filter: this frame's pyramid, then LK from the previous landmarks.
            p1.build(black_box(&next), 3);
            pts.copy_from_slice(&from);
            filter.reset();
            filter.apply(&p0, &p0, &mut pts, 5.0, 0.1).unwrap();
            pts.copy_from_slice(&moved);
            filter.apply(&p0, &p1, &mut pts, 5.0, 0.1).unwrap()
        })
    });
    // The same with the default levels (the bench above keeps 3, its figures' history).
    let levels = LkConfig::default().levels;
    let (mut q0, mut q1) = (Pyramid::new(), Pyramid::new());
    q0.build(&prev, levels);
    c.bench_function("flow_filter_68_points_default_levels", |b| {
        b.iter(|| {
            q1.build(black_box(&next), levels);
            pts.copy_from_slice(&from);
            filter.reset();
            filter.apply(&q0, &q0, &mut pts, 5.0, 0.1).unwrap();
            pts.copy_from_slice(&moved);
            filter.apply(&q0, &q1, &mut pts, 5.0, 0.1).unwrap()
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
