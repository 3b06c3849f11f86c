//! The faults `hter sim --fault KIND@T_S` injects, and in one table ([`Fault::spec`]) what
//! each one is: its CLI name, whether it is a fault of the carrier's hardware, of the board
//! around the step or a nuisance the step must ride through, and which reports count as its
//! detection. The mission generator, the mission verdict, the campaign's figures and the
//! simulator's `faults_detected` list all read this table.

use anyhow::{anyhow, bail, Result};
use hter::event::EventKind;
use hter::failsafe::{StopInfo, StopKind};
use hter::persist::ResetCause;

use crate::metrics::Detected;

/// A fault the simulator can inject.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// RTD lead broken.
    SensorOpen,
    /// RTD leads shorted.
    SensorShort,
    /// Converter repeats its last value.
    SensorStuck,
    /// Occasional large spikes.
    SensorSpikes,
    /// +1.5 °C calibration drift.
    SensorOffset,
    /// SSR output shorted.
    SsrStuckOn,
    /// SSR output open.
    SsrStuckOff,
    /// Supply drops from 12 to 9 V.
    SupplySag,
    /// Lid left open: 15 W extra heat.
    LidOpen,
    /// The MCU resets: all controller state is lost and the step restarts from what flash
    /// holds (the model last stored; the cold-chain record as the history last stored left it).
    Brownout,
    /// The supply-enable switch shorts: it conducts whatever it is told.
    SupplySwitchShort,
    /// The control loop hangs: the step is no longer called, the SSR timer keeps its last duty,
    /// the MCU's pins hold their levels; only the board's heartbeat monostable can stop cooling.
    FirmwareHang,
    /// The board's own fail-safe stops (`board-fault-panic`, `-hard-fault`, `-nmi`,
    /// `-unexpected-interrupt`, `-control-stall`): the stop path makes the outputs safe, records
    /// the stop in the RAM a reset keeps ([`hter::failsafe::ResetRecords`]) and resets the MCU;
    /// the next boot restarts the step from what flash holds, as after a brown-out, and reports
    /// the stop (`board_fault_*`, the alarm indicator latched, the stop counted in the stored
    /// history). A control stall first hangs the loop, as `firmware-hang` does, until the glue's
    /// stall check stops it [`hter::failsafe::STALL_SAMPLES`] sample periods after the last
    /// completed step: the loop misses one sample, and the heartbeat's monostable lapses first.
    BoardFault(StopKind),
}

/// Where a fault is, which decides how a randomized mission draws it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultClass {
    /// A fault of the carrier's hardware (sensor, SSR, supply, lid) or of the MCU's supply (a
    /// brown-out): a mission carries one with probability 0.2.
    Hardware,
    /// A fault of the board around the step (the supply switch, a hung control loop, the
    /// board's own fail-safe stops): drawn
    /// only in missions without a hardware fault, from a stream of its own.
    Board,
    /// A nuisance the step must ride through (spikes): reported, never judged as a fault.
    Nuisance,
}

/// One row of the fault table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FaultSpec {
    /// The `--fault` name (kebab-case).
    pub name: &'static str,
    /// Where the fault is.
    pub class: FaultClass,
    /// The `faults_detected` reports that count as its detection, the first the most specific.
    pub detected_by: &'static [Detected],
}

impl Fault {
    /// Every fault, in the order of `--fault`'s help and of the mission draws.
    pub const ALL: [Fault; 17] = [
        Fault::SensorOpen,
        Fault::SensorShort,
        Fault::SensorStuck,
        Fault::SensorSpikes,
        Fault::SensorOffset,
        Fault::SsrStuckOn,
        Fault::SsrStuckOff,
        Fault::SupplySag,
        Fault::LidOpen,
        Fault::Brownout,
        Fault::SupplySwitchShort,
        Fault::FirmwareHang,
        Fault::BoardFault(StopKind::Panic),
        Fault::BoardFault(StopKind::HardFault),
        Fault::BoardFault(StopKind::Nmi),
        Fault::BoardFault(StopKind::UnexpectedInterrupt),
        Fault::BoardFault(StopKind::ControlStall),
    ];

    /// The fault table.
    ///
    /// The detections: an open or shorted RTD may read as implausible before it reads as
    /// open or short (`sensor_out_of_range`); an open lid on a loop already at full duty shows
    /// as the load warming at full duty (`ssr_stuck_off`), and under the relay On-Off
    /// controller the lid check stays silent (its limit cycle hides the jump of the holding
    /// duty the check looks for); a brown-out is the reset flags the firmware reads at boot
    /// (`restarted_brownout`, handed to the step by `Carrier::note_reset`, as the simulator
    /// does when it restarts the step); a hang is the board's heartbeat monostable expiring,
    /// not the step; a fail-safe stop is the next boot's report of it (`board_fault_*`), and a
    /// control stall sounds the monostable first (its 15 s lapse before the stall check's two
    /// sample periods).
    pub const fn spec(self) -> FaultSpec {
        use Detected::Event;
        use EventKind as E;
        use FaultClass::{Board, Hardware, Nuisance};
        let (name, class, detected_by): (&str, FaultClass, &[Detected]) = match self {
            Fault::SensorOpen => ("sensor-open", Hardware, &[Event(E::SensorOpen), Event(E::SensorOutOfRange)]),
            Fault::SensorShort => ("sensor-short", Hardware, &[Event(E::SensorShort), Event(E::SensorOutOfRange)]),
            Fault::SensorStuck => ("sensor-stuck", Hardware, &[Event(E::SensorStuck)]),
            Fault::SensorSpikes => ("sensor-spikes", Nuisance, &[Event(E::SensorSpikes)]),
            Fault::SensorOffset => ("sensor-offset", Hardware, &[Event(E::SensorOffset)]),
            Fault::SsrStuckOn => ("ssr-stuck-on", Hardware, &[Event(E::SsrStuckOn)]),
            Fault::SsrStuckOff => ("ssr-stuck-off", Hardware, &[Event(E::SsrStuckOff)]),
            Fault::SupplySag => ("supply-sag", Hardware, &[Event(E::SupplySag)]),
            Fault::LidOpen => ("lid-open", Hardware, &[Event(E::LidOpen), Event(E::SsrStuckOff)]),
            Fault::Brownout => ("brownout", Hardware, &[Event(E::Restarted(ResetCause::BrownOut))]),
            Fault::SupplySwitchShort => ("supply-switch-short", Board, &[Event(E::SupplySwitchShorted)]),
            Fault::FirmwareHang => ("firmware-hang", Board, &[Detected::FirmwareHang]),
            Fault::BoardFault(k) => match k {
                StopKind::Panic => ("board-fault-panic", Board, &[Event(E::BoardFault(StopKind::Panic))]),
                StopKind::HardFault => ("board-fault-hard-fault", Board, &[Event(E::BoardFault(StopKind::HardFault))]),
                StopKind::Nmi => ("board-fault-nmi", Board, &[Event(E::BoardFault(StopKind::Nmi))]),
                StopKind::UnexpectedInterrupt => {
                    ("board-fault-unexpected-interrupt", Board, &[Event(E::BoardFault(StopKind::UnexpectedInterrupt))])
                }
                StopKind::ControlStall => (
                    "board-fault-control-stall",
                    Board,
                    &[Event(E::BoardFault(StopKind::ControlStall)), Detected::FirmwareHang],
                ),
            },
        };
        FaultSpec { name, class, detected_by }
    }

    /// The `--fault` name.
    pub const fn name(self) -> &'static str {
        self.spec().name
    }

    /// Whether the board restarts through this fault and carries on as before it: a brown-out
    /// and the fail-safe stops, whose boot restarts the step from flash with every part of the
    /// carrier still working. A mission goes on being judged after one ([`crate::mission`]).
    pub const fn restarts(self) -> bool {
        matches!(self, Fault::Brownout | Fault::BoardFault(_))
    }

    /// Whether `report` counts as this fault's detection.
    pub fn detected_by(self, report: Detected) -> bool {
        self.spec().detected_by.contains(&report)
    }

    /// The faults of one class, in [`Fault::ALL`]'s order.
    pub fn of_class(class: FaultClass) -> Vec<Fault> {
        Fault::ALL.into_iter().filter(|f| f.spec().class == class).collect()
    }

    /// Parses `KIND@T_S`.
    pub fn parse(s: &str) -> Result<(f64, Fault)> {
        let (kind, t) =
            s.split_once('@').ok_or_else(|| anyhow!("fault '{s}' must be KIND@T_S, e.g. sensor-open@1800"))?;
        let fault = Self::ALL.into_iter().find(|f| f.name() == kind).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|f| f.name()).collect();
            anyhow!("unknown fault '{kind}' (expected one of {})", names.join(", "))
        })?;
        let t: f64 = t.parse().map_err(|_| anyhow!("fault '{s}': time '{t}' is not a number"))?;
        if !(t.is_finite() && t >= 0.0) {
            bail!("fault '{s}': time must be a finite number of seconds ≥ 0");
        }
        Ok((t, fault))
    }
}

/// What the stop path of an injected board fault records ([`Fault::BoardFault`]; the virtual
/// board's and the simulator's): a panic at a made-up place in the glue, a control stall of
/// [`hter::failsafe::STALL_SAMPLES`] sample periods (its `detail`, ms: never 0, which is a
/// boot's stall), the other kinds with no address or status word.
pub fn stop_info(kind: StopKind) -> StopInfo {
    match kind {
        StopKind::Panic => hter::failsafe::panic_info("simulated-board", 1),
        StopKind::ControlStall => {
            let ts_ms = hter::step::CarrierConfig::DEFAULT.ts_s as u32 * 1000;
            StopInfo::new(kind, 0, 0, hter::failsafe::STALL_SAMPLES * ts_ms)
        }
        k => StopInfo::new(k, 0, 0, 0),
    }
}

impl serde::Serialize for Fault {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// Whether the simulator lists an event of the step in `faults_detected`: a hardware fault
/// (the library's classification) or the detection of an injectable fault (a brown-out's
/// restart).
pub fn is_reported(kind: EventKind) -> bool {
    kind.is_hardware_fault() || Fault::ALL.into_iter().any(|f| f.detected_by(Detected::Event(kind)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_parse_back() {
        for (i, f) in Fault::ALL.iter().enumerate() {
            assert!(Fault::ALL[i + 1..].iter().all(|g| g != f && g.name() != f.name()), "{f:?}");
            assert_eq!(Fault::parse(&format!("{}@5", f.name())).unwrap(), (5.0, *f));
        }
    }

    #[test]
    fn each_board_fault_is_named_after_its_stop_kind_and_detected_by_its_report() {
        for k in StopKind::ALL {
            let f = Fault::BoardFault(k);
            assert!(Fault::ALL.contains(&f), "{k:?}");
            assert_eq!(f.name(), format!("board-fault-{}", k.name().replace('_', "-")));
            assert_eq!(f.spec().class, FaultClass::Board);
            assert_eq!(f.spec().detected_by[0], Detected::Event(EventKind::BoardFault(k)));
            assert_eq!(stop_info(k).kind, k);
        }
        // A stall's record is the glue's, not a boot's (`detail` 0 would read as one).
        assert_eq!(stop_info(StopKind::ControlStall).detail, 20_000);
        assert!(Fault::parse("board-fault-reboot@5").unwrap_err().to_string().contains("board-fault-control-stall"));
    }

    #[test]
    fn every_detection_is_reported() {
        for f in Fault::ALL {
            assert!(!f.spec().detected_by.is_empty(), "{f:?} has no detection");
            for d in f.spec().detected_by {
                if let Detected::Event(k) = d {
                    assert!(is_reported(*k), "{f:?}: {k:?} would never reach faults_detected");
                }
            }
        }
        // Supervisor actions and the self-tuner's mode changes are not fault reports.
        for k in [EventKind::FreezeGuardTripped, EventKind::SetpointClamped, EventKind::AdaptiveFrozen] {
            assert!(!is_reported(k), "{k:?}");
        }
    }
}
