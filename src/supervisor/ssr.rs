//! SSR monitor: is the solid-state relay doing what it is told?
//!
//! - **Stuck on** (shorted: the modules cool whatever the duty). Three paths, because a shorted
//!   SSR shows itself differently on light and heavy carriers and in hot and cold ambients:
//!   1. *on an unrequested trip* (`SsrMonitor::freeze_tripped`): the freeze guard trips with
//!      no cooling asked for a minute, and the load either falls fast without slowing down or
//!      trips for the second time within half an hour. A light carrier pulled down from a cool
//!      ambient coasts fast after cooling stops, seen through the ≈ 50 s sensor lag, but its
//!      fall slows down; a very light one fed by a shorted SSR falls faster every sample. In a
//!      hot ambient a shorted SSR only holds the load near its full-cooling floor (≈ 1.5 °C),
//!      and the guard trips, opens the supply, releases and trips again every ≈ 15 min; a cold
//!      ambient pulls the load down once and needs hours to warm it past the release and back.
//!   2. *between trips* (`SsrMonitor::between_trips`): within half an hour of a trip,
//!      nothing asked for a minute, yet falling more than 0.6 °C a minute and faster every
//!      sample: a very light carrier on a shorted SSR after the guard has released, before the
//!      next trip comes too late. Not outside that window: the coast after a pull-down does the
//!      same for a minute or two on light carriers.
//!   3. *after the off-run* (`SsrMonitor::still_falling`): the duty was 0 for four minutes
//!      and the load still falls (0.3 °C in two minutes), and not slower than the two minutes
//!      before — the coast after full cooling stops decelerates, a shorted SSR does not.
//!
//!   And the **supply probe** (`SsrMonitor::probe`) for the case none of them sees: a
//!   shorted SSR that holds the load below its setpoint at a cooling floor above the freeze
//!   guard (a hot day: full cooling barely wins) never trips the guard. Nothing asked for
//!   10 min, 1 °C below the setpoint and still falling: the supply switch opens for 5 min
//!   (harmless, no cooling is wanted). A shorted SSR stops cooling and the load turns up; a load
//!   falling toward a cold ambient does not notice. A request for cooling ends the probe early
//!   only once the load is back at the setpoint: below it, the law asking is its answer to the
//!   turn-up the probe waits for, and it came before the verdict (missions 24204 and 72870,
//!   [`ProbeConfig::yield_within_c`]). One probe an hour at most. A turn-up is a
//!   short only when it comes again: the first closes the supply and lets a confirming probe
//!   start 5 min later, once the load has fallen again with nothing asked; a turn-up at that
//!   probe or the next is the verdict. A lid opened during a probe warms a light load as fast
//!   as a short does, but not on cue twice.
//! - **Stuck off** (`SsrMonitor::warms_at_full_duty`): full duty for 5 min and the load
//!   warmed (fast), or for 15 min and it is warmer than when full duty began and still rising
//!   (slow, a cool day), or for 10 min and a load warmer than any healthy carrier's
//!   full-cooling floor has not fallen (stalled: an SSR dead before the pull-down began leaves
//!   the load at the ambient, where it neither warms nor falls).
//! - **Limp home** ([`LimpConfig`]): after a shorted SSR, On-Off through the supply switch.
//!
//! The checks read `off_run`/`on_run`/`req_off_run`, the runs of the applied duty at 0 and at
//! full duty and of the requested duty at no cooling (at most a tenth of full,
//! [`StuckOnConfig::unrequested_duty`]: not exactly zero, which a law backing off gradually may
//! reach a sample late) up to the *previous* sample (`SsrMonitor::applied` counts this one
//! last), and a ring of the filtered temperature.

use super::{ms, samples_u16, since};
use crate::units::Duty;

/// Settings of the SSR monitor.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SsrConfig {
    /// An applied duty at or above this is full cooling, duty (the runs of the stuck-off check,
    /// and of the lid check's "overwhelmed").
    pub full_duty: f32,
    /// The stuck-on check.
    pub stuck_on: StuckOnConfig,
    /// The stuck-off check.
    pub stuck_off: StuckOffConfig,
    /// The supply probe.
    pub probe: ProbeConfig,
    /// Limp home after a shorted SSR.
    pub limp: LimpConfig,
}

impl SsrConfig {
    /// The reference board's settings.
    pub const DEFAULT: SsrConfig = SsrConfig {
        full_duty: 0.9,
        stuck_on: StuckOnConfig::DEFAULT,
        stuck_off: StuckOffConfig::DEFAULT,
        probe: ProbeConfig::DEFAULT,
        limp: LimpConfig::DEFAULT,
    };
}

/// Settings of the stuck-on (shorted SSR) check.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StuckOnConfig {
    /// Paths 1 and 2: no cooling requested ([`Self::unrequested_duty`]) for this long before the
    /// sample, s (a minute).
    pub unrequested_s: f32,
    /// A requested duty at or below this is no cooling requested, for every run of it the
    /// checks count (paths 1 and 2, the supply probe) (0.1: a tenth of full cooling). The runs
    /// are there to keep out the coast after cooling the law asked for, and a sample at this
    /// duty leaves a tenth of the cold a full-duty one does: the run is still at least the
    /// minute after the last sample that really cooled, as after a cut straight to zero. Not
    /// zero: a law that backs off gradually can ask a few hundredths for one last sample while a
    /// shorted SSR takes a light load down; with GPC's λ 3 at rest, 0.07 at that sample moved
    /// campaign mission 9515's trip inside the minute, and the short was found at the second
    /// trip, 180 s later with the load at 1.08 °C instead of 1.63 (`--seed 1`).
    pub unrequested_duty: f32,
    /// Path 1: a second unrequested trip within this time of the first is a short; path 2 only
    /// looks this long after a trip, s (half an hour: a hot ambient on a shorted SSR trips
    /// every ≈ 15 min; 45 min on the buck, [`Self::BUCK`]).
    pub trip_window_s: f32,
    /// Paths 1 and 2: the freeze guard's smoothed slope below this is falling fast, °C/s
    /// (−0.18 °C/min).
    pub falling_c_per_s: f32,
    /// Path 2: a fall over one sample larger than this, °C (0.1 °C in 10 s = 0.6 °C/min).
    pub between_trips_drop_c: f32,
    /// Path 3: the duty was 0 for this long, s (4 min: the coast after full cooling stops has
    /// slowed down by then, and both windows lie inside the off-run)…
    pub off_s: f32,
    /// …and the load fell by more than [`Self::drop_c`] over the last window of this length, s
    /// (two minutes: over one minute the filtered reading's ≈ 0.007 °C jitter at each end made
    /// a coast slowing at a ratio of 0.82 read as 0.95 or more, a false short in 2 of 10 000
    /// missions, `hter campaign --missions 10000 --seed 1`, missions 3101 and 8885)…
    pub window_s: f32,
    /// …°C…
    pub drop_c: f32,
    /// …at least this fraction as fast as over the window before: not slowing down (the coast
    /// after full cooling stops decelerates; a shorted SSR keeps cooling at full rate).
    pub keep_pace: f32,
}

impl StuckOnConfig {
    /// The reference board's settings.
    pub const DEFAULT: StuckOnConfig = StuckOnConfig {
        unrequested_s: 60.0,
        unrequested_duty: 0.1,
        trip_window_s: 1800.0,
        falling_c_per_s: -0.003,
        between_trips_drop_c: 0.1,
        off_s: 240.0,
        window_s: 120.0,
        drop_c: 0.3,
        keep_pace: 0.95,
    };

    /// The buck drive's (the firmware's `buck` build, `hter sim --drive buck`): path 1's window
    /// 45 min. A shorted buck's trips in a 29 °C room came 30.2–31.8 min apart (the guard's hold,
    /// then the fall at full cooling), just past half an hour, and the load was held at
    /// 1.5–3 °C by the guard alone for 5.7 h without a report (campaign mission 83165,
    /// `hter campaign --missions 10000 --seed 80001 --drive buck`). With 45 min the five buck
    /// sets of seeds 1 … 80 001 find every short and no false one more (README, "On the buck
    /// drive").
    #[cfg(feature = "buck-drive")]
    pub const BUCK: StuckOnConfig = StuckOnConfig { trip_window_s: 2700.0, ..Self::DEFAULT };
}

/// Settings of the stuck-off (open SSR or modules) check.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StuckOffConfig {
    /// Fast warming: full duty for this long, s (5 min: longer than the warming the sensor lag
    /// shows right after cooling starts)…
    pub on_s: f32,
    /// …and the load rose by more than this over that time, °C.
    pub rise_c: f32,
    /// Slow warming (a cool day, when a dead SSR lets the load rise only ≈ 0.3 °C in 5 min):
    /// full duty for this long, s (15 min, three times the longest lag between cooling starting
    /// and the load turning down)…
    pub slow_on_s: f32,
    /// …the load higher than when full duty began by more than this, °C, and still rising over
    /// the last [`Self::on_s`]. A working SSR has turned the load around long before.
    pub slow_rise_c: f32,
    /// Stalled (no cooling at all: an SSR or modules dead before a pull-down began, the load
    /// at the ambient, neither warming nor falling, and found by neither test above until the
    /// 10 h heat alarm): full duty for this long, s (10 min)…
    pub stalled_on_s: f32,
    /// …the load fell by less than this since full duty began, °C…
    ///
    /// Every healthy carrier falls more: the campaign's carriers (H-TER I and II, each heat
    /// capacity and conductance ×0.5…1.5, 3 000 of them), pulled down from an ambient of
    /// 15–43 °C at full duty on a 9–12 V supply, fell ≥ 1.89 °C in the filtered reading in
    /// their first 10 min (the least: 15 °C ambient, 9 V), and above 15 °C each 5 min of full
    /// duty after the first 10 took ≥ 0.39 °C off (`hal-sim/src/plant.rs`). A dead SSR
    /// leaves the load at the ambient: 0.
    pub stalled_fall_c: f32,
    /// …and the load is warmer than this, °C: above every healthy carrier's full-cooling floor,
    /// where full duty that holds the load still is a carrier at its capacity, not a dead one.
    /// The highest floor of those carriers at 43 °C: 10.9 °C on 9.5 V (a mission's sag), 11.5 °C
    /// on 9 V (`--fault supply-sag`); the nominal H-TER I and II: −3.4 and −2.8 °C on 12 V.
    pub stalled_above_c: f32,
}

impl StuckOffConfig {
    /// The reference board's settings.
    pub const DEFAULT: StuckOffConfig = StuckOffConfig {
        on_s: 300.0,
        rise_c: 0.5,
        slow_on_s: 900.0,
        slow_rise_c: 0.3,
        stalled_on_s: 600.0,
        stalled_fall_c: 0.5,
        stalled_above_c: 15.0,
    };
}

/// Settings of the supply probe.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProbeConfig {
    /// A probe starts when no cooling was requested ([`StuckOnConfig::unrequested_duty`]) for
    /// this long, s (10 min)…
    pub unrequested_s: f32,
    /// …the load is more than this below the setpoint, °C…
    pub below_setpoint_c: f32,
    /// …and it fell by more than [`Self::fall_c`] over this window, s (5 min)…
    pub fall_window_s: f32,
    /// …°C.
    pub fall_c: f32,
    /// The supply stays open for at most this long, s (5 min), and the probe ends early when
    /// cooling is requested again with the load back within [`Self::yield_within_c`] of the
    /// setpoint.
    pub open_s: f32,
    /// A request for cooling ends the probe only once the load is less than this below the
    /// setpoint, °C (0: back at the setpoint). Below it, the request is the law anticipating
    /// the rise it sees — the very turn-up the probe is looking for: GPC saw a shorted SSR's
    /// load turn up at 3.1 °C under a 4 °C setpoint and asked for cooling 90 s into the
    /// confirming probe, one sample before the rise reached [`Self::turn_up_c`] in 30 s; the
    /// probe ended, and the short went unreported (campaign mission 24204, `--seed 20001`, with
    /// GPC's λ 3 at rest). 0.5 °C, half of [`Self::below_setpoint_c`], fixed that one but not a
    /// heavy carrier's slower turn-up: H-TER II at 37 °C rose 0.13–0.14 °C in 30 s as it reached
    /// 0.5 °C below the setpoint, and every probe of the day ended there, a sample or two short
    /// of the verdict (mission 72870, `--seed 70001`). Nothing is lost by waiting: no cooling is
    /// needed below the setpoint, and a warming too slow to be a turn-up (a lid: ≤ 0.1 °C in
    /// 30 s) takes a load from 1 °C below the setpoint at most to it in [`Self::open_s`].
    pub yield_within_c: f32,
    /// A rise of more than [`Self::turn_up_c`] over this window while the supply is open, s…
    pub turn_up_window_s: f32,
    /// …°C, was the supply cooling: a shorted SSR. A shorted SSR's cold side warms a light load
    /// by 0.2–0.4 °C in 30 s once it stops (the hot side's heat flows back), a heavy one by less:
    /// H-TER II at 37 °C turned up by 0.12–0.15 °C in 30 s, reached only in each probe's last
    /// minute, and at 0.15 °C the short went unreported all day (campaign mission 117730,
    /// `--seed 110001`). A lid opening or a warmer ambient that happens to coincide warms a load
    /// by ≤ 0.1 °C in 30 s (a probe starts only on a load falling with nothing asked, which a lid
    /// does not cause), and a first turn-up is a short only when the next probe turns up too.
    pub turn_up_c: f32,
    /// At most one probe in this time, s (an hour), except the one that confirms a first
    /// turn-up: it may start [`Self::open_s`] after it.
    pub interval_s: f32,
}

impl ProbeConfig {
    /// The reference board's settings.
    pub const DEFAULT: ProbeConfig = ProbeConfig {
        unrequested_s: 600.0,
        below_setpoint_c: 1.0,
        fall_window_s: 300.0,
        fall_c: 0.05,
        open_s: 300.0,
        yield_within_c: 0.0,
        turn_up_window_s: 30.0,
        turn_up_c: 0.12,
        interval_s: 3600.0,
    };
}

/// Limp home after a shorted SSR: On-Off through the supply switch (with the SSR commanded
/// alike, in case the short was a false alarm). Cooling that cannot be modulated still keeps
/// vaccines in 2–8 °C, where a latched-off supply would let them warm to the ambient; the
/// freeze guard still cuts.
///
/// The thermostat reads what the freeze guard reads: the filtered temperature extrapolated
/// along its falling slope ([`super::freeze::FreezeConfig::lookahead_s`], 120 s). The RTD reads
/// the water ≈ 50 s late, and on the reading alone the supply stayed on until the water had
/// fallen past the off level by that lag's worth of cooling: on a light carrier (campaign
/// mission 6391, `hter sim --mission-seed 6391`) the water fell 5.0 → 1.4 °C before the
/// supply opened and every cycle's low was 1.2–1.6 °C (0.8 °C once); on the look-ahead the
/// cycles' lows are 1.8–2.3 °C. On the reference carriers (`disturbance`, seed 11, full and half
/// load at 20, 32 and 43 °C) the band moves from 2.4–7.0 to 3.2–7.2 °C (`tests/faults.rs::a_shorted_ssr_limps_home_within_2_to_8`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LimpConfig {
    /// The supply switches on at or above the setpoint plus this, °C…
    pub on_above_c: f32,
    /// …and off at or below the setpoint minus this, °C (the coast after full cooling stops
    /// carries the load ≈ 1 °C further).
    pub off_below_c: f32,
}

impl LimpConfig {
    /// The reference board's settings.
    pub const DEFAULT: LimpConfig = LimpConfig { on_above_c: 1.0, off_below_c: 0.5 };

    /// Whether the supply is on this sample, with the load at `temp_c`, the setpoint `w`, and
    /// the supply `on` the sample before (a hysteresis).
    pub(crate) fn supply_on(&self, on: bool, temp_c: f32, w: f32) -> bool {
        if temp_c >= w + self.on_above_c {
            true
        } else if temp_c <= w - self.off_below_c {
            false
        } else {
            on
        }
    }
}

/// Samples of filtered temperature kept for the SSR checks: more than the longest window
/// ([`StuckOffConfig::on_s`], [`ProbeConfig::fall_window_s`]: 30 samples at 10 s). A window
/// longer than the ring never has its sample, and its check never fires.
pub const HISTORY: usize = 32;

/// What the supply probe does this sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Probe {
    /// Nothing changes.
    Keep,
    /// A probe begins: open the supply.
    Start,
    /// The probe ends without a verdict: cooling wanted again, or time is up.
    End,
    /// The load turned up with the supply open: the SSR is shorted.
    Shorted,
}

/// The sample counts and times the configuration means at the sample period.
#[derive(Clone, Copy, Debug)]
struct Limits {
    unrequested: u16,
    trip_window_ms: u32,
    off: u16,
    window: usize,
    stuck_off: u16,
    slow: u16,
    stalled: u16,
    probe_unrequested: u16,
    probe_fall: usize,
    probe_turn_up: usize,
    probe_open_ms: u32,
    probe_interval_ms: u32,
    /// The confirming probe may start this long less than a probe interval after a first
    /// turn-up ([`ProbeConfig::open_s`] after it).
    probe_again_ms: u32,
}

/// The SSR monitor's state.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SsrMonitor {
    n: Limits,
    /// A ring (not a shifted array: the shift cost ≈ 100 instructions a sample on the M4F).
    history: [f32; HISTORY],
    /// Samples in the ring, up to HISTORY.
    history_len: usize,
    /// Where the next sample goes.
    history_head: usize,
    /// Samples in a row with the applied duty 0, up to the previous sample.
    off_run: u16,
    /// Samples since the last one with the applied duty 0, up to the previous sample
    /// (`u16::MAX`: none yet).
    since_off: u16,
    /// Samples in a row at full duty, up to the previous sample.
    on_run: u16,
    /// Filtered temperature when the current run of full duty began, °C.
    on_start_c: f32,
    /// Samples in a row with no cooling requested (at most [`StuckOnConfig::unrequested_duty`]),
    /// up to the previous sample.
    req_off_run: u16,
    /// Stuck off was reported during this run of full duty.
    off_reported: bool,
    /// When the freeze guard last tripped, ms.
    trip_ms: Option<u64>,
    /// When the freeze guard last tripped with cooling not requested, ms.
    unrequested_trip_ms: Option<u64>,
    /// The fall of the filtered temperature over the previous sample, °C.
    last_drop_c: f32,
    /// When the last supply probe began, ms.
    probe_ms: Option<u64>,
    /// Probe starts left during which a turn-up confirms a first one (0: none to confirm).
    confirm_left: u8,
}

impl SsrMonitor {
    pub(crate) fn new(cfg: &SsrConfig, ts_s: f32) -> Self {
        let (on, off, p) = (&cfg.stuck_on, &cfg.stuck_off, &cfg.probe);
        let n = Limits {
            unrequested: samples_u16(on.unrequested_s, ts_s),
            trip_window_ms: ms(on.trip_window_s),
            off: samples_u16(on.off_s, ts_s),
            window: samples_u16(on.window_s, ts_s) as usize,
            stuck_off: samples_u16(off.on_s, ts_s),
            slow: samples_u16(off.slow_on_s, ts_s),
            stalled: samples_u16(off.stalled_on_s, ts_s),
            probe_unrequested: samples_u16(p.unrequested_s, ts_s),
            probe_fall: samples_u16(p.fall_window_s, ts_s) as usize,
            probe_turn_up: samples_u16(p.turn_up_window_s, ts_s) as usize,
            probe_open_ms: ms(p.open_s),
            probe_interval_ms: ms(p.interval_s),
            probe_again_ms: ms(p.interval_s).saturating_sub(ms(p.open_s)),
        };
        SsrMonitor {
            n,
            history: [0.0; HISTORY],
            history_len: 0,
            history_head: 0,
            off_run: 0,
            since_off: u16::MAX,
            on_run: 0,
            on_start_c: 0.0,
            req_off_run: 0,
            off_reported: false,
            trip_ms: None,
            unrequested_trip_ms: None,
            last_drop_c: 0.0,
            probe_ms: None,
            confirm_left: 0,
        }
    }

    /// Samples in a row at full duty, up to the previous sample.
    pub(crate) fn full_duty_run(&self) -> u16 {
        self.on_run
    }

    /// Path 1, on a sample where the freeze guard trips: whether the trip shows a shorted SSR
    /// (`shorted`: one was found already, nothing more to tell).
    pub(crate) fn freeze_tripped(
        &mut self,
        cfg: &StuckOnConfig,
        t_ms: u64,
        trend: &super::freeze::Trend,
        shorted: bool,
    ) -> bool {
        self.trip_ms = Some(t_ms);
        if shorted || self.req_off_run < self.n.unrequested {
            return false;
        }
        let again = self.unrequested_trip_ms.is_some_and(|t0| since(t_ms, t0) <= u64::from(self.n.trip_window_ms));
        if again || (trend.slope_c_per_s < cfg.falling_c_per_s && trend.drop_c >= self.last_drop_c) {
            true
        } else {
            self.unrequested_trip_ms = Some(t_ms);
            false
        }
    }

    /// Path 2, every sample with a trusted reading, after [`Self::freeze_tripped`]: whether the
    /// load falls fast and faster between trips. Remembers this sample's fall for the next.
    pub(crate) fn between_trips(
        &mut self,
        c: &StuckOnConfig,
        t_ms: u64,
        trend: &super::freeze::Trend,
        shorted: bool,
    ) -> bool {
        let found = !shorted
            && self.trip_ms.is_some_and(|t0| since(t_ms, t0) <= u64::from(self.n.trip_window_ms))
            && self.req_off_run >= self.n.unrequested
            && trend.drop_c > c.between_trips_drop_c
            && trend.drop_c >= self.last_drop_c
            && trend.slope_c_per_s < c.falling_c_per_s;
        self.last_drop_c = trend.drop_c;
        found
    }

    /// The channel's calibration changed by `r`: the temperatures the checks compare the next
    /// ones with, as the new line reads them (a calibration change is no move of the load: not
    /// a fall that keeps pace with the SSR off, nor a warming at full duty, nor a turn-up).
    pub(crate) fn recalibrated(&mut self, r: &crate::calib::Recalibration) {
        for t in &mut self.history {
            *t = r.level(*t);
        }
        self.on_start_c = r.level(self.on_start_c);
        self.last_drop_c = r.difference(self.last_drop_c);
    }

    /// Forgets the temperature history (the reading restarts after a sensor fault): the last
    /// samples before the fault are no window of the load's motion after it, and a drift
    /// across the gap read as a fall that keeps pace with the SSR off (path 3).
    pub(crate) fn restart(&mut self) {
        self.history_len = 0;
    }

    /// Puts this sample's filtered temperature in the ring (before the checks that read it).
    pub(crate) fn remember(&mut self, temp_c: f32) {
        if let Some(slot) = self.history.get_mut(self.history_head) {
            *slot = temp_c;
        }
        self.history_head = if self.history_head + 1 == HISTORY { 0 } else { self.history_head + 1 };
        self.history_len = (self.history_len + 1).min(HISTORY);
    }

    /// The filtered temperature `n` samples before the last one remembered.
    fn ago(&self, n: usize) -> Option<f32> {
        let (head, len) = (self.history_head, self.history_len);
        (n < len).then(|| self.history.get((head + HISTORY - 1 - n) % HISTORY).copied()).flatten()
    }

    /// Path 3: whether the load at `temp_c` still falls after the SSR has been off for a
    /// while, and not slower.
    pub(crate) fn still_falling(&self, c: &StuckOnConfig, temp_c: f32) -> bool {
        if self.off_run < self.n.off {
            return false;
        }
        match (self.ago(self.n.window), self.ago(2 * self.n.window)) {
            (Some(t1), Some(t2)) => {
                let (last, before) = (t1 - temp_c, t2 - t1);
                last > c.drop_c && last >= c.keep_pace * before
            }
            _ => false,
        }
    }

    /// Stuck off: whether the load at `temp_c` warms at full duty; true once per run of full
    /// duty, and again in the same run after the load has stopped warming.
    ///
    /// A carrier at its capacity in the heat runs at full duty for hours. Once the load is no
    /// warmer than [`StuckOffConfig::on_s`] ago the cooling holds it again, and a new fast
    /// warming (a lid opened, the SSR dying) is news: the check is armed again, for the fast
    /// test only (the slow test's start moves out of reach: a slow creep at full duty is the
    /// capacity on a warming afternoon, already reported). Mission 42110 (`--seed 40001`): a
    /// lid opening at 42 °C ambient was reported, the load levelled off, and a lid left open
    /// 10 min later warmed it from 6.6 to 19.5 °C at full duty without a word.
    ///
    /// A run of full duty that began within [`StuckOffConfig::on_s`] of a sample with no
    /// cooling (a supply probe, the supply opened at the floor, limp home's thermostat) is
    /// tested fast only after twice `on_s`: the heat the cabinet took in meanwhile keeps a heavy
    /// load warming for longer than `on_s` at full cooling. Mission 117730 (`--seed 110001`, a heavy
    /// H-TER II at 37 °C with a shorted SSR): after the supply was opened at the floor and after
    /// every limp-home off period it rose 0.7–0.9 °C in the 5 min after the supply closed again,
    /// and the short was reported 12 times that day as an SSR stuck off as well.
    pub(crate) fn warms_at_full_duty(&mut self, c: &StuckOffConfig, temp_c: f32) -> bool {
        let mut found = false;
        // Full duty for `on_run` samples, some cooling for `since_off`: the run's first sample
        // came `since_off − on_run + 1` samples after the last one with none.
        let soaked = u32::from(self.since_off) < u32::from(self.on_run) + u32::from(self.n.stuck_off);
        if self.on_run >= self.n.stuck_off << u16::from(soaked) {
            if let Some(past) = self.ago(self.n.stuck_off as usize) {
                if self.off_reported {
                    if temp_c <= past {
                        self.off_reported = false;
                        self.on_start_c = f32::INFINITY;
                    }
                } else {
                    let fast = temp_c - past > c.rise_c;
                    let slow = self.on_run >= self.n.slow && temp_c - self.on_start_c > c.slow_rise_c && temp_c > past;
                    // After a report the start is INFINITY: never stalled.
                    let stalled = self.on_run >= self.n.stalled
                        && temp_c > c.stalled_above_c
                        && self.on_start_c - temp_c < c.stalled_fall_c;
                    if fast || slow || stalled {
                        self.off_reported = true;
                        found = true;
                    }
                }
            }
        }
        if self.on_run == 0 {
            self.off_reported = false;
        }
        found
    }

    /// The supply probe at `t_ms`, with the one under way (`under_way`: when it began), the
    /// load at `temp_c` and the setpoint `w`. Only while no short has been found.
    pub(crate) fn probe(&mut self, p: &ProbeConfig, t_ms: u64, under_way: Option<u64>, temp_c: f32, w: f32) -> Probe {
        match under_way {
            Some(t0) => {
                if self.ago(self.n.probe_turn_up).is_some_and(|past| temp_c - past > p.turn_up_c) {
                    if self.confirm_left > 0 {
                        return Probe::Shorted;
                    }
                    // The first: close the supply; the confirming probe and the next one
                    // (counted down at their starts) may confirm it. The confirming one starts
                    // once the supply has been closed as long as a probe opens it.
                    self.confirm_left = 3;
                    self.probe_ms = Some(t_ms.saturating_sub(u64::from(self.n.probe_again_ms)));
                    Probe::End
                } else if (self.req_off_run == 0 && temp_c > w - p.yield_within_c)
                    || since(t_ms, t0) >= u64::from(self.n.probe_open_ms)
                {
                    Probe::End
                } else {
                    Probe::Keep
                }
            }
            None => {
                let idle = self.probe_ms.is_none_or(|t| since(t_ms, t) >= u64::from(self.n.probe_interval_ms));
                if idle && self.req_off_run >= self.n.probe_unrequested && temp_c < w - p.below_setpoint_c {
                    if let Some(past) = self.ago(self.n.probe_fall) {
                        if past - temp_c > p.fall_c {
                            self.probe_ms = Some(t_ms);
                            self.confirm_left = self.confirm_left.saturating_sub(1);
                            return Probe::Start;
                        }
                    }
                }
                Probe::Keep
            }
        }
    }

    /// Counts this sample's applied `duty` and `requested` duty (last: every check of the sample
    /// sees the runs up to the one before), with the load at `temp_c`.
    pub(crate) fn applied(&mut self, cfg: &SsrConfig, duty: Duty, requested: f32, temp_c: f32) {
        let full = duty.get() >= cfg.full_duty;
        let off = duty.get() == 0.0;
        self.off_run = if off { self.off_run.saturating_add(1) } else { 0 };
        self.since_off = if off { 0 } else { self.since_off.saturating_add(1) };
        if self.on_run == 0 && full {
            self.on_start_c = temp_c;
        }
        self.on_run = if full { self.on_run.saturating_add(1) } else { 0 };
        // A request that is not a number (a failed law) asked for nothing, and the step applied
        // nothing: no cooling requested (`<=` would take it for cooling, and a law failing
        // every sample would keep stuck-on paths 1 and 2 and the probe from ever looking).
        let asked = requested > cfg.stuck_on.unrequested_duty;
        self.req_off_run = if asked { 0 } else { self.req_off_run.saturating_add(1) };
    }
}

#[cfg(test)]
mod tests {
    use super::super::freeze::Trend;
    use super::*;

    const TS: f32 = 10.0;
    const CFG: SsrConfig = SsrConfig::DEFAULT;

    fn monitor() -> SsrMonitor {
        SsrMonitor::new(&CFG, TS)
    }

    /// `n` samples of `duty` with `requested` applied, the load at `temp_c`.
    fn apply(m: &mut SsrMonitor, n: usize, duty: Duty, requested: f32, temp_c: f32) {
        for _ in 0..n {
            m.applied(&CFG, duty, requested, temp_c);
        }
    }

    fn trend(drop_c: f32, slope_c_per_s: f32) -> Trend {
        Trend { drop_c, slope_c_per_s, predicted_c: 1.5 }
    }

    #[test]
    fn the_windows_are_todays_sample_counts() {
        let n = monitor().n;
        assert_eq!((n.unrequested, n.off, n.window, n.stuck_off, n.slow, n.stalled), (6, 24, 12, 30, 90, 60));
        assert_eq!((n.probe_unrequested, n.probe_fall, n.probe_turn_up), (60, 30, 3));
        assert_eq!((n.trip_window_ms, n.probe_open_ms, n.probe_interval_ms), (1_800_000, 300_000, 3_600_000));
        // Every window fits the ring.
        assert!(2 * n.window < HISTORY && n.probe_fall < HISTORY && (n.stuck_off as usize) < HISTORY);
    }

    #[test]
    fn stuck_on_path_1_needs_a_minute_unrequested_and_a_fast_fall_or_a_second_trip() {
        let fast = trend(0.1, -0.004);
        let mut m = monitor();
        apply(&mut m, 5, Duty::OFF, 0.0, 2.0);
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &fast, false), "five samples unrequested are not a minute");
        m.applied(&CFG, Duty::OFF, 0.0, 2.0);
        assert!(m.freeze_tripped(&CFG.stuck_on, 10_000, &fast, false));
        assert!(!m.freeze_tripped(&CFG.stuck_on, 10_000, &fast, true), "already found");
        // Slowing down (this fall smaller than the last) or slow: not on the first trip…
        let mut m = monitor();
        apply(&mut m, 6, Duty::OFF, 0.0, 2.0);
        assert!(!m.between_trips(&CFG.stuck_on, 0, &trend(0.2, -0.004), false));
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &trend(0.1, -0.004), false), "slowing down");
        let mut m = monitor();
        apply(&mut m, 6, Duty::OFF, 0.0, 2.0);
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &trend(0.3, -0.003), false), "−0.003 °C/s is not below −0.003");
        // …but a second unrequested trip within half an hour is.
        assert!(m.freeze_tripped(&CFG.stuck_on, 1_800_000, &trend(0.0, 0.0), false));
        let mut m = monitor();
        apply(&mut m, 6, Duty::OFF, 0.0, 2.0);
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &trend(0.0, 0.0), false));
        assert!(
            !m.freeze_tripped(&CFG.stuck_on, 1_800_001, &trend(0.0, 0.0), false),
            "half an hour and a millisecond later"
        );
    }

    /// Mission 9515 (`hter campaign --seed 1`, GPC with λ 3 at rest) in outline: a shorted SSR
    /// takes a light load down while the law backs off from its holding duty, 0.25, through
    /// 0.07 for one last sample to nothing; the guard trips five samples after the 0.07, on a
    /// fast fall. A tenth of full duty is no cooling requested: the minute runs from the 0.07,
    /// and the trip is the short's.
    #[test]
    fn a_few_hundredths_asked_are_no_cooling_requested() {
        let fast = trend(0.3, -0.02);
        let backing_off = |m: &mut SsrMonitor, last: f32| {
            apply(m, 10, Duty::saturating(0.25), 0.25, 4.0);
            m.applied(&CFG, Duty::saturating(last), last, 3.9);
            apply(m, 5, Duty::OFF, -1.0, 3.0);
        };
        let mut m = monitor();
        backing_off(&mut m, 0.07);
        assert!(m.freeze_tripped(&CFG.stuck_on, 0, &fast, false), "path 1");
        let mut m = monitor();
        backing_off(&mut m, 0.07);
        assert!(!m.between_trips(&CFG.stuck_on, 0, &fast, false), "no trip yet");
        m.trip_ms = Some(0);
        assert!(m.between_trips(&CFG.stuck_on, 10_000, &fast, false), "path 2");
        // 0.1 is still nothing; 0.11 is cooling, and the minute has not passed since.
        let mut m = monitor();
        backing_off(&mut m, 0.1);
        assert!(m.freeze_tripped(&CFG.stuck_on, 0, &fast, false));
        let mut m = monitor();
        backing_off(&mut m, 0.11);
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &fast, false));
    }

    /// The coast after cooling the law asked for: a pull-down at full duty cut to nothing, the
    /// load still falling fast for the ≈ 50 s the sensor lags. A trip within the minute after the
    /// last sample above a tenth of full duty is no short's, however little was asked at the
    /// samples between.
    #[test]
    fn the_coast_within_a_minute_of_real_cooling_is_no_short() {
        let fast = trend(0.3, -0.02);
        for (cut, last) in [(0.0f32, -0.5f32), (0.08, 0.08), (0.1, 0.1)] {
            let mut m = monitor();
            apply(&mut m, 30, Duty::FULL, 1.0, 6.0);
            m.applied(&CFG, Duty::saturating(0.5), 0.5, 5.0);
            // Five samples at or below a tenth since the 0.5 (`cut` three times, `last`, 0).
            apply(&mut m, 3, Duty::saturating(cut), cut, 4.0);
            m.applied(&CFG, Duty::saturating(last.max(0.0)), last, 3.0);
            apply(&mut m, 1, Duty::OFF, -1.0, 2.5);
            assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &fast, false), "{cut}: 50 s after the 0.5");
            m.trip_ms = Some(0);
            assert!(!m.between_trips(&CFG.stuck_on, 10_000, &fast, false), "{cut}: path 2");
            m.applied(&CFG, Duty::OFF, -1.0, 2.0);
            assert!(m.freeze_tripped(&CFG.stuck_on, 20_000, &fast, false), "{cut}: a minute after it");
        }
    }

    #[test]
    fn stuck_on_path_2_within_half_an_hour_of_a_trip() {
        let mut m = monitor();
        apply(&mut m, 6, Duty::OFF, 0.0, 2.0);
        assert!(!m.between_trips(&CFG.stuck_on, 0, &trend(0.2, -0.004), false), "no trip yet");
        // A trip with cooling requested: no verdict, but the window opens.
        let mut m = monitor();
        assert!(!m.freeze_tripped(&CFG.stuck_on, 0, &trend(0.0, 0.0), false));
        apply(&mut m, 6, Duty::OFF, 0.0, 2.0);
        assert!(!m.between_trips(&CFG.stuck_on, 600_000, &trend(0.1, -0.004), false), "0.1 °C is not more than 0.1");
        assert!(!m.between_trips(&CFG.stuck_on, 610_000, &trend(0.11, -0.003), false), "not falling fast");
        assert!(
            !m.between_trips(&CFG.stuck_on, 620_000, &trend(0.105, -0.004), false),
            "slower than the sample before"
        );
        assert!(m.between_trips(&CFG.stuck_on, 630_000, &trend(0.105, -0.004), false), "as fast as the sample before");
        assert!(!m.between_trips(&CFG.stuck_on, 640_000, &trend(0.2, -0.004), true), "already found");
        assert!(!m.between_trips(&CFG.stuck_on, 1_800_001, &trend(0.3, -0.004), false), "outside the window");
    }

    #[test]
    fn stuck_on_path_3_after_four_minutes_off_and_not_slowing() {
        let mut m = monitor();
        // The load falls 0.03 °C a sample: 0.36 °C in two minutes, the same every two minutes.
        let temps: Vec<f32> = (0..25).map(|k| 5.0 - 0.03 * k as f32).collect();
        for t in &temps {
            m.remember(*t);
        }
        apply(&mut m, 23, Duty::OFF, 0.0, 2.0);
        assert!(!m.still_falling(&CFG.stuck_on, temps[24]), "23 samples off are not four minutes");
        m.applied(&CFG, Duty::OFF, 0.0, 2.0);
        assert!(m.still_falling(&CFG.stuck_on, temps[24]));
        // A coast that slows: 0.36 °C in the last two minutes after 0.4 °C in the two before.
        let mut m = monitor();
        for k in 0..25 {
            m.remember(if k <= 12 { 5.0 - 0.4 * k as f32 / 12.0 } else { 4.6 - 0.36 * (k - 12) as f32 / 12.0 });
        }
        apply(&mut m, 24, Duty::OFF, 0.0, 2.0);
        assert!(!m.still_falling(&CFG.stuck_on, 4.24));
        // Too little fall: 0.288 °C in two minutes, not more than 0.3.
        let mut m = monitor();
        for k in 0..25 {
            m.remember(5.0 - 0.024 * k as f32);
        }
        apply(&mut m, 24, Duty::OFF, 0.0, 2.0);
        assert!(!m.still_falling(&CFG.stuck_on, 5.0 - 0.024 * 24.0));
    }

    /// The sample of full duty at which a load warming 0.02 °C a sample is reported stuck off,
    /// with the stuck-off window `on_s`.
    fn stuck_off_found_with_window(on_s: f32) -> Option<usize> {
        let cfg = SsrConfig { stuck_off: StuckOffConfig { on_s, ..CFG.stuck_off }, ..CFG };
        let mut m = SsrMonitor::new(&cfg, TS);
        let mut t = 5.0f32;
        let mut found = None;
        for k in 0..80 {
            m.remember(t);
            if m.warms_at_full_duty(&cfg.stuck_off, t) && found.is_none() {
                found = Some(k);
            }
            m.applied(&cfg, Duty::FULL, 1.0, t);
            t += 0.02;
        }
        found
    }

    #[test]
    fn the_longest_window_validation_accepts_still_fires_and_one_longer_would_not() {
        let longest = (HISTORY - 1) as f32 * TS;
        let accepted = |on_s| {
            let mut c = crate::supervisor::SupervisorConfig::DEFAULT;
            c.ssr.stuck_off.on_s = on_s;
            c.validate(TS).is_ok()
        };
        assert!(accepted(longest));
        assert_eq!(stuck_off_found_with_window(longest), Some(HISTORY - 1));
        // One sample longer: the ring never holds the sample the window starts at, so the
        // check would be silently off; validation refuses it.
        assert!(!accepted(longest + TS));
        assert_eq!(stuck_off_found_with_window(longest + TS), None);
    }

    #[test]
    fn stuck_off_fast_after_five_minutes_slow_after_fifteen() {
        let mut m = monitor();
        // Full duty; the load rises 0.02 °C a sample (0.6 °C in 5 min).
        let mut t = 5.0f32;
        let mut found = None;
        for k in 0..40 {
            m.remember(t);
            if m.warms_at_full_duty(&CFG.stuck_off, t) {
                assert!(found.is_none(), "reported twice");
                found = Some(k);
            }
            m.applied(&CFG, Duty::FULL, 1.0, t);
            t += 0.02;
        }
        assert_eq!(found, Some(30), "judged once 30 samples of full duty and a 30-sample window are in");
        // Slow: 0.005 °C a sample, 0.15 °C in 5 min; after 15 min 0.45 °C above the start.
        let mut m = monitor();
        let (mut t, mut found) = (5.0f32, None);
        for k in 0..100 {
            m.remember(t);
            if m.warms_at_full_duty(&CFG.stuck_off, t) && found.is_none() {
                found = Some(k);
            }
            m.applied(&CFG, Duty::FULL, 1.0, t);
            t += 0.005;
        }
        assert_eq!(found, Some(90));
        // A working SSR turns the load around: no report.
        let mut m = monitor();
        for k in 0..100u16 {
            let t = 5.0 + 0.01 * (k.min(20) as f32) - 0.01 * (k.saturating_sub(20) as f32);
            m.remember(t);
            assert!(!m.warms_at_full_duty(&CFG.stuck_off, t), "sample {k}");
            m.applied(&CFG, Duty::FULL, 1.0, t);
        }
    }

    /// Mission 117730 (`--seed 110001`): a shorted SSR on a heavy H-TER II at 37 °C, found at
    /// 55 760 s; limp home's thermostat then opens the supply (36 samples here, the load warming
    /// from 3.26 to 5.00 °C) and closes it, and at full cooling the load warms on for 6 min,
    /// 0.86 °C in the first 5, before it turns. The filtered readings, 55 700–56 800 s.
    const SOAK_117730_OFF: [f32; 36] = [
        3.261, 3.294, 3.336, 3.373, 3.413, 3.456, 3.501, 3.544, 3.592, 3.639, 3.684, 3.727, 3.782, 3.836, 3.873, 3.926,
        3.983, 4.030, 4.080, 4.133, 4.181, 4.231, 4.282, 4.338, 4.393, 4.446, 4.501, 4.560, 4.616, 4.665, 4.723, 4.780,
        4.833, 4.890, 4.942, 4.997,
    ];
    const SOAK_117730_FULL: [f32; 75] = [
        5.051, 5.114, 5.172, 5.221, 5.275, 5.338, 5.391, 5.443, 5.495, 5.545, 5.582, 5.617, 5.655, 5.690, 5.715, 5.735,
        5.759, 5.781, 5.797, 5.816, 5.827, 5.841, 5.864, 5.875, 5.883, 5.898, 5.905, 5.903, 5.908, 5.913, 5.923, 5.931,
        5.935, 5.944, 5.949, 5.957, 5.948, 5.953, 5.951, 5.958, 5.961, 5.963, 5.961, 5.965, 5.970, 5.970, 5.965, 5.954,
        5.959, 5.954, 5.964, 5.957, 5.950, 5.949, 5.947, 5.953, 5.956, 5.942, 5.945, 5.945, 5.944, 5.933, 5.938, 5.931,
        5.921, 5.914, 5.916, 5.906, 5.907, 5.904, 5.903, 5.892, 5.889, 5.882, 5.877,
    ];

    /// The samples of full duty at which a monitor reports stuck off on `full`, after the
    /// samples `before` (the load, °C, and the duty applied).
    fn stuck_off_after(before: &[(f32, f32)], full: &[f32]) -> Vec<usize> {
        let mut m = monitor();
        for &(t, duty) in before {
            m.remember(t);
            assert!(!m.warms_at_full_duty(&CFG.stuck_off, t));
            m.applied(&CFG, Duty::new(duty).unwrap(), duty, t);
        }
        let mut found = Vec::new();
        for (k, &t) in full.iter().enumerate() {
            m.remember(t);
            if m.warms_at_full_duty(&CFG.stuck_off, t) {
                found.push(k);
            }
            m.applied(&CFG, Duty::FULL, 1.0, t);
        }
        found
    }

    #[test]
    fn full_duty_after_the_supply_was_open_waits_out_the_heat_the_cabinet_took_in() {
        let at = |duty: f32| SOAK_117730_OFF.map(|t| (t, duty));
        // Mission 117730's limp-home cycle: no report (it was one on every cycle, 11 in the day).
        assert_eq!(stuck_off_after(&at(0.0), &SOAK_117730_FULL), []);
        // The same full-duty run after the same readings at half duty, or from the start, is
        // tested at 5 min, and reported.
        assert_eq!(stuck_off_after(&at(0.5), &SOAK_117730_FULL), [30]);
        assert_eq!(stuck_off_after(&[], &SOAK_117730_FULL), [30]);
        // The last sample with no cooling 310 s before full duty's first: at 5 min; 300 s
        // before (within `on_s`), at 10 min.
        let mut before = at(0.5);
        before[before.len() - 31].1 = 0.0;
        assert_eq!(stuck_off_after(&before, &SOAK_117730_FULL), [30]);
        let dead: Vec<f32> = (0..80).map(|k| 5.0 + 0.02 * k as f32).collect();
        before[before.len() - 30].1 = 0.0;
        assert_eq!(stuck_off_after(&before, &dead), [60]);
        // An SSR that dies while the supply was open: the load keeps warming 0.02 °C a sample
        // (0.6 °C in 5 min) at full duty. Reported at 10 min, and not before.
        assert_eq!(stuck_off_after(&at(0.0), &dead), [60]);
    }

    /// The samples of full duty at which a monitor reports stuck off on a load that starts at
    /// `start_c` and changes by `rate_c` a sample.
    fn stuck_off_on_a_ramp(start_c: f32, rate_c: f32, samples: u16) -> Vec<usize> {
        // The same monitor as `stuck_off_after`'s, from no readings before full duty.
        let ramp: Vec<f32> = (0..samples).map(|k| start_c + rate_c * f32::from(k)).collect();
        stuck_off_after(&[], &ramp)
    }

    #[test]
    fn stuck_off_when_full_duty_leaves_a_warm_load_where_it_is() {
        // An SSR dead before the pull-down: the load stays at the ambient (30 °C), full duty
        // for ever. Neither warming test sees it; stalled at 10 min, once.
        assert_eq!(stuck_off_on_a_ramp(30.0, 0.0, 400), [60]);
        // The same drifting down less than 0.5 °C in 10 min (the ambient falling at night).
        assert_eq!(stuck_off_on_a_ramp(30.0, -0.008, 400), [60]);
        // A healthy pull-down from 15.5 °C at its slowest, 0.39 °C in 5 min: not stalled.
        assert_eq!(stuck_off_on_a_ramp(15.5, -0.013, 100), [0usize; 0]);
        // A carrier at its capacity, full duty holding 12 °C on a hot day: not a dead SSR.
        assert_eq!(stuck_off_on_a_ramp(12.0, 0.0, 400), [0usize; 0]);
    }

    #[test]
    fn stuck_off_again_in_the_same_run_after_the_load_stopped_warming() {
        // Mission 42110 in outline: one run of full duty; a lid opening warms the load (reported),
        // the cooling levels it off, it creeps up slowly (the capacity: not reported again), a
        // second opening warms it fast (reported again).
        let mut m = monitor();
        let mut t = 6.0f32;
        let mut found = Vec::new();
        let phases: [(u16, f32); 4] = [(40, 0.02), (40, -0.001), (120, 0.004), (40, 0.03)];
        let mut k = 0u16;
        for (n, rate) in phases {
            for _ in 0..n {
                m.remember(t);
                if m.warms_at_full_duty(&CFG.stuck_off, t) {
                    found.push(k);
                }
                m.applied(&CFG, Duty::FULL, 1.0, t);
                t += rate;
                k += 1;
            }
        }
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!(found[0], 30);
        assert!((200..230).contains(&found[1]), "{found:?}");
        // Still warming after the first report: not armed again.
        let mut m = monitor();
        let mut t = 6.0f32;
        let mut n = 0;
        for _ in 0..300 {
            m.remember(t);
            n += usize::from(m.warms_at_full_duty(&CFG.stuck_off, t));
            m.applied(&CFG, Duty::FULL, 1.0, t);
            t += 0.02;
        }
        assert_eq!(n, 1);
    }

    #[test]
    fn the_probe_starts_below_the_setpoint_and_finds_a_turn_up() {
        let mut m = monitor();
        // Falling 0.002 °C a sample, 3 °C at setpoint 4.1 °C, nothing asked for 10 min.
        falling_to_3(&mut m);
        apply(&mut m, 59, Duty::OFF, 0.0, 3.0);
        assert_eq!(m.probe(&CFG.probe, 0, None, 3.0, 4.1), Probe::Keep, "59 samples are not 10 min");
        m.applied(&CFG, Duty::OFF, 0.0, 3.0);
        assert_eq!(m.probe(&CFG.probe, 0, None, 3.0, 4.0), Probe::Keep, "not more than 1 °C below");
        assert_eq!(m.probe(&CFG.probe, 0, None, 3.0, 4.1), Probe::Start);
        assert_eq!(m.probe(&CFG.probe, 10_000, None, 3.0, 4.1), Probe::Keep, "one an hour");
        assert_eq!(m.probe(&CFG.probe, 10_000, Some(0), 3.0, 4.1), Probe::Keep);
        assert_eq!(m.probe(&CFG.probe, 300_000, Some(0), 3.0, 4.1), Probe::End, "five minutes");
        // 0.2 °C up in 30 s: the supply was cooling, or a lid opened. A first turn-up ends the
        // probe (what confirms it: the next test).
        m.remember(3.2);
        assert_eq!(m.probe(&CFG.probe, 20_000, Some(0), 3.2, 4.1), Probe::End);
        // Cooling requested again ends it, once the load is back at the setpoint; below it the
        // request is the law's anticipation and the probe goes on. The load warms 0.038 °C a
        // sample (0.114 °C in 30 s: no turn-up) from 3 °C, past a 3.9 °C setpoint at the 24th.
        m.applied(&CFG, Duty::OFF, 0.5, 3.0);
        for k in 1..=24u16 {
            let t = 3.0 + 0.038 * f32::from(k);
            m.remember(t);
            let expected = if k < 24 { Probe::Keep } else { Probe::End };
            assert_eq!(m.probe(&CFG.probe, 20_000 + 10_000 * u64::from(k), Some(0), t, 3.9), expected, "{t} °C");
        }
    }

    /// A probe under way since `t0_ms`, one sample every 10 s from `t0_ms + 10 s`: each sample's
    /// filtered load and the duty the law asked for at it (seen by the probe from the next
    /// sample on, as in the step), at setpoint `w`, under `cfg`. The probe's answers, up to the
    /// first that is not `Keep`.
    fn probe_through(m: &mut SsrMonitor, cfg: &SsrConfig, t0_ms: u64, samples: &[(f32, f32)], w: f32) -> Vec<Probe> {
        let mut out = Vec::new();
        for (k, &(temp_c, requested)) in samples.iter().enumerate() {
            m.remember(temp_c);
            let p = m.probe(&cfg.probe, t0_ms + 10_000 * (k as u64 + 1), Some(t0_ms), temp_c, w);
            out.push(p);
            if p != Probe::Keep {
                break;
            }
            m.applied(cfg, Duty::OFF, requested, temp_c);
        }
        out
    }

    /// Mission 24204 (`hter campaign --seed 20001`, GPC with λ 3 at rest): a shorted SSR's
    /// load at 35 °C ambient, 1 °C under a 4 °C setpoint. At the confirming probe the load
    /// turned up and GPC asked for cooling (0.11, then 0.45) a sample before the rise reached
    /// 0.15 °C in 30 s; the request ended the probe and the short went unreported. The filtered
    /// readings of that probe, the requests as GPC made them.
    #[test]
    fn a_turn_up_is_a_short_though_the_law_asks_for_cooling_far_below_the_setpoint() {
        let confirming: [(f32, f32); 11] = [
            (2.9898, -0.79),
            (2.9889, -0.78),
            (2.9780, -0.92),
            (2.9804, -0.74),
            (2.9790, -0.79),
            (2.9835, -0.70),
            (3.0092, -0.38),
            (3.0351, -0.34),
            (3.0897, 0.114),
            (3.1561, 0.448),
            (3.2232, 0.80),
        ];
        let mut m = monitor();
        assert_eq!(probe_at(&mut m, 7_200_000, true), (Probe::Start, Probe::End), "the first turn-up");
        let again = 7_200_000 + 600_000;
        assert_eq!(start_probe_at(&mut m, again), Probe::Start);
        let answers = probe_through(&mut m, &CFG, again, &confirming, 4.0);
        assert_eq!(answers.last(), Some(&Probe::Shorted), "{answers:?}");
        assert_eq!(answers.len(), confirming.len() - 1, "found at 3.16 °C, 0.147 °C up in 30 s");
        // Before: a request ended the probe whatever the load, and the verdict needed 0.15 °C
        // in 30 s, one sample later.
        let before =
            SsrConfig { probe: ProbeConfig { yield_within_c: f32::INFINITY, turn_up_c: 0.15, ..CFG.probe }, ..CFG };
        let mut m = SsrMonitor::new(&before, TS);
        assert_eq!(probe_at(&mut m, 7_200_000, true).1, Probe::End);
        assert_eq!(start_probe_at(&mut m, again), Probe::Start);
        let answers = probe_through(&mut m, &before, again, &confirming, 4.0);
        assert_eq!((answers.len(), answers.last()), (10, Some(&Probe::End)), "{answers:?}");
    }

    /// Mission 117730 (`hter campaign --seed 110001`): a shorted SSR on a heavy H-TER II at
    /// 37 °C. The filtered readings of one of its probes (52 090 s, setpoint 4 °C): the load
    /// turns up slowly, by 0.13–0.15 °C in 30 s over the probe's last minute only, against the
    /// 0.2–0.4 °C of a light carrier. At 0.15 °C every probe of the day ran its five minutes
    /// without a verdict and the short went unreported; at 0.12 °C the first probe's turn-up
    /// (at the 24th sample) and the confirming probe's make it a short.
    #[test]
    fn a_heavy_carriers_slow_turn_up_is_a_short() {
        const PROBE: [f32; 30] = [
            2.9883, 2.996, 2.9973, 2.9927, 2.9904, 2.9892, 2.986, 2.9923, 3.0032, 3.0217, 3.0335, 3.0525, 3.0776,
            3.1032, 3.129, 3.1627, 3.1927, 3.2232, 3.2594, 3.3009, 3.3373, 3.3763, 3.4193, 3.4642, 3.5075, 3.5526,
            3.5986, 3.6477, 3.7009, 3.7483,
        ];
        let nothing_asked: Vec<(f32, f32)> = PROBE.iter().map(|&t| (t, 0.0)).collect();
        let (first, again) = (7_200_000, 7_200_000 + 600_000);
        let mut m = monitor();
        assert_eq!(start_probe_at(&mut m, first), Probe::Start);
        let answers = probe_through(&mut m, &CFG, first, &nothing_asked, 4.0);
        assert_eq!((answers.len(), answers.last()), (24, Some(&Probe::End)), "the first turn-up: {answers:?}");
        assert_eq!(start_probe_at(&mut m, again), Probe::Start);
        let answers = probe_through(&mut m, &CFG, again, &nothing_asked, 4.0);
        assert_eq!((answers.len(), answers.last()), (24, Some(&Probe::Shorted)), "{answers:?}");
        // At 0.15 °C in 30 s the probe runs its five minutes and ends without a verdict.
        let before = SsrConfig { probe: ProbeConfig { turn_up_c: 0.15, ..CFG.probe }, ..CFG };
        let mut m = SsrMonitor::new(&before, TS);
        assert_eq!(start_probe_at(&mut m, first), Probe::Start);
        let answers = probe_through(&mut m, &before, first, &nothing_asked, 4.0);
        assert_eq!((answers.len(), answers.last()), (30, Some(&Probe::End)), "{answers:?}");
    }

    /// Without a short nothing turns the load up: a probe on a load coasting down, or warming as
    /// slowly as an opened lid warms it (0.1 °C in 30 s), with the law asking for a little
    /// cooling all along, ends without a verdict — at 5 min, or once the warming load is back
    /// at the setpoint.
    #[test]
    fn a_probe_with_cooling_asked_and_no_turn_up_finds_nothing() {
        let mut m = monitor();
        let coast: Vec<(f32, f32)> = (1..=40).map(|k| (3.0 - 0.002 * k as f32, 0.05)).collect();
        let answers = probe_through(&mut m, &CFG, 0, &coast, 4.1);
        assert_eq!(answers.len(), 30, "five minutes: {answers:?}");
        assert_eq!(answers.last(), Some(&Probe::End));
        let mut m = monitor();
        falling_to_3(&mut m);
        let lid: Vec<(f32, f32)> = (1..=40).map(|k| (3.0 + 0.03 * k as f32, 0.3)).collect();
        let answers = probe_through(&mut m, &CFG, 0, &lid, 4.0);
        assert!(!answers.contains(&Probe::Shorted), "{answers:?}");
        // 4.02 °C, above the setpoint, at the 34th sample: the five minutes end it first.
        assert_eq!(answers.len(), 30, "{answers:?}");
        assert_eq!(answers.last(), Some(&Probe::End));
    }

    /// A probe at `t_ms` (the load at 3 °C, setpoint 4.1 °C, falling 0.002 °C a sample, nothing
    /// asked for 10 min): its start, and its verdict 5 min later with the load up 0.2 °C in
    /// 30 s (`up`) or not.
    fn probe_at(m: &mut SsrMonitor, t_ms: u64, up: bool) -> (Probe, Probe) {
        let start = start_probe_at(m, t_ms);
        let t = if up { 3.2 } else { 3.0 };
        m.remember(t);
        (start, m.probe(&CFG.probe, t_ms + 300_000, Some(t_ms), t, 4.1))
    }

    /// Five minutes of the load's history, falling 0.002 °C a sample to 3 °C.
    fn falling_to_3(m: &mut SsrMonitor) {
        for k in 0..31 {
            m.remember(3.06 - 0.002 * k as f32);
        }
    }

    /// [`probe_at`]'s start alone.
    fn start_probe_at(m: &mut SsrMonitor, t_ms: u64) -> Probe {
        falling_to_3(m);
        apply(m, 60, Duty::OFF, 0.0, 3.0);
        m.probe(&CFG.probe, t_ms, None, 3.0, 4.1)
    }

    /// Mission 20465 (`hter campaign --seed 20001`): a lid opened 49 s into a probe warmed a
    /// light load 0.157 °C in 30 s. A turn-up is a short only when it comes again, at the
    /// confirming probe (5 min after the first turn-up at the earliest) or at the next one.
    #[test]
    fn a_turn_up_is_a_short_when_the_confirming_probe_or_the_next_turns_up_too() {
        const H: u64 = 3_600_000;
        let (keep, start, end, shorted) = (Probe::Keep, Probe::Start, Probe::End, Probe::Shorted);
        // Confirmed by the confirming probe.
        let mut m = monitor();
        assert_eq!(probe_at(&mut m, 2 * H, true), (start, end), "a first turn-up");
        let again = 2 * H + 600_000;
        assert_eq!(m.probe(&CFG.probe, again - 1, None, 3.0, 4.1), keep, "closed less than 5 min");
        assert_eq!(probe_at(&mut m, again, true), (start, shorted));
        // By the next one, an hour later.
        let mut m = monitor();
        assert_eq!(probe_at(&mut m, 2 * H, true), (start, end));
        assert_eq!(probe_at(&mut m, again, false), (start, end));
        assert_eq!(m.probe(&CFG.probe, again + H - 1, None, 3.0, 4.1), keep, "one an hour");
        assert_eq!(probe_at(&mut m, again + H, true), (start, shorted));
        // Not by the one after: that turn-up is a first again.
        let mut m = monitor();
        assert_eq!(probe_at(&mut m, 2 * H, true), (start, end));
        assert_eq!(probe_at(&mut m, again, false), (start, end));
        assert_eq!(probe_at(&mut m, again + H, false), (start, end));
        assert_eq!(probe_at(&mut m, again + 2 * H, true), (start, end));
        assert_eq!(probe_at(&mut m, again + 2 * H + 600_000, true), (start, shorted));
    }

    #[test]
    fn limp_home_has_a_hysteresis() {
        let l = LimpConfig::DEFAULT;
        assert!(!l.supply_on(false, 4.99, 4.0));
        assert!(l.supply_on(false, 5.0, 4.0));
        assert!(l.supply_on(true, 3.51, 4.0));
        assert!(!l.supply_on(true, 3.5, 4.0));
        assert!(!l.supply_on(false, 4.5, 4.0));
    }
}

/// The SSR checks as the step runs them.
#[cfg(test)]
mod carrier {
    use crate::event::EventKind;
    use crate::step::tests::{counts_at, pi_carrier};
    use crate::step::{Mode, StepInput};

    /// A load below its setpoint drifting down toward a cold ambient, nothing asked: 0.003 °C a
    /// sample, a tenth of path 3's 0.3 °C in two minutes. A loose sensor lead reads open for
    /// half an hour in between; the load went on drifting (0.54 °C) meanwhile. The first
    /// readings after the fault are no fall that keeps pace with an SSR off: the checks'
    /// history does not span the gap.
    #[test]
    fn a_sensor_fault_in_a_cold_ambient_is_no_shorted_ssr() {
        let mut c = pi_carrier();
        let temp = |k: u64| 3.8 - 0.003 * k as f32;
        let mut events = Vec::new();
        for k in 0..400u64 {
            let counts = if (100..280).contains(&k) { 65_535 } else { counts_at(temp(k)) + (k % 2) as u32 };
            let out = c.step(&StepInput { t_ms: k * 10_000, counts, setpoint_c: 4.0 });
            events.extend(out.events.iter().map(|e| (k, e.kind)));
            assert_ne!(out.mode, Mode::LimpHome, "sample {k}: {events:?}");
        }
        assert_eq!(events, [(100, EventKind::SensorOpen), (280, EventKind::SensorRecovered)]);
    }

    /// A law that always asks for `0` (`Ok(0.0)`: no cooling) or has no answer (`Err`: the step
    /// applies no cooling and says so).
    struct Asks(Result<f32, crate::control::ControlError>);

    impl crate::control::Controller for Asks {
        fn update(&mut self, _: &crate::control::ControlInput) -> Result<f32, crate::control::ControlError> {
            self.0
        }
        fn track(&mut self, _: &crate::control::ControlInput, _: f32) {}
        fn name(&self) -> &'static str {
            "asks"
        }
    }

    /// The sample at which the freeze guard trips on a load falling faster every sample with no
    /// cooling applied (a shorted SSR), and the events of that sample.
    fn trip<C: crate::control::Controller>(mut c: crate::step::Carrier<C>) -> (u64, Vec<EventKind>) {
        for k in 0..60u64 {
            let t = 4.0 - 0.004 * (k * k) as f32;
            let out = c.step(&StepInput { t_ms: k * 10_000, counts: counts_at(t), setpoint_c: 4.0 });
            assert_eq!(out.duty, crate::units::Duty::OFF, "sample {k}");
            let kinds: Vec<EventKind> = out.events.iter().map(|e| e.kind).collect();
            if kinds.contains(&EventKind::FreezeGuardTripped) {
                return (k, kinds);
            }
        }
        panic!("the guard never tripped");
    }

    /// A request that is not a number asked for no cooling (the step applied none): the SSR
    /// checks' "nothing requested for a minute" runs on, and the trip is the short's, as under a
    /// law that asks for nothing.
    #[test]
    fn a_failed_laws_request_is_no_cooling_requested() {
        let asks = |r| crate::step::Carrier::new(crate::step::ValidConfig::DEFAULT, Asks(r));
        let (k, kinds) = trip(asks(Ok(0.0)));
        assert!(kinds.contains(&EventKind::SsrStuckOn), "nothing asked, sample {k}: {kinds:?}");
        let (k, kinds) = trip(asks(Err(crate::control::ControlError::NonFinite)));
        assert!(kinds.contains(&EventKind::SsrStuckOn), "a failed law, sample {k}: {kinds:?}");
    }
}
