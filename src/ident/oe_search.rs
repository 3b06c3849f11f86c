//! Multi-start output-error search in f64: the best of several Levenberg–Marquardt searches
//! ([`super::oe::refine`]) of one ARX structure on a record, from starts that lead to the
//! different local minima of the output-error criterion. Host side (`hter identify --method
//! oe`); no allocation, slices in, like [`super::oe`].
//!
//! # Why several starts
//!
//! V(θ) = Σ (y − q^−nk B/A u)² is not convex in θ (Ljung 1999, §10.5 "local solutions and
//! initial values"): a search ends in the local minimum its start leads to. The 2nd-order
//! criterion of the H-TER I PRBS run, for one, has a local minimum with a fast second pole
//! (≈ 0.25–0.54) besides the global one near 0.95; starts across 0.5…0.98 lead to both, and
//! the better is kept.
//!
//! # Starts, in the order they are tried
//!
//! 1. The instrumental-variable and least-squares estimates ([`super::batch`]).
//! 2. The same structure one sample of delay earlier and later, if already searched: nearly the
//!    same model, shifted.
//! 3. For na = nb = 1: the slow poles [`FIRST_ORDER_POLES`], each with the B that fits best for
//!    it. Otherwise the output-error model of the lower-order structure (4 → 2, otherwise one
//!    less), for each pole p of [`EXTRA_POLES`]: that model itself, its extra pole p cancelled by
//!    a zero at p (the search can only improve on it), and its poles and p with the B that fits
//!    best for them.
//!
//! The B that fits best for fixed poles is a linear least-squares problem: with A fixed, the
//! simulated output is linear in B, x(t) = Σ_j b_j w(t − nk − j) with w = u/A (the inner
//! problem of separable least squares; Golub & Pereyra, "The differentiation of pseudo-inverses
//! and nonlinear least squares problems whose variables separate", *SIAM J. Numer. Anal.*
//! 10(2), 1973).
//!
//! Every start gets [`SCREEN_ITERATIONS`] iterations, the [`FINALISTS`] with the lowest V are
//! refined to convergence, and the lowest V wins. Since one start is the lower-order model
//! itself, each order fits at least as well as the one below it (up to the few initial samples
//! the higher order takes from the record).
//!
//! [`OeMemo`] keeps the models already searched on one record, by (na, nb, nk): the lower-order
//! and neighbouring-delay starts come from it, and a delay scan and an order comparison on the
//! same record share their searches.
//!
//! # Glossary
//!
//! - V — the output-error criterion of [`super::oe`]; start — a θ a search begins from.
//! - screening — the short searches every start gets; finalists — the starts refined to the end.

use super::batch::{self, BatchLs};
use super::model::{Structure, MAX_NK, MAX_PARAMS};
use super::oe::{self, OeConfig};
use crate::model::MAX_NB;

/// Second poles added to the lower-order model's, for the starts of orders above 1 (see the
/// module docs for the two local minima they lead to).
pub const EXTRA_POLES: [f64; 4] = [0.5, 0.8, 0.95, 0.98];

/// Poles of the 1st-order starts: time constants of 95 s, 16 min and 83 min at Ts = 10 s,
/// spanning the carriers' and the TCLab heater's.
pub const FIRST_ORDER_POLES: [f64; 3] = [0.9, 0.99, 0.998];

/// Iterations every start gets before only the best [`FINALISTS`] are refined to the end.
pub const SCREEN_ITERATIONS: u32 = 6;

/// Starts refined to convergence after screening.
pub const FINALISTS: usize = 2;

/// Most starts of one search: IV, LS, two neighbouring delays, and two per extra pole (more
/// than the 1st order's one per pole).
const MAX_STARTS: usize = 4 + 2 * EXTRA_POLES.len();
const _: () = assert!(4 + FIRST_ORDER_POLES.len() <= MAX_STARTS);

/// Largest A order [`Structure::new`] accepts.
const MAX_NA: usize = 4;

/// One memo slot per (na, nb, nk).
const SLOTS: usize = MAX_NA * MAX_NB * MAX_NK;

/// What the memo knows of one structure.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Slot {
    /// Not searched yet.
    Unsearched,
    /// Searched; no start gave a stable model.
    NoStableStart,
    /// Searched; θ = [a, b] of the best model (zeros after na + nb).
    Found([f64; MAX_PARAMS]),
}

/// Output-error models already searched on one record, by (na, nb, nk). Use one memo per
/// record (and per prefilter): the models in it are only valid for the data they came from.
#[derive(Clone, Debug)]
pub struct OeMemo {
    slots: [Slot; SLOTS],
}

impl OeMemo {
    /// Nothing searched yet.
    pub const fn new() -> Self {
        Self { slots: [Slot::Unsearched; SLOTS] }
    }

    fn index(na: usize, nb: usize, nk: usize) -> Option<usize> {
        let inside = (1..=MAX_NA).contains(&na) && (1..=MAX_NB).contains(&nb) && (1..=MAX_NK).contains(&nk);
        inside.then(|| ((na - 1) * MAX_NB + nb - 1) * MAX_NK + nk - 1)
    }

    fn get(&self, na: usize, nb: usize, nk: usize) -> Slot {
        Self::index(na, nb, nk).and_then(|i| self.slots.get(i).copied()).unwrap_or(Slot::Unsearched)
    }

    fn set(&mut self, s: &Structure, slot: Slot) {
        if let Some(x) = Self::index(s.na, s.nb, s.nk).and_then(|i| self.slots.get_mut(i)) {
            *x = slot;
        }
    }

    /// θ = [a, b] of the model a search of `s` found, if `s` was searched and a start gave a
    /// stable model.
    pub fn found(&self, s: &Structure) -> Option<&[f64]> {
        match Self::index(s.na, s.nb, s.nk).and_then(|i| self.slots.get(i)) {
            Some(Slot::Found(th)) => th.get(..s.na + s.nb),
            _ => None,
        }
    }
}

impl Default for OeMemo {
    fn default() -> Self {
        Self::new()
    }
}

/// Why the search gave no model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SearchError {
    /// nc > 0: output error fits B/A only.
    Structure,
    /// y and u differ in length, or the scratch buffer is shorter than them.
    Input,
    /// No start gave a stable model.
    NoStableStart,
}

/// Capacity of [`Poly`]: A of the largest order with its leading 1 is the longest product.
const POLY_CAP: usize = MAX_NA + 1;

/// A polynomial in q⁻¹ of at most [`POLY_CAP`] coefficients, leading coefficient first.
#[derive(Clone, Copy, Debug)]
struct Poly {
    c: [f64; POLY_CAP],
    len: usize,
}

impl Poly {
    fn new(coeffs: &[f64]) -> Self {
        let mut c = [0.0; POLY_CAP];
        let len = coeffs.len().min(POLY_CAP);
        for (d, v) in c.iter_mut().zip(coeffs) {
            *d = *v;
        }
        Self { c, len }
    }

    fn coeffs(&self) -> &[f64] {
        &self.c[..self.len]
    }

    /// The product, cut to [`POLY_CAP`] coefficients (no product of the search is longer).
    fn mul(&self, q: &Poly) -> Poly {
        let mut r = Poly { c: [0.0; POLY_CAP], len: (self.len + q.len).saturating_sub(1).min(POLY_CAP) };
        for (i, a) in self.coeffs().iter().enumerate() {
            for (j, b) in q.coeffs().iter().enumerate() {
                if let Some(x) = r.c.get_mut(i + j) {
                    *x += a * b;
                }
            }
        }
        r
    }
}

/// (1 − p q⁻¹)^k.
fn lag_factor(p: f64, k: usize) -> Poly {
    (0..k).fold(Poly::new(&[1.0]), |acc, _| acc.mul(&Poly::new(&[1.0, -p])))
}

/// The B that fits y best for the fixed A = 1 + a1 q⁻¹ + … (`a` without its leading 1; module
/// docs): least squares of y(t) on w(t − nk − j), w = u/A, computed into `w`. `None` for an
/// unstable A or a singular problem.
fn best_b_for(s: &Structure, a: &[f64], y: &[f64], u: &[f64], w: &mut [f64]) -> Option<[f64; MAX_NB]> {
    if !oe::is_stable(a) {
        return None;
    }
    let w = w.get_mut(..u.len())?;
    for t in 0..w.len() {
        w[t] = u[t] - a.iter().enumerate().filter(|(i, _)| *i < t).map(|(i, ai)| ai * w[t - 1 - i]).sum::<f64>();
    }
    let mut ls = BatchLs::new(s.nb).ok()?;
    let mut phi = [0.0f64; MAX_PARAMS];
    for t in s.first_index()..y.len() {
        for j in 0..s.nb {
            phi[j] = w[t - s.nk - j];
        }
        ls.add(&phi[..s.nb], y[t]).ok()?;
    }
    let mut b = [0.0; MAX_NB];
    ls.solve(&mut b).ok()?;
    Some(b)
}

/// θ = [a, b] from `a` (without its leading 1) and `b`.
fn theta_of(s: &Structure, a: &[f64], b: &[f64]) -> [f64; MAX_PARAMS] {
    let mut th = [0.0; MAX_PARAMS];
    let (a_part, b_part) = th.split_at_mut(s.na);
    for (d, v) in a_part.iter_mut().zip(a) {
        *d = *v;
    }
    for (d, v) in b_part.iter_mut().take(s.nb).zip(b) {
        *d = *v;
    }
    th
}

/// The poles of `a` (without its leading 1) with the B that fits best for them.
fn with_best_b(s: &Structure, a: &[f64], y: &[f64], u: &[f64], w: &mut [f64]) -> Option<[f64; MAX_PARAMS]> {
    best_b_for(s, a, y, u, w).map(|b| theta_of(s, a, &b))
}

/// The lower order an output-error search of `order` starts from: 4 → 2, otherwise one less.
fn reduced(order: usize) -> usize {
    if order == 4 {
        2
    } else {
        order.saturating_sub(1).max(1)
    }
}

/// A fixed-capacity list of θ with their criterion value (0 for starts not yet screened).
struct Candidates {
    items: [(f64, [f64; MAX_PARAMS]); MAX_STARTS],
    len: usize,
}

impl Candidates {
    fn new() -> Self {
        Self { items: [(0.0, [0.0; MAX_PARAMS]); MAX_STARTS], len: 0 }
    }

    fn push(&mut self, cost: f64, theta: [f64; MAX_PARAMS]) {
        if let Some(x) = self.items.get_mut(self.len) {
            *x = (cost, theta);
            self.len += 1;
        }
    }

    fn as_slice(&self) -> &[(f64, [f64; MAX_PARAMS])] {
        &self.items[..self.len]
    }

    /// Stable sort by cost (insertion sort: equal costs keep the order the starts came in).
    fn sort_by_cost(&mut self) {
        let items = &mut self.items[..self.len];
        for i in 1..items.len() {
            let mut j = i;
            while j > 0 && items[j - 1].0.total_cmp(&items[j].0).is_gt() {
                items.swap(j - 1, j);
                j -= 1;
            }
        }
    }
}

/// The starts of a search of `s`, in the order of the module docs.
fn starts(s: &Structure, y: &[f64], u: &[f64], scratch: &mut [f64], memo: &mut OeMemo) -> Candidates {
    let (na, nb) = (s.na, s.nb);
    let mut starts = Candidates::new();
    let mut ls = [0.0; MAX_PARAMS];
    if batch::least_squares(s, y, u, &mut ls).is_ok() {
        let mut iv = ls;
        if batch::instrumental_variables(s, y, u, &mut iv, scratch).is_ok() {
            starts.push(0.0, iv);
        }
        starts.push(0.0, ls);
    }
    for k in [s.nk.checked_sub(1), Some(s.nk + 1)].into_iter().flatten() {
        if let Slot::Found(th) = memo.get(na, nb, k) {
            starts.push(0.0, th);
        }
    }
    if na == 1 && nb == 1 {
        for p in FIRST_ORDER_POLES {
            if let Some(th) = with_best_b(s, &[-p], y, u, scratch) {
                starts.push(0.0, th);
            }
        }
    } else if let Ok(r) = Structure::new(reduced(na), reduced(nb), 0, s.nk) {
        if let Ok(low) = search(&r, y, u, scratch, memo) {
            let mut a_low = [1.0; POLY_CAP];
            for (d, v) in a_low[1..].iter_mut().zip(&low[..r.na]) {
                *d = *v;
            }
            let a_low = Poly::new(&a_low[..=r.na]);
            let b_low = Poly::new(&low[r.na..r.na + r.nb]);
            for p in EXTRA_POLES {
                let a = a_low.mul(&lag_factor(p, na - r.na));
                let b = b_low.mul(&lag_factor(p, nb - r.nb));
                let a = a.coeffs().get(1..).unwrap_or(&[]);
                starts.push(0.0, theta_of(s, a, b.coeffs()));
                if let Some(th) = with_best_b(s, a, y, u, scratch) {
                    starts.push(0.0, th);
                }
            }
        }
    }
    starts
}

/// Output-error estimate θ = [a1 … a_na, b0 … b_{nb−1}] (zeros after na + nb) of the ARX
/// structure `s` on the record y, u (deviation variables, equal length): the best of the
/// multi-start search of the module docs. `scratch` (at least as long as y) holds intermediate
/// signals; `memo` holds this record's searches, and gains this one and the lower orders it
/// starts from.
pub fn search(
    s: &Structure,
    y: &[f64],
    u: &[f64],
    scratch: &mut [f64],
    memo: &mut OeMemo,
) -> Result<[f64; MAX_PARAMS], SearchError> {
    if s.nc > 0 {
        return Err(SearchError::Structure);
    }
    if y.len() != u.len() || scratch.len() < y.len() {
        return Err(SearchError::Input);
    }
    match memo.get(s.na, s.nb, s.nk) {
        Slot::Found(th) => return Ok(th),
        Slot::NoStableStart => return Err(SearchError::NoStableStart),
        Slot::Unsearched => {}
    }
    let n = s.na + s.nb;
    let cfg = OeConfig::DEFAULT;
    let screen = OeConfig { max_iterations: SCREEN_ITERATIONS, ..cfg };
    let mut screened = Candidates::new();
    for (_, start) in starts(s, y, u, scratch, memo).as_slice() {
        let mut th = *start;
        if let Ok(out) = oe::refine(s, &screen, &mut th[..n], y, u) {
            screened.push(out.cost, th);
        }
    }
    screened.sort_by_cost();
    let mut best: Option<(f64, [f64; MAX_PARAMS])> = None;
    for (_, start) in screened.as_slice().iter().take(FINALISTS) {
        let mut th = *start;
        if let Ok(out) = oe::refine(s, &cfg, &mut th[..n], y, u) {
            if best.is_none_or(|(cost, _)| out.cost.total_cmp(&cost).is_lt()) {
                best = Some((out.cost, th));
            }
        }
    }
    match best {
        Some((_, th)) => {
            memo.set(s, Slot::Found(th));
            Ok(th)
        }
        None => {
            memo.set(s, Slot::NoStableStart);
            Err(SearchError::NoStableStart)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ident::oe::tests::{input, mismatched_record, simulate};
    use crate::ident::validate;

    fn fit(s: &Structure, th: &[f64], y: &[f64], u: &[f64]) -> f64 {
        let mut ys = std::vec![0.0; y.len()];
        validate::simulate_fit(s, th, y, u, &mut ys)
    }

    /// A noise-free 2nd-order system with a 3-sample delay is found exactly, and the memo holds
    /// it and the 1st-order model its starts came from.
    #[test]
    fn finds_an_exact_system_and_remembers_the_searches() {
        let s = Structure::new(2, 2, 0, 3).unwrap();
        let truth = [-1.75, 0.76, 0.02, 0.01];
        let u = input(1500, 7);
        let y = simulate(&s, &truth, &u);
        let mut scratch = std::vec![0.0; y.len()];
        let mut memo = OeMemo::new();
        let th = search(&s, &y, &u, &mut scratch, &mut memo).unwrap();
        for (got, want) in th.iter().zip(truth) {
            assert!((got - want).abs() < 1e-6, "{th:?}");
        }
        assert!(th[4..].iter().all(|v| *v == 0.0));
        assert_eq!(memo.found(&s), Some(&th[..4]));
        assert!(memo.found(&Structure::new(1, 1, 0, 3).unwrap()).is_some());
        assert!(memo.found(&Structure::new(2, 2, 0, 2).unwrap()).is_none());
        // A second search of the same structure is the memo's answer.
        assert_eq!(search(&s, &y, &u, &mut scratch, &mut memo), Ok(th));
    }

    /// Under model mismatch and coloured noise, each order simulates the record at least as
    /// well as the one below it (one start is the lower-order model), and the search ends at
    /// least as low as a single search from least squares run to convergence.
    #[test]
    fn higher_orders_fit_no_worse_and_the_search_beats_one_start() {
        let (y, u) = mismatched_record();
        let mut scratch = std::vec![0.0; y.len()];
        let mut memo = OeMemo::new();
        let mut fits = std::vec::Vec::new();
        for order in [1, 2, 4] {
            let s = Structure::new(order, order, 0, 1).unwrap();
            let th = search(&s, &y, &u, &mut scratch, &mut memo).unwrap();
            assert!(oe::is_stable(&th[..order]), "order {order}: {th:?}");
            fits.push(fit(&s, &th[..2 * order], &y, &u));
        }
        // Measured: 1st order 88.8 %, 2nd 97.3 %, 4th 97.6 %.
        assert!(fits[1] > fits[0] + 2.0 && fits[2] >= fits[1] - 0.01, "{fits:?}");
        let s = Structure::new(2, 2, 0, 1).unwrap();
        let mut th = [0.0; 4];
        batch::least_squares(&s, &y, &u, &mut th).unwrap();
        oe::refine(&s, &OeConfig::DEFAULT, &mut th, &y, &u).unwrap();
        let best = memo.found(&s).unwrap();
        let (vb, vl) = (oe::cost(&s, best, &y, &u), oe::cost(&s, &th, &y, &u));
        // Both end in the same minimum here (V equal to 15 digits); the search is never worse.
        assert!(vb <= vl * (1.0 + 1e-9), "search V {vb} vs from LS {vl}");
    }

    #[test]
    fn refuses_armax_bad_lengths_and_unexcited_records() {
        let u = input(300, 5);
        let y = simulate(&Structure::new(1, 1, 0, 1).unwrap(), &[-0.9, 0.1], &u);
        let mut memo = OeMemo::new();
        let mut scratch = std::vec![0.0; y.len()];
        let armax = Structure::new(1, 1, 1, 1).unwrap();
        assert_eq!(search(&armax, &y, &u, &mut scratch, &mut memo), Err(SearchError::Structure));
        let s = Structure::new(1, 1, 0, 1).unwrap();
        assert_eq!(search(&s, &y, &u[..299], &mut scratch, &mut memo), Err(SearchError::Input));
        assert_eq!(search(&s, &y, &u, &mut scratch[..10], &mut memo), Err(SearchError::Input));
        // A constant input excites nothing: no start, and the memo remembers that.
        let zeros = std::vec![0.0; 300];
        assert_eq!(search(&s, &y, &zeros, &mut scratch, &mut memo), Err(SearchError::NoStableStart));
        assert_eq!(memo.get(1, 1, 1), Slot::NoStableStart);
        assert!(memo.found(&s).is_none());
    }

    #[test]
    fn polynomial_products() {
        let p = Poly::new(&[1.0, -0.5]).mul(&lag_factor(0.8, 2));
        // (1 − 0.5 q⁻¹)(1 − 0.8 q⁻¹)² = 1 − 2.1 q⁻¹ + 1.44 q⁻² − 0.32 q⁻³
        let want = [1.0, -2.1, 1.44, -0.32];
        assert_eq!(p.coeffs().len(), 4);
        for (g, w) in p.coeffs().iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{:?}", p.coeffs());
        }
        assert_eq!(lag_factor(0.3, 0).coeffs(), [1.0]);
        assert_eq!((reduced(4), reduced(3), reduced(2), reduced(1)), (2, 2, 1, 1));
    }
}
