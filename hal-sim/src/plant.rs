//! Physical model of the thermoelectric vaccine carrier, in f64.
//!
//! A lumped thermal network of five nodes, integrated with explicit Euler at ≤ 0.1 s (the
//! fastest node, the modules' cold side, has a time constant of ≈ 15 s), with the SSR switched
//! for real inside each PWM period:
//!
//! ```text
//!            G_h                      Peltier module (N in parallel)
//! ambient ───────── hot sink T_h ◄──── Q_h = N(α I T_h + ½I²R − K ΔT)
//!                                      Q_c = N(α I T_c − ½I²R − K ΔT),  ΔT = T_h − T_c
//!                   cold side T_c ───► pumps Q_c out of the cabinet
//!                     │ G_cw (direct module)   │ G_ca (air-to-air module)
//!            container wall T_wl ── G_aw ── cabinet air + liner T_a ── G_leak ── ambient
//!                     │ G_ww
//!                water load T_w ──► RTD (dead time L, first-order lag τ_rtd) ──► T_sensed
//! ```
//!
//! Electrical: each module sees the supply V through the SSR; its current is
//! `I = (V − α ΔT)/R` (the Seebeck back-EMF reduces it) when on and 0 when off, and it draws
//! `P = N(α I ΔT + I² R) = Q_h − Q_c`. Switched off, the module is a plain conductance K: heat
//! flows back from the hot sink into the cabinet, which is why the carrier warms quickly with
//! the SSR open. Equations: Rowe (ed.), *CRC Handbook of Thermoelectrics*, 1995,
//! ch. 54; Huang et al., "Design of thermoelectric coolers", Int. J. Refrig. 23, 2000.
//!
//! ## Parameters
//!
//! | parameter | H-TER I | H-TER II | unit | source / reasoning |
//! | --- | --- | --- | --- | --- |
//! | modules N | 1 | 1 | – | one 12 V module per carrier (the direct and air-to-air heat pumps of the real carriers lumped into one cold side) |
//! | Seebeck α | 0.053 | 0.053 | V/K | TEC1-12706 class (127 couples × 0.42 mV/K) |
//! | resistance R | 2.0 | 2.0 | Ω | TEC1-12706 datasheet, at 25–50 °C |
//! | conductance K | 0.55 | 0.55 | W/K | TEC1-12706 datasheet (ΔT_max 66 K, Q_max 50 W) |
//! | supply V | 12 | 12 | V | seed: 12 V supply through the Crydom CMX60D10 SSR |
//! | hot sink C_h / G_h | 500 / 4.0 | 500 / 4.0 | J/K, W/K | 0.55 kg finned aluminium; 0.25 K/W with its fan |
//! | cold side C_c | 120 | 120 | J/K | cold block + inner fin sink, ≈ 0.13 kg aluminium |
//! | cold side → wall G_cw | 4.0 | 1.5 | W/K | direct module clamped on the container; stainless spreads heat ≈ 13× worse than aluminium |
//! | cold side → air G_ca | 2.5 | 2.5 | W/K | air-to-air module: inner fin sink with fan, h ≈ 25 W/(m²K) on 0.1 m² |
//! | wall C_wl | 180 | 200 | J/K | 0.2 kg Al (900 J/(kg K)) vs 0.4 kg stainless (500 J/(kg K)) |
//! | wall → water G_ww | 6.0 | 1.5 | W/K | wetted area ≈ 0.02 m²; conduction through the wall dominates for stainless (k = 16 vs 205 W/(m K)) |
//! | air ↔ wall G_aw | 1.2 | 1.2 | W/K | natural + fan convection on the container's outer surface |
//! | air + liner C_a | 1500 | 1500 | J/K | ≈ 1 kg of inner liner, racks and vials |
//! | insulation leak G_leak | 0.20 | 0.20 | W/K | 0.3 m² of 4 cm PU foam (k = 0.025) plus lid seal |
//! | water C_w | 419 / 209 | 419 / 209 | J/K | 100 ml (full) / 50 ml (half) × 4186 J/(kg K) |
//! | RTD lag τ_rtd | 20 | 20 | s | Pt100 in a stainless sheath in still water |
//! | dead time L | 20 | 20 | s | transport through the water to the probe; the real carriers' step responses show tens of seconds |
//!
//! Resulting open-loop behaviour (`cargo test -p hal-sim plant`): H-TER I full load pulls down
//! from 28 °C to 4 °C in ≈ 30 min with the SSR fully on; the duty that holds 4 °C is ≈ 0.40,
//! 0.46 and 0.54 at 25, 28 and 32 °C ambient; fully on, the load would go far below 0 °C
//! (the freeze guard's job); switched off at 4 °C it warms by 1 °C in ≈ 2 min.

use crate::sim::PWM_PERIOD_S;

/// Container material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Container {
    /// H-TER I.
    Aluminium,
    /// H-TER II.
    StainlessSteel,
}

/// Water load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Load {
    /// 100 ml.
    Full,
    /// 50 ml.
    Half,
}

/// How the modules are driven from the supply (SPEC §10, "The drive").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Drive {
    /// The DC SSR switches the full supply on and off once per PWM period (the design card's
    /// drive, the default): duty = the fraction of the period on.
    #[default]
    Ssr,
    /// A synchronous buck with an LC filter at ≥ 20 kHz: the modules see a smooth voltage,
    /// duty × supply, and carry a continuous current.
    Buck,
}

impl Drive {
    /// The name `--drive` takes.
    pub fn name(self) -> &'static str {
        match self {
            Drive::Ssr => "ssr",
            Drive::Buck => "buck",
        }
    }
}

/// The buck drive's averaged model (see the module docs, "The buck drive").
pub mod buck {
    /// Peak-to-peak ripple of the module current as a fraction of its mean: the §10 bound
    /// (≤ 10 %), taken whole so the extra I²R is not understated (the README's buck parts, 560 µH
    /// and 220 µF at 40 kHz, leave the inductor 3.6–8.4 % at the hold points and the module ≈ 0.2 %).
    pub const RIPPLE: f64 = 0.10;
    /// Series resistance of the drive, Ω: one MOSFET conducting at a time (R_DS(on) ≈ 10 mΩ,
    /// e.g. a 30 V logic-level part at 4.5 V gate drive, hot) plus the inductor's DCR (≈ 30 mΩ)
    /// and the traces, rounded up.
    pub const R_SERIES_OHM: f64 = 0.05;
    /// Power the drive takes while it switches, W: gate charge (2 × 20 nC × 12 V × 40 kHz ≈ 0.02 W),
    /// the switching transitions (≈ ½ V I (t_r + t_f) f ≈ 0.02 W at 2 A), the gate driver's
    /// quiescent current (≈ 5 mA at 12 V = 0.06 W): 0.1 W.
    pub const SWITCHING_W: f64 = 0.1;
    /// Mean square over mean squared of a triangular ripple of peak-to-peak `r` × mean:
    /// I_rms² = I² (1 + r²/12).
    pub fn rms_factor(r: f64) -> f64 {
        1.0 + r * r / 12.0
    }
}

/// Every physical parameter of the model (see the table in the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantParams {
    /// Container material.
    pub container: Container,
    /// How the modules are driven.
    pub drive: Drive,
    /// Water load.
    pub load: Load,
    /// Number of modules in parallel.
    pub modules: f64,
    /// Module Seebeck coefficient, V/K.
    pub alpha_v_per_k: f64,
    /// Module electrical resistance, Ω.
    pub r_ohm: f64,
    /// Module thermal conductance, W/K.
    pub k_w_per_k: f64,
    /// Nominal supply, V.
    pub supply_v: f64,
    /// Hot sink heat capacity, J/K.
    pub c_hot_j_per_k: f64,
    /// Hot sink to ambient, W/K.
    pub g_hot_w_per_k: f64,
    /// Cold side heat capacity, J/K.
    pub c_cold_j_per_k: f64,
    /// Cold side to container wall, W/K.
    pub g_cold_wall_w_per_k: f64,
    /// Cold side to cabinet air, W/K.
    pub g_cold_air_w_per_k: f64,
    /// Container wall heat capacity, J/K.
    pub c_wall_j_per_k: f64,
    /// Wall to water, W/K.
    pub g_wall_water_w_per_k: f64,
    /// Cabinet air to wall, W/K.
    pub g_air_wall_w_per_k: f64,
    /// Cabinet air and liner heat capacity, J/K.
    pub c_air_j_per_k: f64,
    /// Insulation leak, W/K.
    pub g_leak_w_per_k: f64,
    /// Water heat capacity, J/K.
    pub c_water_j_per_k: f64,
    /// RTD time constant, s.
    pub rtd_tau_s: f64,
    /// Dead time between the water and the RTD, s (whole seconds).
    pub dead_time_s: f64,
}

impl PlantParams {
    fn common(load: Load) -> Self {
        PlantParams {
            container: Container::Aluminium,
            drive: Drive::Ssr,
            load,
            modules: 1.0,
            alpha_v_per_k: 0.053,
            r_ohm: 2.0,
            k_w_per_k: 0.55,
            supply_v: 12.0,
            c_hot_j_per_k: 500.0,
            g_hot_w_per_k: 4.0,
            c_cold_j_per_k: 120.0,
            g_cold_wall_w_per_k: 4.0,
            g_cold_air_w_per_k: 2.5,
            c_wall_j_per_k: 180.0,
            g_wall_water_w_per_k: 6.0,
            g_air_wall_w_per_k: 1.2,
            c_air_j_per_k: 1500.0,
            g_leak_w_per_k: 0.20,
            c_water_j_per_k: 4186.0
                * match load {
                    Load::Full => 0.100,
                    Load::Half => 0.050,
                },
            rtd_tau_s: 20.0,
            dead_time_s: 20.0,
        }
    }

    /// H-TER I: aluminium container.
    pub fn hter1(load: Load) -> Self {
        Self::common(load)
    }

    /// H-TER II: stainless-steel container.
    pub fn hter2(load: Load) -> Self {
        PlantParams {
            container: Container::StainlessSteel,
            g_cold_wall_w_per_k: 1.5,
            c_wall_j_per_k: 200.0,
            g_wall_water_w_per_k: 1.5,
            ..Self::common(load)
        }
    }
}

/// Instantaneous heat flows, W (positive in the direction named).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeatFlows {
    /// Heat the modules take from their cold side (negative: back-conduction into the cabinet).
    pub pumped_from_cold_w: f64,
    /// Heat the modules deliver into the hot sink.
    pub into_hot_sink_w: f64,
    /// Electrical power drawn by the modules.
    pub electrical_w: f64,
    /// Hot sink to ambient.
    pub hot_sink_to_ambient_w: f64,
    /// Ambient into the cabinet through the insulation.
    pub leak_in_w: f64,
    /// Extra heat into the cabinet (disturbance).
    pub extra_w: f64,
    /// Net heat into each node: water, wall, air, cold side, hot sink.
    pub net_w: [f64; 5],
}

/// What the modules are driven with during an integration step.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Excitation {
    /// No current: the module is a plain thermal conductance.
    Off,
    /// The full supply across the modules (the SSR on).
    Full,
    /// The buck's filtered output at this duty, (0, 1].
    Buck(f64),
}

const W: usize = 0;
const WALL: usize = 1;
const AIR: usize = 2;
const COLD: usize = 3;
const HOT: usize = 4;

/// Largest integration step, s.
const MAX_DT_S: f64 = 0.1;
/// Length of the dead-time line, s (one entry per second).
const DELAY_LEN: usize = 64;

/// The plant's state.
#[derive(Clone, Debug)]
pub struct Plant {
    p: PlantParams,
    t: [f64; 5],
    rtd_c: f64,
    delay: [f64; DELAY_LEN],
    delay_head: usize,
    next_delay_s: f64,
    ambient_c: f64,
    supply_v: f64,
    extra_w: f64,
    energy_j: f64,
    time_s: f64,
}

impl Plant {
    /// All nodes at `ambient_c`, SSR off.
    pub fn at_ambient(params: PlantParams, ambient_c: f64) -> Self {
        Self::with_state(params, ambient_c, [ambient_c; 5])
    }

    fn with_state(p: PlantParams, ambient_c: f64, t: [f64; 5]) -> Self {
        Plant {
            p,
            t,
            rtd_c: t[W],
            delay: [t[W]; DELAY_LEN],
            delay_head: 0,
            next_delay_s: 1.0,
            ambient_c,
            supply_v: p.supply_v,
            extra_w: 0.0,
            energy_j: 0.0,
            time_s: 0.0,
        }
    }

    /// Steady state holding the water at `load_c` with a constant average duty (the averaged,
    /// not switched, model); returns it with that duty, or `None` if no duty in [0, 1] holds it.
    pub fn at_load_temperature(params: PlantParams, ambient_c: f64, load_c: f64) -> Option<(Self, f64)> {
        let settle = |d: f64| {
            let mut pl = Plant::at_ambient(params, ambient_c);
            // The averaged model at 4 s steps (stable: the fastest node's time constant is ≈ 15 s)
            // for 10 h: the slowest mode (≈ 1 h) has settled.
            for _ in 0..10 * 900 {
                pl.euler_averaged(4.0, d);
            }
            pl
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        if settle(1.0).t[W] > load_c || settle(0.0).t[W] < load_c {
            return None;
        }
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            if settle(mid).t[W] > load_c {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let d = 0.5 * (lo + hi);
        let s = settle(d);
        Some((Self::with_state(params, ambient_c, s.t), d))
    }

    /// The module current, A, and its mean square over its mean squared, for excitation `x`.
    fn current_a(&self, x: Excitation) -> (f64, f64) {
        let p = &self.p;
        let back_emf = self.seebeck_v();
        match x {
            Excitation::Off => (0.0, 1.0),
            Excitation::Full => (((self.supply_v - back_emf) / p.r_ohm).max(0.0), 1.0),
            // The averaged buck: the filtered output d·V behind the drive's series resistance,
            // which carries the current of all N modules. The current never reverses: the
            // driver runs in diode emulation (the low-side MOSFET turns off at zero current).
            Excitation::Buck(d) => {
                let i = (d * self.supply_v - back_emf) / (p.r_ohm + p.modules * buck::R_SERIES_OHM);
                (i.max(0.0), buck::rms_factor(buck::RIPPLE))
            }
        }
    }

    /// Heat flows with the modules on or off (fully on: the supply across them).
    pub fn heat_flows(&self, on: bool) -> HeatFlows {
        self.flows(if on { Excitation::Full } else { Excitation::Off }).0
    }

    /// Heat flows under excitation `x`, with the power the drive itself dissipates, W.
    fn flows(&self, x: Excitation) -> (HeatFlows, f64) {
        let p = &self.p;
        let (i, rms) = self.current_a(x);
        // Joule heat follows the mean square of the current, Peltier heat its mean.
        let i2 = i * i * rms;
        let t = &self.t;
        let dt = t[HOT] - t[COLD];
        let (tc_k, th_k) = (t[COLD] + 273.15, t[HOT] + 273.15);
        let qc = p.modules * (p.alpha_v_per_k * i * tc_k - 0.5 * i2 * p.r_ohm - p.k_w_per_k * dt);
        let qh = p.modules * (p.alpha_v_per_k * i * th_k + 0.5 * i2 * p.r_ohm - p.k_w_per_k * dt);
        let ww = p.g_wall_water_w_per_k * (t[WALL] - t[W]);
        let aw = p.g_air_wall_w_per_k * (t[AIR] - t[WALL]);
        let cw = p.g_cold_wall_w_per_k * (t[WALL] - t[COLD]);
        let ca = p.g_cold_air_w_per_k * (t[AIR] - t[COLD]);
        let leak = p.g_leak_w_per_k * (self.ambient_c - t[AIR]);
        let hs = p.g_hot_w_per_k * (t[HOT] - self.ambient_c);
        let drive_loss_w = match x {
            Excitation::Buck(d) if d > 0.0 => p.modules * p.modules * i2 * buck::R_SERIES_OHM + buck::SWITCHING_W,
            _ => 0.0,
        };
        let f = HeatFlows {
            pumped_from_cold_w: qc,
            into_hot_sink_w: qh,
            electrical_w: qh - qc,
            hot_sink_to_ambient_w: hs,
            leak_in_w: leak,
            extra_w: self.extra_w,
            net_w: [ww, -ww + aw - cw, leak + self.extra_w - aw - ca, cw + ca - qc, qh - hs],
        };
        (f, drive_loss_w)
    }

    fn euler(&mut self, h: f64, x: Excitation) {
        let (f, loss_w) = self.flows(x);
        self.step_nodes(h, &f.net_w);
        self.energy_j += (f.electrical_w + loss_w) * h;
        self.time_s += h;
        self.advance_sensor(h);
    }

    /// One step of the duty-averaged model (for steady states only): the SSR's on and off
    /// flows weighted by the duty; the buck's flows at that duty (already an average).
    fn euler_averaged(&mut self, h: f64, d: f64) {
        let net = match self.p.drive {
            Drive::Ssr => {
                let on = self.heat_flows(true).net_w;
                let off = self.heat_flows(false).net_w;
                let mut net = [0.0; 5];
                for i in 0..5 {
                    net[i] = d * on[i] + (1.0 - d) * off[i];
                }
                net
            }
            Drive::Buck => self.flows(Excitation::Buck(d)).0.net_w,
        };
        self.step_nodes(h, &net);
        self.rtd_c = self.t[W];
    }

    fn step_nodes(&mut self, h: f64, net: &[f64; 5]) {
        let p = &self.p;
        let c = [p.c_water_j_per_k, p.c_wall_j_per_k, p.c_air_j_per_k, p.c_cold_j_per_k, p.c_hot_j_per_k];
        for i in 0..5 {
            self.t[i] += h * net[i] / c[i];
        }
    }

    fn advance_sensor(&mut self, h: f64) {
        // Dead time: the water temperature enters a 1 s delay line; the RTD sees its tail.
        while self.time_s >= self.next_delay_s {
            self.delay_head = (self.delay_head + 1) % DELAY_LEN;
            self.delay[self.delay_head] = self.t[W];
            self.next_delay_s += 1.0;
        }
        let lag = (self.p.dead_time_s.round() as usize).min(DELAY_LEN - 1);
        let delayed = self.delay[(self.delay_head + DELAY_LEN - lag) % DELAY_LEN];
        self.rtd_c += h * (delayed - self.rtd_c) / self.p.rtd_tau_s;
    }

    /// Advances by `dt_s` with the modules on (the full supply across them) or off.
    pub fn advance(&mut self, dt_s: f64, on: bool) {
        self.advance_with(dt_s, if on { Excitation::Full } else { Excitation::Off });
    }

    fn advance_with(&mut self, dt_s: f64, x: Excitation) {
        if dt_s.is_nan() || dt_s <= 0.0 {
            return;
        }
        let n = (dt_s / MAX_DT_S).ceil().max(1.0);
        let h = dt_s / n;
        for _ in 0..n as usize {
            self.euler(h, x);
        }
    }

    /// One PWM period of the control timer at `duty`: with the SSR, on for `duty · period_s`
    /// then off for the rest; with the buck, the filtered voltage `duty · V` throughout (its
    /// own switching, ≥ 20 kHz, is averaged; see the module docs). Duty 0 is off for both
    /// (the buck's outputs disabled: no switching, no current).
    pub fn advance_pwm_period(&mut self, period_s: f64, duty: f64) {
        let d = if duty.is_finite() { duty.clamp(0.0, 1.0) } else { 0.0 };
        match self.p.drive {
            Drive::Ssr => {
                self.advance(d * period_s, true);
                self.advance((1.0 - d) * period_s, false);
            }
            Drive::Buck if d > 0.0 => self.advance_with(period_s, Excitation::Buck(d)),
            Drive::Buck => self.advance_with(period_s, Excitation::Off),
        }
    }

    /// True water temperature, °C.
    pub fn load_temp_c(&self) -> f64 {
        self.t[W]
    }

    /// Temperature of the RTD (after the dead time and its lag), °C.
    pub fn sensed_temp_c(&self) -> f64 {
        self.rtd_c
    }

    /// Node temperatures: water, wall, air, cold side, hot sink, °C.
    pub fn node_temps_c(&self) -> [f64; 5] {
        self.t
    }

    /// Ambient, °C.
    pub fn ambient_c(&self) -> f64 {
        self.ambient_c
    }

    /// Sets the ambient, °C.
    pub fn set_ambient_c(&mut self, t: f64) {
        self.ambient_c = t;
    }

    /// Sets the supply voltage of the modules, V.
    pub fn set_supply_v(&mut self, v: f64) {
        self.supply_v = v.max(0.0);
    }

    /// The modules' Seebeck voltage, α (T_hot − T_cold), V: what a module gives back across its
    /// terminals with no drive (the module-side sense's reading of a working, open SSR).
    pub fn seebeck_v(&self) -> f64 {
        self.p.alpha_v_per_k * (self.t[HOT] - self.t[COLD])
    }

    /// Supply voltage, V.
    pub fn supply_v(&self) -> f64 {
        self.supply_v
    }

    /// Extra heat into the cabinet (lid open, warm item), W.
    pub fn set_extra_heat_w(&mut self, w: f64) {
        self.extra_w = w;
    }

    /// Electrical energy drawn by the modules since the start, Wh.
    pub fn energy_wh(&self) -> f64 {
        self.energy_j / 3600.0
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The parameters.
    pub fn params(&self) -> &PlantParams {
        &self.p
    }

    /// An open-loop step as the RTD sees it: from the steady state holding the water at
    /// `load_c`, the duty raised by `delta` and held for `n` samples of `ts_s` (switched in PWM
    /// periods of [`PWM_PERIOD_S`], as `hter sim` drives the SSR). The RTD's temperature at each
    /// sample, °C, `n + 1` values, the first before the step; with the duty it started from.
    /// `None` if no duty in [0, 1] holds `load_c`.
    pub fn sensed_step(
        params: PlantParams,
        ambient_c: f64,
        load_c: f64,
        delta: f64,
        ts_s: f64,
        n: usize,
    ) -> Option<(Vec<f64>, f64)> {
        let (mut plant, duty0) = Plant::at_load_temperature(params, ambient_c, load_c)?;
        let periods = (ts_s / PWM_PERIOD_S).round() as usize;
        let mut y = Vec::with_capacity(n + 1);
        y.push(plant.sensed_temp_c());
        for _ in 0..n {
            for _ in 0..periods {
                plant.advance_pwm_period(PWM_PERIOD_S, duty0 + delta);
            }
            y.push(plant.sensed_temp_c());
        }
        Some((y, duty0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(p: &mut Plant, secs: f64, duty: f64) {
        for _ in 0..secs as usize {
            p.advance_pwm_period(1.0, duty);
        }
    }

    #[test]
    fn steady_state_energy_balance() {
        // Fully on for 10 h: every node settles; heat in = heat out at each boundary.
        let mut p = Plant::at_ambient(PlantParams::hter1(Load::Full), 28.0);
        p.advance(36_000.0, true);
        let f = p.heat_flows(true);
        for (i, n) in f.net_w.iter().enumerate() {
            assert!(n.abs() < 1e-3, "node {i} not settled: {n} W");
        }
        // Everything that leaks in is pumped out, and the hot sink rejects pumped heat + power.
        assert!((f.leak_in_w - f.pumped_from_cold_w).abs() < 1e-3, "{f:?}");
        assert!((f.hot_sink_to_ambient_w - (f.pumped_from_cold_w + f.electrical_w)).abs() < 1e-3, "{f:?}");
        assert!(f.electrical_w > 0.0 && f.pumped_from_cold_w > 0.0);
        // Integrated energy matches power × time at steady state.
        let e0 = p.energy_wh();
        p.advance(3600.0, true);
        assert!((p.energy_wh() - e0 - f.electrical_w).abs() < 1e-3 * f.electrical_w);
    }

    #[test]
    fn switched_off_module_conducts_heat_back() {
        let (mut p, _) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
        p.advance(1.0, false);
        let f = p.heat_flows(false);
        let t = p.node_temps_c();
        assert!(t[HOT] > t[COLD]);
        assert!(f.pumped_from_cold_w < -1.0, "back-conduction {} W", -f.pumped_from_cold_w);
        assert_eq!(f.electrical_w, 0.0);
    }

    fn pull_down_s(params: PlantParams) -> f64 {
        let mut p = Plant::at_ambient(params, 28.0);
        while p.load_temp_c() > 4.0 && p.time_s() < 6.0 * 3600.0 {
            p.advance(10.0, true);
        }
        p.time_s()
    }

    #[test]
    fn pull_down_times_and_their_order() {
        let a_full = pull_down_s(PlantParams::hter1(Load::Full));
        let a_half = pull_down_s(PlantParams::hter1(Load::Half));
        let s_full = pull_down_s(PlantParams::hter2(Load::Full));
        assert!((1500.0..=3600.0).contains(&a_full), "H-TER I full: {a_full} s");
        assert!(a_half < a_full, "half {a_half} vs full {a_full}");
        assert!(s_full > a_full, "stainless {s_full} vs aluminium {a_full}");
    }

    #[test]
    fn holding_duty_leaves_authority_both_ways() {
        let d = |amb| Plant::at_load_temperature(PlantParams::hter1(Load::Full), amb, 4.0).unwrap().1;
        let (d25, d28, d32) = (d(25.0), d(28.0), d(32.0));
        assert!(d25 > 0.2 && d32 < 0.8 && d25 < d28 && d28 < d32, "{d25} {d28} {d32}");
        assert!((0.3..=0.6).contains(&d28), "{d28}");
        // Fully on, the load would freeze: the freeze guard is needed.
        let mut p = Plant::at_ambient(PlantParams::hter1(Load::Full), 28.0);
        p.advance(6.0 * 3600.0, true);
        assert!(p.load_temp_c() < 0.0, "{}", p.load_temp_c());
    }

    #[test]
    fn steady_state_holds_under_real_switching() {
        let (mut p, d) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
        run(&mut p, 3600.0, d);
        assert!((p.load_temp_c() - 4.0).abs() < 0.15, "{}", p.load_temp_c());
    }

    #[test]
    fn sensor_shows_dead_time_and_lag() {
        let (mut p, _) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
        let sensed0 = p.sensed_temp_c();
        // Switch off: the water warms at once, the RTD only after the dead time.
        run(&mut p, 15.0, 0.0);
        assert!(p.load_temp_c() > 4.01);
        assert!((p.sensed_temp_c() - sensed0).abs() < 1e-9, "RTD moved within the dead time");
        run(&mut p, 120.0, 0.0);
        assert!(p.sensed_temp_c() > sensed0 + 0.1);
        assert!(p.sensed_temp_c() < p.load_temp_c(), "the RTD lags a warming load");
    }

    #[test]
    fn pwm_lies_between_off_and_on() {
        let (base, _) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
        let (mut on, mut off, mut half) = (base.clone(), base.clone(), base.clone());
        run(&mut on, 600.0, 1.0);
        run(&mut off, 600.0, 0.0);
        run(&mut half, 600.0, 0.5);
        assert!(on.load_temp_c() < half.load_temp_c() && half.load_temp_c() < off.load_temp_c());
    }

    #[test]
    fn supply_sag_weakens_cooling() {
        let (base, d) = Plant::at_load_temperature(PlantParams::hter1(Load::Full), 28.0, 4.0).unwrap();
        let mut sag = base.clone();
        sag.set_supply_v(9.0);
        let mut nominal = base;
        run(&mut nominal, 1800.0, d);
        run(&mut sag, 1800.0, d);
        assert!(sag.load_temp_c() > nominal.load_temp_c() + 0.5);
    }
}
