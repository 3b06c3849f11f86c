//! Self-tuning control (certainty equivalence; Åström & Wittenmark, *Adaptive Control*, 2nd
//! ed., ch. 3–4): every sample the recursive least-squares estimate of a second-order model is
//! updated and the law (GMVC, IGMVC or GPC) is redesigned from it.
//!
//! **What is estimated.** The ARX model with an offset term
//!
//! ```text
//! y(t) = −a1 y(t−1) − a2 y(t−2) + b0 u(t−k) + … + b3 u(t−k−3) + d + ε(t),   θ = [a1 a2 b0 … b3 d]
//! ```
//!
//! Four B terms ([`ESTIMATED_NB`]) for GPC, not two (GMVC and IGMVC keep two: b2 and b3 are held
//! at zero, [`Rls::hold`]; with four, IGMVC let a 15 W heat load take the load to 7 °C): the RTD sees the cooling through the cold plate,
//! the wall and its own lag, and a second-order A cannot shape that first minute with two.
//! Held fixed, a 4-term model fitted to the plant's step takes GPC from 1.17 to 1.10 × the
//! bound on the full load (EXPERIMENTS.md, issue 15); estimated on line, with the projection
//! below, it takes self-tuning GPC from 1.20 to 1.13 × (seeds 1–8, 28 °C).
//!
//! d absorbs the operating point (ambient, hot-side temperature) without knowing it. An
//! incremental (Δy, Δu) estimate would remove it too, but in closed loop it throws away the
//! low-frequency information: on the hal-sim plant it settled on a static gain of ≈ −2 °C per
//! unit duty against the true ≈ −41. The laws use A and B only (GPC and IGMVC are designed on
//! ΔA, so the offset never matters to them). The RLS runs with forgetting λ_f and a bounded
//! covariance ([`crate::ident`] documents the f32 safeguards).
//!
//! **Projection** ([`Rls::project_onto_halfspace`]; Goodwin & Sin, *Adaptive Filtering,
//! Prediction and Control*, 1984, §3.3.8). After each update the estimate is moved, along P c,
//! into the cone of plausible static gains, B(1) ≥ g_min·A(1) and B(1) ≤ g_max·A(1) (both
//! linear in θ; together they also give A(1) ≥ 0). Through the long holds at one setpoint the
//! data excite nothing, forgetting lets the estimate drift along the directions they leave
//! open, and with four B terms that drift took A(1) below zero (a pole at 1.02) on every
//! half-load run: the estimate was refused for the whole hold and GPC limit-cycled ±0.6 °C on
//! the start model. Projected, the estimate stays in the set the laws accept and keeps
//! following the plant. The cone is the one the trust check applies, to the model the laws get
//! (below: B's warming tail clipped) and [`CONE_MARGIN`] inside it. Bounding the raw B(1)
//! instead, a stored estimate that had drifted to the cone's far edge (−1 000 °C/duty, A(1) ≈
//! 1e-4) with a warming b3 of 0.0013 was projected to −1 000 while the trust check saw −1 013:
//! after a brown-out in a long hold (`hter sim --scenario half-load --duration 86400 --fault
//! brownout@20000`) the decision flipped 44 times in 20 minutes, the law switching between the
//! estimate and the rest's model and each flip an event in the log; over seeds 1–8 of
//! `piecewise` (H-TER I and II) and `half-load` at 20, 28 and 36 °C there were 140 such changes in 72 runs, now
//! none. The model the laws get has the tail of B, b1 … b3, clipped at zero: a
//! term the data leave near zero (the start model's b2 = b3 = 0 on a plant that has them so)
//! is estimated a hair above it as often as below, and refusing each such estimate kept the
//! law frozen for hours. b0 > 0 is still refused: it would reverse the first-step gain. Larger
//! warming terms are clipped too: on a randomized H-TER II carrier (campaign mission 2276) the
//! estimate's b3 settled at +0.35 of the cooling terms' sum; refused, GPC ran the whole mission
//! frozen on the start model and swung the load between 2.4 and 3.1 °C, clipped it holds 4 °C
//! (lowest 3.7 °C). The clipping has a limit ([`WARM_TAIL_MAX`], [`clip_warming_tail`]): an
//! estimate whose warming terms cancel more than 0.7 of its cooling terms is refused, for
//! clipped it would hand the law a static gain over 3.3 × the estimate's own. That is where
//! an estimate fed by a ringing loop goes: A and B towards a common factor 1 − q⁻¹ (A(1) and
//! B(1) both → 0). On campaign mission 4384 (`hter sim --mission-seed 4384`, a light H-TER I
//! carrier in a 9 °C room) a warming pulse ended a long rest, GPC at its default λ rang the
//! duty between 0 and 1, and in the ring the estimate went from a1 = −1.82 with b3 at 0.43 of
//! the cooling terms to a1 = −1.96 with b3 at 0.92, still plausible; GPC on it kept the ring
//! going for three hours and the load fell to 2.75 °C (with the estimator held at a rail,
//! below; 2.93 °C before it). Refused, the law runs frozen on the rest's model: from the pulse
//! on, mean error 0.091 → 0.028 °C and lowest 2.75 → 3.62 °C (IAE 16 128 → 13 633 °C·s; PI
//! 13 415). The limit is not tight to the estimates that work: mission 2276's is at 0.50 an
//! hour after its pull-down and settles at 0.30. At a limit of 0.6 that estimate went in and
//! out of the set, the law switched between two models every few samples and rang all day
//! (IAE 8 383 → 16 940 °C·s); at 0.5 its lowest load was 2.92 °C (3.73 at 0.7). Campaigns and
//! the 504 piecewise runs: EXPERIMENTS.md, issue 15.
//!
//! A start model the plausibility rule refuses does not seed the estimate either (the neutral
//! start below): the commissioning's monotone cabinet model (b1 ≈ −b0, two cooling paths in
//! parallel), clipped, became a plausible model of another plant, and GPC from it
//! limit-cycled at 4.9 × the bound (`tests/commission.rs::gpc_from_the_commissioned_model`).
//!
//! **Prefiltered** ([`PREFILTER_POLE`], GPC only). GPC's estimator runs on the data through
//! 1 / (1 − τ q⁻¹), τ = 0.6: y and u both, so A and B are the same polynomials (the filter
//! commutes with them; d becomes d / (1 − τ), which no law uses). Least squares on the raw
//! samples minimises the one-step error, which the measured y(t−1), y(t−2) already predict
//! well; the filter weighs the slower part of the response, where GPC's 5-minute horizon
//! looks, more (Clarke, Mohtadi & Tuffs 1987 prefilter the estimator's data by the T-filter;
//! Shook, Mohtadi & Shah 1991 choose the filter for the long-range criterion). On the
//! half-loaded H-TER I the estimate's first B term was 0.032 against the 0.049 the plant's
//! step over the horizon asks for (f64 batch least squares on the same closed-loop record
//! gave 0.034: the criterion's bias, not the recursion's), and GPC swung the duty after each
//! step. `scripts/targets.sh`, seeds 1–8, medians at 20 · 28 · 36 °C: the half load 1.329 ·
//! 1.352 · 1.276 → 1.294 · 1.317 · 1.233 × the bound, the full load and H-TER II within
//! ±0.003; the best grid PI's share at seed 1, 28 °C, 0.46 · 0.52 · 0.40 → 0.40 · 0.45 ·
//! 0.41. The pole trades the full load against the half: τ 0.5 gives the half load 1.281 ·
//! 1.296 · 1.218 and the full load 1.121 · 1.146 · 1.126, τ 0.7 the full load 1.104 · 1.111 ·
//! 1.102 and the half load 1.348 · 1.383 · 1.271; 0.6 keeps the full load where it was (τ 0.8,
//! GPC's own T-filter, gave the half load a limit cycle of 0.22 °C). GMVC and IGMVC keep the
//! raw data:
//! with the filter IGMVC limit-cycles on `piecewise` (1.49 → 2.42 × the bound, steady-state
//! error 1.2 °C). The rest's check and the first approach read the raw samples.
//!
//! **Paused at rest** ([`REST_PAUSE_SAMPLES`]). Once the load has held within
//! [`REST_BAND_C`] of one setpoint for 30 minutes, the duty strictly between 0 and 1, the
//! estimator stops updating until the setpoint changes, the error leaves [`REST_EXIT_C`] or the
//! applied duty reaches 0 or 1; it keeps its estimate, the law keeps running on it. (A law at a
//! rail is not regulating: in campaign mission 24204 a shorted SSR cooled the load below the
//! setpoint at 35 °C ambient while the estimate stayed paused, the law kept asking for a little
//! cooling, and the short, which the supervisor recognises by freeze-guard trips with none
//! asked, went unreported; ending the rest when the duty sits at 0 lets the estimate, and with
//! it the law, follow. With GPC's λ 3 at rest, below, the same mission lost its short a second
//! way: the supply probe ended on the law's request for cooling, the law's answer to the very
//! turn-up the probe waits for; [`crate::supervisor::ssr::ProbeConfig::yield_within_c`].) At
//! rest the only excitation is the sensor's noise fed back through the law,
//! and the equation-error estimate of a noisy closed loop is biased: on every hold the static
//! gain drifted from the plant's ≈ −44 °C/duty to the projection's bound, −10, within the
//! simulator's 1-hour pre-roll, and GPC, designed on a plant four times too weak, kept the load
//! moving ±0.07 °C for as long as it held (`hter compare --scenario disturbance`: IAE 340 against
//! 291 before issue 15's 4-term estimate; IGMVC 354 against 211). Paused, the same runs give GPC
//! 137 and IGMVC 132 (GMVC, whose duty touches the rails, rarely rests: 451, against 130 before
//! the 4-term estimate), and the piecewise runs (seeds 1–8 at 20, 28 and 36 °C) move by −0.056 …
//! +0.024 in IAE / bound, median and worst seed (EXPERIMENTS.md, issue 15). A dead zone on
//! the prediction error instead (no update while |ε| < 0.01–0.04 °C) also held the gain, but it
//! stopped the learning in the piecewise steps too: 1.15–1.28 × the bound on the full load, up
//! to 2.2 on the half load. Neither a longer memory (forgetting 0.998–0.999) nor a smaller
//! covariance bound (trace P 1–3) nor centred regressors stopped the drift.
//!
//! **Held at a rail** ([`SecondOrderRegressor::input_held`]). While the applied duty has not
//! changed over every u in φ (k + 4 samples: a pull-down at full duty, a warming at none, a
//! cold room at none), φ's input terms are one constant, as the offset's column is, and the
//! data say nothing of B; RLS, whose forgetting keeps the covariance open in that direction,
//! let B drift along it instead. The estimator skips those samples. Found on `step` with the
//! half load (`hter compare --scenario step --load half`): during the half-hour pull-down b3
//! drifted to +0.06 and later b0 above zero, the estimate was refused, and GPC ran frozen with
//! the duty between 0 and 1 for hours, ±0.35 °C (steady-state error 0.05–0.42 °C on seeds 1–8
//! at 20–36 °C since the prefilter, which made the drift larger; 0.020–0.033 °C held);
//! `mission --load half` 28 986 → 17 132 °C·s (seed 1). A self-tuner that starts with a
//! pull-down now engages when the duty first moves, not on the pull-down's noise (the golden
//! `step` trace: at 1 920 s, not 310 s). The piecewise runs, whose full-duty descents also
//! taught A, lose a little: `scripts/targets.sh` medians at 20 · 28 · 36 °C, the full load
//! 1.103 · 1.115 · 1.107 → 1.113 · 1.122 · 1.105 × the bound, the half load and H-TER II
//! within ±0.004; 504 runs at 12–36 °C, the full load +0.004 on the median, at most +0.027
//! (with the warming tail's limit above; EXPERIMENTS.md, issue 15).
//!
//! **Paused sooner once confirmed** ([`CONFIRMED_PAUSE_SAMPLES`], GPC only). The first rest still takes
//! its 30 minutes. Once one has paused the estimator on an estimate the rules trust, every
//! later hold pauses it after one minute within [`REST_BAND_C`] (the rest's λ still waits for
//! the half hour): the estimate learns from the steps, and a hold would only teach it the
//! noise's bias. On the simulator's runs the drift is already there in the hour-long hold
//! before the first step: the half load's response over GPC's 30 predictions is then 1.5 × the
//! plant's (−9.7 against −6.5 °C per unit duty), and it comes back within 10 % during the
//! first step. Paused after one minute from then on, the later holds keep what the steps
//! taught (`scripts/targets.sh`, seeds 1–8, medians at 20 · 28 · 36 °C): the half load 1.255 ·
//! 1.282 · 1.200 → 1.228 · 1.233 · 1.183 × the bound, the full load 1.113 · 1.122 · 1.105 →
//! 1.104 · 1.107 · 1.092, H-TER II within ±0.001; the half load's worst steady-state error
//! 0.060 · 0.061 · 0.060 → 0.045 · 0.047 · 0.047 °C. An estimate in warm-up, or refused,
//! confirms nothing: its next hold runs the half hour again. Pausing sooner on the first rest
//! too (5 minutes) left the pre-roll's estimate half-learnt and the full load ringing ±0.4 °C
//! on some seeds (EXPERIMENTS.md, issue 15).
//!
//! **Resumed from a stored model** ([`AdaptiveConfig::resumed_from`], [`RESUMED_P0`],
//! [`OFFSET_P0`]). After a reset the board starts the self-tuner from the model it stored
//! ([`crate::persist::ModelRecord`]), but not from its offset d, which the record does not
//! hold: d starts at 0. With P(0) = I for every parameter, the first samples' error (the whole
//! operating point) went into B as much as into d, for at a hold φ's input terms are nearly
//! constant, like the offset's column: after a brown-out in a long hold (`hter sim --scenario
//! half-load --duration 86400 --fault brownout@20000`) B fell to a third of the record's within
//! 100 s, and the law, trusting it, swung the load between 3.50 and 4.41 °C for 15 minutes.
//! With the estimate paused sooner (above), the same restart took b0 above zero, the estimate
//! was refused and then paused on the refused estimate, `frozen` for the rest of the day.
//! Resumed, the model's parameters start with P(0) = 0.01·I (the record is a model this
//! self-tuner trusted) and d with 1: the offset takes the error, the estimate stays the
//! record's (b0 −0.0176 → −0.0163), and the load holds 3.99–4.02 °C through the restart
//! (3.96–4.12 °C since the simulated restart starts the law from the board's boot duty, 0.4,
//! held for the four samples of GPC's first design, where it had used the holding duty; b0
//! −0.0210 → −0.0196; the same range with the fallback PI driving those four samples, "The
//! first samples", b0 −0.0180 at the end of the day; 3.97–4.47 °C since the boot starts every
//! law from [`crate::profile::BOOT_DUTY`], 0.2, under the 0.46 that holds this load: the PI
//! takes 40 s to find the hold and the load peaks 140 s after the restart, within 3.97–4.04 °C
//! from 1 000 s on, b0 −0.0167 at the end of the day). A commissioned model ([`AdaptiveConfig::restored_from`]) still starts
//! with the start's P(0).
//!
//! **When the estimate is trusted** (all must hold, else the law runs on the last trusted
//! model or the one its last rest confirmed ("Frozen on the rest's model"), and with no
//! trusted model the bumpless fallback PI drives the SSR):
//! - every θ finite and the estimator healthy;
//! - parameter projection: A stable (Jury's conditions), every b_i ≤ 0 (cooling), static gain
//!   B(1)/A(1) negative and within [`AdaptiveConfig::gain_min_c_per_duty`]…[`AdaptiveConfig::gain_max_c_per_duty`];
//! - B's warming tail, clipped for the law, cancels at most [`WARM_TAIL_MAX`] of its cooling
//!   terms ("Projection");
//! - at least [`AdaptiveConfig::warmup_samples`] updates since start or reset.
//!
//! **Modes** ([`AdaptiveMode`]), decided at every [`Controller::update`]:
//!
//! ```text
//!                          estimate trusted ¹
//!            ┌──────────────────────────────────────────┐
//!            │                                          ▼
//!       ┌────────┐        estimate not trusted ¹   ┌──────────┐
//!       │ Frozen │ ◄────────────────────────────── │ Adaptive │
//!       └────────┘                                 └──────────┘
//!         │    ▲                                       ▲    │
//!  law    │    │ estimate not trusted ¹     estimate   │    │  law
//!  failed │    │ (a trusted model exists)   trusted ¹  │    │  failed
//!         ▼    │                                       │    ▼
//!       ┌──────────────────────────────────────────────────────┐
//!       │                       Fallback                       │
//!       └──────────────────────────────────────────────────────┘
//!
//!  start: Frozen with a plausible start model, else Fallback.
//!  ¹ on a sample the estimator updated, after warm-up (at least
//!    `warmup_samples` updates); and the law must succeed on that sample.
//! ```
//!
//! - Frozen: the law runs on the last trusted model (the start model until the first trusted
//!   estimate); when the estimate is refused after running `Adaptive`, on the model that was
//!   trusted when the estimator last paused at rest, if it has ("Frozen on the rest's model"
//!   below).
//! - Adaptive: the law runs on the current estimate, trusted this sample.
//! - Fallback: the law failed (a numerical error, a non-finite measurement, or no trusted model
//!   yet) and the PI drives.
//!
//! Warm-up and samples the estimator refused keep the mode, unless the law fails.
//!
//! **Frozen on the rest's model.** The model trusted when the estimator pauses at rest (30
//! minutes within 0.2 °C, [`REST_PAUSE_SAMPLES`]) is kept; an estimate refused after the law
//! ran `Adaptive` sends the law back to it rather than to the last model trusted. The estimate
//! that is refused has usually drifted through plausible models on its way out of the set, and
//! the last of them is the furthest gone; a rest's model held the load still for half an
//! hour. Found on campaign mission 4384 (`hter sim --mission-seed 4384`, a light H-TER I
//! carrier whose room falls from 28 to 9 °C): at duty 0.14 a warming pulse ended a long rest,
//! the estimator (its covariance at the bound after the hold) took A from 1 − 1.76 q⁻¹ +
//! 0.76 q⁻² to 1 − 1.99 q⁻¹ + 0.99 q⁻² in 60 samples, GPC on it drove the duty between 0 and
//! 0.94 with the load below the setpoint (2.85 °C), and once the estimate left the plausible
//! set (A(1) → 0: with its warming b3 clipped, a static gain beyond −1 000 °C/duty; then a
//! pole past 1) it ran frozen on that last trusted model for 16 000 s, the load cycling
//! 0.4 °C below the setpoint (IAE 26 014 °C·s, steady-state error 1.21 °C, lowest 2.25 °C;
//! PI 13 415, 0.06, 3.75). On the rest's model: 14 910, 0.13, 2.93 °C; three 10 000-mission
//! campaigns and 504 piecewise runs (12–36 °C, seeds 1–24) keep their trips, 56 of the runs
//! move by −0.019 … +0.009 in IAE / bound, and the campaigns' lowest fault-free load goes
//! from 2.25 to 2.30 °C; IGMVC on H-TER II's `piecewise` 1 878 → 1 768 °C·s, overshoot
//! 0.33 → 0.09 °C. Handing the law to the fallback PI after 30 minutes frozen instead made it
//! worse (lowest 2.02 °C, a freeze-guard trip): under the PI the drifted estimate became
//! plausible again and GPC took it up (EXPERIMENTS.md, issue 15).
//!
//! **Cautious while unconfirmed.** Outside `Adaptive` GPC runs with λ at least
//! [`CAUTIOUS_GPC_LAMBDA`]: the model it designs on is one the estimate has not confirmed on
//! this carrier, and the default λ (0.5) is tuned for a model that has.
//!
//! **Damped at rest.** Paused, the estimate is no longer being confirmed either, and what the
//! law meets there is the sensor's noise and slow disturbances, which λ 0.5 answered by moving
//! the duty more than they need: while resting on a confirmed model GPC runs with λ at least
//! [`REST_GPC_LAMBDA`] (10). It leaves the rest when it ends (a step, an error past
//! [`REST_EXIT_C`], a duty at a rail), so tracking and disturbance rejection run at the default
//! λ again. The rest's λ was the cautious 3 until issue 15 found a half-loaded H-TER I on `step`
//! (28 °C) holding a ±0.25 °C cycle of about 100 s for the last hour and a half: its estimate
//! had drifted into the cycle on the full-load start model and paused there, and λ 3 kept it
//! (steady-state error 0.31 °C). `hter compare --scenario step --load L --ambient A --seed S`,
//! seeds 1–8 at 20 · 28 · 36 °C: the half load's steady-state error, median 0.19 · 0.08 · 0.08
//! → 0.031 · 0.029 · 0.032 °C and worst 0.39 · 0.31 · 0.36 → 0.051 · 0.048 · 0.070; the full
//! load's worst 0.066 · 0.393 · 0.040 → 0.027 · 0.023 · 0.022; IAE / bound, half load medians
//! 1.274 · 1.111 · 1.062 → 1.221 · 1.094 · 1.055, full and H-TER II within 0.004. `disturbance`
//! 87 → 73 (full) and 94 → 79 °C·s (half); `hot-zone` 1 828 → 1 435 and 2 155 → 1 696 °C·s;
//! `mission` on the half load 1.385 → 1.142 × the bound; `piecewise`, whose holds are shorter
//! than the pause, 1.129 · 1.320 · 1.033 → 1.132 · 1.317 · 1.037 (seeds 1–8, 28 °C: the seed
//! spread). λ 30 holds `step` closer (worst 0.030 °C) but a design made at rest still serves the
//! first samples after a setpoint change (the staged design takes four to eight to follow a
//! new λ): `piecewise` 1.146 · 1.339 · 1.044, and `hot-zone` on the half load 2 657 °C·s.
//! Scaling the law's Δu by 0.1–0.15 at rest instead (no redesign) let `hot-zone` reach 4.51 °C.
//! λ 3 at rest had itself taken the disturbance run from 137 to 92 °C·s and the buck drive's
//! holding power at 28 °C from 7.12 to 6.76 W (H-TER I) and 8.48 to 7.27 W (H-TER II), against
//! λ 0.5.
//!
//! **Reset at rest** ([`RESET_GAIN`], GPC only). Once the load has held within
//! [`REST_BAND_C`] of the setpoint for [`RESET_AFTER_SAMPLES`] samples after a setpoint change,
//! the law is handed (once the first approach is over) the setpoint moved by a slow integral
//! of the measured error, r(t) = r(t−1) + [`RESET_GAIN`] · (w − y(t)), at most ±[`RESET_MAX_C`]; r
//! returns to 0 when the rest ends (a setpoint change, an error past [`REST_EXIT_C`], the
//! applied duty at a rail). After a step the wall and the cold plate hold cold (or heat) that
//! keeps pulling the water the step's way beyond the 2-term A the estimate has and beyond the
//! 5-minute horizon: on the 6 → 3 °C step of `piecewise` the half load undershot by 0.08 °C
//! and took 600 s to come back within 0.01 °C, the law cutting the duty from 0.60 to 0.51 only,
//! and the end of that return was the run's steady-state error (0.058 °C, seed 1, 28 °C). The
//! reset is the outer loop's integral action on what the inner model misses. Seeds 1–8 at 20 ·
//! 28 · 36 °C (`scripts/targets.sh`), medians of IAE / bound: the half load 1.294 · 1.317 ·
//! 1.233 → 1.254 · 1.282 · 1.197, the full load 1.112 · 1.133 · 1.117 → 1.103 · 1.115 · 1.107,
//! H-TER II within ±0.002; the worst steady-state error on the full load 0.060 → 0.048 °C
//! and the worst mean error over a hold's last quarter on the half load (seeds 1–8, 28 °C)
//! 0.018–0.025 → 0.009–0.015 °C; H-TER II's grows, 0.005–0.009 → 0.012–0.022 °C (the
//! reset's gain and start are H-TER I's), its steady-state error median 0.031 →
//! 0.036 °C at 28 °C and worst 0.085 → 0.069 °C at 36 °C (EXPERIMENTS.md, issue 15). Gains
//! 0.005–0.08 and starts after 1–36 samples were measured: 0.08 let H-TER II swing
//! (steady-state error up to 0.13 °C); started at the first sample in the band, while the
//! step's own overshoot is still settling, the half load gained 0.01–0.02 less. The bound
//! never binds on these runs (at a gain of 0.01, bounds of 0.08, 0.15 and 0.3 gave the same
//! runs); it is there for a load the law cannot bring back, whose error would otherwise wind
//! the reset up. While the estimator is paused at rest the reset goes on. GMVC and IGMVC aim
//! at the setpoint as given. The reset is logged ([`ControllerStatus::reset_c`]: `hter sim
//! --csv`'s `reset_c` column, the firmware's `est … reset=` line), so a duty that creeps
//! through a long hold can be read back to the error that moves it.
//!
//! **The cost's first row.** Self-tuning GPC's cost starts at N1 = k + 1, one sample after
//! the first one the model's delay k lets the duty reach (`GpcConfig::n1` when larger, N2 when
//! smaller). The
//! estimate's first B term carries the fraction of a sample by which the plant's real delay
//! exceeds k − 1, so it is small and its zero can lie outside the unit circle (b1 larger than
//! b0); a cost that asks the first reachable sample to be right inverts that zero. With λ 0.2
//! (and the design's gains on the predictions of another model, before [`super::gpc::GpcStaged`]'s
//! "One model"), the duty rang between 0 and 1 every sample for minutes on campaign missions
//! 127954 (to 1.99 °C) and 119510; from k + 1 they did not (3.47 and 3.45 °C), for `hter
//! compare` IAE / bound within ±0.01, median and worst of seeds 1–8 at 20, 28 and 36 °C
//! (EXPERIMENTS.md, issue 15). With one model it was not measured again without.
//!
//! **The first approach** (issue 19). From start until the load first stops falling less than
//! 1 °C above the setpoint, the law is handed the setpoint raised by the rate of fall (over the
//! last two samples) times [`APPROACH_LEAD_SAMPLES`], at most [`APPROACH_RAISE_MAX_C`] (never
//! lowered; the fallback PI keeps the setpoint). A pull-down runs at full duty, which excites
//! nothing, so the law runs on the start model, while the cabinet's wall and cold plate store
//! cold. A heavy wall weakly coupled to its water (stainless steel, wall-to-water conductance
//! × 0.5, wall and water capacities × 1.2–1.5) gives that cold back for ten minutes after the
//! duty is cut, beyond the start model and the 5-minute horizon; from a cool ambient (7–12 °C,
//! where little heat leaks back) GPC cut the duty at 4.1–4.5 °C and the load coasted on to
//! 1.5–1.9 °C, 410–1050 s below 2 °C (campaign missions 5639, 20602, 22766, 45876). The water
//! takes its heat from the wall alone, so the wall lies below it by (water capacity × rate of
//! fall) / coupling: the cold still to come grows with the rate of fall, and a law that aims
//! higher while the load falls fast cuts the duty before it is stored. Those missions now
//! bottom out at 2.65–3.35 °C. The lead (15 samples) is the least that kept every cool-ambient
//! pull-down of missions 1–50 000 above 2.5 °C (10 left 45876 at 2.18 °C, 5 at 1.88); without
//! the cap a light, fast H-TER I carrier (measured fall 0.4 °C per sample, the RTD 1.5 °C
//! behind the water) had the duty cut at 9.5 °C and bounced back above 8 °C for up to 60 s
//! after entering 2–8 °C (7 of missions 1–1000). The cost is a slower landing: the step reaches 4.5 °C
//! 200–230 s later from 28 °C and 110–280 s later from 9 °C (H-TER I–II; `hter sim --scenario
//! step --no-approach-lead`). Regulation and setpoint changes
//! after the first approach are not touched.
//!
//! **The first samples.** GPC's first staged design takes four samples ([`super::gpc::GpcStaged`]),
//! in which the law holds the duty it starts from. A board started it at the fallback PI's bias,
//! then 0.4, after every boot (`profile::SelfTuningOrPi::new`), whatever the reading: a load at 2.1–2.4
//! °C in a cold room (0.9–3 °C), restarted by a brown-out or a fail-safe stop, was cooled at 0.4
//! for 40 s, fell to 1.3–1.7 °C, and the freeze guard's trip while it fell fast was taken for a
//! shorted SSR, a false report that is stored (campaign missions 60267, 66503, 68757 of `--seed
//! 60001`). Until the design is complete the fallback PI drives, on the reading (it runs every
//! sample anyway); the mode does not change, and the law takes over from the duty the PI applied,
//! which its history tracks. Those boots now ask for no cooling and the load stays at 1.84–2.14 °C
//! over the next half hour. The PI itself starts from its bias, the board's boot duty
//! ([`crate::profile::BOOT_DUTY`], 0.2 since a light carrier holding at a few hundredths was
//! cooled for three samples from 0.4 and tripped the freeze guard).
//!
//! **Across a sensor fault** ([`GAP_SETTLE_SAMPLES`]). While the step has no trusted reading it
//! runs no controller; it tells the self-tuner what it applied instead ([`Controller::skip`]), and
//! the estimator does not update until [`GAP_SETTLE_SAMPLES`] measurements after the gap. Without
//! that, the first updates after the fault regressed the measurements after it on the outputs
//! before it: on the start model's plant holding 5 °C at duty 0.45 (a 1.3 × stronger cooler), a
//! two-minute fault took b0 above zero and the law ran `frozen` for the remaining 28 h of the run
//! (`across_a_sensor_fault_the_estimate_is_not_corrupted`); a five-minute one likewise.
//! The law's measured past is forgotten as well ([`LawState::reprime`]): its next measurement
//! fills the y history, as a boot's first does. Its last measurement before the gap may be a
//! spike the step has just outvoted (a restart's first reading, 54 °C over a load at 4 °C in
//! mission 42047 of `--seed 40001`: the law cooled at full duty on it and took the load to
//! 3.09 °C), and after a longer fault the history paired readings minutes apart as consecutive
//! samples, a trend the law then extrapolated. Across the campaign's restarts the lowest load
//! in the hour after one went from 2.33 to 3.08 °C (`hter campaign --missions 10000 --seed
//! 20001 --json`, `restart_min_c`).
//!
//! Mode changes are reported through [`Controller::status`] so the step logs each one as an
//! event (engaged, frozen, fallback). The fallback PI tracks the applied duty all the time, so
//! switching in either direction is bumpless; the law's histories also track the applied duty.

use super::fixed::{Law, LawState};
use super::gpc::GpcConfig;
use super::pi::{Pi, PiConfig};
use super::{AdaptiveMode, ControlError, ControlInput, Controller, ControllerStatus};
use crate::ident::rls::{Rls, RlsConfig};
use crate::model::{second_order_stable, Model, ModelError, MAX_K};
use crate::numerics::shift_in;
use nalgebra::SVector;

/// B terms the self-tuner estimates (b0 … b3).
pub const ESTIMATED_NB: usize = 4;

/// Estimated parameters: a1 a2, b0 … b3, d.
pub const N_THETA: usize = 3 + ESTIMATED_NB;

/// Self-tuning configuration. The board's values are [`crate::profile::adaptive`]; a
/// configuration is checked when the controller is built ([`AdaptiveConfig::validate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdaptiveConfig {
    /// Control law.
    pub law: Law,
    /// Delay k of the estimated model, samples (1 … [`MAX_K`]).
    pub k: usize,
    /// Estimator settings.
    pub rls: RlsConfig,
    /// Model to start from (stored on the board, or identified offline), if any.
    pub initial: Option<Model>,
    /// Updates before a fresh estimate is trusted.
    pub warmup_samples: u32,
    /// Most negative plausible static gain, °C per unit duty.
    pub gain_min_c_per_duty: f32,
    /// Least negative plausible static gain, °C per unit duty.
    pub gain_max_c_per_duty: f32,
    /// Fallback PI.
    pub fallback: PiConfig,
    /// Pole τ of the T-filter C = 1 − τ q⁻¹ that GPC designs with on the estimated model
    /// (Clarke, Mohtadi & Tuffs 1987, §4: an observer polynomial against unmodelled dynamics and
    /// noise), 0 ≤ τ < 1; 0 = none. GMVC and IGMVC carry their own (`IgmvcConfig::t_pole`).
    pub t_filter: f32,
}

/// Why a self-tuning configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdaptiveError {
    /// The delay k is outside 1 … [`MAX_K`] samples.
    Delay,
    /// The estimator settings are out of range ([`RlsConfig::is_valid`]).
    Estimator,
    /// The plausible static-gain range is not finite, not negative, or empty.
    GainRange,
    /// The T-filter pole is outside [0, 1).
    TFilter,
    /// The first approach's lead is outside 0 … 3600 s.
    ApproachLead,
    /// The fallback PI's gain is not finite and positive, or its integral time not positive.
    Fallback,
    /// The law's tuning is out of range (GPC: a horizon N2 shorter than the delay k too), or the
    /// law is not built into this image.
    Law(ControlError),
}

impl AdaptiveConfig {
    /// This configuration restarted from a stored model (e.g. [`crate::persist::ModelRecord`]):
    /// the model becomes the starting θ and, if [`plausible_model`], the first trusted model, and
    /// the estimator takes its delay.
    pub const fn restored_from(self, model: Model) -> Self {
        AdaptiveConfig { initial: Some(model), k: model.k(), ..self }
    }

    /// This configuration resumed from the model its own self-tuner stored
    /// ([`crate::persist::ModelRecord`], after a reset): [`Self::restored_from`] with the
    /// estimator's P(0) = [`RESUMED_P0`]·I instead of the start's (module docs, "Resumed from a
    /// stored model").
    pub const fn resumed_from(self, model: Model) -> Self {
        let rls = RlsConfig { p0: RESUMED_P0, ..self.rls };
        AdaptiveConfig { rls, ..self.restored_from(model) }
    }

    /// This configuration with what a boot's flash restore made of it, `restored`
    /// ([`crate::persist::flash::restore_records`]: [`Self::resumed_from`] the stored model, or the
    /// configuration unchanged): the start model, its delay and the estimator's P(0),
    /// [`RESUMED_P0`] if `restored` was resumed; every other field stays this one's (a board's
    /// constant: P(0) is one of two constants too, and the checks fold when it compiles, +72 B
    /// of flash against +152 B for `restored`'s P(0) as it is). Until 2026-12 the default
    /// firmware took the model and the delay alone, so a board that reset in a hold restarted
    /// its estimator from the start's P(0) = I instead of [`RESUMED_P0`]·I (module docs,
    /// "Resumed from a stored model").
    pub const fn with_restored(self, restored: &AdaptiveConfig) -> Self {
        let rls = if restored.rls.p0 == RESUMED_P0 { RlsConfig { p0: RESUMED_P0, ..self.rls } } else { self.rls };
        AdaptiveConfig { initial: restored.initial, k: restored.k, rls, ..self }
    }

    /// Checks every range [`SelfTuning::new`] relies on (usable in constants: a board can
    /// check its configuration when it compiles).
    pub const fn validate(&self) -> Result<(), AdaptiveError> {
        if !(self.k >= 1 && self.k <= MAX_K) {
            return Err(AdaptiveError::Delay);
        }
        if !self.rls.is_valid() {
            return Err(AdaptiveError::Estimator);
        }
        let (lo, hi) = (self.gain_min_c_per_duty, self.gain_max_c_per_duty);
        if !(lo.is_finite() && lo < hi && hi < 0.0) {
            return Err(AdaptiveError::GainRange);
        }
        if !(self.t_filter >= 0.0 && self.t_filter < 1.0) {
            return Err(AdaptiveError::TFilter);
        }
        let pi = &self.fallback;
        if !(pi.kp_per_c.is_finite() && pi.kp_per_c > 0.0 && pi.ti_s > 0.0) {
            return Err(AdaptiveError::Fallback);
        }
        if let Err(e) = self.law.validate() {
            return Err(AdaptiveError::Law(e));
        }
        // GPC's horizon must reach the delay: before it the step response is zero, no duty acts
        // on any predicted sample, and the design holds the duty it starts from for good
        // (`hter sim --n2 4` kept a carrier at 28 °C for 3 h, with no event).
        if let Law::Gpc(g) = self.law {
            if g.n2 < self.k {
                return Err(AdaptiveError::Law(ControlError::Config));
            }
        }
        Ok(())
    }
}

/// The pole τ of the estimator's data prefilter 1 / (1 − τ q⁻¹) (module docs, "Prefiltered").
pub const PREFILTER_POLE: f32 = 0.6;

/// The regressor of the self-tuner's model y(t) = −a1 y(t−1) − a2 y(t−2) + b0 u(t−k) + … +
/// b3 u(t−k−3) + d: φ(t) = [−y(t−1), −y(t−2), u(t−k), …, u(t−k−3), 1], target y(t).
///
/// The output history starts full of the first measurement (the plant is taken to be at rest),
/// the input history full of the starting duty; φ is complete from the third measurement on.
/// The processor-in-the-loop runner builds its shadow estimators on this same type.
#[derive(Clone, Debug, PartialEq)]
pub struct SecondOrderRegressor {
    /// y(t), y(t−1), y(t−2), as measured.
    y: [f32; 3],
    /// The same through the prefilter 1 / (1 − τ q⁻¹).
    yf: [f32; 3],
    /// Measurements taken, saturating.
    filled: u8,
    /// u(t−1), as applied.
    u_last: f32,
    /// u(t−1), u(t−2), … through the prefilter (the newest first).
    u: [f32; MAX_K + ESTIMATED_NB],
    /// Delay, 1 … [`MAX_K`].
    k: usize,
    /// The prefilter's pole τ, 0 ≤ τ < 1 (0: none).
    tau: f32,
    /// Samples in a row the applied duty has not changed, saturating.
    held_n: u16,
    /// Measurements still to take after a gap before φ is complete again ([`Self::gap`]).
    fresh: u8,
}

impl SecondOrderRegressor {
    /// Empty history for delay `k` (1 … [`MAX_K`]), the input held at `u0`, no prefilter.
    pub fn new(k: usize, u0: f32) -> Result<Self, ModelError> {
        Self::prefiltered(k, u0, 0.0)
    }

    /// The same with the data prefilter 1 / (1 − τ q⁻¹) (module docs, "Prefiltered"); τ
    /// outside [0, 1) is refused.
    pub fn prefiltered(k: usize, u0: f32, tau: f32) -> Result<Self, ModelError> {
        if !(1..=MAX_K).contains(&k) || !(0.0..1.0).contains(&tau) {
            return Err(ModelError::Order);
        }
        let uf = u0 / (1.0 - tau);
        Ok(Self {
            y: [0.0; 3],
            yf: [0.0; 3],
            filled: 0,
            u_last: u0,
            u: [uf; MAX_K + ESTIMATED_NB],
            k,
            tau,
            held_n: 0,
            fresh: 0,
        })
    }

    /// The delay k, samples.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Takes the measurement y(t); true when φ(t) is complete. A non-finite y is refused (false,
    /// history unchanged).
    pub fn push_y(&mut self, y: f32) -> bool {
        if !y.is_finite() {
            return false;
        }
        if self.filled == 0 {
            self.y = [y; 3];
            self.yf = [y / (1.0 - self.tau); 3];
        } else {
            shift_in(&mut self.y, y);
            let yf = y + self.tau * self.yf[0];
            shift_in(&mut self.yf, yf);
        }
        self.filled = self.filled.saturating_add(1);
        if self.fresh > 0 {
            self.fresh -= 1;
            return false;
        }
        self.filled >= 3
    }

    /// A sample went by without a measurement (the step's sensor fault) and `applied` was
    /// applied: the input history takes it, and the next [`GAP_SETTLE_SAMPLES`] measurements
    /// complete no φ. Across the gap the output history would pair the last measurement before it
    /// with the inputs after, and the prefilter carries that mismatch on (0.6ⁿ of it n samples
    /// later).
    pub fn gap(&mut self, applied: f32) {
        if applied.is_finite() {
            self.push_u(applied);
        }
        self.fresh = GAP_SETTLE_SAMPLES;
    }

    /// The target y(t) of the last measurement, through the prefilter.
    pub fn y(&self) -> f32 {
        self.yf[0]
    }

    /// The duty applied last, u(t−1).
    pub fn u_last(&self) -> f32 {
        self.u_last
    }

    /// u(t − m), m ≥ 1.
    fn u_past(&self, m: usize) -> f32 {
        // m ≥ 1 and m − 1 ≤ k + ESTIMATED_NB − 1: always inside the history.
        self.u.get(m.wrapping_sub(1)).copied().unwrap_or(0.0)
    }

    /// φ(t) = [−y(t−1), −y(t−2), u(t−k), …, u(t−k−3), 1].
    pub fn phi(&self) -> SVector<f32, N_THETA> {
        let h = &self.yf;
        let k = self.k;
        SVector::<f32, N_THETA>::from([
            -h[1],
            -h[2],
            self.u_past(k),
            self.u_past(k + 1),
            self.u_past(k + 2),
            self.u_past(k + 3),
            1.0,
        ])
    }

    /// Whether the duty applied has not changed over every u in φ, u(t−1) … u(t−k−3) of the
    /// raw duties: φ's input terms are then one constant, as the offset's is, and carry no
    /// information on B.
    pub fn input_held(&self) -> bool {
        usize::from(self.held_n) >= self.k + ESTIMATED_NB
    }

    /// Records the duty applied at t (it becomes u(t−1) for the next φ).
    pub fn push_u(&mut self, applied: f32) {
        if applied.to_bits() == self.u_last.to_bits() {
            self.held_n = self.held_n.saturating_add(1);
        } else {
            self.held_n = 0;
        }
        self.u_last = applied;
        let uf = applied + self.tau * self.u[0];
        shift_in(&mut self.u, uf);
    }
}

/// Measurements after a gap in the data (a sensor fault the step rode out) before the estimator
/// updates again ([`SecondOrderRegressor::gap`]; module docs, "Across a sensor fault"): two for
/// the output lags, ten for the prefilter's memory of the samples before the gap (0.6¹⁰ ≈ 0.6 %).
pub const GAP_SETTLE_SAMPLES: u8 = 12;

/// GPC's λ while the law runs on a model the current estimate has not confirmed (`Frozen`: the
/// start model, one restored from flash, or the last trusted one), at least this. On a
/// carrier far faster than its start model (a small, light load) λ = 0.5 drove full duty for
/// 30 s at start and the cold plate's stored cold then cooled the load at zero duty, which the
/// stuck-on detector read as a stuck SSR (campaign mission 23269); λ = 3 is what GPC ran with
/// before issue 15.
pub const CAUTIOUS_GPC_LAMBDA: f32 = 3.0;

/// GPC's λ while the estimator is paused at rest ([`SelfTuning::resting`]) on a model it had
/// confirmed, at least this (module docs, "Damped at rest"; an unconfirmed one keeps
/// [`CAUTIOUS_GPC_LAMBDA`]): a half-loaded H-TER I that had drifted into a ±0.25 °C cycle of
/// about 100 s on its full-load start model kept it for hours at λ 3.
pub const REST_GPC_LAMBDA: f32 = 10.0;

/// Samples at rest after which the estimator pauses (30 min at Ts = 10 s; module docs, "Paused
/// at rest").
pub const REST_PAUSE_SAMPLES: u16 = 180;

/// P(0) of an estimator resumed from the model its self-tuner stored
/// ([`AdaptiveConfig::resumed_from`]; module docs, "Resumed from a stored model").
pub const RESUMED_P0: f32 = 0.01;

/// P(0) of the offset d, whatever the model's: a stored model does not hold it.
pub const OFFSET_P0: f32 = 1.0;

/// Samples at rest after which the estimator pauses once a rest has confirmed the estimate
/// (1 min at Ts = 10 s; module docs, "Paused sooner once confirmed"). 1–30 samples measured
/// alike on the half load (1.23–1.25 × the bound at 28 °C, seeds 1–8); 6 is past one sample's
/// noise.
pub const CONFIRMED_PAUSE_SAMPLES: u16 = 6;

/// A sample counts towards the rest when the load is within this of the setpoint, °C.
pub const REST_BAND_C: f32 = 0.2;

/// The rest ends, and the estimator resumes, when the load leaves the setpoint by more than
/// this, °C (or the setpoint changes).
pub const REST_EXIT_C: f32 = 0.3;

/// The reset's gain, °C of setpoint per °C of error per sample (module docs, "Reset at rest").
pub const RESET_GAIN: f32 = 0.015;

/// Samples within [`REST_BAND_C`] after which the reset starts (3 min at Ts = 10 s).
pub const RESET_AFTER_SAMPLES: u16 = 18;

/// Most the reset moves the law's setpoint either way, °C.
pub const RESET_MAX_C: f32 = 0.1;

/// Lead of the first approach, samples of Ts (150 s at Ts = 10 s; see the module docs).
pub const APPROACH_LEAD_SAMPLES: f32 = 15.0;

/// Most the first approach raises the law's setpoint, °C (see the module docs).
pub const APPROACH_RAISE_MAX_C: f32 = 1.5;

/// Self-tuning state.
#[derive(Clone, Debug)]
pub struct SelfTuning {
    cfg: AdaptiveConfig,
    rls: Rls<N_THETA>,
    law_state: LawState,
    fallback: Pi,
    trusted: Option<Model>,
    mode: AdaptiveMode,
    /// The first approach lasts.
    approaching: bool,
    updates: u32,
    reg: SecondOrderRegressor,
    last_error: f32,
    /// The setpoint of the hold under way, and its samples within [`REST_BAND_C`] (saturating
    /// at [`REST_PAUSE_SAMPLES`]).
    rest_w: f32,
    rest_n: u16,
    /// The reset's gain ([`RESET_GAIN`] for GPC, 0 for the other laws) and the setpoint's
    /// reset, °C (module docs, "Reset at rest").
    reset_gain: f32,
    reset_c: f32,
    /// GPC's first cost row, N1 = k + 1 or `GpcConfig::n1` when larger, at most N2 (module
    /// docs, "The cost's first row"; 0 for the other laws): made once, not every sample.
    gpc_n1: usize,
    /// The model trusted when the estimator last paused at rest.
    rested: Option<Model>,
    /// Samples within the rest's band after which the estimator pauses: [`REST_PAUSE_SAMPLES`]
    /// until a rest has paused it on an estimate it trusts, [`CONFIRMED_PAUSE_SAMPLES`] after.
    pause_after: u16,
}

impl SelfTuning {
    /// A controller sampled every `ts_s` (the step's period) starting from duty `u0`, or why
    /// `cfg` is refused ([`AdaptiveConfig::validate`]).
    pub fn new(cfg: AdaptiveConfig, ts_s: f32, u0: f32) -> Result<Self, AdaptiveError> {
        cfg.validate()?;
        // The prefilter and the reset for GPC only (module docs, "Prefiltered", "Reset at rest").
        let gpc = matches!(cfg.law, Law::Gpc(_));
        let tau = if gpc { PREFILTER_POLE } else { 0.0 };
        let reg = SecondOrderRegressor::prefiltered(cfg.k, u0, tau).map_err(|_| AdaptiveError::Delay)?;
        let trusted = cfg.initial.filter(|m| plausible_model_cold(&cfg, m));
        let theta0 = match trusted {
            // A start model's B beyond its nb is zero (a second-order identification's b2, b3).
            Some(m) => {
                let (a, b) = (m.a(), m.b());
                SVector::<f32, N_THETA>::from([a[0], a[1], b[0], b[1], b[2], b[3], 0.0])
            }
            // A slow stable pole pair and a small cooling gain: a neutral start for RLS.
            None => SVector::<f32, N_THETA>::from([-1.5, 0.5, -0.01, 0.0, 0.0, 0.0, 0.0]),
        };
        // The start model is designed on as given, without GPC's T-filter. Designed with it (as
        // estimates are), the start is smoother on the piecewise steps (2–4 % less IAE) but
        // GPC, later at 9 V and 36 °C ambient, limit-cycles ±0.3 °C against full duty on 6 of 8
        // seeds (`self_tuning_laws_survive_a_plant_change_mid_run`), against ±0.02 °C without.
        let mut fallback = Pi::new(PiConfig { bias: u0, ..cfg.fallback }, ts_s);
        fallback.track(&ControlInput { y_c: 0.0, w_c: 0.0 }, u0);
        // The offset d is not in a stored model: it starts at 0 with the start's variance, not
        // the model's (module docs, "Resumed from a stored model").
        let mut rls = Rls::new(&cfg.rls, theta0);
        rls.set_variance(N_THETA - 1, OFFSET_P0);
        Ok(Self {
            cfg,
            rls,
            law_state: LawState::new(u0),
            fallback,
            trusted,
            approaching: true,
            mode: if trusted.is_some() { AdaptiveMode::Frozen } else { AdaptiveMode::Fallback },
            updates: 0,
            reg,
            last_error: 0.0,
            rest_w: f32::NAN,
            rest_n: 0,
            reset_gain: if gpc { RESET_GAIN } else { 0.0 },
            reset_c: 0.0,
            // (At most N2: a horizon that ends sooner keeps its last row, as before.)
            gpc_n1: match cfg.law {
                Law::Gpc(g) => g.n1.max(cfg.k + 1).min(g.n2),
                _ => 0,
            },
            rested: None,
            pause_after: REST_PAUSE_SAMPLES,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &AdaptiveConfig {
        &self.cfg
    }

    /// The law's state (e.g. GPC's staged design, [`LawState::gpc`]).
    pub fn law_state(&self) -> &LawState {
        &self.law_state
    }

    /// The current estimate as a model, its B's tail b1 … b3 no warmer than zero; `None` when
    /// the warming terms clipped cancel more than [`WARM_TAIL_MAX`] of the cooling ones (module
    /// docs, "Projection").
    pub fn estimate(&self) -> Option<Model> {
        let th = clip_warming_tail(self.theta())?;
        model_from_theta(&self.cfg, &th[..2 + self.b_terms()])
    }

    /// B terms the law's model has: [`ESTIMATED_NB`] for GPC; two for GMVC and IGMVC, whose
    /// b2, b3 the estimator holds at zero (module docs).
    fn b_terms(&self) -> usize {
        if matches!(self.cfg.law, Law::Gpc(_)) {
            ESTIMATED_NB
        } else {
            2
        }
    }

    /// θ = [a1 a2 b0 b1 b2 b3] (without the offset d).
    pub fn theta(&self) -> [f32; 2 + ESTIMATED_NB] {
        let th = self.rls.theta();
        [th[0], th[1], th[2], th[3], th[4], th[5]]
    }

    /// trace(P) of the estimator.
    pub fn trace_p(&self) -> f32 {
        self.rls.trace_p()
    }

    /// A-priori prediction error of y at the last update, °C (not refreshed while paused at
    /// rest).
    pub fn prediction_error(&self) -> f32 {
        self.last_error
    }

    /// Which controller drives.
    pub fn mode(&self) -> AdaptiveMode {
        self.mode
    }

    /// Estimator updates since start.
    pub fn updates(&self) -> u32 {
        self.updates
    }

    /// The model the law runs on when the estimate is not trusted: the last trusted one, or the
    /// one its last rest confirmed (module docs, "Frozen on the rest's model"); what a board
    /// would persist.
    pub fn trusted_model(&self) -> Option<Model> {
        self.trusted
    }

    /// The setpoint the law is handed during the first approach, for `w` after the measurement
    /// y(t) = `y`: while the load falls, `w` raised by the lead times the fall per sample over
    /// the last two samples, at most [`APPROACH_RAISE_MAX_C`]; else `w`, and the approach ends
    /// if the load is less than 1 °C above `w`. Out of line and called only while the approach
    /// lasts: after it a sample pays one flag test (the processor-in-the-loop budget, and the
    /// default firmware's flash).
    #[inline(never)]
    fn approach_setpoint(&mut self, y: f32, w: f32) -> f32 {
        let fall = self.reg.y[2] - self.reg.y[0];
        if fall > 0.0 {
            let raise = APPROACH_LEAD_SAMPLES * 0.5 * fall;
            return w + if raise < APPROACH_RAISE_MAX_C { raise } else { APPROACH_RAISE_MAX_C };
        }
        if y < w + 1.0 {
            self.approaching = false;
        }
        w
    }

    /// Ends the first approach now (the law aims at the setpoint from the next sample on): for
    /// measuring what the approach's lead does (`hter sim --no-approach-lead`).
    pub fn end_approach(&mut self) {
        self.approaching = false;
    }

    /// Moves the estimate into the cone of plausible static gains (module docs, "Projection"):
    /// B(1) − g_min·A(1) ≥ 0, then g_max·A(1) − B(1) ≥ 0, with A(1) = 1 + a1 + a2 and B(1) the
    /// sum of the b_i, each bound [`CONE_MARGIN`] inside the trust check's. Each is a half-space
    /// cᵀθ ≥ c₀ of θ = [a1 a2 b0 … b3 d]. The far bound (g_min) is on the B the laws and the
    /// trust check get, its warming tail clipped: the tail's terms above zero are left out of
    /// B(1) there. The near bound needs no such care: clipping only makes B(1) cool more.
    fn project(&mut self) {
        let (lo, hi) = (CONE_MARGIN * self.cfg.gain_min_c_per_duty, self.cfg.gain_max_c_per_duty / CONE_MARGIN);
        // B(1) − lo·(1 + a1 + a2) ≥ 0  ⇔  −lo·a1 − lo·a2 + Σb ≥ lo
        let th = self.rls.theta();
        let cool = |b: f32| if b > 0.0 { 0.0 } else { 1.0 };
        let c = SVector::<f32, N_THETA>::from([-lo, -lo, 1.0, cool(th[3]), cool(th[4]), cool(th[5]), 0.0]);
        self.rls.project_onto_halfspace(&c, lo);
        // hi·(1 + a1 + a2) − B(1) ≥ 0  ⇔  hi·a1 + hi·a2 − Σb ≥ −hi
        let c = SVector::<f32, N_THETA>::from([hi, hi, -1.0, -1.0, -1.0, -1.0, 0.0]);
        self.rls.project_onto_halfspace(&c, -hi);
    }

    /// Counts the samples of the hold under way (module docs, "Paused at rest"). A NaN
    /// measurement or setpoint compares false everywhere and ends the rest; so does an applied
    /// duty at 0 or 1.
    fn count_rest(&mut self, input: &ControlInput) {
        let e = input.y_c - input.w_c;
        // The duty applied last: at a rail the law is not regulating.
        let u = self.reg.u_last();
        if input.w_c != self.rest_w || !(e.abs() <= REST_EXIT_C) || !(u > 0.0 && u < 1.0) {
            self.rest_w = input.w_c;
            self.rest_n = 0;
            self.reset_c = 0.0;
            return;
        }
        if e.abs() < REST_BAND_C && self.rest_n < REST_PAUSE_SAMPLES {
            self.rest_n += 1;
        }
        // The reset (module docs, "Reset at rest"); e is finite here (|e| ≤ REST_EXIT_C). It
        // reaches the law only after the first approach.
        // Held where it is rather than clamped at the bound (fewer instructions a sample).
        if self.rest_n >= RESET_AFTER_SAMPLES {
            let r = self.reset_c - self.reset_gain * e;
            if r.abs() <= RESET_MAX_C {
                self.reset_c = r;
            }
        }
    }

    /// The setpoint's reset the law is handed on top of the setpoint, °C (module docs, "Reset
    /// at rest").
    pub fn reset_c(&self) -> f32 {
        self.reset_c
    }

    /// The hold has lasted [`REST_PAUSE_SAMPLES`] within the band: the estimator is paused and
    /// GPC runs with the rest's λ (module docs, "Paused at rest", "Damped at rest"). Once a rest
    /// has confirmed the estimate, the estimator pauses sooner ("Paused sooner once confirmed").
    pub fn resting(&self) -> bool {
        self.rest_n >= REST_PAUSE_SAMPLES
    }

    /// Updates the estimator with y(t); returns true if an update was made, or if it was
    /// skipped at rest (the sample counts towards warm-up; [`Self::prediction_error`] keeps the
    /// last update's).
    fn estimate_step(&mut self, y: f32) -> bool {
        if !self.reg.push_y(y) {
            return false;
        }
        if self.rest_n >= self.pause_after {
            self.updates = self.updates.saturating_add(1);
            // The model the rest confirms (module docs, "Frozen on the rest's model"): kept on
            // the paused samples, which skip the estimator's update, so the samples that run it
            // pay nothing for it. Only a rest of the full half hour confirms: a minute's calm
            // inside a ring (paused sooner) would keep the ring's model.
            if self.resting() {
                self.rested = self.trusted;
                // GPC only: IGMVC paused sooner held H-TER II's `piecewise` (seed 7) 0.21 °C
                // off the setpoint.
                if self.mode == AdaptiveMode::Adaptive && matches!(self.cfg.law, Law::Gpc(_)) {
                    self.pause_after = CONFIRMED_PAUSE_SAMPLES;
                }
            }
            return true;
        }
        // The duty held over the whole window: φ's input terms are one constant, as the
        // offset's is, and the data say nothing of B (module docs, "Held at a rail").
        if self.reg.input_held() {
            return true;
        }
        let mut phi = self.reg.phi();
        // The B terms the law does not use stay at zero (θ index 2 + i is b_i).
        let unused = 2 + self.b_terms()..2 + ESTIMATED_NB;
        for i in unused.clone() {
            phi[i] = 0.0;
        }
        match self.rls.update(&self.cfg.rls, &phi, self.reg.y()) {
            Ok(e) => {
                for i in unused {
                    self.rls.hold(i);
                }
                self.project();
                self.last_error = e;
                self.updates = self.updates.saturating_add(1);
                true
            }
            Err(_) => false,
        }
    }
}

/// The model the laws are designed on for θ = [a1 a2 b0 … b_{nb−1}] (nb = 1 … [`ESTIMATED_NB`])
/// under `cfg`: delay `cfg.k`, and GPC's T-filter C = 1 − τ q⁻¹ when the law is GPC (see
/// [`AdaptiveConfig::t_filter`]). `None` when a coefficient is not finite, `theta` has fewer
/// than 3 or more than 2 + [`ESTIMATED_NB`] entries, or `cfg.k` is out of range.
pub fn model_from_theta(cfg: &AdaptiveConfig, theta: &[f32]) -> Option<Model> {
    if theta.len() < 3 || theta.len() > 2 + ESTIMATED_NB {
        return None;
    }
    let tau = cfg.t_filter;
    let c: &[f32] = if matches!(cfg.law, Law::Gpc(_)) && tau > 0.0 && tau < 1.0 { &[-tau] } else { &[] };
    Model::new(&theta[..2], &theta[2..], c, cfg.k).ok()
}

/// The most of the cooling terms' sum |b0 + …| (those ≤ 0) that the warming terms of B's tail
/// (b1 … b3 > 0) may cancel for the estimate to give the law a model (module docs,
/// "Projection"): clipped at zero, more would give the model a static gain over
/// 1 / (1 − 0.7) ≈ 3.3 × the estimate's own.
pub const WARM_TAIL_MAX: f32 = 0.7;

/// How far inside the trust check's static-gain bounds the projection puts the estimate (module
/// docs, "Projection"): to 0.98 × g_min and g_max / 0.98. With A(1) near zero (an estimate
/// drifted towards an integrator in a long hold), the static gain B(1) / A(1) computed in f32
/// is uncertain by ≈ 0.1 %, and an estimate projected exactly onto the bound went in and out of
/// the trusted set on rounding alone.
pub const CONE_MARGIN: f32 = 0.98;

/// θ = [a1 a2 b0 … b3] with B's tail b1 … b3 clipped at zero, or `None` when the warming terms
/// clipped sum to more than [`WARM_TAIL_MAX`] × the cooling terms' |sum| (b0 included; a b0 above
/// zero is left for [`plausible_model`] to refuse).
pub fn clip_warming_tail(mut th: [f32; 2 + ESTIMATED_NB]) -> Option<[f32; 2 + ESTIMATED_NB]> {
    let (mut cool, mut warm) = (if th[2] < 0.0 { -th[2] } else { 0.0 }, 0.0);
    for b in &mut th[3..] {
        if *b > 0.0 {
            warm += *b;
            *b = 0.0;
        } else {
            cool -= *b;
        }
    }
    // NaN compares false: a non-finite θ is left for the plausibility check.
    if warm > WARM_TAIL_MAX * cool {
        return None;
    }
    Some(th)
}

/// Parameter projection: is `m` a model the laws may be designed from?
///
/// The self-tuner's structure (na ≤ 2, nb ≤ [`ESTIMATED_NB`]), a stable A, a cooling static gain, and every B
/// coefficient cooling (b_i ≤ 0): the step response of a Peltier cooler seen through the RTD
/// is monotone, so a positive b_i is an artefact of poor excitation — and a positive b0
/// reverses the sign of the first-step gain g0 that (I)GMVC divides by, so the law would heat
/// when it should cool (on the simulated H-TER II without this check the load drifted to 12 °C
/// at a 4 °C setpoint).
pub fn plausible_model(cfg: &AdaptiveConfig, m: &Model) -> bool {
    // The self-tuner's structure: anything else cannot be its model.
    let (a, b) = (m.a(), m.b());
    let a2 = if m.na() == 2 { a[1] } else { 0.0 };
    m.na() <= 2
        && m.nb() <= ESTIMATED_NB
        && second_order_stable(a[0], a2)
        && b[..m.nb()].iter().all(|&b| b <= 0.0)
        && m.static_gain().is_some_and(|g| (cfg.gain_min_c_per_duty..=cfg.gain_max_c_per_duty).contains(&g))
}

/// [`plausible_model`] out of line: one copy for the start model's check, a stored record's and
/// the per-sample one in `update`, instead of one inlined into each (−120 B of the default
/// firmware for the first two; −176 B of the calibrated module-sense build for `update`'s, for a
/// call per sample).
#[inline(never)]
pub(crate) fn plausible_model_cold(cfg: &AdaptiveConfig, m: &Model) -> bool {
    plausible_model(cfg, m)
}

impl Controller for SelfTuning {
    fn update(&mut self, input: &ControlInput) -> Result<f32, ControlError> {
        self.count_rest(input);
        let healthy = self.estimate_step(input.y_c);
        if healthy && self.updates >= self.cfg.warmup_samples {
            if let Some(m) = self.estimate().filter(|m| plausible_model_cold(&self.cfg, m)) {
                self.trusted = Some(m);
                self.mode = AdaptiveMode::Adaptive;
            } else if self.trusted.is_some() {
                if self.mode == AdaptiveMode::Adaptive && self.rested.is_some() {
                    self.trusted = self.rested;
                }
                self.mode = AdaptiveMode::Frozen;
            }
        }
        let w = if self.approaching { self.approach_setpoint(input.y_c, input.w_c) } else { input.w_c + self.reset_c };
        let law = match self.cfg.law {
            // Cautious while the model is one the estimate has not confirmed, damped while the
            // estimator is paused at rest; the cost from k + 1 (module docs).
            Law::Gpc(g) => {
                let least = if self.mode != AdaptiveMode::Adaptive {
                    CAUTIOUS_GPC_LAMBDA
                } else if self.resting() {
                    REST_GPC_LAMBDA
                } else {
                    0.0
                };
                let lambda = g.lambda.max(least);
                Law::Gpc(GpcConfig { n1: self.gpc_n1, lambda, ..g })
            }
            other => other,
        };
        // Until GPC's first staged design is complete (four samples after a start, and after a
        // change of horizons) the law would hold its last duty, after a boot the board's boot
        // duty, whatever the reading: the fallback PI drives on the reading instead, and the mode
        // stays (module docs, "The first samples"). Without `mv-laws` the law is GPC, and the
        // match folds away (−56 B of flash on the calibrated module-sense build against matching).
        let other_law = cfg!(feature = "mv-laws") && !matches!(law, Law::Gpc(_));
        let designed = other_law || self.law_state.gpc().model().is_some();
        let law_u = self.law_state.update(&law, self.trusted.as_ref(), input.y_c, w);
        let pi_u = self.fallback.update(input);
        match law_u {
            Ok(u) if self.mode != AdaptiveMode::Fallback => {
                if designed {
                    Ok(u)
                } else {
                    pi_u
                }
            }
            _ => {
                self.mode = AdaptiveMode::Fallback;
                pi_u
            }
        }
    }

    fn track(&mut self, input: &ControlInput, applied: f32) {
        if !applied.is_finite() {
            return;
        }
        self.law_state.track(applied);
        self.fallback.track(input, applied);
        self.reg.push_u(applied);
    }

    /// A sample without a trusted reading: the estimator's regressor records the gap (module
    /// docs, "Across a sensor fault"), the law forgets its measured past, and the PI resumes
    /// where it left off.
    fn skip(&mut self, applied: f32) {
        self.reg.gap(applied);
        self.law_state.reprime();
    }

    fn name(&self) -> &'static str {
        self.cfg.law.name()
    }

    fn status(&self) -> Option<ControllerStatus> {
        Some(ControllerStatus {
            mode: self.mode,
            theta: self.theta(),
            trace_p: self.trace_p(),
            prediction_error: self.last_error,
            reset_c: self.reset_c,
        })
    }

    fn trusted_model(&self) -> Option<Model> {
        self.trusted
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::gpc::GpcConfig;
    use crate::profile::{ADAPTIVE_GPC, START_MODEL_HTER1};

    const TS_S: f32 = 10.0;
    /// The tests run in deviation variables around a rest at 0 °C and zero duty (no offset d):
    /// the plant below is exactly the start model there, so its estimate stays the start model
    /// until the plant changes. The setpoint asks for 1 °C of cooling.
    const W_C: f32 = -1.0;

    /// y(t) = −a1 y(t−1) − a2 y(t−2) + b0 u(t−k) + b1 u(t−k−1), at rest at y = 0, u = 0.
    struct Plant {
        a: [f32; 2],
        b: [f32; 2],
        k: usize,
        y: [f32; 2],
        u: std::vec::Vec<f32>,
    }

    impl Plant {
        /// The start model itself.
        fn start_model() -> Plant {
            let m = START_MODEL_HTER1;
            Plant {
                a: [m.a()[0], m.a()[1]],
                b: [m.b()[0], m.b()[1]],
                k: m.k(),
                y: [0.0; 2],
                u: std::vec![0.0; m.k() + 1],
            }
        }

        /// Applies u(t) and returns y(t + 1).
        fn advance(&mut self, u: f32) -> f32 {
            self.u.rotate_right(1);
            self.u[0] = u;
            let y = -self.a[0] * self.y[0] - self.a[1] * self.y[1]
                + self.b[0] * self.u[self.k - 1]
                + self.b[1] * self.u[self.k];
            self.y = [y, self.y[0]];
            y
        }
    }

    /// One closed-loop sample: the controller's request clipped to [0, 1], or `applied` instead
    /// (what the step's supervisor does when it overrides). Returns the mode after the sample.
    fn sample(c: &mut SelfTuning, plant: &mut Plant, y: &mut f32, applied: Option<f32>) -> AdaptiveMode {
        let input = ControlInput { y_c: *y, w_c: W_C };
        let requested = c.update(&input).unwrap_or(0.0).clamp(0.0, 1.0);
        let u = applied.unwrap_or(requested);
        c.track(&input, u);
        *y = plant.advance(u);
        c.mode()
    }

    /// An excitation the estimator can learn from: 0 and 0.4 duty, switched every 7 samples.
    fn square(t: usize) -> f32 {
        if (t / 7).is_multiple_of(2) {
            0.4
        } else {
            0.0
        }
    }

    fn start(cfg: AdaptiveConfig) -> SelfTuning {
        SelfTuning::new(cfg, TS_S, 0.0).unwrap()
    }

    #[test]
    fn refuses_configurations_it_cannot_run() {
        // A delay of 0 once reached the regressor and indexed u(t − 0 − 1) with an underflow
        // (a panic in a debug build, a wrong input in a release one).
        let refused = |cfg: AdaptiveConfig| SelfTuning::new(cfg, TS_S, 0.4).err();
        assert_eq!(refused(AdaptiveConfig { k: 0, ..ADAPTIVE_GPC }), Some(AdaptiveError::Delay));
        assert_eq!(refused(AdaptiveConfig { k: MAX_K + 1, ..ADAPTIVE_GPC }), Some(AdaptiveError::Delay));
        let rls = RlsConfig { forgetting: 0.0, ..ADAPTIVE_GPC.rls };
        assert_eq!(refused(AdaptiveConfig { rls, ..ADAPTIVE_GPC }), Some(AdaptiveError::Estimator));
        for (lo, hi) in [(-10.0, -1000.0), (-1000.0, 10.0), (f32::NAN, -10.0), (f32::NEG_INFINITY, -10.0)] {
            let cfg = AdaptiveConfig { gain_min_c_per_duty: lo, gain_max_c_per_duty: hi, ..ADAPTIVE_GPC };
            assert_eq!(refused(cfg), Some(AdaptiveError::GainRange), "{lo} … {hi}");
        }
        for tau in [1.0, -0.1, f32::NAN] {
            assert_eq!(refused(AdaptiveConfig { t_filter: tau, ..ADAPTIVE_GPC }), Some(AdaptiveError::TFilter));
        }
        let pi = ADAPTIVE_GPC.fallback;
        for fallback in
            [PiConfig { kp_per_c: f32::NAN, ..pi }, PiConfig { kp_per_c: 0.0, ..pi }, PiConfig { ti_s: 0.0, ..pi }]
        {
            assert_eq!(refused(AdaptiveConfig { fallback, ..ADAPTIVE_GPC }), Some(AdaptiveError::Fallback));
        }
        let law = Law::Gpc(GpcConfig { n1: 0, ..GpcConfig::DEFAULT });
        assert_eq!(refused(AdaptiveConfig { law, ..ADAPTIVE_GPC }), Some(AdaptiveError::Law(ControlError::Config)));
        // A GPC horizon that ends before the delay: no duty acts on any predicted sample. Run,
        // it held its starting duty for good and the PI never took over (`hter sim --n2 4`: a
        // carrier left at 28 °C for 3 h); the board's builds take the PI for a refused
        // configuration (`profile::SelfTuningOrPi`). N2 = k reaches it
        // (`a_horizon_ending_at_the_delay_still_runs_gpc`).
        let k = ADAPTIVE_GPC.k;
        for (n2, nu) in [(k - 1, 1), (1, 1)] {
            let law = Law::Gpc(GpcConfig { n2, nu, ..GpcConfig::DEFAULT });
            let cfg = AdaptiveConfig { law, ..ADAPTIVE_GPC };
            assert_eq!(refused(cfg), Some(AdaptiveError::Law(ControlError::Config)), "N2 {n2}");
        }
        let law = Law::Gpc(GpcConfig { n2: k, nu: 1, ..GpcConfig::DEFAULT });
        assert_eq!(refused(AdaptiveConfig { law, ..ADAPTIVE_GPC }), None);
        // The delay of a restored model counts: a record with k = 10 under N2 = 9.
        let law = Law::Gpc(GpcConfig { n2: 9, ..GpcConfig::DEFAULT });
        let restored = AdaptiveConfig { law, ..ADAPTIVE_GPC }.restored_from(START_MODEL_HTER1.with_delay(10).unwrap());
        assert_eq!(refused(restored), Some(AdaptiveError::Law(ControlError::Config)));
        // The longest delay runs: u(t − k − 1) is the oldest input kept.
        let mut c = SelfTuning::new(AdaptiveConfig { k: MAX_K, ..ADAPTIVE_GPC }, TS_S, 0.4).unwrap();
        for _ in 0..5 {
            let input = ControlInput { y_c: 4.1, w_c: 4.0 };
            assert!(c.update(&input).is_ok());
            c.track(&input, 0.4);
        }
        assert_eq!(c.updates(), 3);
        assert_eq!(SecondOrderRegressor::new(0, 0.4), Err(ModelError::Order));
    }

    #[test]
    fn a_board_restarted_from_its_stored_model_resumes_the_estimator() {
        use crate::persist::ModelRecord;
        // What the boot's flash restore hands the default firmware (`restore_records`): the
        // profile resumed from the model its self-tuner stored.
        let rec = ModelRecord::from_model(&START_MODEL_HTER1).unwrap();
        let restored = rec.restore(&ADAPTIVE_GPC).unwrap();
        let stored = rec.to_model(&ADAPTIVE_GPC).unwrap();
        // The firmware's constant with it: the configuration `resumed_from` documents.
        let cfg = ADAPTIVE_GPC.with_restored(&restored);
        assert_eq!(cfg, ADAPTIVE_GPC.resumed_from(stored));
        // P(0) = 0.01·I for the model's six parameters and 1 for the offset (module docs,
        // "Resumed from a stored model"), not the start's I: trace 1.06, not 7.
        let c = SelfTuning::new(cfg, TS_S, 0.4).unwrap();
        assert!((c.trace_p() - (6.0 * RESUMED_P0 + OFFSET_P0)).abs() < 1e-6, "trace P(0) = {}", c.trace_p());
        // Nothing stored (the restore hands the constant back): the start's P(0).
        assert_eq!(ADAPTIVE_GPC.with_restored(&ADAPTIVE_GPC), ADAPTIVE_GPC);
    }

    #[test]
    fn the_first_approach_aims_above_the_setpoint_while_the_load_falls() {
        let mut c = start(ADAPTIVE_GPC);
        let at = |c: &mut SelfTuning, y: f32| {
            c.reg.push_y(y);
            c.approach_setpoint(y, 4.0)
        };
        // At rest 5 °C above the setpoint (the history starts full of the first reading): the
        // setpoint as it is, and the approach goes on.
        assert_eq!(at(&mut c, 9.0), 4.0);
        assert_eq!(at(&mut c, 9.0), 4.0);
        assert!(c.approaching);
        // Falling 0.125 °C over two samples: 15 × 0.0625 = 0.9375 °C higher; faster, at most
        // 1.5 °C higher.
        assert_eq!(at(&mut c, 8.875), 4.9375);
        assert_eq!(at(&mut c, 8.75), 4.0 + APPROACH_RAISE_MAX_C);
        assert_eq!(at(&mut c, 4.5), 4.0 + APPROACH_RAISE_MAX_C);
        // Near the setpoint, still falling over the last two samples: still raised.
        assert_eq!(at(&mut c, 4.5), 4.0 + APPROACH_RAISE_MAX_C);
        assert!(c.approaching);
        // No longer falling less than 1 °C above it: the approach is over for good.
        assert_eq!(at(&mut c, 4.5), 4.0);
        assert!(!c.approaching);
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        for _ in 0..5 {
            sample(&mut c, &mut plant, &mut y, None);
        }
        assert!(!c.approaching);
        // Started at the setpoint (a restart holding the load, `piecewise`'s pre-roll), the
        // approach ends on the first sample.
        let mut c = start(ADAPTIVE_GPC);
        let (mut plant, mut y) = (Plant::start_model(), W_C);
        sample(&mut c, &mut plant, &mut y, None);
        assert!(!c.approaching);
    }

    #[test]
    fn a_duty_held_over_the_window_holds_the_estimate() {
        // The regressor: held once the same duty has been applied over every u in φ (k + 4
        // samples after the one that changed it), at any value; any change starts again.
        let mut r = SecondOrderRegressor::prefiltered(5, 0.4, PREFILTER_POLE).unwrap();
        r.push_u(1.0);
        for n in 0..9 {
            assert!(!r.input_held(), "held after {n}");
            r.push_u(1.0);
        }
        assert!(r.input_held());
        r.push_u(0.999);
        assert!(!r.input_held());
        // The estimator: a pull-down at full duty moves θ only until the window is full of it.
        let mut c = start(ADAPTIVE_GPC);
        let mut y = 20.0;
        let mut moves = 0;
        for n in 0..60 {
            let before = c.theta();
            let input = ControlInput { y_c: y, w_c: 4.0 };
            c.update(&input).unwrap();
            c.track(&input, 1.0);
            y -= 0.05 + 0.01 * (n % 3) as f32;
            moves += usize::from(c.theta() != before);
        }
        // The first samples fill the regressor (3) and run while the window still holds the
        // start's duty (k + 4 = 9 after the first 1.0).
        assert!((1..=12).contains(&moves), "{moves} updates at full duty");
    }

    #[test]
    fn a_warming_tail_is_clipped_unless_it_cancels_most_of_the_cooling() {
        // Campaign mission 2276's settled estimate: b3 warms by 0.30 of the cooling terms'
        // 0.0515; clipped, the rest of θ untouched.
        let th = [-1.829, 0.831, -0.0344, -0.0072, -0.0099, 0.0152];
        assert_eq!(clip_warming_tail(th), Some([-1.829, 0.831, -0.0344, -0.0072, -0.0099, 0.0]));
        // Mission 4384's estimate after the ringing (with the rail hold, 14 h): b3 = +0.0925
        // against cooling terms summing to −0.1003, 0.92 of them: refused.
        assert_eq!(clip_warming_tail([-1.964, 0.964, -0.0074, -0.0436, -0.0493, 0.0925]), None);
        // The limit, 0.7 of the cooling, over any of the tail's terms together.
        assert!(clip_warming_tail([-1.8, 0.8, -0.05, -0.05, 0.03, 0.039]).is_some());
        assert_eq!(clip_warming_tail([-1.8, 0.8, -0.05, -0.05, 0.03, 0.041]), None);
        // A warming b0 is not clipped nor counted as cooling: the plausibility rule refuses it.
        assert_eq!(clip_warming_tail([-1.8, 0.8, 0.01, -0.05, 0.0, 0.0]), Some([-1.8, 0.8, 0.01, -0.05, 0.0, 0.0]));
        assert_eq!(clip_warming_tail([-1.8, 0.8, 0.01, -0.05, 0.0, 0.04]), None);
    }

    #[test]
    fn the_projection_bounds_the_gain_of_the_model_the_trust_check_sees() {
        // A stored estimate after a brown-out in a long hold (`tests/board_stores.rs`): A near an
        // integrator, A(1) = 1e-4, and a small warming b3. Its raw static gain, −970 °C/duty, is
        // inside the cone; with b3 clipped, as the laws and the trust check take it, −1 000 is
        // on its edge, and rounding put it in and out of the set every few samples.
        let mut c = start(ADAPTIVE_GPC);
        let th = [-1.75, 0.7501, -0.017, -0.046, -0.037, 0.003, 0.0];
        c.rls = Rls::new(&c.cfg.rls, SVector::from(th));
        let gain = |c: &SelfTuning| c.estimate().and_then(|m| m.static_gain()).unwrap();
        let raw = (th[2..6].iter().sum::<f32>()) / (1.0 + th[0] + th[1]);
        assert!((-1000.0..=-10.0).contains(&raw), "{raw}");
        assert!(gain(&c) < -995.0, "{}", gain(&c));
        c.project();
        // Moved into the cone of the clipped model, with a margin that rounding cannot cross.
        let g = gain(&c);
        assert!((-985.0..=-975.0).contains(&g), "{g}");
        assert!(c.estimate().is_some_and(|m| plausible_model(c.config(), &m)));
        // Inside already: left where it is.
        let before = c.theta();
        c.project();
        assert_eq!(c.theta(), before);
    }

    #[test]
    fn the_regressor_holds_the_last_outputs_and_the_delayed_inputs() {
        // The prefilter 1 / (1 − τ q⁻¹) in f64, from its steady state at the first value.
        let tau = f64::from(PREFILTER_POLE);
        let filter = |xs: &[f64]| -> Vec<f64> {
            let mut out = vec![xs[0] / (1.0 - tau)];
            for x in &xs[1..] {
                out.push(x + tau * out[out.len() - 1]);
            }
            out
        };
        let close = |got: &[f32], want: &[f64]| {
            got.len() == want.len()
                && got.iter().zip(want).all(|(g, w)| (f64::from(*g) - w).abs() <= 1e-5 * w.abs().max(1.0))
        };
        let mut r = SecondOrderRegressor::prefiltered(2, 0.4, PREFILTER_POLE).unwrap();
        assert!(!r.push_y(5.0), "φ needs three outputs");
        assert!(!r.push_y(f32::NAN), "a NaN is refused");
        r.push_u(0.1); // u(t−1) after the first sample
        assert!(!r.push_y(6.0));
        r.push_u(0.2);
        assert!(r.push_y(7.0));
        // y(t) = 7, y(t−1) = 6, y(t−2) = 5; u(t−1) = 0.2, u(t−2) = 0.1, u(t−3 … t−5) = 0.4 (the
        // start), each through the prefilter; the rest's check reads the duty as applied.
        let yf = filter(&[5.0, 6.0, 7.0]);
        let uf = filter(&[0.4, 0.1, 0.2]);
        let u0 = uf[0];
        assert!(close(&[r.y()], &[yf[2]]), "{} against {}", r.y(), yf[2]);
        let want = [-yf[1], -yf[0], uf[1], u0, u0, u0, 1.0];
        assert!(close(r.phi().as_slice(), &want), "{:?} against {want:?}", r.phi().as_slice());
        assert_eq!(r.u_last(), 0.2);
        // The first output fills the history at the prefilter's steady state: at rest, φ is
        // complete with it.
        let mut r = SecondOrderRegressor::prefiltered(1, 0.4, PREFILTER_POLE).unwrap();
        r.push_y(5.0);
        r.push_y(5.0);
        assert!(r.push_y(5.5));
        let yf = filter(&[5.0, 5.0, 5.5]);
        let u0 = 0.4 / (1.0 - tau);
        let want = [-yf[1], -yf[0], u0, u0, u0, u0, 1.0];
        assert!(close(r.phi().as_slice(), &want), "{:?} against {want:?}", r.phi().as_slice());
    }

    /// The cost from k + 1 stops at N2: a horizon that ends at the delay (N2 = k = 5) keeps
    /// its last row and GPC runs, instead of a refused N1 > N2 handing every sample to the PI.
    #[test]
    fn a_horizon_ending_at_the_delay_still_runs_gpc() {
        let law = Law::Gpc(GpcConfig { n2: START_MODEL_HTER1.k(), ..GpcConfig::DEFAULT });
        let mut c = start(AdaptiveConfig { law, ..ADAPTIVE_GPC });
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        for t in 0..40 {
            assert_ne!(sample(&mut c, &mut plant, &mut y, None), AdaptiveMode::Fallback, "sample {t}");
        }
    }

    #[test]
    fn warm_up_holds_the_start_model_then_a_trusted_estimate_engages() {
        let mut c = start(ADAPTIVE_GPC);
        assert_eq!(c.mode(), AdaptiveMode::Frozen, "a plausible start model is trusted at once");
        assert_eq!(c.trusted_model(), Some(START_MODEL_HTER1));
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        // The first two samples fill the regressor; the estimator updates from the third on,
        // and its estimate (plausible all along: the plant is the start model) is trusted once
        // it has made `warmup_samples` updates.
        let engaged = (ADAPTIVE_GPC.warmup_samples + 2) as usize;
        for t in 1..engaged {
            assert_eq!(sample(&mut c, &mut plant, &mut y, None), AdaptiveMode::Frozen, "sample {t}");
            assert!(c.estimate().is_some_and(|m| plausible_model(c.config(), &m)), "sample {t}");
            assert_eq!(c.trusted_model(), Some(START_MODEL_HTER1), "sample {t}");
        }
        assert_eq!(sample(&mut c, &mut plant, &mut y, None), AdaptiveMode::Adaptive);
        assert_eq!(c.updates(), ADAPTIVE_GPC.warmup_samples);
        assert_eq!(c.trusted_model(), c.estimate(), "the trusted model follows the estimate");
        for _ in 0..300 {
            assert_eq!(sample(&mut c, &mut plant, &mut y, None), AdaptiveMode::Adaptive);
        }
        assert!((y - W_C).abs() < 0.05, "the law brought the load to the setpoint: {y}");
    }

    #[test]
    fn at_rest_the_law_aims_at_the_setpoint_reset_by_the_error_it_leaves() {
        // The load reads 0.15 °C below the setpoint, the duty held at 0.5 (open loop, as if a
        // slow mode the model lacks kept it there): a rest, so from its 18th counted sample the
        // reset integrates the error, RESET_GAIN × 0.15 a sample, until the next step would
        // pass RESET_MAX_C, and holds there.
        let sample = |c: &mut SelfTuning, y: f32, w: f32| {
            let input = ControlInput { y_c: y, w_c: w };
            let u = c.update(&input).unwrap();
            c.track(&input, 0.5);
            (u, c.reset_c())
        };
        let step = RESET_GAIN * 0.15;
        let mut c = start(ADAPTIVE_GPC);
        let mut last = 0.0;
        for i in 0..200u16 {
            // The first sample starts the rest (a new setpoint, the start's duty 0 at a rail);
            // sample i is its i-th counted one.
            let (_, r) = sample(&mut c, W_C - 0.15, W_C);
            if i < RESET_AFTER_SAMPLES {
                assert_eq!(r, 0.0, "sample {i}: no reset before the 18th sample at rest");
            } else if last + step <= RESET_MAX_C {
                assert!((r - last - step).abs() < 1e-6, "sample {i}: {last} → {r}, not one step of {step}");
            } else {
                assert_eq!(r, last, "sample {i}: held below the bound");
            }
            assert!(r.abs() <= RESET_MAX_C);
            last = r;
        }
        assert!(last > RESET_MAX_C - step, "the reset reached its bound: {last}");
        // A reset the law is handed: the same sample with 0.05 °C more reset asks less cooling
        // (a higher setpoint for the law).
        let mut more = c.clone();
        more.reset_c += 0.05;
        let (u, _) = sample(&mut c, W_C - 0.15, W_C);
        let (u_more, _) = sample(&mut more, W_C - 0.15, W_C);
        assert!(u_more < u, "a higher aim cools less: {u_more} against {u}");
        // The rest ends, and the reset with it: an error beyond REST_EXIT_C, a setpoint change.
        let mut out = c.clone();
        assert_eq!(sample(&mut out, W_C - 0.35, W_C).1, 0.0, "an error beyond 0.3 °C ends the reset");
        assert_eq!(sample(&mut c, W_C - 0.15, W_C + 1.0).1, 0.0, "a setpoint change ends the reset");
        // GMVC and IGMVC aim at the setpoint as given.
        for cfg in [crate::profile::ADAPTIVE_IGMVC, crate::profile::ADAPTIVE_GMVC] {
            let mut c = start(cfg);
            for _ in 0..200 {
                assert_eq!(sample(&mut c, W_C - 0.15, W_C).1, 0.0);
            }
        }
    }

    /// A closed loop on the start model for the rest's tests.
    struct RestRig {
        plant: Plant,
        y: f32,
        t: usize,
    }

    impl RestRig {
        fn new() -> Self {
            Self { plant: Plant::start_model(), y: 0.0, t: 0 }
        }

        /// One closed-loop sample at setpoint `w`, the measurement with a ±4 mK sensor noise (a
        /// fixed pattern) and `offset`: an estimator that updates moves θ on the noise. Returns
        /// |measurement − w|.
        fn run(&mut self, c: &mut SelfTuning, w: f32, offset: f32) -> f32 {
            let noise = [0.004, -0.003, 0.001, -0.004, 0.002][self.t % 5];
            self.t += 1;
            let input = ControlInput { y_c: self.y + noise + offset, w_c: w };
            let u = c.update(&input).unwrap_or(0.0).clamp(0.0, 1.0);
            c.track(&input, u);
            self.y = self.plant.advance(u);
            (input.y_c - w).abs()
        }
    }

    #[test]
    fn the_estimator_pauses_after_half_an_hour_at_rest_and_resumes_when_the_rest_ends() {
        let mut c = start(ADAPTIVE_GPC);
        let mut r = RestRig::new();
        // Until the load has been within 0.2 °C for 180 samples the estimator updates (θ moves
        // on the noise); then it pauses. Counted here from the samples themselves: a sample in
        // the band counts, one beyond 0.3 °C or with the duty at 0 or 1 starts the count again.
        let (mut count, mut moved) = (0u16, 0);
        while !c.resting() {
            let (before, u) = (c.theta(), c.reg.u_last()); // the duty of the sample before
            let e = r.run(&mut c, W_C, 0.0);
            if e > REST_EXIT_C || !(u > 0.0 && u < 1.0) {
                count = 0;
            } else if e < REST_BAND_C {
                count += 1;
            }
            moved += usize::from(c.theta() != before);
            assert!(r.t < 5000, "never at rest");
        }
        assert_eq!(count, REST_PAUSE_SAMPLES, "the pause starts with the 180th counted sample");
        assert!(moved > 100, "before the pause the estimate follows the noise: {moved} moves");
        let (theta, updates, mode) = (c.theta(), c.updates(), c.mode());
        for _ in 0..500 {
            r.run(&mut c, W_C, 0.0);
            assert!(c.resting());
        }
        assert_eq!(c.theta(), theta, "paused: θ unchanged");
        assert_eq!(c.updates(), updates + 500, "the paused samples count towards warm-up");
        assert_eq!(c.mode(), mode, "the trust decision is that of the paused estimate");
        // At rest GPC asks what it would with the rest's λ, bit for bit, though the estimate is
        // trusted; awake (the count started again) it runs with its own λ (0.5). The noise took
        // this estimate outside the plausible set before the pause (Frozen: cautious), so the
        // resting controller is given the start model's, which the rules trust.
        let mut trusting = c.clone();
        trusting.rls = start(ADAPTIVE_GPC).rls;
        let with_lambda = |c: &SelfTuning, lambda: f32| {
            let mut c = c.clone();
            match &mut c.cfg.law {
                Law::Gpc(g) => g.lambda = lambda,
                _ => unreachable!("ADAPTIVE_GPC is GPC"),
            }
            c
        };
        // Sixteen samples of the same measurements (a new λ reaches the staged GPC's design
        // within eight); the duties asked, and whether the controller rested and trusted its
        // estimate throughout.
        let y0 = r.y;
        let asks = |mut c: SelfTuning| {
            let mut out = std::vec::Vec::new();
            for k in 0..16 {
                let input = ControlInput { y_c: y0 + 0.002 * (k % 2) as f32, w_c: W_C };
                let u = c.update(&input).unwrap();
                c.track(&input, u.clamp(0.0, 1.0));
                out.push((u, c.resting(), c.mode()));
            }
            out
        };
        let at_rest = asks(trusting.clone());
        assert!(at_rest.iter().all(|&(_, rest, mode)| rest && mode == AdaptiveMode::Adaptive), "{at_rest:?}");
        assert_eq!(at_rest, asks(with_lambda(&trusting, REST_GPC_LAMBDA)));
        let mut awake = trusting.clone();
        awake.rest_n = 0;
        // (The rest's λ and the cautious one ask differently here: the equality above is the
        // rest's λ at work.)
        assert_ne!(asks(with_lambda(&awake, REST_GPC_LAMBDA)), asks(with_lambda(&awake, CAUTIOUS_GPC_LAMBDA)));
        let own = asks(awake.clone());
        // (The first awake update may find the estimate of this noise-driven history implausible
        // and hold the start model's for that sample: Frozen, cautious; then it is trusted.)
        assert!(own.iter().all(|&(_, rest, _)| !rest), "{own:?}");
        assert!(own[1..].iter().all(|&(_, _, mode)| mode == AdaptiveMode::Adaptive), "{own:?}");
        assert_ne!(own, asks(with_lambda(&awake, REST_GPC_LAMBDA)));
        // A load pushed 0.25 °C off stays at rest (within the exit band); 0.35 °C ends it.
        r.run(&mut c, W_C, 0.25 - (r.y - W_C));
        assert!(c.resting());
        r.run(&mut c, W_C, 0.35 - (r.y - W_C));
        assert!(!c.resting(), "an error beyond 0.3 °C ends the rest");
        let before = c.theta();
        r.run(&mut c, W_C, 0.0);
        assert_ne!(c.theta(), before, "the estimator runs again");
        // A new setpoint ends it too.
        while !c.resting() {
            r.run(&mut c, W_C, 0.0);
        }
        r.run(&mut c, W_C + 0.5, 0.0);
        assert!(!c.resting(), "a setpoint change ends the rest");
    }

    #[test]
    fn once_a_rest_has_confirmed_the_estimate_later_holds_pause_it_within_a_minute() {
        // A setpoint the start model holds at a duty of about 0.37, away from the rails (a duty
        // at 0 or 1 ends a rest).
        const W: f32 = -10.0;
        // A hold after a 0.35 °C error ended the rest: the samples the estimator updates on
        // (θ moves) before it pauses, and the samples until the controller rests (the rest's λ).
        let hold = |c: &mut SelfTuning, r: &mut RestRig| {
            r.run(c, W, 0.35 - (r.y - W));
            let (mut moved, mut rests_after) = (0, None);
            for n in 0..2 * REST_PAUSE_SAMPLES {
                let before = c.theta();
                r.run(c, W, 0.0);
                moved += usize::from(c.theta() != before);
                if c.resting() && rests_after.is_none() {
                    rests_after = Some(usize::from(n) + 1);
                }
            }
            (moved, rests_after)
        };
        let first_rest = |cfg: AdaptiveConfig| {
            let (mut c, mut r) = (start(cfg), RestRig::new());
            let mut moved = 0;
            while !c.resting() {
                let before = c.theta();
                r.run(&mut c, W, 0.0);
                moved += usize::from(c.theta() != before);
                assert!(r.t < 5000, "never at rest");
            }
            // Two paused samples: the second sees the trust decision of the first.
            for _ in 0..2 {
                r.run(&mut c, W, 0.0);
            }
            (c, r, moved)
        };
        // The first rest takes half an hour, trusted estimate or not; it confirms this one.
        let (mut c, mut r, moved) = first_rest(ADAPTIVE_GPC);
        assert_eq!(c.mode(), AdaptiveMode::Adaptive);
        assert!(moved > 150, "{moved}");
        // The next hold pauses the estimator after CONFIRMED_PAUSE_SAMPLES within the band (the
        // samples the load spends beyond 0.2 °C on its way back update too), and GPC keeps its
        // own λ until the half hour is up.
        let (moved, rests_after) = hold(&mut c, &mut r);
        assert!((usize::from(CONFIRMED_PAUSE_SAMPLES)..20).contains(&moved), "{moved}");
        assert!(rests_after.is_some_and(|n| n >= usize::from(REST_PAUSE_SAMPLES)), "{rests_after:?}");
        // An estimate still in warm-up is not trusted (Frozen on the start model): its rest
        // confirms nothing, and the next hold again updates for half an hour.
        let (mut c, mut r, _) = first_rest(AdaptiveConfig { warmup_samples: 100_000, ..ADAPTIVE_GPC });
        assert_eq!(c.mode(), AdaptiveMode::Frozen);
        let (moved, _) = hold(&mut c, &mut r);
        assert!(moved > 150, "{moved}");
    }

    #[test]
    fn without_a_start_model_the_pi_drives_bumplessly_until_an_estimate_is_trusted() {
        let cfg = AdaptiveConfig { initial: None, ..ADAPTIVE_GPC };
        let mut c = start(cfg);
        assert_eq!((c.mode(), c.trusted_model()), (AdaptiveMode::Fallback, None));
        // Until then it is the PI, bit for bit (the same inputs and applied duties).
        let mut pi = Pi::new(PiConfig { bias: 0.0, ..cfg.fallback }, TS_S);
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        let mut engaged = None;
        for t in 0..5000 {
            let input = ControlInput { y_c: y, w_c: W_C };
            let u = c.update(&input).unwrap();
            if c.mode() != AdaptiveMode::Fallback {
                engaged = Some(t);
                break;
            }
            assert_eq!(u.to_bits(), pi.update(&input).unwrap().to_bits(), "sample {t}");
            c.track(&input, square(t));
            pi.track(&input, square(t));
            y = plant.advance(square(t));
        }
        let t = engaged.expect("the excited estimator converges to a plausible model");
        // Sample t (from 0) is the (t + 1)-th; the estimator updates from the third on, so the
        // (warm-up + 2)-th is the first with `warmup_samples` updates.
        assert!(t + 1 >= cfg.warmup_samples as usize + 2, "engaged at {t}, inside the warm-up");
        assert_eq!(c.mode(), AdaptiveMode::Adaptive);
        assert_eq!(c.trusted_model(), c.estimate());
    }

    /// A board boots the self-tuner at its fallback PI's bias (then 0.4), and GPC's first staged design takes
    /// four samples, in which the law would hold that duty whatever the reading: a load already
    /// at 2.1–2.4 °C in a cold room fell to 1.3–1.7 °C under it, and the freeze guard's trip was
    /// taken for a shorted SSR (campaign missions 60267, 66503 and 68757, `--seed 60001`). Until
    /// the design is complete the fallback PI drives, bit for bit, on the reading, and the mode
    /// stays the self-tuner's; from the fifth sample on the law drives.
    #[test]
    fn until_the_first_design_is_complete_the_pi_drives_on_the_reading() {
        let u0 = ADAPTIVE_GPC.fallback.bias;
        let mut c = SelfTuning::new(ADAPTIVE_GPC, TS_S, u0).unwrap();
        let mut pi = Pi::new(PiConfig { bias: u0, ..ADAPTIVE_GPC.fallback }, TS_S);
        pi.track(&ControlInput { y_c: 0.0, w_c: 0.0 }, u0);
        // 1.8 °C below the setpoint: no cooling is wanted.
        let input = ControlInput { y_c: W_C - 1.8, w_c: W_C };
        for t in 0..4 {
            assert!(c.law_state.gpc().model().is_none(), "sample {t}: the design is not complete");
            let u = c.update(&input).unwrap();
            assert_eq!(u.to_bits(), pi.update(&input).unwrap().to_bits(), "sample {t}");
            assert!(u.clamp(0.0, 1.0) < u0, "sample {t}: {u} cools at the boot duty or more");
            assert_eq!(c.mode(), AdaptiveMode::Frozen, "sample {t}: the self-tuner's mode");
            let applied = u.clamp(0.0, 1.0);
            c.track(&input, applied);
            pi.track(&input, applied);
        }
        assert!(c.law_state.gpc().model().is_some(), "the first design is complete");
        let u = c.update(&input).unwrap();
        assert_ne!(u.to_bits(), pi.update(&input).unwrap().to_bits(), "the law drives");
        assert_eq!(c.mode(), AdaptiveMode::Frozen);
    }

    #[test]
    fn an_implausible_estimate_freezes_and_a_failed_law_falls_back() {
        let mut c = start(ADAPTIVE_GPC);
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        for _ in 0..40 {
            sample(&mut c, &mut plant, &mut y, None);
        }
        assert_eq!(c.mode(), AdaptiveMode::Adaptive);
        // A non-finite measurement: the estimator refuses it and the law fails, so the PI
        // drives; the next good sample re-engages the law on a trusted estimate.
        let nan = ControlInput { y_c: f32::NAN, w_c: W_C };
        let _ = c.update(&nan);
        assert_eq!(c.mode(), AdaptiveMode::Fallback);
        c.track(&nan, 0.0);
        assert_eq!(sample(&mut c, &mut plant, &mut y, None), AdaptiveMode::Adaptive);

        // The plant turns into a heater under excitation: the estimate's B turns positive, is
        // not trusted, and the law runs frozen on the last model that was.
        plant.b = [0.03, 0.03];
        let mut frozen_on = None;
        for t in 0..1000 {
            let before = c.trusted_model();
            if sample(&mut c, &mut plant, &mut y, Some(square(t))) == AdaptiveMode::Frozen {
                frozen_on = before;
                break;
            }
        }
        let frozen_on = frozen_on.expect("an implausible estimate freezes the law");
        assert_eq!(c.trusted_model(), Some(frozen_on));
        assert!(c.estimate().is_none_or(|m| !plausible_model(c.config(), &m)));
        // Frozen to fallback and back: a failed sample hands over to the PI; the next one runs
        // the law again, on a plausible model (the projection keeps the estimate's static gain
        // in the cooling range, so it may be trusted again: its B is then a cooler's).
        let _ = c.update(&nan);
        assert_eq!(c.mode(), AdaptiveMode::Fallback);
        c.track(&nan, 0.0);
        assert_ne!(sample(&mut c, &mut plant, &mut y, Some(0.4)), AdaptiveMode::Fallback);
        assert!(c.trusted_model().is_some_and(|m| plausible_model(c.config(), &m)));
    }

    #[test]
    fn a_refused_estimate_freezes_the_law_on_the_model_its_last_rest_confirmed() {
        let mut c = start(ADAPTIVE_GPC);
        let (mut plant, mut y) = (Plant::start_model(), 0.0);
        let gain = |m: Option<Model>| m.and_then(|m| m.static_gain()).expect("a model with a static gain");
        // Closed loop on the start model's own plant until the estimator pauses at rest: the
        // model trusted then is the one the rest confirmed.
        let mut t = 0;
        while !c.resting() {
            sample(&mut c, &mut plant, &mut y, None);
            t += 1;
            assert!(t < 5000, "never at rest");
        }
        assert_eq!(c.mode(), AdaptiveMode::Adaptive);
        let rested = c.trusted_model();
        // The cooler gets 1.6 times stronger and the estimate follows it under excitation: a
        // newer trusted model, far from the rested one.
        plant.b = [plant.b[0] * 1.6, plant.b[1] * 1.6];
        let mut t = 0;
        while !(c.mode() == AdaptiveMode::Adaptive && gain(c.trusted_model()) < 1.4 * gain(rested)) {
            sample(&mut c, &mut plant, &mut y, Some(square(t)));
            t += 1;
            assert!(t < 5000, "the estimate never followed the stronger cooler");
        }
        // Then the plant turns into a heater: the estimate is refused, and the law freezes on the
        // model the rest confirmed, not on the last one trusted (module docs, "Modes").
        plant.b = [0.03, 0.03];
        let mut t = 0;
        loop {
            let last = c.trusted_model();
            if sample(&mut c, &mut plant, &mut y, Some(square(t))) == AdaptiveMode::Frozen {
                assert_ne!(last, rested, "the last trusted model was another");
                break;
            }
            t += 1;
            assert!(t < 1000, "an implausible estimate freezes the law");
        }
        assert_eq!(c.trusted_model(), rested);
    }

    #[test]
    fn across_a_sensor_fault_the_estimate_is_not_corrupted() {
        use crate::step::Carrier;
        use crate::units::Celsius;
        // The start model's plant with a 1.3 × stronger cooler, holding 5 °C in a 28 °C room
        // (deviation variables from the room), its readings through the whole step; after 56 h
        // (the estimate long confirmed) the sensor reads nothing plausible for `gap` samples
        // (cooling off), then reads again.
        let run = |gap: u64| {
            let m = START_MODEL_HTER1;
            let (a, b, k) = ([m.a()[0], m.a()[1]], [1.3 * m.b()[0], 1.3 * m.b()[1]], m.k());
            let c = SelfTuning::new(ADAPTIVE_GPC, TS_S, 0.4).unwrap();
            let mut carrier = Carrier::new(crate::step::ValidConfig::DEFAULT, c);
            let (mut ys, mut us) = ([-23.0f32; 2], std::vec![0.45f32; k + 2]);
            let (t_gap, end) = (20_000u64, 20_000 + gap + 2000);
            let (mut seed, mut frozen) = (3u32, 0);
            for t in 0..end {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let y = 28.0 + ys[0] + 0.005 * ((seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5);
                let reading = if (t_gap..t_gap + gap).contains(&t) { 300.0 } else { y };
                let out = carrier.step_celsius(t * 10_000, Celsius(reading), 5.0);
                if t >= t_gap + gap && carrier.controller().mode() == AdaptiveMode::Frozen {
                    frozen += 1;
                }
                us.rotate_right(1);
                us[0] = out.duty.get();
                ys = [-a[0] * ys[0] - a[1] * ys[1] + b[0] * us[k - 1] + b[1] * us[k], ys[0]];
            }
            (frozen, carrier.controller().theta())
        };
        let (frozen, theta) = run(0);
        assert_eq!(frozen, 0, "no fault: {theta:?}");
        // Two and five minutes without a reading: the estimator waits for fresh data and the
        // estimate stays a cooler's; regressed across the gap, b0 went above zero and the law ran
        // frozen from then on (5.5 h, every sample).
        for gap in [12, 30] {
            let (frozen, theta) = run(gap);
            assert!(theta[2] <= 0.0 && frozen == 0, "gap {gap}: {frozen} samples frozen, θ {theta:?}");
        }
    }

    #[test]
    fn the_step_reports_each_mode_change_as_an_event() {
        use crate::event::EventKind;
        use crate::step::Carrier;
        use crate::units::Celsius;
        let mut carrier = Carrier::new(crate::step::ValidConfig::DEFAULT, start(ADAPTIVE_GPC));
        // The start model about 6 °C with the setpoint at 5 °C: inside 2–8 °C, where the
        // supervisor lets the law cool, and the law has to move the duty to hold it (at a
        // constant duty the estimator is held, module docs "Held at a rail").
        let mut plant = Plant::start_model();
        let (mut y, mut last) = (0.0, None);
        let mut seen = std::vec::Vec::new();
        for t in 0..200u64 {
            let out = carrier.step_celsius(t * 10_000, Celsius(6.0 + y), 6.0 + W_C);
            let mode = out.status.map(|s| s.mode);
            let events: std::vec::Vec<EventKind> = out
                .events
                .iter()
                .map(|e| e.kind)
                .filter(|k| {
                    matches!(k, EventKind::AdaptiveEngaged | EventKind::AdaptiveFrozen | EventKind::FallbackEngaged)
                })
                .collect();
            let want: &[EventKind] = match (mode != last, mode) {
                (true, Some(AdaptiveMode::Adaptive)) => &[EventKind::AdaptiveEngaged],
                (true, Some(AdaptiveMode::Frozen)) => &[EventKind::AdaptiveFrozen],
                (true, Some(AdaptiveMode::Fallback)) => &[EventKind::FallbackEngaged],
                _ => &[],
            };
            assert_eq!(events, want, "sample {t}");
            seen.extend(events);
            last = mode;
            y = plant.advance(out.duty.get());
        }
        assert_eq!(seen, [EventKind::AdaptiveFrozen, EventKind::AdaptiveEngaged]);
    }
}
