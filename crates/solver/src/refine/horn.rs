//! Horn's uniform samples of the rotation space (Kumar–Hanson §3.2, after Horn 1988): the
//! rotation groups of the regular polyhedra, as unit quaternions.
//!
//! In: how many samples are wanted (12, 24 or 60). Out: a `'static` slice of unit quaternions,
//! one per rotation (the sign of a quaternion is fixed so that its first non-zero component is
//! positive), used as starting rotations when a solver has no pose guess.
//!
//! The components take only the values 0, 1, b = 1/2 and c = 1/√2 (eq. 22), plus, for the
//! icosahedral group, φ/2 and 1/(2φ) with φ the golden ratio. The sets are built from those exact
//! values, not by numerically composing generators, so every element is exact to rounding.

use nalgebra::{Quaternion, UnitQuaternion};
use std::sync::OnceLock;

/// The 12 rotations of the tetrahedron: the identity, the three half-turns about the coordinate
/// axes, and the eight third-turns about the cube diagonals, ½(1, ±1, ±1, ±1) up to sign.
pub fn tetrahedral() -> &'static [UnitQuaternion<f64>] {
    static SET: OnceLock<Vec<UnitQuaternion<f64>>> = OnceLock::new();
    SET.get_or_init(|| {
        let mut v = unit_axes();
        v.extend(halves());
        v
    })
}

/// The 24 rotations of the octahedron (and cube): the tetrahedral group plus the twelve
/// quarter-turns and edge half-turns (1/√2)(±1, ±1, 0, 0) over all placements, up to sign.
pub fn octahedral() -> &'static [UnitQuaternion<f64>] {
    static SET: OnceLock<Vec<UnitQuaternion<f64>>> = OnceLock::new();
    SET.get_or_init(|| {
        let mut v = tetrahedral().to_vec();
        let c = std::f64::consts::FRAC_1_SQRT_2;
        for a in 0..4 {
            for b in a + 1..4 {
                for sb in [1.0, -1.0] {
                    // The first non-zero component is the positive one (sign convention).
                    let mut q = [0.0; 4];
                    q[a] = c;
                    q[b] = sb * c;
                    v.push(quat(q));
                }
            }
        }
        v
    })
}

/// The 60 rotations of the icosahedron (and dodecahedron): the tetrahedral group plus the 48
/// elements ½(0, ±1, ±1/φ, ±φ) under the even permutations of the four components, up to sign.
pub fn icosahedral() -> &'static [UnitQuaternion<f64>] {
    static SET: OnceLock<Vec<UnitQuaternion<f64>>> = OnceLock::new();
    SET.get_or_init(|| {
        let mut v = tetrahedral().to_vec();
        let phi = (1.0 + 5f64.sqrt()) / 2.0;
        let base = [0.0, 0.5, 0.5 / phi, 0.5 * phi];
        for perm in EVEN_PERMUTATIONS {
            // Signs of the three non-zero entries; a quaternion and its negative are one rotation,
            // so keep the four sign patterns whose first non-zero component is positive.
            for signs in 0..8u32 {
                let mut q = [0.0; 4];
                let mut k = 0;
                for (slot, &from) in perm.iter().enumerate() {
                    let value = base[from];
                    if value != 0.0 {
                        q[slot] = if signs >> k & 1 == 1 { -value } else { value };
                        k += 1;
                    }
                }
                let first = q.iter().copied().find(|x| *x != 0.0).unwrap_or(1.0);
                if first > 0.0 {
                    v.push(quat(q));
                }
            }
        }
        v
    })
}

/// The sample set for `count` starting rotations: 12, 24 or 60 (any other count takes the
/// smallest group with at least that many elements, and 60 at most).
pub fn rotation_samples(count: u32) -> &'static [UnitQuaternion<f64>] {
    match count {
        0..=12 => tetrahedral(),
        13..=24 => octahedral(),
        _ => icosahedral(),
    }
}

/// The twelve even permutations of four things: `perm[slot]` is the index of the base component
/// placed at `slot`.
const EVEN_PERMUTATIONS: [[usize; 4]; 12] = [
    [0, 1, 2, 3],
    [0, 2, 3, 1],
    [0, 3, 1, 2],
    [1, 0, 3, 2],
    [1, 2, 0, 3],
    [1, 3, 2, 0],
    [2, 0, 1, 3],
    [2, 1, 3, 0],
    [2, 3, 0, 1],
    [3, 0, 2, 1],
    [3, 1, 0, 2],
    [3, 2, 1, 0],
];

/// `[w, x, y, z]` → unit quaternion (the inputs are unit by construction).
fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_unchecked(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// 1, i, j, k.
fn unit_axes() -> Vec<UnitQuaternion<f64>> {
    (0..4)
        .map(|a| {
            let mut q = [0.0; 4];
            q[a] = 1.0;
            quat(q)
        })
        .collect()
}

/// ½(1, ±1, ±1, ±1).
fn halves() -> Vec<UnitQuaternion<f64>> {
    (0..8u32)
        .map(|signs| {
            let s = |k: u32| if signs >> k & 1 == 1 { -0.5 } else { 0.5 };
            quat([0.5, s(0), s(1), s(2)])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same_rotation(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> bool {
        a.coords.dot(&b.coords).abs() > 1.0 - 1e-12
    }

    fn check_group(set: &[UnitQuaternion<f64>], size: usize) {
        assert_eq!(set.len(), size);
        for q in set {
            assert!((q.coords.norm() - 1.0).abs() < 1e-15);
        }
        for (i, a) in set.iter().enumerate() {
            for b in &set[i + 1..] {
                assert!(!same_rotation(a, b), "{a:?} repeats");
            }
        }
        for a in set {
            for b in set {
                let ab = a * b;
                assert!(set.iter().any(|q| same_rotation(q, &ab)), "not closed: {ab:?}");
            }
        }
    }

    #[test]
    fn groups_are_closed_distinct_and_the_right_size() {
        check_group(tetrahedral(), 12);
        check_group(octahedral(), 24);
        check_group(icosahedral(), 60);
        assert_eq!(rotation_samples(16).len(), 24);
    }
}
