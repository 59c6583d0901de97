//! The capture threads: one for a whole-rig [`FrameSource`], or one per [`SensorCapture`] (one
//! capture device, delivering one sensor's images or several sensors' windows of one frame) plus
//! the assembly thread ([`assembly`]).
//!
//! In: the source. Out: frames in pool slots posted through the [`Handover`] (whole-rig), or
//! [`Arrival`]s of images in each sensor's own buffers ([`SensorImages`], of [`super::images`])
//! for the assembly, which posts the frames; faults and the source's failure are counted in the
//! [`Shared`] state. A source's own waits end at the pipeline's stop or halt. Imports run one way: this file starts the assembly; the assembly and this
//! file both use the buffers of `images`, which use neither.

use super::assembly;
use super::images::{Arrival, SensorImages, IMAGES_PER_SENSOR};
use super::options::SensorCapture;
use super::pool::{Handover, Pool};
use super::shared::Shared;
use super::stats::SensorCounters;
use super::stats::ThreadRole;
use super::{PipelineSource, PipelineThread};
use crossbeam::channel::{bounded, Sender};
use omnitrack_config::BudgetConfig;
use omnitrack_core::frame::SensorImage;
use omnitrack_edges::thread_cpu_time;
use omnitrack_io::capture::device::MAX_WINDOWS_PER_DEVICE;
use omnitrack_io::capture::{FrameSource, SourceStats};
use std::thread::{Scope, ScopedJoinHandle};
use std::time::{Duration, Instant};

/// The capture thread of a whole-rig source. Returns the source's counters.
fn capture_rig(source: &mut dyn FrameSource, shared: &Shared, pool: &Pool, handover: Handover) -> SourceStats {
    shared.thread_started(PipelineThread::Capture { sensor: None });
    let mut seq = 0u64;
    // A lossless run with `max_frames` reads that many and no more: read ahead, they would be
    // counted as captured and left.
    while shared.capture_limit.is_none_or(|m| seq < m) {
        let Some(h) = pool.take(shared) else {
            break;
        };
        let mut slot = pool.slot(h);
        let started = Instant::now();
        let cpu = thread_cpu_time();
        // A source's own wait (a real-time replay's gap, a reopening) ends at a stop.
        let got = source.next_frame_or_stop(&mut slot.frame, &|| shared.stopping());
        shared.record_capture(started.elapsed(), thread_cpu_time().saturating_sub(cpu));
        match got {
            Ok(true) => {
                for (img, c) in slot.frame.sensors().iter().zip(shared.sensors.iter()) {
                    if !img.valid {
                        SensorCounters::add(&c.faults, 1);
                    }
                }
                slot.seq = seq;
                slot.arrived = Instant::now();
                seq += 1;
                drop(slot);
                if !handover.post(shared, pool, h) {
                    break;
                }
            }
            Ok(false) => {
                drop(slot);
                pool.release(h);
                if !shared.stopping() {
                    tracing::info!(frames = seq, "source ended");
                }
                break;
            }
            Err(e) => {
                drop(slot);
                pool.release(h);
                shared.fail(e);
                break;
            }
        }
    }
    source.stats().clone()
}

/// The capture thread of one capture device: one image of each of its sensors per read, each
/// taken from that sensor's buffers and announced as an [`Arrival`] of its own.
fn capture_device(
    capture: &mut dyn SensorCapture,
    shared: &Shared,
    images: &[&SensorImages],
    arrivals: Sender<Arrival>,
) {
    let sensors = capture.sensors().to_vec();
    shared.thread_started(PipelineThread::Capture {
        sensor: sensors.first().copied(),
    });
    // Fixed-size lists: nothing is allocated per frame.
    let mut taken = heapless::Vec::<usize, MAX_WINDOWS_PER_DEVICE>::new();
    'frames: loop {
        taken.clear();
        for sensor_images in images {
            match sensor_images.take(shared) {
                Some(i) => {
                    let _ = taken.push(i);
                }
                None => {
                    for (sensor_images, &i) in images.iter().zip(&taken) {
                        sensor_images.release(i);
                    }
                    break 'frames;
                }
            }
        }
        let mut guards: heapless::Vec<_, MAX_WINDOWS_PER_DEVICE> =
            images.iter().zip(&taken).map(|(s, &i)| s.image(i)).collect();
        let started = Instant::now();
        let cpu = thread_cpu_time();
        let got = {
            let mut imgs: heapless::Vec<&mut SensorImage, MAX_WINDOWS_PER_DEVICE> =
                guards.iter_mut().map(|g| &mut **g).collect();
            capture.capture(&mut imgs, &|| shared.stopping())
        };
        shared.record_capture(started.elapsed(), thread_cpu_time().saturating_sub(cpu));
        match got {
            Ok(true) => {
                for (g, &k) in guards.iter().zip(&sensors) {
                    if !g.valid {
                        SensorCounters::add(&shared.sensors[k].faults, 1);
                    }
                }
                drop(guards);
                let arrived = Instant::now();
                for (&k, &slot) in sensors.iter().zip(&taken) {
                    // Room for every buffer of every sensor: never blocks for long.
                    if arrivals
                        .send(Arrival {
                            sensor: k,
                            slot,
                            arrived,
                        })
                        .is_err()
                    {
                        break 'frames;
                    }
                }
            }
            Ok(false) => {
                drop(guards);
                for (sensor_images, &i) in images.iter().zip(&taken) {
                    sensor_images.release(i);
                }
                if !shared.stopping() {
                    tracing::info!(?sensors, "capture stream ended");
                }
                break;
            }
            Err(e) => {
                drop(guards);
                for (sensor_images, &i) in images.iter().zip(&taken) {
                    sensor_images.release(i);
                }
                shared.fail(e);
                break;
            }
        }
    }
}

/// Starts the capture side: one thread for a whole-rig source; for per-sensor sources one per
/// sensor and the assembly thread. `handover` goes to the one thread that posts frames (the
/// whole-rig capture or the assembly). Each handle yields the whole-rig source's counters (`None`
/// from the others).
pub(super) fn spawn_capture<'scope>(
    scope: &'scope Scope<'scope, '_>,
    source: &'scope mut PipelineSource,
    shared: &'scope Shared<'_>,
    pool: &'scope Pool,
    sensor_images: &'scope [SensorImages],
    handover: Handover,
    budgets: &BudgetConfig,
) -> Vec<ScopedJoinHandle<'scope, Option<SourceStats>>> {
    let n = sensor_images.len();
    let mut capture_handles = Vec::new();
    match source {
        PipelineSource::Rig(src) => {
            let src: &mut (dyn FrameSource + Send) = src.as_mut();
            capture_handles.push(
                std::thread::Builder::new()
                    .name("omnitrack-capture".into())
                    .spawn_scoped(scope, move || {
                        let stats = capture_rig(src, shared, pool, handover);
                        shared.add_thread_cpu(ThreadRole::Capture);
                        Some(stats)
                    })
                    .expect("spawn the capture thread"),
            );
        }
        PipelineSource::Sensors { sensors, .. } => {
            let (arrivals_tx, arrivals_rx) = bounded::<Arrival>(n * IMAGES_PER_SENSOR);
            let arrived = Instant::now();
            super::pool::warm_channel(&arrivals_tx, &arrivals_rx, || Arrival {
                sensor: 0,
                slot: 0,
                arrived,
            });
            for capture in sensors.iter_mut() {
                let capture: &mut dyn SensorCapture = capture.as_mut();
                let ids = capture.sensors();
                let images: Vec<&SensorImages> = ids.iter().map(|&k| &sensor_images[k]).collect();
                let name = match ids {
                    [k] => format!("omnitrack-capture-{k}"),
                    _ => format!(
                        "omnitrack-capture-{}",
                        ids.iter().map(|k| k.to_string()).collect::<Vec<_>>().join("+")
                    ),
                };
                let tx = arrivals_tx.clone();
                capture_handles.push(
                    std::thread::Builder::new()
                        .name(name)
                        .spawn_scoped(scope, move || {
                            capture_device(capture, shared, &images, tx);
                            shared.add_thread_cpu(ThreadRole::Capture);
                            None
                        })
                        .expect("spawn a capture thread"),
                );
            }
            drop(arrivals_tx);
            let images = sensor_images;
            let tolerance = Duration::from_secs_f64(budgets.frame_sync_tolerance_ms / 1e3);
            let wait = Duration::from_secs_f64(budgets.frame_assembly_wait_ms / 1e3);
            capture_handles.push(
                std::thread::Builder::new()
                    .name("omnitrack-assembly".into())
                    .spawn_scoped(scope, move || {
                        shared.thread_started(PipelineThread::Assembly);
                        let mut a = assembly::Assembler::new(shared, pool, images, handover, tolerance, wait);
                        a.run(arrivals_rx);
                        shared.add_thread_cpu(ThreadRole::Capture);
                        None
                    })
                    .expect("spawn the assembly thread"),
            );
        }
    }
    capture_handles
}
