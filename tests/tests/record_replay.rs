//! Record and replay with the shipped models (`monotrack_core::record`): a recording made while
//! tracking a moving face — in the caller's thread and on a live stream's worker, which drops
//! frames — replays through a tracker built from its header with every result bit for bit the
//! recorded one, and a recording of models that are not at hand is refused.

use monotrack_core::Error;
use monotrack_core::bench::{android_portrait_camera, clip};
use monotrack_core::gaze::Target;
use monotrack_core::image::{Frame, FrameDesc, GrayImage, rgb_to_contract_luma};
use monotrack_core::record::{ModelIdentity, Recording, RecordingTracker, Replay, result_digest};
use monotrack_core::track::live::{LiveListener, LiveStream};
use monotrack_core::track::{Tracker, TrackerConfig, TrackingResult};
use std::io::Write;
use std::path::PathBuf;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

const FRAME_NS: i64 = 33_333_333;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The moving-face clip `monotrack bench` runs, laid out as an Android camera's NV21 frames.
struct Clip {
    source: GrayImage,
    desc: FrameDesc,
    upright: GrayImage,
    buf: Vec<u8>,
}

impl Clip {
    fn new() -> Self {
        let rgb = image::open(repo().join("samples/data/astronaut.jpg"))
            .unwrap()
            .to_rgb8();
        let (w, h) = rgb.dimensions();
        let mut source = GrayImage::new(w as usize, h as usize);
        rgb_to_contract_luma(rgb.as_raw(), source.data_mut());
        Self {
            source,
            desc: android_portrait_camera(),
            upright: GrayImage::default(),
            buf: Vec::new(),
        }
    }

    fn frame(&mut self, t: usize) -> Frame<'_> {
        let (w, h) = self.desc.upright_size();
        clip::render(&self.source, t, None, w, h, &mut self.upright);
        clip::encode(&self.upright, &self.desc, &mut self.buf).unwrap();
        Frame::new(&self.buf, self.desc).unwrap()
    }
}

/// A writer into memory the test keeps a handle on.
#[derive(Clone, Default)]
struct Memory(Arc<Mutex<Vec<u8>>>);

impl Write for Memory {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Memory {
    fn bytes(&self) -> Vec<u8> {
        self.0.lock().unwrap().clone()
    }
}

fn screen() -> Target {
    Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap()
}

/// Replays `bytes` and returns each frame's digest, checking each against the recorded one.
fn replayed_digests(bytes: &[u8]) -> Vec<u64> {
    let recording = Recording::parse(bytes).unwrap();
    let mut replay = Replay::new(&recording, None).unwrap();
    let mut out = Vec::new();
    while let Some(f) = replay.next_frame().unwrap() {
        assert_eq!(f.identical(), Some(true), "frame {}", f.index);
        out.push(f.digest().unwrap());
    }
    assert_eq!(out.len() as u64, recording.frames());
    out
}

/// Started mid-stream (after frames, targets and a tap the replay never sees), with a tap and a
/// reset while recording: every frame replays bit for bit, face ids and frame indices included.
#[test]
fn a_recording_replays_bit_for_bit() {
    let mut clip = Clip::new();
    let tracker = Tracker::with_default_models(TrackerConfig::default()).unwrap();
    let mut rec = RecordingTracker::new(tracker, ModelIdentity::builtin());
    rec.set_gaze_targets(vec![screen()]);
    for t in 0..3 {
        let r = rec
            .process_frame(&clip.frame(t), t as i64 * FRAME_NS)
            .unwrap();
        assert_eq!(r.faces.len(), 1, "frame {t}");
    }
    rec.add_calibration_point(0, [20.0, 40.0], 2 * FRAME_NS)
        .unwrap();
    let memory = Memory::default();
    let switch = rec.switch();
    switch.start(Box::new(memory.clone()), 64 << 20).unwrap();
    assert!(matches!(
        switch.start(Box::new(Memory::default()), 64 << 20),
        Err(Error::InvalidState(_))
    ));
    let mut recorded: Vec<(u64, TrackingResult)> = Vec::new();
    for t in 3..11 {
        let ts = t as i64 * FRAME_NS;
        let r = rec.process_frame(&clip.frame(t), ts).unwrap();
        assert_eq!(r.faces.len(), 1, "frame {t}");
        recorded.push((result_digest(r), r.clone()));
        if t == 5 {
            assert_eq!(rec.add_calibration_point(0, [35.0, 50.0], ts).unwrap(), 2);
        }
        if t == 8 {
            rec.reset();
        }
    }
    let summary = switch.stop().unwrap();
    assert!(matches!(switch.stop(), Err(Error::InvalidState(_))));
    let bytes = memory.bytes();
    // tests/aarch64.sh replays this recording, made on the phone's kernels under qemu, with the
    // host's `monotrack replay` on the portable path: every frame must be identical there too.
    if let Some(dir) = std::env::var_os("MONOTRACK_RECORDING_OUT") {
        std::fs::write(PathBuf::from(dir).join("record_replay.mtrec"), &bytes).unwrap();
    }
    assert_eq!(summary.frames, 8);
    assert_eq!(summary.bytes, bytes.len() as u64);
    assert!(!summary.truncated);
    // The recording started a new stream: the face was detected anew, with the next id.
    let first = &recorded[0].1.faces[0];
    assert_eq!(first.state, monotrack_core::track::FaceState::Detected);
    assert_eq!(first.id, 2);
    assert!(recorded[0].1.faces[0].gaze.unwrap().hit.is_some());
    let digests = replayed_digests(&bytes);
    assert_eq!(
        digests,
        recorded.iter().map(|(d, _)| *d).collect::<Vec<_>>()
    );
    // The digest sees a single bit of any output.
    let (d, r) = &recorded[2];
    let mut r = r.clone();
    let p = &mut r.faces[0].landmarks.points[30][0];
    *p = f32::from_bits(p.to_bits() ^ 1);
    assert_ne!(result_digest(&r), *d);
    let mut r = recorded[2].1.clone();
    let z = &mut r.faces[0].fit.pose.translation.z;
    *z = f64::from_bits(z.to_bits() ^ 1);
    assert_ne!(result_digest(&r), *d);
}

struct Deliveries(mpsc::Sender<(i64, u64, u64)>);

impl LiveListener for Deliveries {
    fn on_result(
        &mut self,
        timestamp_ns: i64,
        frames_dropped: u64,
        _: &FrameDesc,
        result: &TrackingResult,
        _: &[Target],
    ) {
        let _ = self
            .0
            .send((timestamp_ns, frames_dropped, result_digest(result)));
    }

    fn on_error(&mut self, timestamp_ns: i64, _: u64, error: Error) {
        panic!("frame at {timestamp_ns} ns: {error}");
    }
}

/// A live stream records the frames its worker took and notes the ones it dropped; the frames
/// replay bit for bit.
#[test]
fn a_live_stream_records_the_frames_it_took_and_its_drops() {
    let mut clip = Clip::new();
    let tracker = Tracker::with_default_models(TrackerConfig::default()).unwrap();
    let rec = RecordingTracker::new(tracker, ModelIdentity::builtin());
    let switch = rec.switch();
    let memory = Memory::default();
    switch.start(Box::new(memory.clone()), 64 << 20).unwrap();
    let (tx, rx) = mpsc::channel();
    let mut live = LiveStream::start(rec, Box::new(Deliveries(tx))).unwrap();
    let submitted = 12;
    for t in 0..submitted {
        live.submit(&clip.frame(t), t as i64 * FRAME_NS).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    let last = (submitted - 1) as i64 * FRAME_NS;
    let mut delivered = Vec::new();
    while delivered.last().is_none_or(|(ts, _, _)| *ts != last) {
        delivered.push(rx.recv_timeout(Duration::from_secs(120)).unwrap());
    }
    let summary = switch.stop().unwrap();
    live.close();
    let dropped: u64 = delivered.iter().map(|(_, d, _)| d).sum();
    assert!(dropped > 0, "frames every 2 ms outrun the tracker");
    assert_eq!(summary.frames, delivered.len() as u64);
    assert_eq!(summary.dropped_frames, dropped);
    assert_eq!(summary.frames + summary.dropped_frames, submitted as u64);
    let bytes = memory.bytes();
    let recording = Recording::parse(&bytes).unwrap();
    assert_eq!(recording.dropped_frames(), dropped);
    assert_eq!(
        replayed_digests(&bytes),
        delivered.iter().map(|(_, _, d)| *d).collect::<Vec<_>>()
    );
}

/// A recording of models that are not at hand is refused rather than replayed on others.
#[test]
fn a_recording_of_other_models_is_refused() {
    for models in [
        ModelIdentity {
            builtin: false,
            checksum: 1,
        },
        ModelIdentity {
            builtin: true,
            checksum: ModelIdentity::builtin().checksum ^ 1,
        },
    ] {
        let rec = RecordingTracker::new(
            Tracker::with_default_models(TrackerConfig::ultra_light()).unwrap(),
            models,
        );
        let memory = Memory::default();
        rec.switch()
            .start(Box::new(memory.clone()), 1 << 20)
            .unwrap();
        rec.switch().stop().unwrap();
        let bytes = memory.bytes();
        let recording = Recording::parse(&bytes).unwrap();
        assert!(matches!(
            Replay::new(&recording, None),
            Err(Error::ModelLoad(_))
        ));
    }
}
