//! Recording allocates nothing per frame (`monotrack_core::record::Recorder`): after warm-up, a
//! recording tracker's frames make exactly the allocations the same tracker's frames make with
//! its recorder off. Its own test binary, so that the counting allocator sees this test alone.

// A global allocator is an `unsafe impl` by definition; counting needs one.
#![allow(unsafe_code)]

use monotrack_core::bench::{android_portrait_camera, clip};
use monotrack_core::image::{Frame, GrayImage, rgb_to_contract_luma};
use monotrack_core::record::{ModelIdentity, RecordingTracker};
use monotrack_core::track::{Tracker, TrackerConfig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded to `System` unchanged; only a counter is updated besides.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Relaxed);
        // SAFETY: the caller's contract for `alloc` is passed on as is.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as for `alloc`.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Relaxed);
        // SAFETY: as for `alloc`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Counts what it is given, keeping nothing (a file's cost without a disk).
struct Counted(std::sync::Arc<AtomicUsize>);

impl Write for Counted {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.fetch_add(b.len(), Relaxed);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn recording_allocates_nothing_per_frame() {
    let rgb = image::open(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/data/astronaut.jpg"
    ))
    .unwrap()
    .to_rgb8();
    let mut source = GrayImage::new(rgb.width() as usize, rgb.height() as usize);
    rgb_to_contract_luma(rgb.as_raw(), source.data_mut());
    let desc = android_portrait_camera();
    let (w, h) = desc.upright_size();
    let frames: Vec<Vec<u8>> = (0..16)
        .map(|t| {
            let (mut upright, mut buf) = (GrayImage::default(), Vec::new());
            clip::render(&source, t, None, w, h, &mut upright);
            clip::encode(&upright, &desc, &mut buf).unwrap();
            buf
        })
        .collect();
    let written = std::sync::Arc::new(AtomicUsize::new(0));
    // Allocations per run of the later frames, recorder off then on (each on a fresh tracker
    // warmed up on the first frames).
    let mut counts = Vec::new();
    for record in [false, true] {
        let tracker = Tracker::with_default_models(TrackerConfig::default()).unwrap();
        let mut rec = RecordingTracker::new(tracker, ModelIdentity::builtin());
        if record {
            let out = Box::new(Counted(std::sync::Arc::clone(&written)));
            rec.switch().start(out, 1 << 30).unwrap();
        }
        let mut run = |range: std::ops::Range<usize>| {
            for t in range {
                let frame = Frame::new(&frames[t], desc).unwrap();
                let r = rec.process_frame(&frame, t as i64 * 33_333_333).unwrap();
                assert_eq!(r.faces.len(), 1, "frame {t}");
            }
        };
        run(0..8);
        let before = ALLOCS.load(Relaxed);
        run(8..16);
        counts.push(ALLOCS.load(Relaxed) - before);
        if record {
            let summary = rec.switch().stop().unwrap();
            assert_eq!(summary.frames, 16);
            assert_eq!(summary.bytes, written.load(Relaxed) as u64);
        }
    }
    assert_eq!(
        counts[1], counts[0],
        "allocations in 8 frames with the recorder on vs off"
    );
}
