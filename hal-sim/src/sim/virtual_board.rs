//! The virtual board: the library's [`App`] — the very step, record and interface handler the
//! firmware runs — in front of the simulated carrier, with the board's flash as the mock L4
//! flash ([`crate::flash::MockFlash`]: the settings/model/history store and the cold-chain log,
//! in regions the size of the firmware's) and its write gate. `hter virtual-board` serves it on
//! a pseudo-terminal; the tests drive it directly.
//!
//! What differs from the board, and why it does not matter to the interface: time is simulated
//! (one sample per [`VirtualBoard::step`], N× faster than real time when served), the supply is
//! always good (the write gate still holds writes off for its minute after every boot), and a
//! power cut is injected on request ([`VirtualBoard::cut_next_settings_write`]) instead of
//! happening.

use anyhow::{bail, Result};
use embassy_futures::block_on;
use hter::app::{App, AppConfig, Handled, SampleOut};
use hter::control::adaptive::AdaptiveConfig;
use hter::control::PiConfig;
use hter::failsafe::{ResetRecords, StopInfo, Stops};
use hter::iface::Law;
use hter::persist::flash::{self, LogStore, Store};
use hter::persist::log::{write_csv_row, CSV_HEADER};
use hter::persist::{PendingSaves, ResetCause, Save, StoreFailures, WriteGate};
use hter::profile;
use hter::step::ValidConfig;

use super::rig::Rig;
use super::{ControllerChoice, ControllerSpec, PlantChoice, SimOptions};
use crate::flash::{MockEcc, MockFlash};
use crate::plant::Load;
use crate::scenario::{Scenario, Start};

/// The L4's flash page, bytes.
const PAGE: usize = 2048;
/// The settings/model/history region: 4 pages, as `memory.x`'s PERSIST.
const STORE_PAGES: usize = 4;
/// The cold-chain log region: 248 pages, as the firmware's.
const LOG_PAGES: usize = 248;

type MockStore = Store<MockFlash<PAGE>, MockEcc>;
type MockLog = LogStore<MockFlash<PAGE>, MockEcc>;

/// The laws of the default firmware build.
pub const LAWS: &[Law] = &[Law::Gpc, Law::Pi, Law::OnOff];

/// The virtual board's build: the default firmware's (self-tuning GPC, its PI and On-Off; the
/// board profile's cadences) starting from `adaptive`.
pub fn app_config(adaptive: AdaptiveConfig) -> AppConfig {
    let ts_s = hter::step::CarrierConfig::DEFAULT.ts_s;
    AppConfig {
        carrier: ValidConfig::DEFAULT,
        adaptive,
        laws: LAWS,
        setpoint_c: 4.0,
        firmware: concat!("hter-virtual-board ", env!("CARGO_PKG_VERSION")),
        history_save_samples: profile::samples(profile::HISTORY_SAVE_S, ts_s),
        model_save_samples: profile::samples(profile::MODEL_SAVE_S, ts_s),
    }
}

/// What the virtual board simulates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VirtualOptions {
    /// The carrier (`hter1` or `hter2`).
    pub plant: PlantChoice,
    /// Its load.
    pub load: Load,
    /// Ambient, °C.
    pub ambient_c: f64,
    /// Seed of the ADC noise.
    pub seed: u64,
    /// The board has the module-side sense (the firmware's `interface,module-sense` build): the
    /// modules' voltage in the conversion window goes to the step with each sample.
    pub module_sense: bool,
}

/// Why [`VirtualBoard::inject`] refuses a hung control loop.
pub const HANG_REFUSED: &str = "the virtual board serves requests from its control loop and cannot hang it \
                                (`hter sim --fault firmware-hang@T` simulates one)";

/// The simulated carrier and its board.
pub struct VirtualBoard {
    rig: Rig,
    app: App,
    adaptive: AdaptiveConfig,
    store: Option<MockStore>,
    log: Option<MockLog>,
    pending: PendingSaves,
    gate: WriteGate,
    /// Board time since the last boot, ms.
    t_ms: u64,
    /// Simulated time since the start, s.
    sim_s: f64,
    last_on: bool,
    cut_settings: Option<usize>,
    /// Boots after the first (power cuts, resets).
    pub restarts: u32,
    /// Flash writes that failed (each logged to stderr by the server).
    pub write_errors: u32,
    /// Stores failed in a row in each region (the firmware's persist task keeps the same).
    failures: StoreFailures,
    /// The fail-safe's reset-surviving record (the firmware's `.uninit` RAM): the stops the
    /// stored history does not have yet. A reset keeps it, a power cut loses it.
    ram: ResetRecords,
}

impl VirtualBoard {
    /// A carrier holding 4 °C with a blank flash, booted.
    pub fn new(opts: &VirtualOptions) -> Result<VirtualBoard> {
        Self::starting(opts, Start::Holding(4.0))
    }

    /// A carrier that starts as `start` says (`Start::Ambient`: just switched on, everything at
    /// the ambient) with a blank flash, booted.
    pub fn starting(opts: &VirtualOptions, start: Start) -> Result<VirtualBoard> {
        if matches!(opts.plant, PlantChoice::Arx(_)) {
            bail!("the virtual board simulates a physical carrier: --plant hter1 or hter2");
        }
        let scenario = Scenario {
            name: "virtual-board".into(),
            description: "a carrier holding 4 °C".into(),
            start,
            setpoints: vec![(0.0, 4.0)],
            changes: Vec::new(),
            duration_s: f64::INFINITY,
            load: None,
            excitation: false,
            cut: None,
        };
        let sim = SimOptions {
            plant: opts.plant,
            load: opts.load,
            ambient_c: opts.ambient_c,
            seed: opts.seed,
            module_sense: opts.module_sense,
            ..SimOptions::new(scenario, ControllerSpec::new(ControllerChoice::Gpc))
        };
        let (rig, _u0) = Rig::new(&sim)?;
        // The carrier's own start model, as a board commissioned on it would hold.
        let initial = match opts.plant {
            PlantChoice::Hter2 => profile::START_MODEL_HTER2,
            _ => profile::START_MODEL_HTER1,
        };
        let adaptive = AdaptiveConfig {
            initial: Some(initial),
            k: initial.k(),
            // The carrier's PI, booted as the board's profile boots it.
            fallback: PiConfig { bias: profile::BOOT_DUTY, ..opts.plant.default_pi() },
            ..profile::ADAPTIVE_GPC
        };
        let (mut store, mut log) = (open_store(MockFlash::blank(STORE_PAGES)), open_log(MockFlash::blank(LOG_PAGES)));
        let app = booted(adaptive, &mut store, &mut log, ResetCause::Other, false, Stops::default());
        Ok(VirtualBoard {
            rig,
            app,
            adaptive,
            store: Some(store),
            log: Some(log),
            pending: PendingSaves::EMPTY,
            gate: WriteGate::firmware(),
            t_ms: 0,
            sim_s: 0.0,
            last_on: false,
            cut_settings: None,
            restarts: 0,
            write_errors: 0,
            failures: StoreFailures::NEW,
            ram: ResetRecords::EMPTY,
        })
    }

    /// The application (for tests).
    pub fn app(&self) -> &App {
        &self.app
    }

    /// The load's true temperature, °C.
    pub fn load_c(&self) -> f64 {
        self.rig.true_temp_c()
    }

    /// Simulated time since the start, s.
    pub fn sim_s(&self) -> f64 {
        self.sim_s
    }

    /// The next settings write loses power after `ops` flash operations (word programs, page
    /// erases); the board then restarts as after a brown-out and restores what flash holds.
    pub fn cut_next_settings_write(&mut self, ops: usize) {
        self.cut_settings = Some(ops);
    }

    /// Test hook: the records region (`log`: the log region) refuses every program and erase
    /// from now on, as a write-protected region does ([`MockError::WriteProtected`](crate::flash::MockError::WriteProtected));
    /// `false` lifts it.
    pub fn write_protect(&mut self, log: bool, on: bool) {
        match (log, self.store.as_mut(), self.log.as_mut()) {
            (false, Some(store), _) => store.flash_mut().write_protected = on,
            (true, _, Some(l)) => l.flash_mut().write_protected = on,
            _ => {}
        }
    }

    /// Test hook: stores `bytes` under `key` (`hter::persist::flash::key`) in the records region
    /// as another firmware would have written them, unchecked: what a firmware update finds
    /// there at its first boot ([`Self::reset`]).
    pub fn store_raw(&mut self, key: u8, bytes: &[u8]) -> Result<()> {
        let Some(store) = self.store.as_mut() else { bail!("the board has no flash") };
        block_on(store.store(key, bytes)).map_err(|e| anyhow::anyhow!("the flash refused the record: {e:?}"))
    }

    /// Injects a fault into the simulated carrier from the next sample on (`hter virtual-board
    /// --fault`, tests): a brown-out is a power cut between two samples ([`Self::power_cut`]);
    /// a hung control loop is refused (the virtual board answers requests from its step: `hter
    /// sim --fault firmware-hang` simulates it).
    pub fn inject(&mut self, fault: crate::fault::Fault) -> Result<()> {
        use crate::fault::Fault;
        match fault {
            Fault::FirmwareHang => bail!(HANG_REFUSED),
            Fault::Brownout => self.power_cut(),
            Fault::BoardFault(k) => self.fail_safe_stop(crate::fault::stop_info(k)),
            f => self.rig.inject(f),
        }
        Ok(())
    }

    /// Powers the board up from what its flash holds: scrub, restore, a new [`App`].
    fn boot(&mut self, reset: ResetCause, button_held: bool) {
        let (Some(store), Some(log)) = (self.store.as_mut(), self.log.as_mut()) else { return };
        let stops = self.ram.boot(reset);
        self.app = booted(self.adaptive, store, log, reset, button_held, stops);
        self.pending = PendingSaves::EMPTY;
        self.gate = WriteGate::firmware();
        self.t_ms = 0;
    }

    /// A power cut between two samples (no write under way): the board boots again from what
    /// its flash holds, as after a brown-out.
    pub fn power_cut(&mut self) {
        self.power_cycle();
    }

    /// A fail-safe stop between two samples (a panic, a fault, a stalled loop): the stop path's
    /// record in the reset-surviving RAM, the outputs safe, a reset; the board boots again from
    /// what its flash holds and reports the stop (`board_fault_*`, the indicator latched) until
    /// a history that counts it is stored ([`hter::failsafe::ResetRecords`], as the firmware's).
    pub fn fail_safe_stop(&mut self, stop: StopInfo) {
        self.ram.record(&stop);
        self.restarts += 1;
        self.boot(ResetCause::Other, false);
    }

    /// A power cut: both flashes power down and up, the board boots again.
    fn power_cycle(&mut self) {
        if let (Some(store), Some(log)) = (self.store.take(), self.log.take()) {
            let (mut a, mut b) = (store.release(), log.release());
            a.power_on();
            b.power_on();
            self.store = Some(open_store(a));
            self.log = Some(open_log(b));
        }
        self.restarts += 1;
        // RAM does not keep the stop record through a power loss (its magic and CRC reject the
        // noise there).
        self.ram = ResetRecords::EMPTY;
        self.boot(ResetCause::BrownOut, false);
    }

    /// The reset button between two samples (RAM lost, flash and the carrier as they are); with
    /// `button_held`, the acknowledge button held through it: a technician's service reset
    /// ([`hter::app::Boot::service_reset`]).
    pub fn reset(&mut self, button_held: bool) {
        self.restarts += 1;
        self.boot(ResetCause::Other, button_held);
    }

    /// One control sample: the step, the actuator, Ts of plant, then the flash writes the gate
    /// lets through.
    pub fn step(&mut self) -> Option<SampleOut> {
        let ts = f64::from(hter::step::CarrierConfig::DEFAULT.ts_s);
        let input = self.rig.sample_in(self.t_ms)?;
        self.app.note_store_failures(self.failures.in_a_row());
        let out = self.app.sample(&input);
        let d = self.rig.actuate(&out.step, self.sim_s);
        self.rig.advance(self.sim_s, d, ts, &mut self.last_on, true);
        self.gate.note_supply(self.t_ms, true);
        self.flush();
        self.t_ms += (ts * 1000.0) as u64;
        self.sim_s += ts;
        Some(out)
    }

    /// Moves the application's saves to the gate's queue and writes what it lets through.
    fn flush(&mut self) {
        while let Some(save) = self.app.next_save() {
            self.pending.put(save);
        }
        while let Some(save) = self.pending.next(&self.gate, self.t_ms) {
            let (Some(store), Some(log)) = (self.store.as_mut(), self.log.as_mut()) else { return };
            let cut = matches!(save, Save::Settings(_)).then(|| self.cut_settings.take()).flatten();
            if let Some(ops) = cut {
                store.flash_mut().cut_after(ops);
            }
            // The firmware's recovery: a corrupt region erased and the record written again,
            // the records nothing stores on a cadence handed over again.
            let (result, erased) = block_on(flash::write_or_erase(store, log, &save));
            if erased == flash::Erased::Records {
                self.app.records_erased();
            }
            if cut.is_some() {
                if store.flash_mut().is_dead() {
                    self.power_cycle();
                    return;
                }
                // The write completed before the cut: nothing is armed any more.
                store.flash_mut().ops_left = None;
            }
            // A history in flash counts the boot's stops: RAM need not keep them (the firmware's
            // `failsafe::stops_stored`).
            if result.is_ok() && matches!(save, Save::History(_) | Save::AlarmHistory(_)) {
                self.ram.stored();
            }
            self.failures.note(&save, result.is_ok());
            if result.is_err() {
                self.write_errors += 1;
            }
        }
    }

    /// Runs one request line; returns the whole reply (`\r\n` line ends, the final line `ok` or
    /// `err …`), `history` included.
    pub fn request(&mut self, line: &str) -> String {
        let mut out = String::new();
        match self.app.handle(line, &mut out) {
            Handled::Done => {}
            Handled::History { since_s } => {
                // What waits for the gate is written first: the host sees every entry made.
                self.flush();
                out.push_str(CSV_HEADER);
                out.push_str("\r\n");
                let walked = match self.log.as_mut() {
                    Some(log) => block_on(log.for_each(since_s, async |e: &hter::persist::log::LogEntry| {
                        let _ = write_csv_row(e, &mut out);
                        out.push_str("\r\n");
                        true
                    })),
                    None => Ok(0),
                };
                match walked {
                    Ok(_) => out.push_str("ok\r\n"),
                    Err(e) => out.push_str(&format!("err history: the log could not be read ({e:?})\r\n")),
                }
            }
        }
        // An accepted setting is written at once if the gate allows.
        self.flush();
        out
    }
}

/// An [`App`] booted from what the flash holds: scrub, restore, a new application (the
/// firmware's boot sequence).
fn booted(
    adaptive: AdaptiveConfig,
    store: &mut MockStore,
    log: &mut MockLog,
    reset: ResetCause,
    button_held: bool,
    stops: Stops,
) -> App {
    let restored = block_on(flash::restore(store, log, Some(adaptive)));
    App::new(app_config(adaptive), &hter::app::Boot { button_held, ..restored.boot(reset, stops) })
}

fn open_store(flash: MockFlash<PAGE>) -> MockStore {
    let ecc = flash.ecc.clone();
    // The region is the constant above: page-aligned, 4 pages.
    Store::new(flash, ecc, 0..(STORE_PAGES * PAGE) as u32).unwrap_or_else(|_| unreachable!("a valid region"))
}

fn open_log(flash: MockFlash<PAGE>) -> MockLog {
    let ecc = flash.ecc.clone();
    LogStore::new(flash, ecc, 0..(LOG_PAGES * PAGE) as u32).unwrap_or_else(|_| unreachable!("a valid region"))
}
