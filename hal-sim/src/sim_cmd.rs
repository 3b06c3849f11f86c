//! `hter sim`: one closed-loop scenario, the firmware's per-sample step against the plant
//! model, with its summary, JSON metrics, CSV trace and plot. [`options`] turns the arguments
//! into a checked [`SimOptions`]; `hter compare` and the demo reuse it.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

use hter::control::gpc::{MAX_N2, MAX_NU};

use crate::plant::Load;
use crate::plot;
use crate::scenario::Scenario;
use crate::sim::{self, ControllerChoice, ControllerSpec, Drive, PlantChoice, SimOptions, SimOutput};

/// Why `--module-sense` is refused with `--drive buck`: the sense reads the SSR's off time in
/// the conversion window, and a buck's filtered output has none.
pub const MODULE_SENSE_SSR_ONLY: &str =
    "--module-sense needs --drive ssr: it reads the modules in the SSR's off time, and a buck's output has none";

/// Arguments of `hter sim` (and the scenario and controller of `hter compare`).
#[derive(clap::Args, Debug)]
pub struct SimArgs {
    /// Scenario name (step, piecewise, half-load, disturbance, prbs, hot-zone, mission, power-cut) or a
    /// JSON scenario file.
    #[arg(long, default_value = "step")]
    pub scenario: String,
    /// Controller [default: gpc, self-tuning GPC, the board's default build]. The tuning
    /// flags below name the controllers they apply to; one given for another controller is
    /// refused, not ignored.
    #[arg(long, value_enum)]
    pub controller: Option<ControllerChoice>,
    /// Plant: hter1 (aluminium container), hter2 (stainless steel), or an ideal ARX model
    /// arx:A;B;K (y = temperature − ambient, u = duty; no C field; refused unless A is stable
    /// and the static gain is in [−1000, 0) °C per unit duty).
    #[arg(long, default_value = "hter1")]
    pub plant: String,
    /// Fixed model for gmvc/igmvc/gpc, arx:A;B;K or arx:A;B;K;C (without it they are
    /// self-tuning); refused unless A is stable, the static gain is in [−1000, 0) °C per unit
    /// duty and C (the T-filter) has its roots strictly inside the unit circle.
    #[arg(long)]
    pub model: Option<String>,
    /// GPC: first predicted sample in the cost.
    #[arg(long, allow_negative_numbers = true, value_parser = whole("GPC's first predicted sample N1", 1, MAX_N2))]
    pub n1: Option<usize>,
    /// GPC: last predicted sample in the cost (≤ 30).
    #[arg(long, allow_negative_numbers = true, value_parser = whole("GPC's last predicted sample N2", 1, MAX_N2))]
    pub n2: Option<usize>,
    /// GPC: control horizon (≤ 5).
    #[arg(long, allow_negative_numbers = true, value_parser = whole("GPC's control horizon Nu", 1, MAX_NU))]
    pub nu: Option<usize>,
    /// GPC and IGMVC: weight on the control increment (≥ 0).
    #[arg(long, allow_negative_numbers = true)]
    pub lambda: Option<f64>,
    /// GMVC: output weight P(1), 0.01…100 (default 1). The law aims P·y at R·w and divides
    /// by g0² + S² with g0 ∝ P, so only R/P and S/P matter: P ≤ 0 aims the load away from the
    /// setpoint (−1 froze it), and four decades from the defaults S swamps g0 (1e-30 cools
    /// nothing) or vanishes against it.
    #[arg(long, allow_negative_numbers = true)]
    pub p_weight: Option<f64>,
    /// GMVC: reference weight R, 0.01…100 (default 1; R = P tracks w at steady state with S =
    /// 0, other ratios aim at (R/P)·w); R ≤ 0 aims at 0 °C or below.
    #[arg(long, allow_negative_numbers = true)]
    pub r_weight: Option<f64>,
    /// GMVC: control weight S, °C per unit duty, 0…10 (default 0.05): the steady-state offset
    /// grows with S, and above 10 S² outweighs g0² thousands of times at P = 1: the law
    /// barely cools.
    #[arg(long, allow_negative_numbers = true)]
    pub s_weight: Option<f64>,
    /// GMVC and IGMVC: pole α of the output weight P = (1 − α q⁻¹)/(1 − α), 0 ≤ α < 1
    /// (default 0.9 for GMVC, 0.93 for IGMVC; 0 gives the classical P = 1).
    #[arg(long, allow_negative_numbers = true)]
    pub p_pole: Option<f64>,
    /// IGMVC and self-tuning GPC: pole τ of the T-filter T = 1 − τ q⁻¹, 0 ≤ τ < 1 (0: none;
    /// default 0.9 for IGMVC, 0.8 for self-tuning GPC).
    #[arg(long, allow_negative_numbers = true)]
    pub t_pole: Option<f64>,
    /// Self-tuning laws: no first-approach lead (the law aims at the setpoint from the start;
    /// the board always runs with it: `hter::control::adaptive`, "The first approach").
    #[arg(long)]
    pub no_approach_lead: bool,
    /// PI: proportional gain, duty per °C (0.001…100; default: the carrier's SIMC tuning).
    #[arg(long, allow_negative_numbers = true)]
    pub kp: Option<f64>,
    /// PI: integral time, s (1…1e6; default: the carrier's SIMC tuning).
    #[arg(long, allow_negative_numbers = true)]
    pub ti: Option<f64>,
    /// Water load: full (100 ml) or half (50 ml).
    #[arg(long, value_enum, default_value = "full")]
    pub load: LoadArg,
    /// Ambient temperature, °C.
    #[arg(long, default_value_t = 28.0, allow_negative_numbers = true)]
    pub ambient: f64,
    /// Duration, s (default: the scenario's own).
    #[arg(long, allow_negative_numbers = true)]
    pub duration: Option<f64>,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = whole("the noise seed", 0, u64::MAX))]
    pub seed: u64,
    /// How the modules are driven: ssr (switched fully on and off at 1 Hz, the default) or buck
    /// (a synchronous buck with an LC filter: a smooth voltage, duty × supply).
    #[arg(long, value_enum, default_value = "ssr")]
    pub drive: Drive,
    /// A board that reads the modules' voltage in the conversion window (a board change the
    /// reference board does not have; SSR drive only): a shorted SSR is found within two
    /// samples (`hter::supervisor::module`).
    #[arg(long)]
    pub module_sense: bool,
    /// Inject a fault at a time, KIND@T_S (repeatable): sensor-open, sensor-short,
    /// sensor-stuck, sensor-spikes, sensor-offset, ssr-stuck-on, ssr-stuck-off, supply-sag,
    /// lid-open, brownout; of the board: supply-switch-short, firmware-hang, and its fail-safe
    /// stops board-fault-panic, board-fault-hard-fault, board-fault-nmi,
    /// board-fault-unexpected-interrupt, board-fault-control-stall (the stop, a reset, the
    /// boot that reports it).
    #[arg(long = "fault")]
    pub faults: Vec<String>,
    /// Write the trace as CSV (one row per control sample).
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Plot temperature, setpoint and duty to a .png or .svg file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Print the metrics as one JSON object instead of the summary.
    #[arg(long)]
    pub json: bool,
    /// Commission the carrier first, as a board told `identify` does (rest, PRBS and the board's
    /// fit, holding 4 °C at this plant, load and ambient). `board`: what the board's App does,
    /// one run giving the control model (every b_i ≤ 0) as the self-tuner's start and the
    /// cabinet model (the monotone rule's best fit) as the holdover's. `every-coefficient` or
    /// `monotone`: one rule alone, its model both (the self-tuner's start only if it trusts
    /// it: every b_i ≤ 0).
    #[arg(long, value_enum)]
    pub commission: Option<CommissionRule>,
    /// Ambient of the `--commission` run, °C (default: the run's `--ambient`): a carrier
    /// commissioned once and then carried elsewhere.
    #[arg(long, allow_negative_numbers = true, requires = "commission")]
    pub commission_ambient: Option<f64>,
    /// Replay the randomized mission of this seed from `hter campaign` (its carrier, ambient,
    /// lid openings, supply sag, faults and noise seed); the controller flags still apply.
    #[arg(
        long,
        conflicts_with_all = ["scenario", "plant", "load", "ambient", "duration", "seed", "faults"],
        allow_negative_numbers = true,
        value_parser = whole("the mission seed", 0, u64::MAX)
    )]
    pub mission_seed: Option<u64>,
}

/// The sign rule of `--commission` ([`hter::ident::commission::SignRule`]).
// Doc comments on the variants would become clap's help for each value.
#[allow(missing_docs)]
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum CommissionRule {
    Board,
    EveryCoefficient,
    Monotone,
}

/// The water load of `--load`: `full` is 100 ml of water, `half` 50 ml.
// Doc comments on the variants would become clap's help for each value and change
// `hter sim --help`.
#[allow(missing_docs)]
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum LoadArg {
    Full,
    Half,
}

impl From<LoadArg> for Load {
    fn from(l: LoadArg) -> Load {
        match l {
            LoadArg::Full => Load::Full,
            LoadArg::Half => Load::Half,
        }
    }
}

/// `x` if it is finite, else a one-line error naming the flag `--name`.
pub fn finite(name: &str, x: f64) -> Result<f64> {
    if x.is_finite() {
        Ok(x)
    } else {
        bail!("--{name} must be a finite number, got {}", shown(x))
    }
}

/// `x` for a one-line message: as typed for everyday magnitudes, in exponent form beyond them
/// (1e300 is not 301 digits, 1e-300 not 300 zeros).
pub fn shown(x: f64) -> String {
    if x != 0.0 && x.is_finite() && !(1e-6..1e16).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// `x` as the f32 the library computes with, or a one-line error naming the flag `--name`: a
/// finite f64 can overflow to ±inf (`--ti 1e39`) or underflow to 0 or a subnormal
/// (`--kp 1e-300`) on the way, and silently change what the flag means (a PI without its
/// integral, a controller that never cools).
pub fn single(name: &str, x: f64) -> Result<f32> {
    let v = finite(name, x)? as f32;
    if !v.is_finite() {
        bail!("--{name} = {} is too large for the library's f32 arithmetic (at most {:e})", shown(x), f32::MAX);
    }
    if x != 0.0 && !v.is_normal() {
        bail!(
            "--{name} = {} is too small for the library's f32 arithmetic (at least {:e})",
            shown(x),
            f32::MIN_POSITIVE
        );
    }
    Ok(v)
}

/// A pole in [0, 1) as the f32 the library computes with, or a one-line error naming the flag
/// `--name`: 0.999999999 is in range as typed but 1 in f32, and the library refused it as
/// "Gmvc: configuration refused (Law(Config))".
fn pole(name: &str, x: f64) -> Result<f32> {
    let v = x as f32;
    if !(0.0..1.0).contains(&x) {
        bail!("--{name} must be in [0, 1), got {}", shown(x));
    }
    if v >= 1.0 {
        bail!(
            "--{name} must be in [0, 1), got {x}, which is {v} in the library's f32 arithmetic (at most {})",
            1.0 - f32::EPSILON / 2.0
        );
    }
    Ok(v)
}

/// A clap value parser of a whole-number flag within `lo..=hi` whose message says what the
/// flag is and its range (clap names the flag and the value). With `allow_negative_numbers` on
/// the flag, `--seed -1` is this error instead of clap's "unexpected argument '-1' found".
pub fn whole<T>(
    what: &'static str,
    lo: T,
    hi: T,
) -> impl Fn(&str) -> std::result::Result<T, String> + Clone + Send + Sync + 'static
where
    T: std::str::FromStr + PartialOrd + Copy + std::fmt::Display + Send + Sync + 'static,
{
    move |s: &str| {
        s.parse::<T>()
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .ok_or_else(|| format!("{what} must be a whole number in {lo}…{hi}"))
    }
}

/// [`whole`] with no upper bound but the type's.
pub fn at_least<T>(
    what: &'static str,
    lo: T,
) -> impl Fn(&str) -> std::result::Result<T, String> + Clone + Send + Sync + 'static
where
    T: std::str::FromStr + PartialOrd + Copy + std::fmt::Display + Send + Sync + 'static,
{
    move |s: &str| {
        s.parse::<T>().ok().filter(|v| *v >= lo).ok_or_else(|| format!("{what} must be a whole number ≥ {lo}"))
    }
}

/// PI gain range accepted by `--kp`, duty per °C. Below 0.001 the proportional term of the
/// largest error a run can see (≈ 50 °C, the hottest supported ambient against the setpoint)
/// is under 5 % duty: a loop that barely cools. Above 100 an error of 0.01 °C, the size of the
/// ADC noise (1.5 counts), already asks for the whole drive: on-off control, which `--controller onoff`
/// is. `--kp 1e39` was infinite in f32 and the loop never cooled.
pub const KP_RANGE_PER_C: (f64, f64) = (1e-3, 100.0);

/// PI integral time range accepted by `--ti`, s. Below 1 s (a tenth of the 10 s sample) the
/// integral adds ten times the proportional term every sample: the discrete PI (Kp·Ts/Ti per
/// sample) is then a relay, not the PI it names. Above 1e6 s (11.6 days) its per-sample step
/// Kp·Ts·e/Ti is lost in the f32 rounding of the integral for small errors: P control in
/// disguise, which `--controller p` is. `--ti 1e39` was infinite in f32 and `--ti 1e-300` 0,
/// and both silently turned PI into P.
pub const TI_RANGE_S: (f64, f64) = (1.0, 1e6);

/// GMVC output weight range of `--p-weight` (and reference weight of `--r-weight`): the
/// law (`hter::control::mv`) aims P·y at R·w and computes u = g0 (R w − F y − …)/(g0² + S²)
/// with g0 ∝ P (P = A E + q^−k F, G = E B), so it depends on R/P and S/P only. A P or R ≤ 0 aims
/// the load at −w or 0 °C (`--p-weight=-1` froze it); four decades from the defaults P = R = 1
/// the default S = 0.05 swamps g0 (`--p-weight=1e-30` cooled nothing) or the weights leave the
/// range the f32 law was tuned in.
pub const PR_WEIGHT_RANGE: (f64, f64) = (0.01, 100.0);

/// Largest GMVC control weight `--s-weight`, °C per unit duty: the steady-state offset grows
/// with S (`hter::control::mv`), and at 10 S² outweighs the carrier's g0² (≈ 0.07 at P = 1,
/// α = 0.9) over a thousand times: a law that barely cools.
pub const S_WEIGHT_MAX: f64 = 10.0;

/// Whether a tuning flag applies to a controller (with `--model` given or not).
type Applies = fn(ControllerChoice, bool) -> bool;

/// The tuning flags of `hter sim` and `hter compare` that apply to some controllers only, given
/// on this command line, each with the controllers it applies to (the bool: whether `--model`
/// is given, which turns the self-tuning laws into fixed-model ones).
fn tuning_flags(a: &SimArgs) -> Vec<(&'static str, &'static str, Applies)> {
    use ControllerChoice::{Gmvc, Gpc, Igmvc, Pi};
    let model_based: Applies = |c, _| matches!(c, Gmvc | Igmvc | Gpc);
    let gpc: Applies = |c, _| c == Gpc;
    let gmvc: Applies = |c, _| c == Gmvc;
    let pi: Applies = |c, _| c == Pi;
    let flags: [(bool, &str, &str, Applies); 13] = [
        (a.model.is_some(), "--model", "gmvc, igmvc and gpc", model_based),
        (a.n1.is_some(), "--n1", "gpc", gpc),
        (a.n2.is_some(), "--n2", "gpc", gpc),
        (a.nu.is_some(), "--nu", "gpc", gpc),
        (a.lambda.is_some(), "--lambda", "gpc and igmvc", |c, _| matches!(c, Gpc | Igmvc)),
        (a.p_weight.is_some(), "--p-weight", "gmvc", gmvc),
        (a.r_weight.is_some(), "--r-weight", "gmvc", gmvc),
        (a.s_weight.is_some(), "--s-weight", "gmvc", gmvc),
        (a.p_pole.is_some(), "--p-pole", "gmvc and igmvc", |c, _| matches!(c, Gmvc | Igmvc)),
        (
            a.t_pole.is_some(),
            "--t-pole",
            "igmvc and self-tuning gpc (gpc without --model: a fixed model's T-filter is its C)",
            |c, m| c == Igmvc || (c == Gpc && !m),
        ),
        (a.no_approach_lead, "--no-approach-lead", "the self-tuning gmvc, igmvc and gpc (without --model)", |c, m| {
            matches!(c, Gmvc | Igmvc | Gpc) && !m
        }),
        (a.kp.is_some(), "--kp", "pi", pi),
        (a.ti.is_some(), "--ti", "pi", pi),
    ];
    flags.into_iter().filter(|f| f.0).map(|(_, name, who, applies)| (name, who, applies)).collect()
}

/// Refuses a tuning flag that applies to none of `controllers` (for `hter sim`, its one
/// controller; for `hter compare`, at least one of those it runs must take each flag): such a
/// flag was silently ignored.
pub fn check_tuning_applies(a: &SimArgs, controllers: &[ControllerChoice]) -> Result<()> {
    let with_model = a.model.is_some();
    for (flag, who, applies) in tuning_flags(a) {
        if !controllers.iter().any(|&c| applies(c, with_model)) {
            let names: Vec<String> = controllers.iter().map(|c| controller_name(*c)).collect();
            let what = if controllers.len() == 1 { "the controller" } else { "any of the controllers" };
            bail!("{flag} does not apply to {what} {} (it applies to {who})", names.join(", "));
        }
    }
    Ok(())
}

/// The `--controller` value naming `c`.
fn controller_name(c: ControllerChoice) -> String {
    use clap::ValueEnum;
    c.to_possible_value().map_or_else(|| format!("{c:?}"), |v| v.get_name().to_string())
}

/// The path `p` stands for: canonical if it exists, else made absolute (so `x.csv` and
/// `./x.csv` are one file).
fn resolved(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf()))
}

/// Refuses an output that is an input or another output: `--csv sc.json --scenario sc.json`
/// overwrote the scenario, `--csv x.svg --plot x.svg` replaced the trace with the plot and
/// still said both were written. `inputs` and `outputs` are (flag, path).
pub fn check_paths(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    for (i, (flag, path)) in outputs.iter().enumerate() {
        let p = resolved(path);
        for (other, q) in inputs.iter().chain(&outputs[..i]) {
            if resolved(q) == p {
                bail!(
                    "{flag} '{}' is the same file as {other} '{}': it would overwrite it",
                    path.display(),
                    q.display()
                );
            }
        }
    }
    Ok(())
}

/// The files a `hter sim` or `hter compare` command line reads (a scenario file: a built-in
/// name reads nothing).
pub fn input_paths(a: &SimArgs) -> Vec<(&'static str, &Path)> {
    if a.mission_seed.is_none() && Scenario::built_in(&a.scenario).is_none() {
        vec![("--scenario", Path::new(&a.scenario))]
    } else {
        vec![]
    }
}

/// The simulation a `hter sim` command line asks for: its arguments checked and resolved.
pub fn options(a: &SimArgs) -> Result<SimOptions> {
    let scenario = Scenario::resolve(&a.scenario)?;
    // The identification run drives the SSR with its PRBS: a controller or its tuning was
    // silently replaced by it (`--controller pi --kp 1` ran the PRBS and said "controller prbs").
    if scenario.excitation && a.mission_seed.is_none() {
        let flag = a.controller.map(|c| format!("--controller {}", controller_name(c)));
        if let Some(flag) = flag.or_else(|| tuning_flags(a).first().map(|f| f.0.to_string())) {
            bail!(
                "{flag} does not apply to the {} scenario: it runs no controller (open loop, a PRBS on the SSR)",
                scenario.name
            );
        }
    }
    let duration_s = match a.duration {
        Some(d) => finite("duration", d)?,
        None => scenario.duration_s,
    };
    let mut controller = ControllerSpec::new(a.controller.unwrap_or(ControllerChoice::Gpc));
    if let Some(m) = &a.model {
        controller.model = Some(crate::arx::carrier_model(m)?);
    }
    if let Some(n) = a.n1 {
        controller.gpc.n1 = n;
    }
    if let Some(n) = a.n2 {
        controller.gpc.n2 = n;
    }
    if let Some(n) = a.nu {
        controller.gpc.nu = n;
    }
    if let Some(l) = a.lambda {
        let l = single("lambda", l)?;
        if l < 0.0 {
            bail!("--lambda must be ≥ 0, got {}", shown(f64::from(l)));
        }
        controller.gpc.lambda = l;
        controller.igmvc.lambda = l;
    }
    let g = &controller.gpc;
    if g.n1 < 1 || g.n2 < g.n1 || g.n2 > hter::control::gpc::MAX_N2 {
        bail!("GPC horizons need 1 ≤ N1 ≤ N2 ≤ {}, got N1 = {}, N2 = {}", hter::control::gpc::MAX_N2, g.n1, g.n2);
    }
    if g.nu < 1 || g.nu > hter::control::gpc::MAX_NU || g.nu > g.n2 {
        bail!("GPC control horizon needs 1 ≤ Nu ≤ min(N2, {}), got Nu = {}", hter::control::gpc::MAX_NU, g.nu);
    }
    let (w_lo, w_hi) = PR_WEIGHT_RANGE;
    for (name, w, field) in
        [("p-weight", a.p_weight, &mut controller.gmvc.p), ("r-weight", a.r_weight, &mut controller.gmvc.r)]
    {
        if let Some(w) = w {
            let w = finite(name, w)?;
            if !(w_lo..=w_hi).contains(&w) {
                bail!("--{name} must be within {w_lo}…{w_hi} (positive: see --help), got {}", shown(w));
            }
            *field = single(name, w)?;
        }
    }
    if let Some(sw) = a.s_weight {
        let sw = finite("s-weight", sw)?;
        if !(0.0..=S_WEIGHT_MAX).contains(&sw) {
            bail!("--s-weight must be within 0…{S_WEIGHT_MAX} °C per unit duty, got {}", shown(sw));
        }
        controller.gmvc.s = single("s-weight", sw)?;
    }
    if let Some(al) = a.p_pole {
        let al = finite("p-pole", al)?;
        let al = pole("p-pole", al)?;
        controller.gmvc.p_pole = al;
        controller.igmvc.p_pole = al;
    }
    if let Some(tp) = a.t_pole {
        let tp = finite("t-pole", tp)?;
        let tp = pole("t-pole", tp)?;
        controller.igmvc.t_pole = tp;
        controller.gpc_t_filter = tp;
    }
    controller.approach_lead = !a.no_approach_lead;
    let plant = PlantChoice::parse(&a.plant)?;
    // The ideal ARX plant takes the duty as is and has no hardware to fail: a fault or a drive
    // on it would be silently ignored, as `--commission` would.
    if let PlantChoice::Arx(_) = plant {
        if let Some(f) = a.faults.first() {
            bail!("--fault {f} needs a physical plant (hter1 or hter2): an ARX plant has no hardware to fail");
        }
        if a.drive == Drive::Buck {
            bail!("--drive buck needs a physical plant (hter1 or hter2): an ARX plant takes the duty as is");
        }
        if a.module_sense {
            bail!("--module-sense needs a physical plant (hter1 or hter2): an ARX plant has no modules to read");
        }
    }
    if a.module_sense && a.drive == Drive::Buck {
        bail!("{MODULE_SENSE_SSR_ONLY}");
    }
    if a.kp.is_some() || a.ti.is_some() {
        let mut pi = plant.default_pi();
        if let Some(kp) = a.kp {
            let kp = finite("kp", kp)?;
            if kp <= 0.0 {
                bail!("--kp must be > 0 (duty per °C), got {}", shown(kp));
            }
            let (lo, hi) = KP_RANGE_PER_C;
            if !(lo..=hi).contains(&kp) {
                bail!("--kp must be within {lo}…{hi} duty per °C, got {}", shown(kp));
            }
            pi.kp_per_c = single("kp", kp)?;
        }
        if let Some(ti) = a.ti {
            let ti = finite("ti", ti)?;
            if ti <= 0.0 {
                bail!("--ti must be > 0 (s), got {}", shown(ti));
            }
            let (lo, hi) = TI_RANGE_S;
            if !(lo..=hi).contains(&ti) {
                bail!("--ti must be within {lo}…{hi:e} s, got {}", shown(ti));
            }
            pi.ti_s = single("ti", ti)?;
        }
        controller.pi = Some(pi);
    }
    let mut opts = match a.mission_seed {
        Some(seed) => SimOptions {
            drive: a.drive,
            module_sense: a.module_sense,
            ..crate::mission::Mission::generate(seed).options(controller)
        },
        None => SimOptions {
            scenario,
            controller,
            plant,
            load: a.load.into(),
            ambient_c: finite("ambient", a.ambient)?,
            duration_s,
            seed: a.seed,
            faults: a.faults.iter().map(|f| sim::Fault::parse(f)).collect::<Result<_>>()?,
            drive: a.drive,
            module_sense: a.module_sense,
        },
    };
    // A fault is injected at the first sample at or after its time: one after the last sample
    // never happens, and the run would report a clean carrier.
    let ts = f64::from(hter::step::CarrierConfig::DEFAULT.ts_s);
    let last_sample_s = ((opts.duration_s / ts).round() - 1.0) * ts;
    // (A run shorter than one sample is refused by `sim::run` for what it is.)
    let late = |(t, _): &&(f64, sim::Fault)| opts.duration_s >= ts && *t > last_sample_s;
    if let Some((t, f)) = opts.faults.iter().find(late).filter(|_| a.mission_seed.is_none()) {
        bail!(
            "--fault {}@{}: the run lasts {} s (last sample at {last_sample_s} s), the fault would never happen",
            f.name(),
            shown(*t),
            shown(opts.duration_s)
        );
    }
    // A power cut after the last sample never happens: the run reported the holdover the step
    // predicted for a cut it never saw.
    if let Some(cut) = opts.scenario.cut.filter(|c| opts.duration_s >= ts && last_sample_s < c.at_s) {
        bail!(
            "--duration {}: the {} scenario cuts the supply at {} s, and the run's last sample is at {last_sample_s} s (it must last at least {} s)",
            shown(opts.duration_s),
            opts.scenario.name,
            cut.at_s,
            cut.at_s + ts
        );
    }
    if let Some(rule) = a.commission {
        let Some(params) = opts.plant_params() else { bail!("--commission needs a physical plant (hter1 or hter2)") };
        let ambient = match a.commission_ambient {
            Some(c) => finite("commission-ambient", c)?,
            None => opts.ambient_c,
        };
        let show = |what: &str, m: &hter::model::Model| {
            eprintln!(
                "commissioned {what}: A = 1 {:+} q^-1 {:+} q^-2, B = {} {:+} q^-1, k = {}, static gain {:.1} °C per unit duty",
                m.a()[0],
                m.a()[1],
                m.b()[0],
                m.b()[1],
                m.k(),
                m.static_gain().unwrap_or(f32::NAN)
            )
        };
        let sign = match rule {
            CommissionRule::Board => {
                // As the board's App: the control model for the self-tuner, the cabinet model
                // for the holdover.
                let c = crate::commission::commission_board(params, ambient, opts.seed)?;
                show("control model", &c.control);
                show("cabinet model", &c.cabinet);
                opts.controller.initial = Some(c.control);
                opts.controller.holdover = Some(c.cabinet);
                return Ok(opts);
            }
            CommissionRule::EveryCoefficient => hter::ident::commission::SignRule::EveryCoefficient,
            CommissionRule::Monotone => hter::ident::commission::SignRule::Monotone,
        };
        let m = crate::commission::commission(params, ambient, opts.seed, sign)?;
        show("model", &m);
        // One rule's model is both: the self-tuner's start if it trusts it (every b_i ≤ 0), and
        // the holdover's.
        if hter::control::adaptive::plausible_model(&hter::profile::ADAPTIVE_GPC, &m) {
            opts.controller.initial = Some(m);
        }
        opts.controller.holdover = Some(m);
    }
    Ok(opts)
}

/// `hter sim`.
pub fn run(a: &SimArgs) -> Result<()> {
    check_tuning_applies(a, &[a.controller.unwrap_or(ControllerChoice::Gpc)])?;
    let outputs: Vec<(&str, &Path)> = [("--csv", &a.csv), ("--plot", &a.plot)]
        .into_iter()
        .filter_map(|(f, p)| p.as_deref().map(|p| (f, p)))
        .collect();
    check_paths(&input_paths(a), &outputs)?;
    if let Some(p) = &a.csv {
        plot::check_dir(p)?;
    }
    if let Some(p) = &a.plot {
        plot::check_path(p)?;
    }
    let opts = options(a)?;
    let out = sim::run(&opts)?;
    if let Some(path) = &a.csv {
        write_csv(path, &out)?;
    }
    if let Some(path) = &a.plot {
        plot_run(path, &opts, &out)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&out.metrics)?);
    } else {
        print_summary(&opts, &out);
        if let Some(p) = &a.csv {
            println!("trace written to {}", p.display());
        }
        if let Some(p) = &a.plot {
            println!("plot written to {}", p.display());
        }
    }
    Ok(())
}

/// The trace, one row per control sample.
fn write_csv(path: &std::path::Path, out: &SimOutput) -> Result<()> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in &out.rows {
        w.serialize(r)?;
    }
    let bytes = w.into_inner().map_err(|e| anyhow::anyhow!("cannot write '{}': {}", path.display(), e.error()))?;
    crate::output::write(path, &bytes)
}

/// Temperature, duty and, for self-tuning runs, the estimate, to a .png or .svg file.
fn plot_run(path: &std::path::Path, opts: &SimOptions, out: &SimOutput) -> Result<()> {
    let minutes = |t: f64| t / 60.0;
    let pts = |f: &dyn Fn(&sim::Row) -> f64| out.rows.iter().map(|r| (minutes(r.t_s), f(r))).collect();
    let temp = plot::Panel {
        title: "Load temperature".into(),
        y_label: "°C".into(),
        series: vec![
            plot::Series { name: "setpoint".into(), points: pts(&|r| r.setpoint_c) },
            plot::Series { name: "true load".into(), points: pts(&|r| r.true_temp_c) },
            plot::Series { name: "measured (filtered)".into(), points: pts(&|r| r.temp_c) },
            plot::Series { name: "2 °C limit".into(), points: pts(&|_| 2.0) },
        ],
        y_range: None,
    };
    let duty = plot::Panel {
        title: "SSR duty".into(),
        y_label: "duty".into(),
        series: vec![plot::Series { name: "duty".into(), points: pts(&|r| r.duty) }],
        y_range: Some((-0.02, 1.02)),
    };
    let title = format!(
        "{} — {} on {} ({}), {:?} load, {} °C ambient",
        opts.scenario.name,
        out.metrics.controller,
        opts.plant.name(),
        opts.drive.name(),
        opts.scenario.load.unwrap_or(opts.load),
        opts.ambient_c
    );
    let mut panels = vec![temp, duty];
    // Self-tuning runs: the estimate over time.
    let est = |f: &dyn Fn(&sim::Row) -> Option<f32>| -> Vec<(f64, f64)> {
        out.rows.iter().filter_map(|r| f(r).map(|v| (minutes(r.t_s), f64::from(v)))).collect()
    };
    if out.rows.iter().any(|r| r.a1.is_some()) {
        panels.push(plot::Panel {
            title: "Estimated A(q⁻¹) = 1 + a1 q⁻¹ + a2 q⁻²".into(),
            y_label: "coefficient".into(),
            series: vec![
                plot::Series { name: "a1".into(), points: est(&|r| r.a1) },
                plot::Series { name: "a2".into(), points: est(&|r| r.a2) },
            ],
            y_range: None,
        });
        panels.push(plot::Panel {
            title: "Estimated B(q⁻¹) = b0 + b1 q⁻¹ + b2 q⁻² + b3 q⁻³ (°C per unit duty)".into(),
            y_label: "coefficient".into(),
            series: vec![
                plot::Series { name: "b0".into(), points: est(&|r| r.b0) },
                plot::Series { name: "b1".into(), points: est(&|r| r.b1) },
                plot::Series { name: "b2".into(), points: est(&|r| r.b2) },
                plot::Series { name: "b3".into(), points: est(&|r| r.b3) },
            ],
            y_range: None,
        });
    }
    plot::panels(path, &title, "time (min)", &panels)
}

/// The text summary of a run.
pub fn print_summary(opts: &SimOptions, out: &SimOutput) {
    let m = &out.metrics;
    println!("scenario    {} — {}", opts.scenario.name, opts.scenario.description);
    println!(
        "plant       {} ({} drive), {:?} load, ambient {} °C; controller {}; Ts = {} s",
        opts.plant.name(),
        opts.drive.name(),
        opts.scenario.load.unwrap_or(opts.load),
        opts.ambient_c,
        m.controller,
        out.ts_s
    );
    println!("IAE                         {:10.1} °C·s", m.tracking.iae);
    let band = format!("settle time (±{} °C)", crate::metrics::SETTLE_BAND_C);
    match m.tracking.settle_time_s {
        Some(s) => println!("{band:<28}{s:10.0} s"),
        None => println!("{band:<28}   never"),
    }
    match m.tracking.max_abs_error_after_settle_c {
        Some(e) => println!("max |error| after settling  {e:10.2} °C"),
        None => println!("max |error| after settling   not settled"),
    }
    println!("steady-state |error|        {:10.2} °C", m.tracking.steady_state_error_c);
    println!("overshoot                   {:10.2} °C", m.tracking.overshoot_c);
    println!("min / max load temperature  {:6.2} / {:.2} °C", m.tracking.min_temp_c, m.tracking.max_temp_c);
    println!("time outside 2–8 °C         {:10.0} s", m.tracking.time_outside_2_8_s);
    println!("energy                      {:10.2} Wh", m.energy_wh);
    println!("mean power                  {:10.2} W", m.mean_power_w);
    println!("SSR switches                {:10}", m.ssr_switches);
    println!("freeze-guard trips          {:10}", m.freeze_guard_trips);
    if !m.faults_detected.is_empty() {
        let list: Vec<String> = m.faults_detected.iter().map(|f| format!("{}@{}s", f.kind, f.t_s)).collect();
        println!("faults detected             {}", list.join(", "));
    }
}
