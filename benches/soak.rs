//! Soak (issue 50, item 9): the threaded device pipeline on a replay looped for 10,000 frames,
//! relocalising at least once every 100 frames, and the process's memory watched throughout.
//!
//! In: the `lab` scenario rendered through the shipped rig (`--rendered N` frames at the
//! scenario's 5 Hz, default 51, cached in `target/omnitrack-cache/` or `$OMNITRACK_CACHE`), held
//! decoded in memory and played back and forth (0, 1, …, 50, 49, …), restamped at 5 Hz, through
//! `run_pipeline` (lossless, pose and status published). Every `--every N` frames (100) the rig
//! jumps `--jump K` rendered frames further along its way (3: 0.57–0.80 m, where a frame moves
//! 0.19–0.27 m); there, and where it turns back (every 50 frames), the motion prior fails and
//! the tracker relocalises on its search thread (about 3.4 relocalisations per 100 frames).
//! Out, at frame 100 (tracking, the first search over) and every `--print-every N` frames
//! (1,000): the heap in use (bytes allocated and not yet freed, from a counting global allocator
//! over every thread), the resident set (`/proc/self/statm`), the allocations made since frame
//! 100 (every thread: frame path, search thread, capture and sink; iceoryx2's own
//! once-per-sample apart) and the relocalisations so far; at the end the growth of both from
//! frame 100 and from frame 1,000 on, printed and written to
//! `benches/results/DATE-MACHINE/soak.md` (`omnitrack::desk::results`). The done criterion:
//! flat within 1 MB after the first 1,000 frames. Before the start-up buffers were made resident
//! (`omnitrack_core::memory`) the resident set grew 2.1 MB between frames 100 and 1,000 here,
//! and 0.3 MB more by frame 10,000, with the heap flat throughout.
//!
//! Run: `cargo bench --bench soak` (needs the `desk` feature, on by default; about four minutes
//! on 2 cores). Options after `--`: `--frames N` (10,000), `--every N`, `--jump K`,
//! `--rendered N`, `--print-every N`, `--no-results` (print only). The source holds the rendered
//! frames decoded (3.5 MB each, 180 MB of the heap), so the replay decodes nothing per frame and
//! every allocation counted is the pipeline's.

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::Point3;
    use omnitrack::capture::{FrameSource, Pacing, ReplaySource, SourceError, SourceStats};
    use omnitrack::config::TrackerConfig;
    use omnitrack::desk::recording::{cached_scenario, RecordingOptions};
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::frame::FrameSet;
    use omnitrack::runtime::pipeline::{inside_publish, run_pipeline, FrameSink, PipelineOptions};
    use omnitrack::runtime::{load_or_build_table, FrameRecord, RunOptions, SinkError};
    use omnitrack::tracker::{SearchVolume, TrackerEvent};
    use omnitrack::{Model, Rig};
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::os::unix::fs::FileExt;
    use std::path::{Path, PathBuf};
    use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
    use std::sync::Arc;
    use std::time::Instant;

    /// Bytes allocated and not yet freed, by every thread: the heap the process holds, which a
    /// resident-set figure blurs with pages first touched late and the allocator's own arenas.
    static LIVE: AtomicI64 = AtomicI64::new(0);
    /// Allocations (and reallocations) while `COUNTING`, apart from those inside an iceoryx2
    /// publish (`PUBLISH`): iceoryx2 0.10 allocates once per sample it sends.
    static ALLOCS: AtomicU64 = AtomicU64::new(0);
    static PUBLISH: AtomicU64 = AtomicU64::new(0);
    static COUNTING: AtomicBool = AtomicBool::new(false);

    pub struct Counting;

    fn note() {
        if COUNTING.load(Ordering::Relaxed) {
            if inside_publish() {
                PUBLISH.fetch_add(1, Ordering::Relaxed);
            } else {
                ALLOCS.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            note();
            let p = unsafe { System.alloc(layout) };
            if !p.is_null() {
                LIVE.fetch_add(layout.size() as i64, Ordering::Relaxed);
            }
            p
        }
        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            note();
            let p = unsafe { System.alloc_zeroed(layout) };
            if !p.is_null() {
                LIVE.fetch_add(layout.size() as i64, Ordering::Relaxed);
            }
            p
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            note();
            let p = unsafe { System.realloc(ptr, layout, new_size) };
            if !p.is_null() {
                LIVE.fetch_add(new_size as i64 - layout.size() as i64, Ordering::Relaxed);
            }
            p
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            LIVE.fetch_sub(layout.size() as i64, Ordering::Relaxed);
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    fn cache_root() -> PathBuf {
        omnitrack::desk::recording::cache_root(Path::new(env!("CARGO_MANIFEST_DIR")))
    }

    /// The resident set read from `/proc/self/statm` through a file opened once and a fixed
    /// buffer: reading it allocates nothing, so the reading does not disturb what it measures.
    struct Resident {
        statm: std::fs::File,
        page: u64,
    }

    impl Resident {
        fn open() -> Resident {
            // SAFETY: sysconf only reads a system constant.
            let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(1) as u64;
            Resident {
                statm: std::fs::File::open("/proc/self/statm").expect("/proc/self/statm"),
                page,
            }
        }

        fn bytes(&self) -> u64 {
            let mut buf = [0u8; 128];
            let n = self.statm.read_at(&mut buf, 0).unwrap_or(0);
            // statm: size resident shared …, in pages.
            let mut fields = buf[..n].split(|b| *b == b' ');
            let _size = fields.next();
            let resident = fields.next().unwrap_or(b"0");
            let pages = resident
                .iter()
                .take_while(|b| b.is_ascii_digit())
                .fold(0u64, |a, b| a * 10 + u64::from(b - b'0'));
            pages * self.page
        }
    }

    /// Which rendered frame the `j`-th delivered frame shows: back and forth over `rendered`
    /// frames, and every `every` frames a jump of `jump` frames further the way the rig goes.
    pub(crate) struct Schedule {
        rendered: usize,
        every: usize,
        jump: usize,
        at: usize,
        forward: bool,
        j: usize,
    }

    impl Schedule {
        fn new(rendered: usize, every: usize, jump: usize) -> Schedule {
            Schedule {
                rendered,
                every: every.max(1),
                jump,
                at: 0,
                forward: true,
                j: 0,
            }
        }

        fn step(&mut self) {
            let last = self.rendered - 1;
            if self.forward && self.at == last {
                self.forward = false;
            } else if !self.forward && self.at == 0 {
                self.forward = true;
            }
            self.at = if self.forward { self.at + 1 } else { self.at - 1 };
        }

        fn next(&mut self) -> usize {
            if self.j > 0 {
                let steps = if self.j % self.every == 0 { 1 + self.jump } else { 1 };
                for _ in 0..steps {
                    self.step();
                }
            }
            self.j += 1;
            self.at
        }
    }

    /// The rendered frames, decoded once, delivered in the [`Schedule`]'s order and stamped at
    /// the recording's frame period, until the pipeline is stopped: a replay that decodes and
    /// allocates nothing per frame.
    struct Looped {
        rig: Rig,
        frames: Vec<FrameSet>,
        schedule: Schedule,
        period_ns: u64,
        delivered: usize,
        stats: SourceStats,
    }

    impl FrameSource for Looped {
        fn rig(&self) -> &Rig {
            &self.rig
        }
        fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
            let src = &self.frames[self.schedule.next()];
            let ts = (self.delivered as u64 + 1) * self.period_ns;
            for (o, s) in out.sensors_mut().iter_mut().zip(src.sensors()) {
                o.pixels_mut().copy_from_slice(s.pixels());
                o.set_valid(ts);
            }
            out.sequence = self.delivered as u64;
            self.delivered += 1;
            self.stats.frames_delivered += 1;
            Ok(true)
        }
        fn stats(&self) -> &SourceStats {
            &self.stats
        }
    }

    /// One line of the printed table.
    #[derive(Clone, Copy)]
    struct Sample {
        frames: usize,
        live: i64,
        resident: u64,
        allocs: u64,
        publish: u64,
        relocalised: u64,
        seconds: f64,
    }

    /// Counts the frames and relocalisations, and samples the memory at frame `early` and every
    /// `print_every` frames; the counting window opens at the first sample and closes at the
    /// last, after `total` frames, which stops the run: the threads' ends (a source's counters
    /// handed back) are not the frames' work.
    struct Watch {
        frames: usize,
        total: usize,
        /// A sample before the first print: tracking, the first search over.
        early: usize,
        print_every: usize,
        stop: Arc<AtomicBool>,
        relocalised: u64,
        resident: Resident,
        samples: Vec<Sample>,
        started: Instant,
    }

    impl Watch {
        fn note(&mut self, r: &FrameRecord) {
            if matches!(r.result.event, Some(TrackerEvent::Relocalised)) {
                self.relocalised += 1;
            }
        }
    }

    impl FrameSink for Watch {
        fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
            self.note(r);
            self.frames += 1;
            if self.frames == self.early || self.frames % self.print_every == 0 || self.frames == self.total {
                if self.samples.is_empty() {
                    COUNTING.store(true, Ordering::Relaxed);
                }
                let s = Sample {
                    frames: self.frames,
                    live: LIVE.load(Ordering::Relaxed),
                    resident: self.resident.bytes(),
                    allocs: ALLOCS.load(Ordering::Relaxed),
                    publish: PUBLISH.load(Ordering::Relaxed),
                    relocalised: self.relocalised,
                    seconds: self.started.elapsed().as_secs_f64(),
                };
                if self.samples.len() < self.samples.capacity() {
                    self.samples.push(s);
                }
                // Standard error is unbuffered: the line is written without an allocation.
                eprintln!(
                    "{:>6} frames  heap {:>9.3} MB  resident {:>8.3} MB  allocations {:>6} (+{} in iceoryx2 publish)  relocalised {:>4}  {:>6.1} s",
                    s.frames,
                    s.live as f64 / 1e6,
                    s.resident as f64 / 1e6,
                    s.allocs,
                    s.publish,
                    s.relocalised,
                    s.seconds
                );
            }
            if self.frames == self.total {
                COUNTING.store(false, Ordering::Relaxed);
                self.stop.store(true, Ordering::Relaxed);
            }
            Ok(())
        }
        fn late(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
            self.note(r);
            Ok(())
        }
    }

    /// The frame of the first sample: the first search is over (a second at 5 Hz), the tracker
    /// tracking, and no relocalisation yet.
    const EARLY: usize = 100;

    fn arg<T: std::str::FromStr>(it: &mut impl Iterator<Item = String>, what: &str) -> T {
        it.next()
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("{what}"))
    }

    pub fn main() {
        let mut frames = 10_000usize;
        let mut every = 100usize;
        let mut jump = 3usize;
        let mut rendered = 51usize;
        let mut print_every = 1_000usize;
        let mut write_results = true;
        let mut it = std::env::args().skip(1);
        while let Some(x) = it.next() {
            match x.as_str() {
                "--frames" => frames = arg(&mut it, "--frames N"),
                "--every" => every = arg(&mut it, "--every N"),
                "--jump" => jump = arg(&mut it, "--jump K"),
                "--rendered" => rendered = arg::<usize>(&mut it, "--rendered N").max(2),
                "--print-every" => print_every = arg::<usize>(&mut it, "--print-every N").max(1),
                "--no-results" => write_results = false,
                _ => {}
            }
        }
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let rig = Rig::load(&root.join("firmware_config/ladybug2.toml")).unwrap();
        let scenario = Scenario::get(ScenarioName::Lab);
        let (rec, made) = cached_scenario(
            &cache_root(),
            &scenario,
            rendered,
            11,
            "default",
            &rig,
            &RecordingOptions::default(),
            |d, t| eprint!("\rrendering lab: {d}/{t}"),
        )
        .unwrap();
        if made {
            eprintln!();
        }
        let cfg = TrackerConfig::default();
        let model_path = rec.join("model.obj");
        let model = Model::load(&model_path).unwrap();
        let (table, origin) = load_or_build_table(&model_path, &model, None, &cfg).unwrap();
        eprintln!("{origin}");
        let mut replay = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
        let truth = replay.ground_truth().unwrap().to_vec();
        let period_ns = truth[1].timestamp_ns - truth[0].timestamp_ns;
        let mut decoded = Vec::with_capacity(rendered);
        let mut frame = FrameSet::for_rig(&rig);
        while replay.next_frame(&mut frame).unwrap() {
            decoded.push(frame.clone());
        }
        drop(replay);
        let hint = SearchVolume {
            centre: Point3::from(truth[0].pose.translation.vector),
            diameter_m: Some(3.0),
        };
        let source = Looped {
            rig: rig.clone(),
            frames: decoded,
            schedule: Schedule::new(rendered, every, jump),
            period_ns,
            delivered: 0,
            stats: SourceStats::new(rig.sensors.len()),
        };
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos();
        let service = format!("omnitrack-bench/soak/{}/{nanos}", std::process::id());
        let opts = PipelineOptions {
            run: RunOptions {
                hint: Some(hint),
                seed: 1,
                max_frames: None,
            },
            pose_service: Some(service.clone()),
            status_service: Some(format!("{service}/status")),
            lossless: true,
            ..PipelineOptions::default()
        };
        let what = format!(
            "`lab` ({rendered} frames rendered at 5 Hz through the shipped rig, decoded in memory), \
             played back and forth for {frames} frames with a jump of {jump} frames every {every}, \
             through the threaded pipeline (lossless, poses and status published)"
        );
        eprintln!("soak: {what}");
        let mut watch = Watch {
            frames: 0,
            total: frames,
            early: EARLY.min(print_every),
            print_every,
            stop: Arc::clone(&opts.stop),
            relocalised: 0,
            resident: Resident::open(),
            samples: Vec::with_capacity(frames / print_every + 3),
            started: Instant::now(),
        };
        let source: Box<dyn FrameSource + Send> = Box::new(source);
        let summary = run_pipeline(source, &model, &table, &cfg, &opts, &mut watch).unwrap();
        COUNTING.store(false, Ordering::Relaxed);
        eprintln!("{summary}");
        let t = &summary.tracker;

        let mut table_md = String::new();
        table_md.push_str(&format!("Soak of {what}.\n\n"));
        table_md.push_str(&format!(
            "Tracker: {} frames, {} tracked, {} relocalisations, {} losses, {} re-initialisations, {} search waits, {} search backstops.\n\n",
            t.frames, t.tracked, t.relocalisations, t.losses, t.reinitialisations, t.search_waits, t.search_backstops
        ));
        table_md.push_str("| frames | heap in use (MB) | resident (MB) | allocations since the first row | inside iceoryx2 publish | relocalisations | time (s) |\n");
        table_md.push_str("| --- | --- | --- | --- | --- | --- | --- |\n");
        let first = watch.samples.first().copied();
        for s in &watch.samples {
            let base = first.unwrap_or(*s);
            table_md.push_str(&format!(
                "| {} | {:.3} | {:.3} | {} | {} | {} | {:.1} |\n",
                s.frames,
                s.live as f64 / 1e6,
                s.resident as f64 / 1e6,
                s.allocs - base.allocs,
                s.publish - base.publish,
                s.relocalised,
                s.seconds
            ));
        }
        // The criterion's stretch, from the print at `print_every` frames on; and the warm-up
        // before it, from the first sample, where the resident set used to creep up.
        let at = |frames: usize| watch.samples.iter().find(|s| s.frames == frames).copied();
        let mut growth = |from: Option<Sample>, what: &str| -> bool {
            let (Some(a), Some(b)) = (from, watch.samples.last()) else {
                return false;
            };
            let (heap, resident) = (
                (b.live - a.live) as f64 / 1e6,
                (b.resident as f64 - a.resident as f64) / 1e6,
            );
            let flat = heap.abs() <= 1.0 && resident.abs() <= 1.0;
            table_md.push_str(&format!(
                "\nFrom frame {} to {} ({what}): heap {heap:+.3} MB, resident {resident:+.3} MB, {} allocations outside \
                 iceoryx2's publish, over {} relocalisations: {} (flat within 1 MB).\n",
                a.frames,
                b.frames,
                b.allocs - a.allocs,
                b.relocalised - a.relocalised,
                if flat { "flat" } else { "NOT flat" }
            ));
            flat
        };
        growth(first, "tracking after the first search on");
        let met = growth(at(print_every), "the criterion: after the first 1,000 frames");
        table_md.push_str(&format!(
            "\nDone criterion (memory flat within 1 MB after the first {print_every} frames): {}.\n",
            if met { "met" } else { "NOT met" }
        ));
        println!();
        print!("{table_md}");
        if write_results {
            match omnitrack::desk::results::write(
                root,
                "soak",
                "Soak: memory over 10,000 looped frames with relocalisations (issue 50, item 9)",
                &format!(
                    "cargo bench --bench soak -- --frames {frames} --every {every} --jump {jump} --rendered {rendered}"
                ),
                &table_md,
            ) {
                Ok(path) => eprintln!("results in {}", path.display()),
                Err(e) => eprintln!("results file not written: {e}"),
            }
        }
    }

    #[global_allocator]
    static ALLOCATOR: Counting = Counting;
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the soak needs the `desk` feature");
}
