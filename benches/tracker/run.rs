//! One tracking run over a recording from a hint: its ATE, tracked share and commits, printed
//! as a table row.

use nalgebra::Point3;
use omnitrack::capture::{Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::runtime::{track, RunOptions};
use omnitrack::tracker::{SearchVolume, TrackerEvent};
use omnitrack::trajectory::Stamped;
use omnitrack::Model;
use std::path::Path;
use std::time::Duration;

use crate::largest_sigma;
use omnitrack::desk::results::percentile;

/// What one tracking run over a recording gave.
pub(crate) struct RunOutcome {
    pub(crate) frames: u64,
    pub(crate) tracked: u64,
    pub(crate) ate_pos_cm: f64,
    pub(crate) ate_rot_deg: f64,
    pub(crate) commits: usize,
    pub(crate) wrong_commits: usize,
}

/// The configured search volume about the true start: the hint of the benchmark's runs.
pub(crate) fn hint_at_start(truth: &[Stamped], cfg: &TrackerConfig) -> SearchVolume {
    SearchVolume {
        centre: Point3::from(truth[0].pose.translation.vector),
        diameter_m: Some(cfg.initialisation.search_diameter_m),
    }
}

/// Tracks a whole recording once from `hint`, prints its table row and the lines under it.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_once(
    row: &str,
    name: &str,
    dir: &Path,
    model: &Model,
    table: &omnitrack::visibility::VisibilityTable,
    cfg: &TrackerConfig,
    truth: &[Stamped],
    hint: Option<SearchVolume>,
    tracker_seed: u64,
    verbose: bool,
) -> Option<RunOutcome> {
    let mut source = ReplaySource::open(dir, Pacing::AsFastAsPossible).unwrap();
    let opts = RunOptions {
        hint,
        seed: tracker_seed,
        max_frames: None,
    };
    let mut estimate: Vec<Stamped> = Vec::new();
    let mut pos_err = Vec::new();
    let mut rot_err = Vec::new();
    let mut latency = Vec::new();
    let mut busy = Duration::ZERO;
    // Commits (initial or after a loss), those > 30 cm or 3° off the truth, and frames
    // whose pose is that far off: a tracker may say "no pose", not give a wrong one.
    let (mut commits, mut wrong_commits, mut wrong_frames) = (0usize, 0usize, 0usize);
    let (mut relocs, mut wrong_relocs) = (0usize, 0usize);
    let stats = track(&mut source, model, table, cfg, &opts, &mut |r, tracker| {
        // A late record (a frame kept during a search, worked out later) took no frame time of
        // its own: its work is in the frame that worked it out.
        if !r.late {
            busy += r.frame_time;
            latency.push(r.frame_time.as_secs_f64() * 1e3);
        }
        if let Some(TrackerEvent::Searched(rep)) = r.result.event {
            if verbose {
                eprintln!(
                    "  search: {}/{} cells, {} triplet matches, {} samples, {:.0} ms (grid under {} rotations {:.0} ms){}",
                    rep.cells_searched,
                    rep.cells_in_volume,
                    rep.triplet_matches,
                    rep.samples,
                    rep.elapsed.as_secs_f64() * 1e3,
                    rep.rotations,
                    rep.grid_elapsed.as_secs_f64() * 1e3,
                    if rep.timed_out { " (timed out)" } else { "" }
                );
            }
        }
        let gt = truth
            .iter()
            .find(|s| s.timestamp_ns.abs_diff(r.timestamp_ns) < 1_000_000);
        if verbose {
            if let Some(g) = gt {
                for omnitrack::tracker::Weighed { pose: p, merit: score, frames, alive } in tracker.candidates() {
                    eprintln!(
                        "    candidate {:6.1} cm {:6.2}° score {:.2e} over {frames} frames{}",
                        (p.translation.vector - g.pose.translation.vector).norm() * 100.0,
                        p.rotation.angle_to(&g.pose.rotation).to_degrees(),
                        score,
                        if alive { "" } else { " (dropped)" }
                    );
                }
            }
        }
        if let Some(p) = &r.result.pose {
            estimate.push(Stamped {
                timestamp_ns: r.timestamp_ns,
                pose: *p,
            });
        }
        let err = match (&r.result.pose, gt) {
            (Some(p), Some(g)) => {
                let dp = (p.translation.vector - g.pose.translation.vector).norm();
                let dr = p.rotation.angle_to(&g.pose.rotation).to_degrees();
                pos_err.push(dp);
                rot_err.push(dr);
                Some((dp, dr))
            }
            _ => None,
        };
        let wrong = err.is_some_and(|(dp, dr)| dp > 0.3 || dr > 3.0);
        wrong_frames += usize::from(wrong);
        match r.result.event {
            Some(TrackerEvent::Committed { .. }) => {
                commits += 1;
                wrong_commits += usize::from(wrong);
            }
            Some(TrackerEvent::Relocalised) => {
                relocs += 1;
                wrong_relocs += usize::from(wrong);
            }
            _ => {}
        }
        if verbose {
            let r2 = &r.result;
            eprintln!(
                "{:4} {:?} {} σ {:5.1} cm expl {:.2} inl {:3} u/p/a {:?} samples {:4} edges {:4} match {:.2} solve {:.2} ms{}",
                r.sequence,
                r2.state,
                match err {
                    Some((dp, dr)) => format!("{:6.1} cm {:5.2}°", dp * 100.0, dr),
                    None => "      --         ".into(),
                },
                largest_sigma(&r2.covariance, 0) * 100.0,
                r2.explained,
                r2.inliers,
                r2.states,
                r2.samples,
                r.edges,
                r2.match_time.as_secs_f64() * 1e3,
                r2.solve_time.as_secs_f64() * 1e3,
                match r2.event {
                    Some(TrackerEvent::Committed {
                        candidates,
                        changed_mind,
                    }) => format!(" committed ({candidates} candidates, changed mind: {changed_mind})"),
                    Some(TrackerEvent::LostLock) => " LOST".into(),
                    Some(TrackerEvent::Relocalised) => " relocalised".into(),
                    _ => String::new(),
                }
            );
        }
        Ok(())
    })
    .unwrap();
    let init_ms = stats.first_search.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
    // The table's ATE is desk::eval's (the same numbers as `evo_ape tum`, checked by
    // tools/check_evo.py); the estimate is written beside the recording for evo itself.
    let est_path = dir.join("estimate.tum");
    std::fs::write(&est_path, omnitrack::trajectory::to_tum_string(&estimate)).unwrap();
    if estimate.is_empty() {
        println!("| {row} | {} | 0.0 % | no pose on any frame | | | | | |", stats.frames);
        return None;
    }
    let ev = omnitrack::desk::eval::evaluate(truth, &estimate, &omnitrack::desk::eval::EvalOptions::default()).unwrap();
    eprintln!(
        "{name}: evo_ape tum {} {} (ATE {:.4} m RMSE over {} poses)",
        dir.join("groundtruth.tum").display(),
        est_path.display(),
        ev.ate.translation_m.rmse,
        ev.ate.translation_m.count
    );
    let (pos_err, rot_err): (Vec<f64>, Vec<f64>) = ev
        .ate
        .per_pose
        .iter()
        .map(|e| (e.translation_m, e.rotation_deg))
        .unzip();
    let rmse = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let max = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    latency.sort_by(f64::total_cmp);
    println!(
        "| {row} | {} | {:.1} % ({:.1} %) | {} ({}) | {:.2} / {:.1} | {:.3} / {:.2} | {:.0} | {:.1} / {:.1} / {:.1} | {:.1} |",
        stats.frames,
        100.0 * stats.tracked as f64 / stats.frames.max(1) as f64,
        100.0 * (stats.tracked + stats.late_poses) as f64 / stats.frames.max(1) as f64,
        stats.reinitialisations,
        stats.relocalisations,
        rmse(&pos_err) * 100.0,
        max(&pos_err) * 100.0,
        rmse(&rot_err),
        max(&rot_err),
        init_ms,
        percentile(&latency, 0.5),
        percentile(&latency, 0.99),
        latency.last().copied().unwrap_or(f64::NAN),
        stats.frames as f64 / busy.as_secs_f64(),
    );
    eprintln!(
        "{name}: {} solves far from the prediction replaced by a second opinion",
        stats.second_opinions
    );
    eprintln!(
        "{name}: {commits} commits ({wrong_commits} wrong: > 30 cm or 3° off the truth), {relocs} relocalisations \
({wrong_relocs} wrong); {wrong_frames} frames with a pose that far off"
    );
    Some(RunOutcome {
        frames: stats.frames,
        tracked: stats.tracked,
        ate_pos_cm: rmse(&pos_err) * 100.0,
        ate_rot_deg: rmse(&rot_err),
        commits,
        wrong_commits,
    })
}
