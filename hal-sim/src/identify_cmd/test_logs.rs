//! Synthetic logs and arguments shared by the tests of `hter identify`.

use std::path::PathBuf;

use super::{run, Delay, IdentifyArgs, Method, OperatingPointChoice};

/// Writes `text` to a temporary CSV named after `name` and the process.
pub(super) fn write(name: &str, text: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("hter-ident-{}-{name}.csv", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

/// `hter identify` arguments for `input`: ARX(2, 2) by least squares at nk = 1, from the initial
/// rest, JSON out.
pub(super) fn args(input: PathBuf) -> IdentifyArgs {
    IdentifyArgs {
        input,
        na: 2,
        nb: 2,
        nc: 0,
        nk: Delay::Samples(1),
        method: Method::Ls,
        forgetting: None,
        filter: None,
        prefilter: None,
        y_column: "temp_c".into(),
        decimate: 1,
        operating_point: OperatingPointChoice::Initial,
        auto_order: false,
        json: true,
        plot: None,
    }
}

/// The error `run` returns for `a`, checked to be one line.
pub(super) fn err(a: &IdentifyArgs) -> String {
    let e = run(a).unwrap_err().to_string();
    assert!(!e.contains('\n'), "not one line: {e}");
    e
}

/// A log of y(t) = 1.8 y(t−1) − 0.81 y(t−2) + 2 u(t−1) + u(t−2) around 25 °C and duty 0.3,
/// starting at rest, with a PRBS-like duty.
pub(super) fn synthetic_log(n: usize) -> String {
    synthetic_log_delayed(n, 1, 0.0)
}

/// [`synthetic_log`] with the input delayed by `nk` samples and white noise of amplitude
/// ±`noise` °C added to the logged output (an output-error system).
pub(super) fn synthetic_log_delayed(n: usize, nk: usize, noise: f64) -> String {
    let mut text = String::from("duty,extra,t_s,temp_c\n");
    let (mut y1, mut y2) = (0.0f64, 0.0);
    let mut past_u = vec![0.0f64; nk + 1];
    let mut state = 0b1010_1100u8;
    let mut seed = 5u32;
    for t in 0..n {
        let (u1, u2) = (past_u[nk - 1], past_u[nk]);
        let y = 1.8 * y1 - 0.81 * y2 + 2.0 * u1 + u2;
        let u = if t < 20 {
            0.0
        } else {
            // 8-bit LFSR bit, held 4 samples.
            if t % 4 == 0 {
                let fb = (state >> 7) ^ (state >> 5) ^ (state >> 4) ^ (state >> 3);
                state = (state << 1) | (fb & 1);
            }
            if state & 1 == 1 {
                0.1
            } else {
                -0.1
            }
        };
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let v = noise * (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5) * 2.0;
        text += &format!("{},x,{},{}\n", 0.3 + u, 10.0 * t as f64, 25.0 + y + v);
        (y2, y1) = (y1, y);
        past_u.rotate_right(1);
        past_u[0] = u;
    }
    text
}
