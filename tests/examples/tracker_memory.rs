//! The heap a tracker holds, per landmark mode: the default (detector + M3 networks + MSBP) and
//! the ultra-light mode (detector + the learning-free gradient detector + FFBP), on the moving-face
//! clip `monotrack bench` times (640×480, the committed sample picture).
//!
//! ```text
//! cargo run --profile bench -p monotrack-tests --example tracker_memory [-- --frames N]
//! ```
//! A counting allocator measures the tracker alone: the bytes it holds once built (networks read
//! and planned), the peak while the clip runs, what it holds after the clip, and the allocations
//! made by the frames after the first 30 (the frame path's "nothing per frame after warm-up").
//! The embedded model bytes are static data in the library, not heap, and are listed apart.
//! Prints a markdown table.

// A global allocator is an `unsafe impl` by definition; this measuring tool needs one.
#![allow(unsafe_code)]

use monotrack_core::bench::clip;
use monotrack_core::image::{GrayImage, rgb_to_contract_luma};
use monotrack_core::track::{Tracker, TrackerConfig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

/// The system allocator, counting live bytes, their peak and the number of allocations.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Relaxed) + by;
    PEAK.fetch_max(now, Relaxed);
    ALLOCS.fetch_add(1, Relaxed);
}

// SAFETY: every call is forwarded to `System` unchanged; only counters are updated besides.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc` is passed on as is.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as for `alloc`.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as for `alloc`.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Relaxed);
            grew(new_size);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The sample picture the CLI's `bench` and `demo` build their clip from.
const PICTURE: &[u8] = include_bytes!("../../samples/data/astronaut.jpg");

/// Frames after which the frame path is warm (buffers sized, plans built).
const WARM_UP: usize = 30;

struct Row {
    built: usize,
    peak: usize,
    after: usize,
    allocs_after_warm_up: usize,
    frames: usize,
    faces: usize,
}

fn measure(config: TrackerConfig, source: &GrayImage, frames: usize) -> Row {
    let mut frame = GrayImage::default();
    // The clip's buffer first, so that only the tracker is counted below.
    clip::render(source, 0, None, 640, 480, &mut frame);
    let base = LIVE.load(Relaxed);
    PEAK.store(base, Relaxed);
    let mut tracker = Tracker::with_default_models(config).expect("the shipped models load");
    let built = LIVE.load(Relaxed) - base;
    let (mut faces, mut allocs) = (0, 0);
    for t in 0..frames {
        clip::render(source, t, None, 640, 480, &mut frame);
        if t == WARM_UP {
            allocs = ALLOCS.load(Relaxed);
        }
        let r = tracker
            .process(&frame, t as i64 * 33_333_333)
            .expect("a valid frame");
        faces += usize::from(!r.faces.is_empty());
    }
    let allocs_after_warm_up = ALLOCS.load(Relaxed) - allocs;
    let row = Row {
        built,
        peak: PEAK.load(Relaxed) - base,
        after: LIVE.load(Relaxed) - base,
        allocs_after_warm_up,
        frames,
        faces,
    };
    drop(tracker);
    row
}

fn kib(b: usize) -> String {
    format!("{:.0} KiB", b as f64 / 1024.0)
}

fn main() {
    let mut frames = 300;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--frames" => {
                frames = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|&n| n > WARM_UP)
                    .expect("--frames N, N > 30");
            }
            other => panic!("unknown argument {other}"),
        }
    }
    let rgb = image::load_from_memory(PICTURE)
        .expect("the sample picture decodes")
        .to_rgb8();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let mut luma = vec![0u8; w * h];
    rgb_to_contract_luma(rgb.as_raw(), &mut luma);
    let source = GrayImage::from_vec(w, h, luma).expect("sizes match");
    println!(
        "| mode | held once built | peak over the clip | held after | allocations after frame {WARM_UP} | frames with a face |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, config) in [
        ("default (M3 + MSBP)", TrackerConfig::default()),
        (
            "ultra-light (gradient + FFBP)",
            TrackerConfig::ultra_light(),
        ),
    ] {
        let r = measure(config, &source, frames);
        println!(
            "| {name} | {} | {} | {} | {} | {} of {} |",
            kib(r.built),
            kib(r.peak),
            kib(r.after),
            r.allocs_after_warm_up,
            r.faces,
            r.frames
        );
    }
}
