//! Events: what the step reports besides the duty — every detection, guard action and mode
//! change, stamped with the sample time. The glue logs them (defmt on the board, JSON/CSV on
//! the host); the cold-chain record is built from them.

/// What happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EventKind {
    /// The RTD reads open circuit (counts at full scale).
    SensorOpen,
    /// The RTD reads short circuit.
    SensorShort,
    /// The RTD reads a temperature outside the plausible range of the carrier.
    SensorOutOfRange,
    /// The RTD conversion has not changed for [`crate::supervisor::sensor::SensorConfig::stuck_s`]
    /// seconds: a real reading always carries some noise (stuck converter, frozen front end).
    SensorStuck,
    /// Readings jumped by more than physics allows several times within an hour (EMI, a loose
    /// contact); each spike is ignored and control continues on the filtered value.
    SensorSpikes,
    /// The load keeps cooling although the SSR has been commanded off for minutes: the SSR is
    /// shorted. Until reset the step limps home: the supply-enable switch does the On-Off
    /// control the SSR no longer can ([`crate::step::Mode::LimpHome`]).
    SsrStuckOn,
    /// The load warms although the SSR has been commanded fully on for minutes, or a warm load
    /// does not cool at all ([`crate::supervisor::ssr::StuckOffConfig::stalled_on_s`]): the SSR
    /// or the modules are open, or the cabinet is open.
    SsrStuckOff,
    /// The reading stepped by more than physics allows in one sample and stayed at the new level
    /// (a drifting reference, a damaged lead, a probe pulled out of the load). A step up of at
    /// most 3 °C is measured and subtracted from then on; a larger one the spike filter takes
    /// for a real jump holds cooling off as a sensor fault for the stuck-converter window
    /// first. This alarm asks for a service check.
    SensorOffset,
    /// The measured supply of the Peltier modules is below its minimum (a failing battery, a
    /// weak car socket or solar panel): cooling power falls with the square of the voltage.
    SupplySag,
    /// The duty needed to hold the setpoint rose sharply within half an hour: a sudden extra
    /// heat load (the lid left open, a warm load put in).
    LidOpen,
    /// The sensor reads plausibly again after a fault.
    SensorRecovered,
    /// The freeze guard cut cooling: the measured load came too close to 0 °C.
    FreezeGuardTripped,
    /// The freeze guard released: the load is warm enough again.
    FreezeGuardReleased,
    /// The requested setpoint was outside 2…8 °C and was clamped.
    SetpointClamped,
    /// The controller asked for a non-finite duty; the step applied the safe state instead.
    ControllerNonFinite,
    /// Self-tuning: the law now runs on the current estimate.
    AdaptiveEngaged,
    /// Self-tuning: the estimate is not trusted; the law runs on the last trusted model (or the
    /// one its last rest confirmed, [`crate::control::adaptive`]).
    AdaptiveFrozen,
    /// Self-tuning: no trusted model or the law failed; the fallback PI drives.
    FallbackEngaged,
    /// The first sample after the MCU restarted, and why it restarted (the glue reads the
    /// reset flags at boot and hands them to [`crate::step::Carrier::note_reset`]). A
    /// brown-out or a watchdog bite means minutes of control and record were lost.
    Restarted(crate::persist::ResetCause),
    /// The previous boot stopped through a fail-safe path (panic, HardFault, NMI, an unexpected
    /// interrupt, a control stall): its outputs went safe, its reason survived the reset in
    /// RAM ([`crate::failsafe::ResetRecords`]), and this boot reports it with its first sample.
    /// A stop the boot before did not get into flash is reported again (by each boot until a
    /// history that counts it is stored), before the newest.
    BoardFault(crate::failsafe::StopKind),
    /// The persistence region could not be read where a power cut interrupted a flash write (an
    /// ECC error on the L4: a torn double-word). The store repaired it at boot — the torn word
    /// cleared, or the page erased when its header or an erase was torn — so only the record
    /// being written then was lost; every other record was kept.
    FlashPageLost,
    /// The switched supply rail (after the supply-enable switch) reads powered although the
    /// switch is commanded open: the switch is shorted and the second cut-off is gone. The SSR
    /// still controls; the alarm asks for service.
    SupplySwitchShorted,
    /// The reference-resistor conversions on either side of the RTD conversion are outside
    /// their window (excitation current or front end broken, VDDA out of range): the RTD
    /// reading is not trusted, a sensor fault.
    ReferenceOutOfRange,
    /// Cold-chain log entries were lost before they reached flash: more than
    /// [`crate::persist::PENDING_LOG`] waited for the write gate (the minute after a boot, or a
    /// bad supply) and the oldest were dropped. Not a step event: the write queue puts it in
    /// the record ([`crate::persist::PendingSaves`]) at the newest lost entry's time, before
    /// the entries it kept, so the record shows where its hole is.
    LogEntriesLost,
    /// A record stored in flash failed this firmware's checks at boot, though its storage CRC
    /// passed: a record an earlier firmware wrote under looser checks (the usual cause, after an
    /// update), or one a newer firmware wrote in a layout this one cannot read (after going
    /// back), or a corruption the CRC missed. The board runs the build's default in its place
    /// (the calibration constant or none, the default settings, the start model, an empty
    /// history) and asks for a person: a calibration or a setpoint set on this carrier is not
    /// the one in force. Reported once per refusal ([`crate::persist::HistoryRecord::refused`]);
    /// the record stays in flash as it is until a new one of its kind replaces it.
    RecordRefused(crate::persist::Record),
    /// The board's flash writes keep failing: [`crate::persist::STORE_FAILURES`] stores in a row
    /// failed (a write-protected or worn region, a flash driver fault), so the cold-chain
    /// record and the settings are not being kept; a restart would lose what RAM holds. Not a
    /// step event: the board application raises it ([`crate::app::App::note_store_failures`])
    /// from the persist task's count, once per run of failures. Asks for a person.
    StoreFailed,
}

impl EventKind {
    /// Every kind, in declaration order (each reset cause and fail-safe stop its own kind).
    pub const ALL: [EventKind; 36] = {
        use crate::failsafe::StopKind;
        use crate::persist::{Record, ResetCause};
        [
            EventKind::SensorOpen,
            EventKind::SensorShort,
            EventKind::SensorOutOfRange,
            EventKind::SensorStuck,
            EventKind::SensorSpikes,
            EventKind::SsrStuckOn,
            EventKind::SsrStuckOff,
            EventKind::SensorOffset,
            EventKind::SupplySag,
            EventKind::LidOpen,
            EventKind::SensorRecovered,
            EventKind::FreezeGuardTripped,
            EventKind::FreezeGuardReleased,
            EventKind::SetpointClamped,
            EventKind::ControllerNonFinite,
            EventKind::AdaptiveEngaged,
            EventKind::AdaptiveFrozen,
            EventKind::FallbackEngaged,
            EventKind::Restarted(ResetCause::Watchdog),
            EventKind::Restarted(ResetCause::BrownOut),
            EventKind::Restarted(ResetCause::Other),
            EventKind::BoardFault(StopKind::Panic),
            EventKind::BoardFault(StopKind::HardFault),
            EventKind::BoardFault(StopKind::Nmi),
            EventKind::BoardFault(StopKind::UnexpectedInterrupt),
            EventKind::BoardFault(StopKind::ControlStall),
            EventKind::FlashPageLost,
            EventKind::SupplySwitchShorted,
            EventKind::ReferenceOutOfRange,
            EventKind::LogEntriesLost,
            EventKind::RecordRefused(Record::Model),
            EventKind::RecordRefused(Record::Calibration),
            EventKind::RecordRefused(Record::History),
            EventKind::RecordRefused(Record::Settings),
            EventKind::RecordRefused(Record::Cabinet),
            EventKind::StoreFailed,
        ]
    };

    /// A detected hardware fault of the carrier (sensor, front end, SSR, supply, supply
    /// switch, lid): the supervisor's detections, each of which asks for a person
    /// ([`crate::alarm::needs_attention`]). Restarts, guard actions, the self-tuner's mode
    /// changes and the board's fail-safe stops are not.
    pub fn is_hardware_fault(self) -> bool {
        matches!(
            self,
            EventKind::SensorOpen
                | EventKind::SensorShort
                | EventKind::SensorOutOfRange
                | EventKind::SensorStuck
                | EventKind::SensorSpikes
                | EventKind::SensorOffset
                | EventKind::SsrStuckOn
                | EventKind::SsrStuckOff
                | EventKind::SupplySag
                | EventKind::LidOpen
                | EventKind::SupplySwitchShorted
                | EventKind::ReferenceOutOfRange
        )
    }

    /// Stable snake_case name, as `hter sim --json`, the CSV traces and the board's log spell it.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::SensorOpen => "sensor_open",
            EventKind::SensorShort => "sensor_short",
            EventKind::SensorOutOfRange => "sensor_out_of_range",
            EventKind::SensorRecovered => "sensor_recovered",
            EventKind::SensorOffset => "sensor_offset",
            EventKind::SupplySag => "supply_sag",
            EventKind::LidOpen => "lid_open",
            EventKind::SensorStuck => "sensor_stuck",
            EventKind::SensorSpikes => "sensor_spikes",
            EventKind::SsrStuckOn => "ssr_stuck_on",
            EventKind::SsrStuckOff => "ssr_stuck_off",
            EventKind::FreezeGuardTripped => "freeze_guard_tripped",
            EventKind::FreezeGuardReleased => "freeze_guard_released",
            EventKind::SetpointClamped => "setpoint_clamped",
            EventKind::ControllerNonFinite => "controller_non_finite",
            EventKind::AdaptiveEngaged => "adaptive_engaged",
            EventKind::AdaptiveFrozen => "adaptive_frozen",
            EventKind::FallbackEngaged => "fallback_engaged",
            EventKind::Restarted(crate::persist::ResetCause::BrownOut) => "restarted_brownout",
            EventKind::Restarted(crate::persist::ResetCause::Watchdog) => "restarted_watchdog",
            EventKind::Restarted(crate::persist::ResetCause::Other) => "restarted",
            EventKind::BoardFault(crate::failsafe::StopKind::Panic) => "board_fault_panic",
            EventKind::BoardFault(crate::failsafe::StopKind::HardFault) => "board_fault_hard_fault",
            EventKind::BoardFault(crate::failsafe::StopKind::Nmi) => "board_fault_nmi",
            EventKind::BoardFault(crate::failsafe::StopKind::UnexpectedInterrupt) => "board_fault_unexpected_interrupt",
            EventKind::BoardFault(crate::failsafe::StopKind::ControlStall) => "board_fault_control_stall",
            EventKind::FlashPageLost => "flash_page_lost",
            EventKind::SupplySwitchShorted => "supply_switch_shorted",
            EventKind::ReferenceOutOfRange => "reference_out_of_range",
            EventKind::LogEntriesLost => "log_entries_lost",
            EventKind::RecordRefused(crate::persist::Record::Model) => "record_refused_model",
            EventKind::RecordRefused(crate::persist::Record::Calibration) => "record_refused_calibration",
            EventKind::RecordRefused(crate::persist::Record::History) => "record_refused_history",
            EventKind::RecordRefused(crate::persist::Record::Settings) => "record_refused_settings",
            EventKind::RecordRefused(crate::persist::Record::Cabinet) => "record_refused_cabinet",
            EventKind::StoreFailed => "store_failed",
        }
    }

    /// A stable number for the kind, for compact logs and checksums (the processor-in-the-loop
    /// runner compares events by it).
    pub fn code(self) -> u32 {
        use crate::persist::ResetCause;
        match self {
            EventKind::SensorOpen => 0,
            EventKind::SensorShort => 1,
            EventKind::SensorOutOfRange => 2,
            EventKind::SensorStuck => 3,
            EventKind::SensorSpikes => 4,
            EventKind::SsrStuckOn => 5,
            EventKind::SsrStuckOff => 6,
            EventKind::SensorOffset => 7,
            EventKind::SupplySag => 8,
            EventKind::LidOpen => 9,
            EventKind::SensorRecovered => 10,
            EventKind::FreezeGuardTripped => 11,
            EventKind::FreezeGuardReleased => 12,
            EventKind::SetpointClamped => 13,
            EventKind::ControllerNonFinite => 14,
            EventKind::AdaptiveEngaged => 15,
            EventKind::AdaptiveFrozen => 16,
            EventKind::FallbackEngaged => 17,
            EventKind::Restarted(ResetCause::Watchdog) => 18,
            EventKind::Restarted(ResetCause::BrownOut) => 19,
            EventKind::Restarted(ResetCause::Other) => 20,
            EventKind::BoardFault(k) => 0x40 + u32::from(k as u8),
            EventKind::FlashPageLost => 21,
            EventKind::SupplySwitchShorted => 22,
            EventKind::ReferenceOutOfRange => 23,
            EventKind::LogEntriesLost => 24,
            EventKind::RecordRefused(r) => 0x50 + u32::from(r as u8),
            EventKind::StoreFailed => 25,
        }
    }
}

/// One timestamped event.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Event {
    /// Sample time, ms (the step's integer clock: exact for the whole mission).
    pub t_ms: u64,
    /// What happened.
    pub kind: EventKind,
}

impl Event {
    /// Sample time, s, for display (f64 holds every millisecond exactly).
    pub fn t_s(&self) -> f64 {
        crate::units::secs_f64(self.t_ms)
    }
}

/// Most events one step can raise; more are counted in [`Events::dropped`] (never silently lost).
pub const MAX_EVENTS_PER_STEP: usize = 8;

/// The events of one step: a fixed-capacity list. They share the step's sample time, which it
/// keeps once: a u64 per event would double the list the step returns every sample (measured:
/// +100 instructions a sample on the Cortex-M4F in copies, `cargo xtask pil`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Events {
    t_ms: u64,
    kinds: [Option<EventKind>; MAX_EVENTS_PER_STEP],
    len: usize,
    dropped: u16,
}

impl Events {
    /// Records an event, or counts it as dropped if the list is full. The list's time becomes
    /// the event's (one list holds one sample's events).
    pub fn push(&mut self, e: Event) {
        match self.kinds.get_mut(self.len) {
            Some(slot) => {
                *slot = Some(e.kind);
                self.t_ms = e.t_ms;
                self.len += 1;
            }
            None => self.dropped = self.dropped.saturating_add(1),
        }
    }

    /// The recorded events, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = Event> + '_ {
        let t_ms = self.t_ms;
        self.kinds.iter().flatten().map(move |&kind| Event { t_ms, kind })
    }

    /// Number of recorded events.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True if nothing happened.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Events that did not fit.
    pub fn dropped(&self) -> u16 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_codes_and_names_are_unique() {
        let all = EventKind::ALL;
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                assert_ne!(a, b);
                assert_ne!(a.code(), b.code(), "{a:?} {b:?}");
                assert_ne!(a.name(), b.name(), "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn every_reset_cause_and_stop_is_listed() {
        for c in [
            crate::persist::ResetCause::Watchdog,
            crate::persist::ResetCause::BrownOut,
            crate::persist::ResetCause::Other,
        ] {
            assert!(EventKind::ALL.contains(&EventKind::Restarted(c)), "{c:?}");
        }
        for k in crate::failsafe::StopKind::ALL {
            assert!(EventKind::ALL.contains(&EventKind::BoardFault(k)), "{k:?}");
        }
        for r in crate::persist::Record::ALL {
            assert!(EventKind::ALL.contains(&EventKind::RecordRefused(r)), "{r:?}");
        }
    }

    #[test]
    fn board_fault_and_refusal_names_follow_their_kinds() {
        for k in crate::failsafe::StopKind::ALL {
            assert_eq!(EventKind::BoardFault(k).name(), format!("board_fault_{}", k.name()));
        }
        for r in crate::persist::Record::ALL {
            assert_eq!(EventKind::RecordRefused(r).name(), format!("record_refused_{}", r.name()));
        }
    }

    #[test]
    fn overflow_is_counted_not_lost_silently() {
        let mut ev = Events::default();
        let kinds = [EventKind::SensorOpen, EventKind::SensorStuck];
        for i in 0..MAX_EVENTS_PER_STEP + 3 {
            ev.push(Event { t_ms: 7_689_600_249, kind: kinds[i % 2] });
        }
        assert_eq!(ev.len(), MAX_EVENTS_PER_STEP);
        assert_eq!(ev.dropped(), 3);
        let got: Vec<Event> = ev.iter().collect();
        let want: Vec<Event> =
            (0..MAX_EVENTS_PER_STEP).map(|i| Event { t_ms: 7_689_600_249, kind: kinds[i % 2] }).collect();
        assert_eq!(got, want);
    }
}
