//! `monotrack`: the desktop command line of the SDK. Its JSON in and out follows
//! `../shared/CONTRACT.md` exactly; it is how the SDK is measured from outside.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "monotrack", version, about = "monotrack SDK command line")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {}
}
