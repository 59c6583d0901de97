//! The random building generator (issue 20): every building loads as a model, its plan parses,
//! walks through it keep clear of its walls, and the draws are what its description says.

#![cfg(feature = "desk")]

use omnitrack::desk::scenario::check_path;
use omnitrack::desk::scenario::random::{Choices, Outline, RandomBuilding, WallStyle};
use omnitrack::Model;

#[test]
fn twenty_buildings_load_and_walk() {
    for seed in 1..=20 {
        let b = RandomBuilding::new(seed);
        let model = Model::from_obj_str(&b.obj, &format!("{}.obj", b.name()))
            .unwrap_or_else(|e| panic!("building {seed} ({b}): {}", e.message));
        assert!(
            model.segments.len() > 20,
            "building {seed}: {} segments",
            model.segments.len()
        );
        let plan = b.plan().unwrap_or_else(|e| panic!("building {seed}: {e}"));
        let walk = b.trajectory(60, seed);
        assert_eq!(walk.len(), 60);
        check_path(&plan, &walk).unwrap_or_else(|e| panic!("building {seed} ({b}): {e}"));
    }
}

#[test]
fn same_seed_same_building_and_choices_are_kept() {
    assert_eq!(RandomBuilding::new(7), RandomBuilding::new(7));
    assert_ne!(RandomBuilding::new(7).obj, RandomBuilding::new(8).obj);
    let b = RandomBuilding::generate(
        3,
        &Choices {
            outline: Some(Outline::L),
            walls: Some(WallStyle::Thin),
            triangulated: Some(false),
            ..Choices::default()
        },
    );
    assert_eq!(
        (b.outline, b.walls, b.triangulated),
        (Outline::L, WallStyle::Thin, false)
    );
    // About half the faces wound the other way.
    let share = b.flipped as f64 / b.faces as f64;
    assert!((0.3..0.7).contains(&share), "{} of {} flipped", b.flipped, b.faces);
    // Single-face walls: every face of a wall group lies in its wall's vertical plane (a box
    // would add faces across it: ends, tops, the other side's offset plane).
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut in_wall = false;
    let mut wall_faces = 0;
    for line in b.obj.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => vertices.push([0, 1, 2].map(|_| it.next().unwrap().parse().unwrap())),
            Some("g") => in_wall = it.next().unwrap().starts_with("wall_"),
            Some("f") if in_wall => {
                let pts: Vec<[f64; 3]> = it.map(|i| vertices[i.parse::<usize>().unwrap() - 1]).collect();
                let same = |k: usize| pts.iter().all(|p| (p[k] - pts[0][k]).abs() < 1e-9);
                assert!(same(0) || same(1), "a wall face off its wall's plane: {pts:?}");
                wall_faces += 1;
            }
            _ => {}
        }
    }
    assert!(wall_faces > 10, "{wall_faces} wall faces");
    Model::from_obj_str(&b.obj, "l.obj").unwrap();
}

#[test]
fn two_storeys_have_a_hall_and_a_stair() {
    let mut found = 0;
    for seed in 1..=10 {
        let b = RandomBuilding::generate(
            seed,
            &Choices {
                storeys: Some(2),
                ..Choices::default()
            },
        );
        if b.storeys == 2 {
            found += 1;
            assert!(b.obj.contains("g stair"));
            let model = Model::from_obj_str(&b.obj, "two.obj").unwrap();
            let (lo, hi) = model.bounds().unwrap();
            assert!(hi.z - lo.z > 2.0 * b.storey_height_m, "{}", hi.z - lo.z);
            let plan = b.plan().unwrap();
            check_path(&plan, &b.trajectory(100, seed)).unwrap_or_else(|e| panic!("building {seed}: {e}"));
        }
    }
    assert!(found >= 5, "only {found} of 10 two-storey draws had room for a stair");
}

#[test]
fn pins_parse_and_unknown_ones_say_what_is_allowed() {
    let c = Choices::parse("L, thin ,cart,2-storeys,quads").unwrap();
    assert_eq!(c.outline, Some(Outline::L));
    assert_eq!(c.walls, Some(WallStyle::Thin));
    assert_eq!((c.cart, c.storeys, c.triangulated), (Some(true), Some(2), Some(false)));
    let b = RandomBuilding::generate(4, &Choices::parse("courtyard,hand-held").unwrap());
    assert_eq!(b.outline, Outline::Courtyard);
    assert_eq!(b.motion, omnitrack::desk::scenario::Motion::HandHeld6Dof);
    let err = Choices::parse("L,hexagon").unwrap_err().to_string();
    assert!(
        err.contains("\"hexagon\"") && err.contains("courtyard") && !err.contains('\n'),
        "{err}"
    );
}
