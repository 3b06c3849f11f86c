//! The arguments of `hter identify` and the choices they name.

use std::path::PathBuf;

use hter::ident::model::MAX_NK;
use hter::model::{MAX_NA, MAX_NB, MAX_NC};
use serde::Serialize;

use crate::sim_cmd::{at_least, whole};

/// Estimation method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Batch least squares (f64), ARX.
    Ls,
    /// Recursive least squares (the firmware's f32 estimator), ARX.
    Rls,
    /// Recursive extended least squares, ARMAX (nc ≥ 1).
    Rels,
    /// Instrumental variables (f64), ARX: least squares, then three rounds with instruments
    /// simulated from the previous model. Unbiased under coloured noise, but still an
    /// equation-error criterion.
    Iv,
    /// Output error (f64), ARX structure: Levenberg–Marquardt on the simulated-output error
    /// ([`hter::ident::oe`]) from the IV and LS estimates and from lower-order OE models with a
    /// few second-pole starts; the best is kept. Maximises the simulated fit itself.
    Oe,
}

/// The delay nk: given, or scanned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Delay {
    /// Fit every delay 1…[`MAX_NK`] and keep the best simulated fit.
    Auto,
    /// This many samples.
    Samples(usize),
}

impl std::str::FromStr for Delay {
    type Err = String;
    fn from_str(v: &str) -> Result<Self, String> {
        if v == "auto" {
            return Ok(Delay::Auto);
        }
        v.parse().map(Delay::Samples).map_err(|_| format!("'{v}' is not a delay: give 1–{MAX_NK} samples or 'auto'"))
    }
}

/// Where the deviation variables are taken from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OperatingPointChoice {
    /// `initial` if the log starts at rest, else `mean`.
    Auto,
    /// u(0) and the mean of y while the duty keeps its initial value (the log starts at rest).
    Initial,
    /// The means of y and u over the record.
    Mean,
}

/// Arguments of `hter identify`.
#[derive(clap::Args, Debug, Clone)]
pub struct IdentifyArgs {
    /// CSV log with a header row and columns t_s, duty (input) and temp_c (output), any order.
    #[arg(long)]
    pub input: PathBuf,
    /// Order of A (1–4).
    #[arg(long, default_value_t = 2, allow_negative_numbers = true, value_parser = whole("the order of A, na,", 1, MAX_NA))]
    pub na: usize,
    /// Number of B coefficients (1–4).
    #[arg(long, default_value_t = 2, allow_negative_numbers = true, value_parser = whole("the number of B coefficients, nb,", 1, MAX_NB))]
    pub nb: usize,
    /// Order of C (0–2; rels needs ≥ 1 and uses 1 when 0 is given).
    #[arg(long, default_value_t = 0, allow_negative_numbers = true, value_parser = whole("the order of C, nc,", 0, MAX_NC))]
    pub nc: usize,
    /// Delay in samples (1–10), or `auto`: fit each delay 1–10 and keep the best simulated fit
    /// (per order in the 1/2/4 comparison).
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    pub nk: Delay,
    /// Estimator: oe (output error, the default), ls, iv, rls or rels.
    #[arg(long, value_enum, default_value = "oe")]
    pub method: Method,
    /// Forgetting factor λ_f of rls/rels, in [0.5, 1] (default 1; below 1 refused with another
    /// method, which forgets nothing).
    #[arg(long, allow_negative_numbers = true)]
    pub forgetting: Option<f64>,
    /// First-order filter parameter F_a in [0, 1) applied to the output first.
    #[arg(long, allow_negative_numbers = true)]
    pub filter: Option<f64>,
    /// Prefilter both duty and temperature with the same first-order low-pass (pole in [0, 1))
    /// before estimating (Ljung 1999, §14.4): weights the equation-error fit toward the slow
    /// dynamics that matter for control, instead of the one-sample-ahead detail ARX favours.
    /// Validation uses the unprefiltered data.
    #[arg(long, allow_negative_numbers = true)]
    pub prefilter: Option<f64>,
    /// Output column to identify from (e.g. raw_temp_c for the unfiltered reading of a
    /// `hter sim` trace).
    #[arg(long, default_value = "temp_c")]
    pub y_column: String,
    /// Average every N samples into one before identifying (for logs sampled much faster than
    /// the plant moves, where quantisation noise would dominate each step).
    #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = at_least("--decimate", 1usize))]
    pub decimate: usize,
    /// Operating point removed: initial (the log starts at rest), mean, or auto (initial when
    /// the log starts at rest, else mean).
    #[arg(long, value_enum, default_value = "auto")]
    pub operating_point: OperatingPointChoice,
    /// Report the order the 1/2/4 comparison chooses (na = nb) instead of --na/--nb (refused
    /// with either: one of the two orders would be silently ignored).
    #[arg(long, conflicts_with_all = ["na", "nb"])]
    pub auto_order: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Plot parameter convergence and measured vs simulated output (.png or .svg).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}
