//! `omnitrack`: the device binary's command line (docs/interfaces.md, "Command line").
//!
//! Standard output carries only documented output (CSV, JSON, TUM); messages go to standard
//! error; every failure is one line and a non-zero exit, never a panic.

use clap::{Parser, Subcommand};
use omnitrack::config::TrackerConfig;
use omnitrack::solver::{self, Method};
use omnitrack::{Model, Rig};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "omnitrack",
    version,
    about = "6-DOF tracking of an omnidirectional rig in a known building model"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The embedded default: synthetic building, recording, visibility table, tracking, report.
    Demo,
    /// Tracks: frames from the source, poses on the iceoryx2 pose service and, if asked, a TUM
    /// trajectory. Without --init the whole model is searched.
    Run(RunArgs),
    /// Validates a rig, and optionally a model and a tracker config, and summarises them.
    Check {
        /// The rig file to validate.
        #[arg(long, value_name = "RIG.toml")]
        rig: Option<PathBuf>,
        /// A building model (OBJ) to load, with its faces and segments summarised.
        #[arg(long, value_name = "MODEL.obj")]
        model: Option<PathBuf>,
        /// A tracker config to validate (every key's type and range).
        #[arg(long, value_name = "tracker.toml")]
        config: Option<PathBuf>,
    },
    /// Solves one pose T_world_rig from line correspondences and prints it as JSON.
    Pose {
        /// The rig whose sensors the lines' image end points belong to.
        #[arg(long, value_name = "RIG.toml")]
        rig: PathBuf,
        /// CSV with header sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2.
        #[arg(long, value_name = "FILE.csv")]
        lines: PathBuf,
        /// Solver: Kumar–Hanson's R_and_T, R_then_T or Med_R_and_T (lms), or the ξ simplex (xi).
        #[arg(long, default_value = "r_and_t", value_parser = method_parser())]
        method: Method,
        /// Starting pose tx,ty,tz,qw,qx,qy,qz (without it the solvers search rotation space).
        #[arg(long, value_name = "tx,ty,tz,qw,qx,qy,qz", allow_hyphen_values = true)]
        guess: Option<String>,
        /// Tracker config whose [solver] and [noise] tunables to use (default: the papers' values).
        #[arg(long, value_name = "tracker.toml")]
        config: Option<PathBuf>,
    },
    /// Prints the detected edges of one sensor image as CSV (docs/interfaces.md).
    Edges {
        /// The rig the image comes from (its sensor's lens and size).
        #[arg(long, value_name = "RIG.toml")]
        rig: PathBuf,
        /// The sensor's id in the rig.
        #[arg(long)]
        sensor: usize,
        /// Tracker config whose [edges] section to use (default: the papers' values).
        #[arg(long, value_name = "tracker.toml")]
        config: Option<PathBuf>,
        /// The sensor image (PNG or JPEG).
        #[arg(value_name = "IMAGE.png")]
        image: PathBuf,
    },
    /// Builds or queries the prior visibility table (Koch–Teller §4.3).
    Visibility {
        #[command(subcommand)]
        command: VisibilityCommand,
    },
    /// Subscribes to the pose service and prints one line per sample.
    Listen {
        /// Stop after N samples (default: until Ctrl-C).
        #[arg(long)]
        count: Option<u64>,
    },
    /// Prints the model segments of an OBJ as CSV: x1,y1,z1,x2,y2,z2,faces (OBJ face numbers,
    /// space-separated; empty for a free `l` segment).
    Segments {
        /// The building model.
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
    },
}

#[derive(Subcommand)]
enum VisibilityCommand {
    /// Builds the table of visible faces, segments and vertices per node (progress on stderr).
    Build {
        /// The building model.
        #[arg(long, value_name = "MODEL.obj")]
        model: PathBuf,
        /// Where to write the table.
        #[arg(long, value_name = "TABLE.vis")]
        out: PathBuf,
        /// Node spacing in metres (default: [visibility] node_spacing_m of tracker.toml, 1 m).
        #[arg(long, value_name = "METRES", allow_hyphen_values = true)]
        spacing_m: Option<f64>,
    },
    /// Prints the visibility set serving a position as one line of JSON.
    Query {
        /// The table, as `visibility build` wrote it.
        #[arg(long, value_name = "TABLE.vis")]
        visibility: PathBuf,
        /// The position in world coordinates, metres.
        #[arg(long, value_name = "x,y,z", allow_hyphen_values = true)]
        at: String,
    },
}

/// `--method`: the solver's own names, listed in the help.
fn method_parser() -> impl clap::builder::TypedValueParser<Value = Method> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(Method::ALL.map(Method::name))
        .map(|name| name.parse::<Method>().expect("a listed name"))
}

fn main() -> ExitCode {
    let cli: Cli = omnitrack::runtime::cli::parse_or_exit("omnitrack", "omnitrack demo");
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("omnitrack: {message}");
            ExitCode::from(2)
        }
    }
}

fn run(command: Command) -> Result<(), String> {
    match command {
        #[cfg(feature = "desk")]
        Command::Demo => {
            let report = omnitrack::desk::demo::run_demo(&omnitrack::desk::demo::DemoOptions::default())?;
            println!("{report}");
            Ok(())
        }
        #[cfg(not(feature = "desk"))]
        Command::Demo => Err(
            "demo needs the `desk` feature, which this device build leaves out (`cargo run --release -- demo` \
             has it by default)"
                .into(),
        ),
        Command::Run(args) => run_tracker(args),
        Command::Check { rig, model, config } => {
            if rig.is_none() && model.is_none() && config.is_none() {
                return Err("check needs at least one of --rig, --model, --config".into());
            }
            if let Some(path) = rig {
                let rig = Rig::load(&path).map_err(|e| e.to_string())?;
                eprintln!("{}: rig '{}', {} sensors", path.display(), rig.name, rig.sensors.len());
                for s in &rig.sensors {
                    let c = s.centre();
                    eprintln!(
                        "  sensor {}: {}×{}, {} lens seeing {:.1}° off-axis at the corners, centre ({:.3}, {:.3}, {:.3}) m",
                        s.id,
                        s.width,
                        s.height,
                        lens_name(&s.lens),
                        s.max_off_axis().to_degrees(),
                        c.x,
                        c.y,
                        c.z
                    );
                }
            }
            if let Some(path) = model {
                let m = Model::load(&path).map_err(|e| e.to_string())?;
                eprintln!(
                    "{}: {} vertices, {} faces, {} segments ({} free); skipped {} degenerate faces, \
                     split {} non-planar faces, welded {} duplicate vertices, ignored {} records",
                    path.display(),
                    m.vertices.len(),
                    m.faces.len(),
                    m.segments.len(),
                    m.segments.iter().filter(|s| s.is_free()).count(),
                    m.stats.degenerate_faces,
                    m.stats.nonplanar_faces,
                    m.stats.welded_vertices,
                    m.stats.ignored_records
                );
            }
            if let Some(path) = config {
                TrackerConfig::load(&path).map_err(|e| e.to_string())?;
                eprintln!("{}: tracker config valid", path.display());
            }
            Ok(())
        }
        Command::Pose {
            rig,
            lines,
            method,
            guess,
            config,
        } => {
            let guess = guess.as_deref().map(parse_guess).transpose()?;
            let rig = Rig::load(&rig).map_err(|e| e.to_string())?;
            let options = match config {
                Some(path) => TrackerConfig::load(&path).map_err(|e| e.to_string())?.solver_options(),
                None => TrackerConfig::default().solver_options(),
            };
            let name = lines.display().to_string();
            let text = std::fs::read_to_string(&lines).map_err(|e| format!("{name}: cannot read: {e}"))?;
            let correspondences = omnitrack::lines::parse_lines(&text, &name, &rig).map_err(|e| e.to_string())?;
            let solution = solver::solve(method, &correspondences, guess.as_ref(), &options, 0)
                .map_err(|e| format!("{name}: no pose: {e}"))?;
            println!("{}", pose_json(&solution));
            Ok(())
        }
        Command::Edges {
            rig,
            sensor,
            config,
            image,
        } => {
            let rig = Rig::load(&rig).map_err(|e| e.to_string())?;
            let edges = match config {
                Some(p) => TrackerConfig::load(&p).map_err(|e| e.to_string())?.edges,
                None => omnitrack::config::EdgeConfig::default(),
            };
            let csv = omnitrack::edges::edges_csv_for_image(&rig, &edges, sensor, &image)?;
            let mut out = std::io::stdout().lock();
            out.write_all(csv.as_bytes())
                .map_err(|e| format!("cannot write to standard output: {e}"))
        }
        #[cfg(feature = "desk")]
        Command::Visibility {
            command: VisibilityCommand::Build { model, out, spacing_m },
        } => {
            let config = TrackerConfig::default().visibility;
            let summary =
                omnitrack::visibility::build::run_build(&model, &out, spacing_m, &config).map_err(|e| e.to_string())?;
            eprintln!("{summary}");
            Ok(())
        }
        #[cfg(not(feature = "desk"))]
        Command::Visibility {
            command: VisibilityCommand::Build { .. },
        } => Err(
            "visibility build is desk work: this binary was built without the `desk` feature (build with default \
             features)"
                .into(),
        ),
        Command::Visibility {
            command: VisibilityCommand::Query { visibility, at },
        } => {
            let at = omnitrack::visibility::parse_point(&at)?;
            let json = omnitrack::visibility::run_query(&visibility, &at).map_err(|e| e.to_string())?;
            println!("{json}");
            Ok(())
        }
        Command::Listen { count } => {
            omnitrack::publish::listen(omnitrack::publish::POSE_SERVICE, count, &mut std::io::stdout().lock())
                .map_err(|e| e.to_string())
        }
        Command::Segments { model } => {
            let m = Model::load(&model).map_err(|e| e.to_string())?;
            let mut out = std::io::BufWriter::new(std::io::stdout().lock());
            let write = |out: &mut std::io::BufWriter<_>| -> std::io::Result<()> {
                writeln!(out, "x1,y1,z1,x2,y2,z2,faces")?;
                for s in &m.segments {
                    let faces: Vec<String> = s
                        .faces
                        .iter()
                        .map(|&f| m.faces[f as usize].obj_number.to_string())
                        .collect();
                    writeln!(
                        out,
                        "{},{},{},{},{},{},{}",
                        s.a.x,
                        s.a.y,
                        s.a.z,
                        s.b.x,
                        s.b.y,
                        s.b.z,
                        faces.join(" ")
                    )?;
                }
                out.flush()
            };
            write(&mut out).map_err(|e| format!("cannot write to standard output: {e}"))
        }
    }
}

/// `tx,ty,tz,qw,qx,qy,qz` (the order of docs/interfaces.md) to a pose.
fn parse_guess(text: &str) -> Result<omnitrack::Pose, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|f| f.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("--guess '{text}': expected 7 finite numbers tx,ty,tz,qw,qx,qy,qz"))?;
    if v.len() != 7 {
        return Err(format!(
            "--guess '{text}': expected 7 numbers tx,ty,tz,qw,qx,qy,qz, found {}",
            v.len()
        ));
    }
    omnitrack::geometry::pose_from_parts([v[0], v[1], v[2]], [v[3], v[4], v[5], v[6]])
        .map_err(|e| format!("--guess '{text}': {e}"))
}

/// A JSON number; JSON has no NaN or infinity, so those become null.
fn json_number(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}")
    } else {
        "null".into()
    }
}

/// The JSON object docs/interfaces.md specifies for `omnitrack pose`.
fn pose_json(s: &solver::Solution) -> String {
    let list = |xs: &mut dyn Iterator<Item = f64>| xs.map(json_number).collect::<Vec<_>>().join(",");
    let t = s.pose.translation.vector;
    let q = omnitrack::geometry::rotation_to_wxyz(&s.pose.rotation);
    let inliers: Vec<String> = s.inliers.iter().map(|i| i.to_string()).collect();
    format!(
        "{{\"position\":[{}],\"rotation_wxyz\":[{}],\"covariance\":[{}],\"inliers\":[{}],\"xi_rad2\":{},\"iterations\":{}}}",
        list(&mut t.iter().copied()),
        list(&mut q.iter().copied()),
        list(&mut s.covariance.transpose().iter().copied()),
        inliers.join(","),
        json_number(s.xi_rad2),
        s.iterations
    )
}

fn lens_name(lens: &omnitrack::geometry::Lens) -> &'static str {
    match lens {
        omnitrack::geometry::Lens::Pinhole(_) => "pinhole",
        omnitrack::geometry::Lens::Kb4(_) => "kb4",
    }
}

/// `omnitrack run` (docs/interfaces.md).
#[derive(clap::Args)]
struct RunArgs {
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
    source: String,
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
    /// Replay at the recorded frame rate (default: as fast as the tracker goes).
    #[arg(long)]
    realtime: bool,
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

fn run_tracker(a: RunArgs) -> Result<(), String> {
    use omnitrack::capture::{Pacing, SourceOptions};
    use omnitrack::publish::{POSE_SERVICE, STATUS_SERVICE};
    use omnitrack::runtime::load_or_build_table;
    use omnitrack::runtime::pipeline::{
        init_logging, open_pipeline_source, run_pipeline, FrameSink, PipelineOptions, TumSink,
    };
    use omnitrack::runtime::{FrameRecord, RunOptions, SinkError};
    use omnitrack::tracker::TrackerEvent;

    /// Progress lines on standard error and, if asked, the TUM trajectory.
    struct RunSink {
        tum: Option<TumSink>,
        /// Searches run, those that had no cell to search, and those widened to the nearest
        /// valid nodes: why no pose came out, if none did.
        searches: u64,
        empty: u64,
        widened: u64,
    }
    impl FrameSink for RunSink {
        fn frame(&mut self, r: &FrameRecord) -> Result<(), SinkError> {
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
                    eprintln!(
                        "omnitrack: frame {}: searched {} of {} cells in {:.0} ms",
                        r.sequence,
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
            match &mut self.tum {
                Some(t) => t.frame(r),
                None => Ok(()),
            }
        }
        fn finish(&mut self) -> Result<(), SinkError> {
            match &mut self.tum {
                Some(t) => t.finish(),
                None => Ok(()),
            }
        }
    }

    init_logging();
    let cfg = match &a.config {
        Some(p) => TrackerConfig::load(p).map_err(|e| e.to_string())?,
        None => TrackerConfig::default(),
    };
    let hint = a
        .init
        .as_deref()
        .map(|t| parse_init(t, cfg.initialisation.search_diameter_m))
        .transpose()?;
    let rig = a.rig.as_deref().map(Rig::load).transpose().map_err(|e| e.to_string())?;
    let options = SourceOptions {
        pacing: if a.realtime {
            Pacing::RealTime
        } else {
            Pacing::AsFastAsPossible
        },
        ..SourceOptions::default()
    };
    let source = open_pipeline_source(&a.source, rig.as_ref(), &options).map_err(|e| e.to_string())?;
    let model = Model::load(&a.model).map_err(|e| e.to_string())?;
    let (table, origin) =
        load_or_build_table(&a.model, &model, a.visibility.as_deref(), &cfg).map_err(|e| e.to_string())?;
    eprintln!("omnitrack: {origin}");
    let mut sink = RunSink {
        tum: a
            .trajectory
            .as_deref()
            .map(TumSink::create)
            .transpose()
            .map_err(|e| e.to_string())?,
        searches: 0,
        empty: 0,
        widened: 0,
    };
    let publish = (!a.no_publish).then_some(());
    let opts = PipelineOptions {
        run: RunOptions {
            hint,
            seed: 1,
            max_frames: a.frames,
        },
        handle_signals: true,
        pose_service: publish.map(|_| POSE_SERVICE.to_string()),
        status_service: publish.map(|_| STATUS_SERVICE.to_string()),
        // A replay not paced in real time would otherwise race ahead while the tracker works.
        lossless: !a.realtime && a.source.starts_with("replay:"),
        ..PipelineOptions::default()
    };
    let summary = run_pipeline(source, &model, &table, &cfg, &opts, &mut sink).map_err(|e| e.to_string())?;
    let stats = &summary.tracker;
    eprintln!(
        "omnitrack: {} frames, {} tracked ({:.1} %), {} losses, {} re-initialisations, {} relocalisations",
        stats.frames,
        stats.tracked,
        100.0 * stats.tracked as f64 / stats.frames.max(1) as f64,
        stats.losses,
        stats.reinitialisations,
        stats.relocalisations
    );
    eprintln!("omnitrack: {summary}");
    if stats.tracked == 0 {
        eprintln!(
            "omnitrack: no pose: {}",
            no_pose_reason(stats.frames, sink.searches, sink.empty, sink.widened)
        );
    }
    Ok(())
}

/// Why a run gave no pose, in one line, from what its searches reported.
fn no_pose_reason(frames: u64, searches: u64, empty: u64, widened: u64) -> String {
    if frames == 0 {
        "no frame came from the source".to_string()
    } else if searches == 0 {
        "no search finished".to_string()
    } else if empty == searches {
        "the visibility table has no valid node (nowhere in the model has room for a person to stand: check the model's floors and scale, or rebuild the table)".to_string()
    } else if widened == searches {
        format!("the search volume holds no valid visibility node; {searches} searches of the nearest nodes found no pose that explains the frames clearly (check the --init hint)")
    } else {
        format!("{searches} searches found no pose that explains the frames clearly enough to commit (a wrong pose is refused: a model that differs from the building, or a hint far from the rig?)")
    }
}
