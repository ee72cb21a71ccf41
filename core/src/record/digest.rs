//! The result digest (FORMAT.md, "The result digest").

use crate::track::TrackingResult;
use std::fmt::Write;

/// 64-bit FNV-1a, fed as text.
struct Fnv1a(u64);

impl Write for Fnv1a {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        for b in s.bytes() {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        Ok(())
    }
}

/// The digest of every output of `result` but its timings: FNV-1a over the `Debug` text of its
/// fields. Through `Debug` every field of every face counts, those added later included, without
/// a list here to keep up; the text is streamed into the hash, so nothing is allocated.
pub fn result_digest(result: &TrackingResult) -> u64 {
    // Named one by one, so that a field added to the result is a compile error here until it
    // is counted in or left out on purpose.
    let TrackingResult {
        timestamp_ns,
        frame_index,
        faces,
        detector_ran,
        reasons,
        timings: _,
    } = result;
    let mut h = Fnv1a(0xcbf2_9ce4_8422_2325);
    // Writing into the hasher cannot fail.
    let _ = write!(
        h,
        "{timestamp_ns:?}|{frame_index:?}|{faces:?}|{detector_ran:?}|{reasons:?}"
    );
    h.0
}
