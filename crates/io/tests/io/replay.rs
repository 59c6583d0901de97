//! The mock camera: a recording on disk replays frame by frame into preallocated buffers, in frame
//! order, with its timestamps and pixels intact; every fault of one image or one index row is
//! counted and survived; a recording that cannot be opened is a one-line error naming the file;
//! real-time pacing keeps the recorded spacing; and the steady state's allocations are counted.

use image::{GrayAlphaImage, GrayImage, ImageBuffer, Rgb, RgbImage, RgbaImage};
use omnitrack_core::frame::{FrameSet, ImageFault};
use omnitrack_core::rig::Rig;
use omnitrack_io::capture::{FrameSource, Pacing, ReplaySource, SourceError};
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};
use tempfile::TempDir;

// ---------------------------------------------------------------------------------------------
// Recordings.

const T0_NS: u64 = 1_700_000_000_000_000_000;
const FRAME_SPACING_NS: u64 = 33_000_000;

/// A two-sensor pinhole rig of the given image sizes.
fn pinhole_rig_toml(sizes: &[(u32, u32)]) -> String {
    let mut s = String::from("name = \"test-rig\"\n");
    for (id, (w, h)) in sizes.iter().enumerate() {
        let _ = write!(
            s,
            "\n[[sensors]]\nid = {id}\nresolution = [{w}, {h}]\nmodel = \"pinhole\"\n\
             intrinsics = [100.0, 100.0, {}, {}]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
             translation_m = [{}, 0.0, 0.0]\n",
            (*w as f64 - 1.0) / 2.0,
            (*h as f64 - 1.0) / 2.0,
            0.01 * id as f64
        );
    }
    s
}

/// The pixel every recording here stores at (u, v) of `sensor` in `frame`.
fn expected_rgb(frame: u64, sensor: usize, u: u32, v: u32) -> [u8; 3] {
    [
        (u * 7 + frame as u32 * 13) as u8,
        (v * 5 + sensor as u32 * 31) as u8,
        ((u ^ v) + frame as u32 * 3 + sensor as u32) as u8,
    ]
}

fn frame_image(frame: u64, sensor: usize, w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |u, v| Rgb(expected_rgb(frame, sensor, u, v)))
}

fn timestamp(frame: u64, sensor: usize) -> u64 {
    // Sensors of one frame differ by a few ms, as on the real rig.
    T0_NS + frame * FRAME_SPACING_NS + sensor as u64 * 1_500_000
}

fn image_path(frame: u64, sensor: usize) -> String {
    format!("sensor{sensor}/{frame:06}.png")
}

/// A recording of `frames` frames for a rig of these sensor sizes, every image present; index rows
/// written in reverse order (replay must sort them). Returns the directory.
fn recording(sizes: &[(u32, u32)], frames: u64) -> TempDir {
    recording_with_rig(&pinhole_rig_toml(sizes), sizes, frames)
}

fn recording_with_rig(rig_toml: &str, sizes: &[(u32, u32)], frames: u64) -> TempDir {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::write(root.join("rig.toml"), rig_toml).unwrap();
    let mut rows = Vec::new();
    for (sensor, &(w, h)) in sizes.iter().enumerate() {
        std::fs::create_dir_all(root.join(format!("sensor{sensor}"))).unwrap();
        for frame in 0..frames {
            frame_image(frame, sensor, w, h)
                .save(root.join(image_path(frame, sensor)))
                .unwrap();
            rows.push(format!(
                "{frame},{sensor},{},{}",
                timestamp(frame, sensor),
                image_path(frame, sensor)
            ));
        }
    }
    rows.reverse();
    write_index(root, &rows);
    dir
}

fn write_index(root: &Path, rows: &[String]) {
    let mut text = String::from("frame,sensor,timestamp_ns,path\n");
    for r in rows {
        text.push_str(r);
        text.push('\n');
    }
    std::fs::write(root.join("frames.csv"), text).unwrap();
}

fn append_index(root: &Path, extra: &str) {
    let mut text = std::fs::read_to_string(root.join("frames.csv")).unwrap();
    text.push_str(extra);
    std::fs::write(root.join("frames.csv"), text).unwrap();
}

const SMALL: [(u32, u32); 2] = [(16, 12), (20, 10)];

fn open(dir: &TempDir) -> (ReplaySource, FrameSet) {
    let source = ReplaySource::open(dir.path(), Pacing::AsFastAsPossible).unwrap();
    let frame = FrameSet::for_rig(source.rig());
    (source, frame)
}

fn assert_pixels(frame: &FrameSet, sensor: usize) {
    let img = frame.sensor(sensor);
    for v in 0..img.height() {
        for u in 0..img.width() {
            assert_eq!(
                img.rgb(u, v),
                expected_rgb(frame.sequence, sensor, u, v),
                "frame {} sensor {sensor} pixel ({u}, {v})",
                frame.sequence
            );
        }
    }
}

fn open_err(dir: &Path) -> String {
    let err: SourceError = ReplaySource::open(dir, Pacing::AsFastAsPossible).unwrap_err();
    let msg = err.to_string();
    assert!(!msg.contains('\n'), "one line: {msg}");
    msg
}

// ---------------------------------------------------------------------------------------------
// The good path.

#[test]
fn delivers_every_frame_in_order_with_timestamps_and_pixels() {
    let dir = recording(&SMALL, 4);
    let (mut source, mut frame) = open(&dir);
    assert_eq!(source.frame_count(), 4);
    assert_eq!(source.rig().sensors.len(), 2);
    assert_eq!(frame.sensors().len(), 2);
    assert_eq!((frame.sensor(1).width(), frame.sensor(1).height()), (20, 10));
    assert_eq!(frame.sensor(1).pixels().len(), 20 * 10 * 3);

    for expected in 0..4u64 {
        assert_eq!(source.remaining(), (4 - expected) as usize);
        assert!(source.next_frame(&mut frame).unwrap());
        assert_eq!(frame.sequence, expected);
        assert_eq!(frame.valid_count(), 2);
        for sensor in 0..2 {
            let img = frame.sensor(sensor);
            assert!(img.valid);
            assert_eq!(img.fault, None);
            assert_eq!(img.sensor(), sensor);
            assert_eq!(img.timestamp_ns, timestamp(expected, sensor));
            assert_pixels(&frame, sensor);
        }
        assert_eq!(frame.timestamp_ns(), Some(timestamp(expected, 0)));
    }
    assert!(!source.next_frame(&mut frame).unwrap(), "end of stream");
    assert!(!source.next_frame(&mut frame).unwrap(), "stays ended");

    let stats = source.stats();
    assert_eq!(stats.frames_delivered, 4);
    assert_eq!(stats.images_delivered(), 8);
    assert!(stats.sensors.iter().all(|s| s.delivered == 4 && s.total_faults() == 0));
    assert_eq!(stats.bad_rows.total(), 0);
    assert_eq!(stats.warnings_printed + stats.warnings_suppressed, 0);
    assert_eq!(source.ground_truth(), None);
    assert_eq!(source.model_path(), None);
    let line = stats.to_string();
    assert!(
        line.starts_with("4 frames, 8/8 images") && !line.contains('\n'),
        "{line}"
    );

    source.rewind();
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sequence, 0);
    assert_pixels(&frame, 1);
}

#[test]
fn six_sensor_ladybug_rig_replays_through_a_trait_object() {
    let rig_text = std::fs::read_to_string(omnitrack_testkit::SHIPPED_RIG).unwrap();
    let rig = omnitrack_testkit::shipped_rig();
    let sizes: Vec<(u32, u32)> = rig.sensors.iter().map(|s| (s.width, s.height)).collect();
    let dir = recording_with_rig(&rig_text, &sizes, 2);

    let mut source: Box<dyn FrameSource> = Box::new(ReplaySource::open(dir.path(), Pacing::AsFastAsPossible).unwrap());
    assert_eq!(source.rig(), &rig);
    let mut frame = FrameSet::for_rig(source.rig());
    let mut n = 0;
    while source.next_frame(&mut frame).unwrap() {
        assert_eq!(frame.valid_count(), 6);
        assert_pixels(&frame, 5);
        n += 1;
    }
    assert_eq!(n, 2);
    assert_eq!(source.stats().images_delivered(), 12);
}

#[test]
fn frame_numbers_with_gaps_keep_their_numbers() {
    let dir = recording(&SMALL, 5);
    // Drop frame 2 entirely from the index.
    let rows: Vec<String> = (0..5u64)
        .filter(|&f| f != 2)
        .flat_map(|f| (0..2).map(move |s| format!("{f},{s},{},{}", timestamp(f, s), image_path(f, s))))
        .collect();
    write_index(dir.path(), &rows);
    let (mut source, mut frame) = open(&dir);
    let mut seen = Vec::new();
    while source.next_frame(&mut frame).unwrap() {
        assert_pixels(&frame, 0);
        seen.push(frame.sequence);
    }
    assert_eq!(seen, [0, 1, 3, 4]);
}

#[test]
fn ground_truth_and_model_are_found() {
    let dir = recording(&SMALL, 3);
    let mut tum = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for f in 0..3u64 {
        let t = timestamp(f, 0);
        let _ = writeln!(
            tum,
            "{}.{:09} {} 2.0 1.5 0 0 0 1",
            t / 1_000_000_000,
            t % 1_000_000_000,
            f as f64 * 0.1
        );
    }
    std::fs::write(dir.path().join("groundtruth.tum"), tum).unwrap();
    std::fs::write(dir.path().join("model.obj"), "v 0 0 0\nv 1 0 0\nl 1 2\n").unwrap();

    let (source, _) = open(&dir);
    let gt = source.ground_truth().expect("ground truth loaded");
    assert_eq!(gt.len(), 3);
    for (f, s) in gt.iter().enumerate() {
        assert_eq!(s.timestamp_ns, timestamp(f as u64, 0));
        assert!((s.pose.translation.vector.x - f as f64 * 0.1).abs() < 1e-12);
        assert_eq!(s.pose.translation.vector.y, 2.0);
    }
    assert_eq!(source.model_path(), Some(dir.path().join("model.obj").as_path()));
}

#[test]
fn grey_and_rgba_pngs_become_rgb_and_16_bit_is_refused() {
    let dir = recording(&SMALL, 3);
    let (w, h) = SMALL[0];
    let grey = |u: u32, v: u32| (u * 11 + v * 3) as u8;
    GrayImage::from_fn(w, h, |u, v| image::Luma([grey(u, v)]))
        .save(dir.path().join(image_path(0, 0)))
        .unwrap();
    GrayAlphaImage::from_fn(w, h, |u, v| image::LumaA([grey(u, v), 77]))
        .save(dir.path().join(image_path(1, 0)))
        .unwrap();
    RgbaImage::from_fn(w, h, |u, v| {
        let [r, g, b] = expected_rgb(2, 0, u, v);
        image::Rgba([r, g, b, 128])
    })
    .save(dir.path().join(image_path(2, 0)))
    .unwrap();
    let (w1, h1) = SMALL[1];
    ImageBuffer::<Rgb<u16>, Vec<u16>>::from_pixel(w1, h1, Rgb([1000, 2000, 3000]))
        .save(dir.path().join(image_path(1, 1)))
        .unwrap();

    let (mut source, mut frame) = open(&dir);
    for f in 0..3u64 {
        assert!(source.next_frame(&mut frame).unwrap());
        let img = frame.sensor(0);
        assert!(img.valid, "frame {f}");
        for v in 0..h {
            for u in 0..w {
                let want = if f < 2 {
                    [grey(u, v); 3]
                } else {
                    expected_rgb(2, 0, u, v)
                };
                assert_eq!(img.rgb(u, v), want, "frame {f} ({u}, {v})");
            }
        }
        if f == 1 {
            assert!(!frame.sensor(1).valid);
            assert_eq!(frame.sensor(1).fault, Some(ImageFault::WrongFormat));
        } else {
            assert_pixels(&frame, 1);
        }
    }
    assert_eq!(source.stats().sensors[0].delivered, 3);
    assert_eq!(source.stats().sensors[1].wrong_format, 1);
}

#[test]
fn real_time_pacing_keeps_the_recorded_spacing() {
    let dir = recording(&SMALL, 3);
    let rows: Vec<String> = (0..3u64)
        .flat_map(|f| {
            (0..2).map(move |s| format!("{f},{s},{},{}", T0_NS + f * 20_000_000 + s as u64, image_path(f, s)))
        })
        .collect();
    write_index(dir.path(), &rows);
    let span_ms = 40.0;

    let mut source = ReplaySource::open(dir.path(), Pacing::RealTime).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    let start = Instant::now();
    while source.next_frame(&mut frame).unwrap() {}
    let elapsed_ms = start.elapsed().as_secs_f64() * 1e3;
    assert_eq!(source.stats().frames_delivered, 3);
    assert!(
        elapsed_ms >= span_ms - 2.0,
        "3 frames 20 ms apart took {elapsed_ms:.1} ms"
    );

    // As fast as possible does not wait: frames a minute apart come at once.
    let rows: Vec<String> = (0..3u64)
        .flat_map(|f| (0..2).map(move |s| format!("{f},{s},{},{}", T0_NS + f * 60_000_000_000, image_path(f, s))))
        .collect();
    write_index(dir.path(), &rows);
    let (mut source, mut frame) = open(&dir);
    let start = Instant::now();
    while source.next_frame(&mut frame).unwrap() {}
    assert!(start.elapsed().as_secs_f64() < 30.0, "no sleeping");
}

/// Issue 50: a real-time replay waits for a frame far in the future (40 s, or `u64::MAX` ns, a
/// corrupt timestamp) only until its caller stops it: the wait ends within a slice of the stop,
/// nothing overflows, and the frame is not taken (the next call delivers it).
#[test]
fn a_stop_ends_the_wait_for_a_distant_frame() {
    use omnitrack_io::capture::STOP_SLICE;
    let dir = recording(&SMALL, 2);
    for far_ns in [T0_NS + 40_000_000_000, u64::MAX] {
        let rows: Vec<String> = (0..2u64)
            .flat_map(|f| {
                let t = if f == 0 { T0_NS } else { far_ns };
                (0..2).map(move |s| format!("{f},{s},{t},{}", image_path(f, s)))
            })
            .collect();
        write_index(dir.path(), &rows);
        let mut source = ReplaySource::open(dir.path(), Pacing::RealTime).unwrap();
        let mut frame = FrameSet::for_rig(source.rig());
        assert!(source.next_frame_or_stop(&mut frame, &|| false).unwrap());
        let started = Instant::now();
        let stop_at = started + Duration::from_millis(100);
        let got = source.next_frame_or_stop(&mut frame, &|| Instant::now() >= stop_at);
        let took = started.elapsed();
        assert!(!got.unwrap(), "{far_ns}: no frame when stopped");
        assert!(
            took >= Duration::from_millis(100) && took < Duration::from_millis(100) + 10 * STOP_SLICE,
            "{far_ns}: stopped after {took:?}"
        );
        assert_eq!(
            (source.remaining(), source.stats().frames_delivered),
            (1, 1),
            "{far_ns}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Faults of one image: counted, warned, survived.

#[test]
fn missing_image_is_counted_and_skipped() {
    let dir = recording(&SMALL, 3);
    std::fs::remove_file(dir.path().join(image_path(1, 1))).unwrap();
    let (mut source, mut frame) = open(&dir);
    for f in 0..3u64 {
        assert!(source.next_frame(&mut frame).unwrap());
        assert_pixels(&frame, 0);
        let img = frame.sensor(1);
        if f == 1 {
            assert!(!img.valid);
            assert_eq!(img.fault, Some(ImageFault::Missing));
            assert_eq!(img.timestamp_ns, timestamp(1, 1), "the recorded time is still known");
        } else {
            assert!(img.valid);
            assert_pixels(&frame, 1);
        }
    }
    let stats = source.stats();
    assert_eq!(stats.frames_delivered, 3);
    assert_eq!((stats.sensors[1].missing, stats.sensors[1].delivered), (1, 2));
    assert_eq!(stats.faults(ImageFault::Missing), 1);
    assert_eq!(stats.warnings_printed, 1);
}

#[test]
fn corrupt_pngs_are_counted_and_skipped() {
    let dir = recording(&SMALL, 3);
    std::fs::write(
        dir.path().join(image_path(0, 0)),
        b"this is not a PNG at all, just garbage bytes",
    )
    .unwrap();
    // A truncated PNG: a valid header, half the data.
    let good = std::fs::read(dir.path().join(image_path(2, 1))).unwrap();
    std::fs::write(dir.path().join(image_path(2, 1)), &good[..good.len() / 2]).unwrap();
    // An empty file.
    std::fs::write(dir.path().join(image_path(1, 0)), b"").unwrap();

    let (mut source, mut frame) = open(&dir);
    let mut faults = Vec::new();
    while source.next_frame(&mut frame).unwrap() {
        for img in frame.sensors() {
            if let Some(fault) = img.fault {
                faults.push((frame.sequence, img.sensor(), fault));
            } else {
                assert_pixels(&frame, img.sensor());
            }
        }
    }
    assert_eq!(
        faults,
        [
            (0, 0, ImageFault::Corrupt),
            (1, 0, ImageFault::Corrupt),
            (2, 1, ImageFault::Corrupt)
        ]
    );
    assert_eq!(source.stats().faults(ImageFault::Corrupt), 3);
    assert_eq!(source.stats().frames_delivered, 3);
    assert_eq!(source.stats().images_delivered(), 3);
}

#[test]
fn wrong_size_png_is_counted_and_skipped() {
    let dir = recording(&SMALL, 2);
    frame_image(1, 0, 17, 12)
        .save(dir.path().join(image_path(1, 0)))
        .unwrap();
    let (mut source, mut frame) = open(&dir);
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 2);
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sensor(0).fault, Some(ImageFault::WrongSize));
    assert!(frame.sensor(1).valid);
    assert!(!source.next_frame(&mut frame).unwrap());
    assert_eq!(source.stats().sensors[0].wrong_size, 1);
}

#[test]
fn missing_sensor_directory_invalidates_that_sensor_every_frame() {
    let dir = recording(&SMALL, 3);
    std::fs::remove_dir_all(dir.path().join("sensor1")).unwrap();
    let (mut source, mut frame) = open(&dir);
    let mut n = 0;
    while source.next_frame(&mut frame).unwrap() {
        assert_pixels(&frame, 0);
        assert_eq!(frame.sensor(1).fault, Some(ImageFault::Missing));
        n += 1;
    }
    assert_eq!(n, 3);
    let stats = source.stats();
    assert_eq!((stats.sensors[0].delivered, stats.sensors[1].missing), (3, 3));
    // One warning for the directory at open, plus per-image warnings.
    assert!(stats.warnings_printed >= 2);
}

#[test]
fn a_sensor_without_a_row_is_dropped_not_an_error() {
    let dir = recording(&SMALL, 3);
    let rows: Vec<String> = (0..3u64)
        .flat_map(|f| (0..2).map(move |s| (f, s)))
        .filter(|&(f, s)| !(f == 1 && s == 0))
        .map(|(f, s)| format!("{f},{s},{},{}", timestamp(f, s), image_path(f, s)))
        .collect();
    write_index(dir.path(), &rows);
    let (mut source, mut frame) = open(&dir);
    assert!(source.next_frame(&mut frame).unwrap());
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sequence, 1);
    let img = frame.sensor(0);
    assert!(!img.valid);
    assert_eq!((img.fault, img.timestamp_ns), (Some(ImageFault::Dropped), 0));
    assert_pixels(&frame, 1);
    assert_eq!(frame.timestamp_ns(), Some(timestamp(1, 1)));
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.valid_count(), 2, "a sensor recovers on the next frame");
    assert_eq!(source.stats().sensors[0].dropped, 1);
}

#[test]
fn repeated_faults_are_warned_a_few_times_then_only_counted() {
    let dir = recording(&SMALL, 12);
    for f in 0..12 {
        std::fs::write(dir.path().join(image_path(f, 0)), b"garbage").unwrap();
    }
    let (mut source, mut frame) = open(&dir);
    while source.next_frame(&mut frame).unwrap() {
        assert_pixels(&frame, 1);
    }
    let stats = source.stats();
    assert_eq!(stats.sensors[0].corrupt, 12);
    assert!(
        stats.warnings_printed >= 1 && stats.warnings_printed < 12,
        "{}",
        stats.warnings_printed
    );
    assert_eq!(stats.warnings_printed + stats.warnings_suppressed, 12);
}

#[test]
fn a_frame_set_of_another_rig_is_refused() {
    let dir = recording(&SMALL, 1);
    let (mut source, _) = open(&dir);
    let other = Rig::from_toml_str(&pinhole_rig_toml(&[(16, 12), (20, 11)]), "other.toml").unwrap();
    let mut wrong = FrameSet::for_rig(&other);
    let err = source.next_frame(&mut wrong).unwrap_err();
    assert!(matches!(err, SourceError::FrameSetMismatch { .. }), "{err}");
    assert!(err.to_string().contains("test-rig"));
    let mut right = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut right).unwrap(), "the source is still usable");
}

// ---------------------------------------------------------------------------------------------
// The index: bad rows skipped and counted, unusable files refused.

#[test]
fn bad_index_rows_of_every_kind_are_skipped_and_counted() {
    let dir = recording(&SMALL, 2);
    append_index(
        dir.path(),
        "\n\
         5,0,123\n\
         5,0,123,sensor0/000000.png,extra\n\
         x,0,123,sensor0/000000.png\n\
         5,-1,123,sensor0/000000.png\n\
         5,0,1.5,sensor0/000000.png\n\
         5,7,123,sensor0/000000.png\n\
         1,1,999,sensor0/000000.png\n\
         5,0,123,\n",
    );
    let (mut source, mut frame) = open(&dir);
    let bad = &source.stats().bad_rows;
    assert_eq!(bad.field_count, 2);
    assert_eq!(bad.not_a_number, 3);
    assert_eq!(bad.unknown_sensor, 1);
    assert_eq!(bad.duplicate, 1);
    assert_eq!(bad.empty_path, 1);
    assert_eq!(bad.total(), 8);
    assert_eq!(source.frame_count(), 2, "no frame 5 was made from bad rows");
    while source.next_frame(&mut frame).unwrap() {
        assert_eq!(frame.valid_count(), 2);
        assert_pixels(&frame, 0);
        // The duplicate (1, 1) row came after the original and is the one dropped.
        assert_pixels(&frame, 1);
        assert_eq!(frame.sensor(1).timestamp_ns, timestamp(frame.sequence, 1));
    }
    assert_eq!(source.stats().frames_delivered, 2);
}

/// The index as bytes (a row may be any bytes at all), under the header.
fn write_index_bytes(root: &Path, rows: &[Vec<u8>]) {
    let mut bytes = b"frame,sensor,timestamp_ns,path\n".to_vec();
    for r in rows {
        bytes.extend_from_slice(r);
        bytes.push(b'\n');
    }
    std::fs::write(root.join("frames.csv"), bytes).unwrap();
}

fn row(frame: u64, sensor: usize) -> Vec<u8> {
    format!(
        "{frame},{sensor},{},{}",
        timestamp(frame, sensor),
        image_path(frame, sensor)
    )
    .into_bytes()
}

/// Bad lines of every kind inside a frame's rows, and rows that fall out of (frame, sensor) order
/// part way through (which the format allows): every frame comes out whole, in order, its first
/// row kept of two for one sensor, each bad line counted once.
#[test]
fn index_rows_in_any_order_with_bad_lines_among_them_replay_whole() {
    let long = vec![b'7'; 5000];
    let not_text = b"0,1,5,sensor1/\xff\xfe.png".to_vec();
    let in_order = vec![
        row(0, 0),
        long.clone(),
        not_text.clone(),
        b"0,1".to_vec(),
        row(0, 1),
        row(0, 1),
        row(1, 0),
        row(1, 1),
        row(2, 0),
        row(2, 1),
        row(3, 0),
        row(3, 1),
    ];
    // The same rows with frame 3 before frame 2 and a late second row for (0, 1).
    let mut shuffled = in_order.clone();
    shuffled.swap(8, 10);
    shuffled.swap(9, 11);
    let mut late = row(0, 1);
    late.extend_from_slice(b"x");
    shuffled.push(late);
    for (name, rows, duplicates) in [("in order", in_order, 1), ("out of order", shuffled, 2)] {
        let dir = recording(&SMALL, 4);
        write_index_bytes(dir.path(), &rows);
        let (mut source, mut frame) = open(&dir);
        let bad = source.stats().bad_rows.clone();
        assert_eq!(
            (bad.unreadable, bad.field_count, bad.duplicate, bad.total()),
            (2, 1, duplicates, 3 + duplicates),
            "{name}: {bad:?}"
        );
        assert_eq!(source.frame_count(), 4, "{name}");
        for expected in 0..4 {
            assert!(source.next_frame(&mut frame).unwrap(), "{name}");
            assert_eq!(frame.sequence, expected, "{name}");
            assert_eq!(frame.valid_count(), 2, "{name}: frame {expected}");
            for sensor in 0..2 {
                assert_pixels(&frame, sensor);
                assert_eq!(frame.sensor(sensor).timestamp_ns, timestamp(expected, sensor), "{name}");
            }
        }
        assert!(!source.next_frame(&mut frame).unwrap(), "{name}");
    }
}

/// A day's index (a row per sensor per frame) is not held in memory: opening it keeps a few dozen
/// bytes per frame whatever its rows hold, and reads the file through a fixed buffer. Held whole
/// (text and parsed rows with their paths), these 120,000 rows took over 10 MB.
#[test]
fn a_long_index_is_held_per_frame_not_per_row() {
    const FRAMES: u64 = 20_000;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("rig.toml"), pinhole_rig_toml(&[(16, 12); 6])).unwrap();
    let rows: Vec<Vec<u8>> = (0..FRAMES).flat_map(|f| (0..6).map(move |s| row(f, s))).collect();
    write_index_bytes(dir.path(), &rows);
    drop(rows);

    let (source, peak, kept) =
        omnitrack_testkit::heap_in(|| ReplaySource::open(dir.path(), Pacing::AsFastAsPossible).unwrap());
    let mut source = source;
    eprintln!("opening a {}-row index: peak heap {peak} B, kept {kept} B", FRAMES * 6);
    assert_eq!(source.frame_count(), FRAMES as usize);
    assert!(
        kept <= 48 * FRAMES as i64 + (64 << 10),
        "kept {kept} B for {FRAMES} frames"
    );
    assert!(
        peak <= 64 * FRAMES as i64 + (256 << 10),
        "peak {peak} B for {FRAMES} frames"
    );

    // Its frames still come out, their rows read back from the file.
    let mut frame = FrameSet::for_rig(source.rig());
    source.seek(FRAMES as usize - 1);
    assert!(source.next_frame(&mut frame).unwrap());
    assert_eq!(frame.sequence, FRAMES - 1);
    assert_eq!(frame.sensor(5).timestamp_ns, timestamp(FRAMES - 1, 5));
    assert_eq!(frame.sensor(5).fault, Some(ImageFault::Missing), "no image was written");
}

/// An index cut short while it is replayed is an error naming it, not a panic or a wrong frame.
#[test]
fn an_index_truncated_during_replay_is_a_one_line_error() {
    let dir = recording(&SMALL, 3);
    write_index_bytes(
        dir.path(),
        &(0..3).flat_map(|f| [row(f, 0), row(f, 1)]).collect::<Vec<_>>(),
    );
    let (mut source, mut frame) = open(&dir);
    assert!(source.next_frame(&mut frame).unwrap());
    write_index_bytes(dir.path(), &[]);
    let err = source.next_frame(&mut frame).unwrap_err().to_string();
    assert!(err.contains("frames.csv") && !err.contains('\n'), "{err}");
}

#[test]
fn index_with_only_a_header_is_an_empty_stream() {
    let dir = recording(&SMALL, 1);
    write_index(dir.path(), &[]);
    let (mut source, mut frame) = open(&dir);
    assert_eq!(source.frame_count(), 0);
    assert!(!source.next_frame(&mut frame).unwrap());
}

#[test]
fn missing_or_malformed_files_are_one_line_errors_naming_the_file() {
    let dir = recording(&SMALL, 1);
    std::fs::remove_file(dir.path().join("frames.csv")).unwrap();
    let msg = open_err(dir.path());
    assert!(msg.contains("frames.csv") && msg.contains("cannot read"), "{msg}");

    std::fs::write(
        dir.path().join("frames.csv"),
        "frame;sensor;timestamp_ns;path\n0;0;1;a.png\n",
    )
    .unwrap();
    let msg = open_err(dir.path());
    assert!(msg.contains("frames.csv:1") && msg.contains("header"), "{msg}");

    std::fs::write(dir.path().join("frames.csv"), "").unwrap();
    let msg = open_err(dir.path());
    assert!(msg.contains("frames.csv:1"), "{msg}");

    let dir = recording(&SMALL, 1);
    std::fs::remove_file(dir.path().join("rig.toml")).unwrap();
    let msg = open_err(dir.path());
    assert!(msg.contains("rig.toml"), "{msg}");

    let dir = recording(&SMALL, 1);
    std::fs::write(dir.path().join("groundtruth.tum"), "0.0 1 2 3 0 0 0\n").unwrap();
    let msg = open_err(dir.path());
    assert!(msg.contains("groundtruth.tum:1"), "{msg}");

    let missing = dir.path().join("no-such-recording");
    let msg = open_err(&missing);
    assert!(msg.contains("no-such-recording"), "{msg}");
}

// ---------------------------------------------------------------------------------------------
// Allocations in the steady state.

/// After the first frame, `next_frame` allocates nothing of its own; the `image` crate's PNG decoder
/// still allocates its inflate state and row buffers for every image it opens (its API cannot reuse
/// them). This pins that count: the same small number for every frame, proportional to the number
/// of sensors, so that a regression (a per-frame `Vec`, a path built per frame) shows up here.
#[test]
fn steady_state_allocations_per_frame_are_constant_and_only_the_decoders() {
    let rig_text = std::fs::read_to_string(omnitrack_testkit::SHIPPED_RIG).unwrap();
    let rig = omnitrack_testkit::shipped_rig();
    let sizes: Vec<(u32, u32)> = rig.sensors.iter().map(|s| (s.width, s.height)).collect();
    let dir = recording_with_rig(&rig_text, &sizes, 6);

    let mut source = ReplaySource::open(dir.path(), Pacing::AsFastAsPossible).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut frame).unwrap(), "warm-up frame");

    let mut counts = Vec::new();
    loop {
        let (more, allocations) = omnitrack_testkit::allocations_in(|| source.next_frame(&mut frame).unwrap());
        if !more {
            assert_eq!(allocations, 0, "end of stream allocates nothing");
            break;
        }
        assert_eq!(frame.valid_count(), 6);
        counts.push(allocations);
    }
    eprintln!("allocations per six-sensor frame after warm-up: {counts:?}");
    assert_eq!(counts.len(), 5);
    assert!(counts.iter().all(|&c| c == counts[0]), "constant per frame: {counts:?}");
    let per_image = counts[0] as f64 / 6.0;
    assert!(
        counts[0] % 6 == 0 && per_image <= 16.0,
        "a few decoder allocations per image: {counts:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// The faster formats: QOI and raw PPM/PGM.

/// Rewrites `sensor`'s image of `frame` in `dir` (written as a PNG by `recording`) as `ext`
/// (qoi, ppm or pgm; pgm keeps the green channel), under a name of that extension, and points its
/// index row at it.
fn convert(dir: &Path, frame: u64, sensor: usize, ext: &str) {
    let png = dir.join(image_path(frame, sensor));
    let rgb = image::open(&png).unwrap().to_rgb8();
    let (w, h) = rgb.dimensions();
    let bytes = match ext {
        "qoi" => qoi::encode_to_vec(rgb.as_raw(), w, h).unwrap(),
        "ppm" => [
            format!("P6\n# made by a test\n{w} {h}\n255\n").into_bytes(),
            rgb.into_raw(),
        ]
        .concat(),
        "pgm" => [
            format!("P5 {w}\n{h} 255\n").into_bytes(),
            rgb.pixels().map(|p| p.0[1]).collect::<Vec<u8>>(),
        ]
        .concat(),
        _ => unreachable!(),
    };
    let name = image_path(frame, sensor).replace(".png", &format!(".{ext}"));
    std::fs::write(dir.join(&name), bytes).unwrap();
    std::fs::remove_file(&png).unwrap();
    let index = std::fs::read_to_string(dir.join("frames.csv")).unwrap();
    std::fs::write(dir.join("frames.csv"), index.replace(&image_path(frame, sensor), &name)).unwrap();
}

/// A recording whose images are QOI, PPM and PGM files, mixed with PNGs (each file's first bytes
/// say what it is): the same pixels come back (a PGM's grey in all three channels).
#[test]
fn qoi_and_ppm_images_replay_to_the_same_pixels_as_png() {
    let dir = recording(&SMALL, 4);
    let formats = ["qoi", "ppm", "png", "qoi"];
    for (frame, ext) in formats.iter().enumerate() {
        for sensor in 0..2 {
            if *ext != "png" {
                convert(dir.path(), frame as u64, sensor, ext);
            }
        }
    }
    convert(dir.path(), 2, 1, "pgm");
    let (mut source, mut frame) = open(&dir);
    let mut frames = 0;
    while source.next_frame(&mut frame).unwrap() {
        assert_eq!(frame.valid_count(), 2, "frame {}", frame.sequence);
        for sensor in 0..2 {
            if (frame.sequence, sensor) == (2, 1) {
                let img = frame.sensor(1);
                for (u, v) in [(0, 0), (5, 3), (19, 9)] {
                    let g = expected_rgb(2, 1, u, v)[1];
                    assert_eq!(img.rgb(u, v), [g; 3], "PGM pixel ({u}, {v})");
                }
            } else {
                assert_pixels(&frame, sensor);
            }
        }
        frames += 1;
    }
    assert_eq!(frames, 4);
    assert_eq!(source.stats().images_delivered(), 8);
}

/// A PPM of the sensor's size is read straight into the image; one whose header runs past the
/// bytes first read (a long comment), one with bytes after its pixels and one smaller than a
/// block give the same pixels.
#[test]
fn ppm_headers_of_any_length_and_trailing_bytes_replay_the_same_pixels() {
    let dir = recording(&SMALL, 3);
    for frame in 0..3 {
        convert(dir.path(), frame, 0, "ppm");
    }
    let rewrite = |frame: u64, edit: &dyn Fn(&[u8]) -> Vec<u8>| {
        let path = dir.path().join(format!("sensor0/{frame:06}.ppm"));
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, edit(&bytes)).unwrap();
    };
    // A 10 kB comment before the width.
    rewrite(0, &|b| [b"P6\n#".as_slice(), &[b'x'; 10_000], b"\n", &b[3..]].concat());
    // Junk after the pixels.
    rewrite(1, &|b| [b, b"trailing bytes".as_slice()].concat());
    let (mut source, mut frame) = open(&dir);
    let mut frames = 0;
    while source.next_frame(&mut frame).unwrap() {
        assert_eq!(frame.valid_count(), 2, "frame {}", frame.sequence);
        for sensor in 0..2 {
            assert_pixels(&frame, sensor);
        }
        frames += 1;
    }
    assert_eq!(frames, 3);
}

/// A damaged QOI or PPM, or a file of no known format, makes that sensor's image corrupt for
/// that frame (counted, one warning line), and the replay goes on.
#[test]
fn corrupt_qoi_and_ppm_images_are_counted_and_skipped() {
    let dir = recording(&SMALL, 5);
    for frame in 0..5 {
        convert(dir.path(), frame, 0, if frame % 2 == 0 { "qoi" } else { "ppm" });
    }
    let qoi0 = dir.path().join("sensor0/000000.qoi");
    let good = std::fs::read(&qoi0).unwrap();
    std::fs::write(&qoi0, &good[..good.len() / 2]).unwrap();
    let ppm1 = dir.path().join("sensor0/000001.ppm");
    let good = std::fs::read(&ppm1).unwrap();
    std::fs::write(&ppm1, &good[..good.len() - 7]).unwrap();
    std::fs::write(dir.path().join("sensor0/000003.ppm"), b"P6\n20 12\n65535\n\x00\x00").unwrap();
    std::fs::write(dir.path().join("sensor0/000004.qoi"), b"GIF89a and then some").unwrap();
    let (mut source, mut frame) = open(&dir);
    let mut faults = Vec::new();
    while source.next_frame(&mut frame).unwrap() {
        for img in frame.sensors() {
            match img.fault {
                Some(fault) => faults.push((frame.sequence, img.sensor(), fault)),
                None => assert_pixels(&frame, img.sensor()),
            }
        }
    }
    assert_eq!(
        faults,
        [0, 1, 3, 4].map(|f| (f, 0, ImageFault::Corrupt)),
        "frame 2's QOI is whole"
    );
    assert_eq!(source.stats().frames_delivered, 5);
}

/// Replaying QOI or PPM images allocates one thing per image, the file's resolved path (the
/// check that it lies inside the recording), and none of the PNG decoder's state (seven per
/// image in the test above).
#[test]
fn qoi_and_ppm_replays_allocate_only_the_resolved_path() {
    let rig_text = std::fs::read_to_string(omnitrack_testkit::SHIPPED_RIG).unwrap();
    let rig = omnitrack_testkit::shipped_rig();
    let sizes: Vec<(u32, u32)> = rig.sensors.iter().map(|s| (s.width, s.height)).collect();
    let dir = recording_with_rig(&rig_text, &sizes, 5);
    for frame in 0..5 {
        for sensor in 0..sizes.len() {
            convert(
                dir.path(),
                frame,
                sensor,
                if (frame + sensor as u64) % 2 == 0 { "qoi" } else { "ppm" },
            );
        }
    }
    let mut source = ReplaySource::open(dir.path(), Pacing::AsFastAsPossible).unwrap();
    let mut frame = FrameSet::for_rig(source.rig());
    assert!(source.next_frame(&mut frame).unwrap(), "warm-up frame");
    for _ in 1..5 {
        let (more, allocations) = omnitrack_testkit::allocations_in(|| source.next_frame(&mut frame).unwrap());
        assert!(more);
        assert_eq!(frame.valid_count(), 6);
        assert_eq!(allocations, 6, "frame {}: one per image", frame.sequence);
        for (sensor, &(w, h)) in sizes.iter().enumerate() {
            for (u, v) in [(0, 0), (w / 2, h / 3), (w - 1, h - 1)] {
                assert_eq!(
                    frame.sensor(sensor).rgb(u, v),
                    expected_rgb(frame.sequence, sensor, u, v)
                );
            }
        }
    }
}

/// A recording reads only regular files inside its folder: paths with `..` or absolute ones are
/// bad rows; a link out of the folder (the file itself, or a folder on its path), a FIFO (which would block the read forever) and a device
/// (which never ends) are skipped images, counted and warned about, and the run goes on.
#[test]
fn a_recording_reads_nothing_outside_its_folder() {
    let outside = tempfile::tempdir().unwrap();
    let secret = outside.path().join("secret.png");
    let dir = recording(&SMALL, 3);
    std::fs::copy(dir.path().join("sensor0/000000.png"), &secret).unwrap();
    append_index(
        dir.path(),
        &format!(
            "\n7,0,700,../{}\n7,1,700,{}\n8,0,800,outlink/{}\n",
            secret.file_name().unwrap().to_str().unwrap(),
            secret.display(),
            secret.file_name().unwrap().to_str().unwrap(),
        ),
    );
    // Frame 8: sensor 0 a file inside a folder that is a link out of the recording.
    std::os::unix::fs::symlink(outside.path(), dir.path().join("outlink")).unwrap();
    // Frame 1: sensor 0 a link out of the folder, sensor 1 a FIFO; frame 2: sensor 0 /dev/zero.
    let s0 = dir.path().join("sensor0");
    std::fs::remove_file(s0.join("000001.png")).unwrap();
    std::os::unix::fs::symlink(&secret, s0.join("000001.png")).unwrap();
    let s1 = dir.path().join("sensor1/000001.png");
    std::fs::remove_file(&s1).unwrap();
    let made = std::process::Command::new("mkfifo").arg(&s1).status().unwrap();
    assert!(made.success());
    std::fs::remove_file(s0.join("000002.png")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", s0.join("000002.png")).unwrap();

    let (mut source, mut frame) = open(&dir);
    assert_eq!(source.stats().bad_rows.outside, 2, "the absolute and the .. rows");
    let mut valid = Vec::new();
    while source.next_frame(&mut frame).unwrap() {
        valid.push((frame.sensor(0).valid, frame.sensor(1).valid));
    }
    assert_eq!(valid, vec![(true, true), (false, false), (false, true), (false, false)]);
    assert_eq!(source.stats().sensors[0].missing, 3);
    assert_eq!(source.stats().sensors[1].missing, 1);
}

/// A rig whose two sensors are windows of one device's frame (`crop`, a dual-fisheye camera):
/// a recording whose rows of both sensors name the same whole frame gives each sensor its
/// window, in any pixel format; a sensor's own image (of its size) is taken as it is; a frame
/// that does not hold a window is a wrong-size image, counted, and the stream goes on.
#[test]
fn sensors_with_a_crop_take_their_window_of_a_shared_frame() {
    let (w, h) = (6u32, 4u32);
    let mut rig = pinhole_rig_toml(&[(w, h), (w, h)]);
    // Sensor 0 is the left half of a 13 × 5 frame, sensor 1 the right half one row down.
    rig = rig.replacen(
        "translation_m = [0, 0.0, 0.0]\n",
        "translation_m = [0, 0.0, 0.0]\ncrop = [0, 0, 6, 4]\n",
        1,
    );
    rig = rig.replacen(
        "translation_m = [0.01, 0.0, 0.0]\n",
        "translation_m = [0.01, 0.0, 0.0]\ncrop = [7, 1, 6, 4]\n",
        1,
    );
    assert_eq!(rig.matches("crop").count(), 2, "{rig}");
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::write(root.join("rig.toml"), &rig).unwrap();
    let whole = |frame: u64| RgbImage::from_fn(13, 5, |u, v| Rgb(expected_rgb(frame, 9, u, v)));
    whole(0).save(root.join("f0.png")).unwrap();
    RgbaImage::from_fn(13, 5, |u, v| {
        let [r, g, b] = expected_rgb(1, 9, u, v);
        image::Rgba([r, g, b, 200])
    })
    .save(root.join("f1.png"))
    .unwrap();
    // Frame 2: sensor 0 has its own image, sensor 1 a frame too small for its window.
    frame_image(2, 0, w, h).save(root.join("own.png")).unwrap();
    RgbImage::from_fn(12, 5, |u, v| Rgb(expected_rgb(2, 9, u, v)))
        .save(root.join("small.png"))
        .unwrap();
    let mut rows = Vec::new();
    for (frame, paths) in [
        (0u64, ["f0.png", "f0.png"]),
        (1, ["f1.png", "f1.png"]),
        (2, ["own.png", "small.png"]),
    ] {
        for (sensor, path) in paths.iter().enumerate() {
            rows.push(format!("{frame},{sensor},{},{path}", timestamp(frame, 0)));
        }
    }
    write_index(root, &rows);

    let (mut source, mut frame) = open(&dir);
    for f in 0..2u64 {
        assert!(source.next_frame(&mut frame).unwrap());
        assert_eq!(frame.valid_count(), 2, "frame {f}");
        for v in 0..h {
            for u in 0..w {
                assert_eq!(frame.sensor(0).rgb(u, v), expected_rgb(f, 9, u, v));
                assert_eq!(frame.sensor(1).rgb(u, v), expected_rgb(f, 9, u + 7, v + 1));
            }
        }
    }
    assert!(source.next_frame(&mut frame).unwrap());
    assert_pixels(&frame, 0);
    assert!(!frame.sensor(1).valid);
    assert_eq!(frame.sensor(1).fault, Some(ImageFault::WrongSize));
    assert_eq!(source.stats().sensors[1].wrong_size, 1);
    assert!(!source.next_frame(&mut frame).unwrap());
}
