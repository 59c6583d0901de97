//! Per-sensor capture: six fake cameras delivering decoded images from memory, one of which
//! dies mid-run; frames are assembled by timestamp and the dead sensor is counted, not waited for.

use super::*;
use omnitrack::capture::device::Window;

/// Decoded images of the first `FRAMES_IN_MEMORY` rendered frames, per frame per sensor.
struct Images {
    frames: Vec<Vec<Vec<u8>>>,
    period_ns: u64,
}

const FRAMES_IN_MEMORY: usize = 12;

/// What the fake cameras share: the images, the wall-clock start, and the failure plan.
struct FakeEnv {
    images: Arc<Images>,
    start: Instant,
    /// Wall-clock time between frames.
    pace: Duration,
    /// (sensor, from frame): that sensor's reads fail from then on.
    dead: Option<(usize, u64)>,
    /// (sensor, ns): added to that sensor's timestamps.
    skew: Option<(usize, u64)>,
}

/// A camera serving the decoded images back and forth at `pace`: one sensor's, or, for a device
/// split into windows, every window's sensor image placed at its window of the frame.
struct FakeCamera {
    sensor: usize,
    size: (u32, u32),
    windows: Option<Vec<Window>>,
    env: Arc<FakeEnv>,
    next: u64,
}

impl LiveCamera for FakeCamera {
    type Env = Arc<FakeEnv>;

    fn open(env: &mut Arc<FakeEnv>, device: &CaptureDevice, _: &SourceOptions) -> Result<Self, SourceError> {
        Ok(FakeCamera {
            sensor: device.index,
            size: (device.width, device.height),
            windows: (!device.direct).then(|| device.windows.clone()),
            env: Arc::clone(env),
            next: 0,
        })
    }

    fn name(&self) -> &str {
        "fake"
    }

    fn frame_size(&self) -> (u32, u32) {
        self.size
    }

    fn read(&mut self, img: &mut SensorImage) -> Result<u64, ReadFailure> {
        let j = self.next;
        self.next += 1;
        let due = self.env.start + self.env.pace * j as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        if self.env.dead.is_some_and(|(k, from)| k == self.sensor && j >= from) {
            return Err(ReadFailure {
                fault: ImageFault::Dropped,
                lost: false,
                detail: FailureDetail::Text("fake camera: no image"),
            });
        }
        let cycle = 2 * (FRAMES_IN_MEMORY as u64 - 1);
        let c = j % cycle;
        let src = if c < FRAMES_IN_MEMORY as u64 { c } else { cycle - c } as usize;
        let images = &self.env.images.frames[src];
        match &self.windows {
            None => img.pixels_mut().copy_from_slice(&images[self.sensor]),
            Some(windows) => {
                let stride = self.size.0 as usize * 3;
                for w in windows {
                    let row = w.width as usize * 3;
                    for (r, src_row) in images[w.sensor].chunks_exact(row).enumerate() {
                        let at = (w.y as usize + r) * stride + w.x as usize * 3;
                        img.pixels_mut()[at..at + row].copy_from_slice(src_row);
                    }
                }
            }
        }
        let skew = self.env.skew.filter(|(k, _)| *k == self.sensor).map_or(0, |(_, s)| s);
        Ok(j * self.env.images.period_ns + skew)
    }
}

fn images_in_memory(f: &Fixture) -> Arc<Images> {
    static I: OnceLock<Arc<Images>> = OnceLock::new();
    Arc::clone(I.get_or_init(|| {
        let mut source = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap();
        let mut frame = FrameSet::for_rig(source.rig());
        let mut frames = Vec::new();
        let mut ts = Vec::new();
        while frames.len() < FRAMES_IN_MEMORY && source.next_frame(&mut frame).unwrap() {
            ts.push(frame.timestamp_ns().unwrap());
            frames.push(frame.sensors().iter().map(|s| s.pixels().to_vec()).collect());
        }
        Arc::new(Images {
            frames,
            period_ns: ts[1] - ts[0],
        })
    }))
}

#[test]
fn per_sensor_capture_assembles_frames_by_timestamp_and_survives_a_dead_sensor() {
    let _serial = serial();
    let f = fixture();
    let rig = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible)
        .unwrap()
        .rig()
        .clone();
    const FRAMES: u64 = 60;
    const DEAD: usize = 4;
    const FROM: u64 = 20;
    let env = Arc::new(FakeEnv {
        images: images_in_memory(f),
        start: Instant::now() + Duration::from_millis(300),
        pace: Duration::from_millis(50),
        dead: Some((DEAD, FROM)),
        // Within the 5 ms tolerance.
        skew: Some((1, 2_000_000)),
    });
    let source = live_sensors::<FakeCamera>(&rig, env, &SourceOptions::default()).unwrap();
    let mut opts = options(f, "per-sensor");
    opts.run.max_frames = Some(FRAMES);
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let summary = run_pipeline(source, &f.model, &f.table, &TrackerConfig::default(), &opts, &mut sink).unwrap();
    eprintln!("{summary}");
    eprintln!("{:?}", summary.sensors);
    assert_eq!(summary.reason, RunEnd::MaxFrames);
    assert_eq!(summary.frames_processed, FRAMES);
    assert!(summary.source.is_none());
    // Before the failure the six images of an instant made one frame; after it, five.
    let records = &sink.records;
    let whole = records
        .iter()
        .filter(|r| r.sequence < FROM && r.valid_sensors == 6)
        .count();
    assert!(whole as u64 >= FROM - 2, "{whole} of the first {FROM} frames complete");
    let after: Vec<&FrameRecord> = records.iter().filter(|r| r.sequence > FROM).collect();
    assert!(after.iter().all(|r| r.valid_sensors <= 5));
    let five = after.iter().filter(|r| r.valid_sensors == 5).count();
    assert!(
        five * 10 >= after.len() * 9,
        "{five} of {} frames with 5 sensors",
        after.len()
    );
    let tracked = records.iter().filter(|r| r.result.pose.is_some()).count();
    assert!(
        tracked * 10 >= records.len() * 7,
        "{tracked} of {} tracked",
        records.len()
    );
    let dead = &summary.sensors[DEAD];
    assert!(dead.faults >= FRAMES - FROM - 2, "{dead:?}");
    // Its failed reads stood for it in their frames: hardly any frame waited for it in vain.
    assert!(dead.sync_missed <= 2, "{dead:?}");
    assert!(summary.stage(Stage::Capture).count >= 6 * FRAMES);
    // Timestamps of a frame are within the tolerance of each other.
    assert!(records.iter().all(|r| r.sequence == 0 || r.timestamp_ns > 0));
}

/// A 360° camera that delivers all six sensors' images in one frame (3 × 2 windows, each sensor
/// `crop`ped from it, as a dual-fisheye camera holds its two circles): one capture thread reads
/// the device, every frame is whole, and the poses are those of the ground truth.
#[test]
fn one_device_split_into_six_windows_tracks_as_six_cameras() {
    let _serial = serial();
    let f = fixture();
    let source = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap();
    let truth = source.ground_truth().unwrap().clone();
    let mut rig = source.rig().clone();
    for (k, s) in rig.sensors.iter_mut().enumerate() {
        s.device = Some("/dev/fake-360".into());
        s.crop = Some([(k % 3) as u32 * s.width, (k / 3) as u32 * s.height, s.width, s.height]);
    }
    let images = images_in_memory(f);
    let period_ns = images.period_ns;
    let env = Arc::new(FakeEnv {
        images,
        start: Instant::now() + Duration::from_millis(300),
        pace: Duration::from_millis(50),
        dead: None,
        skew: None,
    });
    const FRAMES: u64 = 30;
    let source = live_sensors::<FakeCamera>(&rig, env, &SourceOptions::default()).unwrap();
    let omnitrack::runtime::pipeline::PipelineSource::Sensors { sensors, .. } = &source else {
        panic!("a live source is per device");
    };
    assert_eq!(sensors.len(), 1);
    assert_eq!(sensors[0].sensors(), &[0, 1, 2, 3, 4, 5]);
    let mut opts = options(f, "one-device");
    opts.run.max_frames = Some(FRAMES);
    let mut sink = Recorder {
        records: Vec::new(),
        tum: None,
        stop_after: None,
    };
    let summary = run_pipeline(source, &f.model, &f.table, &TrackerConfig::default(), &opts, &mut sink).unwrap();
    eprintln!("{summary}");
    assert_eq!(summary.frames_processed, FRAMES);
    assert!(sink.records.iter().all(|r| r.valid_sensors == 6), "every frame whole");
    // Frame j showed the images of recorded frame `src`: its pose is that frame's truth.
    let cycle = 2 * (FRAMES_IN_MEMORY as u64 - 1);
    let mut worst = 0.0f64;
    let mut tracked = 0;
    for r in &sink.records {
        let Some(p) = &r.result.pose else { continue };
        let c = (r.timestamp_ns / period_ns) % cycle;
        let src = if c < FRAMES_IN_MEMORY as u64 { c } else { cycle - c } as usize;
        let t = &truth[src].pose;
        worst = worst.max((p.translation.vector - t.translation.vector).norm());
        tracked += 1;
    }
    let start = common::start_frames(
        TrackerConfig::default().initialisation.time_budget_ms,
        period_ns as f64 / 1e6,
    );
    assert!(tracked as u64 >= FRAMES - start as u64, "{tracked} of {FRAMES} tracked");
    assert!(worst < 0.10, "worst {:.1} cm", worst * 100.0);
}
