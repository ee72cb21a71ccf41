//! Frame descriptions and bytes as an app passes them: every format, stride, rotation and size,
//! through `luma_image`, the face tracker and the live tracker.
use crate::bytes::{Bytes, typed};
use monotrack_ffi::{
    FaceTracker, FaceTrackerOptions, FrameDesc, LiveStreamListener, LiveStreamResult,
    MonotrackError, PixelFormat, RunningMode, frame_byte_count, luma_image, upright_size,
};
use std::sync::{Arc, OnceLock};

struct Ignore;

impl LiveStreamListener for Ignore {
    fn on_result(&self, _: LiveStreamResult) {}
    fn on_error(&self, _: i64, _: u64, error: MonotrackError) {
        if let MonotrackError::Internal { msg } = error {
            // On the worker thread: abort so that libFuzzer records the input.
            eprintln!("live worker: internal error {msg}");
            std::process::abort();
        }
    }
}

/// One tracker per running mode: image, video, live stream.
fn trackers() -> &'static [Arc<FaceTracker>; 3] {
    static T: OnceLock<[Arc<FaceTracker>; 3]> = OnceLock::new();
    T.get_or_init(|| {
        let options = |mode| FaceTrackerOptions {
            running_mode: Some(mode),
            ..FaceTrackerOptions::default()
        };
        [
            FaceTracker::new(options(RunningMode::Image), None).unwrap(),
            FaceTracker::new(options(RunningMode::Video), None).unwrap(),
            FaceTracker::new(options(RunningMode::LiveStream), Some(Arc::new(Ignore))).unwrap(),
        ]
    })
}

const FORMATS: [PixelFormat; 7] = [
    PixelFormat::Rgba8,
    PixelFormat::Bgra8,
    PixelFormat::Rgb8,
    PixelFormat::Gray8,
    PixelFormat::Nv21,
    PixelFormat::Nv12,
    PixelFormat::I420,
];

/// One input of the `frames` target.
pub fn run(data: &[u8]) {
    let mut b = Bytes(data);
    let small = b.u8() & 1 == 0;
    // Mostly small frames (the tracker runs on them quickly); sometimes any size, for the arithmetic.
    let dim = |b: &mut Bytes<'_>| if small { b.below(97) } else { b.u32() };
    let desc = FrameDesc {
        width: dim(&mut b),
        height: dim(&mut b),
        format: FORMATS[b.below(7) as usize],
        row_stride: dim(&mut b),
        uv_row_stride: dim(&mut b),
        uv_pixel_stride: b.below(4),
        rotation_degrees: [0, 90, 180, 270, b.u32()][b.below(5) as usize],
        mirrored: b.u8() & 1 == 1,
    };
    let ts = i64::from(b.u32());
    let bytes = b.rest();
    typed("luma_image", luma_image(bytes, desc));
    typed("upright_size", upright_size(desc));
    typed("frame_byte_count", frame_byte_count(desc));
    if small {
        let [image, video, live] = trackers();
        typed("detect", image.detect(bytes, desc));
        typed("detect_for_video", video.detect_for_video(bytes, desc, ts));
        typed("detect_async", live.detect_async(bytes, desc, ts));
    }
}
