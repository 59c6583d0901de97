//! The error series of an evaluation and their statistics, as evo reports them.
//!
//! In: per-pose errors ([`PoseError`]: translation in metres, rotation in degrees). Out: an
//! [`ErrorSeries`] of them with RMSE, mean, median, population standard deviation, min and max
//! ([`Stats`]) of each; no series for none.

/// Summary statistics of one error series, in the series' unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stats {
    pub rmse: f64,
    pub mean: f64,
    pub median: f64,
    /// Population standard deviation (numpy's `std`, as evo reports).
    pub std: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Stats {
    /// Statistics of a series; `None` when it is empty.
    pub fn of(values: &[f64]) -> Option<Stats> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let rmse = (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median = if sorted.len() % 2 == 0 {
            (sorted[mid - 1] + sorted[mid]) / 2.0
        } else {
            sorted[mid]
        };
        Some(Stats {
            rmse,
            mean,
            median,
            std,
            min: sorted[0],
            max: sorted[sorted.len() - 1],
            count: values.len(),
        })
    }
}

/// The error of one associated pose (ATE) or one pose pair (RPE).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// Timestamp of the estimated pose (for RPE: of the pair's later pose).
    pub timestamp_ns: u64,
    /// Index in the ground-truth trajectory as given (for RPE: of the pair's later pose).
    pub gt_index: usize,
    /// Index in the estimated trajectory as given (for RPE: of the pair's later pose).
    pub est_index: usize,
    pub translation_m: f64,
    pub rotation_deg: f64,
}

/// One metric (ATE or RPE): per-pose errors and their statistics.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorSeries {
    pub per_pose: Vec<PoseError>,
    pub translation_m: Stats,
    pub rotation_deg: Stats,
}

impl ErrorSeries {
    pub(super) fn from_errors(per_pose: Vec<PoseError>) -> Option<ErrorSeries> {
        let t: Vec<f64> = per_pose.iter().map(|e| e.translation_m).collect();
        let r: Vec<f64> = per_pose.iter().map(|e| e.rotation_deg).collect();
        Some(ErrorSeries {
            translation_m: Stats::of(&t)?,
            rotation_deg: Stats::of(&r)?,
            per_pose,
        })
    }
}
