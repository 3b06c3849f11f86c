//! `arx:A;B;K` model strings and the ideal ARX plant of `--plant arx:...`.
//!
//! `arx:-1.8,0.81;-0.02,-0.01;1` is A = 1 − 1.8 q⁻¹ + 0.81 q⁻², B = −0.02 − 0.01 q⁻¹, k = 1:
//! `y(t) = 1.8 y(t−1) − 0.81 y(t−2) − 0.02 u(t−1) − 0.01 u(t−2)`, with y the temperature minus
//! the ambient and u the duty in [0, 1]. An optional fourth field gives C for the controller's
//! T-filter: `arx:A;B;K;C` (`--model` only: a plant has no C), with its roots strictly inside
//! the unit circle (the filter divides by C).

use anyhow::{anyhow, bail, Result};
use hter::model::{Model, MAX_K, MAX_NA, MAX_NB, MAX_NC};

/// Parses `arx:A;B;K[;C]`: every field given must have at least one number (a trailing `;`
/// is an empty C, refused), and C, if given, must be stable ([`c_is_stable`]).
pub fn parse(spec: &str) -> Result<Model> {
    let body = spec.strip_prefix("arx:").ok_or_else(|| anyhow!("model '{spec}' must start with 'arx:'"))?;
    let parts: Vec<&str> = body.split(';').collect();
    if !(3..=4).contains(&parts.len()) {
        bail!("model '{spec}' must be arx:A;B;K (coefficients comma-separated, K the delay in samples)");
    }
    if let Some(i) = parts.iter().position(|p| p.trim().is_empty()) {
        bail!("model '{spec}': field {} ({}) is empty", i + 1, ["A", "B", "K", "C"][i]);
    }
    let coeffs = |name: &str, s: &str, max: usize| -> Result<Vec<f32>> {
        let s = s.trim();
        let v = s
            .split(',')
            .map(|x| {
                let v: f64 = x
                    .trim()
                    .parse()
                    .map_err(|_| anyhow!("model '{spec}': '{}' in {name} is not a number", x.trim()))?;
                if !v.is_finite() {
                    bail!("model '{spec}': {name} has a non-finite coefficient");
                }
                // The model is f32: 1e39 became inf there, refused as "NonFinite".
                if !(v as f32).is_finite() {
                    bail!(
                        "model '{spec}': {name} coefficient {} is too large for the library's f32 arithmetic (at most {:e})",
                        crate::sim_cmd::shown(v),
                        f32::MAX
                    );
                }
                Ok(v as f32)
            })
            .collect::<Result<Vec<f32>>>()?;
        if v.len() > max {
            bail!("model '{spec}': {name} has {} coefficients, at most {max} are supported", v.len());
        }
        Ok(v)
    };
    let a = coeffs("A", parts[0], MAX_NA)?;
    let b = coeffs("B", parts[1], MAX_NB)?;
    let k: usize = parts[2]
        .trim()
        .parse()
        .map_err(|_| anyhow!("model '{spec}': delay K '{}' is not a whole number", parts[2].trim()))?;
    if !(1..=MAX_K).contains(&k) {
        bail!("model '{spec}': delay K must be 1..={MAX_K}, got {k}");
    }
    let c = match parts.get(3) {
        Some(s) => coeffs("C", s, MAX_NC)?,
        None => vec![],
    };
    if !c_is_stable(&c) {
        bail!("model '{spec}': C (the T-filter, 1 + c1 q⁻¹ + …) must have its roots strictly inside the unit circle");
    }
    Model::new(&a, &b, &c, k).map_err(|e| anyhow!("model '{spec}': {e:?}"))
}

/// Whether C = 1 + c1 q⁻¹ (+ c2 q⁻²) has its roots strictly inside the unit circle: the
/// controller filters the data by 1/C, which grows without bound otherwise (C = 1 + 5 q⁻¹ +
/// 6 q⁻², roots −2 and −3, ran). No C is C = 1.
pub fn c_is_stable(c: &[f32]) -> bool {
    match c {
        [] => true,
        [c1] => c1.abs() < 1.0,
        [c1, c2] => hter::model::second_order_stable(*c1, *c2),
        _ => false,
    }
}

/// Parses the ideal plant of `--plant arx:A;B;K`: [`carrier_model`], without a C (a plant is
/// A y = q⁻ᵏ B u; the C of `--model` only shapes the controller's T-filter).
pub fn plant_model(spec: &str) -> Result<Model> {
    let fields = spec.strip_prefix("arx:").map_or(0, |b| b.split(';').count());
    if fields > 3 {
        bail!("plant '{spec}' must be arx:A;B;K: a plant takes no fourth (C) field, only --model does");
    }
    carrier_model(spec)
}

/// Parses a model that stands for a carrier: a controller's fixed design model (`--model`) or
/// the ideal plant (`--plant arx:…`, through [`plant_model`]). [`parse`], and the model must be
/// one a cooler can have: a stable A and a static gain in [−1000, 0) °C per unit duty. The
/// lower end is the most negative gain the self-tuner finds plausible
/// (`hter::profile::ADAPTIVE_GPC.gain_min_c_per_duty`): a plant of −3e38 °C per unit duty ran to
/// −1e33 °C. The self-tuner's other end (−10) is deliberately not enforced here: small gains are
/// valid ideal plants (the documented example's is −3), only unable to hold a setpoint far from
/// ambient, and `--model` is a research option; the messages say the rule that is enforced.
/// Anything else is refused here, with why: any other design model runs the loop into a drive
/// saturated for the whole scenario; an unstable plant drove the simulated
/// temperature to ±10¹⁸⁰ °C and printed that as the run's IAE (`arx:1;2;3`, A written with its
/// leading 1), and a heating plant is a sign error the run would only show as a load stuck at
/// the ambient.
pub fn carrier_model(spec: &str) -> Result<Model> {
    let m = parse(spec)?;
    if !m.a_is_stable() {
        let hint = if m.a().first().is_some_and(|a1| (*a1 - 1.0).abs() < 1e-6) {
            " (A lists a1,…,an without the leading 1: arx:-1.8,0.81;… is A = 1 − 1.8 q⁻¹ + 0.81 q⁻²)"
        } else {
            ""
        };
        bail!("model '{spec}': A is not stable (a pole on or outside the unit circle){hint}");
    }
    let gain_min = hter::profile::ADAPTIVE_GPC.gain_min_c_per_duty;
    match m.static_gain() {
        Some(g) if g < gain_min => bail!(
            "model '{spec}': static gain {g:e} °C per unit duty is beyond what a carrier can have (it must be in [{gain_min}, 0) °C per unit duty)"
        ),
        Some(g) if g < 0.0 => Ok(m),
        Some(g) => bail!(
            "model '{spec}': static gain {g:.3} °C per unit duty does not cool (it must be in [{gain_min}, 0) °C per unit duty)"
        ),
        None => bail!("model '{spec}': the static gain is not finite"),
    }
}

/// The ideal ARX plant: y = temperature − ambient, exact measurement, duty applied as is.
#[derive(Clone, Debug)]
pub struct ArxPlant {
    model: Model,
    ambient_c: f64,
    y: Vec<f64>, // y(t), y(t−1), …
    u: Vec<f64>, // u(t−1), u(t−2), …
}

impl ArxPlant {
    /// At steady state holding `temp_c`: past y and u at their steady values. Fails if the
    /// model has no static gain or the steady duty lies outside [0, 1].
    pub fn at_steady_state(model: Model, ambient_c: f64, temp_c: f64) -> Result<ArxPlant> {
        let a1 = 1.0 + model.a()[..model.na()].iter().map(|&x| f64::from(x)).sum::<f64>();
        let b1: f64 = model.b()[..model.nb()].iter().map(|&x| f64::from(x)).sum();
        let y_ss = temp_c - ambient_c;
        let u_ss = if y_ss == 0.0 {
            0.0
        } else if b1.abs() > 1e-12 {
            y_ss * a1 / b1
        } else {
            let t = crate::sim_cmd::shown(temp_c);
            bail!("the ARX plant has zero static gain and cannot hold {t} °C at {ambient_c} °C ambient");
        };
        if !(0.0..=1.0).contains(&u_ss) {
            let t = crate::sim_cmd::shown(temp_c);
            let u = if u_ss.abs() < 1e6 { format!("{u_ss:.3}") } else { crate::sim_cmd::shown(u_ss) };
            bail!("the ARX plant cannot hold {t} °C at {ambient_c} °C ambient: steady duty would be {u}");
        }
        Ok(ArxPlant { model, ambient_c, y: vec![y_ss; model.na() + 1], u: vec![u_ss; model.nb() + model.k()] })
    }

    /// Temperature now, °C.
    pub fn temp_c(&self) -> f64 {
        self.ambient_c + self.y[0]
    }

    /// The duty applied last (the steady duty right after construction).
    pub fn last_duty(&self) -> f64 {
        self.u[0]
    }

    /// Applies duty `u` (clipped to [0, 1]) for one sample and advances y.
    pub fn advance(&mut self, u: f64) {
        let m = &self.model;
        self.u.rotate_right(1);
        self.u[0] = u.clamp(0.0, 1.0);
        let mut y = 0.0;
        for i in 0..m.na() {
            y -= f64::from(m.a()[i]) * self.y[i];
        }
        for i in 0..m.nb() {
            y += f64::from(m.b()[i]) * self.u[m.k() + i - 1];
        }
        self.y.rotate_right(1);
        self.y[0] = y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_spec_example() {
        let m = parse("arx:-1.8,0.81;-0.02,-0.01;1").unwrap();
        assert_eq!((m.na(), m.nb(), m.k(), m.nc()), (2, 2, 1, 0));
        assert_eq!(&m.a()[..2], &[-1.8, 0.81]);
        assert_eq!(&m.b()[..2], &[-0.02, -0.01]);
        let m = parse("arx:-0.9;0.1;2;0.5").unwrap();
        assert_eq!((m.k(), m.nc(), m.c()[0]), (2, 1, 0.5));
        let m = parse("arx:-0.9;0.1;2;-1.2,0.4").unwrap();
        assert_eq!(m.nc(), 2);
    }

    /// C = 1 + 5 q⁻¹ + 6 q⁻² (roots −2, −3) ran; 1 + 1.0 q⁻¹ has its root on the circle.
    #[test]
    fn an_unstable_c_is_refused() {
        for bad in
            ["arx:-1.8,0.81;-0.02,-0.01;1;5,6", "arx:-0.9;-0.1;1;1", "arx:-0.9;-0.1;1;-1.1", "arx:-0.9;-0.1;1;0,1"]
        {
            let e = parse(bad).unwrap_err().to_string();
            assert!(e.contains("C (the T-filter") && e.contains("inside the unit circle"), "{bad}: {e}");
        }
        assert!(c_is_stable(&[-0.9]) && c_is_stable(&[-1.2, 0.4]) && c_is_stable(&[]));
        assert!(!c_is_stable(&[5.0, 6.0]) && !c_is_stable(&[0.0, -1.0]));
    }

    /// A finite coefficient beyond f32 is refused by name, not as the library's "NonFinite".
    #[test]
    fn a_coefficient_beyond_f32_is_refused_by_name() {
        for (bad, field) in [("arx:-0.9;-1e39;1", "B"), ("arx:1e39;-0.1;1", "A"), ("arx:-0.9;-0.1;1;-1e300", "C")] {
            let e = parse(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("{field} coefficient")) && e.contains("too large"), "{bad}: {e}");
        }
    }

    /// A trailing `;` (an empty C) or any other empty field is refused, not read as "no C".
    #[test]
    fn an_empty_field_is_refused() {
        for (bad, field) in [
            ("arx:-0.9;-0.1;1;", "field 4 (C)"),
            ("arx:-0.9;;1", "field 2 (B)"),
            ("arx:-0.9;-0.1; ", "field 3 (K)"),
            ("arx:;-0.1;1", "field 1 (A)"),
        ] {
            let e = parse(bad).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("empty"), "{bad}: {e}");
        }
    }

    /// `--plant arx:-0.9;-0.1;1;0.5` silently dropped the C: a plant takes A;B;K.
    #[test]
    fn a_plant_takes_no_c() {
        let e = plant_model("arx:-0.9;-0.1;1;0.5").unwrap_err().to_string();
        assert!(e.contains("no fourth (C) field"), "{e}");
        assert!(plant_model("arx:-0.9;-0.1;1").is_ok());
        assert!(carrier_model("arx:-0.9;-0.1;1;0.5").is_ok());
    }

    #[test]
    fn a_carrier_model_must_be_stable_and_cooling() {
        // The documented example: stable, static gain −0.03 / 0.01 = −3 °C per unit duty.
        assert!(carrier_model("arx:-1.8,0.81;-0.02,-0.01;1").is_ok());
        // A written with its leading 1 is a third-order A with a1 = 1 (roots 1 ± …): refused,
        // and the message says how A is written.
        let e = carrier_model("arx:1,-1.936244,0.936443;-0.286523,0.277790;9").unwrap_err().to_string();
        assert!(e.contains("not stable") && e.contains("without the leading 1"), "{e}");
        // y(t) = 1.1 y(t−1) …: a pole at 1.1.
        let e = carrier_model("arx:-1.1;-0.1;1").unwrap_err().to_string();
        assert!(e.contains("not stable") && !e.contains("leading"), "{e}");
        // b0 = +0.1 with a1 = −0.9: gain +1 °C per unit duty heats.
        let e = carrier_model("arx:-0.9;0.1;2").unwrap_err().to_string();
        assert!(e.contains("does not cool"), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }

    /// `--plant arx:1;2;3` (A written with its leading 1: a pole at −1, and a heating B) ran and
    /// printed an IAE of 265 560 °C·s; `arx:-1.5;-0.1;3` (a pole at 1.5) one of 5·10¹⁸⁶ °C·s.
    #[test]
    fn a_plant_is_held_to_the_same_rules() {
        assert!(carrier_model("arx:-1.8,0.81;-0.2,-0.1;1").is_ok());
        let e = carrier_model("arx:1;2;3").unwrap_err().to_string();
        assert!(e.contains("not stable") && e.contains("without the leading 1"), "{e}");
        let e = carrier_model("arx:-1.5;-0.1;3").unwrap_err().to_string();
        assert!(e.contains("not stable"), "{e}");
        let e = carrier_model("arx:-0.9;0.1;2").unwrap_err().to_string();
        assert!(e.contains("does not cool"), "{e}");
    }

    /// `arx:-0.5;-3e38;1` (a finite but absurd gain, −6e38 °C per unit duty) drove the
    /// simulated load to −1e33 °C. The bound is the self-tuner's: −1000 °C per unit duty is
    /// allowed, just beyond it is not, and the tiny gains of the ideal plants in the tests stay.
    #[test]
    fn a_gain_beyond_any_carrier_is_refused() {
        let e = carrier_model("arx:-0.5;-3e38;1").unwrap_err().to_string();
        assert!(e.contains("beyond what a carrier can have") && e.contains("[-1000, 0)"), "{e}");
        // The message states the rule it enforces, not a range it only half enforces.
        assert!(!e.contains("plausible range"), "{e}");
        let e = carrier_model("arx:-0.9;0.1;2").unwrap_err().to_string();
        assert!(e.contains("[-1000, 0)"), "{e}");
        // A(1) = 0.5: B(1) = −500 is −1000 °C per unit duty, −500.5 is −1001.
        assert!(carrier_model("arx:-0.5;-500;1").is_ok());
        assert!(carrier_model("arx:-0.5;-500.5;1").is_err());
        assert!(carrier_model("arx:-0.5;-0.0001;1").is_ok());
    }

    #[test]
    fn rejects_malformed_models() {
        for bad in
            ["-1.8;1;1", "arx:-1.8;1", "arx:-1.8;x;1", "arx:-1.8;1;0", "arx:;1;1", "arx:nan;1;1", "arx:1,2,3,4,5;1;1"]
        {
            let e = parse(bad).unwrap_err().to_string();
            assert!(!e.contains('\n'), "{e}");
        }
    }

    #[test]
    fn steady_state_holds_and_the_equation_is_the_documented_one() {
        // The documented example model has a static gain of −3 °C per unit duty: it cannot hold 4 °C at
        // 28 °C ambient (it would need u = 8).
        let spec = parse("arx:-1.8,0.81;-0.02,-0.01;1").unwrap();
        assert!(ArxPlant::at_steady_state(spec, 28.0, 4.0).is_err());
        let m = parse("arx:-1.8,0.81;-0.2,-0.1;1").unwrap();
        // A(1) = 0.01, B(1) = −0.3: holding 4 °C at 28 °C ambient needs u = −24·0.01/−0.3 = 0.8.
        let mut p = ArxPlant::at_steady_state(m, 28.0, 4.0).unwrap();
        let u_ss = p.last_duty();
        assert!((u_ss - 0.8).abs() < 1e-4, "{u_ss}");
        for _ in 0..50 {
            p.advance(u_ss);
        }
        assert!((p.temp_c() - 4.0).abs() < 1e-6);
        // One step at u = 1 from that steady state: y(t+1) = 1.8·(−24) − 0.81·(−24) − 0.2·1 − 0.1·0.8
        let mut p = ArxPlant::at_steady_state(m, 28.0, 4.0).unwrap();
        p.advance(1.0);
        let want = 28.0 + 1.8 * -24.0 - 0.81 * -24.0 - 0.2 * 1.0 - 0.1 * u_ss;
        assert!((p.temp_c() - want).abs() < 1e-4, "{} vs {want}", p.temp_c());
        assert!(ArxPlant::at_steady_state(m, 28.0, -30.0).is_err());
    }
}
