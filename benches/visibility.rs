//! Visibility table (Koch–Teller §4.3) on the `corridor` scenario (~7,000 m², ~7,000 segments):
//! build time on 2 threads, table size, and recall / precision of VIS(T) at the nearest node
//! against brute-force ray casting from 1,000 random camera positions in free space.
//!
//! Brute force: a segment is visible from a position if any sample point along it (samples at
//! most 0.5° apart as seen from the position, at most 2,000 per segment) within the table's
//! range is unoccluded (a ray from the position stops short of it by 1 mm without hitting a
//! face). Its visible extent is the angle subtended by runs of consecutive unoccluded samples.
//! Recall is reported over all visible segments and over those whose visible extent exceeds
//! 2° (the target: ≥ 95 %); precision is |VIS ∩ visible| / |VIS|.
//!
//! Run: `cargo bench --bench visibility` (needs the `desk` feature). Environment:
//! `VIS_RES=64,128` cube-map resolutions, `VIS_MERGE=0,1` without / with neighbour merging,
//! `VIS_POSITIONS=1000`. Prints figures; asserts nothing.

#[cfg(feature = "desk")]
mod bench {
    use nalgebra::{Point3, Vector3};
    use omnitrack::desk::scenario::{Scenario, ScenarioName};
    use omnitrack::visibility::build::{build_raw, BuildOptions, Scene};
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

    /// Per segment: (visible at all, visible extent in radians).
    fn brute_force(scene: &Scene, model: &Model, eye: &Point3<f64>, range: f64) -> Vec<(bool, f64)> {
        let step_rad = 0.5f64.to_radians();
        model
            .segments
            .iter()
            .map(|s| {
                let ab = s.b - s.a;
                let len = ab.norm();
                // Nearest distance for a quick range reject.
                let t = ((eye - s.a).dot(&ab) / (len * len)).clamp(0.0, 1.0);
                let near = (s.a + ab * t - eye).norm();
                if near > range {
                    return (false, 0.0);
                }
                let n = ((len / (near.max(0.05) * step_rad)).ceil() as usize).clamp(1, 2000);
                let mut any = false;
                let mut extent = 0.0;
                let mut prev: Option<Vector3<f64>> = None;
                for k in 0..=n {
                    let p = s.a + ab * (k as f64 / n as f64);
                    let d = p - eye;
                    let dist = d.norm();
                    let visible =
                        dist <= range && dist > 1e-6 && scene.clear_line(eye, &(eye + d * (1.0 - 1e-3 / dist)));
                    if visible {
                        any = true;
                        if let Some(q) = prev {
                            extent += q.angle(&d);
                        }
                        prev = Some(d);
                    } else {
                        prev = None;
                    }
                }
                (any, extent)
            })
            .collect()
    }

    pub fn main() {
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
        let resolutions: Vec<u32> = list("VIS_RES", "64,128");
        let merges: Vec<u32> = list("VIS_MERGE", "0,1");
        let positions: usize = list("VIS_POSITIONS", "1000").first().copied().unwrap_or(1000);
        let base = BuildOptions::default();
        let range = base.max_range_m;

        // Random camera positions in free space, heights 1.0–2.0 m above the floor.
        let scene = Scene::new(&model);
        let (lo, hi) = model.bounds().expect("non-empty model");
        let mut rng = SmallRng::seed_from_u64(6);
        let mut eyes = Vec::with_capacity(positions);
        while eyes.len() < positions {
            let p = Point3::new(
                rng.random_range(lo.x..hi.x),
                rng.random_range(lo.y..hi.y),
                lo.z + rng.random_range(1.0..2.0),
            );
            if scene.is_free(&p, base.clearance_m) {
                eyes.push(p);
            }
        }
        let t = Instant::now();
        let truth: Vec<Vec<(bool, f64)>> =
            pool.install(|| eyes.par_iter().map(|e| brute_force(&scene, &model, e, range)).collect());
        let visible_mean =
            truth.iter().map(|v| v.iter().filter(|x| x.0).count()).sum::<usize>() as f64 / positions as f64;
        println!(
            "brute force: {positions} positions, {:.1} segments visible per position (range {range} m), {:.1} s",
            visible_mean,
            t.elapsed().as_secs_f64()
        );

        for &res in &resolutions {
            for &merge in &merges {
                let opts = BuildOptions {
                    cube_map_resolution: res,
                    merge_neighbours: merge != 0,
                    ..base.clone()
                };
                let t = Instant::now();
                let (raw, stats) = pool.install(|| build_raw(&model, "corridor.obj", &opts));
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
                    "res {res:4} merge {}: build {build_s:.1} s on 2 threads (nodes {:.1} s, render {:.1} s), {} valid nodes of {} cells, \
                     {:.0} faces / {:.0} segments per node, {} distinct sets, table {:.2} MB, query {query_ns:.0} ns; \
                     recall {:.1} % (segments > 2°: {:.1} % of {}), precision {:.1} %",
                    merge != 0,
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
