//! Recordings as `monotrack replay` reads them (`Recording::parse`, then every event, each frame
//! converted as a tracker would read it): bad input must be `Error::InvalidRecording` and a file
//! that parses must give every event and frame it promised (seeded with recordings the writer
//! makes, `crate::seeds`, and the committed corpus, written from `core/src/record/FORMAT.md`
//! alone by `fuzz/make_recording_corpus.py`).
use monotrack_core::Error;
use monotrack_core::image::GrayImage;
use monotrack_core::record::{Event, Recording};

/// One input of the `recording` target.
pub fn run(data: &[u8]) {
    match Recording::parse(data) {
        Ok(rec) => {
            let mut luma = GrayImage::default();
            let mut frames = 0;
            for e in rec.events() {
                match e {
                    Ok(Event::Frame(f)) => {
                        let frame = f
                            .frame()
                            .unwrap_or_else(|e| panic!("a parsed frame does not read: {e}"));
                        frame.to_luma(&mut luma);
                        frames += 1;
                    }
                    Ok(Event::Dropped(d)) => assert!(d.timestamps_ns().count() as u64 <= d.frames),
                    Ok(_) => {}
                    Err(e) => panic!("an event of a parsed recording fails: {e}"),
                }
            }
            assert_eq!(frames, rec.frames(), "the frames counted and given differ");
        }
        Err(Error::InvalidRecording(_)) => {}
        Err(e) => panic!("Recording::parse: {e} (not InvalidRecording)"),
    }
}
