//! The tracker alone, on edges detected beforehand: its CPU time per six-sensor frame (the frame
//! path's share of issue 51's "edges + tracking", item 3: ≤ 1 ms at p50) and a digest of every
//! answer it gives, bit for bit, so that a change meant to make tracking cheaper without changing
//! it can show both on one run.
//!
//! Each scenario's recording is the pipeline bench's (`lab`, `corridor`, `handheld` rendered at
//! 30 Hz, seed 11, the same cache): its frames' edges are detected once
//! (`EdgeDetector::for_tracking`, as the pipeline runs it) and held; then a fresh tracker (seed
//! 1, a 3 m hint about the first true pose, the searches on a worker thread as in the pipeline,
//! a lossless replay) tracks them `--passes N` times (default 3). Each frame's `process` is timed
//! by the calling thread's CPU clock (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`): the searches'
//! CPU is on the worker and not counted, as in the pipeline's "track" column. A frame's figure
//! is its least over the passes (other work on a shared machine only adds to it); the table gives
//! p50, p90, p99 and the mean over the frames with a pose from maintenance, and over all frames.
//!
//! The digest hashes every frame's result (state, pose, covariance, inliers, ξ, explained share,
//! samples drawn, correspondence counts, event) and every late result, from the first pass; the
//! other passes must give the same one (a pass that does not says so). The consensus's clock
//! backstop (`maintenance.time_budget_ms`) is moved out of reach so that the count of samples
//! decides, as it does on an idle machine; the searches stop on their work and give the same
//! result whatever the load, short of their wall-clock backstop (counted: a digest from a run
//! with backstops is not comparable).
//!
//! Run: `cargo bench --bench tracking` (needs the `desk` feature). Options after `--`:
//! `--scenario lab|corridor|handheld` (repeatable; default all three), `--frames N` (300),
//! `--passes N` (3), `--seed S` (11, the rendering's). Prints only: the pipeline bench's results
//! files hold the official figures.

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::Point3;
    use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
    use omnitrack::config::TrackerConfig;
    use omnitrack::desk::recording::{cached_scenario, RecordingOptions};
    use omnitrack::desk::results::percentile;
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::edges::{thread_cpu_time, Edge, EdgeDetector};
    use omnitrack::frame::FrameSet;
    use omnitrack::runtime::load_or_build_table;
    use omnitrack::tracker::{search_link, FrameResult, SearchVolume, Tracker, TrackerStats};
    use omnitrack::{Model, Rig};
    use std::hash::{Hash, Hasher};
    use std::path::{Path, PathBuf};
    use std::time::Duration;

    fn cache_root() -> PathBuf {
        omnitrack::desk::recording::cache_root(Path::new(env!("CARGO_MANIFEST_DIR")))
    }

    fn hash_result(h: &mut impl Hasher, r: &FrameResult) {
        format!("{:?}", r.state).hash(h);
        if let Some(p) = &r.pose {
            for v in p.translation.vector.iter().chain(p.rotation.coords.iter()) {
                v.to_bits().hash(h);
            }
        }
        for v in r.covariance.iter() {
            v.to_bits().hash(h);
        }
        (r.inliers, r.xi_rad2.to_bits(), r.explained.to_bits(), r.samples).hash(h);
        (r.states.unknown, r.states.pending, r.states.accepted).hash(h);
        format!("{:?}", r.event.map(|e| std::mem::discriminant(&e))).hash(h);
    }

    /// One pass: each frame's CPU time, the digest, and the stats.
    fn pass(
        rig: &Rig,
        model: &Model,
        table: &omnitrack::visibility::VisibilityTable,
        cfg: &TrackerConfig,
        hint: SearchVolume,
        frames: &[(u64, Vec<Edge>)],
    ) -> (Vec<(Duration, bool)>, u64, TrackerStats) {
        let (link, worker) = search_link();
        std::thread::scope(|scope| {
            scope.spawn(move || worker.run());
            let mut tracker = Tracker::new(rig, model, table, cfg, Some(hint), 1);
            tracker.attach_search_worker(link);
            let mut h = std::collections::hash_map::DefaultHasher::new();
            let mut times = Vec::with_capacity(frames.len());
            for (t, edges) in frames {
                let before = thread_cpu_time();
                let r = tracker.process(edges, *t);
                let cpu = thread_cpu_time().saturating_sub(before);
                // A maintenance frame: a pose, and no search taken up on it.
                times.push((cpu, r.pose.is_some() && r.event.is_none() && tracker.late().is_empty()));
                hash_result(&mut h, &r);
                for (lt, lr) in tracker.late() {
                    lt.hash(&mut h);
                    hash_result(&mut h, lr);
                }
            }
            tracker.finish();
            for (lt, lr) in tracker.late() {
                lt.hash(&mut h);
                hash_result(&mut h, lr);
            }
            (times, h.finish(), *tracker.stats())
        })
    }

    pub fn main() {
        let mut names = Vec::new();
        let (mut frames, mut passes, mut seed) = (300usize, 3usize, 11u64);
        let mut it = std::env::args().skip(1);
        while let Some(x) = it.next() {
            match x.as_str() {
                "--frames" => frames = it.next().and_then(|s| s.parse().ok()).expect("--frames N"),
                "--passes" => passes = it.next().and_then(|s| s.parse().ok()).expect("--passes N"),
                "--seed" => seed = it.next().and_then(|s| s.parse().ok()).expect("--seed S"),
                "--scenario" => {
                    let want = it.next().expect("--scenario lab|corridor|handheld");
                    names.push(
                        *ScenarioName::ALL
                            .iter()
                            .find(|n| n.as_str() == want)
                            .expect("--scenario lab|corridor|handheld"),
                    );
                }
                _ => {}
            }
        }
        if names.is_empty() {
            names = ScenarioName::ALL.to_vec();
        }
        let rig = Rig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware_config/ladybug2.toml")).unwrap();
        let mut cfg = TrackerConfig::default();
        cfg.maintenance.time_budget_ms = 1e6;
        println!(
            "load average before: {}",
            std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
        );
        println!("| scenario | frames | tracked | maintenance frames | CPU p50 / p90 / p99 / mean, maintenance (ms) | CPU p50 / mean, all frames (ms) | search backstops | digest |");
        println!("| --- | ---: | ---: | ---: | --- | --- | ---: | --- |");
        for name in names {
            let mut scenario = Scenario::get(name);
            scenario.frame_rate_hz = 30.0;
            let (rec, _) = cached_scenario(
                &cache_root(),
                &scenario,
                frames,
                seed,
                "30hz",
                &rig,
                &RecordingOptions::default(),
                |d, t| eprint!("\rrendering {}: {d}/{t}", name.as_str()),
            )
            .unwrap();
            let model_path = rec.join("model.obj");
            let model = Model::load(&model_path).unwrap();
            let (table, _) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
            let mut source = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
            let first = source.ground_truth().unwrap()[0].pose;
            let hint = SearchVolume {
                centre: Point3::from(first.translation.vector),
                diameter_m: Some(3.0),
            };
            let mut frame = FrameSet::for_rig(&rig);
            let mut detector = EdgeDetector::for_tracking(&rig, &cfg.edges);
            let mut held = Vec::new();
            while source.next_frame(&mut frame).unwrap() {
                held.push((frame.timestamp_ns().unwrap(), detector.detect(&frame).to_vec()));
            }
            drop(detector);
            let mut best: Vec<(Duration, bool)> = Vec::new();
            let mut digests = Vec::new();
            let mut stats = TrackerStats::default();
            let mut backstops = 0;
            for _ in 0..passes.max(1) {
                let (times, digest, s) = pass(&rig, &model, &table, &cfg, hint, &held);
                backstops += s.search_backstops - s.searches_cancelled;
                if best.is_empty() {
                    best = times;
                    stats = s;
                } else {
                    for (b, t) in best.iter_mut().zip(&times) {
                        b.0 = b.0.min(t.0);
                    }
                }
                digests.push(digest);
            }
            let ms = |v: &[f64], q: f64| percentile(v, q);
            let mut maint: Vec<f64> = best.iter().filter(|t| t.1).map(|t| t.0.as_secs_f64() * 1e3).collect();
            let mut all: Vec<f64> = best.iter().map(|t| t.0.as_secs_f64() * 1e3).collect();
            maint.sort_by(f64::total_cmp);
            all.sort_by(f64::total_cmp);
            // NaN over no frames, as the percentiles (a sum of none is −0.0).
            let mean = |v: &[f64]| {
                if v.is_empty() {
                    f64::NAN
                } else {
                    v.iter().sum::<f64>() / v.len() as f64
                }
            };
            let same = digests.iter().all(|d| *d == digests[0]);
            println!(
                "| {} | {} | {} | {} | {:.3} / {:.3} / {:.3} / {:.3} | {:.3} / {:.3} | {} | {:016x}{} |",
                name.as_str(),
                held.len(),
                stats.tracked,
                maint.len(),
                ms(&maint, 0.5),
                ms(&maint, 0.9),
                ms(&maint, 0.99),
                mean(&maint),
                ms(&all, 0.5),
                mean(&all),
                backstops,
                digests[0],
                if same { "" } else { " (passes differ)" }
            );
        }
        println!(
            "load average after: {}",
            std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim()
        );
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the tracking bench needs the `desk` feature");
}
