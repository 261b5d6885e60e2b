//! A quasi-Newton minimiser (BFGS on the inverse Hessian, backtracking Armijo line search)
//! with central finite-difference gradients evaluated side by side, and the finite-difference
//! Hessian of the observed information.
//!
//! # Why not argmin
//! argmin 0.11 (the current release) with `argmin-math` 0.5 supports nalgebra up to 0.34, not
//! the workspace's 0.35, so its nalgebra backend cannot take our vectors; its `Vec` backend
//! would do, but `argmin-math`'s `vec` feature turns on `rand` 0.9 with its default features
//! and argmin itself always depends on `rand_xoshiro` 0.7, so either would put a second rand
//! core (0.9 beside the workspace's 0.10) and an OS entropy source into the lock, which the
//! workspace avoids (faer is used without default features for the same reason); and its
//! cost functions return `anyhow::Error`, which library crates here do not use. The problem
//! is small (a handful of parameters, each evaluation a filter run), so a textbook BFGS
//! (Nocedal and Wright 2006, Algorithm 6.1 with the scaling 6.20 and a backtracking line
//! search, Algorithm 3.1, whose full step is tried once more at the minimum of the quadratic
//! interpolant, section 3.5, when that lies well beyond it) is short and tested here on
//! functions with known minima.

use rayon::prelude::*;

/// The objective: `None` where it cannot be evaluated (an infeasible candidate), which the
/// line search treats as `+inf`.
pub(crate) trait Objective: Sync {
    fn value(&self, x: &[f64]) -> Option<f64>;
}

impl<F: Fn(&[f64]) -> Option<f64> + Sync> Objective for F {
    fn value(&self, x: &[f64]) -> Option<f64> {
        self(x)
    }
}

/// Why the minimiser stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The largest gradient component fell below the tolerance: converged.
    Gradient,
    /// The iteration limit was reached first.
    MaxIterations,
    /// No step along the search direction decreased the objective (the gradient is then at
    /// the level of its finite-difference error, or the objective is not smooth there).
    LineSearch,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Settings {
    pub gradient_tolerance: f64,
    pub max_iterations: usize,
}

#[derive(Clone, Debug)]
pub(crate) struct Outcome {
    pub x: Vec<f64>,
    pub f: f64,
    pub gradient: Vec<f64>,
    pub iterations: usize,
    pub evaluations: usize,
    pub stop: StopReason,
}

impl Outcome {
    pub fn gradient_norm(&self) -> f64 {
        self.gradient.iter().fold(0.0, |m, g| m.max(g.abs()))
    }
}

/// The finite-difference step of coordinate `x_i` for a central first difference: the cube
/// root of the machine epsilon balances truncation (`h^2`) and rounding (`eps / h`) errors.
fn gradient_step(xi: f64) -> f64 {
    6e-6 * xi.abs().max(1.0)
}

/// The central-difference gradient at `x` (value `fx`), components evaluated in parallel; a
/// one-sided difference where one side is infeasible. `None` if neither side is, or if a
/// difference leaves f64 (values of opposite signs near its limits).
pub(crate) fn gradient(obj: &dyn Objective, x: &[f64], fx: f64) -> Option<Vec<f64>> {
    let g: Vec<f64> = (0..x.len())
        .into_par_iter()
        .map(|i| {
            let h = gradient_step(x[i]);
            let at = |d: f64| {
                let mut y = x.to_vec();
                y[i] += d;
                obj.value(&y)
            };
            match (at(h), at(-h)) {
                (Some(up), Some(down)) => Some((up - down) / (2.0 * h)),
                (Some(up), None) => Some((up - fx) / h),
                (None, Some(down)) => Some((fx - down) / h),
                (None, None) => None,
            }
        })
        .collect::<Option<Vec<f64>>>()?;
    g.iter().all(|v| v.is_finite()).then_some(g)
}

/// The central-difference Hessian at `x` with step `h` on every coordinate, the evaluations
/// run in parallel: `(f(x+h e_i+h e_j) - f(x+h e_i-h e_j) - f(x-h e_i+h e_j) + f(x-h e_i-h e_j))
/// / 4h^2` off the diagonal and `(f(x+2h e_i) - 2 f(x) + f(x-2h e_i)) / 4h^2` on it (the same
/// step pattern). `None` if any evaluation fails or an entry leaves f64.
pub(crate) fn hessian(obj: &dyn Objective, x: &[f64], fx: f64, h: f64) -> Option<Vec<Vec<f64>>> {
    let p = x.len();
    let pairs: Vec<(usize, usize)> = (0..p).flat_map(|i| (0..=i).map(move |j| (i, j))).collect();
    let entries: Option<Vec<f64>> = pairs
        .par_iter()
        .map(|&(i, j)| {
            let at = |di: f64, dj: f64| {
                let mut y = x.to_vec();
                y[i] += di;
                y[j] += dj;
                obj.value(&y)
            };
            if i == j {
                Some((at(h, h)? - 2.0 * fx + at(-h, -h)?) / (4.0 * h * h))
            } else {
                Some((at(h, h)? - at(h, -h)? - at(-h, h)? + at(-h, -h)?) / (4.0 * h * h))
            }
        })
        .collect();
    let entries = entries?;
    if !entries.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mut out = vec![vec![0.0; p]; p];
    for (&(i, j), v) in pairs.iter().zip(entries) {
        out[i][j] = v;
        out[j][i] = v;
    }
    Some(out)
}

/// The model minimiser along the direction, in full steps, beyond which a full step is
/// extended to it.
const EXTRAPOLATE: f64 = 1.5;

/// A decrease of the objective below this fraction of its magnitude is rounding.
const STALL: f64 = 1e-15;
/// Consecutive iterations with such decreases that stop the minimiser.
const MAX_STALLS: usize = 5;

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimises `obj` from `x0` (where it must be feasible: `None` otherwise).
pub(crate) fn minimise(obj: &dyn Objective, x0: &[f64], settings: Settings) -> Option<Outcome> {
    let p = x0.len();
    let mut x = x0.to_vec();
    let mut f = obj.value(&x)?;
    let mut evaluations = 1;
    let mut g = gradient(obj, &x, f)?;
    evaluations += 2 * p;
    // The inverse Hessian approximation, row-major; identity until the first step scales it.
    let mut hinv = vec![0.0; p * p];
    for i in 0..p {
        hinv[i * p + i] = 1.0;
    }
    let mut first = true;
    let mut iterations = 0;
    let mut stalls = 0;
    let stop = loop {
        if g.iter().fold(0.0f64, |m, v| m.max(v.abs())) <= settings.gradient_tolerance {
            break StopReason::Gradient;
        }
        if iterations >= settings.max_iterations {
            break StopReason::MaxIterations;
        }
        iterations += 1;
        let mut d: Vec<f64> = (0..p)
            .map(|i| -(0..p).map(|j| hinv[i * p + j] * g[j]).sum::<f64>())
            .collect();
        let mut slope = dot(&g, &d);
        if slope >= 0.0 {
            // Not a descent direction (the approximation lost definiteness): restart from
            // steepest descent.
            hinv.iter_mut().for_each(|v| *v = 0.0);
            for i in 0..p {
                hinv[i * p + i] = 1.0;
            }
            first = true;
            d = g.iter().map(|v| -v).collect();
            slope = dot(&g, &d);
        }
        // The first step is at most 1 in the largest coordinate (log scales: a factor e).
        let dmax = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut alpha = if first { (1.0 / dmax).min(1.0) } else { 1.0 };
        let mut accepted = None;
        for halvings in 0..50 {
            // A halved step whose predicted decrease is rounding of the objective cannot show
            // a decrease the Armijo test can trust: the search gives up there rather than
            // halving on, an evaluation each time (the second start of `cargo xtask bench
            // tune` spent most of its evaluations so, at the gradient's noise level).
            if halvings > 0 && alpha * slope.abs() <= STALL * f.abs() {
                break;
            }
            let trial: Vec<f64> = x.iter().zip(&d).map(|(xi, di)| xi + alpha * di).collect();
            // A step too small to move `x` cannot decrease the objective; accepting it (the
            // Armijo test can pass at equality) would repeat the iteration without end.
            if trial == x {
                break;
            }
            evaluations += 1;
            if let Some(ft) = obj.value(&trial)
                && ft <= f + 1e-4 * alpha * slope
            {
                accepted = Some((trial, ft));
                break;
            }
            alpha *= 0.5;
        }
        let Some((mut xn, mut fnew)) = accepted else {
            break StopReason::LineSearch;
        };
        // A quadratic through `f`, the slope and the full step's value with its minimum
        // beyond `EXTRAPOLATE` steps says the approximation overstates the curvature along
        // `d`: one trial there (at most 4 steps) crosses a long valley in fewer iterations,
        // each a gradient (the third start of `cargo xtask bench tune` otherwise crawls).
        if !first && alpha == 1.0 {
            let curvature = 2.0 * (fnew - f - slope);
            if curvature > 0.0 && -slope / curvature > EXTRAPOLATE {
                let a = (-slope / curvature).min(4.0);
                let trial: Vec<f64> = x.iter().zip(&d).map(|(xi, di)| xi + a * di).collect();
                evaluations += 1;
                if let Some(ft) = obj.value(&trial)
                    && ft < fnew
                {
                    (xn, fnew) = (trial, ft);
                }
            }
        }
        // Steps that lower the objective by no more than its rounding: the gradient is at the
        // level of its finite-difference error; without this a start can wander there until
        // the iteration limit, each iteration a full gradient.
        if f - fnew <= STALL * f.abs() {
            stalls += 1;
            if stalls >= MAX_STALLS {
                x = xn;
                f = fnew;
                break StopReason::LineSearch;
            }
        } else {
            stalls = 0;
        }
        let Some(gn) = gradient(obj, &xn, fnew) else {
            break StopReason::LineSearch;
        };
        evaluations += 2 * p;
        let s: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        // The BFGS update keeps the approximation positive definite only with s^T y > 0;
        // a step without enough curvature information keeps the old approximation.
        if sy > 1e-12 * dot(&s, &s).sqrt() * dot(&y, &y).sqrt() {
            if first {
                let scale = sy / dot(&y, &y);
                hinv.iter_mut().for_each(|v| *v *= scale);
                first = false;
            }
            let rho = 1.0 / sy;
            let hy: Vec<f64> = (0..p)
                .map(|i| (0..p).map(|j| hinv[i * p + j] * y[j]).sum())
                .collect();
            let yhy = dot(&y, &hy);
            for i in 0..p {
                for j in 0..p {
                    hinv[i * p + j] += -rho * (hy[i] * s[j] + s[i] * hy[j])
                        + (rho * rho * yhy + rho) * s[i] * s[j];
                }
            }
        }
        x = xn;
        f = fnew;
        g = gn;
    };
    Some(Outcome {
        x,
        f,
        gradient: g,
        iterations,
        evaluations,
        stop,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SETTINGS: Settings = Settings {
        gradient_tolerance: 1e-8,
        max_iterations: 500,
    };

    #[test]
    fn rosenbrock_minimum_is_found() {
        let f = |x: &[f64]| Some(100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2));
        let out = minimise(&f, &[-1.2, 1.0], SETTINGS).unwrap();
        assert_eq!(out.stop, StopReason::Gradient, "{out:?}");
        assert!(
            (out.x[0] - 1.0).abs() < 1e-6 && (out.x[1] - 1.0).abs() < 1e-6,
            "{out:?}"
        );
    }

    #[test]
    fn quadratic_hessian_is_exact_and_walls_are_respected() {
        // f = (x - 1)^T A (x - 1) / 2 with A = [[3, 1], [1, 2]]; infeasible for x0 < -5.
        let f = |x: &[f64]| {
            (x[0] >= -5.0).then(|| {
                let (a, b) = (x[0] - 1.0, x[1] - 1.0);
                0.5 * (3.0 * a * a + 2.0 * a * b + 2.0 * b * b)
            })
        };
        let out = minimise(&f, &[-4.9, 7.0], SETTINGS).unwrap();
        assert!((out.x[0] - 1.0).abs() < 1e-7 && (out.x[1] - 1.0).abs() < 1e-7);
        let h = hessian(&f, &out.x, out.f, 1e-3).unwrap();
        assert!((h[0][0] - 3.0).abs() < 1e-6 && (h[0][1] - 1.0).abs() < 1e-6);
        assert!((h[1][1] - 2.0).abs() < 1e-6);
        assert!(minimise(&f, &[-6.0, 0.0], SETTINGS).is_none());
    }

    #[test]
    fn iteration_limit_is_reported() {
        let f = |x: &[f64]| Some(100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2));
        let out = minimise(
            &f,
            &[-1.2, 1.0],
            Settings {
                max_iterations: 3,
                ..SETTINGS
            },
        )
        .unwrap();
        assert_eq!(out.stop, StopReason::MaxIterations);
        assert_eq!(out.iterations, 3);
    }
}
