//! A replayed recording's images for the view: each sensor's image as a JPEG
//! (`foxglove.CompressedImage`) with the model re-projected at the tracked pose and the edges the
//! tracker's detector finds (`foxglove.ImageAnnotations`), at a reduced rate.
//!
//! In: the recording the tracker replays (`--source replay:DIR`), the model's segments, and
//! each pose sample. Out: for a sample at least [`ImageOptions::every`] after the last image set,
//! one (image, annotations) pair per sensor, as JSON bytes.
//!
//! [`Worker`] runs them on a thread of their own. The images are the view's own reading of the recording, not the tracker's frames: the
//! tracker shares nothing but its pose and status, so the view never touches its frame path.
//! The frame of a sample is the recording's frame at the sample's sequence number, checked by
//! its timestamp (a sample whose frame has another time gets no images, counted). A live camera
//! has no such second reader; its images are not in the view (docs/interfaces.md).
//!
//! Green: the model's segments at the pose (omnitrack-core's `rig::reproject`, as the desk's
//! pictures draw them: sampled along each segment, so that they curve as the lens curves them;
//! without hidden-line removal). Orange: the detected edges, drawn along
//! their great circles. The detector runs here with the tracker's default settings on one
//! thread.

use std::path::PathBuf;
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

use base64::Engine;
use nalgebra::{Point2, Point3};
use omnitrack_core::frame::FrameSet;
use omnitrack_core::geometry::Pose;
use omnitrack_core::rig::{project_segments, Rig};
use omnitrack_edges::{EdgeDetector, EdgeParams};
use omnitrack_io::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack_io::publish::PoseSample;
use serde_json::{json, Value};

use crate::messages::{is_tracking, time};

/// Pixels between the samples of a re-projected model segment: smooth enough at the images'
/// size in a viewer, and a few dozen points per segment rather than the desk's hundreds.
const SEGMENT_SPACING_PX: f64 = 6.0;
/// Samples along a detected edge.
const EDGE_SAMPLES: usize = 12;
const MODEL_COLOUR: [f64; 4] = [0.1, 0.9, 0.2, 1.0];
const EDGE_COLOUR: [f64; 4] = [1.0, 0.55, 0.0, 1.0];

/// Which images to send.
#[derive(Debug, Clone)]
pub struct ImageOptions {
    /// The recording being replayed.
    pub recording: PathBuf,
    /// At most one image set per this much of the recording's time.
    pub every: Duration,
    /// Whether to detect and draw the edges.
    pub edges: bool,
    /// JPEG quality, 1–100.
    pub quality: u8,
}

/// A recording that cannot be read: one line.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{0}")]
    Source(#[from] omnitrack_io::capture::SourceError),
    #[error("cannot encode the image of sensor {sensor} as JPEG: {detail}")]
    Encode { sensor: usize, detail: String },
}

/// A recording's images, read beside the tracker.
pub struct Images {
    source: ReplaySource,
    rig: Rig,
    frame: FrameSet,
    detector: Option<EdgeDetector>,
    segments: Vec<([f64; 3], [f64; 3])>,
    every_ns: u64,
    quality: u8,
    last_ns: Option<u64>,
    /// Samples whose frame in the recording has another timestamp.
    pub mismatched: u64,
}

impl Images {
    /// Opens the recording (its rig is the rig of the images); `segments`: the model to draw.
    pub fn open(o: &ImageOptions, segments: Option<&Vec<([f64; 3], [f64; 3])>>) -> Result<Images, ImageError> {
        let source = ReplaySource::open(&o.recording, Pacing::AsFastAsPossible)?;
        let rig = source.rig().clone();
        let detector = o.edges.then(|| {
            let params = EdgeParams {
                threads: 1,
                ..EdgeParams::default()
            };
            EdgeDetector::with_params(&rig, &omnitrack_config::EdgeConfig::default(), params)
        });
        Ok(Images {
            frame: FrameSet::for_rig(&rig),
            source,
            rig,
            detector,
            segments: segments.cloned().unwrap_or_default(),
            every_ns: o.every.as_nanos() as u64,
            quality: o.quality.clamp(1, 100),
            last_ns: None,
            mismatched: 0,
        })
    }

    /// Sensors of the recording's rig.
    pub fn sensors(&self) -> usize {
        self.rig.sensors.len()
    }

    /// The image set of a sample, if one is due: per sensor, its `CompressedImage` and its
    /// `ImageAnnotations`.
    pub fn at(&mut self, s: &PoseSample) -> Result<Option<ImageSet>, ImageError> {
        let t = s.timestamp_ns;
        if self.last_ns.is_some_and(|last| t.saturating_sub(last) < self.every_ns) {
            return Ok(None);
        }
        let Ok(index) = usize::try_from(s.sequence) else {
            return Ok(None);
        };
        self.source.seek(index);
        if !self.source.next_frame(&mut self.frame)? || self.frame.timestamp_ns() != Some(t) {
            self.mismatched += 1;
            return Ok(None);
        }
        self.last_ns = Some(t);
        if let Some(d) = &mut self.detector {
            d.detect(&self.frame);
        }
        // A sample with a damaged quaternion (not unit, not finite) has no pose to draw.
        let t_rig_world = is_tracking(s).then(|| s.pose().ok()).flatten().map(|p| p.inverse());
        let mut set = Vec::with_capacity(self.rig.sensors.len());
        for (k, sensor) in self.rig.sensors.iter().enumerate() {
            let image = self.frame.sensor(k);
            let jpeg = if image.width() > 0 {
                encode_jpeg(image.pixels(), image.width(), image.height(), self.quality)
                    .map_err(|detail| ImageError::Encode { sensor: k, detail })?
            } else {
                Vec::new()
            };
            let compressed = json!({
                "timestamp": time(t),
                "frame_id": format!("sensor{k}"),
                "data": base64::engine::general_purpose::STANDARD.encode(&jpeg),
                "format": "jpeg",
            });
            let mut annotations = Vec::new();
            if let Some(t_rig_world) = &t_rig_world {
                let pieces = model_pieces(sensor, &self.segments, t_rig_world);
                annotations.push(points(t, &pieces, MODEL_COLOUR, 1.5));
            }
            if let Some(d) = &self.detector {
                let pieces = edge_pieces(sensor, d.sensor_edges(k));
                annotations.push(points(t, &pieces, EDGE_COLOUR, 2.0));
            }
            let annotations = json!({"circles": [], "points": annotations, "texts": []});
            set.push((to_bytes(&compressed), to_bytes(&annotations)));
        }
        Ok(Some(set))
    }
}

/// One sensor's image and its annotations, as JSON bytes.
pub type ImageSet = Vec<(Vec<u8>, Vec<u8>)>;

/// [`Images`] on a thread of their own: the view's pose loop hands a sample over when the
/// thread is idle and never waits for an image to be read, detected and encoded (tens of
/// milliseconds), so that the poses reach the viewer and the file at the tracker's rate.
pub struct Worker {
    to: Option<SyncSender<PoseSample>>,
    from: Receiver<Result<(u64, ImageSet), ImageError>>,
    thread: Option<JoinHandle<()>>,
    sensors: usize,
    /// Samples offered while the thread was busy.
    pub busy: u64,
}

impl Worker {
    /// Starts the thread.
    pub fn start(mut images: Images) -> Worker {
        let sensors = images.sensors();
        let (to, rx) = sync_channel::<PoseSample>(1);
        let (tx, from) = channel();
        let thread = std::thread::Builder::new()
            .name("view-images".into())
            .spawn(move || {
                for s in rx {
                    match images.at(&s) {
                        Ok(Some(set)) => {
                            if tx.send(Ok((s.timestamp_ns, set))).is_err() {
                                return;
                            }
                        }
                        Ok(None) => {}
                        Err(e) => {
                            let _ = tx.send(Err(e));
                            return;
                        }
                    }
                }
            })
            .ok();
        Worker {
            to: thread.is_some().then_some(to),
            from,
            thread,
            sensors,
            busy: 0,
        }
    }

    /// Sensors of the recording's rig.
    pub fn sensors(&self) -> usize {
        self.sensors
    }

    /// Hands `s` to the thread if it is idle; never blocks.
    pub fn offer(&mut self, s: &PoseSample) {
        if let Some(to) = &self.to {
            if let Err(TrySendError::Full(_)) = to.try_send(*s) {
                self.busy += 1;
            }
        }
    }

    /// An image set made since the last call (its sample's time), or why the images stopped.
    pub fn take(&self) -> Option<Result<(u64, ImageSet), ImageError>> {
        self.from.try_recv().ok()
    }

    /// Lets the thread finish the sample in hand and returns what it made since the last take.
    pub fn finish(mut self) -> Vec<Result<(u64, ImageSet), ImageError>> {
        drop(self.to.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.from.try_iter().collect()
    }
}

fn to_bytes(v: &Value) -> Vec<u8> {
    serde_json::to_vec(v).unwrap_or_default()
}

fn encode_jpeg(rgb: &[u8], width: u32, height: u32, quality: u8) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
        .encode(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| e.to_string())?;
    Ok(out)
}

/// Line-list pairs (pixels) of the model's segments as `sensor` sees them from the pose
/// (`t_rig_world`, the inverse of the sample's `T_world_rig`): omnitrack-core's projection, the
/// one the desk's pictures draw, clipped at the image's border.
fn model_pieces(
    sensor: &omnitrack_core::rig::Sensor,
    segments: &[([f64; 3], [f64; 3])],
    t_rig_world: &Pose,
) -> Vec<[Point2<f64>; 2]> {
    let segments = segments.iter().map(|(a, b)| (Point3::from(*a), Point3::from(*b)));
    project_segments(sensor, t_rig_world, segments, SEGMENT_SPACING_PX)
        .iter()
        .flat_map(|run| run.windows(2).map(|w| [w[0], w[1]]))
        .collect()
}

/// Line-list pairs (pixels) of detected edges, along their great circles.
fn edge_pieces(sensor: &omnitrack_core::rig::Sensor, edges: &[omnitrack_edges::Edge]) -> Vec<[Point2<f64>; 2]> {
    let mut pieces = Vec::new();
    for e in edges {
        let mut prev: Option<Point2<f64>> = None;
        for i in 0..=EDGE_SAMPLES {
            let ray = e.ray_at(e.length_rad * i as f64 / EDGE_SAMPLES as f64);
            let px = sensor.project_from_rig(&(e.plane.centre + ray));
            if let (Some(p0), Some(p1)) = (prev, px) {
                pieces.push([p0, p1]);
            }
            prev = px;
        }
    }
    pieces
}

/// A `foxglove.PointsAnnotation` line list.
fn points(t: u64, pieces: &[[Point2<f64>; 2]], c: [f64; 4], thickness: f64) -> Value {
    let colour = json!({"r": c[0], "g": c[1], "b": c[2], "a": c[3]});
    let pts: Vec<Value> = pieces
        .iter()
        .flat_map(|[a, b]| [json!({"x": a.x, "y": a.y}), json!({"x": b.x, "y": b.y})])
        .collect();
    json!({
        "timestamp": time(t),
        "type": 4,
        "points": pts,
        "outline_color": colour,
        "outline_colors": [],
        "fill_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0},
        "thickness": thickness,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};
    use omnitrack_core::status::TrackerState;

    #[test]
    fn a_point_ahead_of_a_sensor_lands_where_its_lens_puts_it() {
        let rig =
            Rig::load(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../firmware_config/ladybug2.toml")).unwrap();
        // The rig stands at (2, 3, 1.5), turned 90° about z: its x axis points along the world's y.
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let s = PoseSample {
            status: TrackerState::Tracking as u8,
            position_m: [2.0, 3.0, 1.5],
            rotation_wxyz: [q.w, q.i, q.j, q.k],
            ..PoseSample::default()
        };
        let t_rig_world = s.pose().unwrap().inverse();
        // A segment 3 m ahead of the rig (world +y), across its view.
        let seg = ([1.5, 6.0, 1.5], [2.5, 6.0, 1.5]);
        let a_rig = t_rig_world.transform_point(&Point3::from(seg.0));
        assert!((a_rig - Point3::new(3.0, 0.5, 0.0)).norm() < 1e-12, "{a_rig}");
        let seen: Vec<_> = rig
            .sensors
            .iter()
            .map(|k| model_pieces(k, &[seg], &t_rig_world))
            .filter(|p| !p.is_empty())
            .collect();
        assert!(!seen.is_empty(), "no sensor sees a segment 3 m ahead");
        for (k, sensor) in rig.sensors.iter().enumerate() {
            let pieces = model_pieces(sensor, &[seg], &t_rig_world);
            if let (Some(first), Some(want)) = (pieces.first(), sensor.project_from_rig(&a_rig)) {
                assert!((first[0] - want).norm() < 1e-9, "sensor {k}");
            }
        }
        let not_a_rotation = PoseSample {
            rotation_wxyz: [0.0; 4],
            ..s
        };
        assert!(not_a_rotation.pose().is_err(), "a damaged sample is not drawn");
    }
}
