//! hter firmware: the vaccine carrier controller on a NUCLEO-L476RG.
//!
//! One task per concern, talking through static channels (the tasks share no mutable
//! state; each channel has one writer); `main` only
//! initialises, restores what flash holds and spawns:
//!
//! ```text
//! sample ──(t, counts, supply V)──► control ──(duty, supply, alarm)──► actuate ──► SSR PWM (or buck: TIM1 CH1/CH1N), supply enable, LEDs
//!   every Ts                         Carrier::step, cold-chain Recorder, Annunciator
//!                                     ├──(telemetry record)──► telemetry ──► defmt over RTT
//!                                     └──(model every 4 h of trust, history hourly and at alarms)──► persist ──► flash
//! serial (feature `serial`): USART2 request lines ──► serial::handle ──► reply (its own task; never blocks control)
//! ```
//!
//! `main` starts the watchdog before anything else, then the clocks; a stop recorded by the
//! fault handlers before the last reset (`failsafe`) is logged and reported by the first step.
//! At boot `main` restores the calibration, the cold-chain history and (self-tuning builds) the
//! learned model from flash (`hter::persist`; a missing, torn or implausible record means its
//! default, and the boot log says which), counts the reset in the history, and starts the loop.
//!
//! The control math is the library's [`hter::step::Carrier`], the very object the host
//! simulator and the tests drive, and the record and alarm rules are the library's
//! [`hter::persist::Recorder`] and [`hter::alarm::Annunciator`]: this crate only moves data
//! between peripherals and them.
#![no_std]
#![no_main]

mod board;
// The interface build's App builds its own laws: the fixed-law constructors go unused there.
#[cfg_attr(feature = "interface", allow(dead_code))]
mod config;
mod ecc;
mod failsafe;
mod persist;
#[cfg(feature = "interface")]
mod serial;

use core::sync::atomic::Ordering;

use defmt::{error, info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
#[cfg(feature = "interface")]
use embassy_futures::select::{select, Either};
use embassy_stm32::gpio::{Input, Output};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use hter::alarm::Indication;
use hter::app::Boot;
#[cfg(feature = "interface")]
use hter::app::Handled;
#[cfg(feature = "interface")]
use hter::app::{App, SampleIn};
use hter::control::{Controller, ControllerStatus};
use hter::event::Event;
use hter::hal::apply_duty;
use hter::persist::ResetCause;
use hter::step::Mode;
use hter::units::Duty;

/// One sample of the analog inputs and when it was taken.
#[derive(Clone, Copy)]
struct Sample {
    /// Milliseconds since boot (monotonic, u64: no wrap, full resolution for any mission).
    t_ms: u64,
    /// RTD conversion (ratio to the reference resistor), counts.
    counts: u32,
    /// The reference conversions on both sides of the RTD's, and VDDA, were in their windows.
    reference_ok: bool,
    /// The modules' supply ahead of the switch, the switched rail after it, the rail at the end of
    /// a test pulse, and (`module-sense`) the modules in the conversion window, V: each `None`
    /// if it could not be measured or was not taken.
    board: hter::step::BoardReadings,
    /// VDD above the PVD level: flash may be written.
    supply_ok: bool,
}

/// What the actuator must do.
#[derive(Clone, Copy)]
struct Actuation {
    duty: Duty,
    supply_enable: bool,
    /// The step asks for a supply-switch test pulse with the next sample.
    switch_test: bool,
    alarm: bool,
}

/// One telemetry record per sample.
#[derive(Clone, Copy, defmt::Format)]
struct Telemetry {
    t_ms: u64,
    temp_c: f32,
    setpoint_c: f32,
    duty: f32,
    mode: Mode,
    counts: u32,
    supply_v: Option<f32>,
    switched_v: Option<f32>,
    /// The modules' side of the SSR in the conversion window, V (`None`: not read in it).
    #[cfg(feature = "module-sense")]
    module_v: Option<f32>,
    alarm: Indication,
    /// Estimator state of a self-tuning controller (θ, trace P, prediction error, mode).
    status: Option<ControllerStatus>,
    /// The step's holdover estimate, s (NaN: none); the interface build only (the default build
    /// leaves the estimate out for flash, README "Flash budget").
    #[cfg(feature = "interface")]
    holdover_s: f32,
}

static SAMPLES: Channel<CriticalSectionRawMutex, Sample, 2> = Channel::new();
static ACTUATION: Signal<CriticalSectionRawMutex, Actuation> = Signal::new();
static TELEMETRY: Channel<CriticalSectionRawMutex, Telemetry, 4> = Channel::new();
static EVENTS: Channel<CriticalSectionRawMutex, Event, 16> = Channel::new();
/// The user button was pressed: the alarm has been seen.
static ACKNOWLEDGE: Signal<CriticalSectionRawMutex, ()> = Signal::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // A stack overflow from here on is a HardFault (safe outputs, recorded), not corrupt statics.
    failsafe::arm_stack_guard();
    // Before the clocks and before flash is read: no boot path runs unwatched.
    board::start_watchdog();
    // Why we (re)started; the flags are cleared so the next boot reads its own. The step reports
    // it with the first sample and the history counts it (a brown-out or watchdog bite shows in
    // the log and the cold-chain record as a gap, not as silence).
    let (reset, csr) = {
        let rcc = embassy_stm32::pac::RCC;
        let csr = rcc.csr().read().0;
        rcc.csr().modify(|w| w.set_rmvf(true));
        (ResetCause::from_stm32l4_csr(csr), csr)
    };
    let stops = failsafe::boot_stops(reset);
    // From here to the control loop no stall check watches: a hang is the watchdog's, and the
    // phase left in a reset-surviving word beside the stop record tells the next boot where it was.
    failsafe::note_boot(hter::failsafe::BootPhase::Board);
    let b = board::init();
    // Read before the flash is: the technician holds the button only for a moment past the
    // reset.
    let button_held = board::button_held(&b.button);
    // The stop that ended the previous boot as `board fault:` (what `hter log2csv` reads as the
    // boot's cause). One an earlier boot reported and did not store (a reset in its first
    // minute, a supply under the PVD level), and one before it, are counted again but are not
    // why this boot started: that boot logged them (a second line with the record's format
    // cost ≈ 100 B of flash).
    match &stops.latest {
        Some(f) if stops.fresh => error!("board fault: {}", f),
        Some(_) => warn!("a stop reported before and not yet stored: counted again"),
        None => {}
    }
    if stops.earlier.is_some() {
        warn!("and the stop before it, not yet stored: counted again");
    }
    let power = board::power_check(csr);
    // The write gate's first supply reading: a boot's urgent store (a new fail-safe stop) need
    // not wait for the first sample, which comes with the first step.
    persist::note_supply(power.supply_ok);
    let watchdog = if board::watchdog_is_hardware() { "hardware (option byte)" } else { "software" };
    // One boot line (the reset, the watchdog, the power check, the firmware's settings): each
    // defmt call costs flash, and the 64 KiB builds have none to spare.
    #[cfg(not(feature = "buck"))]
    info!(
        "hter firmware {}: reset cause {}; watchdog {}; brown-out level {} (need {}), VDD above PVD: {}; Ts = {} s, setpoint {} °C, SSR PWM {} Hz ({} ticks)",
        env!("CARGO_PKG_VERSION"),
        reset,
        watchdog,
        power.bor_level,
        config::BOR_LEVEL,
        power.supply_ok,
        config::CARRIER.ts_s,
        config::SETPOINT_C,
        b.ssr.get_frequency().0,
        b.ssr.max_duty_cycle()
    );
    #[cfg(feature = "buck")]
    info!(
        "hter firmware {}: reset cause {}; watchdog {}; brown-out level {} (need {}), VDD above PVD: {}; Ts = {} s, setpoint {} °C, buck PWM {} Hz",
        env!("CARGO_PKG_VERSION"),
        reset,
        watchdog,
        power.bor_level,
        config::BOR_LEVEL,
        power.supply_ok,
        config::CARRIER.ts_s,
        config::SETPOINT_C,
        config::BUCK_PWM_HZ
    );
    // The persist task owns the flash: it restores both regions, then serves the writes.
    failsafe::note_boot(hter::failsafe::BootPhase::Restore);
    spawner.spawn(persist::persist(b.flash).unwrap());
    let restored = persist::BOOTED.receive().await;
    failsafe::note_boot(hter::failsafe::BootPhase::Start);
    let mut boot = restored.boot(reset, stops);
    boot.button_held = button_held;
    if boot.service_reset() {
        warn!("service reset: the SSR's short is forgotten, or the sensor offset if no short was stored");
    }
    if restored.settings.is_err() {
        // No settings stored: this build's calibration constant, if it has one.
        if let Some(cal) = config::CALIBRATION {
            boot.run_calibration_constant(cal);
            // Stored once, for the images after this one built without it.
            if let Some(cal) = restored.calibration_to_store(cal) {
                persist::request(persist::Save::Calibration(cal));
            }
        }
    } else if config::CALIBRATION.is_some() {
        // Settings stored (the interface build): their calibration runs, which `set cal_ice` and
        // `set cal_warm` change; the constant would undo those at every boot.
        warn!("config.rs CALIBRATION not run: the stored settings' calibration runs (set cal_ice / cal_warm)");
    }
    spawner.spawn(sample(b.analog).unwrap());
    // The boot's records go to the control task by reference, from a static: a task's
    // arguments stay in its state for its whole life, and `Boot`, used only before the loop,
    // held ≈ 0.4 KiB of it (`cargo xtask size`: −376 B of static RAM, −28 B of flash).
    let boot: &'static Boot = cortex_m::singleton!(: Boot = boot).unwrap_or_else(|| unreachable!());
    spawner.spawn(control(boot, b.heartbeat).unwrap());
    #[cfg(not(feature = "buck"))]
    let drive = b.ssr;
    #[cfg(feature = "buck")]
    let drive = b.buck;
    spawner.spawn(actuate(drive, b.supply_enable, b.led, b.alarm).unwrap());
    spawner.spawn(acknowledge(b.button).unwrap());
    spawner.spawn(telemetry().unwrap());
    #[cfg(feature = "interface")]
    spawner.spawn(serial::serial(b.serial).unwrap());
}

/// Takes one oversampled conversion of each analog input every Ts, at a fixed phase of the SSR
/// PWM period.
#[embassy_executor::task]
async fn sample(mut analog: board::Analog) {
    let mut ticker = Ticker::every(Duration::from_millis(config::SAMPLE_PERIOD_MS));
    loop {
        let c = analog.sample().await;
        if !c.in_window {
            warn!("sample outside the SSR-quiet window");
        }
        if !c.reference_ok {
            warn!("RTD sample rejected: VDDA {} V or the reference out of its window", c.vdda_v.unwrap_or(f32::NAN));
        }
        let t_ms = Instant::now().as_millis();
        let supply_ok = board::supply_ok();
        SAMPLES
            .send(Sample {
                t_ms,
                counts: c.counts,
                reference_ok: c.reference_ok,
                board: hter::step::BoardReadings {
                    supply_v: c.supply_v,
                    switched_v: c.switched_v,
                    switch_test_v: c.switch_test_v,
                    #[cfg(feature = "module-sense")]
                    module_v: c.module_v,
                },
                supply_ok,
            })
            .await;
        ticker.next().await;
    }
}

/// A cold-chain alarm on the log, with the part of its run before this boot (a run carried
/// through a restart, `Alarm::carried_s`).
fn log_alarm(a: &hter::coldchain::Alarm) {
    error!(
        "ALARM {} t={=u64:ms} (condition since t={=u64:ms}, and {=u32}s before this boot)",
        a.kind.name(),
        a.trigger_ms,
        a.start_ms,
        a.carried_s
    );
}

/// The stored cold-chain record the boot goes on from, in one line: on a board without the
/// interface the boot log is the only place a technician reads what the carrier went through
/// before this boot (the hourly `coldchain` line counts this boot alone).
fn log_stored(h: &hter::persist::HistoryRecord) {
    use hter::coldchain::AlarmKind::{Freeze60min, Heat10h, Ship30c10h, Ship45c1h};
    use hter::failsafe::StopKind::{ControlStall, HardFault, Nmi, Panic, UnexpectedInterrupt};
    use hter::persist::ResetCause::{BrownOut, Other, Watchdog};
    use hter::persist::{alarm_index as a, reset_index as r, stop_index as s};
    // The slots by their kinds, at compile time: an index out of its array fails the build.
    let (alarms, resets, stops) = (&h.alarms, &h.resets, &h.stops);
    info!(
        "stored record: {=u32} s, min={=f32} max={=f32} °C, below2_s={=u32} above8_s={=u32} excursions={=u32}; alarms heat_10h={=u16} freeze_60min={=u16} ship_45c_1h={=u16} ship_30c_10h={=u16}; boots watchdog={=u16} brown-out={=u16} other={=u16}; stops panic={=u16} hard_fault={=u16} nmi={=u16} unexpected_interrupt={=u16} control_stall={=u16}; flash_pages_lost={=u16} latched={=bool}",
        h.recorded_s,
        h.min_c.unwrap_or(f32::NAN),
        h.max_c.unwrap_or(f32::NAN),
        h.below_2_s,
        h.above_8_s,
        h.excursions,
        alarms[const { a(Heat10h) }],
        alarms[const { a(Freeze60min) }],
        alarms[const { a(Ship45c1h) }],
        alarms[const { a(Ship30c10h) }],
        resets[const { r(Watchdog) }],
        resets[const { r(BrownOut) }],
        resets[const { r(Other) }],
        stops[const { s(Panic) }],
        stops[const { s(HardFault) }],
        stops[const { s(Nmi) }],
        stops[const { s(UnexpectedInterrupt) }],
        stops[const { s(ControlStall) }],
        h.flash_pages_lost,
        h.unacknowledged()
    );
}

/// The step, built from the constant profile, so that its derived sample counts fold at compile
/// time; only the calibration (and the self-tuner's start model) come from flash. Out of line:
/// inlined into the control task, its constants were stored field by field into the task's
/// future and copied about there (−256 B of flash; `config::controller` likewise).
#[cfg(not(feature = "interface"))]
#[inline(never)]
fn new_carrier(boot: &Boot) -> hter::step::Carrier<config::Ctl> {
    hter::step::Carrier::new(
        config::VALID_CARRIER.with_calibration(boot.calibration),
        config::controller(boot.adaptive),
    )
}

/// Runs the library's per-sample step on each sample, records it, decides the alarm
/// indicator; after each completed step beats the heartbeat, tells the stall check and feeds
/// the watchdog.
#[cfg(not(feature = "interface"))]
#[embassy_executor::task]
async fn control(boot: &'static Boot, mut heartbeat_pin: Output<'static>) {
    let mut carrier = new_carrier(boot);
    let mut recorder = hter::persist::Recorder::new(boot.history, config::HISTORY_SAVE_SAMPLES);
    // In a block: the boot's history (156 B) is not kept in the task's state through the loop.
    let mut annunciator = {
        // The boot counted, the sensor offset and a shorted SSR resumed.
        let history = boot.resume(&mut carrier, &mut recorder);
        log_stored(&history);
        for _ in 0..boot.pages_lost {
            if EVENTS.try_send(Event { t_ms: 0, kind: hter::event::EventKind::FlashPageLost }).is_err() {
                warn!("event queue full, dropped FlashPageLost");
            }
        }
        // Waits for the write gate: a power-bounce loop does not write at every boot; a new
        // fail-safe stop goes at once (`Boot::history_save`), before the first step can stop
        // again.
        persist::request(boot.history_save(history));
        // A restart does not acknowledge: the latch is in the stored history.
        hter::alarm::Annunciator::restored(&history)
    };
    info!(
        "controller: {}, calibration gain {} offset {} °C",
        carrier.controller().name(),
        carrier.config().cal.gain,
        carrier.config().cal.offset_c
    );
    let mut model_cadence = hter::persist::ModelCadence::new(config::MODEL_SAVE_SAMPLES);
    let mut store_watch = hter::persist::StoreWatch::NEW;
    let mut samples = 0u32;
    failsafe::boot_done();
    board::start_stall_check();
    loop {
        let s = SAMPLES.receive().await;
        // Flash writes wait while VDD is under the PVD level.
        persist::note_supply(s.supply_ok);
        carrier.observe(&s.board);
        let input = hter::step::StepInput { t_ms: s.t_ms, counts: s.counts, setpoint_c: config::SETPOINT_C };
        let out = if s.reference_ok { carrier.step(&input) } else { carrier.step_with_reference_fault(&input) };
        let mut rec = recorder.push(s.t_ms, out.recorded_c());
        if ACKNOWLEDGE.try_take().is_some() {
            info!("alarm acknowledged t={=u64:ms}", s.t_ms);
            annunciator.acknowledge();
        }
        // The flash refusing its writes: on the log as `event t=… StoreFailed` (what `hter
        // log2csv` reads), and the indicator latched.
        if store_watch.observe(persist::failed_in_a_row()) {
            let kind = hter::event::EventKind::StoreFailed;
            annunciator.note(kind);
            if EVENTS.try_send(Event { t_ms: s.t_ms, kind }).is_err() {
                warn!("event queue full, dropped StoreFailed");
            }
        }
        let alarm = annunciator.update(&out, &rec.raised);
        recorder.note_carried(&mut rec, annunciator.latched(), carrier.sensor_offset(), carrier.ssr_shorted());
        ACTUATION.signal(Actuation {
            duty: out.duty,
            supply_enable: out.supply_enable,
            switch_test: out.switch_test,
            alarm: alarm.is_on(),
        });
        for e in out.events.iter() {
            // Never block the loop on logging: a full queue drops the event, and says so.
            if EVENTS.try_send(e).is_err() {
                warn!("event queue full, dropped {}", e);
            }
        }
        if out.events.dropped() > 0 {
            warn!("{} events of this step did not fit the step's list", out.events.dropped());
        }
        for a in rec.raised.iter().flatten() {
            log_alarm(a);
        }
        // The records region erased as corrupt: the history is stored again now, not at the
        // next hourly store (the model follows at its own cadence), and the calibration that
        // runs, which nothing stores again (the next image without a constant reads it).
        if persist::RECORDS_ERASED.swap(false, Ordering::Relaxed) {
            rec.save_due = true;
            persist::request(persist::Save::Calibration(carrier.config().cal));
        }
        // An alarm's history is stored as soon as the supply allows, without the boot's hold-off.
        if let Some(save) = recorder.due_save(&rec) {
            persist::request(save);
        }
        let record = Telemetry {
            t_ms: s.t_ms,
            temp_c: out.temp_c.0,
            setpoint_c: out.setpoint_c.0,
            duty: out.duty.get(),
            mode: out.mode,
            counts: s.counts,
            supply_v: s.board.supply_v,
            switched_v: s.board.switched_v,
            #[cfg(feature = "module-sense")]
            module_v: s.board.module_v,
            alarm,
            status: out.status,
        };
        if TELEMETRY.try_send(record).is_err() {
            warn!("telemetry queue full, dropped t={=u64:ms}", s.t_ms);
        }
        samples = samples.wrapping_add(1);
        if samples.is_multiple_of(config::SUMMARY_SAMPLES) {
            let m = recorder.monitor();
            info!(
                "coldchain t={=u64:ms} mkt={} min={} max={} below2_s={} above8_s={} excursions={}",
                s.t_ms,
                m.mkt_c().unwrap_or(f32::NAN),
                m.min_c().unwrap_or(f32::NAN),
                m.max_c().unwrap_or(f32::NAN),
                m.time_below_2_s(),
                m.time_above_8_s(),
                m.excursion_count()
            );
        }
        if let Some(rec) = model_cadence.push(out.status.map(|st| st.mode), carrier.controller()) {
            persist::request(persist::Save::Model(rec));
        }
        // Healthy = the step completed: the monostable also gates the modules' supply, so a beat
        // that stopped at every alarm would stop cooling at a heat alarm. The alarm pin sounds
        // the buzzer through the OR in the wiring (README) instead.
        board::heartbeat_pulse(&mut heartbeat_pin);
        board::note_step();
        board::pet_watchdog();
    }
}

/// Runs the board application ([`hter::app::App`]: the step, the record and log, the
/// settings) on each sample and each interface request; after each completed step beats the
/// heartbeat, tells the stall check and feeds the watchdog.
#[cfg(feature = "interface")]
#[embassy_executor::task]
async fn control(boot: &'static Boot, mut heartbeat_pin: Output<'static>) {
    let mut app = App::new(config::APP, boot);
    log_stored(&app.recorder().history());
    // The boot's history now, not after the first step: a new fail-safe stop in it is stored at
    // once (`Boot::history_save`), before the first step can stop the board again.
    while let Some(save) = app.next_save() {
        persist::request(save);
    }
    if boot.pages_lost > 0 {
        warn!("{} flash pages were torn by a power cut and repaired", boot.pages_lost);
    }
    info!(
        "controller: {}, calibration gain {} offset {} °C",
        app.carrier().controller().name(),
        app.carrier().config().cal.gain,
        app.carrier().config().cal.offset_c
    );
    let mut samples = 0u32;
    failsafe::boot_done();
    board::start_stall_check();
    loop {
        let s = match select(SAMPLES.receive(), serial::REQUESTS.receive()).await {
            Either::First(s) => s,
            Either::Second(line) => {
                let handled = serial::REPLY.lock(|r| {
                    let mut r = r.borrow_mut();
                    r.clear();
                    app.handle(&line, &mut *r)
                });
                while let Some(save) = app.next_save() {
                    persist::request(save);
                }
                if let Handled::History { since_s } = handled {
                    persist::HISTORY.signal(since_s);
                }
                serial::REPLIED.signal(handled);
                continue;
            }
        };
        // Flash writes wait while VDD is under the PVD level.
        persist::note_supply(s.supply_ok);
        if ACKNOWLEDGE.try_take().is_some() {
            info!("alarm acknowledged t={=u64:ms}", s.t_ms);
            app.acknowledge();
        }
        app.note_store_failures(persist::failed_in_a_row());
        let out =
            app.sample(&SampleIn { t_ms: s.t_ms, counts: s.counts, reference_ok: s.reference_ok, board: s.board });
        let step = &out.step;
        ACTUATION.signal(Actuation {
            duty: step.duty,
            supply_enable: step.supply_enable,
            switch_test: step.switch_test,
            alarm: out.alarm.is_on(),
        });
        for e in step.events.iter() {
            // Never block the loop on logging: a full queue drops the event, and says so.
            if EVENTS.try_send(e).is_err() {
                warn!("event queue full, dropped {}", e);
            }
        }
        if step.events.dropped() > 0 {
            warn!("{} events of this step did not fit the step's list", step.events.dropped());
        }
        for a in out.raised.iter().flatten() {
            log_alarm(a);
        }
        if persist::RECORDS_ERASED.swap(false, Ordering::Relaxed) {
            warn!("flash records region erased: settings and models stored again");
            app.records_erased();
        }
        while let Some(save) = app.next_save() {
            persist::request(save);
        }
        let record = Telemetry {
            t_ms: s.t_ms,
            temp_c: step.temp_c.0,
            setpoint_c: step.setpoint_c.0,
            duty: step.duty.get(),
            mode: step.mode,
            counts: s.counts,
            supply_v: s.board.supply_v,
            switched_v: s.board.switched_v,
            #[cfg(feature = "module-sense")]
            module_v: s.board.module_v,
            alarm: out.alarm,
            status: step.status,
            holdover_s: step.holdover_s.unwrap_or(f32::NAN),
        };
        if TELEMETRY.try_send(record).is_err() {
            warn!("telemetry queue full, dropped t={=u64:ms}", s.t_ms);
        }
        samples = samples.wrapping_add(1);
        if samples.is_multiple_of(config::SUMMARY_SAMPLES) {
            let m = app.recorder().monitor();
            info!(
                "coldchain t={=u64:ms} mkt={} min={} max={} below2_s={} above8_s={} excursions={}",
                s.t_ms,
                m.mkt_c().unwrap_or(f32::NAN),
                m.min_c().unwrap_or(f32::NAN),
                m.max_c().unwrap_or(f32::NAN),
                m.time_below_2_s(),
                m.time_above_8_s(),
                m.excursion_count()
            );
        }
        // Healthy = the step completed: the monostable also gates the modules' supply, so a beat
        // that stopped at every alarm would stop cooling at a heat alarm. The alarm pin sounds
        // the buzzer through the OR in the wiring (README) instead.
        board::heartbeat_pulse(&mut heartbeat_pin);
        board::note_step();
        board::pet_watchdog();
    }
}

/// The modules' drive: the SSR's timer, or the buck's half bridge (TIM1).
#[cfg(not(feature = "buck"))]
type Drive = embassy_stm32::timer::simple_pwm::SimplePwm<'static, embassy_stm32::peripherals::TIM3>;
#[cfg(feature = "buck")]
type Drive = board::Buck;

/// Starts the SSR's channel.
#[cfg(not(feature = "buck"))]
fn start_drive(ssr: &mut Drive) {
    ssr.ch1().enable();
}

/// Nothing to start: the buck's gates follow CCER, which each write sets.
#[cfg(feature = "buck")]
fn start_drive(_: &mut Drive) {}

/// Writes `duty` to the SSR with its falling edge kept out of the RTD sampling window; returns
/// the duty written.
#[cfg(not(feature = "buck"))]
fn write_drive(ssr: &mut Drive, duty: Duty) -> Duty {
    let duty = config::SAMPLE_WINDOW.clear_duty(duty);
    if apply_duty(&mut ssr.ch1(), duty).is_err() {
        warn!("SSR duty write failed");
    }
    duty
}

/// Writes `duty` to the buck as it is: it switches at 40 kHz whatever the duty, and the 2.1 ms
/// oversampled conversion averages 84 of its periods, so there is no window to keep off.
#[cfg(feature = "buck")]
fn write_drive(buck: &mut Drive, duty: Duty) -> Duty {
    if apply_duty(buck, duty).is_err() {
        warn!("buck duty write failed");
    }
    duty
}

/// Applies each actuation to the drive (the SSR or the buck), the supply-enable switch and the
/// indicators.
#[embassy_executor::task]
async fn actuate(
    mut drive: Drive,
    mut supply_enable: Output<'static>,
    mut led: Output<'static>,
    mut alarm: Output<'static>,
) {
    start_drive(&mut drive);
    loop {
        let a = ACTUATION.wait().await;
        // Switch the supply first when cutting, last when enabling: the modules never see a
        // duty the supervisor did not allow.
        if !a.supply_enable {
            supply_enable.set_low();
        }
        let duty = write_drive(&mut drive, a.duty);
        if a.supply_enable {
            supply_enable.set_high();
        }
        // Cleared whenever the switch opens: a pulse under way then leaves it open.
        board::SWITCH_TEST.store(a.switch_test && a.supply_enable, Ordering::Relaxed);
        if a.supply_enable && duty.get() > 0.0 {
            led.set_high();
        } else {
            led.set_low();
        }
        if a.alarm {
            alarm.set_high();
        } else {
            alarm.set_low();
        }
    }
}

/// The user button acknowledges the alarm indicator (debounced by a 50 ms re-check).
#[embassy_executor::task]
async fn acknowledge(button: Input<'static>) {
    loop {
        // Pressed pulls the line low (the Nucleo's B1).
        while button.is_high() {
            embassy_time::Timer::after_millis(20).await;
        }
        embassy_time::Timer::after_millis(50).await;
        if button.is_low() {
            ACKNOWLEDGE.signal(());
            while button.is_low() {
                embassy_time::Timer::after_millis(20).await;
            }
        }
    }
}

/// Streams one record per sample and every event over defmt/RTT.
#[embassy_executor::task]
async fn telemetry() {
    loop {
        let r = TELEMETRY.receive().await;
        // `hter log2csv` parses this line: keep its `key=value` fields.
        #[cfg(feature = "interface")]
        info!(
            "t={=u64:ms} temp={} sp={} duty={} mode={} counts={} supply={} rail={} alarm={} holdover={}",
            r.t_ms,
            r.temp_c,
            r.setpoint_c,
            r.duty,
            r.mode,
            r.counts,
            r.supply_v.unwrap_or(f32::NAN),
            r.switched_v.unwrap_or(f32::NAN),
            r.alarm,
            r.holdover_s
        );
        #[cfg(not(feature = "interface"))]
        info!(
            "t={=u64:ms} temp={} sp={} duty={} mode={} counts={} supply={} rail={} alarm={}",
            r.t_ms,
            r.temp_c,
            r.setpoint_c,
            r.duty,
            r.mode,
            r.counts,
            r.supply_v.unwrap_or(f32::NAN),
            r.switched_v.unwrap_or(f32::NAN),
            r.alarm
        );
        // The module-side sense's reading (NaN: not read in the window), on a line of its own so
        // that `hter log2csv` (which keys on `temp=`) reads logs of either build alike.
        #[cfg(feature = "module-sense")]
        info!("module t={=u64:ms} v={}", r.t_ms, r.module_v.unwrap_or(f32::NAN));
        if let Some(st) = r.status {
            info!(
                "est t={=u64:ms} ctl={} theta={} trace_p={} pe={} reset={}",
                r.t_ms, st.mode, st.theta, st.trace_p, st.prediction_error, st.reset_c
            );
        }
        while let Ok(e) = EVENTS.try_receive() {
            warn!("event t={=u64:ms} {}", e.t_ms, e.kind);
        }
    }
}
