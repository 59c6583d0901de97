//! Association of two trajectories by timestamp, as evo associates them.
//!
//! In: the ground truth and the estimate (in time order) and the largest timestamp difference.
//! Out: the `(gt index, est index)` pairs, in time order: the shorter trajectory keeps each pose
//! whose nearest timestamp in the other lies within the difference (a tie goes to the earlier).

use omnitrack_core::trajectory::Stamped;

/// Pairs `(gt index, est index)` of poses whose timestamps match within `max_diff_s`, as evo
/// associates them (see the module doc). Both trajectories must be in time order.
pub fn associate(gt: &[Stamped], est: &[Stamped], max_diff_s: f64) -> Vec<(usize, usize)> {
    // evo starts from the shorter trajectory so that none of its poses is lost; on a tie the
    // second argument (the estimate) is the short one.
    let est_is_short = est.len() <= gt.len();
    let (short, long) = if est_is_short { (est, gt) } else { (gt, est) };
    let max_diff_ns = (max_diff_s * 1e9).round() as i128;
    let mut pairs = Vec::new();
    for (i_short, s) in short.iter().enumerate() {
        let t = i128::from(s.timestamp_ns);
        // First pose of the long trajectory strictly after t (evo's searchsorted side="right").
        let upper = long.partition_point(|p| i128::from(p.timestamp_ns) <= t);
        let diff_after = long.get(upper).map(|p| i128::from(p.timestamp_ns) - t);
        let diff_before = upper.checked_sub(1).map(|k| t - i128::from(long[k].timestamp_ns));
        let best = match (diff_before, diff_after) {
            (Some(b), Some(a)) if a < b => Some((upper, a)),
            (Some(b), _) => Some((upper - 1, b)),
            (None, Some(a)) => Some((upper, a)),
            (None, None) => None,
        };
        if let Some((i_long, _)) = best.filter(|&(_, d)| d <= max_diff_ns) {
            pairs.push(if est_is_short {
                (i_long, i_short)
            } else {
                (i_short, i_long)
            });
        }
    }
    pairs
}
