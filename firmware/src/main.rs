//! hter firmware: the vaccine carrier controller on a NUCLEO-L476RG.
//!
//! One task per concern, talking through static channels (STYLE.md, layer 3); `main` only
//! initialises and spawns:
//!
//! ```text
//! sample ──(t, counts)──► control ──(duty, supply)──► actuate ──► SSR PWM, supply enable, LED
//!   every Ts               Carrier::step                    │
//!                           ├──(telemetry record)──► telemetry ──► defmt over RTT
//!                           └──(trusted model, every 4 h of trust)──► persist ──► flash
//! ```
//!
//! With `adaptive`, `main` restores the self-tuner's model from flash before the loop starts
//! (`hter::persist`; a missing, torn or implausible record means the built-in starting model,
//! and the boot log says which) and the `persist` task saves it.
//!
//! The control math is the library's [`hter::step::Carrier`], the very object the host
//! simulator and the tests drive: this crate only moves data between peripherals and it.
#![no_std]
#![no_main]

mod board;
mod config;
#[cfg(feature = "adaptive")]
mod persist;

use defmt::{info, warn};
use embassy_executor::Spawner;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use hter::control::{Controller, ControllerStatus};
use hter::event::Event;
use hter::hal::{apply_duty, RtdSampler};
use hter::persist::ResetCause;
use hter::step::{Carrier, Mode, StepInput};
use hter::units::Duty;
use {defmt_rtt as _, panic_probe as _};

/// One RTD conversion and when it was taken.
#[derive(Clone, Copy)]
struct Sample {
    t_s: f32,
    counts: u32,
}

/// What the actuator must do.
#[derive(Clone, Copy)]
struct Actuation {
    duty: Duty,
    supply_enable: bool,
}

/// One telemetry record per sample.
#[derive(Clone, Copy, defmt::Format)]
struct Telemetry {
    t_s: f32,
    temp_c: f32,
    setpoint_c: f32,
    duty: f32,
    mode: Mode,
    /// Estimator state of a self-tuning controller (θ, trace P, prediction error, mode).
    status: Option<ControllerStatus>,
}

static SAMPLES: Channel<CriticalSectionRawMutex, Sample, 2> = Channel::new();
static ACTUATION: Signal<CriticalSectionRawMutex, Actuation> = Signal::new();
static TELEMETRY: Channel<CriticalSectionRawMutex, Telemetry, 4> = Channel::new();
static EVENTS: Channel<CriticalSectionRawMutex, Event, 16> = Channel::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Why we (re)started, before anything else; the flags are cleared so the next boot
    // reads its own. The step reports it with the first sample (a brown-out or watchdog bite
    // shows in the log and the cold-chain record as a gap, not as silence).
    let reset = {
        let rcc = embassy_stm32::pac::RCC;
        let csr = rcc.csr().read().0;
        rcc.csr().modify(|w| w.set_rmvf(true));
        ResetCause::from_stm32l4_csr(csr)
    };
    let b = board::init();
    info!("reset cause: {}", reset);
    info!(
        "hter firmware {}: Ts = {} s, setpoint {} °C, SSR PWM {} Hz ({} ticks)",
        env!("CARGO_PKG_VERSION"),
        config::CARRIER.ts_s,
        config::SETPOINT_C,
        b.ssr.get_frequency().0,
        b.ssr.max_duty_cycle()
    );
    #[cfg(feature = "adaptive")]
    let seed = {
        let mut store = persist::open(b.flash);
        let cfg = match store.as_mut() {
            Some(store) => persist::restore(store).await,
            None => config::ADAPTIVE,
        };
        if let Some(store) = store {
            spawner.spawn(persist::persist(store).unwrap());
        }
        cfg
    };
    #[cfg(not(feature = "adaptive"))]
    let seed = config::ControllerSeed;
    let mut wdg = IndependentWatchdog::new(b.iwdg, config::WATCHDOG_TIMEOUT_US);
    wdg.unleash();
    spawner.spawn(sample(b.rtd).unwrap());
    spawner.spawn(control(wdg, seed, reset).unwrap());
    spawner.spawn(actuate(b.ssr, b.supply_enable, b.led).unwrap());
    spawner.spawn(telemetry().unwrap());
}

/// Takes one oversampled RTD conversion every Ts.
#[embassy_executor::task]
async fn sample(mut rtd: board::RtdAdc) {
    let mut ticker = Ticker::every(Duration::from_millis(config::SAMPLE_PERIOD_MS));
    let start = Instant::now();
    loop {
        let Ok(counts) = rtd.sample();
        let t_s = (Instant::now() - start).as_millis() as f32 / 1000.0;
        SAMPLES.send(Sample { t_s, counts }).await;
        ticker.next().await;
    }
}

/// Runs the library's per-sample step on each conversion; feeds the watchdog after each one.
#[embassy_executor::task]
async fn control(
    mut wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    seed: config::ControllerSeed,
    reset: ResetCause,
) {
    let mut carrier = Carrier::new(config::CARRIER, config::controller(seed));
    carrier.note_reset(reset);
    info!("controller: {}", carrier.controller().name());
    #[cfg(feature = "adaptive")]
    let mut trusted_samples = 0u32;
    loop {
        let s = SAMPLES.receive().await;
        let out = carrier.step(&StepInput { t_s: s.t_s, counts: s.counts, setpoint_c: config::SETPOINT_C });
        ACTUATION.signal(Actuation { duty: out.duty, supply_enable: out.supply_enable });
        for e in out.events.iter() {
            // Never block the loop on logging: a full queue drops the event, and says so.
            if EVENTS.try_send(*e).is_err() {
                warn!("event queue full, dropped {}", e);
            }
        }
        if out.events.dropped() > 0 {
            warn!("{} events of this step did not fit the step's list", out.events.dropped());
        }
        let record = Telemetry {
            t_s: s.t_s,
            temp_c: out.temp_c.0,
            setpoint_c: out.setpoint_c.0,
            duty: out.duty.get(),
            mode: out.mode,
            status: out.status,
        };
        if TELEMETRY.try_send(record).is_err() {
            warn!("telemetry queue full, dropped t={}", s.t_s);
        }
        #[cfg(feature = "adaptive")]
        if out.status.is_some_and(|st| st.mode == hter::control::AdaptiveMode::Adaptive) {
            trusted_samples += 1;
            if trusted_samples >= config::MODEL_SAVE_SAMPLES {
                trusted_samples = 0;
                persist::request_save(carrier.controller());
            }
        }
        wdg.pet();
    }
}

/// Applies each actuation to the SSR timer and the supply-enable switch.
#[embassy_executor::task]
async fn actuate(
    mut ssr: embassy_stm32::timer::simple_pwm::SimplePwm<'static, embassy_stm32::peripherals::TIM3>,
    mut supply_enable: embassy_stm32::gpio::Output<'static>,
    mut led: embassy_stm32::gpio::Output<'static>,
) {
    ssr.ch1().enable();
    loop {
        let a = ACTUATION.wait().await;
        // Switch the supply first when cutting, last when enabling: the modules never see a
        // duty the supervisor did not allow.
        if !a.supply_enable {
            supply_enable.set_low();
        }
        let mut ch = ssr.ch1();
        if apply_duty(&mut ch, a.duty).is_err() {
            warn!("SSR duty write failed");
        }
        if a.supply_enable {
            supply_enable.set_high();
        }
        if a.supply_enable && a.duty.get() > 0.0 {
            led.set_high();
        } else {
            led.set_low();
        }
    }
}

/// Streams one record per sample and every event over defmt/RTT.
#[embassy_executor::task]
async fn telemetry() {
    loop {
        let r = TELEMETRY.receive().await;
        // `hter log2csv` parses this line: keep its `key=value` fields.
        info!("t={} temp={} sp={} duty={} mode={}", r.t_s, r.temp_c, r.setpoint_c, r.duty, r.mode);
        if let Some(st) = r.status {
            info!(
                "est t={} ctl={} theta={} trace_p={} pe={}",
                r.t_s, st.mode, st.theta, st.trace_p, st.prediction_error
            );
        }
        while let Ok(e) = EVENTS.try_receive() {
            warn!("event t={} {}", e.t_s, e.kind);
        }
    }
}
