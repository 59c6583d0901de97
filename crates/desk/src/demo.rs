//! `omnitrack demo`: the whole pipeline on the embedded synthetic `lab` building, so that a
//! newcomer sees the tracker work, and how well, from one command on a fresh machine.
//!
//! In: [`DemoOptions`] (scenario, frames, seed, rig, cache directory, whether to show progress).
//! Out: in the cache directory, the rendered recording and its visibility table (made once,
//! reused afterwards) and the pictures in `<cache>/demo/`; a [`DemoReport`] whose `Display` is the
//! table printed by the command (accuracy against the ground truth with no alignment, speed,
//! initialisation time, the stage times and the pictures' paths). Progress bars and stage lines
//! go to standard error when asked for; every failure is one line.
//!
//! Steps: cache directory → recording ([`cached_scenario`]) → model and visibility table
//! ([`load_or_build_table`]) → tracking from a 3 m search volume around a point 1 m off the true
//! start ([`track`]) → evaluation ([`eval::evaluate`]) → pictures ([`pictures`]).
//!
//! Files: the run here; module `cache` where the recording and pictures are kept, module
//! `report` the printed table.

mod cache;
mod report;

use crate::eval::{self, EvalError, EvalOptions, Evaluation};
use crate::pictures::{self, CorrespondenceState, ErrorTrace, OmniOptions, PictureError, PlanOptions, StateTrace};
use crate::recording::{cached_scenario, RecordingError, RecordingOptions};
use crate::results::percentile;
use crate::scenario::{Scenario, ScenarioName};
pub use cache::CacheError;
use cache::{cache_label, choose_cache_dir, create_dir, join};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{Point3, Vector3};
use omnitrack_config::TrackerConfig;
use omnitrack_core::frame::FrameSet;
use omnitrack_core::geometry::Pose;
use omnitrack_core::model::{Model, ModelError};
use omnitrack_core::rig::{Rig, RigError};
use omnitrack_core::trajectory::Stamped;
use omnitrack_io::capture::{FrameSource, Pacing, ReplaySource, SourceError};
use omnitrack_runtime::{load_or_build_table, track, RunError, RunOptions};
use omnitrack_tracker::visibility::VisibilityError;
use omnitrack_tracker::SearchVolume;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The shipped rig, embedded so that the demo runs from any working directory.
const SHIPPED_RIG: &str = include_str!("../../../firmware_config/ladybug2.toml");
const SHIPPED_RIG_NAME: &str = "firmware_config/ladybug2.toml";

/// Frames of the default demo: 30 s at the lab's 5 Hz, which renders in about a minute on two
/// cores where the paper's full 1500 frames would take ten.
pub const DEMO_FRAMES: usize = 150;
/// Seed of the default demo's tour (the benchmark's, so that both share a cached recording).
pub const DEMO_SEED: u64 = 11;
/// Diameter of the initial search volume: a person's "I am about here" (Koch–Teller §5.3).
pub const HINT_DIAMETER_M: f64 = 3.0;
/// How far the search volume's centre is put from the true start: the hint is a guess, not the
/// answer.
pub const HINT_OFFSET: [f64; 3] = [0.8, -0.6, 0.0];
/// Sizes of the plots (the plan view uses [`PlanOptions::default`], the omni view the rig's
/// layout).
pub const ERROR_PLOT_SIZE: (u32, u32) = (1400, 800);
pub const STATES_PLOT_SIZE: (u32, u32) = (1400, 500);
/// Correspondences drawn in the state traces (Figure 14 shows a handful).
const TRACED: usize = 4;

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoOptions {
    /// Building and trajectory generator; a scenario whose plan differs from the built-in one
    /// of its name is cached under its own label.
    pub scenario: Scenario,
    pub frames: usize,
    pub seed: u64,
    /// `None`: the shipped Ladybug-class rig.
    pub rig: Option<Rig>,
    /// `None`: `$OMNITRACK_CACHE`, else the platform cache directory, else
    /// `target/omnitrack-cache` of this source tree, else the temporary directory.
    pub cache_dir: Option<PathBuf>,
    /// Progress bars and stage lines on standard error.
    pub progress: bool,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            scenario: Scenario::get(ScenarioName::Lab),
            frames: DEMO_FRAMES,
            seed: DEMO_SEED,
            rig: None,
            cache_dir: None,
            progress: true,
        }
    }
}

/// One picture written.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    pub name: &'static str,
    pub path: PathBuf,
}

/// Wall time of each stage.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    pub recording: Duration,
    pub table: Duration,
    /// The tracking run including the replay's PNG decoding.
    pub tracking: Duration,
    pub pictures: Duration,
    pub total: Duration,
}

/// What the demo found; `Display` is the report the command prints.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoReport {
    pub scenario: ScenarioName,
    pub frames_requested: usize,
    pub paper_frames: usize,
    pub frame_rate_hz: f64,
    pub seed: u64,
    pub cache_dir: PathBuf,
    /// Why this cache directory (which variable or fallback chose it).
    pub cache_origin: String,
    pub recording_dir: PathBuf,
    pub rendered_now: bool,
    /// Where the visibility table came from ([`load_or_build_table`]'s line).
    pub table_origin: String,
    pub hint: SearchVolume,
    pub first_truth: Point3<f64>,
    pub frames: u64,
    /// Frames answered with a pose on time, and more with a pose given late (kept during a
    /// search, `Tracker::late`).
    pub tracked: u64,
    pub late: u64,
    /// ATE (no alignment) position RMSE and max (m), rotation RMSE and max (degrees); `None`
    /// when no frame was tracked.
    pub ate_position_m: Option<(f64, f64)>,
    pub ate_rotation_deg: Option<(f64, f64)>,
    /// Wall time of the first initialisation search.
    pub init_time: Option<Duration>,
    /// First frame with a pose.
    pub first_pose_frame: Option<u64>,
    /// Frames per second of edge extraction + tracking (capture excluded).
    pub frames_per_s: f64,
    /// Per-frame latency (edges + tracking) percentiles, ms.
    pub latency_p50_ms: f64,
    pub latency_p99_ms: f64,
    pub reinitialisations: u64,
    pub losses: u64,
    pub relocalisations: u64,
    /// The evaluation's own table (ATE and RPE), for those who want more than the summary.
    pub evaluation_table: Option<String>,
    pub pictures: Vec<Picture>,
    /// Pictures not drawn, with why.
    pub skipped: Vec<String>,
    pub times: StageTimes,
}

/// Why the demo stopped; displays as one line.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("the demo needs at least one frame")]
    NoFrames,
    /// The cache directory given, or one the demo made inside the cache.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// `$OMNITRACK_CACHE` names a directory that does not work: reported, not papered over.
    #[error("$OMNITRACK_CACHE: {0}")]
    CacheVariable(CacheError),
    /// Every fallback failed, each for the reason listed.
    #[error("no usable cache directory (set $OMNITRACK_CACHE): {}", join(.tried))]
    NoCache { tried: Vec<CacheError> },
    #[error("{}: no groundtruth.tum", .recording.display())]
    NoGroundTruth { recording: PathBuf },
    #[error("{}: empty ground truth", .recording.display())]
    EmptyGroundTruth { recording: PathBuf },
    #[error("{}: recording ended before frame {frame}", .recording.display())]
    RecordingEnded { recording: PathBuf, frame: u64 },
    #[error(transparent)]
    Rig(#[from] RigError),
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Visibility(#[from] VisibilityError),
    #[error(transparent)]
    Replay(#[from] SourceError),
    #[error(transparent)]
    Tracking(#[from] RunError),
    #[error(transparent)]
    Evaluation(#[from] EvalError),
    #[error(transparent)]
    Picture(#[from] PictureError),
}

/// The per-user cache directory the desk tools share with the demo (`$OMNITRACK_CACHE`, else
/// `$XDG_CACHE_HOME/omnitrack`, else `~/.cache/omnitrack`, else a fallback named in the second
/// value), created and checked writable.
pub fn user_cache_dir() -> Result<(PathBuf, String), DemoError> {
    choose_cache_dir(None)
}

fn bar(show: bool, len: u64, template: &str) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar()));
    bar
}

/// Per segment that was accepted at some point: its state on every frame (unknown when it was
/// not in the tracker's table).
fn state_traces(per_frame: &[(f64, HashMap<u32, CorrespondenceState>)], frames: u64) -> Vec<StateTrace> {
    let mut accepted: HashMap<u32, (usize, usize)> = HashMap::new();
    for (_, states) in per_frame {
        for (&seg, &s) in states {
            if s == CorrespondenceState::Accepted {
                accepted.entry(seg).or_default().0 += 1;
            }
        }
    }
    for (seg, (_, changes)) in accepted.iter_mut() {
        let state = |k: usize| per_frame[k].1.get(seg).copied().unwrap_or(CorrespondenceState::Unknown);
        *changes = (1..per_frame.len()).filter(|&k| state(k) != state(k - 1)).count();
    }
    // Two held longest show a steady correspondence, two that changed state most show the
    // machine at work (Figure 14 shows both kinds); segment ids break ties so runs repeat.
    let mut by_held: Vec<(u32, usize, usize)> = accepted.iter().map(|(&s, &(a, c))| (s, a, c)).collect();
    by_held.sort_by_key(|&(s, a, c)| (std::cmp::Reverse(a), std::cmp::Reverse(c), s));
    let mut chosen: Vec<(u32, usize, usize)> = by_held.iter().take(TRACED / 2).copied().collect();
    let mut by_changes: Vec<(u32, usize, usize)> = by_held.iter().filter(|x| !chosen.contains(x)).copied().collect();
    by_changes.sort_by_key(|&(s, a, c)| (std::cmp::Reverse(c), std::cmp::Reverse(a), s));
    chosen.extend(by_changes.into_iter().take(TRACED - chosen.len()));
    chosen
        .into_iter()
        .map(|(seg, held, changes)| StateTrace {
            label: format!("segment {seg}: accepted {held}/{frames} frames, {changes} changes"),
            samples: per_frame
                .iter()
                .map(|(t, states)| (*t, states.get(&seg).copied().unwrap_or(CorrespondenceState::Unknown)))
                .collect(),
        })
        .collect()
}

/// The images of frame `index` of a recording, read again (the tracking run keeps none).
fn reread_frame(dir: &Path, index: u64) -> Result<Vec<image::RgbImage>, DemoError> {
    let mut source = ReplaySource::open(dir, Pacing::AsFastAsPossible)?;
    let mut frame = FrameSet::for_rig(source.rig());
    for _ in 0..=index {
        if !source.next_frame(&mut frame)? {
            return Err(DemoError::RecordingEnded {
                recording: dir.to_path_buf(),
                frame: index,
            });
        }
    }
    Ok(pictures::frame_images(&frame))
}

/// Runs the demo (see the module doc).
pub fn run_demo(opts: &DemoOptions) -> Result<DemoReport, DemoError> {
    let started = Instant::now();
    let say = |line: String| {
        if opts.progress {
            eprintln!("demo: {line}");
        }
    };
    if opts.frames == 0 {
        return Err(DemoError::NoFrames);
    }
    let scenario = &opts.scenario;
    let rig = match &opts.rig {
        Some(r) => r.clone(),
        None => Rig::from_toml_str(SHIPPED_RIG, SHIPPED_RIG_NAME)?,
    };
    let (cache_dir, cache_origin) = choose_cache_dir(opts.cache_dir.as_deref())?;
    say(format!("cache directory {} ({cache_origin})", cache_dir.display()));

    let t = Instant::now();
    let render_bar = bar(
        opts.progress,
        opts.frames as u64,
        "rendering {msg} [{bar:30}] {pos}/{len} frames, {elapsed}, eta {eta}",
    );
    render_bar.set_message(scenario.name.to_string());
    let (recording_dir, rendered_now) = cached_scenario(
        &cache_dir,
        scenario,
        opts.frames,
        opts.seed,
        &cache_label(scenario),
        &rig,
        &RecordingOptions::default(),
        |done, _| render_bar.set_position(done as u64),
    )?;
    render_bar.finish_and_clear();
    let recording_time = t.elapsed();
    say(format!(
        "recording {} ({})",
        recording_dir.display(),
        if rendered_now {
            format!("rendered in {:.1} s", recording_time.as_secs_f64())
        } else {
            "cached".into()
        }
    ));

    let t = Instant::now();
    let model_path = recording_dir.join("model.obj");
    let model = Model::load(&model_path)?;
    let cfg = TrackerConfig::default();
    let (table, table_origin) = load_or_build_table(&model_path, &model, None, &cfg)?;
    let table_time = t.elapsed();
    say(table_origin.clone());

    let t = Instant::now();
    let mut source = ReplaySource::open(&recording_dir, Pacing::AsFastAsPossible)?;
    let truth: Vec<Stamped> = source
        .ground_truth()
        .ok_or_else(|| DemoError::NoGroundTruth {
            recording: recording_dir.clone(),
        })?
        .to_vec();
    let first_truth = truth
        .first()
        .map(|s| Point3::from(s.pose.translation.vector))
        .ok_or_else(|| DemoError::EmptyGroundTruth {
            recording: recording_dir.clone(),
        })?;
    let hint = SearchVolume {
        centre: first_truth + Vector3::from(HINT_OFFSET),
        diameter_m: Some(HINT_DIAMETER_M),
    };
    let run = RunOptions {
        hint: Some(hint),
        seed: 1,
        max_frames: None,
    };
    let t0 = truth[0].timestamp_ns;
    let track_bar = bar(
        opts.progress,
        source.frame_count() as u64,
        "tracking  [{bar:30}] {pos}/{len} frames, {elapsed}, eta {eta}",
    );
    let mut estimate: Vec<Stamped> = Vec::new();
    let mut estimate_frame: Vec<u64> = Vec::new();
    let mut latency_ms: Vec<f64> = Vec::new();
    let mut busy = Duration::ZERO;
    let mut states: Vec<(f64, HashMap<u32, CorrespondenceState>)> = Vec::new();
    // Each frame's number by its timestamp: a late pose (a frame kept during a search, worked
    // out a few frames on) is drawn on its own frame's images.
    let mut frame_at: HashMap<u64, u64> = HashMap::new();
    let stats = track(&mut source, &model, &table, &cfg, &run, &mut |r, tracker| {
        if r.late {
            // The trajectory has it, as the TUM file does; its time and the correspondence
            // states belong to the frame it was worked out on.
            if let (Some(pose), Some(&frame)) = (r.result.pose, frame_at.get(&r.timestamp_ns)) {
                estimate.push(Stamped {
                    timestamp_ns: r.timestamp_ns,
                    pose,
                });
                estimate_frame.push(frame);
            }
            return Ok(());
        }
        frame_at.insert(r.timestamp_ns, r.sequence);
        busy += r.frame_time;
        latency_ms.push(r.frame_time.as_secs_f64() * 1e3);
        if let Some(pose) = r.result.pose {
            estimate.push(Stamped {
                timestamp_ns: r.timestamp_ns,
                pose,
            });
            estimate_frame.push(r.sequence);
        }
        let time_s = r.timestamp_ns.saturating_sub(t0) as f64 * 1e-9;
        let now = tracker.correspondences().iter().map(|c| (c.segment, c.state)).collect();
        states.push((time_s, now));
        track_bar.inc(1);
        Ok(())
    })?;
    track_bar.finish_and_clear();
    let tracking_time = t.elapsed();
    say(format!(
        "tracked {} of {} frames on time and {} more late (kept during a search) in {:.1} s",
        stats.tracked,
        stats.frames,
        stats.late_poses,
        tracking_time.as_secs_f64()
    ));

    // Timestamps of the estimate are the frames' earliest sensor times, which the recording
    // staggers by under a millisecond from the ground truth's frame times.
    let evaluation: Option<Evaluation> = if estimate.is_empty() {
        None
    } else {
        Some(eval::evaluate(&truth, &estimate, &EvalOptions::default())?)
    };

    let t = Instant::now();
    let out_dir = cache_dir.join("demo");
    create_dir(&out_dir)?;
    let mut written = Vec::new();
    let mut skipped = Vec::new();
    let title = format!(
        "{} building, {} frames at {} Hz (seed {})",
        scenario.name, stats.frames, scenario.frame_rate_hz, opts.seed
    );

    let path = out_dir.join("plan_view.png");
    let errors = evaluation
        .as_ref()
        .map(Evaluation::position_error_per_estimate)
        .unwrap_or_default();
    let plan = PlanOptions {
        title: format!("Ground truth and estimate over the floor plan: {title}"),
        ..PlanOptions::default()
    };
    pictures::plan_view(&path, &model, &truth, &estimate, &errors, &plan)?;
    written.push(Picture {
        name: "plan view",
        path,
    });

    match pick_frame(&estimate_frame, &estimate, stats.frames) {
        Some((index, pose)) => {
            let path = out_dir.join("omni_view.png");
            let images = reread_frame(&recording_dir, index)?;
            let omni = OmniOptions {
                title: format!("Frame {index}: model re-projected at the estimated pose"),
                // The visibility set stands in for occlusion, so walls behind walls stay hidden.
                segments: table
                    .query(&Point3::from(pose.translation.vector))
                    .map(|s| s.segments.iter().map(|&i| i as usize).collect()),
                ..OmniOptions::default()
            };
            pictures::omni_view(&path, &rig, &images, &model, &pose, &omni)?;
            written.push(Picture {
                name: "omni view",
                path,
            });
        }
        None => skipped.push("omni view: no frame was tracked".into()),
    }

    match &evaluation {
        Some(ev) => {
            let path = out_dir.join("error_over_time.png");
            let trace = ErrorTrace {
                label: "ATE, no alignment",
                errors: &ev.ate.per_pose,
            };
            pictures::error_over_time(&path, &format!("Error over time: {title}"), &[trace], ERROR_PLOT_SIZE)?;
            written.push(Picture {
                name: "error over time",
                path,
            });
        }
        None => skipped.push("error over time: no frame was tracked".into()),
    }

    let traces = state_traces(&states, stats.frames);
    if traces.is_empty() {
        skipped.push("correspondence states: no correspondence was ever accepted".into());
    } else {
        let path = out_dir.join("correspondence_states.png");
        pictures::correspondence_states(
            &path,
            &format!("Correspondence states (Figure 14): {title}"),
            &traces,
            STATES_PLOT_SIZE,
        )?;
        written.push(Picture {
            name: "correspondence states",
            path,
        });
    }
    let pictures_time = t.elapsed();

    latency_ms.sort_by(f64::total_cmp);
    let ate = evaluation.as_ref().map(|e| &e.ate);
    Ok(DemoReport {
        scenario: scenario.name,
        frames_requested: opts.frames,
        paper_frames: scenario.paper_frames,
        frame_rate_hz: scenario.frame_rate_hz,
        seed: opts.seed,
        cache_dir,
        cache_origin,
        recording_dir,
        rendered_now,
        table_origin,
        hint,
        first_truth,
        frames: stats.frames,
        tracked: stats.tracked,
        late: stats.late_poses,
        ate_position_m: ate.map(|a| (a.translation_m.rmse, a.translation_m.max)),
        ate_rotation_deg: ate.map(|a| (a.rotation_deg.rmse, a.rotation_deg.max)),
        init_time: stats.first_search,
        first_pose_frame: estimate_frame.first().copied(),
        frames_per_s: if busy > Duration::ZERO {
            stats.frames as f64 / busy.as_secs_f64()
        } else {
            f64::NAN
        },
        latency_p50_ms: percentile(&latency_ms, 0.5),
        latency_p99_ms: percentile(&latency_ms, 0.99),
        reinitialisations: stats.reinitialisations,
        losses: stats.losses,
        relocalisations: stats.relocalisations,
        evaluation_table: evaluation.as_ref().map(Evaluation::table),
        pictures: written,
        skipped,
        times: StageTimes {
            recording: recording_time,
            table: table_time,
            tracking: tracking_time,
            pictures: pictures_time,
            total: started.elapsed(),
        },
    })
}

/// The tracked frame nearest the middle of the run, and its estimated pose.
fn pick_frame(frames: &[u64], estimate: &[Stamped], total: u64) -> Option<(u64, Pose)> {
    let middle = total / 2;
    frames
        .iter()
        .zip(estimate)
        .min_by_key(|(f, _)| f.abs_diff(middle))
        .map(|(&f, s)| (f, s.pose))
}
