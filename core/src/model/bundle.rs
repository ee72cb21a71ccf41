//! Model bundles: every network and the face model the tracker runs on, in one versioned,
//! checksummed file, so that a product can ship weights it trained itself (`models/train`,
//! `make_bundle.py`) without forking the build. The library's own models form
//! [`ModelBundle::builtin`].
//!
//! Format (version [`ModelBundle::FORMAT_VERSION`], little-endian): the magic `MTBUNDLE`, the
//! format version (u32), the entry count (u32); per entry its name's length (u16), the name
//! (UTF-8) and its size (u64); then the entries' bytes in that order; last the CRC-32 (IEEE) of
//! everything before it (u32).

use crate::error::{Error, Result};

/// The files a bundle must hold besides those `m3.json` names.
pub const REQUIRED: [&str; 4] = [
    "m3.json",
    "detector.json",
    "detector.onnx",
    "face_model.json",
];

const MAGIC: &[u8; 8] = b"MTBUNDLE";

/// The largest bundle read: far above any model set, small enough that a corrupt size cannot make
/// a phone allocate without bound.
const MAX_BYTES: u64 = 256 << 20;

/// Named model files, checked: a bundle read from bytes had the right magic, version and checksum
/// and holds every [`REQUIRED`] file (whether the networks load is the tracker's to say).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelBundle {
    files: Vec<(String, Vec<u8>)>,
}

/// Reads little-endian fields off the front of a byte slice.
struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: u64) -> Result<&'a [u8]> {
        let n = usize::try_from(n).ok().filter(|&n| n <= self.0.len());
        let n = n.ok_or_else(|| Error::ModelLoad("model bundle is truncated".into()))?;
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Ok(head)
    }

    fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(
            self.take(2)?.try_into().unwrap_or_default(),
        ))
    }

    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or_default(),
        ))
    }

    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or_default(),
        ))
    }
}

impl ModelBundle {
    /// The bundle format this library reads and writes.
    pub const FORMAT_VERSION: u32 = 1;

    /// The models built into the library.
    pub fn builtin() -> Self {
        let files = builtin_files()
            .map(|(n, b)| (n.to_string(), b.to_vec()))
            .collect();
        Self { files }
    }

    /// The CRC-32 a bundle file of these files ends with ([`Self::to_bytes`]): the bundle's
    /// identity, which a recording's header names (`crate::record`) so that a replay can tell
    /// the models it ran on.
    pub fn checksum(&self) -> u32 {
        checksum_of(self.files.iter().map(|(n, b)| (n.as_str(), b.as_slice())))
    }

    /// [`Self::checksum`] of [`Self::builtin`], without copying the models.
    pub fn builtin_checksum() -> u32 {
        checksum_of(builtin_files())
    }

    /// A bundle of `files` (name, bytes).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] when a [`REQUIRED`] file is missing or a name repeats.
    pub fn from_files(files: Vec<(String, Vec<u8>)>) -> Result<Self> {
        for (i, (name, _)) in files.iter().enumerate() {
            if files[..i].iter().any(|(n, _)| n == name) {
                return Err(Error::ModelLoad(format!(
                    "model bundle names {name:?} twice"
                )));
            }
        }
        if let Some(missing) = REQUIRED
            .iter()
            .find(|r| !files.iter().any(|(n, _)| n == *r))
        {
            return Err(Error::ModelLoad(format!("model bundle has no {missing:?}")));
        }
        Ok(Self { files })
    }

    /// Reads a bundle file.
    ///
    /// # Errors
    /// [`Error::BundleVersion`] for another format version, [`Error::BundleChecksum`] for bytes
    /// that are not what was written, [`Error::ModelLoad`] for bytes that are no bundle at all
    /// (no magic, truncated, a missing required file).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        if bytes.len() < MAGIC.len() + 8 || &bytes[..MAGIC.len()] != MAGIC {
            return Err(Error::ModelLoad(
                "not a model bundle (no MTBUNDLE magic)".into(),
            ));
        }
        let mut r = Reader(&bytes[MAGIC.len()..]);
        let version = r.u32()?;
        if version != Self::FORMAT_VERSION {
            return Err(Error::BundleVersion(format!(
                "model bundle format {version}; this library reads format {}",
                Self::FORMAT_VERSION
            )));
        }
        let (body, tail) = bytes.split_at(bytes.len().saturating_sub(4));
        let stored = u32::from_le_bytes(tail.try_into().unwrap_or_default());
        let computed = crc32fast::hash(body);
        if stored != computed {
            return Err(Error::BundleChecksum(format!(
                "model bundle checksum {computed:08x} does not match the stored {stored:08x}: \
                 the file is damaged"
            )));
        }
        let mut r = Reader(&body[MAGIC.len() + 4..]);
        let count = r.u32()?;
        let mut heads = Vec::new();
        let mut total = 0u64;
        for _ in 0..count {
            let n = r.u16()?;
            let name = std::str::from_utf8(r.take(u64::from(n))?)
                .map_err(|_| Error::ModelLoad("model bundle entry name is not UTF-8".into()))?
                .to_string();
            let size = r.u64()?;
            total = total.saturating_add(size);
            if total > MAX_BYTES {
                return Err(Error::ModelLoad("model bundle is implausibly large".into()));
            }
            heads.push((name, size));
        }
        let mut files = Vec::with_capacity(heads.len());
        for (name, size) in heads {
            files.push((name, r.take(size)?.to_vec()));
        }
        if !r.0.is_empty() {
            return Err(Error::ModelLoad(
                "model bundle has bytes after its entries".into(),
            ));
        }
        Self::from_files(files)
    }

    /// The bundle as a file ([`Self::from_bytes`] reads it back).
    pub fn to_bytes(&self) -> Vec<u8> {
        // The layout is also walked by `checksum_of`: a change here changes both.
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&Self::FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(self.files.len() as u32).to_le_bytes());
        for (name, bytes) in &self.files {
            out.extend_from_slice(&(name.len() as u16).to_le_bytes());
            out.extend_from_slice(name.as_bytes());
            out.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        }
        for (_, bytes) in &self.files {
            out.extend_from_slice(bytes);
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// The file called `name`.
    pub fn file(&self, name: &str) -> Option<&[u8]> {
        self.files
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, b)| b.as_slice())
    }

    /// Every file, as (name, bytes) pairs.
    pub fn files(&self) -> impl Iterator<Item = (&str, &[u8])> {
        self.files.iter().map(|(n, b)| (n.as_str(), b.as_slice()))
    }

    /// A required file ([`REQUIRED`], present by construction).
    pub(crate) fn required(&self, name: &str) -> Result<&[u8]> {
        self.file(name)
            .ok_or_else(|| Error::ModelLoad(format!("model bundle has no {name:?}")))
    }
}

/// The files of [`ModelBundle::builtin`], borrowed from the library's embedded bytes.
fn builtin_files() -> impl Iterator<Item = (&'static str, &'static [u8])> + Clone {
    crate::landmarks::EMBEDDED_FILES.iter().copied().chain([
        ("detector.json", crate::detect::MODEL_JSON.as_bytes()),
        ("detector.onnx", crate::detect::MODEL_ONNX),
        ("face_model.json", super::BUILTIN_JSON),
    ])
}

/// The CRC-32 of the bundle file of `files` ([`ModelBundle::to_bytes`]'s layout), streamed.
fn checksum_of<'a>(files: impl Iterator<Item = (&'a str, &'a [u8])> + Clone) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(MAGIC);
    h.update(&ModelBundle::FORMAT_VERSION.to_le_bytes());
    h.update(&(files.clone().count() as u32).to_le_bytes());
    for (name, bytes) in files.clone() {
        h.update(&(name.len() as u16).to_le_bytes());
        h.update(name.as_bytes());
        h.update(&(bytes.len() as u64).to_le_bytes());
    }
    for (_, bytes) in files {
        h.update(bytes);
    }
    h.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_bundle_round_trips() {
        let b = ModelBundle::builtin();
        let bytes = b.to_bytes();
        assert_eq!(ModelBundle::from_bytes(&bytes).unwrap(), b);
        assert!(REQUIRED.iter().all(|r| b.file(r).is_some()));
        // The checksum is the one the file ends with, streamed or not.
        let tail = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap());
        assert_eq!(b.checksum(), tail);
        assert_eq!(ModelBundle::builtin_checksum(), tail);
        let mut other = b
            .files()
            .map(|(n, x)| (n.to_string(), x.to_vec()))
            .collect::<Vec<_>>();
        other[0].1.push(b' ');
        assert_ne!(ModelBundle::from_files(other).unwrap().checksum(), tail);
    }

    #[test]
    fn damaged_bundles_are_typed_errors() {
        let bytes = ModelBundle::builtin().to_bytes();
        // A flipped bit anywhere after the version: the checksum.
        for at in [20, bytes.len() / 2, bytes.len() - 1] {
            let mut bad = bytes.clone();
            bad[at] ^= 0x10;
            assert!(
                matches!(ModelBundle::from_bytes(&bad), Err(Error::BundleChecksum(_))),
                "flip at {at}"
            );
        }
        let mut newer = bytes.clone();
        newer[8] = 2;
        assert!(matches!(
            ModelBundle::from_bytes(&newer),
            Err(Error::BundleVersion(_))
        ));
        for bad in [&b"hello"[..], &bytes[..30], &[]] {
            assert!(matches!(
                ModelBundle::from_bytes(bad),
                Err(Error::ModelLoad(_) | Error::BundleChecksum(_))
            ));
        }
        let no_face_model = ModelBundle::builtin()
            .files()
            .filter(|(n, _)| *n != "face_model.json")
            .map(|(n, b)| (n.to_string(), b.to_vec()))
            .collect();
        assert!(matches!(
            ModelBundle::from_files(no_face_model),
            Err(Error::ModelLoad(_))
        ));
    }
}
