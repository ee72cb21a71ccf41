//! `monotrack track VIDEO_OR_FRAME_DIR [--out OUT.jsonl] [--overlay DIR]` (CONTRACT.md): the parts
//! that do not depend on which detector and landmark estimator the tracker holds — frame input (a
//! directory of PNG/JPEG frames in file-name order, or a video piped through `ffmpeg`), a progress
//! bar on stderr, the CONTRACT JSON line of a [`TrackingResult`], overlay drawing (landmarks,
//! projected model mesh, head axes) and the loop [`run`], through the recorder (`--record`).

use crate::LineSink;
use crate::json::{put_eyes, put_fit, put_point_of_gaze, put_quality, reasons_json};
use monotrack_core::camera::Intrinsics;
use monotrack_core::gaze::Target;
use monotrack_core::image::GrayImage;
use monotrack_core::landmarks::{BROW_GESTURES, MOUTH_GESTURES};
use monotrack_core::model::{FaceModel, N_LANDMARKS};
use monotrack_core::overlay;
use monotrack_core::record::RecordingTracker;
use monotrack_core::track::{FaceState, FrameState, TrackedFace, TrackingResult};
use serde_json::{Map, Value, json};
use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::time::Instant;

/// Frame rate assumed for a frame directory (no timing information there): 30 fps, the usual
/// phone camera rate.
pub const DIR_FPS: f64 = 30.0;

/// What `ffmpeg` missing means for the user.
const NO_FFMPEG: &str = "reading video files needs ffmpeg and ffprobe (Debian/Ubuntu: \
     apt-get install ffmpeg); a directory of PNG/JPEG frames always works";

/// The frame files of `dir` (PNG/JPEG by extension, any case), in file-name order.
///
/// # Errors
/// A message when the directory cannot be read or holds no frame.
pub fn list_frames(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let rd = std::fs::read_dir(dir).map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for entry in rd {
        let p = entry.map_err(|e| e.to_string())?.path();
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if p.is_file() && matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg")) {
            files.push(p);
        }
    }
    files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    if files.is_empty() {
        return Err(format!("{} holds no PNG or JPEG frame", dir.display()));
    }
    Ok(files)
}

/// Where frames come from.
pub enum FrameSource {
    /// Image files, read in order.
    Dir {
        /// The files.
        files: Vec<PathBuf>,
        /// Next index.
        next: usize,
    },
    /// Raw gray frames from `ffmpeg -f rawvideo -pix_fmt gray`.
    Video {
        /// The ffmpeg process.
        child: Child,
        /// Its stdout.
        stdout: ChildStdout,
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
        /// Frames per second (from ffprobe).
        fps: f64,
        /// Frame count if the container says.
        frames: Option<usize>,
        /// Next index.
        next: usize,
        /// A second ffmpeg giving the same frames as RGB, when colour was asked for (overlays):
        /// the luma the tracker reads stays the video's own in either case.
        colour: Option<(Child, ChildStdout)>,
    },
}

/// Spawns `ffmpeg` decoding `path` to raw frames of `pix_fmt` on its stdout.
fn ffmpeg_raw(path: &Path, pix_fmt: &str) -> Result<(Child, ChildStdout), String> {
    // -noautorotate: frames keep the stream's stored size, the one ffprobe reported.
    let mut child = Command::new("ffmpeg")
        .args(["-v", "error", "-noautorotate", "-i"])
        .arg(path)
        .args(["-f", "rawvideo", "-pix_fmt", pix_fmt, "-"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                NO_FFMPEG.to_string()
            } else {
                format!("ffmpeg: {e}")
            }
        })?;
    let stdout = child
        .stdout
        .take()
        .ok_or_else(|| "ffmpeg: no stdout".to_string())?;
    Ok((child, stdout))
}

/// Fills `buf` from `r`; `Ok(false)` at a clean end (nothing read).
fn read_frame(r: &mut ChildStdout, buf: &mut [u8], index: usize) -> Result<bool, String> {
    let mut filled = 0;
    while filled < buf.len() {
        match r.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(format!("reading ffmpeg output: {e}")),
        }
    }
    if filled == 0 {
        return Ok(false);
    }
    if filled < buf.len() {
        return Err(format!(
            "ffmpeg output ended inside frame {index} ({filled} of {} bytes)",
            buf.len()
        ));
    }
    Ok(true)
}

/// Runs ffprobe for width, height, frame rate and (if known) frame count of the first video stream.
fn probe(path: &Path) -> Result<(usize, usize, f64, Option<usize>), String> {
    let out = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=width,height,avg_frame_rate,nb_frames,duration",
            "-of",
            "default=noprint_wrappers=1",
        ])
        .arg(path)
        .output()
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                NO_FFMPEG.to_string()
            } else {
                format!("ffprobe: {e}")
            }
        })?;
    if !out.status.success() {
        return Err(format!(
            "ffprobe cannot read {}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    parse_probe(&String::from_utf8_lossy(&out.stdout))
        .ok_or_else(|| format!("{}: no video stream", path.display()))
}

/// Parses ffprobe's `key=value` lines. The frame count is the container's `nb_frames` unless the
/// stream's duration at its frame rate says otherwise by more than a frame: an edit list that trims
/// a clip (the shared news video: 158 packets, 55 frames shown, all ffmpeg decodes) leaves
/// `nb_frames` counting the trimmed packets too.
fn parse_probe(text: &str) -> Option<(usize, usize, f64, Option<usize>)> {
    let (mut w, mut h, mut fps, mut n, mut duration) = (None, None, None, None, None);
    for line in text.lines() {
        let Some((k, v)) = line.trim().split_once('=') else {
            continue;
        };
        match k {
            "width" => w = v.parse().ok(),
            "height" => h = v.parse().ok(),
            "avg_frame_rate" => {
                fps = match v.split_once('/') {
                    Some((a, b)) => match (a.parse::<f64>(), b.parse::<f64>()) {
                        (Ok(a), Ok(b)) if b > 0.0 && a > 0.0 => Some(a / b),
                        _ => None,
                    },
                    None => v.parse().ok().filter(|f: &f64| *f > 0.0),
                }
            }
            "nb_frames" => n = v.parse::<usize>().ok(),
            "duration" => duration = v.parse::<f64>().ok().filter(|d| d.is_finite() && *d > 0.0),
            _ => {}
        }
    }
    let shown = fps.zip(duration).map(|(f, d)| (f * d).round() as usize);
    let n = match (n, shown) {
        (Some(n), Some(s)) if n.abs_diff(s) > 1 => Some(s),
        (n, s) => n.or(s),
    };
    Some((w?, h?, fps.unwrap_or(DIR_FPS), n))
}

impl FrameSource {
    /// Opens a frame directory or (through ffmpeg) a video file.
    ///
    /// # Errors
    /// A message for an unreadable path, an empty directory, or a video without ffmpeg installed.
    pub fn open(path: &Path) -> Result<Self, String> {
        Self::open_with(path, false)
    }

    /// [`Self::open`]; with `colour`, [`Self::next_frame`] can also give each frame as RGB.
    ///
    /// # Errors
    /// As [`Self::open`].
    pub fn open_with(path: &Path, colour: bool) -> Result<Self, String> {
        if path.is_dir() {
            return Ok(Self::Dir {
                files: list_frames(path)?,
                next: 0,
            });
        }
        if !path.is_file() {
            return Err(format!(
                "{} is neither a file nor a directory",
                path.display()
            ));
        }
        let (width, height, fps, frames) = probe(path)?;
        let (child, stdout) = ffmpeg_raw(path, "gray")?;
        let colour = if colour {
            Some(ffmpeg_raw(path, "rgb24")?)
        } else {
            None
        };
        Ok(Self::Video {
            child,
            stdout,
            width,
            height,
            fps,
            frames,
            next: 0,
            colour,
        })
    }

    /// Number of frames, when known in advance.
    pub fn len_hint(&self) -> Option<usize> {
        match self {
            Self::Dir { files, .. } => Some(files.len()),
            Self::Video { frames, .. } => *frames,
        }
    }

    /// Reads the next frame into `out`; returns its index and timestamp (ns), `None` at the end.
    ///
    /// # Errors
    /// A message when a frame cannot be read or decoded.
    pub fn next_frame(&mut self, out: &mut GrayImage) -> Result<Option<(usize, i64)>, String> {
        self.next_frame_with(out, None)
    }

    /// [`Self::next_frame`], also filling `rgb` (resized; 3 bytes a pixel, rows packed) with the
    /// frame in colour when given: image files as decoded, videos when opened with colour.
    ///
    /// # Errors
    /// As [`Self::next_frame`]; a video opened without colour when `rgb` is asked for.
    pub fn next_frame_with(
        &mut self,
        out: &mut GrayImage,
        rgb: Option<&mut Vec<u8>>,
    ) -> Result<Option<(usize, i64)>, String> {
        match self {
            Self::Dir { files, next } => {
                let Some(path) = files.get(*next) else {
                    return Ok(None);
                };
                let img = image::open(path)
                    .map_err(|e| format!("cannot read image {}: {e}", path.display()))?;
                crate::luma::to_luma(&img, out);
                if let Some(rgb) = rgb {
                    rgb.clear();
                    rgb.extend_from_slice(img.to_rgb8().as_raw());
                }
                let i = *next;
                *next += 1;
                Ok(Some((i, (i as f64 * 1e9 / DIR_FPS).round() as i64)))
            }
            Self::Video {
                stdout,
                width,
                height,
                fps,
                next,
                colour,
                ..
            } => {
                out.resize(*width, *height);
                if !read_frame(stdout, out.data_mut(), *next)? {
                    return Ok(None);
                }
                if let Some(rgb) = rgb {
                    let (_, colour_out) = colour
                        .as_mut()
                        .ok_or_else(|| "the video was opened without colour".to_string())?;
                    rgb.resize(*width * *height * 3, 0);
                    if !read_frame(colour_out, rgb, *next)? {
                        return Err(format!("ffmpeg's colour output ended at frame {next}"));
                    }
                }
                let i = *next;
                *next += 1;
                Ok(Some((i, (i as f64 * 1e9 / *fps).round() as i64)))
            }
        }
    }
}

impl Drop for FrameSource {
    fn drop(&mut self) {
        if let Self::Video { child, colour, .. } = self {
            // Stop ffmpeg if we quit early; it exits on its own at the end of the video.
            let _ = child.kill();
            let _ = child.wait();
            if let Some((c, _)) = colour {
                let _ = c.kill();
                let _ = c.wait();
            }
        }
    }
}

/// A one-line progress bar on stderr (redrawn at most 10 times a second on a terminal; a line
/// every 10 % otherwise, so logs stay short).
pub struct Progress {
    total: Option<usize>,
    start: Instant,
    last: Option<Instant>,
    tty: bool,
    last_decile: usize,
}

impl Progress {
    /// A bar for `total` frames (unknown: a counter).
    pub fn new(total: Option<usize>) -> Self {
        Self {
            total,
            start: Instant::now(),
            last: None,
            tty: std::io::stderr().is_terminal(),
            last_decile: 0,
        }
    }

    /// The bar's text after `done` frames, `elapsed_s` seconds in.
    pub fn line(total: Option<usize>, done: usize, elapsed_s: f64) -> String {
        let fps = if elapsed_s > 0.0 {
            done as f64 / elapsed_s
        } else {
            0.0
        };
        match total {
            Some(t) if t > 0 => {
                const WIDTH: usize = 30;
                let filled = (done.min(t) * WIDTH) / t;
                format!(
                    "[{}{}] {done}/{t} frames  {fps:.1} fps",
                    "#".repeat(filled),
                    "-".repeat(WIDTH - filled)
                )
            }
            _ => format!("{done} frames  {fps:.1} fps"),
        }
    }

    /// Reports `done` frames.
    pub fn update(&mut self, done: usize) {
        let elapsed = self.start.elapsed().as_secs_f64();
        if self.tty {
            if self.last.is_some_and(|l| l.elapsed().as_millis() < 100) {
                return;
            }
            self.last = Some(Instant::now());
            eprint!("\r{}", Self::line(self.total, done, elapsed));
            let _ = std::io::stderr().flush();
        } else if let Some(t) = self.total.filter(|&t| t > 0) {
            let decile = done * 10 / t;
            if decile > self.last_decile {
                self.last_decile = decile;
                eprintln!("{}", Self::line(self.total, done, elapsed));
            }
        }
    }

    /// Ends the bar with a final line.
    pub fn finish(&mut self, done: usize) {
        let line = Self::line(self.total, done, self.start.elapsed().as_secs_f64());
        if self.tty {
            eprintln!("\r{line}");
        } else {
            eprintln!("{line}");
        }
    }
}

fn round(v: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (v * p).round() / p
}

/// One CONTRACT FACE object (plus `id` and `state`) for a tracked face.
pub fn face_json(face: &TrackedFace, targets: Option<&[Target]>) -> Value {
    let lm = &face.landmarks;
    let r = face.rect;
    let mut m = Map::new();
    m.insert("id".into(), json!(face.id));
    m.insert(
        "state".into(),
        json!(match face.state {
            FaceState::Detected => "detected",
            FaceState::Tracked => "tracked",
        }),
    );
    m.insert(
        "box".into(),
        json!([
            round(f64::from(r.x), 2),
            round(f64::from(r.y), 2),
            round(f64::from(r.w), 2),
            round(f64::from(r.h), 2)
        ]),
    );
    m.insert("score".into(), json!(round(f64::from(face.score), 4)));
    // A point the estimator does not measure has weight 0 (the ultra-light mode's gradient
    // detector has 27 of the 68): `null`, as are the fields only M3 gives.
    let gradient = lm.weights.contains(&0.0);
    m.insert(
        "landmarks68".into(),
        Value::Array(
            lm.points
                .iter()
                .zip(&lm.weights)
                .map(|(p, w)| {
                    if *w == 0.0 {
                        Value::Null
                    } else {
                        json!([round(f64::from(p[0]), 2), round(f64::from(p[1]), 2)])
                    }
                })
                .collect(),
        ),
    );
    put_eyes(&mut m, &lm.points, &lm.weights);
    if gradient {
        for k in ["yaw_class_deg", "yaw_probs", "gestures", "gaze"] {
            m.insert(k.into(), Value::Null);
        }
        put_fit(&mut m, &face.fit);
        put_quality(&mut m, &face.quality);
        m.insert("shape_held".into(), json!(face.shape_held));
        m.insert("flow_points".into(), json!(face.flow_points));
        return Value::Object(m);
    }
    m.insert("yaw_class_deg".into(), json!(lm.yaw_class_deg()));
    let probs = |v: &[f32]| -> Vec<f64> { v.iter().map(|p| round(f64::from(*p), 4)).collect() };
    m.insert("yaw_probs".into(), json!(probs(&lm.yaw_probs)));
    let named = |names: &[&str], v: &[f32]| -> Value {
        Value::Object(
            names
                .iter()
                .zip(v)
                .map(|(n, p)| (n.to_string(), json!(round(f64::from(*p), 4))))
                .collect(),
        )
    };
    m.insert(
        "gestures".into(),
        json!({"mouth": named(&MOUTH_GESTURES, &lm.mouth), "brows": named(&BROW_GESTURES, &lm.brows)}),
    );
    m.insert(
        "gaze".into(),
        json!({
            "left": probs(&lm.gaze_left),
            "right": probs(&lm.gaze_right),
            "combined": probs(&lm.gaze_combined),
        }),
    );
    put_fit(&mut m, &face.fit);
    put_quality(&mut m, &face.quality);
    if let (Some(t), Some(g)) = (targets, &face.gaze) {
        put_point_of_gaze(&mut m, g, t);
    }
    m.insert("shape_held".into(), json!(face.shape_held));
    m.insert("flow_points".into(), json!(face.flow_points));
    Value::Object(m)
}

/// The CONTRACT `track` output line of one frame.
/// `targets`: those of `--targets`, whose point of gaze each face then carries.
pub fn frame_json(result: &TrackingResult, targets: Option<&[Target]>) -> Value {
    let t = &result.timings;
    json!({
        "frame": result.frame_index,
        "timestamp_ms": round(result.timestamp_ns as f64 / 1e6, 3),
        "state": match result.state() {
            FrameState::Detected => "detected",
            FrameState::Tracked => "tracked",
            FrameState::Lost => "lost",
        },
        "faces": result.faces.iter().map(|f| face_json(f, targets)).collect::<Vec<_>>(),
        "reasons": reasons_json(result.reasons),
        "timings_us": {
            "image": t.image_us, "region": t.region_us, "detect": t.detect_us,
            "landmarks": t.landmarks_us, "flow": t.flow_us, "fit": t.fit_us, "total": t.total_us,
        },
    })
}

/// A 3×5 pixel glyph of `c` (letters upper-cased), rows top to bottom, 3 bits each with the left
/// pixel highest; blank for characters it does not have. Enough for plot titles and legends.
fn glyph(c: char) -> u16 {
    match c.to_ascii_uppercase() {
        'A' => 0b010101111101101,
        'B' => 0b110101110101110,
        'C' => 0b011100100100011,
        'D' => 0b110101101101110,
        'E' => 0b111100110100111,
        'F' => 0b111100110100100,
        'G' => 0b011100101101011,
        'H' => 0b101101111101101,
        'I' => 0b111010010010111,
        'J' => 0b001001001101010,
        'K' => 0b101101110101101,
        'L' => 0b100100100100111,
        'M' => 0b101111111101101,
        'N' => 0b110101101101101,
        'O' => 0b010101101101010,
        'P' => 0b110101110100100,
        'Q' => 0b010101101110011,
        'R' => 0b110101110101101,
        'S' => 0b011100010001110,
        'T' => 0b111010010010010,
        'U' => 0b101101101101111,
        'V' => 0b101101101101010,
        'W' => 0b101101111111101,
        'X' => 0b101101010101101,
        'Y' => 0b101101010010010,
        'Z' => 0b111001010100111,
        '0' => 0b111101101101111,
        '1' => 0b010110010010111,
        '2' => 0b110001010100111,
        '3' => 0b110001010001110,
        '4' => 0b101101111001001,
        '5' => 0b111100110001110,
        '6' => 0b011100111101111,
        '7' => 0b111001010010010,
        '8' => 0b111101111101111,
        '9' => 0b111101111001110,
        '.' => 0b000000000000010,
        '-' => 0b000000111000000,
        ':' => 0b000010000010000,
        '%' => 0b101001010100101,
        '(' => 0b001010010010001,
        ')' => 0b100010010010100,
        '/' => 0b001001010100100,
        '_' => 0b000000000000111,
        ',' => 0b000000000010100,
        _ => 0,
    }
}

/// An RGB drawing surface for overlays.
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

/// Overlay colours.
const LANDMARK_RGB: [u8; 3] = [0, 255, 0];
const MESH_RGB: [u8; 3] = [0, 170, 255];
const BOX_RGB: [u8; 3] = [255, 255, 0];
const AXIS_RGB: [[u8; 3]; 3] = [[255, 0, 0], [0, 255, 0], [0, 0, 255]];
/// Drawn head-axis length, millimetres (about half a face).
const AXIS_MM: f64 = 60.0;

impl Canvas {
    /// A gray image as RGB.
    pub fn from_gray(img: &GrayImage) -> Self {
        let mut c = Self {
            width: 0,
            height: 0,
            rgb: Vec::new(),
        };
        c.set_gray(img);
        c
    }

    /// Replaces the contents with a `width`×`height` RGB image (3 bytes a pixel, rows packed;
    /// allocation reused).
    pub fn set_rgb(&mut self, width: usize, height: usize, rgb: &[u8]) {
        self.width = width;
        self.height = height;
        self.rgb.clear();
        self.rgb.extend_from_slice(&rgb[..width * height * 3]);
    }

    /// Replaces the contents with a gray image (allocation reused).
    pub fn set_gray(&mut self, img: &GrayImage) {
        self.width = img.width();
        self.height = img.height();
        self.rgb.clear();
        self.rgb.extend(img.data().iter().flat_map(|&v| [v, v, v]));
    }

    /// The pixel at (x, y), if inside.
    pub fn get(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height).then(|| {
            let k = 3 * (y * self.width + x);
            [self.rgb[k], self.rgb[k + 1], self.rgb[k + 2]]
        })
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let k = 3 * (y as usize * self.width + x as usize);
            self.rgb[k..k + 3].copy_from_slice(&c);
        }
    }

    /// Writes `text` with its top-left corner at (x, y), each glyph pixel a `scale`×`scale`
    /// block (a 3×5 font: letters, digits, `.-:%()/_,`).
    pub fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, c: [u8; 3]) {
        for (k, ch) in text.chars().enumerate() {
            let g = glyph(ch);
            let x0 = x + k as i64 * 4 * scale;
            for row in 0..5 {
                for col in 0..3 {
                    if g >> (14 - (row * 3 + col)) & 1 == 1 {
                        for dy in 0..scale {
                            for dx in 0..scale {
                                self.put(x0 + col * scale + dx, y + row * scale + dy, c);
                            }
                        }
                    }
                }
            }
        }
    }

    /// A line between two points in CONTRACT pixel coordinates (Bresenham; clipped to the image;
    /// non-finite or absurdly far endpoints draw nothing).
    pub fn line(&mut self, a: [f64; 2], b: [f64; 2], c: [u8; 3]) {
        let lim = 4.0 * (self.width + self.height) as f64 + 1e4;
        if !a.iter().chain(&b).all(|v| v.is_finite() && v.abs() < lim) {
            return;
        }
        // Pixel (i, j) holds the point (i + 0.5, j + 0.5): floor gives the pixel.
        let (mut x0, mut y0) = (a[0].floor() as i64, a[1].floor() as i64);
        let (x1, y1) = (b[0].floor() as i64, b[1].floor() as i64);
        let dx = (x1 - x0).abs();
        let dy = -(y1 - y0).abs();
        let sx = if x0 < x1 { 1 } else { -1 };
        let sy = if y0 < y1 { 1 } else { -1 };
        let mut err = dx + dy;
        loop {
            self.put(x0, y0, c);
            if x0 == x1 && y0 == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x0 += sx;
            }
            if e2 <= dx {
                err += dx;
                y0 += sy;
            }
        }
    }

    /// A filled disc of radius `r` pixels around a point.
    pub fn disc(&mut self, p: [f64; 2], r: f64, c: [u8; 3]) {
        if !(p[0].is_finite() && p[1].is_finite() && r.is_finite()) {
            return;
        }
        let (x0, x1) = ((p[0] - r).floor() as i64, (p[0] + r).ceil() as i64);
        let (y0, y1) = ((p[1] - r).floor() as i64, (p[1] + r).ceil() as i64);
        for y in y0.max(0)..=y1.min(self.height as i64) {
            for x in x0.max(0)..=x1.min(self.width as i64) {
                let (cx, cy) = (x as f64 + 0.5 - p[0], y as f64 + 0.5 - p[1]);
                if cx * cx + cy * cy <= r * r {
                    self.put(x, y, c);
                }
            }
        }
    }

    /// Writes a PNG.
    ///
    /// # Errors
    /// A message when the file cannot be written.
    pub fn save_png(&self, path: &Path) -> Result<(), String> {
        image::save_buffer(
            path,
            &self.rgb,
            self.width as u32,
            self.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// Draws every face of `result`: its box, the fitted model's mesh projected through `camera`, the
/// head axes (x red, y green, z blue, from the head frame's origin) and the 68 landmarks.
pub fn draw_overlay(canvas: &mut Canvas, result: &TrackingResult, camera: &Intrinsics) {
    let model = FaceModel::builtin();
    for face in &result.faces {
        let r = face.rect;
        let (x0, y0) = (f64::from(r.x), f64::from(r.y));
        let (x1, y1) = (x0 + f64::from(r.w), y0 + f64::from(r.h));
        for (a, b) in [
            ([x0, y0], [x1, y0]),
            ([x1, y0], [x1, y1]),
            ([x1, y1], [x0, y1]),
            ([x0, y1], [x0, y0]),
        ] {
            canvas.line(a, b, BOX_RGB);
        }
        let fit = &face.fit;
        let (rot, t) = (&fit.pose.rotation, &fit.pose.translation);
        let mut proj = [[0.0; 2]; N_LANDMARKS];
        model.project_into(&fit.shape, &fit.animation, rot, t, camera, &mut proj);
        for tri in model.triangles() {
            for k in 0..3 {
                let (a, b) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
                canvas.line(proj[a], proj[b], MESH_RGB);
            }
        }
        // The SDK's one definition of the head's axes (the FFI's `head_axes` too).
        if let Some(a) = overlay::head_axes(&fit.pose.head_rotation(), t, camera, AXIS_MM) {
            for (tip, col) in [a.x, a.y, a.z].iter().zip(AXIS_RGB) {
                canvas.line(a.origin, *tip, col);
            }
        }
        for p in &face.landmarks.points {
            canvas.disc([f64::from(p[0]), f64::from(p[1])], 1.5, LANDMARK_RGB);
        }
    }
}

/// Tracks every frame of `input` with `tracker` (recorded when its recording runs), writing one
/// CONTRACT JSON line per frame to `out` (stdout when `None`) and, with `overlay`,
/// `frame_NNNNNN.png` overlays there. Returns whether every frame succeeded (a failed frame writes
/// `{"frame": i, "error": ...}` and goes on).
///
/// # Errors
/// A message when the input cannot be opened or an output cannot be written.
pub fn run(
    tracker: &mut RecordingTracker,
    input: &Path,
    out: Option<&Path>,
    overlay: Option<&Path>,
) -> Result<bool, String> {
    // Overlays are drawn on the frame in colour; the tracker reads its luma either way.
    let mut source = FrameSource::open_with(input, overlay.is_some())?;
    let mut rgb = Vec::new();
    let mut sink = LineSink::new(out)?;
    if let Some(dir) = overlay {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut progress = Progress::new(source.len_hint());
    let mut frame = GrayImage::default();
    let mut canvas = Canvas::from_gray(&frame);
    let mut all_ok = true;
    let mut done = 0;
    while let Some((i, ts)) = source.next_frame_with(&mut frame, overlay.map(|_| &mut rgb))? {
        match tracker.process_image(&frame, ts).map(|_| ()) {
            Ok(()) => {
                let tracker = tracker.tracker();
                // Point of gaze only with --targets (CONTRACT.md).
                let targets = Some(tracker.gaze_targets()).filter(|t| !t.is_empty());
                let mut line = frame_json(tracker.result(), targets);
                // The tracker counts calls; the CLI's frame number is the input's.
                line["frame"] = json!(i);
                sink.write(&line)?;
                if let Some(dir) = overlay {
                    let camera = match tracker.config().camera {
                        Some(c) => c,
                        None => {
                            Intrinsics::default_for(frame.width() as u32, frame.height() as u32)
                                .map_err(|e| e.to_string())?
                        }
                    };
                    canvas.set_rgb(frame.width(), frame.height(), &rgb);
                    draw_overlay(&mut canvas, tracker.result(), &camera);
                    canvas.save_png(&dir.join(format!("frame_{i:06}.png")))?;
                }
            }
            Err(e) => {
                all_ok = false;
                eprintln!("monotrack: frame {i}: {e}");
                sink.write(&json!({"frame": i, "error": e.to_string()}))?;
            }
        }
        done += 1;
        progress.update(done);
    }
    progress.finish(done);
    Ok(all_ok)
}

#[cfg(test)]
mod tests {
    use super::*;
    use monotrack_core::fit::{Msbp, MsbpConfig, Pose};
    use monotrack_core::landmarks::FaceLandmarks;
    use monotrack_core::model::{N_ANIM, N_SHAPE};
    use monotrack_core::track::StageTimings;

    fn result(cam: &Intrinsics) -> TrackingResult {
        let pose = Pose::from_euler_deg(20.0, -5.0, 3.0, nalgebra::Vector3::new(10.0, 0.0, 600.0));
        let mut p = [[0.0; 2]; N_LANDMARKS];
        FaceModel::builtin().project_into(
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &pose.rotation,
            &pose.translation,
            cam,
            &mut p,
        );
        let fit = Msbp::new(MsbpConfig::default())
            .fit(&p, None, cam, None)
            .unwrap();
        let mut lm = FaceLandmarks::default();
        for (o, q) in lm.points.iter_mut().zip(&p) {
            *o = [q[0] as f32, q[1] as f32];
        }
        lm.yaw_probs = [0.0, 0.1, 0.2, 0.7, 0.0];
        TrackingResult {
            timestamp_ns: 66_666_667,
            frame_index: 2,
            faces: vec![TrackedFace {
                id: 7,
                rect: monotrack_core::image::Rect::new(250.0, 180.0, 140.0, 150.0),
                score: 0.93,
                state: FaceState::Tracked,
                landmarks: lm,
                fit,
                shape_held: true,
                flow_points: 60,
                gaze: Some(monotrack_core::gaze::point_of_gaze(
                    &lm,
                    &fit,
                    &Default::default(),
                    &Default::default(),
                    None,
                    &[],
                )),
                quality: Default::default(),
            }],
            detector_ran: false,
            reasons: Default::default(),
            timings: StageTimings {
                total_us: 900,
                fit_us: 30,
                ..Default::default()
            },
        }
    }

    #[test]
    fn frame_json_follows_the_contract() {
        use monotrack_core::track::quality::QualityReason;
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let r = result(&cam);
        let v = frame_json(&r, None);
        assert_eq!(v["frame"], 2);
        assert_eq!(v["timestamp_ms"], 66.667);
        assert_eq!(v["state"], "tracked");
        assert_eq!(v["timings_us"]["total"], 900);
        let f = &v["faces"][0];
        assert_eq!(f["id"], 7);
        assert_eq!(f["state"], "tracked");
        assert_eq!(f["box"], json!([250.0, 180.0, 140.0, 150.0]));
        assert_eq!(f["landmarks68"].as_array().unwrap().len(), 68);
        assert_eq!(f["yaw_class_deg"], 30);
        assert_eq!(f["yaw_probs"].as_array().unwrap().len(), 5);
        for k in ["smile", "frown", "kiss", "neutral"] {
            assert!(f["gestures"]["mouth"][k].is_number(), "{k}");
        }
        for k in ["raise", "frown", "neutral"] {
            assert!(f["gestures"]["brows"][k].is_number(), "{k}");
        }
        assert_eq!(f["gaze"]["combined"], json!([0.0, 0.0, 1.0]));
        let yaw = f["pose"]["yaw_deg"].as_f64().unwrap();
        assert!((yaw - 20.0).abs() < 1.0, "{yaw}");
        assert_eq!(f["pose"]["rotation"].as_array().unwrap().len(), 3);
        assert_eq!(f["shape_units"].as_object().unwrap().len(), N_SHAPE);
        assert_eq!(f["action_units"].as_object().unwrap().len(), N_ANIM);
        assert!(f["fit_rms_px"].as_f64().unwrap() < 0.5);
        assert_eq!(
            f["uncertainty"]["rotation_deg"].as_array().unwrap().len(),
            3
        );
        assert_eq!(
            f["uncertainty"]["translation_mm"].as_array().unwrap().len(),
            3
        );
        assert!(f["quality"]["score"].is_number());
        assert_eq!(f["quality"]["reasons"], json!([]));
        assert_eq!(v["reasons"], json!([]));
        let mut poor = r.clone();
        poor.reasons.insert(QualityReason::Dark);
        poor.reasons.insert(QualityReason::NoFace);
        poor.faces[0]
            .quality
            .reasons
            .insert(QualityReason::PartlyOutside);
        poor.faces[0].quality.reasons.insert(QualityReason::Turned);
        let v = frame_json(&poor, None);
        assert_eq!(v["reasons"], json!(["dark", "no_face"]));
        assert_eq!(
            v["faces"][0]["quality"]["reasons"],
            json!(["partly_outside", "turned"])
        );
        let mut lost = r.clone();
        lost.faces.clear();
        assert_eq!(frame_json(&lost, None)["state"], "lost");
        lost.faces = r.faces.clone();
        lost.faces[0].state = FaceState::Detected;
        assert_eq!(frame_json(&lost, None)["state"], "detected");
    }

    #[test]
    fn text_draws_the_glyph_pixels() {
        let mut c = Canvas::from_gray(&GrayImage::new(12, 6));
        let ink = [9, 9, 9];
        // 'L': the left column, then the bottom row; 'l' is the same glyph; '~' draws nothing.
        c.text(0, 0, "l~", 1, ink);
        for row in 0..5 {
            assert_eq!(c.get(0, row), Some(ink), "row {row}");
            assert_eq!(
                c.get(1, row),
                if row == 4 { Some(ink) } else { Some([0, 0, 0]) }
            );
        }
        assert!((4..8).all(|x| (0..5).all(|y| c.get(x, y) == Some([0, 0, 0]))));
    }

    #[test]
    fn lines_and_discs_land_on_the_right_pixels() {
        let mut c = Canvas::from_gray(&GrayImage::new(20, 10));
        let red = [255, 0, 0];
        c.line([0.5, 0.5], [9.5, 0.5], red);
        for x in 0..10 {
            assert_eq!(c.get(x, 0), Some(red));
        }
        assert_eq!(c.get(10, 0), Some([0, 0, 0]));
        // Diagonal: every step touches one pixel per column.
        c.line([0.5, 2.5], [5.5, 7.5], red);
        for k in 0..6 {
            assert_eq!(c.get(k, 2 + k), Some(red));
        }
        // Far outside, NaN: clipped or skipped, never a panic.
        c.line([-1e3, -1e3], [1e3, 1e3], red);
        c.line([f64::NAN, 0.0], [1.0, 1.0], red);
        c.line([1e30, 0.0], [1.0, 1.0], red);
        c.disc([15.5, 5.5], 1.5, [0, 255, 0]);
        assert_eq!(c.get(15, 5), Some([0, 255, 0]));
        assert_eq!(c.get(16, 6), Some([0, 255, 0]));
        assert_eq!(c.get(18, 5), Some([0, 0, 0]));
        c.disc([19.9, 9.9], 3.0, [0, 255, 0]);
    }

    #[test]
    fn overlay_draws_mesh_axes_and_landmarks_and_saves_a_png() {
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let r = result(&cam);
        let mut c = Canvas::from_gray(&GrayImage::new(640, 480));
        draw_overlay(&mut c, &r, &cam);
        let count = |col: [u8; 3]| {
            (0..480)
                .flat_map(|y| (0..640).map(move |x| (x, y)))
                .filter(|&(x, y)| c.get(x, y) == Some(col))
                .count()
        };
        assert!(count(MESH_RGB) > 300, "mesh {}", count(MESH_RGB));
        assert!(count(LANDMARK_RGB) >= 68);
        for col in AXIS_RGB {
            assert!(count(col) > 10);
        }
        let p = r.faces[0].landmarks.points[30];
        assert_eq!(c.get(p[0] as usize, p[1] as usize), Some(LANDMARK_RGB));
        let dir = std::env::temp_dir().join(format!("monotrack-overlay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("o.png");
        c.save_png(&path).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!((back.width(), back.height()), (640, 480));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn frame_directories_read_in_name_order_as_contract_luma() {
        let dir = std::env::temp_dir().join(format!("monotrack-frames-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Written out of order; one non-image file is ignored.
        for (name, rgb) in [
            ("b_002.png", [10u8, 200, 30]),
            ("a_001.PNG", [255, 0, 0]),
            ("c_003.png", [1, 2, 3]),
        ] {
            let img = image::RgbImage::from_pixel(4, 3, image::Rgb(rgb));
            img.save(dir.join(name)).unwrap();
        }
        std::fs::write(dir.join("notes.txt"), "x").unwrap();
        let mut src = FrameSource::open(&dir).unwrap();
        assert_eq!(src.len_hint(), Some(3));
        let mut g = GrayImage::default();
        let mut got = Vec::new();
        while let Some((i, ts)) = src.next_frame(&mut g).unwrap() {
            got.push((i, ts, g.get(0, 0)));
        }
        // 0.299·255 = 76.245 → 76; 0.299·10 + 0.587·200 + 0.114·30 = 123.81 → 124.
        assert_eq!(got[0], (0, 0, 76));
        assert_eq!(got[1], (1, 33_333_333, 124));
        assert_eq!(got[2].2, 2);
        // In colour too, for overlays: the decoded pixels.
        let mut src = FrameSource::open_with(&dir, true).unwrap();
        let mut rgb = Vec::new();
        src.next_frame_with(&mut g, Some(&mut rgb))
            .unwrap()
            .unwrap();
        assert_eq!((rgb.len(), &rgb[..3]), (4 * 3 * 3, &[255u8, 0, 0][..]));
        let mut canvas = Canvas::from_gray(&g);
        canvas.set_rgb(g.width(), g.height(), &rgb);
        assert_eq!(canvas.get(3, 2), Some([255, 0, 0]));
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(FrameSource::open(Path::new("/nonexistent/monotrack")).is_err());
    }

    #[test]
    #[cfg_attr(not(has_ffmpeg), ignore = "needs ffmpeg on PATH")]
    fn videos_are_read_through_ffmpeg() {
        assert!(
            Command::new("ffmpeg").arg("-version").output().is_ok(),
            "ffmpeg is not on PATH"
        );
        let dir = std::env::temp_dir().join(format!("monotrack-video-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gray.mkv");
        // Lossless (FFV1) mid-gray 64×48 at 10 fps, 5 frames.
        let ok = Command::new("ffmpeg")
            .args(["-v", "error", "-y", "-f", "lavfi", "-i"])
            .arg("color=c=0x808080:size=64x48:rate=10")
            .args(["-frames:v", "5", "-c:v", "ffv1"])
            .arg(&path)
            .status()
            .unwrap()
            .success();
        assert!(ok);
        let mut src = FrameSource::open(&path).unwrap();
        let mut g = GrayImage::default();
        let mut n = 0;
        while let Some((i, ts)) = src.next_frame(&mut g).unwrap() {
            assert_eq!((g.width(), g.height()), (64, 48));
            assert_eq!(ts, i as i64 * 100_000_000);
            assert!(
                (i32::from(g.get(10, 10)) - 128).abs() <= 2,
                "{}",
                g.get(10, 10)
            );
            n += 1;
        }
        assert_eq!(n, 5);
        drop(src);
        let mut src = FrameSource::open_with(&path, true).unwrap();
        let mut rgb = Vec::new();
        src.next_frame_with(&mut g, Some(&mut rgb))
            .unwrap()
            .unwrap();
        assert_eq!(rgb.len(), 64 * 48 * 3);
        assert!((i32::from(rgb[0]) - 128).abs() <= 2, "{}", rgb[0]);
        drop(src);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn probe_output_parses_and_progress_formats() {
        let p =
            parse_probe("width=1280\nheight=720\navg_frame_rate=25/1\nnb_frames=158\n").unwrap();
        assert_eq!(p, (1280, 720, 25.0, Some(158)));
        let p = parse_probe("width=640\nheight=480\navg_frame_rate=0/0\nnb_frames=N/A\n").unwrap();
        assert_eq!(p, (640, 480, DIR_FPS, None));
        // An edit-listed clip: the duration's frames, not the packets; within a frame the count.
        let clip =
            "width=1280\nheight=720\navg_frame_rate=25/1\nduration=2.186044\nnb_frames=158\n";
        assert_eq!(parse_probe(clip).unwrap(), (1280, 720, 25.0, Some(55)));
        let p =
            parse_probe("width=8\nheight=8\navg_frame_rate=30/1\nduration=9.99\nnb_frames=300\n");
        assert_eq!(p.unwrap().3, Some(300));
        let p =
            parse_probe("width=8\nheight=8\navg_frame_rate=30/1\nduration=2.0\nnb_frames=N/A\n");
        assert_eq!(p.unwrap().3, Some(60));
        let p = parse_probe("width=8\nheight=8\navg_frame_rate=30/1\nduration=N/A\nnb_frames=12\n");
        assert_eq!(p.unwrap().3, Some(12));
        assert!(parse_probe("").is_none());
        assert_eq!(
            Progress::line(Some(10), 5, 1.0),
            format!(
                "[{}{}] 5/10 frames  5.0 fps",
                "#".repeat(15),
                "-".repeat(15)
            )
        );
        assert_eq!(Progress::line(None, 7, 0.0), "7 frames  0.0 fps");
    }
}
