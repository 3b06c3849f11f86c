//! `hter log2csv`: turns the firmware's defmt telemetry (as printed by probe-rs or defmt-print)
//! into the CSV that `hter identify` and `hter monitor` read.
//!
//! The firmware prints one line per sample, `t=… temp=… sp=… duty=… mode=… counts=… supply=…
//! alarm=…`, possibly behind a timestamp, a level and a location; every other line (events,
//! boot messages, estimates, summaries) is skipped. `counts` (the RTD conversion), `supply`
//! (V, NaN when not measured) and `alarm` (the indicator's state) are kept when present; logs
//! of older firmware without them leave those cells empty.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

/// Arguments of `hter log2csv`.
#[derive(clap::Args, Debug, Clone)]
pub struct Log2CsvArgs {
    /// The saved log (e.g. `cargo fw-run | tee carrier.log`).
    #[arg(long)]
    pub input: PathBuf,
    /// Where to write the CSV (columns t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm).
    #[arg(long)]
    pub output: PathBuf,
}

/// One telemetry sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Setpoint, °C.
    pub setpoint_c: f64,
    /// Filtered temperature, °C.
    pub temp_c: f64,
    /// Duty applied.
    pub duty: f64,
    /// Safety mode.
    pub mode: String,
    /// RTD conversion, counts (newer firmware).
    pub counts: Option<u32>,
    /// The modules' supply, V (newer firmware; `None` also when the board could not measure it).
    pub supply_v: Option<f64>,
    /// The alarm indicator's state (newer firmware).
    pub alarm: String,
}

fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let start = line.split_whitespace().find_map(|w| w.strip_prefix(key))?;
    Some(start.trim_end_matches(','))
}

/// Parses one telemetry line; `None` for any other line.
pub fn parse_line(line: &str) -> Option<Result<Sample>> {
    let (t, temp, sp, duty) = (field(line, "t=")?, field(line, "temp=")?, field(line, "sp=")?, field(line, "duty=")?);
    let mode = field(line, "mode=").unwrap_or("").to_string();
    let alarm = field(line, "alarm=").unwrap_or("").to_string();
    let counts = field(line, "counts=");
    let supply = field(line, "supply=");
    let num = |name: &str, v: &str| -> Result<f64> {
        let x: f64 = v.parse().with_context(|| format!("{name} '{v}' is not a number"))?;
        if x.is_finite() {
            Ok(x)
        } else {
            bail!("{name} is not finite")
        }
    };
    Some((|| {
        Ok(Sample {
            t_s: num("t", t)?,
            temp_c: num("temp", temp)?,
            setpoint_c: num("sp", sp)?,
            duty: num("duty", duty)?,
            mode,
            counts: counts
                .map(|c| c.parse::<u32>().with_context(|| format!("counts '{c}' is not a whole number")))
                .transpose()?,
            // NaN is how the firmware says "not measured".
            supply_v: supply
                .map(|v| v.parse::<f64>().with_context(|| format!("supply '{v}' is not a number")))
                .transpose()?
                .filter(|v| v.is_finite()),
            alarm,
        })
    })())
}

/// `hter log2csv`.
pub fn run(args: &Log2CsvArgs) -> Result<()> {
    let f = std::fs::File::open(&args.input).with_context(|| format!("cannot read '{}'", args.input.display()))?;
    let mut rows = Vec::new();
    for (i, line) in std::io::BufReader::new(f).lines().enumerate() {
        let line = line.with_context(|| format!("'{}' line {}: not text", args.input.display(), i + 1))?;
        if let Some(s) = parse_line(&line) {
            rows.push(s.with_context(|| format!("'{}' line {}", args.input.display(), i + 1))?);
        }
    }
    if rows.is_empty() {
        bail!("'{}' has no telemetry lines (t=… temp=… sp=… duty=…)", args.input.display());
    }
    let mut out =
        std::fs::File::create(&args.output).with_context(|| format!("cannot write '{}'", args.output.display()))?;
    let mut text = String::from("t_s,setpoint_c,temp_c,duty,mode,counts,supply_v,alarm\n");
    let opt = |v: Option<String>| v.unwrap_or_default();
    for r in &rows {
        text.push_str(&format!(
            "{},{},{},{},{},{},{},{}\n",
            r.t_s,
            r.setpoint_c,
            r.temp_c,
            r.duty,
            r.mode,
            opt(r.counts.map(|c| c.to_string())),
            opt(r.supply_v.map(|v| v.to_string())),
            r.alarm
        ));
    }
    out.write_all(text.as_bytes()).with_context(|| format!("cannot write '{}'", args.output.display()))?;
    eprintln!("{} samples written to {}", rows.len(), args.output.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_probe_rs_lines_and_skips_others() {
        let l = "12.345678 INFO  t=10 temp=4.0123 sp=4 duty=0.456 mode=Normal\n└─ firmware::__telemetry_task @ src/main.rs:160";
        let s = parse_line(l.lines().next().unwrap()).unwrap().unwrap();
        assert_eq!(
            s,
            Sample {
                t_s: 10.0,
                setpoint_c: 4.0,
                temp_c: 4.0123,
                duty: 0.456,
                mode: "Normal".into(),
                counts: None,
                supply_v: None,
                alarm: String::new()
            }
        );
        // Today's firmware line: the conversion, the supply (NaN: not measured) and the alarm.
        let l = "0.000 INFO  t=20 temp=4.01 sp=4 duty=0.45 mode=Normal counts=49918 supply=12.04 alarm=Off";
        let s = parse_line(l).unwrap().unwrap();
        assert_eq!((s.counts, s.supply_v, s.alarm.as_str()), (Some(49_918), Some(12.04), "Off"));
        let l = "t=30 temp=4.01 sp=4 duty=0.45 mode=Normal counts=49920 supply=NaN alarm=OutOfRange";
        assert_eq!(parse_line(l).unwrap().unwrap().supply_v, None);
        let bad = parse_line("t=30 temp=4.01 sp=4 duty=0.45 mode=Normal counts=4.5 supply=12 alarm=Off").unwrap();
        assert!(bad.unwrap_err().to_string().contains("counts"));
        assert!(parse_line("WARN  event t=10 SensorOpen").is_none());
        assert!(parse_line("INFO  hter firmware 0.1.0: Ts = 10 s").is_none());
        let bad = parse_line("INFO t=10 temp=warm sp=4 duty=0.5 mode=Normal").unwrap();
        assert!(bad.unwrap_err().to_string().contains("temp"));
    }
}
