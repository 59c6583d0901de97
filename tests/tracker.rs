//! The tracker end to end on a rendered `lab` recording (Koch–Teller §4.1, §4.2): initialisation
//! from a 3 m search volume, 100 frames without loss of lock, recovery after the rig is occluded
//! for a second, no heap allocation (and no memory first written) while tracking and
//! relocalising, and the same through rigs other than the shipped one (`tools/rigs/`).
#![cfg(feature = "desk")]

use nalgebra::{Point3, Vector3};
use omnitrack::capture::{FrameSource, Pacing, ReplaySource, SourceError, SourceStats};
use omnitrack::config::{GridBlank, TrackerConfig};
use omnitrack::edges::EdgeDetector;
use omnitrack::frame::FrameSet;
use omnitrack::runtime::{track, FrameRecord, RunOptions};
use omnitrack::tracker::{SearchKind, SearchVolume, Tracker, TrackerEvent, TrackerState, TrackerStats};
use omnitrack::Rig;
use std::path::Path;
use std::sync::OnceLock;

mod common;
use common::LabRecording;

#[global_allocator]
static ALLOCATOR: common::Counting = common::Counting;

const FRAMES: usize = 100;

/// One recording and table for all tests of this binary (rendering is the slow part).
fn fixture() -> &'static LabRecording {
    static F: OnceLock<LabRecording> = OnceLock::new();
    F.get_or_init(|| common::lab_recording(FRAMES))
}

/// A 3 m search volume whose centre is 1 m from the first true position (not on it).
/// Frames without a pose at the start of the 5 Hz replays ([`common::start_frames`]).
fn start_frames() -> usize {
    common::start_frames(config().initialisation.time_budget_ms, 200.0)
}

fn hint(f: &LabRecording) -> SearchVolume {
    let p = f.truth[0].pose.translation.vector + Vector3::new(0.8, -0.6, 0.0);
    SearchVolume {
        centre: Point3::from(p),
        diameter_m: Some(3.0),
    }
}

fn errors(f: &LabRecording, timestamp_ns: u64, pose: &omnitrack::Pose) -> (f64, f64) {
    let g = f
        .truth
        .iter()
        .find(|s| s.timestamp_ns.abs_diff(timestamp_ns) < 1_000_000)
        .expect("a ground-truth pose for every frame");
    (
        (pose.translation.vector - g.pose.translation.vector).norm(),
        pose.rotation.angle_to(&g.pose.rotation).to_degrees(),
    )
}

/// The default configuration with the consensus's clock backstop (30 ms) out of reach: these
/// tests run side by side on a loaded machine. The searches keep the shipped budgets: they are
/// work, so runs repeat under load, and a search's result is taken up when its budget has passed
/// on the recording's clock (module `background`), as on the device. Time bounds are the
/// benchmarks' business.
fn config() -> TrackerConfig {
    let mut cfg = TrackerConfig::default();
    cfg.maintenance.time_budget_ms = 10_000.0;
    cfg
}

/// The first `n` frames of the fixture's replay: each one's timestamp and detected edges.
fn detected_frames(f: &LabRecording, n: usize) -> Vec<(u64, Vec<omnitrack::edges::Edge>)> {
    let (mut source, _, _, mut frame, mut detector) = replay(f);
    std::iter::from_fn(|| {
        source
            .next_frame(&mut frame)
            .unwrap()
            .then(|| (frame.timestamp_ns().unwrap(), detector.detect(&frame).to_vec()))
    })
    .take(n)
    .collect()
}

/// The fixture's replay, its rig, the test configuration, a frame buffer and a detector.
fn replay(f: &LabRecording) -> (ReplaySource, Rig, TrackerConfig, FrameSet, EdgeDetector) {
    let source = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap();
    let rig = source.rig().clone();
    let cfg = config();
    let frame = FrameSet::for_rig(&rig);
    let detector = EdgeDetector::new(&rig, &cfg.edges);
    (source, rig, cfg, frame, detector)
}

/// Tracks `source` with the test configuration from the 3 m hint, each frame to `sink` as it is
/// answered on time (the late results of frames kept during a search are left out: these tests
/// judge what a live subscriber gets, frame by frame).
fn run_hinted(
    f: &LabRecording,
    source: &mut dyn FrameSource,
    sink: &mut dyn FnMut(&FrameRecord, &Tracker) -> Result<(), omnitrack::runtime::SinkError>,
) -> TrackerStats {
    run_hinted_seeded(f, source, RunOptions::default().seed, sink)
}

/// [`run_hinted`] with the tracker's sampling drawn from `seed`.
fn run_hinted_seeded(
    f: &LabRecording,
    source: &mut dyn FrameSource,
    seed: u64,
    sink: &mut dyn FnMut(&FrameRecord, &Tracker) -> Result<(), omnitrack::runtime::SinkError>,
) -> TrackerStats {
    let opts = RunOptions {
        hint: Some(hint(f)),
        seed,
        ..RunOptions::default()
    };
    track(source, &f.model, &f.table, &config(), &opts, &mut |r, t| {
        if r.late {
            Ok(())
        } else {
            sink(r, t)
        }
    })
    .unwrap()
}

/// A recording whose images are uniform grey for a range of frames (in the first `sensors`
/// sensors): a hand over the rig.
struct Occluded {
    inner: ReplaySource,
    frame: usize,
    from: usize,
    to: usize,
    /// The first this many sensors are covered.
    sensors: usize,
}

impl FrameSource for Occluded {
    fn rig(&self) -> &Rig {
        self.inner.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        let more = self.inner.next_frame(out)?;
        if more && (self.from..self.to).contains(&self.frame) {
            for s in out.sensors_mut().iter_mut().take(self.sensors) {
                s.pixels_mut().iter_mut().for_each(|p| *p = 40);
            }
        }
        self.frame += 1;
        Ok(more)
    }
    fn stats(&self) -> &SourceStats {
        self.inner.stats()
    }
}

#[test]
fn initialises_from_a_3m_volume_within_10cm_and_1deg_and_tracks_100_frames_without_loss() {
    let f = fixture();
    let mut source = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap();
    let mut first: Option<(f64, f64)> = None;
    let mut worst = (0.0f64, 0.0f64);
    let mut sum2 = 0.0;
    let mut n = 0;
    let stats = run_hinted(f, &mut source, &mut |r, _| {
        if let Some(p) = &r.result.pose {
            let (dp, dr) = errors(f, r.timestamp_ns, p);
            first.get_or_insert((dp, dr));
            worst = (worst.0.max(dp), worst.1.max(dr));
            sum2 += dp * dp;
            n += 1;
        }
        Ok(())
    });
    let (dp, dr) = first.expect("initialised");
    assert!(dp < 0.10 && dr < 1.0, "first pose {:.1} cm, {dr:.2}°", dp * 100.0);
    assert_eq!(stats.frames, FRAMES as u64);
    assert_eq!(stats.losses, 0, "{stats:?}");
    assert!(stats.tracked as usize >= FRAMES - start_frames(), "{stats:?}");
    let rmse = (sum2 / n as f64).sqrt();
    assert!(
        rmse < 0.05,
        "RMSE {:.1} cm, worst {:.1} cm {:.2}°",
        rmse * 100.0,
        worst.0 * 100.0,
        worst.1
    );
}

/// Half the sensors covered for two seconds: every frame explains about half of what the
/// frames before did, so each is suspect (`maintenance.min_explained_ratio`), but the local
/// search finds nothing that explains more, so the poses stand and lock is never lost (a frame
/// or two with too few inliers may go without a pose; a suspect frame's pose comes late, when
/// its search is taken up), and the accuracy is back once the sensors are uncovered.
#[test]
fn a_poorer_view_is_suspected_but_not_lost() {
    let f = fixture();
    let mut source = Occluded {
        inner: ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap(),
        frame: 0,
        from: 30,
        to: 40,
        sensors: 3,
    };
    let mut covered = Vec::new();
    let mut worst = 0.0f64;
    let mut stamps = Vec::new();
    let mut posed = std::collections::HashSet::new();
    let opts = RunOptions {
        hint: Some(hint(f)),
        ..RunOptions::default()
    };
    let stats = track(&mut source, &f.model, &f.table, &config(), &opts, &mut |r, _| {
        if let Some(p) = &r.result.pose {
            posed.insert(r.timestamp_ns);
            // Three sensors see too little for the usual accuracy: judge after them.
            if r.timestamp_ns >= f.truth[45].timestamp_ns - 1_000_000 {
                worst = worst.max(errors(f, r.timestamp_ns, p).0);
            }
        }
        if r.late {
            return Ok(());
        }
        if (30..40).contains(&r.sequence) {
            covered.push(r.result.explained);
        }
        if r.sequence >= 10 {
            assert_eq!(r.result.state, TrackerState::Tracking, "frame {}", r.sequence);
            stamps.push(r.timestamp_ns);
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(stats.losses, 0, "{stats:?}");
    let untracked = stamps.iter().filter(|t| !posed.contains(t)).count();
    assert!(untracked <= 2, "{untracked} frames without a pose, on time or late");
    // The covered frames did explain less: the check had something to judge.
    let low = covered.iter().filter(|&&e| e < 0.45).count();
    assert!(low >= 5, "explained fractions while covered: {covered:?}");
    assert!(worst < 0.15, "worst error from frame 45 on {:.1} cm", worst * 100.0);
}

#[test]
fn recovers_after_the_rig_is_occluded_for_a_second() {
    let f = fixture();
    // Frames 40..45 at 5 Hz: one second of grey images.
    let mut source = Occluded {
        inner: ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap(),
        frame: 0,
        from: 40,
        to: 45,
        sensors: usize::MAX,
    };
    let mut states = Vec::new();
    let mut searches = Vec::new();
    let mut late = Vec::new();
    let stats = run_hinted(f, &mut source, &mut |r, t| {
        states.push(r.result.state);
        searches.push(t.search_under_way());
        if r.sequence >= 60 {
            if let Some(p) = &r.result.pose {
                late.push(errors(f, r.timestamp_ns, p));
            }
        }
        Ok(())
    });
    let lost_at = states
        .iter()
        .position(|s| *s == TrackerState::Lost)
        .expect("lock is lost");
    assert!((40..48).contains(&lost_at), "lost at frame {lost_at}");
    assert!(
        states[lost_at..].contains(&TrackerState::Tracking),
        "tracking resumes: {states:?}"
    );
    assert!(stats.losses >= 1 && stats.reinitialisations >= 1, "{stats:?}");
    // What the status service says meanwhile: the first search, then after the loss the
    // re-initialisation, and nothing once tracking resumed for good.
    assert_eq!(searches[0], Some(SearchKind::Initialisation));
    let first_pose = states.iter().position(|s| *s == TrackerState::Tracking).unwrap();
    assert!(
        searches[first_pose..]
            .iter()
            .all(|k| *k != Some(SearchKind::Initialisation)),
        "{searches:?}"
    );
    assert!(
        searches[lost_at..].contains(&Some(SearchKind::Reinitialisation)),
        "{searches:?}"
    );
    assert_eq!(searches.last(), Some(&None), "{searches:?}");
    assert!(late.len() >= 35, "frames tracked after recovery: {}", late.len());
    let worst = late.iter().fold(0.0f64, |m, e| m.max(e.0));
    assert!(worst < 0.15, "worst error after recovery {:.1} cm", worst * 100.0);
}

/// The fixture's frames detected, and the walk that turns back twice: the walk, then back from
/// its end and forth again, two frames skipped at each turn (frame indices), with the rig, the
/// test configuration and the frame period.
fn turn_back_walk(f: &LabRecording) -> (Rig, TrackerConfig, Vec<Vec<omnitrack::edges::Edge>>, Vec<usize>, u64) {
    let (mut source, rig, cfg, mut frame, mut detector) = replay(f);
    let mut recorded = Vec::with_capacity(FRAMES);
    while source.next_frame(&mut frame).unwrap() {
        recorded.push(detector.detect(&frame).to_vec());
    }
    let period_ns = f.truth[1].timestamp_ns - f.truth[0].timestamp_ns;
    let last = recorded.len() - 1;
    let schedule: Vec<usize> = (0..=last).chain((60..=last - 3).rev()).chain(63..=last).collect();
    (rig, cfg, recorded, schedule, period_ns)
}

/// Tracking allocates nothing per frame; nor does a bounded search (here the hinted first one:
/// the module doc of `tracker::init`), the translation vote and its height sweep included; nor
/// do relocalisations, however many (issue 50): after the walk the rig turns back twice, each
/// time skipping two frames, which the motion prior cannot follow. And once the first search and
/// the walk have run, no frame writes a page of memory it had not written before: the buffers a
/// relocalisation fills (the frames kept while it runs, its candidates) are resident from start-up,
/// so the process's memory does not creep up with each search (module doc of
/// `omnitrack_core::memory`).
#[test]
fn tracking_searches_and_relocalisations_allocate_nothing_and_touch_no_new_memory() {
    let f = fixture();
    let (rig, cfg, recorded, schedule, period_ns) = turn_back_walk(f);
    let last = recorded.len() - 1;
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
    common::assert_counter_works();
    let (mut allocated, mut counted, mut tracking_frames) = (0, 0, 0);
    let (mut search_allocated, mut searches) = (0, 0);
    let mut faults_after_walk = Vec::new();
    for (k, &i) in schedule.iter().enumerate() {
        let ts = k as u64 * period_ns;
        let edges = &recorded[i];
        let tracking = tracker.state() == TrackerState::Tracking;
        let faults = common::minor_faults();
        let (r, n) = common::allocations_in(|| tracker.process(edges, ts));
        let faults = common::minor_faults() - faults;
        if k > last && faults > 0 {
            faults_after_walk.push((k, faults));
        }
        if tracking {
            allocated += n;
            counted += 1;
            tracking_frames += r.pose.is_some() as usize;
        } else {
            // The first frame starts the search (run here, with no worker attached), the next
            // frames are kept until it is due, and then caught up on.
            if tracker.stats().frames == 1 {
                assert!(tracker.searching() && r.event.is_none(), "{:?}", r.event);
            }
            // Taken up, the search reports itself on its own frame, late (its commit, on trial,
            // comes out with the frames that held it: module `tracker::search`).
            searches += tracker
                .late()
                .iter()
                .filter(|(_, r)| matches!(r.event, Some(TrackerEvent::Searched(_))))
                .count();
            search_allocated += n;
        }
    }
    let stats = tracker.stats();
    eprintln!("{stats:?}; page faults after the walk (frame, faults): {faults_after_walk:?}");
    assert!(counted >= 160 && tracking_frames >= 160, "{counted} frames counted");
    assert!(stats.relocalisations >= 2, "{stats:?}");
    // The frames after each turn held the relocalised poses: published, none withdrawn.
    assert_eq!(stats.relocalisations_withdrawn, 0, "{stats:?}");
    assert_eq!(stats.losses, 0, "{stats:?}");
    assert_eq!(allocated, 0, "allocations while tracking, relocalisations included");
    assert_eq!(searches, 1);
    assert_eq!(
        search_allocated, 0,
        "allocations in the hinted search, its wait and its catch-up"
    );
    assert!(
        faults_after_walk.is_empty(),
        "frames that wrote memory not written before (frame, pages): {faults_after_walk:?}"
    );
}

/// The turn from the image (`motion.frame_rotation`, off by default): on the walk that turns back
/// twice skipping two frames (the test above), the turns the motion model cannot follow are
/// measured from the frames' edges, nothing is allocated for it, and the walk is held as well.
#[test]
fn the_turn_measured_from_the_image_allocates_nothing_and_follows_a_turn_back() {
    let f = fixture();
    let (rig, mut cfg, recorded, schedule, period_ns) = turn_back_walk(f);
    cfg.motion.frame_rotation = true;
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
    let (mut allocated, mut worst) = (0, 0.0f64);
    for (k, &i) in schedule.iter().enumerate() {
        let tracking = tracker.state() == TrackerState::Tracking;
        let (r, n) = common::allocations_in(|| tracker.process(&recorded[i], k as u64 * period_ns));
        if tracking {
            allocated += n;
            if let Some(p) = &r.pose {
                worst = worst.max(errors(f, f.truth[i].timestamp_ns, p).0);
            }
        }
    }
    let stats = tracker.stats();
    eprintln!("{stats:?}; worst {:.1} cm", worst * 100.0);
    assert_eq!(allocated, 0, "allocations while tracking with the turn from the image");
    assert!(stats.frame_turns >= 1, "no turn taken from the image: {stats:?}");
    assert_eq!(stats.losses, 0, "{stats:?}");
    assert!(worst < 0.10, "worst {:.1} cm", worst * 100.0);
}

/// What a schedule of recorded frames (None: a frame that shows nothing) publishes, played
/// through a tracker hinted as `hint`: each schedule frame's pose, late answers included (after
/// the end too), the relocalised answers published late, and the tracker's totals.
struct Played {
    published: std::collections::HashMap<u64, omnitrack::Pose>,
    /// The stamps of the relocalised answers published late.
    relocalised_late: Vec<u64>,
    stats: TrackerStats,
    period_ns: u64,
}

fn play(f: &LabRecording, schedule: &[Option<usize>]) -> Played {
    play_with(f, schedule, |_| {})
}

/// [`play`] with the configuration changed by `change`.
fn play_with(f: &LabRecording, schedule: &[Option<usize>], change: impl FnOnce(&mut TrackerConfig)) -> Played {
    let (_, rig, mut cfg, _, _) = replay(f);
    change(&mut cfg);
    let recorded: Vec<_> = detected_frames(f, FRAMES).into_iter().map(|(_, e)| e).collect();
    let period_ns = f.truth[1].timestamp_ns - f.truth[0].timestamp_ns;
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
    let mut published = std::collections::HashMap::new();
    let mut relocalised_late = Vec::new();
    let blind = Vec::new();
    let mut note_late = |tracker: &Tracker, published: &mut std::collections::HashMap<_, _>| {
        for (t, late) in tracker.late() {
            if matches!(late.event, Some(TrackerEvent::Relocalised)) && late.pose.is_some() {
                relocalised_late.push(*t);
            }
            if let Some(p) = late.pose {
                published.insert(*t, p);
            }
        }
    };
    for (k, i) in schedule.iter().enumerate() {
        let ts = k as u64 * period_ns;
        let r = tracker.process(i.map_or(&blind, |i| &recorded[i]), ts);
        if let Some(p) = r.pose {
            published.insert(ts, p);
        }
        note_late(&tracker, &mut published);
    }
    tracker.finish();
    note_late(&tracker, &mut published);
    Played {
        published,
        relocalised_late,
        stats: *tracker.stats(),
        period_ns,
    }
}

impl Played {
    fn has_pose(&self, k: usize) -> bool {
        self.published.contains_key(&(k as u64 * self.period_ns))
    }

    /// Every pose published for a schedule frame that shows the building lies within 15 cm and
    /// 1° of the truth.
    fn assert_none_wrong(&self, f: &LabRecording, schedule: &[Option<usize>]) {
        for (k, i) in schedule.iter().enumerate() {
            let (Some(i), Some(p)) = (i, self.published.get(&(k as u64 * self.period_ns))) else {
                continue;
            };
            let (dp, dr) = errors(f, f.truth[*i].timestamp_ns, p);
            assert!(
                dp < 0.15 && dr < 1.0,
                "frame {k} (recording frame {i}): {dp:.3} m {dr:.2}°"
            );
        }
    }
}

/// A relocalised pose is published only once a later frame's maintenance holds it (module
/// `tracker::relocalise`, "On probation"). The rig walks, turns back skipping two frames (the
/// motion prior fails: a relocalisation), and the next frames show nothing: the relocalised pose
/// is withdrawn unpublished, the lock is lost, and the walk back finds the rig again. The same
/// turn followed by frames that show the building publishes it (the test above).
#[test]
fn a_relocalised_pose_no_later_frame_holds_is_withdrawn_unpublished() {
    let f = fixture();
    let last = FRAMES - 1;
    // The walk; back from its end two frames skipped; four frames that show nothing; back on.
    let schedule: Vec<Option<usize>> = (0..=last)
        .map(Some)
        .chain([Some(last - 3)])
        .chain([None; 4])
        .chain((20..=last - 8).rev().map(Some))
        .collect();
    let played = play(f, &schedule);
    let stats = played.stats;
    assert!(stats.relocalisations >= 1, "{stats:?}");
    assert!(stats.relocalisations_withdrawn >= 1, "{stats:?}");
    // The turn's relocalised answer is not published, late or otherwise. (A later relocalisation
    // on the walk back that the next frame holds is published, and judged below.)
    let turn_ns = (last + 1) as u64 * played.period_ns;
    assert!(
        !played.relocalised_late.contains(&turn_ns),
        "the turn's relocalised answer was published: {stats:?}"
    );
    assert!(stats.losses >= 1, "{stats:?}");
    // Nothing was published for the turn's frame or the blind ones.
    for k in last + 1..=last + 5 {
        assert!(!played.has_pose(k), "frame {k} of the schedule has a pose");
    }
    // Found again on the walk back, and nothing published anywhere is wrong.
    let after = (last + 6..schedule.len()).filter(|&k| played.has_pose(k)).count();
    assert!(after >= 20, "{after} frames posed on the walk back: {stats:?}");
    played.assert_none_wrong(f, &schedule);
}

/// A fit outside the motion filter's gate that the rig could have reached only faster than
/// `motion.max_speed_m_s` is a bad frame, not a stop the motion model did not expect (module
/// `tracker::maintenance`; walking through FZK-Haus such a fit, 0.3 m along the walls in one
/// frame, restarted the filter at 3 m/s and the pose slid 1.9 m). The rig walks; one frame is
/// skipped (its successor comes at its time, as if the rig had walked twice as fast): the fit
/// there is refused and the local search decides the frame, and the walk is tracked on with
/// nothing published wrong.
#[test]
fn a_fit_the_rig_could_not_have_walked_to_is_a_bad_frame() {
    let f = fixture();
    let period_s = (f.truth[1].timestamp_ns - f.truth[0].timestamp_ns) as f64 * 1e-9;
    let at = |i: usize| f.truth[i].pose.translation.vector;
    // The walk's pace at frame 40; one frame skipped there is twice that pace.
    let from = 40;
    let pace = (at(from) - at(from - 1)).norm() / period_s;
    let schedule: Vec<Option<usize>> = (0..=from).chain(from + 2..FRAMES).map(Some).collect();
    // A rig that walks at most 1.3 times the pace, and a filter sure of it (acceleration noise
    // 0.2 m/s² per √s), so that the skipped frame lies outside the filter's gate.
    let played = play_with(f, &schedule, |cfg| {
        cfg.motion.max_speed_m_s = 1.3 * pace;
        cfg.motion.accel_noise_m_s2 = 0.2;
    });
    let stats = played.stats;
    assert!(stats.too_fast >= 1, "{stats:?}");
    // A bad frame: the local search decides it (it finds the truth of the image here, which the
    // next frame holds), instead of the filter restarting at twice the pace.
    assert!(stats.relocalisations >= 1, "{stats:?}");
    let after = (from + 2..schedule.len()).filter(|&k| played.has_pose(k)).count();
    assert!(
        after + 10 >= schedule.len() - from - 2,
        "{after} frames posed after the jump: {stats:?}"
    );
    played.assert_none_wrong(f, &schedule);
}

/// A rig that walks and then stands still holds where it stopped (module
/// `tracker::maintenance`, the second opinion): the same image frame after frame must give the
/// same place, even though the motion model first expects the walk to go on. (Before a curtain
/// wall's repeated mullions, a solve that slid along them stood whenever the refit near the
/// prediction did not beat it clearly, and a still rig ended 32–54 cm off.)
#[test]
fn a_rig_that_stops_holds_where_it_stopped() {
    let f = fixture();
    let stop = 40;
    let schedule: Vec<Option<usize>> = (0..=stop).chain([stop; 40]).map(Some).collect();
    let played = play(f, &schedule);
    let stats = played.stats;
    let still: Vec<(f64, f64)> = (stop + 1..schedule.len())
        .filter_map(|k| played.published.get(&(k as u64 * played.period_ns)))
        .map(|p| errors(f, f.truth[stop].timestamp_ns, p))
        .collect();
    assert!(still.len() >= 35, "{} still frames posed: {stats:?}", still.len());
    let worst = still.iter().fold((0.0f64, 0.0f64), |w, e| (w.0.max(e.0), w.1.max(e.1)));
    assert!(
        worst.0 < 0.03 && worst.1 < 0.5,
        "worst still frame {:.1} cm {:.2}°: {stats:?}",
        worst.0 * 100.0,
        worst.1
    );
    played.assert_none_wrong(f, &schedule);
}

/// A re-initialisation after a loss is published only once the next frame's maintenance holds
/// it (module `tracker::search`, "On trial"). The rig walks, goes blind until the lock is lost,
/// shows one frame (the re-initialisation's search frame) and goes blind again: the pose the
/// search commits there is withdrawn unpublished, the lock is lost again, and when the rig is
/// seen again it is found, with nothing published anywhere wrong.
#[test]
fn a_reinitialisation_no_later_frame_holds_is_withdrawn_unpublished() {
    let f = fixture();
    let seen = 45;
    let schedule: Vec<Option<usize>> = (0..=40)
        .map(Some)
        .chain([None; 4])
        .chain([Some(seen)])
        .chain([None; 8])
        .chain((seen + 1..FRAMES).map(Some))
        .collect();
    let played = play(f, &schedule);
    let stats = played.stats;
    assert!(stats.losses >= 2, "{stats:?}");
    assert!(stats.reinitialisations_withdrawn >= 1, "{stats:?}");
    // Nothing was published for the seen frame between the blind ones.
    let at = schedule.iter().position(|i| *i == Some(seen)).unwrap();
    for k in 41..at + 9 {
        assert!(!played.has_pose(k), "frame {k} of the schedule has a pose: {stats:?}");
    }
    let after = (at + 9..schedule.len()).filter(|&k| played.has_pose(k)).count();
    assert!(
        after >= 20,
        "{after} frames posed after the rig is seen again: {stats:?}"
    );
    played.assert_none_wrong(f, &schedule);
}

/// A search frame that shows too little (here: only one of the six sensors' edges) commits
/// nothing: its candidates explain less than `accept_explained_fraction` of what they predict,
/// or less than `accept_support_fraction` of the longest edges, or no candidate is a clear
/// winner over the others. The next whole frames search again and commit to the truth.
#[test]
fn a_frame_that_shows_too_little_commits_nothing_and_the_next_frames_find_the_truth() {
    let f = fixture();
    let (mut source, rig, cfg, mut frame, mut detector) = replay(f);
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
    assert!(source.next_frame(&mut frame).unwrap());
    let few: Vec<_> = detector
        .detect(&frame)
        .iter()
        .filter(|e| e.sensor == 0)
        .cloned()
        .collect();
    let r = tracker.process(&few, frame.timestamp_ns().unwrap());
    assert_eq!(r.state, TrackerState::Initialising, "{:?}", r.event);
    assert!(r.pose.is_none());
    assert!(tracker.searching(), "{:?}", r.event);

    let mut committed = None;
    while committed.is_none() && source.next_frame(&mut frame).unwrap() {
        let ts = frame.timestamp_ns().unwrap();
        let r = tracker.process(detector.detect(&frame), ts);
        if let (TrackerState::Tracking, Some(p)) = (r.state, r.pose) {
            committed = Some(errors(f, ts, &p));
        }
    }
    assert!(tracker.stats().reinitialisations >= 1, "searched again");
    let (dp, dr) = committed.expect("committed");
    assert!(dp < 0.10 && dr < 1.0, "committed {:.1} cm, {dr:.2}°", dp * 100.0);
}

/// A hint says where the rig is: with the truth 0.4 m outside a 2 m volume, the polish carries
/// starts at the volume's edge onto the truth (without the rule, the first frame commits it,
/// 1.4 m from the centre); the searches commit nothing, or only a pose inside the volume.
#[test]
fn a_search_commits_no_pose_outside_the_volume_it_searched() {
    let f = fixture();
    let (mut source, rig, cfg, mut frame, mut detector) = replay(f);
    let p = f.truth[0].pose.translation.vector + Vector3::new(1.4, 0.0, 0.0);
    let volume = SearchVolume {
        centre: Point3::from(p),
        diameter_m: Some(2.0),
    };
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(volume), 1);
    let mut searched = 0;
    for _ in 0..6 {
        assert!(source.next_frame(&mut frame).unwrap());
        let r = tracker.process(detector.detect(&frame), frame.timestamp_ns().unwrap());
        // The search is taken up (and may commit on its own frame) a budget later: its event
        // and that frame's pose come late.
        let mut committed = false;
        for r in tracker.late().iter().map(|(_, r)| r).chain([&r]) {
            searched += usize::from(matches!(r.event, Some(TrackerEvent::Searched(_))));
            if let Some(pose) = r.pose {
                let off = (pose.translation.vector - p).norm();
                assert!(off <= 1.1, "committed {off:.2} m from the centre of a 2 m volume");
                committed = true;
            }
        }
        if committed {
            break;
        }
    }
    assert!(searched >= 1);
}

/// Issue 47, item 3: a hint says where the rig was when tracking started. Replayed standing
/// still (the first frame again and again) every search keeps the 3 m volume as given; walking
/// the recording, the searches on frames after the rig has moved search the hint grown by the
/// walk it may have made (twice 2 m/s × the time it moved). (Nothing is accepted here, so that
/// every search reports its volume; that a commit lies in the volume searched is the test
/// above.)
#[test]
fn the_hint_grows_with_the_walk_the_rig_may_have_made_and_not_while_it_stands_still() {
    let f = fixture();
    let (_, rig, mut cfg, _, _) = replay(f);
    cfg.initialisation.accept_explained_fraction = 0.999;
    let frames = detected_frames(f, 20);
    let hint = SearchVolume {
        centre: Point3::from(f.truth[0].pose.translation.vector),
        diameter_m: Some(3.0),
    };
    let period = frames[1].0 - frames[0].0;
    // Every search of a run: (the frame it searched, its volume's diameter).
    let run = |still: bool| {
        let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint), 1);
        let mut searched = Vec::new();
        for (k, (t, edges)) in frames.iter().enumerate() {
            let (t, edges) = if still {
                (frames[0].0 + k as u64 * period, &frames[0].1)
            } else {
                (*t, edges)
            };
            let r = tracker.process(edges, t);
            for (t, r) in tracker.late().iter().map(|(t, r)| (*t, r)).chain([(t, &r)]) {
                assert!(r.pose.is_none());
                if let Some(TrackerEvent::Searched(s)) = &r.event {
                    searched.push((t, s.diameter_m.expect("a volume")));
                }
            }
        }
        searched
    };
    let searched = run(true);
    assert!(searched.len() >= 2, "{searched:?}");
    assert!(searched.iter().all(|&(_, d)| d == 3.0), "standing still: {searched:?}");
    let searched = run(false);
    assert!(searched.len() >= 2, "{searched:?}");
    assert_eq!(searched[0].1, 3.0, "the first frame is the hint's");
    let max_growth = |t: u64| 3.0 + 2.0 * cfg.motion.max_speed_m_s * (t - frames[0].0) as f64 * 1e-9;
    for &(t, d) in &searched[1..] {
        assert!(d > 3.0 && d <= max_growth(t) + 1e-9, "walking: {searched:?}");
    }
}

/// Issue 47, item 1 (`sweep_volume`, off by default): a volume one search's budget does not
/// cover is swept by the searches that follow, each going on from the cells the earlier ones
/// looked at (their best candidates carried along as rivals), and nothing is committed before
/// every cell has been looked at. Judged part by part, this sweep committed a pose 1.65 m off
/// on its third search.
#[test]
fn a_volume_too_large_for_one_search_is_swept_by_the_next_searches() {
    let f = fixture();
    let (mut source, rig, mut cfg, mut frame, mut detector) = replay(f);
    // A fifth of the budget: a 10 m volume of the lab takes several searches.
    cfg.initialisation.time_budget_ms /= 5.0;
    cfg.initialisation.sweep_volume = true;
    // The volume as given: the rig walks, and a hint grown by its walk (module
    // `tracker::hint_age`) would be a new volume for each search, never swept to its end.
    cfg.motion.max_speed_m_s = 0.0;
    let volume = SearchVolume {
        centre: Point3::from(f.truth[0].pose.translation.vector + Vector3::new(3.5, -2.0, 0.0)),
        diameter_m: Some(10.0),
    };
    let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(volume), 1);
    let mut reports = Vec::new();
    let mut committed = None;
    while committed.is_none() && source.next_frame(&mut frame).unwrap() {
        let ts = frame.timestamp_ns().unwrap();
        let r = tracker.process(detector.detect(&frame), ts);
        for (t, r) in tracker.late().iter().map(|(t, r)| (*t, r)).chain([(ts, &r)]) {
            if let Some(TrackerEvent::Searched(s)) = &r.event {
                reports.push(*s);
            }
            if let (Some(p), None) = (r.pose, committed) {
                committed = Some(errors(f, t, &p));
            }
        }
    }
    if let Some((dp, dr)) = committed {
        assert!(dp < 0.10 && dr < 1.0, "committed {:.1} cm, {dr:.2}° off", dp * 100.0);
        // The search that committed (its event is the commit) ended a sweep: the searches
        // had looked at every cell by then.
        let in_volume = reports.first().map_or(0, |r| r.plan_cells_in_volume) as u64;
        assert!(tracker.stats().plan_cells_scanned >= in_volume, "{:?}", tracker.stats());
    }
    assert!(reports.len() >= 2, "{} searches", reports.len());
    assert_eq!(
        reports[0].plan_cells_skipped, 0,
        "the first search starts at the centre"
    );
    assert!(
        reports[0].swept_to_m.is_some(),
        "one search covered the volume: the test needs a larger one"
    );
    // Each search of the first sweep skips at least what the one before it looked at, up to
    // the last, which reaches the volume's end.
    let mut looked_at = 0;
    for (k, r) in reports.iter().enumerate() {
        assert!(r.plan_cells_skipped + 8 >= looked_at, "search {k} went back: {r:?}");
        looked_at = r.plan_cells_skipped + r.plan_cells_scanned;
        if r.swept_to_m.is_none() {
            assert_eq!(looked_at, r.plan_cells_in_volume, "{r:?}");
            return;
        }
    }
    assert!(
        committed.is_some(),
        "neither a commit nor a whole sweep in {} searches",
        reports.len()
    );
}

/// With `grid_blank` (in a hint's volume) the grid's coarse merit also loses the share of predicted points with no
/// edge near (module `near_edges`): it never gains; at the truth of a rendered frame, where
/// the lines in view are edges, it keeps most of its merit; the truth turned a quarter round
/// in place draws lines across plain surfaces and loses more; and the search still finds the
/// truth.
#[test]
fn the_grid_ranked_with_the_blank_share_keeps_the_truth_and_marks_its_twin_down() {
    use nalgebra::UnitQuaternion;
    use rand::SeedableRng;
    let f = fixture();
    let (rig, mut cfg, edges, truth) = first_frame(f);
    let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
    let twin = omnitrack::Pose::from_parts(truth.translation, turn * truth.rotation);
    let merits = |cfg: &TrackerConfig| {
        let mut init = lab_initialiser(f, &rig, cfg);
        let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
        let found = finds_truth(init.run(&edges, &hint(f), &mut rng).0, &truth);
        (
            init.grid_merit(&truth).expect("segments in sight of the truth"),
            init.grid_merit(&twin).expect("segments in sight of the twin"),
            found,
        )
    };
    cfg.initialisation.grid_blank = GridBlank::Off;
    let (plain_truth, plain_twin, _) = merits(&cfg);
    // The shipped setting: the blank share in a bounded volume's search, as this hint's.
    cfg.initialisation.grid_blank = GridBlank::Volumes;
    let (truth_m, twin_m, found) = merits(&cfg);
    let (kept_truth, kept_twin) = (truth_m / plain_truth, twin_m / plain_twin);
    assert!(
        kept_truth <= 1.0 + 1e-12 && kept_twin <= 1.0 + 1e-12,
        "{kept_truth} {kept_twin}"
    );
    assert!(kept_truth >= 0.8, "the truth kept {kept_truth:.3} of its merit");
    assert!(
        kept_twin < kept_truth - 0.1,
        "the twin kept {kept_twin:.3} of its merit, the truth {kept_truth:.3}"
    );
    assert!(found, "the search with the blank share lost the truth");
}

/// Whether a search's candidates hold the truth (within 10 cm and 1°).
fn finds_truth(found: &[omnitrack::tracker::Candidate], truth: &omnitrack::Pose) -> bool {
    found.iter().any(|c| {
        (c.pose.translation.vector - truth.translation.vector).norm() < 0.1
            && c.pose.rotation.angle_to(&truth.rotation) < 1f64.to_radians()
    })
}

/// The initialiser of the lab fixture's model and table for `rig` and `cfg`.
/// Its budget is 60 s of work, which lets every search here finish its volume: these tests judge
/// the search, not its budget (which the test of issue 24 below sets itself).
fn lab_initialiser<'a>(f: &'a LabRecording, rig: &Rig, cfg: &TrackerConfig) -> omnitrack::tracker::Initialiser<'a> {
    let mut opts = omnitrack::tracker::InitOptions::from_config(cfg);
    opts.time_budget = std::time::Duration::from_secs(60);
    omnitrack::tracker::Initialiser::new(
        rig,
        &f.model,
        &f.table,
        opts,
        cfg.solver_options(),
        rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize,
    )
}

/// A hint whose volume holds no valid node (here above the lab's ceiling) is widened about its
/// centre out to the nearest valid nodes, says so, and finds the truth below.
#[test]
fn a_search_volume_without_a_valid_node_searches_the_nearest_nodes() {
    use rand::SeedableRng;
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let mut init = lab_initialiser(f, &rig, &cfg);
    let volume = SearchVolume {
        centre: Point3::from(truth.translation.vector + Vector3::new(0.0, 0.0, 2.6)),
        diameter_m: Some(1.0),
    };
    let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
    let (found, report) = init.run(&edges, &volume, &mut rng);
    let widened = report.widened_to_m.expect("the volume was widened");
    assert!(widened > 1.0 && report.cells_in_volume > 0, "{report:?}");
    assert!(finds_truth(found, &truth), "{found:?}");
    // A volume with valid nodes is searched as given.
    let (_, report) = init.run(&edges, &hint(f), &mut rng);
    assert_eq!(report.widened_to_m, None);
}

/// A search told where the rotation is (after a bad frame: the last good one and the turn the
/// rig can have made since) keeps to it: with the prior on the truth it still finds the truth,
/// with the prior on the truth's half-turn twin nothing near the truth comes out, although the
/// same search without the prior finds it. And a search drops samples tilted further from
/// upright than `motion.max_tilt_deg`: with a tight limit it drops some, still finds the
/// (upright) truth and returns nothing tilted beyond the limit; with 180° it drops none.
/// The lab's first frame: the rig, the test configuration, the frame's edges and its true pose.
fn first_frame(f: &LabRecording) -> (Rig, TrackerConfig, Vec<omnitrack::edges::Edge>, omnitrack::Pose) {
    let (mut source, rig, cfg, mut frame, mut detector) = replay(f);
    assert!(source.next_frame(&mut frame).unwrap());
    let ts = frame.timestamp_ns().unwrap();
    let edges = detector.detect(&frame).to_vec();
    let truth = f
        .truth
        .iter()
        .find(|s| s.timestamp_ns.abs_diff(ts) < 1_000_000)
        .unwrap()
        .pose;
    (rig, cfg, edges, truth)
}

#[test]
fn a_rotation_prior_and_a_tilt_limit_keep_the_search_to_plausible_rotations() {
    use nalgebra::UnitQuaternion;
    use rand::SeedableRng;
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let initialiser = |max_tilt_deg: f64| {
        let mut c = cfg.clone();
        c.motion.max_tilt_deg = max_tilt_deg;
        let mut init = lab_initialiser(f, &rig, &c);
        init.set_yaw_twins(false);
        init
    };
    let volume = hint(f);
    let mut init = initialiser(180.0);
    let limit = 30f64.to_radians();
    let twin = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI) * truth.rotation;
    for (prior, expect_truth) in [
        (None, true),
        (Some((truth.rotation, limit)), true),
        (Some((twin, limit)), false),
    ] {
        init.set_rotation_prior(prior);
        let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
        let (found, report) = init.run(&edges, &volume, &mut rng);
        assert_eq!(finds_truth(found, &truth), expect_truth, "prior {prior:?}: {found:?}");
        assert_eq!(report.tilted, 0, "no tilt limit at 180°");
        if let Some((r, _)) = prior {
            // The polish may settle a little beyond the limit, never on the far side.
            assert!(
                found.iter().all(|c| c.pose.rotation.angle_to(&r) < 2.0 * limit),
                "{found:?}"
            );
        }
    }
    // The lab rig rolls upright: 10° keeps the truth and drops the samples of wrong triplets,
    // whose rotations fall anywhere.
    let mut init = initialiser(10.0);
    let mut rng = rand::rngs::SmallRng::seed_from_u64(5);
    let (found, report) = init.run(&edges, &volume, &mut rng);
    assert!(finds_truth(found, &truth), "{found:?}");
    assert!(report.tilted > 0, "{report:?}");
    let tilt = |c: &omnitrack::tracker::Candidate| (c.pose.rotation * Vector3::z()).z.acos().to_degrees();
    assert!(found.iter().all(|c| tilt(c) < 12.0), "{found:?}");
}

/// Issue 24: a search's budget is work, not time. With the shipped budget (which the search
/// spends: it stops on the budget, not on running out of volume, in a volume of 8 m, larger
/// than one search covers on its `VOLUME_LANES`), the same frame and seed give
/// bit-identical candidates and the same work whether the machine is idle or two threads spin
/// beside it; the whole-model search (its lanes on every core) likewise. A clock deadline gave
/// different answers on a loaded machine. (The backstop is moved out of reach: the shipped one
/// stops a search at 4× its budget on the wall clock, which a test run beside others can meet.)
#[test]
fn a_search_spends_its_work_budget_and_answers_the_same_beside_two_cpu_hogs() {
    use rand::SeedableRng;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    let f = fixture();
    let (rig, _, edges, _) = first_frame(f);
    let shipped = TrackerConfig::default();
    let search = |volume: &SearchVolume, budget_ms: f64| {
        let mut init = lab_initialiser(f, &rig, &shipped);
        init.set_time_budget(std::time::Duration::from_secs_f64(budget_ms / 1e3));
        // Tests run side by side, and two hogs more: the clock's backstop (4× the budget on
        // the wall) must not be what stops the search here.
        init.set_backstop_factor(1000);
        let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
        let (found, report) = init.run(&edges, volume, &mut rng);
        (found.to_vec(), report)
    };
    let whole = SearchVolume {
        centre: Point3::origin(),
        diameter_m: None,
    };
    let bounded = SearchVolume {
        diameter_m: Some(8.0),
        ..hint(f)
    };
    let budget = shipped.initialisation.time_budget_ms;
    let idle = [search(&bounded, budget), search(&whole, 2.0 * budget)];
    let spinning = Arc::new(AtomicBool::new(true));
    let hogs: Vec<_> = (0..2)
        .map(|_| {
            let on = Arc::clone(&spinning);
            std::thread::spawn(move || {
                let mut x = 0u64;
                while on.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            })
        })
        .collect();
    let loaded = [search(&bounded, budget), search(&whole, 2.0 * budget)];
    spinning.store(false, Ordering::Relaxed);
    for h in hogs {
        h.join().unwrap();
    }
    for ((a, ra), (b, rb)) in idle.iter().zip(&loaded) {
        assert!(!ra.backstop && !rb.backstop, "{ra:?} {rb:?}");
        assert!(ra.timed_out, "the budget decides: {ra:?}");
        assert!(ra.work >= (budget * 1e3) as u64, "{ra:?}");
        assert!(!a.is_empty(), "{ra:?}");
        assert_eq!(a, b, "idle {ra:?}\nloaded {rb:?}");
        assert_eq!(
            (ra.work, ra.cells_searched, ra.samples),
            (rb.work, rb.cells_searched, rb.samples)
        );
    }
}

/// A search deals the grid's cells and the triplets' cells to lanes (`LANES` for the whole
/// model, `VOLUME_LANES` for a bounded volume), and what each lane searches is fixed by the
/// dealing alone: on one thread or on several, it spends the same work on the same cells and
/// returns the same candidates (issue 47: the grid's scan, three quarters of a search, runs on
/// every core).
#[test]
fn a_search_answers_the_same_on_one_thread_and_on_several() {
    use rand::SeedableRng;
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let whole = SearchVolume {
        centre: Point3::origin(),
        diameter_m: None,
    };
    let mut centre = Point3::from(truth.translation.vector);
    centre.x += 0.7;
    let hint = SearchVolume {
        centre,
        diameter_m: Some(6.0),
    };
    // Budgets the scans run out of, so that their lanes stop at different distances.
    for (volume, budget_ms) in [(whole, 1000), (hint, 150)] {
        let search = |threads: usize| {
            let mut init = lab_initialiser(f, &rig, &cfg);
            init.set_time_budget(std::time::Duration::from_millis(budget_ms));
            init.set_backstop_factor(1000);
            init.set_threads(Some(threads));
            let mut rng = rand::rngs::SmallRng::seed_from_u64(11);
            let (found, report) = init.run(&edges, &volume, &mut rng);
            (found.to_vec(), report)
        };
        let (one, r1) = search(1);
        assert!(!one.is_empty(), "{r1:?}");
        assert!(!r1.backstop, "{r1:?}");
        assert!(
            r1.plan_cells_scanned > 0 && r1.plan_cells_scanned < r1.plan_cells_in_volume,
            "the scan's budget must cut it here: {r1:?}"
        );
        let resumed = r1.swept_to_m.expect("cells left for a sweep");
        // Two threads, and three (fewer lanes than threads for a bounded volume).
        for threads in [2, 3] {
            let (many, r) = search(threads);
            assert_eq!(one, many, "{threads} threads\n1: {r1:?}\n{threads}: {r:?}");
            assert_eq!(
                (r.work, r.cells_searched, r.samples, r.plan_cells_scanned, r.swept_to_m),
                (
                    r1.work,
                    r1.cells_searched,
                    r1.samples,
                    r1.plan_cells_scanned,
                    Some(resumed)
                ),
                "{threads} threads"
            );
        }
    }
}

/// A recording as a monochrome camera delivers it: every pixel grey (R = G = B = its luma).
struct Grey {
    inner: ReplaySource,
}

impl FrameSource for Grey {
    fn rig(&self) -> &Rig {
        self.inner.rig()
    }
    fn next_frame(&mut self, out: &mut FrameSet) -> Result<bool, SourceError> {
        let more = self.inner.next_frame(out)?;
        for s in out.sensors_mut() {
            for p in s.pixels_mut().chunks_exact_mut(3) {
                let y = (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32).round() as u8;
                p.fill(y);
            }
        }
        Ok(more)
    }
    fn stats(&self) -> &SourceStats {
        self.inner.stats()
    }
}

/// A monochrome camera is a camera too: with every hue NaN (no colour to sign an edge by), the
/// lab initialises from the 3 m volume within 10 cm and 1° and tracks every frame within the
/// targets, as in colour, whatever the tracker's random draws: five seeds, no frame 30 cm off.
/// (Without hues, a head turn the motion model missed let a solve slide 20–30 cm along the
/// room's repeated lines on six seeds of ten, and on one the pose then drifted 9.5 m:
/// docs/decisions.md, 2026-12-01.)
#[test]
fn a_grey_recording_tracks_as_the_colour_one() {
    let f = fixture();
    for seed in 1..=5 {
        let mut source = Grey {
            inner: ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap(),
        };
        let mut errs = Vec::new();
        let stats = run_hinted_seeded(f, &mut source, seed, &mut |r, _| {
            if let Some(p) = &r.result.pose {
                errs.push(errors(f, r.timestamp_ns, p));
            }
            Ok(())
        });
        assert_eq!(stats.losses, 0, "seed {seed}: {stats:?}");
        assert!(
            errs.len() >= FRAMES - start_frames(),
            "seed {seed}: {} frames with a pose",
            errs.len()
        );
        let (dp, dr) = errs[0];
        assert!(
            dp < 0.10 && dr < 1.0,
            "seed {seed}: first pose {:.1} cm, {dr:.2}°",
            dp * 100.0
        );
        let rmse = (errs.iter().map(|e| e.0 * e.0).sum::<f64>() / errs.len() as f64).sqrt();
        let worst = errs.iter().map(|e| e.0).fold(0.0, f64::max);
        let cm: Vec<i64> = errs.iter().map(|e| (e.0 * 100.0).round() as i64).collect();
        assert!(
            rmse < 0.05 && worst < 0.30,
            "seed {seed}: RMSE {:.1} cm, worst {:.1} cm; per frame (cm): {cm:?}; {stats:?}",
            rmse * 100.0,
            worst * 100.0
        );
    }
}

/// Real rooms hold more than their model: with three times the furniture, shelves and posters,
/// twice the people and five times the surface texture of the default render, no frame of the
/// lab's first 30 is given a pose more than 30 cm or 3° off, from the 3 m volume: "no pose yet"
/// is allowed, a wrong one is not.
/// Tracks `f` from the 3 m hint: (frames with a pose, the worst position error (m) and rotation
/// error (°) over them).
fn worst_errors(f: &LabRecording) -> (usize, f64, f64) {
    let mut source = ReplaySource::open(&f.rec, Pacing::AsFastAsPossible).unwrap();
    let mut errs = Vec::new();
    run_hinted(f, &mut source, &mut |r, _| {
        if let Some(p) = &r.result.pose {
            errs.push(errors(f, r.timestamp_ns, p));
        }
        Ok(())
    });
    let worst = errs.iter().fold((0.0f64, 0.0f64), |m, e| (m.0.max(e.0), m.1.max(e.1)));
    (errs.len(), worst.0, worst.1)
}

#[test]
fn heavy_clutter_and_texture_commit_no_wrong_pose() {
    use omnitrack::desk::recording::RecordingOptions;
    use omnitrack::desk::render::Appearance;
    let options = RecordingOptions {
        appearance: Appearance {
            clutter: 3.0,
            people: 2.0,
            texture: 0.3,
            ..Appearance::default()
        },
        ..RecordingOptions::default()
    };
    let f = common::lab_recording_with(30, "firmware_config/ladybug2.toml", "cluttered", &options);
    let (n, worst_m, worst_deg) = worst_errors(&f);
    assert!(
        worst_m < 0.30 && worst_deg < 3.0,
        "a pose {:.1} cm, {worst_deg:.2}° off ({n} frames with a pose)",
        worst_m * 100.0
    );
    eprintln!(
        "heavy clutter: {n} of 30 frames with a pose, worst {:.1} cm",
        worst_m * 100.0
    );
}

/// The realistic world (docs/real-photos.md, "A synthetic world that predicts the real one": casings, one
/// paint, floorboards, closed doors, walls off the model, blur and JPEG): the tracker may track
/// less well than in the default world, but never commits or relocalises to a wrong place.
#[test]
fn the_realistic_world_commits_no_wrong_pose() {
    use omnitrack::desk::recording::RecordingOptions;
    use omnitrack::desk::render::Appearance;
    let options = RecordingOptions {
        appearance: Appearance::realistic(),
        ..RecordingOptions::default()
    };
    let f = common::lab_recording_with(30, "firmware_config/ladybug2.toml", "realistic", &options);
    let (n, worst_m, worst_deg) = worst_errors(&f);
    eprintln!(
        "realistic world: {n} of 30 frames with a pose, worst {:.1} cm, {worst_deg:.2}°",
        worst_m * 100.0
    );
    assert!(n >= 20, "only {n} of 30 frames with a pose");
    assert!(
        worst_m < 0.30 && worst_deg < 3.0,
        "a pose {:.1} cm, {worst_deg:.2}° off",
        worst_m * 100.0
    );
}

/// Frames of the other-rig runs (5 Hz: eight seconds of the lab tour).
const OTHER_RIG_FRAMES: usize = 40;

/// Every rig of the TOML format is first-class: the lab, rendered through `rig`, initialises
/// from the same 3 m volume within 10 cm and 1° and tracks every frame to the shipped rig's
/// limits (those of the first test above). Returns the recording and each frame's pose.
fn tracks_through(rig: &str, sensors: usize) -> (LabRecording, Vec<Option<omnitrack::Pose>>) {
    let f = common::lab_recording_with_rig(OTHER_RIG_FRAMES, rig);
    let poses = tracks_recording(&f, &f.rec, rig, sensors);
    (f, poses)
}

/// [`tracks_through`] on the recording at `rec` (of `f`'s lab and truth).
fn tracks_recording(f: &LabRecording, rec: &Path, rig: &str, sensors: usize) -> Vec<Option<omnitrack::Pose>> {
    let mut source = ReplaySource::open(rec, Pacing::AsFastAsPossible).unwrap();
    assert_eq!(source.rig().sensors.len(), sensors, "{rig}");
    let mut errs = Vec::new();
    let mut poses = Vec::new();
    let stats = run_hinted(f, &mut source, &mut |r, _| {
        if let Some(p) = &r.result.pose {
            errs.push(errors(f, r.timestamp_ns, p));
        }
        poses.push(r.result.pose);
        Ok(())
    });
    assert_eq!(stats.frames, OTHER_RIG_FRAMES as u64, "{rig}");
    assert_eq!(stats.losses, 0, "{rig}: {stats:?}");
    assert!(
        errs.len() >= OTHER_RIG_FRAMES - start_frames(),
        "{rig}: {} frames with a pose",
        errs.len()
    );
    let (dp, dr) = errs[0];
    assert!(
        dp < 0.10 && dr < 1.0,
        "{rig}: first pose {:.1} cm, {dr:.2}°",
        dp * 100.0
    );
    let rmse = (errs.iter().map(|e| e.0 * e.0).sum::<f64>() / errs.len() as f64).sqrt();
    let worst = errs.iter().fold(0.0f64, |m, e| m.max(e.0));
    assert!(
        rmse < 0.05,
        "{rig}: RMSE {:.1} cm, worst {:.1} cm",
        rmse * 100.0,
        worst * 100.0
    );
    poses
}

/// Four landscape pinhole sensors 90° apart, none of which sees up (`tools/rigs/pinhole4.toml`):
/// no lens distortion, no zenith, a narrower vertical view than the shipped rig's.
#[test]
fn a_rig_of_four_landscape_pinhole_sensors_tracks_as_the_shipped_one() {
    tracks_through("tools/rigs/pinhole4.toml", 4);
}

/// Two fisheye lenses back to back whose images reach 144° off their axes
/// (`tools/rigs/dual_fisheye.toml`): much of every image lies past 90°, where a pinhole has no
/// image at all, and each sensor covers more than a hemisphere.
#[test]
fn a_rig_of_two_fisheye_lenses_seeing_past_90_degrees_tracks_as_the_shipped_one() {
    let (f, poses) = tracks_through("tools/rigs/dual_fisheye.toml", 2);
    // The same two fisheyes as one dual-fisheye camera: both images in one frame of one device,
    // each sensor cropped from it on replay. The pixels are the same, so are the poses.
    let joined = f.dir.path().join("one-frame");
    assert!(omnitrack::desk::recording::join_sensors(&f.rec, &joined, "/dev/video0").unwrap());
    let rig = Rig::load(&joined.join("rig.toml")).unwrap();
    assert_eq!(rig.sensors[1].crop, Some([640, 0, 640, 640]));
    let one_frame = tracks_recording(&f, &joined, "dual fisheye in one frame", 2);
    assert_eq!(one_frame, poses);
}

/// Two double-sphere fisheyes back to back (`tools/rigs/dual_double_sphere.toml`, Basalt's and
/// Kalibr's `ds` model, issue 49): a lens model read from those calibrations goes through the
/// whole pipeline (rendering, edges, field of view, search, maintenance) as the others do.
#[test]
fn a_rig_of_two_double_sphere_lenses_tracks_as_the_shipped_one() {
    let (f, _) = tracks_through("tools/rigs/dual_double_sphere.toml", 2);
    let rig = Rig::load(&f.rec.join("rig.toml")).unwrap();
    assert!(rig.sensors.iter().all(|s| s.lens.model_name() == "ds"));
    assert!(rig.sensors[0].max_off_axis() > 110f64.to_radians());
}

#[test]
fn the_true_pose_draws_fewer_lines_across_plain_surfaces_than_a_wrong_one() {
    use nalgebra::{Translation3, UnitQuaternion};
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let mut init = lab_initialiser(f, &rig, &cfg);
    let at_truth = init.blank_share(&truth, &edges);
    // A quarter turn where the rig stands, and the truth 0.6 m aside: the building's lines are
    // drawn where the images show plain wall, floor and ceiling.
    let turned = omnitrack::Pose::from_parts(
        truth.translation,
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2) * truth.rotation,
    );
    let aside = omnitrack::Pose::from_parts(
        Translation3::from(truth.translation.vector + Vector3::new(0.6, 0.0, 0.0)),
        truth.rotation,
    );
    let (b_turned, b_aside) = (init.blank_share(&turned, &edges), init.blank_share(&aside, &edges));
    // Measured: 0.007 at the truth, 0.32 turned, 0.14 aside.
    assert!(at_truth < 0.05, "blank share at the truth {at_truth:.2}");
    assert!(
        b_turned > at_truth + 0.15 && b_aside > at_truth + 0.07,
        "truth {at_truth:.2}, turned {b_turned:.2}, aside {b_aside:.2}"
    );
    // And the candidates' merit carries it: the truth polished keeps a small blank share.
    let c = init.polish(&truth, &edges).expect("the truth polishes");
    assert!((c.blank - init.blank_share(&c.pose, &edges)).abs() < 1e-12);
    assert!(c.blank < 0.05, "the polished truth's blank share {:.2}", c.blank);
    // Radius 0 turns it off.
    let mut off = cfg.clone();
    off.initialisation.blank_radius_deg = 0.0;
    let mut init0 = lab_initialiser(f, &rig, &off);
    assert_eq!(init0.blank_share(&turned, &edges), 0.0);
}

/// The disputed edges side with the truth: of the frame's edges that exactly one of the truth
/// and a wrong pose (a quarter or half turn where the rig stands, the truth 0.6 m aside)
/// explains, the wrong pose explains at most the third `disputed_share_max` allows, and they are
/// more than the 3 % of the frame's edges below which a dispute decides nothing. The truth and
/// itself dispute nothing.
#[test]
fn the_edges_only_one_of_the_truth_and_a_wrong_pose_explains_side_with_the_truth() {
    use nalgebra::{Translation3, UnitQuaternion};
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let mut init = lab_initialiser(f, &rig, &cfg);
    let min_len = cfg.edges.min_edge_length_deg.to_radians();
    let total: f64 = edges
        .iter()
        .filter(|e| e.length_rad >= min_len)
        .map(|e| e.length_rad)
        .sum();
    let (mut at_truth, mut at_other) = (Vec::new(), Vec::new());
    init.edges_explained(&truth, &edges, &mut at_truth);
    assert_eq!(at_truth.len(), edges.len());
    let disputed = |a: &[bool], b: &[bool]| {
        let (mut only_a, mut only_b) = (0.0, 0.0);
        for ((e, &x), &y) in edges.iter().zip(a).zip(b) {
            match (x, y) {
                (true, false) => only_a += e.length_rad,
                (false, true) => only_b += e.length_rad,
                _ => {}
            }
        }
        (only_a, only_b)
    };
    assert_eq!(disputed(&at_truth, &at_truth), (0.0, 0.0));
    let turned = |deg: f64| {
        omnitrack::Pose::from_parts(
            truth.translation,
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), deg.to_radians()) * truth.rotation,
        )
    };
    let aside = omnitrack::Pose::from_parts(
        Translation3::from(truth.translation.vector + Vector3::new(0.6, 0.0, 0.0)),
        truth.rotation,
    );
    let share_max = cfg.initialisation.disputed_share_max;
    let min_fraction = cfg.initialisation.disputed_min_fraction;
    for (name, wrong) in [
        ("quarter turn", turned(90.0)),
        ("half turn", turned(180.0)),
        ("0.6 m aside", aside),
    ] {
        init.edges_explained(&wrong, &edges, &mut at_other);
        let (only_truth, only_wrong) = disputed(&at_truth, &at_other);
        let share = only_wrong / (only_truth + only_wrong);
        // Measured: the wrong pose's share 0.17 (quarter turn), 0.10 (half), 0.03 (aside), of
        // disputed edges 49 %, 39 % and 26 % of the frame's.
        assert!(
            only_truth + only_wrong >= min_fraction * total && share <= share_max,
            "{name}: the truth alone explains {only_truth:.3} rad, the wrong pose alone {only_wrong:.3} rad \
             of {total:.3} rad"
        );
    }
}

/// Issue 24: the searches run off the frame path. A tracker whose searches go to a worker thread
/// answers every frame exactly as one that searches inline (the result is taken up at a frame
/// fixed by the timestamps, and a search stops on its work, never the clock), on time and late;
/// the frames kept during the first search are caught up on, so the first pose on time is
/// followed by every later frame's, and the search frame's own pose, given late, is within the
/// first test's limits.
#[test]
fn a_search_on_a_worker_thread_answers_every_frame_as_one_inline() {
    use omnitrack::tracker::search_link;
    let f = fixture();
    let frames = detected_frames(f, 30);
    let (_, rig, cfg, _, _) = replay(f);
    type Answers = Vec<(Option<omnitrack::Pose>, Vec<(u64, Option<omnitrack::Pose>)>)>;
    let answer = |tracker: &mut Tracker| -> Answers {
        let mut answers: Answers = frames
            .iter()
            .map(|(t, edges)| {
                let r = tracker.process(edges, *t);
                let late = tracker.late().iter().map(|(t, r)| (*t, r.pose)).collect();
                (r.pose, late)
            })
            .collect();
        tracker.finish();
        let rest = tracker.late().iter().map(|(t, r)| (*t, r.pose));
        answers.last_mut().expect("frames").1.extend(rest);
        answers
    };
    // Every pose, on time or late, by timestamp.
    let trajectory = |a: &Answers| -> std::collections::BTreeMap<u64, omnitrack::Pose> {
        let on_time = a.iter().zip(&frames).filter_map(|((p, _), (t, _))| p.map(|p| (*t, p)));
        let late = a
            .iter()
            .flat_map(|(_, l)| l.iter())
            .filter_map(|(t, p)| p.map(|p| (*t, p)));
        on_time.chain(late).collect()
    };
    let inline = answer(&mut Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1));
    let threaded = |defer: bool| {
        let (link, worker) = search_link();
        std::thread::scope(|scope| {
            scope.spawn(move || worker.run());
            let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
            tracker.attach_search_worker(link);
            tracker.defer_late_searches(defer);
            (answer(&mut tracker), *tracker.stats())
        })
    };
    // Waiting for the worker when it is late (a lossless replay): every frame as inline.
    let (waiting, stats) = threaded(false);
    assert_eq!(waiting, inline, "{stats:?}");
    assert_eq!(stats.search_deferrals, 0);
    // Not waiting (a live source): a worker that fell behind (a loaded machine) leaves some
    // frames answered late, with the same poses.
    let (deferring, stats) = threaded(true);
    if stats.search_deferrals == 0 {
        assert_eq!(deferring, inline, "{stats:?}");
    }
    assert_eq!(trajectory(&deferring), trajectory(&inline), "{stats:?}");
    let first = inline.iter().position(|(p, _)| p.is_some()).expect("a pose on time");
    assert!(first <= start_frames() - 3, "first pose on time at frame {first}");
    assert!(
        inline[first..].iter().all(|(p, _)| p.is_some()),
        "every frame after the first"
    );
    let late: Vec<_> = inline.iter().flat_map(|(_, l)| l.iter()).collect();
    // The search frame shows its search's report first, and its pose once the commit's trial
    // frames held it (module `tracker::search`, "Frames agreeing").
    let (t0, p0) = late
        .iter()
        .find_map(|(t, p)| p.map(|p| (*t, p)))
        .expect("the search frame's pose, late");
    assert_eq!(t0, frames[0].0);
    let (dp, dr) = errors(f, t0, &p0);
    assert!(
        dp < 0.10 && dr < 1.0,
        "the search frame: {:.1} cm, {dr:.2}°",
        dp * 100.0
    );
    // Every frame before the first on time has its pose late, in time order.
    let stamps: Vec<u64> = late.iter().filter(|(_, p)| p.is_some()).map(|(t, _)| *t).collect();
    assert_eq!(stamps, frames[..first].iter().map(|(t, _)| *t).collect::<Vec<_>>());
}

/// The lab's model with the detail of an architect's model added: on every wall, both faces,
/// rows of window panes 0.15 m square standing 2 mm proud (four segments each, all long enough
/// to enter the visibility sets), as sashes, trims and fittings add them to an IFC export.
fn detailed_lab_obj(f: &LabRecording) -> String {
    use std::fmt::Write;
    let mut obj = std::fs::read_to_string(f.rec.join("model.obj")).unwrap();
    obj.push('\n');
    let mut v = obj.lines().filter(|l| l.starts_with("v ")).count();
    let floor = f.model.bounds().unwrap().0.z;
    for face in &f.model.faces {
        let n = face.normal.into_inner();
        if n.z.abs() > 1e-6 {
            continue;
        }
        let along = Vector3::new(-n.y, n.x, 0.0);
        let ps: Vec<Point3<f64>> = face.vertices.iter().map(|&i| f.model.vertices[i as usize]).collect();
        let (lo, hi) = ps
            .iter()
            .map(|p| p.coords.dot(&along))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
        let (z_lo, z_hi) = ps
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.z), b.max(p.z)));
        let origin = ps[0] - along * (ps[0].coords.dot(&along) - lo);
        for side in [-1.0, 1.0] {
            let mut s = lo + 0.2;
            while s + 0.15 < hi - 0.1 {
                for row in [0.9, 1.3, 1.7] {
                    let z = floor + row;
                    if z < z_lo + 0.05 || z + 0.15 > z_hi - 0.05 {
                        continue;
                    }
                    let base = origin + along * (s - lo) + n * (0.002 * side);
                    for (da, dz) in [(0.0, 0.0), (0.15, 0.0), (0.15, 0.15), (0.0, 0.15)] {
                        let p = base + along * da;
                        let _ = writeln!(obj, "v {} {} {}", p.x, p.y, z + dz);
                    }
                    let _ = writeln!(obj, "f {} {} {} {}", v + 1, v + 2, v + 3, v + 4);
                    v += 4;
                }
                s += 0.35;
            }
        }
    }
    obj
}

/// Issue 47: on a model as detailed as an architect's, a search's cost follows what its
/// positions can see, and is charged for it. The lab with panes on every wall (rendered with
/// them) is searched from the 3 m hint with the shipped budget: every occlusion ray the search
/// casts is in the work it charges (a flat charge per position let a detailed model's search
/// run for four times its budget on the clock before it had searched one cell), the report says
/// how many of the volume's cells the grid looked at, and the truth is among the candidates.
#[test]
fn a_search_in_a_detailed_model_is_charged_for_its_rays_and_still_finds_the_truth() {
    use omnitrack::desk::recording::{write_recording, RecordingOptions};
    use omnitrack::tracker::{InitOptions, Initialiser};
    use omnitrack::trajectory::Stamped;
    use omnitrack::visibility::build::{build_table, BuildOptions};
    use rand::SeedableRng;
    let f = fixture();
    let (rig, cfg, _, truth) = first_frame(f);
    let obj = detailed_lab_obj(f);
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("detailed");
    let frames = vec![Stamped {
        timestamp_ns: 0,
        pose: truth,
    }];
    write_recording(&rec, &rig, &obj, &frames, &RecordingOptions::default(), |_, _| {}).unwrap();
    let model = omnitrack::Model::load(&rec.join("model.obj")).unwrap();
    assert!(
        model.segments.len() >= 4 * f.model.segments.len(),
        "{} segments against the lab's {}",
        model.segments.len(),
        f.model.segments.len()
    );
    let table = build_table(&model, "model.obj", &BuildOptions::default());
    let mut source = ReplaySource::open(&rec, Pacing::AsFastAsPossible).unwrap();
    let mut frame = FrameSet::for_rig(&rig);
    assert!(source.next_frame(&mut frame).unwrap());
    let mut detector = EdgeDetector::new(&rig, &cfg.edges);
    let edges = detector.detect(&frame).to_vec();
    let mut init = Initialiser::new(
        &rig,
        &model,
        &table,
        InitOptions::from_config(&cfg),
        cfg.solver_options(),
        rig.sensors.len() * cfg.edges.max_edges_per_sensor as usize,
    );
    // The clock plays no part here (a debug build on a loaded machine is far slower than the
    // reference): what is judged is the work charged and what it bought.
    init.set_backstop_factor(1000);
    let rays = init.rays_cast();
    let mut rng = rand::rngs::SmallRng::seed_from_u64(3);
    let (found, report) = init.run(&edges, &hint(f), &mut rng);
    let found = found.to_vec();
    let cast = init.rays_cast() - rays;
    assert!(cast > 0);
    assert!(
        report.work >= cast / omnitrack::tracker::init::work::RAYS_PER_UNIT,
        "{cast} rays cast, {} work charged",
        report.work
    );
    // The grid says how much of the volume it looked at (on this model about half of the 3 m
    // volume's cells fit in the shipped budget: issue 47 wants all of them).
    assert!(
        report.plan_cells_in_volume > 0 && report.plan_cells_scanned > 0,
        "{report:?}"
    );
    assert!(report.plan_cells_scanned <= report.plan_cells_in_volume, "{report:?}");
    assert!(finds_truth(&found, &truth), "{found:?} truth {truth:?} {report:?}");
}

/// A volume too large for one search's budget is swept over several searches (issue 47): each
/// continues where the last stopped (`set_sweep_from` at the last `swept_to_m`), skips exactly
/// the cells nearer the centre, and together they look at every cell of the volume, the far
/// one holding the truth included, which the first search never reached.
#[test]
fn a_volume_too_large_for_one_search_is_swept_over_several_until_every_cell_is_looked_at() {
    use rand::SeedableRng;
    let f = fixture();
    let (rig, cfg, edges, truth) = first_frame(f);
    let mut init = lab_initialiser(f, &rig, &cfg);
    init.set_time_budget(std::time::Duration::from_millis(150));
    init.set_backstop_factor(1000);
    let volume = SearchVolume {
        centre: Point3::from(truth.translation.vector + Vector3::new(3.5, -2.0, 0.0)),
        diameter_m: Some(10.0),
    };
    let mut rng = rand::rngs::SmallRng::seed_from_u64(7);
    let (mut from, mut looked_at, mut searches, mut found_at) = (0.0, 0, 0, None);
    let mut in_volume;
    loop {
        init.set_sweep_from(from);
        let (found, report) = init.run(&edges, &volume, &mut rng);
        let found_truth = finds_truth(found, &truth);
        in_volume = report.plan_cells_in_volume;
        // Exactly the cells looked at before are skipped (up to those tied in distance with
        // the first one not looked at, which are looked at again).
        assert!(report.plan_cells_skipped <= looked_at, "{report:?}");
        assert!(report.plan_cells_skipped + 8 >= looked_at, "{report:?}");
        assert!(
            report.plan_cells_scanned > 0,
            "a sweep that looks at nothing never ends"
        );
        looked_at = report.plan_cells_skipped + report.plan_cells_scanned;
        if found_truth && found_at.is_none() {
            found_at = Some(searches);
        }
        searches += 1;
        match report.swept_to_m {
            Some(m) => {
                assert!(m > from, "the sweep moves out: {m} after {from}");
                from = m;
            }
            None => break,
        }
        assert!(searches < 60, "the sweep of {in_volume} cells did not end");
    }
    assert_eq!(looked_at, in_volume);
    assert!(
        searches >= 3,
        "one budget looked at {in_volume} cells: the test needs a larger volume"
    );
    assert!(
        found_at.is_some_and(|k| k > 0),
        "the truth, 4 m from the centre, found by search {found_at:?} of {searches}"
    );
}

/// Issue 50: a search a stop cuts short ([`Tracker::stop_searches_on`]) commits nothing, on its
/// own frame or later: its best candidate may not have met the rival that would have refused it.
/// The same frames without the stop commit the truth; stopped before the search starts, or late
/// in it (when the part searched may well hold the truth), nothing is committed, and the search
/// on the worker ends at its next check rather than after its budget. The stop comes at a known
/// point of the search's work ([`SearchProgress::raise_at_work`](omnitrack::tracker::SearchProgress::raise_at_work)),
/// not after a wall-clock delay, and each search's report is read on its way back from the
/// worker: the test asks the same of every run, idle or loaded.
#[test]
fn a_search_cut_short_by_a_stop_commits_nothing() {
    use omnitrack::tracker::{search_link, InitReport, SearchLink};
    use std::sync::atomic::AtomicBool;
    use std::sync::{Arc, Mutex};
    let f = fixture();
    let frames = detected_frames(f, start_frames() + 2);
    let (_, rig, cfg, _, _) = replay(f);
    // Every pose, on time or late, the stats, and each search's report in order. `stop_at`:
    // none, the flag set before the first frame, or set by the first search itself once it has
    // spent that much work.
    #[derive(Clone, Copy)]
    enum Stop {
        Never,
        Before,
        AtWork(u64),
    }
    let run = |stop: Stop| {
        let (to_worker, worker) = search_link();
        let (jobs_tx, jobs_rx) = crossbeam::channel::bounded(1);
        let (done_tx, done_rx) = crossbeam::channel::bounded(1);
        let reports = Mutex::new(Vec::<InitReport>::new());
        let flag = Arc::new(AtomicBool::new(matches!(stop, Stop::Before)));
        let poses_and_stats = std::thread::scope(|scope| {
            scope.spawn(move || worker.run());
            // Between the tracker and the worker: each job on to it, and back with its report read.
            let reports = &reports;
            scope.spawn(move || {
                while let Ok(job) = jobs_rx.recv() {
                    if to_worker.jobs.send(job).is_err() {
                        break;
                    }
                    let Ok(job) = to_worker.done.recv() else { break };
                    reports.lock().unwrap().push(*job.result().1);
                    if done_tx.send(job).is_err() {
                        break;
                    }
                }
            });
            let mut tracker = Tracker::new(&rig, &f.model, &f.table, &cfg, Some(hint(f)), 1);
            tracker.attach_search_worker(SearchLink {
                jobs: jobs_tx,
                done: done_rx,
            });
            tracker.stop_searches_on(Arc::clone(&flag));
            if let Stop::AtWork(units) = stop {
                tracker.search_progress().raise_at_work(Arc::clone(&flag), units);
            }
            let mut poses = Vec::new();
            for (t, edges) in &frames {
                let r = tracker.process(edges, *t);
                poses.extend(tracker.late().iter().filter_map(|(_, r)| r.pose));
                poses.extend(r.pose);
            }
            tracker.finish();
            poses.extend(tracker.late().iter().filter_map(|(_, r)| r.pose));
            (poses, *tracker.stats())
        });
        (poses_and_stats, reports.into_inner().unwrap())
    };
    let ((poses, stats), reports) = run(Stop::Never);
    assert!(!poses.is_empty() && stats.searches_cancelled == 0, "{stats:?}");
    let whole = reports[0];
    assert!(!whole.cancelled && !whole.backstop && whole.work > 0, "{whole:?}");
    // At once, then late in the search and earlier. (Late cuts are the ones that matter:
    // without the rule, the cut at 0.9 of the search commits 11 poses.)
    let cuts = [0.9, 0.75, 0.5].map(|share| Stop::AtWork((whole.work as f64 * share) as u64));
    for stop in std::iter::once(Stop::Before).chain(cuts) {
        let ((poses, stats), reports) = run(stop);
        let (name, at) = match stop {
            Stop::Before => ("before the search".to_string(), 0),
            Stop::AtWork(w) => (format!("at {w} of {} work units", whole.work), w),
            Stop::Never => unreachable!(),
        };
        let cut = reports[0];
        eprintln!(
            "stopped {name}: ended at {} work units, {} searches ({} cut short), whole search {}",
            cut.work,
            reports.len(),
            stats.searches_cancelled,
            whole.work
        );
        assert!(cut.cancelled, "stopped {name}: {cut:?}");
        assert!(poses.is_empty(), "stopped {name}: {} poses", poses.len());
        assert_eq!(stats.tracked + stats.late_poses, 0, "stopped {name}: {stats:?}");
        assert!(stats.searches_cancelled >= 1, "stopped {name}: {stats:?}");
        // It ended at its next check, not after its budget: the work past the stop is a
        // step's, a small part of what the whole search went on to do.
        assert!(
            cut.work >= at && cut.work - at <= (whole.work - at) / 4,
            "stopped {name}: the search went on to {} work units",
            cut.work
        );
        // And every search after it, the flag still set, stopped at once as well.
        for later in &reports[1..] {
            assert!(later.cancelled, "stopped {name}, a later search: {later:?}");
        }
    }
}
