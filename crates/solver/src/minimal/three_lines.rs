//! Three lines, three planes: every rotation R with n_i · R d_i = 0 (Kumar–Hanson eq. 8, the
//! rotation stage of R_then_T, solved exactly for the minimal case of three lines).
//!
//! In: three correspondences (edge plane normal n_i in the rig frame ↔ model segment of world
//! direction d_i). Out: up to 12 rotation matrices R, world → rig (the rotation of
//! `T_rig_world`), each polished to rounding.
//!
//! Med_R_and_T (§4) draws 3-line subsets and needs every pose each allows; this is where those
//! rotations come from when there is no guess. Nothing here allocates.

use nalgebra::{Complex, Matrix3, Rotation3, Unit, Vector3};
use omnitrack_core::geometry::Correspondence;

/// Every rotation that puts three model lines into their observed planes, n_i · R d_i = 0 (R_then_T's
/// rotation stage, eq. 8, solved exactly for three lines), written into `out`; returns how many.
///
/// Iterating from Horn's starts (§3.2) is chaotic for three lines: we measured that 12
/// tetrahedral starts miss the true rotation of 4 % of exact subsets, and even 60 icosahedral
/// starts miss some. Solved in closed form instead: the first constraint puts R d₁ on the great
/// circle ⊥ n₁, so R = Rot(n₁, θ) A₀ Rot(d₁, φ) with A₀ any rotation taking d₁ onto that circle.
/// For fixed θ the other two constraints are linear in (cos φ, sin φ); asking that these be a
/// unit vector gives one trigonometric polynomial of degree 4 in θ, i.e. a polynomial of degree
/// 8 in t = tan(θ/2), whose roots `polynomial_roots` finds. A complex pair
/// with a small imaginary part is what noise makes of two nearby real roots, so its real part
/// is kept too (the least-squares rotation there); every rotation is then polished by Newton's
/// method on the three equations.
pub fn three_line_rotations(sub: &[Correspondence; 3], out: &mut [Matrix3<f64>; 12]) -> usize {
    let [a, b, c] = sub;
    let n = [
        a.edge.normal.into_inner(),
        b.edge.normal.into_inner(),
        c.edge.normal.into_inner(),
    ];
    let dir = |l: &Correspondence| (l.segment[1] - l.segment[0]).try_normalize(1e-12);
    let (Some(d1), Some(d2), Some(d3)) = (dir(a), dir(b), dir(c)) else {
        return 0;
    };
    let d = [d1, d2, d3];
    // A₀: d₁ onto e₁ ⊥ n₁, as the product of two right-handed frames.
    let perpendicular = |v: &Vector3<f64>| {
        let helper = if v.x.abs() < 0.6 { Vector3::x() } else { Vector3::y() };
        v.cross(&helper).normalize()
    };
    let e1 = perpendicular(&n[0]);
    let p = perpendicular(&d1);
    let frame_e = Matrix3::from_columns(&[e1, n[0], e1.cross(&n[0])]);
    let frame_d = Matrix3::from_columns(&[d1, p, d1.cross(&p)]);
    let a0 = frame_e * frame_d.transpose();
    // Constraint i (i = 2, 3) is m_i(θ) · w_i(φ) = 0 with m_i = Rot(n₁, −θ) n_i and
    // w_i = A₀ Rot(d₁, φ) d_i, each affine in (cos, sin) of its angle.
    let mut forms = [[[0.0; 3]; 3]; 2]; // [constraint][α β γ][1, cos θ, sin θ]
    for (k, i) in [1usize, 2].into_iter().enumerate() {
        let along = n[0].dot(&n[i]);
        let m = [n[0] * along, n[i] - n[0] * along, n[i].cross(&n[0])];
        let dd = d1.dot(&d[i]);
        let w_const = a0 * (d1 * dd);
        let w_cos = a0 * (d[i] - d1 * dd);
        let w_sin = a0 * d1.cross(&d[i]);
        for (slot, w) in [w_cos, w_sin, w_const].iter().enumerate() {
            for (j, mj) in m.iter().enumerate() {
                forms[k][slot][j] = mj.dot(w);
            }
        }
    }
    let mut count = 0;
    let mut push = |r: Matrix3<f64>, count: &mut usize| {
        if r.iter().all(|v| v.is_finite())
            && *count < out.len()
            && out[..*count].iter().all(|k| (r - k).norm_squared() > 2e-6)
        {
            out[*count] = r;
            *count += 1;
        }
    };
    // θ is measured from an offset δ; a second δ is used if the first puts a root at t = ∞.
    for offset in [0.0f64, 0.61] {
        let (co, so) = (offset.cos(), offset.sin());
        // A form l₀ + l₁ cos θ + l₂ sin θ, θ = θ' + δ, as a quadratic in t = tan(θ'/2) over 1 + t².
        let quadratic = |l: &[f64; 3]| {
            let (l1, l2) = (l[1] * co + l[2] * so, -l[1] * so + l[2] * co);
            [l[0] + l1, 2.0 * l2, l[0] - l1]
        };
        let [al2, be2, ga2] = forms[0].map(|l| quadratic(&l));
        let [al3, be3, ga3] = forms[1].map(|l| quadratic(&l));
        let cos_num = sub_poly(&mul2(&ga3, &be2), &mul2(&ga2, &be3));
        let sin_num = sub_poly(&mul2(&al3, &ga2), &mul2(&al2, &ga3));
        let det = sub_poly(&mul2(&al2, &be3), &mul2(&al3, &be2));
        let mut g = [0.0; 9];
        for (k, v) in g.iter_mut().enumerate() {
            *v = square_coeff(&cos_num, k) + square_coeff(&sin_num, k) - square_coeff(&det, k);
        }
        let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if !scale.is_finite() || scale <= 0.0 {
            return 0;
        }
        if g[8].abs() < 1e-9 * scale && offset == 0.0 {
            continue;
        }
        for root in polynomial_roots(&g).iter() {
            if !root.re.is_finite() || !root.im.is_finite() || root.im.abs() > 1e-2 * (1.0 + root.re.abs()) {
                continue;
            }
            let theta = 2.0 * root.re.atan() + offset;
            let (ct, st) = (theta.cos(), theta.sin());
            // The two remaining constraints at this θ: rows (α, β, γ) of α cos φ + β sin φ + γ = 0.
            let rows = forms.map(|f| Vector3::from(f.map(|l| l[0] + l[1] * ct + l[2] * st)));
            let rotation = |cphi: f64, sphi: f64| {
                // Off a real root (a complex pair's real part) (cos φ, sin φ) is not quite unit.
                let norm = cphi.hypot(sphi);
                let (cphi, sphi) = (cphi / norm, sphi / norm);
                let r = Rotation3::from_axis_angle(&Unit::new_unchecked(n[0]), theta).into_inner()
                    * a0
                    * rodrigues(&d1, cphi, sphi);
                polish(&r, &n, &d)
            };
            let v = rows[0].cross(&rows[1]);
            // At a root, v = k (cos φ, sin φ, 1): its first two components are as large as the
            // third. When they vanish the rows are (nearly) parallel, the roots of the polynomial
            // are double and known to ~1e-8 only, so the test is relative to that.
            if v.x.hypot(v.y) > 1e-6 * rows[0].norm() * rows[1].norm() {
                if v.z.abs() > 1e-12 * v.norm() {
                    push(rotation(v.x / v.z, v.y / v.z), &mut count);
                }
            } else {
                // Dependent rows (e.g. mutually perpendicular lines, where γ vanishes): the one
                // line α cos φ + β sin φ = −γ meets the unit circle in up to two points.
                let row = if rows[0].norm() >= rows[1].norm() {
                    rows[0]
                } else {
                    rows[1]
                };
                let radius = row.x.hypot(row.y);
                if radius > 1e-12 && row.z.abs() <= radius * (1.0 + 1e-9) {
                    let psi = row.y.atan2(row.x);
                    let spread = (-row.z / radius).clamp(-1.0, 1.0).acos();
                    for phi in [psi + spread, psi - spread] {
                        push(rotation(phi.cos(), phi.sin()), &mut count);
                    }
                }
            }
        }
        break;
    }
    count
}

/// The 8 complex roots of g₀ + g₁ t + … + g₈ t⁸ (g₈ ≠ 0) by the Aberth–Ehrlich iteration: all
/// roots at once, cubically convergent, about 1 µs. (It replaced the companion matrix's
/// eigenvalues, which cost a third of Med_R_and_T's time.)
fn polynomial_roots(g: &[f64; 9]) -> [Complex<f64>; 8] {
    let monic: [f64; 9] = std::array::from_fn(|k| g[k] / g[8]);
    let eval = |z: Complex<f64>| {
        let mut p = Complex::new(1.0, 0.0);
        let mut dp = Complex::new(0.0, 0.0);
        for k in (0..8).rev() {
            dp = dp * z + p;
            p = p * z + monic[k];
        }
        (p, dp)
    };
    // Start on a circle of the roots' geometric mean radius, off the real axis.
    let radius = monic[0].abs().powf(1.0 / 8.0).clamp(1e-3, 1e3);
    let mut z: [Complex<f64>; 8] =
        std::array::from_fn(|k| Complex::from_polar(radius, 0.4 + k as f64 * std::f64::consts::TAU / 8.0));
    let mut done = [false; 8];
    for _ in 0..60 {
        let mut all_done = true;
        for i in 0..8 {
            if done[i] {
                continue;
            }
            let (p, dp) = eval(z[i]);
            let ratio = p / dp;
            let mut repulsion = Complex::new(0.0, 0.0);
            for j in (0..8).filter(|&j| j != i) {
                repulsion += (z[i] - z[j]).inv();
            }
            let step = ratio / (Complex::new(1.0, 0.0) - ratio * repulsion);
            if !(step.re.is_finite() && step.im.is_finite()) {
                done[i] = true;
                continue;
            }
            z[i] -= step;
            // Converged to rounding: further steps only wander.
            done[i] = step.norm_sqr() <= 1e-26 * (1.0 + z[i].norm_sqr());
            all_done &= done[i];
        }
        if all_done {
            break;
        }
    }
    z
}

/// Rot(axis, φ) from cos φ and sin φ.
fn rodrigues(axis: &Vector3<f64>, c: f64, s: f64) -> Matrix3<f64> {
    let k = axis.cross_matrix();
    Matrix3::identity() + k * s + k * k * (1.0 - c)
}

/// Newton's method on n_i · R d_i = 0 (three equations, three unknowns), a few steps: closed-form
/// roots are accurate to about 1e-8, and this takes them to rounding.
fn polish(r: &Matrix3<f64>, n: &[Vector3<f64>; 3], d: &[Vector3<f64>; 3]) -> Matrix3<f64> {
    let mut r = *r;
    for _ in 0..3 {
        let mut rows = [Vector3::zeros(); 3];
        let mut res = [0.0; 3];
        for i in 0..3 {
            let rd = r * d[i];
            res[i] = n[i].dot(&rd);
            rows[i] = rd.cross(&n[i]);
        }
        let adj = [
            rows[1].cross(&rows[2]),
            rows[2].cross(&rows[0]),
            rows[0].cross(&rows[1]),
        ];
        let det = rows[0].dot(&adj[0]);
        let size = rows[0].norm() * rows[1].norm() * rows[2].norm();
        if det.is_nan() || det.abs() <= 1e-9 * size {
            break;
        }
        let step = -(adj[0] * res[0] + adj[1] * res[1] + adj[2] * res[2]) / det;
        // A polish, not a search: a complex pair's real part is no root, and a step longer
        // than this would leave the place the polynomial pointed to.
        if step.norm().is_nan() || step.norm() >= 1e-2 {
            break;
        }
        r = Rotation3::new(step).into_inner() * r;
        if step.norm() < 1e-15 {
            break;
        }
    }
    r
}

/// The product of two quadratics (ascending coefficients).
fn mul2(a: &[f64; 3], b: &[f64; 3]) -> [f64; 5] {
    let mut p = [0.0; 5];
    for i in 0..3 {
        for j in 0..3 {
            p[i + j] += a[i] * b[j];
        }
    }
    p
}

fn sub_poly(a: &[f64; 5], b: &[f64; 5]) -> [f64; 5] {
    std::array::from_fn(|k| a[k] - b[k])
}

/// The coefficient of t^k in p(t)² for a quartic p.
fn square_coeff(p: &[f64; 5], k: usize) -> f64 {
    (0..5).filter(|&i| k >= i && k - i < 5).map(|i| p[i] * p[k - i]).sum()
}
