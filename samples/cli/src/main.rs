//! `monotrack`: the desktop command line of the SDK. Its JSON in and out follows
//! `CONTRACT.md` exactly; it is how the SDK is measured from outside.

mod bench;
mod body;
mod demo;
mod detect;
mod fit;
mod json;
mod landmarks;
mod luma;
mod motion;
mod replay;
// Some frame-source helpers are used by tests only.
#[allow(dead_code)]
mod track;

use clap::{Parser, Subcommand};
use monotrack_core::body::BodyFitConfig;
use std::io::{BufRead, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "monotrack", version, about = "monotrack SDK command line")]
struct Cli {
    /// Which kernel forms run: `native` (the CPU's fastest), `portable` (an aarch64 phone's
    /// choices, on any CPU), optionally with `,conv=FORM` or `,flow=FORM` to time one form
    /// (`monotrack_core::kernels::KernelChoice`). Default: `MONOTRACK_KERNELS`, else native.
    #[arg(long, global = true)]
    kernels: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit the deformable 3D face model to given 68-point landmarks (no image needed).
    Fit {
        /// Input JSON lines: {"width", "height", "camera"?, "faces": [{"landmarks68": [[x, y] x68]}]}.
        input: PathBuf,
        /// Output JSON lines (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Fitting method.
        #[arg(long, value_enum, default_value = "msbp")]
        method: fit::Method,
    },
    /// M3 landmarks, gestures, gaze and the MSBP fit of the faces of each image (detects the faces
    /// when a line gives no boxes).
    Landmarks {
        /// Input JSON lines: {"image", "camera"?, "faces": [{"box": [x, y, w, h]}]?}.
        input: PathBuf,
        /// Output JSON lines (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// M3 in single-pass mode (each net runs once, as the video tracker runs it): faster, less
        /// accurate. By default a still image's landmarks are in mirror-average mode: level 1 and
        /// the zones marked in m3.json also run on their mirrored input and the two runs average
        /// (core/models/MODEL_CARD.md).
        #[arg(long, conflicts_with = "mirror_average")]
        single_pass: bool,
        /// Mirror-average mode, the default (kept so that earlier command lines still run).
        #[arg(long, hide = true)]
        mirror_average: bool,
        /// Detect at the small-faces operating point (min face 16 px, detector score 0.25: faces
        /// down to ~17 px, twice the detector time, more false positives on clutter;
        /// core/models/MODEL_CARD.md) instead of the SDK's default (min face 24 px, score 0.4).
        #[arg(long)]
        small_faces: bool,
        /// Gaze targets (CONTRACT.md `T.json`): each face gets its point of gaze.
        #[arg(long)]
        targets: Option<PathBuf>,
        /// The landmark detector: the M3 networks, or the learning-free 32-point gradient
        /// detector with the FFBP fit (ultra-light mode, no landmark network loaded).
        #[arg(long, value_enum, default_value = "m3")]
        landmarks: landmarks::Landmarker,
    },
    /// Detect faces in images with the SDK's detector: {"image": path} lines in, boxes + scores out.
    Detect {
        /// Input JSON lines: {"image": "path (absolute or relative to this file's folder)"}.
        input: PathBuf,
        /// Output JSON lines (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Smallest face to find, pixels (max side of the tight landmark box).
        #[arg(long, default_value_t = monotrack_core::detect::DetectorConfig::default().min_face_px)]
        min_face: f32,
        /// Minimum face probability.
        #[arg(long, default_value_t = monotrack_core::detect::DetectorConfig::default().score_threshold)]
        threshold: f32,
        /// Also report M3 level 1's face probability of every detection ("face_prob").
        #[arg(long)]
        face_prob: bool,
        /// Report the faces the SDK's detection cascade accepts (the tracker's and `landmarks`'
        /// detections): candidates down to --threshold, checked by M3 level 1 (re-boxed on its
        /// points), kept at face probability >= 0.95; implies --face-prob.
        #[arg(long)]
        cascade: bool,
    },
    /// Track faces through a video file (via ffmpeg) or a directory of frames (file-name order).
    Track {
        /// A video file or a directory of PNG/JPEG frames.
        input: PathBuf,
        /// Output JSON lines, one per frame (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write PNG frames with landmarks, the projected mesh and head axes here.
        #[arg(long)]
        overlay: Option<PathBuf>,
        /// Tracker settings as a JSON file (the core's `TrackerConfig`; missing fields keep defaults).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Gaze targets (CONTRACT.md `T.json`): each face gets its point of gaze.
        #[arg(long)]
        targets: Option<PathBuf>,
        /// The landmark detector: M3, or the ultra-light mode's gradient detector with FFBP
        /// (`TrackerConfig::ultra_light`'s thresholds unless --config gives a file).
        #[arg(long, value_enum, default_value = "m3")]
        landmarks: landmarks::Landmarker,
        /// Also write a recording of what was tracked here (core/src/record/FORMAT.md), for
        /// `monotrack replay`.
        #[arg(long)]
        record: Option<PathBuf>,
        /// The most bytes the recording may take: recording stops (truncated) before the frame
        /// that would pass it.
        #[arg(long, default_value_t = 1 << 30, requires = "record")]
        record_max_bytes: u64,
    },
    /// Re-run a recording (`track --record`, an app's `FaceTracker.start_recording`) through a
    /// tracker built from its settings, print what `track` prints for its frames, and check each
    /// result bit for bit against the recorded one (exit 1 when any differs).
    Replay {
        /// The recording.
        input: PathBuf,
        /// Output JSON lines, one per recorded frame (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// The model bundle the recording was made on, when it was not the built-in models.
        #[arg(long)]
        models: Option<PathBuf>,
    },
    /// The whole pipeline on a clip made from the committed sample image: overlays + timing table.
    Demo {
        /// Where the overlay PNGs go.
        #[arg(long, default_value = "target/demo")]
        overlay: PathBuf,
        /// Number of frames.
        #[arg(long, default_value_t = 120)]
        frames: usize,
        /// Also write the CONTRACT `track` JSON lines here.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Time the face pipeline per stage from camera frames (a moving-face clip laid out as the
    /// camera delivers it) to the result; `--kernels portable` times the phone's kernels.
    Bench {
        /// Camera frame format.
        #[arg(long, value_enum, default_value = "nv21")]
        format: bench::FormatArg,
        /// Clockwise rotation that makes the 640x480 sensor buffer upright (90: a back camera in
        /// portrait).
        #[arg(long, default_value_t = 90, value_parser = bench::parse_rotation)]
        rotation: u32,
        /// Mirror the upright image (front cameras).
        #[arg(long)]
        mirrored: bool,
        /// Frames in the clip (each runs once tracked and once detected).
        #[arg(long, default_value_t = 300)]
        frames: u32,
        /// Print the report as one JSON object.
        #[arg(long)]
        json: bool,
        /// The landmark detector timed: the M3 networks, or the ultra-light mode (the
        /// learning-free gradient detector with the FFBP fit, no landmark network loaded).
        #[arg(long, value_enum, default_value = "m3")]
        landmarks: landmarks::Landmarker,
    },
    /// Score a trial motion against a reference (3D joints from body-fit) and say what to fix.
    CompareMotion {
        /// The reference: body-fit output lines (`joints3d_mm`, the 15 joints).
        #[arg(long)]
        reference: PathBuf,
        /// The trial, in the same form.
        #[arg(long)]
        trial: PathBuf,
        /// Phases of the reference and weighted features (CONTRACT.md).
        #[arg(long)]
        weights: PathBuf,
        /// Print the CONTRACT.md JSON instead of the readable report.
        #[arg(long)]
        json: bool,
        /// Write one PNG per weighted feature here (reference blue, trial orange, phase shaded,
        /// similarity as the green bar; the file name says phase, joint, feature and score).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Frames per second of both sequences (velocities and accelerations are per second;
        /// Human3.6M's files as `tests/scripts/body_data.py` writes them are 10).
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
    },
    /// 3D body pose and dimensions from 2D joints with a known or floor-calibrated camera.
    BodyFit {
        /// Input JSON lines: {"frame", "sequence"?, "camera"? | "floor"?, "joints2d": {NAME: [x, y]}}.
        input: PathBuf,
        /// Output JSON lines (default: stdout).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Frames at the start of each sequence used to estimate its body dimensions.
        #[arg(long, default_value_t = 5)]
        dimension_frames: usize,
        /// Joint-definition convention of the input joints.
        #[arg(long, value_enum, default_value = "humaneva")]
        convention: body::ConventionArg,
        /// Strength of the learnt pose prior, px per standard deviation: about the error of the
        /// 2D joints (5 suits detectors and annotations; exact synthetic joints want <= 1).
        #[arg(long, default_value_t = monotrack_core::body::fit::DEFAULT_PRIOR_WEIGHT_PX)]
        prior_weight: f64,
        /// Refine each frame in the full 21-joint, 54-DoF body model (clavicles, pelvis girdle,
        /// three-joint spine): about 1 mm more accurate on HumanEva-I, 2.4x the pose time.
        #[arg(long)]
        full_model: bool,
    },
}

/// Non-empty input lines with their 1-based line numbers.
pub(crate) fn read_lines(path: &Path) -> Result<Vec<(usize, String)>, String> {
    let f =
        std::fs::File::open(path).map_err(|e| format!("cannot open {}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in std::io::BufReader::new(f).lines().enumerate() {
        let line = line.map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?;
        if !line.trim().is_empty() {
            out.push((i + 1, line));
        }
    }
    Ok(out)
}

/// Writes one JSON value per line to a file or stdout.
pub(crate) struct LineSink(Box<dyn Write>);

impl LineSink {
    pub(crate) fn new(out: Option<&Path>) -> Result<Self, String> {
        Ok(Self(match out {
            Some(p) => Box::new(BufWriter::new(
                std::fs::File::create(p)
                    .map_err(|e| format!("cannot create {}: {e}", p.display()))?,
            )),
            None => Box::new(BufWriter::new(std::io::stdout().lock())),
        }))
    }

    pub(crate) fn write(&mut self, v: &serde_json::Value) -> Result<(), String> {
        serde_json::to_writer(&mut self.0, v).map_err(|e| e.to_string())?;
        self.0.write_all(b"\n").map_err(|e| e.to_string())
    }
}

impl Drop for LineSink {
    fn drop(&mut self) {
        let _ = self.0.flush();
    }
}

/// Where and how large `monotrack track --record` writes.
struct RecordTo<'a> {
    path: &'a Path,
    max_bytes: u64,
}

/// `monotrack track`: the tracker over the shipped models, configured from an optional JSON file,
/// recorded with `record`.
fn run_track(
    input: &Path,
    out: Option<&Path>,
    overlay: Option<&Path>,
    config: Option<&Path>,
    targets: Option<&Path>,
    landmarker: landmarks::Landmarker,
    record: Option<RecordTo<'_>>,
) -> Result<bool, String> {
    let gradient = landmarker == landmarks::Landmarker::Gradient;
    if gradient && targets.is_some() {
        return Err("--targets needs the eyes' gaze, which only --landmarks m3 gives".into());
    }
    let mut cfg: monotrack_core::TrackerConfig = match config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| format!("cannot read {}: {e}", p.display()))?;
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?
        }
        None if gradient => monotrack_core::TrackerConfig::ultra_light(),
        None => monotrack_core::TrackerConfig::default(),
    };
    if gradient {
        cfg.landmarks = monotrack_core::track::LandmarkMode::Gradient;
    }
    if targets.is_some() && !cfg.gaze {
        return Err(
            "--targets needs the gaze stage, which the --config turns off (\"gaze\": false)".into(),
        );
    }
    let tracker =
        monotrack_core::track::Tracker::with_default_models(cfg).map_err(|e| e.to_string())?;
    let mut tracker = monotrack_core::record::RecordingTracker::new(
        tracker,
        monotrack_core::record::ModelIdentity::builtin(),
    );
    if let Some(p) = targets {
        tracker.set_gaze_targets(json::load_targets(p)?);
    }
    let switch = tracker.switch();
    if let Some(r) = &record {
        let file = std::fs::File::create(r.path)
            .map_err(|e| format!("cannot create {}: {e}", r.path.display()))?;
        switch
            .start(Box::new(BufWriter::new(file)), r.max_bytes)
            .map_err(|e| format!("{}: {e}", r.path.display()))?;
    }
    let all_ok = track::run(&mut tracker, input, out, overlay)?;
    if let Some(r) = &record {
        let s = switch
            .stop()
            .map_err(|e| format!("{}: {e}", r.path.display()))?;
        eprintln!(
            "monotrack: recorded {} frames ({} bytes) to {}{}",
            s.frames,
            s.bytes,
            r.path.display(),
            if s.truncated {
                ", truncated at --record-max-bytes"
            } else {
                ""
            }
        );
    }
    Ok(all_ok)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(spec) = &cli.kernels {
        let chosen = monotrack_core::kernels::KernelChoice::parse(spec)
            .and_then(monotrack_core::kernels::select);
        if let Err(e) = chosen {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    }
    let result = match cli.command {
        Command::Fit { input, out, method } => fit::run(&input, out.as_deref(), method),
        Command::Landmarks {
            input,
            out,
            single_pass,
            mirror_average: _,
            small_faces,
            targets,
            landmarks: landmarker,
        } => landmarks::run(
            &input,
            out.as_deref(),
            !single_pass,
            small_faces,
            targets.as_deref(),
            landmarker,
        ),
        Command::Detect {
            input,
            out,
            min_face,
            threshold,
            face_prob,
            cascade,
        } => detect::run(
            &input,
            out.as_deref(),
            monotrack_core::detect::DetectorConfig {
                min_face_px: min_face,
                score_threshold: threshold,
                ..Default::default()
            },
            if cascade {
                detect::Check::Cascade
            } else if face_prob {
                detect::Check::FaceProb
            } else {
                detect::Check::None
            },
        ),
        Command::Track {
            input,
            out,
            overlay,
            config,
            targets,
            landmarks: landmarker,
            record,
            record_max_bytes,
        } => run_track(
            &input,
            out.as_deref(),
            overlay.as_deref(),
            config.as_deref(),
            targets.as_deref(),
            landmarker,
            record.as_deref().map(|path| RecordTo {
                path,
                max_bytes: record_max_bytes,
            }),
        ),
        Command::Replay { input, out, models } => replay::run(
            &input,
            out.as_deref(),
            models.as_deref(),
            cli.kernels.is_some(),
        ),
        Command::Demo {
            overlay,
            frames,
            out,
        } => demo::run(frames, Some(&overlay), out.as_deref()),
        Command::Bench {
            format,
            rotation,
            mirrored,
            frames,
            json,
            landmarks: landmarker,
        } => bench::run(
            format,
            rotation,
            mirrored,
            frames,
            json,
            landmarker == landmarks::Landmarker::Gradient,
        ),
        Command::CompareMotion {
            reference,
            trial,
            weights,
            json,
            plot,
            fps,
        } => motion::run(&reference, &trial, &weights, json, plot.as_deref(), fps).map(|()| true),
        Command::BodyFit {
            input,
            out,
            dimension_frames,
            convention,
            prior_weight,
            full_model,
        } => body::run(
            &input,
            out.as_deref(),
            dimension_frames,
            convention,
            BodyFitConfig {
                prior_weight_px: prior_weight,
                full_model,
                ..BodyFitConfig::default()
            },
        ),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("monotrack: {e}");
            ExitCode::from(2)
        }
    }
}
