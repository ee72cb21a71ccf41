//! `monotrack`: the desktop command line of the SDK. Its JSON in and out follows
//! `../shared/CONTRACT.md` exactly; it is how the SDK is measured from outside.

mod body;
mod fit;
mod json;

use clap::{Parser, Subcommand};
use std::io::{BufRead, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "monotrack", version, about = "monotrack SDK command line")]
struct Cli {
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fit { input, out, method } => fit::run(&input, out.as_deref(), method),
        Command::BodyFit {
            input,
            out,
            dimension_frames,
            convention,
        } => body::run(&input, out.as_deref(), dimension_frames, convention),
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
