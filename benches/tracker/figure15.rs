//! Koch–Teller Figure 15 reproduced as a table: the tracker's sampling on the paper's setup.

use nalgebra::Point3;
use omnitrack::config::TrackerConfig;
use omnitrack::desk::scenario::{Scenario, ScenarioName};
use omnitrack::{Model, Rig};

/// Koch–Teller Figure 15: pose error against the number of correspondences, with the paper's
/// noise model (§5.1: σ = 0.5° on every edge, 25 % of the correspondences removed and σ = 2°
/// added to the rest), along a `lab` tour. Each trial keeps N random correspondences of the
/// frame and solves from the previous frame's pose as the tracker does (R_and_T, then also the
/// ξ simplex for comparison).
pub(crate) fn figure15(rig: &Rig) {
    use omnitrack::desk::observations::{observe, NoiseModel};
    use omnitrack::solver::{minimise_xi, r_and_t_refine, SimplexOptions};
    use omnitrack::visibility::build::Occluders;
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let scenario = Scenario::get(ScenarioName::Lab);
    let model = Model::from_obj_str(&scenario.model_obj().unwrap(), "lab.obj").unwrap();
    let scene = Occluders::new(&model);
    let tour = scenario.trajectory(101, 5);
    let solver = TrackerConfig::default().solver_options();
    let mut rng = rand::rngs::SmallRng::seed_from_u64(15);
    println!();
    println!("Koch–Teller Figure 15 (lab tour, 100 poses per row, paper noise model §5.1):");
    println!();
    println!("| correspondences | R_and_T position RMSE (cm) | R_and_T rotation RMSE (°) | ξ simplex position RMSE (cm) | ξ simplex rotation RMSE (°) |");
    println!("| --- | --- | --- | --- | --- |");
    for n in [5usize, 10, 20, 30, 40, 60, 80] {
        let (mut p_kh, mut r_kh, mut p_xi, mut r_xi, mut trials) = (0.0, 0.0, 0.0, 0.0, 0usize);
        for k in 1..tour.len() {
            let truth = tour[k].pose;
            let obs = observe(
                &model,
                rig,
                &truth,
                &NoiseModel::paper_clutter(),
                k as u64,
                &|a: &Point3<f64>, b: &Point3<f64>| scene.clear_line(a, b),
            );
            let mut c = obs.correspondences;
            if c.len() < n {
                continue;
            }
            c.shuffle(&mut rng);
            c.truncate(n);
            let start = tour[k - 1].pose;
            let err = |p: &omnitrack::Pose| {
                (
                    (p.translation.vector - truth.translation.vector).norm_squared(),
                    p.rotation.angle_to(&truth.rotation).to_degrees().powi(2),
                )
            };
            let Some(kh) = r_and_t_refine(&c, &start, &solver) else {
                continue;
            };
            let xi = minimise_xi(&c, &kh, &SimplexOptions::default()).0;
            let (a, b) = err(&kh);
            let (x, y) = err(&xi);
            p_kh += a;
            r_kh += b;
            p_xi += x;
            r_xi += y;
            trials += 1;
        }
        if trials == 0 {
            println!("| {n} | n/a (no frame sees {n}) | | | |");
            continue;
        }
        let t = trials as f64;
        println!(
            "| {n} | {:.1} | {:.2} | {:.1} | {:.2} |",
            (p_kh / t).sqrt() * 100.0,
            (r_kh / t).sqrt(),
            (p_xi / t).sqrt() * 100.0,
            (r_xi / t).sqrt()
        );
    }
    println!();
}
