//! Generalized Predictive Control (Clarke, Mohtadi & Tuffs, "Generalized predictive control —
//! Part I. The basic algorithm", Automatica 23(2), 1987).
//!
//! Model (CARIMA, [`Model`]): `A y(t) = q^−k B u(t) + C e(t)/Δ`, Δ = 1 − q⁻¹. Cost
//!
//! ```text
//! J = Σ_{j=N1..N2} (ŷ(t+j|t) − w)² + λ Σ_{j=1..Nu} Δu(t+j−1)²
//! ```
//!
//! with w the current setpoint (no preview). The j-step predictor splits into a free response
//! f_j (past data, future increments zero) and a forced response `Σ g_i Δu(t+j−i)` with g the
//! step response of `q^−k B/A` (eq. 8–11 of the paper):
//!
//! ```text
//! ŷ = G Δũ + f,   Δũ = (GᵀG + λI)⁻¹ Gᵀ (w − f),   only Δu(t) = first element is applied.
//! ```
//!
//! **How the free response is computed.** Instead of solving the Diophantine identity
//! `C = E_j ÃΔ... ` for every j, the predictor is evaluated by running the incremental model
//! `Ã ŷ(t+j) = B Δu(t+j−k) + C ê(t+j)` forward with future Δu and future ê set to zero, where
//! ê(t) is reconstructed each sample from the model (ê(t) = Ã y(t) − B Δu(t−k) − Σ c_i ê(t−i)).
//! This is algebraically the same predictor as `F_j y(t)/C + …` from the Diophantine solution
//! (Clarke et al., §3; Camacho & Bordons, *Model Predictive Control*, 2nd ed., §4.2), costs
//! O(N2·(na+nb+nc)) flops with no polynomial division, and needs no storage for E_j, F_j.
//! [`crate::control::diophantine`] solves the identity explicitly for GMVC/IGMVC and for the
//! tests that cross-check the two.
//!
//! The Nu×Nu normal matrix `GᵀG + λI` is symmetric positive definite for λ > 0 and is solved by
//! Cholesky (no general inverse). u is clipped to [0, 1] and the *applied* u is fed back
//! through [`GpcState::track`], so saturation never winds anything up.
//!
//! Glossary: N1/N2 — first/last predicted sample in the cost; Nu — control horizon (number of
//! free future increments); λ — weight on the control increments; f — free response;
//! g — step response coefficients; w — setpoint.
#![allow(non_snake_case)]

use crate::model::{Model, MAX_K, MAX_NA, MAX_NB, MAX_NC};
use crate::numerics::{dot_from, finite_probe, shift_in, sqrtf};

/// Largest prediction horizon N2.
pub const MAX_N2: usize = 30;
/// Largest control horizon Nu.
pub const MAX_NU: usize = 5;

/// Why GPC could not produce an increment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GpcError {
    /// N1, N2, Nu or λ out of range: need 1 ≤ N1 ≤ N2 ≤ 30, 1 ≤ Nu ≤ min(5, N2), λ ≥ 0 finite.
    Config,
    /// `GᵀG + λI` is not positive definite (λ = 0 with a step response that is zero over the horizon).
    Singular,
    /// A non-finite number appeared (model or measurement).
    NonFinite,
    /// [`GpcStaged`] on a model beyond na 2, nb 4 in a build without the library feature
    /// `gpc-any-order` (a board: its models are the self-tuner's).
    NotBuilt,
}

/// GPC tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GpcConfig {
    /// First predicted sample in the cost.
    pub n1: usize,
    /// Last predicted sample in the cost (≤ [`MAX_N2`]).
    pub n2: usize,
    /// Control horizon (≤ [`MAX_NU`]).
    pub nu: usize,
    /// Weight on the squared control increments, (°C per unit duty)².
    pub lambda: f32,
}

impl GpcConfig {
    /// N1 = 1, N2 = 30 (5 min at Ts = 10 s, the closed-loop settling scale), Nu = 3, λ = 0.5
    /// (the self-tuner starts its cost one sample after the model's delay instead,
    /// [`crate::control::adaptive`], "The cost's first row").
    /// λ weighs Δu² (duty in [0, 1], so Δu ≤ 1) against squared errors in °C summed over 30
    /// predictions, with step-response coefficients of tens of °C per unit duty. Tuned for the
    /// self-tuner's 4-term B with its T-filter (τ = 0.8 after issue 15's campaigns, `AdaptiveConfig::t_filter`):
    /// 64 settings (τ 0.3–0.7, λ 0.5–3, Nu 2–3, N2 25–30) on seeds 1–3 at 28 °C, the best five
    /// on seeds 1–8 at 20, 28 and 36 °C, then τ 0.6–0.8 × λ 0.5–1 again with the staged design
    /// ([`GpcStaged`]); this one has the lowest IAE / bound over the full load, the half load and
    /// H-TER II together (EXPERIMENTS.md; `hter compare --scenario S --plant P --lambda L
    /// --t-pole T --nu U --n2 N`). With the old 2-term B, λ = 3: smaller values let GPC bang
    /// the SSR on the model's unmodelled lag. At rest the duty moves more than with λ = 3
    /// (standard deviation 0.08 against 0.02 over the last hour of `hter sim --scenario step`,
    /// the load within 3.92–4.06 °C against 3.96–4.04), for the same energy. λ 0.2 with one
    /// model ([`GpcStaged`], "One model") has less IAE everywhere (28 °C, seed 1: 1.130 · 1.320
    /// · 1.048 × the bound) and no ringing, but its worst sample in `cargo xtask pil` is 5 056
    /// instructions, over the 5 000 budget (EXPERIMENTS.md).
    pub const DEFAULT: GpcConfig = GpcConfig { n1: 1, n2: 30, nu: 3, lambda: 0.5 };

    /// Checks the ranges of [`GpcError::Config`].
    pub const fn validate(&self) -> Result<(), GpcError> {
        let ok = self.n1 >= 1
            && self.n1 <= self.n2
            && self.n2 <= MAX_N2
            && self.nu >= 1
            && self.nu <= MAX_NU
            && self.nu <= self.n2
            && self.lambda.is_finite()
            && self.lambda >= 0.0;
        if ok {
            Ok(())
        } else {
            Err(GpcError::Config)
        }
    }
}

const HY: usize = MAX_NA + 2; // y(t) … y(t − na − 1)
                              // `responses` reads ã_1…ã_{MAX_NA+1} and y(t)…y(t − MAX_NA).
const _: () = assert!(HY > MAX_NA);
const HU: usize = MAX_NB + MAX_K; // Δu(t−1) … Δu(t − k − nb)
const HE: usize = MAX_NC + 1; // ê(t) … ê(t − nc)

/// Past data the predictor needs, and the last applied u.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpcState {
    y: [f32; HY],
    du: [f32; HU],
    e: [f32; HE],
    u_prev: f32,
    primed: bool,
}

/// The design of one sample, for logging and tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpcDesign {
    /// Step response g_1 … g_N2 (index 0 is g_1).
    pub g: [f32; MAX_N2],
    /// Free response f_1 … f_N2.
    pub f: [f32; MAX_N2],
    /// First row of (GᵀG + λI)⁻¹Gᵀ over j = N1 … N2 (index 0 is j = N1).
    pub k1: [f32; MAX_N2],
    /// The increment Δu(t) before clipping.
    pub du: f32,
}

impl GpcDesign {
    /// All zeros.
    pub const ZERO: GpcDesign = GpcDesign { g: [0.0; MAX_N2], f: [0.0; MAX_N2], k1: [0.0; MAX_N2], du: 0.0 };
}

impl GpcState {
    /// Empty history, holding `u0`.
    pub fn new(u0: f32) -> Self {
        Self { y: [0.0; HY], du: [0.0; HU], e: [0.0; HE], u_prev: u0, primed: false }
    }

    /// The last applied u.
    pub fn u_prev(&self) -> f32 {
        self.u_prev
    }

    /// Forgets the measured past: the next [`push_y`](Self::push_y) fills the y history with
    /// its measurement, as the first does (and clears ê's). The Δu history stays.
    pub fn reprime(&mut self) {
        self.primed = false;
    }

    /// Takes the new measurement y(t). The first call fills the whole y history with it (the
    /// plant is assumed at rest), so there is no start-up kick.
    pub fn push_y(&mut self, y: f32, m: &Model) -> Result<(), GpcError> {
        if !y.is_finite() {
            return Err(GpcError::NonFinite);
        }
        if !self.primed {
            self.y = [y; HY];
            self.e = [0.0; HE];
            self.primed = true;
        } else {
            shift_in(&mut self.y, y);
        }
        // ê(t) = Ã y(t) − B Δu(t−k) − Σ c_i ê(t−i)
        let at = m.atilde();
        let mut e = 0.0;
        for (i, ai) in at.iter().enumerate().take(m.na() + 2) {
            e += ai * self.y[i];
        }
        for i in 0..m.nb() {
            e -= m.b()[i] * self.du_past(m.k() + i);
        }
        shift_in(&mut self.e, 0.0);
        for i in 0..m.nc() {
            e -= m.c()[i] * self.e[i + 1];
        }
        self.e[0] = if e.is_finite() { e } else { 0.0 };
        Ok(())
    }

    /// Δu(t − m), m ≥ 1 (zero beyond the stored history).
    fn du_past(&self, m: usize) -> f32 {
        // m = 0 wraps to an index past the end, which `get` refuses.
        self.du.get(m.wrapping_sub(1)).copied().unwrap_or(0.0)
    }

    /// Step response g_1…g_N2 and free response f_1…f_N2 into `d`, with A and B zero-padded to
    /// `NA` ≥ na and `NB` ≥ nb coefficients and Ã to `NH` = NA + 1 (ã_1…ã_NH). Returns the
    /// finiteness probe Σ (x − x) over both (+0 exactly when every value is finite).
    ///
    /// A padded term adds 0·y = ±0 to a sum that starts at +0.0 and so is never −0: the sum is
    /// unchanged, bit for bit, and the inner sums have fixed lengths and unroll. The past values
    /// the recursions need stay in registers ([`shift_in`]).
    #[inline(always)]
    fn responses<const NA: usize, const NB: usize, const NH: usize>(
        &self,
        m: &Model,
        n2: usize,
        d: &mut GpcDesign,
    ) -> f32 {
        step_response::<NA, NB>(m, n2, &mut d.g) + self.free_response::<NB, NH>(m, n2, &mut d.f)
    }

    /// The free response f_1…f_N2 of [`responses`](Self::responses) alone: its head
    /// ([`free_head`](Self::free_head), up to where past data stop entering) and its tail.
    #[inline(always)]
    fn free_response<const NB: usize, const NH: usize>(&self, m: &Model, n2: usize, f: &mut [f32; MAX_N2]) -> f32 {
        let split = head_end::<NB>(m, n2);
        let (past, probe) = self.free_head::<NB, NH>(m, split, f);
        probe + free_tail(&m.atilde(), past, &mut f[split - 1..n2])
    }

    /// The free response's head f_1…f_{split−1} into `f` (`split` ≥ [`head_end`], ≤ N2 + 1), and
    /// the past values ŷ(t+split−1), ŷ(t+split−2), … the rest of it continues from (beyond the
    /// head no past increment or residual enters: f_j = −Σ ã_i f_{j−i}), with the finiteness
    /// probe of the head.
    #[inline(always)]
    fn free_head<const NB: usize, const NH: usize>(
        &self,
        m: &Model,
        split: usize,
        f: &mut [f32; MAX_N2],
    ) -> ([f32; NH], f32) {
        let nb = m.nb().min(NB);
        let nc = m.nc().min(MAX_NC);
        let b: [f32; NB] = core::array::from_fn(|i| if i < nb { m.b()[i] } else { 0.0 });
        let mut probe = 0.0f32;

        // Free response: run Ã ŷ(t+j) = B Δu(t+j−k) + C ê(t+j) with future Δu, ê = 0;
        // ŷ(t + j − i) = y(t + j − i) for j ≤ i. Past increments enter while j < k + nb, past
        // residuals while j ≤ nc.
        let at = m.atilde();
        let mut past: [f32; NH] = core::array::from_fn(|i| self.y[i]); // ŷ(t+j−1), ŷ(t+j−2), …
        for (idx, fj) in f[..split - 1].iter_mut().enumerate() {
            let j = idx + 1;
            let mut v = 0.0;
            for (ai, yp) in at[1..].iter().zip(&past) {
                v -= ai * yp;
            }
            // Δu(t + j − k − i) is known only when j − k − i ≤ −1.
            for (i, bi) in b[..nb].iter().enumerate() {
                if m.k() + i > j {
                    v += bi * self.du_past(m.k() + i - j);
                }
            }
            for i in j..=nc {
                v += m.c()[i - 1] * self.e[i - j];
            }
            probe += finite_probe(v);
            shift_in(&mut past, v);
            *fj = v;
        }
        (past, probe)
    }

    /// The free response f_1 … f_R into `f` (R = its length) for a model with na ≤ 2, nb ≤ 4
    /// ([`GpcStaged`]'s), and its last four values f_R, f_{R−1}, f_{R−2}, f_{R−3} (y(t + j) for
    /// j ≤ 0), with the finiteness probe. [`free_head`](Self::free_head) and
    /// [`free_tail`] with every row alike: the past increments row j sees,
    /// Δu(t + j − k − i) for i = 0 … 3 (zero from t on), slide through four registers one
    /// value a row, and the residuals' share (rows 1 and 2) through two, so every row is the
    /// same eight products with no comparisons.
    #[inline(always)]
    fn free_window(&self, m: &Model, f: &mut [f32]) -> ([f32; 4], f32) {
        let at = m.atilde();
        let (b, c, e) = (m.b(), m.c(), &self.e);
        let k = m.k().min(MAX_K);
        // Δu(t − 1 − q) = du[q]; row 1 sees q = k − 2 … k + 1, each row after one less.
        let du = |q: usize| self.du.get(q).copied().unwrap_or(0.0);
        let mut win = [du(k.wrapping_sub(2)), du(k - 1), du(k), du(k + 1)];
        let mut incoming = self.du[..k.saturating_sub(2)].iter().rev();
        let mut res = [c[0] * e[0] + c[1] * e[1], c[1] * e[0]];
        let mut past: [f32; 4] = core::array::from_fn(|i| self.y[i]);
        for fj in f.iter_mut() {
            let mut v = 0.0;
            for (ai, yp) in at[1..4].iter().zip(&past) {
                v -= ai * yp;
            }
            for (bi, ui) in b.iter().zip(&win) {
                v += bi * ui;
            }
            v += res[0];
            shift_in(&mut past, v);
            shift_in(&mut res, 0.0);
            shift_in(&mut win, incoming.next().copied().unwrap_or(0.0));
            *fj = v;
        }
        // The last value is finite only if every row is ([`recursion_probe`]).
        let probe = recursion_probe(past[0]);
        (past, probe)
    }

    /// The GPC increment Δu(t) for setpoint `w`, after [`push_y`](Self::push_y).
    ///
    /// Runs every sample of the self-tuning controller (the model changes every sample), so it
    /// is written for the Cortex-M4F: slices instead of indexed loops with run-time checks,
    /// products that are zero by the structure of G skipped, the symmetric normal matrix built
    /// band by band from shared partial sums. Every floating-point operation that is kept is
    /// the one of the plain formulas, in the same order, so the result is bit-for-bit that of
    /// the textbook loops (skipped terms are exact zeros and adding ±0 changes nothing).
    pub fn design(&self, m: &Model, cfg: &GpcConfig, w: f32) -> Result<GpcDesign, GpcError> {
        let mut d = GpcDesign::ZERO;
        self.design_into(m, cfg, w, &mut d)?;
        Ok(d)
    }

    /// [`design`](Self::design) into the caller's `d`, which the self-tuning loop keeps from
    /// sample to sample (no 364-byte zeroing and copy per sample on the M4). Only g_1…g_N2,
    /// f_1…f_N2, k1 over N1…N2 and du are written; entries beyond are left as they were.
    pub fn design_into(&self, m: &Model, cfg: &GpcConfig, w: f32, d: &mut GpcDesign) -> Result<(), GpcError> {
        cfg.validate()?;
        if !w.is_finite() {
            return Err(GpcError::NonFinite);
        }
        let n2 = cfg.n2;
        // The self-tuning controller's models (na ≤ 2, nb ≤ 4) get the recursions unrolled for
        // two A and four B coefficients; anything larger for the most the model holds.
        let probe = if m.na() <= 2 && m.nb() <= 4 {
            self.responses::<2, 4, 3>(m, n2, d)
        } else {
            self.responses::<MAX_NA, MAX_NB, { MAX_NA + 1 }>(m, n2, d)
        };
        if probe != 0.0 {
            return Err(GpcError::NonFinite);
        }

        // Normal equations H x = Gᵀ(w − f), H = GᵀG + λI, rows j = N1..N2, G[j][c] = g_{j−c}.
        let (n1, nu) = (cfg.n1, cfg.nu);
        // g_1 … g_lead are exact zeros (the dead time): their products are ±0 and are skipped
        // below (adding ±0 to a sum that is not −0 changes nothing). g_1 … g_{k−1} are +0 by
        // construction (no b_i enters before j = k, and 0 − a_i·0 is +0), so the count starts
        // at k − 1 (k ≥ 1 in every model; the probe above has refused a non-finite one).
        let lead = dead_lead(&d.g, m.k(), n2);
        let z = first_row_solve(normal_matrix(&d.g, cfg, lead), nu)?;
        let start = gain_row_nu(&z, &d.g, &mut d.k1, n1, n2, nu, lead);
        let du = increment(d, n1, n2, start, w);
        if !du.is_finite() {
            return Err(GpcError::NonFinite);
        }
        d.du = du;
        Ok(())
    }

    /// Records the u actually applied this sample (after clipping or an override).
    pub fn track(&mut self, applied: f32) {
        if !applied.is_finite() {
            return;
        }
        shift_in(&mut self.du, applied - self.u_prev);
        self.u_prev = applied;
    }
}

/// GPC with the model's share of the design spread over samples, and the cost solved with the
/// duty's limits as constraints, for the self-tuning loop on the M4F.
///
/// **Staged.** Of a design, only the free response f depends on the data; the step response g,
/// H = GᵀG + λI, its inverse Z, the levels' gain rows and P = Q⁻¹ (below) depend on the model
/// alone, and they are most of the work. Each sample computes f and the levels with the design
/// in use, on that design's own model (below), and does one stage of the next design on the
/// current model:
/// stage 0 the step response and its dead time, stage 1 H, stage 2 H's Cholesky factor,
/// Z = H⁻¹, M = D⁻¹Z, P and every level's gain row, stage 3 every level's folded tail, which
/// puts the new design in use (a swap of banks, no copy). A design is thus at most eight
/// samples old (the constrained samples below skip their stage), against a model that moves
/// over tens of minutes; the sample's work falls from a whole design to its largest stage
/// (`cargo xtask pil`, BENCHMARKS.md). The staleness costs a little: the same law designed
/// whole every sample (a host experiment) has 0.01 less IAE / bound on `hter compare`'s
/// piecewise run (EXPERIMENTS.md).
///
/// **One model.** Stage 0 keeps the model it starts from with the design, stages 1–3 build on
/// it, and the samples the design serves compute f on it ([`GpcStaged::model`]; `LawState`
/// also computes the residuals ê on it, which f's C terms read), not on the current estimate.
/// The law is then GPC on a model a few samples old, not the gains of one model on the
/// predictions of another. With f on the current model, a self-tuner whose estimate moved
/// fast (the first samples after it was trusted, a light carrier's swings) met gains designed
/// for a model 2–4 times stronger or weaker, and the duty rang between 0 and 1 every sample
/// while the load fell below the setpoint: the dips of campaign missions 4700, 120740, 123834
/// and 127954 to 2.0–2.6 °C (issue 15; EXPERIMENTS.md).
///
/// **Level gains.** The unconstrained plan is Δũ = Z Gᵀ(w − f), and its levels relative to
/// u(t−1) are v = D⁻¹Δũ = M Gᵀ(w − f), M = D⁻¹Z (D⁻¹ the lower triangle of ones: M's row i
/// is the sum of Z's rows 0 … i). So level i is a gain row `L_i[j]` = Σ_c `M[i][c]` g_{j−c} over
/// the rows j = N1 … N2, as the unconstrained law's Δu(t) is the gain row of Z's first row
/// (level 0 is exactly that), and the sums over c cancel on the model's numbers only, once a
/// design, not on the data every sample.
///
/// **Folded tail.** Past increments and residuals enter f only up to j < k + nb (and j ≤ nc,
/// `head_end`); beyond, f runs alone on Ã, so level i's share of it,
/// Σ_{j ≥ split} `L_i[j]` (w − f_j), is −T_i·(ŷ − w) for a fixed combination T_i of the three
/// values the tail starts from (`fold_weights` with the weights `L_i[j]`). The head's rows in
/// the cost are at most the four from the dead time k to k + 3 (the longest head of the small
/// models, `fold_split`), so the gain row's head and the folded tail make four weights C_i on
/// the last four values of the head, f_{split−4} … f_{split−1}. Each sample computes the head
/// f_1 … f_{k+3} (`GpcState::free_window`) and v_i = C_i·(f_window − w): Nu × 4 products
/// (`staged_increment_with_the_tail_folded_in_is_the_full_designs`). A model beyond na ≤ 2,
/// nb ≤ 4 runs the whole f and the whole sums instead.
///
/// **Constrained** (issue 15). The Nu future duties are the levels u(t−1) + v_i; the cost is
/// minimised over them with 0 ≤ u(t−1) + v_i ≤ 1, not solved unconstrained and clipped. In
/// v, Δũ = D v with D lower bidiagonal (1, −1), so the cost ½ΔũᵀHΔũ − bᵀΔũ (b = Gᵀ(w − f))
/// is ½vᵀQv − (Dᵀb)ᵀv with Q = DᵀHD, whose unconstrained minimiser is the v above. It is kept
/// when every level is within the box, which is most samples; otherwise `box_qp` solves the
/// levels' problem from it through P = Q⁻¹ = D⁻¹ZD⁻ᵀ (M's prefix sums along its rows), and
/// that sample skips its design stage, so that no sample does both (`cargo xtask pil`).
/// After `MAX_SKIPS` such samples in a row the next one clips v_0 into the box instead and
/// does its stage: while the limits hold for long (a pull-down) the design still moves on,
/// at one stage in `MAX_SKIPS + 1` samples. If the soft floor (below) moved a plan among the
/// samples that skipped, that sample does not raise the duty (v_0 is clipped into
/// [−u(t−1), 0]): it goes without the floor, and amid a fast descent's landing its plan asked
/// for full duty again between samples the floor had eased off. Without a floor sample it
/// clips into the box: on a pull-down from a warm start a hold there held the duty at 0 for
/// a sample the load needed cooling (campaign mission 4207: 8.29 °C for 40 s after the
/// pull-down, against 8.01 °C for 10 s). Δu(t) = v_0.
///
/// **Soft floor** (issue 15). The cost also weighs ρ (`FLOOR_WEIGHT`) times the squared
/// amount by which the plan falls below either of two rows, so that the plan itself keeps the
/// load off the freeze guard, which stays the second line:
/// - the *floor row*: the plan's prediction midway from the fold to N2 (`floor_row`: the
///   plan's largest undershoot comes some samples after its first move takes effect) against
///   [`SOFT_FLOOR_C`] (at most [`FLOOR_GAP_C`] below the setpoint), as ŷ_j = f_j + Σ_i d_i v_i,
///   three weights on the head's last values for f_j and three on the levels;
/// - the *guard row*: what the freeze guard will extrapolate from the plan at row k + 3, the
///   head's last (its reading plus its smoothed slope times its 120 s look-ahead,
///   [`GUARD_ROW_WEIGHTS`] on the head's last four values), against [`GUARD_ROW_C`]: its
///   free response is the head's own values, and its weights on the levels are made once a
///   design (at stage 2, with the level rows; the floor row's at stage 0).
///
/// The row the plan falls further below enters the levels' problem: Q + ρddᵀ, whose inverse is
/// P less a rank-one term (Sherman–Morrison), so the plan moves along Pd by the penalised
/// cost's Newton step, and its first move, clipped into the box, is Δu(t). The plan is the
/// box's levels when the limits were at work, and a plan that does not cool now (its first
/// move is the "no cooling" bound) is left as it is: the penalty could only push it further
/// in. That sample skips its design stage like a constrained one (and the one sample in
/// `MAX_SKIPS + 1` that may not skip goes without the floor, so that no sample pays for both);
/// `a_soft_floor_lifts_a_plan_that_dips_below_it` checks it against the f64 move of the
/// penalised cost.
///
/// The guard row is the one that acts on `hter compare`'s runs: a full-duty descent from 6 to
/// 3 °C that any plan close to the bound makes (the half-loaded H-TER I at 20 °C, the RTD
/// falling 1.5 °C a minute at 4.1 °C) reached the guard's extrapolated 1.5 °C with the load
/// itself turning at 3.24 °C, and the trip's 40 s without cooling then cost an undershoot to
/// 2.73 °C; with the row the plan eases off a sample or two earlier on its own and lands
/// without a trip (`scripts/targets.sh`: 8 trips on seeds 1–8 at 20 °C to none). The floor
/// row changes a plan in states like its test's (λ 50, the box holding no cooling after the
/// first move). `cargo xtask pil` times such samples in a case made up to meet the floor
/// (readings falling 0.2 °C a sample through a 3 °C setpoint, GPC at λ 200;
/// [`Self::floor_samples`] tells it which samples), the box solved on the same sample.
///
/// **Sizes.** Everything runs on [`NQ`] = 3 levels, fixed, so the loops unroll and carry no
/// bounds checks: a smaller Nu pads H with the identity (its factor, inverse and P are then the
/// Nu×Nu ones bordered by the identity, exactly, and the padded levels stay 0 inside the box).
/// A larger Nu (4, 5) runs the same code on [`MAX_NU`] levels, in builds with the library
/// feature `gpc-any-nu` (the host's); a board's Nu is the profile's 3, and without the feature
/// a larger one is [`GpcError::NotBuilt`].
///
/// Until the first design is complete (the first four samples, and after a change of
/// horizons) Δu is 0: the law holds the duty it starts from. A stage that fails (a non-finite
/// or singular design) returns its error for that sample and the cycle starts again; the last
/// complete design, if any, keeps serving.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpcStaged {
    /// g of the cycle under way (stage 0).
    g: [f32; MAX_N2],
    /// f of this sample (its head only when the tail folds).
    f: [f32; MAX_N2],
    /// H = GᵀG + λI of the cycle under way (stage 1), then its Cholesky factor (stage 2).
    h: [[f32; MAX_NU]; MAX_NU],
    /// Dead-time zeros of the step response in `g` of the cycle under way.
    lead: usize,
    /// The design in use, `bank[cur]`, and the one under way, the other.
    bank: [StagedBank; 2],
    cur: usize,
    /// The tuning everything here was built with: new horizons start over.
    cfg: GpcConfig,
    /// A design is complete in `bank[cur]`.
    ready: bool,
    /// Next stage: 0 … 3.
    stage: u8,
    /// Samples in a row that skipped their stage.
    skipped: u8,
    /// The soft floor moved a plan since the last sample that did its stage.
    floored: bool,
    /// Samples on which the soft floor moved the plan, modulo 256 ([`Self::floor_samples`]).
    floors: u8,
}

/// One [`GpcStaged`] design: what the sample's solve reads.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StagedBank {
    /// The levels' gain rows L_i[j] over j = N1 … N2 (`l[j − N1][i]`; +0 on the levels beyond
    /// Nu; the rows before `start` are never read, and may hold an earlier design's).
    l: [[f32; MAX_NU]; MAX_N2],
    /// Level i's weights on f_{split−1−r} − w, r = 0 … 3: the gain row's head and the folded
    /// tail (type docs), valid when `tail_ok` (the small models, na ≤ 2, nb ≤ 4).
    c: [[f32; 4]; MAX_NU],
    /// P = Q⁻¹ = D⁻¹ZD⁻ᵀ, bordered by the identity beyond Nu.
    p: [[f32; MAX_NU]; MAX_NU],
    /// The first row that is not an exact zero, where the tail folds, and whether it does.
    start: usize,
    split: usize,
    tail_ok: bool,
    /// The model the design is made on (stage 0's), which the sample's free response runs on.
    m: Model,
    /// The soft floor's check row j (type docs, "Soft floor"), its free response's weights on
    /// f_{split−1−r} − w (r < 3, when `tail_ok`), and its forced response's on the levels.
    fj: usize,
    fa: [f32; 3],
    fd: [f32; MAX_NU],
    /// The guard row's forced response's weights on the levels (type docs, "Soft floor").
    gd: [f32; MAX_NU],
}

impl StagedBank {
    const ZERO: StagedBank = StagedBank {
        l: [[0.0; MAX_NU]; MAX_N2],
        c: [[0.0; 4]; MAX_NU],
        p: [[0.0; MAX_NU]; MAX_NU],
        start: 0,
        split: 0,
        tail_ok: false,
        m: Model::ZERO,
        fj: 0,
        fa: [0.0; 3],
        fd: [0.0; MAX_NU],
        gd: [0.0; MAX_NU],
    };
}

/// The number of levels [`GpcStaged`] is written for: the board's Nu (`GpcConfig::DEFAULT`).
pub const NQ: usize = 3;

impl GpcStaged {
    /// No design yet. All zeros, so a board fills it with a memset, not a copy of a
    /// kilobyte constant (the zero tuning is no tuning: the first update starts over).
    pub const NEW: GpcStaged = GpcStaged {
        g: [0.0; MAX_N2],
        f: [0.0; MAX_N2],
        h: [[0.0; MAX_NU]; MAX_NU],
        lead: 0,
        bank: [StagedBank::ZERO; 2],
        cur: 0,
        cfg: GpcConfig { n1: 0, n2: 0, nu: 0, lambda: 0.0 },
        ready: false,
        stage: 0,
        skipped: 0,
        floored: false,
        floors: 0,
    };

    /// How many samples the soft floor has moved the plan on, modulo 256 (type docs, "Soft
    /// floor"): what `cargo xtask pil` checks to time such a sample on the M4F (it sits in
    /// padding: no RAM).
    pub fn floor_samples(&self) -> u8 {
        self.floors
    }

    /// The model of the design in use, once one is complete.
    pub fn model(&self) -> Option<&Model> {
        self.ready.then(|| &self.bank[self.cur & 1].m)
    }

    /// Δu(t) for setpoint `w` on model `m`, after [`GpcState::push_y`]; see the type's docs.
    pub fn update(&mut self, st: &GpcState, m: &Model, cfg: &GpcConfig, w: f32) -> Result<f32, GpcError> {
        // A tuning is checked when it changes (the one in use passed; a NaN never compares
        // equal, so it is checked, and refused, every sample).
        if *cfg != self.cfg {
            cfg.validate()?;
        }
        if !w.is_finite() {
            return Err(GpcError::NonFinite);
        }
        // New horizons start over; a new λ (the self-tuner's cautious λ, `adaptive`) enters at
        // the next normal matrix, and the design follows within eight samples.
        if (cfg.n1, cfg.n2, cfg.nu) != (self.cfg.n1, self.cfg.n2, self.cfg.nu) {
            self.ready = false;
            self.stage = 0;
        }
        self.cfg = *cfg;
        if cfg.nu <= NQ {
            return self.update_n::<NQ>(st, m, w);
        }
        #[cfg(feature = "gpc-any-nu")]
        {
            self.update_n::<MAX_NU>(st, m, w)
        }
        #[cfg(not(feature = "gpc-any-nu"))]
        Err(GpcError::NotBuilt)
    }

    /// [`update`](Self::update) on `N` ≥ Nu levels.
    #[inline(always)]
    fn update_n<const N: usize>(&mut self, st: &GpcState, m: &Model, w: f32) -> Result<f32, GpcError> {
        let small = m.na() <= 2 && m.nb() <= 4;
        let bk = &self.bank[self.cur & 1];
        let mut v = [0.0f32; N];
        // The check row's and the guard row's free responses less w (type docs, "Soft floor").
        let mut x = 0.0f32;
        let mut xg = 0.0f32;
        if self.ready {
            // The free response on the design's own model (type docs, "One model"): its head
            // and the levels through the folded tails for the small models, or the whole f and
            // the whole gain rows.
            let m = &bk.m;
            let probe = if bk.tail_ok {
                let (past, probe) = st.free_window(m, &mut self.f[..bk.split - 1]);
                let d = past.map(|x| x - w);
                for (vi, ci) in v.iter_mut().zip(&bk.c) {
                    *vi = ci[0] * d[0] + ci[1] * d[1] + ci[2] * d[2] + ci[3] * d[3];
                }
                let a = &bk.fa;
                x = a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
                xg = guard_value(d);
                probe
            } else {
                // (A model the tail does not fold for is larger than na ≤ 2, nb ≤ 4.)
                #[cfg(not(feature = "gpc-any-order"))]
                return Err(GpcError::NotBuilt);
                #[cfg(feature = "gpc-any-order")]
                {
                    let (n1, n2, start) = (self.cfg.n1, self.cfg.n2, bk.start);
                    let probe = st.free_response::<MAX_NB, { MAX_NA + 1 }>(m, n2, &mut self.f);
                    for (lj, fj) in bk.l[start - n1..n2 + 1 - n1].iter().zip(&self.f[start - 1..n2]) {
                        let e = w - fj;
                        for (vi, li) in v.iter_mut().zip(lj) {
                            *vi += li * e;
                        }
                    }
                    x = self.f[bk.fj - 1] - w;
                    // (Rows 0, −1, … are y(t), y(t − 1), …: split ≥ 2.)
                    let split = bk.split;
                    xg = guard_value(core::array::from_fn(|r| {
                        (if split > r + 1 { self.f[split - r - 2] } else { st.y[r + 1 - split] }) - w
                    }));
                    probe
                }
            };
            if probe != 0.0 {
                return Err(GpcError::NonFinite);
            }
        }
        let (du, heavy) = if self.ready {
            let (du, heavy) = self.constrain::<N>(&bk.p, &mut v, st.u_prev());
            // The floor, on the plan (the box's, if the limits were at work) unless it cools
            // not at all now, and the stage waits (so that a sample never does both); not on
            // the sample whose stage has waited long enough, which clipped.
            let cools = du > -st.u_prev();
            match if !cools || self.skipped >= MAX_SKIPS {
                None
            } else {
                soft_floor::<N>(bk, x, xg, &v, w, st.u_prev())
            } {
                Some(du) => {
                    self.floors = self.floors.wrapping_add(1);
                    self.floored = true;
                    (du, true)
                }
                None => (du, heavy),
            }
        } else {
            (0.0, false)
        };
        // A sample whose solve met the limits skips its design stage (type docs).
        if heavy {
            self.skipped += 1;
        } else {
            self.skipped = 0;
            self.floored = false;
            if let Err(e) = self.advance::<N>(m, small) {
                self.stage = 0;
                return Err(e);
            }
        }
        if !du.is_finite() {
            return Err(GpcError::NonFinite);
        }
        Ok(du)
    }

    /// Δu(t) of the constrained cost with the design in use (type docs) from the unconstrained
    /// levels `v` relative to u(t−1) = `u_prev`, and whether the limits were at work (the
    /// longer path: the design stage waits); `v` becomes the box's levels then. After
    /// [`MAX_SKIPS`] such samples in a row a level outside the box is clipped instead (v_0 into
    /// the box, and after a floor sample never above the duty before: into [−u(t−1), 0]). `p`
    /// is the design in use's P, which the caller holds (indexing the bank again here costs
    /// 128 B of flash).
    #[inline(always)]
    fn constrain<const N: usize>(&self, p: &[[f32; MAX_NU]; MAX_NU], v: &mut [f32; N], u_prev: f32) -> (f32, bool) {
        let (lo, hi) = (-u_prev, 1.0 - u_prev);
        if v.iter().all(|x| *x >= lo && *x <= hi) {
            return (v[0], false);
        }
        if self.skipped >= MAX_SKIPS {
            // After a floor sample, hold the duty rather than raise it (type docs); (not
            // `f32::clamp`: its assertion formats floats, kilobytes of flash).
            let top = if self.floored { 0.0 } else { hi };
            return (v[0].max(lo).min(top), false);
        }
        *v = box_qp::<N>(p, v, lo, hi);
        (v[0], true)
    }

    /// This sample's stage of the next design, on `N` ≥ Nu levels.
    #[inline(always)]
    fn advance<const N: usize>(&mut self, m: &Model, small: bool) -> Result<(), GpcError> {
        let cfg = self.cfg;
        let (n1, n2, nu) = (cfg.n1, cfg.n2, cfg.nu);
        // (`& 1`: no bounds check.)
        let next = (self.cur ^ 1) & 1;
        match self.stage {
            0 => {
                // (`update` has refused a larger model in a build without `gpc-any-order`.)
                let probe = if small {
                    step_response::<2, 4>(m, n2, &mut self.g)
                } else {
                    #[cfg(feature = "gpc-any-order")]
                    {
                        step_response::<MAX_NA, MAX_NB>(m, n2, &mut self.g)
                    }
                    #[cfg(not(feature = "gpc-any-order"))]
                    return Err(GpcError::NotBuilt);
                };
                if probe != 0.0 {
                    return Err(GpcError::NonFinite);
                }
                self.lead = dead_lead(&self.g, m.k(), n2);
                let nb = &mut self.bank[next];
                nb.m = *m;
                nb.split = fold_split(m, n2);
                nb.tail_ok = small;
                nb.start = n1.max(self.lead + 1).min(n2 + 1);
                floor_row(&m.atilde(), &self.g, nb, n2, nu);
            }
            1 => {
                normal_matrix_into(&self.g, &cfg, self.lead, &mut self.h);
                // Bordered by the identity beyond Nu (type docs). Tested first: `skip` is an
                // out-of-line `nth` call, and at Nu = N there is no border.
                if nu < N {
                    for (r, hr) in self.h.iter_mut().enumerate().take(N).skip(nu) {
                        hr[r] = 1.0;
                    }
                }
            }
            2 => {
                if !cholesky_in_place(&mut self.h, N) {
                    return Err(GpcError::Singular);
                }
                // Z = H⁻¹ column by column (symmetric: its rows are its columns), M = D⁻¹Z
                // (row i the sum of Z's rows 0 … i: D⁻¹ is lower triangular with ones), and
                // P = M D⁻ᵀ, M's prefix sums along each row, bordered by the identity.
                let mut mz = [[0.0f32; MAX_NU]; MAX_NU];
                for (i, zi) in mz.iter_mut().enumerate().take(N) {
                    zi[i] = 1.0;
                    chol_solve(&self.h, N, zi);
                }
                let mut acc = [0.0f32; N];
                let p = &mut self.bank[next].p;
                for (i, (zi, pi)) in mz.iter_mut().zip(p.iter_mut()).enumerate().take(N) {
                    let mut s = 0.0;
                    for (k, ((a, z), pk)) in acc.iter_mut().zip(zi.iter_mut()).zip(pi.iter_mut()).enumerate() {
                        *a += *z;
                        // (The padded levels get no gains: they stay 0.)
                        *z = if i < nu { *a } else { 0.0 };
                        s += *a;
                        *pk = if i < nu && k < nu {
                            s
                        } else if i == k {
                            1.0
                        } else {
                            0.0
                        };
                    }
                }
                // Every level's gain row, and the guard row's weights.
                let nb = &mut self.bank[next];
                level_rows::<N>(&mz, &self.g, &mut nb.l, n1, n2, nb.start);
                guard_row(&self.g, nb, nu);
            }
            _ => {
                // Every level's folded tail (on the design's Ã, the one its samples' f runs on) and
                // its four weights, and the design is complete: in use from the next sample.
                let nb = &mut self.bank[next];
                if nb.tail_ok {
                    nb.c = fold_weights::<N>(&nb.m.atilde(), &nb.l, n1, n2, nb.start, nb.split);
                }
                self.cur = next;
                self.ready = true;
                self.stage = 0;
                return Ok(());
            }
        }
        self.stage += 1;
        Ok(())
    }
}

/// The soft floor ([`GpcStaged`], "Soft floor"), with `x` and `xg` the floor row's and the
/// guard row's free responses less `w` and `v` the plan's levels, within the box, u(t−1) =
/// `u_prev`: if the plan falls below either row, Δu(t) of the problem penalised on the one it
/// falls further below, clipped into the box.
/// (Out of line: inlined, it slowed the whole controller update by a fifth on the M4F,
/// `cargo xtask pil`.)
#[inline(never)]
fn soft_floor<const N: usize>(bk: &StagedBank, x: f32, xg: f32, v: &[f32; N], w: f32, u_prev: f32) -> Option<f32> {
    let (lo, hi) = (-u_prev, 1.0 - u_prev);
    let (mut y, mut yg) = (w + x, w + xg);
    for ((di, gi), vi) in bk.fd.iter().zip(&bk.gd).zip(v) {
        y += di * vi;
        yg += gi * vi;
    }
    // The row the plan violates more.
    let (below, d) = {
        let (fb, gb) = (SOFT_FLOOR_C.min(w - FLOOR_GAP_C) - y, GUARD_ROW_C.min(w - FLOOR_GAP_C) - yg);
        if gb > fb {
            (gb, &bk.gd)
        } else {
            (fb, &bk.fd)
        }
    };
    if !(below > 0.0) {
        return None;
    }
    // Its squared violation weighed ρ in the cost: Q + ρddᵀ, whose inverse is P − γssᵀ
    // (s = Pd, γ = ρ/(1 + ρdᵀs), Sherman–Morrison), so the minimiser moves by
    // γ·(floor − ŷ_j)·s; only its first level is applied.
    let mut s0 = 0.0;
    let mut q = 0.0;
    for (i, (pi, di)) in bk.p.iter().zip(d).take(N).enumerate() {
        let mut si = 0.0;
        for (pk, dk) in pi.iter().zip(d).take(N) {
            si += pk * dk;
        }
        q += di * si;
        if i == 0 {
            s0 = si;
        }
    }
    let du = v[0] + FLOOR_WEIGHT / (1.0 + FLOOR_WEIGHT * q) * below * s0;
    // (Not `f32::clamp`: its assertion formats floats, kilobytes of flash.)
    Some(du.max(lo).min(hi))
}

/// The soft floor's check row j, midway from the fold to N2 (`fj`; the plan's largest
/// undershoot comes a few samples after its first move takes effect, the fold), the free
/// response's weights on f_{split−1−r} − w there (`fa`, [`adjoint_step`] with the row's weight
/// alone: beyond the head, f − w runs on Ã from the window's last three values) and the forced
/// response's on the levels (`fd`: Σ_c g_{j−c}Δũ_c with Δũ = Dv is
/// Σ_i (g_{j−i} − g_{j−i−1}) v_i, the last level held, g_{j−i} alone).
#[inline(always)]
fn floor_row(at: &[f32; MAX_NA + 2], g: &[f32; MAX_N2], bk: &mut StagedBank, n2: usize, nu: usize) {
    let split = bk.split;
    // (split ≤ N2 + 1: the row is at least split − 1, the window's last value.)
    let j = (split + n2) / 2;
    bk.fj = j;
    let mut l = [1.0f32, 0.0, 0.0];
    if j >= split {
        let mut s = 1.0;
        l = [0.0; 3];
        for _ in split..=j {
            l = adjoint_step(at, l, s);
            s = l[0];
        }
    }
    bk.fa = l;
    bk.fd = [0.0; MAX_NU];
    add_forced_weights(g, j, nu, 1.0, &mut bk.fd);
}

/// The guard row's forced response's weights on the levels (`gd`), on rows split − 1 …
/// split − 4 with [`GUARD_ROW_WEIGHTS`] (a row ≤ 0 has no forced response). Made at stage 2
/// with the level rows, not with the floor row at stage 0: g and the split stay as stage 0
/// left them until the design is complete, and stage 0 (the step response and the floor row)
/// was the heaviest of the four (`cargo xtask pil`; the same values).
#[inline(always)]
fn guard_row(g: &[f32; MAX_N2], bk: &mut StagedBank, nu: usize) {
    let split = bk.split;
    bk.gd = [0.0; MAX_NU];
    for (r, wr) in GUARD_ROW_WEIGHTS.iter().enumerate() {
        add_forced_weights(g, split.wrapping_sub(r + 1), nu, *wr, &mut bk.gd);
    }
}

/// Adds `scale` times row j's forced response's weights on the levels to `d`: Σ_c g_{j−c}Δũ_c
/// with Δũ = Dv is Σ_i (g_{j−i} − g_{j−i−1}) v_i, the last level held, g_{j−i} alone (g at an
/// index ≤ 0 is 0; so is every weight of a row j ≤ 0, passed wrapped).
#[inline(never)]
fn add_forced_weights(g: &[f32; MAX_N2], j: usize, nu: usize, scale: f32, d: &mut [f32; MAX_NU]) {
    let mut prev = 0.0;
    for i in (0..nu.min(MAX_NU)).rev() {
        let gi = j.checked_sub(i + 1).and_then(|q| g.get(q)).copied().unwrap_or(0.0);
        d[i] += scale * (gi - prev);
        prev = gi;
    }
}

/// The freeze guard's look-ahead on four consecutive values of a plan, the last first
/// ([`GUARD_ROW_WEIGHTS`]): linear in them, so it applies alike to the predictions, their
/// free responses less w (the weights sum to 1) and their weights on the levels.
#[inline(always)]
fn guard_value(y: [f32; 4]) -> f32 {
    let w = &GUARD_ROW_WEIGHTS;
    w[0] * y[0] + w[1] * y[1] + w[2] * y[2] + w[3] * y[3]
}

/// Every level's gain row L_i[j] = Σ_{c<N} M[i][c] g_{j−c} (g_{≤0} = 0) over j = `start` … N2
/// into `l` (row j − N1; the rows before are left as they were: nothing reads them), in one pass over the rows:
/// the last N g's slide through registers, each a row's N² products.
#[inline(always)]
fn level_rows<const N: usize>(
    m: &[[f32; MAX_NU]; MAX_NU],
    g: &[f32; MAX_N2],
    l: &mut [[f32; MAX_NU]; MAX_N2],
    n1: usize,
    n2: usize,
    start: usize,
) {
    // g_{start−1}, g_{start−2}, … (zero for an index ≤ 0), then each row shifts its own in.
    let mut win = [0.0f32; N];
    for (c, wc) in win.iter_mut().enumerate() {
        if let Some(x) = start.checked_sub(2 + c).and_then(|q| g.get(q)) {
            *wc = *x;
        }
    }
    for (lj, gj) in l[start - n1..n2 + 1 - n1].iter_mut().zip(&g[start - 1..n2]) {
        shift_in(&mut win, *gj);
        for (li, mi) in lj.iter_mut().zip(m).take(N) {
            let mut x = 0.0;
            for (mc, gc) in mi.iter().zip(&win) {
                x += mc * gc;
            }
            *li = x;
        }
    }
}

/// Every level's four weights on f_{split−1−r} − w, r = 0 … 3 ([`GpcStaged`]'s folded tail),
/// from the gain rows `l` (row j − N1, read from `start` on): −L_i[split−1−r] where that row is in
/// the cost, less the folded tail's T_i[r] ([`adjoint_step`] over the rows from
/// `split` on, all levels in one pass).
#[inline(always)]
fn fold_weights<const N: usize>(
    at: &[f32; MAX_NA + 2],
    l: &[[f32; MAX_NU]; MAX_N2],
    n1: usize,
    n2: usize,
    start: usize,
    split: usize,
) -> [[f32; 4]; MAX_NU] {
    let from = split.max(start);
    let rows = if from <= n2 { &l[from - n1..n2 + 1 - n1] } else { &[] };
    let mut lam = [[0.0f32; 3]; N];
    for r in rows.iter().rev() {
        for (li, ri) in lam.iter_mut().zip(r) {
            *li = adjoint_step(at, *li, ri + li[0]);
        }
    }
    // The rows with no weight: the recursion runs on.
    for _ in 0..start.saturating_sub(split) {
        for li in lam.iter_mut() {
            *li = adjoint_step(at, *li, li[0]);
        }
    }
    let mut c = [[0.0f32; 4]; MAX_NU];
    for (r, cr) in (0..4).zip(0..) {
        // Row split − 1 − r (≥ 1 or not in the cost), before N2.
        let j = split.wrapping_sub(1 + r);
        let head = if j >= start && j <= n2 { l.get(j - n1) } else { None };
        for (i, (ci, li)) in c.iter_mut().zip(&lam).enumerate() {
            let h = head.map_or(0.0, |row| row[i]);
            ci[cr] = -h - li.get(r).copied().unwrap_or(0.0);
        }
    }
    c
}

/// The free response's tail into `f` (f_split … f_N2), from the head's last values `past`:
/// f_j = −Σ ã_i f_{j−i}. Returns its finiteness probe.
#[inline(always)]
fn free_tail<const NH: usize>(at: &[f32; MAX_NA + 2], mut past: [f32; NH], f: &mut [f32]) -> f32 {
    let mut probe = 0.0f32;
    for fj in f.iter_mut() {
        let mut v = 0.0;
        for (ai, yp) in at[1..].iter().zip(&past) {
            v -= ai * yp;
        }
        probe += finite_probe(v);
        shift_in(&mut past, v);
        *fj = v;
    }
    probe
}

/// Where the free response's head ends: the first j ≥ 1 at which no past increment (j < k + nb)
/// and no past residual (j ≤ nc) enters, capped at N2 + 1.
#[inline(always)]
fn head_end<const NB: usize>(m: &Model, n2: usize) -> usize {
    (m.k() + m.nb().min(NB)).max(m.nc().min(MAX_NC) + 1).min(n2 + 1)
}

/// One step of the adjoint that folds a weight row's share of the free response's tail onto
/// the values it starts from ([`fold_weights`]). Beyond the head the free response runs alone,
/// x_j = −Σ_i ã_{i+1} P_j[i] with P_j = (x_{j−1}, x_{j−2}, x_{j−3}) (and so does x = f − w:
/// Ã(1) = 0), so Σ_{j = split…N2} r_j x_j = σ·P_split for the σ of the adjoint recursion run
/// backwards from j = N2: λ ← 0, then for each j λ_i ← −ã_{i+1} (r_j + λ_0) + λ_{i+1}
/// (λ_3 = 0), and σ = λ at j = split; `s` is r_j + λ_0 (r_j = 0 on the rows known to be
/// zero: the dead time's and those before N1). Three products a row, computed once a design,
/// instead of the row's four every sample (three for f_j, one for its weight).
#[inline(always)]
fn adjoint_step(at: &[f32; MAX_NA + 2], lam: [f32; 3], s: f32) -> [f32; 3] {
    [-at[1] * s + lam[1], -at[2] * s + lam[2], -at[3] * s]
}

/// Where [`GpcStaged`] folds the tail in, for the small models: after the longest head any of
/// them has (nb ≤ 4, nc ≤ 2 < k + 4), so that it depends on the delay alone and an estimate
/// with more or fewer B terms than the model before it (the self-tuner's start model has two,
/// its estimate four) folds at the same place.
#[inline(always)]
fn fold_split(m: &Model, n2: usize) -> usize {
    (m.k() + 4).max(MAX_NC + 1).min(n2 + 1)
}

/// The soft lower output bound (issue 15), °C: the freeze guard's release level
/// (`FreezeConfig::DEFAULT.release_c`), so that the plan keeps the load where the guard would let
/// cooling resume ([`GpcStaged`], "Soft floor"). Never closer than [`FLOOR_GAP_C`] below the setpoint.
pub const SOFT_FLOOR_C: f32 = 2.5;

/// The freeze guard's prediction (`supervisor::freeze`: the reading plus its smoothed slope
/// times the look-ahead) as weights on four consecutive predictions ŷ_j, ŷ_{j−1}, ŷ_{j−2},
/// ŷ_{j−3} ([`GpcStaged`], "Soft floor"): ŷ_j + L·s_j with L the look-ahead in samples
/// (`FreezeConfig::DEFAULT`: 120 s at the board's Ts of 10 s, 12) and s_j the guard's
/// smoothing of the slope (memory m = 0.7: the last three differences weighted (1 − m)·mⁱ),
/// truncated to the three differences the four values give and scaled back to a slope.
pub const GUARD_ROW_WEIGHTS: [f32; 4] = guard_row_weights(12.0, 0.7);

const fn guard_row_weights(l: f32, m: f32) -> [f32; 4] {
    let (a, b, c) = (1.0 - m, (1.0 - m) * m, (1.0 - m) * m * m);
    let n = a + b + c;
    let (a, b, c) = (l * a / n, l * b / n, l * c / n);
    [1.0 + a, b - a, c - b, -c]
}

/// The level the soft floor's guard row keeps the plan's guard prediction above, °C: 0.5 °C
/// above the freeze guard's cut (`FreezeConfig::DEFAULT.cut_c`, 1.5 °C), for the model's
/// error on a fast descent ([`GpcStaged`], "Soft floor"); never closer than [`FLOOR_GAP_C`] below
/// the setpoint, as the floor row (the same level for every setpoint the board accepts, 2.5 °C
/// and up). `scripts/targets.sh`: the half load at 20 °C (seeds 1–8) trips the guard with the
/// level at 1.5–1.7 °C (8, 7 and 3 trips), not from 1.8.
pub const GUARD_ROW_C: f32 = 2.0;

/// How far the soft floor stays below the setpoint, °C: a setpoint of 2.5 °C, the lowest the
/// board accepts, gets a floor at 2.0 °C, and no setpoint has its steady state pushed up.
pub const FLOOR_GAP_C: f32 = 0.5;

/// ρ, the weight of the floor's squared violation against the cost's squared errors (1 a row):
/// with the step responses of the carriers (tens of °C per unit duty over 30 rows) the plan
/// keeps a few percent of the violation it would otherwise have.
const FLOOR_WEIGHT: f32 = 1000.0;

/// Most samples in a row whose constrained solve skips [`GpcStaged`]'s design stage; the next
/// clips instead and does its stage.
const MAX_SKIPS: u8 = 8;

/// min ½vᵀQv − cᵀv over lo ≤ v_i ≤ hi (i < N), Q symmetric positive definite, given P = Q⁻¹
/// and the unconstrained minimiser `unc` = P c, by the primal active-set method (Nocedal &
/// Wright, *Numerical Optimization*, 2nd ed., Alg. 16.3) from `unc` clamped into the box, with
/// the bounds it touches as the first working set W.
///
/// The equality-constrained problem of W (v_W = t_W) is solved through P: its minimiser is
/// y = P(c + E_W μ) = unc + P_{:W} μ with P_WW μ = t_W − unc_W, and μ = (Qy − c)_W is then the
/// gradient on the held bounds, their multipliers. P_WW is factored bordered by the identity
/// (rows and columns of the free levels replaced by those of I, right-hand side 0 there): an
/// N×N Cholesky factor of fixed size, which unrolls, whose free entries come out exact zeros.
/// Each iteration either steps to y, or stops at the first bound in the way and holds it; at y
/// it drops the held bound whose multiplier has the wrong sign (μ > 0 at hi: the cost falls
/// below it; μ < 0 at lo), the worst first, or stops. Each iteration adds or drops a bound,
/// and with N ≤ 5 levels the optimum is reached in far fewer than 2N (the tests enumerate
/// every active set); every iterate is feasible, so running out returns a feasible, if not
/// optimal, plan.
#[inline(never)]
fn box_qp<const N: usize>(p: &[[f32; MAX_NU]; MAX_NU], unc: &[f32; N], lo: f32, hi: f32) -> [f32; N] {
    let mut v = *unc;
    let mut held = [false; N];
    for (vi, h) in v.iter_mut().zip(&mut held) {
        if *vi > hi {
            *vi = hi;
            *h = true;
        } else if *vi < lo {
            *vi = lo;
            *h = true;
        }
    }
    for _ in 0..2 * N {
        // P_WW bordered by I, and t_W − unc_W (0 on the free levels).
        let mut a = [[0.0f32; MAX_NU]; MAX_NU];
        let mut mu = [0.0f32; MAX_NU];
        for r in 0..N {
            if held[r] {
                mu[r] = v[r] - unc[r];
                for s in 0..r {
                    if held[s] {
                        a[r][s] = p[r][s];
                    }
                }
                a[r][r] = p[r][r];
            } else {
                a[r][r] = 1.0;
            }
        }
        if !cholesky_in_place(&mut a, N) {
            return v;
        }
        chol_solve(&a, N, &mut mu);
        let mut y = *unc;
        for (yi, pi) in y.iter_mut().zip(p) {
            for (pk, mk) in pi.iter().zip(&mu).take(N) {
                *yi += pk * mk;
            }
        }
        for ((yi, vi), h) in y.iter_mut().zip(&v).zip(&held) {
            if *h {
                *yi = *vi;
            }
        }
        // The longest step toward y that stays in the box, and the level that stops it.
        let (mut alpha, mut block) = (1.0f32, N);
        for (i, (yi, vi)) in y.iter().zip(&v).enumerate() {
            let to = if *yi > hi {
                hi
            } else if *yi < lo {
                lo
            } else {
                continue;
            };
            let t = (to - vi) / (yi - vi);
            if t < alpha {
                (alpha, block) = (t, i);
            }
        }
        if block < N {
            for (vi, yi) in v.iter_mut().zip(&y) {
                *vi += alpha * (yi - *vi);
            }
            v[block] = if y[block] > hi { hi } else { lo };
            held[block] = true;
            continue;
        }
        v = y;
        // Release the held bound whose multiplier has the worst wrong sign, or stop.
        let (mut worst, mut drop) = (0.0f32, N);
        for (i, ((vi, m), h)) in v.iter().zip(&mu).zip(&held).enumerate() {
            let wrong = if *vi == hi { *m } else { -*m };
            if *h && wrong > worst {
                (worst, drop) = (wrong, i);
            }
        }
        if drop == N {
            return v;
        }
        held[drop] = false;
    }
    v
}

/// The number of exact zeros g_1 … g_lead that open the step response (the dead time).
#[inline(always)]
fn dead_lead(g: &[f32; MAX_N2], k: usize, n2: usize) -> usize {
    let mut lead = (k - 1).min(n2);
    while lead < n2 && g[lead] == 0.0 {
        lead += 1;
    }
    lead
}

/// z = H⁻¹ e₁ for H = GᵀG + λI (the first row of H⁻¹Gᵀ is then k1_j = Σ_c z_c G[j][c], see
/// [`gain_row`]): one Cholesky factorisation of `h` (its lower triangle, [`normal_matrix`]) and
/// one solve.
#[inline(always)]
fn first_row_solve(mut h: [[f32; MAX_NU]; MAX_NU], nu: usize) -> Result<[f32; MAX_NU], GpcError> {
    if !cholesky_in_place(&mut h, nu) {
        return Err(GpcError::Singular);
    }
    let mut z = [0.0f32; MAX_NU];
    z[0] = 1.0;
    chol_solve(&h, nu, &mut z);
    Ok(z)
}

/// The step response g_1…g_N2 of q^−k B/A into `g`, A and B zero-padded to `NA` ≥ na and
/// `NB` ≥ nb coefficients; returns the finiteness probe Σ (g − g).
#[inline(always)]
fn step_response<const NA: usize, const NB: usize>(m: &Model, n2: usize, g: &mut [f32; MAX_N2]) -> f32 {
    let na = m.na().min(NA);
    let nb = m.nb().min(NB);
    // (Element by element: a run-time-length copy is a memcpy call on the M4.)
    let a: [f32; NA] = core::array::from_fn(|i| if i < na { m.a()[i] } else { 0.0 });
    let b: [f32; NB] = core::array::from_fn(|i| if i < nb { m.b()[i] } else { 0.0 });
    // Step response of q^−k B/A: y(j) = −Σ a_i y(j−i) + Σ b_i u(j−k−i), u = 1 from j = 0;
    // y(j ≤ 0) = 0. From j = k + nb − 1 on every b_i is in (the padded zeros add +0), so
    // that part needs no comparisons.
    let mut past = [0.0f32; NA]; // y(j−1), y(j−2), …
    let steady = (m.k() + nb).saturating_sub(1).clamp(1, n2 + 1);
    let (head, tail) = g[..n2].split_at_mut(steady - 1);
    for (idx, gj) in head.iter_mut().enumerate() {
        let j = idx + 1;
        let mut v = 0.0;
        for (ai, yp) in a.iter().zip(&past) {
            v -= ai * yp;
        }
        for (i, bi) in b.iter().enumerate() {
            if j >= m.k() + i {
                v += bi;
            }
        }
        shift_in(&mut past, v);
        *gj = v;
    }
    for gj in tail.iter_mut() {
        let mut v = 0.0;
        for (ai, yp) in a.iter().zip(&past) {
            v -= ai * yp;
        }
        for bi in &b {
            v += bi;
        }
        shift_in(&mut past, v);
        *gj = v;
    }
    // The last value is finite only if every g_j is ([`recursion_probe`]).
    recursion_probe(past[0])
}

/// The finiteness probe of a whole recursion from its last value: +0 when every value it made
/// is finite, NaN otherwise, as the sum of every value's [`finite_probe`] would be. Each
/// value of the recursions it serves enters the next one through a product with a finite
/// coefficient (Ã's, A's, zero included) added to finite terms, and ±∞ or NaN times a finite
/// number is ±∞ or NaN, and stays so through a sum: one non-finite value makes every later
/// one non-finite, down to the last. One probe instead of one a row: 2 instructions a row, on
/// the free response every sample (`cargo xtask pil`).
#[inline(always)]
fn recursion_probe(last: f32) -> f32 {
    finite_probe(last)
}

/// The lower triangle of H = GᵀG + λI (all the Cholesky factorisation reads) for rows j = N1..N2 of
/// G[j][c] = g_{j−c} (g_0 = 0): H[r][c] = λδ_rc + Σ_{j = max(N1, r+1)..N2} g_{j−r} g_{j−c},
/// summed in increasing j, for r ≥ c.
///
/// With N1 = 1 the sums of one band r − c = δ are prefixes of each other (row r + 1 has the
/// terms of row r but the last), so each band is summed once, from the shortest row up: N2·Nu
/// products instead of N2·Nu², with the same additions in the same order. The first `lead`
/// g's are exact zeros (dead time); their products are skipped there.
#[inline(always)]
fn normal_matrix(g: &[f32; MAX_N2], cfg: &GpcConfig, lead: usize) -> [[f32; MAX_NU]; MAX_NU] {
    let mut h = [[0.0f32; MAX_NU]; MAX_NU];
    normal_matrix_into(g, cfg, lead, &mut h);
    h
}

/// [`normal_matrix`] written into `h` (zeroed first): the staged design's stage 1 makes it in
/// its own `h`, without a copy of the matrix through the stack (≈ 120 instructions a design).
#[inline(always)]
fn normal_matrix_into(g: &[f32; MAX_N2], cfg: &GpcConfig, lead: usize, h: &mut [[f32; MAX_NU]; MAX_NU]) {
    let (n1, n2, nu) = (cfg.n1, cfg.n2, cfg.nu);
    *h = [[0.0f32; MAX_NU]; MAX_NU];
    if n1 == 1 {
        for band in 0..nu {
            let mut s = if band == 0 { cfg.lambda } else { 0.0 };
            // Row r sums g[p]·g[p + band] (0-based g, g[p] = g_{p+1}) for p = 0..n2 − r.
            let last = nu - 1;
            // Terms with p < lead are products with an exact zero g[p]: skipped.
            let p0 = lead.min(n2 - last);
            for (x, y) in g[p0..n2 - last].iter().zip(&g[p0 + band..n2 - last + band]) {
                s += x * y;
            }
            h[last][last - band] = s;
            for r in (band..last).rev() {
                let p = n2 - r - 1;
                s += g[p] * g[p + band];
                h[r][r - band] = s;
            }
        }
    } else {
        for r in 0..nu {
            for c in 0..=r {
                let mut s = if r == c { cfg.lambda } else { 0.0 };
                let lo = n1.max(r + 1);
                if lo <= n2 {
                    s = dot_from(s, &g[lo - r - 1..n2 - r], &g[lo - c - 1..n2 - c]);
                }
                h[r][c] = s;
            }
        }
    }
}

/// k1_j = Σ_{c<Nu} z_c G[j][c] for j = N1…N2 into `d.k1`, summed in the textbook order (k1_j
/// from 0.0 over c = 0, 1, …). Nu is a constant so the sum over c unrolls; G[j][c] = g_{j−c} is
/// zero for c ≥ j, and those terms are skipped (rows j < Nu only). Returns the first row that
/// is not an exact zero (rows j ≤ lead see only the dead time's zero g's: k1_j = +0).
#[inline(always)]
fn gain_row<const NU: usize>(
    z: &[f32; MAX_NU],
    g: &[f32; MAX_N2],
    k1: &mut [f32; MAX_N2],
    n1: usize,
    n2: usize,
    lead: usize,
) -> usize {
    let start = n1.max(lead + 1).min(n2 + 1);
    for kj in &mut k1[..start - n1] {
        *kj = 0.0;
    }
    let first_full = NU.max(start); // from this j on every c < Nu has g_{j−c} with j − c ≥ 1
    for j in start..first_full.min(n2 + 1) {
        let mut kj = 0.0;
        for (c, zc) in z[..NU].iter().enumerate() {
            if j > c {
                kj += zc * g[j - c - 1];
            }
        }
        k1[j - n1] = kj;
    }
    for j in first_full..n2 + 1 {
        let mut kj = 0.0;
        // z_0 g_j, z_1 g_{j−1}, …: the window holds g_{j−NU+1} … g_j.
        for (zc, gv) in z[..NU].iter().zip(g[j - NU..j].iter().rev()) {
            kj += zc * gv;
        }
        k1[j - n1] = kj;
    }
    start
}

/// [`gain_row`] for the run-time Nu, the one both [`GpcState::design_into`] and [`GpcStaged`]
/// call: the default Nu = 3 gets its own unrolled copy (the staged gain row is the largest
/// stage of the board's sample, `cargo xtask pil`), every other Nu the `MAX_NU` copy. z is zero
/// beyond Nu ([`first_row_solve`]), so the padded terms add ±0 to sums that are not −0: the
/// same bits as `gain_row::<Nu>`.
fn gain_row_nu(
    z: &[f32; MAX_NU],
    g: &[f32; MAX_N2],
    k1: &mut [f32; MAX_N2],
    n1: usize,
    n2: usize,
    nu: usize,
    lead: usize,
) -> usize {
    if nu == 3 {
        gain_row::<3>(z, g, k1, n1, n2, lead)
    } else {
        gain_row::<MAX_NU>(z, g, k1, n1, n2, lead)
    }
}

/// Δu = Σ_j k1_j (w − f_j) over j = `start` … N2, in increasing j from 0.0 (the rows before
/// `start` have k1_j = +0 and would add ±0).
#[inline(always)]
fn increment(d: &GpcDesign, n1: usize, n2: usize, start: usize, w: f32) -> f32 {
    let mut du = 0.0;
    for (kj, fj) in d.k1[start - n1..=n2 - n1].iter().zip(&d.f[start - 1..n2]) {
        du += kj * (w - fj);
    }
    du
}

/// Lower Cholesky factor of the leading n×n block, computed in place over the lower triangle
/// of `h` (each entry is read before it is overwritten); false if not positive definite.
/// Inlined: with a constant n ([`GpcStaged`]'s stages and [`box_qp`]) it unrolls.
#[inline(always)]
fn cholesky_in_place(h: &mut [[f32; MAX_NU]; MAX_NU], n: usize) -> bool {
    for i in 0..n {
        for j in 0..=i {
            let mut s = h[i][j];
            for p in 0..j {
                s -= h[i][p] * h[j][p];
            }
            if i == j {
                if !(s > 1e-12) {
                    return false;
                }
                h[i][i] = sqrtf(s);
            } else {
                h[i][j] = s / h[j][j];
            }
        }
    }
    true
}

/// Solves L Lᵀ x = b in place (L in the lower triangle).
#[inline(always)]
fn chol_solve(l: &[[f32; MAX_NU]; MAX_NU], n: usize, b: &mut [f32; MAX_NU]) {
    for i in 0..n {
        let mut s = b[i];
        for p in 0..i {
            s -= l[i][p] * b[p];
        }
        b[i] = s / l[i][i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for p in i + 1..n {
            s -= l[p][i] * b[p];
        }
        b[i] = s / l[i][i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent f64 reference: build G explicitly and solve the normal equations by
    /// Gaussian elimination.
    fn reference_k1(g: &[f64], n1: usize, n2: usize, nu: usize, lambda: f64) -> Vec<f64> {
        let rows = n2 - n1 + 1;
        let gm = |j: usize, c: usize| if j > c { g[j - c - 1] } else { 0.0 };
        let mut h = vec![vec![0.0; nu]; nu];
        for r in 0..nu {
            for c in 0..nu {
                h[r][c] = (n1..=n2).map(|j| gm(j, r) * gm(j, c)).sum::<f64>() + if r == c { lambda } else { 0.0 };
            }
        }
        // inverse of h by Gauss–Jordan
        let mut a: Vec<Vec<f64>> = h.to_vec();
        let mut inv = vec![vec![0.0; nu]; nu];
        for i in 0..nu {
            inv[i][i] = 1.0;
        }
        for i in 0..nu {
            let p = a[i][i];
            for c in 0..nu {
                a[i][c] /= p;
                inv[i][c] /= p;
            }
            for r in 0..nu {
                if r != i {
                    let f = a[r][i];
                    for c in 0..nu {
                        a[r][c] -= f * a[i][c];
                        inv[r][c] -= f * inv[i][c];
                    }
                }
            }
        }
        (0..rows).map(|jj| (0..nu).map(|c| inv[0][c] * gm(n1 + jj, c)).sum()).collect()
    }

    /// The textbook loops of the design (every term of every sum, G built by index), as the
    /// design was first written: the optimised `design` must give the same bits.
    fn textbook_design(
        s: &GpcState,
        m: &Model,
        cfg: &GpcConfig,
        w: f32,
    ) -> ([f32; MAX_N2], [f32; MAX_N2], [f32; MAX_N2], f32) {
        let n2 = cfg.n2;
        let (mut g, mut f, mut k1) = ([0.0f32; MAX_N2], [0.0f32; MAX_N2], [0.0f32; MAX_N2]);
        let mut ys = [0.0f32; MAX_N2 + 1];
        for j in 1..=n2 {
            let mut v = 0.0;
            for i in 1..=m.na() {
                if let Some(yp) = j.checked_sub(i).and_then(|x| ys.get(x)) {
                    v -= m.a()[i - 1] * yp;
                }
            }
            for i in 0..m.nb() {
                if j >= m.k() + i {
                    v += m.b()[i];
                }
            }
            ys[j] = v;
            g[j - 1] = v;
        }
        let at = m.atilde();
        let mut yy = [0.0f32; HY + MAX_N2];
        for i in 0..HY {
            yy[HY - 1 - i] = s.y[i];
        }
        for j in 1..=n2 {
            let mut v = 0.0;
            for i in 1..=m.na() + 1 {
                v -= at[i] * yy[HY - 1 + j - i];
            }
            for i in 0..m.nb() {
                if m.k() + i > j {
                    v += m.b()[i] * s.du_past(m.k() + i - j);
                }
            }
            for i in j..=m.nc() {
                v += m.c()[i - 1] * s.e[i - j];
            }
            yy[HY - 1 + j] = v;
            f[j - 1] = v;
        }
        let nu = cfg.nu;
        let gjc = |j: usize, c: usize| if j > c { g[j - c - 1] } else { 0.0 };
        let mut h = [[0.0f32; MAX_NU]; MAX_NU];
        for (r, row) in h.iter_mut().enumerate().take(nu) {
            for (c, hrc) in row.iter_mut().enumerate().take(nu) {
                let mut acc = if r == c { cfg.lambda } else { 0.0 };
                for j in cfg.n1..=n2 {
                    acc += gjc(j, r) * gjc(j, c);
                }
                *hrc = acc;
            }
        }
        assert!(cholesky_in_place(&mut h, nu));
        let mut z = [0.0f32; MAX_NU];
        z[0] = 1.0;
        chol_solve(&h, nu, &mut z);
        let mut du = 0.0;
        for j in cfg.n1..=n2 {
            let mut kj = 0.0;
            for (c, zc) in z.iter().enumerate().take(nu) {
                kj += zc * gjc(j, c);
            }
            k1[j - cfg.n1] = kj;
            du += kj * (w - f[j - 1]);
        }
        (g, f, k1, du)
    }

    #[test]
    fn design_is_bit_for_bit_the_textbook_loops() {
        let models = [
            Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.029_865], &[], 5).unwrap(),
            Model::new(&[-1.8, 0.81], &[-0.02, -0.01], &[], 1).unwrap(),
            Model::new(&[-0.8], &[0.4, 0.6], &[0.5], 1).unwrap(),
            Model::new(&[-2.8, 2.86, -1.26, 0.2025], &[0.1, -0.05, 0.02, 0.01], &[-0.3, 0.1], 3).unwrap(),
            Model::new(&[-1.5, 0.56], &[-0.03], &[0.2], 10).unwrap(),
        ];
        let cfgs = [
            GpcConfig::DEFAULT,
            GpcConfig { n1: 1, n2: 3, nu: 3, lambda: 0.8 },
            GpcConfig { n1: 3, n2: 20, nu: 2, lambda: 1.0 },
            GpcConfig { n1: 1, n2: 30, nu: 5, lambda: 0.1 },
            GpcConfig { n1: 2, n2: 12, nu: 1, lambda: 3.0 },
        ];
        for m in &models {
            let mut s = GpcState::new(0.4);
            for (t, y) in [4.3f32, 4.25, 4.31, 4.1, 3.95, 4.02, 4.0, 3.97].iter().enumerate() {
                s.push_y(*y, m).unwrap();
                s.track(0.4 + 0.05 * (t % 3) as f32);
            }
            s.push_y(3.99, m).unwrap();
            for cfg in &cfgs {
                let (g, f, k1, du) = textbook_design(&s, m, cfg, 4.0);
                let d = s.design(m, cfg, 4.0).unwrap();
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&d.g), bits(&g), "g, {m:?} {cfg:?}");
                assert_eq!(bits(&d.f), bits(&f), "f, {m:?} {cfg:?}");
                assert_eq!(bits(&d.k1), bits(&k1), "k1, {m:?} {cfg:?}");
                assert_eq!(d.du.to_bits(), du.to_bits(), "du, {m:?} {cfg:?}");
            }
        }
    }

    /// A reprimed state's prediction depends on its Δu history and the next measurement only:
    /// a history of spikes (54 °C, a restart's first reading) and one of good readings give the
    /// same design after it, bit for bit, also through a noise model (ê's history is cleared).
    #[test]
    fn a_reprimed_state_forgets_every_measurement_before_it() {
        let m = Model::new(&[-0.8], &[-0.4, -0.6], &[0.5], 1).unwrap();
        let fed = |ys: &[f32]| {
            let mut s = GpcState::new(0.4);
            for (t, y) in ys.iter().enumerate() {
                s.push_y(*y, &m).unwrap();
                s.track(0.4 + 0.1 * (t % 2) as f32);
            }
            s
        };
        let (mut spiked, mut good) = (fed(&[4.0, 54.0, 54.0, 4.1]), fed(&[4.0, 4.02, 3.98, 4.1]));
        let design = |s: &GpcState| s.design(&m, &GpcConfig::DEFAULT, 4.0).unwrap();
        spiked.push_y(4.05, &m).unwrap();
        good.push_y(4.05, &m).unwrap();
        assert_ne!(design(&spiked).f, design(&good).f, "the spike is in the prediction");
        for s in [&mut spiked, &mut good] {
            s.reprime();
            s.push_y(4.05, &m).unwrap();
        }
        assert_eq!(spiked, good);
        let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&design(&spiked).f), bits(&design(&good).f));
        // At rest: the free response is the measurement carried on by the past increments alone.
        let mut rest = GpcState::new(0.4);
        rest.push_y(4.05, &m).unwrap();
        rest.track(0.4);
        rest.reprime();
        rest.push_y(4.05, &m).unwrap();
        let f = design(&rest).f;
        assert!(f.iter().take(GpcConfig::DEFAULT.n2).all(|f| (f - 4.05).abs() < 1e-4), "{f:?}");
    }

    #[test]
    fn step_response_and_gains_match_an_independent_f64_solution() {
        let m = Model::new(&[-1.8, 0.81], &[-0.02, -0.01], &[], 1).unwrap();
        let cfg = GpcConfig { n1: 1, n2: 30, nu: 3, lambda: 0.1 };
        let mut s = GpcState::new(0.4);
        s.push_y(4.0, &m).unwrap();
        let d = s.design(&m, &cfg, 4.0).unwrap();
        // Step response by direct simulation in f64.
        let mut y = vec![0.0f64; 32];
        for j in 1..=30 {
            let mut v = 1.8 * y[j - 1] - if j >= 2 { 0.81 * y[j - 2] } else { 0.0 };
            v += -0.02 + if j >= 2 { -0.01 } else { 0.0 };
            y[j] = v;
        }
        for j in 1..=30 {
            assert!((f64::from(d.g[j - 1]) - y[j]).abs() < 1e-4 * y[j].abs().max(1e-3), "g{j}");
        }
        let k1 = reference_k1(&y[1..], 1, 30, 3, 0.1);
        for (j, r) in k1.iter().enumerate() {
            assert!((f64::from(d.k1[j]) - r).abs() < 2e-3 * r.abs().max(1e-2), "k1[{j}] {} vs {r}", d.k1[j]);
        }
        // At rest at the setpoint the free response is flat and the increment is zero.
        assert!(d.f[..30].iter().all(|f| (f - 4.0).abs() < 1e-5));
        assert!(d.du.abs() < 1e-5);
    }

    #[test]
    fn a_recursion_that_overflows_anywhere_is_refused_by_its_last_value() {
        // An unstable A that reaches f32's range early (row 3 of 30) and then keeps every later
        // row non-finite: ±∞, and NaN once ∞ − ∞ or 0·∞ meets it. The one probe of the last
        // value must say what a probe of every row would.
        for (a, b) in
            [(vec![-1e20f32], vec![-1.0f32]), (vec![-1e20, 1e20], vec![-1.0, 2.0]), (vec![0.5, -1e25], vec![-0.1])]
        {
            let m = Model::new(&a, &b, &[], 1).unwrap();
            let mut g = [0.0f32; MAX_N2];
            let probe = step_response::<2, 4>(&m, 30, &mut g);
            assert!(g[..30].iter().any(|x| !x.is_finite()), "a {a:?}: the test's model overflows");
            assert!(probe.is_nan(), "a {a:?}: step response probe {probe}, g {:?}", &g[..6]);
            let mut s = GpcState::new(0.0);
            s.push_y(1.0, &m).unwrap();
            let mut f = [0.0f32; 30];
            let (_, probe) = s.free_window(&m, &mut f);
            assert!(f.iter().any(|x| !x.is_finite()), "a {a:?}: the free response overflows");
            assert!(probe.is_nan(), "a {a:?}: free response probe {probe}");
        }
        // Finite throughout: exactly +0.
        let m = Model::second_order([-1.8, 0.81], [-0.05, -0.02], 3).unwrap();
        let mut g = [0.0f32; MAX_N2];
        assert_eq!(step_response::<2, 4>(&m, 30, &mut g).to_bits(), 0);
        let mut s = GpcState::new(0.0);
        s.push_y(4.0, &m).unwrap();
        assert_eq!(s.free_window(&m, &mut [0.0f32; 30]).1.to_bits(), 0);
    }

    #[test]
    fn free_response_continues_a_past_increment() {
        // First-order y(t) = 0.9 y(t−1) + 0.1 u(t−1): after Δu(t−1) = 1 from rest, the free
        // response is the remainder of that step: f_j = 1 − 0.9^{j+1}.
        let m = Model::new(&[-0.9], &[0.1], &[], 1).unwrap();
        let mut s = GpcState::new(0.0);
        s.push_y(0.0, &m).unwrap();
        s.track(1.0); // u(t−1) = 1
        s.push_y(0.1, &m).unwrap(); // y(t) = 0.1
        let d = s.design(&m, &GpcConfig { n1: 1, n2: 10, nu: 1, lambda: 1.0 }, 0.0).unwrap();
        for j in 1..=10 {
            let want = 1.0 - 0.9f32.powi(j as i32 + 1);
            assert!((d.f[j - 1] - want).abs() < 1e-5, "f{j} = {} want {want}", d.f[j - 1]);
        }
    }

    /// Camacho & Bordons, *Model Predictive Control* (2nd ed., 2007), §4.2, worked example:
    /// (1 − 0.8 z⁻¹) y(t) = (0.4 + 0.6 z⁻¹) u(t−1) + e(t)/Δ, N1 = 1, N2 = Nu = 3, λ = 0.8.
    /// Published: G = [0.4; 1.32; 2.056] (lower-triangular Toeplitz), F1 = 1.8 − 0.8 z⁻¹,
    /// F2 = 2.44 − 1.44 z⁻¹, F3 = 2.952 − 1.952 z⁻¹, and the control law
    /// Δu(t) = −0.6042 Δu(t−1) − 1.371 y(t) + 0.805 y(t−1) + 0.1334 w(t+1) + 0.2861 w(t+2) + 0.1474 w(t+3).
    #[test]
    fn camacho_bordons_worked_example() {
        let m = Model::new(&[-0.8], &[0.4, 0.6], &[], 1).unwrap();
        let cfg = GpcConfig { n1: 1, n2: 3, nu: 3, lambda: 0.8 };
        // G and K from a state at rest.
        let mut s = GpcState::new(0.0);
        s.push_y(0.0, &m).unwrap();
        let d = s.design(&m, &cfg, 0.0).unwrap();
        for (g, want) in d.g.iter().zip([0.4, 1.32, 2.056]) {
            assert!((g - want).abs() < 1e-5, "g = {:?}", &d.g[..3]);
        }
        for (k, want) in d.k1.iter().zip([0.1334, 0.2861, 0.1474]) {
            assert!((k - want).abs() < 5e-4, "k1 = {:?}", &d.k1[..3]);
        }
        // The Diophantine F_j for Ã = 1 − 1.8 z⁻¹ + 0.8 z⁻².
        for (j, want) in [(1, [1.8, -0.8]), (2, [2.44, -1.44]), (3, [2.952, -1.952])] {
            let sol = crate::control::diophantine::solve(&[1.0, -1.8, 0.8], &[1.0], j).unwrap();
            assert!((sol.f[0] - want[0]).abs() < 1e-5 && (sol.f[1] - want[1]).abs() < 1e-5, "F{j}");
        }
        // The control law's coefficients, probed one past value at a time (the law is linear):
        // history (oldest first) of y, with Δu(t−1) applied before the last sample.
        let probe = |ys: &[f32], du_t1: f32| {
            let mut s = GpcState::new(0.0);
            for (i, y) in ys.iter().enumerate() {
                if i + 1 == ys.len() {
                    s.track(du_t1);
                }
                s.push_y(*y, &m).unwrap();
            }
            s.design(&m, &cfg, 0.0).unwrap().du
        };
        let c_y = probe(&[0.0, 1.0], 0.0);
        let c_y1 = probe(&[0.0, 1.0, 0.0], 0.0);
        let c_du = probe(&[0.0, 0.0], 1.0);
        assert!((c_y + 1.371).abs() < 2e-3, "y(t) coefficient {c_y}");
        assert!((c_y1 - 0.805).abs() < 2e-3, "y(t−1) coefficient {c_y1}");
        assert!((c_du + 0.6042).abs() < 2e-3, "Δu(t−1) coefficient {c_du}");
    }

    /// Δu of the whole design in f64 from the state's histories: the step response and free
    /// response by their recursions, the gain row by [`reference_k1`].
    fn reference_du(s: &GpcState, m: &Model, cfg: &GpcConfig, w: f32) -> f64 {
        let (n1, n2) = (cfg.n1, cfg.n2);
        let (g, f) = reference_gf(s, m, n2);
        let k1 = reference_k1(&g[1..], n1, n2, cfg.nu, f64::from(cfg.lambda));
        k1.iter().enumerate().map(|(jj, k)| k * (f64::from(w) - f[n1 + jj])).sum()
    }

    /// The step response g_0 = 0, g_1 … g_N2 and the free response f_0 = 0, f_1 … f_N2 in f64
    /// from the state's histories, by their recursions.
    fn reference_gf(s: &GpcState, m: &Model, n2: usize) -> (Vec<f64>, Vec<f64>) {
        let a: Vec<f64> = m.a()[..m.na()].iter().map(|&x| f64::from(x)).collect();
        let b: Vec<f64> = m.b()[..m.nb()].iter().map(|&x| f64::from(x)).collect();
        let mut g = vec![0.0f64; n2 + 1];
        for j in 1..=n2 {
            let mut v = 0.0;
            for (i, ai) in a.iter().enumerate() {
                v -= ai * if j > i + 1 { g[j - i - 1] } else { 0.0 };
            }
            for (i, bi) in b.iter().enumerate() {
                if j >= m.k() + i {
                    v += bi;
                }
            }
            g[j] = v;
        }
        // Ã = (1 − q⁻¹) A in f64.
        let mut at = vec![0.0f64; a.len() + 2];
        at[0] = 1.0;
        for i in 1..at.len() {
            at[i] = a.get(i - 1).copied().unwrap_or(0.0) - if i == 1 { 1.0 } else { a[i - 2] };
        }
        let mut yy: Vec<f64> = (0..HY).rev().map(|i| f64::from(s.y[i])).collect();
        let mut f = vec![0.0f64; n2 + 1];
        for j in 1..=n2 {
            let mut v = 0.0;
            for (i, ai) in at.iter().enumerate().skip(1) {
                v -= ai * yy[HY - 1 + j - i];
            }
            for (i, bi) in b.iter().enumerate() {
                if m.k() + i > j {
                    v += bi * f64::from(s.du_past(m.k() + i - j));
                }
            }
            for i in j..=m.nc() {
                v += f64::from(m.c()[i - 1]) * f64::from(s.e[i - j]);
            }
            yy.push(v);
            f[j] = v;
        }
        (g, f)
    }

    /// Solves a x = r by Gaussian elimination with partial pivoting (f64, small and dense).
    fn gauss(mut a: Vec<Vec<f64>>, mut r: Vec<f64>) -> Vec<f64> {
        let n = r.len();
        for col in 0..n {
            let piv = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs())).unwrap();
            a.swap(col, piv);
            r.swap(col, piv);
            for row in 0..n {
                if row != col {
                    let f = a[row][col] / a[col][col];
                    for k in col..n {
                        a[row][k] -= f * a[col][k];
                    }
                    r[row] -= f * r[col];
                }
            }
        }
        (0..n).map(|i| r[i] / a[i][i]).collect()
    }

    /// The constrained law's Δu(t) in f64 from scratch: G by index from the step response,
    /// H = GᵀG + λI, b = Gᵀ(w − f), the unconstrained plan H⁻¹b; if its levels
    /// u(t−1) + Σ_{k≤i} Δu_k leave [0, 1], the levels' problem (Q = DᵀHD, Dᵀb, relative to
    /// u(t−1)) by enumerating every active set ([`reference_box_qp`]). Also whether the
    /// unconstrained plan was inside.
    fn reference_constrained_du(s: &GpcState, m: &Model, cfg: &GpcConfig, w: f32) -> (f64, bool) {
        reference_du_floor(s, m, cfg, w, true).0
    }

    /// Which of the soft floor's rows moved a plan ([`reference_du_floor`]).
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum FloorRow {
        None,
        Floor,
        Guard,
    }

    /// [`reference_constrained_du`] with or without the soft floor, and which row of it was at
    /// work. The plan (the box's levels if the unconstrained one leaves the box) is checked on
    /// two rows: its prediction midway from k + 4 to N2 against 2.5 °C (at most 0.5 °C below
    /// w), and the freeze guard's look-ahead on it against 2.0 °C (as far below w at most):
    /// ŷ_j + 12·s_j at j = k + 3, s_j the guard's slope smoothing (memory 0.7) over the three
    /// differences of ŷ_j … ŷ_{j−3}, its weights scaled to sum to 1. If the plan cools now (its first level is above "no
    /// cooling") and falls below either, the row it falls further below adds ρ(level − r·Δũ)² to
    /// the cost, and the move is the first of the plan plus the penalised cost's Newton step
    /// from it, (H + ρrrᵀ)⁻¹ρr·(level − r·Δũ), clipped into the box.
    fn reference_du_floor(
        s: &GpcState,
        m: &Model,
        cfg: &GpcConfig,
        w: f32,
        with_floor: bool,
    ) -> ((f64, bool), FloorRow) {
        let (n1, n2, nu) = (cfg.n1, cfg.n2, cfg.nu);
        let (g, f) = reference_gf(s, m, n2);
        let gm = |j: usize, c: usize| if j > c { g[j - c] } else { 0.0 };
        let mut h: Vec<Vec<f64>> = (0..nu)
            .map(|r| {
                (0..nu)
                    .map(|c| {
                        (n1..=n2).map(|j| gm(j, r) * gm(j, c)).sum::<f64>()
                            + if r == c { f64::from(cfg.lambda) } else { 0.0 }
                    })
                    .collect()
            })
            .collect();
        let b: Vec<f64> = (0..nu).map(|c| (n1..=n2).map(|j| gm(j, c) * (f64::from(w) - f[j])).sum()).collect();
        let u = f64::from(s.u_prev());
        let (lvl, inside) = reference_box_plan(&h, &b, u);
        let du: Vec<f64> = (0..nu).map(|c| lvl[c] - if c > 0 { lvl[c - 1] } else { 0.0 }).collect();
        // Row q's weights on Δũ, and the plan's prediction there.
        let row = |q: usize| (0..nu).map(|c| gm(q, c)).collect::<Vec<f64>>();
        let predict = |r: &[f64], free: f64| free + r.iter().zip(&du).map(|(a, d)| a * d).sum::<f64>();
        let split = (m.k() + 4).max(3).min(n2 + 1);
        let j = (split + n2) / 2;
        // The free response at row q, and the measured y(t + q) at q ≤ 0.
        let free = |q: isize| if q >= 1 { f[q as usize] } else { f64::from(s.y[(-q) as usize]) };
        let (floor_r, floor_f) = (row(j), f[j]);
        // The guard's look-ahead: weights on ŷ_{split−1−q}, q = 0 … 3.
        let (look, mem) = (12.0f64, 0.7f64);
        let sw: Vec<f64> = (0..3).map(|i| (1.0 - mem) * mem.powi(i)).collect();
        let total: f64 = sw.iter().sum();
        let mut cw = [1.0f64, 0.0, 0.0, 0.0];
        for (i, si) in sw.iter().enumerate() {
            cw[i] += look * si / total;
            cw[i + 1] -= look * si / total;
        }
        let mut guard_r = vec![0.0f64; nu];
        let mut guard_f = 0.0;
        for (q, wq) in cw.iter().enumerate() {
            let at = split as isize - 1 - q as isize;
            if at >= 1 {
                for (gr, x) in guard_r.iter_mut().zip(row(at as usize)) {
                    *gr += wq * x;
                }
            }
            guard_f += wq * free(at);
        }
        let floor = 2.5f64.min(f64::from(w) - 0.5) - predict(&floor_r, floor_f);
        let guard = 2.0f64.min(f64::from(w) - 0.5) - predict(&guard_r, guard_f);
        let (below, r, which) =
            if guard > floor { (guard, guard_r, FloorRow::Guard) } else { (floor, floor_r, FloorRow::Floor) };
        if !(with_floor && below > 0.0 && lvl[0] > -u) {
            return ((lvl[0], inside), FloorRow::None);
        }
        let rho = 1000.0;
        for (hr, ra) in h.iter_mut().zip(&r) {
            for (hc, rc) in hr.iter_mut().zip(&r) {
                *hc += rho * ra * rc;
            }
        }
        let step = gauss(h, r.iter().map(|x| rho * x * below).collect());
        // The penalised plan's first move, clipped into the box.
        (((du[0] + step[0]).clamp(-u, 1.0 - u), inside), which)
    }

    /// The levels u(t + i) − u(t − 1) minimising ½ΔũᵀHΔũ − bᵀΔũ with 0 ≤ u(t − 1) + level ≤ 1,
    /// and whether the unconstrained minimiser was inside the box.
    fn reference_box_plan(h: &[Vec<f64>], b: &[f64], u: f64) -> (Vec<f64>, bool) {
        let nu = b.len();
        let x = gauss(h.to_vec(), b.to_vec());
        let (lo, hi) = (-u, 1.0 - u);
        let lvl: Vec<f64> = x
            .iter()
            .scan(0.0, |acc, xi| {
                *acc += xi;
                Some(*acc)
            })
            .collect();
        if lvl.iter().all(|l| (lo..=hi).contains(l)) {
            return (lvl, true);
        }
        // D: Δu_0 = v_0, Δu_i = v_i − v_{i−1}; Q = DᵀHD, c = Dᵀb.
        let d = |r: usize, c: usize| {
            if r == c {
                1.0
            } else if r == c + 1 {
                -1.0
            } else {
                0.0
            }
        };
        let q: Vec<Vec<f64>> = (0..nu)
            .map(|i| {
                (0..nu)
                    .map(|k| (0..nu).map(|r| (0..nu).map(|c| d(r, i) * h[r][c] * d(c, k)).sum::<f64>()).sum())
                    .collect()
            })
            .collect();
        let c: Vec<f64> = (0..nu).map(|i| (0..nu).map(|r| d(r, i) * b[r]).sum()).collect();
        (reference_box_qp(&q, &c, lo, hi).0, false)
    }

    /// A plan falling toward the soft floor: the law's Δu is the f64 move of the penalised cost
    /// ([`reference_du_floor`]), and the row at work is the reference's. The guard row acts on
    /// plans inside the box and on the box's own plans (full duty, the load falling 0.1–0.3 °C
    /// a sample toward the 3 °C setpoint) and asks for less cooling than the optimum without
    /// it; the floor row on a damped plan (λ 50) the box holds at no duty after the first
    /// move; neither on a plan that cools not at all now, nor on one that lands well above.
    #[test]
    fn a_soft_floor_lifts_a_plan_that_dips_below_it() {
        let m = Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.029_865], &[], 5).unwrap();
        // (λ, the load's fall a sample, the duty held, where it ends against the 3 °C setpoint,
        // the row at work, how much less duty it asks for at least)
        let cases = [
            (50.0, -0.15, 1.0, -0.2, FloorRow::Guard, 0.5),
            (3.0, -0.15, 0.9, 0.6, FloorRow::Guard, 0.1),
            (10.0, -0.1, 0.6, 0.0, FloorRow::Guard, 0.03),
            (20.0, -0.3, 1.0, 0.0, FloorRow::Guard, 0.15),
            (50.0, -0.1, 0.3, 0.3, FloorRow::Floor, 0.04),
            (50.0, -0.15, 1.0, 1.5, FloorRow::None, 0.0),
            (0.5, -0.1, 0.3, -0.2, FloorRow::None, 0.0),
            (0.5, -0.05, 0.6, 0.0, FloorRow::None, 0.0),
            (0.5, -0.02, 0.3, 1.0, FloorRow::None, 0.0),
        ];
        let w = 3.0;
        for (lambda, slope, u0, end, row, less) in cases {
            let cfg = GpcConfig { lambda, ..GpcConfig::DEFAULT };
            let ys: Vec<f32> = (0..12).map(|t| w + end - slope * (11 - t) as f32).collect();
            let (du, s) = staged_du(&m, &cfg, &ys, u0, w);
            let ((want, _), at_work) = reference_du_floor(&s, &m, &cfg, w, true);
            let ((without, _), _) = reference_du_floor(&s, &m, &cfg, w, false);
            let case = format!("λ {lambda}, fall {slope}, u {u0}, end {end}");
            assert!((f64::from(du) - want).abs() < 1e-4, "{case}: Δu {du} against the reference {want}");
            assert_eq!(at_work, row, "{case}: the row at work");
            if row == FloorRow::None {
                assert_eq!(want, without, "{case}");
            } else {
                assert!(want < without - less, "{case}: {want} against {without} without the floor");
            }
        }
    }

    /// Independent f64 reference of a box QP: min ½vᵀQv − cᵀv over lo ≤ v ≤ hi by enumerating
    /// every assignment of each level to free, lo or hi (3ⁿ), solving the free block by Gaussian
    /// elimination, keeping the feasible ones and the least cost.
    fn reference_box_qp(q: &[Vec<f64>], c: &[f64], lo: f64, hi: f64) -> (Vec<f64>, f64) {
        let n = c.len();
        let cost = |v: &[f64]| {
            let mut j = 0.0;
            for i in 0..n {
                j -= c[i] * v[i];
                for k in 0..n {
                    j += 0.5 * v[i] * q[i][k] * v[k];
                }
            }
            j
        };
        let mut best: Option<(Vec<f64>, f64)> = None;
        for code in 0..3usize.pow(n as u32) {
            let kind: Vec<usize> = (0..n).map(|i| code / 3usize.pow(i as u32) % 3).collect();
            let mut v: Vec<f64> = kind.iter().map(|&k| if k == 1 { lo } else { hi }).collect();
            let free: Vec<usize> = (0..n).filter(|&i| kind[i] == 0).collect();
            // Q_FF v_F = c_F − Q_FW v_W.
            let qff: Vec<Vec<f64>> = free.iter().map(|&i| free.iter().map(|&j| q[i][j]).collect()).collect();
            let rhs: Vec<f64> = free
                .iter()
                .map(|&i| c[i] - (0..n).filter(|j| kind[*j] != 0).map(|j| q[i][j] * v[j]).sum::<f64>())
                .collect();
            for (&i, vi) in free.iter().zip(gauss(qff, rhs)) {
                v[i] = vi;
            }
            if free.iter().all(|&i| v[i] >= lo - 1e-12 && v[i] <= hi + 1e-12) {
                let j = cost(&v);
                if best.as_ref().is_none_or(|(_, b)| j < *b) {
                    best = Some((v, j));
                }
            }
        }
        best.unwrap()
    }

    #[test]
    fn box_qp_finds_the_optimum_of_every_active_set() {
        // Random symmetric positive definite Q = AᵀA + εI, n = 1 … 5, with c scaled so that
        // anything from no bound to every bound is active (a small LCG: no host RNG needed).
        let mut seed = 0x2545_f491u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f64 / (1u32 << 24) as f64 * 2.0 - 1.0
        };
        let mut active_seen = [false; MAX_NU + 1];
        for case in 0..3000 {
            let n = 1 + case % MAX_NU;
            let a: Vec<Vec<f64>> = (0..n).map(|_| (0..n).map(|_| rnd()).collect()).collect();
            let q: Vec<Vec<f64>> = (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| (0..n).map(|k| a[k][i] * a[k][j]).sum::<f64>() + if i == j { 0.05 } else { 0.0 })
                        .collect()
                })
                .collect();
            let scale = 0.2 + 3.0 * (rnd() + 1.0);
            let c: Vec<f64> = (0..n).map(|_| scale * rnd()).collect();
            let u_prev = 0.5 * (rnd() + 1.0);
            let (lo, hi) = (-u_prev, 1.0 - u_prev);
            // P = Q⁻¹ column by column and the unconstrained minimiser P c, in f64, rounded.
            let mut pf = [[0.0f32; MAX_NU]; MAX_NU];
            for k in 0..n {
                let col = gauss(q.clone(), (0..n).map(|i| if i == k { 1.0 } else { 0.0 }).collect());
                for i in 0..n {
                    pf[i][k] = col[i] as f32;
                }
            }
            let unc = gauss(q.clone(), c.clone());
            let mut uf = [0.0f32; MAX_NU];
            for i in 0..n {
                uf[i] = unc[i] as f32;
            }
            let (want, want_cost) = reference_box_qp(&q, &c, lo, hi);
            // Bordered by the identity beyond n, as `GpcStaged` pads P: on NQ levels where
            // n ≤ NQ (the board's), else on MAX_NU.
            for (i, pi) in pf.iter_mut().enumerate().skip(n) {
                pi[i] = 1.0;
            }
            let v: Vec<f32> = if n <= NQ {
                let mut u = [0.0f32; NQ];
                u.copy_from_slice(&uf[..NQ]);
                let v = box_qp::<NQ>(&pf, &u, lo as f32, hi as f32);
                assert!(v[n..].iter().all(|&x| x == 0.0), "case {case}: padded levels {v:?}");
                v.to_vec()
            } else {
                box_qp::<MAX_NU>(&pf, &uf, lo as f32, hi as f32).to_vec()
            };
            let vf: Vec<f64> = v[..n].iter().map(|&x| f64::from(x)).collect();
            assert!(vf.iter().all(|&x| x >= lo - 1e-6 && x <= hi + 1e-6), "case {case}: {vf:?} outside");
            let cost: f64 =
                (0..n).map(|i| -c[i] * vf[i] + (0..n).map(|j| 0.5 * vf[i] * q[i][j] * vf[j]).sum::<f64>()).sum();
            assert!(
                cost - want_cost <= 1e-4 * (1.0 + want_cost.abs()),
                "case {case}: cost {cost} against the optimum {want_cost} ({vf:?} vs {want:?})"
            );
            let bound = want.iter().filter(|&&x| x == lo || x == hi).count();
            active_seen[bound] = true;
        }
        assert!(active_seen.iter().all(|&s| s), "every number of active bounds was exercised: {active_seen:?}");
    }

    /// Runs the staged law on `m` through a history `ys` (oldest first, u held at `u0`); its
    /// last Δu and the state.
    fn staged_du(m: &Model, cfg: &GpcConfig, ys: &[f32], u0: f32, w: f32) -> (f32, GpcState) {
        let mut s = GpcState::new(u0);
        let mut st = GpcStaged::NEW;
        let mut du = 0.0;
        for (t, y) in ys.iter().enumerate() {
            if t > 0 {
                s.track(u0);
            }
            s.push_y(*y, m).unwrap();
            du = st.update(&s, m, cfg, w).unwrap();
        }
        (du, s)
    }

    #[test]
    fn staged_law_solves_the_constrained_cost() {
        // The H-TER I start model's shape. A pull-down from 12 °C to 4 °C at duty 0.3 (the
        // unconstrained levels ask for more than full cooling), a warm-up at duty 0.9 with the
        // load far below the setpoint (less than none), a load just above the setpoint (no
        // bound active), and a load at 5 °C falling 0.1 °C a sample toward 3 °C at duty 0.3.
        let m = Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.029_865], &[], 5).unwrap();
        // (Twelve samples: the first design is in use from sample 4, and the ninth
        // constrained sample in a row would clip instead.)
        let hist = |y0: f32, slope: f32| (0..12).map(|t| y0 + slope * t as f32).collect::<Vec<_>>();
        let cases = [
            (hist(12.0, 0.0), 0.3, 4.0),
            (hist(3.0, -0.01), 0.9, 6.0),
            (hist(4.2, -0.005), 0.5, 4.0),
            (hist(5.0, -0.1), 0.3, 3.0),
            (hist(4.0, 0.05), 0.95, 4.0),
        ];
        let mut clipped_differs = false;
        let mut constrained = 0;
        // Nu 1 and 2 run on three levels bordered by the identity, 5 on five.
        let cfgs = [
            GpcConfig::DEFAULT,
            GpcConfig { nu: 2, ..GpcConfig::DEFAULT },
            GpcConfig { nu: 1, lambda: 1.0, ..GpcConfig::DEFAULT },
            GpcConfig { nu: 5, lambda: 0.1, ..GpcConfig::DEFAULT },
        ];
        for cfg in cfgs {
            for (ys, u0, w) in &cases {
                let (du, s) = staged_du(&m, &cfg, ys, *u0, *w);
                let (want, inside) = reference_constrained_du(&s, &m, &cfg, *w);
                constrained += usize::from(!inside);
                assert!(
                    (f64::from(du) - want).abs() < 1e-3,
                    "Δu {du} against the reference {want} ({u0}, {w}, inside {inside}, {cfg:?})"
                );
                // The unconstrained design, clipped, is what the law did before.
                let free = s.design(&m, &cfg, *w).unwrap().du;
                clipped_differs |= ((u0 + free).clamp(0.0, 1.0) - (u0 + du)).abs() > 0.01;
            }
        }
        assert!(constrained >= 4, "the limits were at work in {constrained} cases");
        assert!(clipped_differs, "some case has a constrained move unlike the clipped one");
    }

    /// One model per design: when the estimate moves, the samples before its design is in use
    /// plan on the design's model alone (its free response too), and from the sample its own
    /// design is complete they plan on the new one. Both against the f64 constrained reference.
    #[test]
    fn a_design_plans_on_its_own_model_until_the_next_is_in_use() {
        // The start model, and an estimate with a B three times as strong a sample after the
        // delay (the first trusted estimates of light carriers were 2–4 times off).
        let old = Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.029_865], &[], 5).unwrap();
        let new = Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.089_6], &[], 5).unwrap();
        let cfg = GpcConfig { n1: 6, ..GpcConfig::DEFAULT };
        let (u0, w) = (0.4, 4.0);
        // The load at 4.6 °C and falling, on the old model, until its design is in use; the
        // duty stepped up 0.2 four samples ago, so past increments enter the free response.
        let (mut s, mut st) = (GpcState::new(u0), GpcStaged::NEW);
        for t in 0..12 {
            if t > 0 {
                s.track(if t >= 8 { u0 + 0.2 } else { u0 });
            }
            s.push_y(4.6 - 0.02 * t as f32, st.model().unwrap_or(&old)).unwrap();
            st.update(&s, &old, &cfg, w).unwrap();
        }
        assert_eq!(st.model(), Some(&old));
        // The estimate moves to `new`: its design takes four samples (none constrained here).
        let mut seen_new = false;
        for t in 0..6 {
            s.track(u0 + 0.2);
            let in_use = *st.model().unwrap();
            s.push_y(4.36 - 0.02 * t as f32, &in_use).unwrap();
            let du = st.update(&s, &new, &cfg, w).unwrap();
            let (want, inside) = reference_constrained_du(&s, &in_use, &cfg, w);
            assert!(inside, "sample {t}: the case is meant to leave the limits alone");
            assert!((f64::from(du) - want).abs() < 1e-3, "sample {t}: Δu {du}, its design's model gives {want}");
            if in_use == old {
                // What the sample would plan on the new model: far off.
                let (other, _) = reference_constrained_du(&s, &new, &cfg, w);
                assert!((want - other).abs() > 0.02, "sample {t}: the two models plan alike ({want}, {other})");
            } else {
                seen_new = true;
            }
        }
        assert!(seen_new, "the new design came into use within six samples");
        assert_eq!(st.model(), Some(&new));
    }

    /// The staged law's Δu, its free response's tail folded into the gain row
    /// ([`fold_weights`]), against the whole design in f64 ([`reference_du`]) and the textbook
    /// loops in f32: as close as the whole design is, on horizons that end before, across and
    /// after the head, and an N1 beyond it.
    #[test]
    fn staged_increment_with_the_tail_folded_in_is_the_full_designs() {
        let models = [
            Model::new(&[-1.749_27, 0.751_376], &[-0.027_079_1, -0.029_865], &[], 5).unwrap(),
            Model::new(&[-1.8, 0.81], &[-0.02, -0.01, -0.005, -0.001], &[-0.8], 5).unwrap(),
            Model::new(&[-0.8], &[0.4, 0.6], &[0.5], 1).unwrap(),
            Model::new(&[-1.5, 0.56], &[-0.03], &[0.2], 10).unwrap(),
        ];
        let cfgs = [
            GpcConfig::DEFAULT,
            GpcConfig { lambda: 3.0, ..GpcConfig::DEFAULT },
            GpcConfig { n1: 1, n2: 3, nu: 3, lambda: 0.8 },
            GpcConfig { n1: 3, n2: 20, nu: 2, lambda: 1.0 },
            GpcConfig { n1: 12, n2: 30, nu: 1, lambda: 1.0 },
            GpcConfig { n1: 1, n2: 30, nu: 5, lambda: 0.1 },
        ];
        for m in &models {
            for cfg in &cfgs {
                let mut s = GpcState::new(0.4);
                let mut staged = GpcStaged::NEW;
                let mut checked = 0;
                let mut unconstrained = 0;
                for t in 0..40 {
                    let y = 4.0 + 0.3 * libm::sinf(0.37 * t as f32) + 0.02 * (t % 3) as f32;
                    s.push_y(y, m).unwrap();
                    // (After `MAX_SKIPS` constrained samples in a row the next one clips.)
                    let clips = staged.skipped >= MAX_SKIPS;
                    let floored = staged.floored;
                    let du = staged.update(&s, m, cfg, 4.0).unwrap();
                    // (The first design is in use from sample 4.)
                    if t >= 4 {
                        // Both f32 paths are within 2.2e-4 of the f64 design here (the H-TER model's
                        // pole at 0.9986 makes the gain row's rounding the larger part).
                        let r = reference_du(&s, m, cfg, 4.0);
                        let tol = 4e-4 * r.abs().max(1.0);
                        let want = textbook_design(&s, m, cfg, 4.0).3;
                        assert!((f64::from(want) - r).abs() <= tol, "t {t}: whole design {want} against {r}");
                        // Where the f64 plan's levels stay within [0, 1], the same increment;
                        // where not, the f64 levels' box QP (`staged_law_solves_the_constrained_cost`).
                        let (mut rc, inside) = reference_constrained_du(&s, m, cfg, 4.0);
                        if clips && !inside {
                            // (That sample clips into the box, and after a floor sample it never
                            // raises the duty.)
                            let u = f64::from(s.u_prev());
                            rc = r.clamp(-u, if floored { 0.0 } else { 1.0 - u });
                        }
                        if inside {
                            assert!((rc - r).abs() <= 1e-9 * r.abs().max(1.0), "{rc} against {r}");
                            unconstrained += 1;
                        }
                        // (The levels' problem goes through P = Q⁻¹, Z's prefix sums: its f32
                        // rounding is about four times the plain design's on this model.)
                        let tol = if inside { tol } else { 4.0 * tol };
                        assert!(
                            (f64::from(du) - rc).abs() <= tol,
                            "t {t}: staged Δu {du} against {rc} (inside {inside}; whole design {want}), {m:?} {cfg:?}"
                        );
                        checked += 1;
                    }
                    s.track((0.4 + 0.3 * du).clamp(0.0, 1.0));
                }
                assert!(checked > 0 && staged.bank[staged.cur].tail_ok, "{m:?} {cfg:?}");
                // The unconstrained law, at the tight tolerance, is exercised in every case.
                assert!(unconstrained > 0, "{unconstrained} of {checked} inside, {m:?} {cfg:?}");
            }
        }
    }

    #[test]
    fn config_ranges_are_enforced() {
        let bad = [
            GpcConfig { n1: 0, ..GpcConfig::DEFAULT },
            GpcConfig { n1: 5, n2: 4, ..GpcConfig::DEFAULT },
            GpcConfig { n2: 31, ..GpcConfig::DEFAULT },
            GpcConfig { nu: 6, ..GpcConfig::DEFAULT },
            GpcConfig { lambda: -1.0, ..GpcConfig::DEFAULT },
            GpcConfig { lambda: f32::NAN, ..GpcConfig::DEFAULT },
        ];
        for c in bad {
            assert_eq!(c.validate(), Err(GpcError::Config), "{c:?}");
        }
        assert_eq!(GpcConfig::DEFAULT.validate(), Ok(()));
    }
}
