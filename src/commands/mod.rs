//! One module per command of `omnitrack` (docs/interfaces.md, "Command line"): each holds its
//! arguments (clap) and its `run`, which returns the command's error, whatever its layer's type,
//! for `main` to print as one line.

pub mod check;
pub mod edges;
pub mod pose;
pub mod record;
pub mod run;
pub mod segments;
pub mod visibility;

/// A command's outcome: its output is written; an error is reported by `main` in one line.
pub type CommandResult = Result<(), Box<dyn std::error::Error>>;
