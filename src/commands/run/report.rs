//! `run --json`: the run's summary as one JSON object (docs/interfaces.md, "JSON output"), made
//! from the pipeline's summary and what `run`'s sink counted.

use super::RunSink;
use omnitrack::runtime::pipeline::{PipelineSummary, Realtime, RunEnd, Stage, StageSummary};
use serde::ser::{Serialize, SerializeMap, Serializer};
use serde::Serialize as Derive;
use std::path::Path;
use std::time::Duration;

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// The run's summary.
#[derive(Derive)]
pub struct RunReport<'a> {
    /// `end_of_stream`, `max_frames` or `stopped`.
    end: &'static str,
    exit_code: u8,
    no_pose_reason: Option<&'a str>,
    frames: Frames,
    poses: Poses,
    samples_published: Published,
    trajectory: Option<Trajectory<'a>>,
    tracker: Searches,
    elapsed_s: f64,
    frame_rate_hz: f64,
    latency_ms: Latency,
    stages: Stages,
    sensors: Vec<Sensor>,
    scheduling: Scheduling<'a>,
}

#[derive(Derive)]
struct Frames {
    captured: u64,
    processed: u64,
    dropped: u64,
    left: u64,
}

#[derive(Derive)]
struct Poses {
    total: u64,
    on_time: u64,
    late: u64,
    fraction: f64,
    first_timestamp_ns: Option<u64>,
    first_after_s: Option<f64>,
}

#[derive(Derive)]
struct Published {
    pose: u64,
    status: u64,
    errors: u64,
}

#[derive(Derive)]
struct Trajectory<'a> {
    path: &'a Path,
    poses_written: u64,
    out_of_order: u64,
    failed: bool,
}

#[derive(Derive)]
struct Searches {
    searches: u64,
    searches_cancelled: u64,
    losses: u64,
    reinitialisations: u64,
    relocalisations: u64,
    relocalisations_withdrawn: u64,
    reinitialisations_withdrawn: u64,
    commits_withdrawn: u64,
    first_search_s: Option<f64>,
    search_time_s: f64,
}

#[derive(Derive)]
struct Latency {
    p50: f64,
    p99: f64,
    max: f64,
}

#[derive(Derive)]
struct StageJson {
    count: u64,
    p50_ms: f64,
    p99_ms: f64,
    max_ms: f64,
    mean_ms: f64,
    budget_ms: Option<f64>,
    overruns: u64,
}

impl From<&StageSummary> for StageJson {
    fn from(s: &StageSummary) -> Self {
        StageJson {
            count: s.count,
            p50_ms: ms(s.p50),
            p99_ms: ms(s.p99),
            max_ms: ms(s.max),
            mean_ms: ms(s.mean),
            budget_ms: s.budget.map(ms),
            overruns: s.overruns,
        }
    }
}

/// Every stage by name, in the pipeline's order (`capture`, `edges`, `match`, `solve`,
/// `publish`, `frame`, `track`).
struct Stages(Vec<(&'static str, StageJson)>);

impl Serialize for Stages {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (name, stage) in &self.0 {
            map.serialize_entry(name, stage)?;
        }
        map.end()
    }
}

#[derive(Derive)]
struct Sensor {
    id: usize,
    delivered: u64,
    overwritten: u64,
    faults: u64,
    sync_missed: u64,
    left: u64,
}

#[derive(Derive)]
struct Scheduling<'a> {
    /// `off`, `lossless`, `realtime` or `refused`.
    mode: &'static str,
    priority: Option<u8>,
    reason: Option<&'a str>,
}

impl<'a> RunReport<'a> {
    pub fn new(
        summary: &'a PipelineSummary,
        sink: &RunSink,
        trajectory: Option<&'a Path>,
        no_pose_reason: Option<&'a str>,
        exit_code: u8,
    ) -> RunReport<'a> {
        let stats = &summary.tracker;
        let total = sink.on_time + sink.late;
        let latency = summary.stage(Stage::Frame);
        RunReport {
            end: match summary.reason {
                RunEnd::EndOfStream => "end_of_stream",
                RunEnd::MaxFrames => "max_frames",
                RunEnd::Stopped => "stopped",
            },
            exit_code,
            no_pose_reason,
            frames: Frames {
                captured: summary.frames_captured,
                processed: summary.frames_processed,
                dropped: summary.frames_dropped,
                left: summary.frames_left,
            },
            poses: Poses {
                total,
                on_time: sink.on_time,
                late: sink.late,
                fraction: total as f64 / summary.frames_processed.max(1) as f64,
                first_timestamp_ns: sink.first_pose_ns,
                first_after_s: sink
                    .first_pose_ns
                    .zip(sink.first_frame_ns)
                    .map(|(p, f)| p.saturating_sub(f) as f64 * 1e-9),
            },
            samples_published: Published {
                pose: summary.poses_published,
                status: summary.status_published,
                errors: summary.publish_errors,
            },
            trajectory: trajectory.zip(sink.tum.as_ref()).map(|(path, t)| Trajectory {
                path,
                poses_written: t.poses(),
                out_of_order: t.out_of_order(),
                failed: t.failed(),
            }),
            tracker: Searches {
                searches: stats.searches,
                searches_cancelled: stats.searches_cancelled,
                losses: stats.losses,
                reinitialisations: stats.reinitialisations,
                relocalisations: stats.relocalisations,
                relocalisations_withdrawn: stats.relocalisations_withdrawn,
                reinitialisations_withdrawn: stats.reinitialisations_withdrawn,
                commits_withdrawn: stats.commits_withdrawn,
                first_search_s: stats.first_search.map(|d| d.as_secs_f64()),
                search_time_s: stats.search_time.as_secs_f64(),
            },
            elapsed_s: summary.elapsed.as_secs_f64(),
            frame_rate_hz: summary.frame_rate_hz(),
            latency_ms: Latency {
                p50: ms(latency.p50),
                p99: ms(latency.p99),
                max: ms(latency.max),
            },
            stages: Stages(
                Stage::ALL
                    .iter()
                    .map(|&s| (s.name(), StageJson::from(summary.stage(s))))
                    .collect(),
            ),
            sensors: summary
                .sensors
                .iter()
                .enumerate()
                .map(|(id, s)| Sensor {
                    id,
                    delivered: s.delivered,
                    overwritten: s.overwritten,
                    faults: s.faults,
                    sync_missed: s.sync_missed,
                    left: s.left,
                })
                .collect(),
            scheduling: match &summary.realtime {
                Realtime::Off => Scheduling {
                    mode: "off",
                    priority: None,
                    reason: None,
                },
                Realtime::Lossless => Scheduling {
                    mode: "lossless",
                    priority: None,
                    reason: None,
                },
                Realtime::Granted(p) => Scheduling {
                    mode: "realtime",
                    priority: Some(*p),
                    reason: None,
                },
                Realtime::Refused { priority, reason } => Scheduling {
                    mode: "refused",
                    priority: Some(*priority),
                    reason: Some(reason),
                },
            },
        }
    }
}
