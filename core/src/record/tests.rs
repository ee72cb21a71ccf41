//! The format's own tests: every chunk kind round trips, the size limit holds, and every damaged
//! file is a typed error (the tracker's record and replay: `tests/tests/record_replay.rs`).

use super::*;
use crate::camera::Rotation;
use crate::detect::DetectorConfig;
use crate::error::Error;
use crate::gaze::{GazeCalibration, GazeConfig, Target};
use crate::image::{Frame, FrameDesc, PixelFormat};
use crate::track::{TrackerConfig, TrackingResult};

fn header() -> Header {
    Header {
        library_version: "0.0.0-test".into(),
        arch: "aarch64".into(),
        kernels: "native".into(),
        cpu: "a test CPU".into(),
        tracker: TrackerConfig::default(),
        detector: DetectorConfig::default(),
        mirror_average: false,
        gaze: GazeConfig::default(),
        models: ModelIdentity {
            builtin: true,
            checksum: 7,
        },
    }
}

fn start() -> StreamStart {
    StreamStart {
        next_face_id: 5,
        frame_index: 12,
        whole_frame_turns: 3,
        calibration: GazeCalibration::from_tap_offsets(&[
            [[0.01, -0.02], [0.03, 0.04]],
            [[-0.5, 0.25], [1e-9, -3.0]],
        ])
        .unwrap(),
    }
}

/// An NV21 frame turned and mirrored, rows padded, with bytes past what it describes.
fn nv21() -> (Vec<u8>, FrameDesc) {
    let desc = FrameDesc {
        row_stride: 12,
        chroma_row_stride: 12,
        rotation: Rotation::R90,
        mirrored: true,
        ..FrameDesc::packed(9, 5, PixelFormat::Nv21)
    };
    let need = desc.required_len().unwrap();
    let bytes = (0..need + 17).map(|i| (i * 7 % 251) as u8).collect();
    (bytes, desc)
}

fn gray() -> (Vec<u8>, FrameDesc) {
    (
        (0..24u8).collect(),
        FrameDesc::packed(6, 4, PixelFormat::Gray8),
    )
}

fn screen() -> Target {
    Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap()
}

/// A recording with every chunk kind, and the events it must read back as.
fn every_kind() -> (Vec<u8>, RecordingSummary) {
    let (nv, nv_desc) = nv21();
    let (g, g_desc) = gray();
    let mut r = Recorder::new(Vec::new(), 1 << 20, &header()).unwrap();
    r.begin(&start(), &[screen()]);
    r.frame(&Frame::new(&nv, nv_desc).unwrap(), 1_000);
    r.result(Some(0xdead_beef_0123_4567));
    r.dropped(3, &[1_100, 1_200, 1_300]);
    r.frame(&Frame::new(&g, g_desc).unwrap(), -7);
    r.result(None);
    r.gaze_targets(&[]);
    r.tap(0, [1.5, -2.0], 99);
    r.reset(ResetKind::Tracks);
    r.reset(ResetKind::GazeCalibration);
    r.frame(&Frame::new(&g, g_desc).unwrap(), 2_000);
    let (bytes, summary) = r.finish_into().unwrap();
    (bytes, summary)
}

#[test]
fn every_chunk_kind_round_trips() {
    let (bytes, summary) = every_kind();
    assert_eq!(
        summary,
        RecordingSummary {
            frames: 3,
            dropped_frames: 3,
            bytes: bytes.len() as u64,
            truncated: false,
        }
    );
    let rec = Recording::parse(&bytes).unwrap();
    assert_eq!(rec.header(), &header());
    assert_eq!((rec.frames(), rec.checked_frames()), (3, 2));
    assert_eq!((rec.dropped_frames(), rec.truncated()), (3, false));
    let events: Vec<Event<'_>> = rec.events().map(Result::unwrap).collect();
    let (nv, nv_desc) = nv21();
    let (g, g_desc) = gray();
    let need = nv_desc.required_len().unwrap();
    let frame = |timestamp_ns, desc, bytes| {
        Event::Frame(RecordedFrame {
            timestamp_ns,
            desc,
            bytes,
        })
    };
    assert_eq!(events.len(), 13, "{events:?}");
    assert_eq!(events[0], Event::Start(start()));
    assert_eq!(events[1], Event::GazeTargets(vec![screen()]));
    // Only the bytes the description covers.
    assert_eq!(events[2], frame(1_000, nv_desc, &nv[..need]));
    assert_eq!(events[3], Event::Result(Some(0xdead_beef_0123_4567)));
    let Event::Dropped(d) = &events[4] else {
        panic!("{:?}", events[4]);
    };
    assert_eq!(d.frames, 3);
    assert_eq!(d.timestamps_ns().collect::<Vec<_>>(), [1_100, 1_200, 1_300]);
    assert_eq!(events[5], frame(-7, g_desc, &g[..]));
    assert_eq!(events[6], Event::Result(None));
    assert_eq!(events[7], Event::GazeTargets(vec![]));
    assert_eq!(
        events[8],
        Event::Tap(Tap {
            target: 0,
            point_mm: [1.5, -2.0],
            timestamp_ns: 99,
        })
    );
    assert_eq!(events[9], Event::Reset(ResetKind::Tracks));
    assert_eq!(events[10], Event::Reset(ResetKind::GazeCalibration));
    // The last frame's result was never given: the frame stands alone, then the end.
    assert_eq!(events[11], frame(2_000, g_desc, &g[..]));
    assert_eq!(events[12], Event::End { truncated: false });
    let mut all = rec.events();
    assert_eq!(all.by_ref().count(), 13);
    assert!(all.next().is_none(), "the events end at the end chunk");
    let Event::Frame(f) = &events[2] else {
        unreachable!()
    };
    assert_eq!(f.frame().unwrap().desc(), &nv_desc);
}

/// A recorder that stops before its stream begins still writes a file that reads: a header
/// and its end.
#[test]
fn an_empty_recording_reads() {
    let r = Recorder::new(Vec::new(), 1 << 20, &header()).unwrap();
    let (bytes, summary) = r.finish_into().unwrap();
    assert_eq!(summary.bytes, bytes.len() as u64);
    let rec = Recording::parse(&bytes).unwrap();
    assert_eq!(rec.frames(), 0);
    assert_eq!(
        rec.events().map(Result::unwrap).collect::<Vec<_>>(),
        [Event::End { truncated: false }]
    );
    // Dropping an unfinished recorder ends the file too.
    let mut buf = Vec::new();
    {
        let mut r = Recorder::new(&mut buf, 1 << 20, &header()).unwrap();
        r.begin(&start(), &[]);
    }
    assert_eq!(Recording::parse(&buf).unwrap().events().count(), 2);
}

/// Under every limit from the smallest that holds the header: the file never passes it, it
/// reads, its end says whether frames were left out, and every frame in it has its result.
#[test]
fn the_size_limit_truncates_and_the_file_still_reads() {
    let (g, desc) = gray();
    let frame = Frame::new(&g, desc).unwrap();
    let write = |max: u64| -> Option<(Vec<u8>, RecordingSummary)> {
        let mut r = Recorder::new(Vec::new(), max, &header()).ok()?;
        r.begin(&start(), &[screen()]);
        for ts in 0..6 {
            r.frame(&frame, ts);
            r.result(Some(ts as u64));
            r.tap(0, [0.0, 0.0], ts);
        }
        Some(r.finish_into().unwrap())
    };
    let (full, whole) = write(1 << 20).unwrap();
    assert!(!whole.truncated);
    let smallest = (0..full.len() as u64)
        .find(|&m| write(m).is_some())
        .unwrap();
    assert!(matches!(
        Recorder::new(Vec::new(), smallest - 1, &header()),
        Err(Error::InvalidConfig(_))
    ));
    for max in smallest..=full.len() as u64 + 3 {
        let (bytes, summary) = write(max).unwrap();
        assert!(bytes.len() as u64 <= max, "{} > {max}", bytes.len());
        assert_eq!(summary.bytes, bytes.len() as u64);
        let rec = Recording::parse(&bytes).unwrap();
        assert_eq!(rec.frames(), summary.frames);
        assert_eq!(rec.checked_frames(), rec.frames(), "limit {max}");
        assert_eq!(rec.truncated(), summary.truncated);
        assert_eq!(summary.truncated, max < full.len() as u64, "limit {max}");
        if max >= full.len() as u64 {
            assert_eq!(bytes, full);
        }
    }
}

/// Every prefix of a recording, every value of every chunk's length field, and a file of
/// another version or magic are typed errors (and none panics); a flipped bit anywhere is an
/// error or a file that still reads, never a panic.
#[test]
fn damaged_recordings_are_typed_errors() {
    let (bytes, _) = every_kind();
    for n in 0..bytes.len() {
        match Recording::parse(&bytes[..n]) {
            Err(Error::InvalidRecording(_)) => {}
            other => panic!("a prefix of {n} bytes: {other:?}"),
        }
    }
    // The chunks' offsets, walked by their lengths.
    let mut heads = Vec::new();
    let mut at = MAGIC.len() + 4;
    while at < bytes.len() {
        heads.push(at);
        at += 5 + u32::from_le_bytes(bytes[at + 1..at + 5].try_into().unwrap()) as usize;
    }
    assert_eq!(at, bytes.len());
    assert_eq!(heads.len(), 14);
    for &h in &heads {
        let len = u32::from_le_bytes(bytes[h + 1..h + 5].try_into().unwrap());
        for bad in [
            0,
            1,
            len.wrapping_sub(1),
            len + 1,
            len + 8,
            u32::MAX / 2,
            u32::MAX,
        ] {
            if bad == len {
                continue;
            }
            let mut b = bytes.clone();
            b[h + 1..h + 5].copy_from_slice(&bad.to_le_bytes());
            assert!(
                matches!(Recording::parse(&b), Err(Error::InvalidRecording(_))),
                "length {bad} instead of {len} at {h}"
            );
        }
        for kind in [0, 10, 255] {
            let mut b = bytes.clone();
            b[h] = kind;
            assert!(matches!(
                Recording::parse(&b),
                Err(Error::InvalidRecording(_))
            ));
        }
    }
    let mut newer = bytes.clone();
    newer[8] = 2;
    match Recording::parse(&newer) {
        Err(Error::InvalidRecording(m)) => assert!(m.contains("version 2"), "{m}"),
        other => panic!("{other:?}"),
    }
    let mut other = bytes.clone();
    other[0] = b'X';
    assert!(matches!(
        Recording::parse(&other),
        Err(Error::InvalidRecording(_))
    ));
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(
        Recording::parse(&longer),
        Err(Error::InvalidRecording(_))
    ));
    for i in 0..bytes.len() {
        for bit in [0x01, 0x80] {
            let mut b = bytes.clone();
            b[i] ^= bit;
            if let Err(e) = Recording::parse(&b) {
                assert!(matches!(e, Error::InvalidRecording(_)), "byte {i}: {e}");
            }
        }
    }
}

/// The order rules: a result must follow a frame, nothing but the end before the start, one
/// start and one header.
#[test]
fn chunks_out_of_order_are_refused() {
    let chunk = |kind: u8, payload: &[u8]| {
        let mut c = vec![kind];
        c.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        c.extend_from_slice(payload);
        c
    };
    let head = Recorder::new(Vec::new(), 1 << 20, &header())
        .unwrap()
        .finish_into()
        .unwrap()
        .0;
    let head = &head[..head.len() - 6];
    let start = chunk(2, &[0; 24]);
    let result = chunk(4, &[1, 0, 0, 0, 0, 0, 0, 0, 0]);
    let reset = chunk(8, &[0]);
    let end = chunk(9, &[0]);
    let file = |chunks: &[&[u8]]| {
        let mut v = head.to_vec();
        for c in chunks {
            v.extend_from_slice(c);
        }
        v
    };
    assert!(Recording::parse(&file(&[&start, &reset, &end])).is_ok());
    for bad in [
        file(&[&reset, &end]),
        file(&[&start, &result, &end]),
        file(&[&start, &start, &end]),
        file(&[&start, &chunk(1, b"{}"), &end]),
        file(&[&start, &chunk(4, &[0, 1, 0, 0, 0, 0, 0, 0, 0]), &end]),
        file(&[&start, &chunk(5, &[0; 12]), &end]),
        file(&[&start, &chunk(8, &[2]), &end]),
        file(&[&start, &chunk(9, &[2])]),
        file(&[&start, &reset]),
    ] {
        assert!(
            matches!(Recording::parse(&bad), Err(Error::InvalidRecording(_))),
            "{:?}",
            &bad[head.len()..]
        );
    }
    // A header that is no header, or whose tracker settings are out of range.
    let mut bad_header = b"MTRECORD\x01\0\0\0".to_vec();
    bad_header.extend(chunk(1, br#"{"library_version": 1}"#));
    bad_header.extend(&end);
    assert!(matches!(
        Recording::parse(&bad_header),
        Err(Error::InvalidRecording(_))
    ));
    let mut h = header();
    h.tracker.max_faces = 0;
    let mut out_of_range = b"MTRECORD\x01\0\0\0".to_vec();
    out_of_range.extend(chunk(1, &serde_json::to_vec(&h).unwrap()));
    out_of_range.extend(&end);
    match Recording::parse(&out_of_range) {
        Err(Error::InvalidRecording(m)) => assert!(m.contains("max_faces"), "{m}"),
        other => panic!("{other:?}"),
    }
}

/// A writer that fails: tracking goes on, and the recording says so when it stops.
#[test]
fn a_failed_write_is_reported_when_the_recording_stops() {
    struct Full(usize);
    impl std::io::Write for Full {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.0 < buf.len() {
                return Err(std::io::Error::other("disk full"));
            }
            self.0 -= buf.len();
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    assert!(matches!(
        Recorder::new(Full(10), 1 << 20, &header()),
        Err(Error::Io(_))
    ));
    let mut r = Recorder::new(Full(2_000), 1 << 20, &header()).unwrap();
    r.begin(&start(), &[]);
    let (g, desc) = gray();
    for ts in 0..200 {
        r.frame(&Frame::new(&g, desc).unwrap(), ts);
        r.result(Some(1));
    }
    match r.finish() {
        Err(Error::Io(m)) => assert!(m.contains("disk full"), "{m}"),
        other => panic!("{other:?}"),
    }
}

/// The digest sees every output bit and no timing.
#[test]
fn the_digest_counts_every_output_and_no_timing() {
    let mut r = TrackingResult {
        timestamp_ns: 5,
        frame_index: 2,
        ..TrackingResult::default()
    };
    let base = result_digest(&r);
    r.timings.total_us = 12_345;
    r.timings.fit_us = 3;
    assert_eq!(result_digest(&r), base, "timings are not outputs");
    r.frame_index = 3;
    assert_ne!(result_digest(&r), base);
    r.frame_index = 2;
    r.detector_ran = true;
    assert_ne!(result_digest(&r), base);
    r.detector_ran = false;
    assert_eq!(result_digest(&r), base);
}
