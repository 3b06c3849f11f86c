//! On-board commissioning of a simulated carrier, as a board does it when told `identify`
//! (`hter board … identify`, [`hter::app::App`]): the carrier holding 4 °C, the step runs the
//! library's [`Commissioning`] (rest, one PRBS period, the board's output-error fit) through the
//! simulated ADC and SSR, with the supply-switch test pulses held off (the record holds its own
//! excitation and nothing else) and the run aborted if the step's mode leaves normal, exactly as the
//! App's glue does. [`commission_board`] gives what the board stores and adopts from one run:
//! the control model (every b_i ≤ 0: the self-tuner's start) and the cabinet model (the
//! monotone rule's best fit: the holdover's). [`commission`] runs one sign rule alone.
//!
//! `hter sim --commission RULE` runs this on the run's own plant, load and ambient first and
//! gives the step the model(s) it found ([`crate::sim::ControllerSpec::initial`],
//! [`crate::sim::ControllerSpec::holdover`]): the carrier commissioned at the load it carries.

use anyhow::{anyhow, bail, Result};
use hter::control::adaptive::AdaptiveConfig;
use hter::hal::{apply_duty, RtdSampler};
use hter::ident::commission::{CommissionConfig, Commissioning, SignRule};
use hter::model::Model;
use hter::profile;
use hter::step::{Carrier, CarrierConfig, StepInput};

use crate::periph::{SimAdc, SimSsr};
use crate::plant::{Container, Plant, PlantParams};
use crate::sim::PWM_PERIOD_S;

/// The temperature the carrier holds while it is commissioned, °C (the setpoint a board holds
/// when told `identify`; the power-cut scenario holds the same).
pub const HOLD_C: f64 = 4.0;

/// Commissions the carrier `params` at `ambient_c` (noise seed `seed`) with the board's
/// default settings ([`CommissionConfig::DEFAULT`], the plausibility rule of the carrier's
/// self-tuner) and the sign rule `sign` (the board's is [`SignRule::EveryCoefficient`]): the
/// model the fit gives, or why it gave none.
///
/// With [`SignRule::Monotone`] the model may have b1 > 0, which the self-tuner does not trust
/// ([`hter::control::adaptive::plausible_model`]); the board keeps such a model as its cabinet
/// model only.
pub fn commission(params: PlantParams, ambient_c: f64, seed: u64, sign: SignRule) -> Result<Model> {
    let c = run(params, ambient_c, seed, |cfg| CommissionConfig { sign, cabinet: false, ..cfg })?;
    c.outcome()
        .ok_or_else(|| anyhow!("commissioning did not finish"))?
        .map_err(|e| anyhow!("commissioning failed: {}", e.name()))
}

/// The two models of one board commissioning ([`commission_board`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Commissioned {
    /// Every b_i ≤ 0: what the self-tuner starts from (`App`: the model record).
    pub control: Model,
    /// The monotone rule's best fit: what the holdover runs on (`App`: the cabinet record).
    pub cabinet: Model,
}

/// Commissions the carrier as the board's App does ([`CommissionConfig::DEFAULT`]: one run, the
/// control model and the cabinet model).
pub fn commission_board(params: PlantParams, ambient_c: f64, seed: u64) -> Result<Commissioned> {
    let c = run(params, ambient_c, seed, |cfg| cfg)?;
    match (c.outcome(), c.cabinet()) {
        (Some(Ok(control)), Some(cabinet)) => Ok(Commissioned { control, cabinet }),
        (Some(Err(e)), _) => bail!("commissioning failed: {}", e.name()),
        _ => bail!("commissioning gave no cabinet model"),
    }
}

/// Runs a commissioning of `configure(the board's configuration)` to its end.
fn run(
    params: PlantParams,
    ambient_c: f64,
    seed: u64,
    configure: impl FnOnce(CommissionConfig) -> CommissionConfig,
) -> Result<Commissioning> {
    let plausible: AdaptiveConfig = match params.container {
        Container::Aluminium => profile::ADAPTIVE_GPC,
        // The App's H-TER II profile starts from its own model; the plausibility rule (the
        // gain range) is the same.
        Container::StainlessSteel => {
            AdaptiveConfig { initial: Some(profile::START_MODEL_HTER2), ..profile::ADAPTIVE_GPC }
        }
    };
    let cfg = configure(CommissionConfig { plausible, ..CommissionConfig::DEFAULT });
    let Some((mut plant, u0)) = Plant::at_load_temperature(params, ambient_c, HOLD_C) else {
        bail!("the plant cannot hold {HOLD_C} °C at {ambient_c} °C ambient to be commissioned");
    };
    let ccfg = CarrierConfig::DEFAULT;
    let ts_s = f64::from(ccfg.ts_s);
    // Settled at the holding duty for 2 h, as the board has been holding before it is told.
    for _ in 0..(7200.0 / PWM_PERIOD_S) as usize {
        plant.advance_pwm_period(PWM_PERIOD_S, u0);
    }
    let valid = ccfg.validated().map_err(|e| anyhow!("carrier configuration refused: {e}"))?;
    let c = Commissioning::new(cfg, ccfg.ts_s, u0 as f32).map_err(|e| anyhow!("commissioning refused: {e:?}"))?;
    let mut carrier = Carrier::new(valid, c);
    carrier.hold_switch_tests(true);
    let (mut adc, mut ssr) = (SimAdc::new(seed), SimSsr::new());
    for n in 0..cfg.max_total_samples() as u64 + 10 {
        adc.set_temperature_c(plant.sensed_temp_c());
        carrier.observe_supply_v(plant.supply_v() as f32);
        carrier.observe_switched_rail_v(ssr.switched_rail_v(plant.supply_v()) as f32);
        let counts = match adc.sample() {
            Ok(c) => c,
            Err(never) => match never {},
        };
        let out = carrier.step(&StepInput { t_ms: n * (ts_s * 1000.0) as u64, counts, setpoint_c: HOLD_C as f32 });
        carrier.controller_mut().abort_on_mode(out.mode);
        if carrier.controller().outcome().is_some() {
            return Ok(carrier.controller().clone());
        }
        let duty = adc.window.clear_duty(out.duty);
        let _ = apply_duty(&mut ssr, duty);
        ssr.set_supply_enabled(out.supply_enable);
        let d = ssr.effective_duty();
        for _ in 0..(ts_s / PWM_PERIOD_S).round() as usize {
            plant.advance_pwm_period(PWM_PERIOD_S, d);
            adc.set_ssr_duty(d);
        }
    }
    bail!("commissioning did not finish")
}
