//! The `--hold N` mode (the bench's doc): maintenance alone over stretches of a recording, each
//! started at the true pose. In: a recording, its ground truth, the tracker's config. Out: one
//! line per scenario, the share of frames whose pose (on time or late) is within 10 cm and 1° of
//! the truth, those more than 30 cm or 3° off, those without a pose, and the losses of lock.
//!
//! Issue 47's measure of a narrow or moving view: "≥ 90 % of frames after the first pose within
//! 10 cm / 1°". Started at the truth, the search is out of it: what is left is how maintenance
//! holds a view that turns past its lines (and what a loss's searches then make of it).

use omnitrack::capture::{FrameSource, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::edges::EdgeDetector;
use omnitrack::frame::FrameSet;
use omnitrack::tracker::{FrameResult, Tracker, TrackerEvent};
use omnitrack::trajectory::Stamped;
use omnitrack::{Model, Rig};

/// Frames per stretch: 18 s of `lab` or `corridor` (5 Hz), 6 s of `handheld` (15 Hz).
pub(crate) const HOLD_FRAMES: usize = 90;

/// What `hold` counted over every stretch of one recording.
#[derive(Default, Clone, Copy)]
pub(crate) struct HoldSummary {
    pub(crate) frames: usize,
    pub(crate) right: usize,
    pub(crate) wrong: usize,
    pub(crate) none: usize,
    pub(crate) losses: usize,
    /// Frames of fewer than `min_inliers` lines the motion filter took.
    pub(crate) filtered_few_lines: usize,
    /// Relocalisations, and of them those withdrawn unpublished (no later frame held the pose).
    pub(crate) relocalised: usize,
    pub(crate) withdrawn: usize,
}

impl HoldSummary {
    /// Adds another recording's counts.
    pub(crate) fn add(&mut self, o: &HoldSummary) {
        self.frames += o.frames;
        self.right += o.right;
        self.wrong += o.wrong;
        self.none += o.none;
        self.losses += o.losses;
        self.filtered_few_lines += o.filtered_few_lines;
        self.relocalised += o.relocalised;
        self.withdrawn += o.withdrawn;
    }

    /// A row of the results table.
    pub(crate) fn row(&self, name: &str) -> String {
        let pct = |n: usize| 100.0 * n as f64 / self.frames.max(1) as f64;
        format!(
            "| {name} | {} | {:.1} % | {:.1} % | {:.1} % | {} | {} ({}) | {} |",
            self.frames,
            pct(self.right),
            pct(self.wrong),
            pct(self.none),
            self.losses,
            self.relocalised,
            self.withdrawn,
            self.filtered_few_lines
        )
    }
}

/// The results table's header.
pub(crate) const HOLD_HEADER: &str = "| recording | frames | within 10 cm / 1° | more than 30 cm or 3° off | no pose | losses of lock | relocalised (withdrawn) | frames of few lines the filter took |\n| --- | --- | --- | --- | --- | --- | --- | --- |";

/// The `--hold N` mode (module doc): `stretches` starts spread over the recording.
#[allow(clippy::too_many_arguments)]
pub(crate) fn hold(
    name: &str,
    rig: &Rig,
    model: &Model,
    table: &omnitrack::visibility::VisibilityTable,
    cfg: &TrackerConfig,
    source: &mut ReplaySource,
    truth: &[Stamped],
    stretches: usize,
    verbose: bool,
) -> HoldSummary {
    let frames = source.frame_count();
    let spacing = (frames.saturating_sub(HOLD_FRAMES) / stretches.max(1)).max(1);
    let starts: Vec<usize> = (0..stretches)
        .map(|k| k * spacing)
        .filter(|&s| s + HOLD_FRAMES <= frames)
        .collect();
    let mut frame = FrameSet::for_rig(rig);
    let mut detector = EdgeDetector::new(rig, &cfg.edges);
    let mut sum = HoldSummary::default();
    let truth_at = |ts: u64| {
        truth
            .iter()
            .find(|s| s.timestamp_ns.abs_diff(ts) < 1_000_000)
            .map(|s| s.pose)
    };
    for (k, &start) in starts.iter().enumerate() {
        source.seek(start);
        let mut tracker = Tracker::new(rig, model, table, cfg, None, 1 + k as u64);
        // Each frame's pose by its time; late answers fill in the frames they belong to.
        let mut poses: Vec<(u64, Option<omnitrack::geometry::Pose>)> = Vec::with_capacity(HOLD_FRAMES);
        // With --verbose: each frame's edges, for taking apart a search that found nothing, and
        // the last pose a frame had (where the searches after a loss are centred).
        let mut kept_edges: Vec<Vec<omnitrack::edges::Edge>> = Vec::new();
        let mut last_pose = truth[start].pose;
        let mut diagnosed = 0;
        for i in 0..HOLD_FRAMES {
            if !source.next_frame(&mut frame).unwrap() {
                break;
            }
            let ts = frame.timestamp_ns().unwrap_or(0);
            let edges = detector.detect(&frame);
            let r: FrameResult = if i == 0 {
                tracker.start_at(&truth[start].pose, edges, ts)
            } else {
                tracker.process(edges, ts)
            };
            poses.push((ts, r.pose));
            if verbose {
                kept_edges.push(edges.to_vec());
            }
            for (lt, late) in tracker.late() {
                if let Some(slot) = poses.iter_mut().find(|(t, _)| t == lt) {
                    slot.1 = slot.1.or(late.pose);
                }
                if verbose {
                    let at = poses.iter().position(|(t, _)| t == lt).map_or(0, |j| start + j);
                    let err = late.pose.zip(truth_at(*lt)).map(|(p, g)| {
                        format!(
                            "{:.1} cm {:.2}°",
                            (p.translation.vector - g.translation.vector).norm() * 100.0,
                            p.rotation.angle_to(&g.rotation).to_degrees()
                        )
                    });
                    eprintln!(
                        "      late answer for frame {at}: {:?} {}{}",
                        late.state,
                        err.unwrap_or_else(|| "no pose".into()),
                        match late.event {
                            Some(TrackerEvent::LostLock) => " LOST",
                            Some(TrackerEvent::Relocalised) => " relocalised",
                            Some(TrackerEvent::Committed { .. }) => " committed",
                            Some(TrackerEvent::Searched(ref s)) => {
                                // The first searches after a loss, taken apart: the truth as
                                // their scores see it, and their candidates.
                                if diagnosed < 3 {
                                    if let Some(g) = truth_at(*lt) {
                                        diagnosed += 1;
                                        let j = poses.iter().position(|(t, _)| t == lt).unwrap_or(0);
                                        let volume = omnitrack::tracker::SearchVolume {
                                            centre: nalgebra::Point3::from(last_pose.translation.vector),
                                            diameter_m: s.diameter_m,
                                        };
                                        eprintln!(
                                            "{}",
                                            crate::detailed::diagnose(
                                                rig,
                                                model,
                                                table,
                                                cfg,
                                                &kept_edges[j],
                                                Some(volume),
                                                &g,
                                                1
                                            )
                                        );
                                    }
                                }
                                eprint!(
                                    " [searched: {} rotations, plan cells {} of {}, triplet cells {} of {}, diameter {:?}, work {}{}]",
                                    s.rotations,
                                    s.plan_cells_scanned,
                                    s.plan_cells_in_volume,
                                    s.cells_searched,
                                    s.cells_in_volume,
                                    s.diameter_m,
                                    s.work,
                                    if s.backstop { ", backstop" } else { "" }
                                );
                                ""
                            }
                            None => "",
                        }
                    );
                }
            }
            if let Some(p) = r.pose {
                last_pose = p;
            }
            if verbose {
                let err = r.pose.zip(truth_at(ts)).map(|(p, g)| {
                    format!(
                        "{:6.1} cm {:5.2}°",
                        (p.translation.vector - g.translation.vector).norm() * 100.0,
                        p.rotation.angle_to(&g.rotation).to_degrees()
                    )
                });
                // The published covariance's largest position σ: how well the frame's lines
                // (and the filter) fix the pose, beside how far it is from the truth.
                let sigma_cm = r.pose.map(|_| {
                    r.covariance
                        .fixed_view::<3, 3>(0, 0)
                        .symmetric_eigenvalues()
                        .max()
                        .max(0.0)
                        .sqrt()
                        * 100.0
                });
                eprintln!(
                    "    {name} stretch {k} frame {}: {:?} {} σ {} edges {} inliers {} explains {:.2} u/p/a {:?}{} | {}",
                    start + i,
                    r.state,
                    err.unwrap_or_else(|| "     --          ".into()),
                    sigma_cm.map_or_else(|| "  -- ".into(), |s| format!("{s:5.1}")),
                    edges.len(),
                    r.inliers,
                    r.explained,
                    r.states,
                    match r.event {
                        Some(TrackerEvent::LostLock) => " LOST",
                        Some(TrackerEvent::Relocalised) => " relocalised",
                        Some(TrackerEvent::Committed { .. }) => " committed",
                        Some(TrackerEvent::Searched(_)) => " searched",
                        None => "",
                    },
                    truth_at(ts).map_or_else(String::new, |g| truth_fit(rig, model, table, cfg, edges, &g, r.pose))
                );
            }
        }
        tracker.finish();
        // Losses are counted by the tracker: one concluded late (a relocalisation that found
        // nothing) carries its event in `late()`, not in the frame's own result.
        let losses = tracker.stats().losses as usize;
        sum.filtered_few_lines += tracker.stats().filtered_few_lines as usize;
        sum.relocalised += tracker.stats().relocalisations as usize;
        sum.withdrawn += tracker.stats().relocalisations_withdrawn as usize;
        for (lt, late) in tracker.late() {
            if let Some(slot) = poses.iter_mut().find(|(t, _)| t == lt) {
                slot.1 = slot.1.or(late.pose);
            }
        }
        let (mut right, mut wrong, mut none) = (0, 0, 0);
        for (ts, pose) in &poses {
            match pose.zip(truth_at(*ts)) {
                Some((p, g)) => {
                    let dp = (p.translation.vector - g.translation.vector).norm();
                    let dr = p.rotation.angle_to(&g.rotation).to_degrees();
                    right += usize::from(dp <= 0.10 && dr <= 1.0);
                    wrong += usize::from(dp > 0.30 || dr > 3.0);
                }
                None => none += 1,
            }
        }
        if verbose {
            eprintln!(
                "  {name} stretch {k} from frame {start}: {right} of {} within 10 cm / 1°, {wrong} wrong, {none} without a pose, {losses} losses",
                poses.len()
            );
        }
        sum.frames += poses.len();
        sum.right += right;
        sum.wrong += wrong;
        sum.none += none;
        sum.losses += losses;
    }
    let pct = |n: usize| 100.0 * n as f64 / sum.frames.max(1) as f64;
    println!(
        "{name}: held from the truth over {} stretches of {HOLD_FRAMES} frames: {:.1} % of {} frames within 10 cm / 1°, {:.1} % more than 30 cm or 3° off, {:.1} % without a pose, {} losses of lock, {} frames of few lines taken by the motion filter",
        starts.len(),
        pct(sum.right),
        sum.frames,
        pct(sum.wrong),
        pct(sum.none),
        sum.losses,
        sum.filtered_few_lines
    );
    sum
}

/// With `--verbose`: the pose the frame's own lines give when every segment in sight of the
/// true pose is matched there (the nearest edge within the inlier angle) and fitted from it.
/// Far from the truth, the lines themselves (their detection, or the model) carry the error;
/// near it, maintenance's matching or its sampling does.
fn truth_fit(
    rig: &Rig,
    model: &Model,
    table: &omnitrack::visibility::VisibilityTable,
    cfg: &TrackerConfig,
    edges: &[omnitrack::edges::Edge],
    truth: &omnitrack::geometry::Pose,
    tracked: Option<omnitrack::geometry::Pose>,
) -> String {
    use omnitrack::tracker::matching::{best_edge, correspondence, Gate, Predicted};
    let centres: Vec<_> = rig.sensors.iter().map(|s| s.centre()).collect();
    let Some(set) = table.query(&nalgebra::Point3::from(truth.translation.vector)) else {
        return "truth fit: no visibility set".into();
    };
    let gate = Gate::geometric(cfg.maintenance.inlier_angle_deg.to_radians());
    let min_len = cfg.edges.min_edge_length_deg.to_radians();
    let mut c = Vec::new();
    for &s in set.segments {
        let seg = &model.segments[s as usize];
        let ends = [seg.a, seg.b];
        let pred = Predicted::new(&ends, truth, &centres);
        if pred.length_rad < min_len {
            continue;
        }
        if let Some((e, _)) = best_edge(&pred, &centres, edges, &gate) {
            c.push(correspondence(&edges[e], &ends));
        }
    }
    let Some(p) = (c.len() >= 4)
        .then(|| omnitrack::solver::r_and_t_refine(&c, truth, &cfg.solver_options()))
        .flatten()
    else {
        return format!("truth fit: {} lines, no fit", c.len());
    };
    let mut scratch = vec![0.0; 2 * c.len()];
    let robust = omnitrack::solver::r_and_t_cauchy(&c, truth, &cfg.solver_options(), &mut scratch)
        .map_or(f64::NAN, |r| {
            (r.translation.vector - truth.translation.vector).norm() * 100.0
        });
    let from_tracked = tracked
        .and_then(|t| omnitrack::solver::r_and_t_cauchy(&c, &t, &cfg.solver_options(), &mut scratch))
        .map_or(f64::NAN, |r| {
            (r.translation.vector - truth.translation.vector).norm() * 100.0
        });
    let mut alphas: Vec<f64> = c
        .iter()
        .map(|k| omnitrack::geometry::Correspondence::alpha(k, truth).to_degrees())
        .collect();
    alphas.sort_by(f64::total_cmp);
    format!(
        "truth fit: {} lines, {:.1} cm {:.2}° from the truth (Cauchy {:.1} cm, from the tracked pose {:.1} cm), α at the truth median {:.2}° worst {:.2}°",
        c.len(),
        (p.translation.vector - truth.translation.vector).norm() * 100.0,
        p.rotation.angle_to(&truth.rotation).to_degrees(),
        robust,
        from_tracked,
        alphas[alphas.len() / 2],
        alphas[alphas.len() - 1]
    )
}
