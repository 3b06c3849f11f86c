//! `hter rtd`: RTD resistance ⇔ temperature by IEC 60751, or a conversion of the board's RTD
//! channel through the default front end.

use anyhow::{bail, Result};
use hter::rtd::Rtd;
use hter::units::{Celsius, Ohms};

use crate::sim_cmd::{finite, whole};

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
    #[arg(long, allow_negative_numbers = true)]
    pub ohms: Option<f64>,
    /// Temperature to convert, °C.
    #[arg(long, allow_negative_numbers = true)]
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
    let from_counts = match a.counts {
        Some(c) => {
            let fe = hter::adc::AdcFrontEnd::DEFAULT;
            let r = fe.ohms(c).map_err(|e| {
                anyhow::anyhow!(
                    "{c} counts is not a working RTD on the default front end ({e:?}: open at ≥ {}, short below {} Ω)",
                    fe.full_scale_counts - fe.open_margin_counts,
                    fe.short_below_ohm
                )
            })?;
            Some(f64::from(r.0))
        }
        None => None,
    };
    let (ohms, celsius) = match (from_counts.or(a.ohms), a.celsius) {
        (Some(r), _) => {
            let r = finite("ohms", r)?;
            if r <= 0.0 {
                bail!("--ohms must be positive, got {r}");
            }
            let t = rtd.temperature(Ohms(r as f32)).map_err(|e| {
                anyhow::anyhow!("{r} Ω is outside the Pt{} range of IEC 60751 (−200…850 °C): {e:?}", a.r0)
            })?;
            (r, f64::from(t.0))
        }
        (None, Some(t)) => {
            let t = finite("celsius", t)?;
            let r = rtd
                .resistance(Celsius(t as f32))
                .map_err(|e| anyhow::anyhow!("{t} °C is outside the IEC 60751 range −200…850 °C: {e:?}"))?;
            (f64::from(r.0), t)
        }
        (None, None) => bail!("give --ohms, --celsius or --counts"),
    };
    if a.json {
        let mut v = serde_json::json!({ "ohms": ohms, "celsius": celsius });
        if let Some(c) = a.counts {
            v["counts"] = c.into();
        }
        println!("{v}");
    } else if let Some(c) = a.counts {
        println!("{c} counts: Pt{}: {:.4} Ω  ⇔  {:.3} °C (uncalibrated, default front end)", a.r0, ohms, celsius);
    } else {
        println!("Pt{}: {:.3} Ω  ⇔  {:.3} °C", a.r0, ohms, celsius);
    }
    Ok(())
}
