//! `hter rtd`: RTD resistance ⇔ temperature by IEC 60751, or a conversion of the board's RTD
//! channel through the default front end.

use anyhow::{bail, Result};
use hter::rtd::Rtd;
use hter::units::{Celsius, Ohms};

use crate::sim_cmd::{finite, shown, whole};

/// The clap value parser of `--r0`: a negative one (`--r0 -100`) is this error, naming the
/// values, instead of clap's "unexpected argument '-100' found".
fn r0(s: &str) -> std::result::Result<u32, String> {
    match s.parse() {
        Ok(r @ (100 | 1000)) => Ok(r),
        _ => Err("the nominal resistance must be 100 (Pt100) or 1000 (Pt1000)".into()),
    }
}

/// Arguments of `hter rtd`.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("input").required(true).args(["ohms", "celsius", "counts"])))]
pub struct RtdArgs {
    /// Resistance to convert, Ω.
    // Hyphen values, not only negative numbers: `--ohms -inf` reaches the check of the value
    // instead of clap's "unexpected argument '-i'".
    #[arg(long, allow_hyphen_values = true)]
    pub ohms: Option<f64>,
    /// Temperature to convert, °C.
    #[arg(long, allow_hyphen_values = true)]
    pub celsius: Option<f64>,
    /// A conversion of the board's RTD channel (the `counts=` of its telemetry) to convert
    /// through the default front end, uncalibrated: the "measured" reading of a calibration.
    #[arg(long, allow_negative_numbers = true, value_parser = whole("the RTD conversion in counts", 0, u32::MAX))]
    pub counts: Option<u32>,
    /// Nominal resistance at 0 °C: 100 (Pt100) or 1000 (Pt1000).
    #[arg(long, default_value_t = 100, allow_negative_numbers = true, value_parser = r0)]
    pub r0: u32,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `hter rtd`.
pub fn run(a: &RtdArgs) -> Result<()> {
    let rtd = match a.r0 {
        100 => Rtd::PT100,
        1000 => Rtd::PT1000,
        other => bail!("--r0 must be 100 or 1000, got {other}"),
    };
    if a.counts.is_some() && a.r0 != 100 {
        bail!(
            "--counts converts through the board's default front end, which is for a Pt100: --r0 {} does not apply",
            a.r0
        );
    }
    let from_counts = match a.counts {
        Some(c) => {
            let fe = hter::adc::AdcFrontEnd::DEFAULT;
            let r = fe.ohms(c).map_err(|e| {
                anyhow::anyhow!(
                    "{c} counts is not a working RTD on the default front end ({}: open at ≥ {}, short below {} Ω)",
                    adc_why(e),
                    fe.full_scale_counts - fe.open_margin_counts,
                    fe.short_below_ohm
                )
            })?;
            Some(f32_decimal(r.0))
        }
        None => None,
    };
    let (ohms, celsius) = match (from_counts.or(a.ohms), a.celsius) {
        (Some(r), _) => {
            let r = finite("ohms", r)?;
            if r <= 0.0 {
                bail!("--ohms must be positive, got {}", crate::sim_cmd::shown(r));
            }
            // (NonFinite too: only a value far out of range overflows the f32.)
            let t = rtd.temperature(Ohms(r as f32)).map_err(|_| {
                anyhow::anyhow!("{} Ω is outside the Pt{} range of IEC 60751 (−200…850 °C)", shown(r), a.r0)
            })?;
            (r, f32_decimal(t.0))
        }
        (None, Some(t)) => {
            let t = finite("celsius", t)?;
            let r = rtd
                .resistance(Celsius(t as f32))
                .map_err(|_| anyhow::anyhow!("{} °C is outside the IEC 60751 range −200…850 °C", shown(t)))?;
            (f32_decimal(r.0), t)
        }
        (None, None) => bail!("give --ohms, --celsius or --counts"),
    };
    // −0 (typed, or a tiny negative rounded) prints as 0.
    let (ohms, celsius) = (ohms + 0.0, celsius + 0.0);
    if a.json {
        let mut v = serde_json::json!({ "ohms": ohms, "celsius": celsius });
        if let Some(c) = a.counts {
            v["counts"] = c.into();
        }
        println!("{v}");
    } else if let Some(c) = a.counts {
        println!(
            "{c} counts: Pt{}: {} Ω  ⇔  {} °C (uncalibrated, default front end)",
            a.r0,
            fixed(ohms, 4),
            fixed(celsius, 3)
        );
    } else {
        println!("Pt{}: {} Ω  ⇔  {} °C", a.r0, fixed(ohms, 3), fixed(celsius, 3));
    }
    Ok(())
}

/// An f32 result as the f64 of its shortest decimal: the precision the library's f32
/// conversion has (848.35663 °C, not 848.3566284179688), for the JSON.
fn f32_decimal(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// `x` with `decimals` decimals, without the sign of a value that rounds to zero (−0.0001 °C
/// is 0.000 °C, not −0.000).
fn fixed(x: f64, decimals: usize) -> String {
    let s = format!("{x:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// A front-end refusal in words.
fn adc_why(e: hter::adc::AdcError) -> &'static str {
    match e {
        hter::adc::AdcError::Open => "an open circuit",
        hter::adc::AdcError::Short => "a short circuit",
        hter::adc::AdcError::ReferenceOutOfRange => "the reference conversions are out of their window",
    }
}
