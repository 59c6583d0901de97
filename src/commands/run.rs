//! `omnitrack run`: frames from a source (replay, V4L2, USB3 Vision) through the threaded
//! pipeline, poses on the iceoryx2 pose service and, if asked, a TUM trajectory; progress and
//! the summary on standard error.

mod mcap;
mod report;

use super::CommandResult;
use omnitrack::capture::SourceSpec;
use omnitrack::config::TrackerConfig;
use omnitrack::{Model, Rig};
use std::path::{Path, PathBuf};

/// `run`'s arguments (docs/interfaces.md).
#[derive(clap::Args)]
pub struct Args {
    /// The rig (a replay recording's own rig.toml is used when this is omitted).
    #[arg(long, value_name = "RIG.toml")]
    rig: Option<PathBuf>,
    /// The building model (OBJ, metres, z up).
    #[arg(long, value_name = "MODEL.obj")]
    model: PathBuf,
    /// Prior visibility table (default: MODEL.vis beside the model, built if absent).
    #[arg(long, value_name = "TABLE.vis")]
    visibility: Option<PathBuf>,
    /// replay:DIR, v4l or usb.
    #[arg(long, value_name = "replay:DIR|v4l|usb")]
    source: SourceSpec,
    /// Initial search volume: centre x,y,z and optionally its radius in metres (default: half
    /// of [initialisation] search_diameter_m of tracker.toml, i.e. a 3 m volume).
    #[arg(long, value_name = "x,y,z[,radius_m]", allow_hyphen_values = true)]
    init: Option<String>,
    /// Write the trajectory (TUM) here.
    #[arg(long, value_name = "OUT.tum")]
    trajectory: Option<PathBuf>,
    /// Tracker tunables (default: the shipped firmware_config/tracker.toml values).
    #[arg(long, value_name = "tracker.toml")]
    config: Option<PathBuf>,
    /// Stop after N frames.
    #[arg(long)]
    frames: Option<u64>,
    /// Do not publish on iceoryx2.
    #[arg(long)]
    no_publish: bool,
    /// Service prefix: poses on PREFIX/pose, status on PREFIX/status. A second tracker on the
    /// same computer (another rig) takes another prefix; `omnitrack listen --services` follows it.
    #[arg(long, value_name = "PREFIX", default_value = "omnitrack")]
    services: String,
    /// Replay at the recorded frame rate (default: as fast as the tracker goes).
    #[arg(long)]
    realtime: bool,
    /// Print the run's summary as one JSON object on standard output at the end (fields in
    /// docs/interfaces.md); the human lines stay on standard error.
    #[arg(long)]
    json: bool,
    /// Also write the run to this MCAP file (replaced if it exists): poses, status, the model
    /// and, for a replay, the images, as the live view has them. The omnitrack-view program,
    /// found beside omnitrack or on PATH, writes it, subscribed before the first frame.
    #[arg(long, value_name = "FILE.mcap", conflicts_with = "no_publish")]
    mcap: Option<PathBuf>,
}

/// `--init x,y,z[,radius_m]` (docs/interfaces.md): the search volume's centre and radius; without
/// a radius, the configured diameter.
fn parse_init(text: &str, default_diameter: f64) -> Result<omnitrack::tracker::SearchVolume, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("--init {text:?}: expected x,y,z or x,y,z,radius_m (numbers)"))?;
    if !(v.len() == 3 || v.len() == 4) || v.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "--init {text:?}: expected x,y,z or x,y,z,radius_m (finite numbers)"
        ));
    }
    let diameter = v.get(3).map(|r| 2.0 * r).unwrap_or(default_diameter);
    if diameter <= 0.0 {
        return Err(format!("--init {text:?}: the radius must be positive"));
    }
    Ok(omnitrack::tracker::SearchVolume {
        centre: nalgebra::Point3::new(v[0], v[1], v[2]),
        diameter_m: Some(diameter),
    })
}

pub fn run(a: Args) -> CommandResult {
    use omnitrack::capture::{Pacing, SourceOptions};
    use omnitrack::runtime::load_or_build_table;
    use omnitrack::runtime::pipeline::{init_logging, open_pipeline_source, run_pipeline, PipelineOptions, TumSink};
    use omnitrack::runtime::RunOptions;

    let (pose_service, status_service) = (
        super::service_name(&a.services, "pose")?,
        super::service_name(&a.services, "status")?,
    );
    let inputs = [Some(&a.model), a.rig.as_ref(), a.visibility.as_ref(), a.config.as_ref()];
    if let Some(out) = &a.trajectory {
        refuse_to_overwrite("--trajectory", out, inputs.into_iter().flatten())?;
    }
    // Everything `--mcap` needs is checked before anything is loaded or tracked.
    let view = match &a.mcap {
        Some(file) => {
            refuse_to_overwrite("--mcap", file, inputs.into_iter().flatten())?;
            mcap::check_writable(file)?;
            Some(mcap::find_view()?)
        }
        None => None,
    };
    init_logging();
    let cfg = match &a.config {
        Some(p) => TrackerConfig::load(p)?,
        None => TrackerConfig::default(),
    };
    let hint = a
        .init
        .as_deref()
        .map(|t| parse_init(t, cfg.initialisation.search_diameter_m))
        .transpose()?;
    let rig = a.rig.as_deref().map(Rig::load).transpose()?;
    let options = SourceOptions {
        pacing: if a.realtime {
            Pacing::RealTime
        } else {
            Pacing::AsFastAsPossible
        },
        ..SourceOptions::default()
    };
    // The model before the cameras: a model that cannot be used fails before a device is opened.
    let model = Model::load(&a.model)?;
    if model.segments.is_empty() {
        return Err(format!(
            "{}: the model has no segments: nothing for the edges to match",
            a.model.display()
        )
        .into());
    }
    let source = open_pipeline_source(&a.source, rig.as_ref(), &options)?;
    let (table, origin) = load_or_build_table(&a.model, &model, a.visibility.as_deref(), &cfg)?;
    eprintln!("omnitrack: {origin}");
    let mut sink = RunSink::new(
        a.trajectory.as_deref().map(TumSink::create).transpose()?,
        cfg.initialisation.sweep_volume,
        hint.and_then(|h| h.diameter_m),
    );
    let publish = (!a.no_publish).then_some(());
    let opts = PipelineOptions {
        run: RunOptions {
            hint,
            seed: 1,
            max_frames: a.frames,
        },
        handle_signals: true,
        pose_service: publish.map(|_| pose_service),
        status_service: publish.map(|_| status_service),
        // A replay not paced in real time would otherwise race ahead while the tracker works.
        lossless: !a.realtime && a.source.is_replay(),
        ..PipelineOptions::default()
    };
    let recorder = match (&view, &a.mcap) {
        (Some(program), Some(file)) => Some(mcap::McapRecorder::start(&mcap::ViewArgs {
            program,
            file,
            services: &a.services,
            model: &a.model,
            recording: match &a.source {
                omnitrack::capture::SourceSpec::Replay(dir) => Some(dir),
                _ => None,
            },
        })?),
        _ => None,
    };
    let summary = run_pipeline(source, &model, &table, &cfg, &opts, &mut sink)?;
    // Right after the last sample: the view has all of them in its buffers, and its summary
    // comes before the run's.
    let mcap_line = recorder.map(mcap::McapRecorder::finish);
    if let Some(e) = &summary.publisher_error {
        return Err(format!(
            "cannot publish: {e} (`--no-publish` tracks without publishing; another user's tracker, or files \
             it left in /dev/shm, can hold the service)"
        )
        .into());
    }
    let stats = &summary.tracker;
    let poses = sink.on_time + sink.late;
    eprintln!(
        "omnitrack: {} frames, {} with a pose ({:.1} %): {} on time, {} late (kept during a search, worked out after it); \
         {} losses, {} re-initialisations, {} relocalisations",
        summary.frames_processed,
        poses,
        100.0 * poses as f64 / summary.frames_processed.max(1) as f64,
        sink.on_time,
        sink.late,
        stats.losses,
        stats.reinitialisations,
        stats.relocalisations
    );
    eprintln!("omnitrack: {summary}");
    if stats.searches_cancelled > 0 {
        // Half a search may have missed the rival that would have refused its winner.
        eprintln!(
            "omnitrack: {} search(es) cut short by the stop: no pose from them",
            stats.searches_cancelled
        );
    }
    if let Some(line) = &mcap_line {
        eprintln!("omnitrack: {line}");
    }
    let no_pose = (poses == 0).then(|| no_pose_reason(&summary, &sink));
    let code = if no_pose.is_some() {
        super::exit::NO_POSE
    } else {
        super::exit::SUCCESS
    };
    if a.json {
        super::print_json(&report::RunReport::new(
            &summary,
            &sink,
            a.trajectory.as_deref(),
            no_pose.as_deref(),
            code,
        ))?;
    }
    if let Some(reason) = &no_pose {
        eprintln!("omnitrack: no pose: {reason}");
    }
    match code {
        super::exit::SUCCESS => Ok(()),
        code => Err(Box::new(super::Exit(code))),
    }
}

/// What `run` counts of the frames handed to its sink, writes to the trajectory if asked, and
/// says on standard error as it goes (searches, commits, losses, a long search's progress).
pub struct RunSink {
    tum: Option<omnitrack::runtime::pipeline::TumSink>,
    /// Frames with a pose of their own, and earlier frames' poses worked out late (kept during
    /// a search): together, every pose the run found.
    on_time: u64,
    late: u64,
    /// The first frame's and the first pose's capture times.
    first_frame_ns: Option<u64>,
    first_pose_ns: Option<u64>,
    /// Searches reported, those that had no cell to search, and those widened to the nearest
    /// valid nodes: why no pose came out, if none did.
    searches: u64,
    empty: u64,
    widened: u64,
    /// `initialisation.sweep_volume`: a search that left cells is followed by one that goes
    /// on with them.
    sweeps: bool,
    /// The hint's diameter (m), and the widest volume a search reported: a hint that grew with
    /// the walk the rig may have made before its first pose (the tracker's `hint_age`).
    hint_m: Option<f64>,
    widest_m: f64,
}

impl RunSink {
    fn new(tum: Option<omnitrack::runtime::pipeline::TumSink>, sweeps: bool, hint_m: Option<f64>) -> RunSink {
        RunSink {
            tum,
            sweeps,
            hint_m,
            widest_m: 0.0,
            on_time: 0,
            late: 0,
            first_frame_ns: None,
            first_pose_ns: None,
            searches: 0,
            empty: 0,
            widened: 0,
        }
    }

    /// The events of a record (a frame's own, or a late one), on standard error.
    fn say(&mut self, r: &omnitrack::runtime::FrameRecord) {
        use omnitrack::tracker::TrackerEvent;
        match r.result.event {
            Some(TrackerEvent::Searched(rep)) => {
                self.searches += 1;
                self.empty += u64::from(rep.cells_in_volume == 0);
                if let Some(d) = rep.widened_to_m {
                    self.widened += 1;
                    eprintln!(
                        "omnitrack: frame {}: no valid visibility node in the search volume; searched the nearest, {:.1} m about its centre",
                        r.sequence, d
                    );
                }
                if rep.widened_to_m.is_none() {
                    self.widest_m = self.widest_m.max(rep.diameter_m.unwrap_or(0.0));
                }
                let volume = match rep.diameter_m {
                    Some(d) => format!("a {d:.1} m volume"),
                    None => "the whole model".to_string(),
                };
                // A sweep's later searches leave the cells the earlier ones looked at: the count
                // is of the whole sweep so far, and a sweep that goes on says so (without
                // `sweep_volume` nothing is skipped and the next search starts afresh).
                let looked_at = (rep.plan_cells_skipped + rep.plan_cells_scanned).min(rep.plan_cells_in_volume);
                let goes_on = if self.sweeps && rep.swept_to_m.is_some() {
                    ", the next search goes on with the rest"
                } else {
                    ""
                };
                eprintln!(
                    "omnitrack: frame {}: in {volume}, looked at {} of {} cells (positions scored under the vanishing directions{goes_on}), searched {} of {} (segment-edge triplets) in {:.0} ms",
                    r.sequence,
                    looked_at,
                    rep.plan_cells_in_volume,
                    rep.cells_searched,
                    rep.cells_in_volume,
                    rep.elapsed.as_secs_f64() * 1e3
                )
            }
            Some(TrackerEvent::Committed { candidates, .. }) => {
                eprintln!(
                    "omnitrack: frame {}: tracking ({candidates} candidates weighed)",
                    r.sequence
                )
            }
            Some(TrackerEvent::LostLock) => {
                eprintln!("omnitrack: frame {}: lost lock, re-initialising", r.sequence)
            }
            Some(TrackerEvent::Relocalised) | None => {}
        }
        if r.result.pose.is_some() {
            self.first_pose_ns = Some(self.first_pose_ns.map_or(r.timestamp_ns, |t| t.min(r.timestamp_ns)));
        }
    }
}

impl omnitrack::runtime::pipeline::FrameSink for RunSink {
    fn frame(&mut self, r: &omnitrack::runtime::FrameRecord) -> Result<(), omnitrack::runtime::SinkError> {
        self.first_frame_ns.get_or_insert(r.timestamp_ns);
        self.on_time += u64::from(r.result.pose.is_some());
        self.say(r);
        match &mut self.tum {
            Some(t) => t.frame(r),
            None => Ok(()),
        }
    }
    /// A late record (a search's frame and those kept during it) carries its events and pose
    /// like any other, and its pose counts: the trajectory has it.
    fn late(&mut self, r: &omnitrack::runtime::FrameRecord) -> Result<(), omnitrack::runtime::SinkError> {
        self.late += u64::from(r.result.pose.is_some());
        self.say(r);
        match &mut self.tum {
            Some(t) => t.late(r),
            None => Ok(()),
        }
    }
    fn finish(&mut self) -> Result<(), omnitrack::runtime::SinkError> {
        match &mut self.tum {
            Some(t) => t.finish(),
            None => Ok(()),
        }
    }
    /// A search of more than a second: one line a second on standard error, so a whole-model
    /// search (seconds without a pose) is not silence.
    fn search_progress(&mut self, p: &omnitrack::runtime::pipeline::SearchSnapshot) {
        use omnitrack::publish::SearchKind;
        let kind = match p.kind {
            Some(SearchKind::Relocalisation) => "relocalisation",
            Some(SearchKind::Reinitialisation) => "re-initialisation",
            Some(SearchKind::Initialisation) | None => "initialisation",
        };
        let (whole, d) = match p.diameter_m {
            Some(d) => ("", d),
            None => ("the whole model", 0.0),
        };
        // Straight to the unbuffered standard error: nothing is allocated.
        if whole.is_empty() {
            eprintln!(
                "omnitrack: {kind} search of a {d:.1} m volume: {:.0} % of its work after {:.1} s",
                100.0 * p.fraction_done(),
                p.elapsed.as_secs_f64()
            );
        } else {
            eprintln!(
                "omnitrack: {kind} search of {whole}: {:.0} % of its work after {:.1} s",
                100.0 * p.fraction_done(),
                p.elapsed.as_secs_f64()
            );
        }
    }
}

/// Why a run gave no pose, in one line, from what its searches reported.
fn no_pose_reason(summary: &omnitrack::runtime::pipeline::PipelineSummary, sink: &RunSink) -> String {
    let stats = &summary.tracker;
    let (searches, empty, widened) = (sink.searches, sink.empty, sink.widened);
    if summary.frames_processed == 0 {
        "no frame came from the source".to_string()
    } else if stats.searches == 0 {
        "no search started (no frame had edges enough to search with)".to_string()
    } else if searches == 0 && stats.searches_cancelled > 0 {
        "the stop cut the search short before it finished".to_string()
    } else if searches == 0 {
        "no search finished before the frames ended".to_string()
    } else if empty == searches {
        "the visibility table has no valid node (nowhere in the model has room for a person to stand: check the model's floors and scale, or rebuild the table)".to_string()
    } else if widened == searches {
        format!("the search volume holds no valid visibility node; {searches} searches of the nearest nodes found no pose that explains the frames clearly (check the --init hint)")
    } else if sink.hint_m.is_some_and(|h| sink.widest_m > h + 0.01) {
        format!(
            "{searches} searches found no pose that explains the frames clearly enough to commit; the rig moved before its first pose and the hint grew with the walk it may have made, to {:.1} m (a wrong pose is refused; a rig standing still keeps the hint as given)",
            sink.widest_m
        )
    } else {
        format!("{searches} searches found no pose that explains the frames clearly enough to commit (a wrong pose is refused: a model that differs from the building, or a hint far from the rig?)")
    }
}

/// An output that is one of the inputs (`--trajectory model.obj`) would destroy it: refused.
/// Only a file that exists can be an input, so a new output path passes.
fn refuse_to_overwrite<'a>(option: &str, out: &Path, inputs: impl Iterator<Item = &'a PathBuf>) -> Result<(), String> {
    let Ok(target) = std::fs::canonicalize(out) else {
        return Ok(());
    };
    for input in inputs {
        if std::fs::canonicalize(input).is_ok_and(|i| i == target) {
            return Err(format!(
                "{option} {}: that is the input {}; refusing to overwrite it",
                out.display(),
                input.display()
            ));
        }
    }
    Ok(())
}
