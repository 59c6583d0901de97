//! Edge extraction on real photographs: runs `EdgeDetector` on every image of a directory, writes
//! each image's edges as the `omnitrack edges` CSV and prints the time per image. The line
//! quality (recall and precision against hand-marked segments) and OpenCV's detectors on the
//! same images are scored by `tools/bench_lines_real.py`, which runs this bench.
//!
//! Run: `cargo bench --bench edges_real -- --images DIR --out DIR [OPTIONS]` (needs the `desk`
//! feature, on by default). DIR holds 8-bit PNG or JPEG photographs (`*.png`, `*.jpg`, `*.jpeg`,
//! searched one level of sub-directories deep as well); for each image NAME.ext the CSV is
//! written to OUT/NAME.csv (the header and extra columns of docs/interfaces.md, "Edges CSV") and
//! every timed detection to OUT/timing.csv (`image,pass,ms`). Options:
//! - `--intrinsics fx,fy,cx,cy` (pixels, OpenCV convention): the pinhole every image is seen
//!   through; without it f = image width and the principal point at the image centre. The
//!   detector fits planes to unprojected rays, so the intrinsics matter slightly.
//! - `--passes N` (default 5): timed passes over all images, after one warm-up pass.
//! - `--max-edges N`, `--min-length-deg D`: override `[edges]` of the shipped tracker config
//!   (defaults: those of `EdgeConfig::default()`, which firmware_config/tracker.toml ships).
//! - `--threshold G`, `--merge-deg A`, `--gap-deg A`, `--min-support F`, `--gap-evidence F`,
//!   `--two-line X`: override `EdgeParams` (`gradient_threshold`, `merge_angle_rad`,
//!   `merge_gap_rad`, `merge_min_support`, `merge_gap_evidence`, `two_line_excess`), for sweeps.
//! - `--piece-nfa 0|1`, `--piece-trim 0|1`: the a-contrario test of the pieces shown, and their
//!   trimming (`EdgeParams::piece_nfa`, `piece_trim`; both on by default).
//! - `--hue-samples N`: `EdgeParams::hue_samples_per_edge`, the places along a piece whose hue
//!   strips are read.
//!
//! Besides the times it prints the mean phase times and counters per image
//! (`EdgeDetector::sensor_stats`: pixel pass, chains, merging and selection), and a digest of
//! every edge of every image bit for bit: a change meant to leave the detector's output as it
//! was must leave the digest as it was.
//!
//! Each image goes through a one-sensor pinhole rig of its size (built once per size) and
//! `EdgeDetector::detect_sensor` on the calling thread (one thread: one sensor cannot be split
//! over two), the image already decoded into the sensor buffer as a capture source leaves it;
//! decoding is not timed.

#[cfg(feature = "desk")]
mod bench {
    use omnitrack::config::EdgeConfig;
    use omnitrack::edges::{edges_csv, EdgeDetector, EdgeParams};
    use omnitrack::frame::SensorImage;
    use omnitrack::Rig;
    use std::collections::HashMap;
    use std::path::{Path, PathBuf};
    use std::time::Instant;

    const USAGE: &str = "usage: cargo bench --bench edges_real -- --images DIR --out DIR \
[--intrinsics fx,fy,cx,cy] [--passes N] [--max-edges N] [--min-length-deg D] [--threshold G] \
[--merge-deg A] [--gap-deg A] [--min-support F] [--gap-evidence F] [--two-line X] [--piece-nfa 0|1] \
[--piece-trim 0|1] [--hue-samples N]";

    fn fail(msg: &str) -> ! {
        eprintln!("edges_real bench: {msg}");
        std::process::exit(2);
    }

    use omnitrack::desk::results::percentile;

    fn is_image(p: &Path) -> bool {
        matches!(
            p.extension()
                .and_then(|e| e.to_str())
                .map(|e| e.to_ascii_lowercase())
                .as_deref(),
            Some("png" | "jpg" | "jpeg")
        )
    }

    /// Images in `dir` and in its direct sub-directories, sorted by path.
    fn find_images(dir: &Path) -> Vec<PathBuf> {
        let read = |d: &Path| -> Vec<PathBuf> {
            match std::fs::read_dir(d) {
                Ok(rd) => rd.filter_map(|e| e.ok().map(|e| e.path())).collect(),
                Err(e) => fail(&format!("{}: {e}", d.display())),
            }
        };
        let mut out = Vec::new();
        for p in read(dir) {
            if p.is_dir() {
                out.extend(read(&p).into_iter().filter(|q| q.is_file() && is_image(q)));
            } else if is_image(&p) {
                out.push(p);
            }
        }
        out.sort();
        out
    }

    /// A one-sensor pinhole rig for images of `w`×`h`.
    fn pinhole_rig(w: u32, h: u32, k: Option<[f64; 4]>) -> Rig {
        let [fx, fy, cx, cy] = k.unwrap_or([w as f64, w as f64, (w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0]);
        let text = format!(
            "name = \"photo{w}x{h}\"\n\n[[sensors]]\nid = 0\nresolution = [{w}, {h}]\nmodel = \"pinhole\"\n\
intrinsics = [{fx:?}, {fy:?}, {cx:?}, {cy:?}]\nrotation_wxyz = [1.0, 0.0, 0.0, 0.0]\ntranslation_m = [0.0, 0.0, 0.0]\n"
        );
        Rig::from_toml_str(&text, "(pinhole rig of edges_real)").unwrap_or_else(|e| fail(&e.to_string()))
    }

    pub fn main() {
        let args: Vec<String> = std::env::args().collect();
        let value = |flag: &str| -> Option<&str> {
            let k = args.iter().position(|a| a == flag)?;
            match args.get(k + 1) {
                Some(v) => Some(v.as_str()),
                None => fail(&format!("{flag} needs a value\n{USAGE}")),
            }
        };
        let number = |flag: &str| -> Option<f64> {
            value(flag).map(|v| {
                v.parse::<f64>()
                    .unwrap_or_else(|_| fail(&format!("{flag}: not a number: {v}")))
            })
        };
        let (Some(images_dir), Some(out_dir)) = (value("--images"), value("--out")) else {
            fail(USAGE);
        };
        let intrinsics = value("--intrinsics").map(|v| {
            let n: Vec<f64> = v.split(',').filter_map(|x| x.trim().parse().ok()).collect();
            match n[..] {
                [fx, fy, cx, cy] => [fx, fy, cx, cy],
                _ => fail(&format!("--intrinsics needs fx,fy,cx,cy, got {v}")),
            }
        });
        let passes = number("--passes").map_or(5, |p| p.max(1.0) as usize);
        let mut config = EdgeConfig::default();
        if let Some(n) = number("--max-edges") {
            config.max_edges_per_sensor = n as u32;
        }
        if let Some(d) = number("--min-length-deg") {
            config.min_edge_length_deg = d;
        }
        let out_dir = PathBuf::from(out_dir);
        std::fs::create_dir_all(&out_dir).unwrap_or_else(|e| fail(&format!("{}: {e}", out_dir.display())));

        let paths = find_images(Path::new(images_dir));
        if paths.is_empty() {
            fail(&format!("{images_dir}: no *.png, *.jpg or *.jpeg images"));
        }
        let mut images: Vec<(String, SensorImage)> = Vec::with_capacity(paths.len());
        for p in &paths {
            let img = match image::open(p) {
                Ok(i) => i.to_rgb8(),
                Err(e) => fail(&format!("{}: cannot read image: {e}", p.display())),
            };
            let mut si = SensorImage::new(0, img.width(), img.height());
            si.pixels_mut().copy_from_slice(img.as_raw());
            si.set_valid(0);
            let name = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            images.push((name, si));
        }
        // One rig and one detector per image size; every buffer sized once, as on the device.
        let mut params = EdgeParams {
            threads: 1,
            ..EdgeParams::default()
        };
        if let Some(g) = number("--threshold") {
            params.gradient_threshold = g as u16;
        }
        if let Some(a) = number("--merge-deg") {
            params.merge_angle_rad = a.to_radians();
        }
        if let Some(a) = number("--gap-deg") {
            params.merge_gap_rad = a.to_radians();
        }
        if let Some(x) = number("--min-support") {
            params.merge_min_support = x;
        }
        if let Some(x) = number("--gap-evidence") {
            params.merge_gap_evidence = x;
        }
        if let Some(x) = number("--two-line") {
            params.two_line_excess = x;
        }
        if let Some(x) = number("--piece-nfa") {
            params.piece_nfa = x != 0.0;
        }
        if let Some(x) = number("--piece-trim") {
            params.piece_trim = x != 0.0;
        }
        if let Some(x) = number("--hue-samples") {
            params.hue_samples_per_edge = x as usize;
        }
        let mut detectors: HashMap<(u32, u32), (EdgeDetector, Rig)> = HashMap::new();
        for (_, si) in &images {
            let size = (si.width(), si.height());
            detectors.entry(size).or_insert_with(|| {
                let rig = pinhole_rig(size.0, size.1, intrinsics);
                (EdgeDetector::with_params(&rig, &config, params), rig)
            });
        }
        // Warm-up pass; it also writes the CSVs (the detector is deterministic) and hashes every
        // edge's fields bit for bit (their `Debug` text: shortest round-trip floats), so that a
        // change meant to keep the output can be checked for exactly that.
        let mut edges_total = 0usize;
        let mut digest = std::collections::hash_map::DefaultHasher::new();
        for (name, si) in &images {
            let (det, rig) = detectors
                .get_mut(&(si.width(), si.height()))
                .expect("a detector per size");
            let edges = det.detect_sensor(si);
            edges_total += edges.len();
            std::hash::Hash::hash(&format!("{edges:?}"), &mut digest);
            let path = out_dir.join(format!("{name}.csv"));
            std::fs::write(&path, edges_csv(edges, rig)).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
        }
        let mut timing = String::from("image,pass,ms\n");
        let mut ms = Vec::with_capacity(passes * images.len());
        // Sums over the timed detections: pixel, chain, merge ns; edgels, chains, candidates,
        // candidates dropped, merged, capped.
        let mut phase = [0f64; 3];
        let mut counts = [0f64; 7];
        for pass in 0..passes {
            for (name, si) in &images {
                let (det, _) = detectors
                    .get_mut(&(si.width(), si.height()))
                    .expect("a detector per size");
                let t = Instant::now();
                let n = det.detect_sensor(si).len();
                let dt = t.elapsed().as_secs_f64() * 1e3;
                std::hint::black_box(n);
                ms.push(dt);
                let st = det.sensor_stats(0);
                phase[0] += st.pixel_ns as f64;
                phase[1] += st.chain_ns as f64;
                phase[2] += (st.merge_ns + st.select_ns) as f64;
                for (c, v) in counts.iter_mut().zip([
                    st.edgels,
                    st.chains,
                    st.candidates,
                    st.candidates_dropped,
                    st.merged,
                    st.capped,
                    st.merges_refused,
                ]) {
                    *c += v as f64;
                }
                timing.push_str(&format!("{name},{pass},{dt:.4}\n"));
            }
        }
        let path = out_dir.join("timing.csv");
        std::fs::write(&path, timing).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
        ms.sort_by(f64::total_cmp);
        let sizes: Vec<String> = detectors.keys().map(|(w, h)| format!("{w}x{h}")).collect();
        println!(
            "omnitrack EdgeDetector (edges + hue, 1 thread), {} images ({}), {passes} passes: \
p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms per image, {:.1} edges per image \
(max_edges_per_sensor {}, min_edge_length_deg {})",
            images.len(),
            sizes.join(", "),
            percentile(&ms, 0.5),
            percentile(&ms, 0.99),
            ms[ms.len() - 1],
            edges_total as f64 / images.len() as f64,
            config.max_edges_per_sensor,
            config.min_edge_length_deg
        );
        let runs = ms.len() as f64;
        println!(
            "mean per image: pixel pass {:.0} µs, chains (link, fit, hue) {:.0} µs, merge and select {:.0} µs; \
{:.0} edgels, {:.0} chains, {:.0} candidates ({:.0} dropped: buffer full), {:.0} merges \
({:.0} refused for want of the line across the gap), {:.0} capped",
            phase[0] / runs / 1e3,
            phase[1] / runs / 1e3,
            phase[2] / runs / 1e3,
            counts[0] / runs,
            counts[1] / runs,
            counts[2] / runs,
            counts[3] / runs,
            counts[4] / runs,
            counts[6] / runs,
            counts[5] / runs
        );
        println!(
            "digest of every edge of every image, bit for bit: {:016x}",
            std::hash::Hasher::finish(&digest)
        );
        println!("CSV per image and timing.csv: {}", out_dir.display());
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the edges_real benchmark needs the `desk` feature");
}
