//! `monotrack bench`: the face pipeline timed from camera frames as phones deliver them to the
//! result, per stage, on a moving-face clip made from the committed sample picture
//! (`monotrack_core::bench::run_camera_benchmark`). Which kernel forms ran and on which CPU are
//! part of the report: `--kernels portable` times the forms an aarch64 phone runs.

use monotrack_core::TrackerConfig;
use monotrack_core::bench::{
    CameraBenchReport, FrameStages, Percentiles, android_portrait_camera, run_camera_benchmark,
};
use monotrack_core::camera::Rotation;
use monotrack_core::image::{FrameDesc, PixelFormat};

/// The frame formats a camera delivers (`--format`).
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum FormatArg {
    /// Android's camera default: Y plane + interleaved V/U.
    Nv21,
    /// iOS bi-planar: Y plane + interleaved U/V.
    Nv12,
    /// Y, U and V planes.
    I420,
    /// The Y plane alone.
    Gray8,
    /// 8-bit R, G, B, A.
    Rgba,
}

impl From<FormatArg> for PixelFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Nv21 => PixelFormat::Nv21,
            FormatArg::Nv12 => PixelFormat::Nv12,
            FormatArg::I420 => PixelFormat::I420,
            FormatArg::Gray8 => PixelFormat::Gray8,
            FormatArg::Rgba => PixelFormat::Rgba8,
        }
    }
}

/// `--rotation`: 0, 90, 180 or 270.
pub fn parse_rotation(s: &str) -> Result<u32, String> {
    match s {
        "0" | "90" | "180" | "270" => Ok(s.parse().expect("a listed number")),
        _ => Err(format!("{s} is not one of 0, 90, 180, 270")),
    }
}

/// Runs the benchmark (the ultra-light mode's pipeline with `ultra_light`) and prints its report
/// (JSON with `json`, else a table); false when the clip gave no measurement.
pub fn run(
    format: FormatArg,
    rotation: u32,
    mirrored: bool,
    frames: u32,
    json: bool,
    ultra_light: bool,
) -> Result<bool, String> {
    let rotation = Rotation::from_degrees(rotation as i32).map_err(|e| e.to_string())?;
    let source = crate::demo::source()?;
    let sensor = android_portrait_camera();
    let camera = FrameDesc {
        rotation,
        mirrored,
        ..FrameDesc::packed(sensor.width, sensor.height, format.into())
    };
    let config = if ultra_light {
        TrackerConfig::ultra_light()
    } else {
        TrackerConfig::default()
    };
    let report =
        run_camera_benchmark(&source, &camera, frames, &config).map_err(|e| e.to_string())?;
    if json {
        println!(
            "{}",
            serde_json::to_string(&report).map_err(|e| e.to_string())?
        );
    } else {
        print_table(&report, &camera);
    }
    Ok(true)
}

fn print_table(r: &CameraBenchReport, c: &FrameDesc) {
    println!(
        "monotrack bench: {} frames of {:?} {}x{} rotated {}°{}, {} path on {}",
        r.frames,
        c.format,
        c.width,
        c.height,
        c.rotation.degrees(),
        if c.mirrored { " and mirrored" } else { "" },
        r.path,
        r.cpu
    );
    println!("models loaded in {:.1} ms", r.model_load_us / 1000.0);
    println!(
        "{:<10} {:>20} {:>20}",
        "stage", "tracked µs (p90)", "detected µs (p90)"
    );
    type Get = fn(&FrameStages) -> Percentiles;
    let rows: [(&str, Get); 6] = [
        ("convert", |s| s.convert),
        ("region", |s| s.region),
        ("landmarks", |s| s.landmarks),
        ("flow", |s| s.flow),
        ("fit", |s| s.fit),
        ("total", |s| s.total),
    ];
    for (name, get) in rows {
        let (a, b) = (get(&r.tracked), get(&r.detected));
        println!(
            "{name:<10} {:>20} {:>20}",
            format!("{:.0} ({:.0})", a.median_us, a.p90_us),
            format!("{:.0} ({:.0})", b.median_us, b.p90_us)
        );
    }
}
