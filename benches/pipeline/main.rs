//! The threaded pipeline end to end on a replayed `lab` recording: frames per second, drops, and
//! latency from capture (the frame complete in memory and handed to the pipeline) to the pose
//! sample received by a subscriber on another thread (iceoryx2 shared memory, event wake-up).
//!
//! The recording is `lab` rendered at 30 frames/s (the paper's is 5; at 5 the motion between
//! frames is six times a 30 Hz camera's, and a dropped frame means 0.4 s of walking). Three runs:
//! as fast as the replay decodes, lossless (throughput: capture waits for the tracker); and paced
//! like a 30 Hz camera with the latest frame winning (the device policy; the target: ≥ 30
//! frames/s on 2 cores, p99 latency < 33 ms, docs/design.md), once with the wearer standing still
//! until tracking starts (frame 0 repeated, then the walk), once walking from the first frame
//! (the frames that go by during the initialisation search are dropped, and the tracker must
//! catch up with the motion they held: that row measures the tracker's recovery as much as the
//! pipeline). Latency is over the frames after tracking started (the first frame processed, the
//! initialisation search, is reported apart as "init").
//! The load average is printed: other work on the machine slows every stage.
//!
//! Run: `cargo bench --bench pipeline` (needs the `desk` feature, on by default). Options after
//! `--`: `--frames N` (default 300), `--seed S` (default 11), `--hogs N` (N threads spinning at
//! the normal priority for the whole measurement: a machine busy with other work, issue 24's
//! "two CPU hogs"), `--scenario lab|corridor|handheld` (default `lab`), `--building SEED` (a
//! random building of issue 11 instead, `tracker` bench's `--buildings`, walked at 30 Hz), `--no-realtime` (the frame
//! path at the normal policy, `[budgets] realtime_priority = 0`, as where the OS refuses
//! `SCHED_FIFO`; the header says which the runs got), `--format png|qoi|ppm` (replay the
//! recording with its images in that format: the rendered PNGs re-recorded once with
//! `omnitrack_runtime::record`, cached beside them; default png), `--no-opencv` (skip the peers),
//! `--peer-frames N` (frames the edge detectors are compared on, default 20), `--no-results`
//! (print only), `--appearance SPEC` (render with `Appearance::from_spec(SPEC)`, e.g.
//! `realistic`, the preset of docs/real-photos.md; the recording and the results file are named
//! after it), `--view` (two more paced runs with the live view beside them, `view.rs`, and the
//! change of their p99 latency against the runs without). Recordings are cached in `target/omnitrack-cache/` (or `$OMNITRACK_CACHE`), as
//! for `benches/tracker/`.
//!
//! CPU (issue 51): besides wall-clock times, every run reports CPU time from the threads' own
//! CPU clocks (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, [`omnitrack::runtime::pipeline::CpuSummary`]):
//! per frame, the edge stage (every edge thread's share), the tracker and the whole frame path
//! (edges + tracker + publishing), the capture thread's per frame (reading and decoding the
//! recording), and per thread over the run (the search thread's included). The share of one core
//! at 30 Hz is the frame path's mean CPU per frame × 30; "all threads" is every pipeline thread's
//! CPU over the run divided by its wall time. A profile of where the time goes follows, from the
//! lossless run (capture, edge phases, tracker parts, publishing, search), the edge phases timed
//! by the detector itself (`ExtractionStats`, thread CPU clocks) on the first `--peer-frames`
//! frames, on this thread. Then OpenCV's FastLineDetector and LSD (`tools/bench_edges.py`, its
//! own venv with opencv-contrib-python-headless) on the same frames' images in the same run, on
//! one thread (`cv2.setNumThreads(1)`), their CPU time per six-sensor frame against ours on one
//! thread, and the ratio; ours as the pipeline runs it (`EdgeDetector::for_tracking`) and, a row
//! of its own, with the pieces each edge shows tested a contrario (a line detector's output). The load average (`/proc/loadavg`) before and after is in the header:
//! the CPU times are what other work disturbs least, the wall-clock ones are not. The tables go to
//! `benches/results/DATE-ARCH-Nc/pipeline-SCENARIO[-FORMAT][-hogsN].md`
//! (`omnitrack::desk::results`).

#[cfg(feature = "desk")]
mod bench {
    use crate::costs::{format_costs, run_peers, time_ours};
    use crate::runs::{converted, load_average, run};
    use nalgebra::Point3;
    use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
    use omnitrack::config::TrackerConfig;
    use omnitrack::desk::recording::{cached_building, cached_scenario, RecordingOptions};
    use omnitrack::desk::results::percentile;
    use omnitrack::desk::scenario::random::RandomBuilding;
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::edges::EdgeParams;

    use omnitrack::frame::FrameSet;

    use omnitrack::runtime::load_or_build_table;
    use omnitrack::runtime::pipeline::Stage;
    use omnitrack::runtime::record::ImageFormat;
    use omnitrack::tracker::SearchVolume;

    use omnitrack::{Model, Rig};
    use std::fmt::Write as _;
    use std::path::{Path, PathBuf};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    use std::time::Duration;

    fn cache_root() -> PathBuf {
        omnitrack::desk::recording::cache_root(Path::new(env!("CARGO_MANIFEST_DIR")))
    }

    pub fn main() {
        let mut frames = 300usize;
        let mut seed = 11u64;
        let mut hogs = 0usize;
        let mut realtime = true;
        let mut name = ScenarioName::Lab;
        let mut building: Option<u64> = None;
        let mut format = ImageFormat::Png;
        let mut opencv = true;
        let mut peer_frames = 20usize;
        let mut results = true;
        let mut appearance: Option<String> = None;
        let mut view = false;
        let mut it = std::env::args().skip(1);
        while let Some(x) = it.next() {
            match x.as_str() {
                "--frames" => frames = it.next().and_then(|s| s.parse().ok()).expect("--frames N"),
                "--seed" => seed = it.next().and_then(|s| s.parse().ok()).expect("--seed S"),
                "--hogs" => hogs = it.next().and_then(|s| s.parse().ok()).expect("--hogs N"),
                "--no-realtime" => realtime = false,
                "--no-opencv" => opencv = false,
                "--no-results" => results = false,
                "--view" => view = true,
                "--appearance" => appearance = Some(it.next().expect("--appearance SPEC")),
                "--peer-frames" => peer_frames = it.next().and_then(|s| s.parse().ok()).expect("--peer-frames N"),
                "--format" => {
                    format = it
                        .next()
                        .and_then(|s| ImageFormat::parse(&s))
                        .expect("--format png|qoi|ppm");
                }
                "--building" => {
                    building = Some(it.next().and_then(|s| s.parse().ok()).expect("--building SEED"));
                }
                "--scenario" => {
                    let want = it.next().expect("--scenario lab|corridor|handheld");
                    name = *ScenarioName::ALL
                        .iter()
                        .find(|n| n.as_str() == want)
                        .expect("--scenario lab|corridor|handheld");
                }
                _ => {}
            }
        }
        let rig = Rig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("firmware_config/ladybug2.toml")).unwrap();
        let mut options = RecordingOptions::default();
        let mut label = "30hz".to_string();
        if let Some(spec) = &appearance {
            options.appearance = omnitrack::desk::render::Appearance::from_spec(spec).unwrap_or_else(|e| {
                eprintln!("--appearance {e}");
                std::process::exit(2);
            });
            label = format!("30hz-{spec}");
        }
        let (rec, made, title) = match building {
            // A building nobody here drew (issue 11), walked at a camera's 30 Hz.
            Some(b) => {
                let mut b = RandomBuilding::new(b);
                b.frame_rate_hz = 30.0;
                let title = b.name();
                eprintln!("{title}: {b}");
                let (rec, made) = cached_building(&cache_root(), &b, frames, &label, &rig, &options, |d, t| {
                    eprint!("\rrendering {title}: {d}/{t}")
                })
                .unwrap();
                (rec, made, title)
            }
            None => {
                let mut scenario = Scenario::get(name);
                scenario.frame_rate_hz = 30.0;
                let (rec, made) = cached_scenario(
                    &cache_root(),
                    &scenario,
                    frames,
                    seed,
                    &label,
                    &rig,
                    &options,
                    |d, t| eprint!("\rrendering {}: {d}/{t}", name.as_str()),
                )
                .unwrap();
                let title = match &appearance {
                    Some(spec) => format!("{}-{spec}", name.as_str()),
                    None => name.as_str().to_string(),
                };
                (rec, made, title)
            }
        };
        if made {
            eprintln!();
        }
        // The images replayed: the rendered PNGs, or the same frames in another format.
        let replayed = match format {
            ImageFormat::Png => rec.clone(),
            other => converted(&rec, other),
        };
        let mut cfg = TrackerConfig::default();
        if !realtime {
            cfg.budgets.realtime_priority = 0;
        }
        let model_path = rec.join("model.obj");
        let model = Model::load(&model_path).unwrap();
        let (table, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
        eprintln!("{origin}");
        let first = ReplaySource::open(&rec, Pacing::AsFastAsPossible)
            .unwrap()
            .ground_truth()
            .unwrap()[0]
            .pose;
        let hint = SearchVolume {
            centre: Point3::from(first.translation.vector),
            diameter_m: Some(3.0),
        };
        let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
        let load = load_average();
        let pace = Some(Duration::from_nanos(33_333_333));
        // Busy threads for the whole measurement, as other programs on the rig's computer would be.
        let hogging = Arc::new(AtomicBool::new(true));
        let hog_threads: Vec<_> = (0..hogs)
            .map(|_| {
                let on = Arc::clone(&hogging);
                std::thread::spawn(move || {
                    let mut x = 0u64;
                    while on.load(Ordering::Relaxed) {
                        for _ in 0..10_000 {
                            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                        }
                    }
                })
            })
            .collect();
        let mut plan = vec![
            ("as fast as it decodes, lossless", None, true, false, false),
            (
                "paced 30 Hz, latest wins, standing still to start",
                pace,
                false,
                true,
                false,
            ),
            (
                "paced 30 Hz, latest wins, walking from the start",
                pace,
                false,
                false,
                false,
            ),
        ];
        if view {
            plan.push(("the same, standing still, with the live view", pace, false, true, true));
            plan.push(("the same, walking, with the live view", pace, false, false, true));
        }
        let runs: Vec<_> = plan
            .into_iter()
            .map(|(name, pace, lossless, still, view)| {
                run(
                    name, &replayed, &model, &table, &cfg, hint, frames, pace, lossless, still, view,
                )
            })
            .collect();

        // The edge detectors alone on the first frames, on this thread (hogs still running).
        let mut peer_source = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
        let peer_set: Vec<FrameSet> = (0..peer_frames)
            .map_while(|_| {
                let mut f = FrameSet::for_rig(&rig);
                peer_source.next_frame(&mut f).unwrap().then_some(f)
            })
            .collect();
        // As the pipeline runs it, and as a line detector's user gets it (the pieces each edge
        // shows tested a contrario: `omnitrack edges`, the YorkUrban benchmark).
        let ours = time_ours(&rig, &cfg, &peer_set, 3, EdgeParams::for_tracking());
        let ours_pieces = time_ours(&rig, &cfg, &peer_set, 3, EdgeParams::default());
        let formats = format_costs(&rec, &peer_set);
        let peers = if opencv {
            Some(run_peers(&rec, peer_set.len()))
        } else {
            None
        };
        hogging.store(false, Ordering::Relaxed);
        for h in hog_threads {
            let _ = h.join();
        }
        let load_after = load_average();

        let mut out = String::new();
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let _ = writeln!(
            out,
            "Threaded pipeline, replayed `{title}` at 30 Hz ({frames} frames of six 512×384 sensors, images as {}, {cores} cores, {hogs} CPU hogs, load average before: {load}, after: {load_after}; {}):",
            format.extension(),
            runs[1].summary.realtime
        );
        let _ = writeln!(out);
        let _ = writeln!(out, "| run | captured | processed | dropped | tracked | frames/s | init (ms) | latency p50 / p99 / max (ms) | sent p99 (ms) | edges p50 / p99 (ms) | track p50 / p99 (ms) | publish p50 / p99 (µs) | overruns edges / track / frame |");
        let _ = writeln!(
            out,
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
        );
        for r in &runs {
            let s = &r.summary;
            let e = s.stage(Stage::Edges);
            let t = s.stage(Stage::Track);
            let p = s.stage(Stage::Publish);
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.1} / {:.1} / {:.1} | {:.1} | {:.1} / {:.1} | {:.1} / {:.1} | {:.0} / {:.0} | {} / {} / {} |",
                r.name,
                s.frames_captured,
                s.frames_processed,
                s.frames_dropped,
                s.tracker.tracked,
                s.frame_rate_hz(),
                r.init_ms,
                percentile(&r.latency, 0.5),
                percentile(&r.latency, 0.99),
                r.latency.last().copied().unwrap_or(f64::NAN),
                ms(s.stage(Stage::Frame).p99),
                ms(e.p50),
                ms(e.p99),
                ms(t.p50),
                ms(t.p99),
                p.p50.as_secs_f64() * 1e6,
                p.p99.as_secs_f64() * 1e6,
                e.overruns,
                t.overruns,
                s.stage(Stage::Frame).overruns,
            );
            if r.received as u64 != s.poses_published {
                let _ = writeln!(
                    out,
                    "(run '{}': {} samples received of {} published)",
                    r.name, r.received, s.poses_published
                );
            }
        }
        for r in &runs {
            if let Some((v, received)) = &r.view {
                let _ = writeln!(
                    out,
                    "(run '{}': the view got {} poses, {} missed, wrote {} MCAP messages, sent {} image sets; its client received {} messages, {} lost)",
                    r.name, v.poses, v.poses_missed, v.mcap_messages, v.image_sets, received, v.ws_dropped
                );
            }
        }
        if view {
            let _ = writeln!(out);
            for (without, with) in [(1, 3), (2, 4)] {
                let (a, b) = (
                    percentile(&runs[without].latency, 0.99),
                    percentile(&runs[with].latency, 0.99),
                );
                let _ = writeln!(
                    out,
                    "Live view (issue 49: p99 within 10 % of without): '{}' p99 {a:.1} ms without, {b:.1} ms with the view ({:+.1} %).",
                    runs[without].name,
                    100.0 * (b / a - 1.0)
                );
            }
        }
        let rate = runs[1].summary.frame_rate_hz().min(runs[2].summary.frame_rate_hz());
        let p99 = [&runs[1], &runs[2]].map(|r| percentile(&r.latency, 0.99));
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "Target (docs/design.md): ≥ 30 frames/s, p99 latency < 33 ms on 2 cores — paced runs: {rate:.1} frames/s at least ({}), \
             p99 {:.1} standing / {:.1} walking ms ({}); unpaced throughput {:.1} frames/s.",
            if rate >= 29.5 { "met" } else { "NOT met" },
            p99[0],
            p99[1],
            if p99.iter().all(|&p| p < 33.0) { "met" } else { "NOT met" },
            runs[0].summary.frame_rate_hz()
        );

        // CPU (thread clocks).
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "CPU time (thread CPU clocks), per processed frame and per thread over the run:"
        );
        let _ = writeln!(out);
        let _ = writeln!(out, "| run | edges p50 / p99 (ms) | track p50 / p99 (ms) | edges + track p50 (ms) | frame path p50 / p99 / mean (ms) | share of one core at 30 Hz | capture per frame p50 (ms) | search thread (s) | all threads (s) / wall (s) = cores |");
        let _ = writeln!(out, "| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
        for r in &runs {
            let s = &r.summary;
            let c = &s.cpu;
            let _ = writeln!(
                out,
                "| {} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} | {:.2} / {:.2} / {:.2} | {:.1} % | {:.2} | {:.2} | {:.2} / {:.2} = {:.2} |",
                r.name,
                ms(c.edges.p50),
                ms(c.edges.p99),
                ms(c.track.p50),
                ms(c.track.p99),
                ms(c.edges.p50) + ms(c.track.p50),
                ms(c.frame.p50),
                ms(c.frame.p99),
                ms(c.frame.mean),
                ms(c.frame.mean) * 30.0 / 10.0,
                ms(c.capture.p50),
                c.search_total.as_secs_f64(),
                c.total().as_secs_f64(),
                s.elapsed.as_secs_f64(),
                c.total().as_secs_f64() / s.elapsed.as_secs_f64().max(1e-9),
            );
        }
        let _ = writeln!(
            out,
            "\nTarget (issue 51): edges + tracking ≤ 5 ms of CPU per frame at p50, ≤ 15 % of one core at 30 Hz paced. \
             \"edges + track p50\" adds the two medians; the share of one core is the frame path's mean × 30 Hz \
             (the search thread and capture apart)."
        );

        // Profile: where the time goes (lossless run, mean CPU per processed frame).
        let l = &runs[0].summary;
        let n = l.frames_processed.max(1) as f64;
        let c = &l.cpu;
        let capture = c.capture_total.as_secs_f64() * 1e3 / n;
        let edges = ms(c.edges.mean);
        let track = ms(c.track.mean);
        let publish = (ms(c.frame.mean) - edges - track).max(0.0);
        let search = c.search_total.as_secs_f64() * 1e3 / n;
        let rest = (c.total().as_secs_f64() * 1e3 / n - capture - edges - track - publish - search).max(0.0);
        let total = capture + edges + track + publish + search + rest;
        let pct = |x: f64| 100.0 * x / total.max(1e-9);
        let phase_sum: f64 = ours.phases.iter().sum::<f64>().max(1e-9);
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "Where the CPU goes (lossless run, mean per processed frame; edge phases split in the proportions the detector's own phase clocks give on {} frames, one thread; the tracker's in the proportions of its own wall-clock parts):",
            peer_set.len()
        );
        let _ = writeln!(out);
        let _ = writeln!(out, "| part | ms of CPU per frame | share |");
        let _ = writeln!(out, "| --- | ---: | ---: |");
        let mut row = |name: &str, x: f64| {
            let _ = writeln!(out, "| {name} | {x:.2} | {:.0} % |", pct(x));
        };
        row(
            &format!("capture: read and decode the {} images", format.extension()),
            capture,
        );
        row("edges", edges);
        for (k, label) in [
            "pixel pass (gradients, non-maximum suppression)",
            "chains (link, sub-pixel rays, fit, hue strips)",
            "merge across chains",
            "select (the strongest, into the rig frame)",
        ]
        .iter()
        .enumerate()
        {
            row(&format!("  edges: {label}"), edges * ours.phases[k] / phase_sum);
        }
        row("tracker (frame path)", track);
        // The tracker's CPU split in the proportions of its own wall-clock parts.
        let track_wall = ms(l.stage(Stage::Track).mean).max(1e-9);
        let matching = (ms(l.stage(Stage::Match).mean) / track_wall).min(1.0);
        let solving = (ms(l.stage(Stage::Solve).mean) / track_wall).min(1.0 - matching);
        row("  tracker: matching", track * matching);
        row("  tracker: solving", track * solving);
        row(
            "  tracker: the rest (prediction, gates, bookkeeping)",
            track * (1.0 - matching - solving),
        );
        row("publishing the pose", publish);
        row("search thread", search);
        row("sink and start-up", rest);
        let _ = writeln!(out, "| total | {total:.2} | 100 % |");

        // The edge detectors side by side, one thread, on the same images.
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "Edge detectors on the same {} six-sensor frames (PNG decoding excluded), one thread, 3 passes, CPU per frame:",
            peer_set.len()
        );
        let _ = writeln!(out);
        let _ = writeln!(out, "| detector | CPU p50 / p99 (ms per frame) | per image p50 (ms) | lines or edges per frame | ratio to ours (CPU p50) |");
        let _ = writeln!(out, "| --- | --- | ---: | ---: | ---: |");
        let ours_p50 = percentile(&ours.cpu_ms, 0.5);
        let _ = writeln!(
            out,
            "| omnitrack EdgeDetector (edges + hue), as the pipeline runs it | {:.2} / {:.2} | {:.2} | {:.1} | 1.00 |",
            ours_p50,
            percentile(&ours.cpu_ms, 0.99),
            ours_p50 / rig.sensors.len() as f64,
            ours.edges_per_frame
        );
        let pieces_p50 = percentile(&ours_pieces.cpu_ms, 0.5);
        let _ = writeln!(
            out,
            "| omnitrack EdgeDetector, with the pieces tested a contrario (a line detector's output) | {:.2} / {:.2} | {:.2} | {:.1} | {:.2} |",
            pieces_p50,
            percentile(&ours_pieces.cpu_ms, 0.99),
            pieces_p50 / rig.sensors.len() as f64,
            ours_pieces.edges_per_frame,
            pieces_p50 / ours_p50
        );
        match &peers {
            None => {
                let _ = writeln!(out, "| (OpenCV skipped: --no-opencv) | | | | |");
            }
            Some(Err(e)) => {
                let _ = writeln!(out, "| (OpenCV failed: {}) | | | | |", e.lines().last().unwrap_or(""));
            }
            Some(Ok(peers)) => {
                for p in peers {
                    let _ = writeln!(
                        out,
                        "| {} (grey, cv2.setNumThreads(1); wall p50 {:.2} ms) | {:.2} / {:.2} | {:.2} | {:.1} | {:.2} |",
                        p.name,
                        p.wall_p50_ms,
                        p.cpu_p50_ms,
                        p.cpu_p99_ms,
                        p.cpu_p50_ms / rig.sensors.len() as f64,
                        p.lines_per_frame,
                        p.cpu_p50_ms / ours_p50
                    );
                }
                let _ = writeln!(
                    out,
                    "\nRatio: the peer's CPU per frame over ours (below 1: the peer is cheaper). Target (issue 51): ours no slower than FastLineDetector."
                );
            }
        }
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "Recording formats, the same {} frames, one thread (CPU per six-sensor frame; reading back = the replay's `next_frame` from the page cache: file read, checks, decode):",
            peer_set.len()
        );
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "| format | encode (ms) | read back (ms) | MB per frame | read back, ratio to PNG |"
        );
        let _ = writeln!(out, "| --- | ---: | ---: | ---: | ---: |");
        let png_read = formats.first().map_or(f64::NAN, |f| f.decode_ms);
        for f in &formats {
            let _ = writeln!(
                out,
                "| {} | {:.2} | {:.2} | {:.2} | {:.2} |",
                f.format.extension(),
                f.encode_ms,
                f.decode_ms,
                f.bytes / 1e6,
                f.decode_ms / png_read
            );
        }
        println!();
        print!("{out}");
        if results {
            let root = Path::new(env!("CARGO_MANIFEST_DIR"));
            let mut file = format!("pipeline-{title}");
            if format != ImageFormat::Png {
                file.push_str(&format!("-{}", format.extension()));
            }
            if hogs > 0 {
                file.push_str(&format!("-hogs{hogs}"));
            }
            if view {
                file.push_str("-view");
            }
            let mut command = format!("cargo bench --bench pipeline -- --frames {frames}");
            match building {
                Some(b) => command.push_str(&format!(" --building {b}")),
                None => command.push_str(&format!(" --scenario {} --seed {seed}", name.as_str())),
            }
            if format != ImageFormat::Png {
                command.push_str(&format!(" --format {}", format.extension()));
            }
            if let Some(spec) = &appearance {
                command.push_str(&format!(" --appearance {spec}"));
            }
            if hogs > 0 {
                command.push_str(&format!(" --hogs {hogs}"));
            }
            if !realtime {
                command.push_str(" --no-realtime");
            }
            if view {
                command.push_str(" --view");
            }
            match omnitrack::desk::results::write(
                root,
                &file,
                &format!("Pipeline: `{title}`, CPU and wall time"),
                &command,
                &out,
            ) {
                Ok(path) => eprintln!("results: {}", path.display()),
                Err(e) => eprintln!("results not written: {e}"),
            }
        }
    }
}

#[cfg(feature = "desk")]
mod costs;
#[cfg(feature = "desk")]
mod runs;
#[cfg(feature = "desk")]
mod view;

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
}
