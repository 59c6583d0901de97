//! Per-sensor capture: six fake cameras delivering decoded images from memory, one of which
//! dies mid-run; frames are assembled by timestamp and the dead sensor is counted, not waited for.

use super::*;

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

/// A camera of one sensor serving the decoded images back and forth at `pace`.
struct FakeCamera {
    sensor: usize,
    env: Arc<FakeEnv>,
    next: u64,
}

impl LiveCamera for FakeCamera {
    type Env = Arc<FakeEnv>;

    fn open(env: &mut Arc<FakeEnv>, sensor: &Sensor, _: &SourceOptions) -> Result<Self, SourceError> {
        Ok(FakeCamera {
            sensor: sensor.id,
            env: Arc::clone(env),
            next: 0,
        })
    }

    fn name(&self) -> &str {
        "fake"
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
        img.pixels_mut()
            .copy_from_slice(&self.env.images.frames[src][self.sensor]);
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
