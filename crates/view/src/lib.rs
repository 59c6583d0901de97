//! A live view of the tracker in Foxglove, and the same view written to an MCAP file.
//!
//! In: the tracker's iceoryx2 services `omnitrack/pose` and `omnitrack/status` (zero-copy
//! subscribers, like any other local consumer), the building model (OBJ) if given, and for a
//! replayed recording its images ([`images`]). Out, as Foxglove's well-known types in JSON
//! ([`schemas`] lists the channels):
//!
//! - the rig's pose (`foxglove.PoseInFrame`, and world → rig as a `foxglove.FrameTransform`),
//!   its 3σ position ellipsoid and the trajectory so far over the model's segments
//!   (`foxglove.SceneUpdate`), every pose sample with its covariance (`omnitrack.PoseSample`);
//! - the tracker's status (`omnitrack.StatusSample`) and its state changes as log lines
//!   (`foxglove.Log`);
//! - each sensor's image (`foxglove.CompressedImage`) with the re-projected model and the
//!   detected edges (`foxglove.ImageAnnotations`), for a replay, at a reduced rate;
//!
//! to the clients of a Foxglove WebSocket server ([`ws`]) and to an MCAP file ([`mcap_out`]).
//!
//! It is a process of its own, not a part of the tracker: the frame path publishes its sample
//! as it does for any subscriber (iceoryx2 keeps a buffer per subscriber, the publisher never
//! waits for one), and everything that allocates, encodes or writes happens here. A view that
//! falls behind loses samples from its buffer of 8 (counted in the summary), never slows the
//! tracker. A file that cannot be written stops the file, not the live view.

pub mod images;
pub mod mcap_out;
pub mod messages;
pub mod schemas;
pub mod ws;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use omnitrack_io::publish::{
    PoseSample, PoseSubscriber, PublishError, StatusSample, StatusSubscriber, SUBSCRIBER_BUFFER,
};

use mcap_out::{McapError, McapOut};
use schemas::channels;
use ws::{Keep, Server, ServerError};

/// The default port of the live view: Foxglove's default for a WebSocket connection.
pub const DEFAULT_PORT: u16 = 8765;
/// The trajectory is sent in pieces of this much time.
pub const TRAJECTORY_PIECE: Duration = Duration::from_secs(1);

/// The fixed channels' indices in [`schemas::channels`].
mod ch {
    pub const POSE: usize = 0;
    pub const TF: usize = 1;
    pub const SAMPLE: usize = 2;
    pub const UNCERTAINTY: usize = 3;
    pub const TRAJECTORY: usize = 4;
    pub const MODEL: usize = 5;
    pub const STATUS: usize = 6;
    pub const LOG: usize = 7;
    pub const FIXED: usize = 8;
}

/// What to view and where to.
#[derive(Debug, Clone)]
pub struct Options {
    pub pose_service: String,
    pub status_service: String,
    /// The WebSocket server's address; `None`: no server (an MCAP file only).
    pub listen: Option<SocketAddr>,
    /// The MCAP file to write.
    pub mcap: Option<PathBuf>,
    /// The building model, drawn under the trajectory.
    pub model: Option<PathBuf>,
    /// A replayed recording's images, re-projection and edges.
    pub images: Option<images::ImageOptions>,
    /// Stop after this many pose samples.
    pub count: Option<u64>,
}

/// Why the view cannot go on: one line.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("{0}")]
    Local(#[from] PublishError),
    #[error("{0}")]
    Mcap(#[from] McapError),
    #[error("{0}")]
    Server(#[from] ServerError),
    #[error("{0}")]
    Model(#[from] omnitrack_core::model::ModelError),
    #[error("{0}")]
    Images(#[from] images::ImageError),
}

/// What a view did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Summary {
    /// Pose samples received, of them tracking.
    pub poses: u64,
    pub tracking: u64,
    /// Status samples received.
    pub statuses: u64,
    /// Sequence numbers of the pose service skipped (samples the view's buffer lost).
    pub poses_missed: u64,
    /// Messages written to the MCAP file.
    pub mcap_messages: u64,
    /// Why the MCAP file stopped before the end, if it did.
    pub mcap_error: Option<String>,
    /// Image sets (one image per sensor) sent.
    pub image_sets: u64,
    /// Pose samples that came while the images' thread was busy (no image set looked for).
    pub images_skipped: u64,
    /// Why the images stopped before the end, if they did.
    pub images_error: Option<String>,
    /// WebSocket messages sent, lost by slow clients, connections refused.
    pub ws_sent: u64,
    pub ws_dropped: u64,
    pub ws_refused: u64,
}

/// Where the messages go: the file and the server.
struct Out {
    mcap: Option<McapOut>,
    server: Option<Server>,
    summary: Summary,
}

impl Out {
    fn send(&mut self, channel: usize, log_time_ns: u64, data: &[u8]) {
        self.write_file(channel, log_time_ns, data);
        if let Some(server) = &mut self.server {
            server.send(channel, log_time_ns, data);
        }
    }

    /// A quiet moment: the file gets what it holds in memory, at most once per flush interval.
    fn tick(&mut self) {
        if let Some(file) = &mut self.mcap {
            if let Err(e) = file.tick() {
                eprintln!("omnitrack-view: {e}; the file ends here, the live view goes on");
                self.summary.mcap_error = Some(e.to_string());
                self.mcap = None;
            }
        }
    }

    /// Sends an image set; false when the images stopped (one line says why; the poses go on).
    fn images(&mut self, made: Result<(u64, images::ImageSet), images::ImageError>) -> bool {
        match made {
            Ok((t, set)) => {
                self.summary.image_sets += 1;
                for (k, (image, annotations)) in set.into_iter().enumerate() {
                    self.send(ch::FIXED + 2 * k, t, &image);
                    self.send(ch::FIXED + 2 * k + 1, t, &annotations);
                }
                true
            }
            Err(e) => {
                eprintln!("omnitrack-view: images: {e}; the images stop here, the poses go on");
                self.summary.images_error = Some(e.to_string());
                false
            }
        }
    }

    fn write_file(&mut self, channel: usize, log_time_ns: u64, data: &[u8]) {
        if let Some(file) = &mut self.mcap {
            match file.write(channel, log_time_ns, data) {
                Ok(()) => self.summary.mcap_messages += 1,
                Err(e) => {
                    // What was written stays readable; the live view goes on.
                    eprintln!("omnitrack-view: {e}; the file ends here, the live view goes on");
                    self.summary.mcap_error = Some(e.to_string());
                    self.mcap = None;
                }
            }
        }
    }
}

/// The trajectory's current piece: the tracking positions since the last piece went out.
#[derive(Default)]
struct Trajectory {
    piece: u64,
    positions: Vec<[f64; 3]>,
    started_ns: u64,
    last_ns: u64,
}

impl Trajectory {
    fn push(&mut self, out: &mut Out, t_ns: u64, p: [f64; 3]) {
        if self.positions.is_empty() {
            self.started_ns = t_ns;
        }
        self.positions.push(p);
        self.last_ns = t_ns;
        if t_ns.saturating_sub(self.started_ns) >= TRAJECTORY_PIECE.as_nanos() as u64 {
            self.flush(out, true);
        }
    }

    /// Sends the piece; `connect`: the next piece starts where this one ended (a loss breaks
    /// the line instead of drawing the jump).
    fn flush(&mut self, out: &mut Out, connect: bool) {
        if self.positions.len() >= 2 {
            let data = messages::trajectory_piece(self.piece, &self.positions, self.last_ns);
            out.send(ch::TRAJECTORY, self.last_ns, &data);
            self.piece += 1;
        }
        let last = self.positions.last().copied();
        self.positions.clear();
        if let (true, Some(p)) = (connect, last) {
            self.positions.push(p);
            self.started_ns = self.last_ns;
        }
    }
}

/// The view's state between samples: where they go and what it remembers of the last ones.
struct View<'a> {
    out: Out,
    images: Option<images::Worker>,
    segments: &'a [([f64; 3], [f64; 3])],
    model_in_file: bool,
    trajectory: Trajectory,
    last_status: Option<StatusSample>,
    last_sequence: Option<u64>,
}

impl View<'_> {
    fn status(&mut self, s: StatusSample) {
        let out = &mut self.out;
        out.summary.statuses += 1;
        out.send(ch::STATUS, s.timestamp_ns, &messages::status_sample(&s));
        if let Some((level, line)) = messages::state_change(self.last_status.as_ref(), &s) {
            out.send(ch::LOG, s.timestamp_ns, &messages::log(s.timestamp_ns, level, &line));
        }
        self.last_status = Some(s);
    }

    fn pose(&mut self, sample: &PoseSample) {
        let out = &mut self.out;
        let t = sample.timestamp_ns;
        if !self.model_in_file {
            out.write_file(ch::MODEL, t, &messages::model(self.segments, t));
            self.model_in_file = true;
        }
        out.summary.poses += 1;
        if let Some(prev) = self.last_sequence {
            out.summary.poses_missed += sample.sequence.saturating_sub(prev + 1);
        }
        self.last_sequence = Some(sample.sequence);
        out.send(ch::SAMPLE, t, &messages::pose_sample(sample));
        if messages::is_tracking(sample) {
            out.summary.tracking += 1;
            out.send(ch::POSE, t, &messages::pose_in_frame(sample));
            out.send(ch::TF, t, &messages::frame_transform(sample));
            if let Some(u) = messages::uncertainty(sample) {
                out.send(ch::UNCERTAINTY, t, &u);
            }
            self.trajectory.push(out, t, sample.position_m);
        } else {
            self.trajectory.flush(out, false);
        }
        if let Some(worker) = &mut self.images {
            worker.offer(sample);
            while let Some(made) = worker.take() {
                if !out.images(made) {
                    self.images = None;
                    break;
                }
            }
        }
    }
}

/// Views the pose and status services until `stop` is set or `count` poses came; `on_start`
/// gets the server's address (port 0 picks one) once everything is open.
pub fn run(o: &Options, stop: &AtomicBool, on_start: &mut dyn FnMut(Option<SocketAddr>)) -> Result<Summary, ViewError> {
    // Everything a user can get wrong is checked before anything is subscribed or written.
    let segments = match &o.model {
        Some(path) => messages::segments(&omnitrack_core::model::Model::load(path)?),
        None => Vec::new(),
    };
    let images = match &o.images {
        Some(io) => Some(images::Worker::start(images::Images::open(
            io,
            o.model.is_some().then_some(&segments),
        )?)),
        None => None,
    };
    let table = channels(images.as_ref().map_or(0, |i| i.sensors()));
    let mut keep = vec![Keep::Last; table.len()];
    keep[ch::TRAJECTORY] = Keep::All;
    let server = match o.listen {
        Some(addr) => Some(Server::bind(addr, table.clone(), &keep)?),
        None => None,
    };
    let mcap = match &o.mcap {
        Some(path) => Some(McapOut::create(path, &table)?),
        None => None,
    };
    let poses = PoseSubscriber::create(&o.pose_service)?;
    let statuses = StatusSubscriber::create(&o.status_service)?;
    let mut out = Out {
        mcap,
        server,
        summary: Summary::default(),
    };
    on_start(out.server.as_ref().map(Server::addr));

    let model_message = (!segments.is_empty()).then(|| messages::model(&segments, 0));
    if let (Some(m), Some(server)) = (&model_message, &mut out.server) {
        // The live view's model at once, before any pose (the file's goes in at the first
        // sample's time, so that its time line is the run's).
        server.send(ch::MODEL, 0, m);
    }
    let mut view = View {
        model_in_file: model_message.is_none() || out.mcap.is_none(),
        segments: &segments,
        out,
        images,
        trajectory: Trajectory::default(),
        last_status: None,
        last_sequence: None,
    };
    // A service that fails mid-run ends the loop, not the file: what came is finished first.
    let mut failure: Option<PublishError> = None;
    let more = |v: &View| o.count.is_none_or(|n| v.out.summary.poses < n);

    while !stop.load(Ordering::Relaxed) && more(&view) {
        if let Some(server) = &mut view.out.server {
            server.accept();
        }
        let status = match statuses.receive() {
            Ok(s) => s,
            Err(e) => {
                failure = Some(e);
                break;
            }
        };
        if let Some(s) = status {
            view.status(s);
            // The next status before the next pose wait: a burst is taken whole.
            continue;
        }
        match poses.wait(Duration::from_millis(20)) {
            Ok(Some(s)) => view.pose(&s),
            Ok(None) => view.out.tick(),
            // SIGINT/SIGTERM interrupt the wait (iceoryx2 reports it as an error): a stop.
            Err(_) if stop.load(Ordering::Relaxed) => break,
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
    }
    // A stop first takes what the buffers already hold: `omnitrack run --mcap` stops the view
    // right after its last publish, and those samples are the run's last poses. Bounded, as a
    // tracker that goes on publishing would otherwise keep it here.
    if failure.is_none() {
        for _ in 0..2 * SUBSCRIBER_BUFFER {
            let status = statuses.receive().ok().flatten();
            let pose = if more(&view) {
                poses.receive().ok().flatten()
            } else {
                None
            };
            if status.is_none() && pose.is_none() {
                break;
            }
            if let Some(s) = status {
                view.status(s);
            }
            if let Some(s) = pose {
                view.pose(&s);
            }
        }
    }
    let View {
        mut out,
        mut trajectory,
        images,
        ..
    } = view;
    trajectory.flush(&mut out, false);
    if let Some(worker) = images {
        out.summary.images_skipped = worker.busy;
        for made in worker.finish() {
            out.images(made);
        }
    }
    let mut summary = std::mem::take(&mut out.summary);
    if let Some(file) = out.mcap.take() {
        match file.finish() {
            Ok(_) => {}
            Err(e) => summary.mcap_error = Some(e.to_string()),
        }
    }
    if let Some(server) = out.server.take() {
        (summary.ws_sent, summary.ws_dropped, summary.ws_refused) = server.close();
    }
    if let Some(e) = failure {
        return Err(e.into());
    }
    Ok(summary)
}

/// A flag set by SIGINT or SIGTERM (the subscriber processes' one, from omnitrack-io).
pub use omnitrack_io::publish::stop_on_signals;
