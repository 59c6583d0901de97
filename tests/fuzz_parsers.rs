//! Every parser of outside input, fed mutated copies of valid files: no panic, no abort, no hang,
//! and every refusal one line (issue 24's "Done when": ≥ 10,000 inputs per parser).
//!
//! The inputs are deterministic (a seeded mutator, so a failure repeats): valid seed files with
//! 1–8 mutations each — bit flips, bytes set to a syntax character, numbers replaced by extreme
//! ones (1e308, NaN, 2⁶⁴, −0, 1e−320), ranges deleted, duplicated or spliced from another seed,
//! truncation. A structure-aware fuzzer reaches deeper than random bytes with far fewer cases;
//! the mutations keep most inputs close to valid so that the checks after the syntax run.
//!
//! Per parser: `OMNITRACK_FUZZ_CASES` inputs (default 10,000). A panic saves its input under
//! `target/fuzz-failures/` and fails the test; a case that runs longer than [`HANG_LIMIT`] is a
//! hang (its input saved likewise); an abort or stack overflow kills the process, which fails
//! the run. The figures are printed per parser; a recording "refuses" an input when replay
//! skipped an image or a row of it (and went on).
#![cfg(feature = "desk")]

use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::desk::opencv_calib::{rig_from_opencv, OpenCvModel};
use omnitrack::frame::FrameSet;
use omnitrack::visibility::build::{build_table, BuildOptions};
use omnitrack::visibility::VisibilityTable;
use omnitrack::{Model, Rig};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod common;

/// A case slower than this is a hang.
const HANG_LIMIT: Duration = Duration::from_secs(20);

fn cases() -> usize {
    std::env::var("OMNITRACK_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000)
}

/// Fragments spliced into inputs: syntax characters of the formats and numbers at the edges.
const TOKENS: &[&[u8]] = &[
    b"1e308",
    b"-1e308",
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b"-0",
    b"0",
    b"1e-320",
    b"18446744073709551616",
    b"4294967295",
    b"-1",
    b"99999999",
    b"0x7fffffff",
    b"\n",
    b",",
    b"[",
    b"]",
    b"{",
    b"}",
    b"\"",
    b"=",
    b"#",
    b":",
    b"-",
    b" ",
    b"/",
    b"f 1 2 3\n",
    b"v 1e300 0 0\n",
    b"l 1 2\n",
    b"f -1 -2 -3\n",
    b"[[sensors]]\n",
    b"!!opencv-matrix\n",
    b"\t",
    b"\0",
    b"\xff\xfe",
];

struct Mutator {
    rng: SmallRng,
}

impl Mutator {
    fn new(seed: u64) -> Mutator {
        Mutator {
            rng: SmallRng::seed_from_u64(seed),
        }
    }

    fn token(&mut self) -> &'static [u8] {
        TOKENS[self.rng.random_range(0..TOKENS.len())]
    }

    fn mutate(&mut self, seeds: &[Vec<u8>]) -> Vec<u8> {
        let mut b = seeds[self.rng.random_range(0..seeds.len())].clone();
        for _ in 0..self.rng.random_range(1..=8) {
            let n = b.len();
            let at = if n == 0 { 0 } else { self.rng.random_range(0..n) };
            match self.rng.random_range(0..9) {
                0 if n > 0 => b[at] ^= 1 << self.rng.random_range(0..8),
                1 if n > 0 => b[at] = self.token()[0],
                2 => {
                    let t = self.token();
                    b.splice(at..at, t.iter().copied());
                }
                3 => {
                    // A number (a run of digits, dots, signs, exponents) replaced by another token.
                    let is_num = |c: u8| c.is_ascii_digit() || b".-+eE".contains(&c);
                    if let Some(start) = (at..n).find(|&i| b[i].is_ascii_digit()) {
                        let s = (0..start).rev().take_while(|&i| is_num(b[i])).last().unwrap_or(start);
                        let e = (start..n).find(|&i| !is_num(b[i])).unwrap_or(n);
                        let t = self.token();
                        b.splice(s..e, t.iter().copied());
                    }
                }
                4 if n > 0 => {
                    let end = (at + self.rng.random_range(1..64)).min(n);
                    b.drain(at..end);
                }
                5 if n > 0 => {
                    let end = (at + self.rng.random_range(1..256)).min(n);
                    let copy = b[at..end].to_vec();
                    let to = self.rng.random_range(0..=n);
                    b.splice(to..to, copy);
                }
                6 => {
                    let other = &seeds[self.rng.random_range(0..seeds.len())];
                    if !other.is_empty() {
                        let s = self.rng.random_range(0..other.len());
                        let e = (s + self.rng.random_range(1..512)).min(other.len());
                        b.splice(at..at, other[s..e].iter().copied());
                    }
                }
                7 if n > 0 => b.truncate(at),
                _ => {
                    let k = self.rng.random_range(1..8);
                    let junk: Vec<u8> = (0..k).map(|_| self.rng.random()).collect();
                    b.splice(at..at, junk);
                }
            }
        }
        b
    }
}

/// What one parser made of its inputs.
#[derive(Debug, Default)]
struct Tally {
    accepted: u64,
    refused: u64,
    slowest: Duration,
}

/// Runs `parse` on [`cases`] mutations of `seeds` on a worker thread watched for hangs. `parse`
/// returns `Ok` or the error's text, which must be one line.
fn fuzz(name: &str, seed: u64, seeds: Vec<Vec<u8>>, parse: impl Fn(&[u8]) -> Result<(), String> + Send + 'static) {
    assert!(!seeds.is_empty());
    let n = cases();
    let done = Arc::new(AtomicU64::new(0));
    let current = Arc::new(Mutex::new(Vec::new()));
    let worker = {
        let (done, current) = (Arc::clone(&done), Arc::clone(&current));
        let name = name.to_string();
        std::thread::spawn(move || {
            let mut m = Mutator::new(seed);
            let mut tally = Tally::default();
            for _ in 0..n {
                let input = m.mutate(&seeds);
                *current.lock().unwrap() = input.clone();
                let t = Instant::now();
                let outcome = catch_unwind(AssertUnwindSafe(|| parse(&input)));
                tally.slowest = tally.slowest.max(t.elapsed());
                match outcome {
                    Ok(Ok(())) => tally.accepted += 1,
                    Ok(Err(e)) => {
                        if e.contains('\n') {
                            let path = save(&name, "multiline", &input);
                            panic!("{name}: an error of more than one line ({}): {e:?}", path.display());
                        }
                        tally.refused += 1;
                    }
                    Err(_) => {
                        let path = save(&name, "panic", &input);
                        panic!("{name}: the parser panicked on {}", path.display());
                    }
                }
                done.fetch_add(1, Ordering::Relaxed);
            }
            tally
        })
    };
    let start = Instant::now();
    let (mut last, mut moved) = (0, Instant::now());
    while !worker.is_finished() {
        std::thread::sleep(Duration::from_millis(50));
        let now = done.load(Ordering::Relaxed);
        if now != last {
            (last, moved) = (now, Instant::now());
        } else if moved.elapsed() > HANG_LIMIT {
            let input = current.lock().unwrap().clone();
            let path = save(name, "hang", &input);
            panic!("{name}: no answer within {HANG_LIMIT:?} on {}", path.display());
        }
    }
    let tally = match worker.join() {
        Ok(t) => t,
        Err(e) => std::panic::resume_unwind(e),
    };
    println!(
        "{name}: {n} inputs in {:.1} s: {} accepted, {} refused in one line, 0 panics, 0 hangs, slowest {:.1} ms",
        start.elapsed().as_secs_f64(),
        tally.accepted,
        tally.refused,
        tally.slowest.as_secs_f64() * 1e3
    );
    assert_eq!(tally.accepted + tally.refused, n as u64);
}

fn save(name: &str, kind: &str, input: &[u8]) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join(format!("{}-{kind}.bin", name.replace([' ', '/'], "_")));
    let _ = std::fs::write(&path, input);
    path
}

fn text(b: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(b)
}

fn file(rel: &str) -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)).unwrap()
}

/// Two rooms and a door opening, with groups, a free segment and negative indices.
const ROOMS_OBJ: &str =
    "# two rooms\no rooms\nv 0 0 0\nv 4 0 0\nv 4 3 0\nv 0 3 0\nv 0 0 2.5\nv 4 0 2.5\nv 4 3 2.5\nv 0 3 2.5\n\
g floor\nf 1 2 3 4\ng walls\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf -5 -8 -4 -1\ng ceiling\nusemtl white\nf 5 6 7 8\n\
v 4 0 0\nv 8 0 0\nv 8 3 0\nv 4 3 0\nv 4 0 2.5\nv 8 0 2.5\nv 8 3 2.5\nv 4 3 2.5\nf 9 10 11 12\nf 10 11 15 14\n\
f 9/1/1 10/2/1 14/3/1 13/4/1\nf 11 12 16 15\nl 1 7\nl 2 3\n";

const TUM: &str = "# timestamp tx ty tz qx qy qz qw\n1700000000.000000000 1.0 2.0 1.6 0 0 0 1\n\
1700000000.033333333 1.01 2.0 1.6 0 0 0.0087 0.99996\n1700000000.066666667 1.02 2.0 1.6 0 0 0.0175 0.99985\n";

fn small_rig() -> String {
    "name = \"fuzz\"\n[[sensors]]\nid = 0\nresolution = [8, 6]\nmodel = \"pinhole\"\n\
     intrinsics = [8.0, 8.0, 3.5, 2.5]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n\
     [[sensors]]\nid = 1\nresolution = [8, 6]\nmodel = \"pinhole\"\nintrinsics = [8.0, 8.0, 3.5, 2.5]\n\
     rotation_wxyz = [0.0, 0.0, 1.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\ncrop = [0, 0, 8, 6]\n"
        .to_string()
}

/// The sphere lens models not in a shipped rig: an EUCM and an omni (unified + radtan) sensor.
fn sphere_rig() -> String {
    "name = \"spheres\"\n[[sensors]]\nid = 0\nresolution = [8, 6]\nmodel = \"eucm\"\n\
     intrinsics = [4.0, 4.0, 3.5, 2.5]\ndistortion = [0.6, 1.1]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\n\
     translation_m = [0.0, 0.0, 0.0]\n[[sensors]]\nid = 1\nresolution = [8, 6]\nmodel = \"omni\"\n\
     intrinsics = [8.0, 8.0, 3.5, 2.5]\ndistortion = [0.9, -0.2, 0.05, 0.001, 0.0]\n\
     rotation_wxyz = [0.0, 0.0, 1.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n"
        .to_string()
}

#[test]
fn rig_files() {
    let seeds = [
        "firmware_config/ladybug2.toml",
        "tools/rigs/dual_fisheye.toml",
        "tools/rigs/dual_fisheye_one_frame.toml",
        "tools/rigs/dual_double_sphere.toml",
        "tools/rigs/equirect.toml",
        "tools/rigs/pinhole1.toml",
        "tools/rigs/pinhole4.toml",
    ]
    .iter()
    .map(|f| file(f))
    .chain([small_rig().into_bytes(), sphere_rig().into_bytes()])
    .collect();
    fuzz("rig TOML", 1, seeds, |b| {
        Rig::from_toml_str(&text(b), "rig.toml")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn tracker_configs() {
    fuzz("tracker TOML", 2, vec![file("firmware_config/tracker.toml")], |b| {
        TrackerConfig::from_toml_str(&text(b), "tracker.toml")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn obj_models() {
    fuzz("OBJ", 3, vec![ROOMS_OBJ.as_bytes().to_vec()], |b| {
        Model::from_obj_str(&text(b), "model.obj")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn geojson_floor_plans() {
    fuzz("GeoJSON", 4, vec![file("tools/plans/example_office.geojson")], |b| {
        omnitrack::desk::floorplan::extrude(&text(b), "plan.geojson")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn tum_trajectories() {
    fuzz("TUM", 5, vec![TUM.as_bytes().to_vec()], |b| {
        omnitrack::trajectory::parse_tum(&text(b), "walk.tum")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn line_correspondences() {
    let rig = common::shipped_rig();
    let csv = "sensor,u1,v1,u2,v2,x1,y1,z1,x2,y2,z2\n0,10.5,20.25,200,30,1,2,0,1,2,2.5\n\
               3,100,400,120,40,5,-1,0,5,-1,2.5\n5,190,250,10,260,0,0,2.5,4,0,2.5\n";
    fuzz("lines CSV", 6, vec![csv.as_bytes().to_vec()], move |b| {
        omnitrack::lines::parse_lines(&text(b), "lines.csv", &rig)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

#[test]
fn kalibr_and_opencv_calibrations() {
    let kalibr = "cam0:\n  camera_model: pinhole\n  intrinsics: [458.654, 457.296, 367.215, 248.375]\n  \
                  distortion_model: radtan\n  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n  \
                  resolution: [752, 480]\ncam1:\n  T_cn_cnm1:\n  - [0.9999972564779, 0.0023120725, 0.0003413143, -0.1100738323]\n  \
                  - [-0.0023117532, 0.9999971445, -0.0009321052, 0.0003991804]\n  \
                  - [-0.0003434688, 0.0009313133, 0.9999995073, -0.0008536743]\n  - [0.0, 0.0, 0.0, 1.0]\n  \
                  camera_model: pinhole\n  intrinsics: [285.0, 285.0, 191.5, 255.5]\n  distortion_model: equidistant\n  \
                  distortion_coeffs: [-0.015, 0.002, -0.0003, 0.0]\n  resolution: [384, 512]\n";
    let kalibr_seeds = vec![
        kalibr.as_bytes().to_vec(),
        file("tests/desk/calibrations/kalibr-euroc-ds-camchain.yaml"),
        file("tests/desk/calibrations/kalibr-omni-eucm-camchain.yaml"),
    ];
    fuzz("Kalibr YAML", 7, kalibr_seeds, |b| {
        omnitrack::desk::kalibr::rig_from_kalibr(&text(b), "camchain.yaml", "k", "cam0")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    let opencv = "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   \
                  data: [ 285., 0., 191.5, 0., 285., 255.5, 0., 0., 1. ]\nD: !!opencv-matrix\n   rows: 4\n   cols: 1\n   \
                  dt: d\n   data: [ -0.015, 0.002, -0.0003, 0. ]\nimage_width: 384\nimage_height: 512\n";
    let opencv_seeds = vec![
        opencv.as_bytes().to_vec(),
        file("tests/desk/calibrations/opencv-tutorial-default.yml"),
        file("tests/desk/calibrations/ros-camera-info-plumb-bob.yaml"),
        file("tests/desk/calibrations/ros-camera-info-equidistant.yaml"),
    ];
    fuzz("OpenCV YAML", 8, opencv_seeds, |b| {
        let model = (b.len() % 3 == 0).then_some(OpenCvModel::Fisheye);
        rig_from_opencv(&text(b), "cam.yaml", "o", model, None)
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
    let basalt_seeds = vec![
        file("tests/desk/calibrations/basalt-euroc-ds-calibration.json"),
        file("tests/desk/calibrations/basalt-tumvi-kb4-eucm-ucm-calibration.json"),
    ];
    fuzz("Basalt JSON", 9, basalt_seeds, |b| {
        omnitrack::desk::basalt::rig_from_basalt(&text(b), "calibration.json", "b", "cam0")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

/// FNV-1a 64, the `.vis` checksum (crates/tracker/src/visibility/mod.rs), so that half of the
/// mutated tables pass it and reach the decoder and the consistency checks behind it.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[test]
fn visibility_tables() {
    let model = Model::from_obj_str(ROOMS_OBJ, "rooms.obj").unwrap();
    let opts = BuildOptions {
        cube_map_resolution: 32,
        ..BuildOptions::default()
    };
    let bytes = build_table(&model, "rooms.obj", &opts).to_bytes();
    assert!(VisibilityTable::from_bytes(&bytes, "rooms.vis").is_ok());
    let parity = AtomicU64::new(0);
    fuzz("visibility table", 9, vec![bytes], move |b| {
        let mut b = b.to_vec();
        if parity.fetch_add(1, Ordering::Relaxed) % 2 == 0 && b.len() > 8 {
            let n = b.len() - 8;
            let sum = fnv1a(&b[..n]);
            b[n..].copy_from_slice(&sum.to_le_bytes());
        }
        VisibilityTable::from_bytes(&b, "rooms.vis")
            .map(|_| ())
            .map_err(|e| e.to_string())
    });
}

/// A recording of the two-sensor rig (the second sensor cropped) with `frames.csv` as given
/// and frame images of `png`, replayed to its end.
struct Recording {
    dir: tempfile::TempDir,
}

impl Recording {
    fn new() -> Recording {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("rig.toml"), small_rig()).unwrap();
        std::fs::create_dir_all(dir.path().join("sensor0")).unwrap();
        Recording { dir }
    }

    fn replay(&self) -> Result<(), String> {
        let mut source = ReplaySource::open(self.dir.path(), Pacing::AsFastAsPossible).map_err(|e| e.to_string())?;
        let mut frame = FrameSet::for_rig(source.rig());
        let mut frames = 0;
        while source.next_frame(&mut frame).map_err(|e| e.to_string())? {
            frames += 1;
            assert!(frames <= 64, "more frames than rows");
        }
        // Replay goes on past a bad image or row, counting it: those count as refused here
        // (each was warned in one line), so that the tally says what the inputs did.
        let stats = source.stats();
        let skipped: u64 = stats.sensors.iter().map(|s| s.total_faults() - s.dropped).sum();
        match skipped + stats.bad_rows.total() {
            0 => Ok(()),
            n => Err(format!("{n} images or rows skipped")),
        }
    }
}

#[test]
fn recording_indexes() {
    let rec = Recording::new();
    let png = png_rgb(8, 6);
    std::fs::write(rec.dir.path().join("sensor0/000000.png"), &png).unwrap();
    // A valid index, and one with rows that must be refused, for the splices to draw on.
    let valid = "frame,sensor,timestamp_ns,path\n0,0,1700000000000000000,sensor0/000000.png\n\
                 0,1,1700000000000700000,sensor0/000000.png\n1,0,1700000000033000000,sensor0/000000.png\n";
    let hostile = format!("{valid}2,1,1700000000066000000,../outside.png\n3,0,18446744073709551615,/etc/hostname\n");
    let path = rec.dir.path().join("frames.csv");
    fuzz(
        "frames.csv",
        10,
        vec![valid.as_bytes().to_vec(), hostile.into_bytes()],
        move |b| {
            std::fs::write(&path, b).unwrap();
            rec.replay()
        },
    );
}

fn png_rgb(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |u, v| image::Rgb([(u * 30) as u8, (v * 40) as u8, 7]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

#[test]
fn png_images() {
    let rec = Recording::new();
    let csv = "frame,sensor,timestamp_ns,path\n0,0,1,sensor0/000000.png\n0,1,1,sensor0/000000.png\n";
    std::fs::write(rec.dir.path().join("frames.csv"), csv).unwrap();
    let grey = {
        let img = image::GrayImage::from_fn(8, 6, |u, v| image::Luma([(u * v) as u8]));
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    };
    let path = rec.dir.path().join("sensor0/000000.png");
    // A larger frame too: the cropped sensor takes its window of it.
    fuzz("PNG", 11, vec![png_rgb(8, 6), grey, png_rgb(16, 6)], move |b| {
        std::fs::write(&path, b).unwrap();
        rec.replay()
    });
}

/// What the fuzzer found first (200,000 inputs): a quoted YAML string holding a newline, echoed
/// in the Kalibr error, made it two lines.
#[test]
fn a_kalibr_string_with_a_newline_is_echoed_on_one_line() {
    let yaml = "cam0:\n  camera_model: pinhole\n  intrinsics: [1, 1, 0, 0]\n  distortion_model: \"equi\\ndistant\"\n  \
                distortion_coeffs: [0, 0, 0, 0]\n  resolution: [4, 3]\n";
    let e = omnitrack::desk::kalibr::rig_from_kalibr(yaml, "c.yaml", "k", "cam0")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "c.yaml: cam0: camera model 'pinhole' with distortion 'equi\\ndistant' is not supported (omnitrack reads \
         pinhole with radtan, equidistant or none; omni with radtan or none; ds and eucm with none)"
    );
}
