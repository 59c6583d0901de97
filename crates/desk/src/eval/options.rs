//! What a comparison of two trajectories is given, and how it fails.
//!
//! In: nothing (the caller's choices; `Default` is evo's default). Out: [`EvalOptions`] (the
//! association window, alignment, the RPE distance) and [`EvalError`], the one error type of the
//! evaluation, from an unreadable file to a degenerate alignment.

use omnitrack_core::trajectory::TumError;

/// How to compare two trajectories.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// Largest timestamp difference (seconds) for two poses to be associated (evo `--t_max_diff`).
    pub max_diff_s: f64,
    /// Rigidly align the estimate onto the ground truth first (evo `--align`).
    pub align: bool,
    /// RPE frame distance, in associated poses (evo `--delta N --delta_unit f`).
    pub rpe_delta: usize,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            max_diff_s: 0.01,
            align: false,
            rpe_delta: 1,
        }
    }
}

/// Why two trajectories could not be compared.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Trajectory(#[from] TumError),
    #[error("{gt} vs {est}: {source}")]
    Files {
        gt: String,
        est: String,
        #[source]
        source: Box<EvalError>,
    },
    #[error("bad option: {0}")]
    Option(String),
    #[error("no timestamps match within {max_diff_s} s ({gt_poses} ground-truth poses, {est_poses} estimated poses)")]
    NoMatches {
        max_diff_s: f64,
        gt_poses: usize,
        est_poses: usize,
    },
    #[error("cannot align: {0}")]
    Alignment(String),
}
