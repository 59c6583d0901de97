//! The paper's scenarios (Koch–Teller Table 2): their buildings extrude and load, have the
//! paper's floor area, and their trajectories are physically plausible: inside the free space,
//! walking speed, limited yaw rate, the right degrees of freedom, deterministic in the seed.
#![cfg(feature = "desk")]

use omnitrack::desk::scenario::{check_path, doorways_passed, Motion, Scenario, ScenarioName};
use omnitrack::model::Model;
use omnitrack::trajectory::Trajectory;

fn euler(t: &Trajectory, k: usize) -> (f64, f64, f64) {
    t[k].pose.rotation.euler_angles()
}

fn wrap(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

fn path_length(t: &Trajectory) -> f64 {
    t.windows(2)
        .map(|w| (w[1].pose.translation.vector.xy() - w[0].pose.translation.vector.xy()).norm())
        .sum()
}

/// Everything the brief asks of a trajectory, other than the free-space check.
fn check_plausible(sc: &Scenario, t: &Trajectory, frames: usize) {
    assert_eq!(t.len(), frames);
    let period = sc.frame_period_ns();
    let dt = period as f64 * 1e-9;
    for (k, s) in t.iter().enumerate() {
        assert_eq!(s.timestamp_ns, k as u64 * period, "{}: frame {k} timestamp", sc.name);
        let (roll, pitch, _) = euler(t, k);
        let z = s.pose.translation.z;
        match sc.motion {
            Motion::Rolling3Dof { height_m } => {
                assert!(
                    roll.abs() < 1e-9 && pitch.abs() < 1e-9,
                    "{}: frame {k} not yaw-only",
                    sc.name
                );
                assert!((z - height_m).abs() < 1e-12, "{}: frame {k} height {z}", sc.name);
            }
            Motion::HandHeld6Dof => {
                assert!(roll.abs() < 10f64.to_radians(), "{}: frame {k} roll {roll}", sc.name);
                assert!(pitch.abs() < 10f64.to_radians(), "{}: frame {k} pitch {pitch}", sc.name);
                assert!((1.3..=1.7).contains(&z), "{}: frame {k} height {z}", sc.name);
            }
        }
    }
    let (mut vmin, mut vmax, mut wmax) = (f64::INFINITY, 0.0f64, 0.0f64);
    for k in 1..t.len() {
        let v = (t[k].pose.translation.vector - t[k - 1].pose.translation.vector).norm() / dt;
        vmin = vmin.min(v);
        vmax = vmax.max(v);
        let w = wrap(euler(t, k).2 - euler(t, k - 1).2).abs() / dt;
        wmax = wmax.max(w);
        assert!((0.5..=1.8).contains(&v), "{}: speed {v:.3} m/s at frame {k}", sc.name);
        assert!(
            w < 90f64.to_radians(),
            "{}: yaw rate {:.1}°/s at frame {k}",
            sc.name,
            w.to_degrees()
        );
    }
    eprintln!(
        "{}: {frames} frames, {:.1} m, speed {vmin:.2}–{vmax:.2} m/s, max yaw rate {:.1}°/s",
        sc.name,
        path_length(t),
        wmax.to_degrees()
    );
}

fn scenario_checks(name: ScenarioName) {
    let sc = Scenario::get(name);
    assert_eq!(sc.name, name);
    let obj = sc.model_obj().expect("extrudes");
    let model = Model::from_obj_str(&obj, &format!("{name}.obj")).expect("loads");
    let area = sc.floor_area_m2().unwrap();
    eprintln!(
        "{name}: floor area {area:.0} m² (paper {:.0}), {} faces, {} segments (paper: see Table 2)",
        sc.paper_area_m2,
        model.faces.len(),
        model.segments.len()
    );
    assert!(
        (area - sc.paper_area_m2).abs() <= 0.15 * sc.paper_area_m2,
        "{name}: area {area} vs paper {}",
        sc.paper_area_m2
    );
    assert!(!model.segments.is_empty());

    let plan = sc.plan().unwrap();
    let t = sc.trajectory(300, 7);
    check_path(&plan, &t).unwrap_or_else(|e| panic!("{name}: {e}"));
    check_plausible(&sc, &t, 300);
    assert_eq!(t, sc.trajectory(300, 7), "{name}: same seed, same trajectory");
    assert_ne!(t, sc.trajectory(300, 8), "{name}: another seed, another trajectory");

    // Other seeds pass the free-space check too.
    for seed in [1, 2, 3, 99] {
        let t = sc.trajectory(300, seed);
        check_path(&plan, &t).unwrap_or_else(|e| panic!("{name} seed {seed}: {e}"));
        check_plausible(&sc, &t, 300);
    }
}

#[test]
fn lab() {
    scenario_checks(ScenarioName::Lab);
}

#[test]
fn handheld() {
    scenario_checks(ScenarioName::Handheld);
}

#[test]
fn corridor() {
    scenario_checks(ScenarioName::Corridor);
}

#[test]
fn corridor_full_length_walks_hundreds_of_metres_through_many_doorways() {
    let sc = Scenario::get(ScenarioName::Corridor);
    let plan = sc.plan().unwrap();
    let t = sc.trajectory(sc.paper_frames, 11);
    check_path(&plan, &t).unwrap();
    check_plausible(&sc, &t, sc.paper_frames);
    let len = path_length(&t);
    let doors = doorways_passed(&plan, &t);
    eprintln!("corridor: {} frames, {len:.0} m, {doors} doorways", sc.paper_frames);
    assert!(len >= 300.0, "{len}");
    assert!(doors >= 10, "{doors}");
    // It uses both buildings (x < 160 and x > 160).
    assert!(t.iter().any(|s| s.pose.translation.x < 150.0) && t.iter().any(|s| s.pose.translation.x > 170.0));
}

#[test]
fn paper_length_lab_and_handheld_pass() {
    for name in [ScenarioName::Lab, ScenarioName::Handheld] {
        let sc = Scenario::get(name);
        let t = sc.trajectory(sc.paper_frames, 5);
        check_path(&sc.plan().unwrap(), &t).unwrap_or_else(|e| panic!("{name}: {e}"));
        check_plausible(&sc, &t, sc.paper_frames);
    }
}

#[test]
fn names_parse_and_display() {
    for n in ScenarioName::ALL {
        assert_eq!(n.to_string().parse::<ScenarioName>().unwrap(), n);
    }
    assert_eq!("corridor".parse::<ScenarioName>().unwrap(), ScenarioName::Corridor);
    let e = "office".parse::<ScenarioName>().unwrap_err().to_string();
    assert!(
        e.contains("office") && e.contains("lab") && e.contains("corridor") && e.contains("handheld"),
        "{e}"
    );
}

#[test]
fn any_length_and_zero_frames() {
    let sc = Scenario::get(ScenarioName::Lab);
    assert!(sc.trajectory(0, 1).is_empty());
    assert_eq!(sc.trajectory(1, 1).len(), 1);
    assert_eq!(sc.trajectory(17, 1).len(), 17);
}

#[test]
fn check_path_rejects_walking_through_a_wall() {
    let sc = Scenario::get(ScenarioName::Corridor);
    let plan = sc.plan().unwrap();
    let mut t = sc.trajectory(2, 3);
    // Two points in adjacent offices of building A, straight through the partition at x = 8.
    t[0].pose.translation.vector = nalgebra::Vector3::new(6.0, 5.0, 1.2);
    t[1].pose.translation.vector = nalgebra::Vector3::new(10.0, 5.0, 1.2);
    let e = check_path(&plan, &t).unwrap_err().to_string();
    assert!(e.contains("wall"), "{e}");
    // Outside the building.
    t[1].pose.translation.vector = nalgebra::Vector3::new(6.0, -3.0, 1.2);
    assert!(check_path(&plan, &t).is_err());
    // Through a door centre is fine.
    t[0].pose.translation.vector = nalgebra::Vector3::new(9.3, 8.5, 1.2);
    t[1].pose.translation.vector = nalgebra::Vector3::new(9.3, 10.5, 1.2);
    check_path(&plan, &t).unwrap();
}

/// Many seeds, every tenth at the paper's length: `cargo test --test scenario -- --ignored` (about a minute).
#[test]
#[ignore]
fn stress_seeds() {
    for name in ScenarioName::ALL {
        let sc = Scenario::get(name);
        let plan = sc.plan().unwrap();
        for seed in 0..300u64 {
            let frames = if seed % 10 == 0 { sc.paper_frames } else { 300 };
            let t = sc.trajectory(frames, seed);
            check_path(&plan, &t).unwrap_or_else(|e| panic!("{name} seed {seed}: {e}"));
            check_plausible(&sc, &t, frames);
        }
    }
}

#[test]
fn room_graphs() {
    use omnitrack::desk::scenario::path::Space;
    let lab = Scenario::get(ScenarioName::Lab).plan().unwrap();
    // The lab's doors lead outside: no room-to-room links.
    assert!(Space::new(&lab).room_links().is_empty());
    let plan = Scenario::get(ScenarioName::Corridor).plan().unwrap();
    let links = Space::new(&plan).room_links();
    // 144 office doors and the fire door; every office hangs off one of the two corridors.
    assert_eq!(links.len(), 145);
    let mut degree = vec![0; plan.rooms.len()];
    for &(_, a, b) in &links {
        degree[a] += 1;
        degree[b] += 1;
    }
    let mut d: Vec<usize> = degree.clone();
    d.sort();
    assert_eq!(&d[..144], &[1; 144][..]);
    assert_eq!(&d[144..], &[65, 81]);
}
