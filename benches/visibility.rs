//! Visibility table (Koch–Teller §4.3) on the `corridor` scenario (~7,000 m², ~7,000 segments):
//! build time on 2 threads, table size, and recall / precision of VIS(T) at the nearest node
//! against brute-force ray casting from 1,000 random camera positions in free space.
//!
//! Brute force (`omnitrack::desk::vis_truth`): a segment is visible from a position if any sample point along it (samples at
//! most 0.5° apart as seen from the position, at most 2,000 per segment) within the table's
//! range is unoccluded (a ray from the position stops short of it by 1 mm without hitting a
//! face). Its visible extent is the angle subtended by runs of consecutive unoccluded samples.
//! Recall is reported over all visible segments and over those whose visible extent exceeds
//! 2° (the target: ≥ 95 %); precision is |VIS ∩ visible| / |VIS|.
//!
//! Positions are uniform over the model's bounding box at 1.0–2.0 m above the floor, kept
//! when they are free space (the node rule with 0.2 m clearance). Build time is wall time on a
//! 2-thread rayon pool, with the process CPU time beside it (other load on the machine inflates
//! the wall time, not the CPU time).
//!
//! `VIS_CAMPUS_M2=25000,100000` measures scale instead: campuses of random buildings
//! (`desk::scenario::random::campus`, 16 × 12 bays each) of about those floor areas, built with
//! the shipped settings on 2 threads; it prints build time, CPU time, peak resident memory of the
//! process (it only grows, so rows are in ascending area) and table size (`VIS_PROGRESS=1` shows
//! the build's progress bar).
//!
//! Run: `cargo bench --bench visibility` (needs the `desk` feature). Environment:
//! `VIS_RES=64,256` cube-map resolutions; `VIS_MERGE=0,1` (0 none, 1 neighbour merging, 2
//! cell-corner renders); `VIS_POSITIONS=1000`; `VIS_CLEARANCE` node clearance in metres.
//! Diagnostics: `VIS_AT_NODES=1` snaps the positions to their nodes (rendering error alone);
//! `VIS_DEBUG=k` compares the raster ids of position k's node with ray casts and lists its
//! misses and false positives; `VIS_DEBUG=999` lists the > 2° misses of the first 200
//! positions. Prints figures; asserts nothing.
//!
//! Measured 2026-11-27 (2 cores, 1,000 positions, range 40 m; recall of segments > 2° /
//! precision): res 64: 9.2 s, 2.4 MB, 97.3 % / 87.7 %; with neighbour merging 10.0 s, 2.9 MB,
//! 99.6 % / 72.9 %; res 128: 15.9 s, 97.5 % / 90.7 %; res 256: 31.5 s, 2.6 MB, 97.5 % / 92.6 %.
//! Campus: 97,794 m² in 493 s, 708 MB peak (docs/visibility.md, "Campus scale").

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::Point3;
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::desk::vis_truth::visible_segments;
    use omnitrack::visibility::build::{build_raw, BuildOptions, Merge, Occluders};
    use omnitrack::visibility::VisibilityTable;
    use omnitrack::Model;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use rayon::prelude::*;
    use std::time::Instant;

    fn list<T: std::str::FromStr>(var: &str, default: &str) -> Vec<T> {
        std::env::var(var)
            .unwrap_or_else(|_| default.to_string())
            .split(',')
            .filter_map(|s| s.trim().parse().ok())
            .collect()
    }

    /// CPU time of this process so far (user + system, from /proc; 0 where unavailable): the
    /// build's CPU time over 2 is its wall time on 2 otherwise idle cores.
    fn cpu_seconds() -> f64 {
        let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
            return 0.0;
        };
        let Some(rest) = stat.rsplit(')').next() else {
            return 0.0;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        let ticks = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
        // Fields after the command: state is 0, utime 11, stime 12 (clock ticks, 100 Hz).
        (ticks(11) + ticks(12)) / 100.0
    }

    /// Peak resident memory of this process so far, bytes (0 where /proc is missing).
    fn peak_rss_bytes() -> u64 {
        std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix("VmHWM:"))
                    .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            })
            .map_or(0, |kb| kb * 1024)
    }

    /// `VIS_CAMPUS_M2=A,B,…`: campuses of random buildings of about these floor areas; the
    /// shipped table settings on 2 threads; build time, memory and size against area.
    fn campus_scale(areas: &[f64]) {
        use omnitrack::desk::scenario::random::campus;
        // 16 × 12 bays of 3–6.5 m: about 3,500 m² of rooms per building on average.
        const BAYS: [usize; 2] = [16, 12];
        const PER_BUILDING_M2: f64 = 3500.0;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("rayon pool");
        println!("| floor area (m²) | buildings | segments | valid nodes | build (s, 2 threads) | CPU (s) | peak RSS (MB) | table (MB) |");
        println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
        for &area in areas {
            let count = (area / PER_BUILDING_M2).ceil().max(1.0) as usize;
            let c = campus(1, count, BAYS, 15.0);
            let model = Model::from_obj_str(&c.obj, "campus.obj").expect("the campus loads");
            let mut opts = BuildOptions::from_config(&omnitrack::config::TrackerConfig::default().visibility);
            opts.progress = std::env::var_os("VIS_PROGRESS").is_some();
            let t = Instant::now();
            let cpu0 = cpu_seconds();
            let (raw, stats) = pool.install(|| build_raw(&model, "campus.obj", &opts));
            let table = VisibilityTable::from_raw(raw);
            let bytes = table.to_bytes().len();
            println!(
                "| {:.0} | {count} | {} | {} | {:.1} | {:.1} | {:.0} | {:.1} |",
                c.floor_area_m2,
                model.segments.len(),
                stats.nodes,
                t.elapsed().as_secs_f64(),
                cpu_seconds() - cpu0,
                peak_rss_bytes() as f64 / 1e6,
                bytes as f64 / 1e6
            );
        }
    }

    pub fn main() {
        let campus: Vec<f64> = list("VIS_CAMPUS_M2", "");
        if !campus.is_empty() {
            campus_scale(&campus);
            return;
        }
        let scenario = Scenario::get(ScenarioName::Corridor);
        let obj = scenario.model_obj().expect("corridor plan extrudes");
        let model = Model::from_obj_str(&obj, "corridor.obj").expect("corridor model loads");
        let area = scenario.floor_area_m2().unwrap_or(f64::NAN);
        println!(
            "corridor: {:.0} m² floor, {} vertices, {} faces, {} segments",
            area,
            model.vertices.len(),
            model.faces.len(),
            model.segments.len()
        );
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("rayon pool");
        let resolutions: Vec<u32> = list("VIS_RES", "64,256");
        let merges: Vec<u32> = list("VIS_MERGE", "0,1");
        let positions: usize = list("VIS_POSITIONS", "1000").first().copied().unwrap_or(1000);
        let mut base = BuildOptions::default();
        if let Some(c) = list::<f64>("VIS_CLEARANCE", "").first() {
            base.clearance_m = *c;
        }
        let range = base.max_range_m;

        // Random camera positions in free space, heights 1.0–2.0 m above the floor.
        let scene = Occluders::new(&model);
        let (lo, hi) = model.bounds().expect("non-empty model");
        let mut rng = SmallRng::seed_from_u64(6);
        let mut eyes = Vec::with_capacity(positions);
        while eyes.len() < positions {
            let p = Point3::new(
                rng.random_range(lo.x..hi.x),
                rng.random_range(lo.y..hi.y),
                lo.z + rng.random_range(1.0..2.0),
            );
            if scene.is_free(&p, 0.2) {
                eyes.push(p);
            }
        }
        if std::env::var("VIS_AT_NODES").is_ok() {
            // Diagnostic: positions snapped to the node grid (isolates rendering from sampling).
            let probe = VisibilityTable::from_raw(
                build_raw(
                    &model,
                    "corridor.obj",
                    &BuildOptions {
                        cube_map_resolution: 8,
                        merge: Merge::None,
                        ..base.clone()
                    },
                )
                .0,
            );
            for e in eyes.iter_mut() {
                *e = probe.query(e).expect("valid nodes").node_position;
            }
        }
        let t = Instant::now();
        let truth: Vec<Vec<(bool, f64)>> = pool.install(|| {
            eyes.par_iter()
                .map(|e| visible_segments(&scene, &model, e, range))
                .collect()
        });
        let visible_mean =
            truth.iter().map(|v| v.iter().filter(|x| x.0).count()).sum::<usize>() as f64 / positions as f64;
        println!(
            "brute force: {positions} positions, {:.1} segments visible per position (range {range} m), {:.1} s",
            visible_mean,
            t.elapsed().as_secs_f64()
        );

        if let Ok(k) = std::env::var("VIS_DEBUG") {
            // Diagnostic: the misses of one position.
            let k: usize = k.parse().unwrap_or(0);
            if k == 999 {
                let opts = BuildOptions {
                    cube_map_resolution: resolutions[0],
                    merge: Merge::None,
                    ..base.clone()
                };
                let table = VisibilityTable::from_raw(build_raw(&model, "corridor.obj", &opts).0);
                for (e, tr) in eyes.iter().zip(&truth).take(200) {
                    let set = table.query(e).expect("valid nodes");
                    for (s, &(v, ext)) in tr.iter().enumerate() {
                        if v && ext > 2f64.to_radians() && set.segments.binary_search(&(s as u32)).is_err() {
                            let g = &model.segments[s];
                            let mid = nalgebra::center(&g.a, &g.b);
                            println!(
                                "miss eye {:.2?} node {:.1?} seg {:.2?}->{:.2?} len {:.1} dist {:.1} ext {:.1}",
                                e,
                                set.node_position,
                                g.a,
                                g.b,
                                g.length(),
                                (mid - e).norm(),
                                ext.to_degrees()
                            );
                        }
                    }
                }
            }
            let opts = BuildOptions {
                cube_map_resolution: resolutions[0],
                merge: Merge::None,
                ..base.clone()
            };
            let table = VisibilityTable::from_raw(build_raw(&model, "corridor.obj", &opts).0);
            let set = table.query(&eyes[k]).expect("valid nodes");
            let mut cube =
                omnitrack::visibility::build::CubeMap::new(opts.cube_map_resolution as usize, model.faces.len());
            let _ = cube.visibility(&scene, &set.node_position, &opts);
            let (mut agree, mut total) = (0, 0);
            let r = opts.cube_map_resolution as usize;
            for f in 0..6 {
                for y in 0..r {
                    for x in 0..r {
                        let d = cube.pixel_direction(f, x, y).normalize();
                        let hit = scene.cast(&set.node_position, &d, 1e6).map_or(u32::MAX, |h| h.0);
                        total += 1;
                        if hit == cube.id_at(f, x, y) {
                            agree += 1;
                        } else if total % 50 == 0 {
                            println!("pixel {f} {x} {y}: raster {} ray {}", cube.id_at(f, x, y), hit);
                        }
                    }
                }
            }
            println!("raster vs ray ids: {agree} of {total} agree");
            println!("eye {:?} node {:?} faces {:?}", eyes[k], set.node_position, set.faces);
            for &s in set.segments {
                if !truth[k][s as usize].0 {
                    let g = &model.segments[s as usize];
                    println!("false {s}: {:?} -> {:?} faces {:?}", g.a, g.b, g.faces);
                }
            }
            for (s, &(v, ext)) in truth[k].iter().enumerate() {
                if v && ext > 2f64.to_radians() && set.segments.binary_search(&(s as u32)).is_err() {
                    let g = &model.segments[s];
                    println!(
                        "miss {s}: {:?} -> {:?} faces {:?} extent {:.1}°",
                        g.a,
                        g.b,
                        g.faces,
                        ext.to_degrees()
                    );
                }
            }
        }
        for &res in &resolutions {
            for &merge in &merges {
                let opts = BuildOptions {
                    cube_map_resolution: res,
                    merge: [Merge::None, Merge::Neighbours, Merge::CellCorners][merge as usize % 3],
                    ..base.clone()
                };
                let t = Instant::now();
                let cpu0 = cpu_seconds();
                let (raw, stats) = pool.install(|| build_raw(&model, "corridor.obj", &opts));
                let build_cpu = cpu_seconds() - cpu0;
                let table = VisibilityTable::from_raw(raw);
                let bytes = table.to_bytes();
                let build_s = t.elapsed().as_secs_f64();
                let table = VisibilityTable::from_bytes(&bytes, "corridor.vis").expect("round trip");

                let t = Instant::now();
                let mut n = 0usize;
                for e in &eyes {
                    n += table.query(e).map_or(0, |s| s.segments.len());
                }
                let query_ns = t.elapsed().as_secs_f64() * 1e9 / positions as f64;
                std::hint::black_box(n);

                let (mut tp, mut vis, mut truth_all, mut tp_big, mut truth_big) = (0usize, 0usize, 0, 0, 0);
                let big = 2f64.to_radians();
                for (e, tr) in eyes.iter().zip(&truth) {
                    let set = table.query(e).expect("valid nodes");
                    vis += set.segments.len();
                    for &s in set.segments {
                        if tr[s as usize].0 {
                            tp += 1;
                        }
                    }
                    for (s, &(v, ext)) in tr.iter().enumerate() {
                        if !v {
                            continue;
                        }
                        let hit = set.segments.binary_search(&(s as u32)).is_ok();
                        truth_all += 1;
                        if ext > big {
                            truth_big += 1;
                            tp_big += hit as usize;
                        }
                    }
                }
                let tp_all = {
                    let mut k = 0;
                    for (e, tr) in eyes.iter().zip(&truth) {
                        let set = table.query(e).expect("valid nodes");
                        k += set.segments.iter().filter(|&&s| tr[s as usize].0).count();
                    }
                    k
                };
                println!(
                    "res {res:4} merge {:?}: build {build_s:.1} s wall on 2 threads, {build_cpu:.1} s CPU (nodes {:.1} s, render {:.1} s), {} valid nodes of {} cells, \
                     {:.0} faces / {:.0} segments per node, {} distinct sets, table {:.2} MB, query {query_ns:.0} ns; \
                     recall {:.1} % (segments > 2°: {:.1} % of {}), precision {:.1} %",
                    opts.merge,
                    stats.seconds_nodes,
                    stats.seconds_render,
                    stats.nodes,
                    stats.cells,
                    stats.mean_faces,
                    stats.mean_segments,
                    table.set_count(),
                    bytes.len() as f64 / 1e6,
                    100.0 * tp_all as f64 / truth_all.max(1) as f64,
                    100.0 * tp_big as f64 / truth_big.max(1) as f64,
                    truth_big,
                    100.0 * tp as f64 / vis.max(1) as f64,
                );
            }
        }
    }
}

fn main() {
    #[cfg(feature = "desk")]
    bench::main();
    #[cfg(not(feature = "desk"))]
    eprintln!("the visibility benchmark needs the `desk` feature");
}
