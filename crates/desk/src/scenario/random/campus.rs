//! A campus: several random buildings side by side in one model, for building large visibility
//! tables. A seed, a count, bays and a gap in; the buildings and their OBJ text joined (vertices
//! moved to each building's lot, groups prefixed `bK_`) out.

use super::{Choices, RandomBuilding};
use std::fmt::Write as _;

/// Several random buildings side by side: a campus for building large visibility tables.
#[derive(Debug, Clone, PartialEq)]
pub struct Campus {
    pub buildings: Vec<RandomBuilding>,
    /// Floor area of all ground storeys, m².
    pub floor_area_m2: f64,
    /// The whole campus, OBJ text (each building's groups prefixed `bK_`).
    pub obj: String,
}

/// `count` random buildings of `bays` each (seeds `seed`, `seed + 1`, …), on a grid of rows
/// `gap_m` apart.
pub fn campus(seed: u64, count: usize, bays: [usize; 2], gap_m: f64) -> Campus {
    let buildings: Vec<RandomBuilding> = (0..count as u64)
        .map(|k| {
            RandomBuilding::generate(
                seed + k,
                &Choices {
                    bays: Some(bays),
                    ..Choices::default()
                },
            )
        })
        .collect();
    // Every building starts at its plan's origin; its extent is its largest vertex coordinate.
    let extent = |b: &RandomBuilding| {
        b.obj
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .fold([0.0f64; 2], |m, l| {
                let mut it = l.split_whitespace().filter_map(|x| x.parse::<f64>().ok());
                let (x, y) = (it.next().unwrap_or(0.0), it.next().unwrap_or(0.0));
                [m[0].max(x), m[1].max(y)]
            })
    };
    let per_row = (count as f64).sqrt().ceil().max(1.0) as usize;
    let pitch = buildings
        .iter()
        .map(extent)
        .fold([0.0f64; 2], |m, e| [m[0].max(e[0]), m[1].max(e[1])]);
    let mut obj = format!(
        "# A campus of {count} random buildings (omnitrack::desk::scenario::random, seeds {seed}..{}).\n",
        seed + count as u64
    );
    let mut base = 0usize;
    for (k, b) in buildings.iter().enumerate() {
        let (ox, oy) = (
            (k % per_row) as f64 * (pitch[0] + gap_m),
            (k / per_row) as f64 * (pitch[1] + gap_m),
        );
        let mut vertices = 0;
        for line in b.obj.lines() {
            if let Some(v) = line.strip_prefix("v ") {
                let c: Vec<f64> = v.split_whitespace().filter_map(|x| x.parse().ok()).collect();
                let _ = writeln!(obj, "v {} {} {}", c[0] + ox, c[1] + oy, c[2]);
                vertices += 1;
            } else if let Some(f) = line.strip_prefix("f ") {
                obj.push('f');
                for i in f.split_whitespace().filter_map(|x| x.parse::<usize>().ok()) {
                    let _ = write!(obj, " {}", i + base);
                }
                obj.push('\n');
            } else if let Some(g) = line.strip_prefix("g ") {
                let _ = writeln!(obj, "g b{k}_{g}");
            }
        }
        base += vertices;
    }
    Campus {
        floor_area_m2: buildings.iter().map(|b| b.floor_area_m2).sum(),
        buildings,
        obj,
    }
}
