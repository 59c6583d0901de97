//! What a frame's images cost outside the pipeline, for the bench's CPU tables: our edge
//! detector on one thread with its phases, OpenCV's FastLineDetector and LSD on the same images
//! (run by `tools/bench_edges.py` in a venv the bench makes), and each recording format's CPU to
//! write and read back and its bytes.
//!
//! In: a recording and its frames. Out: [`Ours`], [`Peer`]s and [`FormatCost`]s.

use omnitrack::capture::{FrameSource, Pacing, ReplaySource};
use omnitrack::config::TrackerConfig;
use omnitrack::edges::{thread_cpu_time, EdgeDetector, EdgeParams};
use omnitrack::frame::FrameSet;
use omnitrack::runtime::record::ImageFormat;
use omnitrack::Rig;
use std::path::Path;
use std::time::Duration;

/// Our detector's CPU per six-sensor frame on one thread, and its phases (CPU, per frame),
/// over `frames` (each detected `passes` times after a warm-up pass).
pub(crate) struct Ours {
    pub(crate) cpu_ms: Vec<f64>,
    /// Pixel pass, chains (link, fit, hue), merge, select: mean ms per frame.
    pub(crate) phases: [f64; 4],
    pub(crate) edges_per_frame: f64,
}

pub(crate) fn time_ours(
    rig: &Rig,
    cfg: &TrackerConfig,
    frames: &[FrameSet],
    passes: usize,
    params: EdgeParams,
) -> Ours {
    let params = EdgeParams { threads: 1, ..params };
    let mut det = EdgeDetector::with_params(rig, &cfg.edges, params);
    for f in frames {
        det.detect(f);
    }
    let mut cpu_ms = Vec::new();
    let mut phases = [0.0; 4];
    let mut edges = 0;
    for _ in 0..passes {
        for f in frames {
            edges += det.detect(f).len();
            cpu_ms.push(det.last_cpu().as_secs_f64() * 1e3);
            for k in 0..rig.sensors.len() {
                let st = det.sensor_stats(k);
                for (p, ns) in phases
                    .iter_mut()
                    .zip([st.pixel_ns, st.chain_ns, st.merge_ns, st.select_ns])
                {
                    *p += ns as f64 / 1e6;
                }
            }
        }
    }
    let n = cpu_ms.len().max(1) as f64;
    cpu_ms.sort_by(f64::total_cmp);
    Ours {
        cpu_ms,
        phases: phases.map(|p| p / n),
        edges_per_frame: edges as f64 / n,
    }
}

/// One OpenCV detector's figures from `tools/bench_edges.py`.
pub(crate) struct Peer {
    pub(crate) name: String,
    pub(crate) cpu_p50_ms: f64,
    pub(crate) cpu_p99_ms: f64,
    pub(crate) wall_p50_ms: f64,
    pub(crate) lines_per_frame: f64,
}

/// OpenCV's LSD and FastLineDetector on the PNGs of `frames` frames of `rec`, one thread.
pub(crate) fn run_peers(rec: &Path, frames: usize) -> Result<Vec<Peer>, String> {
    let dir = std::env::temp_dir().join(format!("omnitrack-pipeline-peers-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let index = std::fs::read_to_string(rec.join("frames.csv")).map_err(|e| e.to_string())?;
    for line in index.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (Some(Ok(frame)), Some(sensor), Some(path)) = (f.first().map(|x| x.parse::<usize>()), f.get(1), f.get(3))
        else {
            continue;
        };
        if frame < frames {
            std::os::unix::fs::symlink(rec.join(path), dir.join(format!("frame{frame:03}_s{sensor}.png")))
                .map_err(|e| e.to_string())?;
        }
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/bench_edges.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .arg(&dir)
        .args(["--repeats", "3", "--threads", "1"])
        .output()
        .map_err(|e| e.to_string())?;
    let _ = std::fs::remove_dir_all(&dir);
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).trim().to_string());
    }
    let mut peers = Vec::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        peers.push(Peer {
            name: match v["detector"].as_str() {
                Some("lsd") => "OpenCV LSD".into(),
                Some("fld") => "OpenCV FastLineDetector".into(),
                other => format!("OpenCV {other:?}"),
            },
            cpu_p50_ms: f("cpu_p50_ms"),
            cpu_p99_ms: f("cpu_p99_ms"),
            wall_p50_ms: f("p50_ms"),
            lines_per_frame: f("lines_per_frame"),
        });
    }
    Ok(peers)
}

/// One image format of a recording: CPU to encode and to read back (file read and decode,
/// `ReplaySource::next_frame`), and bytes, per six-sensor frame.
pub(crate) struct FormatCost {
    pub(crate) format: ImageFormat,
    pub(crate) encode_ms: f64,
    pub(crate) decode_ms: f64,
    pub(crate) bytes: f64,
}

/// `frames` written in each format to a scratch recording (encoding timed on this thread's CPU
/// clock), then replayed three times from the page cache (the first pass untimed).
pub(crate) fn format_costs(rec: &Path, frames: &[FrameSet]) -> Vec<FormatCost> {
    let mut costs = Vec::new();
    for format in [ImageFormat::Png, ImageFormat::Qoi, ImageFormat::Ppm] {
        let dir = std::env::temp_dir().join(format!(
            "omnitrack-pipeline-formats-{}-{}",
            std::process::id(),
            format.extension()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::copy(rec.join("rig.toml"), dir.join("rig.toml")).unwrap();
        let mut csv = String::from("frame,sensor,timestamp_ns,path\n");
        let (mut encode, mut bytes, mut buf) = (Duration::ZERO, 0usize, Vec::new());
        for f in frames {
            for img in f.sensors().iter().filter(|i| i.valid) {
                let name = format!("s{}_{:06}.{}", img.sensor(), f.sequence, format.extension());
                let t = thread_cpu_time();
                format
                    .encode(img.pixels(), img.width(), img.height(), &mut buf)
                    .unwrap();
                encode += thread_cpu_time() - t;
                bytes += buf.len();
                std::fs::write(dir.join(&name), &buf).unwrap();
                csv.push_str(&format!(
                    "{},{},{},{name}\n",
                    f.sequence,
                    img.sensor(),
                    img.timestamp_ns
                ));
            }
        }
        std::fs::write(dir.join("frames.csv"), csv).unwrap();
        let mut replay = ReplaySource::open(&dir, Pacing::AsFastAsPossible).unwrap();
        let mut frame = FrameSet::for_rig(replay.rig());
        let mut decode = Duration::ZERO;
        for pass in 0..3 {
            replay.rewind();
            let t = thread_cpu_time();
            while replay.next_frame(&mut frame).unwrap() {}
            if pass > 0 {
                decode += thread_cpu_time() - t;
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
        let n = frames.len().max(1) as f64;
        costs.push(FormatCost {
            format,
            encode_ms: encode.as_secs_f64() * 1e3 / n,
            decode_ms: decode.as_secs_f64() * 1e3 / (2.0 * n),
            bytes: bytes as f64 / n,
        });
    }
    costs
}
