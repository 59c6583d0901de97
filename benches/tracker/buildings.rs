//! The `--buildings` mode (the bench's doc): walks through random buildings, the recall of
//! their visibility tables, tracking runs and initialisation trials.

use nalgebra::Point3;
use omnitrack::capture::{Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::desk::recording::RecordingOptions;
use omnitrack::desk::scenario::Motion;
use omnitrack::runtime::load_or_build_table;
use omnitrack::trajectory::Stamped;
use omnitrack::{Model, Rig};

use crate::init_trials::{init_trials, TrialSummary};
use crate::run::{hint_at_start, run_once, RunOutcome};
use crate::{cache_root, Args};
use omnitrack::desk::results::percentile;

/// The `--buildings` mode (module doc): per random building, a rendered walk, its visibility
/// table's recall along the walk, one tracking run and initialisation trials; then the table
/// over all of them.
pub(crate) fn buildings(a: &Args, rig: &Rig, label: &str, options: &RecordingOptions) {
    use omnitrack::desk::recording::cached_building;
    use omnitrack::desk::scenario::random::{Choices, RandomBuilding};
    use omnitrack::desk::vis_truth::{recall, Recall};
    let pins = match &a.pins {
        Some(spec) => Choices::parse(spec).unwrap_or_else(|e| {
            eprintln!("--pin: {e}");
            std::process::exit(2);
        }),
        None => Choices::default(),
    };
    // Pinned buildings are other buildings: cached apart.
    let label = match &a.pins {
        Some(spec) => format!("{label}-pin-{}", spec.replace(',', "-")),
        None => label.to_string(),
    };
    let label = label.as_str();
    use omnitrack::visibility::build::Occluders;
    struct Row {
        name: String,
        kind: String,
        segments: usize,
        nodes: u32,
        recall: Recall,
        run: Option<RunOutcome>,
        trials: TrialSummary,
    }
    let mut rows = Vec::new();
    for &seed in &a.buildings {
        let b = RandomBuilding::generate(seed, &pins);
        let name = b.name();
        let frames = (a.seconds * b.frame_rate_hz).round() as usize;
        eprintln!("{name}: {b}");
        let (dir, made) = cached_building(&cache_root(), &b, frames, label, rig, options, |d, t| {
            eprint!("\rrendering {name}: {d}/{t}")
        })
        .unwrap();
        if made {
            eprintln!();
        }
        let model_path = dir.join("model.obj");
        let model = Model::load(&model_path).unwrap();
        let cfg = match &a.config {
            Some(p) => TrackerConfig::load(p).unwrap(),
            None => TrackerConfig::default(),
        };
        let (table, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
        eprintln!("{name}: {origin}");
        let mut source = ReplaySource::open(&dir, Pacing::AsFastAsPossible).unwrap();
        let truth: Vec<Stamped> = source.ground_truth().unwrap().to_vec();
        // VIS(T) against brute force at every 10th pose of the walk.
        let scene = Occluders::new(&model);
        let eyes: Vec<Point3<f64>> = truth
            .iter()
            .step_by(10)
            .map(|s| Point3::from(s.pose.translation.vector))
            .collect();
        let rec = recall(&table, &scene, &model, &eyes);
        eprintln!(
            "{name}: VIS(T) recall {:.1} % of segments wider than 2° ({:.1} % of all visible), precision {:.1} %, at {} poses of the walk",
            rec.big_percent(),
            rec.all_percent(),
            rec.precision_percent(),
            eyes.len()
        );
        let hint = Some(hint_at_start(&truth, &cfg));
        let run = run_once(
            &name,
            &name,
            &dir,
            &model,
            &table,
            &cfg,
            &truth,
            hint,
            a.tracker_seeds[0],
            a.verbose,
        );
        let trials = if a.starts > 0 {
            init_trials(
                &name,
                rig,
                &model,
                &table,
                &cfg,
                &mut source,
                &truth,
                a.starts,
                a.verbose,
                false,
                false,
                1,
            )
        } else {
            TrialSummary::default()
        };
        let kind = format!(
            "{:?}, {}, {}{}{}",
            b.outline,
            match b.walls {
                omnitrack::desk::scenario::random::WallStyle::Thin => "thin",
                omnitrack::desk::scenario::random::WallStyle::Thick => "thick",
                omnitrack::desk::scenario::random::WallStyle::ThickOutside => "thick outside",
            },
            if b.storeys > 1 { "2 storeys, " } else { "" },
            if b.triangulated { "triangles, " } else { "" },
            match b.motion {
                Motion::Rolling3Dof { .. } => "cart",
                Motion::HandHeld6Dof => "hand-held",
            }
        );
        rows.push(Row {
            name,
            kind,
            segments: model.segments.len(),
            nodes: table.header.node_count,
            recall: rec,
            run,
            trials,
        });
    }
    println!();
    println!(
        "| building | kind | segments | nodes | VIS recall > 2° | tracked | ATE pos / rot RMSE (cm / °) | run commits (wrong) | starts: right / off (> 1 m or 10°) / none |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let (mut ate_p, mut ate_r, mut tracked) = (Vec::new(), Vec::new(), Vec::new());
    let (mut inits, mut wrong_inits, mut far_inits) = (0usize, 0usize, 0usize);
    for r in &rows {
        let t = &r.trials;
        let run = match &r.run {
            Some(o) => {
                let pct = 100.0 * o.tracked as f64 / o.frames.max(1) as f64;
                tracked.push(pct);
                ate_p.push(o.ate_pos_cm);
                ate_r.push(o.ate_rot_deg);
                inits += o.commits;
                wrong_inits += o.wrong_commits;
                format!(
                    "{pct:.1} % | {:.2} / {:.3} | {} ({})",
                    o.ate_pos_cm, o.ate_rot_deg, o.commits, o.wrong_commits
                )
            }
            None => {
                tracked.push(0.0);
                "0 % | no pose | 0 (0)".to_string()
            }
        };
        inits += t.right + t.wrong;
        wrong_inits += t.wrong;
        far_inits += t.far;
        println!(
            "| {} | {} | {} | {} | {:.1} % | {run} | {} / {} ({}) / {} of {} |",
            r.name,
            r.kind,
            r.segments,
            r.nodes,
            r.recall.big_percent(),
            t.right,
            t.wrong,
            t.far,
            t.none,
            t.counted
        );
    }
    ate_p.sort_by(f64::total_cmp);
    ate_r.sort_by(f64::total_cmp);
    tracked.sort_by(f64::total_cmp);
    let recall_all: Recall = rows.iter().fold(Recall::default(), |mut s, r| {
        s.visible_big += r.recall.visible_big;
        s.held_big += r.recall.held_big;
        s
    });
    println!();
    println!(
        "{} buildings: median ATE {:.2} cm / {:.3}°; fewest frames tracked {:.1} %; VIS recall > 2° {:.1} % overall; \
         {inits} commits (run commits and trial commits), {wrong_inits} of them off the truth ({:.1} %; run: > 30 cm or 3°, trials: > 10 cm or 1°), \
         {far_inits} trial commits more than 1 m or 10° off",
        rows.len(),
        percentile(&ate_p, 0.5),
        percentile(&ate_r, 0.5),
        tracked.first().copied().unwrap_or(f64::NAN),
        recall_all.big_percent(),
        100.0 * wrong_inits as f64 / inits.max(1) as f64
    );
}
