//! `zind_bench --diagnose`: per panorama, what the initialisation sees at the true pose (the
//! share of VIS(T) explained, the polished truth's scores) and the search's candidates, each
//! with the grid's coarse merit; the best wrong candidate drawn over the images.
//!
//! In: a panorama's recording, the model, its table, the config, a search volume and the truth.
//! Out: one line on stdout and `rival.jpg`; the rank of the truth among the candidates.

use super::*;

/// One line per panorama: the truth as the initialisation sees it, and the search's candidates.
#[allow(clippy::too_many_arguments)]
pub(crate) fn diagnose(
    dir: &Path,
    id: &str,
    model: &Model,
    table: &VisibilityTable,
    cfg: &TrackerConfig,
    volume: SearchVolume,
    seed: u64,
    truth: &Pose,
) -> Result<Option<usize>, String> {
    use omnitrack::capture::FrameSource;
    use omnitrack::edges::EdgeDetector;
    use omnitrack::frame::FrameSet;
    use omnitrack::tracker::{InitOptions, Initialiser};
    let mut source = ReplaySource::open(dir, Pacing::AsFastAsPossible).map_err(|e| e.to_string())?;
    let rig = source.rig().clone();
    let mut frame = FrameSet::for_rig(&rig);
    source.next_frame(&mut frame).map_err(|e| e.to_string())?;
    let mut detector = EdgeDetector::new(&rig, &cfg.edges);
    let edges = detector.detect(&frame).to_vec();
    let max_edges = rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize;
    let mut init = Initialiser::new(
        &rig,
        model,
        table,
        InitOptions::from_config(cfg),
        cfg.solver_options(),
        max_edges,
    );
    // The whole house is searched on the tracker's whole-model budget, as `run` does.
    if volume.diameter_m.is_none() {
        let budget = cfg.initialisation.whole_model_time_budget_ms / 1e3;
        init.set_time_budget(Duration::from_secs_f64(budget));
    }
    let cap2 = cfg.maintenance.inlier_angle_deg.to_radians().powi(2);
    let limit = (1.0 - cfg.initialisation.accept_explained_fraction) * cap2;
    let err = |p: &Pose| {
        (
            (p.translation.vector - truth.translation.vector).norm(),
            p.rotation.angle_to(&truth.rotation).to_degrees(),
        )
    };
    let at_truth = init.explained(truth, &edges);
    let vanishing = init
        .vanishing_rotations(&edges)
        .iter()
        .map(|r| r.angle_to(&truth.rotation).to_degrees())
        .fold(f64::INFINITY, f64::min);
    // How far the frame's vertical (the rotations share it) is from the truth's.
    let up_error = init.vanishing_rotations(&edges).first().map_or(f64::NAN, |r| {
        let up = |q: &nalgebra::UnitQuaternion<f64>| q.inverse() * Vector3::z();
        up(r).angle(&up(&truth.rotation)).to_degrees()
    });
    let polished = init.polish(truth, &edges);
    let mut line = format!(
        "{id:<8} edges {:>4} vanishing {vanishing:.1}° (vertical {up_error:.1}°)  truth: explained {:.2} score/limit {:.2}",
        edges.len(),
        at_truth,
        init.score(truth, &edges) / limit
    );
    match polished {
        Some(c) => {
            let (dp, dr) = err(&c.pose);
            let _ = write!(
                line,
                "  polished: {dp:.3} m {dr:.2}° merit {:.3} inliers {} explained {:.2} support {:.2} blank {:.2}",
                c.merit(),
                c.inliers,
                c.explained,
                c.support,
                c.blank
            );
        }
        None => line.push_str("  polished: none"),
    }
    let mut rank = None;
    let mut rival = None;
    let mut rng = SmallRng::seed_from_u64(seed);
    let (candidates, report) = init.run(&edges, &volume, &mut rng);
    let candidates = candidates.to_vec();
    let _ = write!(
        line,
        "  | search {} cells {:.0} ms (grid under {} rotations {:.0} ms):",
        report.cells_searched,
        ms(report.elapsed),
        report.rotations,
        ms(report.grid_elapsed)
    );
    let _ = write!(
        line,
        " grid merit: truth {:.3}",
        init.grid_merit(truth).unwrap_or(f64::NAN)
    );
    for (k, c) in candidates.iter().enumerate() {
        let (dp, dr) = err(&c.pose);
        let _ = write!(line, " ({:.3})", init.grid_merit(&c.pose).unwrap_or(f64::NAN));
        if dp <= 0.1 && dr <= 2.0 && rank.is_none() {
            rank = Some(k);
        }
        if rival.is_none() && (dp > 0.3 || dr > 5.0) {
            rival = Some(c.pose);
        }
        let _ = write!(
            line,
            " [{dp:.2} m {dr:.1}° z {:.2} merit {:.3} inliers {} expl {:.2} sup {:.2} blank {:.2} soft {:.2}]",
            c.pose.translation.vector.z,
            c.merit(),
            c.inliers,
            c.explained,
            c.support,
            c.blank,
            1.0 - c.score / cap2
        );
    }
    println!("{line}");
    // A picture of the best wrong candidate (over 0.3 m or 5° off): what it aligns with.
    if let Some(c) = rival {
        let images: Vec<_> = (0..rig.sensors.len())
            .map(|s| image::open(dir.join(image_path(rig.sensors[s].id, 0))).map(|i| i.to_rgb8()))
            .collect::<Result<_, _>>()
            .map_err(|e| format!("{}: {e}", dir.display()))?;
        let options = OmniOptions {
            title: format!(
                "{id}: the search's best wrong candidate, {:.2} m and {:.1}° from the truth",
                err(&c).0,
                err(&c).1
            ),
            segments: Some(in_sight(model, table, &c)),
            ..OmniOptions::default()
        };
        omni_view(&dir.join("rival.jpg"), &rig, &images, model, &c, &options).map_err(|e| e.to_string())?;
    }
    Ok(rank)
}
