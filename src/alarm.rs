//! The alarm indicator: what the health worker sees and hears (a buzzer or red lamp on the
//! board's alarm output), decided here so the host tests the same rule the board runs.
//!
//! The indicator is on while
//! - the load is outside +2…+8 °C now (the vaccines are at risk this minute), or
//! - the step is not in control: a sensor fault (cooling is off) or limping home on a shorted
//!   SSR ([`Mode::SensorFault`], [`Mode::LimpHome`]; a shorted SSR for the rest of the boot, as
//!   the supervisor's limp home lasts: while the freeze guard holds the step reports
//!   [`Mode::FreezeGuard`], and an acknowledged indicator went off there), or
//! - something was detected since the last acknowledgement: a cold-chain alarm
//!   (`heat_10h`, `freeze_60min`, …) or a hardware fault event (sensor, SSR, supply, lid,
//!   offset). These latch: a fault that cleared by itself still needs a look, and the one who
//!   carries the box may not have been there when it happened.
//!
//! Acknowledging (the board's user button) clears the latch; what is still true now keeps the
//! indicator on. A watchdog restart latches too (the loop hung), and so does a fail-safe stop
//! of the previous boot ([`EventKind::BoardFault`]: a panic, a fault, or the loop stalled,
//! which the stall check caught before the watchdog would have), a stored record the boot
//! refused ([`EventKind::RecordRefused`]) and a flash that refuses its writes
//! ([`EventKind::StoreFailed`], [`Annunciator::note`]). Power-on and brown-out
//! restarts (the STM32L4 flags both alike), freeze-guard actions, mode changes of the
//! self-tuner and setpoint clamps are not alarms: they are the supervisor doing its job, and
//! they are in the log.
//!
//! [`Mode::SensorFault`]: crate::step::Mode::SensorFault
//! [`Mode::LimpHome`]: crate::step::Mode::LimpHome
//! [`Mode::FreezeGuard`]: crate::step::Mode::FreezeGuard

use crate::coldchain::Raised;
use crate::event::EventKind;
use crate::step::StepOutput;

/// Whether an event asks for a person: a hardware fault ([`EventKind::is_hardware_fault`]), a
/// controller that produced no number, a watchdog restart or a fail-safe stop.
pub fn needs_attention(kind: EventKind) -> bool {
    kind.is_hardware_fault()
        || matches!(
            kind,
            EventKind::ControllerNonFinite
                // A watchdog bite is a hung loop: minutes without control. A brown-out is not
                // here: the L4 flags every power-on as one, and switching the box on is no alarm.
                | EventKind::Restarted(crate::persist::ResetCause::Watchdog)
                // The previous boot stopped on its fail-safe path: a hung loop the stall check
                // caught (the watchdog bite's case, found sooner; its reset is a software one),
                // a panic or a fault. Quiet, a control stall was no alarm where the same hang
                // caught by the watchdog was one.
                | EventKind::BoardFault(_)
                // A stored record refused at boot: the carrier runs a default in its place (a
                // calibration or a setpoint set on it is not the one in force).
                | EventKind::RecordRefused(_)
                // The flash keeps refusing writes: the record is not being kept.
                | EventKind::StoreFailed
        )
}

/// Why the indicator is on (the first reason that holds, in this order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Indication {
    /// Nothing to report.
    Off,
    /// The step is not in control (sensor fault or limp home).
    NotInControl,
    /// The load is outside 2…8 °C now.
    OutOfRange,
    /// A cold-chain alarm or fault was detected and not yet acknowledged.
    Unacknowledged,
}

impl Indication {
    /// Every indication, in declaration order.
    pub const ALL: [Indication; 4] =
        [Indication::Off, Indication::NotInControl, Indication::OutOfRange, Indication::Unacknowledged];

    /// True if the indicator is on.
    pub fn is_on(self) -> bool {
        self != Indication::Off
    }

    /// Stable snake_case name: the `alarm` column of `hter sim --csv` and `hter log2csv` (the
    /// board's telemetry prints the variant name, which `hter log2csv` maps to this).
    pub fn name(self) -> &'static str {
        match self {
            Indication::Off => "off",
            Indication::NotInControl => "not_in_control",
            Indication::OutOfRange => "out_of_range",
            Indication::Unacknowledged => "unacknowledged",
        }
    }
}

/// The indicator's state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Annunciator {
    latched: bool,
    /// The SSR was found shorted ([`EventKind::SsrStuckOn`]): the step limps home until reset,
    /// and its freeze guard's holds report [`crate::step::Mode::FreezeGuard`], not limp home.
    shorted: bool,
}

impl Annunciator {
    /// Nothing latched.
    pub const fn new() -> Self {
        Annunciator { latched: false, shorted: false }
    }

    /// After a restart, as the stored history says: latched
    /// ([`crate::persist::HistoryRecord::unacknowledged`]), so a restart does not acknowledge,
    /// and the SSR shorted ([`crate::persist::HistoryRecord::ssr_shorted`]), which the step
    /// resumes without a new [`EventKind::SsrStuckOn`]. Before, a restart forgot the short here:
    /// acknowledged, the indicator went off through limp home's freeze-guard holds, a carrier
    /// with a known bad relay looking healthy after every power cycle.
    pub fn restored(history: &crate::persist::HistoryRecord) -> Self {
        Annunciator { latched: history.unacknowledged(), shorted: history.ssr_shorted() }
    }

    /// Takes one sample's step output and the cold-chain alarms it raised.
    pub fn update(&mut self, out: &StepOutput, raised: &Raised) -> Indication {
        for e in out.events.iter() {
            self.latched |= needs_attention(e.kind);
            self.shorted |= e.kind == EventKind::SsrStuckOn;
        }
        if raised.iter().any(Option::is_some) {
            self.latched = true;
        }
        let t = out.temp_c.0;
        if out.mode.not_in_control() || self.shorted {
            Indication::NotInControl
        } else if !crate::coldchain::IN_RANGE_C.contains(&t) {
            Indication::OutOfRange
        } else if self.latched {
            Indication::Unacknowledged
        } else {
            Indication::Off
        }
    }

    /// An event from outside the step (the board application's [`EventKind::StoreFailed`]):
    /// latches as the step's own events do when it asks for a person.
    pub fn note(&mut self, kind: EventKind) {
        self.latched |= needs_attention(kind);
    }

    /// Something latched that a person has not acknowledged yet.
    pub fn latched(&self) -> bool {
        self.latched
    }

    /// A person has seen it: clears what latched.
    pub fn acknowledge(&mut self) {
        self.latched = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coldchain::{Alarm, AlarmKind};
    use crate::event::{Event, Events};
    use crate::step::Mode;
    use crate::units::{Celsius, Duty};

    fn out(temp_c: f32, mode: Mode, events: &[EventKind]) -> StepOutput {
        let mut ev = Events::default();
        for k in events {
            ev.push(Event { t_ms: 0, kind: *k });
        }
        StepOutput {
            raw_c: Some(Celsius(temp_c)),
            temp_c: Celsius(temp_c),
            setpoint_c: Celsius(4.0),
            requested: 0.5,
            duty: Duty::saturating(0.5),
            supply_enable: true,
            switch_test: false,
            mode,
            events: ev,
            status: None,
            holdover_s: None,
        }
    }

    #[test]
    fn faults_latch_until_acknowledged_and_present_danger_stays() {
        let mut a = Annunciator::new();
        let none: Raised = [None; 4];
        assert_eq!(a.update(&out(4.0, Mode::Normal, &[]), &none), Indication::Off);
        // Supervisor actions alone are not alarms.
        let quiet = [EventKind::FreezeGuardTripped, EventKind::AdaptiveEngaged, EventKind::SetpointClamped];
        assert_eq!(a.update(&out(4.0, Mode::FreezeGuard, &quiet), &none), Indication::Off);
        // A sensor fault: on while it lasts, latched after it cleared.
        assert_eq!(a.update(&out(4.0, Mode::SensorFault, &[EventKind::SensorOpen]), &none), Indication::NotInControl);
        assert_eq!(a.update(&out(4.0, Mode::Normal, &[EventKind::SensorRecovered]), &none), Indication::Unacknowledged);
        a.acknowledge();
        assert_eq!(a.update(&out(4.0, Mode::Normal, &[]), &none), Indication::Off);
        // Out of range shows while it lasts, acknowledged or not.
        assert_eq!(a.update(&out(8.3, Mode::Normal, &[]), &none), Indication::OutOfRange);
        a.acknowledge();
        assert_eq!(a.update(&out(8.3, Mode::Normal, &[]), &none), Indication::OutOfRange);
        assert_eq!(a.update(&out(7.9, Mode::Normal, &[]), &none), Indication::Off);
        // A cold-chain alarm latches.
        let raised: Raised = [
            Some(Alarm { kind: AlarmKind::Heat10h, start_ms: 0, trigger_ms: 36_000_000, carried_s: 0 }),
            None,
            None,
            None,
        ];
        assert_eq!(a.update(&out(7.9, Mode::Normal, &[]), &raised), Indication::Unacknowledged);
        assert!(a.update(&out(5.0, Mode::Normal, &[]), &none).is_on());
        // A shorted SSR: limp home is not in control, even acknowledged.
        a.acknowledge();
        assert_eq!(a.update(&out(5.0, Mode::LimpHome, &[EventKind::SsrStuckOn]), &none), Indication::NotInControl);
        a.acknowledge();
        assert_eq!(a.update(&out(5.0, Mode::LimpHome, &[]), &none), Indication::NotInControl);
    }

    #[test]
    fn exactly_the_faults_a_watchdog_bite_a_fail_safe_stop_a_refused_record_and_a_failing_flash_ask_for_attention() {
        use crate::failsafe::StopKind;
        use crate::persist::{Record, ResetCause};
        use EventKind::*;
        let attention = [
            SensorOpen,
            SensorShort,
            SensorOutOfRange,
            SensorStuck,
            SensorSpikes,
            SensorOffset,
            ReferenceOutOfRange,
            SsrStuckOn,
            SsrStuckOff,
            SupplySag,
            SupplySwitchShorted,
            LidOpen,
            ControllerNonFinite,
            Restarted(ResetCause::Watchdog),
            BoardFault(StopKind::Panic),
            BoardFault(StopKind::HardFault),
            BoardFault(StopKind::Nmi),
            BoardFault(StopKind::UnexpectedInterrupt),
            BoardFault(StopKind::ControlStall),
            RecordRefused(Record::Model),
            RecordRefused(Record::Calibration),
            RecordRefused(Record::History),
            RecordRefused(Record::Settings),
            RecordRefused(Record::Cabinet),
            StoreFailed,
        ];
        for k in EventKind::ALL {
            assert_eq!(needs_attention(k), attention.contains(&k), "{k:?}");
        }
    }

    /// A short the stored history carries is the indicator's too after a restart: the step
    /// resumes limp home without a new `ssr_stuck_on`, and its freeze guard's holds report
    /// `freeze_guard`; acknowledged, the indicator stays `not_in_control` through them.
    #[test]
    fn a_short_carried_through_a_restart_stays_not_in_control() {
        let none: Raised = [None; 4];
        let stored = crate::persist::HistoryRecord::EMPTY.with_carried(false, true);
        let mut a = Annunciator::restored(&stored);
        assert_eq!(a.update(&out(2.6, Mode::FreezeGuard, &[]), &none), Indication::NotInControl);
        a.acknowledge();
        assert_eq!(a.update(&out(2.6, Mode::FreezeGuard, &[]), &none), Indication::NotInControl);
        // Unshorted and latched: latched, off once acknowledged.
        let mut b = Annunciator::restored(&crate::persist::HistoryRecord::EMPTY.with_carried(true, false));
        assert!(b.latched());
        b.acknowledge();
        assert_eq!(b.update(&out(2.6, Mode::FreezeGuard, &[]), &none), Indication::Off);
    }

    /// Limp home lasts until reset, but while its freeze guard holds cooling off the step
    /// reports `freeze_guard` (`hter sim --fault ssr-stuck-on@1000`: limp_home and freeze_guard
    /// alternate every few minutes): acknowledged, the indicator went off there with the SSR
    /// still shorted.
    #[test]
    fn a_shorted_ssr_stays_not_in_control_through_the_freeze_guards_holds() {
        let mut a = Annunciator::new();
        let none: Raised = [None; 4];
        // Found shorted on the sample the guard trips (path 1): the step reports freeze_guard.
        let found = [EventKind::FreezeGuardTripped, EventKind::SsrStuckOn];
        assert_eq!(a.update(&out(2.6, Mode::FreezeGuard, &found), &none), Indication::NotInControl);
        a.acknowledge();
        assert_eq!(a.update(&out(2.6, Mode::FreezeGuard, &[]), &none), Indication::NotInControl);
        assert_eq!(
            a.update(&out(3.0, Mode::LimpHome, &[EventKind::FreezeGuardReleased]), &none),
            Indication::NotInControl
        );
        a.acknowledge();
        assert_eq!(
            a.update(&out(2.7, Mode::FreezeGuard, &[EventKind::FreezeGuardTripped]), &none),
            Indication::NotInControl
        );
        assert_eq!(a.update(&out(3.1, Mode::LimpHome, &[]), &none), Indication::NotInControl);
        // A freeze guard's hold without a short is the supervisor doing its job.
        let mut b = Annunciator::new();
        assert_eq!(b.update(&out(2.6, Mode::FreezeGuard, &[EventKind::FreezeGuardTripped]), &none), Indication::Off);
    }

    /// A control stall is the hung loop a watchdog bite is, caught sooner by the stall check
    /// and followed by a software reset: the first sample of the next boot reports it, and the
    /// indicator latches as it does for the bite (it stayed off).
    #[test]
    fn a_fail_safe_stop_of_the_previous_boot_latches() {
        use crate::failsafe::StopKind;
        use crate::persist::ResetCause;
        let none: Raised = [None; 4];
        for kind in StopKind::ALL {
            let mut a = Annunciator::new();
            let first = [EventKind::Restarted(ResetCause::Other), EventKind::BoardFault(kind)];
            assert_eq!(a.update(&out(4.0, Mode::Normal, &first), &none), Indication::Unacknowledged, "{kind:?}");
            assert_eq!(a.update(&out(4.0, Mode::Normal, &[]), &none), Indication::Unacknowledged, "{kind:?}");
            a.acknowledge();
            assert_eq!(a.update(&out(4.0, Mode::Normal, &[]), &none), Indication::Off, "{kind:?}");
        }
    }

    #[test]
    fn indication_names_are_unique() {
        for (i, a) in Indication::ALL.iter().enumerate() {
            assert!(Indication::ALL[i + 1..].iter().all(|b| a.name() != b.name()), "{a:?}");
        }
    }
}
